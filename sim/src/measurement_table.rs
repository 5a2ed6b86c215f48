//! The measurement table (`shared/spec/measurements.md`): one row per measurement, read from and written
//! to CSV or Parquet (the file extension decides). Columns are stored column-wise.
//!
//! Units: q in rad (or m for prismatic joints), positions in m in the tracker frame, t in s, temp in °C,
//! payload in kg, sigma in m.

/// A measurement table. All `Option` columns are either absent or have one entry per row.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MeasurementTable {
    /// Number of joint columns `q1..qN`.
    pub n_joints: usize,
    /// Pose id per row; rows sharing an id are repeated measurements of one pose.
    pub pose: Vec<i64>,
    /// Joint positions, row-major: row `r` is `q[r * n_joints .. (r + 1) * n_joints]` (rad or m).
    pub q: Vec<f64>,
    /// Measured target position `p_tracker` per row (m, tracker frame).
    pub position: Vec<[f64; 3]>,
    /// Measured target orientation per row, unit quaternion `[qw, qx, qy, qz]` (tracker frame).
    pub orientation: Option<Vec<[f64; 4]>>,
    /// Time since the start of the campaign (s).
    pub t: Option<Vec<f64>>,
    /// Robot temperature (°C).
    pub temp: Option<Vec<f64>>,
    /// Sign of each joint's last motion, row-major like `q` (−1, 0, +1).
    pub dir: Option<Vec<i8>>,
    /// Mass carried at the flange (kg).
    pub payload: Option<Vec<f64>>,
    /// 1-sigma position uncertainty of the row (m).
    pub sigma: Option<Vec<f64>>,
}
