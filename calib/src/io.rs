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

/// Reads a CSV of joint configurations without measured positions (`pose, q1..qN`, other columns
/// ignored), as `plan-poses` writes it, into a [`sim::measurement_table::MeasurementTable`] whose
/// positions are zero. For `predict`, whose input needs no `x, y, z`. Errors name the file, the row
/// and the column.
pub fn read_joint_csv(path: &Path) -> Result<sim::measurement_table::MeasurementTable> {
    use sim::measurement_table::{MeasurementTable, OptionalColumns, Row};
    let file = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| CalibError::Io {
        path: file.clone(),
        message: e.to_string(),
    })?;
    let bad = |row: Option<usize>, column: &str, value: &str, problem: &str| CalibError::BadValue {
        context: match row {
            Some(r) => format!("{file}: row {r}"),
            None => file.clone(),
        },
        field: column.to_string(),
        value: value.to_string(),
        problem: problem.to_string(),
    };
    let mut lines = text
        .trim_start_matches('\u{feff}')
        .lines()
        .filter(|l| !l.trim().is_empty());
    let header: Vec<String> = lines
        .next()
        .ok_or_else(|| bad(None, "header", "", "the file is empty"))?
        .split(',')
        .map(|c| c.trim().trim_matches('"').to_string())
        .collect();
    let pose_col = header
        .iter()
        .position(|c| c == "pose")
        .ok_or_else(|| bad(None, "pose", "", "missing required column"))?;
    let mut q_cols = Vec::new();
    while let Some(c) = header
        .iter()
        .position(|h| *h == format!("q{}", q_cols.len() + 1))
    {
        q_cols.push(c);
    }
    if q_cols.is_empty() {
        return Err(bad(None, "q1", "", "missing required column"));
    }
    let mut t = MeasurementTable::new(q_cols.len(), OptionalColumns::NONE);
    let mut q = vec![0.0; q_cols.len()];
    for (i, line) in lines.enumerate() {
        let row = i + 1;
        let cells: Vec<&str> = line
            .split(',')
            .map(|c| c.trim().trim_matches('"'))
            .collect();
        let cell = |c: usize, name: &str| -> Result<&str> {
            cells
                .get(c)
                .copied()
                .ok_or_else(|| bad(Some(row), name, "", "the row is too short"))
        };
        let ps = cell(pose_col, "pose")?;
        let pose: i64 = ps
            .parse()
            .map_err(|_| bad(Some(row), "pose", ps, "not an integer"))?;
        for (j, &c) in q_cols.iter().enumerate() {
            let name = format!("q{}", j + 1);
            let s = cell(c, &name)?;
            let v: f64 = s
                .parse()
                .map_err(|_| bad(Some(row), &name, s, "not a number"))?;
            if !v.is_finite() {
                return Err(bad(Some(row), &name, s, "not finite"));
            }
            q[j] = v;
        }
        t.push_row(&Row {
            pose,
            q: &q,
            position: [0.0; 3],
            ..Row::default()
        })?;
    }
    if t.is_empty() {
        return Err(bad(None, "rows", "0", "no data rows"));
    }
    Ok(t)
}
