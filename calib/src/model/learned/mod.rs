//! Learned residual models: what the physical model leaves over, as a function of the joint angles.
//!
//! After a physical calibration the tracker-frame residual `r = p_measured − p_predicted(q)` (m) may
//! still depend on the configuration (gear eccentricity, unmodelled elasticity, cable forces). Following
//! learning-based calibration (Schillreff and Ortmeier, ICINCO 2018: error parameters as polynomial
//! functions of the joint values), [`fit`] learns `r̂(q)`, a correction to add to the physical prediction:
//!
//! - `"poly1"`, `"poly2"`, `"poly3"`: ridge regression on the monomials of the standardised joint angles
//!   up to that total degree ([`polynomial`]); `"poly"` chooses the degree from 1 to 3 by
//!   cross-validation;
//! - `"kernel"`: kernel ridge regression (Gaussian-process posterior mean) with first- and second-order
//!   additive plus full RBF kernels on the standardised joint angles ([`kernel`]);
//! - `"adjoint"`: the seed paper's own formulation, each joint's error twist and zero offset as a
//!   polynomial in the joint values, identified through the product-of-exponentials chain, degree
//!   cross-validated ([`adjoint`]; fitted with [`fit_adjoint`], evaluated by [`crate::model::predict`]).
//!
//! Hyperparameters (degree, ridge `λ`, length scale) are chosen by 5-fold cross-validation over the pose
//! rows, folds drawn from the seed ([`cross_validation`]); among candidates within 0.5 % of the best
//! cross-validated error the simplest wins. The model is kept only if its cross-validated RMS is below
//! the RMS without correction; otherwise it predicts zero and says so. That is what stops a flexible model
//! from memorising noise. The reported cross-validated RMS is that of the selected candidate, so it is
//! slightly optimistic (the selection itself is not cross-validated); held-out data tell the truth.

pub mod adjoint;
pub mod cross_validation;
pub mod kernel;
pub mod polynomial;
pub mod support;

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::error::CalibError;
use cross_validation::{K_FOLDS, fold_assignment, rms_norm, select_simplest};
use kernel::KernelModel;
use polynomial::PolynomialModel;
pub use support::Support;

/// A kind of learned residual model, as written after `learned:` in a model name.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LearnedKind {
    /// Polynomial ridge regression, degree chosen by cross-validation from 1 to 3 (`poly`).
    Poly,
    /// Polynomial ridge regression of total degree 1 (`poly1`).
    Poly1,
    /// Polynomial ridge regression of total degree 2 (`poly2`).
    Poly2,
    /// Polynomial ridge regression of total degree 3 (`poly3`).
    Poly3,
    /// Kernel ridge regression (`kernel`).
    Kernel,
    /// The adjoint error model with polynomial parameters, through the chain (`adjoint`).
    Adjoint,
}

impl LearnedKind {
    /// Every kind, in the order of [`KINDS`].
    pub const ALL: [LearnedKind; 6] = [
        LearnedKind::Poly,
        LearnedKind::Poly1,
        LearnedKind::Poly2,
        LearnedKind::Poly3,
        LearnedKind::Kernel,
        LearnedKind::Adjoint,
    ];

    /// The kind's word (`poly`, `poly1`, `poly2`, `poly3`, `kernel`, `adjoint`).
    pub fn name(self) -> &'static str {
        match self {
            LearnedKind::Poly => "poly",
            LearnedKind::Poly1 => "poly1",
            LearnedKind::Poly2 => "poly2",
            LearnedKind::Poly3 => "poly3",
            LearnedKind::Kernel => "kernel",
            LearnedKind::Adjoint => "adjoint",
        }
    }

    /// The kind named `word`, if any.
    pub fn from_name(word: &str) -> Option<LearnedKind> {
        LearnedKind::ALL.into_iter().find(|k| k.name() == word)
    }

    /// Polynomial degrees it tries (empty for the kernel model).
    fn degrees(self) -> &'static [usize] {
        match self {
            LearnedKind::Poly => &[1, 2, 3],
            LearnedKind::Poly1 => &[1],
            LearnedKind::Poly2 => &[2],
            LearnedKind::Poly3 => &[3],
            LearnedKind::Kernel | LearnedKind::Adjoint => &[],
        }
    }
}

