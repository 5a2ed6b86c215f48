//! The measurement table (`shared/spec/measurements.md`): one row per measurement, read from and written
//! to CSV or Parquet (the file extension decides). Columns are stored column-wise.
//!
//! Units: q in rad (or m for prismatic joints), positions in m in the tracker frame, t in s, temp in °C,
//! payload in kg, sigma in m.
//!
//! # Branch joints
//! A column named `q_<joint name>` (`q_` followed by a non-empty name, e.g. `q_neck_yaw`) holds the
//! value (rad; m for prismatic joints) of a movable joint of a *branch* that hangs off the measured
//! chain (a second arm, a head): its links load the chain with their mass but are not on it. Such
//! columns are optional and kept in [`MeasurementTable::branch`] ([`BranchColumns`]), in header
//! order, their values numbers and finite exactly like `q1..qN`. Which joints they are, and whether
//! they lie within their limits, is the robot model's business, not the table's. `q_` alone (no
//! name) is an error.
//!
//! # Files
//! [`read`] and [`write`] choose the format from the extension (`.csv` or `.parquet`, any letter case).
//! Column order on write: `pose, q1..qN, [q_<branch joint>…], x, y, z, [qw, qx, qy, qz], [t], [temp],
//! [dir1..dirN], [payload], [sigma], [campaign]`. On read, columns may come in any order, and columns
//! the contract does not name are ignored.
//! The number of joints N is the number of `q1..qN` columns, which must run from `q1` without a gap;
//! `dir1..dirN`, when present, must match N. Writes are atomic: a temporary file in the same folder is
//! renamed over the target once complete.
//!
//! * CSV: header row, comma separator, `.` decimal point, optional UTF-8 BOM, blank lines skipped,
//!   blanks around cells trimmed, RFC 4180 quotes understood. Floats are written as the shortest decimal
//!   that reads back to the same `f64` (Rust's `{:?}`: always with a `.` or an exponent, so that every
//!   reader infers a float column), so CSV round-trips bit-exactly, `-0.0` and subnormals included.
//! * Parquet: `pose` and `campaign` Int64, `dir*` Int8, every other column (`q_<joint>` included)
//!   Float64, none nullable; SNAPPY compression;
//!   at most [`PARQUET_MAX_ROW_GROUP_ROWS`] rows per row group; the same table always gives the same
//!   bytes (no timestamps; writer properties set explicitly). On read any integer or float Arrow type is
//!   accepted when its values convert exactly (Int32 pose, Float32 positions, …); nulls are errors.
//!
//! # Errors
//! Every problem is one [`SimError::Table`] line naming the file, the row and the column, such as
//! `data.csv: row 17 (line 18), column q3: 'abc' is not a number`. Rows are numbered from 1 for the
//! first data row (the header is not a row); for CSV the 1-based line of the text file follows in
//! parentheses (it differs from `row + 1` when there are blank lines or quoted line breaks).
//!
//! Errors on read (and on write, which refuses to store such a table): a missing required column
//! (`pose`, `q1`, `x`, `y`, `z`), a gap in `q1..qN` or `dir1..dirN`, part of `qw, qx, qy, qz`, a duplicate
//! column name, a `q_` column without a joint name, no data rows, a cell that is empty, not a number or
//! not finite, a `pose` that is not an integer, a `campaign` that is not an integer, a `dir` that is not −1, 0 or +1, negative `payload` or `sigma`, a `sigma` outside
//! [[`MIN_SIGMA_M`], [`MAX_SIGMA_M`]] (zero and subnormals included), and an orientation quaternion
//! whose norm differs from 1 by more than [`QUATERNION_NORM_ERROR`] (not a unit quaternion at all).
//! Quaternions closer to unit than that are kept exactly as stored (so files round-trip);
//! [`check_against_model`] warns beyond [`QUATERNION_NORM_WARNING`] and users of orientations should
//! call [`MeasurementTable::unit_orientation`], which normalises.
//!
//! Checks that need the robot (joint count, URDF limits, units that look like millimetres or degrees)
//! are in [`check_against_model`].
//!
//! ```
//! use sim::measurement_table::{self as mt, MeasurementTable, OptionalColumns, Row};
//! let columns = OptionalColumns { sigma: true, ..OptionalColumns::NONE };
//! let mut table = MeasurementTable::new(2, columns);
//! let q = [0.5, -1.0]; // rad
//! let row = Row { pose: 0, q: &q, position: [0.1, 0.2, 0.3], sigma: Some(1e-5), ..Default::default() };
//! table.push_row(&row).unwrap();
//! let text = mt::write_csv_string(&table).unwrap();
//! assert_eq!(text, "pose,q1,q2,x,y,z,sigma\n0,0.5,-1.0,0.1,0.2,0.3,1e-5\n");
//! assert_eq!(mt::read_csv_str(&text, "m.csv").unwrap(), table);
//! let err = mt::read_csv_str("pose,q1,x,y,z\n0,abc,0,0,0\n", "m.csv").unwrap_err();
//! assert_eq!(err.to_string(), "m.csv: row 1 (line 2), column q1: 'abc' is not a number");
//! ```

mod branch_values;
mod check;
mod chunks;
mod columns;
mod couple;
mod csv;
mod parquet;

pub use branch_values::BranchValues;
pub use check::{
    LIMIT_TOLERANCE, ModelCheck, check_against_model, check_within_limits, reach_bound,
};
pub use chunks::{
    CSV_BLOCK_BYTES, Chunk, DEFAULT_CHUNK_ROWS, TableChunks, read_chunks, read_configuration_chunks,
};
pub use columns::{Column, ColumnValues, configurations_from_columns, from_columns};
pub use couple::{COUPLING_TOLERANCE, couple, drive_columns, whole_chain};
pub use csv::{read_csv_str, write_csv_string};
pub use parquet::{PARQUET_MAX_ROW_GROUP_ROWS, ParquetTableWriter, write_parquet_bytes};

