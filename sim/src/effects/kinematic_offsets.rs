//! Kinematic offsets: the geometric errors of the real robot, in adjoint (error-twist) form.
//!
//! # Model
//!
//! The nominal robot is `T(q) = exp([S₁]q₁) ⋯ exp([Sₙ]qₙ) M` (base frame, see [`crate`]). The real robot
//! differs by
//!
//! * one error twist per joint, `ξᵢ = [ω; v] ∈ R⁶` (base frame at q = 0; rad, m): the real screw is
//!   `Sᵢ' = Ad(exp([ξᵢ])) Sᵢ`, the nominal axis moved by the small rigid motion `exp([ξᵢ])`;
//! * one zero offset per joint, `δqᵢ` (rad; m for prismatic joints): the real joint angle is `qᵢ + δqᵢ`;
//! * a base error twist `ξ_base` (applied on the left, in the base frame) and a tool error twist
//!   `ξ_tool` (applied on the right of `M`, in the flange frame):
//!
//! ```text
//! T_base_flange(q) = exp([ξ_base]) exp([S₁'](q₁ + δq₁)) ⋯ exp([Sₙ'](qₙ + δqₙ)) M exp([ξ_tool])
//! ```
//!
//! With thermal drift ([`super::thermal_drift`]), `Sᵢ` and `M` are those of the thermally grown chain
//! (thermal first, then the kinematic errors on top), and the angles also carry the thermal zero drift.
//!
//! # Evaluation
//!
//! Writing `Sᵢ' = Ad(Hᵢ') Aᵢ` with `Hᵢ' = exp([ξᵢ]) Hᵢ` (`Hᵢ` the home pose of joint frame `i`, `Aᵢ` its
//! local unit screw), `exp([Sᵢ']θ) = Hᵢ' exp([Aᵢ]θ) Hᵢ'⁻¹`, so the product collapses into a chain of
//! local joint frames with origins `Oᵢ' = H'ᵢ₋₁⁻¹ Hᵢ'` and flange offset `H'ₙ⁻¹ M exp([ξ_tool])`: the same
//! cheap recursion as [`crate::forward_kinematics`], prepared once per [`super::Effects`]. Thermal
//! growth moves the origins of `Hᵢ` by `ΔT gᵢ` (`gᵢ` the growth of joint `i`'s home origin per kelvin,
//! base frame) and leaves the rotations alone, so each prepared origin is exactly `p₀ + ΔT dp`.
//!
//! The base frame is the nominal robot's base (the frame the tracker-to-base transform refers to).

use crate::error::{Result, SimError};
use crate::lie::{Pose, adjoint_apply, exp_twist, pose_from};
use crate::model::Model;
use nalgebra::{Matrix3, Vector3, Vector6};

/// Largest accepted rotation part `|ω|` of an error twist and largest zero offset (rad): these are
/// errors, not poses; more than 0.5 rad is almost surely a value in degrees.
pub const MAX_ROTATION_ERROR_RAD: f64 = 0.5;
/// Largest accepted translation part `|v|` of an error twist (m); more is almost surely millimetres.
pub const MAX_TRANSLATION_ERROR_M: f64 = 1.0;

const EFFECT: &str = "kinematic_offsets";

fn bad(field: impl Into<String>, value: impl ToString, problem: impl Into<String>) -> SimError {
    SimError::BadEffect {
        effect: EFFECT,
        field: field.into(),
        value: value.to_string(),
        problem: problem.into(),
    }
}

/// Geometric errors of the real robot (see the module docs for the model).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "KinematicOffsetsSpec")]
pub struct KinematicOffsets {
    /// Error twist `ξᵢ = [ω; v]` of each joint (base frame at q = 0; rad, m).
    joint_twists: Vec<[f64; 6]>,
    /// Zero offset `δqᵢ` of each joint (rad; m for prismatic joints).
    zero_offsets: Vec<f64>,
    /// Base error twist `ξ_base = [ω; v]` (base frame; rad, m).
    base_twist: [f64; 6],
    /// Tool error twist `ξ_tool = [ω; v]` (flange frame; rad, m).
    tool_twist: [f64; 6],
}

/// Serialized form of [`KinematicOffsets`]; `zero_offsets`, `base_twist` and `tool_twist` default to 0.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct KinematicOffsetsSpec {
    joint_twists: Vec<[f64; 6]>,
    #[serde(default)]
    zero_offsets: Option<Vec<f64>>,
    #[serde(default)]
    base_twist: [f64; 6],
    #[serde(default)]
    tool_twist: [f64; 6],
}

