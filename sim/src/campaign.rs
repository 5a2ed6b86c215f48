//! Measurement campaigns: which joint positions are measured, in which order, when, at which
//! temperature, after which direction of motion and with which payload.
//!
//! A [`CampaignSpec`] is turned into a [`Plan`] by [`plan`]: one row per measurement (pose × repeat),
//! with everything the controller and the environment impose, but nothing of the truth.
//!
//! # Pose sources ([`Sampling`])
//!
//! * **random**: every joint uniform within its URDF limits shrunk by a margin (continuous joints in
//!   [−π, π]), redrawn until the pose passes the [`Reachability`] filter (nominal kinematics): every
//!   joint frame origin from joint 2 on, the flange and the target above `floor_z_m` (base frame), and
//!   the target at least `min_axis_distance_m` from the base z axis.
//! * **iso9283**: the five points of ISO 9283 (pose accuracy and repeatability test): in a cube of side
//!   `L` centred at `c` (base frame), the plane through the cube edges `y = z = −L/2` and `y = z = +L/2`;
//!   `P1` is the centre and `P2 … P5` lie on the plane's two diagonals at 10 % of the diagonal length
//!   (`L√3`) from its corners. Joint positions come from damped-least-squares inverse kinematics
//!   ([`solve_ik`]) of the target position, the orientation kept from a seed pose; poses cycle
//!   `P1 → P2 → … → P5 → P1 …` as in the standard's test cycles.
//! * **grid**: a regular grid in joint space (`points_per_joint[i]` values evenly spaced over the
//!   shrunk limits, the midpoint for 1), last joint fastest, filtered by [`Reachability`].
//! * **file**: the joint positions of a measurement table (CSV or Parquet): the `q` of the first row of
//!   each pose id, in order of first appearance.
//!
//! For the list sources (iso9283, grid, file) a pose count cycles through the list (`pose k` uses
//! entry `k mod len`); without a count the list is used once.
//!
//! # Sequencing
//!
//! Pose `k` is measured `repeats` times at `t = k · seconds_per_pose + r · seconds_per_repeat` (s); the
//! temperature is the profile's value at `t` (°C). Approach directions ([`DirectionRule`]):
//! * `move` (default): `dirᵢ = sign(q_k,i − q_{k−1},i)`, the previous pose of the first being `start_q`;
//!   a joint that did not move keeps its last direction (its gear stays on the same flank), starting
//!   from 0 (unknown);
//! * `random`: ±1 with equal probability, per joint and pose;
//! * `unknown`: no `dir` columns.
//!
//! Payload ([`PayloadRule`]): one fixed mass, or per pose a mass drawn uniformly from a list; the
//! centre of mass is fixed (flange frame).
//!
//! # Random streams
//!
//! Every draw comes from a [`rand::rngs::Xoshiro256PlusPlus`] seeded with [`derive_seed`]`(seed,
//! stream, index)`, a SplitMix64 mix of the campaign seed, a stream id (one per kind of draw) and the
//! pose (or row) index. Xoshiro256++ is a named algorithm, so its output does not change with the
//! `rand` version (unlike `StdRng`), and it is cheap to seed once per pose. Draws therefore never depend
//! on thread scheduling, and changing one kind of draw leaves the others alone.

use crate::effects::thermal_drift::TemperatureProfile;
use crate::error::{Result, SimError};
use crate::kinematics::{Data, forward_kinematics, point_jacobian, spatial_jacobian};
use crate::lie::{Pose, log_pose, pose_from};
use crate::model::{JointKind, Model};
use nalgebra::{DMatrix, DVector, Matrix3, Matrix3xX, Vector3};
use rand::RngExt;
use rayon::prelude::*;
use std::path::PathBuf;

pub use crate::seeds::{
    STREAM_DIRECTIONS, STREAM_PARAMETERS, STREAM_PAYLOAD, STREAM_POSES, STREAM_TRACKER,
    derive_seed, rng_for, splitmix64,
};

/// Which poses a robot can take in the cell (evaluated with the nominal kinematics).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Reachability {
    /// Floor height in the base frame (m): joint frames 2 … n, the flange and the target stay above it.
    pub floor_z_m: f64,
    /// Smallest distance of the target from the base z axis (m).
    pub min_axis_distance_m: f64,
}

impl Default for Reachability {
    /// Floor 5 cm above the base plane, target at least 10 cm from the base axis.
    fn default() -> Self {
        Reachability {
            floor_z_m: 0.05,
            min_axis_distance_m: 0.10,
        }
    }
}

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
}

