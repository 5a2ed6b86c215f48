//! Sensitivity studies: generate, calibrate and score many datasets over a grid of effect magnitudes,
//! noise levels and pose counts (`robocal sweep`), in shards that merge to the same bytes
//! (`robocal sweep-merge`).
//!
//! A sweep is a [`SweepSpec`]: a scenario, the magnitudes of its injected effects, the noise
//! multipliers, the pose counts, the repetitions per cell, a seed, the fitted model and the pose
//! selection. Cell `c = (m · N + i) · P + j` pairs magnitude `m` with noise level `i` and pose count
//! `j` (`N` noise levels, `P` pose counts); without `--magnitude` there is one magnitude, 1, and
//! `c = i · P + j` as in sweeps before the magnitude axis. Run `r = c · reps + k` is repetition `k` of
//! cell `c`. Run `r` uses the seed `splitmix64(splitmix64(splitmix64(seed) ^ c) ^ k)` ([`run_seed`])
//! for everything random in it (the scenario's parameter draws, poses, tracker noise, the train/test
//! split), so it depends on nothing but the sweep seed, its cell and its repetition: it can be re-run
//! alone (`--only-cell`, or, at magnitude 1, `robocal generate --seed S --poses N --noise M` and
//! `robocal calibrate --seed S`, see `docs/sweep.md`), on any machine, with any number of threads.
//!
//! Each run ([`run_one`]):
//! 1. resolves the scenario with the run's seed, pose count and noise multiplier, scales its injected
//!    effects by the run's magnitude ([`magnitude::scaled`]) and simulates the campaign in memory
//!    (`sim::generate`, the same code as `robocal generate`);
//! 2. splits the poses into training and held-out ones (`calib::model::stats::split_by_pose`, as the validation
//!    split of `robocal calibrate --test-fraction F --seed S`; with planned selection the training poses are the planned
//!    ones and the held-out ones random, see [`split_counts`]) and calibrates the sweep's model on the training rows
//!    (`calib::fit`, default options; `auto` is resolved on the training rows as `robocal calibrate --model auto`
//!    resolves it);
//! 3. scores the result against the truth ([`score`]): the held-out prediction error against the
//!    noise-free true target positions and what the covariance predicts for it, the error of each
//!    identifiable parameter combination in units of its predicted standard deviation, the error of
//!    each extension parameter against the simulator's value ([`truth_params`]) in units of its σ,
//!    and the observability of the training poses ([`table::COLUMNS`], [`params_table::COLUMNS`]).

pub mod detection;
pub mod magnitude;
pub mod params_table;
pub mod power;
pub mod score;
pub mod table;
pub mod truth_params;

use crate::error::CliError;
use calib::fit::{CalibrationOptions, Dataset, FitRequest, Part, fit};
use calib::model::spec::ModelSpec;
use nalgebra::Vector3;
use params_table::ParamRow;
use sim::campaign::splitmix64;
use sim::scenario::{Overrides, Scenario};
use table::SweepRow;

/// Significance level of diagnose's tests with `--score diagnose` (`robocal diagnose`'s default).
pub const DIAGNOSE_ALPHA: f64 = 1e-3;

/// Regions of diagnose's transfer test when a run resolves `--model auto` or is diagnosed with
/// `--score diagnose`: the default of `robocal calibrate` and `robocal diagnose`, so that a sweep
/// studies what users run.
pub const AUTO_REGIONS: usize = calib::validate::regions::DEFAULT_REGIONS;

/// Version of the sweep file layout (columns and metadata).
pub const FORMAT_VERSION: u32 = 3;

/// How the calibration poses of a run are chosen (also the values of `robocal sweep --selection`).
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize, clap::ValueEnum,
)]
#[serde(rename_all = "snake_case")]
pub enum Selection {
    /// The scenario's own campaign (random poses for the shipped scenarios).
    Random,
    /// D-optimal selection (`calib::fit::plan`) for the fitted model from random candidate
    /// configurations, each with one of the campaign's payload masses.
    Planned,
}

/// What a sweep scores (also the values of `robocal sweep --score`).
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize, clap::ValueEnum,
)]
#[serde(rename_all = "snake_case")]
pub enum Score {
    /// The fitted model against the truth (held-out error, combinations, parameters).
    Fit,
    /// Also diagnose on every run's data: which causes it names against those hidden
    /// ([`detection`]).
    Diagnose,
}

