//! A serial chain prepared for fast evaluation: the nominal robot with thermal growth (joint origins
//! affine in `ΔT`) and, optionally, kinematic errors folded into its joint origins. The geometry every
//! stage of the truth ([`super::Truth`]) evaluates; see [`super::kinematic_offsets`] (the evaluation
//! scheme) and [`super::thermal_drift`] (the growth).

use crate::error::Result;
use crate::lie::{Pose, exp_twist, pose_from};
use crate::model::Model;
use nalgebra::{Matrix3, Vector3, Vector6};

fn vec6(a: &[f64; 6]) -> Vector6<f64> {
    Vector6::from_column_slice(a)
}

/// One joint of a [`Chain`]: local axis, folded rotation terms and a temperature-affine origin.
#[derive(Clone, Copy, Debug)]
pub(crate) struct ChainJoint {
    /// Revolute or continuous (true) vs prismatic.
    pub rotational: bool,
    /// Unit axis in the joint frame.
    pub axis: Vector3<f64>,
    /// Rodrigues terms of the origin rotation and axis (see [`crate::model::Joint::rotation_terms`]).
    pub terms: [Matrix3<f64>; 3],
    /// Origin rotation (used by prismatic joints).
    pub origin_rot: Matrix3<f64>,
    /// Origin translation at `T_ref` (m), in the previous joint frame.
    pub p0: Vector3<f64>,
    /// Change of the origin translation per kelvin (m/K).
    pub dp: Vector3<f64>,
    /// `Some((k, σ))` for a hinge about `σ eₖ` (a coordinate axis, `σ = ±1`) at the previous frame's
    /// origin with no origin rotation or translation (the deflection hinges of
    /// [`super::link_deflection`]): evaluated by turning two columns of the frame, the same numbers as
    /// the general product without its multiplications by 0 and 1.
    pub coordinate_hinge: Option<(usize, f64)>,
}

/// A serial chain prepared for evaluation: optional base pose, joint origins affine in `ΔT`, flange
/// offset affine in `ΔT`. Evaluates without allocating.
#[derive(Clone, Debug, Default)]
pub(crate) struct Chain {
    /// Pose of the chain's root in the base frame (`None` = identity, keeping nominal results exact).
    pub base: Option<Pose>,
    /// Joints from base to tip.
    pub joints: Vec<ChainJoint>,
    /// Flange rotation in the last joint frame.
    pub flange_rot: Matrix3<f64>,
    /// Flange translation in the last joint frame at `T_ref` (m).
    pub flange_p0: Vector3<f64>,
    /// Change of the flange translation per kelvin (m/K).
    pub flange_dp: Vector3<f64>,
}

/// Growth per kelvin of each joint's home origin, `g[i]` (base frame, m/K), and of the flange origin,
/// for per-link coefficients `alpha` (links 0 … n); all zero without thermal drift.
fn growth(model: &Model, alpha: Option<&[f64]>) -> (Vec<Vector3<f64>>, Vector3<f64>) {
    let a = |k: usize| alpha.map_or(0.0, |al| al[k]);
    let mut g = Vec::with_capacity(model.nq());
    let mut acc = Vector3::zeros();
    let mut r_prev = Matrix3::identity();
    for (k, j) in model.joints().iter().enumerate() {
        acc += r_prev * j.origin.translation.vector * a(k);
        g.push(acc);
        r_prev = *j.home.rotation.matrix();
    }
    let gf = acc + r_prev * model.flange_offset().translation.vector * a(model.nq());
    (g, gf)
}

/// Largest angle (rad) [`small_sin_cos`] takes its series for.
const SMALL_ANGLE_RAD: f64 = 1e-2;

/// `(sin x, cos x)`: for `|x| ≤` [`SMALL_ANGLE_RAD`] (the deflection hinges turn by 10⁻⁴ rad) the
/// Taylor series to degree 7 and 8, whose next terms are below 3·10⁻²² relative (the rounding of the
/// few operations stays within about an ulp); beyond it [`crate::trig::sin_cos`].
#[inline]
fn small_sin_cos(x: f64) -> (f64, f64) {
    if x.abs() > SMALL_ANGLE_RAD {
        return crate::trig::sin_cos(x);
    }
    let x2 = x * x;
    let s = x + x * x2 * (-1.0 / 6.0 + x2 * (1.0 / 120.0 + x2 * (-1.0 / 5040.0)));
    let c = 1.0 + x2 * (-0.5 + x2 * (1.0 / 24.0 + x2 * (-1.0 / 720.0 + x2 * (1.0 / 40320.0))));
    (s, c)
}

impl Chain {
    /// The nominal chain, with link growth `alpha` (1/K, links 0 … n) when given. At `ΔT = 0` it
    /// evaluates exactly like [`crate::forward_kinematics`].
    pub fn grown(model: &Model, alpha: Option<&[f64]>) -> Chain {
        let a = |k: usize| alpha.map_or(0.0, |al| al[k]);
        let joints = model
            .joints()
            .iter()
            .enumerate()
            .map(|(k, j)| ChainJoint {
                rotational: j.kind.is_rotational(),
                axis: j.axis,
                terms: j.rotation_terms,
                origin_rot: *j.origin.rotation.matrix(),
                p0: j.origin.translation.vector,
                dp: j.origin.translation.vector * a(k),
                coordinate_hinge: None,
            })
            .collect();
        let f = &model.flange_offset();
        Chain {
            base: None,
            joints,
            flange_rot: *f.rotation.matrix(),
            flange_p0: f.translation.vector,
            flange_dp: f.translation.vector * a(model.nq()),
        }
    }

