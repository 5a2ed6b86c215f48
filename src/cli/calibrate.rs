//! `robocal calibrate`: identify the kinematic error model from a measurement table.

use super::paths::{Inputs, check_distinct};
use super::robot_arg::RobotArgs;
use super::shared::{CliError, CliResult, print_json, read_table};
use calib::CalibError;
use calib::calibrate::{Calibration, CalibrationOptions, Dataset, RobustLoss, calibrate_model};
use calib::extensions::{ModelChoice, ModelSpec};
use calib::model_file::CalibratedModel;
use calib::robot::Robot;
use calib::stats::split_by_pose;
use serde_json::json;
use sim::ChainSpec;
use sim::measurement_table::MeasurementTable;
use std::path::{Path, PathBuf};

/// Arguments of `robocal calibrate`.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(flatten)]
    robot: RobotArgs,
    /// Measurement table (.csv or .parquet, see the measurement contract).
    #[arg(long, value_name = "FILE")]
    data: PathBuf,
    #[command(flatten)]
    options: Options,
    /// Where to write the calibrated model (JSON, with the robot embedded).
    #[arg(long, value_name = "MODEL.json")]
    out: PathBuf,
    /// Held-out measurements for validation (instead of splitting --data).
    #[arg(long, value_name = "FILE")]
    test_data: Option<PathBuf>,
    /// Also write the calibrated URDF: the --robot URDF with the chain's joint origins moved to the
    /// calibrated robot, everything else kept, base and target transforms in a comment.
    #[arg(long, value_name = "FILE.urdf")]
    urdf_out: Option<PathBuf>,
    /// Print one JSON document on stdout instead of text on stderr.
    #[arg(long)]
    json: bool,
}

/// The flags of `robocal calibrate` that are values rather than files: one definition for the command
/// line (flattened into its arguments) and the Python package (`robocal.calibrate(data, **options)`,
/// keyword arguments parsed by [`super::flags::parse`]). A flag added here is a keyword argument there.
#[derive(clap::Args, Debug, Clone)]
pub struct Options {
    /// Error model: `kinematic` (joint error twists, zero offsets, base and target), a `+`-joined
    /// extension such as `kinematic+joint_compliance+thermal_drift` (also `gear_backlash`,
    /// `learned:poly|poly1|poly2|poly3|kernel`), or `auto` (what diagnose chooses).
    #[arg(long, value_name = "MODEL", default_value = "kinematic")]
    pub model: String,
    /// Fraction of the poses of --data held out for validation (0 = calibrate on everything).
    /// Repeated measurements of a pose stay together.
    #[arg(long, value_name = "F", default_value_t = 0.3)]
    pub test_fraction: f64,
    /// Seed of the train/test split.
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub seed: u64,
    /// Robust loss against outliers (iteratively reweighted).
    #[arg(long, value_name = "LOSS", value_enum)]
    robust: Option<Robust>,
}

/// `--robust`: the robust loss against outliers.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum Robust {
    /// Huber loss (quadratic near zero, linear beyond its threshold).
    Huber,
    /// Cauchy loss (logarithmic: far outliers hardly count).
    Cauchy,
}

impl Robust {
    /// The loss with calib's default threshold.
    fn loss(self) -> RobustLoss {
        match self {
            Robust::Huber => RobustLoss::HUBER,
            Robust::Cauchy => RobustLoss::CAUCHY,
        }
    }
}

impl Options {
    /// The model `--model` names, `None` for `auto`.
    fn model_spec(&self) -> Result<Option<ModelSpec>, CliError> {
        Ok(match self.model.parse::<ModelChoice>()? {
            ModelChoice::Auto => None,
            ModelChoice::Model(m) => Some(m),
        })
    }

    /// The model to fit (`None` for `auto`) and calib's calibration options; bad values are input
    /// errors naming the flag.
    fn resolve(&self) -> Result<(Option<ModelSpec>, CalibrationOptions), CliError> {
        let model_spec = self.model_spec()?;
        if !(0.0..1.0).contains(&self.test_fraction) {
            return Err(CliError::Input(format!(
                "--test-fraction {}: must be in [0, 1)",
                self.test_fraction
            )));
        }
        let options = CalibrationOptions {
            robust: self.robust.map(Robust::loss),
            ..CalibrationOptions::default()
        };
        Ok((model_spec, options))
    }
}

/// A measurement table and the name that stands for it in messages and reports (its file name).
#[derive(Clone, Copy, Debug)]
pub struct Named<'a> {
    /// The table, checked against the robot.
    pub table: &'a MeasurementTable,
    /// Its name (a file as given, or a description of a table in memory).
    pub name: &'a str,
}

/// What `robocal calibrate` computes between reading its inputs and writing its outputs.
pub struct Outcome {
    /// The fitted model (`auto` resolved).
    pub model_spec: ModelSpec,
    /// The calibration.
    pub cal: Calibration,
    /// How the poses were split: the report's `split` object.
    pub split: serde_json::Value,
    /// The rows of the data the model was fitted on.
    pub train_rows: Vec<usize>,
}

impl Outcome {
    /// The message of a calibration that did not converge (a runtime failure), if it did not.
    pub fn failure(&self) -> Option<String> {
        let report = &self.cal.report;
        (!report.was_successful()).then(|| {
            format!(
                "calibration did not converge: {} after {} iterations",
                report.after.solver.termination, report.after.solver.iterations
            )
        })
    }