/// Everything that decides a sweep's rows; stored as JSON in every file of the sweep.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SweepSpec {
    /// `robocal-sweep`.
    pub format: String,
    /// [`FORMAT_VERSION`].
    pub format_version: u32,
    /// Software version that wrote the file.
    pub software_version: String,
    /// The scenario's file name (no folder: the bytes must not depend on where it lies).
    pub scenario_file: String,
    /// The scenario's text, FNV-1a 64 hash (hex).
    pub scenario_fnv1a64: String,
    /// The scenario's text.
    pub scenario_text: String,
    /// Factors on the injected effects (`--magnitude`, see [`magnitude`]), in grid order; `[1]`
    /// without `--magnitude`.
    pub magnitude: Vec<f64>,
    /// The one effect the magnitudes scale (`--magnitude-of`, its name), `None` for all of them.
    pub magnitude_of: Option<String>,
    /// Payload sets (`--payloads`, kg), in grid order: a run of set `k` draws every pose's payload
    /// from `payloads[k]` (one mass: every pose carries it), as `[campaign.payload] choice_kg`
    /// does, with the scenario's centre of mass. `None`: the scenario's own payloads.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub payloads: Option<Vec<Vec<f64>>>,
    /// Noise multipliers (as `robocal generate --noise`), in grid order.
    pub noise_scale: Vec<f64>,
    /// Pose counts per run (as `robocal generate --poses`), in grid order.
    pub poses: Vec<usize>,
    /// Repetitions per cell.
    pub reps: usize,
    /// Sweep seed.
    pub seed: u64,
    /// Fraction of each run's poses held out (as `robocal calibrate --test-fraction`).
    pub test_fraction: f64,
    /// Fitted model: its canonical name (`kinematic+joint_compliance@2,4`), or `auto`.
    pub model: String,
    /// Pose selection.
    pub selection: Selection,
    /// What is scored.
    pub score: Score,
    /// Candidates per planned selection (`selection = planned` only).
    pub candidates: Option<usize>,
    /// Cells (magnitudes × payload sets × noise levels × pose counts).
    pub cells: usize,
    /// Runs (cells × reps).
    pub runs: usize,
}

/// Run `r` of a sweep: its cell, repetition and grid values.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RunId {
    /// Run index.
    pub run: usize,
    /// Cell index.
    pub cell: usize,
    /// Repetition.
    pub rep: usize,
    /// Factor on the injected effects.
    pub magnitude: f64,
    /// Index of the payload set in [`SweepSpec::payloads`], `None` for the scenario's payloads.
    pub payload_set: Option<usize>,
    /// Noise multiplier.
    pub noise_scale: f64,
    /// Poses generated.
    pub poses: usize,
    /// The run's seed ([`run_seed`]).
    pub seed: u64,
}

/// Where a cell lies in the grid: its magnitude, payload set, noise level and pose count.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GridPoint {
    /// Factor on the injected effects.
    pub magnitude: f64,
    /// Index of the payload set, `None` for the scenario's payloads.
    pub payload_set: Option<usize>,
    /// Noise multiplier.
    pub noise_scale: f64,
    /// Poses generated per run.
    pub poses: usize,
}

/// The seed of repetition `rep` of cell `cell` under the sweep seed `seed`.
pub fn run_seed(seed: u64, cell: usize, rep: usize) -> u64 {
    splitmix64(splitmix64(splitmix64(seed) ^ cell as u64) ^ rep as u64)
}

impl SweepSpec {
    /// Payload sets in the grid: 1 without `--payloads`.
    pub fn payload_sets(&self) -> usize {
        self.payloads.as_ref().map_or(1, Vec::len)
    }

    /// The grid values of cell `cell`: cells run over the pose counts fastest, then the noise
    /// levels, the payload sets and the magnitudes (without `--payloads` the cell numbers are
    /// those of a sweep without the axis).
    pub fn grid(&self, cell: usize) -> GridPoint {
        let np = self.poses.len();
        let nn = self.noise_scale.len();
        let nl = self.payload_sets();
        GridPoint {
            magnitude: self.magnitude[cell / (np * nn * nl)],
            payload_set: self.payloads.as_ref().map(|_| (cell / (np * nn)) % nl),
            noise_scale: self.noise_scale[(cell / np) % nn],
            poses: self.poses[cell % np],
        }
    }

    /// The masses of payload set `k` as a label, `/`-separated (kg): `0/3.5/7`; empty for `None`.
    pub fn payload_label(&self, k: Option<usize>) -> String {
        match (k, &self.payloads) {
            (Some(k), Some(sets)) => sets[k]
                .iter()
                .map(|m| m.to_string())
                .collect::<Vec<_>>()
                .join("/"),
            _ => String::new(),
        }
    }

    /// Run `r` (`r < runs`).
    pub fn run_id(&self, r: usize) -> RunId {
        let cell = r / self.reps;
        let rep = r % self.reps;
        let g = self.grid(cell);
        RunId {
            run: r,
            cell,
            rep,
            magnitude: g.magnitude,
            payload_set: g.payload_set,
            noise_scale: g.noise_scale,
            poses: g.poses,
            seed: run_seed(self.seed, cell, rep),
        }
    }

    /// The metadata entry of this spec.
    pub fn to_json(&self) -> String {
        serde_json::to_string(self).unwrap_or_default()
    }
}

