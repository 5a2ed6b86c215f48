//! The one error type of the `sim` crate.

use crate::effect_id::EffectId;
use std::path::PathBuf;

/// Everything that can go wrong when loading a robot or evaluating it with bad input.
///
/// Each variant carries what a user needs to fix the input: the file, the element and the value.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SimError {
    /// An input file could not be opened or read (missing, unreadable, a folder): bad input, the user
    /// named a file that is not there.
    #[error("{path}: cannot read: {source}")]
    Read {
        /// File that was asked for.
        path: PathBuf,
        /// Underlying I/O error.
        source: std::io::Error,
    },
    /// An output file could not be written (or its bytes could not be produced): a runtime failure, the
    /// input was fine. Every write of [`crate::io`] fails with this.
    #[error("{path}: cannot write: {source}")]
    Io {
        /// File (or folder) that was being written.
        path: PathBuf,
        /// Underlying I/O error.
        source: std::io::Error,
    },
    /// The file is a xacro macro file, not a URDF.
    #[error(
        "{source_name}: this is a xacro file, not a URDF; expand it first (`xacro {source_name} > robot.urdf`)"
    )]
    Xacro {
        /// File or source name.
        source_name: String,
    },
    /// The XML could not be parsed as a URDF.
    #[error("{source_name}: not a valid URDF: {message}")]
    Parse {
        /// File or source name.
        source_name: String,
        /// What the parser said.
        message: String,
    },
    /// The URDF parsed, but its structure cannot give a serial chain.
    #[error("{source_name}: {message}")]
    Structure {
        /// File or source name.
        source_name: String,
        /// What is wrong, naming links and joints.
        message: String,
    },
    /// A numeric value in the URDF is NaN, infinite or out of its domain.
    #[error("{source_name}: {element} '{name}': {field} = {value} is {problem}")]
    BadValue {
        /// File or source name.
        source_name: String,
        /// `joint` or `link`.
        element: &'static str,
        /// Name of the joint or link.
        name: String,
        /// Attribute, e.g. `origin xyz`, `mass`, `inertia ixx`.
        field: &'static str,
        /// The offending value.
        value: f64,
        /// What is wrong with it, e.g. `not finite`.
        problem: &'static str,
    },
    /// Gravity torques or compliance were asked for but some moving bodies have no inertial data.
    #[error(
        "robot '{robot}': statics need masses, but these moving links have no <inertial> (or zero mass): {links}"
    )]
    MissingInertial {
        /// Robot name.
        robot: String,
        /// Comma-separated link names.
        links: String,
    },
    /// A joint vector has the wrong length.
    #[error("expected {expected} joint values, got {got}")]
    JointCount {
        /// Joints in the chain.
        expected: usize,
        /// Values given.
        got: usize,
    },
    /// A joint value is NaN or infinite.
    #[error("joint {joint} (1-based) value {value} is not finite")]
    NonFiniteJoint {
        /// 1-based joint number.
        joint: usize,
        /// The value.
        value: f64,
    },
    /// A name given for a built-in robot is unknown.
    #[error("unknown robot '{name}': not a file, and not one of the built-in robots ({known})")]
    UnknownRobot {
        /// What was asked for.
        name: String,
        /// Built-in names.
        known: String,
    },
    /// A measurement table (CSV or Parquet, `shared/spec/measurements.md`) is malformed or does not fit
    /// the robot. Displayed on one line as `data.csv: row 17 (line 18), column q3: 'abc' is not a number`.
    #[error("{file}{}: {message}", table_location(.row, .line, .column))]
    Table {
        /// File name as given (or a description such as `<measurement table>` for in-memory tables).
        file: String,
        /// 1-based data row (row 1 is the first row after the header), when the problem is in one row.
        row: Option<usize>,
        /// 1-based line of the text file holding that row (CSV only; counts the header and blank lines).
        line: Option<usize>,
        /// Column name, when the problem is in one column.
        column: Option<String>,
        /// What is wrong, with the offending value.
        message: String,
    },
    /// An injected-effect parameter is out of its domain, or its length does not fit the robot.
    /// Displayed as `joint_compliance: stiffness[3] = -5: must be > 0 N m/rad (inf = rigid)`.
    #[error("{effect}: {field} = {value}: {problem}")]
    BadEffect {
        /// The effect (displayed by its name: `kinematic_offsets`, `joint_compliance`, …).
        effect: EffectId,
        /// Field, with a 0-based index where it is a list entry (e.g. `stiffness[3]`).
        field: String,
        /// The offending value (or length), as text.
        value: String,
        /// What is wrong with it.
        problem: String,
    },
    /// The conditions of one simulated measurement (joint values, directions, temperature, payload,
    /// gravity, target offset) are unusable.
    #[error("measurement conditions: {field} = {value}: {problem}")]
    BadCondition {
        /// Field, e.g. `dir[2]` (0-based) or `payload.mass`.
        field: String,
        /// The offending value, as text.
        value: String,
        /// What is wrong with it.
        problem: String,
    },
    /// A scenario file (TOML) is malformed, or asks for something that cannot be simulated. Displayed on
    /// one line as `iiwa7.toml: effects.compliance.stiffness_nm_per_rad[2]: -5e4 must be > 0 N m/rad`.
    #[error("{file}: {key}: {message}")]
    Scenario {
        /// Scenario file name as given.
        file: String,
        /// Dotted key path (with a 0-based index for list entries), or `line L, [section] key` for
        /// TOML syntax and type errors.
        key: String,
        /// What is wrong, with the offending value.
        message: String,
    },
    /// The joint-compliance equilibrium `K (q - θ) = τ_g(θ)` has no solution near the commanded pose
    /// (joints too soft for the load) or the iteration failed to converge.
    #[error("joint compliance: no equilibrium found: {reason}")]
    ComplianceDiverged {
        /// What happened, with the iteration count and the size of the last step.
        reason: String,
    },
    /// A setting of the rapier physics-engine truth ([`crate::rapier_truth`]) is out of its domain.
    #[error("rapier truth: {field} = {value}: {problem}")]
    BadSettleOption {
        /// Setting, e.g. `dt` or `stiffness_nm_per_rad[2]`.
        field: String,
        /// The offending value, as text.
        value: String,
        /// What is wrong with it.
        problem: String,
    },
    /// The rapier physics-engine truth did not come to rest within its step budget (or ran away).
    #[error("rapier truth: not settled: {reason}")]
    NotSettled {
        /// What happened, with the step count, the last joint speed and the torque residual.
        reason: String,
    },
}