impl TryFrom<KinematicOffsetsSpec> for KinematicOffsets {
    type Error = SimError;
    fn try_from(s: KinematicOffsetsSpec) -> Result<Self> {
        let n = s.joint_twists.len();
        KinematicOffsets::new(
            s.joint_twists,
            s.zero_offsets.unwrap_or_else(|| vec![0.0; n]),
            s.base_twist,
            s.tool_twist,
        )
    }
}

fn check_twist(field: &str, xi: &[f64; 6]) -> Result<()> {
    for (k, v) in xi.iter().enumerate() {
        if !v.is_finite() {
            return Err(bad(format!("{field}[{k}]"), v, "not finite"));
        }
    }
    let w = Vector3::new(xi[0], xi[1], xi[2]).norm();
    if w > MAX_ROTATION_ERROR_RAD {
        return Err(bad(
            format!("{field} |ω|"),
            w,
            format!(
                "rotation error above {MAX_ROTATION_ERROR_RAD} rad; give it in rad, not degrees"
            ),
        ));
    }
    let v = Vector3::new(xi[3], xi[4], xi[5]).norm();
    if v > MAX_TRANSLATION_ERROR_M {
        return Err(bad(
            format!("{field} |v|"),
            v,
            format!("translation error above {MAX_TRANSLATION_ERROR_M} m; give it in m, not mm"),
        ));
    }
    Ok(())
}

fn vec6(a: &[f64; 6]) -> Vector6<f64> {
    Vector6::from_column_slice(a)
}

impl KinematicOffsets {
    /// Geometric errors from per-joint error twists `[ω; v]` (base frame at q = 0; rad, m), per-joint
    /// zero offsets (rad or m), and base and tool error twists. Refuses non-finite values, unequal
    /// lengths, `|ω|` or zero offsets above [`MAX_ROTATION_ERROR_RAD`] and `|v|` above
    /// [`MAX_TRANSLATION_ERROR_M`].
    pub fn new(
        joint_twists: Vec<[f64; 6]>,
        zero_offsets: Vec<f64>,
        base_twist: [f64; 6],
        tool_twist: [f64; 6],
    ) -> Result<Self> {
        if zero_offsets.len() != joint_twists.len() {
            return Err(bad(
                "zero_offsets",
                format!("{} entries", zero_offsets.len()),
                format!(
                    "needs one per joint, as joint_twists ({})",
                    joint_twists.len()
                ),
            ));
        }
        for (i, xi) in joint_twists.iter().enumerate() {
            check_twist(&format!("joint_twists[{i}]"), xi)?;
        }
        for (i, &d) in zero_offsets.iter().enumerate() {
            if !d.is_finite() {
                return Err(bad(format!("zero_offsets[{i}]"), d, "not finite"));
            }
            if d.abs() > MAX_ROTATION_ERROR_RAD {
                return Err(bad(
                    format!("zero_offsets[{i}]"),
                    d,
                    format!(
                        "offset above {MAX_ROTATION_ERROR_RAD} rad; give it in rad, not degrees"
                    ),
                ));
            }
        }
        check_twist("base_twist", &base_twist)?;
        check_twist("tool_twist", &tool_twist)?;
        Ok(KinematicOffsets {
            joint_twists,
            zero_offsets,
            base_twist,
            tool_twist,
        })
    }

    /// No geometric error on an `nq`-joint robot.
    pub fn zero(nq: usize) -> Self {
        KinematicOffsets {
            joint_twists: vec![[0.0; 6]; nq],
            zero_offsets: vec![0.0; nq],
            base_twist: [0.0; 6],
            tool_twist: [0.0; 6],
        }
    }

    /// Error twist of each joint `[ω; v]` (base frame at q = 0; rad, m).
    pub fn joint_twists(&self) -> &[[f64; 6]] {
        &self.joint_twists
    }

    /// Zero offset of each joint (rad or m).
    pub fn zero_offsets(&self) -> &[f64] {
        &self.zero_offsets
    }

    /// Base error twist `[ω; v]` (base frame; rad, m).
    pub fn base_twist(&self) -> [f64; 6] {
        self.base_twist
    }

    /// Tool error twist `[ω; v]` (flange frame; rad, m).
    pub fn tool_twist(&self) -> [f64; 6] {
        self.tool_twist
    }

    /// Checks that the lengths fit a robot with `nq` joints.
    pub fn check_fits(&self, nq: usize) -> Result<()> {
        if self.joint_twists.len() != nq {
            return Err(bad(
                "joint_twists",
                format!("{} entries", self.joint_twists.len()),
                format!("the robot has {nq} joints"),
            ));
        }
        Ok(())
    }

