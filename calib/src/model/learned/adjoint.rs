//! `learned:adjoint`: the adjoint error model with configuration-dependent parameters (Schillreff and
//! Ortmeier, "Learning-based kinematic calibration using adjoint error model", ICINCO 2018): each
//! joint's error twist and zero offset become polynomials in the joint values, identified through the
//! product-of-exponentials chain.
//!
//! After the physical calibration (error twists `Gᵢ = exp[ξᵢ]`, zero offsets `δqᵢ`, extensions, tracker
//! registrations), joint `i`'s screw and angle at configuration `q` are
//!
//! ```text
//! Sᵢ'(q) = Ad(exp[ζᵢ(q)] Gᵢ) Sᵢ,   θᵢ = qᵢ + δqᵢ + δᵢ(q) (+ extension terms),
//! ζᵢ(q) = Σₖ cᵢₖ φₖ(q) ∈ R⁶ (rad, m),   δᵢ(q) = Σₖ dᵢₖ φₖ(q) (rad, m)
//! ```
//!
//! with features `φ₀ = 1` (a correction of the joint's constant error twist and zero offset) and `φₖ`
//! the monomials of the standardised joint values `zⱼ = (qⱼ − mean)/std` of total degree 1 to `d`,
//! each centred and scaled over the fit rows (as in [`super::polynomial`]). The coefficients are
//! identified jointly with every campaign's tracker registration and the target (refitted, since the
//! physical fit's compromise for a configuration-dependent error biased them too): with `u` the
//! parameters scaled by [`COEFFICIENT_SCALE`], they minimise `Σ_rows |p(q) − p_measured|² + Σ μ u²`
//! (positions, tracker frame of each row's campaign, m), `μ = λ ·` the normal matrix's mean diagonal
//! on the coefficients and [`FLOOR_RIDGE`] times it on the registration.
//!
//! The Jacobian is analytic: a change `Δcᵢₖ` turns `exp[ζᵢ]` into `exp[J_l(ζᵢ) Δcᵢₖ φₖ] exp[ζᵢ]`
//! ([`crate::lie3::se3_left_jacobian`]), which moves the target by the chain's error-twist Jacobian
//! `∂p/∂ξᵢ` ([`crate::model::chain::Chain::position_jacobian`]) times `J_l(ζᵢ) φₖ`; a change of `dᵢₖ` moves it
//! by the zero-offset column times `φₖ`; both times `1 + γ` with a growth term. (Checked against central
//! differences in `tests/learned.rs`.)
//!
//! Degree and `λ` are chosen by 5-fold cross-validation over the rows on the model linearised at the
//! physical solution (`u = 0`), where a fold's error is the exact quadratic form
//! `s_f + 2uᵀg_f + uᵀG_f u` of the fold's normal equations, so no Jacobian is stored; the selected model
//! is then solved on every row and refined by Gauss–Newton steps through the exact chain. A degree is
//! tried only while there are at least [`EQUATIONS_PER_COEFFICIENT`] position equations per coefficient
//! (degree 1 always). Orientation measurements are not used by the fit (its predictions of orientation
//! follow from the chain). As with the other learned models, the correction is kept only when its
//! cross-validated RMS beats the physical model's.

use super::cross_validation::{K_FOLDS, fold_assignment, select_simplest};
use super::polynomial::{joint_standardisation, monomials};
use crate::lie3::se3_left_jacobian;
use crate::model::chain::Chain;
use crate::model::observations::Observations;
use crate::model::params::{KinematicParams, ParamLayout};
pub use crate::model::physical_row::AdjointScratch;
use crate::model::physical_row::{PredictScratch, physical_row};
use nalgebra::{DMatrix, DVector, Vector3, Vector6};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sim::Model;
use sim::lie::exp_twist;

/// Expected size of a coefficient (rad or m per standardised feature unit): the unit of `u`.
pub const COEFFICIENT_SCALE: f64 = 1e-4;
/// Ridge strengths tried, relative to the mean diagonal of the normal matrix per row.
pub const LAMBDAS: [f64; 5] = [1e-6, 1e-4, 1e-3, 1e-2, 1e-1];
/// Degrees tried.
pub const DEGREES: [usize; 2] = [1, 2];
/// A degree is tried only with at least this many position equations per coefficient (degree 1
/// always is).
pub const EQUATIONS_PER_COEFFICIENT: usize = 5;
/// Most coefficients of a degree tried.
pub const MAX_COEFFICIENTS: usize = 2000;
/// Gauss–Newton refinements through the exact chain after the linearised solve (the model is
/// nearly linear in its coefficients: one settles it; each costs a pass over the rows).
pub const REFINEMENTS: usize = 1;
/// Measurement rows per block of the normal-equation products.
const BLOCK_ROWS: usize = 128;

