//! Dense kernels where nalgebra's general routines are memory bound: for tall matrices (many rows, few
//! columns) `Aᵀ B` by the cache-blocked matrix product and the `R` factor of a QR decomposition by blocks
//! of rows in parallel; the Householder QR itself blocked by panels ([`householder_r`], 1.5–1.9 times
//! nalgebra's `qr` on 600–6,000 × 72); for large symmetric positive definite matrices (the kernel
//! models' Gram matrices) a blocked Cholesky factorisation.
//!
//! All give the same result as the plain routines up to rounding (another summation order). The tall
//! `Aᵀ B` leaves small inputs to nalgebra's product, so that its results on small problems do not
//! change at all.

use nalgebra::DMatrix;
use rayon::prelude::*;

/// Rows below which [`tr_mul`] and [`r_factor`] use nalgebra's plain routines.
pub const TALL_ROWS: usize = 4096;
/// Rows per block of [`r_factor`]: a block of up to 100 columns fits in the second-level cache.
const QR_BLOCK_ROWS: usize = 1024;

/// `Aᵀ B` (`a`: n × p, `b`: n × k). nalgebra's `tr_mul` computes every entry as a dot product of two
/// columns, one pass over `A` per column of `B`; for tall inputs this transposes `A` once and uses the
/// cache-blocked product (matrixmultiply) instead.
pub fn tr_mul(a: &DMatrix<f64>, b: &DMatrix<f64>) -> DMatrix<f64> {
    assert_eq!(a.nrows(), b.nrows(), "Aᵀ B needs as many rows in A as in B");
    if a.nrows() < TALL_ROWS {
        return a.tr_mul(b);
    }
    a.transpose() * b
}

/// The upper-triangular `R` (min(n, p) × p) of a QR decomposition of `a` (n × p), up to the signs of
/// its rows, which do not change `RᵀR = AᵀA` or the singular values and right singular vectors.
///
/// For tall inputs (`n ≥ TALL_ROWS` and `n ≥ 4p`) this is the tall-skinny QR (TSQR, Demmel et al.,
/// "Communication-optimal parallel and sequential QR and LU factorizations", SIAM J. Sci. Comput.
/// 2012): blocks of rows are factored in parallel, their `R` factors stacked and factored again. It is
/// as stable as one Householder QR, and each block stays in cache instead of every reflection sweeping
/// the whole matrix.
pub fn r_factor(a: &DMatrix<f64>) -> DMatrix<f64> {
    r_factor_scaled(a, None)
}

/// [`r_factor`] of `a D` with the column scales `D = diag(scales)` (all ones without), without
/// forming the scaled copy of a tall `a`: each block is scaled as it is copied.
pub fn r_factor_scaled(a: &DMatrix<f64>, scales: Option<&[f64]>) -> DMatrix<f64> {
    let (n, p) = a.shape();
    let scale = |m: &mut DMatrix<f64>| {
        if let Some(s) = scales {
            for (c, s) in s.iter().enumerate() {
                m.column_mut(c).scale_mut(*s);
            }
        }
    };
    if !is_tall(n, p) {
        let mut m = a.clone();
        scale(&mut m);
        return householder_r(&mut m);
    }
    let block = tsqr_block_rows(p);
    let starts: Vec<usize> = (0..n).step_by(block).collect();
    let factors: Vec<DMatrix<f64>> = starts
        .par_iter()
        .map(|&s| {
            let rows = block.min(n - s);
            let mut m = a.rows(s, rows).clone_owned();
            scale(&mut m);
            householder_r(&mut m)
        })
        .collect();
    stacked_r_factor(&factors, p)
}

/// Whether an `n × p` matrix takes the tall-skinny path of [`r_factor`].
#[inline]
pub fn is_tall(n: usize, p: usize) -> bool {
    n >= TALL_ROWS && n >= 4 * p
}

/// Rows per block of the tall-skinny path of [`r_factor`] for `p` columns: block `b` is rows
/// `b · tsqr_block_rows(p) ..`, the last one shorter.
#[inline]
pub fn tsqr_block_rows(p: usize) -> usize {
    QR_BLOCK_ROWS.max(4 * p)
}

/// The `R` factor of the blocks' `R` factors `factors` stacked in order (`p` columns): the second
/// stage of the tall-skinny QR, whatever computed the blocks.
pub fn stacked_r_factor(factors: &[DMatrix<f64>], p: usize) -> DMatrix<f64> {
    let stacked_rows: usize = factors.iter().map(|r| r.nrows()).sum();
    let mut stacked = DMatrix::zeros(stacked_rows, p);
    let mut at = 0;
    for r in factors {
        stacked.rows_mut(at, r.nrows()).copy_from(r);
        at += r.nrows();
    }
    r_factor(&stacked)
}

