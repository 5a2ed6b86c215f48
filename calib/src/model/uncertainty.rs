//! The standard deviation of a prediction: how well the calibration data determined it.
//!
//! With `C` the parameters' covariance (the fit's, in physical units; zero along the combinations
//! the data did not determine, which the fit held at their nominal values) and `J` the 3 × p Jacobian
//! of a row's predicted position ([`crate::model::jacobian`]), the prediction's covariance is
//! `J Σ Jᵀ` and its standard deviation (m) is
//!
//! ```text
//! σ = √ trace(J Σ Jᵀ),   Σ = C + (the prior, on the combinations C leaves undetermined)
//! ```
//!
//! the root of the expected squared distance between the predicted and the true position. The
//! undetermined combinations take a **prior**, the nominal geometry's tolerance: `P = S²` with `S`
//! the diagonal of every parameter's prior standard deviation ([`Prior::length_m`] for lengths,
//! [`Prior::angle_rad`] for angles, the cause's expected magnitude for an extension parameter),
//! restricted to them. They are found where the fit decided its rank, in its scaled coordinates
//! `z = D⁻¹ θ` (`D` the default [`ParameterScales`]): `V⊥`, the eigenvectors of `D⁻¹ C D⁻¹` with
//! eigenvalues below [`NULL_RATIO`] of the largest, and in those coordinates
//! `Σ_z = D⁻¹ C D⁻¹ + V⊥ (V⊥ᵀ D⁻¹ P D⁻¹ V⊥) V⊥ᵀ`, `Σ = D Σ_z D`. (In any other metric the
//! complement of the determined directions would tilt into them.) A pose whose prediction leans on a
//! combination the calibration never saw (another flange orientation than a single-orientation
//! campaign's, say) then has a large σ, and a pose like the calibration's a small one.
//!
//! Gauge directions (a zero offset and the matching twist component, which move no prediction)
//! are null too; their `J` columns cancel, so their prior adds nothing.

use crate::model::params::{ParamLayout, ParameterScales};
use nalgebra::{DMatrix, SymmetricEigen};

/// Eigenvalues of the prior-scaled covariance below this share of the largest count as undetermined.
pub const NULL_RATIO: f64 = 1e-12;

/// The tolerance of the nominal geometry: the prior standard deviation of a parameter the
/// calibration data did not determine.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Prior {
    /// Lengths: joint twist translations, base and target positions (m). Default 1 mm.
    pub length_m: f64,
    /// Angles: joint twist rotations, zero offsets, base and target rotations (rad). Default 1 mrad.
    pub angle_rad: f64,
}

impl Default for Prior {
    fn default() -> Self {
        Prior {
            length_m: 1e-3,
            angle_rad: 1e-3,
        }
    }
}

impl Prior {
    /// The prior standard deviation of every parameter of `layout`.
    pub fn scales(&self, layout: &ParamLayout) -> Vec<f64> {
        let scales = ParameterScales {
            joint_rotation_rad: self.angle_rad,
            joint_translation_m: self.length_m,
            zero_offset_rad: self.angle_rad,
            zero_offset_m: self.length_m,
            base_rotation_rad: self.angle_rad,
            base_translation_m: self.length_m,
            target_position_m: self.length_m,
            target_rotation_rad: self.angle_rad,
        };
        scales.vector(layout).iter().copied().collect()
    }
}

/// A factor `B` (p × r, physical units) of the parameter covariance `Σ = B Bᵀ` (module docs):
/// `σ² = ‖J B‖²` for a row's Jacobian `J`.
#[derive(Clone, Debug)]
pub struct PredictionUncertainty {
    /// `B` of the determined directions (p × r).
    factor: RowMajor,
    /// `B` of the prior on the undetermined directions (p × m).
    prior: RowMajor,
    /// Directions that took the prior.
    n_undetermined: usize,
}