/// Which runs of the grid to do.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Subset {
    /// Every run.
    All,
    /// Runs `r` with `r mod n = k` (0-based `k < n`): round robin, so that every shard gets a similar
    /// mix of small and large pose counts.
    Shard {
        /// This shard, 0-based.
        k: usize,
        /// Number of shards.
        n: usize,
    },
    /// The runs of one cell.
    Cell(usize),
}

impl Subset {
    /// True when run `id` belongs to the subset.
    pub fn contains(&self, id: &RunId) -> bool {
        match *self {
            Subset::All => true,
            Subset::Shard { k, n } => id.run % n == k,
            Subset::Cell(c) => id.cell == c,
        }
    }

    /// The metadata value of a partial file, `None` for [`Subset::All`].
    pub fn describe(&self) -> Option<String> {
        match *self {
            Subset::All => None,
            Subset::Shard { k, n } => Some(format!("shard {k}/{n}")),
            Subset::Cell(c) => Some(format!("cell {c}")),
        }
    }
}

impl RunId {
    /// `run R (cell C, rep K, magnitude M, [payload set L,] noise N, poses P, seed S)`: the prefix
    /// of a failed run's error.
    fn describe(&self) -> String {
        let payload = self
            .payload_set
            .map_or_else(String::new, |k| format!("payload set {}, ", k + 1));
        format!(
            "run {} (cell {}, rep {}, magnitude {}, {payload}noise {}, poses {}, seed {})",
            self.run, self.cell, self.rep, self.magnitude, self.noise_scale, self.poses, self.seed
        )
    }
}

/// What every run shares: the parsed scenario and the settings.
pub struct Context<'a> {
    /// The scenario.
    pub scenario: &'a Scenario,
    /// The sweep.
    pub spec: &'a SweepSpec,
    /// Calibration settings (defaults, as `robocal calibrate`).
    pub options: CalibrationOptions,
    /// The fitted model; `None` for `auto` (resolved per run on its training rows).
    pub model: Option<ModelSpec>,
    /// The one effect the magnitudes scale, `None` for all.
    pub magnitude_of: Option<sim::effects::EffectId>,
}

/// What one run gives: its row of the wide table and its rows of the parameter table.
pub struct RunResult {
    /// The wide row.
    pub row: SweepRow,
    /// Its extension parameters (none for the kinematic model).
    pub params: Vec<ParamRow>,
}

/// Quantile `q ∈ [0, 1]` of sorted finite values by linear interpolation between order statistics
/// (Hyndman and Fan type 7, numpy's default); NaN when empty.
pub fn quantile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let h = (sorted.len() - 1) as f64 * q.clamp(0.0, 1.0);
    let lo = h.floor() as usize;
    let hi = (lo + 1).min(sorted.len() - 1);
    sorted[lo] + (h - lo as f64) * (sorted[hi] - sorted[lo])
}

/// Held-out and training pose counts of `n` poses for the test fraction `f`, by the rule of
/// `calib::model::stats::split_by_pose`: `round(f · n)` held out, at least one when `f > 0` and `n ≥ 2`, never
/// all. Returns `(train, test)`.
pub fn split_counts(n: usize, f: f64) -> (usize, usize) {
    let mut t = (f.clamp(0.0, 1.0) * n as f64).round() as usize;
    if f > 0.0 && t == 0 && n >= 2 {
        t = 1;
    }
    t = t.min(n.saturating_sub(1));
    (n - t, t)
}

