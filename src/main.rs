//! `robocal`: robot calibration testbed command line (see `shared/spec/cli.md` and the README). The
//! subcommands live in the library (`src/lib.rs`), which the Python package shares.

use clap::Parser;
use clap::error::ErrorKind;
use robocal::cli;
use std::process::ExitCode;

/// Exit code of a usage error (clap's own, and ours for a flag value that is not one of its values).
const USAGE: u8 = 2;

fn main() -> ExitCode {
    sim::decoder_guard::install_quiet_hook();
    let args = match cli::Cli::try_parse() {
        Ok(a) => a,
        Err(e) if e.kind() == ErrorKind::InvalidValue => {
            eprintln!(
                "error: {}",
                sim::error::one_line(&cli::flags::invalid_value_line(&e))
            );
            return ExitCode::from(USAGE);
        }
        // Help, version and every other usage error: as clap prints them (usage errors exit 2).
        Err(e) => e.exit(),
    };
    match cli::run(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // Whatever a message quotes (a file name, a library's text), it stays on one line.
            eprintln!("error: {}", sim::error::one_line(&e.to_string()));
            ExitCode::from(e.exit_code())
        }
    }
}
