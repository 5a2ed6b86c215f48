//! The Levenberg–Marquardt solver on small hand-made problems: every termination reason, the closed-form
//! solution of linear problems, the minimum-norm step on rank-deficient ones, and the numerical-health
//! counts (non-finite values, overflow, near-singular normal matrix, iteration and damping limits).

use calib::health::{Health, Warning};
use calib::lm::{
    LeastSquaresProblem, LmOptions, LmWorkspace, MinimizationReport, Subspace, TerminationReason,
    minimize,
};
use nalgebra::{DMatrix, DVector};

type Residuals = Box<dyn Fn(&[f64], &mut [f64])>;
type Jacobian = Box<dyn Fn(&[f64], &mut DMatrix<f64>)>;

/// A problem on `Rᵖ`: residuals and Jacobian as functions of the trial point.
struct Euclid {
    m: usize,
    /// Linearisation point.
    x: Vec<f64>,
    /// Trial point (`x + step`).
    trial: Vec<f64>,
    f: Residuals,
    j: Jacobian,
}

impl Euclid {
    fn new(m: usize, x0: &[f64], f: Residuals, j: Jacobian) -> Self {
        Euclid {
            m,
            x: x0.to_vec(),
            trial: x0.to_vec(),
            f,
            j,
        }
    }
}

impl LeastSquaresProblem for Euclid {
    fn n_params(&self) -> usize {
        self.x.len()
    }
    fn n_residuals(&self) -> usize {
        self.m
    }
    fn set_params(&mut self, step: &[f64]) {
        for ((t, x), s) in self.trial.iter_mut().zip(&self.x).zip(step) {
            *t = x + s;
        }
    }
    fn accept(&mut self) {
        self.x.copy_from_slice(&self.trial);
    }
    fn residuals(&mut self, out: &mut [f64]) {
        (self.f)(&self.trial, out);
    }
    fn jacobian(&mut self, out: &mut DMatrix<f64>) {
        (self.j)(&self.trial, out);
    }
}

fn solve(
    problem: &mut Euclid,
    scales: &[f64],
    options: &LmOptions,
) -> (MinimizationReport, Subspace, LmWorkspace) {
    let mut ws = LmWorkspace::new(problem.m, problem.x.len());
    let (report, sub) = minimize(problem, scales, options, &mut ws);
    (report, sub, ws)
}

/// The weighted linear problem `r = W (A x − b)`.
struct Linear {
    wa: DMatrix<f64>,
    wb: DVector<f64>,
}

impl Linear {
    fn new(a: DMatrix<f64>, b: DVector<f64>, w: &[f64]) -> Self {
        let mut wa = a;
        let mut wb = b;
        for (i, wi) in w.iter().enumerate() {
            wa.row_mut(i).scale_mut(*wi);
            wb[i] *= wi;
        }
        Linear { wa, wb }
    }

    /// The textbook case: six equations in three unknowns, inconsistent, unequal weights.
    fn example() -> Self {
        let a = DMatrix::from_row_slice(
            6,
            3,
            &[
                1.0, 0.2, 0.0, //
                0.1, 1.0, -0.3, //
                0.0, 0.4, 1.0, //
                1.0, 1.0, 0.5, //
                -0.5, 1.0, 1.0, //
                1.0, -0.7, 1.0,
            ],
        );
        let b = DVector::from_column_slice(&[1.0, -2.0, 3.0, 0.5, 2.5, -1.0]);
        Linear::new(a, b, &[1.0, 2.0, 0.5, 1.5, 1.0, 3.0])
    }

    /// The least-squares solution from Householder QR of `W A` (independent of the solver's normal
    /// equations).
    fn closed_form(&self) -> DVector<f64> {
        let qr = self.wa.clone().qr();
        let qtb = qr.q().transpose() * &self.wb;
        qr.r()
            .solve_upper_triangular(&qtb)
            .expect("full column rank")
    }

    fn chi2(&self, x: &DVector<f64>) -> f64 {
        (&self.wa * x - &self.wb).norm_squared()
    }

    fn problem(&self, x0: &[f64]) -> Euclid {
        let (wa, wb) = (self.wa.clone(), self.wb.clone());
        let wa2 = self.wa.clone();
        Euclid::new(
            self.wa.nrows(),
            x0,
            Box::new(move |x, out| {
                let r = &wa * DVector::from_column_slice(x) - &wb;
                out.copy_from_slice(r.as_slice());
            }),
            Box::new(move |_, out| out.copy_from(&wa2)),
        )
    }
}

