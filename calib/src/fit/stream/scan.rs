//! The first pass of a streamed fit: how many rows, which campaigns, and a seeded sample of rows to
//! start from.
//!
//! The sample is drawn by priority: every row gets a key, a seeded hash of its 0-based row number
//! ([`row_key`]), and each campaign keeps the rows of smallest key. The draw depends on the seed and
//! the row numbers only, not on how the file is cut into pieces, and it holds at most twice the
//! sample per campaign at any time. A campaign gets `max(MIN_CAMPAIGN_SAMPLE, its share of the
//! sample)` rows (all of its rows when it has fewer), so that every campaign's tracker can be
//! registered from the sample.

use super::source::ChunkSource;
use crate::cancel;
use crate::error::{CalibError, Result};
use sim::measurement_table::MeasurementTable;
use std::collections::BTreeMap;

/// Fewest rows of each campaign in the sample (when it has that many).
pub const MIN_CAMPAIGN_SAMPLE: usize = 256;

/// SplitMix64's finaliser: a bijective, well-mixing map of 64-bit words (Steele, Lea and Flood,
/// 2014).
fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// A seeded hash of a pose (its campaign and pose id): the same for every row of the pose, however
/// the file is cut into pieces. Streamed validation deals folds by it, streamed diagnose samples
/// whole poses by it.
pub fn pose_hash(seed: u64, campaign: i64, pose: i64) -> u64 {
    mix(mix(mix(seed) ^ campaign as u64) ^ pose as u64)
}

/// The sampling key of the 0-based table row `row` under `seed`.
pub fn row_key(seed: u64, row: usize) -> u64 {
    mix(mix(seed) ^ row as u64)
}

/// One campaign's candidates: rows with their keys, pruned to the `keep` smallest keys.
struct Reservoir {
    keys: Vec<(u64, usize)>,
    rows: MeasurementTable,
    rows_seen: usize,
    /// Keys above it cannot be among the smallest: the largest key kept after the last pruning.
    bar: u64,
}

impl Reservoir {
    fn prune(&mut self, keep: usize) {
        if self.keys.len() <= keep {
            return;
        }
        let mut order: Vec<usize> = (0..self.keys.len()).collect();
        order.sort_unstable_by_key(|&k| self.keys[k]);
        order.truncate(keep);
        self.rows = self.rows.select_rows(&order);
        self.keys = order.iter().map(|&k| self.keys[k]).collect();
    }

    /// The largest key kept.
    fn largest_key(&self) -> u64 {
        self.keys.iter().map(|k| k.0).max().unwrap_or(u64::MAX)
    }
}

/// What the first pass learns.
pub struct Scan {
    /// Rows of the table.
    pub rows: usize,
    /// Joint columns.
    pub n_joints: usize,
    /// Whether the table has orientation columns.
    pub orientation: bool,
    /// Campaign ids, ascending (`[0]` without a campaign column).
    pub campaigns: Vec<i64>,
    /// Runs of consecutive rows with the same campaign and pose id: the poses of a stream, whose
    /// repeats follow each other.
    pub pose_runs: usize,
    /// The sample, rows in table order.
    pub sample: MeasurementTable,
    /// The scatter of each run's repeated measurements, when a run has several rows.
    pub repeatability: Option<crate::fit::repeats::Repeatability>,
}

/// Reads every row of `source` once: counts them and draws the sample of about `sample_rows` rows
/// (module docs). `progress` hears the rows read.
pub fn scan(
    source: &dyn ChunkSource,
    sample_rows: usize,
    seed: u64,
    progress: &mut dyn FnMut(&str),
) -> Result<Scan> {
    let sample_rows = sample_rows.max(MIN_CAMPAIGN_SAMPLE);
    let mut reservoirs: BTreeMap<i64, Reservoir> = BTreeMap::new();
    let mut rows = 0;
    // An empty table of the file's columns (branch joints included), for the reservoirs and sample.
    let mut layout: Option<MeasurementTable> = None;
    let mut pose_runs = 0;
    let mut last: Option<(i64, i64)> = None;
    let mut scatter = crate::fit::repeats::RepeatScatter::default();
    for chunk in source.pass()? {
        cancel::checkpoint()?;
        let chunk = chunk?;
        let t = &chunk.table;
        if chunk.first_row != rows {
            return Err(CalibError::BadValue {
                context: source.name().to_string(),
                field: "rows".into(),
                value: chunk.first_row.to_string(),
                problem: format!(
                    "a piece starts at row {}, after {rows} rows",
                    chunk.first_row
                ),
            });
        }
        let empty = &*layout.get_or_insert_with(|| t.empty_like(0));
        for r in 0..t.len() {
            let key = t.pose_key(r);
            if last != Some(key) {
                pose_runs += 1;
                last = Some(key);
            }
            scatter.add(key, t.position[r]);
            let campaign = t.campaign_of(r).unwrap_or(0);
            let res = reservoirs.entry(campaign).or_insert_with(|| Reservoir {
                keys: Vec::new(),
                rows: empty.empty_like(0),
                rows_seen: 0,
                bar: u64::MAX,
            });
            res.rows_seen += 1;
            let k = row_key(seed, chunk.first_row + r);
            if k > res.bar {
                continue;
            }
            res.keys.push((k, chunk.first_row + r));
            res.rows.push_row(&t.row(r))?;
            if res.keys.len() >= 2 * sample_rows {
                res.prune(sample_rows);
                res.bar = res.largest_key();
            }
        }
        rows += t.len();
        progress(&format!("reading {}: {rows} rows", source.name()));
    }
    let Some(empty) = layout else {
        return Err(CalibError::BadValue {
            context: source.name().to_string(),
            field: "rows".into(),
            value: "0".into(),
            problem: "no rows to calibrate on".into(),
        });
    };
    // Each campaign's share, the smallest keys of each.
    for res in reservoirs.values_mut() {
        let share =
            (sample_rows as f64 * res.rows_seen as f64 / rows.max(1) as f64).round() as usize;
        res.prune(share.max(MIN_CAMPAIGN_SAMPLE));
    }
    // Rows in table order.
    let mut order: Vec<(usize, i64, usize)> = Vec::new();
    for (campaign, res) in &reservoirs {
        for (i, &(_, row)) in res.keys.iter().enumerate() {
            order.push((row, *campaign, i));
        }
    }
    order.sort_unstable();
    let mut sample = empty.empty_like(order.len());
    for (_, campaign, i) in order {
        sample.push_row(&reservoirs[&campaign].rows.row(i))?;
    }
    Ok(Scan {
        rows,
        n_joints: empty.n_joints,
        orientation: empty.orientation.is_some(),
        campaigns: reservoirs.keys().copied().collect(),
        pose_runs,
        sample,
        repeatability: scatter.finish(),
    })
}
