//! What a pose set can and cannot determine: observability indices of the scaled Jacobian and the
//! unidentifiable directions of parameter space, named in parameter words.
//!
//! # Observability indices
//! For the `L` identifiable singular values `σ₁ ≥ … ≥ σ_L` of the weighted, column-scaled Jacobian
//! (m rows), as numbered by Sun and Hollerbach (*Observability index selection for robot calibration*,
//! ICRA 2008):
//!
//! | index | formula | origin | meaning |
//! |---|---|---|---|
//! | O1 | `(σ₁ ⋯ σ_L)^{1/L} / √m` | Borm and Menq 1991 | D-optimality: volume of the uncertainty ellipsoid |
//! | O2 | `σ_L / σ₁` | Driels and Pathre 1990 | inverse condition number |
//! | O3 | `σ_L` | Nahvi, Hollerbach and Hayward 1994 | E-optimality: the worst combination |
//! | O4 | `σ_L² / σ₁` | Nahvi and Hollerbach 1996 | noise amplification index |
//! | O5 | `1 / Σ 1/σₖ` | Sun and Hollerbach 2008 | A-optimality-like |
//!
//! With columns scaled by the expected parameter magnitudes and rows by the noise, `1/σ_L` is the
//! standard deviation of the worst-determined combination in units of its expected magnitude: above 1 the
//! data say less about it than the prior guess ("weakly identifiable").
//!
//! # Naming the null space
//! Candidate directions with a known meaning are built at the current parameter point and kept when they
//! lie in the null space (projection residual below 1e-6): for every joint, the error twists that leave
//! its own axis unchanged (rotation about it, sliding along it); for every joint, the zero offset together
//! with the same rotation of all later axes and the target; the tracker-to-base transform against a common
//! error twist of all axes; and, data-specific, each joint's twist component absorbed by base and target
//! (e.g. a joint that never moves). Base and target parts of a candidate are fitted by least squares, so
//! the candidates need no hand-derived tool terms. Whatever the candidates do not explain is listed as
//! combinations of named parameters.

use crate::fit::problem::Observations;
use crate::lm::Subspace;
use crate::model::params::{KinematicParams, ParamLayout, TWIST_COMPONENTS};
use nalgebra::{DMatrix, DVector, Vector6};
use sim::lie::adjoint_apply;
use sim::{JointKind, Model};

/// Observability of a pose set: singular-value statistics of the weighted, scaled Jacobian.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Observability {
    /// Scalar residuals (rows of the Jacobian).
    pub n_residuals: usize,
    /// Parameters (columns).
    pub n_params: usize,
    /// Identifiable combinations `L`.
    pub rank: usize,
    /// Largest singular value `σ₁`.
    pub sigma_max: f64,
    /// Smallest identifiable singular value `σ_L`.
    pub sigma_min: f64,
    /// `σ₁ / σ_L`.
    pub condition_number: f64,
    /// O1 = `(σ₁ ⋯ σ_L)^{1/L} / √m`.
    pub o1: f64,
    /// O2 = `σ_L / σ₁`.
    pub o2: f64,
    /// O3 = `σ_L`.
    pub o3: f64,
    /// O4 = `σ_L² / σ₁` (noise amplification index).
    pub o4: f64,
    /// O5 = `1 / Σ 1/σₖ`.
    pub o5: f64,
    /// `log det` of the scaled information matrix in the identifiable subspace, `2 Σ ln σₖ`.
    pub log_det_information: f64,
    /// `1/σ_L`: standard deviation of the worst-determined combination in units of its expected
    /// magnitude, per unit noise (multiply by `√(χ²/dof)` for the estimate's).
    pub worst_combination_sigma: f64,
    /// Identifiable combinations with `σₖ < 1` (worse determined than their expected magnitude).
    pub weak_combinations: usize,
}

