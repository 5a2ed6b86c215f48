//! The calibrated URDF (`--urdf-out`): the user's own URDF, with the origins of the chain's joints
//! moved to the calibrated robot and a comment block giving the base and target transforms. Every
//! other byte of the file is kept ([`sim::urdf_text`]): link and joint names, axes, limits, inertials,
//! visuals, collisions, meshes, transmissions, `<gazebo>` and `<ros2_control>` tags, comments, links
//! off the chain. A ROS user swaps it in for `robot_description`, and TF then shows the calibrated arm.
//!
//! # What the origins become
//! The calibrated model is (crate [`crate::model::chain`]) `Fᵢ = Fᵢ₋₁ O'ᵢ exp([Aᵢ](qᵢ + δqᵢ))` with
//! `O'ᵢ = H'ᵢ₋₁⁻¹ H'ᵢ`, `H'ᵢ = Gᵢ Hᵢ` the calibrated home pose of joint frame `i` (the child link frame of
//! movable joint `i`), and the flange `Fₙ H'ₙ⁻¹ M`. In URDF terms, the child link of joint `i` sits at
//! `parent · origin · motion(qᵢ)` with the motion a rotation about (translation along) the axis through
//! the origin. So:
//!
//! * **Axis errors** (the rotation and position of each joint axis, the six components of `Gᵢ`) are
//!   joint origins: movable joint `i` gets `originᵢ = P⁻¹ O'ᵢ exp([Aᵢ] δqᵢ)`, where `P` is the product of
//!   the fixed joints between the previous movable joint's child link and joint `i`'s parent link
//!   (they keep their origins). The `<axis>` element keeps its value: the axis is fixed in the joint
//!   frame, and the frame carries the error.
//! * **Zero offsets** `δqᵢ` cannot be told apart from an origin rotated about the joint's own axis (a
//!   translation along it, prismatic), because that rotation commutes with the joint motion:
//!   `O' exp([A] δq) exp([A] q) = O' exp([A](q + δq))`. They are folded in, so the joint positions of
//!   the file stay the controller's readings (`/joint_states`, limits, trajectories); everything on link
//!   `i` (meshes, collision shapes, frames) turns with it by `δqᵢ`, as the real link does. The
//!   alternative, a `<calibration>` element or an offset added to the joint states, would need every
//!   consumer of `/joint_states` to apply it: not a drop-in.
//! * **The flange**: the first fixed joint after the last movable joint gets `H'ₙ⁻¹ M R⁻¹` (`R` the
//!   fixed joints after it), so the tip link is the calibrated model's flange, and the frames below it
//!   (`tool0`) keep their offsets from it. When the tip link is the last movable joint's own child
//!   link there is no such joint: the file's tip frame is then the last joint frame, the difference
//!   `T_tip_flange = H'ₙ⁻¹ M` goes into the target transform of the comment (exact for the target), and
//!   a warning says so.
//! * **Base and target**: the tracker-to-base transform and the target (reflector) in the tip frame
//!   are not part of a robot description; the comment gives them as `<origin>` elements, and as fixed
//!   joints to paste for a `robocal_tracker` and a `robocal_target` frame.
//! * **Model extensions** (joint compliance, backlash, thermal drift) and a learned correction depend
//!   on the load, the direction of motion, the temperature: a URDF has no element for them. The file
//!   holds the kinematic part; the comment names what it leaves out, and [`unexpressed_gap`] measures
//!   how far that is from the full model on a table.
//!
//! Origins that differ from the input by less than 1e-15 (m, or rotation-matrix entry) are left as
//! written. Numbers are written as the shortest decimal that reads back to the same `f64`.

use crate::error::{CalibError, Result};
use crate::lie3::rpy_from_rotation;
use crate::model::chain::{Chain, ChainScratch};
use crate::model::file::CalibratedModel;
use crate::model::params::KinematicParams;
use crate::model::predict::Predictor;
use nalgebra::{Matrix3, Vector3, Vector6};
use sim::lie::{Pose, exp_twist, pose_from};
use sim::measurement_table::MeasurementTable;
use sim::urdf_text::{CommentBlock, OriginEdit, edit_joint_origins, number};
use sim::{ChainSpec, JointKind, Model};

/// The first word of the comment block the file carries (a block of an earlier export is replaced).
pub const COMMENT_MARKER: &str = "robocal-calibration";

