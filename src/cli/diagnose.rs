//! `robocal diagnose`: what the kinematic model misses, its cause, and the gain on held-out poses.

use super::calibrate_stream::{CheckedFile, StreamMode, check_chunk_rows, decide_stream};
use super::paths::Inputs;
use super::robot_arg::RobotArgs;
use super::shared::{CliError, CliResult, print_json, read_table};
use crate::report;
use calib::model::robot::Robot;
use calib::select::diagnose::stream::diagnose_streamed;
use calib::select::diagnose::{DiagnoseOptions, Diagnosis, diagnose_with_progress};
use std::io::IsTerminal;
use std::path::PathBuf;

/// Arguments of `robocal diagnose`.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(flatten)]
    robot: RobotArgs,
    /// Measurement table (.csv or .parquet, see the measurement contract).
    #[arg(long, value_name = "FILE")]
    data: PathBuf,
    /// Print one JSON document on stdout (the diagnose contract) instead of text on stderr.
    #[arg(long)]
    json: bool,
    /// Write plots (SVG) and a one-page summary (index.html, summary.md) into this folder.
    #[arg(long, value_name = "DIR")]
    report: Option<PathBuf>,
    /// Read the table in pieces (docs/diagnose.md, "Large files"): diagnose a seeded sample of
    /// whole poses (--sample-rows) and predict every other row with the models fitted on it.
    /// `auto` does so for tables of more than 262,144 rows; `always` for any table; `never` holds
    /// the table in memory.
    #[arg(long, value_enum, value_name = "WHEN", default_value_t = StreamMode::Auto)]
    stream: StreamMode,
    /// Rows of the sample a streamed diagnosis diagnoses (whole poses, about this many rows).
    #[arg(long, value_name = "N", default_value_t = calib::select::diagnose::stream::DEFAULT_SAMPLE_ROWS)]
    sample_rows: usize,
    /// Rows read at a time when streaming.
    #[arg(long, value_name = "N", default_value_t = sim::measurement_table::DEFAULT_CHUNK_ROWS)]
    chunk_rows: usize,
    #[command(flatten)]
    options: Options,
}

/// The flags of `robocal diagnose` that are values rather than files: one definition for the command
/// line (flattened into its arguments) and the Python package (`robocal.diagnose(data, **options)`,
/// keyword arguments parsed by [`super::flags::parse`]). A flag added here is a keyword argument there.
#[derive(clap::Args, Debug, Clone)]
pub struct Options {
    /// Fraction of the poses held out to judge every decision (repeats of a pose stay together).
    /// A decimal or a ratio such as `1/3`.
    #[arg(long, value_name = "F", default_value = "1/3", value_parser = parse_fraction)]
    pub test_fraction: f64,
    /// Seed of the train/test split and of the learned models' folds.
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub seed: u64,
    /// False-alarm level of each round's training test (family-wise over its candidates); the
    /// held-out test that must also pass is at 0.05.
    #[arg(long, value_name = "P", default_value_t = 1e-3)]
    pub alpha: f64,
    /// The noise floor (m, RMS of the position error norm) when known better than the data tell, e.g.
    /// a robot's repeatability; by default estimated from repeated poses, `sigma` or the tracker model.
    #[arg(long, value_name = "M")]
    pub noise_floor: Option<f64>,
    /// With more poses than this, the candidate causes are tried on a seeded subsample of this many
    /// (training and test in the split's proportion) and the models adopted there are refitted on
    /// every pose, which every reported figure comes from; 0 uses every pose throughout (slow on
    /// large tables: each candidate of each round is fitted on every pose).
    #[arg(long, value_name = "N", default_value_t = calib::select::diagnose::screening::DEFAULT_SCREEN_POSES)]
    pub screen_poses: usize,
    /// Regions of the configuration space every adopted cause must transfer to: the training poses
    /// clustered into K regions (seeded k-means on sin q, cos q), the model fitted without each in
    /// turn must predict it better with the cause than without (0 = no transfer test).
    #[arg(long, value_name = "K", default_value_t = calib::validate::regions::DEFAULT_REGIONS)]
    pub regions: usize,
}

impl Options {
    /// calib's diagnose options; bad values are input errors naming the flag.
    pub fn resolve(&self) -> Result<DiagnoseOptions, CliError> {
        let mut o = options(self.test_fraction, self.seed, self.alpha)?;
        if self.screen_poses != 0 && self.screen_poses < MIN_SCREEN_POSES {
            return Err(CliError::Input(format!(
                "--screen-poses {}: must be 0 (no subsample) or at least {MIN_SCREEN_POSES}",
                self.screen_poses
            )));
        }
        o.screen_poses = self.screen_poses;
        if self.regions == 1 {
            return Err(CliError::Input(
                "--regions 1: the transfer test needs at least 2 regions (0 for none)".into(),
            ));
        }
        o.regions = self.regions;
        if let Some(v) = self.noise_floor {
            if !(v > 0.0 && v.is_finite() && v < 0.1) {
                return Err(CliError::Input(format!(
                    "--noise-floor {v}: must be a position error in m, > 0 and < 0.1"
                )));
            }
            o.noise_floor_m = Some(v);
        }
        Ok(o)
    }
}

