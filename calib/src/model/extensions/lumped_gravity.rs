//! Gravity without masses: the holding torque of each joint as a linear function of the mass
//! moments that a robot without inertials (a DH table, a URDF without `<inertial>`) does not give,
//! reduced to the combinations of them that the robot's geometry lets the torque depend on.
//!
//! Body `j` (the child link of joint `j` with every link fixed to it) has mass `mⱼ` and first moment
//! `sⱼ = mⱼ rⱼ` (kg m; `rⱼ` its centre of mass in joint `j`'s frame). In the mass-moment coordinates
//! `φⱼ = (mⱼ L, sⱼ)` (kg m each; `L` the arm's length scale, [`LumpedGravity::length_m`], so that the
//! four are of one unit), a rotational joint `i` with axis `wᵢ` and origin `oᵢ` (base frame) holds
//!
//! ```text
//! τᵢ = −Σ_{j≥i} [ mⱼ (pⱼ − oᵢ) + Rⱼ sⱼ ] · uᵢ,    uᵢ = g × wᵢ,
//! ```
//!
//! (`pⱼ`, `Rⱼ` joint `j`'s frame; the torque of [`sim::statics::gravity_torques`] written in `φ`), a
//! prismatic one `τᵢ = −(wᵢ · g) Σ_{j≥i} mⱼ`. That is `τᵢ = Yᵢ(q) φ`, linear in the `4 (n − i)`
//! moments beyond the joint. Most combinations of them never show in the torque (a first moment
//! along a joint's own axis turns nothing about it; a body's mass at its origin and its
//! predecessor's first moment along the link between them add up; no torque at all about a vertical
//! first axis): the rows `Yᵢ(q)` of every configuration lie in a subspace of dimension `rᵢ`, found
//! once per robot as the right singular vectors `vᵢₖ` of `Yᵢ` stacked over [`SAMPLES`]
//! configurations drawn within the joint limits (the numerical base parameters of Gautier, 1991).
//! Then
//!
//! ```text
//! τᵢ(q) = Σₖ Gᵢₖ(q) bᵢₖ,    Gᵢₖ = Yᵢ(q) vᵢₖ / |g|  (dimensionless),    bᵢₖ = |g| vᵢₖ · φ  (N m),
//! ```
//!
//! and a joint of compliance `cᵢ` sags by `cᵢ τᵢ = Σₖ Gᵢₖ βᵢₖ` with the lumped products
//! `βᵢₖ = cᵢ bᵢₖ` (rad): what the data determine when the masses are unknown ("elastic gains" in
//! FIGAROH's words). A prismatic joint's `Gᵢₖ` is multiplied by `L`, so that its `βᵢₖ = cᵢ bᵢₖ / L`
//! is in metres.
//!
//! A payload of known mass at the flange adds its own torque, which needs no unknown moment: a
//! joint's compliance then multiplies a known torque too, and a payload mass that changes over the
//! data separates the compliance from the moments (see [`LumpedGravity::payload_torque`]).
//!
//! The estimator's own equations: they share nothing with the simulator's effect code.

use nalgebra::{DMatrix, Vector3};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use serde::{Deserialize, Serialize};
use sim::Model;

/// Configurations drawn to find the subspace of each joint's torque coefficients: seven times the
/// largest number of moments (28 for seven joints) and more, so that a coincidental dependence
/// over the draws is out of the question.
pub const SAMPLES: usize = 240;

/// Seed of the configurations drawn for the subspaces: fixed, so that a robot has one basis.
const SAMPLE_SEED: u64 = 0x6c75_6d70_6564;

/// A singular value below this share of the largest is a combination the torque never sees (the
/// exact dependencies leave values at the rounding level, about 1e-15 of the largest).
const RANK_TOLERANCE: f64 = 1e-9;

/// Moments per body: `m L, sx, sy, sz`.
pub const MOMENTS_PER_BODY: usize = 4;

