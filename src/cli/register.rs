//! `robocal register`: a new measurement campaign (the tracker was moved) for a calibrated model.

use super::calibrate::Named;
use super::paths::Inputs;
use super::shared::{CliError, CliResult, print_json, read_table};
use calib::fit::register::{RegisterOptions, RegistrationReport, register as register_campaign};
use calib::model::file::CalibratedModel;
use calib::model::predict::Predictor;
use serde_json::json;
use std::path::{Path, PathBuf};

/// Arguments of `robocal register`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Calibrated model written by `robocal calibrate` (or by an earlier `register`).
    #[arg(long, value_name = "MODEL.json")]
    model: PathBuf,
    /// Measurements of the new campaign (the measurement contract; a `campaign` column, if any,
    /// must hold one id, which the new campaign takes).
    #[arg(long, value_name = "FILE")]
    data: PathBuf,
    /// Where to write the model with the campaign registered; rows without a `campaign` column
    /// are predicted in it.
    #[arg(long, value_name = "MODEL2.json")]
    out: PathBuf,
    #[command(flatten)]
    options: Options,
    /// Print one JSON document on stdout instead of text on stderr.
    #[arg(long)]
    json: bool,
}

/// The value flags of `robocal register`: one definition for the command line and the Python
/// package (`Model.register(data, **options)`, parsed by [`super::flags::parse`]).
#[derive(clap::Args, Debug, Clone)]
pub struct Options {
    /// Also fit the campaign's own target offset (a re-seated reflector).
    #[arg(long)]
    pub target: bool,
    /// Refit the registration of this campaign, which the model knows, instead of adding one.
    #[arg(long, value_name = "ID")]
    pub campaign: Option<i64>,
}

/// Registers the campaign measured in `data` for the model `file`, as `robocal register` does with
/// `options`: the model with the campaign registered (every robot parameter kept) and the
/// registration's report.
pub fn register(
    file: &CalibratedModel,
    data: Named<'_>,
    options: &Options,
) -> Result<(CalibratedModel, RegistrationReport), CliError> {
    let predictor = Predictor::from_file(file)?;
    let model_rms = file
        .fit
        .as_ref()
        .map(|f| f.held_out_rms_m.unwrap_or(f.train_rms_m));
    let options = RegisterOptions {
        target: options.target,
        campaign: options.campaign,
        ..RegisterOptions::default()
    };
    let reg = register_campaign(
        &predictor.model,
        &predictor.params,
        predictor.extensions.as_ref(),
        predictor.learned.as_ref(),
        model_rms,
        data.table,
        data.name,
        &options,
    )?;
    Ok((file.registered(&predictor.model, &reg), reg.report))
}

/// The `register --json` document: `model` and `out` name the files read and written (null when
/// none, as from Python).
pub fn json(
    model: Option<&Path>,
    data: &str,
    out: Option<&Path>,
    report: &RegistrationReport,
) -> serde_json::Value {
    json!({
        "model": model.map(|p| p.display().to_string()),
        "data": data,
        "out": out.map(|p| p.display().to_string()),
        "report": report,
    })
}

/// Runs `robocal register`.
pub fn run(args: Args) -> CliResult {
    let mut inputs = Inputs::new();
    inputs.add("--model", &args.model).add("--data", &args.data);
    inputs.check("--out", &args.out)?;
    let file = CalibratedModel::load(&args.model)?;
    let robot = Predictor::from_file(&file)?.model;
    let table = read_table(&args.data, &robot)?;
    let name = args.data.display().to_string();
    let data = Named {
        table: &table,
        name: &name,
    };
    let (out, report) = register(&file, data, &args.options)?;
    sim::io::write_atomic(&args.out, out.to_json().as_bytes())?;
    if args.json {
        print_json(&json(Some(&args.model), &name, Some(&args.out), &report))
    } else {
        eprint!("{}", report.text());
        eprintln!("wrote {}", args.out.display());
        Ok(())
    }
}
