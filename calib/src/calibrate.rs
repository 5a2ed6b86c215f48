//! The calibration procedure: start, base-and-target fit, full kinematic fit, covariance, identifiability,
//! validation, outliers. See the crate documentation for the model.
//!
//! 1. Start: the nominal robot with the target at the flange origin; `T_tracker_base` from the
//!    closed-form rigid fit (Kabsch) of the nominal flange positions to the measured points; with
//!    orientation, `R_flange_target` from the chordal mean of `(R_tracker_base R_base_flange)ᵀ R_measured`.
//! 2. "Before": only the tracker-to-base transform and the target are fitted (nominal joints), the
//!    reference for what calibration gains.
//! 3. "After": every parameter, in the identifiable subspace ([`crate::lm`]). With a robust loss, the
//!    fit is repeated with iteratively reweighted rows (IRLS) until the weights settle.
//! 4. Covariance `σ̂² D V_r Σ_r⁻² V_rᵀ D` with the variance factor `σ̂² = χ²/(m − rank)` estimated from the
//!    residuals (so a wrong absolute noise level does not distort the standard deviations; `χ²/dof`
//!    reports it).

use crate::chain::{Chain, ChainScratch};
use crate::error::{CalibError, Result};
use crate::extensions::thermal_drift::WARM_UP_TAUS_S;
use crate::extensions::{
    Cause, ExtensionSettings, ModelSpec, Regressors, ThermalInput, predict_row,
};
use crate::identifiability::{NullSpaceReport, Observability, describe_null_space};
use crate::learned::LearnedResidual;
use crate::lie3::{left_jacobian_inverse, log_rotation};
use crate::lm::{
    LeastSquaresProblem, LmOptions, LmWorkspace, MinimizationReport, Subspace, minimize,
};
use crate::params::{KinematicParams, ParamKind, ParamLayout, ParameterScales};
use crate::problem::{KinematicProblem, NoiseModel, Observations};
use crate::stats::{ResidualStats, position_errors, residual_stats, stats_of_errors};
use nalgebra::{DMatrix, DVector, Matrix3, Matrix3x6, Vector3};
use sim::Model;
use sim::lie::{Pose, pose_from, skew};
use sim::measurement_table::MeasurementTable;

/// A robust loss on the normalised residual norm `t` of a row (see [`CalibrationOptions::robust`]).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case", tag = "loss")]
pub enum RobustLoss {
    /// Weight 1 up to `c`, then `c / t`.
    Huber {
        /// Threshold in units of `t`.
        c: f64,
    },
    /// Weight `1 / (1 + (t/c)²)`.
    Cauchy {
        /// Scale in units of `t`.
        c: f64,
    },
}

impl RobustLoss {
    /// Huber with `c = 3.5`: about 1 % of Gaussian 3-D rows are down-weighted (`√χ²₃(0.99) = 3.37`).
    pub const HUBER: RobustLoss = RobustLoss::Huber { c: 3.5 };
    /// Cauchy with `c = 3.5`.
    pub const CAUCHY: RobustLoss = RobustLoss::Cauchy { c: 3.5 };

    fn weight(&self, t: f64) -> f64 {
        match *self {
            RobustLoss::Huber { c } => {
                if t <= c {
                    1.0
                } else {
                    c / t
                }
            }
            RobustLoss::Cauchy { c } => 1.0 / (1.0 + (t / c) * (t / c)),
        }
    }
}

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

/// Settings of [`calibrate`].
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CalibrationOptions {
    /// Expected parameter magnitudes (column scaling).
    pub scales: ParameterScales,
    /// Measurement noise when the table has no `sigma` column.
    pub noise: NoiseModel,
    /// Solver settings.
    pub lm: LmOptions,
    /// Robust loss (IRLS), or `None` for plain least squares (default).
    pub robust: Option<RobustLoss>,
    /// Rows whose normalised residual norm exceeds this are reported as outliers. The normalised norm
    /// `t` is the row's weighted residual norm divided by a robust scale (the median norm over that of
    /// a Gaussian row), so `t²` follows χ² with 3 (6) degrees of freedom for Gaussian rows; `t > 5` then
    /// happens with probability 1.5e-5 (3.4e-4). A row must also exceed a tenth of the threshold in units
    /// of its own σ from the noise model, so that rounding-level residuals of noise-free data are never
    /// outliers. Default 5.
    pub outlier_threshold: f64,
    /// Seed of the learned models' cross-validation folds.
    pub learned_seed: u64,
}

impl Default for CalibrationOptions {
    fn default() -> Self {
        CalibrationOptions {
            scales: ParameterScales::default(),
            noise: NoiseModel::default(),
            lm: LmOptions::default(),
            robust: None,
            outlier_threshold: 5.0,
            learned_seed: 0,
        }
    }
}

