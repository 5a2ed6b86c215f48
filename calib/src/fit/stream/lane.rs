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
//!
//! # The factor is kept while it predicts well (a chord method)
//! The `R` factor costs about two thirds of a pass. A lane asks for it at its first point only, and
//! again after a rejected step or a step whose actual decrease missed the predicted one by more than
//! [`CHORD_RHO_TOLERANCE`] (`|ρ − 1|`), or after [`MAX_CHORD_STEPS`] steps on one factor; other
//! passes give `χ²` and `D Jᵀr` alone, and the step uses the last factor with the new gradient.
//! Next to the minimum the Jacobian hardly moves over a step (its columns turn by the step, in
//! radians and metres over the arm's reach: about 1e-5 from a sample's fit), so the step and the
//! convergence test are those of Gauss–Newton to that relative precision, and the rank decision and
//! the covariance come from the factor at the last point where it was computed
//! ([`Lane::factor_at`]), one step from the solution.

use crate::health::Health;
use crate::lm::{LmOptions, MinimizationReport, Subspace, TerminationReason};
use crate::model::params::{KinematicParams, ParamLayout};
use nalgebra::DMatrix;

/// Most `|ρ − 1|` (actual over predicted decrease) of a step taken on a kept factor for the factor
/// to be kept for the next step: 0.1. A larger miss means the Jacobian moved, or the model is not
/// quadratic over the step, and the next pass computes the factor again.
pub const CHORD_RHO_TOLERANCE: f64 = 0.1;

/// Most steps a lane takes on one factor: 4.
pub const MAX_CHORD_STEPS: usize = 4;

/// The sums of one pass at one point: `χ²`, `D Jᵀr` and, when asked for, the `R` factor of `J D`.
#[derive(Clone, Debug)]
pub struct Evaluation {
    /// `χ²` (noise units).
    pub cost: f64,
    /// `D Jᵀr` (active parameters).
    pub gradient: Vec<f64>,
    /// `R` of the scaled Jacobian (p × p, or fewer rows while fewer residuals were seen), when the
    /// pass computed it.
    pub factor: Option<DMatrix<f64>>,
    /// Residuals seen.
    pub residuals: usize,
}

impl Evaluation {
    /// Nothing seen yet, for `p` parameters, with the factor or without.
    pub fn empty(p: usize, with_factor: bool) -> Self {
        Evaluation {
            cost: 0.0,
            gradient: vec![0.0; p],
            factor: with_factor.then(|| DMatrix::zeros(0, p)),
            residuals: 0,
        }
    }

