//! The parameters of the kinematic error model, their layout in the step vector, their names and
//! units, and their expected magnitudes (the column scaling).
//!
//! Step vector layout (length [`ParamLayout::len`]): for each joint `i` (0-based) seven entries
//! `[ξᵢ (ω_x, ω_y, ω_z, v_x, v_y, v_z), δqᵢ]`, then the tracker-to-base twist `β` (6, tracker frame),
//! the target position `p_flange` (3, flange frame) and, with orientation measurements, the target
//! rotation `ρ` (3, target frame); with several measurement campaigns, for each campaign after the
//! first its own tracker-to-base twist (6) and, with per-campaign targets, its own target position
//! (3) and rotation (3, with orientation); and last the parameters of any model extension
//! ([`crate::model::extensions`], in [`ParamLayout::extensions`] order). One campaign gives exactly the
//! layout of a table without a `campaign` column.

use crate::lie3::{exp_rotation, log_rotation};
use crate::model::extensions::ExtensionParam;
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
    /// Component (0..6, `[ω; v]`) of campaign `campaign`'s tracker-to-base twist `β` (its tracker
    /// frame; rad, m).
    BaseTwist {
        /// 0-based campaign index ([`ParamLayout::campaign_ids`] order).
        campaign: usize,
        /// 0..3 rotation (rad), 3..6 translation (m).
        component: usize,
    },
    /// Axis (0..3) of the target position `p_flange` (flange frame, m): the shared target (campaign
    /// 0), or a campaign's own with per-campaign targets.
    TargetPosition {
        /// 0-based campaign index (0 for the shared target).
        campaign: usize,
        /// 0 = x, 1 = y, 2 = z.
        axis: usize,
    },
    /// Axis (0..3) of the target rotation increment `ρ` (target frame, rad), shared or per campaign.
    TargetOrientation {
        /// 0-based campaign index (0 for the shared target).
        campaign: usize,
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
    /// Measurement campaigns, one tracker registration each, by id in parameter order (`[0]`: one
    /// campaign, the table without a `campaign` column).
    pub campaign_ids: Vec<i64>,
    /// Whether each campaign after the first has its own target (a re-seated reflector).
    pub campaign_targets: bool,
    /// The robot's coupled joints ([`sim::coupled_joints`]): a joint-angle term of a driven joint
    /// moves the joints it drives as well.
    pub couplings: sim::coupled_joints::Couplings,
}

impl ParamLayout {
    /// Layout for `model`, with target orientation parameters when `orientation`.
    pub fn new(model: &Model, orientation: bool) -> Self {
        ParamLayout {
            n_joints: model.nq(),
            orientation,
            prismatic: model
                .joints()
                .iter()
                .map(|j| j.kind == JointKind::Prismatic)
                .collect(),
            extensions: Vec::new(),
            campaign_ids: vec![0],
            campaign_targets: false,
            couplings: model.couplings().clone(),
        }
    }

    /// The layout for the parameter point `params` (its campaigns) of `model`, with `extensions`.
    pub fn for_params(
        model: &Model,
        params: &KinematicParams,
        extensions: Vec<ExtensionParam>,
    ) -> Self {
        ParamLayout::new(model, params.r_flange_target.is_some())
            .with_campaigns(&params.campaign_ids, params.has_campaign_targets())
            .with_extensions(extensions)
    }

    /// The same layout with one tracker registration per campaign of `ids` (parameter order), and a
    /// target per campaign when `own_targets`. Panics without ids.
    pub fn with_campaigns(mut self, ids: &[i64], own_targets: bool) -> Self {
        assert!(!ids.is_empty(), "at least one campaign");
        self.campaign_ids = ids.to_vec();
        self.campaign_targets = own_targets && ids.len() > 1;
        self
    }

    /// Number of campaigns (tracker registrations).
    #[inline]
    pub fn n_campaigns(&self) -> usize {
        self.campaign_ids.len()
    }

    /// Parameters of the first campaign's target: 3, or 6 with orientation.
    #[inline]
    fn target_len(&self) -> usize {
        if self.orientation { 6 } else { 3 }
    }

    /// Parameters of each campaign after the first: its base twist and, with own targets, its target.
    #[inline]
    fn campaign_block(&self) -> usize {
        6 + if self.campaign_targets {
            self.target_len()
        } else {
            0
        }
    }

    /// Index of component 0 of campaign `c`'s tracker-to-base twist.
    #[inline]
    pub fn campaign_base(&self, c: usize) -> usize {
        if c == 0 {
            self.base()
        } else {
            7 * self.n_joints + 6 + self.target_len() + (c - 1) * self.campaign_block()
        }
    }