/// The gravity torques of a robot without masses, as combinations of its unknown mass moments: one
/// basis per joint, stored in the model file so that `predict` builds the same regressors.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LumpedGravity {
    /// The length scale `L` (m) that puts a body's mass in the unit of its first moment: the sum of
    /// the distances between successive joint origins and the flange at the home configuration (at
    /// least 0.1 m).
    pub length_m: f64,
    /// Per joint (0-based), the combinations `vᵢₖ` of the moments beyond it that its torque depends
    /// on, largest singular value first; each has `4 (n − i)` coefficients, body `i` first, each
    /// body's `m L, sx, sy, sz` (joint frame). Empty for a joint whose torque never changes (a
    /// vertical first axis).
    pub combinations: Vec<Vec<Vec<f64>>>,
    /// Whether each joint's compliance is a parameter of its own, multiplying the known torque of
    /// the payload (the table has payload masses).
    pub payload_compliance: bool,
    /// The bending axes of link deflection without masses, each with the combinations of the
    /// moments beyond its joint that its bending moment depends on ([`LumpedGravity::with_bending`]);
    /// empty without link deflection.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub bending: Vec<BendBasis>,
}

/// The combinations `vₐₖ` of the mass moments beyond joint `joint` that the gravity moment about
/// axis `about` of its frame depends on: `Mₐ(q) = Σₖ Gₐₖ(q) bₐₖ` with the patterns
/// `Gₐₖ = Yₐ(q) vₐₖ / |g|` (dimensionless) of [`moment_coefficients`] and `bₐₖ = |g| vₐₖ · φ`
/// (N m), as for the holding torques.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BendBasis {
    /// 0-based joint.
    pub joint: usize,
    /// Axis of the joint frame: 0 = x, 1 = y, 2 = z.
    pub about: usize,
    /// The combinations, largest singular value first; `4 (n − joint)` coefficients each, ordered
    /// as in [`LumpedGravity::combinations`].
    pub combinations: Vec<Vec<f64>>,
}

impl LumpedGravity {
    /// The bases of `model`'s joints under `gravity` (base frame, m/s²); `payload_compliance` as
    /// the field.
    pub fn for_model(model: &Model, gravity: &Vector3<f64>, payload_compliance: bool) -> Self {
        let n = model.nq();
        let length_m = length_scale(model);
        let mut rows: Vec<DMatrix<f64>> = (0..n)
            .map(|i| DMatrix::zeros(SAMPLES, MOMENTS_PER_BODY * (n - i)))
            .collect();
        let mut coef = vec![0.0; MOMENTS_PER_BODY * n];
        for_each_sample(model, |s, data| {
            for (i, m) in rows.iter_mut().enumerate() {
                let out = &mut coef[..MOMENTS_PER_BODY * (n - i)];
                torque_coefficients(model.joints(), data, gravity, length_m, i, out);
                for (c, v) in out.iter().enumerate() {
                    m[(s, c)] = *v;
                }
            }
        });
        let combinations = rows.into_iter().map(row_space).collect();
        LumpedGravity {
            length_m,
            combinations,
            payload_compliance,
            bending: Vec::new(),
        }
    }

    /// These bases with those of the gravity moments about the bending axes `axes` (0-based joint,
    /// axis of its frame), drawn at the same configurations; an axis already present is kept.
    pub fn with_bending(
        mut self,
        model: &Model,
        gravity: &Vector3<f64>,
        axes: &[(usize, usize)],
    ) -> Self {
        let n = model.nq();
        let new: Vec<(usize, usize)> = axes
            .iter()
            .copied()
            .filter(|&(i, a)| {
                i < n && a < 3 && !self.bending.iter().any(|b| (b.joint, b.about) == (i, a))
            })
            .collect();
        let mut rows: Vec<DMatrix<f64>> = new
            .iter()
            .map(|&(i, _)| DMatrix::zeros(SAMPLES, MOMENTS_PER_BODY * (n - i)))
            .collect();
        let length_m = self.length_m;
        for_each_sample(model, |s, data| {
            for (m, &(i, about)) in rows.iter_mut().zip(&new) {
                let w = data.joint_poses[i].rotation * Vector3::ith(about, 1.0);
                for j in i..n {
                    let b = moment_coefficients(data, gravity, length_m, &w, i, j);
                    for (c, v) in b.iter().enumerate() {
                        m[(s, MOMENTS_PER_BODY * (j - i) + c)] = *v;
                    }
                }
            }
        });
        self.bending
            .extend(new.iter().zip(rows).map(|(&(joint, about), m)| BendBasis {
                joint,
                about,
                combinations: row_space(m),
            }));
        self
    }

    /// The basis of the bending of joint `joint` (0-based) about axis `about` of its frame, if any.
    pub fn bend_basis(&self, joint: usize, about: usize) -> Option<&BendBasis> {
        self.bending
            .iter()
            .find(|b| b.joint == joint && b.about == about)
    }

