//! The rank decision: the SVD split of the scaled Jacobian into identifiable and unidentifiable
//! directions, the covariance and the step measured in standard deviations.

#[allow(unused_imports)]
use super::*;

/// A kept singular value `σₖ < NEAR_SINGULAR_MARGIN · rank_rtol · σ_max` of the scaled Jacobian is
/// near-singular ([`Warning::NearSingularNormalMatrix`]): with the default `rank_rtol = 1e-8`, the
/// scaled normal matrix has a condition number above 1e12 in the identifiable subspace and resolves
/// that combination to about four digits only.
pub const NEAR_SINGULAR_MARGIN: f64 = 100.0;

/// The SVD of the scaled, weighted Jacobian `J D = U Σ Vᵀ`: identifiable and unidentifiable subspaces.
#[derive(Clone, Debug, PartialEq)]
pub struct Subspace {
    /// Column scales `D` (physical units per scaled unit; 0 = frozen).
    pub scales: Vec<f64>,
    /// All `p` singular values, descending (trailing zeros when `m < p`).
    pub singular_values: Vec<f64>,
    /// Right singular vectors as columns (p × p, scaled coordinates), in the order of the singular values.
    pub v: DMatrix<f64>,
    /// Number of singular values above `max(rtol · σ_max, floor)`.
    pub rank: usize,
    /// The relative threshold used.
    pub rtol: f64,
    /// The absolute threshold used.
    pub floor: f64,
    /// Number of residuals the Jacobian had.
    pub n_residuals: usize,
}

impl Subspace {
    /// Computes the split for the weighted Jacobian `j` (m × p) with column scales `scales`: singular
    /// values above `max(rtol · σ_max, floor)` are identifiable.
    pub fn analyze(j: &DMatrix<f64>, scales: &[f64], rtol: f64, floor: f64) -> Subspace {
        Self::from_factor(
            &Self::square_factor(j, scales),
            scales,
            rtol,
            floor,
            j.nrows(),
        )
    }

    /// The square factor of `j D` that [`Subspace::from_factor`] decomposes: `R` of its QR when it has
    /// more rows than columns, else `j D` padded with zero rows (p × p).
    pub fn square_factor(j: &DMatrix<f64>, scales: &[f64]) -> DMatrix<f64> {
        let (m, p) = j.shape();
        if m > p {
            crate::linalg::r_factor_scaled(j, Some(scales))
        } else {
            let mut sq = DMatrix::zeros(p, p);
            sq.view_mut((0, 0), (m, p)).copy_from(j);
            for (c, s) in scales.iter().enumerate() {
                sq.column_mut(c).scale_mut(*s);
            }
            sq
        }
    }

    /// The split from a square factor `square` (p × p; a factor of fewer rows is padded with zero
    /// rows) of the scaled Jacobian of `m` rows ([`Subspace::square_factor`]).
    pub fn from_factor(
        square: &DMatrix<f64>,
        scales: &[f64],
        rtol: f64,
        floor: f64,
        m: usize,
    ) -> Subspace {
        let p = square.ncols();
        // A factor of fewer rows than columns (the `R` of a stack of fewer residuals than
        // parameters, `min(n, p) × p`) is padded with zero rows: the same `RᵀR`, its missing
        // singular values zero.
        let padded;
        let square = if square.nrows() < p {
            let mut sq = DMatrix::zeros(p, p);
            sq.view_mut((0, 0), (square.nrows(), p)).copy_from(square);
            padded = sq;
            &padded
        } else {
            square
        };
        let svd = square.clone().svd(false, true);
        let vt = svd.v_t.expect("SVD was asked for V");
        let mut order: Vec<usize> = (0..p).collect();
        order.sort_by(|&a, &b| svd.singular_values[b].total_cmp(&svd.singular_values[a]));
        let singular_values: Vec<f64> = order.iter().map(|&k| svd.singular_values[k]).collect();
        let mut v = DMatrix::zeros(p, p);
        for (c, &k) in order.iter().enumerate() {
            v.set_column(c, &vt.row(k).transpose());
        }
        let smax = singular_values.first().copied().unwrap_or(0.0);
        let rank = if smax > 0.0 && smax.is_finite() {
            let t = (rtol * smax).max(floor);
            singular_values.iter().filter(|s| **s > t).count()
        } else {
            0
        };
        Subspace {
            scales: scales.to_vec(),
            singular_values,
            v,
            rank,
            rtol,
            floor,
            n_residuals: m,
        }
    }

    /// Number of parameters `p`.
    pub fn n_params(&self) -> usize {
        self.scales.len()
    }

    /// The identifiable singular values `σ₁ ≥ … ≥ σ_rank`.
    pub fn identifiable_singular_values(&self) -> &[f64] {
        &self.singular_values[..self.rank]
    }

    /// Number of identifiable singular values below [`NEAR_SINGULAR_MARGIN`]` · rtol · σ_max`: kept,
    /// but near-singular in the normal matrix.
    pub fn near_singular_count(&self) -> usize {
        let smax = self.singular_values.first().copied().unwrap_or(0.0);
        let t = NEAR_SINGULAR_MARGIN * self.rtol * smax;
        self.identifiable_singular_values()
            .iter()
            .filter(|s| **s < t)
            .count()
    }

    /// The length of the step `delta` (physical units, the columns' order) in standard deviations
    /// of the fit: `‖S Vᵣᵀ D⁻¹ δ‖ / √variance_factor`, the change of the weighted fitted values that
    /// the step makes along the identifiable directions, against the noise the residuals show (1: the
    /// step moves the fit by one standard deviation; [`Subspace::covariance`] is a generalised inverse
    /// of this metric). Unidentifiable directions and frozen columns count nothing.
    pub fn step_in_sigmas(&self, delta: &[f64], variance_factor: f64) -> f64 {
        let mut sum = 0.0;
        for c in 0..self.rank {
            let along: f64 = self
                .scales
                .iter()
                .zip(delta)
                .enumerate()
                .filter(|(_, (s, _))| **s != 0.0)
                .map(|(k, (s, d))| self.v[(k, c)] * d / s)
                .sum();
            sum += (self.singular_values[c] * along).powi(2);
        }
        (sum / variance_factor).sqrt()
    }

    /// Covariance of the step parameters in physical units, `s² D V_r Σ_r⁻² V_rᵀ D` (the pseudo-inverse of
    /// the weighted normal matrix in the identifiable subspace), for a variance factor `s²`.
    pub fn covariance(&self, variance_factor: f64) -> DMatrix<f64> {
        let p = self.n_params();
        let r = self.rank;
        let mut w = DMatrix::zeros(p, r);
        for c in 0..r {
            let s = self.singular_values[c];
            for k in 0..p {
                w[(k, c)] = self.scales[k] * self.v[(k, c)] / s;
            }
        }
        (&w * w.transpose()) * variance_factor
    }
}