/// Columns per panel of [`householder_r`].
const QR_PANEL: usize = 8;

/// The upper-triangular `R` (min(n, p) × p) of the Householder QR decomposition of `a` (n × p),
/// overwriting `a` (its lower part is left with the reflectors), up to the signs of `R`'s rows.
///
/// Blocked as LAPACK's `dgeqrf`: each panel of [`QR_PANEL`] columns is factored one reflector at a
/// time, and its reflectors, gathered into the compact WY form `Q = I − V T Vᵀ` (Schreiber and Van
/// Loan, 1989), update the columns to its right by two cache-blocked products, where nalgebra's
/// `qr` sweeps every trailing column once per reflector. The same reflectors as the unblocked
/// algorithm, applied in another order: equal up to rounding.
pub fn householder_r(a: &mut DMatrix<f64>) -> DMatrix<f64> {
    let (n, p) = a.shape();
    let kmax = n.min(p);
    let mut tau = [0.0; QR_PANEL];
    let mut v = DMatrix::<f64>::zeros(0, 0);
    let mut t = DMatrix::<f64>::zeros(QR_PANEL, QR_PANEL);
    let mut w = DMatrix::<f64>::zeros(0, 0);
    let mut vt = DMatrix::<f64>::zeros(0, 0);
    let mut k0 = 0;
    while k0 < kmax {
        let kb = QR_PANEL.min(kmax - k0);
        // The panel, one reflector at a time (applied to the panel's own columns only).
        for (j, tau_j) in tau.iter_mut().enumerate().take(kb) {
            let k = k0 + j;
            let (beta, t_k) = reflector(a, k);
            *tau_j = t_k;
            if t_k != 0.0 {
                let (left, right) = a.as_mut_slice().split_at_mut((k + 1) * n);
                let vk = &left[k * n + k + 1..(k + 1) * n];
                for c in 0..k0 + kb - (k + 1) {
                    let col = &mut right[c * n + k..(c + 1) * n];
                    let (head, tail) = col.split_first_mut().expect("row k exists");
                    let s = t_k * (*head + dot(vk, tail));
                    *head -= s;
                    for (y, x) in tail.iter_mut().zip(vk) {
                        *y -= s * x;
                    }
                }
            }
            a[(k, k)] = beta;
        }
        let trailing = p - (k0 + kb);
        if trailing > 0 {
            // V (unit lower trapezoidal, (n − k0) × kb) and T (kb × kb upper triangular).
            let rows = n - k0;
            v.resize_mut(rows, kb, 0.0);
            v.fill(0.0);
            for j in 0..kb {
                v[(j, j)] = 1.0;
                for r in j + 1..rows {
                    v[(r, j)] = a[(k0 + r, k0 + j)];
                }
            }
            t.fill(0.0);
            for j in 0..kb {
                t[(j, j)] = tau[j];
                if j > 0 && tau[j] != 0.0 {
                    // T[0..j, j] = −τⱼ T[0..j, 0..j] Vᵀ[0..j] vⱼ
                    let vtv = v.columns(0, j).tr_mul(&v.column(j));
                    let col = t.view((0, 0), (j, j)) * vtv * (-tau[j]);
                    t.view_mut((0, j), (j, 1)).copy_from(&col);
                }
            }
            // A₂ ← Qᵀ A₂ = A₂ − V Tᵀ (Vᵀ A₂).
            let mut a2 = a.view_mut((k0, k0 + kb), (rows, trailing));
            w.resize_mut(kb, trailing, 0.0);
            vt.resize_mut(kb, rows, 0.0);
            vt.tr_copy_from(&v);
            w.gemm(1.0, &vt, &a2, 0.0);
            let tw = t.view((0, 0), (kb, kb)).tr_mul(&w);
            a2.gemm(-1.0, &v, &tw, 1.0);
        }
        k0 += kb;
    }
    let mut r = DMatrix::zeros(kmax, p);
    for c in 0..p {
        for i in 0..kmax.min(c + 1) {
            r[(i, c)] = a[(i, c)];
        }
    }
    r
}

/// `xᵀy` with four partial sums (a single running sum is bound by the latency of each addition).
#[inline]
pub(crate) fn dot(x: &[f64], y: &[f64]) -> f64 {
    let n = x.len().min(y.len());
    let (xh, xt) = x[..n].split_at(n - n % 4);
    let (yh, yt) = y[..n].split_at(n - n % 4);
    let mut acc = [0.0; 4];
    for (a, b) in xh.chunks_exact(4).zip(yh.chunks_exact(4)) {
        for k in 0..4 {
            acc[k] += a[k] * b[k];
        }
    }
    let tail: f64 = xt.iter().zip(yt).map(|(a, b)| a * b).sum();
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail
}