impl Observability {
    /// Indices of the identifiable part of `sub`.
    pub fn from_subspace(sub: &Subspace) -> Self {
        let s = sub.identifiable_singular_values();
        let l = s.len();
        let m = sub.n_residuals;
        let (smax, smin) = (
            s.first().copied().unwrap_or(0.0),
            s.last().copied().unwrap_or(0.0),
        );
        let log_sum: f64 = s.iter().map(|v| v.ln()).sum();
        let o1 = if l > 0 {
            (log_sum / l as f64).exp() / (m as f64).sqrt()
        } else {
            0.0
        };
        Observability {
            n_residuals: m,
            n_params: sub.n_params(),
            rank: l,
            sigma_max: smax,
            sigma_min: smin,
            condition_number: if smin > 0.0 {
                smax / smin
            } else {
                f64::INFINITY
            },
            o1,
            o2: if smax > 0.0 { smin / smax } else { 0.0 },
            o3: smin,
            o4: if smax > 0.0 { smin * smin / smax } else { 0.0 },
            o5: if l > 0 {
                1.0 / s.iter().map(|v| 1.0 / v).sum::<f64>()
            } else {
                0.0
            },
            log_det_information: 2.0 * log_sum,
            worst_combination_sigma: if smin > 0.0 {
                1.0 / smin
            } else {
                f64::INFINITY
            },
            weak_combinations: s.iter().filter(|v| **v < 1.0).count(),
        }
    }
}

/// Kind of an unidentifiable direction.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum NullKind {
    /// An error twist of joint `joint` (1-based) that leaves its own axis unchanged.
    OwnAxis {
        /// 1-based joint.
        joint: usize,
    },
    /// Joint `joint`'s (1-based) zero offset against the later axes and the target.
    ZeroOffset {
        /// 1-based joint.
        joint: usize,
    },
    /// The tracker-to-base transform against a common error twist of all axes.
    BaseGauge,
    /// A twist component of joint `joint` (1-based) absorbed by base and target in this pose set.
    AbsorbedByBase {
        /// 1-based joint.
        joint: usize,
    },
    /// A combination that a coupled joint (1-based `joint`, [`sim::coupled_joints`]) makes
    /// inseparable: it would be determined if the joint moved on its own, which it never does.
    Coupling {
        /// 1-based coupled joint.
        joint: usize,
    },
    /// Not one of the named patterns.
    Other,
}

impl NullKind {
    /// True for the redundancies every pose set has (the model's own); false for data-specific ones.
    pub fn is_structural(&self) -> bool {
        matches!(
            self,
            NullKind::OwnAxis { .. }
                | NullKind::ZeroOffset { .. }
                | NullKind::BaseGauge
                | NullKind::Coupling { .. }
        )
    }
}

/// One unidentifiable direction of parameter space.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct NullDirection {
    /// What kind of redundancy it is.
    #[serde(flatten)]
    pub kind: NullKind,
    /// A sentence saying what cannot be told apart.
    pub description: String,
    /// Largest components (physical units, largest = ±1): parameter name and coefficient.
    pub components: Vec<(String, f64)>,
}

/// The unidentifiable directions and the per-parameter verdicts.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct NullSpaceReport {
    /// Dimension of the null space (parameters minus identifiable combinations).
    pub dimension: usize,
    /// One entry per dimension.
    pub directions: Vec<NullDirection>,
    /// Grouped sentences for a human reader, each starting with the number of directions it covers.
    pub summary: Vec<String>,
    /// The sentences of `summary` that are specific to this pose set (not the model's own
    /// redundancies): what a better pose set would determine.
    pub data_specific: Vec<String>,
    /// Per parameter: true when it is determined on its own (no null-space component).
    pub identifiable_alone: Vec<bool>,
}

impl NullSpaceReport {
    /// Directions that are not the model's structural redundancies: what this pose set fails to determine.
    pub fn data_specific(&self) -> impl Iterator<Item = &NullDirection> {
        self.directions.iter().filter(|d| !d.kind.is_structural())
    }
}

/// Tolerance on the projection residual for a candidate to count as unidentifiable.
const IN_NULL_TOL: f64 = 1e-6;
/// Minimum new component for a candidate to add a dimension to the explained part.
const NEW_DIM_TOL: f64 = 1e-3;

struct Namer<'a> {
    layout: &'a ParamLayout,
    scales: &'a [f64],
    null: DMatrix<f64>,
    gram: &'a DMatrix<f64>,
    /// The base and target columns, and the Cholesky factor of their block of the normal matrix.
    bt_cols: Vec<usize>,
    bt_chol: Option<nalgebra::linalg::Cholesky<f64, nalgebra::Dyn>>,
    explained: Vec<DVector<f64>>,
    directions: Vec<NullDirection>,
}