/// The poses of a planned run: `train` configurations chosen by `calib::fit::plan` (D-optimal for
/// the fitted model `model`, the kinematic one for `auto`) among `candidates` drawn by the scenario's
/// own campaign (so they obey its reachability rules), each with one of the campaign's payload masses
/// when it has several (the plan chooses, as `plan-poses --payloads` does), followed by `test`
/// held-out configurations, the first candidates not chosen (random poses: the score is over the
/// workspace, not over the planner's favourite poses), whose payloads are drawn from the campaign's
/// masses with the run's seed. The campaign is re-planned on exactly that list, so poses
/// `0 … train − 1` are the training poses.
fn planned_plan(
    res: &sim::scenario::Resolved,
    (train, test): (usize, usize),
    candidates: usize,
    options: &CalibrationOptions,
    model: Option<&ModelSpec>,
) -> Result<sim::campaign::Plan, CliError> {
    let mut cand_res = res.clone();
    cand_res.campaign = res
        .campaign
        .to_builder()
        .label(&res.scenario.label)
        .poses(Some(candidates.max(2 * (train + test))))
        .build()
        .map_err(CliError::from)?;
    let cand = sim::generate::plan_of(&cand_res).map_err(CliError::from)?;
    let configs: Vec<Vec<f64>> = (0..cand.n_poses)
        .map(|k| cand.q_row(k * cand.repeats).to_vec())
        .collect();
    let masses: Vec<f64> = match res.campaign.payload() {
        sim::campaign::PayloadRule::Fixed(m) => vec![*m],
        sim::campaign::PayloadRule::Choice(v) | sim::campaign::PayloadRule::PerPose(v) => {
            let mut v = v.clone();
            v.sort_by(f64::total_cmp);
            v.dedup();
            v
        }
    };
    let mut po = calib::fit::plan::PlanOptions::new(configs.len(), train, res.seed);
    po.target_offset = *res.tracker.p_flange();
    po.calibration = *options;
    po.noise = options.noise;
    po.random_sets = 0;
    po.model = model.cloned().unwrap_or_default();
    po.payloads_kg = masses.clone();
    po.payload_com_m = res.campaign.payload_com_m().into();
    let candidates = calib::fit::plan::Candidates::from_configurations(
        &res.model,
        &configs,
        "the scenario's candidates",
    );
    let planned = calib::fit::plan::plan(&res.model, &candidates, &po).map_err(CliError::from)?;
    let chosen: Vec<usize> = planned.source_poses.iter().map(|&p| p as usize).collect();
    let mut list: Vec<Vec<f64>> = planned.selected.clone();
    list.extend(
        (0..configs.len())
            .filter(|c| !chosen.contains(c))
            .take(test)
            .map(|c| configs[c].clone()),
    );
    let mut payloads = planned
        .payload_kg
        .clone()
        .unwrap_or_else(|| vec![masses[0]; train]);
    use rand::{RngExt, SeedableRng};
    let mut rng = rand::rngs::StdRng::seed_from_u64(splitmix64(res.seed ^ 0x7e57));
    payloads.extend((0..test).map(|_| masses[rng.random_range(0..masses.len())]));
    let spec = res
        .campaign
        .to_builder()
        .label(&res.scenario.label)
        .poses(Some(train + test))
        .sampling(sim::campaign::Sampling::List { q: list })
        .payload(
            sim::campaign::PayloadRule::PerPose(payloads),
            res.campaign.payload_com_m(),
        )
        .build()
        .map_err(CliError::from)?;
    sim::campaign::plan(&res.model, &spec, res.seed, &res.scenario.label).map_err(CliError::from)
}

/// The campaign of `res` with every pose's payload drawn from `masses` (kg; one mass: every pose
/// carries it), at the scenario's centre of mass.
pub fn with_payloads(
    res: &sim::scenario::Resolved,
    masses: &[f64],
) -> Result<sim::campaign::CampaignSpec, CliError> {
    let rule = match masses {
        [m] => sim::campaign::PayloadRule::Fixed(*m),
        _ => sim::campaign::PayloadRule::Choice(masses.to_vec()),
    };
    res.campaign
        .to_builder()
        .label(&res.scenario.label)
        .payload(rule, res.campaign.payload_com_m())
        .build()
        .map_err(CliError::from)
}

/// One run: generate, split, calibrate, score (see the module docs).
pub fn run_one(ctx: &Context<'_>, id: &RunId) -> Result<RunResult, CliError> {
    run_inner(ctx, id).map_err(|e| e.prefixed(&id.describe()))
}

