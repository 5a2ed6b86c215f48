//! Kernel ridge regression (the posterior mean of a Gaussian process) of the tracker-frame residual on
//! the joint angles.
//!
//! On the standardised joint angles `z_j = (q_j − mean q_j) / std q_j`, with the per-joint RBF
//! `k_j = exp(−(z_j − z'_j)² / 2ℓ²)` and `n` joints, the kernel is
//!
//! ```text
//! k(z, z') = ⅓ [ (1/n) Σ_j k_j  +  Σ_{i<j} k_i k_j / C(n, 2)  +  exp(−|z − z'|² / 2nℓ²) ]
//! ```
//!
//! (without the middle term and with ½ for a single joint): first- and second-order additive terms
//! (Duvenaud et al., "Additive Gaussian processes", NeurIPS 2011) and a full RBF kernel with the length
//! scale grown by `√n`. The first-order term is one smooth function per joint, as in Schillreff and
//! Ortmeier's per-joint error functions; the second-order term carries pairwise interactions (a joint
//! error seen through a lever arm that depends on another joint) and, unlike a full RBF in 7 dimensions,
//! can still learn them from a few hundred poses; the full term catches the rest when data are dense. The
//! second-order sum costs nothing extra: `Σ_{i<j} k_i k_j = ((Σ k_j)² − Σ k_j²) / 2`. `k(z, z) = 1`.
//! With the centred residuals `yᶜ` of the fit rows, `α = (K + λ I)⁻¹ yᶜ` and the correction is `r̂(q) = ȳ + Σ_i k(z(q), z_i) α_i`;
//! `λ` is the noise-to-signal variance ratio of the Gaussian-process view. `ℓ` and `λ` come from
//! cross-validation over [`LENGTH_SCALES`] × [`LAMBDAS`]. Fits use at most [`MAX_ROWS`] rows (a seeded
//! subsample beyond), which keeps the `O(n³)` Cholesky factorisations of the grid search to seconds.

use nalgebra::{DMatrix, Vector3};
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand::seq::SliceRandom;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::cross_validation::{K_FOLDS, mean_of, split};
use super::polynomial::joint_standardisation;

/// Length scales tried by cross-validation (standardised joint-angle units).
pub const LENGTH_SCALES: [f64; 5] = [0.3, 0.5, 0.8, 1.3, 2.0];
/// Regularisations tried by cross-validation (noise-to-signal variance ratio, dimensionless).
pub const LAMBDAS: [f64; 7] = [1e-6, 1e-4, 1e-2, 1e-1, 1.0, 10.0, 100.0];
/// Most rows a kernel model is fitted on; larger data sets are subsampled with the fit's seed.
pub const MAX_ROWS: usize = 1000;

/// A fitted kernel ridge regression correction.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct KernelModel {
    /// Length scale `ℓ` (standardised joint-angle units).
    pub length_scale: f64,
    /// Regularisation `λ` (noise-to-signal variance ratio).
    pub lambda: f64,
    /// Mean of each joint angle over the fit rows (rad).
    pub q_mean: Vec<f64>,
    /// Standard deviation of each joint angle over the fit rows (rad; 1 for a joint that did not move).
    pub q_scale: Vec<f64>,
    /// Standardised joint angles of the training rows, row-major (rows × joints).
    pub z_train: Vec<f64>,
    /// Weights `α`, row-major (rows × 3 components; m).
    pub alpha: Vec<f64>,
    /// Mean residual of the training rows (m, tracker frame).
    pub intercept: [f64; 3],
    /// Effective degrees of freedom per component: trace of the hat matrix `K (K + λI)⁻¹`, plus 1 for the
    /// intercept.
    pub effective_dof: f64,
}

/// Kernel value between two standardised joint vectors for length scale `ell`.
pub fn kernel(a: &[f64], b: &[f64], ell: f64) -> f64 {
    let n = a.len() as f64;
    let inv = 1.0 / (2.0 * ell * ell);
    let mut additive = 0.0;
    let mut additive_sq = 0.0;
    let mut squared = 0.0;
    for (x, y) in a.iter().zip(b) {
        let d2 = (x - y) * (x - y);
        let k = (-d2 * inv).exp();
        additive += k;
        additive_sq += k * k;
        squared += d2;
    }
    // Second elementary symmetric polynomial of the per-joint kernels: Σ_{i<j} k_i k_j.
    let pairs = if a.len() > 1 {
        0.5 * (additive * additive - additive_sq) / (0.5 * n * (n - 1.0))
    } else {
        0.0
    };
    let terms = if a.len() > 1 { 3.0 } else { 2.0 };
    (additive / n + pairs + (-squared * inv / n).exp()) / terms
}

