//! Where the joint positions of a campaign come from ([`super::Sampling`]), resolved once for a
//! robot: random draws, a joint-space grid, a given list, a measurement table, the ISO 9283 points.

use super::err;
use super::iso9283::iso9283_list;
use super::spec::{CampaignSpec, Sampling};
use crate::error::Result;
use crate::kinematics::ik::reachable;
use crate::kinematics::{Data, forward_kinematics};
use crate::model::{JointKind, Model};
use nalgebra::Vector3;

/// Sampling interval of joint `i`: the limits shrunk by `margin`, `[−π, π]` for unlimited rotational
/// joints.
fn joint_range(model: &Model, i: usize, margin: f64, file: &str, key: &str) -> Result<(f64, f64)> {
    let j = &model.joints()[i];
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

/// Where the joint positions of pose `k` come from, resolved once for a robot by [`super::Planner::new`].
#[derive(Clone, Debug)]
pub(super) enum PoseSource {
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

/// The context columns of a pose file, one entry per pose of its list (the first row of each pose
/// id): where the file has a column, its value replaces the campaign's rule for that pose.
#[derive(Clone, Debug, Default, PartialEq)]
pub(super) struct FileContext {
    /// Payload mass per pose (kg).
    pub payload_kg: Option<Vec<f64>>,
    /// Robot temperature per pose (°C).
    pub temp_c: Option<Vec<f64>>,
    /// Time of the pose's first measurement (s).
    pub t_s: Option<Vec<f64>>,
    /// Approach directions per pose, row-major (−1, 0, +1).
    pub dir: Option<Vec<i8>>,
}

impl FileContext {
    /// The context of `table`'s poses `by_pose` (pose id, its rows).
    fn of(
        table: &crate::measurement_table::MeasurementTable,
        by_pose: &[(i64, Vec<usize>)],
    ) -> Self {
        let first = |c: &Option<Vec<f64>>| {
            c.as_ref()
                .map(|v| by_pose.iter().map(|(_, rows)| v[rows[0]]).collect())
        };
        FileContext {
            payload_kg: first(&table.payload),
            temp_c: first(&table.temp),
            t_s: first(&table.t),
            dir: table.dir.as_ref().map(|_| {
                by_pose
                    .iter()
                    .flat_map(|(_, rows)| table.dir_row(rows[0]).unwrap_or(&[]).to_vec())
                    .collect()
            }),
        }
    }
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
pub(super) fn grid_point(
    index: u64,
    points_per_joint: &[usize],
    ranges: &[(f64, f64)],
    q: &mut [f64],
) {
    let mut rest = index;
    for i in (0..q.len()).rev() {
        let c = points_per_joint[i] as u64;
        q[i] = grid_value(ranges[i], points_per_joint[i], (rest % c) as usize);
        rest /= c;
    }
}

/// The pose source of `spec` for `model` and the number of poses (see the module docs).
pub(super) fn pose_source(
    model: &Model,
    spec: &CampaignSpec,
    file: &str,
) -> Result<(PoseSource, usize, Option<FileContext>)> {
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
                None,
            ))
        }
        Sampling::Iso9283(iso) => {
            let list = iso9283_list(model, iso, &p_flange, file)?;
            let poses = count(5, false)?;
            Ok((PoseSource::List(list), poses, None))
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
                None,
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
            Ok((PoseSource::List(q.concat()), poses, None))
        }
        Sampling::File { path, .. } => {
            // A pose file needs no measured positions: `pose, q1..qN` (and context columns).
            let table = crate::measurement_table::couple(
                crate::measurement_table::read_configurations(path)?,
                model,
                path,
            )?;
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
            crate::measurement_table::check_within_limits(&table, model, path)?;
            let by_pose = table.rows_by_pose();
            let mut list = Vec::with_capacity(by_pose.len() * n);
            for (_, rows) in &by_pose {
                list.extend_from_slice(table.q_row(rows[0]));
            }
            let poses = count(by_pose.len(), true)?;
            Ok((
                PoseSource::List(list),
                poses,
                Some(FileContext::of(&table, &by_pose)),
            ))
        }
    }
}
