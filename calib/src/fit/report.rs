//! What a calibration reports: fit stages, estimates, outliers, the learned stage, and their text.

use super::RobustLoss;
use crate::fit::identifiability::{NullSpaceReport, Observability};
use crate::health::Health;
use crate::lm::MinimizationReport;
use crate::model::spec::ModelSpec;
use crate::model::stats::ResidualStats;
use crate::units::Unit;

/// The learned residual correction of a `learned:` model: what it is and what it does on the data.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LearnedStage {
    /// Its one-line description (kind, selected hyperparameters, cross-validated RMS).
    pub description: String,
    /// Whether cross-validation kept it (otherwise it predicts zero).
    pub active: bool,
    /// Errors of the physical model plus the correction on the training rows.
    pub train: ResidualStats,
    /// The same on the test rows.
    pub test: Option<ResidualStats>,
}

/// One parameter's estimate.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ParameterEstimate {
    /// Name, e.g. `joint 2 twist ω_x`, `T_tracker_base x`.
    pub name: String,
    /// Its unit (`rad` or `m` for the kinematic parameters).
    pub unit: Unit,
    /// Estimate.
    pub value: f64,
    /// Standard deviation (to first order; for parameters not identifiable alone, in the minimum-norm
    /// convention and not meaningful by itself).
    pub sigma: f64,
    /// True when the data determine this parameter on its own.
    pub identifiable_alone: bool,
}

/// A strong correlation between two individually identifiable parameters.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Correlation {
    /// First parameter.
    pub a: String,
    /// Second parameter.
    pub b: String,
    /// Correlation coefficient.
    pub rho: f64,
}

/// A row whose residual is far beyond the noise.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Outlier {
    /// 1-based row of the table.
    pub row: usize,
    /// Pose id.
    pub pose: i64,
    /// Normalised residual norm `t` (see [`CalibrationOptions::outlier_threshold`]).
    pub normalised_residual: f64,
    /// Position error norm (m).
    pub error_m: f64,
}

/// One fit stage: solver outcome and residuals on the training and test rows.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FitStage {
    /// What was fitted.
    pub parameters: String,
    /// Solver outcome.
    pub solver: MinimizationReport,
    /// Errors on the training rows.
    pub train: ResidualStats,
    /// Errors on the held-out rows, when there are any.
    pub test: Option<ResidualStats>,
}

/// IRLS summary.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RobustSummary {
    /// The loss.
    pub loss: RobustLoss,
    /// Reweighting rounds.
    pub rounds: usize,
    /// Rows with a final weight below 0.5.
    pub downweighted_rows: usize,
}

/// Everything a calibration found out: outcomes as data.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CalibrationReport {
    /// Robot name.
    pub robot: String,
    /// Model name (`kinematic`).
    pub model: ModelSpec,
    /// Training rows and distinct poses.
    pub n_train_rows: usize,
    /// Distinct training poses.
    pub n_train_poses: usize,
    /// Held-out rows.
    pub n_test_rows: usize,
    /// Distinct held-out poses.
    pub n_test_poses: usize,
    /// Nominal joints, tracker-to-base transform and target fitted.
    pub before: FitStage,
    /// The full kinematic model fitted.
    pub after: FitStage,
    /// Degrees of freedom `m − rank`.
    pub dof: usize,
    /// `χ²/dof` at the solution: 1 when the noise model is right and the model explains the data.
    pub chi2_per_dof: f64,
    /// Where the variance factor of the covariance comes from.
    pub variance_factor_source: String,
    /// Estimated standard deviation of one measured coordinate (m): the noise model's σ times
    /// `√(χ²/dof)`, as RMS over the training rows.
    pub sigma_hat_m: f64,
    /// Parameter estimates with standard deviations.
    pub parameters: Vec<ParameterEstimate>,
    /// Pairs of individually identifiable parameters with |ρ| ≥ 0.95 (strongest first, at most 20).
    pub strong_correlations: Vec<Correlation>,
    /// Observability of the training pose set.
    pub observability: Observability,
    /// Unidentifiable directions, in words.
    pub unidentifiable: NullSpaceReport,
    /// Rows beyond the outlier threshold (after calibration).
    pub outliers: Vec<Outlier>,
    /// Gross errors excluded from the fit (weight 0; see
    /// [`super::CalibrationOptions::gross_error_threshold`]): the normalised residual when found, the
    /// position error against the final fit of the other rows.
    #[serde(default)]
    pub excluded: Vec<Outlier>,
    /// IRLS summary when a robust loss was used.
    pub robust: Option<RobustSummary>,
    /// The learned residual correction on top of the physical model, with a `learned:` model.
    pub learned: Option<LearnedStage>,
    /// The scatter of repeated measurements of a pose among the training rows, as read (gross
    /// errors included), when there are repeats ([`super::repeats`]).
    #[serde(default)]
    pub repeatability: Option<super::repeats::Repeatability>,
    /// Things a user should know (data-specific unidentifiable parameters, weak combinations, …).
    pub warnings: Vec<String>,
    /// Numerical warnings of every solve behind this report (base-and-target fit, full fit, robust
    /// rounds, equilibrium refits), counted: empty when every solve was clean.
    #[serde(default)]
    pub health: Health,
}

impl CalibrationReport {
    /// True when the full fit converged.
    pub fn was_successful(&self) -> bool {
        self.after.solver.was_successful()
    }

