//! Polynomial ridge regression of the tracker-frame residual on the joint angles.
//!
//! Following Schillreff and Ortmeier (ICINCO 2018), who model each error parameter as a polynomial
//! function of the joint values, the features are all monomials of the standardised joint angles
//! `z_j = (q_j − mean q_j) / std q_j` of total degree 1 to `d` (for 7 joints: 7, 35 and 119 features for
//! `d` = 1, 2, 3), each standardised again over the fit rows, plus an unpenalised intercept. Monomials in
//! `q` rather than in `sin q`, `cos q`: they are what the paper uses, they need half as many variables, and
//! over the joint ranges of a calibration (at most one turn) a cubic in `q` represents the low harmonics
//! the physical causes produce (eccentric gears, elastic deflection under gravity). The three residual
//! components share the features; the coefficients solve the ridge normal equations
//! `(Gᶜ + λ n I) w = Fᶜᵀ yᶜ` (centred features and residuals, `n` rows) through the eigenvectors of `Gᶜ`,
//! so one decomposition serves all `λ` of the cross-validation grid; eigenvalues below `10⁻¹²` of the
//! largest are dropped (features collinear over the data, e.g. a joint that never moves).

use nalgebra::{DMatrix, SymmetricEigen, Vector3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::cross_validation::{K_FOLDS, mean_of, split};

/// Ridge strengths tried by cross-validation (per row, in units of the standardised features).
pub const LAMBDAS: [f64; 8] = [1e-12, 1e-9, 1e-6, 1e-4, 1e-3, 1e-2, 1e-1, 1.0];

/// Exponent lists of all monomials of degree 1 to `degree` in `n_joints` variables: each monomial is the
/// non-decreasing list of the joint indices it multiplies (`[1, 1, 4]` = `z₁² z₄`), ordered by degree.
pub fn monomials(n_joints: usize, degree: usize) -> Vec<Vec<usize>> {
    let mut all = Vec::new();
    let mut current = Vec::with_capacity(degree);
    for d in 1..=degree {
        push_monomials(n_joints, d, 0, &mut current, &mut all);
    }
    all
}

fn push_monomials(
    n: usize,
    d: usize,
    start: usize,
    current: &mut Vec<usize>,
    all: &mut Vec<Vec<usize>>,
) {
    if current.len() == d {
        all.push(current.clone());
        return;
    }
    for j in start..n {
        current.push(j);
        push_monomials(n, d, j, current, all);
        current.pop();
    }
}

/// A fitted polynomial correction: `r̂(q) = c + Σ_k w_k (m_k(z(q)) − μ_k) / s_k` (m, tracker frame).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PolynomialModel {
    /// Total degree of the monomials.
    pub degree: usize,
    /// Ridge strength per row (standardised feature units).
    pub lambda: f64,
    /// Mean of each joint angle over the fit rows (rad).
    pub q_mean: Vec<f64>,
    /// Standard deviation of each joint angle over the fit rows (rad; 1 for a joint that did not move).
    pub q_scale: Vec<f64>,
    /// Monomials as lists of joint indices.
    pub monomials: Vec<Vec<usize>>,
    /// Mean of each monomial over the fit rows.
    pub feature_mean: Vec<f64>,
    /// Standard deviation of each monomial over the fit rows (1 if constant).
    pub feature_scale: Vec<f64>,
    /// Coefficients, row-major (feature × 3 components; m per standardised feature unit).
    pub coefficients: Vec<f64>,
    /// Intercept (m, tracker frame).
    pub intercept: [f64; 3],
    /// Effective degrees of freedom per component (trace of the hat matrix, intercept included).
    pub effective_dof: f64,
}

/// Standardisation of the joint angles: means and standard deviations (rad) over all rows.
pub fn joint_standardisation(q: &[f64], n_joints: usize) -> (Vec<f64>, Vec<f64>) {
    let rows = q.len() / n_joints;
    let mut mean = vec![0.0; n_joints];
    let mut scale = vec![0.0; n_joints];
    for row in q.chunks_exact(n_joints) {
        for (m, &v) in mean.iter_mut().zip(row) {
            *m += v;
        }
    }
    mean.iter_mut().for_each(|m| *m /= rows as f64);
    for row in q.chunks_exact(n_joints) {
        for ((s, &m), &v) in scale.iter_mut().zip(&mean).zip(row) {
            *s += (v - m) * (v - m);
        }
    }
    for s in &mut scale {
        *s = (*s / rows as f64).sqrt();
        if *s <= 1e-12 {
            *s = 1.0;
        }
    }
    (mean, scale)
}