    /// The patterns `Gₐₖ` (dimensionless) of the gravity moment about `basis`'s axis at the joint
    /// frames in `frames`, into `out` (one per combination).
    pub fn bend_patterns(
        &self,
        frames: &sim::Data,
        gravity: &Vector3<f64>,
        basis: &BendBasis,
        out: &mut [f64],
    ) {
        out.fill(0.0);
        let i = basis.joint;
        let w = frames.joint_poses[i].rotation * Vector3::ith(basis.about, 1.0);
        for j in i..frames.joint_poses.len() {
            let b = moment_coefficients(frames, gravity, self.length_m, &w, i, j);
            let at = MOMENTS_PER_BODY * (j - i);
            for (o, v) in out.iter_mut().zip(&basis.combinations) {
                *o += v[at..at + MOMENTS_PER_BODY]
                    .iter()
                    .zip(&b)
                    .map(|(a, c)| a * c)
                    .sum::<f64>();
            }
        }
        let g = gravity.norm().max(f64::MIN_POSITIVE);
        out.iter_mut().for_each(|o| *o /= g);
    }

    /// The regressors of a payload of `mass_kg` in the gravity moment about the line through joint
    /// `i`'s origin along the unit vector `w` (base frame), at the frames in `frames`: its moment
    /// with the mass at the flange origin (N m), then per axis of the flange frame its moment per
    /// unit of `|g| r` (kg; `r` the unknown centre of mass, flange frame, m):
    /// `m (c − oᵢ) · u = m (p_flange − oᵢ) · u + Σₐ (|g| rₐ) m (R_flangeᵀ u)ₐ / |g|`, `u = g × w`.
    pub fn payload_moment_regressors(
        frames: &sim::Data,
        gravity: &Vector3<f64>,
        mass_kg: f64,
        w: &Vector3<f64>,
        i: usize,
    ) -> [f64; 4] {
        let u = gravity.cross(w);
        let o = frames.joint_poses[i].translation.vector;
        let local = frames.flange.rotation.inverse_transform_vector(&u);
        let g = gravity.norm().max(f64::MIN_POSITIVE);
        [
            mass_kg * (frames.flange.translation.vector - o).dot(&u),
            mass_kg * local.x / g,
            mass_kg * local.y / g,
            mass_kg * local.z / g,
        ]
    }

    /// The number of products at 0-based joint `i`.
    pub fn count(&self, i: usize) -> usize {
        self.combinations.get(i).map_or(0, Vec::len)
    }

    /// The patterns `Gᵢₖ` of joint `i` (dimensionless; times `L` for a prismatic joint) at the joint
    /// frames in `frames`, into `out` (one per combination, [`LumpedGravity::count`]).
    pub fn patterns(
        &self,
        joints: &[sim::Joint],
        frames: &sim::Data,
        gravity: &Vector3<f64>,
        i: usize,
        out: &mut [f64],
    ) {
        out.fill(0.0);
        for j in i..joints.len() {
            let b = body_coefficients(joints, frames, gravity, self.length_m, i, j);
            let at = MOMENTS_PER_BODY * (j - i);
            for (o, v) in out.iter_mut().zip(&self.combinations[i]) {
                *o += v[at..at + MOMENTS_PER_BODY]
                    .iter()
                    .zip(&b)
                    .map(|(a, c)| a * c)
                    .sum::<f64>();
            }
        }
        let scale = self.pattern_scale(&joints[i], gravity);
        out.iter_mut().for_each(|o| *o *= scale);
    }

    /// `1/|g|`, times `L` for a prismatic joint: what turns `Yᵢ vᵢₖ` into the pattern `Gᵢₖ`.
    pub fn pattern_scale(&self, joint: &sim::Joint, gravity: &Vector3<f64>) -> f64 {
        let g = gravity.norm().max(f64::MIN_POSITIVE);
        if joint.kind.is_rotational() {
            1.0 / g
        } else {
            self.length_m / g
        }
    }

    /// The holding torque (N m; N for a prismatic joint) at joint `i` of a payload of `mass_kg` at
    /// `com_m` (flange frame), from the frames in `frames`.
    pub fn payload_torque_at(
        joints: &[sim::Joint],
        frames: &sim::Data,
        gravity: &Vector3<f64>,
        mass_kg: f64,
        com_m: &[f64; 3],
        i: usize,
    ) -> f64 {
        let t = &frames.joint_poses[i];
        let w = t.rotation * joints[i].axis;
        if joints[i].kind.is_rotational() {
            let c = frames.flange * nalgebra::Point3::from(Vector3::from(*com_m));
            -mass_kg * (c.coords - t.translation.vector).dot(&gravity.cross(&w))
        } else {
            -mass_kg * w.dot(gravity)
        }
    }
}