/// Rosenbrock's function as residuals `[10 (y − x²), 1 − x]`, from the classic start `(−1.2, 1)`.
fn rosenbrock() -> Euclid {
    Euclid::new(
        2,
        &[-1.2, 1.0],
        Box::new(|x, out| {
            out[0] = 10.0 * (x[1] - x[0] * x[0]);
            out[1] = 1.0 - x[0];
        }),
        Box::new(|x, out| {
            out[(0, 0)] = -20.0 * x[0];
            out[(0, 1)] = 10.0;
            out[(1, 0)] = -1.0;
            out[(1, 1)] = 0.0;
        }),
    )
}

fn assert_clean(h: &Health) {
    assert!(h.is_clean(), "unexpected numerical warnings:\n{h}");
}

/// Undamped LM is Gauss–Newton, and Gauss–Newton solves a linear problem in one step.
#[test]
fn linear_undamped_is_one_gauss_newton_step_to_the_closed_form() {
    let lin = Linear::example();
    let expected = lin.closed_form();
    let mut prob = lin.problem(&[0.0; 3]);
    let options = LmOptions {
        initial_damping: 0.0,
        ..LmOptions::default()
    };
    let (report, sub, ws) = solve(&mut prob, &[1.0; 3], &options);
    assert_eq!(report.termination, TerminationReason::Converged);
    assert!(report.was_successful());
    assert_eq!(report.iterations, 1);
    // The start, the geodesic acceleration's two (the residuals at x and at x + 0.1 v: zero second
    // derivative on a linear problem, so the step stays Gauss–Newton's) and the trial point.
    assert_eq!(report.evaluations, 4);
    assert_eq!(
        (report.n_residuals, report.n_params, report.rank),
        (6, 3, 3)
    );
    assert_eq!(sub.rank, 3);
    for k in 0..3 {
        assert!(
            (prob.x[k] - expected[k]).abs() < 1e-12,
            "x[{k}] = {} against {}",
            prob.x[k],
            expected[k]
        );
    }
    let chi2_min = lin.chi2(&expected);
    assert_eq!(report.cost_initial, lin.wb.norm_squared());
    assert!((report.cost_final - chi2_min).abs() < 1e-12 * chi2_min);
    assert!(report.predicted_decrease <= options.decrease_tol);
    // The workspace holds the residuals and the normal matrix (scales 1: AᵀA) at the solution, and
    // the subspace is the SVD of the Jacobian there.
    let gram = lin.wa.transpose() * &lin.wa;
    assert!((ws.gram() - &gram).amax() <= 1e-12 * gram.amax());
    let svd = lin.wa.clone().svd(false, false);
    for (k, s) in sub.singular_values.iter().enumerate() {
        let e = svd
            .singular_values
            .iter()
            .copied()
            .fold(f64::NAN, |best: f64, v| {
                if best.is_nan() || (v - s).abs() < (best - s).abs() {
                    v
                } else {
                    best
                }
            });
        assert!(
            (e - s).abs() <= 1e-12 * s.max(1.0),
            "singular value {k}: {s} against {e}"
        );
    }
    let r = &lin.wa * DVector::from_column_slice(&prob.x) - &lin.wb;
    assert_eq!(ws.residuals(), r.as_slice());
    assert_clean(&report.health);
}

/// With the default damping the solve stops once the full Gauss–Newton step would gain less than the
/// tolerance; on a linear problem that prediction is exactly `‖W A (x − x*)‖²`, the excess of `χ²`.
#[test]
fn linear_default_options_stop_within_the_decrease_tolerance() {
    let lin = Linear::example();
    let expected = lin.closed_form();
    let mut prob = lin.problem(&[0.0; 3]);
    let options = LmOptions::default();
    let (report, _, _) = solve(&mut prob, &[1.0; 3], &options);
    assert_eq!(report.termination, TerminationReason::Converged);
    let x = DVector::from_column_slice(&prob.x);
    let excess = (&lin.wa * (&x - &expected)).norm_squared();
    let chi2_min = lin.chi2(&expected);
    assert!(
        (report.predicted_decrease - excess).abs() <= 1e-6 * excess + 1e-24,
        "predicted {:e}, actual excess {excess:e}",
        report.predicted_decrease
    );
    assert!(excess <= options.decrease_tol + options.relative_decrease_tol * report.cost_final);
    assert!((report.cost_final - (chi2_min + excess)).abs() < 1e-12 * chi2_min);
    assert_clean(&report.health);
}

