//! `robocal sweep`: a sensitivity study over effect magnitudes, noise levels and pose counts, for any
//! model `robocal calibrate` fits (see `crate::sweep` and `docs/sweep.md`), and `robocal sweep-merge`,
//! which joins the shards of one sweep.

use super::paths::Inputs;
use super::shared::{CliError, CliResult, print_json};
use crate::sweep::params_table::{self, ParamRow};
use crate::sweep::power;
use crate::sweep::table::{self, META_SUBSET, META_SWEEP, SweepRow};
use crate::sweep::{self as sw, Context, Score, Selection, Subset, SweepSpec};
use calib::fit::CalibrationOptions;
use calib::model::spec::ModelChoice;
use sim::scenario::{Overrides, Scenario};
use std::io::IsTerminal;
use std::path::{Path, PathBuf};

/// Arguments of `robocal sweep`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scenario file (TOML), as for `robocal generate`.
    #[arg(long, value_name = "FILE.toml")]
    scenario: PathBuf,
    /// Noise multipliers, comma-separated (each as `robocal generate --noise`: a factor on the
    /// scenario's tracker noise model; 1 = the scenario's noise, 0 = none).
    #[arg(long, value_name = "LIST", allow_hyphen_values = true)]
    noise: String,
    /// Poses generated per run, comma-separated (each as `robocal generate --poses`); the training set
    /// is the part not held out (--test-fraction).
    #[arg(long, value_name = "LIST", allow_hyphen_values = true)]
    poses: String,
    /// Runs (repetitions) per cell (magnitude × payload set × noise level × pose count).
    #[arg(long, value_name = "N", allow_hyphen_values = true)]
    reps: String,
    /// Factors on the scenario's injected effects, comma-separated (each ≥ 0: 1 = the scenario as
    /// written, 0 = the effect absent; a joint stiffness is divided by it). Default: 1 alone.
    #[arg(long, value_name = "LIST", allow_hyphen_values = true)]
    magnitude: Option<String>,
    /// Scale only this effect with --magnitude (e.g. gear_backlash or its key backlash); the
    /// others stay as the scenario writes them.
    #[arg(long, value_name = "CAUSE")]
    magnitude_of: Option<String>,
    /// Payload sets, comma-separated, the masses of a set separated by `/` (kg): a run draws every
    /// pose's payload from its set (`0/3.5/7`: one of them per pose; `7`: every pose), at the
    /// scenario's centre of mass. `0,7,0/3.5/7` sweeps three sets. Default: the scenario's payloads.
    #[arg(long, value_name = "SETS", allow_hyphen_values = true)]
    payloads: Option<String>,
    /// Output Parquet file, one row per run; the plot goes beside it as FILE.svg and the extension
    /// parameters' errors as FILE.params.parquet (one row per run and parameter); with
    /// --score diagnose the power table as FILE.power.csv and the plot shows power curves.
    #[arg(long, value_name = "FILE.parquet")]
    out: PathBuf,
    /// Sweep seed; every run derives its own seed from it, its cell and its repetition.
    #[arg(long, value_name = "N", default_value_t = 0)]
    seed: u64,
    /// Fitted model, as `robocal calibrate --model`: `kinematic`, `+`-joined causes (a cause may
    /// be limited to joints, `joint_compliance@2,4`), a learned correction, or `auto` (resolved per
    /// run on its training poses).
    #[arg(long, value_name = "MODEL", default_value = "kinematic")]
    model: String,
    /// Pose selection: `random` (the scenario's campaign) or `planned` (D-optimal choice, for the
    /// fitted model's parameters and with the payload of each pose among the campaign's masses, of
    /// --candidates poses drawn by the scenario's campaign).
    #[arg(long, value_name = "random|planned", value_enum, default_value_t = Selection::Random)]
    selection: Selection,
    /// What to score: `fit` (the fitted model against the truth) or `diagnose` (also run
    /// `robocal diagnose` on every run's data: the columns hidden, named, detected, false_alarm).
    #[arg(long, value_name = "fit|diagnose", value_enum, default_value_t = Score::Fit)]
    score: Score,
    /// Candidate poses per planned run (default: 10 × the pose count).
    #[arg(long, value_name = "N")]
    candidates: Option<usize>,
    /// Fraction of each run's poses held out for scoring (as `robocal calibrate --test-fraction`).
    #[arg(long, value_name = "F", default_value_t = 0.3)]
    test_fraction: f64,
    /// Run only shard K of N (0 ≤ K < N): the runs whose index is K modulo N. Merge the shards
    /// with `robocal sweep-merge`.
    #[arg(long, value_name = "K/N")]
    shard: Option<String>,
    /// Run only cell K (0-based, as the `cell` column): to reproduce one cell alone.
    #[arg(long, value_name = "K")]
    only_cell: Option<usize>,
    /// Print the per-cell summary as one JSON document on stdout.
    #[arg(long)]
    json: bool,
}

