//! Optimal experiment design over candidate blocks: greedy selection, then exchange passes, for the
//! D-, A- and E-optimal criteria.
//!
//! Each candidate `k` contributes a block `Aₖ` (d × r: its weighted Jacobian rows projected onto the
//! `r` identifiable directions of the scaled parameter space). A selection `S` has the information
//! `M(S) = Σₖ∈S Aₖᵀ Aₖ` (r × r, dimensionless: scaled parameters over noise). The criteria, all to be
//! maximised:
//!
//! | criterion | value | meaning |
//! |---|---|---|
//! | D | `log det M` | volume of the confidence ellipsoid (Borm and Menq's O1, up to a monotone map) |
//! | A | `−tr M⁻¹` | the sum of the scaled parameter variances |
//! | E | `λ_min(M)` | the worst-determined combination (Nahvi and Hollerbach's O3 squared) |
//!
//! Greedy: the inverse `P = M⁻¹` is kept by Woodbury updates from a ridge much smaller than any
//! candidate's information. A candidate's gain is exact for D (`log det(I + A P Aᵀ)`) and A (the trace
//! taken off `P`: `tr((AP)ᵀ (I + A P Aᵀ)⁻¹ AP)`); for E it is the first-order gain `‖A v‖²` along the
//! eigenvector `v` of the current smallest eigenvalue. Exchange passes then swap a selected candidate
//! for another while the exact criterion rises (for E among the ten best by first-order gain).

use nalgebra::{DMatrix, DVector, Matrix3, Matrix6};

/// Criterion of the optimal design.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Criterion {
    /// D-optimal: largest `log det` of the information (the default).
    #[default]
    D,
    /// A-optimal: smallest sum of the scaled parameter variances.
    A,
    /// E-optimal: largest smallest eigenvalue of the information.
    E,
}

impl Criterion {
    /// The command-line letter.
    pub fn letter(self) -> &'static str {
        match self {
            Criterion::D => "d",
            Criterion::A => "a",
            Criterion::E => "e",
        }
    }

    /// Parses `d`, `a` or `e` (either case).
    pub fn parse(text: &str) -> Option<Self> {
        match text.trim().to_ascii_lowercase().as_str() {
            "d" => Some(Criterion::D),
            "a" => Some(Criterion::A),
            "e" => Some(Criterion::E),
            _ => None,
        }
    }

    /// The criterion's value for the information `m` (to be maximised), or `None` when `m` is
    /// singular.
    pub fn value(self, m: &DMatrix<f64>) -> Option<f64> {
        let r = m.nrows();
        let ch = m.clone().cholesky()?;
        let l = ch.l_dirty();
        if (0..r).any(|i| !(l[(i, i)] > 0.0 && l[(i, i)].is_finite())) {
            return None;
        }
        Some(match self {
            Criterion::D => (0..r).map(|i| 2.0 * l[(i, i)].ln()).sum(),
            Criterion::A => -ch.inverse().trace(),
            Criterion::E => m.clone().symmetric_eigenvalues().min(),
        })
    }
}

/// The information `Σₖ∈set Aₖᵀ Aₖ`.
pub fn information(a: &[DMatrix<f64>], set: &[usize], r: usize) -> DMatrix<f64> {
    let mut info = DMatrix::zeros(r, r);
    for &k in set {
        info.gemm_tr(1.0, &a[k], &a[k], 1.0);
    }
    info
}

/// Inverse information of `set`, or `None` when singular.
pub fn inverse_information(a: &[DMatrix<f64>], set: &[usize], r: usize) -> Option<DMatrix<f64>> {
    information(a, set, r).cholesky().map(|c| c.inverse())
}

/// The blocks, row-major and contiguous (`3 r` values per candidate), and `Rₖ = Aₖ P` beside them for
/// the current inverse information `P`: every gain below is then a few products of length `r`, and
/// adding or removing a block updates every `Rₖ` in `O(r)` (Woodbury), instead of `O(r²)` per
/// candidate and step.
struct Work {
    r: usize,
    a: Vec<f64>,
    rp: Vec<f64>,
}

/// `Σᵢ x[i] y[i]`.
fn dot(x: &[f64], y: &[f64]) -> f64 {
    x.iter().zip(y).map(|(a, b)| a * b).sum()
}