    /// The `calibrate --json` document: `out` and `urdf_out` name the files written (null when none).
    pub fn json(
        &self,
        robot: &Robot,
        data: &str,
        out: Option<&Path>,
        urdf_out: Option<&Path>,
    ) -> serde_json::Value {
        json!({
            "robot": robot.model.name,
            "model": self.model_spec.name(),
            "data": data,
            "out": out.map(|p| p.display().to_string()),
            "urdf_out": urdf_out.map(|p| p.display().to_string()),
            "split": self.split,
            "report": self.cal.report,
        })
    }
}

/// Calibrates `robot` on `data` (held out: `test`, or the `--test-fraction` of `data`'s poses) as
/// `robocal calibrate` does with `options`; `progress` hears which model `--model auto`'s diagnosis
/// fits, `note` what it chose. A calibration that does not converge is an [`Outcome`] too (see
/// [`Outcome::failure`]).
pub fn calibrate(
    robot: &Robot,
    data: Named<'_>,
    test: Option<Named<'_>>,
    options: &Options,
    progress: &mut dyn FnMut(&str),
    note: &mut dyn FnMut(&str),
) -> Result<Outcome, CliError> {
    let (model_spec, calibration) = options.resolve()?;
    let model = &robot.model;
    let table = data.table;
    let (train, test_set, split) = match test {
        Some(t) => (
            Dataset::all(table, data.name),
            Some(Dataset::all(t.table, t.name)),
            json!({"kind": "test_file", "test_data": t.name}),
        ),
        None => {
            let (tr, te) = split_by_pose(table, options.test_fraction, options.seed);
            let split = json!({"kind": "by_pose", "test_fraction": options.test_fraction, "seed": options.seed});
            let train = Dataset {
                table,
                rows: tr,
                name: if te.is_empty() {
                    data.name.to_string()
                } else {
                    format!("{} (training set)", data.name)
                },
            };
            let test = (!te.is_empty()).then(|| Dataset {
                table,
                rows: te,
                name: format!("{} (test set)", data.name),
            });
            (train, test, split)
        }
    };
    let model_spec = match model_spec {
        Some(s) => s,
        None => {
            let d = super::diagnose::run_diagnosis_with(
                model,
                table,
                data.name,
                &super::diagnose::options(1.0 / 3.0, options.seed, 1e-3)?,
                progress,
            )?;
            note(&format!("--model auto: diagnose chose {}", d.model));
            d.model
        }
    };
    let cal = calibrate_model(model, &train, test_set.as_ref(), &model_spec, &calibration)
        .map_err(|e| {
            let split_hint = matches!(e, CalibError::TooFewPoses { .. })
                && test.is_none()
                && options.test_fraction > 0.0;
            let e = CliError::from(e);
            if split_hint {
                e.with_hint(&format!(
                    " (--test-fraction {} held out part of the poses; --test-fraction 0 uses all)",
                    options.test_fraction
                ))
            } else {
                e
            }
        })?;
    Ok(Outcome {
        model_spec,
        cal,
        split,
        train_rows: train.rows,
    })
}

/// Runs `robocal calibrate`.
pub fn run(args: Args) -> CliResult {
    args.options.model_spec()?;
    let mut inputs = Inputs::new();
    inputs
        .add("--data", &args.data)
        .add_robot(&args.robot.robot);
    if let Some(t) = &args.test_data {
        inputs.add("--test-data", t);
    }
    inputs.check("--out", &args.out)?;
    if let Some(u) = &args.urdf_out {
        inputs.check("--urdf-out", u)?;
        check_distinct(("--out", &args.out), ("--urdf-out", u))?;
    }
    args.options.resolve()?;
    let spec = ChainSpec {
        base_link: args.robot.base_link.clone(),
        tip_link: args.robot.tip_link.clone(),
    };
    let robot = Robot::load(&args.robot.robot, &spec)?;
    let model = &robot.model;
    let table = read_table(&args.data, model)?;
    let data_name = args.data.display().to_string();
    let test_table = match &args.test_data {
        Some(p) => Some((read_table(p, model)?, p.display().to_string())),
        None => None,
    };
    let test = test_table
        .as_ref()
        .map(|(t, name)| Named { table: t, name });
    let data = Named {
        table: &table,
        name: &data_name,
    };
    let mut spinner = super::diagnose::Spinner::default();
    let quiet = args.json;
    let outcome = calibrate(
        &robot,
        data,
        test,
        &args.options,
        &mut |m| spinner.show(m),
        &mut |m| {
            if !quiet {
                eprintln!("{m}");
            }
        },
    );
    drop(spinner);
    let outcome = outcome?;
    let cal = &outcome.cal;
    let report = &cal.report;
    if let Some(msg) = outcome.failure() {
        if args.json {
            print_json(&json!({"error": msg, "report": report}))?;
        } else {
            eprint!("{}", report.text());
        }
        return Err(CliError::Runtime(msg));
    }
    let file = CalibratedModel::new(&robot, cal);
    sim::io::write_atomic(&args.out, file.to_json().as_bytes())?;
    if let Some(path) = &args.urdf_out {
        super::urdf_out::write(path, &file, &table, &data_name)?;
    }
    if args.json {
        print_json(&outcome.json(
            &robot,
            &data_name,
            Some(&args.out),
            args.urdf_out.as_deref(),
        ))
    } else {
        eprint!("{}", report.text());
        eprintln!("wrote {}", args.out.display());
        if let Some(p) = &args.urdf_out {
            eprintln!("wrote {}", p.display());
        }
        Ok(())
    }
}