use crate::error::{Result, SimError, fragment};
use std::collections::HashMap;
use std::path::Path;

/// An orientation whose quaternion norm differs from 1 by more than this is rejected on read and write.
pub const QUATERNION_NORM_ERROR: f64 = 1e-3;

/// A measured position farther than this from the tracker (m) is rejected: laser trackers measure to
/// tens of metres, so such a value is a unit error or garbage.
pub const MAX_POSITION_M: f64 = 1000.0;
/// A payload heavier than this (kg) is rejected: ten times what the largest industrial arms carry.
pub const MAX_PAYLOAD_KG: f64 = 1000.0;
/// A `sigma` above this (m) is rejected: a tracker's uncertainty is micrometres to millimetres.
pub const MAX_SIGMA_M: f64 = 1.0;
/// A `sigma` below this (m), zero included, is rejected: no tracker measures to a nanometre, and a
/// subnormal `sigma` such as 4.9e-324 m gives its row a weight that overflows the fit (found by the
/// fuzzing suite: `calibrate` ran for minutes on both cores).
pub const MIN_SIGMA_M: f64 = 1e-9;
/// A `temp` outside this range (°C) is rejected: below absolute zero, or hotter than any robot runs
/// (found by the fuzzing suite: 1e15 °C was read without a word).
pub const TEMP_RANGE_C: (f64, f64) = (-273.15, 1000.0);
/// Rows that share a pose id are repeated measurements of one pose: their joint values must agree
/// with the pose's first row to within this (rad; m for prismatic joints). Encoder noise is
/// micro-radians; a milliradian is a millimetre at a metre's reach, another configuration.
pub const POSE_REPEAT_TOLERANCE: f64 = 1e-3;

/// [`check_against_model`] warns about quaternion norms that differ from 1 by more than this.
pub const QUATERNION_NORM_WARNING: f64 = 1e-6;

/// Name shown in errors about a table that has no file (e.g. [`MeasurementTable::validate_shape`]).
pub const IN_MEMORY: &str = "<measurement table>";

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
    /// Measurement campaign per row (an integer id): each campaign has its own tracker placement.
    /// Pose ids are per campaign: a pose is identified by `(campaign, pose)`.
    pub campaign: Option<Vec<i64>>,
    /// Values of the movable joints of branches off the chain (`q_<joint name>` columns, rad or m);
    /// None when the table has no `q_` column.
    pub branch: Option<BranchColumns>,
}

/// Values of the movable joints of branches off the chain (`q_<joint name>` columns): joints whose
/// links load the chain but are not on it (rad; m for prismatic joints).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BranchColumns {
    /// Joint names, the column names without their `q_` prefix, in column order.
    pub names: Vec<String>,
    /// Values, row-major: row `r` is `values[r * names.len() .. (r + 1) * names.len()]`.
    pub values: Vec<f64>,
}

/// Prefix of a branch joint's column: `q_<joint name>`.
const BRANCH_PREFIX: &str = "q_";

/// What is wrong with `name` as the joint name of a branch column `q_<name>`, if anything: empty,
/// or blanks at either end (a file's reader trims column names, so such a name would not read back).
fn branch_name_problem(name: &str) -> Option<&'static str> {
    if name.trim().is_empty() {
        Some("a branch joint column needs the joint's name after 'q_' (q_<joint name>)")
    } else if name.trim() != name {
        Some("a branch joint's name must not start or end with blanks")
    } else {
        None
    }
}

/// Which optional columns a table has (the required ones, `pose, q1..qN, x, y, z`, it always has).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct OptionalColumns {
    /// `qw, qx, qy, qz`: target orientation (unit quaternion, tracker frame).
    pub orientation: bool,
    /// `t`: time since the start of the campaign (s).
    pub t: bool,
    /// `temp`: robot temperature (°C).
    pub temp: bool,
    /// `dir1..dirN`: sign of each joint's last motion (−1, 0, +1).
    pub dir: bool,
    /// `payload`: mass at the flange (kg).
    pub payload: bool,
    /// `sigma`: 1-sigma position uncertainty (m).
    pub sigma: bool,
    /// `campaign`: measurement campaign id (integer).
    pub campaign: bool,
}

impl OptionalColumns {
    /// No optional column.
    pub const NONE: Self = Self {
        orientation: false,
        t: false,
        temp: false,
        dir: false,
        payload: false,
        sigma: false,
        campaign: false,
    };
    /// Every optional column.
    pub const ALL: Self = Self {
        orientation: true,
        t: true,
        temp: true,
        dir: true,
        payload: true,
        sigma: true,
        campaign: true,
    };
}

/// One row of a [`MeasurementTable`], borrowed; used to append rows ([`MeasurementTable::push_row`]) and
/// to read them back ([`MeasurementTable::row`]). Optional fields are `Some` exactly when the table has
/// the column.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Row<'a> {
    /// Pose id.
    pub pose: i64,
    /// Joint positions `q1..qN` (rad or m), `n_joints` values.
    pub q: &'a [f64],
    /// Measured target position `p_tracker` (m, tracker frame).
    pub position: [f64; 3],
    /// Measured target orientation `[qw, qx, qy, qz]` (unit quaternion, tracker frame).
    pub orientation: Option<[f64; 4]>,
    /// Time since the start of the campaign (s).
    pub t: Option<f64>,
    /// Robot temperature (°C).
    pub temp: Option<f64>,
    /// Sign of each joint's last motion (−1, 0, +1), `n_joints` values.
    pub dir: Option<&'a [i8]>,
    /// Mass at the flange (kg).
    pub payload: Option<f64>,
    /// 1-sigma position uncertainty (m).
    pub sigma: Option<f64>,
    /// Measurement campaign id.
    pub campaign: Option<i64>,
    /// Values of the branch joints `q_<name>` (rad or m), one per [`MeasurementTable::branch_names`].
    pub branch: Option<&'a [f64]>,
}