fn run_inner(ctx: &Context<'_>, id: &RunId) -> Result<RunResult, CliError> {
    let spec = ctx.spec;
    let mut res = ctx
        .scenario
        .resolve(&Overrides {
            seed: Some(id.seed),
            poses: Some(id.poses),
            noise: Some(id.noise_scale),
        })
        .map_err(CliError::from)?;
    if id.magnitude != 1.0 {
        res.effects = magnitude::scaled(&res.effects, id.magnitude, ctx.magnitude_of)?;
    }
    if let (Some(k), Some(sets)) = (id.payload_set, &spec.payloads) {
        res.campaign = with_payloads(&res, &sets[k])?;
    }
    let plan = match spec.selection {
        Selection::Random => sim::generate::plan_of(&res).map_err(CliError::from)?,
        Selection::Planned => planned_plan(
            &res,
            split_counts(id.poses, spec.test_fraction),
            spec.candidates.unwrap_or(10 * id.poses),
            &ctx.options,
            ctx.model.as_ref(),
        )?,
    };
    let truth = sim::effects::Truth::new(&res.model, &res.effects).map_err(CliError::from)?;
    let simulation =
        sim::generate::simulate(&truth, &res.tracker, &res.gravity, &plan, id.seed, None)
            .map_err(CliError::from)?;
    let table = sim::generate::measurement_table(&plan, &simulation, &res.tracker);
    let p_true: Vec<Vector3<f64>> = simulation
        .rows
        .iter()
        .map(|r| Vector3::from(r.reading.p_true))
        .collect();
    let (train_rows, test_rows) = match spec.selection {
        Selection::Random => {
            calib::model::stats::split_by_pose(&table, spec.test_fraction, id.seed)
        }
        Selection::Planned => {
            let n_train = split_counts(id.poses, spec.test_fraction).0 as i64;
            (0..table.len()).partition(|&r| table.pose[r] < n_train)
        }
    };
    let model_spec = match &ctx.model {
        Some(m) => m.clone(),
        None => {
            let train_table = table.select_rows(&train_rows);
            let data = crate::cli::calibrate::Named {
                table: &train_table,
                name: "training set",
            };
            // As `calibrate --model auto` with its default regions.
            crate::cli::calibrate::choose_auto(
                &res.model,
                data,
                id.seed,
                AUTO_REGIONS,
                &mut |_| {},
                &mut |_| {},
            )?
            .spec
        }
    };
    let train = Dataset {
        table: &table,
        rows: train_rows,
        name: "training set".into(),
        part: Part::Training,
    };
    let test = Dataset {
        table: &table,
        rows: test_rows,
        name: "test set".into(),
        part: Part::Test,
    };
    let cal = fit(
        &res.model,
        &train,
        &FitRequest::new(&model_spec, &ctx.options)
            .judged_on((!test.rows.is_empty()).then_some(&test)),
    )
    .map_err(CliError::from)?;
    let report = &cal.report;
    let model = &res.model;
    let scored = score::Scored::new(model, &cal, &table).map_err(CliError::from)?;
    let l = score::covariance_factor(&cal);
    let held = score::held_out(&scored, &l, &table, &test.rows, &p_true);
    let combos = score::combinations(&scored, &l, &table, &train.rows, &p_true);
    let (params, causes) = score::extension_params(model, &cal, &res.effects, id.run);

    let (hidden, named, detected, false_alarm) = match spec.score {
        Score::Fit => (String::new(), String::new(), false, false),
        Score::Diagnose => {
            let mut options = crate::cli::diagnose::options(1.0 / 3.0, id.seed, DIAGNOSE_ALPHA)?;
            options.regions = AUTO_REGIONS;
            // A run records only the model diagnose adopts. The learned models of the residual left
            // at the end (what `robocal diagnose` reports under `unexplained.learned`) take no part
            // in choosing it, and were a third of a run's time: not fitted here.
            options.learned_kinds = Vec::new();
            let d = calib::select::diagnose::diagnose(model, &table, "sweep run", &options)
                .map_err(CliError::from)?;
            let h = detection::hidden(&res.effects, model.joints(), &res.gravity);
            let n = detection::Named::of(&d);
            let (detected, false_alarm) = detection::judge(&h, &n, model.nq());
            (h.required.name(), n.name(), detected, false_alarm)
        }
    };
    let rows_n = simulation.rows.len().max(1) as f64;
    let sigma_rms = (simulation
        .rows
        .iter()
        .map(|r| r.reading.sigma_m * r.reading.sigma_m)
        .sum::<f64>()
        / rows_n)
        .sqrt();
    let injected = (simulation
        .rows
        .iter()
        .map(|r| {
            let t = r.contribution.total();
            t[0] * t[0] + t[1] * t[1] + t[2] * t[2]
        })
        .sum::<f64>()
        / rows_n)
        .sqrt();
    let o = &report.observability;
    let mut row = SweepRow {
        run: id.run as i64,
        cell: id.cell as i64,
        rep: id.rep as i64,
        noise_scale: id.noise_scale,
        poses: id.poses as i64,
        magnitude: id.magnitude,
        payloads: spec.payload_label(id.payload_set),
        seed: id.seed,
        train_poses: report.n_train_poses as i64,
        test_poses: report.n_test_poses as i64,
        sigma_rms_m: if res.tracker.noise_scale() > 0.0 {
            sigma_rms
        } else {
            0.0
        },
        injected_rms_m: injected,
        converged: report.was_successful(),
        iterations: report.after.solver.iterations as i64,
        chi2_per_dof: report.chi2_per_dof,
        train_rms_m: report.after.train.rms_m,
        test_rms_measured_m: report.after.test.as_ref().map_or(f64::NAN, |t| t.rms_m),
        test_error_rms_m: held.rms_m,
        test_error_max_m: held.max_m,
        test_error_predicted_m: held.predicted_m,
        test_error_nominal_rms_m: held.nominal_rms_m,
        rank: cal.subspace.rank as i64,
        param_combinations: combos.count as i64,
        param_z2_mean: combos.z2_mean,
        param_z_abs_max: combos.z_abs_max,
        param_beyond_3sigma: combos.beyond_3sigma as i64,
        condition_number: o.condition_number,
        sigma_min: o.sigma_min,
        log_det_information: o.log_det_information,
        learned: cal.learned.is_some(),
        params_joint_compliance: 0,
        param_z2_mean_joint_compliance: f64::NAN,
        params_gear_backlash: 0,
        param_z2_mean_gear_backlash: f64::NAN,
        params_thermal_drift: 0,
        param_z2_mean_thermal_drift: f64::NAN,
        params_transmission_error: 0,
        param_z2_mean_transmission_error: f64::NAN,
        params_link_deflection: 0,
        param_z2_mean_link_deflection: f64::NAN,
        hidden,
        named,
        detected,
        false_alarm,
    };
    let scores: Vec<(i64, f64)> = causes
        .iter()
        .map(|c| (c.params as i64, c.z2_mean))
        .collect();
    row.set_causes(&scores);
    Ok(RunResult { row, params })
}

