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
//!   order, `{key}_{x,y,z}` with `key` = [`EffectId::key`] (`thermal`, `kinematic`, `transmission`,
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

use crate::campaign::{Plan, Planner, STREAM_TRACKER, derive_seed, plan, rng_for};
use crate::effects::{ComplianceSolver, Conditions, Contributions, EffectId, Truth};
use crate::error::{Result, SimError};
use crate::io::{AtomicFile, write_atomic};
use crate::measurement_table::{self, MeasurementTable, OptionalColumns};
use crate::scenario::{Resolved, TruthModel};
use crate::statics::Payload;
use crate::tracker::{Reading, Tracker};
use arrow_array::{ArrayRef, BooleanArray, Float64Array, Int64Array, RecordBatch};
use arrow_schema::{DataType, Field, Schema};
use nalgebra::Vector3;
use rayon::prelude::*;
use serde_json::json;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

mod summary;

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

/// The simulated truth and reading of one row.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RowTruth {
    /// Noise-free target position in the base frame (m).
    pub p_base: [f64; 3],
    /// Displacement by each effect (base frame, m).
    pub contribution: Contributions,
    /// Newton iterations of the compliance equilibrium.
    pub compliance_iterations: usize,
    /// The tracker reading (true and measured target, noise, σ, orientation).
    pub reading: Reading,
}

/// The output of [`simulate`]: one [`RowTruth`] per plan row, and the per-joint vectors.
#[derive(Clone, Debug, PartialEq)]
pub struct Simulation {
    /// Joints.
    pub nq: usize,
    /// Per row.
    pub rows: Vec<RowTruth>,
    /// Link-side joint positions, row-major (rad or m).
    pub q_link: Vec<f64>,
    /// First-order link-side joint positions, row-major (rad or m).
    pub q_link_first_order: Vec<f64>,
}

/// Per-row progress callback: called with the number of rows just finished.
pub type Progress<'a> = &'a (dyn Fn(u64) + Sync);

/// Rows between progress callbacks and the least rows per parallel task: analytic truth (≈ 4 µs a
/// row) and rapier truth (≈ 200 µs a row, so a progress bar moves and two cores share 200 poses).
const fn batching(solver: ComplianceSolver) -> (usize, usize) {
    match solver {
        ComplianceSolver::Analytic => (4096, 64),
        ComplianceSolver::Rapier(_) => (16, 4),
    }
}

/// The truth of a resolved scenario: [`Truth::with_solver`] with the solver its `[truth] model`
/// names (rapier with the default [`crate::rapier_truth::SettleOptions`]). Errors name the scenario
/// file and `effects` or `truth.model`.
pub fn truth_of(res: &Resolved) -> Result<Truth> {
    let (solver, key) = match res.truth_model {
        TruthModel::Analytic => (ComplianceSolver::Analytic, "effects"),
        TruthModel::Rapier => (
            ComplianceSolver::Rapier(crate::rapier_truth::SettleOptions::default()),
            "truth.model",
        ),
    };
    Truth::with_solver(&res.model, &res.effects, solver).map_err(|e| SimError::Scenario {
        file: res.scenario.label.clone(),
        key: key.into(),
        message: e.to_string(),
    })
}

