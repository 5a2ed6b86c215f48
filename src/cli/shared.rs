//! What several subcommands share: reading a measurement table against the robot.

use super::CliError;
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