impl PredictionUncertainty {
    /// The factor of `covariance` (p × p, physical units, in `layout`'s order) with `prior` on the
    /// directions it leaves undetermined. `None` when the sizes disagree or an entry is not finite.
    pub fn new(layout: &ParamLayout, covariance: &DMatrix<f64>, prior: &Prior) -> Option<Self> {
        let p = layout.len();
        if covariance.nrows() != p
            || covariance.ncols() != p
            || covariance.iter().any(|v| !v.is_finite())
        {
            return None;
        }
        let s = prior.scales(layout);
        let d: Vec<f64> = ParameterScales::default()
            .vector(layout)
            .iter()
            .copied()
            .collect();
        if s.iter().chain(&d).any(|v| !(v.is_finite() && *v > 0.0)) {
            return None;
        }
        // The fit's coordinates z = D⁻¹ θ, where its rank decision was made.
        let scaled = DMatrix::from_fn(p, p, |i, j| {
            0.5 * (covariance[(i, j)] + covariance[(j, i)]) / (d[i] * d[j])
        });
        let eig = SymmetricEigen::new(scaled);
        let largest = eig.eigenvalues.iter().fold(0.0f64, |m, v| m.max(*v));
        let threshold = NULL_RATIO * largest.max(f64::MIN_POSITIVE);
        let (determined, undetermined): (Vec<usize>, Vec<usize>) =
            (0..p).partition(|&k| eig.eigenvalues[k] > threshold);
        let columns: Vec<nalgebra::DVector<f64>> = determined
            .iter()
            .map(|&k| eig.eigenvectors.column(k) * eig.eigenvalues[k].sqrt())
            .collect();
        let mut prior_columns: Vec<nalgebra::DVector<f64>> = Vec::new();
        if !undetermined.is_empty() {
            // The prior on the undetermined subspace: V⊥ (V⊥ᵀ P_z V⊥) V⊥ᵀ, P_z = diag(S²/D²).
            let v = DMatrix::from_fn(p, undetermined.len(), |i, c| {
                eig.eigenvectors[(i, undetermined[c])]
            });
            let pz = DMatrix::from_fn(
                p,
                p,
                |i, j| {
                    if i == j { (s[i] / d[i]).powi(2) } else { 0.0 }
                },
            );
            let m = v.transpose() * pz * &v;
            let inner = SymmetricEigen::new(m);
            for c in 0..undetermined.len() {
                let lambda = inner.eigenvalues[c].max(0.0);
                prior_columns.push(&v * inner.eigenvectors.column(c) * lambda.sqrt());
            }
        }
        // Back to physical units: θ = D z.
        let factor = DMatrix::from_fn(p, columns.len(), |i, c| d[i] * columns[c][i]);
        let prior = DMatrix::from_fn(p, prior_columns.len(), |i, c| d[i] * prior_columns[c][i]);
        Some(PredictionUncertainty {
            factor: RowMajor::from(&factor),
            prior: RowMajor::from(&prior),
            n_undetermined: undetermined.len(),
        })
    }

    /// `σ` (m) of a prediction whose position Jacobian is `jacobian` (3 × p, row-major, physical
    /// units), with the prior's part evaluated on `reference`, the Jacobian of the same
    /// configuration in the first campaign's tracker frame.
    ///
    /// Why the reference: the undetermined combinations include gauge moves (a joint's error twist
    /// and the base transforms together) that move no prediction of the campaigns the model was
    /// fitted on. A campaign added later by `register` has a covariance conditional on the robot
    /// (no cross terms), so in its own frame such a move would not cancel; its registration would
    /// absorb it. In the first campaign's frame it cancels, and the robot's columns there are those
    /// of any campaign turned by a rotation, which keeps the norm.
    pub fn sigma(&self, jacobian: &[f64], reference: &[f64]) -> f64 {
        (quadratic(&self.factor, jacobian) + quadratic(&self.prior, reference)).sqrt()
    }

    /// Number of parameter combinations that took the prior.
    pub fn n_undetermined(&self) -> usize {
        self.n_undetermined
    }
}

/// A p × k matrix stored row by row: row `i` (parameter `i`'s entries of every column) is
/// contiguous, so that [`quadratic`] reads it in the order it multiplies.
#[derive(Clone, Debug)]
struct RowMajor {
    rows: usize,
    cols: usize,
    values: Vec<f64>,
}

impl From<&DMatrix<f64>> for RowMajor {
    fn from(m: &DMatrix<f64>) -> Self {
        let (rows, cols) = m.shape();
        RowMajor {
            rows,
            cols,
            values: (0..rows)
                .flat_map(|i| (0..cols).map(move |k| m[(i, k)]))
                .collect(),
        }
    }
}

/// Columns of `B` multiplied together in [`quadratic`]: twelve independent running sums (3 rows of
/// `J` × 4 columns), where one dot product at a time waits on each addition.
const BLOCK: usize = 4;

