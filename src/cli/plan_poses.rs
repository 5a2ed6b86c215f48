//! `robocal plan-poses` (being written).

use super::{CliError, CliResult};

/// Arguments of `robocal plan-poses`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Runs `robocal plan-poses`.
pub fn run(_args: Args) -> CliResult {
    Err(CliError::Runtime("not implemented yet".into()))
}
