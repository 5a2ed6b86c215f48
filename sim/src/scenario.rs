//! Scenario files: one TOML file says which robot, which injected errors, which tracker and which
//! campaign. [`Scenario::parse`] reads it (refusing unknown keys and wrong types, naming the line and
//! key); [`Scenario::resolve`] draws every random magnitude from the seed and checks the result against
//! the robot, giving a [`Resolved`] scenario ready for [`crate::generate`].
//!
//! # Layout
//!
//! ```toml
//! name = "iiwa7_all"          # optional
//! description = "..."         # optional
//! seed = 42                   # optional (default 0); `robocal generate --seed` overrides it
//!
//! [robot]
//! name = "iiwa7"              # a built-in robot, or:
//! # urdf = "robots/my.urdf"   # a URDF file, relative to this scenario file
//! # base_link = "..."; tip_link = "..."
//! # gravity_m_per_s2 = [0.0, 0.0, -9.81]
//!
//! [campaign]                  # see crate::campaign for the meaning
//! poses = 200                 # default: 100 random, 150 for iso9283, the whole list for grid/file
//! repeats = 1
//! sampling = "random"         # "random" | "iso9283" | "grid" | "file" (default: random, or the one
//!                             #  sub-table given)
//! seconds_per_pose = 10.0
//! seconds_per_repeat = 1.0
//! directions = "move"         # "move" | "random" | "unknown"
//! start_q = [0, 0, 0, 0, 0, 0, 0]
//! joint_margin_rad = 0.05     # random and grid
//! floor_z_m = 0.05            # reachability filter, base frame
//! min_axis_distance_m = 0.10
//! max_tries_per_pose = 10000
//! [campaign.iso9283]          # cube_side_m = 0.3, center_m = [x, y, z] (optional), seed_q = [...]
//! [campaign.grid]             # points_per_joint = [3, 3, 3, 3, 3, 3, 1] (or one number for all)
//! [campaign.file]             # path = "poses.csv"
//! [campaign.payload]          # mass_kg = 2.0, or choice_kg = [0.0, 1.5, 3.0]; com_m = [0, 0, 0.05]
//! [campaign.temperature]      # constant = 20.0 | warm_up = { t0_c, delta_c, tau_s } |
//!                             # schedule = [[t_s, temp_c], ...]
//!
//! [tracker]
//! xyz_m = [2.5, 1.0, -0.2]    # robot base origin in the tracker frame (m)
//! rpy_rad = [0.0, 0.0, 2.5]   # robot base orientation in the tracker frame (rad)
//! reflector_m = [0.0, 0.0, 0.05]   # target in the flange frame (m)
//! six_dof = false; probe_rpy_rad = [0, 0, 0]
//! radial_sigma_a_m = 5e-6; radial_sigma_b_m_per_m = 0.15e-6
//! transverse_sigma_a_m = 7.5e-6; transverse_sigma_b_m_per_m = 3e-6
//! orientation_sigma_rad = 8.7e-5
//! outlier_rate = 0.0; outlier_magnitude_m = 1e-3
//! noise_scale = 1.0           # `robocal generate --noise` overrides it
//!
//! [effects.kinematic]         # any subset; each: shape below
//! joint_rotation_rad = { normal = [0.0, 3e-4] }     # [n][3]: ω of each joint's error twist
//! joint_translation_m = { normal = [0.0, 2e-4] }    # [n][3]: v of each joint's error twist
//! zero_offset_rad = { normal = [0.0, 5e-4] }        # [n]
//! base_rotation_rad = ...; base_translation_m = ... # [3] each
//! tool_rotation_rad = ...; tool_translation_m = ... # [3] each
//! [effects.compliance]
//! stiffness_nm_per_rad = { uniform = [5e3, 2e4] }   # [n]; inf = rigid
//! [effects.backlash]
//! dead_band_rad = 2.9e-4      # [n]
//! mode = "direction"          # or "gravity" (then threshold_nm, [n])
//! [effects.thermal]
//! t_ref_c = 20.0
//! alpha_per_k = 23e-6         # [n + 1], links 0 … n
//! beta_rad_per_k = 0.0        # [n]
//!
//! [truth]
//! model = "analytic"          # or "rapier": joint compliance settled by the rapier physics engine
//! ```
//!
//! Every effect table may carry `enabled = false` to switch it off without deleting it.
//!
//! # Magnitudes
//!
//! Every effect magnitude (and the tracker placement) is a [`Magnitude`]: a number (the same value
//! for every entry), a random draw `{ uniform = [low, high] }` or `{ normal = [mean, sd] }` (drawn
//! independently for every entry), or a list with one item per joint (each item again a magnitude,
//! so `[1e4, { uniform = [5e3, 2e4] }, ...]` and, for `[n][3]` shapes, `[[0, 0, 1e-4], ...]` work).
//! Draws come from a generator seeded by the scenario seed and the key's name (see
//! [`crate::campaign::derive_seed`]), drawn in list order, so the same seed always gives the same
//! robot and adding a key does not change the others' draws.