/// Per-cell statistics of a set of rows (for the summary table, the plot and `--json`).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct CellSummary {
    /// Cell index.
    pub cell: usize,
    /// Factor on the injected effects.
    pub magnitude: f64,
    /// The payload set's masses, `/`-separated (kg; [`SweepSpec::payload_label`]), empty for the
    /// scenario's payloads.
    pub payloads: String,
    /// Noise multiplier.
    pub noise_scale: f64,
    /// Poses per run.
    pub poses: usize,
    /// Runs found.
    pub runs: usize,
    /// Runs whose fit did not converge.
    pub not_converged: usize,
    /// Median of `sigma_rms_m`: the tracker noise per axis (m).
    pub sigma_median_m: f64,
    /// Median of `test_error_rms_m` (m).
    pub test_error_median_m: f64,
    /// Its 10 % quantile (m).
    pub test_error_p10_m: f64,
    /// Its 90 % quantile (m).
    pub test_error_p90_m: f64,
    /// Median of `test_error_predicted_m` (m).
    pub predicted_median_m: f64,
    /// Median of `param_z2_mean`.
    pub param_z2_mean_median: f64,
    /// Median of `condition_number`.
    pub condition_number_median: f64,
    /// `--score diagnose`: runs where diagnose named what was hidden (`None` without it).
    pub detected: Option<usize>,
    /// `--score diagnose`: runs with a false alarm (`None` without it).
    pub false_alarms: Option<usize>,
    /// Per cause in the fitted models: the mean over the runs of `param_z2_mean_<cause>` (runs
    /// without a z for it left out), and how many runs had one. Empty for the kinematic model.
    pub causes: Vec<CauseSummary>,
}

/// One cause's z² over the runs of a cell.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct CauseSummary {
    /// Cause name.
    pub cause: String,
    /// Runs with a `param_z2_mean_<cause>`.
    pub runs: usize,
    /// Their mean of it (1 expected).
    pub z2_mean: f64,
}

/// Summaries of the cells present in `rows`, in cell order.
pub fn summarize(spec: &SweepSpec, rows: &[SweepRow]) -> Vec<CellSummary> {
    let mut out = Vec::new();
    for cell in 0..spec.cells {
        let mine: Vec<&SweepRow> = rows.iter().filter(|r| r.cell as usize == cell).collect();
        if mine.is_empty() {
            continue;
        }
        let sorted = |f: &dyn Fn(&SweepRow) -> f64| {
            let mut v: Vec<f64> = mine
                .iter()
                .map(|r| f(r))
                .filter(|x| x.is_finite())
                .collect();
            v.sort_by(f64::total_cmp);
            v
        };
        let err = sorted(&|r| r.test_error_rms_m);
        let causes = calib::model::extensions::Cause::ALL
            .iter()
            .enumerate()
            .filter_map(|(k, c)| {
                let z2: Vec<f64> = mine
                    .iter()
                    .map(|r| r.causes()[k].1)
                    .filter(|z| z.is_finite())
                    .collect();
                (!z2.is_empty()).then(|| CauseSummary {
                    cause: c.name().to_string(),
                    runs: z2.len(),
                    z2_mean: z2.iter().sum::<f64>() / z2.len() as f64,
                })
            })
            .collect();
        let g = spec.grid(cell);
        out.push(CellSummary {
            cell,
            magnitude: g.magnitude,
            payloads: spec.payload_label(g.payload_set),
            noise_scale: g.noise_scale,
            poses: g.poses,
            runs: mine.len(),
            not_converged: mine.iter().filter(|r| !r.converged).count(),
            sigma_median_m: quantile(&sorted(&|r| r.sigma_rms_m), 0.5),
            test_error_median_m: quantile(&err, 0.5),
            test_error_p10_m: quantile(&err, 0.1),
            test_error_p90_m: quantile(&err, 0.9),
            predicted_median_m: quantile(&sorted(&|r| r.test_error_predicted_m), 0.5),
            param_z2_mean_median: quantile(&sorted(&|r| r.param_z2_mean), 0.5),
            condition_number_median: quantile(&sorted(&|r| r.condition_number), 0.5),
            detected: (spec.score == Score::Diagnose)
                .then(|| mine.iter().filter(|r| r.detected).count()),
            false_alarms: (spec.score == Score::Diagnose)
                .then(|| mine.iter().filter(|r| r.false_alarm).count()),
            causes,
        });
    }
    out
}