/// Simulates every row of `plan`: truth with `truth` under `gravity` (base frame, m/s²), reading with
/// `tracker`, noise drawn from `seed` (see the module docs). Runs on the current rayon pool. Fails with
/// the lowest failing row's error (e.g. a compliance equilibrium that is not found), naming the pose.
pub fn simulate(
    truth: &Truth,
    tracker: &Tracker,
    gravity: &Vector3<f64>,
    plan: &Plan,
    seed: u64,
    progress: Option<Progress<'_>>,
) -> Result<Simulation> {
    let n = plan.len();
    let nq = plan.nq;
    let mut rows = vec![RowTruth::default(); n];
    let mut q_link = vec![0.0; n * nq];
    let mut q_first = vec![0.0; n * nq];
    let failure: Mutex<Option<(usize, SimError)>> = Mutex::new(None);
    let com = plan.payload_com_m;
    let (every, min_len) = batching(truth.solver());
    rows.par_iter_mut()
        .zip(q_link.par_chunks_mut(nq))
        .zip(q_first.par_chunks_mut(nq))
        .enumerate()
        .with_min_len(min_len)
        .for_each_init(
            || truth.scratch(),
            |scratch, (r, ((row, ql), qf))| {
                let mass = plan.payload_kg[r];
                let cond = Conditions {
                    q: plan.q_row(r),
                    dir: plan.dir_row(r),
                    temp_c: plan.temp_c[r],
                    payload: (mass > 0.0).then_some(Payload { mass, com }),
                };
                match truth.target(&cond, tracker.p_flange(), gravity, scratch) {
                    Ok(tp) => {
                        let pose = plan.pose[r] as u64;
                        let repeat = plan.repeat_of(r) as u64;
                        let mut rng = rng_for(
                            derive_seed(seed, STREAM_TRACKER, pose),
                            STREAM_TRACKER,
                            repeat,
                        );
                        *row = RowTruth {
                            p_base: [tp.p_base.x, tp.p_base.y, tp.p_base.z],
                            contribution: tp.contribution,
                            compliance_iterations: tp.compliance_iterations,
                            reading: tracker.measure(&tp.flange, &mut rng),
                        };
                        ql.copy_from_slice(scratch.q_link());
                        qf.copy_from_slice(scratch.q_link_first_order());
                    }
                    Err(e) => {
                        let mut f = failure.lock().unwrap_or_else(|p| p.into_inner());
                        if f.as_ref().is_none_or(|(fr, _)| r < *fr) {
                            *f = Some((r, e));
                        }
                    }
                }
                if let Some(p) = progress
                    && (r + 1) % every == 0
                {
                    p(every as u64);
                }
            },
        );
    if let Some((r, e)) = failure.into_inner().unwrap_or_else(|p| p.into_inner()) {
        return Err(SimError::Scenario {
            file: "simulation".into(),
            key: format!("pose {} (row {})", plan.pose[r], plan.first_row + r + 1),
            message: e.to_string(),
        });
    }
    if let Some(p) = progress {
        p((n % every) as u64);
    }
    Ok(Simulation {
        nq,
        rows,
        q_link,
        q_link_first_order: q_first,
    })
}

/// The measurement table of a simulation: contract columns only (see the module docs).
pub fn measurement_table(plan: &Plan, sim: &Simulation, tracker: &Tracker) -> MeasurementTable {
    let cols = measurement_columns(plan.dir.is_some(), tracker);
    MeasurementTable {
        n_joints: plan.nq,
        pose: plan.pose.clone(),
        q: plan.q.clone(),
        position: sim.rows.iter().map(|r| r.reading.p_measured).collect(),
        orientation: cols.orientation.then(|| {
            sim.rows
                .iter()
                .map(|r| r.reading.orientation_measured)
                .collect()
        }),
        t: Some(plan.t_s.clone()),
        temp: Some(plan.temp_c.clone()),
        dir: plan.dir.clone(),
        payload: Some(plan.payload_kg.clone()),
        sigma: cols
            .sigma
            .then(|| sim.rows.iter().map(|r| r.reading.sigma_m).collect()),
        campaign: None,
    }
}

/// Names of the `truth.parquet` columns for `nq` joints (see the module docs).
pub fn truth_column_names(nq: usize, six_dof: bool) -> Vec<String> {
    let mut v: Vec<String> = vec!["pose".into(), "repeat".into()];
    let effects = EffectId::ALL.iter().map(|id| id.key());
    for p in ["p_tracker", "p_base", "p_nominal_base"]
        .into_iter()
        .chain(effects)
    {
        for a in ["x", "y", "z"] {
            v.push(format!("{p}_{a}"));
        }
    }
    v.extend((1..=nq).map(|j| format!("q_link{j}")));
    v.extend((1..=nq).map(|j| format!("q_link_first_order{j}")));
    v.extend(
        [
            "noise_x",
            "noise_y",
            "noise_z",
            "outlier",
            "sigma_radial",
            "sigma_transverse",
        ]
        .map(String::from),
    );
    v.push("compliance_iterations".into());
    if six_dof {
        v.extend(
            [
                "qw_true",
                "qx_true",
                "qy_true",
                "qz_true",
                "rot_noise_x",
                "rot_noise_y",
                "rot_noise_z",
            ]
            .map(String::from),
        );
    }
    v
}