/// Some rows of a measurement table.
#[derive(Clone, Debug)]
pub struct Dataset<'a> {
    /// The table.
    pub table: &'a MeasurementTable,
    /// 0-based rows to use.
    pub rows: Vec<usize>,
    /// Name for messages, e.g. the file and `training set`.
    pub name: String,
}

impl<'a> Dataset<'a> {
    /// Every row of `table`.
    pub fn all(table: &'a MeasurementTable, name: &str) -> Self {
        Dataset {
            table,
            rows: (0..table.len()).collect(),
            name: name.to_string(),
        }
    }
}

/// One parameter's estimate.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ParameterEstimate {
    /// Name, e.g. `joint 2 twist ω_x`, `T_tracker_base x`.
    pub name: String,
    /// `rad` or `m`.
    pub unit: String,
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
    pub model: String,
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
    /// IRLS summary when a robust loss was used.
    pub robust: Option<RobustSummary>,
    /// The learned residual correction on top of the physical model, with a `learned:` model.
    pub learned: Option<LearnedStage>,
    /// Things a user should know (data-specific unidentifiable parameters, weak combinations, …).
    pub warnings: Vec<String>,
}

impl CalibrationReport {
    /// True when the full fit converged.
    pub fn was_successful(&self) -> bool {
        self.after.solver.was_successful()
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
            let text = match p.unit.as_str() {
                "m" | "rad" => {
                    let unit = if p.unit == "m" { "mm" } else { "mrad" };
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
        s
    }
}

/// A calibration: the estimate, its covariance and the report.
#[derive(Clone, Debug)]
pub struct Calibration {
    /// The calibrated parameters.
    pub params: KinematicParams,
    /// The nominal robot with only base and target fitted (the "before" model).
    pub before: KinematicParams,
    /// Their layout.
    pub layout: ParamLayout,
    /// Covariance of a step at the solution ([`ParamLayout`] order, physical units).
    pub covariance: DMatrix<f64>,
    /// The SVD split of the final scaled Jacobian.
    pub subspace: Subspace,
    /// The report.
    pub report: CalibrationReport,
    /// Settings of the model extensions (what their regressors are made from), if any.
    pub extensions: Option<ExtensionSettings>,
    /// The learned residual correction fitted after the physical model, if asked for.
    pub learned: Option<LearnedResidual>,
}

/// Rigid transform `T` with `dst ≈ T src` in the least-squares sense (Kabsch / Horn).
fn kabsch(src: &[Vector3<f64>], dst: &[Vector3<f64>]) -> Pose {
    let n = src.len() as f64;
    let cs = src.iter().sum::<Vector3<f64>>() / n;
    let cd = dst.iter().sum::<Vector3<f64>>() / n;
    let mut h = Matrix3::zeros();
    for (a, b) in src.iter().zip(dst) {
        h += (a - cs) * (b - cd).transpose();
    }
    let svd = h.svd(true, true);
    let (u, vt) = (svd.u.unwrap(), svd.v_t.unwrap());
    let mut d = Matrix3::identity();
    if (vt.transpose() * u.transpose()).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    let r = vt.transpose() * d * u.transpose();
    pose_from(r, cd - r * cs)
}

/// Projection of a 3×3 matrix onto the nearest rotation.
fn nearest_rotation(m: &Matrix3<f64>) -> Matrix3<f64> {
    let svd = m.svd(true, true);
    let (u, vt) = (svd.u.unwrap(), svd.v_t.unwrap());
    let mut d = Matrix3::identity();
    if (u * vt).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    u * d * vt
}

/// The start: nominal joints, closed-form base transform, target at the flange (see module docs).
pub fn initial_params(model: &Model, obs: &Observations) -> KinematicParams {
    let orientation = obs.orientation.is_some();
    let mut params = KinematicParams::nominal(model.nq(), orientation);
    let chain = Chain::new(model, &params);
    let mut s = ChainScratch::new(model.nq());
    let mut src = Vec::with_capacity(obs.len());
    let mut rots = Vec::with_capacity(obs.len());
    for r in 0..obs.len() {
        chain.forward(&mut s, obs.q_row(r));
        src.push(s.p_tracker);
        rots.push(*s.t_tracker_flange.rotation.matrix());
    }
    params.t_tracker_base = kabsch(&src, &obs.position);
    if let Some(meas) = &obs.orientation {
        let rb = params.t_tracker_base.rotation.matrix();
        let mut sum = Matrix3::zeros();
        for (rf, rm) in rots.iter().zip(meas) {
            sum += (rb * rf).transpose() * rm;
        }
        params.r_flange_target = Some(nearest_rotation(&sum));
    }
    params
}

/// Number of identifiable parameter combinations of the kinematic model of `model` for a generic pose
/// set (random configurations within the limits, a target off the flange axes).
pub fn generic_rank(model: &Model, orientation: bool, options: &CalibrationOptions) -> usize {
    use rand::{RngExt, SeedableRng};
    let layout = ParamLayout::new(model, orientation);
    let dim = if orientation { 6 } else { 3 };
    let poses = layout.len() / dim + 12;
    let mut rng = rand::rngs::StdRng::seed_from_u64(0x5eed);
    let n = model.nq();
    let mut q = Vec::with_capacity(poses * n);
    for _ in 0..poses {
        for j in &model.joints {
            let (lo, hi) = j.limits.map_or((-3.0, 3.0), |l| (l.lower, l.upper));
            q.push(lo + (hi - lo) * rng.random::<f64>());
        }
    }
    let mut params = KinematicParams::nominal(n, orientation);
    params.p_flange_target = Vector3::new(0.031, -0.022, 0.083);
    let chain = Chain::new(model, &params);
    let mut s = ChainScratch::new(n);
    let mut position = Vec::with_capacity(poses);
    let mut rot = Vec::with_capacity(poses);
    for k in 0..poses {
        chain.forward(&mut s, &q[k * n..(k + 1) * n]);
        position.push(s.p_tracker);
        rot.push(s.r_tracker_target);
    }
    let obs = Observations {
        n_joints: n,
        q,
        position,
        orientation: orientation.then_some(rot),
        sigma: vec![1e-5; poses],
        sigma_rotation: options.noise.orientation_sigma_rad,
        weight: vec![1.0; poses],
        pose: (0..poses as i64).collect(),
        source_row: (0..poses).collect(),
        ext: Regressors::none(),
    };
    let all: Vec<usize> = (0..layout.len()).collect();
    let mut prob = KinematicProblem::new(model, &obs, params, all);
    let mut j = DMatrix::zeros(poses * dim, layout.len());
    crate::lm::LeastSquaresProblem::set_params(&mut prob, &vec![0.0; layout.len()]);
    crate::lm::LeastSquaresProblem::jacobian(&mut prob, &mut j);
    let scales = options.scales.vector(&layout);
    Subspace::analyze(
        &j,
        scales.as_slice(),
        options.lm.rank_rtol,
        options.lm.min_singular_value,
    )
    .rank
}

/// Median of χ² with `d` degrees of freedom, for the robust scale (d = 3 or 6).
fn chi2_median(d: usize) -> f64 {
    if d == 6 { 5.348_120 } else { 2.365_974 }
}

fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    let m = v.len() / 2;
    if v.len() % 2 == 1 {
        v[m]
    } else {
        0.5 * (v[m - 1] + v[m])
    }
}

/// Normalised residual norms `t` per row (robust scale), from weighted norms and robust weights.
fn normalised_norms(norms: &[f64], weights: &[f64], d: usize) -> Vec<f64> {
    let raw: Vec<f64> = norms
        .iter()
        .zip(weights)
        .map(|(n, w)| if *w > 0.0 { n / w.sqrt() } else { *n })
        .collect();
    let scale = median(raw.clone()) / chi2_median(d).sqrt();
    let scale = if scale > 0.0 { scale } else { 1.0 };
    raw.iter().map(|v| v / scale).collect()
}

/// Calibrates the kinematic model of `model` on `train`, validating on `test` when given.
///
/// Errors only for unusable input: a joint count that does not fit the robot, a `sigma` ≤ 0, or too few
/// distinct poses for the identifiable parameters ([`CalibError::TooFewPoses`]). A degenerate pose set is
/// not an error: the report names what it cannot identify.
pub fn calibrate(
    model: &Model,
    train: &Dataset<'_>,
    test: Option<&Dataset<'_>>,
    options: &CalibrationOptions,
) -> Result<Calibration> {
    calibrate_with(model, train, test, options, None, &[])
}

/// Most outer iterations that move the torque evaluation to the estimated equilibrium (see
/// [`Regressors::build`]) and, with payload, re-estimate its centre of mass.
pub const EQUILIBRIUM_REFITS: usize = 12;

/// One Gauss–Newton step (m) for the payload's centre of mass in the flange frame, taken jointly with
/// every other parameter at `cal`: the weighted least-squares step of the stacked Jacobian
/// `[J D, J_c s_c]` (the analytic Jacobian of the identifiable parameters, scaled, and central
/// differences of the residuals in each coordinate of the centre of mass, scaled by 1 cm), minimum-norm
/// in the unidentifiable directions; only its centre-of-mass part is returned (the refit does the rest).
fn payload_com_step(
    model: &Model,
    train: &Dataset<'_>,
    options: &CalibrationOptions,
    settings: &ExtensionSettings,
    cal: &Calibration,
) -> Result<Vector3<f64>> {
    const H: f64 = 1e-3;
    const COM_SCALE_M: f64 = 1e-2;
    let at = &cal.params.extension;
    let residuals = |s: &ExtensionSettings| -> Result<Vec<f64>> {
        let obs = observations(model, train, options, Some(s), at)?;
        let all: Vec<usize> = (0..cal.layout.len()).collect();
        let mut prob = KinematicProblem::new(model, &obs, cal.params.clone(), all);
        let mut r = vec![0.0; prob.n_residuals()];
        prob.set_params(&vec![0.0; cal.layout.len()]);
        prob.residuals(&mut r);
        Ok(r)
    };
    let obs = observations(model, train, options, Some(settings), at)?;
    let p = cal.layout.len();
    let all: Vec<usize> = (0..p).collect();
    let mut prob = KinematicProblem::new(model, &obs, cal.params.clone(), all);
    let m = prob.n_residuals();
    let mut r0 = vec![0.0; m];
    prob.set_params(&vec![0.0; p]);
    prob.residuals(&mut r0);
    let mut j = DMatrix::zeros(m, p + 3);
    let mut jk = DMatrix::zeros(m, p);
    prob.jacobian(&mut jk);
    let scales = options.scales.vector(&cal.layout);
    for c in 0..p {
        let s = if cal.subspace.scales.get(c).is_some_and(|v| *v == 0.0) {
            0.0
        } else {
            scales[c]
        };
        for row in 0..m {
            j[(row, c)] = jk[(row, c)] * s;
        }
    }
    for axis in 0..3 {
        let mut plus = settings.clone();
        plus.payload_com_m[axis] += H;
        let mut minus = settings.clone();
        minus.payload_com_m[axis] -= H;
        let (rp, rm) = (residuals(&plus)?, residuals(&minus)?);
        for row in 0..m {
            j[(row, p + axis)] = (rp[row] - rm[row]) / (2.0 * H) * COM_SCALE_M;
        }
    }
    let svd = j.svd(true, true);
    let smax = svd.singular_values.max();
    let step = svd
        .solve(&DVector::from_vec(r0), 1e-8 * smax)
        .map_err(|e| CalibError::BadValue {
            context: train.name.clone(),
            field: "payload".into(),
            value: String::new(),
            problem: format!("payload centre of mass: {e}"),
        })?;
    Ok(Vector3::new(
        -step[p] * COM_SCALE_M,
        -step[p + 1] * COM_SCALE_M,
        -step[p + 2] * COM_SCALE_M,
    ))
}

/// [`calibrate_with`] for an extended model. With joint compliance it is refitted with the torques at
/// the estimated equilibrium until the compliances settle (relative change below 10⁻⁶ of their scale);
/// when the table carries a payload, each refit also moves the payload's centre of mass (unknown to the
/// table, [`ExtensionSettings::payload_com_m`]) by a Gauss–Newton step, until it moves less than 1 µm.
/// The covariance treats the centre of mass as known.
fn calibrate_extended(
    model: &Model,
    train: &Dataset<'_>,
    test: Option<&Dataset<'_>>,
    options: &CalibrationOptions,
    settings: &ExtensionSettings,
) -> Result<Calibration> {
    let mut settings = settings.clone();
    let mut cal = calibrate_with(model, train, test, options, Some(&settings), &[])?;
    if !settings.causes.contains(&Cause::JointCompliance) {
        return Ok(cal);
    }
    let payload = train
        .table
        .payload
        .as_ref()
        .is_some_and(|m| train.rows.iter().any(|&r| m[r] > 0.0));
    for _ in 0..EQUILIBRIUM_REFITS {
        let at = cal.params.extension.clone();
        let com_step = if payload {
            let d = payload_com_step(model, train, options, &settings, &cal)?;
            for (c, d) in settings.payload_com_m.iter_mut().zip(d.iter()) {
                *c += d;
            }
            d.norm()
        } else {
            0.0
        };
        let next = calibrate_with(model, train, test, options, Some(&settings), &at)?;
        let change = next
            .params
            .extension
            .iter()
            .zip(&at)
            .zip(&next.layout.extensions)
            .map(|((a, b), p)| (a - b).abs() / p.scale)
            .fold(0.0, f64::max);
        cal = next;
        if change < 1e-6 && com_step < 1e-6 {
            break;
        }
    }
    Ok(cal)
}

/// Calibrates the model `spec` (kinematic, extensions identified jointly with it, then an optional
/// learned residual correction fitted on the training residuals) on `train`, validating on `test`.
///
/// Extensions take their regressor settings from the training rows ([`ExtensionSettings::for_data`]);
/// thermal drift from time stamps alone searches the warm-up time constant over
/// [`WARM_UP_TAUS_S`] and keeps the one with the smallest training `χ²`. Errors as [`calibrate`], and
/// for an extension the data cannot feed (thermal drift without `temp` or `t`, compliance on a robot
/// without inertials).
pub fn calibrate_model(
    model: &Model,
    train: &Dataset<'_>,
    test: Option<&Dataset<'_>>,
    spec: &ModelSpec,
    options: &CalibrationOptions,
) -> Result<Calibration> {
    let mut cal = if spec.causes.is_empty() {
        calibrate_with(model, train, test, options, None, &[])?
    } else {
        let settings = |tau| {
            ExtensionSettings::for_data(
                model,
                &spec.causes,
                train.table,
                &train.rows,
                tau,
                &train.name,
            )
        };
        let first = settings(None)?;
        if matches!(first.thermal, Some(ThermalInput::WarmUp { .. })) {
            let mut best: Option<Calibration> = None;
            for tau in WARM_UP_TAUS_S {
                let cal = calibrate_extended(model, train, test, options, &settings(Some(tau))?)?;
                if best.as_ref().is_none_or(|b| {
                    cal.report.after.solver.cost_final < b.report.after.solver.cost_final
                }) {
                    best = Some(cal);
                }
            }
            best.expect("at least one time constant")
        } else {
            calibrate_extended(model, train, test, options, &first)?
        }
    };
    cal.report.model = spec.name();
    if let Some(kind) = &spec.learned {
        add_learned(model, &mut cal, kind, train, test, options)?;
    }
    Ok(cal)
}

/// Fits the learned correction `kind` to the training residuals of `cal` and records its statistics.
fn add_learned(
    model: &Model,
    cal: &mut Calibration,
    kind: &str,
    train: &Dataset<'_>,
    test: Option<&Dataset<'_>>,
    options: &CalibrationOptions,
) -> Result<()> {
    let at = cal.params.extension.clone();
    let obs = observations(model, train, options, cal.extensions.as_ref(), &at)?;
    let residual: Vec<Vector3<f64>> = position_errors(model, &cal.params, &obs)
        .iter()
        .map(|e| -e)
        .collect();
    let learned = crate::learned::fit(kind, &obs.q, model.nq(), &residual, options.learned_seed)?;
    let stats_with = |o: &Observations| {
        let corrected: Vec<Vector3<f64>> = position_errors(model, &cal.params, o)
            .iter()
            .enumerate()
            .map(|(r, e)| e + learned.predict(o.q_row(r)))
            .collect();
        stats_of_errors(&corrected, o)
    };
    let test_stats = match test {
        Some(t) if !t.rows.is_empty() => Some(stats_with(&observations(
            model,
            t,
            options,
            cal.extensions.as_ref(),
            &at,
        )?)),
        _ => None,
    };
    cal.report.learned = Some(LearnedStage {
        description: learned.describe(),
        active: learned.is_active(),
        train: stats_with(&obs),
        test: test_stats,
    });
    cal.learned = Some(learned);
    Ok(())
}

/// The rows of `data` prepared for the solver, with the extensions' regressors under `extensions`,
/// torques evaluated at the extension values `at` ([`Regressors::build`]).
pub fn observations(
    model: &Model,
    data: &Dataset<'_>,
    options: &CalibrationOptions,
    extensions: Option<&ExtensionSettings>,
    at: &[f64],
) -> Result<Observations> {
    let mut obs = Observations::from_table(data.table, &data.rows, &options.noise, &data.name)?;
    if let Some(s) = extensions {
        obs.ext = Regressors::build(model, s, data.table, &data.rows, &data.name, at)?;
    }
    Ok(obs)
}

fn calibrate_with(
    model: &Model,
    train: &Dataset<'_>,
    test: Option<&Dataset<'_>>,
    options: &CalibrationOptions,
    extensions: Option<&ExtensionSettings>,
    at: &[f64],
) -> Result<Calibration> {
    for d in std::iter::once(train).chain(test) {
        if d.table.n_joints != model.nq() {
            return Err(CalibError::BadValue {
                context: d.name.clone(),
                field: "q1..qN".into(),
                value: format!("{} joint columns", d.table.n_joints),
                problem: format!("robot '{}' has {} joints", model.name, model.nq()),
            });
        }
    }
    if train.rows.is_empty() {
        return Err(CalibError::BadValue {
            context: train.name.clone(),
            field: "rows".into(),
            value: "0".into(),
            problem: "no rows to calibrate on".into(),
        });
    }
    let mut obs = observations(model, train, options, extensions, at)?;
    let test_obs = match test {
        Some(t) if !t.rows.is_empty() => Some(observations(model, t, options, extensions, at)?),
        _ => None,
    };
    let orientation = obs.orientation.is_some();
    if let Some(t) = &test_obs
        && t.orientation.is_some() != orientation
    {
        return Err(CalibError::BadValue {
            context: test.map(|t| t.name.clone()).unwrap_or_default(),
            field: "qw, qx, qy, qz".into(),
            value: if orientation { "absent" } else { "present" }.into(),
            problem:
                "the test data must have orientation columns exactly when the training data do"
                    .into(),
        });
    }
    let layout = ParamLayout::new(model, orientation).with_extensions(obs.ext.params.clone());
    let p = layout.len();
    let dim = obs.dim();
    let n_poses = obs.n_poses();
    let equations = n_poses * dim;
    if equations <= p {
        let r = generic_rank(model, orientation, options);
        if equations < r + 1 {
            return Err(CalibError::TooFewPoses {
                context: train.name.clone(),
                robot: model.name.clone(),
                joints: model.nq(),
                poses: n_poses,
                equations,
                identifiable: r,
                needed: (r + 1).div_ceil(dim),
            });
        }
    }
    let scales = options.scales.vector(&layout);
    let mut warnings = Vec::new();

    // Before: base and target only.
    let mut start = initial_params(model, &obs);
    start.extension = vec![0.0; obs.ext.len()];
    let bt = layout.base_and_target();
    let bt_scales: Vec<f64> = bt.iter().map(|&k| scales[k]).collect();
    let mut ws = LmWorkspace::new(obs.len() * dim, bt.len());
    let mut prob = KinematicProblem::new(model, &obs, start, bt);
    let (before_report, _) = minimize(&mut prob, &bt_scales, &options.lm, &mut ws);
    let before_params = prob.into_params();
    if !before_report.was_successful() {
        warnings.push(format!(
            "the base-and-target fit did not converge ({})",
            before_report.termination
        ));
    }
    let before = FitStage {
        parameters: "tracker-to-base transform and target (nominal joints)".into(),
        train: residual_stats(model, &before_params, &obs),
        test: test_obs
            .as_ref()
            .map(|t| residual_stats(model, &before_params, t)),
        solver: before_report,
    };

    // After: everything, optionally with IRLS.
    let all: Vec<usize> = (0..p).collect();
    let mut ws = LmWorkspace::new(obs.len() * dim, p);
    let mut params = before_params.clone();
    let mut robust_summary = None;
    let (report, sub) = match options.robust {
        None => {
            let mut prob = KinematicProblem::new(model, &obs, params.clone(), all.clone());
            let out = minimize(&mut prob, scales.as_slice(), &options.lm, &mut ws);
            params = prob.into_params();
            out
        }
        Some(loss) => {
            let mut rounds = 0;
            let mut first_cost = None;
            let mut total_iterations = 0;
            loop {
                rounds += 1;
                let mut prob = KinematicProblem::new(model, &obs, params.clone(), all.clone());
                let out = minimize(&mut prob, scales.as_slice(), &options.lm, &mut ws);
                first_cost.get_or_insert(out.0.cost_initial);
                total_iterations += out.0.iterations;
                let norms = prob.row_norms();
                params = prob.into_params();
                let t = normalised_norms(&norms, &obs.weight, dim);
                let new: Vec<f64> = t.iter().map(|v| loss.weight(*v)).collect();
                let change = new
                    .iter()
                    .zip(&obs.weight)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0, f64::max);
                obs.weight = new;
                if change < 1e-3 || rounds >= 30 || !out.0.was_successful() {
                    if change >= 1e-3 {
                        warnings.push(format!(
                            "robust reweighting stopped after {rounds} rounds with weights still changing \
                             by {change:.1e}"
                        ));
                    }
                    // Final solve with the settled weights, for a consistent covariance.
                    let mut prob = KinematicProblem::new(model, &obs, params.clone(), all.clone());
                    let mut out = minimize(&mut prob, scales.as_slice(), &options.lm, &mut ws);
                    params = prob.into_params();
                    // Over all rounds: χ² before the first (unweighted), iterations of all.
                    out.0.cost_initial = first_cost.unwrap_or(out.0.cost_initial);
                    out.0.iterations += total_iterations;
                    robust_summary = Some(RobustSummary {
                        loss,
                        rounds,
                        downweighted_rows: obs.weight.iter().filter(|w| **w < 0.5).count(),
                    });
                    break out;
                }
            }
        }
    };
    if !report.was_successful() {
        warnings.push(format!(
            "the kinematic fit did not converge: {}",
            report.termination
        ));
    }
    let m = obs.len() * dim;
    let dof = m.saturating_sub(sub.rank);
    let chi2 = report.cost_final;
    let (variance_factor, source) = if dof > 0 {
        (chi2 / dof as f64, "residuals (χ²/dof)")
    } else {
        warnings.push(
            "no redundancy left (as many equations as identifiable parameters): standard deviations \
             assume the noise model is exact"
                .into(),
        );
        (1.0, "noise model (no degrees of freedom left)")
    };
    let covariance = sub.covariance(variance_factor);
    let observability = Observability::from_subspace(&sub);
    let null = describe_null_space(model, &params, ws.gram(), &sub, &obs);
    for line in &null.data_specific {
        warnings.push(format!("not identifiable from this pose set: {line}"));
    }
    if observability.weak_combinations > 0 {
        warnings.push(format!(
            "{} identifiable combinations are weakly determined (σ_k < 1: the data know them less well \
             than their expected magnitude); the worst has σ {:.2e} in units of its expected magnitude",
            observability.weak_combinations,
            observability.worst_combination_sigma * variance_factor.sqrt()
        ));
    }
    if train.table.sigma.is_some() && dof > 0 && !(0.25..=4.0).contains(&(chi2 / dof as f64)) {
        warnings.push(format!(
            "χ²/dof = {:.3}: the sigma column does not match the residuals (a model error, or sigma in \
             the wrong unit)",
            chi2 / dof as f64
        ));
    }