/// File format of a measurement table.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// Comma-separated text with a header row.
    Csv,
    /// Apache Parquet.
    Parquet,
}

impl Format {
    /// The format named by the file's extension (`.csv` or `.parquet`, any letter case).
    pub fn from_path(path: &Path) -> Result<Format> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        match ext.as_deref() {
            Some("csv") => Ok(Format::Csv),
            Some("parquet") => Ok(Format::Parquet),
            _ => Err(table_err(
                &path.display().to_string(),
                None,
                None,
                "unknown table format: the file name must end in .csv or .parquet".into(),
            )),
        }
    }
}

/// Reads a measurement table from `path` (CSV or Parquet by extension) and checks it
/// ([`MeasurementTable::validate`]). Checks against a robot are separate ([`check_against_model`]).
pub fn read(path: &Path) -> Result<MeasurementTable> {
    read_with(path, Positions::Required)
}

/// [`read`] or [`read_configurations`].
fn read_with(path: &Path, positions: Positions) -> Result<MeasurementTable> {
    let format = Format::from_path(path)?;
    let name = path.display().to_string();
    match format {
        Format::Csv => {
            let bytes = std::fs::read(path).map_err(|e| read_err(path, e))?;
            csv::read_csv_bytes(&bytes, &name, positions)
        }
        Format::Parquet => parquet::read_parquet_file(path, &name, positions),
    }
}

/// Reads a table of joint configurations from `path` (CSV or Parquet by extension): the measurement
/// contract with `x, y, z` optional, for tools that only need the joint values (`robocal predict`).
/// Without them the positions are zero; when present they are read and checked as by [`read`].
/// Everything else is as [`read`].
pub fn read_configurations(path: &Path) -> Result<MeasurementTable> {
    read_with(path, Positions::Optional)
}

/// Whether a reader requires the `x, y, z` columns.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Positions {
    /// The measurement contract: required.
    Required,
    /// Joint configurations: absent means zero.
    Optional,
}

/// Writes `table` to `path` (CSV or Parquet by extension), atomically: the data goes to a temporary file
/// in the same folder, which is renamed over `path` when complete. The table is validated first
/// ([`MeasurementTable::validate`]); an invalid table is not written.
pub fn write(path: &Path, table: &MeasurementTable) -> Result<()> {
    let format = Format::from_path(path)?;
    table.validate(path)?;
    let bytes = match format {
        Format::Csv => csv::write_csv_bytes(table),
        Format::Parquet => parquet::write_parquet_unchecked(table, &path.display().to_string())?,
    };
    crate::io::write_atomic(path, &bytes)
}

/// An input file that cannot be read.
fn read_err(path: &Path, source: std::io::Error) -> SimError {
    SimError::Read {
        path: path.to_path_buf(),
        source,
    }
}

/// A [`SimError::Table`] without a line number.
pub(crate) fn table_err(
    file: &str,
    row: Option<usize>,
    column: Option<&str>,
    message: String,
) -> SimError {
    SimError::Table {
        file: file.to_string(),
        row,
        line: None,
        column: column.map(str::to_string),
        message,
    }
}

/// `e` with a row's error moved to the file's numbering: the 1-based row of a piece (or a whole
/// table, `first_row` 0) plus the `first_row` rows before it, and, when it names no line yet, the
/// line `line_of` gives for the piece's row (CSV). Other errors pass unchanged.
pub(crate) fn at_file_row(
    e: SimError,
    first_row: usize,
    line_of: impl FnOnce(usize) -> Option<usize>,
) -> SimError {
    match e {
        SimError::Table {
            file,
            row: Some(r),
            line,
            column,
            message,
        } => SimError::Table {
            file,
            row: Some(first_row + r),
            line: line.or_else(|| line_of(r)),
            column,
            message,
        },
        e => e,
    }
}

impl MeasurementTable {
    /// An empty table with `n_joints` joint columns and the given optional columns (present ones start
    /// as empty vectors), ready for [`MeasurementTable::push_row`].
    pub fn new(n_joints: usize, columns: OptionalColumns) -> Self {
        Self::with_capacity(n_joints, columns, 0)
    }

    /// Like [`MeasurementTable::new`], with room for `rows` rows.
    pub fn with_capacity(n_joints: usize, columns: OptionalColumns, rows: usize) -> Self {
        let v = |on: bool| on.then(|| Vec::with_capacity(rows));
        MeasurementTable {
            n_joints,
            pose: Vec::with_capacity(rows),
            q: Vec::with_capacity(rows * n_joints),
            position: Vec::with_capacity(rows),
            orientation: columns.orientation.then(|| Vec::with_capacity(rows)),
            t: v(columns.t),
            temp: v(columns.temp),
            dir: columns.dir.then(|| Vec::with_capacity(rows * n_joints)),
            payload: v(columns.payload),
            sigma: v(columns.sigma),
            campaign: columns.campaign.then(|| Vec::with_capacity(rows)),
            branch: None,
        }
    }

    /// An empty table with the columns of this one (joint count, optional columns, branch joint
    /// names), with room for `rows` rows: for copying rows of this table with
    /// [`MeasurementTable::push_row`].
    pub fn empty_like(&self, rows: usize) -> Self {
        let mut out = Self::with_capacity(self.n_joints, self.columns(), rows);
        out.branch = self.branch.as_ref().map(|b| BranchColumns {
            names: b.names.clone(),
            values: Vec::with_capacity(rows * b.names.len()),
        });
        out
    }

