//! `robocal predict`: where a calibrated model says the target is, for every row of a table.

use super::paths::{Inputs, check_distinct};
use super::shared::{CliError, CliResult, print_json};
use calib::model::file::CalibratedModel;
use calib::model::predict::{Predictor, SIGMA_BEYOND_CALIBRATION, SIGMA_MATTERS, SIGMA_OUTSIDE};
use calib::model::uncertainty::Prior;
use serde_json::json;
use sim::measurement_table::{self, DEFAULT_CHUNK_ROWS, MeasurementTable, ModelCheck};
use std::path::{Path, PathBuf};

/// Arguments of `robocal predict`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Calibrated model written by `robocal calibrate`.
    #[arg(long, value_name = "MODEL.json")]
    model: PathBuf,
    /// Joint configurations: a measurement table (CSV or Parquet) whose x, y, z may be absent (and are
    /// ignored when present), e.g. `pose, q1..qN`.
    #[arg(long, value_name = "FILE")]
    data: PathBuf,
    /// Where to write `pose,x,y,z` (and `qw,qx,qy,qz` with orientation), tracker frame, m.
    #[arg(long, value_name = "PRED.csv")]
    out: PathBuf,
    /// Also write the calibrated URDF: the model's URDF with the chain's joint origins moved to the
    /// calibrated robot, everything else kept, base and target transforms in a comment.
    #[arg(long, value_name = "FILE.urdf")]
    urdf_out: Option<PathBuf>,
    /// Prior standard deviation of a length the calibration data did not determine (joint twist
    /// translations, target position), in metres: the nominal geometry's tolerance, for `sigma_m`.
    #[arg(long, value_name = "M", default_value_t = 1e-3)]
    prior_length: f64,
    /// Prior standard deviation of an angle the calibration data did not determine (joint twist
    /// rotations, zero offsets), in radians, for `sigma_m`.
    #[arg(long, value_name = "RAD", default_value_t = 1e-3)]
    prior_angle: f64,
    /// Rows read, predicted and written at a time: memory holds one piece of this many rows (and
    /// its predictions), whatever the file's length. CSV is read in pieces of about 256 bytes a row of
    /// text, at most 8 MiB.
    #[arg(long, value_name = "N", default_value_t = DEFAULT_CHUNK_ROWS)]
    chunk_rows: usize,
    /// Print one JSON summary on stdout instead of text on stderr.
    #[arg(long)]
    json: bool,
}

/// Checks a table of joint configurations against the model's robot (joint count, limits, units);
/// `name` names it in messages. Returns the warnings, one line each.
pub fn check_configurations(
    table: &MeasurementTable,
    robot: &sim::Model,
    name: &str,
) -> Result<Vec<String>, CliError> {
    // A robot with coupled joints: the driven joints' columns, checked as the whole chain.
    let table = measurement_table::whole_chain(table, robot, Path::new(name))?;
    if table.n_joints != robot.nq() {
        return Err(CliError::Input(format!(
            "{name}: {} joint columns, but the model's robot '{}' has {} joints",
            table.n_joints,
            robot.name(),
            robot.nq()
        )));
    }
    Ok(measurement_table::check_against_model(
        &table,
        robot,
        Path::new(name),
    )?)
}

/// Runs `robocal predict`.
pub fn run(args: Args) -> CliResult {
    let mut inputs = Inputs::new();
    inputs.add("--model", &args.model).add("--data", &args.data);
    inputs.check("--out", &args.out)?;
    if let Some(u) = &args.urdf_out {
        inputs.check("--urdf-out", u)?;
        check_distinct(("--out", &args.out), ("--urdf-out", u))?;
    }
    for (flag, v) in [
        ("--prior-length", args.prior_length),
        ("--prior-angle", args.prior_angle),
    ] {
        if !(v.is_finite() && v > 0.0) {
            return Err(CliError::Input(format!(
                "{flag} {v}: a prior standard deviation is a finite number > 0"
            )));
        }
    }
    let file = CalibratedModel::load(&args.model)?;
    let mut predictor = Predictor::from_file(&file)?;
    let prior = Prior {
        length_m: args.prior_length,
        angle_rad: args.prior_angle,
    };
    // The predictor comes with the default prior; another one is set up once more.
    if prior != Prior::default() {
        predictor.set_prior(&file, &prior);
    }
    let name = args.data.display().to_string();
    if args.chunk_rows == 0 {
        return Err(CliError::Input(
            "--chunk-rows 0: a piece holds at least 1 row".into(),
        ));
    }
    let summary = predict_streaming(&mut predictor, &args.data, &args.out, args.chunk_rows)?;
    if let Some(path) = &args.urdf_out {
        super::urdf_out::write(path, &file, &summary.first_rows, &name)?;
    }
    if args.json {
        print_json(&json!({
            "model": args.model.display().to_string(),
            "robot": predictor.model.name(),
            "rows": summary.rows,
            "orientation": summary.orientation,
            "sigma_m": summary.sigma_m,
            "outside_support": summary.outside_support,
            "out": args.out.display().to_string(),
            "urdf_out": args.urdf_out.as_ref().map(|p| p.display().to_string()),
        }))
    } else {
        eprintln!(
            "predicted {} rows with the calibrated '{}' model; wrote {}",
            summary.rows,
            predictor.model.name(),
            args.out.display()
        );
        eprintln!(
            "{}",
            support_line(
                &predictor,
                summary.rows,
                summary.outside_support,
                summary.sigma_m
            )
        );
        if let Some(p) = &args.urdf_out {
            eprintln!("wrote {}", p.display());
        }
        Ok(())
    }
}