impl Work {
    fn new(blocks: &[DMatrix<f64>], r: usize) -> Self {
        let mut a = Vec::with_capacity(3 * r * blocks.len());
        for b in blocks {
            for i in 0..3 {
                a.extend(b.row(i).iter());
            }
        }
        Work {
            r,
            rp: vec![0.0; a.len()],
            a,
        }
    }

    fn a_row(&self, c: usize, i: usize) -> &[f64] {
        &self.a[(3 * c + i) * self.r..(3 * c + i + 1) * self.r]
    }

    fn r_row(&self, c: usize, i: usize) -> &[f64] {
        &self.rp[(3 * c + i) * self.r..(3 * c + i + 1) * self.r]
    }

    /// `Rₖ = Aₖ P` for every candidate.
    fn set_inverse(&mut self, p: &DMatrix<f64>) {
        let r = self.r;
        for row in 0..self.a.len() / r {
            for j in 0..r {
                self.rp[row * r + j] = dot(&self.a[row * r..(row + 1) * r], p.column(j).as_slice());
            }
        }
    }

    /// `Aₓ Pₙ Aᵧᵀ`-like 3 × 3 products: `[x_row(c, i) · y_row(d, j)]`.
    fn cross(&self, rx: bool, c: usize, ry: bool, d: usize) -> Matrix3<f64> {
        let row = |w: bool, k: usize, i: usize| {
            if w {
                self.r_row(k, i)
            } else {
                self.a_row(k, i)
            }
        };
        Matrix3::from_fn(|i, j| dot(row(rx, c, i), row(ry, d, j)))
    }

    /// Adds (`sign = 1`) or removes (`−1`) block `k` from the information: with `U = Rₖ` and
    /// `M = sign I + Aₖ P Aₖᵀ`, `P ← P − Uᵀ M⁻¹ U`, so every `R_c ← R_c − (A_c Uᵀ) M⁻¹ U`.
    fn update(&mut self, k: usize, sign: f64) {
        let r = self.r;
        let m = Matrix3::identity() * sign + self.cross(true, k, false, k);
        let Some(mi) = m.try_inverse() else {
            return;
        };
        let u: Vec<f64> = self.rp[3 * k * r..3 * (k + 1) * r].to_vec();
        let n = self.a.len() / (3 * r);
        for c in 0..n {
            let v = Matrix3::from_fn(|i, j| dot(self.a_row(c, i), &u[j * r..(j + 1) * r]));
            let w = v * mi;
            for i in 0..3 {
                let row = &mut self.rp[(3 * c + i) * r..(3 * c + i + 1) * r];
                for (l, x) in row.iter_mut().enumerate() {
                    *x -= w[(i, 0)] * u[l] + w[(i, 1)] * u[r + l] + w[(i, 2)] * u[2 * r + l];
                }
            }
        }
    }

    /// Greedy gain of adding block `c` (D: `log det(I + S)`, A: `tr((I + S)⁻¹ R Rᵀ)`, the trace
    /// taken off `P`; `S = A_c P A_cᵀ`).
    fn add_gain(&self, criterion: Criterion, c: usize) -> f64 {
        let m = Matrix3::identity() + self.cross(true, c, false, c);
        match criterion {
            Criterion::D | Criterion::E => m.determinant().max(f64::MIN_POSITIVE).ln(),
            Criterion::A => match m.try_inverse() {
                Some(mi) => (mi * self.cross(true, c, true, c)).trace(),
                None => 0.0,
            },
        }
    }

    /// Gain of swapping selected block `o` for candidate `c` (at the current `P`): with
    /// `U = [A_c; A_o]`, `C = diag(I, −I)` and `X = C + U P Uᵀ`, the information gains `Uᵀ C U`, so
    /// `det` changes by the factor `−det X` (the determinant lemma) and `tr P` drops by
    /// `tr(X⁻¹ U P² Uᵀ)` (Woodbury). D: the log of the factor; A: the drop; `None` when singular.
    fn swap_gain(&self, criterion: Criterion, o: usize, c: usize) -> Option<f64> {
        let blocks = [(c, 1.0), (o, -1.0)];
        let x = Matrix6::from_fn(|i, j| {
            let (bi, si) = blocks[i / 3];
            let (bj, _) = blocks[j / 3];
            let v = dot(self.r_row(bi, i % 3), self.a_row(bj, j % 3));
            if i == j { v + si } else { v }
        });
        match criterion {
            Criterion::D | Criterion::E => {
                let f = -x.determinant();
                (f > 0.0).then(|| f.ln())
            }
            Criterion::A => {
                let y = Matrix6::from_fn(|i, j| {
                    dot(
                        self.r_row(blocks[i / 3].0, i % 3),
                        self.r_row(blocks[j / 3].0, j % 3),
                    )
                });
                x.lu().solve(&y).map(|s| s.trace())
            }
        }
    }
}