impl Namer<'_> {
    /// Adds the base and target components that best cancel the effect of `a` (physical units) on the
    /// measurements: the least-squares fit, from the scaled normal equations.
    fn absorb(&self, a: &mut DVector<f64>) {
        let Some(ch) = &self.bt_chol else { return };
        let p = a.len();
        let a_s = DVector::from_fn(p, |k, _| {
            if self.scales[k] > 0.0 {
                a[k] / self.scales[k]
            } else {
                0.0
            }
        });
        let u = DVector::from_fn(self.bt_cols.len(), |i, _| {
            -(0..p)
                .map(|k| self.gram[(self.bt_cols[i], k)] * a_s[k])
                .sum::<f64>()
        });
        let b = ch.solve(&u);
        for (i, &k) in self.bt_cols.iter().enumerate() {
            a[k] += b[i] * self.scales[k];
        }
    }

    /// Tries the candidate `a` (physical units); records it when it adds a null dimension.
    fn offer(&mut self, a: &DVector<f64>, kind: NullKind, description: String) -> bool {
        if self.explained.len() >= self.null.ncols() {
            return false;
        }
        let mut s = DVector::from_fn(a.len(), |k, _| {
            if self.scales[k] > 0.0 {
                a[k] / self.scales[k]
            } else {
                0.0
            }
        });
        let norm = s.norm();
        if norm == 0.0 || !norm.is_finite() {
            return false;
        }
        s /= norm;
        let proj = &self.null * self.null.tr_mul(&s);
        if (&proj - &s).norm() > IN_NULL_TOL {
            return false;
        }
        let mut rest = proj;
        for e in &self.explained {
            let c = e.dot(&rest);
            rest.axpy(-c, e, 1.0);
        }
        let rn = rest.norm();
        if rn < NEW_DIM_TOL {
            return false;
        }
        self.explained.push(rest / rn);
        self.directions.push(NullDirection {
            kind,
            description,
            components: components(self.layout, self.scales, &s),
        });
        true
    }
}

/// Largest components of a scaled direction `s`, in physical units normalised to a largest of ±1.
fn components(layout: &ParamLayout, scales: &[f64], s: &DVector<f64>) -> Vec<(String, f64)> {
    let phys: Vec<f64> = s.iter().zip(scales).map(|(v, d)| v * d).collect();
    // Rank by the scaled size (comparable across units), report physical ratios.
    let mut idx: Vec<usize> = (0..s.len()).filter(|&k| s[k].abs() > 0.05).collect();
    idx.sort_by(|&a, &b| s[b].abs().total_cmp(&s[a].abs()));
    idx.truncate(8);
    let big = idx.first().map(|&k| phys[k]).unwrap_or(1.0);
    idx.iter()
        .map(|&k| (layout.name(k), phys[k] / big))
        .collect()
}

/// `the coupling of joint 4 to joints 2 and 3` (every coupled joint of `model`, 1-based).
fn coupling_words(model: &Model) -> String {
    let each: Vec<String> = model
        .couplings()
        .list()
        .iter()
        .map(|c| {
            let s: Vec<String> = c.sources.iter().map(|(j, _)| (j + 1).to_string()).collect();
            format!(
                "the coupling of joint {} to joint{} {}",
                c.joint + 1,
                if s.len() > 1 { "s" } else { "" },
                s.join(" and ")
            )
        })
        .collect();
    each.join(", ")
}