    /// Which optional columns the table has.
    pub fn columns(&self) -> OptionalColumns {
        OptionalColumns {
            orientation: self.orientation.is_some(),
            t: self.t.is_some(),
            temp: self.temp.is_some(),
            dir: self.dir.is_some(),
            payload: self.payload.is_some(),
            sigma: self.sigma.is_some(),
            campaign: self.campaign.is_some(),
        }
    }

    /// Number of rows (measurements).
    #[inline]
    pub fn len(&self) -> usize {
        self.pose.len()
    }

    /// True when the table has no rows.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.pose.is_empty()
    }

    /// Joint positions `q1..qN` of row `r` (rad or m). Panics if `r >= len()`, like slice indexing.
    #[inline]
    pub fn q_row(&self, r: usize) -> &[f64] {
        &self.q[r * self.n_joints..(r + 1) * self.n_joints]
    }

    /// Motion directions `dir1..dirN` of row `r` (−1, 0, +1), or `None` without `dir` columns.
    /// Panics if `r >= len()`.
    #[inline]
    pub fn dir_row(&self, r: usize) -> Option<&[i8]> {
        self.dir
            .as_ref()
            .map(|d| &d[r * self.n_joints..(r + 1) * self.n_joints])
    }

    /// Branch joint values of row `r` (rad or m), in [`MeasurementTable::branch_names`] order, or
    /// `None` without `q_` columns. Panics if `r >= len()`.
    #[inline]
    pub fn branch_row(&self, r: usize) -> Option<&[f64]> {
        self.branch.as_ref().map(|b| {
            let n = b.names.len();
            &b.values[r * n..(r + 1) * n]
        })
    }

    /// Names of the branch joints, the `q_<name>` columns without their prefix, in column order
    /// (empty without).
    pub fn branch_names(&self) -> &[String] {
        self.branch.as_ref().map_or(&[], |b| &b.names)
    }

    /// Payload of row `r` (kg); 0 when the table has no `payload` column (the contract's default).
    #[inline]
    pub fn payload_or_zero(&self, r: usize) -> f64 {
        self.payload.as_ref().map_or(0.0, |p| p[r])
    }

    /// Orientation of row `r` normalised to a unit quaternion `[qw, qx, qy, qz]` (tracker frame), or
    /// `None` without orientation columns. Stored values are kept as read; use this to consume them.
    pub fn unit_orientation(&self, r: usize) -> Option<[f64; 4]> {
        self.orientation.as_ref().map(|o| {
            let q = o[r];
            let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
            [q[0] / n, q[1] / n, q[2] / n, q[3] / n]
        })
    }

    /// Row `r`, borrowed. Panics if `r >= len()`.
    pub fn row(&self, r: usize) -> Row<'_> {
        Row {
            pose: self.pose[r],
            q: self.q_row(r),
            position: self.position[r],
            orientation: self.orientation.as_ref().map(|v| v[r]),
            t: self.t.as_ref().map(|v| v[r]),
            temp: self.temp.as_ref().map(|v| v[r]),
            dir: self.dir_row(r),
            payload: self.payload.as_ref().map(|v| v[r]),
            sigma: self.sigma.as_ref().map(|v| v[r]),
            campaign: self.campaign.as_ref().map(|v| v[r]),
            branch: self.branch_row(r),
        }
    }

    /// Appends a row. Fails (and leaves the table unchanged) if `row.q` or `row.dir` do not have
    /// `n_joints` values, if `row.branch` does not have one value per branch joint, or if an optional
    /// field is `Some` where the table lacks the column or `None` where it has it. Values are checked when the table is written ([`MeasurementTable::validate`]).
    pub fn push_row(&mut self, row: &Row<'_>) -> Result<()> {
        let at = Some(self.len() + 1);
        let err = |column: &str, message: String| table_err(IN_MEMORY, at, Some(column), message);
        if row.q.len() != self.n_joints {
            return Err(err(
                "q",
                format!(
                    "{} joint values for a table of {} joints",
                    row.q.len(),
                    self.n_joints
                ),
            ));
        }
        if let Some(d) = row.dir
            && d.len() != self.n_joints
        {
            return Err(err(
                "dir",
                format!(
                    "{} directions for a table of {} joints",
                    d.len(),
                    self.n_joints
                ),
            ));
        }
        match (self.branch_names().first(), row.branch) {
            (Some(first), None) => {
                return Err(err(
                    &format!("{BRANCH_PREFIX}{first}"),
                    "the table has this column but the row gives no value".into(),
                ));
            }
            (None, Some(_)) => {
                return Err(err(
                    BRANCH_PREFIX,
                    "the row gives branch joint values but the table has no q_ column".into(),
                ));
            }
            (Some(first), Some(b)) if b.len() != self.branch_names().len() => {
                return Err(err(
                    &format!("{BRANCH_PREFIX}{first}"),
                    format!(
                        "{} branch joint values for a table of {} branch joints",
                        b.len(),
                        self.branch_names().len()
                    ),
                ));
            }
            _ => {}
        }
        let has = self.columns();
        let given = [
            ("qw", has.orientation, row.orientation.is_some()),
            ("t", has.t, row.t.is_some()),
            ("temp", has.temp, row.temp.is_some()),
            ("dir", has.dir, row.dir.is_some()),
            ("payload", has.payload, row.payload.is_some()),
            ("sigma", has.sigma, row.sigma.is_some()),
            ("campaign", has.campaign, row.campaign.is_some()),
        ];
        for (name, col, val) in given {
            if col != val {
                let msg = if col {
                    "the table has this column but the row gives no value"
                } else {
                    "the row gives a value but the table has no such column"
                };
                return Err(err(name, msg.into()));
            }
        }
        self.pose.push(row.pose);
        self.q.extend_from_slice(row.q);
        self.position.push(row.position);
        if let (Some(v), Some(x)) = (self.orientation.as_mut(), row.orientation) {
            v.push(x);
        }
        for (col, val) in [
            (&mut self.t, row.t),
            (&mut self.temp, row.temp),
            (&mut self.payload, row.payload),
            (&mut self.sigma, row.sigma),
        ] {
            if let (Some(v), Some(x)) = (col.as_mut(), val) {
                v.push(x);
            }
        }
        if let (Some(v), Some(x)) = (self.dir.as_mut(), row.dir) {
            v.extend_from_slice(x);
        }
        if let (Some(v), Some(x)) = (self.campaign.as_mut(), row.campaign) {
            v.push(x);
        }
        if let (Some(b), Some(x)) = (self.branch.as_mut(), row.branch) {
            b.values.extend_from_slice(x);
        }
        Ok(())
    }

    /// Column names in file order: `pose, q1..qN`, the branch joints' `q_<name>`, `x, y, z`, then the
    /// optional columns present.
    pub fn column_names(&self) -> Vec<String> {
        let n = self.n_joints;
        let c = self.columns();
        let mut names = vec!["pose".to_string()];
        names.extend((1..=n).map(|j| format!("q{j}")));
        names.extend(
            self.branch_names()
                .iter()
                .map(|b| format!("{BRANCH_PREFIX}{b}")),
        );
        names.extend(["x", "y", "z"].map(String::from));
        if c.orientation {
            names.extend(["qw", "qx", "qy", "qz"].map(String::from));
        }
        if c.t {
            names.push("t".into());
        }
        if c.temp {
            names.push("temp".into());
        }
        if c.dir {
            names.extend((1..=n).map(|j| format!("dir{j}")));
        }
        if c.payload {
            names.push("payload".into());
        }
        if c.sigma {
            names.push("sigma".into());
        }
        if c.campaign {
            names.push("campaign".into());
        }
        names
    }

    /// Distinct pose ids in order of first appearance.
    pub fn pose_ids(&self) -> Vec<i64> {
        self.rows_by_pose().into_iter().map(|(p, _)| p).collect()
    }

    /// Number of distinct poses (pose ids, per campaign when the table has a `campaign` column).
    pub fn n_poses(&self) -> usize {
        let mut seen = std::collections::HashSet::with_capacity(self.len());
        (0..self.len())
            .filter(|&r| seen.insert(self.pose_key(r)))
            .count()
    }

    /// Campaign id of row `r`, or `None` without a `campaign` column. Panics if `r >= len()`.
    #[inline]
    pub fn campaign_of(&self, r: usize) -> Option<i64> {
        self.campaign.as_ref().map(|c| c[r])
    }

    /// Distinct campaign ids, ascending (empty without a `campaign` column).
    pub fn campaign_ids(&self) -> Vec<i64> {
        let mut ids = self.campaign.clone().unwrap_or_default();
        ids.sort_unstable();
        ids.dedup();
        ids
    }

    /// What identifies the pose of row `r`: `(campaign, pose)`, the campaign 0 without the column.
    #[inline]
    pub fn pose_key(&self, r: usize) -> (i64, i64) {
        (self.campaign_of(r).unwrap_or(0), self.pose[r])
    }

    /// The rows of each pose (pose id, per campaign when the table has a `campaign` column), poses in
    /// order of first appearance, rows ascending. The `i64` is the pose id.
    pub fn rows_by_pose(&self) -> Vec<(i64, Vec<usize>)> {
        let mut index: HashMap<(i64, i64), usize> = HashMap::with_capacity(self.len());
        let mut groups: Vec<(i64, Vec<usize>)> = Vec::new();
        for r in 0..self.len() {
            let p = self.pose[r];
            let g = *index.entry(self.pose_key(r)).or_insert_with(|| {
                groups.push((p, Vec::new()));
                groups.len() - 1
            });
            groups[g].1.push(r);
        }
        groups
    }

    /// A new table with the given rows, in the given order (e.g. a train/test split by pose), every
    /// column kept (branch joints included). Panics if a row index is out of range.
    pub fn select_rows(&self, rows: &[usize]) -> MeasurementTable {
        let mut out = self.empty_like(rows.len());
        for &r in rows {
            out.push_row(&self.row(r))
                .expect("a row of a table fits a table with the same columns");
        }
        out
    }

    /// Checks that every column has one entry per row (`q` and `dir`: `n_joints` per row; branch
    /// values: one per branch joint per row) and that branch joint names are unique and not empty
    /// (a table without branch joints has `branch` None, not an empty list of names).
    /// Errors name the table [`IN_MEMORY`].
    pub fn validate_shape(&self) -> Result<()> {
        self.shape_check(IN_MEMORY)
    }

    fn shape_check(&self, file: &str) -> Result<()> {
        let n = self.len();
        let nq = self.n_joints;
        let lens = [
            ("q", self.q.len(), n * nq),
            ("x", self.position.len(), n),
            ("qw", self.orientation.as_ref().map_or(n, Vec::len), n),
            ("t", self.t.as_ref().map_or(n, Vec::len), n),
            ("temp", self.temp.as_ref().map_or(n, Vec::len), n),
            ("dir", self.dir.as_ref().map_or(n * nq, Vec::len), n * nq),
            ("payload", self.payload.as_ref().map_or(n, Vec::len), n),
            ("sigma", self.sigma.as_ref().map_or(n, Vec::len), n),
            ("campaign", self.campaign.as_ref().map_or(n, Vec::len), n),
        ];
        if self.branch.as_ref().is_some_and(|b| b.names.is_empty()) {
            return Err(table_err(
                file,
                None,
                Some(BRANCH_PREFIX),
                "branch columns without a joint name: a table without branch joints has none (None)"
                    .into(),
            ));
        }
        let nb = self.branch_names().len();
        let branch_len = self.branch.as_ref().map_or(0, |b| b.values.len());
        if branch_len != n * nb {
            let column = self
                .branch_names()
                .first()
                .map_or(BRANCH_PREFIX.to_string(), |b| format!("{BRANCH_PREFIX}{b}"));
            return Err(table_err(
                file,
                None,
                Some(&fragment(&column)),
                format!(
                    "{branch_len} values, but {n} rows of {nb} branch joints need {}",
                    n * nb
                ),
            ));
        }
        let names = self.branch_names();
        for (i, name) in names.iter().enumerate() {
            let column = fragment(&format!("{BRANCH_PREFIX}{name}"));
            if let Some(problem) = branch_name_problem(name) {
                return Err(table_err(file, None, Some(&column), problem.into()));
            }
            if let Some(first) = names[..i].iter().position(|m| m == name) {
                return Err(table_err(
                    file,
                    None,
                    Some(&column),
                    format!(
                        "the branch joint appears twice (branch columns {} and {})",
                        first + 1,
                        i + 1
                    ),
                ));
            }
        }
        for (col, got, want) in lens {
            if got != want {
                return Err(table_err(
                    file,
                    None,
                    Some(col),
                    format!(
                        "{got} values, but {n} rows of {} need {want}",
                        if matches!(col, "q" | "dir") {
                            format!("{nq} joints")
                        } else {
                            "1 value".into()
                        }
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Checks everything that does not need the robot: shape ([`MeasurementTable::validate_shape`]), at
    /// least one joint and one row, every float finite, `dir` in {−1, 0, +1}, `payload` and `sigma` not
    /// negative, quaternion norms within [`QUATERNION_NORM_ERROR`] of 1, physically possible magnitudes
    /// (positions within [`MAX_POSITION_M`] of the tracker, `payload` up to [`MAX_PAYLOAD_KG`], `sigma`
    /// from [`MIN_SIGMA_M`] to [`MAX_SIGMA_M`], `temp` within [`TEMP_RANGE_C`]), and the rows of each pose id at one configuration (joint values within
    /// [`POSE_REPEAT_TOLERANCE`]; the error names both rows). Reports the first bad cell in reading
    /// order (row by row, columns in file order); errors name `file`.
    pub fn validate(&self, file: &Path) -> Result<()> {
        let file = file.display().to_string();
        self.validate_named(&file)
    }

    pub(crate) fn validate_named(&self, file: &str) -> Result<()> {
        self.shape_check(file)?;
        if self.n_joints == 0 {
            return Err(table_err(
                file,
                None,
                Some("q1"),
                "no joint columns: q1..qN are required".into(),
            ));
        }
        if self.is_empty() {
            return Err(table_err(file, None, None, "no data rows".into()));
        }
        for r in 0..self.len() {
            self.validate_row(r, file)?;
        }
        self.check_pose_repeats(file)
    }

    /// Every row of a pose (id, per campaign) at the joint values of its first row, within
    /// [`POSE_REPEAT_TOLERANCE`].
    fn check_pose_repeats(&self, file: &str) -> Result<()> {
        // A stream's usual order, pose keys ascending with each pose's rows together, needs no map:
        // a row can only repeat the first row of its run. Any other order takes the map, from the
        // first row, so that the first bad row is named either way.
        let mut run_first = 0;
        let mut ascending = true;
        for r in 1..self.len() {
            let (prev, key) = (self.pose_key(r - 1), self.pose_key(r));
            if key == prev {
                self.check_repeat(run_first, r, file)?;
            } else if key > prev {
                run_first = r;
            } else {
                ascending = false;
                break;
            }
        }
        if ascending {
            return Ok(());
        }
        let mut first: HashMap<(i64, i64), usize> = HashMap::with_capacity(self.len());
        for r in 0..self.len() {
            let f = *first.entry(self.pose_key(r)).or_insert(r);
            if f != r {
                self.check_repeat(f, r, file)?;
            }
        }
        Ok(())
    }

    /// Row `r` at the joint values of row `f`, the first of its pose: the chain's (`q1..qN`) and the
    /// branches' (`q_<joint>`; a branch posed elsewhere loads the chain otherwise, and the scatter of
    /// a pose's repeats is the measured repeatability, [`POSE_REPEAT_TOLERANCE`]).
    fn check_repeat(&self, f: usize, r: usize, file: &str) -> Result<()> {
        let differs = |a: &[f64], b: &[f64]| {
            (0..a.len())
                .find(|&j| (a[j] - b[j]).abs() > POSE_REPEAT_TOLERANCE)
                .map(|j| (j, a[j], b[j]))
        };
        let (column, first, here) = match differs(self.q_row(f), self.q_row(r)) {
            Some((j, a, b)) => (format!("q{}", j + 1), a, b),
            None => {
                let branch = self.branch_row(f).zip(self.branch_row(r));
                match branch.and_then(|(a, b)| differs(a, b)) {
                    Some((j, a, b)) => (format!("q_{}", self.branch_names()[j]), a, b),
                    None => return Ok(()),
                }
            }
        };
        Err(table_err(
            file,
            Some(r + 1),
            Some("pose"),
            format!(
                "pose {} is reused with other joint values: {column} is {here:?} here but {first:?} \
                 in row {} (rows sharing a pose id are repeated measurements of one pose, within {:e})",
                self.pose[r],
                f + 1,
                POSE_REPEAT_TOLERANCE
            ),
        ))
    }

    fn validate_row(&self, r: usize, file: &str) -> Result<()> {
        let bad = |column: &str, message: String| {
            Err(table_err(file, Some(r + 1), Some(column), message))
        };
        let finite = |column: &str, v: f64| {
            if v.is_finite() {
                Ok(())
            } else {
                bad(column, format!("{v} is not finite"))
            }
        };
        for (j, &v) in self.q_row(r).iter().enumerate() {
            if !v.is_finite() {
                return bad(&format!("q{}", j + 1), format!("{v} is not finite"));
            }
        }
        if let Some(b) = self.branch_row(r) {
            for (k, &v) in b.iter().enumerate() {
                if !v.is_finite() {
                    let column = format!("{BRANCH_PREFIX}{}", self.branch_names()[k]);
                    return bad(&fragment(&column), format!("{v} is not finite"));
                }
            }
        }
        for (name, &v) in ["x", "y", "z"].iter().zip(&self.position[r]) {
            finite(name, v)?;
        }
        let p = self.position[r];
        let d2 = p[0] * p[0] + p[1] * p[1] + p[2] * p[2];
        let distance = if d2.is_finite() {
            d2.sqrt()
        } else {
            // Scaled by the largest coordinate, so that 1e300 m gives its distance, not infinity.
            let largest = p.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            largest * p.iter().map(|v| (v / largest).powi(2)).sum::<f64>().sqrt()
        };
        if distance > MAX_POSITION_M {
            let axis = (0..3)
                .max_by(|&a, &b| p[a].abs().total_cmp(&p[b].abs()))
                .unwrap_or(0);
            return bad(
                ["x", "y", "z"][axis],
                format!(
                    "the position is {distance:.3e} m from the tracker, beyond {MAX_POSITION_M} m: not a \
                     laser-tracker measurement (metres are expected)"
                ),
            );
        }
        if let Some(o) = &self.orientation {
            let q = o[r];
            for (name, &v) in ["qw", "qx", "qy", "qz"].iter().zip(&q) {
                finite(name, v)?;
            }
            let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
            if (norm - 1.0).abs() > QUATERNION_NORM_ERROR {
                return bad(
                    "qw",
                    format!(
                        "quaternion [{:?}, {:?}, {:?}, {:?}] has norm {norm:.6}, not a unit quaternion \
                         (tolerance {QUATERNION_NORM_ERROR})",
                        q[0], q[1], q[2], q[3]
                    ),
                );
            }
        }
        if let Some(t) = &self.t {
            finite("t", t[r])?;
        }
        if let Some(temp) = &self.temp {
            let v = temp[r];
            finite("temp", v)?;
            let (low, high) = TEMP_RANGE_C;
            if !(low..=high).contains(&v) {
                return bad(
                    "temp",
                    format!(
                        "{v:e} °C is outside [{low}, {high}] °C: not a robot's temperature (degrees Celsius are expected)"
                    ),
                );
            }
        }
        if let Some(d) = self.dir_row(r) {
            for (j, &v) in d.iter().enumerate() {
                if !(-1..=1).contains(&v) {
                    return bad(
                        &format!("dir{}", j + 1),
                        format!("{v} is not a direction (-1, 0 or +1)"),
                    );
                }
            }
        }
        for (name, col, unit, least, limit, beyond) in [
            (
                "payload",
                &self.payload,
                "kg",
                0.0,
                MAX_PAYLOAD_KG,
                "not a robot payload (kilograms are expected)",
            ),
            (
                "sigma",
                &self.sigma,
                "m",
                MIN_SIGMA_M,
                MAX_SIGMA_M,
                "not a tracker's uncertainty (metres are expected)",
            ),
        ] {
            if let Some(v) = col {
                let v = v[r];
                finite(name, v)?;
                if v < 0.0 {
                    return bad(name, format!("{v:?} {unit} is negative"));
                }
                if v < least {
                    return bad(
                        name,
                        format!(
                            "{v:e} {unit} is below {least:e} {unit}: no tracker measures that precisely \
                             (a 1-sigma uncertainty in metres is expected)"
                        ),
                    );
                }
                if v > limit {
                    return bad(
                        name,
                        format!("{v:e} {unit} is beyond {limit} {unit}: {beyond}"),
                    );
                }
            }
        }
        Ok(())
    }
}

/// What a column of a file means to the contract.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Role {
    /// Not in the contract: ignored.
    Ignore,
    Pose,
    /// Joint column, 0-based joint index.
    Q(usize),
    /// `x`, `y`, `z` as 0, 1, 2.
    Position(usize),
    /// `qw`, `qx`, `qy`, `qz` as 0..4.
    Quaternion(usize),
    T,
    Temp,
    /// Direction column, 0-based joint index.
    Dir(usize),
    /// Branch joint column `q_<name>`, 0-based index among the branch columns in header order.
    Branch(usize),
    Payload,
    Sigma,
    Campaign,
}

/// The columns of a file resolved against the contract.
#[derive(Clone, Debug)]
struct Layout {
    n_joints: usize,
    columns: OptionalColumns,
    /// One role per file column.
    roles: Vec<Role>,
    /// Names of the branch joints (`q_<name>` columns without the prefix), in header order.
    branch: Vec<String>,
}

impl Layout {
    /// The branch columns of an empty table of this layout, with room for `rows` rows.
    fn branch_columns(&self, rows: usize) -> Option<BranchColumns> {
        (!self.branch.is_empty()).then(|| BranchColumns {
            names: self.branch.clone(),
            values: Vec::with_capacity(rows * self.branch.len()),
        })
    }

    /// An empty table of this layout (every column, branch joints included), with room for `rows`
    /// rows.
    fn empty_table(&self, rows: usize) -> MeasurementTable {
        let mut t = MeasurementTable::with_capacity(self.n_joints, self.columns, rows);
        t.branch = self.branch_columns(rows);
        t
    }
}

/// `prefix` followed by a 1-based number written without leading zeros, e.g. `q12`:
/// `Some(Ok(12))`; `q0`, `q01` or an absurd number: `Some(Err(..))`; anything else `None`.
fn numbered(name: &str, prefix: &str) -> Option<std::result::Result<usize, ()>> {
    let rest = name.strip_prefix(prefix)?;
    if rest.is_empty() || !rest.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    if rest.starts_with('0') {
        return Some(Err(()));
    }
    Some(
        rest.parse::<usize>()
            .ok()
            .filter(|&k| k <= 10_000)
            .ok_or(()),
    )
}

/// Maps file column names to [`Role`]s and checks the contract's column rules.
fn resolve_columns(names: &[String], file: &str, positions: Positions) -> Result<Layout> {
    // Names are quoted into messages: escaped and cut to one short line (a binary file's "header").
    let fail = |column: Option<&str>, message: String| {
        table_err(file, None, column.map(fragment).as_deref(), message)
    };
    let err = |column: Option<&str>, message: String| Err(fail(column, message));
    let mut seen: HashMap<&str, usize> = HashMap::new();
    for (i, name) in names.iter().enumerate() {
        if name.is_empty() {
            continue;
        }
        if let Some(first) = seen.insert(name.as_str(), i) {
            return err(
                Some(name),
                format!(
                    "the column name appears twice (columns {} and {} of the header)",
                    first + 1,
                    i + 1
                ),
            );
        }
    }
    let mut roles = Vec::with_capacity(names.len());
    let mut q_idx = Vec::new();
    let mut dir_idx = Vec::new();
    let mut branch = Vec::new();
    for name in names {
        let role = match name.as_str() {
            "pose" => Role::Pose,
            "x" => Role::Position(0),
            "y" => Role::Position(1),
            "z" => Role::Position(2),
            "qw" => Role::Quaternion(0),
            "qx" => Role::Quaternion(1),
            "qy" => Role::Quaternion(2),
            "qz" => Role::Quaternion(3),
            "t" => Role::T,
            "temp" => Role::Temp,
            "payload" => Role::Payload,
            "sigma" => Role::Sigma,
            "campaign" => Role::Campaign,
            _ => {
                if let Some(k) = numbered(name, "q") {
                    let k = k.map_err(|_| {
                        fail(
                            Some(name),
                            "joint columns are numbered q1, q2, … (from 1, without leading zeros)"
                                .into(),
                        )
                    })?;
                    q_idx.push(k);
                    Role::Q(k - 1)
                } else if let Some(k) = numbered(name, "dir") {
                    let k = k.map_err(|_| {
                        fail(
                            Some(name),
                            "direction columns are numbered dir1, dir2, … (from 1, without leading zeros)"
                                .into(),
                        )
                    })?;
                    dir_idx.push(k);
                    Role::Dir(k - 1)
                } else if let Some(joint) = name.strip_prefix(BRANCH_PREFIX) {
                    if let Some(problem) = branch_name_problem(joint) {
                        return err(Some(name), problem.into());
                    }
                    branch.push(joint.to_string());
                    Role::Branch(branch.len() - 1)
                } else {
                    Role::Ignore
                }
            }
        };
        roles.push(role);
    }
    let found = || {
        let mut list: Vec<String> = names.iter().take(20).map(|n| fragment(n)).collect();
        if names.len() > 20 {
            list.push("…".into());
        }
        list.join(", ")
    };
    let missing = |col: &str| {
        let hint = names
            .iter()
            .find(|n| n.eq_ignore_ascii_case(col))
            .map(|n| format!("; there is '{}', but names are case-sensitive", fragment(n)))
            .unwrap_or_default();
        err(
            Some(col),
            format!(
                "missing required column '{col}' (columns found: {}){hint}",
                found()
            ),
        )
    };
    if !roles.contains(&Role::Pose) {
        return missing("pose");
    }
    let n_joints = q_idx.iter().copied().max().unwrap_or(0);
    if n_joints == 0 {
        return missing("q1");
    }
    if let Some(gap) = (1..=n_joints).find(|k| !q_idx.contains(k)) {
        q_idx.sort_unstable();
        let list: Vec<String> = q_idx.iter().map(|k| format!("q{k}")).collect();
        return err(
            Some(&format!("q{gap}")),
            format!(
                "missing: joint columns must run q1..qN without a gap (found {})",
                list.join(", ")
            ),
        );
    }
    let has_position: Vec<bool> = (0..3).map(|k| roles.contains(&Role::Position(k))).collect();
    let all_optional = positions == Positions::Optional && !has_position.iter().any(|&b| b);
    for (k, col) in ["x", "y", "z"].iter().enumerate() {
        if !has_position[k] && !all_optional {
            return missing(col);
        }
    }
    let quat: Vec<bool> = (0..4)
        .map(|k| roles.contains(&Role::Quaternion(k)))
        .collect();
    let orientation = quat.iter().all(|&b| b);
    if !orientation && quat.iter().any(|&b| b) {
        let names4 = ["qw", "qx", "qy", "qz"];
        let absent: Vec<&str> = (0..4).filter(|&k| !quat[k]).map(|k| names4[k]).collect();
        return err(
            Some(absent[0]),
            format!(
                "missing: an orientation needs all of qw, qx, qy, qz (absent: {})",
                absent.join(", ")
            ),
        );
    }
    let dir = !dir_idx.is_empty();
    if dir {
        if let Some(&k) = dir_idx.iter().find(|&&k| k > n_joints) {
            return err(
                Some(&format!("dir{k}")),
                format!(
                    "there is no joint {k}: the file has {n_joints} joint columns (q1..q{n_joints})"
                ),
            );
        }
        if let Some(gap) = (1..=n_joints).find(|k| !dir_idx.contains(k)) {
            return err(
                Some(&format!("dir{gap}")),
                format!("missing: direction columns must be dir1..dir{n_joints}, one per joint"),
            );
        }
    }
    Ok(Layout {
        n_joints,
        columns: OptionalColumns {
            orientation,
            t: roles.contains(&Role::T),
            temp: roles.contains(&Role::Temp),
            dir,
            payload: roles.contains(&Role::Payload),
            sigma: roles.contains(&Role::Sigma),
            campaign: roles.contains(&Role::Campaign),
        },
        roles,
        branch,
    })
}