use crate::campaign::{
    CampaignSpec, DirectionRule, Iso9283, PayloadRule, Reachability, STREAM_PARAMETERS, Sampling,
    rng_for,
};
use crate::effects::Effects;
use crate::effects::gear_backlash::{BacklashMode, GearBacklash};
use crate::effects::joint_compliance::JointCompliance;
use crate::effects::kinematic_offsets::KinematicOffsets;
use crate::effects::thermal_drift::{TemperatureProfile, ThermalDrift};
use crate::error::{Result, SimError};
use crate::model::Model;
use crate::tracker::{self, NoiseModel, Tracker};
use crate::urdf::ChainSpec;
use nalgebra::Vector3;
use rand::RngExt;
use rand_distr::StandardNormal;
use serde::de::{self, MapAccess, SeqAccess, Visitor};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// A fixed value, a random draw, or a list of magnitudes (see the module docs).
#[derive(Clone, Debug, PartialEq)]
pub enum Magnitude {
    /// The same value for every entry.
    Number(f64),
    /// An independent draw for every entry.
    Draw(Draw),
    /// One item per entry of the leading dimension.
    List(Vec<Magnitude>),
}

/// A random draw.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Draw {
    /// Uniform on `[low, high]`.
    Uniform([f64; 2]),
    /// Normal with `[mean, standard deviation]`.
    Normal([f64; 2]),
}

impl Serialize for Magnitude {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        match self {
            Magnitude::Number(x) => s.serialize_f64(*x),
            Magnitude::Draw(d) => d.serialize(s),
            Magnitude::List(v) => v.serialize(s),
        }
    }
}

struct MagnitudeVisitor;

impl<'de> Visitor<'de> for MagnitudeVisitor {
    type Value = Magnitude;
    fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(
            "a number, a list, or a random draw { uniform = [low, high] } or { normal = [mean, sd] }",
        )
    }
    fn visit_f64<E: de::Error>(self, v: f64) -> std::result::Result<Magnitude, E> {
        Ok(Magnitude::Number(v))
    }
    fn visit_i64<E: de::Error>(self, v: i64) -> std::result::Result<Magnitude, E> {
        Ok(Magnitude::Number(v as f64))
    }
    fn visit_u64<E: de::Error>(self, v: u64) -> std::result::Result<Magnitude, E> {
        Ok(Magnitude::Number(v as f64))
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> std::result::Result<Magnitude, A::Error> {
        let mut v = Vec::new();
        while let Some(m) = seq.next_element::<Magnitude>()? {
            v.push(m);
        }
        Ok(Magnitude::List(v))
    }
    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> std::result::Result<Magnitude, A::Error> {
        const KINDS: &[&str] = &["uniform", "normal"];
        let Some(kind) = map.next_key::<String>()? else {
            return Err(de::Error::custom(
                "empty table: a draw is { uniform = [low, high] } or { normal = [mean, sd] }",
            ));
        };
        let params: [f64; 2] = map.next_value()?;
        let draw = match kind.as_str() {
            "uniform" => Draw::Uniform(params),
            "normal" => Draw::Normal(params),
            _ => return Err(de::Error::unknown_field(&kind, KINDS)),
        };
        if let Some(extra) = map.next_key::<String>()? {
            return Err(de::Error::custom(format!(
                "a draw has exactly one key (uniform or normal); found also `{extra}`"
            )));
        }
        Ok(Magnitude::Draw(draw))
    }
}

impl<'de> Deserialize<'de> for Magnitude {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Magnitude, D::Error> {
        d.deserialize_any(MagnitudeVisitor)
    }
}