/// Everything that decides the rows of a campaign. Made with [`CampaignSpec::random`] (the defaults)
/// or a [`CampaignBuilder`] ([`CampaignSpec::builder`], [`CampaignSpec::to_builder`]), which checks
/// every value; read with the accessors.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct CampaignSpec {
    /// Number of poses; `None` = 100 for random sampling, 150 (30 cycles) for ISO 9283, the whole list
    /// for grid and file.
    poses: Option<usize>,
    /// Measurements per pose (≥ 1).
    repeats: usize,
    /// Pose source.
    sampling: Sampling,
    /// Cell constraints for random and grid poses.
    reachability: Reachability,
    /// Time between successive poses (s).
    seconds_per_pose: f64,
    /// Time between repeated measurements of one pose (s).
    seconds_per_repeat: f64,
    /// Approach-direction rule.
    directions: DirectionRule,
    /// Joint positions before the first pose, for the `move` rule (rad or m); `None` = zero, clamped
    /// into the limits.
    start_q: Option<Vec<f64>>,
    /// Payload rule.
    payload: PayloadRule,
    /// Payload centre of mass in the flange frame (m).
    payload_com_m: [f64; 3],
    /// Robot temperature over time.
    temperature: TemperatureProfile,
    /// Target (reflector) position in the flange frame (m), for the reachability filter and ISO 9283.
    p_flange_m: [f64; 3],
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
            start_q: None,
            payload: PayloadRule::Fixed(0.0),
            payload_com_m: [0.0; 3],
            temperature: TemperatureProfile::Constant(20.0),
            p_flange_m: crate::tracker::DEFAULT_P_FLANGE_M,
        }
    }

    /// A builder starting from the defaults of [`CampaignSpec::random`]`(100)`.
    pub fn builder() -> CampaignBuilder {
        CampaignSpec::random(100).to_builder()
    }

    /// A builder starting from this campaign.
    pub fn to_builder(&self) -> CampaignBuilder {
        CampaignBuilder {
            spec: self.clone(),
            label: "campaign".into(),
        }
    }

    /// Number of poses (`None`: see [`CampaignBuilder::poses`]).
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

/// Builds a [`CampaignSpec`]; [`CampaignBuilder::build`] checks every value that does not need the
/// robot (the rest is checked by [`plan`]). Errors are [`SimError::Scenario`] under the builder's
/// label and the scenario key (`campaign.repeats`, …).
#[must_use = "a builder does nothing until `build` is called"]
#[derive(Clone, Debug, PartialEq)]
pub struct CampaignBuilder {
    spec: CampaignSpec,
    label: String,
}

impl CampaignBuilder {
    /// The name errors give (the scenario file; default `campaign`).
    pub fn label(mut self, label: &str) -> CampaignBuilder {
        self.label = label.into();
        self
    }
    /// Number of poses, ≥ 1; `None` = 100 for random sampling, 150 (30 cycles) for ISO 9283, the whole
    /// list for grid and file.
    pub fn poses(mut self, poses: Option<usize>) -> CampaignBuilder {
        self.spec.poses = poses;
        self
    }
    /// Measurements per pose (≥ 1).
    pub fn repeats(mut self, repeats: usize) -> CampaignBuilder {
        self.spec.repeats = repeats;
        self
    }
    /// Pose source.
    pub fn sampling(mut self, sampling: Sampling) -> CampaignBuilder {
        self.spec.sampling = sampling;
        self
    }
    /// Cell constraints (lengths in m, |value| ≤ 10 m).
    pub fn reachability(mut self, reachability: Reachability) -> CampaignBuilder {
        self.spec.reachability = reachability;
        self
    }
    /// Time between successive poses (s, finite, ≥ 0).
    pub fn seconds_per_pose(mut self, s: f64) -> CampaignBuilder {
        self.spec.seconds_per_pose = s;
        self
    }
    /// Time between repeated measurements of one pose (s, finite, ≥ 0).
    pub fn seconds_per_repeat(mut self, s: f64) -> CampaignBuilder {
        self.spec.seconds_per_repeat = s;
        self
    }
    /// Approach-direction rule.
    pub fn directions(mut self, rule: DirectionRule) -> CampaignBuilder {
        self.spec.directions = rule;
        self
    }
    /// Joint positions before the first pose (rad or m; checked against the robot by [`plan`]).
    pub fn start_q(mut self, q: Option<Vec<f64>>) -> CampaignBuilder {
        self.spec.start_q = q;
        self
    }
    /// Payload rule (masses finite, ≥ 0 kg) and centre of mass (flange frame, m, |value| ≤ 2 m).
    pub fn payload(mut self, rule: PayloadRule, com_m: [f64; 3]) -> CampaignBuilder {
        self.spec.payload = rule;
        self.spec.payload_com_m = com_m;
        self
    }
    /// Robot temperature over time (°C).
    pub fn temperature(mut self, profile: TemperatureProfile) -> CampaignBuilder {
        self.spec.temperature = profile;
        self
    }
    /// Target (reflector) position in the flange frame (m).
    pub fn p_flange_m(mut self, p: [f64; 3]) -> CampaignBuilder {
        self.spec.p_flange_m = p;
        self
    }

    /// The campaign, every value checked (see the setters).
    pub fn build(self) -> Result<CampaignSpec> {
        let f = self.label.as_str();
        let spec = self.spec;
        let r = &spec.reachability;
        for (key, v) in [
            ("campaign.floor_z_m", r.floor_z_m),
            ("campaign.min_axis_distance_m", r.min_axis_distance_m),
        ] {
            if !v.is_finite() || v.abs() > 10.0 {
                return Err(err(f, key, format!("{v} is not a plausible length in m")));
            }
        }
        let margin = match &spec.sampling {
            Sampling::Random {
                joint_margin_rad, ..
            }
            | Sampling::Grid {
                joint_margin_rad, ..
            } => Some(*joint_margin_rad),
            _ => None,
        };
        if let Some(m) = margin.filter(|m| !(m.is_finite() && *m >= 0.0)) {
            return Err(err(
                f,
                "campaign.joint_margin_rad",
                format!("{m} must be finite and ≥ 0"),
            ));
        }
        if spec
            .payload_com_m
            .iter()
            .any(|v| !v.is_finite() || v.abs() > 2.0)
        {
            return Err(err(
                f,
                "campaign.payload.com_m",
                format!("{:?} is not a plausible offset in m", spec.payload_com_m),
            ));
        }
        check_model_free(&spec, f)?;
        Ok(spec)
    }
}