    // Outliers.
    let mut prob = KinematicProblem::new(model, &obs, params.clone(), all);
    let norms = prob.row_norms();
    let t = normalised_norms(&norms, &obs.weight, dim);
    let chain = Chain::new(model, &params);
    let mut s = ChainScratch::new(model.nq());
    let mut q_buf = vec![0.0; model.nq()];
    let mut outliers = Vec::new();
    for (r, &tv) in t.iter().enumerate() {
        // Also beyond the noise model itself: residuals at rounding level (noise-free data) are no
        // outliers however they compare with each other.
        let raw = norms[r] / obs.weight[r].max(f64::MIN_POSITIVE).sqrt();
        if tv > options.outlier_threshold && raw > options.outlier_threshold / 10.0 {
            let (p, _, _) = predict_row(
                &chain,
                &mut s,
                &params,
                &obs.ext,
                r,
                obs.q_row(r),
                &mut q_buf,
            );
            outliers.push(Outlier {
                row: obs.source_row[r] + 1,
                pose: obs.pose[r],
                normalised_residual: tv,
                error_m: (p - obs.position[r]).norm(),
            });
        }
    }
    outliers.sort_by(|a, b| b.normalised_residual.total_cmp(&a.normalised_residual));

    let sigma_rms = (obs.sigma.iter().map(|s| s * s).sum::<f64>() / obs.len() as f64).sqrt();
    let parameters = estimates(&layout, &params, &covariance, &sub);
    let strong_correlations = correlations(&layout, &covariance, &null);
    let after = FitStage {
        parameters: "kinematic error model (joint error twists and zero offsets, base, target)"
            .into(),
        train: residual_stats(model, &params, &obs),
        test: test_obs.as_ref().map(|t| residual_stats(model, &params, t)),
        solver: report,
    };
    let report = CalibrationReport {
        robot: model.name.clone(),
        model: "kinematic".into(),
        n_train_rows: obs.len(),
        n_train_poses: n_poses,
        n_test_rows: test_obs.as_ref().map_or(0, |t| t.len()),
        n_test_poses: test_obs.as_ref().map_or(0, |t| t.n_poses()),
        before,
        after,
        dof,
        chi2_per_dof: if dof > 0 { chi2 / dof as f64 } else { f64::NAN },
        variance_factor_source: source.into(),
        sigma_hat_m: sigma_rms * variance_factor.sqrt(),
        parameters,
        strong_correlations,
        observability,
        unidentifiable: null,
        outliers,
        robust: robust_summary,
        learned: None,
        warnings,
    };
    Ok(Calibration {
        params,
        before: before_params,
        layout,
        covariance,
        subspace: sub,
        report,
        extensions: extensions.cloned(),
        learned: None,
    })
}