/// Arguments of `robocal sweep-merge`.
#[derive(clap::Args, Debug)]
pub struct MergeArgs {
    /// Output Parquet file (byte-identical to a single-machine run of the same sweep); the plot goes
    /// beside it as FILE.svg (and, for --score diagnose, the power table as FILE.power.csv).
    #[arg(long, value_name = "F.parquet")]
    out: PathBuf,
    /// Shard files written by `robocal sweep --shard K/N` (or `--only-cell`) of one sweep; each
    /// shard's parameter table is read beside it (`SHARD.params.parquet`; given as a SHARD too, as
    /// a glob `part*.parquet` does, it is skipped).
    #[arg(value_name = "SHARD", required = true)]
    shards: Vec<PathBuf>,
    /// Print the per-cell summary as one JSON document on stdout.
    #[arg(long)]
    json: bool,
}

fn input(flag: &str, value: &str, problem: &str) -> CliError {
    CliError::Input(format!("{flag} {value}: {problem}"))
}

/// Parses a comma-separated list with `parse`, refusing empty items and duplicates.
fn parse_list<T: PartialEq + Copy>(
    flag: &str,
    text: &str,
    what: &str,
    parse: impl Fn(&str) -> Option<T>,
) -> Result<Vec<T>, CliError> {
    let mut out = Vec::new();
    for (i, item) in text.split(',').enumerate() {
        let item = item.trim();
        let v = parse(item).ok_or_else(|| {
            input(
                flag,
                text,
                &format!("item {} ('{item}') is not {what}", i + 1),
            )
        })?;
        if out.contains(&v) {
            return Err(input(
                flag,
                text,
                &format!("item {} ('{item}') repeats an earlier one", i + 1),
            ));
        }
        out.push(v);
    }
    Ok(out)
}

/// `--noise`: finite multipliers ≥ 0.
pub(crate) fn parse_noise(text: &str) -> Result<Vec<f64>, CliError> {
    parse_list("--noise", text, "a finite multiplier ≥ 0", |s| {
        s.parse::<f64>().ok().filter(|v| v.is_finite() && *v >= 0.0)
    })
}

/// `--magnitude`: finite factors ≥ 0 (`[1]` when not given).
pub(crate) fn parse_magnitude(text: Option<&str>) -> Result<Vec<f64>, CliError> {
    match text {
        None => Ok(vec![1.0]),
        Some(t) => parse_list("--magnitude", t, "a finite factor ≥ 0", |s| {
            s.parse::<f64>().ok().filter(|v| v.is_finite() && *v >= 0.0)
        }),
    }
}

