//! The parameters of the kinematic error model, their layout in the step vector, their names and
//! units, and their expected magnitudes (the column scaling).
//!
//! Step vector layout (length [`ParamLayout::len`]): for each joint `i` (0-based) seven entries
//! `[ξᵢ (ω_x, ω_y, ω_z, v_x, v_y, v_z), δqᵢ]`, then the tracker-to-base twist `β` (6, tracker frame),
//! the target position `p_flange` (3, flange frame) and, with orientation measurements, the target
//! rotation `ρ` (3, target frame), and last the parameters of any model extension
//! ([`crate::extensions`], in [`ParamLayout::extensions`] order).

use crate::extensions::ExtensionParam;
use crate::lie3::exp_rotation;
use crate::units::Unit;
use nalgebra::{DVector, Matrix3, Vector3, Vector6};
use sim::lie::{Pose, exp_twist, log_pose};
use sim::{JointKind, Model};

/// Names of the six components of a twist `[ω; v]`.
pub const TWIST_COMPONENTS: [&str; 6] = ["ω_x", "ω_y", "ω_z", "v_x", "v_y", "v_z"];

/// What one entry of the step vector is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParamKind {
    /// Component `component` (0..6, `[ω; v]`) of joint `joint`'s error twist `ξ` (base frame; rad, m).
    JointTwist {
        /// 0-based joint index.
        joint: usize,
        /// 0..3 rotation ω (rad), 3..6 translation v (m).
        component: usize,
    },
    /// Zero offset `δq` of joint `joint` (rad; m for prismatic joints).
    ZeroOffset {
        /// 0-based joint index.
        joint: usize,
    },
    /// Component (0..6, `[ω; v]`) of the tracker-to-base twist `β` (tracker frame; rad, m).
    BaseTwist {
        /// 0..3 rotation (rad), 3..6 translation (m).
        component: usize,
    },
    /// Axis (0..3) of the target position `p_flange` (flange frame, m).
    TargetPosition {
        /// 0 = x, 1 = y, 2 = z.
        axis: usize,
    },
    /// Axis (0..3) of the target rotation increment `ρ` (target frame, rad).
    TargetOrientation {
        /// 0 = x, 1 = y, 2 = z.
        axis: usize,
    },
    /// Parameter `index` of the model extensions ([`ParamLayout::extensions`]).
    Extension {
        /// Index into [`ParamLayout::extensions`].
        index: usize,
    },
}

/// Layout of the parameter (step) vector for one robot.
#[derive(Clone, Debug, PartialEq)]
pub struct ParamLayout {
    /// Number of joints `n`.
    pub n_joints: usize,
    /// Whether target orientation is part of the model (6-DoF measurements).
    pub orientation: bool,
    /// Per joint: true for prismatic joints (zero offset in m).
    pub prismatic: Vec<bool>,
    /// Parameters of the model extensions, after the kinematic ones (empty for the kinematic model).
    pub extensions: Vec<ExtensionParam>,
}

impl ParamLayout {
    /// Layout for `model`, with target orientation parameters when `orientation`.
    pub fn new(model: &Model, orientation: bool) -> Self {
        ParamLayout {
            n_joints: model.nq(),
            orientation,
            prismatic: model
                .joints
                .iter()
                .map(|j| j.kind == JointKind::Prismatic)
                .collect(),
            extensions: Vec::new(),
        }
    }

    /// The same layout with `extensions` appended.
    pub fn with_extensions(mut self, extensions: Vec<ExtensionParam>) -> Self {
        self.extensions = extensions;
        self
    }

    /// Number of kinematic parameters: `7 n + 9`, or `7 n + 12` with orientation.
    #[inline]
    pub fn kinematic_len(&self) -> usize {
        7 * self.n_joints + if self.orientation { 12 } else { 9 }
    }

    /// Index of extension parameter `e`.
    #[inline]
    pub fn extension(&self, e: usize) -> usize {
        self.kinematic_len() + e
    }

    /// Index of component 0 of joint `i`'s error twist.
    #[inline]
    pub fn joint_twist(&self, i: usize) -> usize {
        7 * i
    }

    /// Index of joint `i`'s zero offset.
    #[inline]
    pub fn zero_offset(&self, i: usize) -> usize {
        7 * i + 6
    }

    /// Index of component 0 of the tracker-to-base twist.
    #[inline]
    pub fn base(&self) -> usize {
        7 * self.n_joints
    }

    /// Index of the target position's x.
    #[inline]
    pub fn target_position(&self) -> usize {
        7 * self.n_joints + 6
    }

    /// Index of the target rotation's x, when orientation is modelled.
    #[inline]
    pub fn target_orientation(&self) -> Option<usize> {
        self.orientation.then_some(7 * self.n_joints + 9)
    }

    /// Number of parameters: the kinematic ones and the extensions'.
    #[inline]
    pub fn len(&self) -> usize {
        self.kinematic_len() + self.extensions.len()
    }