/// The most measurement rows (poses × repeats) a campaign planned and simulated in memory may have
/// ([`plan`], used by `robocal sweep` and `demo`, which calibrate on the rows they make):
/// 2,000,000, ten thousand times the shipped scenarios' 200 (about 1.6 kB a row with the simulation
/// and the table, so about 3.5 GB). `robocal generate` streams ([`Planner`]) and has no such limit,
/// only [`MAX_FORMAT_ROWS`] and the free disk space.
pub const MAX_ROWS: usize = 2_000_000;

/// Refuses `rows` measurement rows beyond [`MAX_ROWS`]; `what` says where the count comes from.
pub fn check_row_count(rows: Option<usize>, what: &str) -> std::result::Result<(), String> {
    match rows {
        Some(r) if r <= MAX_ROWS => Ok(()),
        _ => Err(format!(
            "{what}: more than the limit of {MAX_ROWS} measurement rows (poses × repeats) a campaign held in memory may have (see docs/generate.md)"
        )),
    }
}

/// The checks of `spec` that need no robot (shared by [`CampaignBuilder::build`] and [`plan`]).
fn check_model_free(spec: &CampaignSpec, file: &str) -> Result<()> {
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
        PayloadRule::Choice(v) => v,
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

/// Rows of a campaign: what the controller reports and the environment imposes at each
/// measurement. All of them ([`plan`]), or a chunk of consecutive ones ([`Planner::next_chunk`]): row
/// `i` here is row `first_row + i` of the campaign, which belongs to pose `(first_row + i) / repeats`
/// and is its repeat `(first_row + i) % repeats`.
#[derive(Clone, Debug, PartialEq)]
pub struct Plan {
    /// Joints of the robot.
    pub nq: usize,
    /// Number of poses of the campaign.
    pub n_poses: usize,
    /// Measurements per pose.
    pub repeats: usize,
    /// The campaign row of this plan's first row (0 for a whole campaign).
    pub first_row: usize,
    /// Pose id per row (0-based pose index).
    pub pose: Vec<i64>,
    /// Commanded joint positions per row, row-major `nq` per row (rad or m).
    pub q: Vec<f64>,
    /// Time since the start of the campaign per row (s).
    pub t_s: Vec<f64>,
    /// Robot temperature per row (°C).
    pub temp_c: Vec<f64>,
    /// Approach directions per row, row-major (−1, 0, +1); `None` for [`DirectionRule::Unknown`].
    pub dir: Option<Vec<i8>>,
    /// Payload mass per row (kg).
    pub payload_kg: Vec<f64>,
    /// Payload centre of mass in the flange frame (m).
    pub payload_com_m: [f64; 3],
}

impl Plan {
    /// Number of rows (measurements).
    pub fn len(&self) -> usize {
        self.pose.len()
    }
    /// True when there is no row.
    pub fn is_empty(&self) -> bool {
        self.pose.is_empty()
    }
    /// Joint positions of row `r` (rad or m).
    pub fn q_row(&self, r: usize) -> &[f64] {
        &self.q[r * self.nq..(r + 1) * self.nq]
    }
    /// Directions of row `r`, if recorded.
    pub fn dir_row(&self, r: usize) -> Option<&[i8]> {
        self.dir
            .as_ref()
            .map(|d| &d[r * self.nq..(r + 1) * self.nq])
    }
    /// Repeat index of row `r` within its pose (0-based).
    pub fn repeat_of(&self, r: usize) -> usize {
        (self.first_row + r) % self.repeats
    }
}

/// An error about the campaign, reported under the scenario `file` and `key`.
fn err(file: &str, key: &str, message: String) -> SimError {
    SimError::Scenario {
        file: file.to_string(),
        key: key.to_string(),
        message,
    }
}

/// Sampling interval of joint `i`: the limits shrunk by `margin`, `[−π, π]` for unlimited rotational
/// joints.
fn joint_range(model: &Model, i: usize, margin: f64, file: &str, key: &str) -> Result<(f64, f64)> {
    let j = &model.joints[i];
    let (lo, hi) = match (j.limits, j.kind) {
        (Some(l), _) => (l.lower + margin, l.upper - margin),
        (None, JointKind::Prismatic) => {
            return Err(err(
                file,
                key,
                format!(
                    "joint {} ('{}') is prismatic without limits: cannot sample it",
                    i + 1,
                    j.name
                ),
            ));
        }
        (None, _) => (-std::f64::consts::PI, std::f64::consts::PI),
    };
    if lo > hi {
        return Err(err(
            file,
            key,
            format!(
                "margin {margin} leaves nothing of joint {} ('{}') range",
                i + 1,
                j.name
            ),
        ));
    }
    Ok((lo, hi))
}

/// True when the nominal robot at the configuration in `data` (after [`forward_kinematics`]) passes
/// `reach` with the target at `p_flange` (flange frame, m).
pub fn reachable(data: &Data, p_flange: &Vector3<f64>, reach: &Reachability) -> bool {
    let floor = reach.floor_z_m;
    if data
        .joint_poses
        .iter()
        .skip(1)
        .any(|t| t.translation.z <= floor)
    {
        return false;
    }
    if data.flange.translation.z <= floor {
        return false;
    }
    let p = data.flange * nalgebra::Point3::from(*p_flange);
    p.z > floor && p.x.hypot(p.y) >= reach.min_axis_distance_m
}

/// Damped-least-squares inverse kinematics: joint positions near `q_seed` that put the point
/// `p_flange` (flange frame, m) at `target_base` (base frame, m) with the flange rotation `r_target`
/// (base frame). Steps `Δq = Jᵀ (J Jᵀ + λ² I)⁻¹ e` with the 6-row error `e = [log(R_target Rᵀ); Δp]`
/// until `|e| < 1e-12` (rad and m), at most 500 steps; `λ = 1e-3`. Returns `None` if it does not
/// converge.
pub fn solve_ik(
    model: &Model,
    q_seed: &[f64],
    p_flange: &Vector3<f64>,
    target_base: &Vector3<f64>,
    r_target: &Matrix3<f64>,
) -> Option<Vec<f64>> {
    let n = model.nq();
    let mut data = Data::new(model);
    let mut q = q_seed.to_vec();
    let mut jp = Matrix3xX::zeros(n);
    let lambda2 = 1e-6;
    for _ in 0..500 {
        forward_kinematics(model, &mut data, &q);
        let p = point_jacobian(model, &data, p_flange, &mut jp);
        spatial_jacobian(model, &mut data);
        let r = data.flange.rotation.matrix();
        let dr: Pose = pose_from(r_target * r.transpose(), Vector3::zeros());
        let w = log_pose(&dr);
        let dp = target_base - p;
        let e = DVector::from_vec(vec![w[0], w[1], w[2], dp.x, dp.y, dp.z]);
        if e.norm() < 1e-12 {
            return Some(q);
        }
        let mut j = DMatrix::zeros(6, n);
        for c in 0..n {
            for k in 0..3 {
                j[(k, c)] = data.jacobian[(k, c)];
                j[(3 + k, c)] = jp[(k, c)];
            }
        }
        let a = &j * j.transpose() + DMatrix::identity(6, 6) * lambda2;
        let y = a.lu().solve(&e)?;
        let dq = j.transpose() * y;
        for (qi, d) in q.iter_mut().zip(dq.iter()) {
            *qi += d;
        }
    }
    None
}

/// The five ISO 9283 points (base frame, m) of a cube of side `side` centred at `c`, `P1 … P5`.
pub fn iso9283_points(c: &Vector3<f64>, side: f64) -> [Vector3<f64>; 5] {
    let h = 0.5 * side;
    // Corners of the diagonal plane through the edges y = z = −L/2 and y = z = +L/2.
    let a = c + Vector3::new(-h, -h, -h);
    let b = c + Vector3::new(h, -h, -h);
    let cc = c + Vector3::new(h, h, h);
    let d = c + Vector3::new(-h, h, h);
    let at = |from: Vector3<f64>, to: Vector3<f64>| from + (to - from) * 0.1;
    [*c, at(a, cc), at(b, d), at(cc, a), at(d, b)]
}

fn sign(x: f64) -> i8 {
    if x > 0.0 {
        1
    } else if x < 0.0 {
        -1
    } else {
        0
    }
}

/// Where the joint positions of pose `k` come from, resolved once for a robot by [`Planner::new`].
#[derive(Clone, Debug)]
enum PoseSource {
    /// Drawn per pose from its own generator (uniform in `ranges`, filtered by reachability).
    Random {
        /// Sampling interval per joint (rad or m).
        ranges: Vec<(f64, f64)>,
        /// Draws per pose before giving up.
        max_tries: usize,
    },
    /// A finite list, cycled: joint values row-major, `nq` per entry.
    List(Vec<f64>),
    /// The reachable points of a joint-space grid, cycled: their odometer index (last joint fastest;
    /// 4 bytes a point, where the joint values would take 8 per joint).
    Grid {
        /// Reachable points' indices, in grid order.
        index: Vec<u32>,
        /// Grid values per joint.
        points_per_joint: Vec<usize>,
        /// Interval per joint (rad or m).
        ranges: Vec<(f64, f64)>,
    },
}

/// Value `k` of `count` evenly spaced over `(lo, hi)` (the midpoint for one value).
fn grid_value((lo, hi): (f64, f64), count: usize, k: usize) -> f64 {
    if count == 1 {
        0.5 * (lo + hi)
    } else {
        lo + (hi - lo) * k as f64 / (count - 1) as f64
    }
}

/// The joint values of grid point `index` (odometer order, last joint fastest) into `q`.
fn grid_point(index: u64, points_per_joint: &[usize], ranges: &[(f64, f64)], q: &mut [f64]) {
    let mut rest = index;
    for i in (0..q.len()).rev() {
        let c = points_per_joint[i] as u64;
        q[i] = grid_value(ranges[i], points_per_joint[i], (rest % c) as usize);
        rest /= c;
    }
}

/// The largest row count a campaign may have: Parquet counts rows (and robocal numbers poses) in
/// signed 64-bit integers.
pub const MAX_FORMAT_ROWS: u64 = i64::MAX as u64;

/// The rows of a campaign, made in order, a chunk at a time ([`Planner::next_chunk`]), so that a
/// campaign of any length is planned in bounded memory: pose `k` draws from its own generators (see
/// the module docs) and the `move` direction rule carries the previous pose from chunk to chunk, so
/// the rows do not depend on the chunk sizes. [`plan`] is the one-chunk case.
#[derive(Debug)]
pub struct Planner<'a> {
    model: &'a Model,
    spec: &'a CampaignSpec,
    seed: u64,
    file: String,
    source: PoseSource,
    n_poses: usize,
    rows: usize,
    /// The next row to plan.
    next_row: usize,
    /// `move` rule: poses folded into `prev` and `last` so far, the last one's joint values and every
    /// joint's last direction.
    moved: usize,
    prev: Vec<f64>,
    last: Vec<i8>,
}

