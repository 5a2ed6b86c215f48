//! Weighted nonlinear least squares: a Levenberg–Marquardt solver restricted to the identifiable
//! subspace, for any [`LeastSquaresProblem`].
//!
//! # Algorithm
//! The problem gives weighted residuals `r` (each divided by its standard deviation, so the cost
//! `χ² = ‖r‖²` is in noise units) and their Jacobian `J` with respect to a step from the current point
//! (re-linearised after every accepted step). Columns are scaled by the expected parameter magnitudes
//! `D` (`J_s = J D`; a zero scale freezes a parameter). Steps are taken in the identifiable subspace `B`
//! only: at the start it is spanned by the eigenvectors of the scaled normal matrix `J_sᵀ J_s` with
//! eigenvalues above `max(1e-11 λ_max, floor²)` (cheap, and accurate enough to step in); at the solution
//! the SVD `J_s = U Σ Vᵀ` (Householder QR, then the SVD of `R`) decides: singular values below
//! `max(rank_rtol · σ_max, min_singular_value)` are unidentifiable. Should the SVD find another rank
//! than the start, the iterations go on in its subspace; a long solve also takes the SVD every 50
//! iterations, so that a combination whose σ sinks below the floor on the way (a weakly determined
//! joint compliance once the torques move to the equilibrium) is dropped instead of being walked
//! until the iteration cap. Each iteration solves the damped reduced normal
//! equations `(Bᵀ J_sᵀ J_s B + μ diag) z = −Bᵀ J_sᵀ r` (Cholesky; Marquardt's diagonal damping with
//! Nielsen's update of `μ`) and steps by `D B z`. Restricting to `B` makes every step the minimum-norm
//! (in scaled units) Gauss–Newton step.
//!
//! # Curved valleys: geodesic acceleration
//! A fit that misses a large effect (the kinematic model on data with millimetres of joint
//! compliance) walks a long, curved valley: the Gauss–Newton model predicts a step's decrease well
//! only over a short way, the damping settles where half the predicted decrease is realised, and the
//! solve creeps (75 iterations on 200 poses of the bench's data). Each step is therefore corrected by
//! Transtrum and Sethna's geodesic acceleration ("Improvements to the Levenberg–Marquardt algorithm
//! for nonlinear least-squares minimization", 2012): the residuals' second derivative along the
//! damped step `v`, from one more residual evaluation at `x + 0.1 v`, gives the acceleration `a` with
//! the same damped normal matrix, and the step taken is `v + a/2` when `2‖a‖ ≤ 0.75 ‖v‖` (else `v`).
//! The decrease it is judged against stays the one the Gauss–Newton model predicts for `v`, and the
//! stopping rule below is unchanged, so a solve stops at the same minimum to the same tolerance, in
//! fewer iterations (32 instead of 75 on that fit). A solve that starts from normal equations handed
//! over ([`SolveHints::initial`]) takes its first step without it (the Jacobian is not at hand).
//!
//! # Stopping: converged to the noise
//! At each point the full Gauss–Newton step would lower `χ²` by `pred = gᵀ G⁻¹ g` (reduced gradient `g`,
//! reduced normal matrix `G`), the squared length of the residual's projection onto the identifiable
//! column space. The solve stops when `pred ≤ decrease_tol + relative_decrease_tol · χ²`: with the default
//! `decrease_tol = 1e-12`, no remaining step could move the predictions by more than about 1e-6 of a
//! noise standard deviation (in RSS over all rows); `relative_decrease_tol = 1e-10` takes over when
//! model errors keep `χ²` far above its degrees of freedom. It also stops when a step no longer changes `χ²` beyond rounding
//! (`NoFurtherDecrease`, also a success). Only a cap on iterations (`MaxIterations`), a failure to find a
//! decreasing step (`DampingLimit`) or non-finite values end a solve unsuccessfully.
//!
//! # Numerical health
//! Every report carries a [`Health`] record ([`crate::health`]): non-finite residuals and Jacobian
//! entries (at the start, at trial points and at accepted points; counted per row), overflow of `χ²`
//! or the normal matrix, a near-singular normal matrix (failed Cholesky factorisations with finite
//! entries, and identifiable singular values below [`NEAR_SINGULAR_MARGIN`]` · rank_rtol · σ_max` at
//! the solution), and the iteration and damping limits. Recording only reads what the solver computes
//! anyway (on the failure paths it also evaluates the residuals and the Jacobian once to find the
//! rows): the steps are the same with or without it.

use nalgebra::{DMatrix, DVector};

use crate::health::{Health, Warning};

mod subspace;
pub use subspace::{NEAR_SINGULAR_MARGIN, Subspace};