/// Components per joint: the error twist `[ω; v]` (6) and the zero offset.
const PER_JOINT: usize = 7;

/// A fitted adjoint model: the coefficients of every joint's twist and zero-offset polynomials.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AdjointModel {
    /// Total degree of the monomials.
    pub degree: usize,
    /// Ridge strength chosen (relative, see [`LAMBDAS`]).
    pub lambda: f64,
    /// Joints.
    pub n_joints: usize,
    /// Mean of each joint value over the fit rows (rad or m).
    pub q_mean: Vec<f64>,
    /// Standard deviation of each joint value over the fit rows (1 for a joint that did not move).
    pub q_scale: Vec<f64>,
    /// Monomials as lists of joint indices (feature `k + 1` is monomial `k`; feature 0 is the
    /// constant 1).
    pub monomials: Vec<Vec<usize>>,
    /// Mean of each monomial over the fit rows.
    pub feature_mean: Vec<f64>,
    /// Standard deviation of each monomial over the fit rows (1 if constant).
    pub feature_scale: Vec<f64>,
    /// Coefficients (rad or m per standardised feature unit), index
    /// `(joint · 7 + component) · features + feature`, components `ω_x, ω_y, ω_z, v_x, v_y, v_z, δq`.
    pub coefficients: Vec<f64>,
}

impl AdjointModel {
    /// Number of features: the constant and the monomials.
    pub fn n_features(&self) -> usize {
        1 + self.monomials.len()
    }

    /// Number of coefficients.
    pub fn n_coefficients(&self) -> usize {
        self.coefficients.len()
    }

    /// The features `φ(q)` into `out` (length [`AdjointModel::n_features`]): 1, then the standardised
    /// monomials.
    pub fn features(&self, q: &[f64], out: &mut [f64]) {
        out[0] = 1.0;
        for (k, m) in self.monomials.iter().enumerate() {
            let raw: f64 = m
                .iter()
                .map(|&j| (q[j] - self.q_mean[j]) / self.q_scale[j])
                .product();
            out[k + 1] = (raw - self.feature_mean[k]) / self.feature_scale[k];
        }
    }

    /// `params` with joint `i`'s error motion `exp[ζᵢ(q)] Gᵢ` and zero offset `δqᵢ + δᵢ(q)` for
    /// features `phi`, into `out` (a copy of `params` to overwrite; only the joints change).
    pub fn apply(&self, params: &KinematicParams, phi: &[f64], out: &mut KinematicParams) {
        for i in 0..self.n_joints {
            let (zeta, delta) = self.deviation(phi, i);
            out.joint_error[i] = exp_twist(&zeta) * params.joint_error[i];
            out.zero_offset[i] = params.zero_offset[i] + delta;
        }
    }

    /// `ζᵢ(q)` (rad, m) and `δᵢ(q)` of joint `i` for features `phi`.
    fn deviation(&self, phi: &[f64], i: usize) -> (Vector6<f64>, f64) {
        let k = phi.len();
        let base = i * PER_JOINT * k;
        let dot = |c: usize| -> f64 {
            self.coefficients[base + c * k..base + (c + 1) * k]
                .iter()
                .zip(phi)
                .map(|(a, b)| a * b)
                .sum()
        };
        (Vector6::from_fn(|c, _| dot(c)), dot(6))
    }
}

impl AdjointModel {
    /// Prepares `s` for the configuration `q` (controller values, rad or m): the features, the
    /// parameters of `params` with the row's error twists and zero offsets, the chain at them. The
    /// polynomial changes are scaled by `weight` (1 inside the correction's support, 0 outside:
    /// [`crate::model::learned::Support`]).
    pub fn prepare(
        &self,
        s: &mut AdjointScratch,
        params: &KinematicParams,
        q: &[f64],
        weight: f64,
    ) {
        self.features(q, &mut s.phi);
        if weight != 1.0 {
            s.phi.iter_mut().for_each(|v| *v *= weight);
        }
        self.apply(params, &s.phi, &mut s.params);
        s.chain.update_params(&s.params);
    }
}