/// The summary table (text for stderr).
pub fn summary_text(cells: &[CellSummary]) -> String {
    let mut s = String::from(
        " magn.  noise  σ (µm)  poses  runs   held-out error vs truth (µm): median [10 %, 90 %]   predicted   measured/predicted   z² mean   condition\n",
    );
    for c in cells {
        s.push_str(&format!(
            " {:>5}  {:>5}  {:>6.2}  {:>5}  {:>4}   {:>10.3} [{:>9.3}, {:>9.3}]              {:>9.3}   {:>18.3}   {:>7.3}   {:>9.3e}{}\n",
            c.magnitude,
            c.noise_scale,
            c.sigma_median_m * 1e6,
            c.poses,
            c.runs,
            c.test_error_median_m * 1e6,
            c.test_error_p10_m * 1e6,
            c.test_error_p90_m * 1e6,
            c.predicted_median_m * 1e6,
            c.test_error_median_m / c.predicted_median_m,
            c.param_z2_mean_median,
            c.condition_number_median,
            if c.not_converged > 0 {
                format!("   ({} not converged)", c.not_converged)
            } else {
                String::new()
            }
        ));
        if !c.payloads.is_empty() {
            s.push_str(&format!("        payloads: {} kg\n", c.payloads));
        }
        if let (Some(d), Some(f)) = (c.detected, c.false_alarms) {
            s.push_str(&format!(
                "        diagnose: detected in {d} of {} run(s), a false alarm in {f}\n",
                c.runs
            ));
        }
        for k in &c.causes {
            s.push_str(&format!(
                "        {}: mean z² of its parameters {:.3} over {} run(s)\n",
                k.cause, k.z2_mean, k.runs
            ));
        }
    }
    s
}

/// The plot: held-out error against the truth vs poses per run, log-log, one colour per noise level
/// (and magnitude, with several);
/// measured median (line and markers) with its 10–90 % band, and the covariance's prediction (dashed).
pub fn plot_svg(spec: &SweepSpec, cells: &[CellSummary]) -> String {
    use plot::{Plot, Series, Style};
    let mut series = Vec::new();
    let payloads: Vec<String> = (0..spec.payload_sets())
        .map(|k| spec.payload_label(spec.payloads.as_ref().map(|_| k)))
        .collect();
    let mut lines = Vec::new();
    for &m in &spec.magnitude {
        for p in &payloads {
            for &n in &spec.noise_scale {
                lines.push((m, p, n));
            }
        }
    }
    for (magnitude, payload, noise) in lines {
        let mine: Vec<&CellSummary> = cells
            .iter()
            .filter(|c| {
                c.noise_scale == noise && c.magnitude == magnitude && &c.payloads == payload
            })
            .collect();
        let mut label = if spec.magnitude.len() > 1 {
            format!("magnitude ×{magnitude}, noise ×{noise}")
        } else {
            format!("noise ×{noise}")
        };
        if !payload.is_empty() {
            label.push_str(&format!(", payloads {payload} kg"));
        }
        let x = |c: &CellSummary| c.poses as f64;
        series.push(Series {
            label: label.clone(),
            points: mine.iter().map(|c| (x(c), c.test_error_p10_m)).collect(),
            style: Style::Band {
                upper: mine.iter().map(|c| c.test_error_p90_m).collect(),
            },
        });
        series.push(Series {
            label: label.clone(),
            points: mine.iter().map(|c| (x(c), c.test_error_median_m)).collect(),
            style: Style::LineMarkers,
        });
        series.push(Series {
            label,
            points: mine.iter().map(|c| (x(c), c.predicted_median_m)).collect(),
            style: Style::Dashed,
        });
    }
    Plot {
        title: format!(
            "{}: held-out error vs truth — median (line), 10–90 % (band), predicted (dashed)",
            spec.scenario_file
        ),
        x_label: format!(
            "poses per run ({:.0} % calibrate, {:.0} % held out)",
            100.0 * (1.0 - spec.test_fraction),
            100.0 * spec.test_fraction
        ),
        y_label: "held-out RMS error vs truth (m)".into(),
        log_x: true,
        log_y: true,
        series,
    }
    .to_svg(800, 520)
}