/// FNV-1a, 64 bit: a stable hash for stream ids and file fingerprints.
pub fn fnv1a64(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in bytes {
        h ^= u64::from(*b);
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    h
}

impl Magnitude {
    /// Resolves to `shape.iter().product()` numbers, row-major, drawing from a generator seeded by
    /// `seed` and `key`. `file` and `key` name errors.
    pub fn resolve(&self, seed: u64, file: &str, key: &str, shape: &[usize]) -> Result<Vec<f64>> {
        let mut rng = rng_for(seed, STREAM_PARAMETERS, fnv1a64(key.as_bytes()));
        let mut out = Vec::with_capacity(shape.iter().product());
        self.fill(&mut rng, file, key, shape, &mut out)?;
        Ok(out)
    }

    fn fill<R: rand::Rng>(
        &self,
        rng: &mut R,
        file: &str,
        key: &str,
        shape: &[usize],
        out: &mut Vec<f64>,
    ) -> Result<()> {
        let e = |m: String| scenario_err(file, key, m);
        match self {
            Magnitude::Number(x) => {
                if x.is_nan() {
                    return Err(e("NaN is not a value".into()));
                }
                out.extend(std::iter::repeat_n(*x, shape.iter().product()));
            }
            Magnitude::Draw(d) => {
                let count: usize = shape.iter().product();
                match *d {
                    Draw::Uniform([lo, hi]) => {
                        if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
                            return Err(e(format!(
                                "uniform = [{lo}, {hi}] needs finite bounds with low ≤ high"
                            )));
                        }
                        for _ in 0..count {
                            let u: f64 = rng.random();
                            out.push(lo + (hi - lo) * u);
                        }
                    }
                    Draw::Normal([mean, sd]) => {
                        if !(mean.is_finite() && sd.is_finite() && sd >= 0.0) {
                            return Err(e(format!(
                                "normal = [{mean}, {sd}] needs a finite mean and a standard deviation ≥ 0"
                            )));
                        }
                        for _ in 0..count {
                            let z: f64 = rng.sample(StandardNormal);
                            out.push(mean + sd * z);
                        }
                    }
                }
            }
            Magnitude::List(items) => {
                let Some((&first, rest)) = shape.split_first() else {
                    return Err(e(format!(
                        "a list of {} where one value is expected",
                        items.len()
                    )));
                };
                if items.len() != first {
                    return Err(e(format!(
                        "{} entries, expected {first} (or one value or draw for all)",
                        items.len()
                    )));
                }
                for (i, m) in items.iter().enumerate() {
                    m.fill(rng, file, &format!("{key}[{i}]"), rest, out)?;
                }
            }
        }
        Ok(())
    }
}

fn scenario_err(file: &str, key: &str, message: String) -> SimError {
    SimError::Scenario {
        file: file.to_string(),
        key: key.to_string(),
        message,
    }
}

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

/// `[effects.kinematic]`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KinematicSection {
    /// Switch (default on).
    pub enabled: Option<bool>,
    /// Rotation part ω of each joint's error twist (rad, base frame), shape `[n][3]`.
    pub joint_rotation_rad: Option<Magnitude>,
    /// Translation part v of each joint's error twist (m, base frame), shape `[n][3]`.
    pub joint_translation_m: Option<Magnitude>,
    /// Joint zero offsets (rad; m for prismatic joints), shape `[n]`.
    pub zero_offset_rad: Option<Magnitude>,
    /// Base error twist rotation (rad), shape `[3]`.
    pub base_rotation_rad: Option<Magnitude>,
    /// Base error twist translation (m), shape `[3]`.
    pub base_translation_m: Option<Magnitude>,
    /// Tool error twist rotation (rad, flange frame), shape `[3]`.
    pub tool_rotation_rad: Option<Magnitude>,
    /// Tool error twist translation (m, flange frame), shape `[3]`.
    pub tool_translation_m: Option<Magnitude>,
}

/// `[effects.compliance]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ComplianceSection {
    /// Switch (default on).
    pub enabled: Option<bool>,
    /// Joint stiffness (N m/rad; N/m for prismatic joints), shape `[n]`.
    pub stiffness_nm_per_rad: Magnitude,
}

/// `[effects.backlash]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BacklashSection {
    /// Switch (default on).
    pub enabled: Option<bool>,
    /// Dead band (rad; m for prismatic joints), shape `[n]`.
    pub dead_band_rad: Magnitude,
    /// Flank rule; default `direction`.
    pub mode: Option<BacklashMode>,
    /// Gravity-mode holding-torque threshold (N m), shape `[n]`.
    pub threshold_nm: Option<Magnitude>,
}

/// `[effects.thermal]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ThermalSection {
    /// Switch (default on).
    pub enabled: Option<bool>,
    /// Temperature at which the nominal model is exact (°C); default 20.
    pub t_ref_c: Option<f64>,
    /// Link expansion coefficients (1/K), shape `[n + 1]`.
    pub alpha_per_k: Magnitude,
    /// Joint-zero drift (rad/K), shape `[n]`; default 0.
    pub beta_rad_per_k: Option<Magnitude>,
}

/// `[effects]`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EffectsSection {
    /// Geometric errors.
    pub kinematic: Option<KinematicSection>,
    /// Joint stiffness.
    pub compliance: Option<ComplianceSection>,
    /// Gear lost motion.
    pub backlash: Option<BacklashSection>,
    /// Temperature effects.
    pub thermal: Option<ThermalSection>,
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
    /// [`crate::rapier_truth::SettleOptions`]); needs `[effects.compliance]`.
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

