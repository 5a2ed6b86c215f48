//! What decides the rows of a campaign: the [`CampaignSpec`] and its parts (pose source, directions,
//! payload), and the checks that need no robot.

use super::err;
use crate::effects::thermal_drift::TemperatureProfile;
use crate::error::Result;
use crate::kinematics::ik::Reachability;
use std::path::PathBuf;

/// The ISO 9283 test cube (see the module docs).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Iso9283 {
    /// Cube side `L` (m).
    pub cube_side_m: f64,
    /// Cube centre in the base frame (m); `None` = the target position at `seed_q`.
    pub center_base_m: Option<[f64; 3]>,
    /// Joint positions that seed the inverse kinematics and give the orientation kept at every point
    /// (rad or m).
    pub seed_q: Vec<f64>,
}

/// Where the joint positions come from.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Sampling {
    /// Uniform in the joint limits shrunk by `joint_margin_rad`, filtered by reachability.
    Random {
        /// Margin kept from each limit (rad, or m for prismatic joints).
        joint_margin_rad: f64,
        /// Draws per pose before giving up.
        max_tries_per_pose: usize,
    },
    /// The ISO 9283 five-point test.
    Iso9283(Iso9283),
    /// A regular grid in joint space.
    Grid {
        /// Grid values per joint (≥ 1 each).
        points_per_joint: Vec<usize>,
        /// Margin kept from each limit (rad or m).
        joint_margin_rad: f64,
    },
    /// Joint positions given directly (rad or m, one list per pose), e.g. chosen by a pose planner;
    /// cycled or cut to `poses` like a file.
    List {
        /// Joint positions per pose.
        q: Vec<Vec<f64>>,
    },
    /// Joint positions from a measurement table.
    File {
        /// CSV or Parquet measurement table, as opened.
        #[serde(skip)]
        path: PathBuf,
        /// The path as written in the scenario (recorded in `truth.json`).
        as_written: String,
    },
}

/// Where the movable joints of branches off the chain ([`crate::branches`]: a second arm, a head)
/// are at each pose.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BranchRule {
    /// At zero; the table has no `q_<joint>` columns.
    #[default]
    Zero,
    /// Per pose, each uniformly within its limits (±π for a continuous joint), from the seed's
    /// branch stream; written as `q_<joint>` columns.
    Random,
}

/// How approach directions are set (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DirectionRule {
    /// Sign of the move from the previous pose.
    Move,
    /// ±1 at random.
    Random,
    /// Not recorded (no `dir` columns).
    Unknown,
}

/// Mass carried at the flange.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PayloadRule {
    /// The same mass at every pose (kg; 0 = none).
    Fixed(f64),
    /// Per pose, one of these masses (kg) with equal probability.
    Choice(Vec<f64>),
    /// Per pose in order, the mass chosen for it (kg), e.g. by a pose planner; with a pose list of
    /// another length, entry `k` of the cycled list carries mass `k mod len`.
    PerPose(Vec<f64>),
}

/// Everything that decides the rows of a campaign. Made with [`CampaignSpec::random`] (the defaults)
/// or a [`super::CampaignBuilder`] ([`CampaignSpec::builder`], [`CampaignSpec::to_builder`]), which checks
/// every value; read with the accessors.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct CampaignSpec {
    /// Number of poses; `None` = 100 for random sampling, 150 (30 cycles) for ISO 9283, the whole list
    /// for grid and file.
    pub(super) poses: Option<usize>,
    /// Measurements per pose (≥ 1).
    pub(super) repeats: usize,
    /// Pose source.
    pub(super) sampling: Sampling,
    /// Cell constraints for random and grid poses.
    pub(super) reachability: Reachability,
    /// Time between successive poses (s).
    pub(super) seconds_per_pose: f64,
    /// Time between repeated measurements of one pose (s).
    pub(super) seconds_per_repeat: f64,
    /// Approach-direction rule.
    pub(super) directions: DirectionRule,
    /// Where the branches off the chain are.
    pub(super) branches: BranchRule,
    /// Joint positions before the first pose, for the `move` rule (rad or m); `None` = zero, clamped
    /// into the limits.
    pub(super) start_q: Option<Vec<f64>>,
    /// Payload rule.
    pub(super) payload: PayloadRule,
    /// Payload centre of mass in the flange frame (m).
    pub(super) payload_com_m: [f64; 3],
    /// Robot temperature over time.
    pub(super) temperature: TemperatureProfile,
    /// Target (reflector) position in the flange frame (m), for the reachability filter and ISO 9283.
    pub(super) p_flange_m: [f64; 3],
}

