//! UR's kinematics file (`calibrate --ur-kinematics FILE.yaml`): the calibrated geometry of a Universal
//! Robots arm in `ur_description`'s format, which a UR user passes to its `ur.urdf.xacro` as
//! `kinematics_params`, so that ROS plans with the calibrated robot.
//!
//! # The format
//! `kinematics:` gives, for each of the six joints (`shoulder`, `upper_arm`, `forearm`, `wrist_1`,
//! `wrist_2`, `wrist_3`), the origin of its joint frame in the previous one (the first in
//! `base_link_inertia`, UR's `Base`): `x, y, z` (m) and `roll, pitch, yaw` (rad, URDF's convention
//! `R = Rz(yaw) Ry(pitch) Rx(roll)`), each joint turning about its frame's z axis; and a `hash`. The
//! macro adds the fixed `flange` (`rpy = 0 −π/2 −π/2` from `wrist_3_link`) and `tool0`
//! (`rpy = π/2 0 π/2` from `flange`) frames.
//!
//! # What the origins become
//! The calibrated joint frames at `q = 0` are the chain's `Fᵢ` ([`crate::model::chain`]; the frames of
//! the calibrated URDF, [`crate::model::urdf_export`]). A frame slid along its own axis (and turned
//! about it) describes the same joint, since that motion commutes with the joint's; the file's frames
//! are the calibrated `Fᵢ` slid by the nominal robot's slides `sᵢ`, those that put the nominal `Fᵢ` on
//! the foot of the common normal with the next joint's axis (the last joint's on the flange), which is
//! where `ur_description`'s frames are (for the built-in UR5 and UR10, whose base is
//! `base_link_inertia` and whose flange frame is `tool0`): `Wᵢ = Fᵢ Tz(sᵢ)`, origin `Wᵢ₋₁⁻¹ Wᵢ`.
//!
//! * **Zero offsets** turn `Fᵢ` about its axis: folded in as the URDF export does, so the joint
//!   positions stay the controller's readings.
//! * **The flange**: the file cannot move `flange` or `tool0` relative to `wrist_3_link`. The calibrated
//!   flange may sit off the last axis or tilted from it; the target's offset is therefore given in the
//!   `tool0` frame the file makes (exact for the target), under the extra key `robocal`, which
//!   `ur_description` ignores, with the tracker-to-`base_link_inertia` transform.
//! * **Left out**: every non-geometric cause (compliance, backlash, thermal drift, transmission error,
//!   link deflection) and a learned correction: they depend on load, approach direction, temperature
//!   or the configuration, and the format has no place for them. `robocal compensate` applies them.

use crate::error::{CalibError, Result};
use crate::lie3::rpy_from_rotation;
use crate::model::file::CalibratedModel;
use nalgebra::{Matrix3, Vector3, Vector6};
use sim::lie::{Pose, exp_twist, pose_from};
/// A YAML 1.1 float: the shortest decimal that reads back to the same `f64`, with a `.` before any
/// exponent (PyYAML, which xacro uses, reads `1e-5` as a string).
fn number(x: f64) -> String {
    let s = sim::urdf_text::number(x);
    match s.find('e') {
        Some(k) if !s[..k].contains('.') => format!("{}.0{}", &s[..k], &s[k..]),
        _ => s,
    }
}

/// The joint names of `ur_description`'s kinematics file, base to tip.
pub const SEGMENTS: [&str; 6] = [
    "shoulder",
    "upper_arm",
    "forearm",
    "wrist_1",
    "wrist_2",
    "wrist_3",
];

/// Axes closer to parallel than this (sine of the angle) have no common normal's foot.
const PARALLEL: f64 = 1e-9;

/// The written file, with what it leaves out.
#[derive(Clone, Debug)]
pub struct UrKinematics {
    /// The YAML text.
    pub text: String,
    /// The joint origins written (`Wᵢ₋₁⁻¹ Wᵢ`), base to tip.
    pub origins: Vec<Pose>,
    /// The target (reflector) in the file's `tool0` frame (m).
    pub p_tool0_target: Vector3<f64>,
    /// What the file cannot express, one sentence each.
    pub warnings: Vec<String>,
}