/// A weighted nonlinear least-squares problem on a manifold, linearised at a current point.
///
/// Shape of levenberg-marquardt's trait: [`LeastSquaresProblem::set_params`] moves the trial point and
/// caches the shared work, then [`LeastSquaresProblem::residuals`] and the Jacobian functions read it.
pub trait LeastSquaresProblem {
    /// Number of step parameters `p`.
    fn n_params(&self) -> usize;
    /// Number of scalar residuals `m`.
    fn n_residuals(&self) -> usize;
    /// Moves the trial point to the linearisation point plus `step` (length `p`, physical units).
    fn set_params(&mut self, step: &[f64]);
    /// Makes the trial point the new linearisation point.
    fn accept(&mut self);
    /// Weighted residuals (dimensionless, noise units) at the trial point into `out` (length `m`).
    fn residuals(&mut self, out: &mut [f64]);
    /// Weighted Jacobian (m × p) at the trial point, with respect to a step taken from it.
    fn jacobian(&mut self, out: &mut DMatrix<f64>);
    /// Normal equations of the column-scaled problem at the trial point: `gram = D Jᵀ J D` (p × p,
    /// full symmetric), `gradient = D Jᵀ r`; returns `χ² = ‖r‖²`. The default forms `J`; problems
    /// override it to accumulate row by row without allocating.
    fn normal_equations(
        &mut self,
        scales: &[f64],
        gram: &mut DMatrix<f64>,
        gradient: &mut [f64],
    ) -> f64 {
        let (m, p) = (self.n_residuals(), self.n_params());
        let mut j = DMatrix::zeros(m, p);
        let mut r = vec![0.0; m];
        self.jacobian(&mut j);
        self.residuals(&mut r);
        for (c, s) in scales.iter().enumerate() {
            j.column_mut(c).scale_mut(*s);
        }
        gram.copy_from(&j.tr_mul(&j));
        let g = j.tr_mul(&DVector::from_column_slice(&r));
        gradient.copy_from_slice(g.as_slice());
        r.iter().map(|v| v * v).sum()
    }

    /// `D Jᵀ w` (length `p`) for a vector `w` of `m` residual values, with the column-scaled Jacobian
    /// at the trial point; the solver calls it with the trial point where it last called
    /// [`LeastSquaresProblem::normal_equations`], with the same `scales`, so that problems may keep
    /// that call's Jacobian. The default forms `J`.
    fn scaled_jacobian_transpose_times(&mut self, scales: &[f64], w: &[f64], out: &mut [f64]) {
        formed_jacobian_transpose_times(self, scales, w, out);
    }

    /// A square factor `R` (p × p) of the column-scaled Jacobian at the trial point, `RᵀR = D JᵀJ D`,
    /// for the SVD that decides the rank ([`Subspace::from_factor`]): the `R` of a QR decomposition
    /// ([`crate::linalg::r_factor_scaled`]) when `m > p`, else `J D` padded with zero rows. The default
    /// forms `J`; problems override it to factor blocks of rows without forming all of `J`, with the
    /// same arithmetic.
    fn scaled_factor(&mut self, scales: &[f64]) -> DMatrix<f64> {
        let (m, p) = (self.n_residuals(), self.n_params());
        let mut j = DMatrix::zeros(m, p);
        self.jacobian(&mut j);
        Subspace::square_factor(&j, scales)
    }
}

/// [`LeastSquaresProblem::scaled_jacobian_transpose_times`] by forming `J` at the trial point (the
/// default, and the fallback of problems that keep the Jacobian).
pub fn formed_jacobian_transpose_times<P: LeastSquaresProblem + ?Sized>(
    problem: &mut P,
    scales: &[f64],
    w: &[f64],
    out: &mut [f64],
) {
    let (m, p) = (problem.n_residuals(), problem.n_params());
    let mut j = DMatrix::zeros(m, p);
    problem.jacobian(&mut j);
    let jtw = j.tr_mul(&DVector::from_column_slice(w));
    for ((o, v), s) in out.iter_mut().zip(jtw.iter()).zip(scales) {
        *o = v * s;
    }
}

/// Settings of [`minimize`].
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LmOptions {
    /// Safety cap on iterations; reaching it is an unsuccessful termination. Default 500. A fit of a
    /// model that misses a large effect (the kinematic model on `scenarios/iiwa7_all.toml`: millimetres
    /// of joint compliance, `χ²/dof` over 10⁴) walks a long, flat valley of weakly determined
    /// combinations: 36 iterations on that scenario's 200 poses at seed 7 with the geodesic
    /// acceleration (117 without it). Clean fits converge in under 10.
    pub max_iterations: usize,
    /// Singular values of the scaled, weighted Jacobian below `rank_rtol · σ_max` are unidentifiable.
    /// Default 1e-8: structural null directions sit at rounding level (about 1e-15 σ_max), while any
    /// combination with σ/σ_max above 1e-8 can be solved, if with large noise amplification (reported).
    pub rank_rtol: f64,
    /// Singular values below this absolute floor are unidentifiable too. With rows weighted by the
    /// noise and columns scaled by the expected magnitudes, `1/σₖ` is the standard deviation of the
    /// combination in units of its expected magnitude; below the default 0.1 it would exceed ten
    /// expected magnitudes: the data do not determine it, fitting it only fits noise and model errors,
    /// and its Gauss–Newton steps leave the region where the linearisation holds.
    pub min_singular_value: f64,
    /// Absolute tolerance on the predicted decrease of `χ²` by a full Gauss–Newton step. Default 1e-12.
    pub decrease_tol: f64,
    /// Relative tolerance on the same, against `χ²`. Default 1e-10: what is left is a negligible
    /// fraction of the noise-scaled cost (this one matters when model errors keep `χ²/dof` above 1).
    pub relative_decrease_tol: f64,
    /// Initial Marquardt damping `μ` (relative to the reduced normal matrix' diagonal). Default 1e-6.
    pub initial_damping: f64,
}

