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

use super::chain::Chain;
use super::effect::{Effect, Moved, Prepare, ResolveCx, State};
use crate::effect_id::EffectId;
use crate::error::{Result, SimError};
use crate::lie::{adjoint_apply, exp_twist};
use crate::model::Model;
use nalgebra::{Vector3, Vector6};

/// Largest accepted rotation part `|ω|` of an error twist and largest zero offset (rad): these are
/// errors, not poses; more than 0.5 rad is almost surely a value in degrees.
pub const MAX_ROTATION_ERROR_RAD: f64 = 0.5;
/// Largest accepted translation part `|v|` of an error twist (m); more is almost surely millimetres.
pub const MAX_TRANSLATION_ERROR_M: f64 = 1.0;

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
            return Err(SimError::bad_effect(
                EffectId::KinematicOffsets,
                format!("{field}[{k}]"),
                v,
                "not finite",
            ));
        }
    }
    let w = Vector3::new(xi[0], xi[1], xi[2]).norm();
    if w > MAX_ROTATION_ERROR_RAD {
        return Err(SimError::bad_effect(
            EffectId::KinematicOffsets,
            format!("{field} |ω|"),
            w,
            format!(
                "rotation error above {MAX_ROTATION_ERROR_RAD} rad; give it in rad, not degrees"
            ),
        ));
    }
    let v = Vector3::new(xi[3], xi[4], xi[5]).norm();
    if v > MAX_TRANSLATION_ERROR_M {
        return Err(SimError::bad_effect(
            EffectId::KinematicOffsets,
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
            return Err(SimError::bad_effect(
                EffectId::KinematicOffsets,
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
                return Err(SimError::bad_effect(
                    EffectId::KinematicOffsets,
                    format!("zero_offsets[{i}]"),
                    d,
                    "not finite",
                ));
            }
            if d.abs() > MAX_ROTATION_ERROR_RAD {
                return Err(SimError::bad_effect(
                    EffectId::KinematicOffsets,
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
            return Err(SimError::bad_effect(
                EffectId::KinematicOffsets,
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
            .joints()
            .iter()
            .zip(&self.joint_twists)
            .map(|(j, xi)| adjoint_apply(&exp_twist(&vec6(xi)), &j.screw))
            .collect())
    }
}

/// `[effects.kinematic]`.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KinematicSection {
    /// Switch (default on).
    pub enabled: Option<bool>,
    /// Rotation part ω of each joint's error twist (rad, base frame), shape `[n][3]`.
    pub joint_rotation_rad: Option<crate::magnitude::Magnitude>,
    /// Translation part v of each joint's error twist (m, base frame), shape `[n][3]`.
    pub joint_translation_m: Option<crate::magnitude::Magnitude>,
    /// Joint zero offsets (rad; m for prismatic joints), shape `[n]`.
    pub zero_offset_rad: Option<crate::magnitude::Magnitude>,
    /// Base error twist rotation (rad), shape `[3]`.
    pub base_rotation_rad: Option<crate::magnitude::Magnitude>,
    /// Base error twist translation (m), shape `[3]`.
    pub base_translation_m: Option<crate::magnitude::Magnitude>,
    /// Tool error twist rotation (rad, flange frame), shape `[3]`.
    pub tool_rotation_rad: Option<crate::magnitude::Magnitude>,
    /// Tool error twist translation (m, flange frame), shape `[3]`.
    pub tool_translation_m: Option<crate::magnitude::Magnitude>,
}

/// The prepared kinematic-offsets stage: the real chain (thermally grown when thermal drift is
/// present) and the zero offsets.
#[derive(Clone, Debug)]
pub struct KinematicStage {
    real: Chain,
    zero_offsets: Vec<f64>,
}

impl KinematicOffsets {
    /// The real chain of `model` with these errors, grown with `alpha` (1/K, links 0 … n).
    pub(crate) fn real_chain(&self, model: &Model, alpha: Option<&[f64]>) -> Chain {
        Chain::real(
            model,
            alpha,
            &self.joint_twists,
            &self.base_twist,
            &self.tool_twist,
        )
    }
}

impl Effect for KinematicOffsets {
    const ID: EffectId = EffectId::KinematicOffsets;
    type Section = KinematicSection;
    type Stage = KinematicStage;
    type Scratch = ();

    fn enabled(section: &KinematicSection) -> bool {
        section.enabled.unwrap_or(true)
    }

    fn from_section(k: &KinematicSection, cx: &ResolveCx<'_>) -> Result<Self> {
        let n = cx.nq();
        let w = cx.draw_or_zero(&k.joint_rotation_rad, "joint_rotation_rad", &[n, 3])?;
        let v = cx.draw_or_zero(&k.joint_translation_m, "joint_translation_m", &[n, 3])?;
        let dq = cx.draw_or_zero(&k.zero_offset_rad, "zero_offset_rad", &[n])?;
        let bw = cx.draw_or_zero(&k.base_rotation_rad, "base_rotation_rad", &[3])?;
        let bv = cx.draw_or_zero(&k.base_translation_m, "base_translation_m", &[3])?;
        let tw = cx.draw_or_zero(&k.tool_rotation_rad, "tool_rotation_rad", &[3])?;
        let tv = cx.draw_or_zero(&k.tool_translation_m, "tool_translation_m", &[3])?;
        let twists = (0..n)
            .map(|i| {
                [
                    w[3 * i],
                    w[3 * i + 1],
                    w[3 * i + 2],
                    v[3 * i],
                    v[3 * i + 1],
                    v[3 * i + 2],
                ]
            })
            .collect();
        let six = |a: &[f64], b: &[f64]| [a[0], a[1], a[2], b[0], b[1], b[2]];
        cx.checked(KinematicOffsets::new(
            twists,
            dq,
            six(&bw, &bv),
            six(&tw, &tv),
        ))
    }

    fn check_lengths(&self, nq: usize) -> Result<()> {
        self.check_fits(nq)
    }

    fn prepare(&self, cx: &Prepare<'_>) -> Result<KinematicStage> {
        Ok(KinematicStage {
            real: self.real_chain(cx.model, cx.growth),
            zero_offsets: self.zero_offsets.clone(),
        })
    }

    /// Real screws, base and tool errors (the stage's chain replaces the grown nominal one) and zero
    /// offsets `φᵢ += δqᵢ`.
    #[inline]
    fn act<'t>(stage: &'t KinematicStage, st: &mut State<'t, '_>, _: &mut ()) -> Result<Moved> {
        st.geom = &stage.real;
        for (a, b) in st.angles.iter_mut().zip(&stage.zero_offsets) {
            *a += b;
        }
        Ok(Moved::Changed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematics::{Data, forward_kinematics, poe_pose};
    use crate::lie::Pose;
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
        let c = kin.real_chain(&m, None);
        let screws = kin.real_screws(&m).unwrap();
        let home = m.home_flange() * exp_twist(&vec6(&kin.tool_twist));
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
                let w = poses[i].rotation * m.joints()[i].axis;
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
        let c = kin.real_chain(&m, Some(&alpha));
        let dt = 7.5;
        let real = c.model_at(&m, dt).unwrap();
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
            let b = poe_pose(&real.screws(), &real.home_flange(), &q);
            assert!((a.translation.vector - b.translation.vector).amax() < 1e-14);
            assert!((a.rotation.matrix() - b.rotation.matrix()).amax() < 1e-14);
        }
        // The growth is really in it: at another temperature the flange moves.
        let cold = c.model_at(&m, 0.0).unwrap();
        assert!(
            (cold.home_flange().translation.vector - real.home_flange().translation.vector).norm()
                > 1e-5
        );
        assert_eq!(real.bodies(), m.bodies());
    }
}