/// Raw monomial values of one row into `out` (`out.len() == monomials.len()`); `z` is scratch.
fn raw_features(
    q_row: &[f64],
    q_mean: &[f64],
    q_scale: &[f64],
    monomials: &[Vec<usize>],
    z: &mut [f64],
    out: &mut [f64],
) {
    for (j, zj) in z.iter_mut().enumerate() {
        *zj = (q_row[j] - q_mean[j]) / q_scale[j];
    }
    for (o, m) in out.iter_mut().zip(monomials) {
        *o = m.iter().map(|&j| z[j]).product();
    }
}

/// Standardised feature matrix (rows × features) with its column means and scales.
fn feature_matrix(
    q: &[f64],
    n_joints: usize,
    q_mean: &[f64],
    q_scale: &[f64],
    monomials: &[Vec<usize>],
) -> (DMatrix<f64>, Vec<f64>, Vec<f64>) {
    let rows = q.len() / n_joints;
    let p = monomials.len();
    let mut f = DMatrix::zeros(rows, p);
    let mut z = vec![0.0; n_joints];
    let mut out = vec![0.0; p];
    for (r, q_row) in q.chunks_exact(n_joints).enumerate() {
        raw_features(q_row, q_mean, q_scale, monomials, &mut z, &mut out);
        for (k, &v) in out.iter().enumerate() {
            f[(r, k)] = v;
        }
    }
    let mut mean = vec![0.0; p];
    let mut scale = vec![1.0; p];
    for k in 0..p {
        let col = f.column(k);
        let m = col.mean();
        let s = (col.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / rows as f64).sqrt();
        mean[k] = m;
        scale[k] = if s > 1e-12 { s } else { 1.0 };
        for r in 0..rows {
            f[(r, k)] = (f[(r, k)] - m) / scale[k];
        }
    }
    (f, mean, scale)
}

/// Ridge solution on `rows` for every λ in `lambdas`: (feature means, residual mean, eigen-decomposition
/// of the centred Gram matrix, `Vᵀ Fᶜᵀ yᶜ`).
struct RidgeSystem {
    feature_mean: Vec<f64>,
    y_mean: Vector3<f64>,
    eigenvalues: Vec<f64>,
    eigenvectors: DMatrix<f64>,
    projected: DMatrix<f64>,
    n_rows: usize,
}

impl RidgeSystem {
    fn new(f: &DMatrix<f64>, residual_m: &[Vector3<f64>], rows: &[usize]) -> Self {
        let p = f.ncols();
        let n = rows.len();
        // Column by column: `f` is column-major, so each column is one contiguous pass.
        let mut feature_mean = vec![0.0; p];
        for (k, m) in feature_mean.iter_mut().enumerate() {
            let col = f.column(k);
            for &r in rows {
                *m += col[r];
            }
        }
        feature_mean.iter_mut().for_each(|m| *m /= n as f64);
        let y_mean = mean_of(residual_m, rows);
        let mut fc = DMatrix::zeros(n, p);
        let mut yc = DMatrix::zeros(n, 3);
        for (k, &mean) in feature_mean.iter().enumerate() {
            let src = f.column(k);
            for (dst, &r) in fc.column_mut(k).iter_mut().zip(rows) {
                *dst = src[r] - mean;
            }
        }
        for (i, &r) in rows.iter().enumerate() {
            let y = residual_m[r] - y_mean;
            for c in 0..3 {
                yc[(i, c)] = y[c];
            }
        }
        let gram = crate::linalg::tr_mul(&fc, &fc);
        let rhs = crate::linalg::tr_mul(&fc, &yc);
        let eig = SymmetricEigen::new(gram);
        let projected = eig.eigenvectors.tr_mul(&rhs);
        RidgeSystem {
            feature_mean,
            y_mean,
            eigenvalues: eig.eigenvalues.iter().copied().collect(),
            eigenvectors: eig.eigenvectors,
            projected,
            n_rows: n,
        }
    }

    /// Coefficients (p × 3) and the effective degrees of freedom for ridge strength `lambda` per row.
    fn solve(&self, lambda: f64) -> (DMatrix<f64>, f64) {
        let largest = self.eigenvalues.iter().copied().fold(0.0, f64::max);
        let shift = lambda * self.n_rows as f64;
        let mut scaled = self.projected.clone();
        let mut dof = 1.0;
        for (i, &ev) in self.eigenvalues.iter().enumerate() {
            let factor = if ev > 1e-12 * largest && ev > 0.0 {
                dof += ev / (ev + shift);
                1.0 / (ev + shift)
            } else {
                0.0
            };
            for c in 0..3 {
                scaled[(i, c)] *= factor;
            }
        }
        (&self.eigenvectors * scaled, dof)
    }

    /// Prediction for standardised feature row `r` of `f` with coefficients `w`.
    fn predict_row(&self, f: &DMatrix<f64>, r: usize, w: &DMatrix<f64>) -> Vector3<f64> {
        let mut out = self.y_mean;
        for k in 0..f.ncols() {
            let x = f[(r, k)] - self.feature_mean[k];
            for c in 0..3 {
                out[c] += x * w[(k, c)];
            }
        }
        out
    }
}

