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
//! * **file**: the joint positions of a table (CSV or Parquet; the measurement contract with `x, y, z`
//!   optional, so a joint program `pose, q1..qN` serves): the `q` of the first row of each pose id, in
//!   order of first appearance. Where the file has context columns (`payload`, `temp`, `t`,
//!   `dir1..dirN`), the pose's value replaces the rules below (its repeats add `seconds_per_repeat`
//!   to its `t`): so `robocal generate` can run a given program, in its own context, on the hidden
//!   robot (`robocal compensate`'s check against the truth).
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
//!
//! # Modules, by job
//!
//! [`spec`] (what decides the rows: [`CampaignSpec`] and its parts), [`builder`] (the validated way to
//! make one), `sources` (where the joint positions come from: random, grid, list, file),
//! [`iso9283`] (the ISO 9283 test cube) and [`planner`] (the rows, planned in chunks). The inverse
//! kinematics and the reachability filter are kinematics ([`crate::kinematics::ik`]).

pub mod builder;
pub mod iso9283;
pub mod planner;
mod sources;
pub mod spec;

use crate::error::SimError;

pub use crate::kinematics::ik::{Reachability, reachable, solve_ik};
pub use crate::seeds::{
    STREAM_DIRECTIONS, STREAM_PARAMETERS, STREAM_PAYLOAD, STREAM_POSES, STREAM_TRACKER,
    derive_seed, rng_for, splitmix64,
};
pub use builder::CampaignBuilder;
pub use iso9283::iso9283_points;
pub use planner::{MAX_FORMAT_ROWS, MAX_ROWS, Plan, Planner, check_row_count, plan};
pub use spec::{BranchRule, CampaignSpec, DirectionRule, Iso9283, PayloadRule, Sampling};

/// An error about the campaign, reported under the scenario `file` and `key`.
fn err(file: &str, key: &str, message: String) -> SimError {
    SimError::Scenario {
        file: file.to_string(),
        key: key.to_string(),
        message,
    }
}
