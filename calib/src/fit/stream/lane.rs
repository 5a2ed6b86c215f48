//! One Levenberg–Marquardt solve carried across passes over a file: the solver of [`crate::lm`],
//! taken apart so that each of its evaluations is one pass.
//!
//! A pass gives, at the lane's trial point, `χ²`, the scaled gradient `D Jᵀr` and the `R` factor of
//! the scaled Jacobian `J D` ([`Evaluation`]). From the factor at the linearisation point, its SVD
//! `R = U Σ Vᵀ` splits the identifiable subspace as [`Subspace::from_factor`] does for the in-memory
//! solve; in that basis the reduced normal matrix is `Σ²`, so the damped step is
//! `z_k = −g_k / (σ_k² (1 + μ))` (Marquardt's diagonal damping) and the step `D V z`. The rules are
//! those of [`crate::lm::minimize`]: a step is taken when `ρ > 1e-4`, `μ` follows Nielsen's update,
//! and the solve stops when the full Gauss–Newton step would lower `χ²` by at most
//! `decrease_tol + relative_decrease_tol · χ²`. Without the geodesic acceleration: a streamed solve
//! starts next to its minimum (at the fit of a sample), where the Gauss–Newton step is exact to
//! second order and one step converges.

use crate::health::Health;
use crate::lm::{LmOptions, MinimizationReport, Subspace, TerminationReason};
use crate::model::params::{KinematicParams, ParamLayout};
use nalgebra::DMatrix;

/// The sums of one pass at one point: `χ²`, `D Jᵀr` and the `R` factor of `J D`.
#[derive(Clone, Debug)]
pub struct Evaluation {
    /// `χ²` (noise units).
    pub cost: f64,
    /// `D Jᵀr` (active parameters).
    pub gradient: Vec<f64>,
    /// `R` of the scaled Jacobian (p × p, or fewer rows while fewer residuals were seen).
    pub factor: DMatrix<f64>,
    /// Residuals seen.
    pub residuals: usize,
}

impl Evaluation {
    /// Nothing seen yet, for `p` parameters.
    pub fn empty(p: usize) -> Self {
        Evaluation {
            cost: 0.0,
            gradient: vec![0.0; p],
            factor: DMatrix::zeros(0, p),
            residuals: 0,
        }
    }

    /// Adds a piece's sums (pieces in file order: the result does not depend on threads).
    pub fn add(&mut self, cost: f64, gradient: &[f64], factor: DMatrix<f64>, residuals: usize) {
        self.cost += cost;
        for (t, v) in self.gradient.iter_mut().zip(gradient) {
            *t += v;
        }
        let p = self.gradient.len();
        self.factor = if self.factor.nrows() == 0 {
            factor
        } else {
            crate::linalg::stacked_r_factor(&[std::mem::take(&mut self.factor), factor], p)
        };
        self.residuals += residuals;
    }

    /// `D JᵀJ D = RᵀR` (p × p).
    pub fn gram(&self) -> DMatrix<f64> {
        self.factor.tr_mul(&self.factor)
    }
}

/// Where a lane is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Phase {
    /// The next pass evaluates its trial point.
    Running,
    /// Ended (see the report's termination).
    Done,
}

/// A solve of `active` parameters of `layout` with column scales `scales`.
pub struct Lane {
    /// Active parameter indices of the layout.
    pub active: Vec<usize>,
    /// Column scales of the active parameters.
    pub scales: Vec<f64>,
    /// The parameter layout.
    pub layout: ParamLayout,
    /// The linearisation point (the solution once done).
    pub lin: KinematicParams,
    /// The point the next pass evaluates.
    pub trial: KinematicParams,
    at_lin: Option<Evaluation>,
    /// The step from `lin` to `trial` and the decrease the linear model predicts for it.
    pending_pred: f64,
    mu: f64,
    nu: f64,
    options: LmOptions,
    /// Most passes the solve may take.
    max_passes: usize,
    /// The solver's report so far.
    pub report: MinimizationReport,
    /// Where it is.
    pub phase: Phase,
}

impl Lane {
    /// A solve from `start`; `max_passes` evaluations at most.
    pub fn new(
        layout: ParamLayout,
        start: KinematicParams,
        active: Vec<usize>,
        scales: Vec<f64>,
        options: &LmOptions,
        max_passes: usize,
    ) -> Self {
        let p = active.len();
        Lane {
            active,
            scales,
            layout,
            trial: start.clone(),
            lin: start,
            at_lin: None,
            pending_pred: 0.0,
            mu: options.initial_damping,
            nu: 2.0,
            options: *options,
            max_passes,
            report: MinimizationReport {
                termination: TerminationReason::Converged,
                iterations: 0,
                evaluations: 0,
                cost_initial: f64::NAN,
                cost_final: f64::NAN,
                predicted_decrease: f64::NAN,
                n_residuals: 0,
                n_params: p,
                rank: 0,
                health: Health::new(),
            },
            phase: Phase::Running,
        }
    }

    /// The evaluation at the linearisation point (after the first pass).
    pub fn at_lin(&self) -> Option<&Evaluation> {
        self.at_lin.as_ref()
    }