impl Default for LmOptions {
    fn default() -> Self {
        LmOptions {
            max_iterations: 500,
            rank_rtol: 1e-8,
            min_singular_value: 0.1,
            decrease_tol: 1e-12,
            relative_decrease_tol: 1e-10,
            initial_damping: 1e-6,
        }
    }
}

/// Why a solve ended.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TerminationReason {
    /// No Gauss–Newton step could lower `χ²` by more than the tolerance: converged to the noise.
    Converged,
    /// Steps no longer change `χ²` beyond rounding: converged to machine precision.
    NoFurtherDecrease,
    /// Every parameter is frozen or unidentifiable: nothing to solve.
    NoIdentifiableParameters,
    /// [`LmOptions::max_iterations`] reached before convergence.
    MaxIterations,
    /// No damping gave a decreasing step.
    DampingLimit,
    /// A residual or Jacobian entry was NaN or infinite at the start (or `χ²` overflowed); the
    /// report's [`MinimizationReport::health`] names the rows.
    NonFinite,
    /// The caller asked the work to stop ([`crate::cancel`]); the point is where the solve stopped.
    Cancelled,
}

impl std::fmt::Display for TerminationReason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            TerminationReason::Converged => "converged to the noise",
            TerminationReason::NoFurtherDecrease => "converged to rounding level",
            TerminationReason::NoIdentifiableParameters => "no identifiable parameter",
            TerminationReason::MaxIterations => "iteration limit reached before convergence",
            TerminationReason::DampingLimit => "no decreasing step found",
            TerminationReason::NonFinite => "non-finite residuals",
            TerminationReason::Cancelled => "cancelled",
        })
    }
}

/// Outcome of [`minimize`]: a report, not an error.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MinimizationReport {
    /// Why the solve ended.
    pub termination: TerminationReason,
    /// Accepted and rejected iterations (one normal-equation evaluation each).
    pub iterations: usize,
    /// Residual evaluations (trial points).
    pub evaluations: usize,
    /// `χ²` (sum of squared weighted residuals) at the start (with a robust loss: before the first
    /// reweighting round, while `cost_final` carries the final weights).
    pub cost_initial: f64,
    /// `χ²` at the end.
    pub cost_final: f64,
    /// Predicted `χ²` decrease of a full Gauss–Newton step at the end.
    pub predicted_decrease: f64,
    /// Number of residuals `m`.
    pub n_residuals: usize,
    /// Number of parameters `p`.
    pub n_params: usize,
    /// Identifiable combinations at the end (rank of the scaled Jacobian).
    pub rank: usize,
    /// Numerical warnings of the solve, counted (empty in JSON when clean; absent in older reports,
    /// read as clean).
    #[serde(default)]
    pub health: Health,
}

impl MinimizationReport {
    /// True when the solve converged (to the noise or to rounding level).
    pub fn was_successful(&self) -> bool {
        matches!(
            self.termination,
            TerminationReason::Converged | TerminationReason::NoFurtherDecrease
        )
    }
}

/// Buffers of [`minimize`], reusable across solves of the same size. The full Jacobian is never
/// kept (its rank decision factors it by blocks, [`LeastSquaresProblem::scaled_factor`]).
#[derive(Clone, Debug)]
pub struct LmWorkspace {
    residuals: Vec<f64>,
    gram: DMatrix<f64>,
    gradient: Vec<f64>,
}

impl LmWorkspace {
    /// Buffers for `m` residuals and `p` parameters.
    pub fn new(m: usize, p: usize) -> Self {
        LmWorkspace {
            residuals: vec![0.0; m],
            gram: DMatrix::zeros(p, p),
            gradient: vec![0.0; p],
        }
    }

    /// The weighted residuals at the end of the last solve.
    pub fn residuals(&self) -> &[f64] {
        &self.residuals
    }

    /// The column-scaled normal matrix `D JᵀJ D` (p × p) at the end of the last solve.
    pub fn gram(&self) -> &DMatrix<f64> {
        &self.gram
    }
}

fn chi2(r: &[f64]) -> f64 {
    r.iter().map(|v| v * v).sum()
}

/// Records every non-finite entry of `r` as [`Warning::NonFiniteResidual`] at its row; returns how many.
fn record_non_finite_residuals(r: &[f64], health: &mut Health) -> usize {
    let mut n = 0;
    for (row, v) in r.iter().enumerate() {
        if !v.is_finite() {
            health.record(Warning::NonFiniteResidual, row);
            n += 1;
        }
    }
    n
}

/// After non-finite normal equations at the trial point: evaluates the residuals and the Jacobian there
/// (into `ws`) and records each row with a non-finite value; if every entry is finite, records
/// [`Warning::Overflow`] at `iteration`.
fn locate_non_finite<P: LeastSquaresProblem>(
    problem: &mut P,
    ws: &mut LmWorkspace,
    iteration: usize,
    health: &mut Health,
) {
    problem.residuals(&mut ws.residuals);
    let mut jacobian = DMatrix::zeros(problem.n_residuals(), problem.n_params());
    problem.jacobian(&mut jacobian);
    let mut n = record_non_finite_residuals(&ws.residuals, health);
    for row in 0..jacobian.nrows() {
        if jacobian.row(row).iter().any(|v| !v.is_finite()) {
            health.record(Warning::NonFiniteJacobian, row);
            n += 1;
        }
    }
    if n == 0 {
        health.record(Warning::Overflow, iteration);
    }
}