    /// The real screws `Sᵢ' = Ad(exp([ξᵢ])) Sᵢ` of `model` (base frame at q = 0, `[ω; v]`), without
    /// thermal growth. For inspection; evaluation uses the prepared chain.
    pub fn real_screws(&self, model: &Model) -> Result<Vec<Vector6<f64>>> {
        self.check_fits(model.nq())?;
        Ok(model
            .joints
            .iter()
            .zip(&self.joint_twists)
            .map(|(j, xi)| adjoint_apply(&exp_twist(&vec6(xi)), &j.screw))
            .collect())
    }
}

/// One joint of a [`Chain`]: local axis, folded rotation terms and a temperature-affine origin.
#[derive(Clone, Debug)]
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
}

/// A serial chain prepared for evaluation: optional base pose, joint origins affine in `ΔT`, flange
/// offset affine in `ΔT`. Evaluates without allocating.
#[derive(Clone, Debug)]
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
    for (k, j) in model.joints.iter().enumerate() {
        acc += r_prev * j.origin.translation.vector * a(k);
        g.push(acc);
        r_prev = *j.home.rotation.matrix();
    }
    let gf = acc + r_prev * model.flange_offset.translation.vector * a(model.nq());
    (g, gf)
}

impl Chain {
    /// The nominal chain, with link growth `alpha` (1/K, links 0 … n) when given. At `ΔT = 0` it
    /// evaluates exactly like [`crate::forward_kinematics`].
    pub fn grown(model: &Model, alpha: Option<&[f64]>) -> Chain {
        let a = |k: usize| alpha.map_or(0.0, |al| al[k]);
        let joints = model
            .joints
            .iter()
            .enumerate()
            .map(|(k, j)| ChainJoint {
                rotational: j.kind.is_rotational(),
                axis: j.axis,
                terms: j.rotation_terms,
                origin_rot: *j.origin.rotation.matrix(),
                p0: j.origin.translation.vector,
                dp: j.origin.translation.vector * a(k),
            })
            .collect();
        let f = &model.flange_offset;
        Chain {
            base: None,
            joints,
            flange_rot: *f.rotation.matrix(),
            flange_p0: f.translation.vector,
            flange_dp: f.translation.vector * a(model.nq()),
        }
    }