/// The fit rows and the point they are linearised at: the physical model with its registrations.
struct Rows<'a> {
    model: &'a Model,
    obs: &'a Observations,
    params: KinematicParams,
    layout: ParamLayout,
    campaign: Vec<usize>,
    n_joints: usize,
    /// Layout indices of the registration parameters refitted with the adjoint model: every
    /// campaign's base twist, the target positions.
    registration: Vec<usize>,
}

/// Per-thread workspace of [`Rows::eval`].
struct RowEval {
    predict: PredictScratch,
    chain: Chain,
    params: KinematicParams,
    block: Vec<f64>,
    phi: Vec<f64>,
}

impl Rows<'_> {
    fn scratch(&self, n_features: usize) -> RowEval {
        RowEval {
            predict: PredictScratch::new(self.n_joints),
            chain: Chain::new(self.model, &self.params),
            params: self.params.clone(),
            block: vec![0.0; 3 * self.layout.len()],
            phi: vec![0.0; n_features],
        }
    }

    /// Number of parameters: the coefficients of `m` and the registration.
    fn n_params(&self, m: &AdjointModel) -> usize {
        m.n_coefficients() + self.registration.len()
    }

    /// Residual `p − p_measured` (m) of row `r` for the model `m` at the current registration, and
    /// its Jacobian with respect to the scaled parameters `u` (3 × [`Rows::n_params`], row-major
    /// into `jac`).
    fn eval(&self, m: &AdjointModel, r: usize, ws: &mut RowEval, jac: &mut [f64]) -> Vector3<f64> {
        let q = self.obs.q_row(r);
        let k = m.n_features();
        m.features(q, &mut ws.phi);
        m.apply(&self.params, &ws.phi, &mut ws.params);
        ws.chain.update_params(&ws.params);
        let campaign = self.campaign.get(r).copied().unwrap_or(0);
        let pred = physical_row(
            &ws.chain,
            &ws.params,
            &self.obs.ext,
            r,
            q,
            campaign,
            &mut ws.predict,
        );
        let np = self.layout.len();
        ws.chain
            .position_jacobian_of(&ws.predict.chain, &self.layout, true, &mut ws.block);
        let grow = 1.0 + pred.growth;
        let p_cols = jac.len() / 3;
        for i in 0..self.n_joints {
            let (zeta, _) = m.deviation(&ws.phi, i);
            let jl = se3_left_jacobian(&zeta);
            let kt = self.layout.joint_twist(i);
            let kz = self.layout.zero_offset(i);
            for row in 0..3 {
                // ∂p/∂ξᵢ J_l(ζᵢ): a 6-vector per axis.
                let jx = &ws.block[row * np + kt..row * np + kt + 6];
                let mut d = [0.0; 6];
                for (c, dc) in d.iter_mut().enumerate() {
                    *dc = (0..6).map(|a| jx[a] * jl[(a, c)]).sum::<f64>() * grow;
                }
                let dz = ws.block[row * np + kz] * grow;
                let out = &mut jac[row * p_cols..(row + 1) * p_cols];
                let base = i * PER_JOINT * k;
                for (c, dc) in d.iter().enumerate() {
                    for (f, &phi) in ws.phi.iter().enumerate() {
                        out[base + c * k + f] = dc * phi * COEFFICIENT_SCALE;
                    }
                }
                for (f, &phi) in ws.phi.iter().enumerate() {
                    out[base + 6 * k + f] = dz * phi * COEFFICIENT_SCALE;
                }
            }
        }
        // The registration: a base twist moves the (grown) prediction rigidly, [−[p], I]; the
        // target's columns grow with the arm.
        let p = pred.p_tracker;
        let kb = self.layout.campaign_base(campaign);
        let first = m.n_coefficients();
        for row in 0..3 {
            let out = &mut jac[row * p_cols..(row + 1) * p_cols];
            for (j, &col) in self.registration.iter().enumerate() {
                let v = if (kb..kb + 3).contains(&col) {
                    let e = Vector3::from_fn(|a, _| if a == col - kb { 1.0 } else { 0.0 });
                    e.cross(&p)[row]
                } else if (kb + 3..kb + 6).contains(&col) {
                    if row == col - kb - 3 { 1.0 } else { 0.0 }
                } else if col >= self.layout.base() && col < self.layout.kinematic_len() {
                    // Another campaign's base: zero in position_jacobian_of; a target: times 1 + γ.
                    ws.block[row * np + col] * grow
                } else {
                    0.0
                };
                out[first + j] = v * COEFFICIENT_SCALE;
            }
        }
        pred.p_tracker - self.obs.position[r]
    }
}