/// Cross-validated sums of squared 3-D residual norms after correction (m²), one per λ in [`LAMBDAS`],
/// for polynomials of `degree` on the folds `fold_of`.
pub fn cross_validate(
    q: &[f64],
    n_joints: usize,
    residual_m: &[Vector3<f64>],
    fold_of: &[usize],
    degree: usize,
) -> Vec<f64> {
    let (q_mean, q_scale) = joint_standardisation(q, n_joints);
    let monos = monomials(n_joints, degree);
    let (f, _, _) = feature_matrix(q, n_joints, &q_mean, &q_scale, &monos);
    let per_fold: Vec<Vec<f64>> = (0..K_FOLDS)
        .into_par_iter()
        .map(|fold| {
            let (train, test) = split(fold_of, fold);
            let system = RidgeSystem::new(&f, residual_m, &train);
            LAMBDAS
                .iter()
                .map(|&lambda| {
                    let (w, _) = system.solve(lambda);
                    test.iter()
                        .map(|&r| (residual_m[r] - system.predict_row(&f, r, &w)).norm_squared())
                        .sum()
                })
                .collect()
        })
        .collect();
    (0..LAMBDAS.len())
        .map(|l| per_fold.iter().map(|v| v[l]).sum())
        .collect()
}

/// Fits the polynomial of `degree` with ridge strength `lambda` on all rows.
pub fn fit(
    q: &[f64],
    n_joints: usize,
    residual_m: &[Vector3<f64>],
    degree: usize,
    lambda: f64,
) -> PolynomialModel {
    let (q_mean, q_scale) = joint_standardisation(q, n_joints);
    let monos = monomials(n_joints, degree);
    let (f, feature_mean, feature_scale) = feature_matrix(q, n_joints, &q_mean, &q_scale, &monos);
    let rows: Vec<usize> = (0..residual_m.len()).collect();
    let system = RidgeSystem::new(&f, residual_m, &rows);
    let (w, effective_dof) = system.solve(lambda);
    // Fold the centring of the fit rows (zero up to rounding for standardised columns) into the intercept.
    let mut intercept = system.y_mean;
    for k in 0..w.nrows() {
        for c in 0..3 {
            intercept[c] -= system.feature_mean[k] * w[(k, c)];
        }
    }
    let mut coefficients = Vec::with_capacity(w.nrows() * 3);
    for k in 0..w.nrows() {
        coefficients.extend_from_slice(&[w[(k, 0)], w[(k, 1)], w[(k, 2)]]);
    }
    PolynomialModel {
        degree,
        lambda,
        q_mean,
        q_scale,
        monomials: monos,
        feature_mean,
        feature_scale,
        coefficients,
        intercept: [intercept.x, intercept.y, intercept.z],
        effective_dof,
    }
}

impl PolynomialModel {
    /// Correction at joint angles `q` (rad; `n_joints` values) in m, tracker frame.
    pub fn predict(&self, q: &[f64]) -> Vector3<f64> {
        let n = self.q_mean.len();
        let mut z = vec![0.0; n];
        for (j, zj) in z.iter_mut().enumerate() {
            *zj = (q[j] - self.q_mean[j]) / self.q_scale[j];
        }
        let mut out = Vector3::from(self.intercept);
        for (k, m) in self.monomials.iter().enumerate() {
            let raw: f64 = m.iter().map(|&j| z[j]).product();
            let x = (raw - self.feature_mean[k]) / self.feature_scale[k];
            let w = &self.coefficients[3 * k..3 * k + 3];
            out.x += x * w[0];
            out.y += x * w[1];
            out.z += x * w[2];
        }
        out
    }

    /// `∂r̂/∂qⱼ` (m/rad, tracker frame) at `q` into `out` (one per joint): each monomial's product
    /// rule, divided by its feature scale and the joint's standardisation scale.
    pub fn jacobian(&self, q: &[f64], out: &mut [Vector3<f64>]) {
        let n = self.q_mean.len();
        let z: Vec<f64> = (0..n)
            .map(|j| (q[j] - self.q_mean[j]) / self.q_scale[j])
            .collect();
        out.fill(Vector3::zeros());
        for (k, m) in self.monomials.iter().enumerate() {
            let w = &self.coefficients[3 * k..3 * k + 3];
            let w = Vector3::new(w[0], w[1], w[2]) / self.feature_scale[k];
            for (l, &j) in m.iter().enumerate() {
                let others: f64 = m
                    .iter()
                    .enumerate()
                    .filter(|&(o, _)| o != l)
                    .map(|(_, &i)| z[i])
                    .product();
                out[j] += w * (others / self.q_scale[j]);
            }
        }
    }

    /// Number of coefficients: (features + intercept) × 3 components.
    pub fn n_coefficients(&self) -> usize {
        3 * (self.monomials.len() + 1)
    }
}