impl<'a> Planner<'a> {
    /// Resolves the pose source of `spec` for `model` (draws nothing for random sampling; runs the
    /// inverse kinematics of ISO 9283, filters the grid, reads the pose file) and checks the counts:
    /// poses × repeats at most [`MAX_FORMAT_ROWS`]. `file` names the scenario in errors.
    ///
    /// # Errors
    /// [`SimError::Scenario`] naming `file` and the key; a pose file that cannot be read.
    pub fn new(model: &'a Model, spec: &'a CampaignSpec, seed: u64, file: &str) -> Result<Self> {
        let n = model.nq();
        check_model_free(spec, file)?;
        let (source, n_poses) = pose_source(model, spec, file)?;
        let rows = n_poses
            .checked_mul(spec.repeats)
            .filter(|&r| r as u64 <= MAX_FORMAT_ROWS)
            .ok_or_else(|| {
                let key = if spec.repeats > 1 {
                    "campaign.repeats"
                } else {
                    "campaign.poses"
                };
                err(
                    file,
                    key,
                    format!(
                        "{n_poses} poses × {} repeats = {:.4e} measurement rows: more than the {MAX_FORMAT_ROWS} \
                         a Parquet file can count (signed 64-bit)",
                        spec.repeats,
                        n_poses as f64 * spec.repeats as f64
                    ),
                )
            })?;
        // The last measurement's time must be a number (t = k · seconds_per_pose + r ·
        // seconds_per_repeat): 1e308 s a pose overflows at the second pose (fuzzing case 8805).
        let last_pose = n_poses.saturating_sub(1) as f64 * spec.seconds_per_pose;
        let last_repeat = spec.repeats.saturating_sub(1) as f64 * spec.seconds_per_repeat;
        for (key, v, what) in [
            ("campaign.seconds_per_pose", last_pose, "the last pose"),
            (
                "campaign.seconds_per_repeat",
                last_repeat,
                "the last repeat",
            ),
            (
                "campaign.seconds_per_pose",
                last_pose + last_repeat,
                "the last measurement",
            ),
        ] {
            if !v.is_finite() {
                return Err(err(
                    file,
                    key,
                    format!(
                        "{what} would be measured at t = {v} s ({n_poses} poses {} s apart, {} repeats {} s \
                         apart): too long a campaign to time",
                        spec.seconds_per_pose, spec.repeats, spec.seconds_per_repeat
                    ),
                ));
            }
        }
        let prev = match &spec.start_q {
            Some(s) => {
                model
                    .check_q(s)
                    .map_err(|e| err(file, "campaign.start_q", e.to_string()))?;
                s.clone()
            }
            None => model
                .joints
                .iter()
                .map(|j| j.limits.map_or(0.0, |l| 0.0f64.clamp(l.lower, l.upper)))
                .collect(),
        };
        Ok(Planner {
            model,
            spec,
            seed,
            file: file.to_string(),
            source,
            n_poses,
            rows,
            next_row: 0,
            moved: 0,
            prev,
            last: vec![0; n],
        })
    }