/// Runs the runs of `subset` in parallel (rayon, the current pool) and returns their results in run
/// order; `tick` is called after each run. On failure, the error of the lowest failing run.
pub fn run_sweep(
    ctx: &Context<'_>,
    subset: Subset,
    tick: &(dyn Fn() + Sync),
) -> Result<Vec<RunResult>, CliError> {
    use rayon::prelude::*;
    let ids: Vec<RunId> = (0..ctx.spec.runs)
        .map(|r| ctx.spec.run_id(r))
        .filter(|id| subset.contains(id))
        .collect();
    let results: Vec<Result<RunResult, CliError>> = ids
        .par_iter()
        .map(|id| {
            let out = run_one(ctx, id);
            tick();
            out
        })
        .collect();
    results.into_iter().collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_interpolate_like_numpy() {
        // numpy.quantile([1, 2, 3, 4], [0.1, 0.5, 0.9]) = [1.3, 2.5, 3.7]
        let v = [1.0, 2.0, 3.0, 4.0];
        assert!((quantile(&v, 0.1) - 1.3).abs() < 1e-12);
        assert!((quantile(&v, 0.5) - 2.5).abs() < 1e-12);
        assert!((quantile(&v, 0.9) - 3.7).abs() < 1e-12);
        assert_eq!(quantile(&[5.0], 0.9), 5.0);
        assert!(quantile(&[], 0.5).is_nan());
    }

    #[test]
    fn split_counts_follow_calibs_split_by_pose() {
        use sim::measurement_table::{MeasurementTable, OptionalColumns, Row};
        for n in 1..120 {
            let mut t = MeasurementTable::new(1, OptionalColumns::NONE);
            for k in 0..n {
                t.push_row(&Row {
                    pose: k as i64,
                    q: &[0.0],
                    position: [0.0; 3],
                    ..Row::default()
                })
                .unwrap();
            }
            for f in [0.05, 0.3, 0.5, 0.9] {
                let (train, test) = calib::model::stats::split_by_pose(&t, f, 3);
                assert_eq!(
                    split_counts(n, f),
                    (train.len(), test.len()),
                    "n {n}, f {f}"
                );
            }
        }
    }

    #[test]
    fn run_seeds_depend_on_cell_and_rep_only() {
        // splitmix64 of 0 is 0xE220A8397B1DCDAF (Steele, Lea and Flood's reference output).
        assert_eq!(splitmix64(0), 0xE220_A839_7B1D_CDAF);
        let a = run_seed(7, 3, 2);
        assert_eq!(a, splitmix64(splitmix64(splitmix64(7) ^ 3) ^ 2));
        assert_ne!(a, run_seed(7, 2, 3));
        assert_ne!(a, run_seed(8, 3, 2));
    }

    #[test]
    fn runs_are_numbered_cell_major_and_shards_partition_them() {
        let spec = SweepSpec {
            format: "robocal-sweep".into(),
            format_version: FORMAT_VERSION,
            software_version: "test".into(),
            scenario_file: "s.toml".into(),
            scenario_fnv1a64: "0".into(),
            scenario_text: String::new(),
            magnitude: vec![1.0],
            magnitude_of: None,
            payloads: None,
            noise_scale: vec![0.5, 1.0],
            poses: vec![20, 40, 80],
            reps: 4,
            seed: 1,
            test_fraction: 0.3,
            model: "kinematic".into(),
            selection: Selection::Random,
            score: Score::Fit,
            candidates: None,
            cells: 6,
            runs: 24,
        };
        // Run 17 = cell 4 (17 / 4), rep 1; cell 4 = noise index 1, pose index 1.
        let id = spec.run_id(17);
        assert_eq!((id.cell, id.rep, id.noise_scale, id.poses), (4, 1, 1.0, 40));
        assert_eq!(id.magnitude, 1.0);
        // Magnitude outermost: with three magnitudes, cells 0-5 keep their noise and poses, and
        // cell 6 · 2 + 4 = 16 is magnitude 2 (index 2) at noise index 1, pose index 1.
        let mut three = spec.clone();
        three.magnitude = vec![0.0, 0.5, 2.0];
        three.cells = 18;
        three.runs = 72;
        for r in 0..24 {
            let (a, b) = (spec.run_id(r), three.run_id(r));
            assert_eq!(
                (a.cell, a.seed, a.noise_scale, a.poses),
                (b.cell, b.seed, b.noise_scale, b.poses)
            );
            assert_eq!(b.magnitude, 0.0);
        }
        let id = three.run_id(16 * 4 + 3);
        assert_eq!(
            (id.cell, id.magnitude, id.noise_scale, id.poses),
            (16, 2.0, 1.0, 40)
        );
        // Payload sets inside the magnitude: with two sets, cells 0-5 are set 0 of magnitude 0
        // with their noise and poses, cells 6-11 set 1; cell (2 · 2 + 1) · 6 + 4 = 34 is magnitude
        // index 2, set 1, noise index 1, pose index 1.
        let mut sets = three.clone();
        sets.payloads = Some(vec![vec![0.0], vec![0.0, 3.5, 7.0]]);
        sets.cells = 36;
        sets.runs = 144;
        for r in 0..24 {
            let (a, b) = (spec.run_id(r), sets.run_id(r));
            assert_eq!(
                (a.cell, a.seed, a.noise_scale, a.poses),
                (b.cell, b.seed, b.noise_scale, b.poses)
            );
            assert_eq!((b.magnitude, b.payload_set), (0.0, Some(0)));
        }
        let id = sets.run_id(34 * 4 + 2);
        assert_eq!(
            (
                id.cell,
                id.magnitude,
                id.payload_set,
                id.noise_scale,
                id.poses
            ),
            (34, 2.0, Some(1), 1.0, 40)
        );
        assert_eq!(sets.payload_label(id.payload_set), "0/3.5/7");
        assert_eq!(spec.run_id(3).payload_set, None);
        assert_eq!(spec.payload_label(None), "");
        let mut seen = [0; 24];
        for k in 0..5 {
            for (r, count) in seen.iter_mut().enumerate() {
                if (Subset::Shard { k, n: 5 }).contains(&spec.run_id(r)) {
                    *count += 1;
                }
            }
        }
        assert!(seen.iter().all(|&c| c == 1));
    }
}