/// Origins closer than this to the input's (m, or rotation-matrix entry) are left as written.
pub const UNCHANGED_BELOW: f64 = 1e-15;

/// A calibrated URDF.
#[derive(Clone, Debug)]
pub struct CalibratedUrdf {
    /// The URDF text.
    pub text: String,
    /// The joints whose origin was changed, base to tip.
    pub changed: Vec<String>,
    /// `T_tip_flange`: the calibrated model's flange in the file's tip link frame (identity unless the
    /// tip link is the last movable joint's child link).
    pub t_tip_flange: Pose,
    /// `T_tip_target`, as the comment gives it: the target in the file's tip link frame (m); its rotation
    /// is meaningful only when the model has the target orientation.
    pub t_tip_target: Pose,
    /// What the file cannot express, one sentence each (also in its comment).
    pub warnings: Vec<String>,
}

fn differs(a: &Pose, b: &Pose) -> bool {
    (a.translation.vector - b.translation.vector).amax() > UNCHANGED_BELOW
        || (a.rotation.matrix() - b.rotation.matrix()).amax() > UNCHANGED_BELOW
}

fn origin_attrs(t: &Pose) -> ([f64; 3], [f64; 3]) {
    (
        t.translation.vector.into(),
        rpy_from_rotation(t.rotation.matrix()),
    )
}

/// The roll-pitch-yaw of `r` nearest to `near` (rad): a rotation has two triples, `(r, p, y)` and
/// `(r + π, π − p, y + π)`, each angle defined up to 2π. Keeping the written one's branch makes a
/// diff of a calibrated file show small changes of the written numbers (`-1.5707963 3.1415927 0` stays
/// near it instead of becoming `1.5707963 0 3.1415927`).
fn rpy_near(r: &Matrix3<f64>, near: &[f64; 3]) -> [f64; 3] {
    use std::f64::consts::{PI, TAU};
    let [a, b, c] = rpy_from_rotation(r);
    let wrap = |x: f64, to: f64| x + TAU * ((to - x) / TAU).round();
    let candidates = [[a, b, c], [a + PI, PI - b, c + PI]].map(|t| {
        [
            wrap(t[0], near[0]),
            wrap(t[1], near[1]),
            wrap(t[2], near[2]),
        ]
    });
    let dist = |t: &[f64; 3]| (0..3).map(|k| (t[k] - near[k]).abs()).fold(0.0, f64::max);
    if dist(&candidates[1]) < dist(&candidates[0]) {
        candidates[1]
    } else {
        candidates[0]
    }
}

fn origin_element(t: &Pose, with_rpy: bool) -> String {
    let (xyz, rpy) = origin_attrs(t);
    let f = |v: [f64; 3]| format!("{} {} {}", number(v[0]), number(v[1]), number(v[2]));
    if with_rpy {
        format!("<origin xyz=\"{}\" rpy=\"{}\"/>", f(xyz), f(rpy))
    } else {
        format!("<origin xyz=\"{}\"/>", f(xyz))
    }
}

/// Joint `i`'s zero offset as a motion about (along) its axis.
fn zero_offset_motion(kind: JointKind, axis: &Vector3<f64>, d: f64) -> Pose {
    if kind == JointKind::Prismatic {
        pose_from(Matrix3::identity(), axis * d)
    } else {
        exp_twist(&Vector6::new(
            axis.x * d,
            axis.y * d,
            axis.z * d,
            0.0,
            0.0,
            0.0,
        ))
    }
}

