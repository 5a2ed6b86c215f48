//! `robocal calibrate`: identify the kinematic error model from a measurement table.

use super::paths::{Inputs, check_distinct};
use super::robot_arg::RobotArgs;
use super::shared::{CliError, CliResult, print_json, read_table};
use calib::CalibError;
use calib::calibrate::auto::{self, AUTO_LEARNED_KINDS};
use calib::calibrate::validation::{DEFAULT_FOLDS, ValidationPlan, calibrate_validated};
use calib::calibrate::{CalibrationOptions, Dataset, RobustLoss};
use calib::extensions::ModelChoice;
use calib::model_file::{CalibratedModel, calibrated_urdf, urdf_deviation};
use calib::robot::Robot;
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
    /// Held-out measurements for validation, predicted by the saved model (instead of
    /// cross-validation).
    #[arg(long, value_name = "FILE")]
    test_data: Option<PathBuf>,
    /// Validate by k-fold cross-validation by pose: each fold predicted by a model fitted on the
    /// others, folds fitted in parallel (0 = no validation). The saved model is fitted on every pose
    /// either way. Default 5.
    #[arg(long, value_name = "K")]
    folds: Option<usize>,
    /// Validate by one split instead: this fraction of the poses held out and predicted by a model
    /// fitted on the others (repeats of a pose stay together). The saved model is still fitted on
    /// every pose.
    #[arg(long, value_name = "F", default_value_t = 0.0)]
    test_fraction: f64,
    /// Seed of the folds or the split.
    #[arg(long, value_name = "N", default_value_t = 0)]
    seed: u64,
    /// With several campaigns (a `campaign` column), give each its own target offset (a re-seated
    /// reflector) instead of one shared target.
    #[arg(long)]
    per_campaign_target: bool,
    /// Robust loss against outliers (iteratively reweighted).
    #[arg(long, value_name = "LOSS", value_enum)]
    robust: Option<Robust>,
    /// Also write a URDF of the calibrated robot (joint origins adjusted).
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
    let chosen = [
        args.test_data.is_some(),
        args.test_fraction > 0.0,
        args.folds.is_some(),
    ];
    if chosen.iter().filter(|&&b| b).count() > 1 {
        return Err(CliError::Input(
            "--test-data, --test-fraction and --folds are alternative validations: give one".into(),
        ));
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
    let folds = args.folds.unwrap_or(DEFAULT_FOLDS);
    let (plan, split) = match (&test_table, &args.test_data) {
        (Some(t), Some(p)) => (
            ValidationPlan::TestData(Dataset::all(t, &p.display().to_string())),
            json!({"kind": "test_file", "test_data": p.display().to_string()}),
        ),
        _ if args.test_fraction > 0.0 => (
            ValidationPlan::Split {
                fraction: args.test_fraction,
                seed: args.seed,
            },
            json!({"kind": "by_pose", "test_fraction": args.test_fraction, "seed": args.seed}),
        ),
        _ if folds == 0 => (ValidationPlan::None, json!({"kind": "none"})),
        _ => (
            ValidationPlan::Folds {
                k: folds,
                seed: args.seed,
            },
            json!({"kind": "cross_validation", "folds": folds, "seed": args.seed}),
        ),
    };
    let all = Dataset::all(&table, &data_name);
    let options = CalibrationOptions {
        robust,
        per_campaign_target: args.per_campaign_target,
        ..CalibrationOptions::default()
    };
    let mut auto = None;
    let model_spec = match model_spec {
        Some(s) => s,
        None => {
            let diagnose_options = super::diagnose::options(1.0 / 3.0, args.seed, 1e-3)?;
            let d = super::diagnose::run_diagnosis(model, &table, &data_name, &diagnose_options)?;
            let choice = auto::choose(
                model,
                &table,
                &data_name,
                &d,
                &diagnose_options,
                &AUTO_LEARNED_KINDS,
            )?;
            if !args.json {
                eprintln!("--model auto: diagnose chose {}", d.model);
                eprintln!("--model auto: {}", choice.note);
            }
            let spec = choice.spec.clone();
            auto = Some(choice);
            spec
        }
    };
    let (cal, validation) = calibrate_validated(model, &all, &model_spec, &options, &plan)
        .map_err(|e| {
            // Only a validation fit (a fold, or the split's training part) gets the hint: the model
            // on every pose had enough.
            let hint = match (&e, &plan) {
                (CalibError::TooFewPoses { context, .. }, ValidationPlan::Split { fraction, .. })
                    if context.ends_with("(training set)") =>
                {
                    Some(format!(
                        " (--test-fraction {fraction} held out part of the poses for the validation fit; \
                         --folds 0 validates nothing)"
                    ))
                }
                (CalibError::TooFewPoses { context, .. }, ValidationPlan::Folds { k, .. })
                    if context.contains("(fold ") =>
                {
                    Some(format!(
                        " (--folds {k} fits each fold on {}/{k} of the poses; fewer folds, or --folds 0 \
                         for no validation)",
                        k - 1
                    ))
                }
                _ => None,
            };
            let e = CliError::from(e);
            match hint {
                Some(h) => e.with_hint(&h),
                None => e,
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
    let mut file = CalibratedModel::new(&robot, &cal);
    if let (Some(f), Some(v)) = (file.fit.as_mut(), &validation) {
        f.held_out_rms_m = Some(v.final_stats().rms_m);
    }
    sim::io::write_atomic(&args.out, file.to_json().as_bytes())?;
    if let Some(path) = &args.urdf_out {
        let urdf = calibrated_urdf(model, &cal.params);
        let configs: Vec<Vec<f64>> = (0..table.len().min(200))
            .map(|r| table.q_row(r).to_vec())
            .collect();
        let dev = urdf_deviation(model, &cal.params, &urdf, &configs)?;
        if dev > 1e-9 {
            return Err(CliError::Runtime(format!(
                "{}: the calibrated URDF deviates from the model by {dev:.1e} (m or rotation entry); not written",
                path.display()
            )));
        }
        sim::io::write_atomic(path, urdf.as_bytes())?;
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
            "validation": validation,
            "auto": auto,
        }))
    } else {
        eprint!("{}", report.text());
        if let Some(v) = &validation {
            eprint!("{}", v.text(&model_spec.name()));
        }
        eprintln!("wrote {}", args.out.display());
        if let Some(p) = &args.urdf_out {
            eprintln!("wrote {}", p.display());
        }
        Ok(())
    }
}