    /// Always false: a layout has at least the base and target parameters.
    #[inline]
    pub fn is_empty(&self) -> bool {
        false
    }

    /// What entry `k` is.
    pub fn kind(&self, k: usize) -> ParamKind {
        let nj = 7 * self.n_joints;
        if k >= self.kinematic_len() {
            ParamKind::Extension {
                index: k - self.kinematic_len(),
            }
        } else if k < nj {
            let (joint, c) = (k / 7, k % 7);
            if c == 6 {
                ParamKind::ZeroOffset { joint }
            } else {
                ParamKind::JointTwist {
                    joint,
                    component: c,
                }
            }
        } else if k < nj + 6 {
            ParamKind::BaseTwist { component: k - nj }
        } else if k < nj + 9 {
            ParamKind::TargetPosition { axis: k - nj - 6 }
        } else {
            ParamKind::TargetOrientation { axis: k - nj - 9 }
        }
    }

    /// Human name of entry `k`, with joints numbered from 1, e.g. `joint 2 twist ω_z`.
    pub fn name(&self, k: usize) -> String {
        const AXES: [&str; 3] = ["x", "y", "z"];
        match self.kind(k) {
            ParamKind::JointTwist { joint, component } => {
                format!("joint {} twist {}", joint + 1, TWIST_COMPONENTS[component])
            }
            ParamKind::ZeroOffset { joint } => format!("joint {} zero offset", joint + 1),
            ParamKind::BaseTwist { component } => {
                format!("base twist {}", TWIST_COMPONENTS[component])
            }
            ParamKind::TargetPosition { axis } => format!("target p_{}", AXES[axis]),
            ParamKind::TargetOrientation { axis } => format!("target rotation ρ_{}", AXES[axis]),
            ParamKind::Extension { index } => self.extensions[index].name(),
        }
    }

    /// Unit of entry `k`: `rad` or `m` (extensions: their own, e.g. `rad/(N m)`).
    pub fn unit(&self, k: usize) -> Unit {
        match self.kind(k) {
            ParamKind::JointTwist { component, .. } | ParamKind::BaseTwist { component } => {
                Unit::angle_or_length(component < 3)
            }
            ParamKind::ZeroOffset { joint } => Unit::angle_or_length(!self.prismatic[joint]),
            ParamKind::TargetPosition { .. } => Unit::Metre,
            ParamKind::TargetOrientation { .. } => Unit::Radian,
            ParamKind::Extension { index } => self.extensions[index].unit,
        }
    }

    /// Indices of the tracker-to-base and target parameters (the "base and tool" fit).
    pub fn base_and_target(&self) -> Vec<usize> {
        (self.base()..self.kinematic_len()).collect()
    }
}

/// Expected magnitudes of the parameters, used to scale the Jacobian's columns (Hollerbach and Wampler,
/// 1996): a scaled unit step is a change of the size one expects. The minimum-norm step in the scaled
/// coordinates therefore moves unidentifiable combinations into the parameters expected to be large
/// (base, target) rather than into the joint errors, and the singular values become "how many noise
/// standard deviations a change of expected size moves the measurements".
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ParameterScales {
    /// Joint error-twist rotation (rad). Default 1e-3.
    pub joint_rotation_rad: f64,
    /// Joint error-twist translation (m). Default 1e-3.
    pub joint_translation_m: f64,
    /// Zero offset of a revolute joint (rad). Default 1e-3.
    pub zero_offset_rad: f64,
    /// Zero offset of a prismatic joint (m). Default 1e-3.
    pub zero_offset_m: f64,
    /// Tracker-to-base rotation still unknown after the closed-form start (rad). Default 1e-2.
    pub base_rotation_rad: f64,
    /// Tracker-to-base translation still unknown after the closed-form start (m). Default 1e-2.
    pub base_translation_m: f64,
    /// Target position in the flange frame (m). Default 1e-2.
    pub target_position_m: f64,
    /// Target orientation (rad). Default 1e-2.
    pub target_rotation_rad: f64,
}

impl Default for ParameterScales {
    fn default() -> Self {
        ParameterScales {
            joint_rotation_rad: 1e-3,
            joint_translation_m: 1e-3,
            zero_offset_rad: 1e-3,
            zero_offset_m: 1e-3,
            base_rotation_rad: 1e-2,
            base_translation_m: 1e-2,
            target_position_m: 1e-2,
            target_rotation_rad: 1e-2,
        }
    }
}

