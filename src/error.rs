//! The one error type of the `robocal` command line and its one exit-code rule (`shared/spec/cli.md`):
//!
//! | exit | meaning | from |
//! |---|---|---|
//! | 0 | success | |
//! | 1 | runtime failure: the input was fine, the work or the writing failed | [`SimError::Io`] (an output that cannot be written), [`CalibError::Io`], [`CalibError::Misuse`], a calibration that does not converge, … |
//! | 2 | bad input or usage: fix the command line or the files it names | every other [`SimError`] and [`CalibError`] variant (an input that cannot be read, a malformed table, scenario, URDF or model file, too few poses, …), a bad flag value; clap's own usage errors also exit 2 |
//!
//! Errors of the crates are classified by their *variants*, never by their text. It lives at the
//! crate root, not in `cli`, because the harness modules (`sweep`, `dataset`, `report`) return it too.

use calib::CalibError;
use sim::SimError;

/// A failed command: bad input (exit 2) or a runtime failure (exit 1), with its one-line message.
#[derive(Clone, Debug, PartialEq)]
pub enum CliError {
    /// The user's input is wrong: a file, a flag value, a table cell.
    Input(String),
    /// The input was fine but the work failed (including writing the output).
    Runtime(String),
}

impl CliError {
    /// Exit code per `shared/spec/cli.md`: 2 for [`CliError::Input`], 1 for [`CliError::Runtime`].
    pub fn exit_code(&self) -> u8 {
        match self {
            CliError::Input(_) => 2,
            CliError::Runtime(_) => 1,
        }
    }

    /// The same error with `prefix: ` in front of its message (the kind is kept).
    pub fn prefixed(self, prefix: &str) -> CliError {
        match self {
            CliError::Input(m) => CliError::Input(format!("{prefix}: {m}")),
            CliError::Runtime(m) => CliError::Runtime(format!("{prefix}: {m}")),
        }
    }

    /// The same error with `suffix` appended to its message (the kind is kept).
    pub fn with_hint(self, suffix: &str) -> CliError {
        match self {
            CliError::Input(m) => CliError::Input(format!("{m}{suffix}")),
            CliError::Runtime(m) => CliError::Runtime(format!("{m}{suffix}")),
        }
    }
}

impl std::fmt::Display for CliError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            CliError::Input(m) | CliError::Runtime(m) => f.write_str(m),
        }
    }
}

impl std::error::Error for CliError {}

impl From<SimError> for CliError {
    fn from(e: SimError) -> Self {
        match e {
            SimError::Io { .. } => CliError::Runtime(e.to_string()),
            _ => CliError::Input(e.to_string()),
        }
    }
}

impl From<CalibError> for CliError {
    fn from(e: CalibError) -> Self {
        match e {
            CalibError::Sim(inner) => CliError::from(*inner),
            // A stop asked for by the caller (Ctrl-C in Python) is no fault of the input.
            CalibError::Io { .. } | CalibError::Misuse(_) | CalibError::Cancelled => {
                CliError::Runtime(e.to_string())
            }
            _ => CliError::Input(e.to_string()),
        }
    }
}

/// Result of a subcommand.
pub type CliResult = Result<(), CliError>;

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    #[test]
    fn variants_decide_the_exit_code() {
        let io = || std::io::Error::new(std::io::ErrorKind::PermissionDenied, "denied");
        let write = SimError::Io {
            path: PathBuf::from("out/m.parquet"),
            source: io(),
        };
        let read = SimError::Read {
            path: PathBuf::from("in/m.csv"),
            source: io(),
        };
        let table = SimError::Table {
            file: "m.csv".into(),
            row: Some(3),
            line: Some(4),
            column: Some("q2".into()),
            message: "'x' is not a number".into(),
        };
        assert_eq!(CliError::from(write).exit_code(), 1);
        assert_eq!(CliError::from(read).exit_code(), 2);
        assert_eq!(CliError::from(table).exit_code(), 2);
        let wrapped = CalibError::from(SimError::Io {
            path: PathBuf::from("model.json"),
            source: io(),
        });
        assert_eq!(CliError::from(wrapped).exit_code(), 1);
        let calib_io = CalibError::Io {
            path: "x".into(),
            message: "disk full".into(),
        };
        assert_eq!(CliError::from(calib_io).exit_code(), 1);
        let calib_read = CalibError::Read {
            path: "model.json".into(),
            message: "no such file".into(),
        };
        let e = CliError::from(calib_read);
        assert_eq!(e.exit_code(), 2);
        assert_eq!(e.to_string(), "model.json: cannot read: no such file");
        let bad = CalibError::BadValue {
            context: "m.csv row 2".into(),
            field: "temp".into(),
            value: "NaN".into(),
            problem: "not finite".into(),
        };
        assert_eq!(CliError::from(bad).exit_code(), 2);
        assert_eq!(CliError::from(CalibError::Cancelled).exit_code(), 1);
    }

    #[test]
    fn prefixes_and_hints_keep_the_kind() {
        let e = CliError::Input("bad".into())
            .prefixed("run 3")
            .with_hint(" (try this)");
        assert_eq!(e, CliError::Input("run 3: bad (try this)".into()));
        let e = CliError::Runtime("failed".into()).prefixed("run 3");
        assert_eq!(e.exit_code(), 1);
    }
}