/// `--payloads`: sets separated by commas, masses within a set by `/`; each mass finite, ≥ 0 and at
/// most [`sim::measurement_table::MAX_PAYLOAD_KG`] (what a measurement table accepts); no set twice,
/// no mass twice within a set.
pub(crate) fn parse_payloads(text: &str) -> Result<Vec<Vec<f64>>, CliError> {
    const MAX_PAYLOAD_KG: f64 = sim::measurement_table::MAX_PAYLOAD_KG;
    let mut sets: Vec<Vec<f64>> = Vec::new();
    for (i, item) in text.split(',').enumerate() {
        let item = item.trim();
        let bad = |p: &str| {
            input(
                "--payloads",
                text,
                &format!("set {} ('{item}'): {p}", i + 1),
            )
        };
        let mut set: Vec<f64> = Vec::new();
        for m in item.split('/') {
            let v = m
                .trim()
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite() && (0.0..=MAX_PAYLOAD_KG).contains(v))
                .ok_or_else(|| {
                    bad(&format!(
                        "'{}' is not a mass in kg between 0 and {MAX_PAYLOAD_KG}",
                        m.trim()
                    ))
                })?;
            if set.contains(&v) {
                return Err(bad(&format!("{v} kg appears twice")));
            }
            set.push(v);
        }
        if sets.contains(&set) {
            return Err(bad("repeats an earlier set"));
        }
        sets.push(set);
    }
    Ok(sets)
}

/// The number of cause parameters `spec` fits on `res`'s data (its campaign simulated once, every
/// pose for training), as each run configures them.
fn extension_param_count(
    res: &sim::scenario::Resolved,
    spec: &calib::model::spec::ModelSpec,
) -> Result<usize, CliError> {
    let plan = sim::generate::plan_of(res)?;
    let truth = sim::effects::Truth::new(&res.model, &res.effects)?;
    let run = sim::generate::simulate(&truth, &res.tracker, &res.gravity, &plan, res.seed, None)?;
    let table = sim::generate::measurement_table(&plan, &run, &res.tracker);
    let rows: Vec<usize> = (0..table.len()).collect();
    let settings = calib::model::extensions::ExtensionSettings::for_data(
        &res.model,
        &spec.causes,
        &spec.joints,
        &table,
        &rows,
        "the sweep's first run",
    )?;
    Ok(settings.params(&res.model).len())
}

/// `--poses`: integers ≥ 1.
pub(crate) fn parse_poses(text: &str) -> Result<Vec<usize>, CliError> {
    let poses = parse_list("--poses", text, "a whole number ≥ 1", |s| {
        s.parse::<usize>().ok().filter(|v| *v >= 1)
    })?;
    for p in &poses {
        sim::campaign::check_row_count(Some(*p), &format!("--poses {text}: item {p}"))
            .map_err(CliError::Input)?;
    }
    Ok(poses)
}

/// `--shard K/N` with `0 ≤ K < N`.
pub(crate) fn parse_shard(text: &str) -> Result<Subset, CliError> {
    let bad = |p: &str| input("--shard", text, p);
    let (k, n) = text
        .split_once('/')
        .ok_or_else(|| bad("expected K/N, e.g. 0/4 (shard K of N, 0-based)"))?;
    let k: usize = k
        .trim()
        .parse()
        .map_err(|_| bad("K is not a whole number"))?;
    let n: usize = n
        .trim()
        .parse()
        .map_err(|_| bad("N is not a whole number"))?;
    if n == 0 {
        return Err(bad("N must be ≥ 1"));
    }
    if k >= n {
        return Err(bad(&format!("K must be between 0 and N − 1 = {}", n - 1)));
    }
    Ok(Subset::Shard { k, n })
}

/// The plot's path beside `out`: `out` with the extension `svg`.
fn plot_path(out: &Path) -> PathBuf {
    out.with_extension("svg")
}

/// The power table's path beside `out` (`--score diagnose`): `out` with the extension `power.csv`.
fn power_path(out: &Path) -> PathBuf {
    out.with_extension("power.csv")
}

