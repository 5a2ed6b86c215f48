//! The `robocal` command line as a library: the subcommands ([`cli`]) and the one error type with its
//! exit-code rule ([`error`]). The binary (`src/main.rs`) parses the command line and calls
//! [`cli::run`]; the Python package (`python/`) calls the same glue that lies between reading the
//! inputs and writing the outputs (reading a table against a robot, flag values to calib's options,
//! the JSON documents of `calibrate`, `diagnose` and `generate`), so that both give the same numbers
//! and the same messages. See `src/cli/flags.rs` for how keyword arguments become flag values.
//! [`vocabulary`] is the one draw of hidden effects, shared by `robocal demo` and the blind tests.

pub mod cli;
mod dataset;
pub mod document;
pub mod error;
mod report;
mod sweep;
pub mod vocabulary;
