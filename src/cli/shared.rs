//! What several subcommands share: the error type (from [`crate::error`]), one JSON document on
//! stdout, reading a measurement table against the robot. Subcommand modules import from here and from
//! each other, never from their parent `cli`, so that no two source files import each other.

pub(crate) use crate::error::{CliError, CliResult};
use sim::measurement_table::{self, MeasurementTable};
use std::path::Path;

/// Reads a measurement table and checks it against the robot ([`check_table`]); warnings go to stderr.
/// A robot with coupled joints gets the table of its whole chain ([`measurement_table::couple`]).
pub(crate) fn read_table(path: &Path, robot: &sim::Model) -> Result<MeasurementTable, CliError> {
    let table = measurement_table::couple(measurement_table::read(path)?, robot, path)?;
    for w in check_table(&table, robot, &path.display().to_string())? {
        eprintln!("warning: {w}");
    }
    Ok(table)
}

/// Checks a measurement table against the robot (joint count, limits, units); `name` names it in
/// messages (a file name, or a description of a table in memory). Returns the warnings, one line each.
pub fn check_table(
    table: &MeasurementTable,
    robot: &sim::Model,
    name: &str,
) -> Result<Vec<String>, CliError> {
    Ok(measurement_table::check_against_model(
        table,
        robot,
        Path::new(name),
    )?)
}

/// Prints one JSON document to stdout.
pub fn print_json(value: &serde_json::Value) -> CliResult {
    let s = serde_json::to_string_pretty(value)
        .map_err(|e| CliError::Runtime(format!("cannot write JSON: {e}")))?;
    println!("{s}");
    Ok(())
}
