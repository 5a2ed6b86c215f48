//! `robocal calibrate`: identify the kinematic error model from a measurement table.

use super::paths::{Inputs, check_distinct};
use super::robot_arg::RobotArgs;
use super::shared::{CliError, CliResult, print_json, read_table};
use calib::CalibError;
use calib::calibrate::{CalibrationOptions, Dataset, RobustLoss, calibrate_model};
use calib::extensions::ModelChoice;
use calib::model_file::CalibratedModel;
use calib::robot::Robot;
use calib::stats::split_by_pose;
use serde_json::json;
use sim::ChainSpec;
use std::path::PathBuf;

/// Arguments of `robocal calibrate`.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(flatten)]
    robot: RobotArgs,
    /// Measurement table (.csv or .parquet, see the measurement contract).
    #[arg(long, value_name = "FILE")]
    data: PathBuf,
    /// Error model: `kinematic` (joint error twists, zero offsets, base and target), a `+`-joined
    /// extension such as `kinematic+joint_compliance+thermal_drift` (also `gear_backlash`,
    /// `learned:poly|poly1|poly2|poly3|kernel`), or `auto` (what diagnose chooses).
    #[arg(long, value_name = "MODEL", default_value = "kinematic")]
    model: String,
    /// Where to write the calibrated model (JSON, with the robot embedded).
    #[arg(long, value_name = "MODEL.json")]
    out: PathBuf,
    /// Held-out measurements for validation (instead of splitting --data).
    #[arg(long, value_name = "FILE")]
    test_data: Option<PathBuf>,
    /// Fraction of the poses of --data held out for validation (0 = calibrate on everything).
    /// Repeated measurements of a pose stay together.
    #[arg(long, value_name = "F", default_value_t = 0.3)]
    test_fraction: f64,
    /// Seed of the train/test split.
    #[arg(long, value_name = "N", default_value_t = 0)]
    seed: u64,
    /// Robust loss against outliers (iteratively reweighted).
    #[arg(long, value_name = "LOSS", value_enum)]
    robust: Option<Robust>,
    /// Also write the calibrated URDF: the --robot URDF with the chain's joint origins moved to the
    /// calibrated robot, everything else kept, base and target transforms in a comment.
    #[arg(long, value_name = "FILE.urdf")]
    urdf_out: Option<PathBuf>,
    /// Print one JSON document on stdout instead of text on stderr.
    #[arg(long)]
    json: bool,
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

/// Runs `robocal calibrate`.
pub fn run(args: Args) -> CliResult {
    let model_spec = match args.model.parse::<ModelChoice>()? {
        ModelChoice::Auto => None,
        ModelChoice::Model(m) => Some(m),
    };
    let robust = args.robust.map(Robust::loss);
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
    if !(0.0..1.0).contains(&args.test_fraction) {
        return Err(CliError::Input(format!(
            "--test-fraction {}: must be in [0, 1)",
            args.test_fraction
        )));
    }
    let spec = ChainSpec {
        base_link: args.robot.base_link.clone(),
        tip_link: args.robot.tip_link.clone(),
    };
    let robot = Robot::load(&args.robot.robot, &spec)?;
    let model = &robot.model;
    let table = read_table(&args.data, model)?;
    let data_name = args.data.display().to_string();
    let test_table = match &args.test_data {
        Some(p) => Some(read_table(p, model)?),
        None => None,
    };
    let (train, test, split) = match (&test_table, &args.test_data) {
        (Some(t), Some(p)) => (
            Dataset::all(&table, &data_name),
            Some(Dataset::all(t, &p.display().to_string())),
            json!({"kind": "test_file", "test_data": p.display().to_string()}),
        ),
        _ => {
            let (tr, te) = split_by_pose(&table, args.test_fraction, args.seed);
            let split =
                json!({"kind": "by_pose", "test_fraction": args.test_fraction, "seed": args.seed});
            let train = Dataset {
                table: &table,
                rows: tr,
                name: if te.is_empty() {
                    data_name.clone()
                } else {
                    format!("{data_name} (training set)")
                },
            };
            let test = (!te.is_empty()).then(|| Dataset {
                table: &table,
                rows: te,
                name: format!("{data_name} (test set)"),
            });
            (train, test, split)
        }
    };
    let options = CalibrationOptions {
        robust,
        ..CalibrationOptions::default()
    };
    let model_spec = match model_spec {
        Some(s) => s,
        None => {
            let d = super::diagnose::run_diagnosis(
                model,
                &table,
                &data_name,
                &super::diagnose::options(1.0 / 3.0, args.seed, 1e-3)?,
            )?;
            if !args.json {
                eprintln!("--model auto: diagnose chose {}", d.model);
            }
            d.model
        }
    };
    let cal =
        calibrate_model(model, &train, test.as_ref(), &model_spec, &options).map_err(|e| {
            let split_hint = matches!(e, CalibError::TooFewPoses { .. })
                && args.test_data.is_none()
                && args.test_fraction > 0.0;
            let e = CliError::from(e);
            if split_hint {
                e.with_hint(&format!(
                    " (--test-fraction {} held out part of the poses; --test-fraction 0 uses all)",
                    args.test_fraction
                ))
            } else {
                e
            }
        })?;
    let report = &cal.report;
    if !report.was_successful() {
        let msg = format!(
            "calibration did not converge: {} after {} iterations",
            report.after.solver.termination, report.after.solver.iterations
        );
        if args.json {
            print_json(&json!({"error": msg, "report": report}))?;
        } else {
            eprint!("{}", report.text());
        }
        return Err(CliError::Runtime(msg));
    }
    let file = CalibratedModel::new(&robot, &cal);
    sim::io::write_atomic(&args.out, file.to_json().as_bytes())?;
    if let Some(path) = &args.urdf_out {
        super::urdf_out::write(path, &file, &table, &data_name)?;
    }
    if args.json {
        print_json(&json!({
            "robot": model.name,
            "model": model_spec.name(),
            "data": data_name,
            "out": args.out.display().to_string(),
            "urdf_out": args.urdf_out.as_ref().map(|p| p.display().to_string()),
            "split": split,
            "report": report,
        }))
    } else {
        eprint!("{}", report.text());
        eprintln!("wrote {}", args.out.display());
        if let Some(p) = &args.urdf_out {
            eprintln!("wrote {}", p.display());
        }
        Ok(())
    }
}