/// The `truth.parquet` record batch.
fn truth_batch(plan: &Plan, sim: &Simulation, six_dof: bool) -> Result<RecordBatch> {
    let nq = plan.nq;
    let rows = &sim.rows;
    let f = |v: Vec<f64>| Arc::new(Float64Array::from(v)) as ArrayRef;
    let col3 = |g: &dyn Fn(&RowTruth) -> [f64; 3]| -> [ArrayRef; 3] {
        std::array::from_fn(|k| f(rows.iter().map(|r| g(r)[k]).collect()))
    };
    let mut arrays: Vec<ArrayRef> = vec![
        Arc::new(Int64Array::from(plan.pose.clone())),
        Arc::new(Int64Array::from(
            (0..plan.len())
                .map(|r| plan.repeat_of(r) as i64)
                .collect::<Vec<_>>(),
        )),
    ];
    arrays.extend(col3(&|r| r.reading.p_true));
    arrays.extend(col3(&|r| r.p_base));
    arrays.extend(col3(&|r| {
        let t = r.contribution.total();
        std::array::from_fn(|k| r.p_base[k] - t[k])
    }));
    for id in EffectId::ALL {
        arrays.extend(col3(&|r| r.contribution.get(*id)));
    }
    for j in 0..nq {
        arrays.push(f((0..plan.len()).map(|r| sim.q_link[r * nq + j]).collect()));
    }
    for j in 0..nq {
        arrays.push(f((0..plan.len())
            .map(|r| sim.q_link_first_order[r * nq + j])
            .collect()));
    }
    arrays.extend(col3(&|r| r.reading.noise));
    arrays.push(Arc::new(BooleanArray::from(
        rows.iter().map(|r| r.reading.outlier).collect::<Vec<_>>(),
    )));
    arrays.push(f(rows.iter().map(|r| r.reading.sigma_radial_m).collect()));
    arrays.push(f(rows
        .iter()
        .map(|r| r.reading.sigma_transverse_m)
        .collect()));
    arrays.push(Arc::new(Int64Array::from(
        rows.iter()
            .map(|r| r.compliance_iterations as i64)
            .collect::<Vec<_>>(),
    )));
    if six_dof {
        for k in 0..4 {
            arrays.push(f(rows
                .iter()
                .map(|r| r.reading.orientation_true[k])
                .collect()));
        }
        arrays.extend(col3(&|r| r.reading.orientation_noise));
    }
    RecordBatch::try_new(truth_schema(nq, six_dof), arrays).map_err(|e| SimError::Io {
        path: PathBuf::from(TRUTH_PARQUET_FILE),
        source: std::io::Error::other(e.to_string()),
    })
}

/// The Arrow schema of `truth.parquet`: `pose`, `repeat` and `compliance_iterations` Int64, `outlier`
/// Boolean, every other column Float64; none nullable.
fn truth_schema(nq: usize, six_dof: bool) -> Arc<Schema> {
    let fields: Vec<Field> = truth_column_names(nq, six_dof)
        .into_iter()
        .map(|name| {
            let dt = match name.as_str() {
                "pose" | "repeat" | "compliance_iterations" => DataType::Int64,
                "outlier" => DataType::Boolean,
                _ => DataType::Float64,
            };
            Field::new(name, dt, false)
        })
        .collect();
    Arc::new(Schema::new(fields))
}

/// Root-mean-square displacement (m) and largest one of one effect over the rows.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct EffectSize {
    /// Effect name ([`EffectId::name`]: `thermal_drift`, `kinematic_offsets`, `gear_backlash`,
    /// `joint_compliance`).
    pub effect: &'static str,
    /// RMS of the displacement length over the rows (m).
    pub rms_m: f64,
    /// Largest displacement length (m).
    pub max_m: f64,
}