    /// Poses of the campaign.
    pub fn n_poses(&self) -> usize {
        self.n_poses
    }
    /// Measurements per pose.
    pub fn repeats(&self) -> usize {
        self.spec.repeats
    }
    /// Rows of the campaign (poses × repeats).
    pub fn rows(&self) -> usize {
        self.rows
    }
    /// Joints of the robot.
    pub fn nq(&self) -> usize {
        self.model.nq()
    }
    /// Whether the rows have `dir` columns.
    pub fn has_dir(&self) -> bool {
        self.spec.directions != DirectionRule::Unknown
    }

    /// The next at most `max_rows` rows (at least 1), or `None` when every row is planned. A pose's
    /// repeats may straddle two chunks.
    ///
    /// # Errors
    /// A random pose for which no draw passes the reachability filter, naming the pose.
    pub fn next_chunk(&mut self, max_rows: usize) -> Result<Option<Plan>> {
        if self.next_row >= self.rows {
            return Ok(None);
        }
        let n = self.model.nq();
        let repeats = self.spec.repeats;
        let (r0, r1) = (
            self.next_row,
            self.rows.min(self.next_row.saturating_add(max_rows.max(1))),
        );
        let (k0, k1) = (r0 / repeats, (r1 - 1) / repeats + 1);
        let qs = self.joint_values(k0..k1)?;
        let dirs = self.directions(k0..k1, &qs);
        let rows = r1 - r0;
        let mut plan = Plan {
            nq: n,
            n_poses: self.n_poses,
            repeats,
            first_row: r0,
            pose: Vec::with_capacity(rows),
            q: Vec::with_capacity(rows * n),
            t_s: Vec::with_capacity(rows),
            temp_c: Vec::with_capacity(rows),
            dir: dirs.as_ref().map(|_| Vec::with_capacity(rows * n)),
            payload_kg: Vec::with_capacity(rows),
            payload_com_m: self.spec.payload_com_m,
        };
        let mut mass = 0.0;
        for row in r0..r1 {
            let (k, r) = (row / repeats, row % repeats);
            let i = k - k0;
            if row == r0 || r == 0 {
                mass = match &self.spec.payload {
                    PayloadRule::Fixed(m) => *m,
                    PayloadRule::Choice(v) => {
                        let mut rng = rng_for(self.seed, STREAM_PAYLOAD, k as u64);
                        v[rng.random_range(0..v.len())]
                    }
                };
            }
            let t = k as f64 * self.spec.seconds_per_pose + r as f64 * self.spec.seconds_per_repeat;
            plan.pose.push(k as i64);
            plan.q.extend_from_slice(&qs[i * n..(i + 1) * n]);
            let temp = self.spec.temperature.temp_at(t);
            let (low, high) = crate::measurement_table::TEMP_RANGE_C;
            if !(low..=high).contains(&temp) {
                return Err(err(
                    &self.file,
                    "campaign.temperature",
                    format!(
                        "{temp:e} °C at pose {k} (t = {t} s) is outside [{low}, {high}] °C: not a robot's \
                         temperature (degrees Celsius are expected)"
                    ),
                ));
            }
            plan.t_s.push(t);
            plan.temp_c.push(temp);
            if let (Some(out), Some(d)) = (plan.dir.as_mut(), dirs.as_ref()) {
                out.extend_from_slice(&d[i * n..(i + 1) * n]);
            }
            plan.payload_kg.push(mass);
        }
        self.next_row = r1;
        Ok(Some(plan))
    }

