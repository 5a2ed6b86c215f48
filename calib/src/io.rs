//! The small CSV outputs of `predict` and `plan-poses`, and the joint-only CSV input of `predict`.
//! Files are written with [`sim::io::write_atomic`], the project's one atomic writer.

use crate::error::{CalibError, Result};
use std::path::Path;

/// CSV text: a header and rows of an integer id followed by floats, each float written as the shortest
/// decimal that reads back to the same `f64`.
pub fn csv_text(header: &[String], rows: &[(i64, Vec<f64>)]) -> String {
    let mut s = header.join(",");
    s.push('\n');
    for (id, values) in rows {
        s.push_str(&id.to_string());
        for v in values {
            s.push(',');
            s.push_str(&format!("{v:?}"));
        }
        s.push('\n');
    }
    s
}

/// Reads a CSV of joint configurations without measured positions (`pose, q1..qN` and any optional
/// columns of the measurement contract: `t`, `temp`, `dir1..dirN`, `payload`, …), as `plan-poses`
/// writes it, into a [`sim::measurement_table::MeasurementTable`] whose positions are zero. For
/// `predict`, whose input needs no `x, y, z`. The file is read by the contract's own CSV reader, so
/// errors name the file, the row and the column as for any measurement table.
pub fn read_joint_csv(path: &Path) -> Result<sim::measurement_table::MeasurementTable> {
    let file = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| CalibError::Read {
        path: file.clone(),
        message: e.to_string(),
    })?;
    let mut out = String::with_capacity(text.len() + 16 * text.lines().count());
    let mut header = true;
    for line in text.trim_start_matches('\u{feff}').lines() {
        if line.trim().is_empty() {
            continue;
        }
        out.push_str(line.trim_end_matches('\r'));
        out.push_str(if header { ",x,y,z\n" } else { ",0,0,0\n" });
        header = false;
    }
    Ok(sim::measurement_table::read_csv_str(&out, &file)?)
}