/// `‖J B‖²` (Frobenius) for a 3 × p row-major `J`. Each entry `(J B)[r][k] = Σᵢ J[r][i] B[i][k]` is
/// summed over `i` in order and the squares are added column by column, row within column: the
/// same operations in the same order as the plain loop, [`BLOCK`] columns at a time (85 % of
/// `predict`'s time on 10⁶ rows went here; 3–4× less in blocks).
fn quadratic(b: &RowMajor, jacobian: &[f64]) -> f64 {
    let (p, k) = (b.rows, b.cols);
    debug_assert_eq!(jacobian.len(), 3 * p);
    let (j0, rest) = jacobian.split_at(p);
    let (j1, j2) = rest.split_at(p);
    let mut sum = 0.0;
    let mut col = 0;
    while col + BLOCK <= k {
        let mut acc = [[0.0f64; BLOCK]; 3];
        for i in 0..p {
            let row = &b.values[i * k + col..i * k + col + BLOCK];
            let (a0, a1, a2) = (j0[i], j1[i], j2[i]);
            for c in 0..BLOCK {
                acc[0][c] += a0 * row[c];
                acc[1][c] += a1 * row[c];
                acc[2][c] += a2 * row[c];
            }
        }
        for c in 0..BLOCK {
            for a in &acc {
                sum += a[c] * a[c];
            }
        }
        col += BLOCK;
    }
    for c in col..k {
        let mut acc = [0.0f64; 3];
        for i in 0..p {
            let v = b.values[i * k + c];
            acc[0] += j0[i] * v;
            acc[1] += j1[i] * v;
            acc[2] += j2[i] * v;
        }
        for a in acc {
            sum += a * a;
        }
    }
    sum
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::params::KinematicParams;

    fn layout() -> ParamLayout {
        let model = sim::robots::load_builtin("iiwa7").unwrap();
        let params = KinematicParams::nominal(model.nq(), false);
        ParamLayout::for_params(&model, &params, Vec::new())
    }

    /// A full-rank covariance: σ² = trace(J C Jᵀ) computed directly (hand formula).
    #[test]
    fn full_rank_matches_trace_formula() {
        let l = layout();
        let p = l.len();
        let a = DMatrix::from_fn(p, p, |i, j| ((i * 7 + j * 3) % 11) as f64 * 1e-5);
        let c = &a * a.transpose() + DMatrix::identity(p, p) * 1e-8;
        let u = PredictionUncertainty::new(&l, &c, &Prior::default()).unwrap();
        assert_eq!(u.n_undetermined(), 0);
        let jac: Vec<f64> = (0..3 * p)
            .map(|k| ((k * 5) % 13) as f64 * 0.1 - 0.6)
            .collect();
        let jm = DMatrix::from_row_slice(3, p, &jac);
        let direct = (&jm * &c * jm.transpose()).trace().sqrt();
        assert!(
            (u.sigma(&jac, &jac) - direct).abs() < 1e-9 * direct,
            "{} {direct}",
            u.sigma(&jac, &jac)
        );
    }

    /// A covariance that leaves parameter 0 undetermined: the prior (1 mrad on a twist rotation)
    /// adds exactly (J₀ · 1e-3)² to σ² for a Jacobian that reads only it.
    #[test]
    fn undetermined_direction_takes_the_prior() {
        let l = layout();
        let p = l.len();
        let mut c = DMatrix::identity(p, p) * 1e-10;
        c[(0, 0)] = 0.0;
        let u = PredictionUncertainty::new(&l, &c, &Prior::default()).unwrap();
        assert_eq!(u.n_undetermined(), 1);
        let mut jac = vec![0.0; 3 * p];
        jac[0] = 0.5; // m/rad: a lever of 0.5 m
        assert!((u.sigma(&jac, &jac) - 0.5e-3).abs() < 1e-12);
        // A determined parameter: its own variance.
        let mut jac = vec![0.0; 3 * p];
        jac[p + 1] = 2.0;
        assert!((u.sigma(&jac, &jac) - 2.0 * 1e-5).abs() < 1e-15);
        // Wrong sizes: none.
        assert!(PredictionUncertainty::new(&l, &DMatrix::zeros(3, 3), &Prior::default()).is_none());
    }
}
