//! Step 3 of the pipeline, streaming: plan, simulate and write chunk by chunk into a staged output
//! folder, the summary accumulated in row order (see [`super`]).

use super::columns::{measurement_columns, measurement_table, truth_batch, truth_schema};
use super::disk::check_disk;
use super::replay::replay_distances;
use super::simulate::{Progress, Simulation, simulate, truth_of};
use super::summary::{self, Summary, summarize};
use super::truth_json::truth_json;
use super::{MEASUREMENTS_FILE, OUTPUT_FILES, TRUTH_JSON_FILE, TRUTH_PARQUET_FILE};
use crate::campaign::{Plan, Planner};
use crate::effects::EffectId;
use crate::error::{Result, SimError};
use crate::io::{AtomicFile, write_atomic};
use crate::measurement_table;
use crate::scenario::Resolved;
use std::path::Path;

/// Tuning of the streaming generator ([`write_dataset_with`]). Neither setting changes a byte of the
/// output: they trade memory against speed only.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StreamOptions {
    /// Rows planned, simulated and handed to the file writers at a time (≥ 1).
    pub chunk_rows: usize,
    /// Up to this many rows the median target distance of the summary is selected in memory (8 bytes
    /// a row); beyond, by a radix selection that reads `truth.parquet` again once written (see
    /// `generate/summary.rs`).
    pub median_in_memory_rows: usize,
}

impl Default for StreamOptions {
    /// 16,384 rows a chunk (about 15 MB of plan, simulation and Arrow arrays for the iiwa 7 with
    /// every effect); the median in memory up to 2,097,152 rows (16 MB).
    fn default() -> Self {
        StreamOptions {
            chunk_rows: 1 << 14,
            median_in_memory_rows: 1 << 21,
        }
    }
}

/// Plans, simulates and writes the dataset of `res` into `out_dir` (created if missing), streaming:
/// rows are planned, simulated and written in chunks ([`StreamOptions::default`]), so memory does not
/// grow with the number of rows. The three files replace an earlier set as a whole
/// ([`crate::io::StagedDir`]: written into a staging folder beside `out_dir`, then moved in; other
/// files in `out_dir` are kept). A campaign whose files would not fit the free disk space is refused
/// before any work. Returns the summary. `progress` is called from worker threads with rows finished
/// (the total is [`Planner::rows`]).
pub fn write_dataset(
    res: &Resolved,
    out_dir: &Path,
    planner: Planner<'_>,
    progress: Option<Progress<'_>>,
) -> Result<Summary> {
    write_dataset_with(res, out_dir, planner, progress, &StreamOptions::default())
}

/// [`write_dataset`] with chosen [`StreamOptions`] (the bytes written are the same for any).
pub fn write_dataset_with(
    res: &Resolved,
    out_dir: &Path,
    mut planner: Planner<'_>,
    progress: Option<Progress<'_>>,
    options: &StreamOptions,
) -> Result<Summary> {
    let truth = truth_of(res)?;
    check_disk(res, &planner, out_dir)?;
    let (nq, six_dof) = (planner.nq(), res.tracker.six_dof());
    let (poses, rows, repeats) = (planner.n_poses(), planner.rows(), planner.repeats());
    // Every file goes into a staging folder beside `out_dir`; the set replaces the old one as a whole
    // once all three are written (sim::io::StagedDir; files of the user's in `out_dir` are kept).
    let stage = crate::io::StagedDir::new(out_dir)?;
    let written = (|| -> Result<Summary> {
        let dir = stage.path();
        let (m_path, t_path, j_path) = (
            dir.join(MEASUREMENTS_FILE),
            dir.join(TRUTH_PARQUET_FILE),
            dir.join(TRUTH_JSON_FILE),
        );
        let mut measurements = measurement_table::ParquetTableWriter::with_branch_names(
            AtomicFile::create(&m_path)?,
            res.model.n_drives(),
            measurement_columns(planner.has_dir(), &res.tracker),
            &planner.branch_names(),
            &m_path.display().to_string(),
        )?;
        let truth_err = |e: parquet::errors::ParquetError| SimError::Io {
            path: t_path.clone(),
            source: std::io::Error::other(e.to_string()),
        };
        let group = measurement_table::PARQUET_MAX_ROW_GROUP_ROWS;
        let mut truth_rows = crate::io::ParquetStream::new(
            AtomicFile::create(&t_path)?,
            truth_schema(nq, six_dof),
            crate::io::deterministic_writer_properties(group).build(),
            group,
        )
        .map_err(truth_err)?;
        let ids: Vec<EffectId> = res.effects.ids().collect();
        let mut stats = summary::Accumulator::new(ids, rows, options.median_in_memory_rows);
        // Chunk k is written on a thread of its own while chunk k + 1 is planned and simulated (the
        // simulation on the rayon pool): at most two chunks in memory. Chunks are allocated on this
        // thread and the Arrow arrays on the writer's, whatever the number of pool threads, so the
        // allocator keeps no chunk-sized leftovers in one arena per thread (measured: 220 MB resident
        // with 8 threads when the write ran on whichever pool thread was free, against 105 MB with 1).
        // Errors come in row order: a chunk's write failure before the next chunk's simulation's.
        let (send, receive) = std::sync::mpsc::sync_channel::<(Plan, Simulation)>(0);
        let (written, simulated) = std::thread::scope(|scope| {
            let writer = scope.spawn(|| -> Result<()> {
                for (plan, sim) in receive {
                    measurements.append(&measurement_table(&plan, &sim, &res.tracker))?;
                    truth_rows
                        .write(&truth_batch(&plan, &sim, six_dof)?)
                        .map_err(truth_err)?;
                    stats.add(&sim);
                }
                Ok(())
            });
            let simulated = (|| -> Result<()> {
                while let Some(plan) = planner.next_chunk(options.chunk_rows.max(1))? {
                    let sim = simulate(
                        &truth,
                        &res.tracker,
                        &res.gravity,
                        &plan,
                        res.seed,
                        progress,
                    )
                    .map_err(|e| match e {
                        SimError::Scenario { key, message, .. } => SimError::Scenario {
                            file: res.scenario.label.clone(),
                            key,
                            message,
                        },
                        other => other,
                    })?;
                    if send.send((plan, sim)).is_err() {
                        // The writer stopped on an error, which it returns.
                        break;
                    }
                }
                Ok(())
            })();
            drop(send);
            let written = writer
                .join()
                .unwrap_or_else(|panic| std::panic::resume_unwind(panic));
            (written, simulated)
        });
        written?;
        simulated?;
        measurements.finish()?.commit()?;
        truth_rows.finish().map_err(truth_err)?.commit()?;
        let totals = stats.finish();
        let median = stats
            .median
            .select(|visit| replay_distances(&t_path, visit))?;
        let files = OUTPUT_FILES
            .iter()
            .map(|n| out_dir.join(n).display().to_string())
            .collect();
        let summary = summarize(res, (poses, rows), totals, median, files);
        let doc = truth_json(res, (nq, repeats), &summary);
        let mut text = serde_json::to_string_pretty(&doc).map_err(|e| SimError::Io {
            path: j_path.clone(),
            source: std::io::Error::other(e.to_string()),
        })?;
        text.push('\n');
        write_atomic(&j_path, text.as_bytes())?;
        Ok(summary)
    })()
    .map_err(|e| stage.user_error(e))?;
    stage.commit(&|name| OUTPUT_FILES.contains(&name))?;
    Ok(written)
}
