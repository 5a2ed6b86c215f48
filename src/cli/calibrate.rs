//! `robocal calibrate`: identify the kinematic error model from a measurement table.

use super::calibrate_stream::{
    CheckedFile, STREAM_MIN_ROWS, StreamMode, check_chunk_rows, decide_stream, describe,
    needs_memory,
};
use super::paths::{Inputs, check_distinct};
use super::robot_arg::RobotArgs;
use super::shared::{CliError, CliResult, print_json, read_table};
use calib::CalibError;
use calib::fit::{Calibration, CalibrationOptions, Dataset, FitRequest, Part, RobustLoss};
use calib::model::file::CalibratedModel;
use calib::model::robot::Robot;
use calib::model::spec::{ModelChoice, ModelSpec};
use calib::select::auto::{AUTO_LEARNED_KINDS, AutoChoice};
use calib::validate::{DEFAULT_FOLDS, Validation, ValidationPlan, fit_and_validate};
use serde_json::json;
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
    /// Held-out measurements for validation, predicted by the saved model (instead of
    /// cross-validation).
    #[arg(long, value_name = "FILE")]
    test_data: Option<PathBuf>,
    /// Also write the calibrated URDF: the --robot URDF with the chain's joint origins moved to the
    /// calibrated robot, everything else kept, base and target transforms in a comment.
    #[arg(long, value_name = "FILE.urdf")]
    urdf_out: Option<PathBuf>,
    /// Also write the calibrated geometry in ur_description's kinematics format (a UR arm: pass it to
    /// ur.urdf.xacro as kinematics_params); non-geometric causes are left out.
    #[arg(long, value_name = "FILE.yaml")]
    ur_kinematics: Option<PathBuf>,
    /// Read the table in pieces instead of holding it in memory (docs/calibrate.md, "Streams"):
    /// `auto` streams a table of more than 262,144 rows when the options allow it (the kinematic
    /// model, no --robust, no --test-data or --test-fraction; folds and regions validate the stream);
    /// `always` streams any table and refuses options that need it in memory; `never` holds it.
    #[arg(long, value_enum, value_name = "WHEN", default_value_t = StreamMode::Auto)]
    stream: StreamMode,
    /// Rows read at a time when streaming.
    #[arg(long, value_name = "N", default_value_t = sim::measurement_table::DEFAULT_CHUNK_ROWS)]
    chunk_rows: usize,
    /// Print one JSON document on stdout instead of text on stderr.
    #[arg(long)]
    json: bool,
}

/// The flags of `robocal calibrate` that are values rather than files: one definition for the command
/// line (flattened into its arguments) and the Python package (`robocal.calibrate(data, **options)`,
/// keyword arguments parsed by [`super::flags::parse`]). A flag added here is a keyword argument there.
#[derive(clap::Args, Debug, Clone)]
pub struct Options {
    /// Error model: `kinematic`, a `+`-joined extension with calib's causes or a learned residual,
    /// or `auto`. The help lists the words from calib's registries ([`super::model_words`]).
    #[arg(long, value_name = "MODEL", default_value = "kinematic", help = super::model_words::model_help())]
    pub model: String,
    /// Validate by k-fold cross-validation by pose: each fold predicted by a model fitted on the
    /// others, folds fitted in parallel (0 = no validation). The saved model is fitted on every pose
    /// either way. Default 5.
    #[arg(long, value_name = "K")]
    pub folds: Option<usize>,
    /// Validate by one split instead: this fraction of the poses held out and predicted by a model
    /// fitted on the others (repeats of a pose stay together). The saved model is still fitted on
    /// every pose.
    #[arg(long, value_name = "F", default_value_t = 0.0)]
    pub test_fraction: f64,
    /// Also validate on unseen regions of the configuration space: the poses clustered into K
    /// regions (seeded k-means on sin q, cos q; docs/calibrate.md), each predicted by a model fitted
    /// on the others; the saved model's `new_region` figure is what it promises for poses unlike
    /// the ones it saw (0 = off). With several campaigns, each campaign is also predicted by a
    /// model fitted on the others, registered on 20 of its poses.
    #[arg(long, value_name = "K", default_value_t = calib::validate::regions::DEFAULT_REGIONS)]
    pub regions: usize,
    /// Seed of the folds or the split, and of the regions.
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub seed: u64,
    /// With several campaigns (a `campaign` column), give each its own target offset (a re-seated
    /// reflector) instead of one shared target.
    #[arg(long)]
    pub per_campaign_target: bool,
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
    /// Why these options need the table in memory (`None`: the streamed fit applies), with held-out
    /// data given or not (`test_data`).
    pub fn needs_memory(&self, test_data: bool) -> Option<String> {
        needs_memory(
            &self.model,
            self.robust.is_some(),
            self.test_fraction,
            test_data,
        )
    }