impl std::fmt::Display for LearnedKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.pad(self.name())
    }
}

/// Valid kind words: `"poly"` (polynomial, degree chosen by CV from 1..=3), `"poly1"`, `"poly2"`,
/// `"poly3"`, `"kernel"`, `"adjoint"` ([`LearnedKind::name`]).
pub const KINDS: &[&str] = &["poly", "poly1", "poly2", "poly3", "kernel", "adjoint"];

/// Fewest pose rows [`fit`] accepts: two per cross-validation fold.
pub const MIN_ROWS: usize = 2 * K_FOLDS;

/// The fitted correction behind a [`LearnedResidual`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
enum Correction {
    /// Cross-validation found no gain: the correction is zero.
    Zero,
    /// Polynomial ridge regression.
    Polynomial(PolynomialModel),
    /// Kernel ridge regression.
    Kernel(KernelModel),
    /// The adjoint error model with polynomial parameters (evaluated through the chain).
    Adjoint(adjoint::AdjointModel),
}

/// A learned correction of the tracker-frame residual as a function of the joint angles, with its
/// cross-validation statistics.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LearnedResidual {
    kind: LearnedKind,
    n_joints: usize,
    n_rows: usize,
    n_fit_rows: usize,
    selected: String,
    correction: Correction,
    cv_rms_m: f64,
    cv_rms_before_m: f64,
    n_parameters: usize,
    /// Where it has seen data ([`support`]): applied inside, faded at the edge, off outside. Absent in
    /// files written before supports existed: such a correction applies everywhere.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    support: Option<Support>,
}

fn bad(field: String, value: String, problem: &str) -> CalibError {
    CalibError::BadValue {
        context: "learned residual fit".into(),
        field,
        value,
        problem: problem.into(),
    }
}

/// Fit the tracker-frame residual r = measured − physical prediction (m) as a function of the joint
/// angles q (rad). `q` is row-major (rows × n_joints). Hyperparameters (degree, ridge λ, kernel length
/// scale) by k-fold CV (k = 5, folds drawn from `seed`, by pose rows).
///
/// Errors: `n_joints == 0`, lengths that do not fit together, fewer than [`MIN_ROWS`]
/// rows, or a non-finite value (named by row and joint or component).
pub fn fit(
    kind: LearnedKind,
    q: &[f64],
    n_joints: usize,
    residual_m: &[Vector3<f64>],
    seed: u64,
) -> Result<LearnedResidual, CalibError> {
    if n_joints == 0 {
        return Err(bad(
            "n_joints".into(),
            "0".into(),
            "at least one joint is needed",
        ));
    }
    if q.len() != residual_m.len() * n_joints {
        return Err(bad(
            "q".into(),
            format!("{} values", q.len()),
            &format!(
                "expected {} rows × {} joints = {} values",
                residual_m.len(),
                n_joints,
                residual_m.len() * n_joints
            ),
        ));
    }
    let n = residual_m.len();
    if n < MIN_ROWS {
        return Err(bad(
            "rows".into(),
            n.to_string(),
            &format!(
                "at least {MIN_ROWS} pose rows are needed for {K_FOLDS}-fold cross-validation"
            ),
        ));
    }
    for (i, v) in q.iter().enumerate() {
        if !v.is_finite() {
            return Err(bad(
                format!("q (row {}, joint {})", i / n_joints, i % n_joints),
                v.to_string(),
                "not a finite number",
            ));
        }
    }
    for (row, r) in residual_m.iter().enumerate() {
        for (c, v) in r.iter().enumerate() {
            if !v.is_finite() {
                return Err(bad(
                    format!("residual (row {row}, {})", ["x", "y", "z"][c]),
                    v.to_string(),
                    "not a finite number",
                ));
            }
        }
    }
    let mut fitted = match kind {
        LearnedKind::Kernel => fit_kernel(q, n_joints, residual_m, seed)?,
        LearnedKind::Adjoint => {
            return Err(CalibError::Misuse(
                "learned:adjoint is identified through the chain: use learned::fit_adjoint".into(),
            ));
        }
        _ => fit_polynomial(kind, q, n_joints, residual_m, seed),
    };
    fitted.support = Support::of(q, n_joints, seed);
    Ok(fitted)
}