/// Refuses an `--out` (or the plot, power or parameter table beside it) that is one of `inputs`.
fn check_outputs(inputs: &Inputs, out: &Path) -> CliResult {
    inputs.check("--out", out)?;
    inputs.check_as("--out", out, &plot_path(out))?;
    inputs.check_as("--out", out, &power_path(out))?;
    inputs.check_as("--out", out, &params_table::path_beside(out))
}

fn write(path: &Path, bytes: &[u8]) -> CliResult {
    Ok(sim::io::write_atomic(path, bytes)?)
}

/// Writes the sweep file and its parameter table (and, for a complete sweep, its plot) and reports
/// on stderr / stdout.
fn finish(
    spec: &SweepSpec,
    rows: &[SweepRow],
    params: &[ParamRow],
    subset: Option<String>,
    out: &Path,
    json: bool,
) -> CliResult {
    let doc = |cols: &[(&str, &str)]| {
        let m: serde_json::Map<String, serde_json::Value> = cols
            .iter()
            .map(|(n, d)| (n.to_string(), serde_json::Value::from(*d)))
            .collect();
        serde_json::Value::Object(m).to_string()
    };
    let mut meta = vec![
        (META_SWEEP.to_string(), spec.to_json()),
        (table::META_COLUMNS.to_string(), doc(table::COLUMNS)),
    ];
    let mut param_meta = vec![
        (META_SWEEP.to_string(), spec.to_json()),
        (table::META_COLUMNS.to_string(), doc(params_table::COLUMNS)),
    ];
    if let Some(s) = &subset {
        meta.push((META_SUBSET.to_string(), s.clone()));
        param_meta.push((META_SUBSET.to_string(), s.clone()));
    }
    let bytes = table::parquet_bytes(rows, &meta).map_err(CliError::Runtime)?;
    write(out, &bytes)?;
    let params_out = params_table::path_beside(out);
    let bytes = params_table::parquet_bytes(params, &param_meta).map_err(CliError::Runtime)?;
    write(&params_out, &bytes)?;
    let cells = sw::summarize(spec, rows);
    // A partial file's cells are incomplete: no plot and no power table for it.
    let power = subset.is_none().then(|| power::power(&cells)).flatten();
    let power_out = match &power {
        Some(p) => {
            let path = power_path(out);
            write(&path, power::csv(p).as_bytes())?;
            Some(path)
        }
        None => None,
    };
    let plot = if subset.is_none() {
        let p = plot_path(out);
        let svg = match &power {
            Some(pw) => power::plot_svg(&spec.scenario_file, pw),
            None => sw::plot_svg(spec, &cells),
        };
        write(&p, svg.as_bytes())?;
        Some(p)
    } else {
        None
    };
    eprint!("{}", sw::summary_text(&cells));
    if let Some(p) = &power {
        eprint!("{}", power::summary_text(p));
    }
    eprintln!(
        "wrote {} ({} runs{}), {} ({} parameter rows){}{}",
        out.display(),
        rows.len(),
        subset.as_ref().map_or(String::new(), |s| format!(", {s}")),
        params_out.display(),
        params.len(),
        power_out
            .as_ref()
            .map_or(String::new(), |p| format!(", {}", p.display())),
        plot.as_ref()
            .map_or(String::new(), |p| format!(" and {}", p.display()))
    );
    if json {
        print_json(&serde_json::json!({
            "out": out.display().to_string(),
            "params": params_out.display().to_string(),
            "plot": plot.map(|p| p.display().to_string()),
            "power_table": power_out.map(|p| p.display().to_string()),
            "power": power,
            "subset": subset,
            "runs": rows.len(),
            "cells": cells,
        }))?;
    }
    Ok(())
}