/// `R = Rz(yaw) Ry(pitch) Rx(roll)`, URDF's roll-pitch-yaw (rad).
pub fn rotation_from_rpy(rpy: [f64; 3]) -> Matrix3<f64> {
    let [r, p, y] = rpy;
    let (sr, cr) = r.sin_cos();
    let (sp, cp) = p.sin_cos();
    let (sy, cy) = y.sin_cos();
    let rx = Matrix3::new(1.0, 0.0, 0.0, 0.0, cr, -sr, 0.0, sr, cr);
    let ry = Matrix3::new(cp, 0.0, sp, 0.0, 1.0, 0.0, -sp, 0.0, cp);
    let rz = Matrix3::new(cy, -sy, 0.0, sy, cy, 0.0, 0.0, 0.0, 1.0);
    rz * ry * rx
}

/// The joint frames at `q = 0` of the chain `joint_error`, `zero_offset` (base frame; identity error
/// and zero offsets: the nominal robot): `Fᵢ = Fᵢ₋₁ H'ᵢ₋₁⁻¹ H'ᵢ Z(δqᵢ)` ([`crate::model::chain`]), and
/// `H'ₙ⁻¹`, which carries the last frame to the flange (`Fₙ H'ₙ⁻¹ M`).
fn joint_frames(
    model: &sim::Model,
    joint_error: &[Pose],
    zero_offset: &[f64],
) -> (Vec<Pose>, Pose) {
    let mut frames = Vec::with_capacity(model.nq());
    let (mut prev, mut prev_home_inv) = (Pose::identity(), Pose::identity());
    for (i, j) in model.joints().iter().enumerate() {
        let home = joint_error[i] * j.home;
        let d = zero_offset[i];
        let z = exp_twist(&Vector6::new(
            j.axis.x * d,
            j.axis.y * d,
            j.axis.z * d,
            0.0,
            0.0,
            0.0,
        ));
        prev = prev * prev_home_inv * home * z;
        prev_home_inv = home.inverse();
        frames.push(prev);
    }
    (frames, prev_home_inv)
}

/// Slide along axis `z` of frame `a` to the foot of the common normal with axis `z` of frame `b` (m);
/// 0 for parallel axes.
fn foot(a: &Pose, b: &Pose) -> f64 {
    let (pa, za) = (a.translation.vector, a.rotation * Vector3::z());
    let (pb, zb) = (b.translation.vector, b.rotation * Vector3::z());
    let n = za.cross(&zb);
    let nn = n.norm_squared();
    if nn < PARALLEL * PARALLEL {
        return 0.0;
    }
    // pa + s za + t zb on the normal: (pb − pa) × zb · n / |n|².
    (pb - pa).cross(&zb).dot(&n) / nn
}

