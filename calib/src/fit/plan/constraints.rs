//! What a real cell allows: the tracker's range and line of sight, the floor, and margins from the
//! joint limits. Evaluated on the nominal kinematics (`sim::kinematics`), before any calibration.
//!
//! The robot's links are taken as capsules between consecutive joint origins: the base origin, the
//! origin of every joint frame, then the flange. The laser beam is the segment from the tracker to
//! the target; it is blocked when a link's axis comes within the clearance of it. The last stretch
//! of the beam, within `|p_flange_target| + clearance` of the target, is not checked: the target is
//! mounted on the last link, which always comes that close to its own reflector.

use crate::error::{CalibError, Result};
use nalgebra::{Point3, Vector3};
use sim::Model;
use sim::kinematics::{Data, forward_kinematics};

/// A constraint a candidate pose can break.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Constraint {
    /// Within `--joint-margin` of a joint limit (or beyond it).
    JointMargin,
    /// A joint origin, the flange or the target at or below the floor.
    Floor,
    /// The target outside the tracker's range.
    TrackerRange,
    /// A link within the clearance of the laser beam.
    LineOfSight,
}

impl Constraint {
    /// Every constraint, in the order they are checked.
    pub const ALL: [Constraint; 4] = [
        Constraint::JointMargin,
        Constraint::Floor,
        Constraint::TrackerRange,
        Constraint::LineOfSight,
    ];

    /// The name used in the output.
    pub fn name(self) -> &'static str {
        match self {
            Constraint::JointMargin => "joint_margin",
            Constraint::Floor => "floor",
            Constraint::TrackerRange => "tracker_range",
            Constraint::LineOfSight => "line_of_sight",
        }
    }
}

/// The cell's constraints; `None` or zero leaves one out.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CellConstraints {
    /// Tracker position in the robot base frame (m). Needed by the range and the line of sight.
    pub tracker_base_m: Option<Vector3<f64>>,
    /// Smallest and largest distance from the tracker to the target (m).
    pub tracker_range_m: Option<(f64, f64)>,
    /// Clearance (m) between the beam and every link's axis; `None`: line of sight not checked.
    pub line_of_sight_clearance_m: Option<f64>,
    /// Floor height in the base frame (m): every joint origin after the first, the flange and the
    /// target stay above it.
    pub floor_z_m: Option<f64>,
    /// Distance to keep from every joint limit (rad, or m for prismatic joints).
    pub joint_margin: f64,
}