    /// Adds a piece's sums (pieces in file order: the result does not depend on threads).
    pub fn add(
        &mut self,
        cost: f64,
        gradient: &[f64],
        factor: Option<DMatrix<f64>>,
        residuals: usize,
    ) {
        self.cost += cost;
        for (t, v) in self.gradient.iter_mut().zip(gradient) {
            *t += v;
        }
        let p = self.gradient.len();
        if let (Some(total), Some(factor)) = (self.factor.as_mut(), factor) {
            *total = if total.nrows() == 0 {
                factor
            } else {
                crate::linalg::stacked_r_factor(&[std::mem::take(total), factor], p)
            };
        }
        self.residuals += residuals;
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
    /// `χ²` and `D Jᵀr` at `lin` (after the first pass).
    at_lin: Option<Evaluation>,
    /// The factor the steps use and where it was computed.
    factor: Option<(DMatrix<f64>, KinematicParams)>,
    /// Whether the next pass computes the factor.
    refresh: bool,
    /// Steps taken on the current factor.
    chord_steps: usize,
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
            factor: None,
            refresh: true,
            chord_steps: 0,
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

    /// The Marquardt damping `μ` the next step takes (where the solve's steps have been trusted).
    pub fn damping(&self) -> f64 {
        self.mu
    }

    /// Starts with the damping `mu` instead of [`LmOptions::initial_damping`]: a solve of a part of
    /// the rows started at the solution of all of them takes the damping that solve ended with.
    pub fn with_damping(mut self, mu: f64) -> Self {
        if mu.is_finite() && mu > 0.0 {
            self.mu = mu;
        }
        self
    }

    /// Whether the next pass must compute the `R` factor at the trial point (module docs).
    pub fn wants_factor(&self) -> bool {
        self.phase == Phase::Running && self.refresh
    }

    /// Where a finished lane ends if its pending evaluation is accepted: the trial point while it
    /// runs, its solution once done.
    pub fn next_point(&self) -> &KinematicParams {
        match self.phase {
            Phase::Running => &self.trial,
            Phase::Done => &self.lin,
        }
    }

    /// The point where the factor in use was computed (after the first pass).
    pub fn factor_at(&self) -> Option<&KinematicParams> {
        self.factor.as_ref().map(|(_, at)| at)
    }

    /// `D JᵀJ D = RᵀR` (p × p) of the factor in use.
    pub fn gram(&self) -> Option<DMatrix<f64>> {
        self.factor.as_ref().map(|(r, _)| r.tr_mul(r))
    }

    /// The rank decision of the factor in use.
    pub fn subspace(&self) -> Option<Subspace> {
        let residuals = self.at_lin.as_ref()?.residuals;
        self.factor.as_ref().map(|(r, _)| self.split(r, residuals))
    }

    fn split(&self, factor: &DMatrix<f64>, residuals: usize) -> Subspace {
        Subspace::from_factor(
            factor,
            &self.scales,
            self.options.rank_rtol,
            self.options.min_singular_value,
            residuals,
        )
    }

    /// Takes the pass's evaluation at the trial point and sets the next trial point (or ends).
    pub fn take(&mut self, mut e: Evaluation) {
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
        let fresh = e.factor.take();
        match &self.at_lin {
            None => {
                self.report.cost_initial = e.cost;
                let Some(factor) = fresh else {
                    // A pass without the factor (which a lane's first pass asks for): again.
                    self.report.evaluations -= 1;
                    self.refresh = true;
                    return;
                };
                self.factor = Some((factor, self.trial.clone()));
                self.refresh = false;
                self.chord_steps = 0;
                self.accept(e, true);
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
                    // The factor: the one just computed, else the kept one while it predicts well.
                    let predicted_well = (rho - 1.0).abs() <= CHORD_RHO_TOLERANCE;
                    if let Some(factor) = fresh {
                        self.factor = Some((factor, self.lin.clone()));
                        self.chord_steps = 0;
                        self.refresh = false;
                    } else {
                        self.refresh = !predicted_well || self.chord_steps >= MAX_CHORD_STEPS;
                    }
                    let trusted = self.chord_steps == 0 || predicted_well;
                    self.accept(e, trusted);
                } else {
                    // Rejected: the next trial point brings a new factor (one computed at the
                    // rejected point is of no use).
                    self.refresh = true;
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
    /// `trusted`: whether the factor in use may decide convergence (it was computed here, or the
    /// step here on it went as predicted); when not, the lane steps on and computes it anew.
    fn accept(&mut self, e: Evaluation, trusted: bool) {
        self.report.cost_final = e.cost;
        let (factor, _) = self.factor.as_ref().expect("a factor after the first pass");
        let sub = self.split(factor, e.residuals);
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
        if trusted
            && pred_gn <= self.options.decrease_tol + self.options.relative_decrease_tol * cost
        {
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

    /// The damped step from the linearisation point on the factor in use: the next trial point.
    fn step(&mut self) {
        let e = self.at_lin.as_ref().expect("a linearisation point");
        let (factor, _) = self.factor.as_ref().expect("a factor after the first pass");
        let sub = self.split(factor, e.residuals);
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
        self.chord_steps += 1;
        let mut full = vec![0.0; self.layout.len()];
        for ((&k, s), d) in self.active.iter().zip(&scaled).zip(&self.scales) {
            full[k] = s * d;
        }
        let mut trial = self.lin.clone();
        trial.retract(&self.layout, &full);
        self.trial = trial;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The residuals and Jacobian of a two-parameter problem on joint 1's and 2's zero offsets
    /// (additive, so the lane's point is read back exactly): residuals `r(a, b) = [a − 1 + c·b², b − 2, 0.1·(a + b)]`, whose curvature
    /// `c` decides how far a Gauss–Newton step on an old Jacobian misses.
    fn residuals(a: f64, b: f64, c: f64) -> (nalgebra::DVector<f64>, DMatrix<f64>) {
        let r =
            nalgebra::DVector::from_column_slice(&[a - 1.0 + c * b * b, b - 2.0, 0.1 * (a + b)]);
        let j = DMatrix::from_row_slice(3, 2, &[1.0, 2.0 * c * b, 0.0, 1.0, 0.1, 0.1]);
        (r, j)
    }

    /// The pass's sums at `(a, b)`.
    fn evaluation(a: f64, b: f64, c: f64, with_factor: bool) -> Evaluation {
        let (rv, j) = residuals(a, b, c);
        let g = j.tr_mul(&rv);
        Evaluation {
            cost: rv.norm_squared(),
            gradient: g.iter().copied().collect(),
            factor: with_factor.then(|| j.clone().qr().r()),
            residuals: 3,
        }
    }

    /// Drives a lane on the problem with curvature `c` from (0, 0): (factors computed, passes,
    /// the solution).
    fn solve(c: f64) -> (usize, usize, [f64; 2], Lane) {
        let model = sim::robots::load_builtin("iiwa7").unwrap();
        let layout = ParamLayout::new(&model, false);
        let start = KinematicParams::nominal(model.nq(), false);
        let active = vec![layout.zero_offset(0), layout.zero_offset(1)];
        let mut lane = Lane::new(
            layout.clone(),
            start.clone(),
            active.clone(),
            vec![1.0, 1.0],
            &LmOptions::default(),
            100,
        );
        let (mut factors, mut passes) = (0, 0);
        let point = |p: &KinematicParams| {
            let d = start.difference(&layout, p);
            [d[active[0]], d[active[1]]]
        };
        while lane.phase == Phase::Running {
            let [a, b] = point(&lane.trial);
            let with = lane.wants_factor();
            factors += usize::from(with);
            passes += 1;
            lane.take(evaluation(a, b, c, with));
        }
        let x = point(&lane.lin);
        (factors, passes, x, lane)
    }

    /// The minimum of the problem with curvature `c`, by Gauss–Newton with a fresh Jacobian at
    /// every step (an independent computation).
    fn minimum(c: f64) -> [f64; 2] {
        let (mut a, mut b) = (0.0, 0.0);
        for _ in 0..100 {
            let (r, j) = residuals(a, b, c);
            let step = (j.tr_mul(&j)).lu().solve(&(-j.tr_mul(&r))).unwrap();
            a += step[0];
            b += step[1];
        }
        [a, b]
    }

    /// The solution's cost exceeds the minimum's by at most what the stopping rule leaves,
    /// `decrease_tol + relative_decrease_tol · χ²` (twice that: the model is not quite quadratic).
    fn assert_within_stopping_rule(x: [f64; 2], m: [f64; 2], c: f64) {
        let lm = LmOptions::default();
        let (cx, cm) = (
            evaluation(x[0], x[1], c, false).cost,
            evaluation(m[0], m[1], c, false).cost,
        );
        let allowed = 2.0 * (lm.decrease_tol + lm.relative_decrease_tol * cm);
        assert!(
            cx - cm <= allowed,
            "{x:?} costs {cx}, the minimum {m:?} {cm}"
        );
        assert!(cx >= cm - 1e-15, "{x:?} below the minimum {m:?}");
    }

    #[test]
    fn a_linear_problem_takes_one_factor_and_converges_on_it() {
        let (factors, passes, x, lane) = solve(0.0);
        let m = minimum(0.0);
        assert_eq!(factors, 1, "a linear problem's Jacobian never moves");
        assert_eq!(passes, 2);
        assert_eq!(lane.report.termination, TerminationReason::Converged);
        assert_within_stopping_rule(x, m, 0.0);
    }

    #[test]
    fn a_curved_problem_computes_the_factor_again_and_converges_to_the_minimum() {
        // Curvature 0.3 at b ≈ 2: the first step's Jacobian (at b = 0) misses the curvature
        // entirely, the steps on it miss their prediction by far more than the tolerance.
        let (factors, passes, x, lane) = solve(0.3);
        let m = minimum(0.3);
        assert!(factors >= 2, "{factors} factors in {passes} passes");
        assert_eq!(lane.report.termination, TerminationReason::Converged);
        assert_within_stopping_rule(x, m, 0.3);
        // The factor in use was computed at a point on the way, where the lane says.
        let at = lane.factor_at().unwrap();
        assert!(lane.gram().is_some() && at.zero_offset.len() == lane.lin.zero_offset.len());
    }
}