/// A parsed scenario with where it came from.
#[derive(Clone, Debug, PartialEq)]
pub struct Scenario {
    /// File name used in messages (as given).
    pub label: String,
    /// Folder relative paths in the file refer to.
    pub base_dir: PathBuf,
    /// The file's text.
    pub text: String,
    /// The parsed file.
    pub file: ScenarioFile,
}

/// Command-line overrides of the scenario.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Overrides {
    /// Replaces `seed`.
    pub seed: Option<u64>,
    /// Replaces `[campaign] poses`.
    pub poses: Option<usize>,
    /// Replaces `[tracker] noise_scale`.
    pub noise: Option<f64>,
}

/// Where the robot came from, for the record.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RobotSource {
    /// `built-in iiwa7` or the URDF file name.
    pub source: String,
    /// FNV-1a 64 hash of the URDF text, hex.
    pub urdf_fnv1a64: String,
}

/// A scenario with every draw made and every value checked: what the generator runs.
#[derive(Clone, Debug)]
pub struct Resolved {
    /// The parsed scenario.
    pub scenario: Scenario,
    /// The overrides applied.
    pub overrides: Overrides,
    /// The seed in force.
    pub seed: u64,
    /// The nominal robot.
    pub model: Model,
    /// Where the robot came from.
    pub robot_source: RobotSource,
    /// Gravity in the base frame (m/s²).
    pub gravity: Vector3<f64>,
    /// The injected effects, every number resolved.
    pub effects: Effects,
    /// The tracker, placement resolved.
    pub tracker: Tracker,
    /// Tracker placement as drawn: base origin in the tracker frame (m).
    pub tracker_xyz_m: [f64; 3],
    /// Tracker placement as drawn: base roll-pitch-yaw in the tracker frame (rad).
    pub tracker_rpy_rad: [f64; 3],
    /// The campaign.
    pub campaign: CampaignSpec,
    /// Truth model.
    pub truth_model: TruthModel,
}

/// Line, section and key at byte `pos` of `text`: `line 12, [effects.compliance] stiffness`.
fn locate(text: &str, pos: usize) -> String {
    let pos = pos.min(text.len());
    let before = &text[..pos];
    let line_no = before.matches('\n').count() + 1;
    let is_header = |l: &str| {
        let t = l.trim();
        t.starts_with('[')
            && t.chars()
                .nth(1)
                .is_some_and(|c| c.is_ascii_alphabetic() || c == '[' || c == '_')
            && !t.contains('=')
    };
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    let section = text[..line_start]
        .lines()
        .rev()
        .find(|l| is_header(l))
        .map(|l| {
            let t = l.trim();
            t[..t.find(']').map_or(t.len(), |i| i + 1)].to_string()
        })
        .filter(|_| !text.lines().nth(line_no - 1).is_some_and(is_header));
    let line = text.lines().nth(line_no - 1).unwrap_or("");
    let key = line.split_once('=').map(|(k, _)| k.trim().to_string());
    let mut s = format!("line {line_no}");
    if let Some(sec) = section {
        s.push_str(&format!(", {sec}"));
    }
    if let Some(k) = key.filter(|k| !k.is_empty()) {
        s.push_str(&format!(" {k}"));
    }
    s
}

fn on(enabled: Option<bool>) -> bool {
    enabled.unwrap_or(true)
}

fn three(v: Vec<f64>) -> [f64; 3] {
    [v[0], v[1], v[2]]
}

/// Converts an effect constructor's error into one naming the scenario key.
fn effect_err(file: &str, section: &str, e: SimError) -> SimError {
    match e {
        SimError::BadEffect {
            field,
            value,
            problem,
            ..
        } => scenario_err(
            file,
            &format!("effects.{section}.{field}"),
            format!("value {value}: {problem}"),
        ),
        other => scenario_err(file, &format!("effects.{section}"), other.to_string()),
    }
}

impl Scenario {
    /// Parses scenario `text`; `label` names it in errors and `base_dir` anchors its relative paths.
    /// Unknown keys, wrong types and malformed TOML are refused with the line, section and key.
    pub fn parse(text: &str, label: &str, base_dir: &Path) -> Result<Scenario> {
        let file: ScenarioFile = toml::from_str(text).map_err(|e| {
            let key = e
                .span()
                .map_or_else(|| "toml".to_string(), |s| locate(text, s.start));
            let message = e.message().trim().replace('\n', " ");
            scenario_err(label, &key, message)
        })?;
        Ok(Scenario {
            label: label.to_string(),
            base_dir: base_dir.to_path_buf(),
            text: text.to_string(),
            file,
        })
    }