/// Fits `learned:adjoint` ([`adjoint`]) to the training rows `obs` of the physical model `params` of
/// `model` (folds from `seed`): the correction, and the parameters with the registrations refitted
/// with it. Errors as [`fit`] for too few rows.
pub fn fit_adjoint(
    model: &sim::Model,
    params: &crate::model::params::KinematicParams,
    obs: &crate::model::observations::Observations,
    seed: u64,
) -> Result<(LearnedResidual, crate::model::params::KinematicParams), CalibError> {
    let n = obs.len();
    if n < MIN_ROWS {
        return Err(bad(
            "rows".into(),
            n.to_string(),
            &format!(
                "at least {MIN_ROWS} pose rows are needed for {K_FOLDS}-fold cross-validation"
            ),
        ));
    }
    let f = adjoint::fit(model, params, obs, seed)?;
    let p = f.model.n_coefficients();
    let selected = format!(
        "adjoint error model, each joint's error twist and zero offset a polynomial of degree {} in q \
         ({} coefficients, ridge λ = {:.0e})",
        f.model.degree, p, f.model.lambda
    );
    let residual = LearnedResidual {
        kind: LearnedKind::Adjoint,
        n_joints: obs.n_joints,
        n_rows: n,
        n_fit_rows: n,
        selected,
        correction: if f.active {
            Correction::Adjoint(f.model)
        } else {
            Correction::Zero
        },
        cv_rms_m: f.cv_rms_m,
        cv_rms_before_m: f.cv_rms_before_m,
        n_parameters: if f.active { p } else { 0 },
        support: Support::of(&obs.q, obs.n_joints, seed),
    };
    Ok((residual, f.params))
}

fn fit_polynomial(
    kind: LearnedKind,
    q: &[f64],
    n_joints: usize,
    residual_m: &[Vector3<f64>],
    seed: u64,
) -> LearnedResidual {
    let n = residual_m.len();
    let degrees = kind.degrees();
    let fold_of = fold_assignment(n, K_FOLDS, seed);
    // Candidates from the simplest: low degree first, strong ridge first.
    let mut candidates = Vec::new();
    let mut sse = Vec::new();
    for &degree in degrees {
        let per_lambda = polynomial::cross_validate(q, n_joints, residual_m, &fold_of, degree);
        for l in (0..polynomial::LAMBDAS.len()).rev() {
            candidates.push((degree, polynomial::LAMBDAS[l]));
            sse.push(per_lambda[l]);
        }
    }
    let best = select_simplest(&sse, n);
    let (degree, lambda) = candidates[best];
    let cv_rms_m = (sse[best] / n as f64).sqrt();
    let cv_rms_before_m = rms_norm(residual_m);
    let selected = format!("polynomial degree {degree} in q (ridge λ = {lambda:.0e})");
    let (correction, n_parameters) = if cv_rms_m < cv_rms_before_m {
        let model = polynomial::fit(q, n_joints, residual_m, degree, lambda);
        let p = model.n_coefficients();
        (Correction::Polynomial(model), p)
    } else {
        (Correction::Zero, 0)
    };
    LearnedResidual {
        kind,
        n_joints,
        n_rows: n,
        n_fit_rows: n,
        selected,
        correction,
        cv_rms_m,
        cv_rms_before_m,
        n_parameters,
        support: None,
    }
}