/// The calibrated URDF of `file`: its embedded URDF with the chain's joint origins moved (see the
/// module documentation). Only the kinematic part of the model is expressed; the comment and
/// [`CalibratedUrdf::warnings`] name the rest.
///
/// # Errors
/// The embedded URDF cannot be read, or its chain does not match the model's joints.
pub fn calibrated_urdf(file: &CalibratedModel) -> Result<CalibratedUrdf> {
    let model = file.robot_model()?;
    let params = file.params();
    let source = format!("embedded robot '{}'", file.robot.name);
    let spec = ChainSpec {
        base_link: Some(model.base_link().to_string()),
        tip_link: Some(model.tip_link().to_string()),
    };
    let chain = sim::urdf::chain_joints(&file.robot.urdf, &source, &spec)?;
    let movable: Vec<&str> = chain
        .iter()
        .filter(|c| c.movable)
        .map(|c| c.name.as_str())
        .collect();
    let names: Vec<&str> = model.joints().iter().map(|j| j.name.as_str()).collect();
    if movable != names {
        return Err(CalibError::Misuse(format!(
            "{source}: the chain's movable joints {movable:?} are not the model's {names:?}"
        )));
    }
    let last_movable = chain.iter().rposition(|c| c.movable).unwrap_or(0);

    let mut edits = Vec::new();
    let mut changed = Vec::new();
    // `P`: the parent link of the next movable joint in the current calibrated joint frame.
    let mut parent_in_frame = Pose::identity();
    let mut frame_home_inv = Pose::identity(); // H'ᵢ₋₁⁻¹
    let mut i = 0;
    let mut t_tip_flange = Pose::identity();
    for (k, cj) in chain.iter().enumerate() {
        let new_origin = if cj.movable {
            let joint = &model.joints()[i];
            let home = params.joint_error[i] * joint.home;
            let o = frame_home_inv
                * home
                * zero_offset_motion(joint.kind, &joint.axis, params.zero_offset[i]);
            let origin = parent_in_frame.inverse() * o;
            frame_home_inv = home.inverse();
            parent_in_frame = Pose::identity();
            i += 1;
            origin
        } else if k == last_movable + 1 {
            // The first fixed joint after the last movable one carries the calibrated flange.
            let rest = chain[k + 1..]
                .iter()
                .fold(Pose::identity(), |acc, c| acc * c.origin);
            frame_home_inv * model.home_flange() * rest.inverse()
        } else {
            parent_in_frame *= cj.origin;
            continue;
        };
        if differs(&new_origin, &cj.origin) {
            edits.push(OriginEdit {
                joint: cj.name.clone(),
                xyz: new_origin.translation.vector.into(),
                rpy: rpy_near(new_origin.rotation.matrix(), &cj.rpy),
            });
            changed.push(cj.name.clone());
        }
    }
    let mut warnings = Vec::new();
    if last_movable + 1 == chain.len() {
        t_tip_flange = frame_home_inv * model.home_flange();
        let t = t_tip_flange.translation.vector.norm();
        let a = t_tip_flange.rotation.angle();
        if t > UNCHANGED_BELOW || a > UNCHANGED_BELOW {
            warnings.push(format!(
                "the tip link '{}' is the child of the last movable joint '{}', so the calibrated flange \
                 ({:.3} mm and {:.3} mrad from it) cannot be placed by a joint origin; the target transform \
                 in the comment is given in the tip link frame and is exact for the target (add a fixed \
                 flange joint to the URDF to carry it)",
                model.tip_link(),
                chain[last_movable].name,
                t * 1e3,
                a * 1e3
            ));
        }
    }
    if !file.model.is_kinematic() || file.learned.is_some() {
        warnings.push(format!(
            "the model '{}' has parts a URDF cannot express (they depend on load, motion direction, \
             temperature or the learned correction): the file holds its kinematic part only",
            file.model
        ));
    }
    let t_flange_target = pose_from(
        params.r_flange_target.unwrap_or_else(Matrix3::identity),
        params.p_flange_target,
    );
    let t_tip_target = t_tip_flange * t_flange_target;
    let lines = comment_lines(
        file,
        &model,
        &params,
        &changed,
        &t_tip_target,
        params.r_flange_target.is_some(),
        &warnings,
    );
    let text = edit_joint_origins(
        &file.robot.urdf,
        &source,
        &edits,
        &CommentBlock {
            marker: COMMENT_MARKER,
            lines: &lines,
        },
    )?;
    Ok(CalibratedUrdf {
        text,
        changed,
        t_tip_flange,
        t_tip_target,
        warnings,
    })
}

