//! What several subcommands share: the error type (from [`crate::error`]), one JSON document on
//! stdout, reading a measurement table against the robot. Subcommand modules import from here and from
//! each other, never from their parent `cli`, so that no two source files import each other.

pub(crate) use crate::error::{CliError, CliResult};
use sim::measurement_table::{self, MeasurementTable};
use std::path::Path;

/// Reads a measurement table and checks it against the robot; warnings go to stderr.
pub(crate) fn read_table(path: &Path, robot: &sim::Model) -> Result<MeasurementTable, CliError> {
    let table = measurement_table::read(path)?;
    for w in measurement_table::check_against_model(&table, robot, path)? {
        eprintln!("warning: {w}");
    }
    Ok(table)
}

/// Prints one JSON document to stdout.
pub fn print_json(value: &serde_json::Value) -> CliResult {
    let s = serde_json::to_string_pretty(value)
        .map_err(|e| CliError::Runtime(format!("cannot write JSON: {e}")))?;
    println!("{s}");
    Ok(())
}