/// The coefficients `Yᵢ` (N m per kg m; per body `m L, sx, sy, sz`, bodies `i..n`) of joint `i`'s
/// holding torque at the joint frames in `frames`, into `out` (`4 (n − i)` values).
pub fn torque_coefficients(
    joints: &[sim::Joint],
    frames: &sim::Data,
    gravity: &Vector3<f64>,
    length_m: f64,
    i: usize,
    out: &mut [f64],
) {
    for j in i..joints.len() {
        let at = MOMENTS_PER_BODY * (j - i);
        out[at..at + MOMENTS_PER_BODY]
            .copy_from_slice(&body_coefficients(joints, frames, gravity, length_m, i, j));
    }
}

/// Body `j`'s four coefficients (`m L, sx, sy, sz`; N m per kg m) in joint `i`'s holding torque
/// (`j ≥ i`), at the joint frames in `frames`: minus its moment about the joint's axis for a
/// rotational joint ([`moment_coefficients`]), minus its weight along the axis for a prismatic one.
fn body_coefficients(
    joints: &[sim::Joint],
    frames: &sim::Data,
    gravity: &Vector3<f64>,
    length_m: f64,
    i: usize,
    j: usize,
) -> [f64; MOMENTS_PER_BODY] {
    let t_i = &frames.joint_poses[i];
    let w = t_i.rotation * joints[i].axis;
    if joints[i].kind.is_rotational() {
        moment_coefficients(frames, gravity, length_m, &w, i, j).map(|c| -c)
    } else {
        [-w.dot(gravity) / length_m, 0.0, 0.0, 0.0]
    }
}

/// Body `j`'s four coefficients (`m L, sx, sy, sz`; N m per kg m) in the gravity moment about the
/// line through joint `i`'s origin along the unit vector `w` (base frame), at the joint frames in
/// `frames`: `[(pⱼ − oᵢ) · u / L, Rⱼᵀ u]` with `u = g × w`, since the moment of a weight `m g` at
/// `c` about that line is `((c − oᵢ) × m g) · w = m (c − oᵢ) · (g × w)`.
pub fn moment_coefficients(
    frames: &sim::Data,
    gravity: &Vector3<f64>,
    length_m: f64,
    w: &Vector3<f64>,
    i: usize,
    j: usize,
) -> [f64; MOMENTS_PER_BODY] {
    let u = gravity.cross(w);
    let t_i = &frames.joint_poses[i];
    let t = &frames.joint_poses[j];
    let local = t.rotation.inverse_transform_vector(&u);
    [
        (t.translation.vector - t_i.translation.vector).dot(&u) / length_m,
        local.x,
        local.y,
        local.z,
    ]
}

/// Whether the payload masses of the training rows `rows` of `table` differ: then a compliance
/// multiplies a known torque that changes over the data, and is a parameter of its own.
pub fn payload_varies(table: &sim::measurement_table::MeasurementTable, rows: &[usize]) -> bool {
    table.payload.as_ref().is_some_and(|p| {
        let first = rows.first().map_or(0.0, |&r| p[r]);
        rows.iter().any(|&r| p[r] != first)
    })
}

/// Calls `f(s, frames)` at each of the [`SAMPLES`] configurations drawn (seeded, within the joint
/// limits) for the bases, with the joint frames there.
fn for_each_sample(model: &Model, mut f: impl FnMut(usize, &sim::Data)) {
    let mut rng = StdRng::seed_from_u64(SAMPLE_SEED);
    let mut data = sim::Data::new(model);
    let mut q = vec![0.0; model.nq()];
    for s in 0..SAMPLES {
        for (v, j) in q.iter_mut().zip(model.joints()) {
            let (lo, hi) = sample_range(j);
            *v = rng.random_range(lo..=hi);
        }
        sim::kinematics::forward_kinematics(model, &mut data, &q);
        f(s, &data);
    }
}