/// Runs `robocal sweep`.
pub fn run(args: Args) -> CliResult {
    let noise = parse_noise(&args.noise)?;
    let poses = parse_poses(&args.poses)?;
    let reps: usize = args
        .reps
        .trim()
        .parse()
        .ok()
        .filter(|v| *v >= 1)
        .ok_or_else(|| input("--reps", &args.reps, "must be a whole number ≥ 1"))?;
    let magnitude = parse_magnitude(args.magnitude.as_deref())?;
    let payloads = args.payloads.as_deref().map(parse_payloads).transpose()?;
    let payload_sets = payloads.as_ref().map_or(1, Vec::len);
    let magnitude_of = match &args.magnitude_of {
        None => None,
        Some(_) if args.magnitude.is_none() => {
            return Err(CliError::Input(
                "--magnitude-of: only with --magnitude (the factors to scale it by)".into(),
            ));
        }
        Some(w) => Some(sw::magnitude::effect_named(w.trim()).ok_or_else(|| {
            input(
                "--magnitude-of",
                w,
                &format!("not an effect (known: {})", sw::magnitude::effect_names()),
            )
        })?),
    };
    // The same parser as `robocal calibrate --model`; `None` is `auto`.
    let model_spec = match args.model.parse::<ModelChoice>()? {
        ModelChoice::Auto => None,
        ModelChoice::Model(m) => Some(m),
    };
    let selection = args.selection;
    if args.candidates.is_some() && selection != Selection::Planned {
        return Err(input(
            "--candidates",
            &args.candidates.unwrap_or(0).to_string(),
            "only with --selection planned",
        ));
    }
    if !(args.test_fraction > 0.0 && args.test_fraction < 1.0) {
        return Err(input(
            "--test-fraction",
            &args.test_fraction.to_string(),
            "must be in (0, 1): the sweep scores on held-out poses",
        ));
    }
    let subset = match (&args.shard, args.only_cell) {
        (Some(_), Some(_)) => {
            return Err(CliError::Input(
                "--shard and --only-cell: give one of them, not both".into(),
            ));
        }
        (Some(s), None) => parse_shard(s)?,
        (None, Some(c)) => {
            let cells = magnitude.len() * payload_sets * noise.len() * poses.len();
            if c >= cells {
                return Err(input(
                    "--only-cell",
                    &c.to_string(),
                    &format!("the grid has {cells} cells (0 … {})", cells - 1),
                ));
            }
            Subset::Cell(c)
        }
        (None, None) => Subset::All,
    };
    let runs = magnitude
        .len()
        .checked_mul(payload_sets)
        .and_then(|c| c.checked_mul(noise.len()))
        .and_then(|c| c.checked_mul(poses.len()))
        .and_then(|c| c.checked_mul(reps))
        .filter(|r| *r <= 100_000_000)
        .ok_or_else(|| input("--reps", &args.reps, "the grid has more than 10⁸ runs"))?;
    if let Some(dir) = args.out.parent().filter(|d| !d.as_os_str().is_empty())
        && !dir.is_dir()
    {
        return Err(input(
            "--out",
            &args.out.display().to_string(),
            &format!("folder {} does not exist", dir.display()),
        ));
    }
    let scenario = Scenario::load(&args.scenario)?;
    check_outputs(
        Inputs::new().add_scenario("--scenario", &args.scenario, &scenario),
        &args.out,
    )?;
    // Check the scenario and the smallest pose count once, before any work.
    let probe = scenario.resolve(&Overrides {
        seed: Some(args.seed),
        poses: Some(poses[0]),
        noise: Some(noise[0]),
    })?;
    // And the largest, so that a count beyond the campaign limit is refused before any work.
    scenario.resolve(&Overrides {
        seed: Some(args.seed),
        poses: poses.iter().max().copied(),
        noise: Some(noise[0]),
    })?;
    if let Some(m) = &model_spec {
        m.check_joints(probe.model.nq())?;
    }
    if let Some(id) = magnitude_of
        && !probe.effects.contains(id)
    {
        return Err(input(
            "--magnitude-of",
            args.magnitude_of.as_deref().unwrap_or_default(),
            &format!(
                "the scenario {} injects no {}",
                args.scenario.display(),
                id.name()
            ),
        ));
    }
    // The largest factor must leave every effect within what the simulator accepts.
    if let Some(&m) = magnitude.iter().max_by(|a, b| a.total_cmp(b)) {
        sw::magnitude::scaled(&probe.effects, m, magnitude_of)?;
    }
    let options = CalibrationOptions::default();
    let orientation = probe.tracker.six_dof();
    let rank = calib::fit::generic_rank(&probe.model, orientation, &options);
    let dim = if orientation { 6 } else { 3 };
    // An extended model fits its causes' parameters beside the kinematic ones: with fewer training
    // coordinates than parameters the fit is underdetermined and its σ mean nothing (at 11 training
    // poses, 33 coordinates for the iiwa 7's 31 + 7 compliance parameters, z² reached 10¹²).
    let extension = match &model_spec {
        Some(m) if !m.causes.is_empty() => {
            let mut res = probe.clone();
            if let Some(sets) = &payloads {
                res.campaign = sw::with_payloads(&res, &sets[0])?;
            }
            extension_param_count(&res, m)?
        }
        _ => 0,
    };
    let needed = (rank + extension + 1).div_ceil(dim);
    for &n in &poses {
        let (n_train, n_test) = sw::split_counts(n, args.test_fraction);
        if n_train < needed {
            let what = if extension > 0 {
                format!(
                    "the model {} of '{}' has {rank} identifiable kinematic combinations and \
                     {extension} cause parameters",
                    model_spec.as_ref().map_or_else(String::new, |m| m.name()),
                    probe.model.name()
                )
            } else {
                format!(
                    "the kinematic model of '{}' has {rank} identifiable combinations",
                    probe.model.name()
                )
            };
            return Err(input(
                "--poses",
                &args.poses,
                &format!(
                    "{n} poses leave {n_train} for calibration after holding out {n_test}, but {what}: \
                     at least {needed} calibration poses are needed"
                ),
            ));
        }
    }
    let scenario_file = args.scenario.file_name().map_or_else(
        || args.scenario.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    );
    let spec = SweepSpec {
        format: "robocal-sweep".into(),
        format_version: sw::FORMAT_VERSION,
        software_version: env!("CARGO_PKG_VERSION").into(),
        scenario_file,
        scenario_fnv1a64: format!("{:016x}", sim::scenario::fnv1a64(scenario.text.as_bytes())),
        scenario_text: scenario.text.clone(),
        magnitude,
        magnitude_of: magnitude_of.map(|e| e.name().to_string()),
        payloads,
        noise_scale: noise,
        poses,
        reps,
        seed: args.seed,
        test_fraction: args.test_fraction,
        model: model_spec
            .as_ref()
            .map_or_else(|| "auto".to_string(), |m| m.name()),
        selection,
        score: args.score,
        candidates: args.candidates,
        cells: runs / reps,
        runs,
    };
    let ctx = Context {
        scenario: &scenario,
        spec: &spec,
        options,
        model: model_spec,
        magnitude_of,
    };
    let todo = (0..runs)
        .filter(|&r| subset.contains(&spec.run_id(r)))
        .count();
    let bar = std::io::stderr().is_terminal().then(|| {
        let b = indicatif::ProgressBar::new(todo as u64);
        if let Ok(style) = indicatif::ProgressStyle::with_template(
            "{spinner} sweep {pos}/{len} runs [{bar:40}] {elapsed} (eta {eta})",
        ) {
            b.set_style(style.progress_chars("=> "));
        }
        b
    });
    let tick = || {
        if let Some(b) = &bar {
            b.inc(1);
        }
    };
    let started = std::time::Instant::now();
    let rows = sw::run_sweep(&ctx, subset, &tick);
    if let Some(b) = &bar {
        b.finish_and_clear();
    }
    let results = rows?;
    let mut rows: Vec<SweepRow> = Vec::with_capacity(results.len());
    let mut params: Vec<ParamRow> = Vec::new();
    for r in results {
        rows.push(r.row);
        params.extend(r.params);
    }
    eprintln!(
        "sweep of {}: {} magnitude(s) × {} payload set(s) × {} noise level(s) × {} pose count(s) × {} reps; {} run(s) in {:.1} s on {} thread(s) ({} model, {} poses)",
        spec.scenario_file,
        spec.magnitude.len(),
        spec.payload_sets(),
        spec.noise_scale.len(),
        spec.poses.len(),
        spec.reps,
        rows.len(),
        started.elapsed().as_secs_f64(),
        rayon::current_num_threads(),
        spec.model,
        match spec.selection {
            Selection::Random => "random",
            Selection::Planned => "planned",
        }
    );
    finish(
        &spec,
        &rows,
        &params,
        subset.describe(),
        &args.out,
        args.json,
    )
}