fn comment_lines(
    file: &CalibratedModel,
    model: &Model,
    params: &KinematicParams,
    changed: &[String],
    t_tip_target: &Pose,
    orientation: bool,
    warnings: &[String],
) -> Vec<String> {
    let mut l = vec![
        format!(
            "Calibrated by robocal {} (model '{}'). A drop-in replacement for the original URDF: only",
            env!("CARGO_PKG_VERSION"),
            file.model
        ),
        format!(
            "the <origin> of these joints of the chain '{}' -> '{}' differ from it:",
            model.base_link(),
            model.tip_link()
        ),
    ];
    l.push(format!(
        "  {}",
        if changed.is_empty() {
            "(none: the calibrated robot is the nominal one)".to_string()
        } else {
            changed.join(", ")
        }
    ));
    l.push(
        "Joint axes, limits, inertials, meshes and every other element are as they were. The zero"
            .into(),
    );
    l.push(
        "offsets are folded into the origins (rotations about the joint axes, translations along"
            .into(),
    );
    l.push(
        "prismatic ones), so joint positions stay the controller's readings. Zero offsets (rad or m):"
            .into(),
    );
    l.push(format!(
        "  {}",
        model
            .joints()
            .iter()
            .zip(&params.zero_offset)
            .map(|(j, d)| format!("{} {}", j.name, number(*d)))
            .collect::<Vec<_>>()
            .join(", ")
    ));
    l.push(format!(
        "T_tracker_base: {}",
        origin_element(&params.t_tracker_base, true)
    ));
    l.push(format!(
        "  the base link '{}' in the laser-tracker frame (m, rad)",
        model.base_link()
    ));
    l.push(format!(
        "T_tip_target: {}",
        origin_element(t_tip_target, orientation)
    ));
    l.push(format!(
        "  the target in the tip link '{}' frame (m{})",
        model.tip_link(),
        if orientation {
            ", rad"
        } else {
            "; position only, its orientation was not measured"
        }
    ));
    l.push("As fixed joints, for TF (add them and their links to use the frames):".into());
    l.push(format!(
        "  <link name=\"robocal_tracker\"/><joint name=\"robocal_tracker_joint\" type=\"fixed\"><parent link=\"robocal_tracker\"/><child link=\"{}\"/>{}</joint>",
        model.base_link(),
        origin_element(&params.t_tracker_base, true)
    ));
    l.push(format!(
        "  <link name=\"robocal_target\"/><joint name=\"robocal_target_joint\" type=\"fixed\"><parent link=\"{}\"/><child link=\"robocal_target\"/>{}</joint>",
        model.tip_link(),
        origin_element(t_tip_target, orientation)
    ));
    for w in warnings {
        l.push(format!("Warning: {w}."));
    }
    l
}

impl CalibratedUrdf {
    /// How far this file's tip frame, loaded back by sim's URDF reader and carried by
    /// [`CalibratedUrdf::t_tip_flange`], is from the calibrated model's `T_base_flange(q)` over
    /// `configs`: the largest position difference (m) or rotation-matrix entry difference. The CLI's
    /// check before writing.
    pub fn deviation(
        &self,
        model: &Model,
        params: &KinematicParams,
        configs: &[Vec<f64>],
    ) -> Result<f64> {
        let spec = ChainSpec {
            base_link: Some(model.base_link().to_string()),
            tip_link: Some(model.tip_link().to_string()),
        };
        let exported = sim::urdf::load_str(&self.text, "calibrated URDF", &spec)?;
        let mut base_params = params.clone();
        base_params.t_tracker_base = Pose::identity();
        base_params.p_flange_target = Vector3::zeros();
        let chain = Chain::new(model, &base_params);
        let mut s = ChainScratch::new(model.nq());
        let mut data = sim::Data::new(&exported);
        let mut worst = 0.0f64;
        for q in configs {
            chain.forward(&mut s, q);
            let t = sim::flange_pose(&exported, &mut data, q) * self.t_tip_flange;
            let dp = (t.translation.vector - s.t_tracker_flange.translation.vector).norm();
            let dr = (t.rotation.matrix() - s.t_tracker_flange.rotation.matrix()).amax();
            worst = worst.max(dp).max(dr);
        }
        Ok(worst)
    }
}

/// The largest distance (m) on `table` between the full model's predicted target positions and its
/// kinematic part alone, which is what a calibrated URDF holds: 0 for a kinematic model; for a model
/// with extensions or a learned correction, what the URDF leaves out. `name` names the table in errors.
pub fn unexpressed_gap(
    file: &CalibratedModel,
    table: &MeasurementTable,
    name: &str,
) -> Result<f64> {
    if file.model.is_kinematic() && file.learned.is_none() {
        return Ok(0.0);
    }
    let mut predictor = Predictor::from_file(file)?;
    let full = predictor.predict_table(table, name)?;
    let chain = Chain::new(&predictor.model, &predictor.params);
    let mut s = ChainScratch::new(predictor.model.nq());
    let mut worst = 0.0f64;
    for (r, p) in full.position.iter().enumerate() {
        chain.forward(&mut s, table.q_row(r));
        worst = worst.max((s.p_tracker - Vector3::from(*p)).norm());
    }
    Ok(worst)
}