    /// Joint values of poses `ks`, row-major.
    fn joint_values(&self, ks: std::ops::Range<usize>) -> Result<Vec<f64>> {
        let n = self.model.nq();
        let mut out = vec![0.0; ks.len() * n];
        match &self.source {
            PoseSource::List(list) => {
                let len = list.len() / n;
                for (i, k) in ks.enumerate() {
                    let e = k % len;
                    out[i * n..(i + 1) * n].copy_from_slice(&list[e * n..(e + 1) * n]);
                }
            }
            PoseSource::Grid {
                index,
                points_per_joint,
                ranges,
            } => {
                for (i, k) in ks.enumerate() {
                    let idx = u64::from(index[k % index.len()]);
                    grid_point(idx, points_per_joint, ranges, &mut out[i * n..(i + 1) * n]);
                }
            }
            PoseSource::Random { ranges, max_tries } => {
                let (model, spec, seed) = (self.model, self.spec, self.seed);
                let p_flange = Vector3::from(spec.p_flange_m);
                let k0 = ks.start;
                let found: Vec<bool> = out
                    .par_chunks_mut(n)
                    .enumerate()
                    .with_min_len(64)
                    .map_init(
                        || Data::new(model),
                        |data, (i, q)| {
                            let mut rng = rng_for(seed, STREAM_POSES, (k0 + i) as u64);
                            for _ in 0..*max_tries {
                                for (qi, (lo, hi)) in q.iter_mut().zip(ranges) {
                                    let u: f64 = rng.random();
                                    *qi = lo + (hi - lo) * u;
                                }
                                forward_kinematics(model, data, q);
                                if reachable(data, &p_flange, &spec.reachability) {
                                    return true;
                                }
                            }
                            false
                        },
                    )
                    .collect();
                if let Some(i) = found.iter().position(|ok| !ok) {
                    return Err(err(
                        &self.file,
                        "campaign",
                        format!(
                            "pose {}: no configuration passed the reachability filter (floor_z_m = {}, \
                             min_axis_distance_m = {}) in {max_tries} draws; loosen them",
                            k0 + i,
                            spec.reachability.floor_z_m,
                            spec.reachability.min_axis_distance_m
                        ),
                    ));
                }
            }
        }
        Ok(out)
    }

    /// Directions of poses `ks` (row-major), whose joint values are `qs`; `None` without `dir`.
    fn directions(&mut self, ks: std::ops::Range<usize>, qs: &[f64]) -> Option<Vec<i8>> {
        let n = self.model.nq();
        match self.spec.directions {
            DirectionRule::Unknown => None,
            DirectionRule::Random => Some(
                ks.flat_map(|k| {
                    let mut rng = rng_for(self.seed, STREAM_DIRECTIONS, k as u64);
                    (0..n)
                        .map(move |_| if rng.random::<bool>() { 1 } else { -1 })
                        .collect::<Vec<i8>>()
                })
                .collect(),
            ),
            DirectionRule::Move => {
                let mut out = Vec::with_capacity(ks.len() * n);
                for (i, k) in ks.enumerate() {
                    // Only the first pose of a chunk can be folded in already (its repeats straddle
                    // two chunks): its directions are the state as it stands.
                    if k >= self.moved {
                        let q = &qs[i * n..(i + 1) * n];
                        for ((last, prev), qj) in self.last.iter_mut().zip(&self.prev).zip(q) {
                            let s = sign(qj - prev);
                            if s != 0 {
                                *last = s;
                            }
                        }
                        self.prev.copy_from_slice(q);
                        self.moved = k + 1;
                    }
                    out.extend_from_slice(&self.last);
                }
                Some(out)
            }
        }
    }
}

