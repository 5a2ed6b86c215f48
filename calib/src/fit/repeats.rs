//! Repeated measurements of a pose: rows that share a pose id (per campaign) at the same joint values
//! (the measurement table's contract, [`sim::measurement_table::POSE_REPEAT_TOLERANCE`]), as a
//! tracker streams them when the robot stands still. Their scatter about their pose's mean is the
//! measured repeatability of robot and tracker together, the level below which no model predicts.
//!
//! The least-squares fit uses repeats as they are: `n` rows of one pose with the same `σ` give the
//! same solution as their mean with `σ/√n` (the objectives differ by the scatter, a constant), and the
//! scatter enters `χ²` with its `n − 1` degrees of freedom, as noise should.

use sim::measurement_table::MeasurementTable;

/// The pooled scatter of repeated measurements.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Repeatability {
    /// Rows that repeat a pose: beyond the first of each pose, summed (the degrees of freedom).
    pub repeats: usize,
    /// Poses measured more than once.
    pub poses: usize,
    /// Pooled scatter about each pose's mean position, `√(Σ |x − x̄|² / repeats)` (m; the 3-D RMS a
    /// repeat lies from its pose's mean, `√3` times a per-axis standard deviation), the definition of
    /// diagnose's noise floor.
    pub rms_m: f64,
}

impl Repeatability {
    /// The standard deviation per axis (m), `rms_m / √3`.
    pub fn per_axis_m(&self) -> f64 {
        self.rms_m / 3f64.sqrt()
    }
}

/// [`Repeatability`] of rows handed over pose by pose: each pose's rows one after another (a
/// stream's order; a pose that comes back after others counts as a new one). Welford's update within
/// a pose, so that large coordinates do not cancel.
#[derive(Clone, Debug, Default)]
pub struct RepeatScatter {
    key: Option<(i64, i64)>,
    n: usize,
    mean: [f64; 3],
    m2: f64,
    repeats: usize,
    poses: usize,
    ss: f64,
}

impl RepeatScatter {
    /// Adds a row of pose `key` (campaign, pose id) measured at `p` (tracker frame, m).
    pub fn add(&mut self, key: (i64, i64), p: [f64; 3]) {
        if self.key != Some(key) {
            self.close();
            self.key = Some(key);
        }
        self.n += 1;
        let n = self.n as f64;
        for (k, &x) in p.iter().enumerate() {
            let delta = x - self.mean[k];
            self.mean[k] += delta / n;
            self.m2 += delta * (x - self.mean[k]);
        }
    }

    fn close(&mut self) {
        if self.n > 1 {
            self.repeats += self.n - 1;
            self.poses += 1;
            self.ss += self.m2;
        }
        self.n = 0;
        self.mean = [0.0; 3];
        self.m2 = 0.0;
    }

    /// The scatter of every pose added, `None` without a repeat.
    pub fn finish(mut self) -> Option<Repeatability> {
        self.close();
        (self.repeats > 0).then(|| Repeatability {
            repeats: self.repeats,
            poses: self.poses,
            rms_m: (self.ss / self.repeats as f64).sqrt(),
        })
    }
}

/// [`Repeatability`] of the rows `rows` of `table`, in any order (grouped by pose first).
pub fn of_rows(table: &MeasurementTable, rows: &[usize]) -> Option<Repeatability> {
    let mut keep = vec![false; table.len()];
    for &r in rows {
        if let Some(k) = keep.get_mut(r) {
            *k = true;
        }
    }
    let mut scatter = RepeatScatter::default();
    for (_, group) in table.rows_by_pose() {
        for r in group.into_iter().filter(|&r| keep[r]) {
            scatter.add(table.pose_key(r), table.position[r]);
        }
    }
    scatter.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_pooled_scatter_is_the_hand_computed_one() {
        // Pose 1: x at 0, 2 (mean 1, squares 1 + 1); pose 2: y at 10, 13, 16 (mean 13, squares
        // 9 + 0 + 9); pose 3 once. Σ = 20 over 1 + 2 = 3 repeats.
        let mut s = RepeatScatter::default();
        s.add((0, 1), [0.0, 5.0, 5.0]);
        s.add((0, 1), [2.0, 5.0, 5.0]);
        s.add((0, 2), [1.0, 10.0, 1.0]);
        s.add((0, 2), [1.0, 13.0, 1.0]);
        s.add((0, 2), [1.0, 16.0, 1.0]);
        s.add((0, 3), [7.0, 7.0, 7.0]);
        let r = s.finish().unwrap();
        assert_eq!((r.repeats, r.poses), (3, 2));
        assert!((r.rms_m - (20.0f64 / 3.0).sqrt()).abs() < 1e-15);
        assert!((r.per_axis_m() - (20.0f64 / 9.0).sqrt()).abs() < 1e-15);
        // No repeats, nothing.
        let mut s = RepeatScatter::default();
        s.add((0, 1), [0.0; 3]);
        s.add((1, 1), [1.0; 3]);
        assert_eq!(s.finish(), None);
    }

    #[test]
    fn far_from_the_tracker_the_scatter_does_not_cancel() {
        // 1 µm about a pose 5 m away: the naive Σx² − n x̄² loses it, Welford's update keeps it.
        let mut s = RepeatScatter::default();
        for dx in [-1e-6, 1e-6, -1e-6, 1e-6] {
            s.add((0, 7), [5.0 + dx, 5.0, 5.0]);
        }
        let r = s.finish().unwrap();
        assert!(
            (r.rms_m - (4e-12f64 / 3.0).sqrt()).abs() < 1e-15,
            "{}",
            r.rms_m
        );
    }
}