/// Directions (physical units) of the null space of the fit `sub` at `params` that the couplings
/// make: the part of that null space which the same rows determine once every coupled joint is
/// moved on its own (by a fixed offset of up to ±0.3 rad or m per row, so that it no longer follows
/// its sources), with the fit's own rank decision.
fn coupling_directions(
    model: &Model,
    params: &KinematicParams,
    obs: &Observations,
    sub: &Subspace,
    layout: &ParamLayout,
) -> Vec<DVector<f64>> {
    let p = layout.len();
    let n = model.nq();
    let mut free = obs.clone();
    for r in 0..free.len() {
        for c in model.couplings().list() {
            // A fixed, well spread offset per row and joint (golden-ratio sequence in [-0.3, 0.3]).
            let u = ((r * n + c.joint) as f64 * 0.618_033_988_749_895).fract();
            free.q[r * n + c.joint] += 0.6 * u - 0.3;
        }
    }
    let mut problem =
        crate::fit::problem::KinematicProblem::new(model, &free, params.clone(), (0..p).collect());
    let group = vec![0; free.len()];
    let parts = problem.group_parts(&sub.scales, &group, 1);
    let r = crate::linalg::stacked_r_factor(&parts[0].factors, p);
    let m = free.len() * free.dim();
    let decoupled = Subspace::from_factor(&r, &sub.scales, sub.rtol, sub.floor, m);
    // The coupled fit's null directions with their decoupled-null part removed.
    let null = sub.v.columns(sub.rank, p - sub.rank).into_owned();
    let dnull = decoupled
        .v
        .columns(decoupled.rank, p - decoupled.rank)
        .into_owned();
    let rest = &null - &dnull * (dnull.transpose() * &null);
    let extra = decoupled.rank.saturating_sub(sub.rank);
    if extra == 0 {
        return Vec::new();
    }
    let svd = rest.svd(true, false);
    let u = svd.u.expect("asked for U");
    let mut order: Vec<usize> = (0..svd.singular_values.len()).collect();
    order.sort_by(|&a, &b| svd.singular_values[b].total_cmp(&svd.singular_values[a]));
    order
        .into_iter()
        .take(extra)
        .map(|c| {
            let s = u.column(c);
            DVector::from_fn(p, |k, _| s[k] * sub.scales[k])
        })
        .collect()
}

fn joint_range(from: usize, to: usize) -> String {
    if from == to {
        format!("joint {from}")
    } else {
        format!("joints {from}–{to}")
    }
}