impl SimError {
    /// A [`SimError::BadEffect`]: `field` of `effect` (with a 0-based index where it is a list entry,
    /// e.g. `stiffness[3]`) has `value` (or length, as text), which is wrong as `problem` says.
    pub fn bad_effect(
        effect: EffectId,
        field: impl Into<String>,
        value: impl ToString,
        problem: impl Into<String>,
    ) -> SimError {
        SimError::BadEffect {
            effect,
            field: field.into(),
            value: value.to_string(),
            problem: problem.into(),
        }
    }
}

/// Result alias for the `sim` crate.
pub type Result<T> = std::result::Result<T, SimError>;

/// `: row R (line L), column C` part of a [`SimError::Table`] message (empty parts left out).
fn table_location(row: &Option<usize>, line: &Option<usize>, column: &Option<String>) -> String {
    let mut s = String::new();
    if let Some(r) = row {
        s.push_str(&format!(": row {r}"));
        if let Some(l) = line {
            s.push_str(&format!(" (line {l})"));
        }
    }
    if let Some(c) = column {
        s.push_str(if row.is_some() {
            ", column "
        } else {
            ": column "
        });
        s.push_str(c);
    }
    s
}

/// A [`SimError::Scenario`] about `key` of scenario `file`.
pub(crate) fn scenario_err(file: &str, key: &str, message: String) -> SimError {
    SimError::Scenario {
        file: file.to_string(),
        key: key.to_string(),
        message,
    }
}

/// Longest fragment of a file (a header name, a cell) that [`fragment`] quotes into a message, in
/// characters.
pub const FRAGMENT_CHARS: usize = 80;

/// Text taken from a file, made fit for a one-line error message: control characters (line breaks,
/// tabs, NUL, …) escaped as `\n`, `\t`, `\u{0}`, and cut with `…` where the result would exceed
/// `max_chars` characters.
///
/// ```
/// assert_eq!(sim::error::fragment_n("a\nb\u{0}", 80), "a\\nb\\u{0}");
/// assert_eq!(sim::error::fragment_n("abcdef", 3), "abc…");
/// ```
pub fn fragment_n(text: &str, max_chars: usize) -> String {
    let mut out = String::new();
    let mut shown = 0usize;
    for c in text.chars() {
        let escaped: String = if c.is_control() {
            c.escape_default().collect()
        } else {
            c.to_string()
        };
        let n = escaped.chars().count();
        if shown.saturating_add(n) > max_chars {
            out.push('…');
            break;
        }
        shown += n;
        out.push_str(&escaped);
    }
    out
}

/// [`fragment_n`] with [`FRAGMENT_CHARS`].
pub fn fragment(text: &str) -> String {
    fragment_n(text, FRAGMENT_CHARS)
}

/// A whole message on one line: control characters escaped as in [`fragment_n`], nothing cut.
pub fn one_line(text: &str) -> String {
    fragment_n(text, usize::MAX)
}