/// Normal equations of a set of rows: `G = AᵀA`, `g = Aᵀe`, `s = eᵀe` (A: Jacobian in `u`, e: residual).
#[derive(Clone, Debug)]
struct Normal {
    gram: DMatrix<f64>,
    grad: DVector<f64>,
    sse: f64,
    rows: usize,
}

impl Normal {
    fn zeros(p: usize) -> Self {
        Normal {
            gram: DMatrix::zeros(p, p),
            grad: DVector::zeros(p),
            sse: 0.0,
            rows: 0,
        }
    }
}

/// Normal equations per fold (`fold_of[r]`, `k` folds; all rows in fold 0 with `k = 1`) at the
/// coefficients of `m`, accumulated by blocks of rows in parallel.
fn normal_equations(rows: &Rows<'_>, m: &AdjointModel, fold_of: &[usize], k: usize) -> Vec<Normal> {
    let p = rows.n_params(m);
    let n = rows.obs.len();
    let blocks: Vec<Vec<Normal>> = (0..n.div_ceil(BLOCK_ROWS))
        .into_par_iter()
        .map(|b| {
            let range = b * BLOCK_ROWS..((b + 1) * BLOCK_ROWS).min(n);
            let mut ws = rows.scratch(m.n_features());
            let mut out: Vec<Normal> = (0..k).map(|_| Normal::zeros(p)).collect();
            let mut jac = vec![0.0; 3 * p];
            for (f, normal) in out.iter_mut().enumerate() {
                let members: Vec<usize> = range.clone().filter(|&r| fold_of[r] == f).collect();
                if members.is_empty() {
                    continue;
                }
                let mut a = DMatrix::zeros(3 * members.len(), p);
                let mut e = DVector::zeros(3 * members.len());
                for (j, &r) in members.iter().enumerate() {
                    let res = rows.eval(m, r, &mut ws, &mut jac);
                    for row in 0..3 {
                        for (c, v) in jac[row * p..(row + 1) * p].iter().enumerate() {
                            a[(3 * j + row, c)] = *v;
                        }
                        e[3 * j + row] = res[row];
                    }
                }
                normal.gram += a.transpose() * &a;
                normal.grad += a.tr_mul(&e);
                normal.sse += e.norm_squared();
                normal.rows += members.len();
            }
            out
        })
        .collect();
    let mut total: Vec<Normal> = (0..k).map(|_| Normal::zeros(p)).collect();
    for part in blocks {
        for (t, x) in total.iter_mut().zip(part) {
            t.gram += x.gram;
            t.grad += x.grad;
            t.sse += x.sse;
            t.rows += x.rows;
        }
    }
    total
}

/// Solves `(G + diag(μ)) u = −g` by Cholesky; `None` when not positive definite.
fn ridge_solve(gram: &DMatrix<f64>, grad: &DVector<f64>, mu: &[f64]) -> Option<DVector<f64>> {
    let mut a = gram.clone();
    for (i, m) in mu.iter().enumerate() {
        a[(i, i)] += m;
    }
    if !crate::linalg::cholesky_in_place(&mut a) {
        return None;
    }
    let b = DMatrix::from_column_slice(grad.len(), 1, grad.as_slice());
    let x = crate::linalg::cholesky_solve(&a, &b);
    Some(-DVector::from_column_slice(x.as_slice()))
}

/// Relative ridge on the registration: enough to make its redundancy with a common error twist of
/// all axes harmless, too little to bias anything identifiable.
pub const FLOOR_RIDGE: f64 = 1e-9;

/// The ridge per scaled parameter: `λ` on every coefficient (the constant terms included: with a
/// near-zero ridge there, measured on the real UR5, the constants' near-redundant combinations made the
/// linearised cross-validation optimistic, 98.9 µm against 109.7 µm held out, where `λ` on them gives
/// 98.9 µm against 99.2 µm), [`FLOOR_RIDGE`] on the registration; both times `scale` (the normal
/// matrix's mean diagonal, times the rows).
fn ridge(m: &AdjointModel, registration: usize, lambda: f64, scale: f64) -> Vec<f64> {
    let mut mu = vec![lambda * scale; m.n_coefficients()];
    mu.extend(std::iter::repeat_n(FLOOR_RIDGE * scale, registration));
    mu
}

