//! The scenario file as written: one struct per TOML table (see the layout in [`crate::scenario`]).
//! Unknown keys are refused. The `[effects.*]` sections belong to their effects
//! ([`crate::effects::EffectsSection`]).

use crate::campaign::{BranchRule, DirectionRule};
use crate::effects::EffectsSection;
use crate::effects::thermal_drift::TemperatureProfile;
use crate::magnitude::Magnitude;
use serde::{Deserialize, Serialize};

/// `[robot]`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotSection {
    /// Built-in robot name (`iiwa7`, `ur5`, `ur10`, `wam`).
    pub name: Option<String>,
    /// URDF file, relative to the scenario file.
    pub urdf: Option<String>,
    /// Root link of the chain.
    pub base_link: Option<String>,
    /// Tip link of the chain.
    pub tip_link: Option<String>,
    /// Coupled joints declared beside the URDF: a TOML file of `[[coupling]]` tables, relative to the
    /// scenario file ([`crate::coupled_joints`]; the CLI's `--couplings`).
    pub couplings: Option<String>,
    /// Gravity in the base frame (m/s²); default `[0, 0, -9.81]`.
    pub gravity_m_per_s2: Option<[f64; 3]>,
}

/// Which pose source `[campaign] sampling` names.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SamplingKind {
    /// Uniform random in the limits.
    Random,
    /// ISO 9283 cube.
    Iso9283,
    /// Joint-space grid.
    Grid,
    /// From a measurement table.
    File,
}

/// `[campaign.iso9283]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IsoSection {
    /// Cube side (m); default 0.3.
    pub cube_side_m: Option<f64>,
    /// Cube centre, base frame (m); default: the target at `seed_q`.
    pub center_m: Option<[f64; 3]>,
    /// IK seed and orientation pose (rad or m).
    pub seed_q: Vec<f64>,
}

/// Grid points per joint: one number for all joints, or one per joint.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum PointsPerJoint {
    /// The same count for every joint.
    All(usize),
    /// One count per joint.
    PerJoint(Vec<usize>),
}

/// `[campaign.grid]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GridSection {
    /// Grid values per joint.
    pub points_per_joint: PointsPerJoint,
}

/// `[campaign.file]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FileSection {
    /// Measurement table (CSV or Parquet) whose `q` columns give the poses, relative to the scenario.
    pub path: String,
}

/// `[campaign.payload]`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PayloadSection {
    /// Fixed payload (kg).
    pub mass_kg: Option<f64>,
    /// Payload drawn per pose from these (kg).
    pub choice_kg: Option<Vec<f64>>,
    /// Centre of mass in the flange frame (m); default 0.
    pub com_m: Option<[f64; 3]>,
}

/// `[campaign]`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CampaignSection {
    /// Number of poses.
    pub poses: Option<usize>,
    /// Measurements per pose.
    pub repeats: Option<usize>,
    /// Pose source.
    pub sampling: Option<SamplingKind>,
    /// Time between poses (s).
    pub seconds_per_pose: Option<f64>,
    /// Time between repeats (s).
    pub seconds_per_repeat: Option<f64>,
    /// Approach-direction rule.
    pub directions: Option<DirectionRule>,
    /// Where the branches off the chain are.
    pub branches: Option<BranchRule>,
    /// Joint positions before the first pose (rad or m).
    pub start_q: Option<Vec<f64>>,
    /// Margin from the joint limits for random and grid poses (rad or m).
    pub joint_margin_rad: Option<f64>,
    /// Floor height, base frame (m).
    pub floor_z_m: Option<f64>,
    /// Smallest target distance from the base z axis (m).
    pub min_axis_distance_m: Option<f64>,
    /// Random draws per pose before giving up.
    pub max_tries_per_pose: Option<usize>,
    /// ISO 9283 settings.
    pub iso9283: Option<IsoSection>,
    /// Grid settings.
    pub grid: Option<GridSection>,
    /// Pose file settings.
    pub file: Option<FileSection>,
    /// Payload.
    pub payload: Option<PayloadSection>,
    /// Robot temperature over time (°C).
    pub temperature: Option<TemperatureProfile>,
}

/// `[tracker]`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrackerSection {
    /// Robot base origin in the tracker frame (m), shape `[3]`.
    pub xyz_m: Option<Magnitude>,
    /// Robot base roll-pitch-yaw in the tracker frame (rad), shape `[3]`.
    pub rpy_rad: Option<Magnitude>,
    /// Reflector in the flange frame (m).
    pub reflector_m: Option<[f64; 3]>,
    /// 6-DoF probe (adds `qw..qz`).
    pub six_dof: Option<bool>,
    /// Probe orientation in the flange frame, roll-pitch-yaw (rad).
    pub probe_rpy_rad: Option<[f64; 3]>,
    /// Radial σ constant part (m).
    pub radial_sigma_a_m: Option<f64>,
    /// Radial σ per metre of distance (m/m).
    pub radial_sigma_b_m_per_m: Option<f64>,
    /// Transverse σ constant part (m).
    pub transverse_sigma_a_m: Option<f64>,
    /// Transverse σ per metre of distance (m/m).
    pub transverse_sigma_b_m_per_m: Option<f64>,
    /// 6-DoF orientation σ per axis (rad).
    pub orientation_sigma_rad: Option<f64>,
    /// Fraction of rows with a gross error.
    pub outlier_rate: Option<f64>,
    /// Gross error size (m).
    pub outlier_magnitude_m: Option<f64>,
    /// Multiplier on all tracker errors.
    pub noise_scale: Option<f64>,
}

/// How the truth is computed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TruthModel {
    /// Closed-form kinematics with the injected effects ([`crate::effects::Truth`]).
    #[default]
    Analytic,
    /// The analytic truth with its compliance stage settled by the rapier physics engine on the same
    /// real geometry ([`crate::effects::ComplianceSolver::Rapier`] with the default
    /// [`crate::springs::SettleOptions`]); needs `[effects.compliance]`.
    Rapier,
}

/// `[truth]`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TruthSection {
    /// Truth model; default `analytic`.
    pub model: Option<TruthModel>,
}

/// The whole scenario file, as written.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScenarioFile {
    /// Short name.
    pub name: Option<String>,
    /// Free text.
    pub description: Option<String>,
    /// Seed of every random draw; default 0.
    pub seed: Option<u64>,
    /// The robot.
    pub robot: RobotSection,
    /// The campaign.
    #[serde(default)]
    pub campaign: CampaignSection,
    /// The tracker.
    #[serde(default)]
    pub tracker: TrackerSection,
    /// Injected effects.
    #[serde(default)]
    pub effects: EffectsSection,
    /// Truth model.
    #[serde(default)]
    pub truth: TruthSection,
}
