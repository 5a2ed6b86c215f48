//! `robocal compensate`: the joints to command so that the calibrated robot puts the target where it
//! should be (every cause and the learned correction inverted; [`calib::model::compensate`]).

use super::paths::Inputs;
use super::shared::{CliError, CliResult, print_json};
use calib::model::compensate::{Compensations, Targets, compensate_table};
use calib::model::file::CalibratedModel;
use calib::model::predict::Predictor;
use serde_json::json;
use sim::measurement_table::{self, MeasurementTable};
use std::path::{Path, PathBuf};

/// Arguments of `robocal compensate`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Calibrated model written by `robocal calibrate` (or `register`).
    #[arg(long, value_name = "MODEL.json")]
    model: PathBuf,
    /// Targets (CSV or Parquet): `pose`, `x, y, z` where the target should be (m), `q1..qN` the
    /// nominal joints that seed the solve, optionally `qw, qx, qy, qz`, and the context columns the
    /// model reads (`payload`, `temp` or `t`, `dir1..dirN`, `campaign`). With --program, no x, y, z.
    #[arg(long, value_name = "FILE")]
    targets: PathBuf,
    /// Where to write `pose, q1..qN, residual_m, outside_support, converged` and the input's context
    /// columns.
    #[arg(long, value_name = "Q.csv")]
    out: PathBuf,
    #[command(flatten)]
    options: Options,
    /// Print one JSON document on stdout instead of text on stderr.
    #[arg(long)]
    json: bool,
}

/// The value flags of `robocal compensate` (also the keyword arguments of Python's
/// `Model.compensate`).
#[derive(clap::Args, Debug, Clone, Default)]
pub struct Options {
    /// The input is a nominal joint program (`pose, q1..qN` and context, no x, y, z): each row's
    /// target is where the nominal robot puts the target at its joints, in the calibrated
    /// registration; the output is the compensated program.
    #[arg(long)]
    pub program: bool,
    /// Frame of x, y, z (and qw..qz): `tracker` (the row's campaign's tracker frame) or `base` (the
    /// robot's base frame).
    #[arg(long, value_name = "FRAME", default_value = "tracker", value_parser = ["tracker", "base"])]
    pub frame: String,
}

impl Options {
    /// The kind of targets these options ask for.
    pub fn targets(&self) -> Result<Targets, CliError> {
        match (self.program, self.frame.as_str()) {
            (true, "tracker") => Ok(Targets::Program),
            (true, _) => Err(CliError::Input(
                "--frame: a --program has no x, y, z to give in a frame".into(),
            )),
            (false, "tracker") => Ok(Targets::Tracker),
            (false, "base") => Ok(Targets::Base),
            (false, other) => Err(CliError::Input(format!(
                "--frame: '{other}' is not a frame (tracker or base)"
            ))),
        }
    }
}

/// Reads the targets table: the measurement contract, with x, y, z required unless `program`.
pub fn read_targets(
    path: &Path,
    robot: &sim::Model,
    program: bool,
) -> Result<MeasurementTable, CliError> {
    let table = if program {
        measurement_table::read_configurations(path)?
    } else {
        measurement_table::read(path)?
    };
    for w in super::predict::check_configurations(&table, robot, &path.display().to_string())? {
        eprintln!("warning: {w}");
    }
    Ok(table)
}

/// Compensates `table` (named `name`) with the model `file` as `robocal compensate` does with
/// `options`.
pub fn compensate(
    file: &CalibratedModel,
    table: &MeasurementTable,
    name: &str,
    options: &Options,
) -> Result<Compensations, CliError> {
    let targets = options.targets()?;
    let predictor = Predictor::from_file(file)?;
    Ok(compensate_table(&predictor, table, name, targets)?)
}

/// The one-line messages naming the rows not reached (at most `max` of them, then a count).
pub fn failure_lines(c: &Compensations, name: &str, max: usize) -> Vec<String> {
    let failed: Vec<_> = c.failures().collect();
    let mut out: Vec<String> = failed
        .iter()
        .take(max)
        .map(|(r, f)| format!("{name}: row {} (pose {}): {f}", r + 1, c.pose[*r]))
        .collect();
    if failed.len() > max {
        out.push(format!(
            "{name}: {} more rows not reached (converged = 0 in the output)",
            failed.len() - max
        ));
    }
    out
}

/// Runs `robocal compensate`.
pub fn run(args: Args) -> CliResult {
    let mut inputs = Inputs::new();
    inputs
        .add("--model", &args.model)
        .add("--targets", &args.targets);
    inputs.check("--out", &args.out)?;
    args.options.targets()?;
    let file = CalibratedModel::load(&args.model)?;
    let robot = file.robot_model()?;
    let table = read_targets(&args.targets, &robot, args.options.program)?;
    let name = args.targets.display().to_string();
    let c = compensate(&file, &table, &name, &args.options)?;
    sim::io::write_atomic(&args.out, c.to_csv().as_bytes())?;
    let failed: Vec<_> = c.failures().collect();
    let n_failed = failed.len();
    let max_res = c
        .solutions
        .iter()
        .filter(|s| s.converged())
        .map(|s| s.residual_m)
        .fold(0.0, f64::max);
    let iterations: Vec<usize> = c.solutions.iter().map(|s| s.iterations).collect();
    if args.json {
        print_json(&json!({
            "model": args.model.display().to_string(),
            "targets": name,
            "program": args.options.program,
            "frame": args.options.frame,
            "rows": table.len(),
            "converged": table.len() - n_failed,
            "failed": failed.iter().map(|(r, f)| json!({
                "row": r + 1, "pose": c.pose[*r], "problem": f.to_string(),
            })).collect::<Vec<_>>(),
            "outside_support": c.outside_support.iter().filter(|&&o| o).count(),
            "max_residual_m": max_res,
            "max_iterations": iterations.iter().max().copied().unwrap_or(0),
            "out": args.out.display().to_string(),
        }))?;
    } else {
        eprintln!(
            "compensated {} of {} rows with the calibrated '{}' model (largest residual {max_res:.1e} m); wrote {}",
            table.len() - n_failed,
            table.len(),
            robot.name(),
            args.out.display()
        );
    }
    for line in failure_lines(&c, &name, 10) {
        eprintln!("error: {line}");
    }
    if n_failed > 0 {
        return Err(CliError::Runtime(format!(
            "{name}: {n_failed} of {} targets not reached (out of reach or beyond the joint limits; \
             their rows have converged = 0 in {})",
            table.len(),
            args.out.display()
        )));
    }
    Ok(())
}