/// What a generation produced, for the summary paragraph and `truth.json`.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Summary {
    /// Robot name.
    pub robot: String,
    /// How the truth was computed (`analytic` or `rapier`).
    pub truth_model: TruthModel,
    /// Compliance solve per row: mean and largest Newton iterations (analytic) or engine steps
    /// (rapier); zeros without compliance.
    pub compliance_steps_mean_max: [f64; 2],
    /// Seed in force.
    pub seed: u64,
    /// Poses.
    pub poses: usize,
    /// Rows (measurements).
    pub rows: usize,
    /// The injected effects and their sizes at the target.
    pub effects: Vec<EffectSize>,
    /// RMS of the total deviation of the real target from the nominal one (m).
    pub total_rms_m: f64,
    /// Noise multiplier.
    pub noise_scale: f64,
    /// Median target distance from the tracker (m).
    pub median_distance_m: f64,
    /// Radial and transverse σ at the median distance (m, scaled).
    pub sigma_at_median_m: [f64; 2],
    /// RMS length of the added noise vector over rows without outliers (m).
    pub noise_rms_m: f64,
    /// Rows with a gross outlier.
    pub outliers: usize,
    /// Files written (paths as given; not stored in `truth.json`, which must not depend on the output
    /// folder).
    #[serde(skip)]
    pub files: Vec<String>,
}

fn fmt_len(m: f64) -> String {
    if m == 0.0 {
        "0".into()
    } else if m < 1e-3 {
        format!("{:.1} µm", m * 1e6)
    } else {
        format!("{:.3} mm", m * 1e3)
    }
}

impl Summary {
    /// One human-readable paragraph.
    pub fn paragraph(&self) -> String {
        let effects = if self.effects.is_empty() {
            "no injected effects".to_string()
        } else {
            let parts: Vec<String> = self
                .effects
                .iter()
                .map(|e| {
                    format!(
                        "{} (RMS {}, max {})",
                        e.effect,
                        fmt_len(e.rms_m),
                        fmt_len(e.max_m)
                    )
                })
                .collect();
            format!(
                "effects {}; total RMS deviation {}",
                parts.join(", "),
                fmt_len(self.total_rms_m)
            )
        };
        let noise = if self.noise_scale == 0.0 {
            "noise-free (scale 0)".to_string()
        } else {
            format!(
                "tracker noise ×{}: σ_radial {}, σ_transverse {} at the median distance {:.2} m, RMS |noise| {}, {} outlier row(s)",
                self.noise_scale,
                fmt_len(self.sigma_at_median_m[0]),
                fmt_len(self.sigma_at_median_m[1]),
                self.median_distance_m,
                fmt_len(self.noise_rms_m),
                self.outliers
            )
        };
        let truth = match self.truth_model {
            TruthModel::Analytic => String::new(),
            TruthModel::Rapier => format!(
                " (rapier physics-engine compliance, {:.1} steps per pose on average)",
                self.compliance_steps_mean_max[0]
            ),
        };
        format!(
            "generated {} poses ({} measurements) of robot '{}'{truth}, seed {}; {}; {}; wrote {}.",
            self.poses,
            self.rows,
            self.robot,
            self.seed,
            effects,
            noise,
            self.files.join(", ")
        )
    }
}

/// The summary of a campaign of `poses` poses and `rows` rows from its accumulated statistics and the
/// median target distance (m).
fn summarize(
    res: &Resolved,
    (poses, rows): (usize, usize),
    totals: summary::Totals,
    median: f64,
    files: Vec<String>,
) -> Summary {
    let (sr, st) = res.tracker.sigmas(median);
    Summary {
        robot: res.model.name.clone(),
        truth_model: res.truth_model,
        compliance_steps_mean_max: totals.steps_mean_max,
        seed: res.seed,
        poses,
        rows,
        effects: totals.effects,
        total_rms_m: totals.total_rms_m,
        noise_scale: res.tracker.noise_scale(),
        median_distance_m: median,
        sigma_at_median_m: [sr, st],
        noise_rms_m: totals.noise_rms_m,
        outliers: totals.outliers,
        files,
    }
}

/// A pose as `{xyz_m, rpy_rad, matrix}` for `truth.json`.
fn pose_json(xyz: [f64; 3], rpy: [f64; 3], t: &crate::lie::Pose) -> serde_json::Value {
    let m = t.to_homogeneous();
    json!({
        "xyz_m": xyz, "rpy_rad": rpy,
        "matrix": (0..4).map(|r| (0..4).map(|c| m[(r, c)]).collect::<Vec<_>>()).collect::<Vec<_>>(),
    })
}