/// A fitted adjoint correction and its cross-validation.
pub struct AdjointFit {
    /// The model (coefficients zero when cross-validation found no gain).
    pub model: AdjointModel,
    /// The physical parameters with the registrations refitted with the adjoint model (unchanged
    /// when it is not kept).
    pub params: KinematicParams,
    /// Whether it is kept.
    pub active: bool,
    /// Cross-validated RMS of the 3-D position error with the selected model (m).
    pub cv_rms_m: f64,
    /// The same without a correction (m).
    pub cv_rms_before_m: f64,
    /// Rows fitted.
    pub n_rows: usize,
}

/// An adjoint model of `degree` with zero coefficients and the standardisation of `obs`' rows.
pub fn empty_model(obs: &Observations, degree: usize) -> AdjointModel {
    let n = obs.n_joints;
    let (q_mean, q_scale) = joint_standardisation(&obs.q, n);
    let monos = monomials(n, degree);
    let rows = obs.len();
    let k = monos.len();
    let mut mean = vec![0.0; k];
    let mut sq = vec![0.0; k];
    for r in 0..rows {
        let q = obs.q_row(r);
        for (f, m) in monos.iter().enumerate() {
            let v: f64 = m.iter().map(|&j| (q[j] - q_mean[j]) / q_scale[j]).product();
            mean[f] += v;
            sq[f] += v * v;
        }
    }
    let scale: Vec<f64> = (0..k)
        .map(|f| {
            mean[f] /= rows as f64;
            let var = sq[f] / rows as f64 - mean[f] * mean[f];
            if var > 1e-24 { var.sqrt() } else { 1.0 }
        })
        .collect();
    AdjointModel {
        degree,
        lambda: 0.0,
        n_joints: n,
        q_mean,
        q_scale,
        monomials: monos,
        feature_mean: mean,
        feature_scale: scale,
        coefficients: vec![0.0; n * PER_JOINT * (k + 1)],
    }
}

/// The rows of `obs` for the physical model `params` of `model`.
fn rows<'a>(
    model: &'a Model,
    params: &KinematicParams,
    obs: &'a Observations,
) -> crate::error::Result<Rows<'a>> {
    let layout = ParamLayout::for_params(model, params, obs.ext.params.clone());
    let campaign =
        obs.campaign_indices(params)
            .map_err(|(r, id)| crate::error::CalibError::BadValue {
                context: "learned:adjoint".into(),
                field: "campaign".into(),
                value: id.to_string(),
                problem: format!("row {r}: not a campaign of the model"),
            })?;
    let mut registration = Vec::new();
    for c in 0..layout.n_campaigns() {
        let b = layout.campaign_base(c);
        registration.extend(b..b + 6);
        if c == 0 || layout.campaign_targets {
            let t = layout.campaign_target_position(c);
            registration.extend(t..t + 3);
        }
    }
    Ok(Rows {
        model,
        obs,
        params: params.clone(),
        layout,
        campaign,
        n_joints: model.nq(),
        registration,
    })
}

