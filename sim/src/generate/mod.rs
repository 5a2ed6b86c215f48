//! The generator: a resolved scenario ([`crate::scenario::Resolved`]) in, a dataset with its ground
//! truth out.
//!
//! # Pipeline
//!
//! 1. [`crate::campaign::Planner`]: the rows (pose, q, t, temp, dir, payload), a chunk at a time
//!    ([`crate::campaign::plan`]: all at once, for campaigns held in memory).
//! 2. [`simulate`]: per row, the real robot's flange pose from the truth ([`crate::effects::Truth`],
//!    made by [`truth_of`]: with `[truth] model = "rapier"` its joint-compliance stage is settled by
//!    the rapier physics engine on the same real geometry, see [`crate::effects::rapier_compliance`])
//!    and a tracker reading ([`crate::tracker::Tracker::measure`]). Rows are
//!    independent and run in parallel (rayon); the tracker noise of pose `k`, repeat `r` comes from its
//!    own generator seeded by `(seed, k, r)` ([`crate::campaign::derive_seed`]), so the output does not
//!    depend on the number of threads or their scheduling.
//! 3. [`write_dataset`]: three files in the output folder, replaced as a set: written into a hidden
//!    staging folder beside it, then moved in ([`crate::io::StagedDir`]), so that an interrupted run
//!    leaves the old set or the new one. Steps 1–3 stream: chunk `k` is written (on a thread of its
//!    own, through [`crate::io::ParquetStream`], whose bytes do not depend on the chunking) while
//!    chunk `k + 1` is planned and simulated, and the summary accumulates in row order, so memory
//!    stays bounded (two chunks and one row group per file) and the bytes do not depend on the chunk
//!    size ([`StreamOptions`]) or the threads:
//!
//! * `measurements.parquet`: the measurement contract (`shared/spec/measurements.md`) and nothing else:
//!   `pose, q1..qN, x, y, z, [qw, qx, qy, qz], t, temp, [dir1..dirN], payload, [sigma]`. `qw..qz` only
//!   with a 6-DoF probe, `dir*` unless the direction rule is `unknown`, `sigma` unless the noise is
//!   off (scale 0). Never any truth.
//! * `truth.parquet`: one row per measurement, same order: `pose`, `repeat`; the noise-free target
//!   `p_tracker_{x,y,z}` (tracker frame, m), `p_base_{x,y,z}` (base frame, m) and the nominal robot's
//!   target `p_nominal_base_{x,y,z}`; the displacement added by each registered effect, in stage
//!   order, `{key}_{x,y,z}` with `key` = [`crate::effects::EffectId::key`] (`thermal`, `kinematic`, `transmission`,
//!   `coupling`, `coupled_transmission`, `backlash`, `compliance`, `deflection`; base frame, m; they sum
//!   to `p_base − p_nominal_base`; 0 for an absent effect); the
//!   link-side joint positions `q_link1..N` and their first-order compliance approximation
//!   `q_link_first_order1..N` (rad or m); the error added by the tracker `noise_{x,y,z}` (tracker
//!   frame, m, outliers included), the `outlier` flag, the row's `sigma_radial` and
//!   `sigma_transverse` (m), and `compliance_iterations` (Newton iterations, or engine steps with the
//!   rapier truth). With a 6-DoF probe also the true
//!   orientation `qw_true..qz_true` and the rotation error `rot_noise_{x,y,z}` (rad, tracker frame).
//!   Its column names differ from the contract's (`x`, `q1`, …), so it cannot be read as measurements.
//! * `truth.json`: the truth model (`truth_model`, and `truth` with the compliance solver, its
//!   settings and its step counts), every injected parameter resolved to numbers, the scenario (text
//!   and parsed form),
//!   the seed and overrides, the software version, the robot, the tracker placement, reflector offset
//!   and noise model, the campaign settings, and the summary statistics.
//!
//! Same resolved scenario and seed: byte-identical files.
//!
//! ```
//! use sim::scenario::{Overrides, Scenario};
//! let text = "seed = 3\n[robot]\nname = \"iiwa7\"\n[campaign]\nposes = 20\n\
//!             [effects.backlash]\ndead_band_rad = 2.9e-4\n";
//! let res = Scenario::parse(text, "inline.toml", std::path::Path::new("."))
//!     .unwrap()
//!     .resolve(&Overrides::default())
//!     .unwrap();
//! let plan = sim::generate::plan_of(&res).unwrap();
//! let truth = sim::effects::Truth::new(&res.model, &res.effects).unwrap();
//! let out = sim::generate::simulate(&truth, &res.tracker, &res.gravity, &plan, res.seed, None)
//!     .unwrap();
//! let table = sim::generate::measurement_table(&plan, &out, &res.tracker);
//! assert_eq!(table.len(), 20);
//! // Each joint shifts by half its dead band, so the target moves by at most
//! // 7 · 1.45e-4 rad · 1.3 m (the iiwa's reach) ≈ 1.3 mm.
//! for r in &out.rows {
//!     let b = r.contribution.backlash;
//!     assert!((b[0] * b[0] + b[1] * b[1] + b[2] * b[2]).sqrt() < 1.4e-3);
//! }
//! ```
//!
//! # Modules, by job
//!
//! `simulate` (step 2: truth and reading per row, the measurement table), `columns` (the
//! `truth.parquet` schema and the optional measurement columns), `summary` (the statistics, streamed),
//! `truth_json` (the provenance document), `disk` (the size estimate and the free-space check),
//! `stream` (step 3: the streaming writer) and `replay` (reading written files back).

mod columns;
mod disk;
mod replay;
mod simulate;
mod stream;
mod summary;
mod truth_json;

pub use columns::{measurement_table, truth_column_names};
pub use disk::estimated_bytes;
pub use replay::parquet_column_names;
pub use simulate::{Progress, RowTruth, Simulation, simulate, truth_of};
pub use stream::{StreamOptions, write_dataset, write_dataset_with};
pub use summary::{EffectSize, Summary};

use crate::campaign::{Plan, Planner, plan};
use crate::error::Result;
use crate::scenario::Resolved;
use std::path::Path;

/// Software version written into `truth.json`.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");

/// File names inside the output folder.
pub const MEASUREMENTS_FILE: &str = "measurements.parquet";
/// Truth per row.
pub const TRUTH_PARQUET_FILE: &str = "truth.parquet";
/// Parameters and provenance.
pub const TRUTH_JSON_FILE: &str = "truth.json";
/// Every file [`write_dataset`] writes into its output folder, in the order of [`Summary::files`].
pub const OUTPUT_FILES: [&str; 3] = [MEASUREMENTS_FILE, TRUTH_PARQUET_FILE, TRUTH_JSON_FILE];

/// The campaign rows of a resolved scenario (step 1 of the pipeline), all in memory (at most
/// [`crate::campaign::MAX_ROWS`]): for the sweep, the demo's diagnosis and tests.
pub fn plan_of(res: &Resolved) -> Result<Plan> {
    plan(&res.model, &res.campaign, res.seed, &res.scenario.label)
}

/// The campaign of a resolved scenario as a [`Planner`], which makes its rows a chunk at a time
/// ([`write_dataset`] streams them).
pub fn planner_of(res: &Resolved) -> Result<Planner<'_>> {
    Planner::new(&res.model, &res.campaign, res.seed, &res.scenario.label)
}

/// The whole pipeline: plan, simulate, write, streaming. See [`write_dataset`].
pub fn generate(res: &Resolved, out_dir: &Path, progress: Option<Progress<'_>>) -> Result<Summary> {
    write_dataset(res, out_dir, planner_of(res)?, progress)
}