/// The range a joint's value is drawn from: its limits, or a turn for a joint without (or with
/// wider) limits.
fn sample_range(joint: &sim::Joint) -> (f64, f64) {
    let turn = (-std::f64::consts::PI, std::f64::consts::PI);
    match &joint.limits {
        Some(l) if l.lower.is_finite() && l.upper.is_finite() && l.upper > l.lower => {
            if joint.kind.is_rotational() && l.upper - l.lower > 2.0 * std::f64::consts::PI {
                turn
            } else {
                (l.lower, l.upper)
            }
        }
        _ if joint.kind.is_rotational() => turn,
        // A prismatic joint without limits: a metre either way.
        _ => (-1.0, 1.0),
    }
}

/// `L` of [`LumpedGravity::length_m`].
fn length_scale(model: &Model) -> f64 {
    let links: f64 = model
        .joints()
        .iter()
        .skip(1)
        .map(|j| j.origin.translation.vector.norm())
        .sum();
    (links + model.flange_offset().translation.vector.norm()).max(0.1)
}

/// An orthonormal basis of the row space of `m` (its right singular vectors above
/// [`RANK_TOLERANCE`] of the largest singular value), largest first, each signed so that its
/// largest coefficient is positive.
fn row_space(m: DMatrix<f64>) -> Vec<Vec<f64>> {
    let cols = m.ncols();
    if cols == 0 {
        return Vec::new();
    }
    let svd = m.svd(false, true);
    let Some(v_t) = svd.v_t else {
        return Vec::new();
    };
    let s = &svd.singular_values;
    let largest = s.iter().copied().fold(0.0, f64::max);
    if largest <= 0.0 {
        return Vec::new();
    }
    let mut order: Vec<usize> = (0..s.len())
        .filter(|&k| s[k] > RANK_TOLERANCE * largest)
        .collect();
    order.sort_by(|&a, &b| s[b].total_cmp(&s[a]));
    order
        .into_iter()
        .map(|k| {
            let mut v: Vec<f64> = v_t.row(k).iter().copied().collect();
            let lead = v
                .iter()
                .copied()
                .fold(0.0_f64, |a, b| if b.abs() > a.abs() { b } else { a });
            if lead < 0.0 {
                v.iter_mut().for_each(|x| *x = -*x);
            }
            v
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The moment coordinates `φ` of a model's bodies, beyond joint `i`.
    fn moments(model: &Model, length_m: f64, i: usize) -> Vec<f64> {
        model.bodies()[i..]
            .iter()
            .flat_map(|b| {
                let s = b.com * b.mass;
                [b.mass * length_m, s.x, s.y, s.z]
            })
            .collect()
    }

    /// On the iiwa 7 (with its masses), the torques the patterns and the true moments give are the
    /// simulator's gravity torques at configurations the basis was not drawn from: the combinations
    /// span everything the torque depends on.
    #[test]
    fn patterns_times_true_moments_are_the_gravity_torques() {
        let model = sim::robots::load_builtin("iiwa7").unwrap();
        let g = Vector3::from(sim::statics::DEFAULT_GRAVITY);
        let lumped = LumpedGravity::for_model(&model, &g, false);
        let n = model.nq();
        // A vertical first axis: no torque, no combination. Joint 2 carries the most.
        assert_eq!(lumped.count(0), 0);
        assert!(lumped.count(1) >= lumped.count(2));
        let mut data = sim::Data::new(&model);
        let mut rng = StdRng::seed_from_u64(5);
        for _ in 0..20 {
            let q: Vec<f64> = (0..n).map(|_| rng.random_range(-2.0..2.0)).collect();
            sim::statics::gravity_torques(&model, &mut data, &q, &g, None).unwrap();
            for i in 0..n {
                let mut pat = vec![0.0; lumped.count(i)];
                lumped.patterns(model.joints(), &data, &g, i, &mut pat);
                let phi = moments(&model, lumped.length_m, i);
                let tau: f64 = lumped.combinations[i]
                    .iter()
                    .zip(&pat)
                    .map(|(v, p)| {
                        p * g.norm() * v.iter().zip(&phi).map(|(a, b)| a * b).sum::<f64>()
                    })
                    .sum();
                let truth = data.gravity_torque[i];
                assert!(
                    (tau - truth).abs() < 1e-9 * (1.0 + truth.abs()),
                    "joint {}: {tau} against {truth}",
                    i + 1
                );
            }
        }
    }

    /// The same for the bending moments: on the iiwa 7 with its masses, the bending bases of every
    /// axis across every joint, times the true moments, give the gravity moments of
    /// [`super::super::link_deflection::gravity_moments`] (an independent sum over the bodies) at
    /// configurations the bases were not drawn from.
    #[test]
    fn bending_patterns_times_true_moments_are_the_gravity_moments() {
        let model = sim::robots::load_builtin("iiwa7").unwrap();
        let g = Vector3::from(sim::statics::DEFAULT_GRAVITY);
        let n = model.nq();
        let axes: Vec<(usize, usize)> = (0..n).flat_map(|i| (0..3).map(move |a| (i, a))).collect();
        let lumped = LumpedGravity::for_model(&model, &g, false).with_bending(&model, &g, &axes);
        assert_eq!(lumped.bending.len(), 3 * n);
        // Adding axes already there changes nothing.
        let again = lumped.clone().with_bending(&model, &g, &axes[..4]);
        assert_eq!(again, lumped);
        let mut data = sim::Data::new(&model);
        let mut moment = vec![Vector3::zeros(); n];
        let mut rng = StdRng::seed_from_u64(6);
        for _ in 0..20 {
            let q: Vec<f64> = (0..n).map(|_| rng.random_range(-2.0..2.0)).collect();
            sim::kinematics::forward_kinematics(&model, &mut data, &q);
            super::super::link_deflection::gravity_moments(&model, &data, &g, None, &mut moment);
            for basis in &lumped.bending {
                let mut pat = vec![0.0; basis.combinations.len()];
                lumped.bend_patterns(&data, &g, basis, &mut pat);
                let phi = moments(&model, lumped.length_m, basis.joint);
                let m: f64 = basis
                    .combinations
                    .iter()
                    .zip(&pat)
                    .map(|(v, p)| {
                        p * g.norm() * v.iter().zip(&phi).map(|(a, b)| a * b).sum::<f64>()
                    })
                    .sum();
                let truth = moment[basis.joint][basis.about];
                assert!(
                    (m - truth).abs() < 1e-9 * (1.0 + truth.abs()),
                    "joint {} about {}: {m} against {truth}",
                    basis.joint + 1,
                    basis.about
                );
            }
            // A payload's share: its regressors times (1, |g| r) are what it adds to the moments.
            let pl = sim::statics::Payload {
                mass: 2.3,
                com: [0.02, -0.01, 0.07],
            };
            let mut with = vec![Vector3::zeros(); n];
            super::super::link_deflection::gravity_moments(&model, &data, &g, Some(&pl), &mut with);
            for i in 0..n {
                for about in 0..3 {
                    let w = data.joint_poses[i].rotation * Vector3::ith(about, 1.0);
                    let r = LumpedGravity::payload_moment_regressors(&data, &g, pl.mass, &w, i);
                    let share = r[0] + (0..3).map(|a| r[1 + a] * g.norm() * pl.com[a]).sum::<f64>();
                    let truth = with[i][about] - moment[i][about];
                    assert!(
                        (share - truth).abs() < 1e-9 * (1.0 + truth.abs()),
                        "payload at joint {} about {about}: {share} against {truth}",
                        i + 1
                    );
                }
            }
        }
    }

    /// Hand-derived: a planar two-link arm about horizontal axes (y) has at joint 2 exactly two
    /// combinations (the first moment of link 2 along its length and across it in the vertical
    /// plane), at joint 1 four (link 1's two and link 2's two; link 2's mass, at the end of link 1,
    /// adds to link 1's first moment along it, `s₁ₓ + m₂ l₁`, and each link's mass at its own joint
    /// has no lever).
    #[test]
    fn a_planar_two_link_arm_has_the_hand_counted_combinations() {
        let urdf = r#"<robot name="two">
          <link name="base"/>
          <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
            <axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
          <link name="l1"/>
          <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="1 0 0"/>
            <axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
          <link name="l2"/>
          <joint name="tool" type="fixed"><parent link="l2"/><child link="tip"/><origin xyz="0.5 0 0"/></joint>
          <link name="tip"/>
        </robot>"#;
        let model = sim::urdf::load_str(urdf, "two", &sim::urdf::ChainSpec::default()).unwrap();
        let g = Vector3::from(sim::statics::DEFAULT_GRAVITY);
        let lumped = LumpedGravity::for_model(&model, &g, false);
        assert_eq!(lumped.count(1), 2);
        assert_eq!(lumped.count(0), 4);
        assert!((lumped.length_m - 1.5).abs() < 1e-12);
    }
}
