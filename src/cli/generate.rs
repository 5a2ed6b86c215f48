//! `robocal generate`: a measurement campaign with known injected errors, from a scenario file.
//!
//! Writes `DIR/measurements.parquet` (the measurement contract), `DIR/truth.json` and
//! `DIR/truth.parquet` (the ground truth); see `sim::generate` and `docs/generate.md`.

use super::paths::Inputs;
use super::shared::{CliError, CliResult, print_json};
use sim::scenario::{Overrides, Scenario};
use std::io::IsTerminal;
use std::path::PathBuf;

/// Arguments of `robocal generate`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scenario file (TOML): robot, injected effects, tracker and campaign (see scenarios/).
    #[arg(long, value_name = "FILE.toml")]
    scenario: PathBuf,
    /// Output folder (created if missing); an earlier set of the three files is replaced as a whole,
    /// other files in it are kept. It must not hold the scenario or its inputs.
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Seed of every random draw (replaces the scenario's `seed`).
    #[arg(long, value_name = "N")]
    seed: Option<u64>,
    /// Number of poses (replaces `[campaign] poses`).
    #[arg(long, value_name = "N")]
    poses: Option<usize>,
    /// Multiplier on the tracker noise and outlier size (replaces `[tracker] noise_scale`); 0 gives
    /// noise-free measurements.
    #[arg(long, value_name = "M", allow_negative_numbers = true)]
    noise: Option<f64>,
    /// Print the summary as one JSON document on stdout.
    #[arg(long)]
    json: bool,
}

/// Runs `robocal generate`.
pub fn run(args: Args) -> CliResult {
    if args.poses == Some(0) {
        return Err(CliError::Input("--poses: 0: must be ≥ 1".into()));
    }
    if let Some(p) = args.poses
        && p as u64 > sim::campaign::MAX_FORMAT_ROWS
    {
        return Err(CliError::Input(format!(
            "--poses {p}: more than the {} rows a Parquet file can count (signed 64-bit)",
            sim::campaign::MAX_FORMAT_ROWS
        )));
    }
    if let Some(m) = args.noise
        && !(m.is_finite() && m >= 0.0)
    {
        return Err(CliError::Input(format!(
            "--noise: {m}: must be a finite multiplier ≥ 0"
        )));
    }
    let scenario = Scenario::load(&args.scenario)?;
    Inputs::new()
        .add_scenario("--scenario", &args.scenario, &scenario)
        .check_dir("--out", &args.out, &sim::generate::OUTPUT_FILES)?;
    let overrides = Overrides {
        seed: args.seed,
        poses: args.poses,
        noise: args.noise,
    };
    let resolved = scenario.resolve(&overrides)?;
    let planner = sim::generate::planner_of(&resolved)?;
    let bar = progress_bar(planner.rows() as u64, "simulating");
    let tick = |k: u64| {
        if let Some(b) = &bar {
            b.inc(k);
        }
    };
    let summary = sim::generate::write_dataset(&resolved, &args.out, planner, Some(&tick));
    if let Some(b) = &bar {
        b.finish_and_clear();
    }
    let summary = summary?;
    eprintln!("{}", summary.paragraph());
    if args.json {
        let mut v = serde_json::to_value(&summary)
            .map_err(|e| CliError::Runtime(format!("cannot write JSON: {e}")))?;
        v["files"] = serde_json::json!(summary.files);
        return print_json(&v);
    }
    Ok(())
}

/// A progress bar of `len` measurements on stderr, only when stderr is a terminal and not in CI (the
/// `CI` variable set): never in logs or pipes.
pub(super) fn progress_bar(len: u64, what: &str) -> Option<indicatif::ProgressBar> {
    let show = std::io::stderr().is_terminal() && std::env::var_os("CI").is_none();
    show.then(|| {
        let b = indicatif::ProgressBar::new(len);
        if let Ok(style) = indicatif::ProgressStyle::with_template(&format!(
            "{{spinner}} {what} {{human_pos}}/{{human_len}} measurements [{{bar:24}}] {{percent}} %, {{eta}} left"
        )) {
            b.set_style(style.progress_chars("=> "));
        }
        b
    })
}