/// Standardised joint angles (row-major) of all rows.
fn standardise(q: &[f64], n_joints: usize, mean: &[f64], scale: &[f64]) -> Vec<f64> {
    q.chunks_exact(n_joints)
        .flat_map(|row| {
            row.iter()
                .zip(mean)
                .zip(scale)
                .map(|((v, m), s)| (v - m) / s)
        })
        .collect()
}

/// Rows to fit on: all, or a seeded subsample of [`MAX_ROWS`] in increasing order.
pub fn subsample(n_rows: usize, seed: u64) -> Vec<usize> {
    let mut rows: Vec<usize> = (0..n_rows).collect();
    if n_rows > MAX_ROWS {
        let mut rng = StdRng::seed_from_u64(seed ^ 0x6b65_726e_656c);
        rows.shuffle(&mut rng);
        rows.truncate(MAX_ROWS);
        rows.sort_unstable();
    }
    rows
}

fn gram(z: &[f64], n_joints: usize, rows: &[usize], ell: f64) -> DMatrix<f64> {
    let n = rows.len();
    let mut k = DMatrix::zeros(n, n);
    for i in 0..n {
        let zi = &z[rows[i] * n_joints..(rows[i] + 1) * n_joints];
        k[(i, i)] = 1.0;
        for j in 0..i {
            let v = kernel(zi, &z[rows[j] * n_joints..(rows[j] + 1) * n_joints], ell);
            k[(i, j)] = v;
            k[(j, i)] = v;
        }
    }
    k
}

fn centred_targets(residual_m: &[Vector3<f64>], rows: &[usize]) -> (Vector3<f64>, DMatrix<f64>) {
    let mean = mean_of(residual_m, rows);
    let y = DMatrix::from_fn(rows.len(), 3, |i, c| residual_m[rows[i]][c] - mean[c]);
    (mean, y)
}

/// Cross-validated sums of squared 3-D residual norms after correction (m²), indexed
/// `[length scale][λ]`, on the rows `q` (all of them; subsample first) with folds `fold_of`.
pub fn cross_validate(
    q: &[f64],
    n_joints: usize,
    residual_m: &[Vector3<f64>],
    fold_of: &[usize],
) -> Vec<Vec<f64>> {
    let (mean, scale) = joint_standardisation(q, n_joints);
    let z = standardise(q, n_joints, &mean, &scale);
    let jobs: Vec<(usize, usize)> = (0..LENGTH_SCALES.len())
        .flat_map(|l| (0..K_FOLDS).map(move |f| (l, f)))
        .collect();
    let results: Vec<Vec<f64>> = jobs
        .par_iter()
        .map(|&(l, fold)| {
            let ell = LENGTH_SCALES[l];
            let (train, test) = split(fold_of, fold);
            let k = gram(&z, n_joints, &train, ell);
            let (y_mean, y) = centred_targets(residual_m, &train);
            let cross = DMatrix::from_fn(test.len(), train.len(), |i, j| {
                kernel(
                    &z[test[i] * n_joints..(test[i] + 1) * n_joints],
                    &z[train[j] * n_joints..(train[j] + 1) * n_joints],
                    ell,
                )
            });
            LAMBDAS
                .iter()
                .map(|&lambda| {
                    let mut a = k.clone();
                    for i in 0..a.nrows() {
                        a[(i, i)] += lambda;
                    }
                    if !crate::linalg::cholesky_in_place(&mut a) {
                        return f64::INFINITY;
                    }
                    let alpha = crate::linalg::cholesky_solve(&a, &y);
                    let pred = &cross * alpha;
                    test.iter()
                        .enumerate()
                        .map(|(i, &r)| {
                            let p = y_mean + Vector3::new(pred[(i, 0)], pred[(i, 1)], pred[(i, 2)]);
                            (residual_m[r] - p).norm_squared()
                        })
                        .sum()
                })
                .collect()
        })
        .collect();
    (0..LENGTH_SCALES.len())
        .map(|l| {
            (0..LAMBDAS.len())
                .map(|m| (0..K_FOLDS).map(|f| results[l * K_FOLDS + f][m]).sum())
                .collect()
        })
        .collect()
}