/// The `truth.json` document, top-level keys in reading order (nested objects have sorted keys).
#[derive(serde::Serialize)]
struct TruthDoc {
    software: serde_json::Value,
    seed: u64,
    overrides: crate::scenario::Overrides,
    scenario_file: String,
    truth_model: TruthModel,
    truth: serde_json::Value,
    robot: serde_json::Value,
    gravity_m_per_s2: [f64; 3],
    effects: serde_json::Value,
    tracker: serde_json::Value,
    campaign: serde_json::Value,
    summary: serde_json::Value,
    files: serde_json::Value,
    scenario: serde_json::Value,
    scenario_text: String,
}

fn to_value<T: serde::Serialize>(v: &T) -> serde_json::Value {
    serde_json::to_value(v).unwrap_or(serde_json::Value::Null)
}

/// How the truth was computed, for `truth.json`: the compliance solver, its settings, its step
/// counts and, for rapier, what the engine's model holds.
fn truth_record(res: &Resolved, summary: &Summary) -> serde_json::Value {
    use crate::effects::joint_compliance as jc;
    let [mean, max] = summary.compliance_steps_mean_max;
    match res.truth_model {
        TruthModel::Analytic => json!({
            "model": res.truth_model,
            "compliance_solver": "Newton on K (q − θ) = τ_g(θ) in the real geometry (sim::effects::joint_compliance)",
            "newton_tolerance_rad": jc::TOLERANCE_RAD,
            "newton_max_iterations": jc::MAX_ITERATIONS,
            "compliance_iterations_mean": mean,
            "compliance_iterations_max": max,
        }),
        TruthModel::Rapier => {
            let o = crate::rapier_truth::SettleOptions::default();
            json!({
                "model": res.truth_model,
                "compliance_solver": "rapier multibody with joint springs settled to rest, built per temperature and payload from the real geometry: thermally grown links, kinematic error twists, base and tool errors; nominal inertials in the real joint frames; springs anchored at the motor angles after zero offsets, zero drift and backlash (sim::effects::rapier_compliance)",
                "engine": crate::rapier_truth::ENGINE,
                "settle_options": {
                    "dt_s": o.dt, "damping_ratio": o.damping_ratio, "speed_tol_rad_per_s": o.speed_tol,
                    "residual_tol_nm": o.residual_tol, "max_steps": o.max_steps,
                },
                "engine_steps_mean": mean,
                "engine_steps_max": max,
            })
        }
    }
}

