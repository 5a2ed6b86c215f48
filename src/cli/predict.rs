//! `robocal predict` (being written).

use super::{CliError, CliResult};

/// Arguments of `robocal predict`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Runs `robocal predict`.
pub fn run(_args: Args) -> CliResult {
    Err(CliError::Runtime("not implemented yet".into()))
}
