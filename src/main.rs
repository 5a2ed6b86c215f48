//! `robocal`: robot calibration testbed command line (see `shared/spec/cli.md` and the README).

mod cli;
mod dataset;
mod error;
mod report;
mod sweep;

use clap::Parser;
use clap::error::{ContextKind, ContextValue, ErrorKind};
use std::process::ExitCode;

/// Exit code of a usage error (clap's own, and ours for a flag value that is not one of its values).
const USAGE: u8 = 2;

fn main() -> ExitCode {
    sim::decoder_guard::install_quiet_hook();
    let args = match cli::Cli::try_parse() {
        Ok(a) => a,
        Err(e) if e.kind() == ErrorKind::InvalidValue => {
            eprintln!("error: {}", sim::error::one_line(&invalid_value_line(&e)));
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

/// A flag value that is not one of the flag's values, on one line naming the flag and the values:
/// `--robust tukey: not one of huber, cauchy`.
fn invalid_value_line(e: &clap::Error) -> String {
    let text = |k| match e.get(k) {
        Some(ContextValue::String(s)) => s.clone(),
        Some(ContextValue::Strings(v)) => v.join(", "),
        _ => String::new(),
    };
    let flag = text(ContextKind::InvalidArg);
    // `--robust <LOSS>`: the flag without its value name.
    let flag = flag.split_whitespace().next().unwrap_or_default();
    let value = match text(ContextKind::InvalidValue) {
        v if v.is_empty() => "''".to_string(),
        v => v,
    };
    let valid = text(ContextKind::ValidValue);
    if valid.is_empty() {
        format!("{flag} {value}: invalid value")
    } else {
        format!("{flag} {value}: not one of {valid}")
    }
}