/// First-order gain of the smallest eigenvalue along its eigenvector `v`: `‖A v‖²`.
fn first_order_e(a: &DMatrix<f64>, v: &DVector<f64>) -> f64 {
    (a * v).norm_squared()
}

/// Eigenvector of the smallest eigenvalue of the symmetric `m`.
fn weakest_direction(m: &DMatrix<f64>) -> DVector<f64> {
    let eig = m.clone().symmetric_eigen();
    let (k, _) = eig
        .eigenvalues
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))
        .expect("non-empty information");
    eig.eigenvectors.column(k).into_owned()
}

/// Chooses `k` of the blocks `a` (each 3 × r) for `criterion`: greedy, then at most
/// `exchange_passes` exchange passes (see the module docs). Returns the chosen indices in selection
/// order (the exchanges replace in place) and the criterion's value, `−∞` when the selection is
/// singular.
pub fn choose(
    a: &[DMatrix<f64>],
    r: usize,
    k: usize,
    criterion: Criterion,
    exchange_passes: usize,
) -> (Vec<usize>, f64) {
    let n = a.len();
    let mean_trace = a.iter().map(|x| x.norm_squared()).sum::<f64>() / n.max(1) as f64;
    let ridge = (1e-9 * mean_trace / r.max(1) as f64).max(f64::MIN_POSITIVE);
    let mut work = Work::new(a, r);
    work.set_inverse(&(DMatrix::identity(r, r) / ridge));
    let mut info = DMatrix::identity(r, r) * ridge;
    let mut chosen = vec![false; n];
    let mut set = Vec::with_capacity(k);
    for _ in 0..k {
        let weakest = (criterion == Criterion::E).then(|| weakest_direction(&info));
        let mut best = (f64::NEG_INFINITY, usize::MAX);
        for c in (0..n).filter(|&c| !chosen[c]) {
            let g = match &weakest {
                Some(v) => first_order_e(&a[c], v),
                None => work.add_gain(criterion, c),
            };
            if g > best.0 {
                best = (g, c);
            }
        }
        let c = best.1;
        chosen[c] = true;
        set.push(c);
        if criterion != Criterion::E {
            work.update(c, 1.0);
        }
        info.gemm_tr(1.0, &a[c], &a[c], 1.0);
    }
    let value_of = |s: &[usize]| criterion.value(&information(a, s, r));
    let mut current = value_of(&set).unwrap_or(f64::NEG_INFINITY);
    for _ in 0..exchange_passes {
        let improved = match criterion {
            Criterion::E => exchange_e(a, r, &mut set, &mut chosen, &mut current, &value_of),
            _ => {
                let Some(p) = inverse_information(a, &set, r) else {
                    break;
                };
                work.set_inverse(&p);
                exchange_by_formula(&mut work, criterion, p.trace(), &mut set, &mut chosen)
            }
        };
        if criterion != Criterion::E {
            current = value_of(&set).unwrap_or(f64::NEG_INFINITY);
        }
        if !improved {
            break;
        }
    }
    (set, current)
}

/// One exchange pass for D or A: each slot takes the candidate whose swap gains most by
/// [`Work::swap_gain`], when it gains (more than 10⁻¹⁰, relative to `tr P` for A); `P` follows by two Woodbury
/// updates.
fn exchange_by_formula(
    work: &mut Work,
    criterion: Criterion,
    trace_p: f64,
    set: &mut [usize],
    chosen: &mut [bool],
) -> bool {
    let n = chosen.len();
    let mut improved = false;
    let threshold = match criterion {
        Criterion::A => 1e-10 * trace_p.abs().max(f64::MIN_POSITIVE),
        _ => 1e-10,
    };
    for slot in set.iter_mut() {
        let out = *slot;
        let mut best = (threshold, usize::MAX);
        for c in (0..n).filter(|&c| !chosen[c]) {
            if let Some(g) = work.swap_gain(criterion, out, c)
                && g > best.0
            {
                best = (g, c);
            }
        }
        if best.1 != usize::MAX {
            let c = best.1;
            work.update(out, -1.0);
            work.update(c, 1.0);
            chosen[out] = false;
            chosen[c] = true;
            *slot = c;
            improved = true;
        }
    }
    improved
}

