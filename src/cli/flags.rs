//! Flag values from outside a command line: the Python package passes its keyword arguments
//! (`test_fraction=0.2`, `robust="huber"`) as the flags they name (`--test-fraction 0.2 --robust
//! huber`), and [`parse`] reads them with the subcommand's own clap definitions (its `Options`
//! struct, flattened into the subcommand's arguments). Defaults, value parsers, allowed values and the
//! checks that turn flag values into calib's options are therefore written once, for both: a flag
//! added to a subcommand's `Options` is a keyword argument of the Python function at once.

use super::shared::CliError;
use clap::error::{ContextKind, ContextValue, ErrorKind};
use clap::{Args, Command, FromArgMatches};

/// A flag value that is not one of the flag's values, on one line naming the flag and the values:
/// `--robust tukey: not one of huber, cauchy`.
pub fn invalid_value_line(e: &clap::Error) -> String {
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

/// The command that parses the flags of `T` alone (no binary name, no subcommand).
fn command<T: Args>(name: &'static str) -> Command {
    T::augment_args(Command::new(name).no_binary_name(true))
}

/// The long flags of `T` without their dashes and with `_` for `-` (`test_fraction`): the keyword
/// arguments the Python package accepts for that subcommand, in declaration order.
pub fn keywords<T: Args>(name: &'static str) -> Vec<String> {
    command::<T>(name)
        .get_arguments()
        .filter_map(|a| a.get_long())
        .filter(|l| *l != "help")
        .map(|l| l.replace('-', "_"))
        .collect()
}

/// Parses `args` (`["--test-fraction", "0.2", "--robust", "huber"]`) as the flags of subcommand
/// `name`'s options `T`. Every error is bad input ([`CliError::Input`], exit 2) on one line: a value
/// that is not one of the flag's values as the command line says it (`--robust tukey: not one of
/// huber, cauchy`), an unknown flag naming the known ones, a value that does not parse as the first
/// line of the command line's message (`invalid value 'abc' for '--seed <N>': invalid digit found in
/// string`).
pub fn parse<T: Args + FromArgMatches>(name: &'static str, args: &[String]) -> Result<T, CliError> {
    let matches = command::<T>(name)
        .try_get_matches_from(args)
        .map_err(|e| CliError::Input(error_line(name, &e, &keywords::<T>(name))))?;
    T::from_arg_matches(&matches)
        .map_err(|e| CliError::Input(error_line(name, &e, &keywords::<T>(name))))
}

/// One line for a clap error of [`parse`].
fn error_line(name: &str, e: &clap::Error, known: &[String]) -> String {
    let text = |k| match e.get(k) {
        Some(ContextValue::String(s)) => s.clone(),
        Some(ContextValue::Strings(v)) => v.join(", "),
        _ => String::new(),
    };
    match e.kind() {
        ErrorKind::InvalidValue => invalid_value_line(e),
        ErrorKind::UnknownArgument => format!(
            "{name}: unknown option {} (options: {})",
            text(ContextKind::InvalidArg)
                .trim_start_matches('-')
                .replace('-', "_"),
            known.join(", ")
        ),
        // Anything else (a value that does not parse, a flag given twice): clap's own first line, as
        // the command line prints it.
        _ => {
            let rendered = e.to_string();
            let first = rendered.lines().next().unwrap_or_default();
            first.trim_start_matches("error: ").to_string()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(clap::Args, Debug)]
    struct Example {
        /// A fraction.
        #[arg(long, value_name = "F", default_value_t = 0.3)]
        test_fraction: f64,
        /// A loss.
        #[arg(long, value_parser = ["huber", "cauchy"])]
        robust: Option<String>,
        /// A switch.
        #[arg(long)]
        verbose: bool,
    }

    fn args(a: &[&str]) -> Vec<String> {
        a.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn flags_parse_with_their_defaults() {
        let e: Example = parse("example", &[]).unwrap();
        assert_eq!((e.test_fraction, e.robust, e.verbose), (0.3, None, false));
        let e: Example = parse(
            "example",
            &args(&["--test-fraction", "0.25", "--robust", "huber", "--verbose"]),
        )
        .unwrap();
        assert_eq!(
            (e.test_fraction, e.robust.as_deref(), e.verbose),
            (0.25, Some("huber"), true)
        );
        assert_eq!(
            keywords::<Example>("example"),
            ["test_fraction", "robust", "verbose"]
        );
    }

    #[test]
    fn errors_are_one_line_input_errors() {
        let e = parse::<Example>("example", &args(&["--robust", "tukey"])).unwrap_err();
        assert_eq!(
            e,
            CliError::Input("--robust tukey: not one of huber, cauchy".into())
        );
        let e = parse::<Example>("example", &args(&["--folds", "5"])).unwrap_err();
        assert_eq!(
            e,
            CliError::Input(
                "example: unknown option folds (options: test_fraction, robust, verbose)".into()
            )
        );
        let e = parse::<Example>("example", &args(&["--test-fraction", "abc"])).unwrap_err();
        assert_eq!(e.exit_code(), 2);
        assert!(
            e.to_string()
                .starts_with("invalid value 'abc' for '--test-fraction <F>': "),
            "{e}"
        );
        assert_eq!(e.to_string().lines().count(), 1);
    }
}