/// Runs `robocal sweep-merge`.
pub fn run_merge(mut args: MergeArgs) -> CliResult {
    // A shell glob `part*.parquet` also names the shards' parameter tables: those are read beside
    // their shards, not as shards.
    let tables: Vec<PathBuf> = args
        .shards
        .iter()
        .map(|s| params_table::path_beside(s))
        .collect();
    args.shards.retain(|s| !tables.contains(s));
    let mut inputs = Inputs::new();
    let param_paths: Vec<PathBuf> = args
        .shards
        .iter()
        .map(|s| params_table::path_beside(s))
        .collect();
    for (s, p) in args.shards.iter().zip(&param_paths) {
        inputs.add("SHARD", s);
        inputs.add("SHARD", p);
    }
    check_outputs(&inputs, &args.out)?;
    let mut params: Vec<ParamRow> = Vec::new();
    let mut spec_text: Option<(String, PathBuf)> = None;
    let mut owner: Vec<Option<usize>> = Vec::new();
    let mut rows: Vec<Option<SweepRow>> = Vec::new();
    let mut spec: Option<SweepSpec> = None;
    for (f, path) in args.shards.iter().enumerate() {
        let file = table::read(path).map_err(CliError::Input)?;
        let name = path.display().to_string();
        let text = file
            .meta(META_SWEEP)
            .ok_or_else(|| {
                CliError::Input(format!(
                    "{name}: no '{META_SWEEP}' metadata: not a robocal sweep file"
                ))
            })?
            .to_string();
        match &spec_text {
            None => {
                let s: SweepSpec = serde_json::from_str(&text).map_err(|e| {
                    CliError::Input(format!(
                        "{name}: '{META_SWEEP}' metadata is not a sweep description: {e}"
                    ))
                })?;
                if s.runs != s.cells * s.reps
                    || s.magnitude.is_empty()
                    || s.payloads.as_ref().is_some_and(Vec::is_empty)
                    || s.cells
                        != s.magnitude.len()
                            * s.payload_sets()
                            * s.noise_scale.len()
                            * s.poses.len()
                {
                    return Err(CliError::Input(format!(
                        "{name}: inconsistent sweep description (cells {}, reps {}, runs {})",
                        s.cells, s.reps, s.runs
                    )));
                }
                owner = vec![None; s.runs];
                rows = vec![None; s.runs];
                spec = Some(s);
                spec_text = Some((text, path.clone()));
            }
            Some((first, first_path)) if *first != text => {
                return Err(CliError::Input(format!(
                    "{name}: from a different sweep than {} (scenario, grid, seed or settings differ)",
                    first_path.display()
                )));
            }
            Some(_) => {}
        }
        let s = spec
            .as_ref()
            .ok_or_else(|| CliError::Runtime("no sweep".into()))?;
        for row in file.rows {
            let r = usize::try_from(row.run)
                .ok()
                .filter(|r| *r < s.runs)
                .ok_or_else(|| {
                    CliError::Input(format!(
                        "{name}: run {} is outside the sweep's 0 … {}",
                        row.run,
                        s.runs - 1
                    ))
                })?;
            let id = s.run_id(r);
            if row.cell != id.cell as i64 || row.rep != id.rep as i64 || row.seed != id.seed {
                return Err(CliError::Input(format!(
                    "{name}: run {r} does not match the sweep's grid (cell {}, rep {}, seed {})",
                    row.cell, row.rep, row.seed
                )));
            }
            if let Some(other) = owner[r] {
                return Err(CliError::Input(format!(
                    "{name}: run {r} (cell {}, rep {}) is also in {}: the shards overlap",
                    id.cell,
                    id.rep,
                    args.shards[other].display()
                )));
            }
            owner[r] = Some(f);
            rows[r] = Some(row);
        }
        let pp = &param_paths[f];
        if !pp.is_file() {
            return Err(CliError::Input(format!(
                "{name}: its parameter table {} is missing (robocal sweep writes it beside the shard)",
                pp.display()
            )));
        }
        for p in params_table::read(pp).map_err(CliError::Input)? {
            let mine = usize::try_from(p.run)
                .ok()
                .and_then(|r| owner.get(r).copied().flatten())
                == Some(f);
            if !mine {
                return Err(CliError::Input(format!(
                    "{}: run {} is not a run of {name}",
                    pp.display(),
                    p.run
                )));
            }
            params.push(p);
        }
    }
    // Stable: within a run, the model file's parameter order is kept.
    params.sort_by_key(|p| p.run);
    let spec = spec.ok_or_else(|| CliError::Input("sweep-merge: no shard files given".into()))?;
    let missing: Vec<usize> = (0..spec.runs).filter(|&r| rows[r].is_none()).collect();
    if !missing.is_empty() {
        let first = spec.run_id(missing[0]);
        return Err(CliError::Input(format!(
            "sweep-merge: {} of {} runs are missing, the first run {} (cell {}, rep {}): a shard was not given",
            missing.len(),
            spec.runs,
            first.run,
            first.cell,
            first.rep
        )));
    }
    let rows: Vec<SweepRow> = rows.into_iter().flatten().collect();
    eprintln!(
        "merged {} file(s) of the sweep of {}: {} runs",
        args.shards.len(),
        spec.scenario_file,
        rows.len()
    );
    finish(&spec, &rows, &params, None, &args.out, args.json)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn msg(e: CliError) -> String {
        assert_eq!(e.exit_code(), 2);
        e.to_string()
    }

    #[test]
    fn lists_parse_and_bad_items_are_named() {
        assert_eq!(
            parse_noise("0, 0.5,1,2e0").unwrap(),
            vec![0.0, 0.5, 1.0, 2.0]
        );
        assert_eq!(parse_poses("20,40").unwrap(), vec![20, 40]);
        let e = msg(parse_noise("1,abc").unwrap_err());
        assert!(e.starts_with("--noise 1,abc: item 2 ('abc')"), "{e}");
        assert!(msg(parse_noise("-1").unwrap_err()).contains("≥ 0"));
        assert!(msg(parse_noise("1,,2").unwrap_err()).contains("item 2 ('')"));
        assert!(msg(parse_noise("nan").unwrap_err()).starts_with("--noise"));
        assert!(msg(parse_poses("20,0").unwrap_err()).starts_with("--poses 20,0: item 2"));
        assert!(msg(parse_poses("20,20").unwrap_err()).contains("repeats"));
        assert!(msg(parse_poses("2.5").unwrap_err()).starts_with("--poses"));
    }

    #[test]
    fn shards_are_0_based_and_checked() {
        assert_eq!(parse_shard("0/4").unwrap(), Subset::Shard { k: 0, n: 4 });
        assert_eq!(parse_shard("3/4").unwrap(), Subset::Shard { k: 3, n: 4 });
        for bad in ["4/4", "1/0", "x/2", "2", "-1/3", "1/2/3"] {
            let e = msg(parse_shard(bad).unwrap_err());
            assert!(e.starts_with(&format!("--shard {bad}:")), "{e}");
        }
    }
}