/// Smallest sample `--sample-rows` accepts: 1,000 rows, a third of them held out (the held-out test
/// of a 2 % gain needs a few hundred poses, see calib's `diagnose::screening`).
const MIN_SAMPLE_ROWS: usize = 1_000;

/// Smallest screening subsample `--screen-poses` accepts: below it the held-out test of a cause at the
/// smallest adopted gain loses its power (see calib's `diagnose::screening`).
const MIN_SCREEN_POSES: usize = 300;

/// A fraction given as a decimal (`0.25`) or a ratio (`1/3`).
fn parse_fraction(text: &str) -> Result<f64, String> {
    let bad = || format!("'{text}' is not a fraction (e.g. 0.3 or 1/3)");
    match text.split_once('/') {
        Some((a, b)) => {
            let (a, b): (f64, f64) = (
                a.trim().parse().map_err(|_| bad())?,
                b.trim().parse().map_err(|_| bad())?,
            );
            Ok(a / b)
        }
        None => text.trim().parse().map_err(|_| bad()),
    }
}

/// Human-readable summary of a diagnosis: the diagnosis document ([`report::diagnosis::document`])
/// as terminal text, the same content as the report's `summary.md` and `index.html`.
pub(crate) fn text(d: &Diagnosis, data: &str) -> String {
    report::diagnosis::document(d, data, &[]).to_text()
}

/// Checks the shared flags of diagnose-like commands.
pub(crate) fn options(
    test_fraction: f64,
    seed: u64,
    alpha: f64,
) -> Result<DiagnoseOptions, CliError> {
    if !(test_fraction > 0.0 && test_fraction < 1.0) {
        return Err(CliError::Input(format!(
            "--test-fraction {test_fraction}: must be in (0, 1): diagnose judges on held-out poses"
        )));
    }
    if !(alpha > 0.0 && alpha < 0.5) {
        return Err(CliError::Input(format!(
            "--alpha {alpha}: must be in (0, 0.5)"
        )));
    }
    Ok(DiagnoseOptions {
        test_fraction,
        seed,
        alpha,
        ..DiagnoseOptions::default()
    })
}

/// A spinner on stderr, shown from its first message when stderr is a terminal, cleared when dropped.
#[derive(Default)]
pub(crate) struct Spinner(Option<indicatif::ProgressBar>);

impl Spinner {
    /// Shows `fitting {model}`.
    pub(crate) fn show(&mut self, model: &str) {
        self.say(&format!("fitting {model}"));
    }

    /// Shows `text`.
    pub(crate) fn say(&mut self, text: &str) {
        if self.0.is_none() && std::io::stderr().is_terminal() {
            let b = indicatif::ProgressBar::new_spinner();
            b.enable_steady_tick(std::time::Duration::from_millis(120));
            self.0 = Some(b);
        }
        if let Some(b) = &self.0 {
            b.set_message(text.to_string());
        }
    }
}

impl Drop for Spinner {
    fn drop(&mut self) {
        if let Some(b) = &self.0 {
            b.finish_and_clear();
        }
    }
}

/// Runs a diagnosis with a spinner on a terminal.
pub(crate) fn run_diagnosis(
    model: &sim::Model,
    table: &sim::measurement_table::MeasurementTable,
    name: &str,
    options: &DiagnoseOptions,
) -> Result<Diagnosis, CliError> {
    let mut spinner = Spinner::default();
    run_diagnosis_with(model, table, name, options, &mut |m| spinner.show(m))
}

/// Runs a diagnosis of `table` (`name` in messages) on `model`, calling `progress` with the model
/// before each fit: what `robocal diagnose` computes between reading its inputs and writing its
/// outputs (the JSON document is [`json`]).
pub fn run_diagnosis_with(
    model: &sim::Model,
    table: &sim::measurement_table::MeasurementTable,
    name: &str,
    options: &DiagnoseOptions,
    progress: &mut dyn FnMut(&str),
) -> Result<Diagnosis, CliError> {
    diagnose_with_progress(model, table, name, options, progress).map_err(CliError::from)
}

/// The `diagnose --json` document (the diagnose contract).
pub fn json(d: &Diagnosis) -> Result<serde_json::Value, CliError> {
    serde_json::to_value(d).map_err(|e| CliError::Runtime(format!("cannot write JSON: {e}")))
}