/// With the convergence test switched off (zero tolerances), the solve ends when a step no longer
/// changes `χ²` beyond rounding, at the closed-form solution.
#[test]
fn linear_with_zero_tolerances_ends_at_rounding_level() {
    let lin = Linear::example();
    let expected = lin.closed_form();
    let mut prob = lin.problem(&[0.0; 3]);
    let options = LmOptions {
        decrease_tol: 0.0,
        relative_decrease_tol: 0.0,
        ..LmOptions::default()
    };
    let (report, _, _) = solve(&mut prob, &[1.0; 3], &options);
    assert_eq!(report.termination, TerminationReason::NoFurtherDecrease);
    assert!(report.was_successful());
    for k in 0..3 {
        assert!((prob.x[k] - expected[k]).abs() < 1e-12);
    }
    assert_clean(&report.health);
}

#[test]
fn rosenbrock_converges_from_the_classic_start() {
    let mut prob = rosenbrock();
    let (report, sub, _) = solve(&mut prob, &[1.0, 1.0], &LmOptions::default());
    assert_eq!(report.termination, TerminationReason::Converged);
    assert!((report.cost_initial - 24.2).abs() < 1e-12);
    // A zero-residual problem: at the end χ² is about the predicted decrease, below 1e-12.
    assert!(report.cost_final < 1e-12, "{:e}", report.cost_final);
    assert!((prob.x[0] - 1.0).abs() < 1e-6 && (prob.x[1] - 1.0).abs() < 1e-6);
    assert_eq!(sub.rank, 2);
    assert_clean(&report.health);
}

#[test]
fn rosenbrock_with_an_iteration_cap_stops_at_it_and_counts_it() {
    let mut prob = rosenbrock();
    let options = LmOptions {
        max_iterations: 3,
        ..LmOptions::default()
    };
    let (report, _, _) = solve(&mut prob, &[1.0, 1.0], &options);
    assert_eq!(report.termination, TerminationReason::MaxIterations);
    assert!(!report.was_successful());
    assert_eq!(report.iterations, 3);
    assert!(report.cost_final < report.cost_initial);
    let h = report.health;
    assert_eq!(h.count(Warning::IterationLimit), 1);
    assert_eq!(h.last(Warning::IterationLimit), Some(3));
    assert_eq!(h.total(), 1);
    assert_eq!(
        h.to_string(),
        "iteration limit reached: 1 time, last at iteration 3"
    );
}

/// `r_i = w_i (a_i (x + y) − b_i)`: only `x + y` is identifiable. The step is the minimum-norm one in
/// scaled units: with scales `D`, `(x, y) = s · (D₁², D₂²) / (D₁² + D₂²)` for the least-squares sum `s`.
#[test]
fn rank_deficient_problem_takes_the_scaled_minimum_norm_step() {
    let a = [1.0, 2.0, -1.0, 0.5];
    let b = [3.0, 5.0, -2.0, 2.0];
    let w = [1.0, 0.5, 2.0, 1.0];
    let num: f64 = (0..4).map(|i| w[i] * w[i] * a[i] * b[i]).sum();
    let den: f64 = (0..4).map(|i| w[i] * w[i] * a[i] * a[i]).sum();
    let s = num / den;
    for scales in [[1.0, 1.0], [1.0, 2.0], [0.0, 3.0]] {
        let mut prob = Euclid::new(
            4,
            &[0.0, 0.0],
            Box::new(move |x, out| {
                for i in 0..4 {
                    out[i] = w[i] * (a[i] * (x[0] + x[1]) - b[i]);
                }
            }),
            Box::new(move |_, out| {
                for i in 0..4 {
                    out[(i, 0)] = w[i] * a[i];
                    out[(i, 1)] = w[i] * a[i];
                }
            }),
        );
        let options = LmOptions {
            initial_damping: 0.0,
            ..LmOptions::default()
        };
        let (report, sub, _) = solve(&mut prob, &scales, &options);
        assert_eq!(
            report.termination,
            TerminationReason::Converged,
            "{scales:?}"
        );
        assert_eq!(report.rank, 1);
        assert_eq!(sub.rank, 1);
        let d2 = [scales[0] * scales[0], scales[1] * scales[1]];
        for k in 0..2 {
            let want = s * d2[k] / (d2[0] + d2[1]);
            assert!(
                (prob.x[k] - want).abs() < 1e-12,
                "{scales:?}: x[{k}] = {} against {want}",
                prob.x[k]
            );
        }
        assert_clean(&report.health);
    }
}