/// Squared distance between the segments `[p0, p1]` and `[q0, q1]` (closest points clamped to the
/// segments; Ericson, *Real-Time Collision Detection*, 5.1.9).
fn segment_distance_squared(
    p0: &Point3<f64>,
    p1: &Point3<f64>,
    q0: &Point3<f64>,
    q1: &Point3<f64>,
) -> f64 {
    let d1 = p1 - p0;
    let d2 = q1 - q0;
    let r = p0 - q0;
    let (a, e, f) = (d1.norm_squared(), d2.norm_squared(), d2.dot(&r));
    const EPS: f64 = 1e-18;
    let (s, t) = if a <= EPS && e <= EPS {
        (0.0, 0.0)
    } else if a <= EPS {
        (0.0, (f / e).clamp(0.0, 1.0))
    } else {
        let c = d1.dot(&r);
        if e <= EPS {
            ((-c / a).clamp(0.0, 1.0), 0.0)
        } else {
            let b = d1.dot(&d2);
            let denom = a * e - b * b;
            let mut s = if denom > EPS * a * e {
                ((b * f - c * e) / denom).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let mut t = (b * s + f) / e;
            if t < 0.0 {
                t = 0.0;
                s = (-c / a).clamp(0.0, 1.0);
            } else if t > 1.0 {
                t = 1.0;
                s = ((b - c) / a).clamp(0.0, 1.0);
            }
            (s, t)
        }
    };
    ((p0 + d1 * s) - (q0 + d2 * t)).norm_squared()
}

impl CellConstraints {
    /// Checks the settings: the range and the line of sight need the tracker, values must be finite,
    /// a range must be `0 ≤ MIN < MAX`, the clearance and the margin `≥ 0`.
    pub fn validate(&self) -> Result<()> {
        let bad = |field: &str, value: String, problem: &str| CalibError::BadValue {
            context: "plan-poses".into(),
            field: field.into(),
            value,
            problem: problem.into(),
        };
        if let Some(t) = &self.tracker_base_m
            && !t.iter().all(|v| v.is_finite())
        {
            return Err(bad("--tracker", format!("{t:?}"), "must be finite (m)"));
        }
        if let Some((lo, hi)) = self.tracker_range_m {
            if !(lo.is_finite() && hi.is_finite() && lo >= 0.0 && lo < hi) {
                return Err(bad(
                    "--tracker-range",
                    format!("{lo},{hi}"),
                    "must be MIN,MAX in m with 0 ≤ MIN < MAX",
                ));
            }
            if self.tracker_base_m.is_none() {
                return Err(bad(
                    "--tracker-range",
                    format!("{lo},{hi}"),
                    "needs --tracker X,Y,Z (the tracker's position in the base frame, m)",
                ));
            }
        }
        if let Some(c) = self.line_of_sight_clearance_m {
            if !(c.is_finite() && c >= 0.0) {
                return Err(bad("--line-of-sight", c.to_string(), "must be ≥ 0 m"));
            }
            if self.tracker_base_m.is_none() {
                return Err(bad(
                    "--line-of-sight",
                    c.to_string(),
                    "needs --tracker X,Y,Z (the tracker's position in the base frame, m)",
                ));
            }
        }
        if let Some(z) = self.floor_z_m
            && !z.is_finite()
        {
            return Err(bad("--floor", z.to_string(), "must be a height in m"));
        }
        if !(self.joint_margin.is_finite() && self.joint_margin >= 0.0) {
            return Err(bad(
                "--joint-margin",
                self.joint_margin.to_string(),
                "must be ≥ 0 (rad, or m for prismatic joints)",
            ));
        }
        Ok(())
    }

    /// The joint range a draw may use: the limits less the margin (±π for a joint without limits).
    /// `None` when the margin leaves nothing of a joint's range.
    pub fn drawable_range(&self, model: &Model) -> Option<Vec<(f64, f64)>> {
        model
            .joints()
            .iter()
            .map(|j| {
                let (lo, hi) = j
                    .limits
                    .map_or((-std::f64::consts::PI, std::f64::consts::PI), |l| {
                        (l.lower, l.upper)
                    });
                let (lo, hi) = (lo + self.joint_margin, hi - self.joint_margin);
                (lo < hi).then_some((lo, hi))
            })
            .collect()
    }

    /// The first constraint the nominal robot at `q` breaks with the target at `p_flange_target`
    /// (flange frame, m), or `None`. `data` is scratch for the kinematics.
    pub fn broken(
        &self,
        model: &Model,
        data: &mut Data,
        q: &[f64],
        p_flange_target: &Vector3<f64>,
    ) -> Option<Constraint> {
        let margin = self.joint_margin;
        if q.iter().zip(model.joints()).any(|(v, j)| {
            j.limits
                .is_some_and(|l| *v < l.lower + margin || *v > l.upper - margin)
        }) {
            return Some(Constraint::JointMargin);
        }
        forward_kinematics(model, data, q);
        let target = data.flange * Point3::from(*p_flange_target);
        if let Some(floor) = self.floor_z_m {
            let low = data
                .joint_poses
                .iter()
                .skip(1)
                .map(|t| t.translation.z)
                .chain([data.flange.translation.z, target.z])
                .any(|z| z <= floor);
            if low {
                return Some(Constraint::Floor);
            }
        }
        let tracker = self.tracker_base_m.map(Point3::from)?;
        let beam = target - tracker;
        let distance = beam.norm();
        if let Some((lo, hi)) = self.tracker_range_m
            && !(lo..=hi).contains(&distance)
        {
            return Some(Constraint::TrackerRange);
        }
        if let Some(clearance) = self.line_of_sight_clearance_m {
            let skip = p_flange_target.norm() + clearance;
            if distance > skip {
                let end = tracker + beam * ((distance - skip) / distance);
                let mut points: Vec<Point3<f64>> = Vec::with_capacity(model.nq() + 2);
                points.push(Point3::origin());
                points.extend(
                    data.joint_poses
                        .iter()
                        .map(|t| Point3::from(t.translation.vector)),
                );
                points.push(Point3::from(data.flange.translation.vector));
                let blocked = points.windows(2).any(|w| {
                    segment_distance_squared(&w[0], &w[1], &tracker, &end) < clearance * clearance
                });
                if blocked {
                    return Some(Constraint::LineOfSight);
                }
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segment_distances_match_hand_values() {
        let p = |x: f64, y: f64, z: f64| Point3::new(x, y, z);
        // Crossing skew lines 1 m apart.
        let d = segment_distance_squared(
            &p(-1.0, 0.0, 0.0),
            &p(1.0, 0.0, 0.0),
            &p(0.0, -1.0, 1.0),
            &p(0.0, 1.0, 1.0),
        );
        assert!((d - 1.0).abs() < 1e-15);
        // Parallel, offset along their direction: end to end, √(0.5² + 0.2²).
        let d = segment_distance_squared(
            &p(0.0, 0.0, 0.0),
            &p(1.0, 0.0, 0.0),
            &p(1.5, 0.2, 0.0),
            &p(2.5, 0.2, 0.0),
        );
        assert!((d - 0.29).abs() < 1e-15);
        // A point segment against a segment: perpendicular foot inside.
        let d = segment_distance_squared(
            &p(0.3, 0.4, 0.0),
            &p(0.3, 0.4, 0.0),
            &p(0.0, 0.0, 0.0),
            &p(1.0, 0.0, 0.0),
        );
        assert!((d - 0.16).abs() < 1e-15);
    }
}