/// True when `χ²` and every entry of the normal matrix are finite.
fn normal_equations_finite(cost: f64, gram: &DMatrix<f64>) -> bool {
    cost.is_finite() && gram.iter().all(|v| v.is_finite())
}

/// Minimises `χ² = ‖r‖²` of `problem` from its current point with column scales `scales` (physical units
/// per scaled unit, 0 = frozen). On return the problem's linearisation point is the solution and its
/// trial point equals it; the workspace holds the final residuals and normal matrix, and the returned
/// [`Subspace`] is the SVD at the solution (for covariance and identifiability).
pub fn minimize<P: LeastSquaresProblem>(
    problem: &mut P,
    scales: &[f64],
    options: &LmOptions,
    ws: &mut LmWorkspace,
) -> (MinimizationReport, Subspace) {
    minimize_with(problem, scales, options, ws, &SolveHints::default())
}

/// What a solve may take from work done elsewhere ([`minimize_with`]): cross-validation folds,
/// which start at the solution on every row, get these from one pass over all rows.
#[derive(Clone, Copy, Debug, Default)]
pub struct SolveHints<'a> {
    /// The normal equations at the start, as [`LeastSquaresProblem::normal_equations`] gives them
    /// with the solve's scales: `χ²`, `D JᵀJ D` (p × p, full), `D Jᵀr`.
    pub initial: Option<(f64, &'a DMatrix<f64>, &'a [f64])>,
    /// A square factor of the scaled Jacobian ([`LeastSquaresProblem::scaled_factor`]) at a point
    /// next to the solution (the start, when the solve starts next to its minimum). The rank decision
    /// takes its SVD when every singular value lies further than [`RANK_HINT_BAND`] (relative) from
    /// the threshold, where the short way to the solution cannot move one across it; otherwise the
    /// factor at the solution is computed as without a hint.
    pub factor: Option<&'a DMatrix<f64>>,
}

/// Relative distance from the rank threshold that every singular value of
/// [`SolveHints::factor`] must keep for its SVD to stand for the one at the solution.
pub const RANK_HINT_BAND: f64 = 0.01;

impl Subspace {
    /// Whether every singular value lies further than `band · t` from the threshold `t`.
    fn clear_of_threshold(&self, band: f64) -> bool {
        let smax = self.singular_values.first().copied().unwrap_or(0.0);
        let t = (self.rtol * smax).max(self.floor);
        smax.is_finite()
            && smax > 0.0
            && self
                .singular_values
                .iter()
                .all(|s| (s - t).abs() > band * t)
    }
}

/// [`minimize`] with [`SolveHints`]: the same solve, with the hinted work taken instead of computed.
pub fn minimize_with<P: LeastSquaresProblem>(
    problem: &mut P,
    scales: &[f64],
    options: &LmOptions,
    ws: &mut LmWorkspace,
    hints: &SolveHints<'_>,
) -> (MinimizationReport, Subspace) {
    let (m, p) = (problem.n_residuals(), problem.n_params());
    assert_eq!(scales.len(), p, "one scale per parameter");
    if ws.residuals.len() != m || ws.gram.nrows() != p {
        *ws = LmWorkspace::new(m, p);
    }
    let zero = vec![0.0; p];
    problem.set_params(&zero);
    let cost_initial = match hints.initial {
        Some((cost, gram, gradient)) => {
            ws.gram.copy_from(gram);
            ws.gradient.copy_from_slice(gradient);
            cost
        }
        None => problem.normal_equations(scales, &mut ws.gram, &mut ws.gradient),
    };
    let hinted = hints
        .factor
        .map(|f| Subspace::from_factor(f, scales, options.rank_rtol, options.min_singular_value, m))
        .filter(|s| s.clear_of_threshold(RANK_HINT_BAND));
    let mut report = MinimizationReport {
        termination: TerminationReason::Converged,
        iterations: 0,
        evaluations: 1,
        cost_initial,
        cost_final: cost_initial,
        predicted_decrease: 0.0,
        n_residuals: m,
        n_params: p,
        rank: 0,
        health: Health::new(),
    };
    let nothing_solved = || Subspace {
        scales: scales.to_vec(),
        singular_values: vec![0.0; p],
        v: DMatrix::identity(p, p),
        rank: 0,
        rtol: options.rank_rtol,
        floor: options.min_singular_value,
        n_residuals: m,
    };
    if !cost_initial.is_finite() || ws.gram.iter().any(|v| !v.is_finite()) {
        report.termination = TerminationReason::NonFinite;
        locate_non_finite(problem, ws, 0, &mut report.health);
        return (report, nothing_solved());
    }
    // Starting subspace from the eigenvectors of the scaled normal matrix (cheap, and accurate enough
    // to step in); the decision that counts is the SVD at the solution. Should that find a different
    // rank (a combination with σ/σ_max between `rank_rtol` and √GRAM_RTOL, or one whose σ crossed the
    // floor on the way), the iterations go on in the SVD's subspace. The SVD is also taken every
    // RANK_CHECK_INTERVAL iterations of a long solve: a combination that sinks below the floor while
    // the solve walks a long valley is dropped then, not after the iteration cap.
    let mut basis = gram_basis(&ws.gram, options.min_singular_value);
    let mut fresh = true;
    let mut damping = Damping::new(options);
    let mut sub;
    loop {
        if basis.ncols() == 0 {
            report.termination = TerminationReason::NoIdentifiableParameters;
        } else {
            let cap = (options.max_iterations - report.iterations.min(options.max_iterations))
                .min(RANK_CHECK_INTERVAL);
            iterate(
                problem,
                scales,
                ws,
                &basis,
                fresh,
                hints.initial.is_none(),
                cap,
                &mut damping,
                options,
                &mut report,
            );
        }
        fresh = false;
        if report.termination == TerminationReason::Cancelled {
            // No rank decision for a solve the caller stopped: its result is not used.
            return (report, nothing_solved());
        }
        sub = match &hinted {
            Some(h) => h.clone(),
            None => Subspace::from_factor(
                &problem.scaled_factor(scales),
                scales,
                options.rank_rtol,
                options.min_singular_value,
                m,
            ),
        };
        problem.residuals(&mut ws.residuals);
        report.rank = sub.rank;
        let settled = sub.rank == basis.ncols();
        let paused = report.termination == TerminationReason::MaxIterations
            && report.iterations < options.max_iterations;
        if report.termination == TerminationReason::MaxIterations && !paused {
            report
                .health
                .record(Warning::IterationLimit, report.iterations);
        }
        if (!paused && (settled || !report.was_successful()))
            || report.evaluations > 10 * options.max_iterations
        {
            break;
        }
        if !settled {
            basis = sub.v.columns(0, sub.rank).into_owned();
            damping = Damping::new(options);
        }
    }
    if sub.near_singular_count() > 0 {
        report
            .health
            .record(Warning::NearSingularNormalMatrix, report.iterations);
    }
    (report, sub)
}