/// `ur_description`'s kinematics file for the calibrated model `file`, with `hash` (e.g.
/// `calib_1234`).
///
/// # Errors
/// A robot that is not a six-joint arm of revolute joints turning about their frames' z axes.
pub fn ur_kinematics(file: &CalibratedModel) -> Result<UrKinematics> {
    let model = file.robot_model()?;
    let params = file.params();
    let n = model.nq();
    let ok_axes = model
        .joints()
        .iter()
        .all(|j| j.kind.is_rotational() && (j.axis - Vector3::z()).norm() < 1e-12);
    if n != 6 || !ok_axes {
        return Err(CalibError::Misuse(format!(
            "--ur-kinematics: robot '{}' is not a UR arm: six revolute joints turning about their frames' z \
             axes are needed (it has {n} joints)",
            model.name()
        )));
    }
    let identity = vec![Pose::identity(); n];
    let (nominal, _) = joint_frames(&model, &identity, &vec![0.0; n]);
    // The nominal robot must have ur_description's frames: the base is UR's Base (base_link_inertia:
    // the first joint's frame on its z axis, unturned) and the tip frame is tool0.
    let first = nominal[0];
    let tool0_nominal = {
        use std::f64::consts::FRAC_PI_2;
        let slide6 = (model.home_flange().translation.vector - nominal[n - 1].translation.vector)
            .dot(&(nominal[n - 1].rotation * Vector3::z()));
        nominal[n - 1]
            * pose_from(
                rotation_from_rpy([0.0, -FRAC_PI_2, -FRAC_PI_2])
                    * rotation_from_rpy([FRAC_PI_2, 0.0, FRAC_PI_2]),
                Vector3::new(0.0, 0.0, slide6),
            )
    };
    let tip = tool0_nominal.inverse() * model.home_flange();
    if (first.rotation.matrix() - Matrix3::identity()).amax() > 1e-9
        || first.translation.vector.xy().norm() > 1e-9
        || (tip.rotation.matrix() - Matrix3::identity()).amax() > 1e-9
        || tip.translation.vector.norm() > 1e-9
    {
        return Err(CalibError::Misuse(format!(
            "--ur-kinematics: robot '{}' does not have ur_description's frames (its base must be UR's Base, \
             base_link_inertia, and its tip frame tool0, as the built-in ur5 and ur10 have)",
            model.name()
        )));
    }
    let (calibrated, home6_inv) = joint_frames(&model, &params.joint_error, &params.zero_offset);
    // The nominal slides: to the next axis' common normal, the last to the flange.
    let flange = model.home_flange();
    let slides: Vec<f64> = (0..n)
        .map(|i| {
            if i + 1 < n {
                foot(&nominal[i], &nominal[i + 1])
            } else {
                let d = flange.translation.vector - nominal[i].translation.vector;
                d.dot(&(nominal[i].rotation * Vector3::z()))
            }
        })
        .collect();
    let slide = |f: &Pose, s: f64| f * pose_from(Matrix3::identity(), Vector3::new(0.0, 0.0, s));
    let frames: Vec<Pose> = calibrated
        .iter()
        .zip(&slides)
        .map(|(f, &s)| slide(f, s))
        .collect();
    let mut origins = Vec::with_capacity(n);
    let mut prev = Pose::identity();
    for w in &frames {
        origins.push(prev.inverse() * w);
        prev = *w;
    }
    // tool0 = wrist_3_link · rpy(0, −π/2, −π/2) · rpy(π/2, 0, π/2), as ur_macro.xacro writes it.
    use std::f64::consts::FRAC_PI_2;
    let r_wrist3_tool0 = rotation_from_rpy([0.0, -FRAC_PI_2, -FRAC_PI_2])
        * rotation_from_rpy([FRAC_PI_2, 0.0, FRAC_PI_2]);
    let tool0 = frames[n - 1] * pose_from(r_wrist3_tool0, Vector3::zeros());
    // The calibrated flange at q = 0: F₆ H'₆⁻¹ M.
    let t_base_flange = calibrated[n - 1] * home6_inv * flange;
    let p_base_target = t_base_flange * nalgebra::Point3::from(params.p_flange_target);
    let p_tool0_target = (tool0.inverse() * p_base_target).coords;

    let mut text = String::new();
    text.push_str(&format!(
        "# Calibrated kinematics of '{}' for ur_description (kinematics_params:=THIS_FILE), written by\n\
         # robocal {} from the model '{}'. Joint origins as in default_kinematics.yaml (m, rad; URDF rpy,\n\
         # R = Rz(yaw) Ry(pitch) Rx(roll)); zero offsets folded into the origins.\n",
        model.name(),
        env!("CARGO_PKG_VERSION"),
        file.model
    ));
    let mut warnings = Vec::new();
    if !file.model.is_kinematic() || file.learned.is_some() {
        warnings.push(format!(
            "the model '{}' has parts this file cannot express (they depend on load, motion direction, \
             temperature or the configuration): it holds the geometry only; robocal compensate applies \
             the rest",
            file.model
        ));
    }
    for w in &warnings {
        text.push_str(&format!("# Left out: {w}.\n"));
    }
    text.push_str("kinematics:\n");
    let mut values = Vec::new();
    for (name, o) in SEGMENTS.iter().zip(&origins) {
        let xyz = o.translation.vector;
        let rpy = rpy_from_rotation(o.rotation.matrix());
        text.push_str(&format!("  {name}:\n"));
        for (k, v) in ["x", "y", "z"].iter().zip(xyz.iter()) {
            text.push_str(&format!("    {k}: {}\n", number(*v)));
            values.push(*v);
        }
        for (k, v) in ["roll", "pitch", "yaw"].iter().zip(rpy) {
            text.push_str(&format!("    {k}: {}\n", number(v)));
            values.push(v);
        }
    }
    text.push_str(&format!("  hash: calib_{}\n", hash(&values)));
    let t_tb = &params.t_tracker_base;
    let f3 = |v: &[f64]| format!("[{}, {}, {}]", number(v[0]), number(v[1]), number(v[2]));
    text.push_str(
        "# Not read by ur_description: the target (reflector) in the tool0 frame this file makes, and the\n\
         # tracker-to-base_link_inertia transform of the calibration (m, rad).\n",
    );
    text.push_str("robocal:\n");
    text.push_str(&format!(
        "  target_in_tool0_m: {}\n",
        f3(p_tool0_target.as_slice())
    ));
    text.push_str(&format!(
        "  tracker_base_link_inertia_xyz_m: {}\n",
        f3(t_tb.translation.vector.as_slice())
    ));
    text.push_str(&format!(
        "  tracker_base_link_inertia_rpy_rad: {}\n",
        f3(&rpy_from_rotation(t_tb.rotation.matrix()))
    ));
    Ok(UrKinematics {
        text,
        origins,
        p_tool0_target,
        warnings,
    })
}