    /// The real chain: kinematic offsets `kin` applied to the chain grown with `alpha` (see the module
    /// docs). `kin` must fit the model (checked by the caller).
    pub fn real(model: &Model, alpha: Option<&[f64]>, kin: &KinematicOffsets) -> Chain {
        let (g, g_flange) = growth(model, alpha);
        let mut prev_r = Matrix3::identity();
        let mut prev_h = Vector3::zeros();
        let mut prev_g = Vector3::zeros();
        let mut joints = Vec::with_capacity(model.nq());
        for ((j, xi), gi) in model.joints.iter().zip(&kin.joint_twists).zip(&g) {
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
            });
            (prev_r, prev_h, prev_g) = (r, h, gg);
        }
        let x = exp_twist(&vec6(&kin.tool_twist));
        let m = &model.home_flange;
        let rm = m.rotation.matrix();
        let flange_rot = prev_r.transpose() * rm * x.rotation.matrix();
        let flange_p0 =
            prev_r.transpose() * (rm * x.translation.vector + m.translation.vector - prev_h);
        let flange_dp = prev_r.transpose() * (g_flange - prev_g);
        Chain {
            base: Some(exp_twist(&vec6(&kin.base_twist))),
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
    pub fn model_at(&self, nominal: &Model, dt: f64) -> Model {
        let mut model = nominal.clone();
        let mut home = self.base.unwrap_or_else(Pose::identity);
        for (k, (joint, cj)) in model.joints.iter_mut().zip(&self.joints).enumerate() {
            let local = pose_from(cj.origin_rot, cj.p0 + cj.dp * dt);
            joint.origin = match (k, &self.base) {
                (0, Some(b)) => b * local,
                _ => local,
            };
            home *= local;
            joint.home = home;
            let w = home.rotation * cj.axis;
            let v = if cj.rotational {
                -w.cross(&home.translation.vector)
            } else {
                w
            };
            let w = if cj.rotational { w } else { Vector3::zeros() };
            joint.screw = Vector6::new(w.x, w.y, w.z, v.x, v.y, v.z);
            joint.refresh_derived();
        }
        model.flange_offset = pose_from(self.flange_rot, self.flange_p0 + self.flange_dp * dt);
        model.home_flange = home * model.flange_offset;
        model
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
    use crate::kinematics::{Data, forward_kinematics, poe_pose};
    use crate::lie::exp_se3;
    use crate::robots;

    fn twist(k: usize, s: f64) -> [f64; 6] {
        // Deterministic, distinct per joint, |ω| and |v| of order s.
        std::array::from_fn(|m| s * (((k * 6 + m) as f64 * 0.618_034).fract() - 0.5))
    }

    #[test]
    fn grown_chain_at_zero_temperature_is_bit_identical_to_forward_kinematics() {
        let m = robots::load_builtin("iiwa7").unwrap();
        let alpha = vec![23e-6; 8];
        let c = Chain::grown(&m, Some(&alpha));
        let mut d = Data::new(&m);
        let mut poses = vec![Pose::identity(); 7];
        let q = [0.3, -0.7, 1.1, 1.4, -0.5, 0.9, 0.2];
        forward_kinematics(&m, &mut d, &q);
        let f = c.eval(&q, 0.0, &mut poses);
        assert_eq!(f, d.flange);
        assert_eq!(poses, d.joint_poses);
    }

    #[test]
    fn real_chain_equals_product_of_perturbed_exponentials() {
        // Independent path: Sᵢ' = Ad(exp ξᵢ) Sᵢ, then the product of exponentials term by term.
        let m = robots::load_builtin("iiwa7").unwrap();
        let kin = KinematicOffsets::new(
            (0..7).map(|k| twist(k, 0.02)).collect(),
            vec![0.0; 7],
            twist(11, 0.01),
            twist(13, 0.01),
        )
        .unwrap();
        let c = Chain::real(&m, None, &kin);
        let screws = kin.real_screws(&m).unwrap();
        let home = m.home_flange * exp_twist(&vec6(&kin.tool_twist));
        let base = exp_twist(&vec6(&kin.base_twist));
        let mut poses = vec![Pose::identity(); 7];
        for k in 0..20 {
            let q: Vec<f64> = (0..7)
                .map(|i| ((k * 7 + i) as f64 * 0.754_877_7).fract() * 4.0 - 2.0)
                .collect();
            let a = c.eval(&q, 0.0, &mut poses);
            let b = base * poe_pose(&screws, &home, &q);
            assert!((a.translation.vector - b.translation.vector).amax() < 1e-14);
            assert!((a.rotation.matrix() - b.rotation.matrix()).amax() < 1e-14);
            // Intermediate frames: the current screw of joint i, Ad(base exp(S₁'q₁)⋯exp(S'ᵢ₋₁qᵢ₋₁)) Sᵢ',
            // must be the axis of frame i through its origin.
            let mut t = base;
            for (i, s) in screws.iter().enumerate() {
                let expect = adjoint_apply(&t, s);
                let w = poses[i].rotation * m.joints[i].axis;
                let v = poses[i].translation.vector.cross(&w);
                let got = Vector6::new(w.x, w.y, w.z, v.x, v.y, v.z);
                assert!((got - expect).amax() < 1e-14, "joint {i}");
                t *= exp_se3(s, q[i]);
            }
        }
    }

    #[test]
    fn model_at_reproduces_the_real_chain_at_temperature() {
        // The real chain (grown links, error twists, base and tool errors) as a Model: its own forward
        // kinematics and its product of exponentials must both give the chain's frames.
        let m = robots::load_builtin("iiwa7").unwrap();
        let kin = KinematicOffsets::new(
            (0..7).map(|k| twist(k, 0.02)).collect(),
            vec![0.0; 7],
            twist(11, 0.01),
            twist(13, 0.01),
        )
        .unwrap();
        let alpha: Vec<f64> = (0..8).map(|k| 20e-6 + 1e-6 * k as f64).collect();
        let c = Chain::real(&m, Some(&alpha), &kin);
        let dt = 7.5;
        let real = c.model_at(&m, dt);
        let mut d = Data::new(&real);
        let mut poses = vec![Pose::identity(); 7];
        for k in 0..10 {
            let q: Vec<f64> = (0..7)
                .map(|i| ((k * 7 + i) as f64 * 0.754_877_7).fract() * 4.0 - 2.0)
                .collect();
            let a = c.eval(&q, dt, &mut poses);
            forward_kinematics(&real, &mut d, &q);
            assert!((a.translation.vector - d.flange.translation.vector).amax() < 1e-14);
            assert!((a.rotation.matrix() - d.flange.rotation.matrix()).amax() < 1e-14);
            for (p, r) in poses.iter().zip(&d.joint_poses) {
                assert!((p.translation.vector - r.translation.vector).amax() < 1e-14);
                assert!((p.rotation.matrix() - r.rotation.matrix()).amax() < 1e-14);
            }
            let b = poe_pose(&real.screws(), &real.home_flange, &q);
            assert!((a.translation.vector - b.translation.vector).amax() < 1e-14);
            assert!((a.rotation.matrix() - b.rotation.matrix()).amax() < 1e-14);
        }
        // The growth is really in it: at another temperature the flange moves.
        let cold = c.model_at(&m, 0.0);
        assert!(
            (cold.home_flange.translation.vector - real.home_flange.translation.vector).norm()
                > 1e-5
        );
        assert_eq!(real.bodies, m.bodies);
    }
}