/// True when the linear functional `a` (physical units) of a step does not see the null space.
fn invariant(a: &DVector<f64>, sub: &Subspace) -> bool {
    let p = sub.n_params();
    let da = DVector::from_fn(p, |k, _| a[k] * sub.scales[k]);
    let n = da.norm();
    if n == 0.0 {
        return true;
    }
    let null = sub.v.columns(sub.rank, p - sub.rank);
    (null.tr_mul(&da)).norm() <= 1e-6 * n
}

/// Parameter estimates with standard deviations, in reporting form: joint error twists and zero offsets
/// as they are; `T_tracker_base` as translation (m) and rotation vector (rad); the target position and,
/// with orientation, its rotation vector.
fn estimates(
    layout: &ParamLayout,
    params: &KinematicParams,
    cov: &DMatrix<f64>,
    sub: &Subspace,
) -> Vec<ParameterEstimate> {
    let p = layout.len();
    let mut out = Vec::with_capacity(p);
    let mut push = |name: String, unit: &str, value: f64, a: DVector<f64>| {
        let var = (a.transpose() * cov * &a)[(0, 0)];
        out.push(ParameterEstimate {
            name,
            unit: unit.into(),
            value,
            sigma: var.max(0.0).sqrt(),
            identifiable_alone: invariant(&a, sub),
        });
    };
    let unit_vec = |k: usize| {
        let mut a = DVector::zeros(p);
        a[k] = 1.0;
        a
    };
    for i in 0..layout.n_joints {
        let xi = params.joint_twist(i);
        for c in 0..6 {
            let k = layout.joint_twist(i) + c;
            push(layout.name(k), layout.unit(k), xi[c], unit_vec(k));
        }
        let k = layout.zero_offset(i);
        push(
            layout.name(k),
            layout.unit(k),
            params.zero_offset[i],
            unit_vec(k),
        );
    }
    // Base: t ← exp(β) t moves the origin by ω × t + v; φ = log R moves by J_l⁻¹(φ) ω.
    let kb = layout.base();
    let t = params.t_tracker_base.translation.vector;
    let mut lt = Matrix3x6::zeros();
    lt.fixed_view_mut::<3, 3>(0, 0).copy_from(&(-skew(&t)));
    lt.fixed_view_mut::<3, 3>(0, 3)
        .copy_from(&Matrix3::identity());
    for (a, axis) in ["x", "y", "z"].iter().enumerate() {
        let mut f = DVector::zeros(p);
        for c in 0..6 {
            f[kb + c] = lt[(a, c)];
        }
        push(format!("T_tracker_base {axis}"), "m", t[a], f);
    }
    let phi = log_rotation(params.t_tracker_base.rotation.matrix());
    let jl = left_jacobian_inverse(&phi);
    for (a, axis) in ["x", "y", "z"].iter().enumerate() {
        let mut f = DVector::zeros(p);
        for c in 0..3 {
            f[kb + c] = jl[(a, c)];
        }
        push(
            format!("T_tracker_base rotation φ_{axis}"),
            "rad",
            phi[a],
            f,
        );
    }
    let kt = layout.target_position();
    for a in 0..3 {
        push(
            layout.name(kt + a),
            "m",
            params.p_flange_target[a],
            unit_vec(kt + a),
        );
    }
    if let (Some(ko), Some(r)) = (layout.target_orientation(), &params.r_flange_target) {
        // R ← R exp(ρ): φ moves by J_r⁻¹(φ) ρ = J_l⁻¹(−φ) ρ.
        let phi = log_rotation(r);
        let jr = left_jacobian_inverse(&-phi);
        for (a, axis) in ["x", "y", "z"].iter().enumerate() {
            let mut f = DVector::zeros(p);
            for c in 0..3 {
                f[ko + c] = jr[(a, c)];
            }
            push(format!("target rotation φ_{axis}"), "rad", phi[a], f);
        }
    }
    for (e, x) in params.extension.iter().enumerate() {
        let k = layout.extension(e);
        push(layout.name(k), layout.unit(k), *x, unit_vec(k));
    }
    debug_assert!(matches!(layout.kind(0), ParamKind::JointTwist { .. }));
    out
}