/// The pose source of `spec` for `model` and the number of poses (see the module docs).
fn pose_source(model: &Model, spec: &CampaignSpec, file: &str) -> Result<(PoseSource, usize)> {
    let n = model.nq();
    let p_flange = Vector3::from(spec.p_flange_m);
    // A list source: cycled to the pose count, or used once (or 150 times round for ISO 9283).
    let count = |len: usize, default_all: bool| -> Result<usize> {
        if len == 0 {
            return Err(err(file, "campaign", "the pose list is empty".into()));
        }
        Ok(match spec.poses {
            Some(c) => c,
            None if default_all => len,
            None => 150,
        })
    };
    match &spec.sampling {
        Sampling::Random {
            joint_margin_rad,
            max_tries_per_pose,
        } => {
            let ranges = (0..n)
                .map(|i| {
                    joint_range(
                        model,
                        i,
                        *joint_margin_rad,
                        file,
                        "campaign.joint_margin_rad",
                    )
                })
                .collect::<Result<Vec<_>>>()?;
            Ok((
                PoseSource::Random {
                    ranges,
                    max_tries: *max_tries_per_pose,
                },
                spec.poses.unwrap_or(100),
            ))
        }
        Sampling::Iso9283(iso) => {
            let key = "campaign.iso9283";
            if iso.seed_q.len() != n {
                return Err(err(
                    file,
                    &format!("{key}.seed_q"),
                    format!("{} values, but the robot has {n} joints", iso.seed_q.len()),
                ));
            }
            if !(iso.cube_side_m.is_finite() && iso.cube_side_m > 0.0) {
                return Err(err(
                    file,
                    &format!("{key}.cube_side_m"),
                    format!("{} must be a finite length > 0 m", iso.cube_side_m),
                ));
            }
            model
                .check_q(&iso.seed_q)
                .map_err(|e| err(file, &format!("{key}.seed_q"), e.to_string()))?;
            let mut data = Data::new(model);
            forward_kinematics(model, &mut data, &iso.seed_q);
            let r_seed = *data.flange.rotation.matrix();
            let c = iso
                .center_base_m
                .map(Vector3::from)
                .unwrap_or_else(|| (data.flange * nalgebra::Point3::from(p_flange)).coords);
            let mut list = Vec::with_capacity(5 * n);
            for (k, p) in iso9283_points(&c, iso.cube_side_m).iter().enumerate() {
                let q = solve_ik(model, &iso.seed_q, &p_flange, p, &r_seed).ok_or_else(|| {
                    err(
                        file,
                        key,
                        format!(
                            "inverse kinematics did not converge for P{} = ({:.4}, {:.4}, {:.4}) m: the cube \
                             leaves the workspace; make it smaller or move its centre",
                            k + 1,
                            p.x,
                            p.y,
                            p.z
                        ),
                    )
                })?;
                for (i, (j, v)) in model.joints.iter().zip(&q).enumerate() {
                    if let Some(l) = j.limits
                        && (*v < l.lower || *v > l.upper)
                    {
                        return Err(err(
                            file,
                            key,
                            format!(
                                "P{}: inverse kinematics gives q{} = {v:.4} outside the limits [{}, {}]; \
                                 choose another seed_q or a smaller cube",
                                k + 1,
                                i + 1,
                                l.lower,
                                l.upper
                            ),
                        ));
                    }
                }
                list.extend_from_slice(&q);
            }
            let poses = count(5, false)?;
            Ok((PoseSource::List(list), poses))
        }
        Sampling::Grid {
            points_per_joint,
            joint_margin_rad,
        } => {
            let key = "campaign.grid.points_per_joint";
            if points_per_joint.len() != n {
                return Err(err(
                    file,
                    key,
                    format!(
                        "{} entries, but the robot has {n} joints",
                        points_per_joint.len()
                    ),
                ));
            }
            if let Some(i) = points_per_joint.iter().position(|&c| c == 0) {
                return Err(err(
                    file,
                    &format!("{key}[{i}]"),
                    "0 points: must be ≥ 1".into(),
                ));
            }
            let product = points_per_joint
                .iter()
                .try_fold(1usize, |a, &c| a.checked_mul(c));
            let total = product.filter(|&t| t <= 10_000_000).ok_or_else(|| {
                let shown = product.map_or_else(
                    || {
                        let p: f64 = points_per_joint.iter().map(|&c| c as f64).product();
                        format!("{p:.3e}")
                    },
                    |t| t.to_string(),
                );
                err(
                    file,
                    key,
                    format!("{shown} grid points: more than 10 million"),
                )
            })?;
            let ranges = (0..n)
                .map(|i| {
                    joint_range(
                        model,
                        i,
                        *joint_margin_rad,
                        file,
                        "campaign.grid.joint_margin_rad",
                    )
                })
                .collect::<Result<Vec<_>>>()?;
            let mut data = Data::new(model);
            let mut index = Vec::new();
            let mut q = vec![0.0; n];
            for idx in 0..total as u32 {
                grid_point(u64::from(idx), points_per_joint, &ranges, &mut q);
                forward_kinematics(model, &mut data, &q);
                if reachable(&data, &p_flange, &spec.reachability) {
                    index.push(idx);
                }
            }
            if index.is_empty() {
                return Err(err(
                    file,
                    key,
                    format!("none of the {total} grid points passes the reachability filter"),
                ));
            }
            let poses = count(index.len(), true)?;
            Ok((
                PoseSource::Grid {
                    index,
                    points_per_joint: points_per_joint.clone(),
                    ranges,
                },
                poses,
            ))
        }
        Sampling::List { q } => {
            for (k, qk) in q.iter().enumerate() {
                if qk.len() != n {
                    return Err(err(
                        file,
                        "campaign",
                        format!(
                            "pose {k} of the given list has {} joint values, but the robot has {n} joints",
                            qk.len()
                        ),
                    ));
                }
            }
            let poses = count(q.len(), true)?;
            Ok((PoseSource::List(q.concat()), poses))
        }
        Sampling::File { path, .. } => {
            let table = crate::measurement_table::read(path)?;
            if table.n_joints != n {
                return Err(err(
                    file,
                    "campaign.file.path",
                    format!(
                        "{} has {} joint columns, but the robot has {n} joints",
                        path.display(),
                        table.n_joints
                    ),
                ));
            }
            let by_pose = table.rows_by_pose();
            let mut list = Vec::with_capacity(by_pose.len() * n);
            for (_, rows) in &by_pose {
                list.extend_from_slice(table.q_row(rows[0]));
            }
            let poses = count(by_pose.len(), true)?;
            Ok((PoseSource::List(list), poses))
        }
    }
}