impl ParameterScales {
    /// The scale of every entry of `layout` (physical units per scaled unit).
    pub fn vector(&self, layout: &ParamLayout) -> DVector<f64> {
        DVector::from_fn(layout.len(), |k, _| match layout.kind(k) {
            ParamKind::JointTwist { component, .. } => {
                if component < 3 {
                    self.joint_rotation_rad
                } else {
                    self.joint_translation_m
                }
            }
            ParamKind::ZeroOffset { joint } => {
                if layout.prismatic[joint] {
                    self.zero_offset_m
                } else {
                    self.zero_offset_rad
                }
            }
            ParamKind::BaseTwist { component } => {
                if component < 3 {
                    self.base_rotation_rad
                } else {
                    self.base_translation_m
                }
            }
            ParamKind::TargetPosition { .. } => self.target_position_m,
            ParamKind::TargetOrientation { .. } => self.target_rotation_rad,
            ParamKind::Extension { index } => layout.extensions[index].scale,
        })
    }
}

/// A point in the parameter space of the kinematic model (the estimate or the truth).
///
/// The real screw of joint `i` is `Sᵢ' = Ad(Gᵢ) Sᵢ` (base frame), with `Gᵢ = exp([ξᵢ])` the
/// accumulated error motion of its axis; the joint angle is `qᵢ + δqᵢ`.
#[derive(Clone, Debug, PartialEq)]
pub struct KinematicParams {
    /// `Gᵢ` per joint: the rigid motion (base frame) that carries the nominal axis onto the real one.
    pub joint_error: Vec<Pose>,
    /// `δqᵢ` per joint (rad; m for prismatic joints).
    pub zero_offset: Vec<f64>,
    /// `T_tracker_base`: the robot base frame in the tracker frame (m).
    pub t_tracker_base: Pose,
    /// Target (reflector) position in the flange frame (m).
    pub p_flange_target: Vector3<f64>,
    /// Target orientation in the flange frame, when orientation is measured.
    pub r_flange_target: Option<Matrix3<f64>>,
    /// Values of the extension parameters ([`ParamLayout::extensions`] order and units; empty for the
    /// kinematic model).
    pub extension: Vec<f64>,
}

impl KinematicParams {
    /// The nominal robot: no joint errors, identity base transform, target at the flange origin.
    pub fn nominal(n_joints: usize, orientation: bool) -> Self {
        KinematicParams {
            joint_error: vec![Pose::identity(); n_joints],
            zero_offset: vec![0.0; n_joints],
            t_tracker_base: Pose::identity(),
            p_flange_target: Vector3::zeros(),
            r_flange_target: orientation.then(Matrix3::identity),
            extension: Vec::new(),
        }
    }

    /// From error twists `ξᵢ = [ω; v]` (base frame; rad, m) and the other parameters.
    pub fn from_twists(
        twists: &[Vector6<f64>],
        zero_offset: Vec<f64>,
        t_tracker_base: Pose,
        p_flange_target: Vector3<f64>,
        r_flange_target: Option<Matrix3<f64>>,
    ) -> Self {
        KinematicParams {
            joint_error: twists.iter().map(exp_twist).collect(),
            zero_offset,
            t_tracker_base,
            p_flange_target,
            r_flange_target,
            extension: Vec::new(),
        }
    }

    /// The same parameters with extension values `extension` ([`ParamLayout::extensions`] order).
    pub fn with_extension(mut self, extension: Vec<f64>) -> Self {
        self.extension = extension;
        self
    }

    /// Error twist `ξᵢ = log(Gᵢ)` of joint `i` (base frame; rad, m).
    pub fn joint_twist(&self, i: usize) -> Vector6<f64> {
        log_pose(&self.joint_error[i])
    }

    /// Applies a step (physical units, [`ParamLayout`] order): `Gᵢ ← exp([Δξᵢ]) Gᵢ`, `δqᵢ += Δδqᵢ`,
    /// `T_tracker_base ← exp([β]) T_tracker_base`, `p_flange += Δp`, `R_flange_target ← R exp([ρ])`.
    pub fn retract(&mut self, layout: &ParamLayout, step: &[f64]) {
        debug_assert_eq!(step.len(), layout.len());
        for i in 0..layout.n_joints {
            let k = layout.joint_twist(i);
            let d = Vector6::from_column_slice(&step[k..k + 6]);
            if d.iter().any(|v| *v != 0.0) {
                self.joint_error[i] = exp_twist(&d) * self.joint_error[i];
            }
            self.zero_offset[i] += step[layout.zero_offset(i)];
        }
        let b = layout.base();
        let beta = Vector6::from_column_slice(&step[b..b + 6]);
        if beta.iter().any(|v| *v != 0.0) {
            self.t_tracker_base = exp_twist(&beta) * self.t_tracker_base;
        }
        let t = layout.target_position();
        self.p_flange_target += Vector3::from_column_slice(&step[t..t + 3]);
        if let (Some(o), Some(r)) = (layout.target_orientation(), self.r_flange_target.as_mut()) {
            let rho = Vector3::from_column_slice(&step[o..o + 3]);
            *r *= exp_rotation(&rho);
        }
        for (x, &d) in self
            .extension
            .iter_mut()
            .zip(&step[layout.kinematic_len()..])
        {
            *x += d;
        }
    }
}