#[test]
fn nothing_to_solve_when_every_parameter_is_frozen_or_has_no_effect() {
    // Frozen: all scales zero.
    let lin = Linear::example();
    let mut prob = lin.problem(&[0.5, -0.5, 1.0]);
    let (report, sub, _) = solve(&mut prob, &[0.0; 3], &LmOptions::default());
    assert_eq!(
        report.termination,
        TerminationReason::NoIdentifiableParameters
    );
    assert!(!report.was_successful());
    assert_eq!(
        (report.iterations, report.evaluations, report.rank),
        (0, 1, 0)
    );
    assert_eq!(sub.rank, 0);
    assert_eq!(prob.x, vec![0.5, -0.5, 1.0]);
    assert_eq!(report.cost_final, report.cost_initial);
    assert_clean(&report.health);

    // No effect: the residuals do not depend on the parameters.
    let mut prob = Euclid::new(
        3,
        &[1.0, 2.0],
        Box::new(|_, out| out.copy_from_slice(&[1.0, -1.0, 2.0])),
        Box::new(|_, out| out.fill(0.0)),
    );
    let (report, _, _) = solve(&mut prob, &[1.0, 1.0], &LmOptions::default());
    assert_eq!(
        report.termination,
        TerminationReason::NoIdentifiableParameters
    );
    assert_eq!(report.cost_final, 6.0);
    assert_eq!(prob.x, vec![1.0, 2.0]);
    assert_clean(&report.health);
}

/// Residuals `[x − 1, 2 (y − 1), NaN]` or a Jacobian with a NaN in one row, from the start.
fn non_finite_at_start(bad_residual_row: Option<usize>, bad_jacobian_row: Option<usize>) -> Euclid {
    Euclid::new(
        3,
        &[0.0, 0.0],
        Box::new(move |x, out| {
            out[0] = x[0] - 1.0;
            out[1] = 2.0 * (x[1] - 1.0);
            out[2] = x[0] + x[1];
            if let Some(r) = bad_residual_row {
                out[r] = f64::NAN;
            }
        }),
        Box::new(move |_, out| {
            out.copy_from_slice(&[1.0, 0.0, 1.0, 0.0, 2.0, 1.0]);
            if let Some(r) = bad_jacobian_row {
                out[(r, 1)] = f64::INFINITY;
            }
        }),
    )
}

#[test]
fn non_finite_values_at_the_start_end_the_solve_and_name_the_row() {
    let mut prob = non_finite_at_start(Some(2), None);
    let (report, sub, ws) = solve(&mut prob, &[1.0, 1.0], &LmOptions::default());
    assert_eq!(report.termination, TerminationReason::NonFinite);
    assert!(!report.was_successful());
    assert_eq!(
        (report.iterations, report.evaluations, report.rank),
        (0, 1, 0)
    );
    assert_eq!(sub.rank, 0);
    assert!(report.cost_initial.is_nan());
    assert_eq!(prob.x, vec![0.0, 0.0]);
    assert!(ws.residuals()[2].is_nan());
    let h = report.health;
    assert_eq!(h.count(Warning::NonFiniteResidual), 1);
    assert_eq!(h.last(Warning::NonFiniteResidual), Some(2));
    assert_eq!(h.total(), 1);
    assert_eq!(h.to_string(), "non-finite residual: 1 time, last at row 2");

    let mut prob = non_finite_at_start(None, Some(1));
    let (report, _, _) = solve(&mut prob, &[1.0, 1.0], &LmOptions::default());
    assert_eq!(report.termination, TerminationReason::NonFinite);
    assert!(report.cost_initial.is_finite());
    assert_eq!(report.health.count(Warning::NonFiniteJacobian), 1);
    assert_eq!(report.health.last(Warning::NonFiniteJacobian), Some(1));
    assert_eq!(report.health.total(), 1);

    let mut prob = non_finite_at_start(Some(0), Some(2));
    let (report, _, _) = solve(&mut prob, &[1.0, 1.0], &LmOptions::default());
    assert_eq!(report.termination, TerminationReason::NonFinite);
    assert_eq!(report.health.last(Warning::NonFiniteResidual), Some(0));
    assert_eq!(report.health.last(Warning::NonFiniteJacobian), Some(2));
    assert_eq!(report.health.total(), 2);
}