    /// The variance factor of the covariance: `χ²/dof`, or 1 without degrees of freedom left (then
    /// the standard deviations assume the noise model is exact).
    pub fn variance_factor(&self) -> f64 {
        if self.chi2_per_dof.is_finite() {
            self.chi2_per_dof
        } else {
            1.0
        }
    }

    /// The report as text for a terminal.
    pub fn text(&self) -> String {
        let mut s = String::new();
        let mm = |v: f64| format!("{:.4} mm", v * 1e3);
        let line = |s: &mut String, t: String| {
            s.push_str(&t);
            s.push('\n');
        };
        line(
            &mut s,
            format!(
                "calibration of '{}' ({} model): {} training rows ({} poses), {} held-out rows ({} poses)",
                self.robot,
                self.model,
                self.n_train_rows,
                self.n_train_poses,
                self.n_test_rows,
                self.n_test_poses
            ),
        );
        line(
            &mut s,
            format!(
                "solver: {} after {} iterations; χ² {:.6e} -> {:.6e}; χ²/dof = {:.3} (dof {})",
                self.after.solver.termination,
                self.after.solver.iterations,
                self.after.solver.cost_initial,
                self.after.solver.cost_final,
                self.chi2_per_dof,
                self.dof
            ),
        );
        if let Some(r) = &self.repeatability {
            line(
                &mut s,
                format!(
                    "repeatability: {:.2} µm RMS about each pose's mean ({:.2} µm per axis), from {} \
                     repeats of {} poses; noise estimate σ̂ {:.2} µm per axis",
                    r.rms_m * 1e6,
                    r.per_axis_m() * 1e6,
                    r.repeats,
                    r.poses,
                    self.sigma_hat_m * 1e6
                ),
            );
        }
        line(&mut s, "position errors (|predicted − measured|):".into());
        line(
            &mut s,
            "  set    model                 rows    RMS          mean         max".into(),
        );
        let row = |s: &mut String, set: &str, model: &str, st: &ResidualStats| {
            line(
                s,
                format!(
                    "  {set:<6} {model:<20} {:>5}   {:<12} {:<12} {}",
                    st.n,
                    mm(st.rms_m),
                    mm(st.mean_m),
                    mm(st.max_m)
                ),
            )
        };
        row(&mut s, "train", "nominal+base+target", &self.before.train);
        row(&mut s, "train", "calibrated", &self.after.train);
        if let (Some(b), Some(a)) = (&self.before.test, &self.after.test) {
            row(&mut s, "test", "nominal+base+target", b);
            row(&mut s, "test", "calibrated", a);
        }
        let o = &self.observability;
        line(
            &mut s,
            format!(
                "observability: {} of {} parameter combinations identifiable; condition number {:.3e}; \
                 σ_min {:.3e}; O1 {:.3e} O2 {:.3e} O3 {:.3e} O4 {:.3e} O5 {:.3e} (Sun & Hollerbach 2008)",
                o.rank, o.n_params, o.condition_number, o.sigma_min, o.o1, o.o2, o.o3, o.o4, o.o5
            ),
        );
        line(
            &mut s,
            format!(
                "not identifiable ({} directions):",
                self.unidentifiable.dimension
            ),
        );
        for u in &self.unidentifiable.summary {
            line(&mut s, format!("  {u}"));
        }
        line(
            &mut s,
            "parameters (σ from the covariance; * = determined on its own):".into(),
        );
        for p in &self.parameters {
            let mark = if p.identifiable_alone { '*' } else { ' ' };
            let text = match p.unit {
                Unit::Metre | Unit::Radian => {
                    let unit = if p.unit == Unit::Metre { "mm" } else { "mrad" };
                    format!(
                        "  {mark} {:<32} {:>+14.6} ± {:<10.6} {unit}",
                        p.name,
                        p.value * 1e3,
                        p.sigma * 1e3
                    )
                }
                // Extension parameters, in their own units (rad/(N m), 1/K, …).
                unit => format!(
                    "  {mark} {:<32} {:>+14.4e} ± {:<10.2e} {unit}",
                    p.name, p.value, p.sigma
                ),
            };
            line(&mut s, text);
        }
        if let Some(l) = &self.learned {
            line(&mut s, format!("learned correction: {}", l.description));
            let test = l.test.as_ref().map_or(String::new(), |t| {
                format!(", test RMS {:.1} µm", t.rms_m * 1e6)
            });
            line(
                &mut s,
                format!("  with it: train RMS {:.1} µm{test}", l.train.rms_m * 1e6),
            );
        }
        if !self.strong_correlations.is_empty() {
            line(&mut s, "strong correlations:".into());
            for c in &self.strong_correlations {
                line(&mut s, format!("  {} ~ {}: {:+.3}", c.a, c.b, c.rho));
            }
        }
        if !self.outliers.is_empty() {
            line(&mut s, format!("outliers ({}):", self.outliers.len()));
            for o in self.outliers.iter().take(20) {
                line(
                    &mut s,
                    format!(
                        "  row {} (pose {}): normalised residual {:.1}, error {}",
                        o.row,
                        o.pose,
                        o.normalised_residual,
                        mm(o.error_m)
                    ),
                );
            }
        }
        for w in &self.warnings {
            line(&mut s, format!("warning: {w}"));
        }
        for w in self.health.iter() {
            line(&mut s, format!("numerical warning: {w}"));
        }
        s
    }
}
