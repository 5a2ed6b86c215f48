//! `robocal generate`: a measurement campaign with known injected errors, from a scenario file.
//!
//! Writes `DIR/measurements.parquet` (the measurement contract), `DIR/truth.json` and
//! `DIR/truth.parquet` (the ground truth); see `sim::generate` and `docs/generate.md`.

use super::paths::Inputs;
use super::shared::{CliError, CliResult, print_json};
use sim::generate::Summary;
use sim::scenario::{Overrides, Scenario};
use std::io::IsTerminal;
use std::path::{Path, PathBuf};

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
    #[command(flatten)]
    options: Options,
    /// Print the summary as one JSON document on stdout.
    #[arg(long)]
    json: bool,
}

/// The flags of `robocal generate` that are values rather than files: one definition for the command
/// line (flattened into its arguments) and the Python package (`robocal.generate(scenario,
/// **options)`, keyword arguments parsed by [`super::flags::parse`]).
#[derive(clap::Args, Debug, Clone)]
pub struct Options {
    /// Seed of every random draw (replaces the scenario's `seed`).
    #[arg(long, value_name = "N")]
    pub seed: Option<u64>,
    /// Number of poses (replaces `[campaign] poses`).
    #[arg(long, value_name = "N")]
    pub poses: Option<usize>,
    /// Multiplier on the tracker noise and outlier size (replaces `[tracker] noise_scale`); 0 gives
    /// noise-free measurements.
    #[arg(long, value_name = "M", allow_negative_numbers = true)]
    pub noise: Option<f64>,
}

impl Options {
    /// The scenario overrides; bad values are input errors naming the flag.
    fn overrides(&self) -> Result<Overrides, CliError> {
        if self.poses == Some(0) {
            return Err(CliError::Input("--poses: 0: must be ≥ 1".into()));
        }
        if let Some(p) = self.poses
            && p as u64 > sim::campaign::MAX_FORMAT_ROWS
        {
            return Err(CliError::Input(format!(
                "--poses {p}: more than the {} rows a Parquet file can count (signed 64-bit)",
                sim::campaign::MAX_FORMAT_ROWS
            )));
        }
        if let Some(m) = self.noise
            && !(m.is_finite() && m >= 0.0)
        {
            return Err(CliError::Input(format!(
                "--noise: {m}: must be a finite multiplier ≥ 0"
            )));
        }
        Ok(Overrides {
            seed: self.seed,
            poses: self.poses,
            noise: self.noise,
        })
    }
}

/// Generates the dataset of the scenario file `scenario` into the folder `out` as `robocal generate`
/// does with `options` (the folder must not hold the scenario's inputs); `progress` is called with the
/// total number of rows once, then with rows finished, from worker threads.
pub fn generate(
    scenario: &Path,
    out: &Path,
    options: &Options,
    progress: &(dyn Fn(Rows) + Sync),
) -> Result<Summary, CliError> {
    let overrides = options.overrides()?;
    let loaded = Scenario::load(scenario)?;
    Inputs::new()
        .add_scenario("--scenario", scenario, &loaded)
        .check_dir("--out", out, &sim::generate::OUTPUT_FILES)?;
    let resolved = loaded.resolve(&overrides)?;
    let planner = sim::generate::planner_of(&resolved)?;
    progress(Rows::Total(planner.rows() as u64));
    let tick = |k: u64| progress(Rows::Done(k));
    Ok(sim::generate::write_dataset(
        &resolved,
        out,
        planner,
        Some(&tick),
    )?)
}

/// What [`generate`] reports to its progress callback.
#[derive(Clone, Copy, Debug)]
pub enum Rows {
    /// The number of rows the campaign has.
    Total(u64),
    /// Rows just finished.
    Done(u64),
}

/// Runs `robocal generate`.
pub fn run(args: Args) -> CliResult {
    // Made once the campaign's size is known, on a terminal outside CI only.
    let bar = std::sync::OnceLock::new();
    let progress = |r: Rows| match r {
        Rows::Total(n) => {
            if let Some(b) = progress_bar(n, "simulating") {
                bar.get_or_init(|| b);
            }
        }
        Rows::Done(k) => {
            if let Some(b) = bar.get() {
                b.inc(k);
            }
        }
    };
    let summary = generate(&args.scenario, &args.out, &args.options, &progress);
    if let Some(b) = bar.get() {
        b.finish_and_clear();
    }
    let summary = summary?;
    eprintln!("{}", summary.paragraph());
    if args.json {
        return print_json(&summary_json(&summary)?);
    }
    Ok(())
}

/// The `generate --json` document.
pub fn summary_json(summary: &Summary) -> Result<serde_json::Value, CliError> {
    let mut v = serde_json::to_value(summary)
        .map_err(|e| CliError::Runtime(format!("cannot write JSON: {e}")))?;
    v["files"] = serde_json::json!(summary.files);
    Ok(v)
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