    /// The real chain: kinematic errors (per-joint error twists `[ω; v]`, base and tool error twists,
    /// see [`super::kinematic_offsets`]) applied to the chain grown with `alpha`. The lengths must fit
    /// the model (checked by the caller).
    pub fn real(
        model: &Model,
        alpha: Option<&[f64]>,
        joint_twists: &[[f64; 6]],
        base_twist: &[f64; 6],
        tool_twist: &[f64; 6],
    ) -> Chain {
        let (g, g_flange) = growth(model, alpha);
        let mut prev_r = Matrix3::identity();
        let mut prev_h = Vector3::zeros();
        let mut prev_g = Vector3::zeros();
        let mut joints = Vec::with_capacity(model.nq());
        for ((j, xi), gi) in model.joints().iter().zip(joint_twists).zip(&g) {
            let e = exp_twist(&vec6(xi));
            let re = e.rotation.matrix();
            let r = re * j.home.rotation.matrix();
            let h = re * j.home.translation.vector + e.translation.vector;
            let gg = re * gi;
            let origin_rot = prev_r.transpose() * r;
            let p0 = prev_r.transpose() * (h - prev_h);
            let dp = prev_r.transpose() * (gg - prev_g);
            let origin = pose_from(origin_rot, p0);
            joints.push(ChainJoint {
                rotational: j.kind.is_rotational(),
                axis: j.axis,
                terms: crate::model::Joint::rotation_terms_for(&origin, &j.axis),
                origin_rot,
                p0,
                dp,
                coordinate_hinge: None,
            });
            (prev_r, prev_h, prev_g) = (r, h, gg);
        }
        let x = exp_twist(&vec6(tool_twist));
        let m = &model.home_flange();
        let rm = m.rotation.matrix();
        let flange_rot = prev_r.transpose() * rm * x.rotation.matrix();
        let flange_p0 =
            prev_r.transpose() * (rm * x.translation.vector + m.translation.vector - prev_h);
        let flange_dp = prev_r.transpose() * (g_flange - prev_g);
        Chain {
            base: Some(exp_twist(&vec6(base_twist))),
            joints,
            flange_rot,
            flange_p0,
            flange_dp,
        }
    }

    /// Number of joints.
    #[inline]
    pub fn nq(&self) -> usize {
        self.joints.len()
    }

    /// This chain at temperature offset `dt` (K) as a [`Model`] of the real robot: `nominal`'s names,
    /// joint kinds, limits and inertials (masses, centres of mass and inertia tensors stay in their
    /// joint frames), with the chain's joint origins `Oᵢ'(ΔT)` (the base pose folded into the first
    /// origin, so the model's base frame is still the nominal base frame), flange offset, and the
    /// derived home poses and screw axes. Its forward kinematics equal [`Chain::eval`] at `dt` (up to
    /// rounding; a test checks it). `nominal` must be the model the chain was made from.
    pub fn model_at(&self, nominal: &Model, dt: f64) -> Result<Model> {
        let mut parts = nominal.to_parts();
        for (k, (joint, cj)) in parts.joints.iter_mut().zip(&self.joints).enumerate() {
            let local = pose_from(cj.origin_rot, cj.p0 + cj.dp * dt);
            joint.origin = match (k, &self.base) {
                (0, Some(b)) => b * local,
                _ => local,
            };
        }
        parts.flange_offset = pose_from(self.flange_rot, self.flange_p0 + self.flange_dp * dt);
        Model::new(parts)
    }

    /// Joint frames `T_base_joint[i]` into `poses` and the flange pose `T_base_flange` (m), at joint
    /// angles `angles` (rad or m) and temperature offset `dt` (K).
    #[inline]
    pub fn eval(&self, angles: &[f64], dt: f64, poses: &mut [Pose]) -> Pose {
        debug_assert_eq!(angles.len(), self.nq());
        let (mut r, mut p) = match &self.base {
            Some(b) => (*b.rotation.matrix(), b.translation.vector),
            None => (Matrix3::identity(), Vector3::zeros()),
        };
        // Same arithmetic, in the same order, as `forward_kinematics`: bit-identical at dt = 0.
        for ((joint, &qi), out) in self.joints.iter().zip(angles).zip(poses.iter_mut()) {
            if let Some((k, sign)) = joint.coordinate_hinge {
                // r · Rot(σ eₖ, q): columns i, j (the other two, cyclic after k) turn by σ q.
                let (s, c) = small_sin_cos(sign * qi);
                let (i, j) = ((k + 1) % 3, (k + 2) % 3);
                let (ci, cj) = (r.column(i).into_owned(), r.column(j).into_owned());
                r.set_column(i, &(ci * c + cj * s));
                r.set_column(j, &(cj * c - ci * s));
                *out = pose_from(r, p);
                continue;
            }
            let po = joint.p0 + joint.dp * dt;
            p += r * po;
            if joint.rotational {
                let (s, c) = crate::trig::sin_cos(qi);
                let [k0, k1, k2] = &joint.terms;
                r *= k0 + k1 * c + k2 * s;
            } else {
                r *= joint.origin_rot;
                p += r * (joint.axis * qi);
            }
            *out = pose_from(r, p);
        }
        poses[self.nq() - 1] * pose_from(self.flange_rot, self.flange_p0 + self.flange_dp * dt)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_angle_series_is_within_an_ulp_of_std() {
        for k in 0..=2000 {
            let x = (k as f64 - 1000.0) * 1.0000001e-5; // −1e-2 … 1e-2, and 0
            let (s, c) = small_sin_cos(x);
            let (es, ec) = x.sin_cos();
            assert!(
                (s - es).abs() <= f64::EPSILON * es.abs(),
                "sin {x}: {s} vs {es}"
            );
            assert!((c - ec).abs() <= f64::EPSILON, "cos {x}: {c} vs {ec}");
        }
        assert_eq!(small_sin_cos(0.5), crate::trig::sin_cos(0.5));
    }
}