    /// The model `--model` names, `None` for `auto`.
    fn model_spec(&self) -> Result<Option<ModelSpec>, CliError> {
        Ok(match self.model.parse::<ModelChoice>()? {
            ModelChoice::Auto => None,
            ModelChoice::Model(m) => Some(m),
        })
    }

    /// The model to fit (`None` for `auto`) and calib's calibration options; bad values are input
    /// errors naming the flag. `test_data`: whether held-out measurements are given (`--test-data`,
    /// the `test` table), an alternative to `--folds` and `--test-fraction`.
    fn resolve(
        &self,
        test_data: bool,
    ) -> Result<(Option<ModelSpec>, CalibrationOptions), CliError> {
        let model_spec = self.model_spec()?;
        if !(0.0..1.0).contains(&self.test_fraction) {
            return Err(CliError::Input(format!(
                "--test-fraction {}: must be in [0, 1)",
                self.test_fraction
            )));
        }
        let chosen = [test_data, self.test_fraction > 0.0, self.folds.is_some()];
        if chosen.iter().filter(|&&b| b).count() > 1 {
            return Err(CliError::Input(
                "--test-data, --test-fraction and --folds are alternative validations: give one"
                    .into(),
            ));
        }
        if self.regions == 1 {
            return Err(CliError::Input(
                "--regions 1: validation by region needs at least 2 regions (0 for none)".into(),
            ));
        }
        if self.folds == Some(1) {
            return Err(CliError::Input(
                "--folds 1: cross-validation needs at least 2 folds (0 for no validation)".into(),
            ));
        }
        let options = CalibrationOptions {
            robust: self.robust.map(Robust::loss),
            per_campaign_target: self.per_campaign_target,
            ..CalibrationOptions::default()
        };
        Ok((model_spec, options))
    }

    /// How to validate (`test`: the `--test-data` table) and the report's `split` object.
    fn plan<'a>(&self, test: Option<Named<'a>>) -> (ValidationPlan<'a>, serde_json::Value) {
        let folds = self.folds.unwrap_or(DEFAULT_FOLDS);
        match test {
            Some(t) => (
                ValidationPlan::TestData(Dataset::all(t.table, t.name)),
                json!({"kind": "test_file", "test_data": t.name}),
            ),
            None if self.test_fraction > 0.0 => (
                ValidationPlan::Split {
                    fraction: self.test_fraction,
                    seed: self.seed,
                    regions: self.regions,
                },
                json!({"kind": "by_pose", "test_fraction": self.test_fraction, "seed": self.seed}),
            ),
            None if folds == 0 => (ValidationPlan::None, json!({"kind": "none"})),
            None => (
                ValidationPlan::Folds {
                    k: folds,
                    seed: self.seed,
                    regions: self.regions,
                },
                json!({"kind": "cross_validation", "folds": folds, "seed": self.seed, "regions": self.regions}),
            ),
        }
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
    /// How the model was validated: the report's `split` object.
    pub split: serde_json::Value,
    /// The validation (`None` with `--folds 0`).
    pub validation: Option<Validation>,
    /// What `--model auto` chose and why (`None` for a named model).
    pub auto: Option<AutoChoice>,
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

    /// The model file: the calibration, with the validation's held-out RMS in its fit summary and
    /// the predicted standard deviation over the calibration data `data`
    /// ([`CalibratedModel::record_calibration_sigma`]).
    pub fn model_file(&self, robot: &Robot, data: Named<'_>) -> calib::Result<CalibratedModel> {
        let mut file = CalibratedModel::new(robot, &self.cal);
        if let (Some(f), Some(v)) = (file.fit.as_mut(), &self.validation) {
            f.held_out_rms_m = Some(v.final_stats().rms_m);
            f.new_region_rms_m = v.new_region.as_ref().map(|r| r.rms_m);
        }
        let rows: Vec<usize> = (0..data.table.len()).collect();
        file.record_calibration_sigma(data.table, &rows, data.name)?;
        Ok(file)
    }

    /// The validation's text (empty without one).
    pub fn validation_text(&self) -> String {
        self.validation
            .as_ref()
            .map(|v| v.text(&self.model_spec.name()))
            .unwrap_or_default()
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
            "robot": robot.model.name(),
            "model": self.model_spec.name(),
            "data": data,
            "out": out.map(|p| p.display().to_string()),
            "urdf_out": urdf_out.map(|p| p.display().to_string()),
            "split": self.split,
            "report": self.cal.report,
            "validation": self.validation,
            "auto": self.auto,
        })
    }
}

