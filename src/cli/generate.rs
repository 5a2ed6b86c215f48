//! `robocal generate` (being written).

use super::{CliError, CliResult};

/// Arguments of `robocal generate`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Runs `robocal generate`.
pub fn run(_args: Args) -> CliResult {
    Err(CliError::Runtime("not implemented yet".into()))
}
