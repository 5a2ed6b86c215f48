//! `robocal register`: a new measurement campaign (the tracker was moved) for a calibrated model.

use super::paths::Inputs;
use super::shared::{CliResult, print_json, read_table};
use calib::model_file::{CalibratedModel, Predictor};
use calib::register::{RegisterOptions, register};
use serde_json::json;
use std::path::PathBuf;

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
    /// Also fit the campaign's own target offset (a re-seated reflector).
    #[arg(long)]
    target: bool,
    /// Refit the registration of this campaign, which the model knows, instead of adding one.
    #[arg(long, value_name = "ID")]
    campaign: Option<i64>,
    /// Print one JSON document on stdout instead of text on stderr.
    #[arg(long)]
    json: bool,
}

/// Runs `robocal register`.
pub fn run(args: Args) -> CliResult {
    let mut inputs = Inputs::new();
    inputs.add("--model", &args.model).add("--data", &args.data);
    inputs.check("--out", &args.out)?;
    let file = CalibratedModel::load(&args.model)?;
    let predictor = Predictor::from_file(&file)?;
    let table = read_table(&args.data, &predictor.model)?;
    let model_rms = file
        .fit
        .as_ref()
        .map(|f| f.held_out_rms_m.unwrap_or(f.train_rms_m));
    let options = RegisterOptions {
        target: args.target,
        campaign: args.campaign,
        ..RegisterOptions::default()
    };
    let name = args.data.display().to_string();
    let reg = register(
        &predictor.model,
        &predictor.params,
        predictor.extensions.as_ref(),
        predictor.learned.as_ref(),
        model_rms,
        &table,
        &name,
        &options,
    )?;
    let out = file.registered(&predictor.model, &reg);
    sim::io::write_atomic(&args.out, out.to_json().as_bytes())?;
    if args.json {
        print_json(&json!({
            "model": args.model.display().to_string(),
            "data": name,
            "out": args.out.display().to_string(),
            "report": reg.report,
        }))
    } else {
        eprint!("{}", reg.report.text());
        eprintln!("wrote {}", args.out.display());
        Ok(())
    }
}