    /// The rank decision at the linearisation point.
    pub fn subspace(&self) -> Option<Subspace> {
        self.at_lin.as_ref().map(|e| self.split(e))
    }

    fn split(&self, e: &Evaluation) -> Subspace {
        Subspace::from_factor(
            &e.factor,
            &self.scales,
            self.options.rank_rtol,
            self.options.min_singular_value,
            e.residuals,
        )
    }

    /// Takes the pass's evaluation at the trial point and sets the next trial point (or ends).
    pub fn take(&mut self, e: Evaluation) {
        self.report.evaluations += 1;
        self.report.n_residuals = e.residuals;
        if !e.cost.is_finite() || e.gradient.iter().any(|g| !g.is_finite()) {
            self.report.termination = TerminationReason::NonFinite;
            self.phase = Phase::Done;
            if self.at_lin.is_none() {
                self.report.cost_initial = e.cost;
                self.report.cost_final = e.cost;
            }
            return;
        }
        match &self.at_lin {
            None => {
                self.report.cost_initial = e.cost;
                self.accept(e);
            }
            Some(lin) => {
                let actual = lin.cost - e.cost;
                let pred = self.pending_pred;
                if actual.abs() <= 1e-15 * lin.cost && pred <= 1e-12 * lin.cost.max(1e-300) {
                    self.report.termination = TerminationReason::NoFurtherDecrease;
                    self.trial = self.lin.clone();
                    self.phase = Phase::Done;
                    return;
                }
                let rho = if pred > 0.0 { actual / pred } else { -1.0 };
                if rho > 1e-4 {
                    self.mu *= (1.0f64 / 3.0).max(1.0 - (2.0 * rho - 1.0).powi(3));
                    self.nu = 2.0;
                    self.lin = self.trial.clone();
                    self.accept(e);
                } else {
                    self.mu *= self.nu;
                    self.nu *= 2.0;
                    if self.mu > 1e16 {
                        self.report.termination = TerminationReason::DampingLimit;
                        self.report
                            .health
                            .record(crate::health::Warning::DampingLimit, self.report.iterations);
                        self.trial = self.lin.clone();
                        self.phase = Phase::Done;
                        return;
                    }
                    self.step();
                }
            }
        }
        if self.phase == Phase::Running && self.report.evaluations >= self.max_passes {
            self.report.termination = TerminationReason::MaxIterations;
            self.report.health.record(
                crate::health::Warning::IterationLimit,
                self.report.iterations,
            );
            self.trial = self.lin.clone();
            self.phase = Phase::Done;
        }
    }

    /// `e` is the evaluation at the (new) linearisation point: the convergence test, else a step.
    fn accept(&mut self, e: Evaluation) {
        self.report.cost_final = e.cost;
        let sub = self.split(&e);
        self.report.rank = sub.rank;
        let g = self.reduced_gradient(&sub, &e.gradient);
        let pred_gn: f64 = g
            .iter()
            .zip(&sub.singular_values)
            .map(|(g, s)| g * g / (s * s))
            .sum();
        self.report.predicted_decrease = pred_gn;
        let cost = e.cost;
        self.at_lin = Some(e);
        if sub.rank == 0 {
            self.report.termination = TerminationReason::NoIdentifiableParameters;
            self.phase = Phase::Done;
            return;
        }
        if pred_gn <= self.options.decrease_tol + self.options.relative_decrease_tol * cost {
            self.report.termination = TerminationReason::Converged;
            self.phase = Phase::Done;
            return;
        }
        self.step();
    }

    /// `Vᵣᵀ g` over the identifiable directions.
    fn reduced_gradient(&self, sub: &Subspace, gradient: &[f64]) -> Vec<f64> {
        (0..sub.rank)
            .map(|k| {
                sub.v
                    .column(k)
                    .iter()
                    .zip(gradient)
                    .map(|(v, g)| v * g)
                    .sum()
            })
            .collect()
    }

    /// The damped step from the linearisation point: the next trial point.
    fn step(&mut self) {
        let e = self.at_lin.as_ref().expect("a linearisation point");
        let sub = self.split(e);
        let g = self.reduced_gradient(&sub, &e.gradient);
        let damp = 1.0 + self.mu;
        let mut pred = 0.0;
        let p = self.active.len();
        let mut scaled = vec![0.0; p];
        for (k, gk) in g.iter().enumerate() {
            let s2 = sub.singular_values[k] * sub.singular_values[k];
            let z = -gk / (s2 * damp);
            // −(2 g z + z σ² z), the damped step's predicted decrease.
            pred -= 2.0 * gk * z + z * s2 * z;
            for (a, v) in scaled.iter_mut().zip(sub.v.column(k).iter()) {
                *a += v * z;
            }
        }
        self.pending_pred = pred;
        self.report.iterations += 1;
        let mut full = vec![0.0; self.layout.len()];
        for ((&k, s), d) in self.active.iter().zip(&scaled).zip(&self.scales) {
            full[k] = s * d;
        }
        let mut trial = self.lin.clone();
        trial.retract(&self.layout, &full);
        self.trial = trial;
    }
}
