//! k-fold cross-validation folds and error sums for the learned residual models.
//!
//! Folds are drawn by pose row: the row indices are shuffled with a seeded [`StdRng`] and row `i` of the
//! shuffled order goes to fold `i mod k`, so fold sizes differ by at most one and the same seed gives the
//! same folds.

use nalgebra::Vector3;
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand::seq::SliceRandom;

/// Number of cross-validation folds used by [`super::fit`].
pub const K_FOLDS: usize = 5;

/// Fold assignment of `n_rows` rows into `k` folds drawn from `seed`: element `i` is the fold of row `i`.
pub fn fold_assignment(n_rows: usize, k: usize, seed: u64) -> Vec<usize> {
    let mut order: Vec<usize> = (0..n_rows).collect();
    let mut rng = StdRng::seed_from_u64(seed);
    order.shuffle(&mut rng);
    let mut fold_of = vec![0; n_rows];
    for (position, &row) in order.iter().enumerate() {
        fold_of[row] = position % k;
    }
    fold_of
}

/// Training rows (all folds but `fold`) and test rows (fold `fold`), each in increasing row order.
pub fn split(fold_of: &[usize], fold: usize) -> (Vec<usize>, Vec<usize>) {
    let mut train = Vec::with_capacity(fold_of.len());
    let mut test = Vec::with_capacity(fold_of.len() / 2 + 1);
    for (row, &f) in fold_of.iter().enumerate() {
        if f == fold {
            test.push(row);
        } else {
            train.push(row);
        }
    }
    (train, test)
}

/// Mean of the residuals of `rows` (m, tracker frame); zero for no rows.
pub fn mean_of(residual_m: &[Vector3<f64>], rows: &[usize]) -> Vector3<f64> {
    if rows.is_empty() {
        return Vector3::zeros();
    }
    let sum: Vector3<f64> = rows.iter().map(|&r| residual_m[r]).sum();
    sum / rows.len() as f64
}

/// Root mean square of the 3-D norms of `residual_m` (m); zero for none.
pub fn rms_norm(residual_m: &[Vector3<f64>]) -> f64 {
    if residual_m.is_empty() {
        return 0.0;
    }
    (residual_m.iter().map(|r| r.norm_squared()).sum::<f64>() / residual_m.len() as f64).sqrt()
}

/// Index of the candidate to use: candidates are listed from the simplest to the most flexible; the first
/// whose cross-validated sum of squares is within a relative `0.5 %` (plus 1 pm² per row) of the best is
/// taken, so an equally good simpler model wins over a more flexible one.
pub fn select_simplest(sse: &[f64], n_rows: usize) -> usize {
    let best = sse.iter().copied().fold(f64::INFINITY, f64::min);
    let tolerance = best * 5e-3 + 1e-24 * n_rows as f64;
    sse.iter().position(|&s| s <= best + tolerance).unwrap_or(0)
}