/// Iterations between two rank decisions (SVD) of a long solve, see [`minimize`].
const RANK_CHECK_INTERVAL: usize = 50;

/// Marquardt damping `μ` and Nielsen's growth factor `ν`, carried across the rounds of one subspace.
#[derive(Clone, Copy, Debug)]
struct Damping {
    mu: f64,
    nu: f64,
}

impl Damping {
    fn new(options: &LmOptions) -> Self {
        Damping {
            mu: options.initial_damping,
            nu: 2.0,
        }
    }
}

/// Step of the finite difference along the step that gives the residuals' second directional
/// derivative in [`accelerate`], relative to the step (Transtrum and Sethna's 0.1).
const ACCELERATION_FD_STEP: f64 = 0.1;

/// Largest ratio `2‖a‖ / ‖v‖` (Marquardt-scaled norms) of the acceleration `a` to the velocity `v`
/// for which the accelerated step is taken (Transtrum and Sethna's 0.75); beyond it the second-order
/// term is not small and the step is the damped Gauss–Newton step alone.
const ACCELERATION_MAX_RATIO: f64 = 0.75;

/// Buffers of [`accelerate`] for one solve.
#[derive(Clone, Debug, Default)]
struct Acceleration {
    /// The residuals at the linearisation point, when `at_x`.
    r0: Vec<f64>,
    at_x: bool,
    /// The residuals at the finite-difference point, then their difference from `r0`.
    rh: Vec<f64>,
    /// `D Jᵀ (rh − r0)` (p).
    jtw: Vec<f64>,
    /// The finite-difference step (physical units, p).
    h_step: Vec<f64>,
    /// No step (p zeros).
    zero: Vec<f64>,
}

/// Geodesic acceleration (Transtrum and Sethna, 2012): with the damped Gauss–Newton step `v = D B z`
/// in `step`, the residuals' second directional derivative `r_vv ≈ (2/h)((r(x + h v) − r(x))/h − J v)`
/// gives the acceleration `a = −(Bᵀ D JᵀJ D B + μ diag)⁻¹ Bᵀ D Jᵀ r_vv` (the same factor `ch`), and
/// the step becomes `D B (z + a/2)`: the second-order path along a curved valley, where the linear
/// step leaves the valley after a short way. `Jᵀ r_vv` is computed as
/// `(2/h²)(Jᵀ(r(x + h v) − r(x)) − h JᵀJ v)`, one residual evaluation and one product with the
/// Jacobian that the normal equations left. Returns whether `step` was accelerated (not when
/// `2‖a‖/‖z‖ > `[`ACCELERATION_MAX_RATIO`] or on non-finite values); leaves the trial point at `x`.
#[allow(clippy::too_many_arguments)]
fn accelerate<P: LeastSquaresProblem>(
    problem: &mut P,
    scales: &[f64],
    b: &DMatrix<f64>,
    ch: &nalgebra::Cholesky<f64, nalgebra::Dyn>,
    gr: &DMatrix<f64>,
    diag: &[f64],
    z: &DVector<f64>,
    step: &mut [f64],
    acc: &mut Acceleration,
    report: &mut MinimizationReport,
) -> bool {
    let (m, p) = (problem.n_residuals(), problem.n_params());
    let h = ACCELERATION_FD_STEP;
    acc.rh.resize(m, 0.0);
    acc.jtw.resize(p, 0.0);
    acc.h_step.resize(p, 0.0);
    acc.r0.resize(m, 0.0);
    acc.zero.resize(p, 0.0);
    if !acc.at_x {
        problem.set_params(&acc.zero);
        problem.residuals(&mut acc.r0);
        report.evaluations += 1;
        acc.at_x = true;
    }
    for (d, s) in acc.h_step.iter_mut().zip(step.iter()) {
        *d = h * s;
    }
    problem.set_params(&acc.h_step);
    problem.residuals(&mut acc.rh);
    report.evaluations += 1;
    problem.set_params(&acc.zero);
    for (w, r0) in acc.rh.iter_mut().zip(&acc.r0) {
        *w -= r0;
    }
    if acc.rh.iter().any(|v| !v.is_finite()) {
        return false;
    }
    problem.scaled_jacobian_transpose_times(scales, &acc.rh, &mut acc.jtw);
    let jtw = DVector::from_column_slice(&acc.jtw);
    let rhs = (b.tr_mul(&jtw) - gr * z * h) * (2.0 / (h * h));
    let a = -ch.solve(&rhs);
    let norm = |v: &DVector<f64>| {
        v.iter()
            .zip(diag)
            .map(|(x, d)| d * x * x)
            .sum::<f64>()
            .sqrt()
    };
    let ratio = 2.0 * norm(&a) / norm(z);
    if ratio.is_nan() || ratio > ACCELERATION_MAX_RATIO {
        return false;
    }
    let v = b * (z + a * 0.5);
    for ((s, v), d) in step.iter_mut().zip(v.iter()).zip(scales) {
        *s = d * v;
    }
    true
}