/// One exchange pass for E: each slot tries the ten best candidates by first-order gain against the
/// rest and keeps the best exact improvement.
fn exchange_e(
    a: &[DMatrix<f64>],
    r: usize,
    set: &mut [usize],
    chosen: &mut [bool],
    current: &mut f64,
    value_of: &dyn Fn(&[usize]) -> Option<f64>,
) -> bool {
    let n = a.len();
    let mut improved = false;
    for slot in 0..set.len() {
        let out = set[slot];
        let rest: Vec<usize> = set.iter().copied().filter(|&c| c != out).collect();
        let v = weakest_direction(&information(a, &rest, r));
        let mut ranked: Vec<(f64, usize)> = (0..n)
            .filter(|&c| !chosen[c])
            .map(|c| (first_order_e(&a[c], &v), c))
            .collect();
        ranked.sort_by(|x, y| y.0.total_cmp(&x.0).then(x.1.cmp(&y.1)));
        let mut best = (*current, out);
        for &(_, c) in ranked.iter().take(10) {
            let mut trial = set.to_vec();
            trial[slot] = c;
            if let Some(v) = value_of(&trial)
                && v > best.0 + 1e-10 * best.0.abs().max(f64::MIN_POSITIVE)
            {
                best = (v, c);
            }
        }
        if best.1 != out {
            chosen[out] = false;
            chosen[best.1] = true;
            set[slot] = best.1;
            *current = best.0;
            improved = true;
        }
    }
    improved
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    fn blocks(n: usize, r: usize, seed: u64) -> Vec<DMatrix<f64>> {
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        (0..n)
            .map(|_| DMatrix::from_fn(3, r, |_, _| rng.random::<f64>() - 0.5))
            .collect()
    }

    /// Every criterion's choice is at least as good as every other subset of a small problem within
    /// a small margin (greedy plus exchange is not exhaustive), and at least as good as each of the
    /// other criteria's choices by its own measure.
    #[test]
    fn each_criterion_beats_the_others_and_most_subsets_on_its_own_measure() {
        let (n, r, k) = (9, 5, 3);
        let a = blocks(n, r, 3);
        let mut all = Vec::new();
        for i in 0..n {
            for j in i + 1..n {
                for l in j + 1..n {
                    all.push(vec![i, j, l]);
                }
            }
        }
        for criterion in [Criterion::D, Criterion::A, Criterion::E] {
            let (set, value) = choose(&a, r, k, criterion, 4);
            let again = criterion.value(&information(&a, &set, r)).unwrap();
            assert_eq!(value, again, "{criterion:?}: the value is the selection's");
            let mut values: Vec<f64> = all
                .iter()
                .filter_map(|s| criterion.value(&information(&a, s, r)))
                .collect();
            values.sort_by(f64::total_cmp);
            let rank = values.iter().filter(|v| **v > value + 1e-12).count();
            // Greedy + exchange reaches the top 5 % of the 84 subsets on this problem.
            assert!(rank <= 4, "{criterion:?}: {rank} subsets better");
            for other in [Criterion::D, Criterion::A, Criterion::E] {
                let (s, _) = choose(&a, r, k, other, 4);
                let v = criterion.value(&information(&a, &s, r)).unwrap();
                assert!(value >= v - 1e-9 * v.abs(), "{criterion:?} vs {other:?}");
            }
        }
    }

    /// The criteria against closed forms on a diagonal information.
    #[test]
    fn criterion_values_match_closed_forms() {
        let m = DMatrix::from_diagonal(&DVector::from_vec(vec![4.0, 9.0, 0.25]));
        assert!((Criterion::D.value(&m).unwrap() - (4.0f64 * 9.0 * 0.25).ln()).abs() < 1e-12);
        assert!((Criterion::A.value(&m).unwrap() + (0.25 + 1.0 / 9.0 + 4.0)).abs() < 1e-12);
        assert!((Criterion::E.value(&m).unwrap() - 0.25).abs() < 1e-12);
        let singular = DMatrix::from_diagonal(&DVector::from_vec(vec![1.0, 0.0]));
        assert!(Criterion::D.value(&singular).is_none());
        assert_eq!(Criterion::parse("E"), Some(Criterion::E));
        assert_eq!(Criterion::parse("x"), None);
    }
}