fn correlations(
    layout: &ParamLayout,
    cov: &DMatrix<f64>,
    null: &NullSpaceReport,
) -> Vec<Correlation> {
    let alone: Vec<usize> = (0..layout.len())
        .filter(|&k| null.identifiable_alone[k] && cov[(k, k)] > 0.0)
        .collect();
    let mut out = Vec::new();
    for (x, &a) in alone.iter().enumerate() {
        for &b in &alone[x + 1..] {
            let rho = cov[(a, b)] / (cov[(a, a)] * cov[(b, b)]).sqrt();
            if rho.abs() >= 0.95 {
                out.push(Correlation {
                    a: layout.name(a),
                    b: layout.name(b),
                    rho,
                });
            }
        }
    }
    out.sort_by(|x, y| y.rho.abs().total_cmp(&x.rho.abs()));
    out.truncate(20);
    out
}

/// Predicted target pose of `params` at `q` (tracker frame: position in m, rotation matrix) and the
/// Jacobian of the prediction with respect to a step of every parameter ([`ParamLayout::len`] columns,
/// physical units): 3 position rows (m per unit), plus, when the model has target orientation, 3 rows
/// of the tracker-frame rotation vector (rad per unit). For prediction uncertainty `J C Jᵀ` with
/// [`Calibration::covariance`].
pub fn prediction_and_jacobian(
    model: &Model,
    params: &KinematicParams,
    q: &[f64],
) -> (Vector3<f64>, Matrix3<f64>, DMatrix<f64>) {
    let layout = ParamLayout::new(model, params.r_flange_target.is_some());
    let np = layout.len();
    let chain = Chain::new(model, params);
    let mut s = ChainScratch::new(model.nq());
    chain.forward(&mut s, q);
    let rows = if layout.orientation { 6 } else { 3 };
    let mut buf = vec![0.0; rows * np];
    chain.position_jacobian(&s, &layout, &mut buf[..3 * np]);
    if layout.orientation {
        chain.orientation_jacobian(&s, &layout, &mut buf[3 * np..]);
    }
    (
        s.p_tracker,
        s.r_tracker_target,
        DMatrix::from_row_slice(rows, np, &buf),
    )
}