/// Fits the adjoint model to the training rows `obs` (with its extension regressors) of the physical
/// model `params` of `model`; folds from `seed`.
pub fn fit(
    model: &Model,
    params: &KinematicParams,
    obs: &Observations,
    seed: u64,
) -> crate::error::Result<AdjointFit> {
    let n = obs.len();
    let mut rows = rows(model, params, obs)?;
    let n_reg = rows.registration.len();
    let fold_of = fold_assignment(n, K_FOLDS, seed);
    // Candidates from the simplest: low degree first, strong ridge first.
    let mut candidates: Vec<(usize, f64)> = Vec::new();
    let mut sse = Vec::new();
    let mut before = 0.0;
    // The normal equations over every row at the physical model, per degree tried: the first step of
    // the final solve.
    let mut at_zero: Vec<Normal> = Vec::new();
    for &degree in &DEGREES {
        let m = empty_model(obs, degree);
        let p = rows.n_params(&m);
        if degree > 1 && (p * EQUATIONS_PER_COEFFICIENT > 3 * n || p > MAX_COEFFICIENTS) {
            break;
        }
        let folds = normal_equations(&rows, &m, &fold_of, K_FOLDS);
        let mut all = Normal::zeros(p);
        for f in &folds {
            all.gram += &f.gram;
            all.grad += &f.grad;
            all.sse += f.sse;
            all.rows += f.rows;
        }
        before = all.sse;
        at_zero.push(all.clone());
        let scale = all.gram.trace() / (p as f64 * n as f64);
        for &lambda in LAMBDAS.iter().rev() {
            let mut total = 0.0;
            for f in &folds {
                let gram = &all.gram - &f.gram;
                let grad = &all.grad - &f.grad;
                let mu = ridge(&m, n_reg, lambda, scale * (all.rows - f.rows) as f64);
                let total_f = match ridge_solve(&gram, &grad, &mu) {
                    Some(u) => f.sse + 2.0 * u.dot(&f.grad) + u.dot(&(&f.gram * &u)),
                    None => f64::INFINITY,
                };
                total += total_f.max(0.0);
            }
            candidates.push((degree, lambda));
            sse.push(total);
        }
    }
    let best = select_simplest(&sse, n);
    let (degree, lambda) = candidates[best];
    let cv_rms_m = (sse[best] / n as f64).sqrt();
    let cv_rms_before_m = (before / n as f64).sqrt();
    let mut m = empty_model(obs, degree);
    m.lambda = lambda;
    let active = cv_rms_m < cv_rms_before_m;
    if active {
        let nc = m.n_coefficients();
        let all_fold = vec![0; n];
        let mut coef = DVector::zeros(nc);
        let mut mu = Vec::new();
        let mut objective = f64::INFINITY;
        let mut accepted = (coef.clone(), rows.params.clone());
        // The linearised solve at the physical model, then Gauss–Newton steps through the exact
        // chain (coefficients additive, registrations retracted), each kept only if it lowers the
        // penalised objective.
        let mut first =
            Some(at_zero.swap_remove(DEGREES.iter().position(|&d| d == degree).unwrap_or(0)));
        for _ in 0..=REFINEMENTS + 1 {
            for (c, v) in m.coefficients.iter_mut().zip(coef.iter()) {
                *c = v * COEFFICIENT_SCALE;
            }
            let normal = match first.take() {
                Some(n) => n,
                None => normal_equations(&rows, &m, &all_fold, 1).remove(0),
            };
            if mu.is_empty() {
                let p = normal.gram.nrows();
                mu = ridge(&m, n_reg, lambda, normal.gram.trace() / p as f64);
            }
            let penalty: f64 = coef.iter().zip(&mu).map(|(u, m)| m * u * u).sum();
            let value = normal.sse + penalty;
            if value >= objective {
                break;
            }
            objective = value;
            accepted = (coef.clone(), rows.params.clone());
            let mut grad = normal.grad.clone();
            for (g, (u, m)) in grad.iter_mut().zip(coef.iter().zip(&mu)) {
                *g += m * u;
            }
            let Some(step) = ridge_solve(&normal.gram, &grad, &mu) else {
                break;
            };
            coef += step.rows(0, nc);
            let mut full = vec![0.0; rows.layout.len()];
            for (j, &k) in rows.registration.iter().enumerate() {
                full[k] = step[nc + j] * COEFFICIENT_SCALE;
            }
            let layout = rows.layout.clone();
            rows.params.retract(&layout, &full);
        }
        for (c, v) in m.coefficients.iter_mut().zip(accepted.0.iter()) {
            *c = v * COEFFICIENT_SCALE;
        }
        rows.params = accepted.1;
    }
    Ok(AdjointFit {
        model: m,
        params: if active { rows.params } else { params.clone() },
        active,
        cv_rms_m,
        cv_rms_before_m,
        n_rows: n,
    })
}

/// The residual `p − p_measured` (m) of every row of `obs` and its Jacobian with respect to the
/// coefficients in physical units (rad or m per feature unit; rows × 3 by the coefficients), for the
/// tests against finite differences.
pub fn residuals_and_jacobian(
    model: &Model,
    params: &KinematicParams,
    obs: &Observations,
    adjoint: &AdjointModel,
) -> (Vec<Vector3<f64>>, DMatrix<f64>) {
    let rows = rows(model, params, obs).expect("rows of the model's campaigns");
    let p = rows.n_params(adjoint);
    let nc = adjoint.n_coefficients();
    let mut ws = rows.scratch(adjoint.n_features());
    let mut jac = vec![0.0; 3 * p];
    let mut out = DMatrix::zeros(3 * obs.len(), nc);
    let mut res = Vec::with_capacity(obs.len());
    for r in 0..obs.len() {
        res.push(rows.eval(adjoint, r, &mut ws, &mut jac));
        for row in 0..3 {
            for c in 0..nc {
                out[(3 * r + row, c)] = jac[row * p + c] / COEFFICIENT_SCALE;
            }
        }
    }
    (res, out)
}