/// What `--model auto` fits for `data` on `model`: diagnose (held-out third, `seed`, `regions`,
/// α = 10⁻³) and then the learned kinds that still gain ([`calib::select::choose`]); `progress`
/// hears what is fitted, `note` what was chosen. `robocal calibrate` and `robocal sweep --model auto`
/// resolve `auto` here.
pub fn choose_auto(
    model: &sim::Model,
    data: Named<'_>,
    seed: u64,
    regions: usize,
    progress: &mut dyn FnMut(&str),
    note: &mut dyn FnMut(&str),
) -> Result<AutoChoice, CliError> {
    let mut diagnose_options = super::diagnose::options(1.0 / 3.0, seed, 1e-3)?;
    diagnose_options.regions = regions;
    let (d, choice) = calib::select::choose(
        model,
        data.table,
        data.name,
        &diagnose_options,
        &AUTO_LEARNED_KINDS,
        progress,
    )?;
    note(&format!("--model auto: diagnose chose {}", d.model));
    note(&format!("--model auto: {}", choice.note));
    Ok(choice)
}

/// Calibrates `robot` on every pose of `data` as `robocal calibrate` does with `options`, and
/// validates the model (on `test`, by cross-validation or by one split, as `options` say); `progress`
/// hears which model `--model auto`'s diagnosis fits, `note` what it chose. A calibration that does not
/// converge is an [`Outcome`] too (see [`Outcome::failure`]).
pub fn calibrate(
    robot: &Robot,
    data: Named<'_>,
    test: Option<Named<'_>>,
    options: &Options,
    progress: &mut dyn FnMut(&str),
    note: &mut dyn FnMut(&str),
) -> Result<Outcome, CliError> {
    let (model_spec, calibration) = options.resolve(test.is_some())?;
    let model = &robot.model;
    let table = data.table;
    let (plan, split) = options.plan(test);
    let all = Dataset::all(table, data.name);
    let mut auto = None;
    let model_spec = match model_spec {
        Some(s) => s,
        None => {
            let choice = choose_auto(model, data, options.seed, options.regions, progress, note)?;
            let spec = choice.spec.clone();
            auto = Some(choice);
            spec
        }
    };
    let (cal, validation) = fit_and_validate(
        model,
        &all,
        &FitRequest::new(&model_spec, &calibration),
        &plan,
    )
    .map_err(|e| {
        // Only a validation fit (a fold, or the split's training part) gets the hint: the model
        // on every pose had enough.
        let hint = match (&e, &plan) {
            (
                CalibError::TooFewPoses {
                    part: Part::Training,
                    ..
                },
                ValidationPlan::Split { fraction, .. },
            ) => Some(format!(
                " (--test-fraction {fraction} held out part of the poses for the validation fit; \
                         --folds 0 validates nothing)"
            )),
            (
                CalibError::TooFewPoses {
                    part: Part::FoldTraining(_),
                    ..
                },
                ValidationPlan::Folds { k, .. },
            ) => Some(format!(
                " (--folds {k} fits each fold on {}/{k} of the poses; fewer folds, or --folds 0 \
                         for no validation)",
                k - 1
            )),
            (
                CalibError::TooFewPoses {
                    part: Part::RegionTraining(_),
                    ..
                },
                ValidationPlan::Folds { regions, .. } | ValidationPlan::Split { regions, .. },
            ) => Some(format!(
                " (--regions {regions} fits the model without each region in turn; fewer \
                 regions, or --regions 0 for no validation by region)"
            )),
            _ => None,
        };
        let e = CliError::from(e);
        match hint {
            Some(h) => e.with_hint(&h),
            None => e,
        }
    })?;
    Ok(Outcome {
        model_spec,
        cal,
        split,
        validation,
        auto,
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
    if let Some(u) = &args.ur_kinematics {
        inputs.check("--ur-kinematics", u)?;
        check_distinct(("--out", &args.out), ("--ur-kinematics", u))?;
        if let Some(v) = &args.urdf_out {
            check_distinct(("--urdf-out", v), ("--ur-kinematics", u))?;
        }
    }
    args.options.resolve(args.test_data.is_some())?;
    check_chunk_rows(args.chunk_rows)?;
    let robot = args.robot.load_robot()?;
    let model = &robot.model;
    let data_name = args.data.display().to_string();
    let memory_reason = args.options.needs_memory(args.test_data.is_some());
    let (stream, large) = decide_stream(args.stream, &args.data, memory_reason.as_deref(), model)?;
    if let (true, false, Some(r), false) = (large, stream, &memory_reason, args.json) {
        eprintln!(
            "note: {data_name} has more than {STREAM_MIN_ROWS} rows, held in memory for {r}; \
             the kinematic model without --robust, --test-fraction or --test-data reads them in \
             pieces"
        );
    }
    let mut spinner = super::diagnose::Spinner::default();
    let quiet = args.json;
    let (outcome, table, stream_info) = if stream {
        let streamed = calibrate_streamed(
            &robot,
            &args.data,
            &args.options,
            args.chunk_rows,
            &mut |m| spinner.say(m),
        );
        drop(spinner);
        let streamed = streamed?;
        for w in &streamed.warnings {
            eprintln!("warning: {w}");
        }
        (
            streamed.outcome,
            streamed.spaced_rows,
            Some((streamed.line, streamed.json)),
        )
    } else {
        let table = read_table(&args.data, model)?;
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
        (outcome?, table, None)
    };
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
    let file = outcome.model_file(
        &robot,
        Named {
            table: &table,
            name: &data_name,
        },
    )?;
    sim::io::write_atomic(&args.out, file.to_json().as_bytes())?;
    if let Some(path) = &args.urdf_out {
        super::urdf_out::write(path, &file, &table, &data_name)?;
    }
    if let Some(path) = &args.ur_kinematics {
        let ur = calib::model::ur_kinematics::ur_kinematics(&file)?;
        for w in &ur.warnings {
            eprintln!("warning: {}: {w}", path.display());
        }
        sim::io::write_atomic(path, ur.text.as_bytes())?;
    }
    if args.json {
        let mut doc = outcome.json(
            &robot,
            &data_name,
            Some(&args.out),
            args.urdf_out.as_deref(),
        );
        if let Some((_, s)) = &stream_info {
            doc["stream"] = s.clone();
        }
        print_json(&doc)
    } else {
        eprint!("{}", report.text());
        eprint!("{}", outcome.validation_text());
        if let Some((line, _)) = &stream_info {
            eprintln!("{line}");
        }
        eprintln!("wrote {}", args.out.display());
        if let Some(p) = &args.urdf_out {
            eprintln!("wrote {}", p.display());
        }
        if let Some(p) = &args.ur_kinematics {
            eprintln!("wrote {}", p.display());
        }
        Ok(())
    }
}

/// A calibration of a file read in pieces ([`calibrate_streamed`]).
pub struct Streamed {
    /// The calibration, as the in-memory path reports one (no validation).
    pub outcome: Outcome,
    /// Evenly spaced rows of the file: those the model file's predicted σ is computed on.
    pub spaced_rows: MeasurementTable,
    /// The `streamed:` line of the text report.
    pub line: String,
    /// The JSON report's `stream` object.
    pub json: serde_json::Value,
    /// The robot checks' warnings over the whole file, one line each.
    pub warnings: Vec<String>,
}

/// The kinematic calibration of the file `path`, read in pieces of `chunk_rows` rows
/// ([`calib::fit::stream`]), its rows checked against the robot on the first pass. The options must
/// allow it ([`Options::needs_memory`] is `None`). `progress` hears each pass's rows.
pub fn calibrate_streamed(
    robot: &Robot,
    path: &Path,
    options: &Options,
    chunk_rows: usize,
    progress: &mut dyn FnMut(&str),
) -> Result<Streamed, CliError> {
    check_chunk_rows(chunk_rows)?;
    let source = CheckedFile::new(path, chunk_rows, &robot.model);
    let (_, fit_options) = options.resolve(false)?;
    let settings = calib::fit::stream::StreamOptions {
        seed: options.seed,
        ..Default::default()
    };
    let streamed =
        calib::fit::stream::calibrate(&robot.model, &source, &fit_options, &settings, progress)?;
    let mut warnings = source.warnings();
    let (validation, split, validation_passes) = match options.plan(None) {
        (ValidationPlan::Folds { k, seed, regions }, split)
            if streamed.calibration.report.was_successful() =>
        {
            let v = calib::validate::stream::validate_streamed(
                &robot.model,
                &source,
                &fit_options,
                &streamed,
                k,
                regions,
                seed,
                settings.max_passes,
                progress,
            )?;
            warnings.extend(v.warnings);
            (Some(v.validation), split, Some(v.passes))
        }
        (ValidationPlan::Folds { .. }, split) => (None, split, None),
        _ => (None, json!({"kind": "none"}), None),
    };
    let (line, json) = describe(&streamed, validation_passes, chunk_rows);
    Ok(Streamed {
        outcome: Outcome {
            model_spec: ModelSpec::kinematic(),
            cal: streamed.calibration,
            split,
            validation,
            auto: None,
        },
        spaced_rows: streamed.spaced_rows,
        line,
        json,
        warnings,
    })
}