fn fit_kernel(
    q: &[f64],
    n_joints: usize,
    residual_m: &[Vector3<f64>],
    seed: u64,
) -> Result<LearnedResidual, CalibError> {
    let n = residual_m.len();
    let rows = kernel::subsample(n, seed);
    let q_fit: Vec<f64> = rows
        .iter()
        .flat_map(|&r| q[r * n_joints..(r + 1) * n_joints].iter().copied())
        .collect();
    let r_fit: Vec<Vector3<f64>> = rows.iter().map(|&r| residual_m[r]).collect();
    let m = rows.len();
    let fold_of = fold_assignment(m, K_FOLDS, seed);
    let grid = kernel::cross_validate(&q_fit, n_joints, &r_fit, &fold_of);
    // Candidates from the simplest: long length scale first, strong regularisation first.
    let mut candidates = Vec::new();
    let mut sse = Vec::new();
    for l in (0..kernel::LENGTH_SCALES.len()).rev() {
        for k in (0..kernel::LAMBDAS.len()).rev() {
            candidates.push((kernel::LENGTH_SCALES[l], kernel::LAMBDAS[k]));
            sse.push(grid[l][k]);
        }
    }
    let best = select_simplest(&sse, m);
    let (ell, lambda) = candidates[best];
    let cv_rms_m = (sse[best] / m as f64).sqrt();
    let cv_rms_before_m = rms_norm(&r_fit);
    let subsampled = if m < n {
        format!(", fitted on a seeded subsample of {m} of {n} poses")
    } else {
        String::new()
    };
    let selected = format!(
        "kernel ridge regression on q (additive (orders 1, 2) + full RBF kernel, length scale {ell} std, λ = {lambda:.0e}){subsampled}"
    );
    let (correction, n_parameters) = if cv_rms_m < cv_rms_before_m {
        let model = kernel::fit(&q_fit, n_joints, &r_fit, ell, lambda).ok_or_else(|| {
            CalibError::Misuse(format!(
                "kernel matrix not positive definite (length scale {ell}, λ = {lambda})"
            ))
        })?;
        let p = (3.0 * model.effective_dof).round() as usize;
        (Correction::Kernel(model), p)
    } else {
        (Correction::Zero, 0)
    };
    Ok(LearnedResidual {
        kind: LearnedKind::Kernel,
        n_joints,
        n_rows: n,
        n_fit_rows: m,
        selected,
        correction,
        cv_rms_m,
        cv_rms_before_m,
        n_parameters,
        support: None,
    })
}

impl LearnedResidual {
    /// Correction to add to the physical prediction (m, tracker frame) at joint angles `q` (rad, one per
    /// joint). A `q` of the wrong length gives a NaN vector (never a panic), and so does an adjoint
    /// model, which is no additive correction: [`crate::model::predict::Prediction`] evaluates it through
    /// the chain ([`LearnedResidual::adjoint`]).
    /// The correction is weighted by [`LearnedResidual::weight`]: whole inside its support, faded at
    /// the edge, zero outside.
    pub fn predict(&self, q: &[f64]) -> Vector3<f64> {
        if q.len() != self.n_joints {
            return Vector3::repeat(f64::NAN);
        }
        let unweighted = match &self.correction {
            Correction::Zero => return Vector3::zeros(),
            Correction::Polynomial(p) => p.predict(q),
            Correction::Kernel(k) => k.predict(q),
            Correction::Adjoint(_) => return Vector3::repeat(f64::NAN),
        };
        match self.weight(q) {
            0.0 => Vector3::zeros(),
            w => w * unweighted,
        }
    }

    /// Weight of the correction at `q` (rad): 1 inside its support, 0 outside, between at the edge
    /// ([`Support::weight`]); 1 everywhere for a correction without a support (older files).
    pub fn weight(&self, q: &[f64]) -> f64 {
        self.support.as_ref().map_or(1.0, |s| s.weight(q))
    }

    /// Whether `q` lies outside the correction's support: the correction is not applied whole there
    /// (weight below 1). Never for a zero correction, which has nothing to apply.
    pub fn outside_support(&self, q: &[f64]) -> bool {
        self.is_active() && self.weight(q) < 1.0
    }

    /// The support, when the correction has one.
    pub fn support(&self) -> Option<&Support> {
        self.support.as_ref()
    }

