//! The rows of a campaign: [`Planner`] makes them in order, a chunk at a time, in bounded memory;
//! [`plan`] makes them all at once.

use super::err;
use super::sources::{FileContext, PoseSource, grid_point, pose_source};
use super::spec::{BranchRule, CampaignSpec, DirectionRule, PayloadRule, check_model_free};
use crate::error::Result;
use crate::kinematics::ik::reachable;
use crate::kinematics::{Data, forward_kinematics};
use crate::model::Model;
use crate::seeds::{STREAM_BRANCHES, STREAM_DIRECTIONS, STREAM_PAYLOAD, STREAM_POSES, rng_for};
use nalgebra::Vector3;
use rand::RngExt;
use rayon::prelude::*;

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
    /// Chain indices of the driven joints when the robot has coupled joints (their columns are the
    /// measurement table's `q1 … qD`); `None` when every joint is driven.
    pub drives: Option<Vec<usize>>,
    /// Values of the branch joints off the chain per row, row-major in [`Model::branches`] order
    /// (rad or m; the table's `q_<joint>` columns); `None` with the branches at zero
    /// ([`BranchRule::Zero`]).
    pub branch: Option<Vec<f64>>,
    /// The branch joints of `branch`'s values ([`Model::branches`] order; the columns `q_<name>`);
    /// empty with the branches at zero.
    pub branch_names: Vec<String>,
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
    /// Branch joint values of row `r` (rad or m), when the campaign poses the branches.
    pub fn branch_row(&self, r: usize) -> Option<&[f64]> {
        self.branch
            .as_ref()
            .map(|b| &b[r * self.branch_names.len()..(r + 1) * self.branch_names.len()])
    }
    /// Repeat index of row `r` within its pose (0-based).
    pub fn repeat_of(&self, r: usize) -> usize {
        (self.first_row + r) % self.repeats
    }
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
    /// A pose file's context columns (payload, temperature, time, directions), which replace the
    /// campaign's rules where the file has them.
    context: Option<FileContext>,
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
    /// [`crate::error::SimError::Scenario`] naming `file` and the key; a pose file that cannot be read.
    pub fn new(model: &'a Model, spec: &'a CampaignSpec, seed: u64, file: &str) -> Result<Self> {
        let n = model.nq();
        check_model_free(spec, file)?;
        if spec.branches == BranchRule::Random && model.branches().is_empty() {
            return Err(err(
                file,
                "campaign.branches",
                format!(
                    "\"random\", but robot '{}' has no movable joint off its chain to pose",
                    model.name()
                ),
            ));
        }
        let (source, n_poses, context) = pose_source(model, spec, file)?;
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
                .joints()
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
            context,
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
        self.spec.directions != DirectionRule::Unknown || self.file_dir().is_some()
    }

    /// A pose file's directions (row-major per list entry), when it has them.
    fn file_dir(&self) -> Option<&[i8]> {
        self.context.as_ref().and_then(|c| c.dir.as_deref())
    }

    /// The list entry of pose `k` (list sources cycle).
    fn entry(&self, k: usize) -> usize {
        match &self.source {
            PoseSource::List(list) => k % (list.len() / self.model.nq()).max(1),
            _ => k,
        }
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
            drives: (!self.model.couplings().is_empty())
                .then(|| self.model.couplings().drives().to_vec()),
            branch: None,
            branch_names: Vec::new(),
        };
        let branch_values = self.branch_values(k0..k1);
        plan.branch_names = self.branch_names();
        let mut mass = 0.0;
        for row in r0..r1 {
            let (k, r) = (row / repeats, row % repeats);
            let i = k - k0;
            let file = self.context.as_ref();
            let e = self.entry(k);
            if row == r0 || r == 0 {
                mass = match &self.spec.payload {
                    _ if file.is_some_and(|c| c.payload_kg.is_some()) => file
                        .and_then(|c| c.payload_kg.as_ref())
                        .map_or(0.0, |p| p[e]),
                    PayloadRule::Fixed(m) => *m,
                    PayloadRule::Choice(v) => {
                        let mut rng = rng_for(self.seed, STREAM_PAYLOAD, k as u64);
                        v[rng.random_range(0..v.len())]
                    }
                    PayloadRule::PerPose(v) => v[e % v.len()],
                };
            }
            let t0 = match file.and_then(|c| c.t_s.as_ref()) {
                Some(t) => t[e],
                None => k as f64 * self.spec.seconds_per_pose,
            };
            let t = t0 + r as f64 * self.spec.seconds_per_repeat;
            plan.pose.push(k as i64);
            plan.q.extend_from_slice(&qs[i * n..(i + 1) * n]);
            let temp = match file.and_then(|c| c.temp_c.as_ref()) {
                Some(v) => v[e],
                None => self.spec.temperature.temp_at(t),
            };
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
            if let Some(v) = &branch_values {
                let nb = plan.branch_names.len();
                plan.branch
                    .get_or_insert_with(|| Vec::with_capacity(rows * nb))
                    .extend_from_slice(&v[i * nb..(i + 1) * nb]);
            }
        }
        self.next_row = r1;
        Ok(Some(plan))
    }

    /// Joint values of poses `ks`, row-major (every chain joint; coupled joints follow their
    /// sources, whatever was drawn for them).
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
                    self.model.couplings().apply(&mut out[i * n..(i + 1) * n]);
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
                                model.couplings().apply(q);
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

    /// The branch joints whose values the plans carry (the table's `q_<joint>` columns, in
    /// [`Model::branches`] order); empty with the branches at zero.
    pub fn branch_names(&self) -> Vec<String> {
        match self.spec.branches {
            BranchRule::Zero => Vec::new(),
            BranchRule::Random => (self.model.branches().joints().iter())
                .map(|j| j.name.clone())
                .collect(),
        }
    }

    /// Branch joint values of poses `ks` (row-major, [`Model::branches`] order), each drawn from
    /// pose `k`'s own generator; `None` with the branches at zero.
    fn branch_values(&self, ks: std::ops::Range<usize>) -> Option<Vec<f64>> {
        if self.spec.branches == BranchRule::Zero {
            return None;
        }
        let joints = self.model.branches().joints();
        let mut out = Vec::with_capacity(ks.len() * joints.len());
        for k in ks {
            let mut rng = rng_for(self.seed, STREAM_BRANCHES, k as u64);
            for j in joints {
                let (lo, hi) = match j.limits {
                    Some(l) => (l.lower, l.upper),
                    None if j.kind.is_rotational() => (-std::f64::consts::PI, std::f64::consts::PI),
                    None => (0.0, 0.0),
                };
                let u: f64 = rng.random();
                out.push(lo + (hi - lo) * u);
            }
        }
        Some(out)
    }

    /// Directions of poses `ks` (row-major), whose joint values are `qs`; `None` without `dir`.
    fn directions(&mut self, ks: std::ops::Range<usize>, qs: &[f64]) -> Option<Vec<i8>> {
        let n = self.model.nq();
        if let Some(d) = self.file_dir() {
            return Some(
                ks.flat_map(|k| {
                    let e = self.entry(k);
                    d[e * n..(e + 1) * n].to_vec()
                })
                .collect(),
            );
        }
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
    use crate::campaign::Sampling;
    use crate::robots;

    /// A planner's masses (`PayloadRule::PerPose`) go to the poses in order, cycled with the list,
    /// and every repeat of a pose carries its pose's mass.
    #[test]
    fn per_pose_payloads_follow_the_pose_list() {
        let m = robots::load_builtin("iiwa7").unwrap();
        let a = vec![0.1, 0.5, 0.0, -1.0, 0.0, 0.7, 0.2];
        let b = vec![-0.3, 0.8, 0.4, -1.4, 0.1, 0.5, -0.6];
        let spec = CampaignSpec::random(4)
            .to_builder()
            .repeats(2)
            .sampling(Sampling::List { q: vec![a, b] })
            .payload(PayloadRule::PerPose(vec![7.0, 3.5]), [0.0, 0.0, 0.08])
            .build()
            .unwrap();
        let p = plan(&m, &spec, 3, "test").unwrap();
        assert_eq!(p.payload_kg, [7.0, 7.0, 3.5, 3.5, 7.0, 7.0, 3.5, 3.5]);
        let e = spec
            .to_builder()
            .payload(PayloadRule::PerPose(vec![]), [0.0; 3])
            .build()
            .unwrap_err()
            .to_string();
        assert!(e.contains("empty list"), "{e}");
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