#[test]
fn overflowing_cost_with_finite_entries_is_overflow() {
    let mut prob = Euclid::new(
        2,
        &[0.0],
        Box::new(|x, out| {
            out[0] = 1e200 * (x[0] - 1.0);
            out[1] = 1e200;
        }),
        Box::new(|_, out| {
            out[(0, 0)] = 1e200;
            out[(1, 0)] = 0.0;
        }),
    );
    let (report, _, _) = solve(&mut prob, &[1.0], &LmOptions::default());
    assert_eq!(report.termination, TerminationReason::NonFinite);
    assert_eq!(report.cost_initial, f64::INFINITY);
    assert_eq!(report.health.count(Warning::Overflow), 1);
    assert_eq!(report.health.last(Warning::Overflow), Some(0));
    assert_eq!(report.health.total(), 1);
}

/// Residuals `[½ (y − 1), ln x − ln 2]` from `(10, 0)`: the first Gauss–Newton step in `x` is
/// `−ln 5 / 0.1 = −16.1`, to a negative `x` where the logarithm is NaN. Trial steps shrink as
/// `1 / (1 + μ)` with `μ = 10⁻⁶ · 2^(k(k+1)/2)` after `k` rejections: the 6 trials at `μ ≤ 0.033` land
/// below zero, the seventh (`μ = 2.1`, `x = 4.8`) is accepted, and the solve converges to `(2, 1)`.
#[test]
fn nan_at_trial_points_is_counted_and_the_solve_recovers() {
    let mut prob = Euclid::new(
        2,
        &[10.0, 0.0],
        Box::new(|x, out| {
            out[0] = 0.5 * (x[1] - 1.0);
            out[1] = x[0].ln() - 2f64.ln();
        }),
        Box::new(|x, out| {
            out[(0, 0)] = 0.0;
            out[(0, 1)] = 0.5;
            out[(1, 0)] = 1.0 / x[0];
            out[(1, 1)] = 0.0;
        }),
    );
    // Expected magnitude 10 for x: its scaled column is 1, well above the singular-value floor.
    let (report, _, _) = solve(&mut prob, &[10.0, 1.0], &LmOptions::default());
    assert_eq!(report.termination, TerminationReason::Converged);
    assert_eq!(report.rank, 2);
    assert!(
        (prob.x[0] - 2.0).abs() < 1e-5 && (prob.x[1] - 1.0).abs() < 1e-5,
        "{:?} {report:?}",
        prob.x
    );
    let h = report.health;
    assert_eq!(h.count(Warning::NonFiniteResidual), 6, "{h}");
    assert_eq!(h.last(Warning::NonFiniteResidual), Some(1));
    assert_eq!(h.total(), 6);
    assert_eq!(h.to_string(), "non-finite residual: 6 times, last at row 1");
}

/// `r = x − 1` with a Jacobian of the wrong sign: every step goes uphill, and damping only shortens it.
#[test]
fn an_uphill_jacobian_hits_the_damping_limit() {
    let mut prob = Euclid::new(
        1,
        &[0.0],
        Box::new(|x, out| out[0] = x[0] - 1.0),
        Box::new(|_, out| out[(0, 0)] = -1.0),
    );
    let (report, _, ws) = solve(&mut prob, &[1.0], &LmOptions::default());
    assert_eq!(report.termination, TerminationReason::DampingLimit);
    assert!(!report.was_successful());
    assert_eq!(report.iterations, 1);
    assert_eq!(report.cost_final, report.cost_initial);
    // The point is unchanged and the trial point is back on it.
    assert_eq!(prob.x, vec![0.0]);
    assert_eq!(prob.trial, vec![0.0]);
    assert_eq!(ws.residuals(), &[-1.0]);
    let h = report.health;
    assert_eq!(h.count(Warning::DampingLimit), 1);
    assert_eq!(h.last(Warning::DampingLimit), Some(1));
    assert_eq!(h.total(), 1);
}

