//! Writing files atomically, and the small CSV outputs of `predict` and `plan-poses`.

use crate::error::{CalibError, Result};
use std::path::Path;

/// Writes `bytes` to a temporary file in `path`'s folder, syncs it and renames it over `path`.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    use std::io::Write;
    use std::sync::atomic::{AtomicU64, Ordering};
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let err = |e: std::io::Error| CalibError::Io {
        path: path.display().to_string(),
        message: e.to_string(),
    };
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => std::path::PathBuf::from("."),
    };
    let name = path
        .file_name()
        .ok_or_else(|| CalibError::Io {
            path: path.display().to_string(),
            message: "not a file name".into(),
        })?
        .to_string_lossy()
        .into_owned();
    let tmp = dir.join(format!(
        ".{name}.tmp-{}-{}",
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    ));
    let result = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        drop(f);
        std::fs::rename(&tmp, path)
    })();
    result.map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        err(e)
    })
}

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
    let text = std::fs::read_to_string(path).map_err(|e| CalibError::Io {
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