impl CampaignSpec {
    /// A random campaign of `poses` poses with the defaults: one measurement each, 10 s apart,
    /// `move` directions, no payload, 20 °C, the reflector 5 cm in front of the flange.
    pub fn random(poses: usize) -> CampaignSpec {
        CampaignSpec {
            poses: Some(poses),
            repeats: 1,
            sampling: Sampling::Random {
                joint_margin_rad: 0.05,
                max_tries_per_pose: 10_000,
            },
            reachability: Reachability::default(),
            seconds_per_pose: 10.0,
            seconds_per_repeat: 1.0,
            directions: DirectionRule::Move,
            branches: BranchRule::Zero,
            start_q: None,
            payload: PayloadRule::Fixed(0.0),
            payload_com_m: [0.0; 3],
            temperature: TemperatureProfile::Constant(20.0),
            p_flange_m: crate::tracker::DEFAULT_P_FLANGE_M,
        }
    }

    /// Number of poses (`None`: see [`super::CampaignBuilder::poses`]).
    pub fn poses(&self) -> Option<usize> {
        self.poses
    }
    /// Measurements per pose.
    pub fn repeats(&self) -> usize {
        self.repeats
    }
    /// Pose source.
    pub fn sampling(&self) -> &Sampling {
        &self.sampling
    }
    /// Cell constraints for random and grid poses.
    pub fn reachability(&self) -> &Reachability {
        &self.reachability
    }
    /// Time between successive poses (s).
    pub fn seconds_per_pose(&self) -> f64 {
        self.seconds_per_pose
    }
    /// Time between repeated measurements of one pose (s).
    pub fn seconds_per_repeat(&self) -> f64 {
        self.seconds_per_repeat
    }
    /// Approach-direction rule.
    pub fn directions(&self) -> DirectionRule {
        self.directions
    }
    /// Where the branches off the chain are.
    pub fn branches(&self) -> BranchRule {
        self.branches
    }
    /// Joint positions before the first pose (rad or m), if given.
    pub fn start_q(&self) -> Option<&[f64]> {
        self.start_q.as_deref()
    }
    /// Payload rule.
    pub fn payload(&self) -> &PayloadRule {
        &self.payload
    }
    /// Payload centre of mass in the flange frame (m).
    pub fn payload_com_m(&self) -> [f64; 3] {
        self.payload_com_m
    }
    /// Robot temperature over time.
    pub fn temperature(&self) -> &TemperatureProfile {
        &self.temperature
    }
    /// Target (reflector) position in the flange frame (m).
    pub fn p_flange_m(&self) -> [f64; 3] {
        self.p_flange_m
    }
}

/// The checks of `spec` that need no robot (shared by [`super::CampaignBuilder::build`] and [`super::plan`]).
pub(super) fn check_model_free(spec: &CampaignSpec, file: &str) -> Result<()> {
    if spec.repeats == 0 {
        return Err(err(file, "campaign.repeats", "0: must be ≥ 1".into()));
    }
    if spec.poses == Some(0) {
        return Err(err(file, "campaign.poses", "0: must be ≥ 1".into()));
    }
    for (key, v) in [
        ("campaign.seconds_per_pose", spec.seconds_per_pose),
        ("campaign.seconds_per_repeat", spec.seconds_per_repeat),
    ] {
        if !(v.is_finite() && v >= 0.0) {
            return Err(err(file, key, format!("{v} must be finite and ≥ 0 s")));
        }
    }
    spec.temperature
        .validate()
        .map_err(|e| err(file, "campaign.temperature", e.to_string()))?;
    let masses: &[f64] = match &spec.payload {
        PayloadRule::Fixed(m) => std::slice::from_ref(m),
        PayloadRule::Choice(v) | PayloadRule::PerPose(v) => v,
    };
    if masses.is_empty() {
        return Err(err(file, "campaign.payload.choice_kg", "empty list".into()));
    }
    if let Some(m) = masses.iter().find(|m| !(m.is_finite() && **m >= 0.0)) {
        return Err(err(
            file,
            "campaign.payload",
            format!("mass {m} must be finite and ≥ 0 kg"),
        ));
    }
    // What the measurement table accepts (its rows are checked again when written).
    let max = crate::measurement_table::MAX_PAYLOAD_KG;
    if let Some(m) = masses.iter().find(|m| **m > max) {
        return Err(err(
            file,
            "campaign.payload",
            format!("mass {m} kg is beyond {max} kg: not a robot payload (kilograms are expected)"),
        ));
    }
    Ok(())
}