/// The Householder reflector `H = I − τ v vᵀ` (`v₀ = 1`) that maps column `k` of `a` from row `k`
/// down onto `β e₁`: stores `v`'s tail below the diagonal and returns `(β, τ)`; `τ = 0` (no
/// reflection) when the part below the diagonal is zero already.
fn reflector(a: &mut DMatrix<f64>, k: usize) -> (f64, f64) {
    let n = a.nrows();
    let col = &mut a.as_mut_slice()[k * n + k..(k + 1) * n];
    let (alpha, tail) = col.split_first_mut().expect("row k exists");
    let alpha = *alpha;
    let sq = dot(tail, tail);
    if sq == 0.0 {
        return (alpha, 0.0);
    }
    let norm = alpha.hypot(sq.sqrt());
    let beta = if alpha >= 0.0 { -norm } else { norm };
    let scale = 1.0 / (alpha - beta);
    for x in tail.iter_mut() {
        *x *= scale;
    }
    (beta, (beta - alpha) / beta)
}

/// Columns per block of [`cholesky_in_place`].
const CHOLESKY_BLOCK: usize = 64;

/// Overwrites the symmetric positive definite `a` (n × n; only its lower triangle is read) with its
/// lower Cholesky factor `L` (`a = L Lᵀ`; the upper triangle is set to zero). Returns false, leaving
/// `a` unusable, if a pivot is not positive and finite (not positive definite to working precision).
///
/// Right-looking and blocked by [`CHOLESKY_BLOCK`] columns: each block column is factored, its
/// panel below solved against it, and the trailing lower triangle updated by cache-blocked products
/// (matrixmultiply, through nalgebra's `gemm`), where nalgebra's `cholesky` updates one column at a
/// time over the whole trailing matrix.
pub fn cholesky_in_place(a: &mut DMatrix<f64>) -> bool {
    let n = a.nrows();
    assert_eq!(a.ncols(), n, "Cholesky needs a square matrix");
    let mut k = 0;
    while k < n {
        let b = CHOLESKY_BLOCK.min(n - k);
        let below = n - k - b;
        {
            let data = a.as_mut_slice();
            for j in k..k + b {
                // Column j from the columns before it in this block (earlier blocks are already
                // subtracted by the trailing updates), over the rows j..n.
                let (left, right) = data.split_at_mut(j * n);
                let col_j = &mut right[..n];
                for p in k..j {
                    let col_p = &left[p * n..(p + 1) * n];
                    let l = col_p[j];
                    if l != 0.0 {
                        for (x, y) in col_j[j..].iter_mut().zip(&col_p[j..]) {
                            *x -= l * y;
                        }
                    }
                }
                let d = col_j[j];
                if !(d > 0.0 && d.is_finite()) {
                    return false;
                }
                let d = d.sqrt();
                col_j[j] = d;
                let inv = 1.0 / d;
                col_j[j + 1..].iter_mut().for_each(|x| *x *= inv);
            }
        }
        if below > 0 {
            let panel = a.view((k + b, k), (below, b)).clone_owned();
            let panel_t = panel.transpose();
            let mut c0 = 0;
            while c0 < below {
                let cb = CHOLESKY_BLOCK.min(below - c0);
                let lhs = panel.rows(c0, below - c0);
                let rhs = panel_t.columns(c0, cb);
                let mut dst = a.view_mut((k + b + c0, k + b + c0), (below - c0, cb));
                dst.gemm(-1.0, &lhs, &rhs, 1.0);
                c0 += cb;
            }
        }
        k += b;
    }
    for j in 1..n {
        for i in 0..j {
            a[(i, j)] = 0.0;
        }
    }
    true
}

