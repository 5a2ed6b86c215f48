//! `robocal calibrate` (being written).

use super::{CliError, CliResult};

/// Arguments of `robocal calibrate`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Runs `robocal calibrate`.
pub fn run(_args: Args) -> CliResult {
    Err(CliError::Runtime("not implemented yet".into()))
}