    /// Index of the x of the target position campaign `c` uses (its own, or the shared one).
    #[inline]
    pub fn campaign_target_position(&self, c: usize) -> usize {
        if c == 0 || !self.campaign_targets {
            self.target_position()
        } else {
            self.campaign_base(c) + 6
        }
    }

    /// Index of the x of the target rotation campaign `c` uses, when orientation is modelled.
    #[inline]
    pub fn campaign_target_orientation(&self, c: usize) -> Option<usize> {
        if !self.orientation {
            None
        } else if c == 0 || !self.campaign_targets {
            self.target_orientation()
        } else {
            Some(self.campaign_base(c) + 9)
        }
    }

    /// The same layout with `extensions` appended.
    pub fn with_extensions(mut self, extensions: Vec<ExtensionParam>) -> Self {
        self.extensions = extensions;
        self
    }

    /// Number of kinematic parameters: `7 n + 9`, or `7 n + 12` with orientation, plus those of the
    /// campaigns after the first (6 each, 9 or 12 with their own targets).
    #[inline]
    pub fn kinematic_len(&self) -> usize {
        7 * self.n_joints + 6 + self.target_len() + (self.n_campaigns() - 1) * self.campaign_block()
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
            ParamKind::BaseTwist {
                campaign: 0,
                component: k - nj,
            }
        } else if k < nj + 6 + self.target_len() {
            let t = k - nj - 6;
            if t < 3 {
                ParamKind::TargetPosition {
                    campaign: 0,
                    axis: t,
                }
            } else {
                ParamKind::TargetOrientation {
                    campaign: 0,
                    axis: t - 3,
                }
            }
        } else {
            let rest = k - nj - 6 - self.target_len();
            let (campaign, t) = (
                1 + rest / self.campaign_block(),
                rest % self.campaign_block(),
            );
            if t < 6 {
                ParamKind::BaseTwist {
                    campaign,
                    component: t,
                }
            } else if t < 9 {
                ParamKind::TargetPosition {
                    campaign,
                    axis: t - 6,
                }
            } else {
                ParamKind::TargetOrientation {
                    campaign,
                    axis: t - 9,
                }
            }
        }
    }

    /// ` (campaign ID)` after a registration parameter's name when there are several campaigns.
    fn campaign_suffix(&self, c: usize, shared: bool) -> String {
        if self.n_campaigns() == 1 || (shared && !self.campaign_targets) {
            String::new()
        } else {
            format!(" (campaign {})", self.campaign_ids[c])
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
            ParamKind::BaseTwist {
                campaign,
                component,
            } => format!(
                "base twist {}{}",
                TWIST_COMPONENTS[component],
                self.campaign_suffix(campaign, false)
            ),
            ParamKind::TargetPosition { campaign, axis } => format!(
                "target p_{}{}",
                AXES[axis],
                self.campaign_suffix(campaign, true)
            ),
            ParamKind::TargetOrientation { campaign, axis } => format!(
                "target rotation ρ_{}{}",
                AXES[axis],
                self.campaign_suffix(campaign, true)
            ),
            ParamKind::Extension { index } => self.extensions[index].name(),
        }
    }

    /// Unit of entry `k`: `rad` or `m` (extensions: their own, e.g. `rad/(N m)`).
    pub fn unit(&self, k: usize) -> Unit {
        match self.kind(k) {
            ParamKind::JointTwist { component, .. } | ParamKind::BaseTwist { component, .. } => {
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
            ParamKind::BaseTwist { component, .. } => {
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
    /// Ids of the measurement campaigns, in parameter order: the first is registered by
    /// `t_tracker_base` (and the target above), the others by `campaigns`. `[0]` for one campaign.
    pub campaign_ids: Vec<i64>,
    /// The registrations of the campaigns after the first (`campaign_ids[1..]`).
    pub campaigns: Vec<CampaignRegistration>,
    /// Index (into `campaign_ids`) of the campaign of rows that name none (a table without a
    /// `campaign` column): 0, or the campaign `robocal register` added last.
    pub default_campaign: usize,
}

/// The tracker registration of a measurement campaign after the first: where its tracker stood, and,
/// with per-campaign targets, its own target (a re-seated reflector).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CampaignRegistration {
    /// `T_tracker_base` of this campaign (m).
    pub t_tracker_base: Pose,
    /// Its own target position in the flange frame (m), or `None` to share the first campaign's.
    pub p_flange_target: Option<Vector3<f64>>,
    /// Its own target orientation in the flange frame (with own targets and orientation).
    pub r_flange_target: Option<Matrix3<f64>>,
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
            campaign_ids: vec![0],
            campaigns: Vec::new(),
            default_campaign: 0,
        }
    }

    /// Number of campaigns (tracker registrations).
    #[inline]
    pub fn n_campaigns(&self) -> usize {
        self.campaign_ids.len()
    }

    /// Whether the campaigns after the first have their own targets.
    #[inline]
    pub fn has_campaign_targets(&self) -> bool {
        self.campaigns
            .first()
            .is_some_and(|c| c.p_flange_target.is_some())
    }

    /// Index of campaign `id`, if the parameters register it.
    #[inline]
    pub fn campaign_index(&self, id: i64) -> Option<usize> {
        self.campaign_ids.iter().position(|&c| c == id)
    }

    /// `T_tracker_base` of campaign `c` (index).
    #[inline]
    pub fn t_tracker_base_of(&self, c: usize) -> &Pose {
        if c == 0 {
            &self.t_tracker_base
        } else {
            &self.campaigns[c - 1].t_tracker_base
        }
    }

    /// The target position (flange frame, m) campaign `c` uses.
    #[inline]
    pub fn p_flange_target_of(&self, c: usize) -> &Vector3<f64> {
        match c {
            0 => &self.p_flange_target,
            _ => self.campaigns[c - 1]
                .p_flange_target
                .as_ref()
                .unwrap_or(&self.p_flange_target),
        }
    }

    /// The target orientation (flange frame) campaign `c` uses, when orientation is modelled.
    #[inline]
    pub fn r_flange_target_of(&self, c: usize) -> Option<&Matrix3<f64>> {
        match c {
            0 => self.r_flange_target.as_ref(),
            _ => self.campaigns[c - 1]
                .r_flange_target
                .as_ref()
                .or(self.r_flange_target.as_ref()),
        }
    }

    /// The same parameters with the campaigns `ids` (parameter order; the first keeps the current
    /// registration, the others start at `T_tracker_base = start[k]`), each with its own target (a copy
    /// of the shared one) when `own_targets` and there are several.
    pub fn with_campaigns(mut self, ids: &[i64], start: &[Pose], own_targets: bool) -> Self {
        assert!(!ids.is_empty(), "at least one campaign");
        assert_eq!(
            start.len() + 1,
            ids.len(),
            "a start for each campaign after the first"
        );
        let own = own_targets && ids.len() > 1;
        self.campaign_ids = ids.to_vec();
        self.campaigns = start
            .iter()
            .map(|t| CampaignRegistration {
                t_tracker_base: *t,
                p_flange_target: own.then_some(self.p_flange_target),
                r_flange_target: if own { self.r_flange_target } else { None },
            })
            .collect();
        self.default_campaign = 0;
        self
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
            campaign_ids: vec![0],
            campaigns: Vec::new(),
            default_campaign: 0,
        }
    }

    /// The same parameters with extension values `extension` ([`ParamLayout::extensions`] order).
    pub fn with_extension(mut self, extension: Vec<f64>) -> Self {
        self.extension = extension;
        self
    }

    /// The same parameters with a target of its own for every campaign after the first (a copy of
    /// the shared one to start from); unchanged with one campaign.
    pub fn with_own_targets(mut self) -> Self {
        for c in &mut self.campaigns {
            c.p_flange_target = Some(self.p_flange_target);
            c.r_flange_target = self.r_flange_target;
        }
        self
    }

    /// Error twist `ξᵢ = log(Gᵢ)` of joint `i` (base frame; rad, m).
    pub fn joint_twist(&self, i: usize) -> Vector6<f64> {
        log_pose(&self.joint_error[i])
    }

    /// The step (physical units, [`ParamLayout`] order) that [`KinematicParams::retract`] applies to
    /// `self` to reach `other`, both laid out by `layout`: `log(G'ᵢ Gᵢ⁻¹)` per joint,
    /// `log(T' T⁻¹)` per tracker registration, `log(Rᵀ R')` per target rotation, and the differences
    /// of the zero offsets, target positions and extension values.
    pub fn difference(&self, layout: &ParamLayout, other: &KinematicParams) -> Vec<f64> {
        let mut step = vec![0.0; layout.len()];
        let mut put = |k: usize, v: &[f64]| step[k..k + v.len()].copy_from_slice(v);
        for i in 0..layout.n_joints {
            let d = log_pose(&(other.joint_error[i] * self.joint_error[i].inverse()));
            put(layout.joint_twist(i), d.as_slice());
            put(
                layout.zero_offset(i),
                &[other.zero_offset[i] - self.zero_offset[i]],
            );
        }
        let d = log_pose(&(other.t_tracker_base * self.t_tracker_base.inverse()));
        put(layout.base(), d.as_slice());
        put(
            layout.target_position(),
            (other.p_flange_target - self.p_flange_target).as_slice(),
        );
        if let (Some(o), Some(r), Some(r2)) = (
            layout.target_orientation(),
            self.r_flange_target.as_ref(),
            other.r_flange_target.as_ref(),
        ) {
            put(o, log_rotation(&(r.transpose() * r2)).as_slice());
        }
        for (c, (a, b)) in self.campaigns.iter().zip(&other.campaigns).enumerate() {
            let d = log_pose(&(b.t_tracker_base * a.t_tracker_base.inverse()));
            put(layout.campaign_base(c + 1), d.as_slice());
            if let (Some(p), Some(p2)) = (a.p_flange_target, b.p_flange_target) {
                put(layout.campaign_target_position(c + 1), (p2 - p).as_slice());
            }
            if let (Some(r), Some(r2), Some(o)) = (
                a.r_flange_target.as_ref(),
                b.r_flange_target.as_ref(),
                layout.campaign_target_orientation(c + 1),
            ) {
                put(o, log_rotation(&(r.transpose() * r2)).as_slice());
            }
        }
        for (e, (a, b)) in self.extension.iter().zip(&other.extension).enumerate() {
            put(layout.extension(e), &[b - a]);
        }
        step
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
        for (c, reg) in self.campaigns.iter_mut().enumerate() {
            let b = layout.campaign_base(c + 1);
            let beta = Vector6::from_column_slice(&step[b..b + 6]);
            if beta.iter().any(|v| *v != 0.0) {
                reg.t_tracker_base = exp_twist(&beta) * reg.t_tracker_base;
            }
            if let Some(p) = reg.p_flange_target.as_mut() {
                let t = layout.campaign_target_position(c + 1);
                *p += Vector3::from_column_slice(&step[t..t + 3]);
            }
            if let (Some(r), Some(o)) = (
                reg.r_flange_target.as_mut(),
                layout.campaign_target_orientation(c + 1),
            ) {
                *r *= exp_rotation(&Vector3::from_column_slice(&step[o..o + 3]));
            }
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

#[cfg(test)]
mod tests {
    use super::*;
    use rand::rngs::StdRng;
    use rand::{RngExt, SeedableRng};

    /// `difference` inverts `retract`: for random points and steps (joint, base and target motions,
    /// two campaigns with their own targets, orientation, extensions), `a.retract(a.difference(b))`
    /// is `b` and the difference of a retracted step is the step.
    #[test]
    fn difference_inverts_retract() {
        let model = sim::robots::load_builtin("iiwa7").unwrap();
        let mut rng = StdRng::seed_from_u64(11);
        let compliance = |joint: usize| ExtensionParam {
            cause: crate::model::extensions::Cause::ALL[0],
            term: crate::model::extensions::Term::JointAngle { joint },
            quantity: "compliance",
            unit: Unit::RadianPerNewtonMetre,
            scale: 1e-5,
            pattern: None,
        };
        let ext = vec![compliance(1), compliance(3)];
        let start = KinematicParams::nominal(model.nq(), true)
            .with_campaigns(&[0, 4], &[Pose::identity()], true)
            .with_extension(vec![0.0; 2]);
        let layout = ParamLayout::for_params(&model, &start, ext);
        let mut step = |scale: f64| -> Vec<f64> {
            (0..layout.len())
                .map(|_| rng.random_range(-scale..scale))
                .collect()
        };
        let mut a = start.clone();
        a.retract(&layout, &step(0.3));
        let d = step(0.05);
        let mut b = a.clone();
        b.retract(&layout, &d);
        let back = a.difference(&layout, &b);
        for (k, (x, y)) in back.iter().zip(&d).enumerate() {
            assert!((x - y).abs() < 1e-12, "{}: {x} against {y}", layout.name(k));
        }
        let mut c = a.clone();
        c.retract(&layout, &back);
        let again = b.difference(&layout, &c);
        assert!(again.iter().all(|v| v.abs() < 1e-12), "{again:?}");
    }
}
