//! `--urdf-out` of `calibrate` and `predict`: the calibrated URDF ([`calib::model::urdf_export`]), checked
//! before it is written.

use super::shared::CliError;
use calib::CalibratedModel;
use calib::model::urdf_export::{calibrated_urdf, unexpressed_gap};
use sim::measurement_table::MeasurementTable;
use std::path::Path;

/// Largest deviation (m, or rotation-matrix entry) of the written file's forward kinematics from the
/// calibrated model that is accepted; beyond it nothing is written.
const MAX_DEVIATION: f64 = 1e-9;

/// Writes the calibrated URDF of `file` to `path` (atomically), after checking its forward kinematics
/// against the model at the configurations of the first 200 rows of `table` (`table_name` in
/// messages). Warnings (what the file cannot express, with the largest gap on `table`) go to stderr.
pub fn write(
    path: &Path,
    file: &CalibratedModel,
    table: &MeasurementTable,
    table_name: &str,
) -> Result<(), CliError> {
    let urdf = calibrated_urdf(file)?;
    let model = file.robot_model()?;
    let params = file.params();
    let configs: Vec<Vec<f64>> = (0..table.len().min(200))
        .map(|r| table.q_row(r).to_vec())
        .collect();
    let dev = urdf.deviation(&model, &params, &configs)?;
    if dev > MAX_DEVIATION {
        return Err(CliError::Runtime(format!(
            "{}: the calibrated URDF deviates from the model by {dev:.1e} (m or rotation entry); not written",
            path.display()
        )));
    }
    let gap = unexpressed_gap(file, table, table_name)?;
    for w in &urdf.warnings {
        eprintln!("warning: {}: {w}", path.display());
    }
    if gap > 0.0 {
        eprintln!(
            "warning: {}: on {table_name} its target positions differ from the full model's by up to {:.3} mm",
            path.display(),
            gap * 1e3
        );
    }
    sim::io::write_atomic(path, urdf.text.as_bytes())?;
    Ok(())
}