    /// `∂r̂/∂qⱼ` (m/rad, tracker frame) at `q` into `out` (one per joint) of the correction as
    /// [`LearnedResidual::predict`] applies it, weighted by its support: `w ∂r/∂qⱼ + r ∂w/∂qⱼ`, in
    /// closed form for the polynomial and kernel corrections (zero for none); `false` for an adjoint
    /// model, whose effect goes through the chain ([`crate::model::compensate`] differentiates its
    /// chain, not its configuration-dependent parameters).
    pub fn jacobian(&self, q: &[f64], out: &mut [nalgebra::Vector3<f64>]) -> bool {
        match &self.correction {
            Correction::Zero => {
                out.fill(Vector3::zeros());
                return true;
            }
            Correction::Polynomial(p) => p.jacobian(q, out),
            Correction::Kernel(k) => k.jacobian(q, out),
            Correction::Adjoint(_) => {
                out.fill(Vector3::zeros());
                return false;
            }
        }
        let Some(support) = &self.support else {
            return true;
        };
        let mut dw = vec![0.0; q.len()];
        let w = support.weight_and_gradient(q, &mut dw);
        if w == 1.0 {
            return true;
        }
        let r = match &self.correction {
            Correction::Polynomial(p) => p.predict(q),
            Correction::Kernel(k) => k.predict(q),
            _ => Vector3::zeros(),
        };
        for (o, g) in out.iter_mut().zip(&dw) {
            *o = *o * w + r * *g;
        }
        true
    }

    /// The adjoint model, for a kept `learned:adjoint` correction.
    pub fn adjoint(&self) -> Option<&adjoint::AdjointModel> {
        match &self.correction {
            Correction::Adjoint(a) => Some(a),
            _ => None,
        }
    }

    /// The kind it was fitted as.
    pub fn kind(&self) -> LearnedKind {
        self.kind
    }

    /// Number of joints the model expects in `q`.
    pub fn n_joints(&self) -> usize {
        self.n_joints
    }

    /// Whether cross-validation found a gain (otherwise [`Self::predict`] returns zero).
    pub fn is_active(&self) -> bool {
        !matches!(self.correction, Correction::Zero)
    }

    /// Cross-validated RMS of the 3-D residual norm after the correction (m), for the selected
    /// hyperparameters.
    pub fn cv_rms_m(&self) -> f64 {
        self.cv_rms_m
    }

    /// Same folds, RMS of the 3-D residual norm without correction (m).
    pub fn cv_rms_before_m(&self) -> f64 {
        self.cv_rms_before_m
    }

    /// Effective number of parameters over the three components: for a polynomial 3 × (features + 1);
    /// for a kernel model 3 × (trace of the hat matrix + 1), rounded; 0 when the correction is zero.
    pub fn n_parameters(&self) -> usize {
        self.n_parameters
    }

    /// One line: the model, its hyperparameters and size, and the cross-validated RMS with and without.
    pub fn describe(&self) -> String {
        let mm = |v: f64| v * 1e3;
        match self.correction {
            Correction::Zero => format!(
                "{}: no gain found, correction is zero (best candidate {}: CV RMS {:.4} mm vs {:.4} mm without, {} poses)",
                self.kind,
                self.selected,
                mm(self.cv_rms_m),
                mm(self.cv_rms_before_m),
                self.n_rows
            ),
            Correction::Polynomial(_) => format!(
                "{}, {} coefficients; CV RMS {:.4} mm vs {:.4} mm without ({} poses)",
                self.selected,
                self.n_parameters,
                mm(self.cv_rms_m),
                mm(self.cv_rms_before_m),
                self.n_rows
            ),
            Correction::Kernel(_) => format!(
                "{}, {} effective parameters; CV RMS {:.4} mm vs {:.4} mm without ({} poses)",
                self.selected,
                self.n_parameters,
                mm(self.cv_rms_m),
                mm(self.cv_rms_before_m),
                self.n_fit_rows
            ),
            Correction::Adjoint(_) => format!(
                "{}; CV RMS {:.4} mm vs {:.4} mm without ({} poses)",
                self.selected,
                mm(self.cv_rms_m),
                mm(self.cv_rms_before_m),
                self.n_rows
            ),
        }
    }
}