/// Relative eigenvalue threshold of the scaled normal matrix for the starting subspace: rounding in
/// `JᵀJ` leaves structural null eigenvalues near 1e-14 λ_max.
const GRAM_RTOL: f64 = 1e-11;

/// Eigenvectors of the symmetric `gram` with eigenvalues above `max(GRAM_RTOL · λ_max, floor²)`, as
/// columns.
fn gram_basis(gram: &DMatrix<f64>, floor: f64) -> DMatrix<f64> {
    let p = gram.nrows();
    let eig = gram.clone().symmetric_eigen();
    let lmax = eig.eigenvalues.iter().copied().fold(0.0, f64::max);
    let keep: Vec<usize> = (0..p)
        .filter(|&k| lmax > 0.0 && eig.eigenvalues[k] > (GRAM_RTOL * lmax).max(floor * floor))
        .collect();
    let mut b = DMatrix::zeros(p, keep.len());
    for (c, &k) in keep.iter().enumerate() {
        b.set_column(c, &eig.eigenvectors.column(k));
    }
    b
}

/// The LM iterations in the subspace `sub`; leaves the trial point at the linearisation point.
/// With `fresh`, `ws.gram` and `ws.gradient` already hold the normal equations at the current point.
#[allow(clippy::too_many_arguments)]
fn iterate<P: LeastSquaresProblem>(
    problem: &mut P,
    scales: &[f64],
    ws: &mut LmWorkspace,
    b: &DMatrix<f64>,
    mut fresh: bool,
    fresh_from_problem: bool,
    cap: usize,
    damping: &mut Damping,
    options: &LmOptions,
    report: &mut MinimizationReport,
) {
    let p = scales.len();
    let r = b.ncols();
    let mut gb = DMatrix::zeros(p, r);
    let mut gr = DMatrix::zeros(r, r);
    let mut grad_r = DVector::zeros(r);
    let mut z = DVector::zeros(r);
    let mut step = vec![0.0; p];
    let Damping { mut mu, mut nu } = *damping;
    let start_iterations = report.iterations;
    // The Jacobian of the normal equations at x is there for the acceleration (not when a solve
    // starts from normal equations handed over in its hints).
    let mut jacobian_at_x = !fresh || fresh_from_problem;
    let mut accel = Acceleration::default();
    loop {
        // Asked to stop (crate::cancel): before the next normal equations, the costly part.
        if crate::cancel::checkpoint().is_err() {
            report.termination = TerminationReason::Cancelled;
            return;
        }
        let cost = if fresh {
            fresh = false;
            report.cost_final
        } else {
            jacobian_at_x = true;
            problem.normal_equations(scales, &mut ws.gram, &mut ws.gradient)
        };
        let finite = normal_equations_finite(cost, &ws.gram);
        if !finite {
            locate_non_finite(problem, ws, report.iterations, &mut report.health);
        }
        report.cost_final = cost;
        gb.gemm(1.0, &ws.gram, b, 0.0);
        gr.gemm_tr(1.0, b, &gb, 0.0);
        let g = DVector::from_column_slice(&ws.gradient);
        grad_r.gemv_tr(1.0, b, &g, 0.0);
        let diag: Vec<f64> = (0..r).map(|k| gr[(k, k)].max(f64::MIN_POSITIVE)).collect();
        // Full Gauss–Newton prediction (tiny ridge against rounding in the normal matrix).
        let pred_gn = {
            let mut a = gr.clone();
            for k in 0..r {
                a[(k, k)] += 1e-14 * diag[k];
            }
            match a.cholesky() {
                Some(ch) => grad_r.dot(&ch.solve(&grad_r)),
                None => {
                    if finite {
                        report
                            .health
                            .record(Warning::NearSingularNormalMatrix, report.iterations);
                    }
                    f64::INFINITY
                }
            }
        };
        report.predicted_decrease = pred_gn;
        if pred_gn <= options.decrease_tol + options.relative_decrease_tol * cost {
            report.termination = TerminationReason::Converged;
            return;
        }
        if report.iterations - start_iterations >= cap {
            report.termination = TerminationReason::MaxIterations;
            *damping = Damping { mu, nu };
            return;
        }
        report.iterations += 1;
        loop {
            let mut a = gr.clone();
            for k in 0..r {
                a[(k, k)] += mu * diag[k];
            }
            let Some(ch) = a.cholesky() else {
                if finite {
                    report
                        .health
                        .record(Warning::NearSingularNormalMatrix, report.iterations);
                }
                mu *= nu;
                nu *= 2.0;
                if mu > 1e16 {
                    report.termination = TerminationReason::DampingLimit;
                    report
                        .health
                        .record(Warning::DampingLimit, report.iterations);
                    problem.set_params(&vec![0.0; p]);
                    return;
                }
                continue;
            };
            z.copy_from(&ch.solve(&grad_r));
            z.neg_mut();
            // Predicted decrease of the damped step: −(2 gᵀz + zᵀ G z).
            let pred = -(2.0 * grad_r.dot(&z) + z.dot(&(&gr * &z)));
            let bz = b * &z;
            for k in 0..p {
                step[k] = scales[k] * bz[k];
            }
            // Geodesic acceleration (a second-order correction along the curved valley).
            if jacobian_at_x {
                accelerate(
                    problem, scales, b, &ch, &gr, &diag, &z, &mut step, &mut accel, report,
                );
            }
            problem.set_params(&step);
            problem.residuals(&mut ws.residuals);
            report.evaluations += 1;
            let trial = chi2(&ws.residuals);
            if !trial.is_finite()
                && record_non_finite_residuals(&ws.residuals, &mut report.health) == 0
            {
                report.health.record(Warning::Overflow, report.iterations);
            }
            let actual = cost - trial;
            if trial.is_finite() && actual.abs() <= 1e-15 * cost && pred <= 1e-12 * cost.max(1e-300)
            {
                problem.set_params(&vec![0.0; p]);
                report.termination = TerminationReason::NoFurtherDecrease;
                return;
            }
            let rho = if pred > 0.0 { actual / pred } else { -1.0 };
            if trial.is_finite() && rho > 1e-4 {
                problem.accept();
                report.cost_final = trial;
                accel.r0.clone_from(&ws.residuals);
                accel.at_x = true;
                mu *= (1.0f64 / 3.0).max(1.0 - (2.0 * rho - 1.0).powi(3));
                nu = 2.0;
                break;
            }
            mu *= nu;
            nu *= 2.0;
            if mu > 1e16 {
                problem.set_params(&vec![0.0; p]);
                report.termination = TerminationReason::DampingLimit;
                report
                    .health
                    .record(Warning::DampingLimit, report.iterations);
                return;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `step_in_sigmas` is `‖J δ‖ / √variance_factor` for an identifiable step (the change of the
    /// weighted residuals it makes, computed directly), and 0 along a null direction (two equal
    /// columns: `δ = eₐ − e_b` changes nothing).
    /// A factor with fewer rows than columns (the `R` of 4 residuals for 6 parameters, as a left-out
    /// region of a small data set gives) is decided as the same factor padded with zero rows, and
    /// as the Jacobian itself: rank 4, the nonzero singular values of `J D`.
    #[test]
    fn a_factor_of_fewer_rows_than_parameters_is_decided_as_its_padded_square() {
        let j = DMatrix::from_fn(4, 6, |i, k| {
            ((i * 7 + k * 3) % 5) as f64 - 2.0 + 0.1 * k as f64
        });
        let scales = vec![1.0, 2.0, 0.5, 1.0, 3.0, 1.0];
        let r = crate::linalg::r_factor_scaled(&j, Some(&scales));
        assert_eq!(r.shape(), (4, 6));
        let short = Subspace::from_factor(&r, &scales, 1e-10, 0.0, 4);
        let mut padded = DMatrix::zeros(6, 6);
        padded.view_mut((0, 0), (4, 6)).copy_from(&r);
        let square = Subspace::from_factor(&padded, &scales, 1e-10, 0.0, 4);
        assert_eq!(short, square);
        let direct = Subspace::analyze(&j, &scales, 1e-10, 0.0);
        assert_eq!(short.rank, 4);
        assert_eq!(direct.rank, 4);
        for (a, b) in short.singular_values.iter().zip(&direct.singular_values) {
            assert!(
                (a - b).abs() <= 1e-12 * direct.singular_values[0],
                "{a} vs {b}"
            );
        }
    }

    #[test]
    fn step_in_sigmas_is_the_change_of_the_residuals_in_noise_units() {
        let (m, p) = (12, 4);
        let mut j = DMatrix::from_fn(m, p, |r, c| {
            ((r * 7 + c * 3) % 11) as f64 - 5.0 + 0.1 * c as f64
        });
        let scales = [0.5, 2.0, 1e-3, 1.0];
        let sub = Subspace::analyze(&j, &scales, 1e-8, 0.0);
        assert_eq!(sub.rank, p);
        let delta = [0.01, -0.02, 3e-5, 0.004];
        let direct = (&j * DVector::from_column_slice(&delta)).norm();
        let vf = 2.5;
        let got = sub.step_in_sigmas(&delta, vf);
        assert!(
            (got - direct / vf.sqrt()).abs() < 1e-12 * direct,
            "{got} against {}",
            direct / vf.sqrt()
        );
        // Column 3 equal to column 1 (same scale): e₁ − e₃ lies in the null space.
        let c1 = j.column(1).into_owned();
        j.set_column(3, &c1);
        let scales = [0.5, 2.0, 1e-3, 2.0];
        let sub = Subspace::analyze(&j, &scales, 1e-8, 0.0);
        assert_eq!(sub.rank, p - 1);
        let null = [0.0, 0.3, 0.0, -0.3];
        let moved = sub.step_in_sigmas(&null, 1.0);
        assert!(moved < 1e-12, "{moved}");
    }

    /// Residuals quadratic in `x ∈ R²`: `rᵢ(x) = cᵢ + gᵢᵀx + ½ xᵀHᵢx`, so that the second directional
    /// derivative `vᵀHᵢv` is exact and the finite difference of [`accelerate`] has no truncation error.
    struct Quadratic {
        x: [f64; 2],
        trial: [f64; 2],
    }

    const C: [f64; 3] = [0.3, -1.2, 0.8];
    const G: [[f64; 2]; 3] = [[1.0, 0.5], [-0.4, 2.0], [0.7, -0.3]];
    const H: [[[f64; 2]; 2]; 3] = [
        [[0.2, 0.05], [0.05, -0.1]],
        [[0.0, 0.3], [0.3, 0.1]],
        [[-0.15, 0.0], [0.0, 0.25]],
    ];

    impl LeastSquaresProblem for Quadratic {
        fn n_params(&self) -> usize {
            2
        }
        fn n_residuals(&self) -> usize {
            3
        }
        fn set_params(&mut self, step: &[f64]) {
            self.trial = [self.x[0] + step[0], self.x[1] + step[1]];
        }
        fn accept(&mut self) {
            self.x = self.trial;
        }
        fn residuals(&mut self, out: &mut [f64]) {
            let x = self.trial;
            for i in 0..3 {
                let hx = [
                    H[i][0][0] * x[0] + H[i][0][1] * x[1],
                    H[i][1][0] * x[0] + H[i][1][1] * x[1],
                ];
                out[i] =
                    C[i] + G[i][0] * x[0] + G[i][1] * x[1] + 0.5 * (x[0] * hx[0] + x[1] * hx[1]);
            }
        }
        fn jacobian(&mut self, out: &mut DMatrix<f64>) {
            let x = self.trial;
            for i in 0..3 {
                for c in 0..2 {
                    out[(i, c)] = G[i][c] + H[i][c][0] * x[0] + H[i][c][1] * x[1];
                }
            }
        }
    }

    /// The accelerated step against the acceleration computed by hand: `r_vv,i = vᵀHᵢv` and
    /// `a = −(Bᵀ D JᵀJ D B + μ diag)⁻¹ Bᵀ D Jᵀ r_vv`, in a rotated subspace basis with column scales.
    #[test]
    fn the_acceleration_is_the_damped_solve_of_the_residuals_second_derivative() {
        let mut prob = Quadratic {
            x: [0.4, -0.7],
            trial: [0.4, -0.7],
        };
        let scales = [1.0, 2.0];
        let (cs, sn) = (0.6_f64, 0.8_f64);
        let b = DMatrix::from_row_slice(2, 2, &[cs, -sn, sn, cs]);
        let mut gram = DMatrix::zeros(2, 2);
        let mut gradient = vec![0.0; 2];
        prob.normal_equations(&scales, &mut gram, &mut gradient);
        let gr = b.transpose() * &gram * &b;
        let mu = 0.3;
        let diag = vec![gr[(0, 0)], gr[(1, 1)]];
        let mut damped = gr.clone();
        for k in 0..2 {
            damped[(k, k)] += mu * diag[k];
        }
        let ch = damped.clone().cholesky().expect("positive definite");
        let z = DVector::from_vec(vec![0.05, -0.08]);
        let bz = &b * &z;
        let mut step: Vec<f64> = (0..2).map(|k| scales[k] * bz[k]).collect();
        let v = step.clone();
        let mut acc = Acceleration::default();
        let mut report = MinimizationReport {
            termination: TerminationReason::Converged,
            iterations: 0,
            evaluations: 0,
            cost_initial: 0.0,
            cost_final: 0.0,
            predicted_decrease: 0.0,
            n_residuals: 3,
            n_params: 2,
            rank: 2,
            health: Health::new(),
        };
        let taken = accelerate(
            &mut prob,
            &scales,
            &b,
            &ch,
            &gr,
            &diag,
            &z,
            &mut step,
            &mut acc,
            &mut report,
        );
        assert!(taken, "a small second-order term is taken");
        assert_eq!(report.evaluations, 2, "r(x) and r(x + h v)");
        assert_eq!(prob.trial, prob.x, "the trial point is back at x");
        // By hand.
        let mut j = DMatrix::zeros(3, 2);
        prob.jacobian(&mut j);
        let rvv = DVector::from_fn(3, |i, _| {
            (0..2)
                .map(|r| (0..2).map(|c| v[r] * H[i][r][c] * v[c]).sum::<f64>())
                .sum::<f64>()
        });
        let jtr = j.transpose() * rvv;
        let djtr = DVector::from_fn(2, |k, _| scales[k] * jtr[k]);
        let a = -damped.cholesky().unwrap().solve(&(b.transpose() * djtr));
        let expected = &b * (&z + &a * 0.5);
        for k in 0..2 {
            let e = scales[k] * expected[k];
            assert!(
                (step[k] - e).abs() <= 1e-12 * e.abs().max(1e-3),
                "step[{k}] = {} against {e}",
                step[k]
            );
        }
        assert!(a.norm() > 1e-3 * z.norm(), "the test sees a correction");
    }
}