/// Fits the kernel model with length scale `ell` and regularisation `lambda` on all rows of `q`.
/// `None` if the regularised Gram matrix is not positive definite (cannot happen for `λ > 0` but rounding).
pub fn fit(
    q: &[f64],
    n_joints: usize,
    residual_m: &[Vector3<f64>],
    ell: f64,
    lambda: f64,
) -> Option<KernelModel> {
    let (q_mean, q_scale) = joint_standardisation(q, n_joints);
    let z_train = standardise(q, n_joints, &q_mean, &q_scale);
    let rows: Vec<usize> = (0..residual_m.len()).collect();
    let mut a = gram(&z_train, n_joints, &rows, ell);
    for i in 0..a.nrows() {
        a[(i, i)] += lambda;
    }
    let chol = a.cholesky()?;
    let (y_mean, y) = centred_targets(residual_m, &rows);
    let alpha_m = chol.solve(&y);
    // tr K (K + λI)⁻¹ = n − λ tr (K + λI)⁻¹
    let inverse = chol.inverse();
    let effective_dof = rows.len() as f64 - lambda * inverse.trace() + 1.0;
    let mut alpha = Vec::with_capacity(rows.len() * 3);
    for i in 0..rows.len() {
        alpha.extend_from_slice(&[alpha_m[(i, 0)], alpha_m[(i, 1)], alpha_m[(i, 2)]]);
    }
    Some(KernelModel {
        length_scale: ell,
        lambda,
        q_mean,
        q_scale,
        z_train,
        alpha,
        intercept: [y_mean.x, y_mean.y, y_mean.z],
        effective_dof,
    })
}

impl KernelModel {
    /// Correction at joint angles `q` (rad; one value per joint) in m, tracker frame.
    pub fn predict(&self, q: &[f64]) -> Vector3<f64> {
        let n = self.q_mean.len();
        let z: Vec<f64> = (0..n)
            .map(|j| (q[j] - self.q_mean[j]) / self.q_scale[j])
            .collect();
        let mut out = Vector3::from(self.intercept);
        for (zi, a) in self.z_train.chunks_exact(n).zip(self.alpha.chunks_exact(3)) {
            let k = kernel(&z, zi, self.length_scale);
            out.x += k * a[0];
            out.y += k * a[1];
            out.z += k * a[2];
        }
        out
    }

    /// `∂r̂/∂qⱼ` (m/rad, tracker frame) at `q` into `out` (one per joint): the kernel's derivative in
    /// closed form. With `dⱼ = zⱼ − z'ⱼ`, `kⱼ = exp(−dⱼ²/2ℓ²)`, `A = Σ kⱼ` and the full term `F`,
    /// `∂k/∂zⱼ = [∂kⱼ/n + (A − kⱼ) ∂kⱼ / C(n, 2) − F dⱼ/(nℓ²)] / terms` with `∂kⱼ = −kⱼ dⱼ/ℓ²`.
    pub fn jacobian(&self, q: &[f64], out: &mut [Vector3<f64>]) {
        let n = self.q_mean.len();
        let nf = n as f64;
        let ell2 = self.length_scale * self.length_scale;
        let inv = 1.0 / (2.0 * ell2);
        let terms = if n > 1 { 3.0 } else { 2.0 };
        let pairs = if n > 1 { 0.5 * nf * (nf - 1.0) } else { 1.0 };
        out.fill(Vector3::zeros());
        let mut d = vec![0.0; n];
        let mut k = vec![0.0; n];
        let z: Vec<f64> = (0..n)
            .map(|j| (q[j] - self.q_mean[j]) / self.q_scale[j])
            .collect();
        for (zi, a) in self.z_train.chunks_exact(n).zip(self.alpha.chunks_exact(3)) {
            let (mut additive, mut squared) = (0.0, 0.0);
            for j in 0..n {
                d[j] = z[j] - zi[j];
                k[j] = (-d[j] * d[j] * inv).exp();
                additive += k[j];
                squared += d[j] * d[j];
            }
            let full = (-squared * inv / nf).exp();
            for j in 0..n {
                let dk = -k[j] * d[j] / ell2;
                let pair = if n > 1 {
                    (additive - k[j]) * dk / pairs
                } else {
                    0.0
                };
                let g = (dk / nf + pair - full * d[j] / (nf * ell2)) / terms / self.q_scale[j];
                out[j] += g * Vector3::new(a[0], a[1], a[2]);
            }
        }
    }

    /// Number of training rows the model holds.
    pub fn n_train(&self) -> usize {
        self.alpha.len() / 3
    }
}