/// `r = x − 1` whose Jacobian is NaN away from the start: the first step is accepted, then the normal
/// matrix is NaN, no Cholesky factorisation exists at any damping, and the solve ends at the damping
/// limit, counting the NaN Jacobian row (not as a near-singular matrix).
#[test]
fn a_nan_jacobian_after_a_step_is_counted_and_hits_the_damping_limit() {
    let mut prob = Euclid::new(
        1,
        &[0.0],
        Box::new(|x, out| out[0] = x[0] - 1.0),
        Box::new(|x, out| out[(0, 0)] = if x[0] == 0.0 { 1.0 } else { f64::NAN }),
    );
    let (report, _, _) = solve(&mut prob, &[1.0], &LmOptions::default());
    assert_eq!(report.termination, TerminationReason::DampingLimit);
    assert_eq!(report.iterations, 2);
    assert!((prob.x[0] - 1.0).abs() < 1e-5);
    let h = report.health;
    assert_eq!(h.count(Warning::NonFiniteJacobian), 1, "{h}");
    assert_eq!(h.last(Warning::NonFiniteJacobian), Some(0));
    assert_eq!(h.count(Warning::DampingLimit), 1);
    assert_eq!(h.last(Warning::DampingLimit), Some(2));
    assert_eq!(h.total(), 2);
}

/// Three rows `w · [1, 1 ± ε]`, `w · [1, 1]`: `σ_min / σ_max ≈ ε / 3`. With `ε = 1e-6` the weak
/// combination is kept (above `rank_rtol = 1e-8`) but near-singular (below `100 · rank_rtol`); with
/// `ε = 1e-3` it is healthy; with `ε = 1e-9` it is unidentifiable (rank 1), which is not a warning.
#[test]
fn a_near_singular_normal_matrix_is_counted() {
    let run = |eps: f64| {
        let w = 1e7;
        let a = DMatrix::from_row_slice(3, 2, &[1.0, 1.0, 1.0, 1.0 + eps, 1.0, 1.0 - eps]);
        let b = DVector::from_column_slice(&[2.0, 2.0 + 3.0 * eps, 2.0 - eps]);
        let lin = Linear::new(a, b, &[w; 3]);
        let mut prob = lin.problem(&[0.0, 0.0]);
        let (report, sub, _) = solve(&mut prob, &[1.0, 1.0], &LmOptions::default());
        assert_eq!(
            report.termination,
            TerminationReason::Converged,
            "ε {eps:e}"
        );
        (report, sub)
    };
    let (report, sub) = run(1e-6);
    assert_eq!(report.rank, 2);
    let ratio = sub.singular_values[1] / sub.singular_values[0];
    assert!(ratio > 1e-8 && ratio < 1e-6, "{ratio:e}");
    assert_eq!(sub.near_singular_count(), 1);
    let h = report.health;
    assert_eq!(h.count(Warning::NearSingularNormalMatrix), 1, "{h}");
    assert_eq!(
        h.last(Warning::NearSingularNormalMatrix),
        Some(report.iterations)
    );
    assert_eq!(h.total(), 1);

    let (report, sub) = run(1e-3);
    assert_eq!(report.rank, 2);
    assert_eq!(sub.near_singular_count(), 0);
    assert_clean(&report.health);

    let (report, _) = run(1e-9);
    assert_eq!(report.rank, 1);
    assert_clean(&report.health);
}

/// Reports written before the health record existed still read (as clean), and the existing fields keep
/// their names.
#[test]
fn report_json_adds_health_and_reads_old_reports() {
    let mut prob = rosenbrock();
    let (report, _, _) = solve(&mut prob, &[1.0, 1.0], &LmOptions::default());
    let v: serde_json::Value = serde_json::to_value(&report).unwrap();
    let keys: Vec<&str> = v.as_object().unwrap().keys().map(|k| k.as_str()).collect();
    for k in [
        "termination",
        "iterations",
        "evaluations",
        "cost_initial",
        "cost_final",
        "predicted_decrease",
        "n_residuals",
        "n_params",
        "rank",
        "health",
    ] {
        assert!(keys.contains(&k), "{k} missing from {keys:?}");
    }
    assert_eq!(v["termination"], "converged");
    assert_eq!(v["health"], serde_json::json!([]));
    let mut old = v.clone();
    old.as_object_mut().unwrap().remove("health");
    let back: MinimizationReport = serde_json::from_value(old).unwrap();
    assert_eq!(back, report);

    let mut capped = rosenbrock();
    let options = LmOptions {
        max_iterations: 2,
        ..LmOptions::default()
    };
    let (report, _, _) = solve(&mut capped, &[1.0, 1.0], &options);
    let s = serde_json::to_string(&report).unwrap();
    assert!(
        s.contains(r#""health":[{"warning":"iteration_limit","count":1,"last":2}]"#),
        "{s}"
    );
    let back: MinimizationReport = serde_json::from_str(&s).unwrap();
    assert_eq!(back, report);
}