/// Solves `L Lᵀ X = B` for `X` with the factor `l` of [`cholesky_in_place`] (`b`: n × k).
pub fn cholesky_solve(l: &DMatrix<f64>, b: &DMatrix<f64>) -> DMatrix<f64> {
    let mut x = b.clone();
    l.solve_lower_triangular_unchecked_mut(&mut x);
    l.tr_solve_lower_triangular_unchecked_mut(&mut x);
    x
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::rngs::StdRng;
    use rand::{RngExt, SeedableRng};

    fn random(n: usize, p: usize, seed: u64) -> DMatrix<f64> {
        let mut rng = StdRng::seed_from_u64(seed);
        // Columns of very different sizes, as in a Jacobian in physical units.
        DMatrix::from_fn(n, p, |_, c| {
            (2.0 * rng.random::<f64>() - 1.0) * 10f64.powi(c as i32 % 7 - 3)
        })
    }

    #[test]
    fn blocked_cholesky_equals_nalgebras_and_refuses_an_indefinite_matrix() {
        for n in [1, 5, 64, 65, 200, 301] {
            let f = random(n + 3, n, n as u64 + 7);
            let mut a = f.tr_mul(&f);
            for i in 0..n {
                a[(i, i)] += 1e-3;
            }
            let mut l = a.clone();
            assert!(cholesky_in_place(&mut l), "n = {n}");
            let plain = a.clone().cholesky().expect("positive definite").l();
            assert!((&l - &plain).amax() <= 1e-10 * plain.amax(), "n = {n}");
            let b = random(n, 3, 9);
            let x = cholesky_solve(&l, &b);
            assert!(
                (&a * &x - &b).amax() <= 1e-8 * b.amax() * a.amax(),
                "n = {n}"
            );
            let mut bad = a.clone();
            bad[(n / 2, n / 2)] = -1.0;
            assert!(!cholesky_in_place(&mut bad), "n = {n}");
        }
    }

    #[test]
    fn tr_mul_of_tall_matrices_equals_the_plain_product() {
        let a = random(9000, 13, 1);
        let b = random(9000, 4, 2);
        let fast = tr_mul(&a, &b);
        let plain = a.tr_mul(&b);
        let scale = plain.amax();
        assert!((fast - plain).amax() <= 1e-13 * scale);
    }

    #[test]
    fn blocked_householder_r_equals_nalgebras_qr_up_to_row_signs() {
        // Wide, square, tall; panels that do not divide the columns.
        for (n, p) in [(5, 9), (40, 40), (600, 73), (1024, 16), (300, 1), (37, 35)] {
            let a = random(n, p, (n * p) as u64);
            let plain = a.clone().qr().r();
            let blocked = householder_r(&mut a.clone());
            assert_eq!(blocked.shape(), plain.shape(), "{n}×{p}");
            let scale = plain.amax();
            for i in 0..plain.nrows() {
                let sign = if blocked[(i, i)] * plain[(i, i)] < 0.0 {
                    -1.0
                } else {
                    1.0
                };
                for j in 0..p {
                    let d = (blocked[(i, j)] * sign - plain[(i, j)]).abs();
                    assert!(d <= 1e-12 * scale, "{n}×{p}: R[{i},{j}]");
                }
            }
        }
    }

    #[test]
    fn blocked_householder_r_of_a_rank_deficient_matrix_keeps_its_gram_matrix_and_singular_values()
    {
        // A zero column and a repeated one: the reflectors after them are made of rounding, so R is
        // unique only up to an orthogonal transformation of its last rows; RᵀR and σ are not.
        let (n, p) = (500, 40);
        let mut a = random(n, p, 7);
        a.column_mut(2).fill(0.0);
        let c = a.column(0).clone_owned();
        a.set_column(3, &c);
        let r = householder_r(&mut a.clone());
        let gram = a.tr_mul(&a);
        assert!((r.tr_mul(&r) - &gram).amax() <= 1e-12 * gram.amax());
        let mut f: Vec<f64> = r.singular_values().iter().copied().collect();
        let mut g: Vec<f64> = a
            .clone()
            .qr()
            .r()
            .singular_values()
            .iter()
            .copied()
            .collect();
        f.sort_by(f64::total_cmp);
        g.sort_by(f64::total_cmp);
        for (x, y) in f.iter().zip(&g) {
            assert!((x - y).abs() <= 1e-12 * g[p - 1], "{x} vs {y}");
        }
        assert!(
            f[0] <= 1e-12 * f[p - 1] && f[1] <= 1e-12 * f[p - 1],
            "two zero singular values"
        );
    }

    #[test]
    fn blocked_r_factor_gives_the_gram_matrix_and_singular_values_of_one_householder_qr() {
        for (n, p) in [(10_000, 35), (5000, 60), (4200, 1), (100, 7)] {
            let a = random(n, p, n as u64);
            let r = r_factor(&a);
            assert_eq!(r.shape(), (p, p));
            // Upper triangular.
            for i in 0..p {
                for j in 0..i {
                    assert_eq!(r[(i, j)], 0.0, "R[{i},{j}] of {n}×{p}");
                }
            }
            // RᵀR = AᵀA, against the Gram matrix summed directly.
            let gram = a.tr_mul(&a);
            let rtr = r.tr_mul(&r);
            assert!((&rtr - &gram).amax() <= 1e-12 * gram.amax(), "{n}×{p}");
            let s_fast = r.singular_values();
            let s_plain = a.clone().qr().r().singular_values();
            let mut f: Vec<f64> = s_fast.iter().copied().collect();
            let mut g: Vec<f64> = s_plain.iter().copied().collect();
            f.sort_by(f64::total_cmp);
            g.sort_by(f64::total_cmp);
            for (x, y) in f.iter().zip(&g) {
                assert!((x - y).abs() <= 1e-12 * g[p - 1], "{n}×{p}: {x} vs {y}");
            }
        }
    }
}
