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
    if let Some(p) = args.poses {
        sim::campaign::check_row_count(Some(p), &format!("--poses {p}"))
            .map_err(CliError::Input)?;
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
    let plan = sim::generate::plan_of(&resolved)?;
    let bar = std::io::stderr().is_terminal().then(|| {
        let b = indicatif::ProgressBar::new(plan.len() as u64);
        if let Ok(style) = indicatif::ProgressStyle::with_template(
            "{spinner} simulating {pos}/{len} measurements [{bar:40}] {eta}",
        ) {
            b.set_style(style.progress_chars("=> "));
        }
        b
    });
    let tick = |k: u64| {
        if let Some(b) = &bar {
            b.inc(k);
        }
    };
    let summary = sim::generate::write_dataset(&resolved, &args.out, &plan, Some(&tick));
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
