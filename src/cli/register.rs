//! `robocal register`: a new measurement campaign (the tracker was moved) for a calibrated model.

use super::calibrate::Named;
use super::calibrate_stream::decide_stream;
use super::calibrate_stream::{CheckedFile, StreamMode, check_chunk_rows};
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
    /// Read the data in pieces, in bounded memory: `auto` streams a table of more than 262,144
    /// rows (positions only), `always` any table, `never` none.
    #[arg(long, value_name = "auto|always|never", value_enum, default_value_t = StreamMode::Auto)]
    stream: StreamMode,
    /// Rows read at a time when streaming.
    #[arg(long, value_name = "N", default_value_t = sim::measurement_table::DEFAULT_CHUNK_ROWS)]
    chunk_rows: usize,
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
    let model_rms = model_rms(file);
    let options = register_options(options);
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

/// The model's own RMS error: held-out when the file has it, else on its calibration rows (m).
fn model_rms(file: &CalibratedModel) -> Option<f64> {
    file.fit
        .as_ref()
        .map(|f| f.held_out_rms_m.unwrap_or(f.train_rms_m))
}

fn register_options(options: &Options) -> RegisterOptions {
    RegisterOptions {
        target: options.target,
        campaign: options.campaign,
        ..RegisterOptions::default()
    }
}

/// Registers the campaign of the file `path`, read in pieces of `chunk_rows` rows and checked
/// against the robot on the first pass ([`calib::fit::stream::register`]): the model with the
/// campaign, the report, the robot checks' warnings and the JSON `stream` object.
pub fn register_streamed(
    file: &CalibratedModel,
    path: &Path,
    options: &Options,
    chunk_rows: usize,
) -> Result<
    (
        CalibratedModel,
        RegistrationReport,
        Vec<String>,
        serde_json::Value,
    ),
    CliError,
> {
    check_chunk_rows(chunk_rows)?;
    let predictor = Predictor::from_file(file)?;
    let source = CheckedFile::new(path, chunk_rows, &predictor.model);
    let streamed = calib::fit::stream::register::register_streamed(
        &predictor.model,
        &predictor.params,
        predictor.extensions.as_ref(),
        predictor.learned.as_ref(),
        model_rms(file),
        &source,
        &register_options(options),
        &calib::fit::stream::StreamOptions::default(),
        &mut |_| {},
    )?;
    let info = json!({
        "rows": streamed.rows,
        "passes": streamed.passes,
        "chunk_rows": chunk_rows,
        "sample_rows": streamed.sample_rows,
    });
    Ok((
        file.registered(&predictor.model, &streamed.registration),
        streamed.registration.report,
        source.warnings(),
        info,
    ))
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
    check_chunk_rows(args.chunk_rows)?;
    let name = args.data.display().to_string();
    let (stream, _) = decide_stream(args.stream, &args.data, None, &robot)?;
    let (out, report, info) = if stream {
        let (out, report, warnings, info) =
            register_streamed(&file, &args.data, &args.options, args.chunk_rows)?;
        for w in warnings {
            eprintln!("warning: {w}");
        }
        (out, report, Some(info))
    } else {
        let table = read_table(&args.data, &robot)?;
        let data = Named {
            table: &table,
            name: &name,
        };
        let (out, report) = register(&file, data, &args.options)?;
        (out, report, None)
    };
    sim::io::write_atomic(&args.out, out.to_json().as_bytes())?;
    if args.json {
        let mut doc = json(Some(&args.model), &name, Some(&args.out), &report);
        if let Some(info) = info {
            doc["stream"] = info;
        }
        print_json(&doc)
    } else {
        eprint!("{}", report.text());
        if let Some(info) = info {
            eprintln!(
                "streamed: {} rows in {} passes of pieces of up to {} rows, starting from the \
                 registration of a seeded sample of {} rows",
                info["rows"], info["passes"], info["chunk_rows"], info["sample_rows"]
            );
        }
        eprintln!("wrote {}", args.out.display());
        Ok(())
    }
}