/// What [`predict_streaming`] wrote.
pub struct StreamSummary {
    /// Rows predicted.
    pub rows: usize,
    /// Rows marked `outside_support`.
    pub outside_support: usize,
    /// Whether the output has `qw, qx, qy, qz`.
    pub orientation: bool,
    /// Whether the output has `sigma_m`.
    pub sigma_m: bool,
    /// The first piece's rows (for `--urdf-out`, which compares at the first 200).
    pub first_rows: MeasurementTable,
}

/// Predicts every row of the configurations file `data` into the CSV file `out`, piece by piece
/// ([`measurement_table::read_configuration_chunks`], `chunk_rows` rows): memory holds one
/// piece and its predictions, whatever the file's length. Each piece is checked against the robot
/// ([`ModelCheck`]: errors name file-wide rows); the warnings go to stderr at the end. `out` is
/// written atomically: an error leaves it as it was. The Python API's `Model.predict_file` calls it.
pub fn predict_streaming(
    predictor: &mut Predictor,
    data: &Path,
    out: &Path,
    chunk_rows: usize,
) -> Result<StreamSummary, CliError> {
    use std::io::Write;
    let name = data.display().to_string();
    let chunks = measurement_table::read_configuration_chunks(data, chunk_rows)?;
    let robot = predictor.model.clone();
    // A robot with coupled joints: a file of its driven joints, each piece completed
    // ([`measurement_table::couple`]).
    let coupled = !robot.couplings().is_empty() && chunks.n_joints() == robot.n_drives();
    if chunks.n_joints() != robot.nq() && !coupled {
        return Err(CliError::Input(format!(
            "{name}: {} joint columns, but the model's robot '{}' has {} joints",
            chunks.n_joints(),
            robot.name(),
            robot.nq()
        )));
    }
    let mut check = ModelCheck::new(&robot, data);
    let mut file = sim::io::AtomicFile::create(out)?;
    let mut summary = StreamSummary {
        rows: 0,
        outside_support: 0,
        orientation: false,
        sigma_m: false,
        first_rows: MeasurementTable::new(robot.nq(), Default::default()),
    };
    for chunk in chunks {
        let mut chunk = chunk?;
        if coupled {
            chunk.table = measurement_table::couple(chunk.table, &robot, data)?;
        }
        check.add(&chunk.table, chunk.first_row)?;
        let preds = predictor.predict_table(&chunk.table, &name)?;
        if summary.rows == 0 {
            file.write_all(preds.csv_header().as_bytes())
                .map_err(|e| file.error(e))?;
            summary.orientation = preds.orientation.is_some();
            summary.sigma_m = preds.sigma_m.is_some();
            summary.first_rows = chunk.table.clone();
        }
        file.write_all(preds.csv_rows().as_bytes())
            .map_err(|e| file.error(e))?;
        summary.rows += chunk.table.len();
        summary.outside_support += preds.n_outside_support();
    }
    for w in check.warnings() {
        eprintln!("warning: {w}");
    }
    file.commit()?;
    Ok(summary)
}

/// One line on stderr: how many of `rows` predictions lie outside the model's support (`outside`),
/// and why that matters (`sigma_m`: whether they had a predicted standard deviation).
pub fn support_line(predictor: &Predictor, rows: usize, outside: usize, sigma_m: bool) -> String {
    let n = rows;
    let mut why = Vec::new();
    if predictor.learned.as_ref().is_some_and(|l| l.is_active()) {
        why.push("beyond the configurations its learned correction was fitted on (the correction is faded out there)".to_string());
    }
    if let Some(h) = predictor.held_out_rms_m.filter(|_| sigma_m) {
        why.push(format!(
            "with sigma_m above {SIGMA_OUTSIDE} × its held-out RMS ({:.4} mm)",
            h * 1e3
        ));
    }
    if let (Some(c), Some(h)) = (
        predictor.calibration_sigma_m,
        predictor.held_out_rms_m.filter(|_| sigma_m),
    ) {
        why.push(format!(
            "with sigma_m above both {SIGMA_BEYOND_CALIBRATION} × its 95th percentile on the calibration poses \
             ({:.4} mm) and {SIGMA_MATTERS:.2} × the held-out RMS ({:.4} mm; enough to raise the error by 20 %): \
             parameter combinations the calibration determined far less well than where it was validated",
            c * 1e3,
            h * 1e3
        ));
    }
    if why.is_empty() {
        return format!(
            "outside_support: {outside} of {n} rows (the model has no learned correction and no held-out error to compare sigma_m with)"
        );
    }
    format!(
        "outside_support: {outside} of {n} rows ({}): expect larger errors there",
        why.join("; or ")
    )
}