/// How `diagnose` reads a file: `--stream`, `--sample-rows`, `--chunk-rows`.
#[derive(Clone, Copy, Debug)]
pub struct Streaming {
    /// Whether to read the file in pieces.
    pub mode: StreamMode,
    /// Rows of the sample diagnosed.
    pub sample_rows: usize,
    /// Rows read at a time.
    pub chunk_rows: usize,
}

/// A diagnosis of a file read in pieces ([`diagnose_file`]).
pub struct StreamedFile {
    /// The diagnosis of the sample.
    pub diagnosis: Diagnosis,
    /// The JSON `stream` object.
    pub json: serde_json::Value,
    /// The text report's lines on the stream.
    pub text: String,
    /// The robot checks' warnings over the whole file.
    pub warnings: Vec<String>,
}

/// The streamed diagnosis of the file `path` ([`calib::select::diagnose::stream`]) when `streaming`
/// says to read it in pieces (`None`: diagnose it in memory), its rows checked against the robot on
/// the first pass. Bad `--chunk-rows` or `--sample-rows` are input errors naming the flag.
pub fn diagnose_file(
    robot: &Robot,
    path: &std::path::Path,
    options: &DiagnoseOptions,
    streaming: &Streaming,
) -> Result<Option<StreamedFile>, CliError> {
    check_chunk_rows(streaming.chunk_rows)?;
    if streaming.sample_rows < MIN_SAMPLE_ROWS {
        return Err(CliError::Input(format!(
            "--sample-rows {}: a streamed diagnosis needs a sample of at least {MIN_SAMPLE_ROWS} rows",
            streaming.sample_rows
        )));
    }
    let (stream, _) = decide_stream(streaming.mode, path, None, &robot.model)?;
    if !stream {
        return Ok(None);
    }
    let source = CheckedFile::new(path, streaming.chunk_rows, &robot.model);
    let mut spinner = Spinner::default();
    let s = diagnose_streamed(
        &robot.model,
        &source,
        options,
        streaming.sample_rows,
        &mut |m| spinner.say(m),
    );
    drop(spinner);
    let s = s?;
    Ok(Some(StreamedFile {
        json: s.json(streaming.chunk_rows),
        text: s.text(),
        diagnosis: s.diagnosis,
        warnings: source.warnings(),
    }))
}

/// Runs `robocal diagnose`.
pub fn run(args: Args) -> CliResult {
    let options = args.options.resolve()?;
    if let Some(dir) = &args.report {
        let mut inputs = Inputs::new();
        inputs
            .add("--data", &args.data)
            .add_robot(&args.robot.robot);
        // The files a report writes: the fixed ones and any plot of an old report it may replace.
        let mut names: Vec<String> = report::FIXED_FILES.iter().map(|n| n.to_string()).collect();
        if let Ok(entries) = std::fs::read_dir(dir) {
            names.extend(
                entries
                    .flatten()
                    .map(|e| e.file_name().to_string_lossy().into_owned())
                    .filter(|n| report::is_report_file(n)),
            );
        }
        let names: Vec<&str> = names.iter().map(String::as_str).collect();
        inputs.check_dir("--report", dir, &names)?;
    }
    let robot = args.robot.load_robot()?;
    let name = args.data.display().to_string();
    let streamed = diagnose_file(
        &robot,
        &args.data,
        &options,
        &Streaming {
            mode: args.stream,
            sample_rows: args.sample_rows,
            chunk_rows: args.chunk_rows,
        },
    )?;
    let (d, streamed) = match streamed {
        Some(s) => {
            for w in &s.warnings {
                eprintln!("warning: {w}");
            }
            (s.diagnosis, Some((s.json, s.text)))
        }
        None => {
            let table = read_table(&args.data, &robot.model)?;
            (run_diagnosis(&robot.model, &table, &name, &options)?, None)
        }
    };
    if let Some(dir) = &args.report {
        let files = report::write(dir, &d, &d.plots, &name)?;
        if !args.json {
            eprintln!(
                "wrote {} ({} files, open index.html)",
                dir.display(),
                files.len()
            );
        }
    }
    if args.json {
        // The text names the causes not tried; with --json, stderr still says so in one line.
        if let Some(w) = report::diagnosis::not_tried(&d) {
            eprintln!("warning: {w}");
        }
        let mut doc = json(&d)?;
        if let Some((s, _)) = &streamed {
            doc["stream"] = s.clone();
        }
        return print_json(&doc);
    }
    eprint!("{}", text(&d, &name));
    if let Some((_, t)) = &streamed {
        eprint!("{t}");
    }
    Ok(())
}