/// The `truth.json` document.
fn truth_json(res: &Resolved, (nq, repeats): (usize, usize), summary: &Summary) -> TruthDoc {
    let sc = &res.scenario;
    let tr = &res.tracker;
    let file_name = Path::new(&sc.label)
        .file_name()
        .map_or_else(|| sc.label.clone(), |n| n.to_string_lossy().into_owned());
    TruthDoc {
        software: json!({"name": "robocal", "version": VERSION}),
        seed: res.seed,
        overrides: res.overrides,
        scenario_file: file_name,
        truth_model: res.truth_model,
        truth: truth_record(res, summary),
        robot: json!({
            "name": res.model.name, "source": res.robot_source.source,
            "urdf_fnv1a64": res.robot_source.urdf_fnv1a64,
            "base_link": res.model.base_link, "tip_link": res.model.tip_link,
            "joints": res.model.nq(),
            "joint_names": res.model.joints.iter().map(|j| j.name.clone()).collect::<Vec<_>>(),
        }),
        gravity_m_per_s2: [res.gravity.x, res.gravity.y, res.gravity.z],
        effects: to_value(&res.effects),
        tracker: json!({
            "T_tracker_base": pose_json(res.tracker_xyz_m, res.tracker_rpy_rad, tr.t_tracker_base()),
            "reflector_flange_m": [tr.p_flange().x, tr.p_flange().y, tr.p_flange().z],
            "six_dof": tr.six_dof(),
            "R_flange_probe": (0..3).map(|r| (0..3).map(|c| tr.r_flange_probe()[(r, c)]).collect::<Vec<_>>()).collect::<Vec<_>>(),
            "noise_model": tr.noise(),
            "noise_scale": tr.noise_scale(),
            "noise_law": "error = s (σ_r n_r u + σ_t (n1 e1 + n2 e2)), σ_r = radial_a_m + radial_b_m_per_m d, σ_t = transverse_a_m + transverse_b_m_per_m d; u line of sight, e1 = z×u/|z×u|, e2 = u×e1; plus, at outlier_rate, s outlier_magnitude_m in a uniform direction",
            "sigma_column": "sqrt((σ_r² + 2 σ_t²)/3) at the measured distance (RMS of the per-axis σ), scaled by noise_scale; absent when noise_scale = 0",
        }),
        campaign: json!({
            "spec": res.campaign,
            "poses": summary.poses, "repeats": repeats, "rows": summary.rows,
        }),
        summary: to_value(summary),
        files: json!({
            "measurements": MEASUREMENTS_FILE, "truth_rows": TRUTH_PARQUET_FILE,
            "truth_rows_columns": truth_column_names(nq, tr.six_dof()),
        }),
        scenario: to_value(&sc.file),
        scenario_text: sc.text.clone(),
    }
}

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
fn check_disk(res: &Resolved, planner: &Planner<'_>, out_dir: &Path) -> Result<()> {
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

/// The optional columns of the measurement table (see the module docs).
fn measurement_columns(has_dir: bool, tracker: &Tracker) -> OptionalColumns {
    OptionalColumns {
        orientation: tracker.six_dof(),
        t: true,
        temp: true,
        dir: has_dir,
        payload: true,
        sigma: tracker.noise_scale() > 0.0,
        campaign: false,
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
        let mut measurements = measurement_table::ParquetTableWriter::new(
            AtomicFile::create(&m_path)?,
            nq,
            measurement_columns(planner.has_dir(), &res.tracker),
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

/// Calls `visit` with the length of every row's noise-free target `p_tracker` (m), read back from
/// the `truth.parquet` at `path` (the median's radix selection; the values are those simulated, bit
/// for bit, as Parquet stores doubles exactly).
fn replay_distances(path: &Path, visit: &mut dyn FnMut(f64)) -> Result<()> {
    use arrow_array::cast::AsArray;
    use arrow_array::types::Float64Type;
    let io = |e: &dyn std::fmt::Display| SimError::Io {
        path: path.to_path_buf(),
        source: std::io::Error::other(format!("reading back: {e}")),
    };
    let f = std::fs::File::open(path).map_err(|e| io(&e))?;
    let b = parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(f)
        .map_err(|e| io(&e))?;
    let mask = parquet::arrow::ProjectionMask::columns(
        b.parquet_schema(),
        ["p_tracker_x", "p_tracker_y", "p_tracker_z"],
    );
    let reader = b
        .with_projection(mask)
        .with_batch_size(1 << 16)
        .build()
        .map_err(|e| io(&e))?;
    for batch in reader {
        let batch = batch.map_err(|e| io(&e))?;
        let col = |name: &str| {
            batch
                .column_by_name(name)
                .and_then(|c| c.as_primitive_opt::<Float64Type>())
                .ok_or_else(|| io(&format!("no Float64 column {name}")))
        };
        let (x, y, z) = (
            col("p_tracker_x")?,
            col("p_tracker_y")?,
            col("p_tracker_z")?,
        );
        for i in 0..batch.num_rows() {
            visit(summary::distance([x.value(i), y.value(i), z.value(i)]));
        }
    }
    Ok(())
}

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

/// Column names of a Parquet file, in file order (to check what a file holds without interpreting it).
pub fn parquet_column_names(path: &Path) -> Result<Vec<String>> {
    let io = |e: &dyn std::fmt::Display| SimError::Read {
        path: path.to_path_buf(),
        source: std::io::Error::other(e.to_string()),
    };
    let f = std::fs::File::open(path).map_err(|source| SimError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    let b = parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(f)
        .map_err(|e| io(&e))?;
    Ok(b.schema()
        .fields()
        .iter()
        .map(|f| f.name().clone())
        .collect())
}