/// Turns `spec` into the rows of the campaign for `model`, drawing from `seed` (see the module docs),
/// all in memory: at most [`MAX_ROWS`] rows (larger campaigns are streamed with a [`Planner`]).
/// `file` names the scenario in errors.
pub fn plan(model: &Model, spec: &CampaignSpec, seed: u64, file: &str) -> Result<Plan> {
    let mut planner = Planner::new(model, spec, seed, file)?;
    let rows = planner.rows();
    if rows > MAX_ROWS {
        let what = format!("{} poses × {} repeats", planner.n_poses(), spec.repeats);
        return Err(err(
            file,
            "campaign.repeats",
            check_row_count(None, &what).unwrap_err(),
        ));
    }
    planner
        .next_chunk(rows)?
        .ok_or_else(|| err(file, "campaign", "no rows".into()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robots;

    #[test]
    fn iso9283_points_lie_on_the_plane_diagonals_at_ten_percent() {
        let c = Vector3::new(0.5, 0.1, 0.4);
        let l = 0.3;
        let p = iso9283_points(&c, l);
        assert_eq!(p[0], c);
        // Diagonal length L√3; P2..P5 are 0.1·L√3 from a corner and 0.4·L√3 from the centre.
        for q in &p[1..] {
            assert!(((q - c).norm() - 0.4 * l * 3f64.sqrt()).abs() < 1e-15);
            // On the plane y = z (relative to the centre).
            assert!(((q - c).y - (q - c).z).abs() < 1e-15);
        }
        // Hand value of P2: corner (−L/2)(1,1,1) moved 10 % towards (+L/2)(1,1,1): −0.4 L (1,1,1).
        assert!((p[1] - (c - Vector3::repeat(0.4 * l))).amax() < 1e-15);
    }

    #[test]
    fn ik_reaches_the_target_and_keeps_the_orientation() {
        let m = robots::load_builtin("iiwa7").unwrap();
        let seed = [0.1, 0.6, 0.0, -1.2, 0.0, 0.8, 0.0];
        let pf = Vector3::new(0.0, 0.0, 0.05);
        let mut d = Data::new(&m);
        forward_kinematics(&m, &mut d, &seed);
        let r0 = *d.flange.rotation.matrix();
        let p0 = (d.flange * nalgebra::Point3::from(pf)).coords;
        let target = p0 + Vector3::new(0.08, -0.05, 0.06);
        let q = solve_ik(&m, &seed, &pf, &target, &r0).unwrap();
        forward_kinematics(&m, &mut d, &q);
        let p = (d.flange * nalgebra::Point3::from(pf)).coords;
        assert!((p - target).norm() < 1e-11);
        assert!((d.flange.rotation.matrix() - r0).amax() < 1e-11);
    }

    #[test]
    fn a_given_pose_list_is_cycled_and_checked() {
        let m = robots::load_builtin("iiwa7").unwrap();
        let a = vec![0.1, 0.5, 0.0, -1.0, 0.0, 0.7, 0.2];
        let b = vec![-0.3, 0.8, 0.4, -1.4, 0.1, 0.5, -0.6];
        let spec = CampaignSpec::random(5)
            .to_builder()
            .sampling(Sampling::List {
                q: vec![a.clone(), b.clone()],
            })
            .build()
            .unwrap();
        let p = plan(&m, &spec, 3, "test").unwrap();
        assert_eq!(p.n_poses, 5);
        for (k, want) in [&a, &b, &a, &b, &a].iter().enumerate() {
            assert_eq!(p.q_row(k), want.as_slice());
        }
        let spec = spec
            .to_builder()
            .sampling(Sampling::List {
                q: vec![a, vec![0.0; 6]],
            })
            .build()
            .unwrap();
        let e = plan(&m, &spec, 3, "test").unwrap_err().to_string();
        assert!(e.contains("pose 1") && e.contains("6 joint values"), "{e}");
    }

    #[test]
    fn move_directions_follow_the_sign_of_the_motion() {
        let m = robots::load_builtin("iiwa7").unwrap();
        let spec = CampaignSpec::random(30)
            .to_builder()
            .repeats(2)
            .build()
            .unwrap();
        let p = plan(&m, &spec, 7, "test").unwrap();
        assert_eq!(p.len(), 60);
        let dir = p.dir.as_ref().unwrap();
        for r in 2..p.len() {
            let k = r / 2;
            if k == 0 {
                continue;
            }
            let (q, qp) = (p.q_row(r), p.q_row((k - 1) * 2));
            for i in 0..7 {
                let expect = if q[i] > qp[i] { 1 } else { -1 };
                assert_eq!(dir[r * 7 + i], expect);
            }
        }
        // Repeats share q, dir and payload; time advances by seconds_per_repeat.
        assert_eq!(p.q_row(4), p.q_row(5));
        assert_eq!(p.t_s[5] - p.t_s[4], 1.0);
        assert_eq!(p.t_s[4], 20.0);
    }
}
