//! The disk space a dataset takes: the estimate, and the refusal before any work of a campaign whose
//! files would not fit.

use super::columns::{measurement_columns, truth_column_names};
use crate::campaign::Planner;
use crate::error::{Result, SimError};
use crate::measurement_table::MeasurementTable;
use crate::scenario::Resolved;
use std::path::Path;

/// Bytes `rows` rows of a campaign of `nq` joints take on disk, estimated from the columns of the two
/// Parquet files: 8 bytes per 64-bit value, 1 per direction and flag (Snappy hardly compresses the
/// noisy values; measured: 101 and 325 bytes a row for `iiwa7_all.toml`, against 127 and 345
/// estimated), plus 1 MB of metadata.
pub fn estimated_bytes(res: &Resolved, nq: usize, has_dir: bool, rows: usize) -> u64 {
    let m = measurement_columns(has_dir, &res.tracker);
    let wide = MeasurementTable::new(nq, m).column_names().len() - if has_dir { nq } else { 0 };
    let narrow = if has_dir { nq } else { 0 };
    let truth = truth_column_names(nq, res.tracker.six_dof()).len();
    let per_row = 8 * (wide + truth - 1) + narrow + 1;
    (rows as u64)
        .saturating_mul(per_row as u64)
        .saturating_add(1 << 20)
}

/// Refuses, before any work, a campaign whose files would not fit the free space of the file system
/// that `out_dir` (or its nearest existing parent) is on, naming the counts and the sizes.
pub(super) fn check_disk(res: &Resolved, planner: &Planner<'_>, out_dir: &Path) -> Result<()> {
    let need = estimated_bytes(res, planner.nq(), planner.has_dir(), planner.rows());
    let Some(free) = crate::io::available_bytes(out_dir) else {
        return Ok(());
    };
    if need <= free {
        return Ok(());
    }
    let poses = match res.overrides.poses {
        Some(p) => format!("{p} poses (--poses)"),
        None => format!("{} poses", planner.n_poses()),
    };
    let key = if planner.repeats() > 1 {
        "campaign.repeats"
    } else {
        "campaign.poses"
    };
    Err(SimError::Scenario {
        file: res.scenario.label.clone(),
        key: key.into(),
        message: format!(
            "{poses} × {} repeats = {} measurement rows need about {} on disk ({} bytes a row, \
             estimated), but the file system of {} has {} free",
            planner.repeats(),
            planner.rows(),
            fmt_bytes(need),
            need.saturating_sub(1 << 20) / planner.rows().max(1) as u64,
            out_dir.display(),
            fmt_bytes(free)
        ),
    })
}

/// `b` bytes for people: `612.3 GB`.
fn fmt_bytes(b: u64) -> String {
    let units = ["bytes", "kB", "MB", "GB", "TB", "PB", "EB"];
    let mut v = b as f64;
    let mut u = 0;
    while v >= 1000.0 && u + 1 < units.len() {
        v /= 1000.0;
        u += 1;
    }
    if u == 0 {
        format!("{b} bytes")
    } else {
        format!("{v:.1} {}", units[u])
    }
}