/// Names the null space of the full-parameter problem at `params`.
///
/// `gram` is the column-scaled normal matrix `D JᵀJ D` of all [`ParamLayout`] parameters at `params`
/// (as [`crate::lm::LmWorkspace::gram`] holds it after a solve) and `sub` the SVD split of `J D`
/// ([`Subspace::analyze`]); `obs` the rows (to say which joints do not move).
pub fn describe_null_space(
    model: &Model,
    params: &KinematicParams,
    gram: &DMatrix<f64>,
    sub: &Subspace,
    obs: &Observations,
) -> NullSpaceReport {
    let layout = ParamLayout::for_params(model, params, obs.ext.params.clone());
    let p = layout.len();
    assert_eq!(gram.ncols(), p, "the normal matrix of all parameters");
    let k = p - sub.rank;
    let null = sub.v.columns(sub.rank, k).into_owned();
    let identifiable_alone: Vec<bool> = (0..p).map(|c| null.row(c).norm() <= IN_NULL_TOL).collect();
    if k == 0 {
        return NullSpaceReport {
            dimension: 0,
            directions: Vec::new(),
            summary: Vec::new(),
            data_specific: Vec::new(),
            identifiable_alone,
        };
    }
    let bt_cols = layout.base_and_target();
    let gbt = DMatrix::from_fn(bt_cols.len(), bt_cols.len(), |i, j| {
        gram[(bt_cols[i], bt_cols[j])]
    });
    let mut namer = Namer {
        layout: &layout,
        scales: &sub.scales,
        null,
        gram,
        bt_chol: gbt.cholesky(),
        bt_cols,
        explained: Vec::new(),
        directions: Vec::new(),
    };
    let n = model.nq();
    // Current screws S'ᵢ = Ad(Gᵢ) Sᵢ (base frame).
    let screws: Vec<Vector6<f64>> = model
        .joints()
        .iter()
        .zip(&params.joint_error)
        .map(|(j, g)| adjoint_apply(g, &j.screw))
        .collect();
    let set_twist = |a: &mut DVector<f64>, i: usize, xi: &Vector6<f64>| {
        let k0 = layout.joint_twist(i);
        for c in 0..6 {
            a[k0 + c] = xi[c];
        }
    };
    let mut summary = Vec::new();
    let mut data_specific = Vec::new();

    // 1. Error twists that leave a joint's own axis unchanged.
    let mut own = Vec::new();
    for (i, joint) in model.joints().iter().enumerate() {
        let s = screws[i];
        let w = nalgebra::Vector3::new(s[0], s[1], s[2]);
        let cands: Vec<(Vector6<f64>, &str)> = if joint.kind == JointKind::Prismatic {
            let u = nalgebra::Vector3::new(s[3], s[4], s[5]);
            let mut c = vec![(
                Vector6::new(u.x, u.y, u.z, 0.0, 0.0, 0.0),
                "rotates the axis about its own direction",
            )];
            for e in 0..3 {
                let mut t = Vector6::zeros();
                t[3 + e] = 1.0;
                c.push((t, "translates the axis"));
            }
            c
        } else {
            vec![
                (s, "rotates the axis about itself"),
                (
                    Vector6::new(0.0, 0.0, 0.0, w.x, w.y, w.z),
                    "slides the axis along itself",
                ),
            ]
        };
        let mut count = 0;
        for (xi, what) in cands {
            let mut a = DVector::zeros(p);
            set_twist(&mut a, i, &xi);
            if namer.offer(
                &a,
                NullKind::OwnAxis { joint: i + 1 },
                format!(
                    "joint {}: an error twist that {what} leaves the axis unchanged, so it has no effect",
                    i + 1
                ),
            ) {
                count += 1;
            }
        }
        if count > 0 {
            own.push((i + 1, count));
        }
    }
    if !own.is_empty() {
        let total: usize = own.iter().map(|(_, c)| c).sum();
        let joints: Vec<String> = own.iter().map(|(j, _)| j.to_string()).collect();
        summary.push(format!(
            "{total}: rotating a joint's axis about itself or sliding it along itself changes nothing \
             (joints {})",
            joints.join(", ")
        ));
    }

    // 2. Zero offsets: δqᵢ = 1 with ξⱼ = −S'ᵢ for j > i, base and target fitted.
    let mut zero = Vec::new();
    for i in 0..n {
        let mut a = DVector::zeros(p);
        a[layout.zero_offset(i)] = 1.0;
        for j in i + 1..n {
            set_twist(&mut a, j, &(-screws[i]));
        }
        namer.absorb(&mut a);
        let motion = if layout.prismatic[i] {
            "sliding"
        } else {
            "turning"
        };
        let what = if i + 1 < n {
            format!(
                "{motion} the axes of {} and the target about joint {}'s axis; it is not separable from \
                 their error twists and the target offset",
                joint_range(i + 2, n),
                i + 1
            )
        } else {
            format!(
                "{motion} the target about joint {}'s axis; the target offset absorbs it",
                i + 1
            )
        };
        if namer.offer(
            &a,
            NullKind::ZeroOffset { joint: i + 1 },
            format!("joint {} zero offset: the same as {what}", i + 1),
        ) {
            zero.push(i + 1);
        }
    }
    if !zero.is_empty() {
        let joints: Vec<String> = zero.iter().map(|j| j.to_string()).collect();
        summary.push(format!(
            "{}: the zero offset of joints {} — each is the same as turning all later axes and the target \
             about that joint's axis",
            zero.len(),
            joints.join(", ")
        ));
    }

    // 3. Base transform against a common error twist of all axes.
    let mut base = 0;
    for c in 0..6 {
        let mut a = DVector::zeros(p);
        let mut e = Vector6::zeros();
        e[c] = 1.0;
        for j in 0..n {
            set_twist(&mut a, j, &e);
        }
        namer.absorb(&mut a);
        if namer.offer(
            &a,
            NullKind::BaseGauge,
            format!(
                "base twist {}: moving every joint axis by the same error twist is the same as moving the \
                 tracker-to-base transform",
                TWIST_COMPONENTS[c]
            ),
        ) {
            base += 1;
        }
    }
    if base > 0 {
        summary.push(format!(
            "{base}: the tracker-to-base transform against a common error twist of all joint axes (the split \
             between them is a convention; predictions do not depend on it)"
        ));
    }

    // 3b. What the couplings make inseparable: the directions that would be determined, at the same
    // poses, if every coupled joint moved on its own (structural: no pose set moves it so).
    if !model.couplings().is_empty() {
        let found = coupling_directions(model, params, obs, sub, &layout);
        let joints = coupling_words(model);
        let mut count = 0;
        for a in found {
            if namer.offer(
                &a,
                NullKind::Coupling {
                    joint: model.couplings().list()[0].joint + 1,
                },
                format!(
                    "a combination that {joints} makes inseparable: it would be determined if the \
                     coupled joint moved on its own"
                ),
            ) {
                count += 1;
            }
        }
        if count > 0 {
            // Which parameters they involve (the share of each scaled unit parameter in them).
            let dirs: Vec<&NullDirection> = namer
                .directions
                .iter()
                .filter(|d| matches!(d.kind, NullKind::Coupling { .. }))
                .collect();
            let mut names: Vec<String> = Vec::new();
            for d in &dirs {
                for (name, v) in d.components.iter().take(3) {
                    if v.abs() > 0.3 && !names.contains(name) {
                        names.push(name.clone());
                    }
                }
            }
            names.truncate(6);
            summary.push(format!(
                "{count}: combinations {joints} makes inseparable, whatever the poses (the coupled \
                 joint never moves on its own), mostly of {}",
                names.join(", ")
            ));
        }
    }

    // 4. Data-specific: a joint's twist components absorbed by base and target.
    for i in 0..n {
        let mut comps = Vec::new();
        for c in 0..6 {
            let mut a = DVector::zeros(p);
            a[layout.joint_twist(i) + c] = 1.0;
            namer.absorb(&mut a);
            if namer.offer(
                &a,
                NullKind::AbsorbedByBase { joint: i + 1 },
                format!(
                    "joint {} twist {}: absorbed by the tracker-to-base transform and the target offset in \
                     this pose set",
                    i + 1,
                    TWIST_COMPONENTS[c]
                ),
            ) {
                comps.push(TWIST_COMPONENTS[c]);
            }
        }
        if !comps.is_empty() {
            let qs: Vec<f64> = (0..obs.len()).map(|r| obs.q_row(r)[i]).collect();
            let (lo, hi) = qs
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| {
                    (l.min(v), h.max(v))
                });
            let why = if hi - lo < 1e-6 {
                format!(
                    "joint {} does not move (q{} = {lo} in every row)",
                    i + 1,
                    i + 1
                )
            } else {
                format!(
                    "joint {} moves too little or in too few combinations (q{} from {lo:.4} to {hi:.4})",
                    i + 1,
                    i + 1
                )
            };
            data_specific.push(format!(
                "{}: joint {}'s error twist ({}) cannot be told apart from the tracker-to-base transform and \
                 the target offset: {why}",
                comps.len(),
                i + 1,
                comps.join(", ")
            ));
            for d in namer
                .directions
                .iter_mut()
                .filter(|d| d.kind == NullKind::AbsorbedByBase { joint: i + 1 })
            {
                d.description = format!("{} ({why})", d.description);
            }
        }
    }

    // 5. Whatever is left: combinations of named parameters.
    let left = k - namer.explained.len();
    if left > 0 {
        let mut rest = namer.null.clone();
        for e in &namer.explained {
            let c = e.tr_mul(&rest);
            rest -= e * c;
        }
        let svd = rest.svd(true, false);
        let u = svd.u.expect("asked for U");
        let mut order: Vec<usize> = (0..svd.singular_values.len()).collect();
        order.sort_by(|&a, &b| svd.singular_values[b].total_cmp(&svd.singular_values[a]));
        let basis: Vec<DVector<f64>> = order
            .iter()
            .take(left)
            .map(|&c| u.column(c).into_owned())
            .collect();
        // Which parameters the undetermined subspace involves: the length of each scaled unit
        // parameter's projection onto it (1 = entirely undetermined).
        let mut involved: Vec<(usize, f64)> = (0..p)
            .map(|q| (q, basis.iter().map(|b| b[q] * b[q]).sum::<f64>().sqrt()))
            .filter(|(_, f)| *f > 0.2)
            .collect();
        involved.sort_by(|a, b| b.1.total_cmp(&a.1));
        let words: Vec<String> = involved
            .iter()
            .take(6)
            .map(|(q, f)| format!("{} ({f:.2})", layout.name(*q)))
            .collect();
        data_specific.push(format!(
            "{left}: combinations this pose set does not determine, mostly of {} (in parentheses: the \
             share of each parameter that lies in them)",
            words.join(", ")
        ));
        for s in basis {
            let comps = components(&layout, &sub.scales, &s);
            let terms: Vec<String> = comps
                .iter()
                .map(|(name, v)| format!("{v:+.3} × {name}"))
                .collect();
            namer.directions.push(NullDirection {
                kind: NullKind::Other,
                description: format!(
                    "the combination {} is not determined by this pose set",
                    terms.join(" ")
                ),
                components: comps,
            });
        }
    }
    summary.extend(data_specific.iter().cloned());
    NullSpaceReport {
        dimension: k,
        directions: namer.directions,
        summary,
        data_specific,
        identifiable_alone,
    }
}