    /// Reads and parses the scenario file at `path`.
    pub fn load(path: &Path) -> Result<Scenario> {
        let text = std::fs::read_to_string(path).map_err(|source| SimError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        let base = path
            .parent()
            .map_or_else(|| PathBuf::from("."), Path::to_path_buf);
        Scenario::parse(&text, &path.display().to_string(), &base)
    }

    fn load_robot(&self) -> Result<(Model, RobotSource)> {
        let f = &self.label;
        let r = &self.file.robot;
        let spec = ChainSpec {
            base_link: r.base_link.clone(),
            tip_link: r.tip_link.clone(),
        };
        let (text, source) = match (&r.name, &r.urdf) {
            (Some(_), Some(_)) => {
                return Err(scenario_err(
                    f,
                    "robot",
                    "give either name or urdf, not both".into(),
                ));
            }
            (None, None) => {
                return Err(scenario_err(
                    f,
                    "robot",
                    "needs name (a built-in robot) or urdf (a file)".into(),
                ));
            }
            (Some(name), None) => {
                let t = crate::robots::builtin_urdf(name).ok_or_else(|| {
                    scenario_err(
                        f,
                        "robot.name",
                        format!(
                            "unknown built-in robot '{name}' (known: {}); for a file use urdf = \"...\"",
                            crate::robots::BUILTIN
                                .iter()
                                .map(|(n, _)| *n)
                                .collect::<Vec<_>>()
                                .join(", ")
                        ),
                    )
                })?;
                (t.to_string(), format!("built-in {name}"))
            }
            (None, Some(u)) => {
                let path = self.base_dir.join(u);
                let t = std::fs::read_to_string(&path).map_err(|e| {
                    scenario_err(
                        f,
                        "robot.urdf",
                        format!("cannot read {}: {e}", path.display()),
                    )
                })?;
                let name = Path::new(u)
                    .file_name()
                    .map_or_else(|| u.clone(), |n| n.to_string_lossy().into_owned());
                (t, name)
            }
        };
        let model = crate::urdf::load_str(&text, &source, &spec)
            .map_err(|e| scenario_err(f, "robot", e.to_string()))?;
        Ok((
            model,
            RobotSource {
                source,
                urdf_fnv1a64: format!("{:016x}", fnv1a64(text.as_bytes())),
            },
        ))
    }

    fn effects(&self, model: &Model, seed: u64) -> Result<Effects> {
        let f = self.label.as_str();
        let n = model.nq();
        let fx = &self.file.effects;
        let mut effects = Effects::default();
        let get = |m: &Option<Magnitude>, key: &str, shape: &[usize]| -> Result<Vec<f64>> {
            match m {
                Some(m) => m.resolve(seed, f, key, shape),
                None => Ok(vec![0.0; shape.iter().product()]),
            }
        };
        if let Some(k) = fx.kinematic.as_ref().filter(|k| on(k.enabled)) {
            let key = |s: &str| format!("effects.kinematic.{s}");
            let w = get(&k.joint_rotation_rad, &key("joint_rotation_rad"), &[n, 3])?;
            let v = get(&k.joint_translation_m, &key("joint_translation_m"), &[n, 3])?;
            let dq = get(&k.zero_offset_rad, &key("zero_offset_rad"), &[n])?;
            let bw = get(&k.base_rotation_rad, &key("base_rotation_rad"), &[3])?;
            let bv = get(&k.base_translation_m, &key("base_translation_m"), &[3])?;
            let tw = get(&k.tool_rotation_rad, &key("tool_rotation_rad"), &[3])?;
            let tv = get(&k.tool_translation_m, &key("tool_translation_m"), &[3])?;
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
            effects.kinematic = Some(
                KinematicOffsets::new(twists, dq, six(&bw, &bv), six(&tw, &tv))
                    .map_err(|e| effect_err(f, "kinematic", e))?,
            );
        }
        if let Some(c) = fx.compliance.as_ref().filter(|c| on(c.enabled)) {
            model.require_inertials().map_err(|e| {
                scenario_err(
                    f,
                    "effects.compliance",
                    format!("{e}; compliance needs them"),
                )
            })?;
            let k = c.stiffness_nm_per_rad.resolve(
                seed,
                f,
                "effects.compliance.stiffness_nm_per_rad",
                &[n],
            )?;
            effects.compliance =
                Some(JointCompliance::new(k).map_err(|e| effect_err(f, "compliance", e))?);
        }
        if let Some(b) = fx.backlash.as_ref().filter(|b| on(b.enabled)) {
            let band = b
                .dead_band_rad
                .resolve(seed, f, "effects.backlash.dead_band_rad", &[n])?;
            let mode = b.mode.unwrap_or(BacklashMode::Direction);
            let bl = match (mode, &b.threshold_nm) {
                (BacklashMode::Direction, None) => GearBacklash::direction(band),
                (BacklashMode::Direction, Some(_)) => {
                    return Err(scenario_err(
                        f,
                        "effects.backlash.threshold_nm",
                        "only used with mode = \"gravity\"".into(),
                    ));
                }
                (BacklashMode::Gravity, None) => {
                    return Err(scenario_err(
                        f,
                        "effects.backlash.threshold_nm",
                        "mode = \"gravity\" needs a holding-torque threshold (N m)".into(),
                    ));
                }
                (BacklashMode::Gravity, Some(t)) => {
                    model.require_inertials().map_err(|e| {
                        scenario_err(
                            f,
                            "effects.backlash.mode",
                            format!("{e}; gravity-mode backlash needs them"),
                        )
                    })?;
                    let t = t.resolve(seed, f, "effects.backlash.threshold_nm", &[n])?;
                    GearBacklash::gravity(band, t)
                }
            };
            effects.backlash = Some(bl.map_err(|e| effect_err(f, "backlash", e))?);
        }
        if let Some(t) = fx.thermal.as_ref().filter(|t| on(t.enabled)) {
            let alpha = t
                .alpha_per_k
                .resolve(seed, f, "effects.thermal.alpha_per_k", &[n + 1])?;
            let beta = get(&t.beta_rad_per_k, "effects.thermal.beta_rad_per_k", &[n])?;
            effects.thermal = Some(
                ThermalDrift::new(t.t_ref_c.unwrap_or(20.0), alpha, beta)
                    .map_err(|e| effect_err(f, "thermal", e))?,
            );
        }
        effects
            .check_fits(model)
            .map_err(|e| scenario_err(f, "effects", e.to_string()))?;
        Ok(effects)
    }

    fn tracker(&self, seed: u64, noise: Option<f64>) -> Result<(Tracker, [f64; 3], [f64; 3])> {
        let f = self.label.as_str();
        let t = &self.file.tracker;
        let xyz = match &t.xyz_m {
            Some(m) => three(m.resolve(seed, f, "tracker.xyz_m", &[3])?),
            None => tracker::DEFAULT_BASE_XYZ_M,
        };
        let rpy = match &t.rpy_rad {
            Some(m) => three(m.resolve(seed, f, "tracker.rpy_rad", &[3])?),
            None => tracker::DEFAULT_BASE_RPY_RAD,
        };
        let d = Vector3::from(xyz).norm();
        if d > 100.0 {
            return Err(scenario_err(
                f,
                "tracker.xyz_m",
                format!("the robot is {d} m from the tracker: give metres, not millimetres"),
            ));
        }
        if let Some((k, v)) = rpy
            .iter()
            .enumerate()
            .find(|(_, v)| v.abs() > 2.0 * std::f64::consts::PI)
        {
            return Err(scenario_err(
                f,
                &format!("tracker.rpy_rad[{k}]"),
                format!("{v} is more than 2π: give radians, not degrees"),
            ));
        }
        let reflector = t.reflector_m.unwrap_or(tracker::DEFAULT_P_FLANGE_M);
        let r = Vector3::from(reflector).norm();
        if r > 2.0 {
            return Err(scenario_err(
                f,
                "tracker.reflector_m",
                format!("{r} m from the flange: give metres, not millimetres"),
            ));
        }
        let dflt = NoiseModel::default();
        let noise_model = NoiseModel {
            radial_a_m: t.radial_sigma_a_m.unwrap_or(dflt.radial_a_m),
            radial_b_m_per_m: t.radial_sigma_b_m_per_m.unwrap_or(dflt.radial_b_m_per_m),
            transverse_a_m: t.transverse_sigma_a_m.unwrap_or(dflt.transverse_a_m),
            transverse_b_m_per_m: t
                .transverse_sigma_b_m_per_m
                .unwrap_or(dflt.transverse_b_m_per_m),
            orientation_sigma_rad: t
                .orientation_sigma_rad
                .unwrap_or(dflt.orientation_sigma_rad),
            outlier_rate: t.outlier_rate.unwrap_or(dflt.outlier_rate),
            outlier_magnitude_m: t.outlier_magnitude_m.unwrap_or(dflt.outlier_magnitude_m),
        };
        let scale = noise.or(t.noise_scale).unwrap_or(1.0);
        let map = |e: SimError| match e {
            SimError::BadCondition {
                field,
                value,
                problem,
            } => {
                let key = match field.as_str() {
                    "tracker.radial_a_m" => "tracker.radial_sigma_a_m".to_string(),
                    "tracker.radial_b_m_per_m" => "tracker.radial_sigma_b_m_per_m".to_string(),
                    "tracker.transverse_a_m" => "tracker.transverse_sigma_a_m".to_string(),
                    "tracker.transverse_b_m_per_m" => {
                        "tracker.transverse_sigma_b_m_per_m".to_string()
                    }
                    "tracker.noise_scale" if noise.is_some() => "--noise".to_string(),
                    other => other.to_string(),
                };
                scenario_err(f, &key, format!("value {value}: {problem}"))
            }
            other => scenario_err(f, "tracker", other.to_string()),
        };
        let mut tr = Tracker::new(xyz, rpy, reflector, noise_model, scale).map_err(map)?;
        if t.six_dof.unwrap_or(false) {
            tr = tr.with_six_dof(t.probe_rpy_rad.unwrap_or([0.0; 3]));
        } else if t.probe_rpy_rad.is_some() {
            return Err(scenario_err(
                f,
                "tracker.probe_rpy_rad",
                "only used with six_dof = true".into(),
            ));
        }
        Ok((tr, xyz, rpy))
    }

    fn campaign(
        &self,
        model: &Model,
        poses: Option<usize>,
        p_flange: [f64; 3],
    ) -> Result<CampaignSpec> {
        let f = self.label.as_str();
        let c = &self.file.campaign;
        let mut spec = CampaignSpec::random(100);
        spec.poses = poses.or(c.poses);
        spec.repeats = c.repeats.unwrap_or(1);
        spec.seconds_per_pose = c.seconds_per_pose.unwrap_or(spec.seconds_per_pose);
        spec.seconds_per_repeat = c.seconds_per_repeat.unwrap_or(spec.seconds_per_repeat);
        spec.directions = c.directions.unwrap_or(DirectionRule::Move);
        spec.start_q = c.start_q.clone();
        spec.p_flange_m = p_flange;
        spec.reachability = Reachability {
            floor_z_m: c.floor_z_m.unwrap_or(spec.reachability.floor_z_m),
            min_axis_distance_m: c
                .min_axis_distance_m
                .unwrap_or(spec.reachability.min_axis_distance_m),
        };
        for (key, v) in [
            ("campaign.floor_z_m", spec.reachability.floor_z_m),
            (
                "campaign.min_axis_distance_m",
                spec.reachability.min_axis_distance_m,
            ),
        ] {
            if !v.is_finite() || v.abs() > 10.0 {
                return Err(scenario_err(
                    f,
                    key,
                    format!("{v} is not a plausible length in m"),
                ));
            }
        }
        let margin = c.joint_margin_rad.unwrap_or(0.05);
        if !(margin.is_finite() && margin >= 0.0) {
            return Err(scenario_err(
                f,
                "campaign.joint_margin_rad",
                format!("{margin} must be finite and ≥ 0"),
            ));
        }
        let given: Vec<SamplingKind> = [
            (c.iso9283.is_some(), SamplingKind::Iso9283),
            (c.grid.is_some(), SamplingKind::Grid),
            (c.file.is_some(), SamplingKind::File),
        ]
        .into_iter()
        .filter_map(|(g, k)| g.then_some(k))
        .collect();
        let kind = match (c.sampling, given.as_slice()) {
            (Some(k), []) => k,
            (Some(k), [g]) if *g == k => k,
            (None, []) => SamplingKind::Random,
            (None, [g]) => *g,
            (_, gs) => {
                return Err(scenario_err(
                    f,
                    "campaign.sampling",
                    format!(
                        "sampling = {:?} but the tables {:?} are given; keep only the one that is used",
                        c.sampling.unwrap_or(SamplingKind::Random),
                        gs
                    ),
                ));
            }
        };
        spec.sampling = match kind {
            SamplingKind::Random => Sampling::Random {
                joint_margin_rad: margin,
                max_tries_per_pose: c.max_tries_per_pose.unwrap_or(10_000),
            },
            SamplingKind::Iso9283 => {
                let iso = c.iso9283.as_ref().ok_or_else(|| {
                    scenario_err(
                        f,
                        "campaign.iso9283",
                        "sampling = \"iso9283\" needs [campaign.iso9283] with seed_q".into(),
                    )
                })?;
                Sampling::Iso9283(Iso9283 {
                    cube_side_m: iso.cube_side_m.unwrap_or(0.3),
                    center_base_m: iso.center_m,
                    seed_q: iso.seed_q.clone(),
                })
            }
            SamplingKind::Grid => {
                let g = c.grid.as_ref().ok_or_else(|| {
                    scenario_err(
                        f,
                        "campaign.grid",
                        "sampling = \"grid\" needs [campaign.grid] points_per_joint".into(),
                    )
                })?;
                Sampling::Grid {
                    points_per_joint: match &g.points_per_joint {
                        PointsPerJoint::All(k) => vec![*k; model.nq()],
                        PointsPerJoint::PerJoint(v) => v.clone(),
                    },
                    joint_margin_rad: margin,
                }
            }
            SamplingKind::File => {
                let p = c.file.as_ref().ok_or_else(|| {
                    scenario_err(
                        f,
                        "campaign.file",
                        "sampling = \"file\" needs [campaign.file] path".into(),
                    )
                })?;
                Sampling::File {
                    path: self.base_dir.join(&p.path),
                    as_written: p.path.clone(),
                }
            }
        };
        if let Some(p) = &c.payload {
            spec.payload = match (p.mass_kg, &p.choice_kg) {
                (Some(_), Some(_)) => {
                    return Err(scenario_err(
                        f,
                        "campaign.payload",
                        "give mass_kg or choice_kg, not both".into(),
                    ));
                }
                (Some(m), None) => PayloadRule::Fixed(m),
                (None, Some(v)) => PayloadRule::Choice(v.clone()),
                (None, None) => PayloadRule::Fixed(0.0),
            };
            spec.payload_com_m = p.com_m.unwrap_or([0.0; 3]);
            if spec
                .payload_com_m
                .iter()
                .any(|v| !v.is_finite() || v.abs() > 2.0)
            {
                return Err(scenario_err(
                    f,
                    "campaign.payload.com_m",
                    format!("{:?} is not a plausible offset in m", spec.payload_com_m),
                ));
            }
        }
        if let Some(t) = &c.temperature {
            spec.temperature = t.clone();
        }
        Ok(spec)
    }

    /// Draws every random magnitude from the seed (the override's, else the file's, else 0), loads
    /// the robot, builds the effects, the tracker and the campaign, and checks them against each
    /// other. Errors name the file and the key.
    pub fn resolve(&self, overrides: &Overrides) -> Result<Resolved> {
        let f = self.label.as_str();
        let truth_model = self.file.truth.model.unwrap_or_default();
        let seed = overrides.seed.or(self.file.seed).unwrap_or(0);
        let (model, robot_source) = self.load_robot()?;
        let gravity = self
            .file
            .robot
            .gravity_m_per_s2
            .unwrap_or(crate::statics::DEFAULT_GRAVITY);
        if let Some((k, v)) = gravity
            .iter()
            .enumerate()
            .find(|(_, v)| !v.is_finite() || v.abs() > 100.0)
        {
            return Err(scenario_err(
                f,
                &format!("robot.gravity_m_per_s2[{k}]"),
                format!("{v} is not a plausible gravity in m/s²"),
            ));
        }
        let effects = self.effects(&model, seed)?;
        if truth_model == TruthModel::Rapier && effects.compliance.is_none() {
            return Err(scenario_err(
                f,
                "truth.model",
                "\"rapier\" settles the compliant joints in the physics engine: it needs an enabled \
                 [effects.compliance] (without one the truth is purely kinematic; use \"analytic\")"
                    .into(),
            ));
        }
        let (tracker, xyz, rpy) = self.tracker(seed, overrides.noise)?;
        let p_flange = [tracker.p_flange.x, tracker.p_flange.y, tracker.p_flange.z];
        let campaign = self.campaign(&model, overrides.poses, p_flange)?;
        Ok(Resolved {
            scenario: self.clone(),
            overrides: *overrides,
            seed,
            model,
            robot_source,
            gravity: Vector3::from(gravity),
            effects,
            tracker,
            tracker_xyz_m: xyz,
            tracker_rpy_rad: rpy,
            campaign,
            truth_model,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn locate_names_line_section_and_key() {
        let text = "seed = 1\n[robot]\nname = \"iiwa7\"\n\n[effects.compliance]\nstifness = 3\n";
        let pos = text.find("stifness").unwrap();
        assert_eq!(locate(text, pos), "line 6, [effects.compliance] stifness");
    }

    #[test]
    fn magnitudes_broadcast_and_lists_nest() {
        let m: Magnitude = toml::from_str::<toml::Table>("a = [[1, 2, 3], 4]")
            .unwrap()
            .get("a")
            .unwrap()
            .clone()
            .try_into()
            .unwrap();
        assert_eq!(
            m.resolve(0, "f", "a", &[2, 3]).unwrap(),
            vec![1.0, 2.0, 3.0, 4.0, 4.0, 4.0]
        );
        let e = m.resolve(0, "f", "a", &[3, 3]).unwrap_err().to_string();
        assert!(e.contains("a: 2 entries, expected 3"), "{e}");
    }
}