/// FNV-1a (64-bit) of the values' bytes: the file's `hash`, which changes with any value.
fn hash(values: &[f64]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for v in values {
        for b in v.to_le_bytes() {
            h ^= u64::from(b);
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
    }
    h
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn yaml_floats_have_a_point() {
        assert_eq!(number(1e-5), "1.0e-5");
        assert_eq!(number(-2.5e-7), "-2.5e-7");
        assert_eq!(number(0.125), "0.125");
        assert_eq!(number(0.0), "0");
    }

    /// URDF's rpy convention, round trip: `rotation_from_rpy` is `Rz(yaw) Ry(pitch) Rx(roll)` (checked
    /// against rotations about the fixed axes composed by nalgebra), and `rpy_from_rotation` inverts it
    /// away from pitch ±π/2. Eigen's `eulerAngles(0, 1, 2)`, which UR's own calibration tool uses,
    /// returns angles for `Rx Ry Rz`: a different matrix for the same numbers.
    #[test]
    fn urdf_rpy_round_trip() {
        let axis = |v: Vector3<f64>, a: f64| {
            *nalgebra::Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(v), a).matrix()
        };
        for rpy in [
            [0.3, -0.7, 1.9],
            [-2.5, 0.2, -0.4],
            // ur_description's rounded π/2 (1.570796327 in default_kinematics.yaml) and its wrist_3
            // rotation.
            [std::f64::consts::FRAC_PI_2 + 3e-10, 0.0, 0.0],
            [
                std::f64::consts::FRAC_PI_2,
                std::f64::consts::PI,
                std::f64::consts::PI,
            ],
        ] {
            let r = rotation_from_rpy(rpy);
            let want = axis(Vector3::z(), rpy[2])
                * axis(Vector3::y(), rpy[1])
                * axis(Vector3::x(), rpy[0]);
            assert!((r - want).amax() < 1e-15, "{rpy:?}");
            let xyz_order = axis(Vector3::x(), rpy[0])
                * axis(Vector3::y(), rpy[1])
                * axis(Vector3::z(), rpy[2]);
            // Generic angles: the two orders give different matrices (ur_description's wrist_3
            // triple is a special case where they agree: Rz(π) Ry(π) = Ry(π) Rz(π) = Rx(π)).
            if rpy[0].abs() < 3.0 && rpy[1].abs() > 0.1 && rpy[2].abs() > 0.1 && rpy[2].abs() < 3.0
            {
                assert!(
                    (r - xyz_order).amax() > 1e-3,
                    "the two conventions differ: {rpy:?}"
                );
            }
            let back = rotation_from_rpy(rpy_from_rotation(&r));
            assert!((back - r).amax() < 1e-15, "{rpy:?}");
        }
    }
}
