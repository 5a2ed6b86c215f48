//! `robocal demo`: the whole loop on the embedded iiwa 7. A hidden effect is drawn, a campaign is
//! simulated with it, and `diagnose` (which sees only the measurement file) has to find it; the findings
//! are printed beside the truth and a report is written.

use super::diagnose::{options, run_diagnosis, text};
use super::shared::read_table;
use super::shared::{CliError, CliResult, print_json};
use crate::report;
use rand::{RngExt, SeedableRng};
use serde_json::json;
use sim::effects::gear_backlash::BacklashMode;
use sim::effects::thermal_drift::{TemperatureProfile, WarmUp};
use sim::scenario::{Magnitude, Overrides, Scenario, ScenarioBuilder};
use std::path::{Path, PathBuf};

/// The scenario every demo starts from: the iiwa 7 with drawn geometric errors.
const BASE_SCENARIO: &str = include_str!("../../scenarios/iiwa7_kinematic.toml");

/// Arguments of `robocal demo`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Seed of the hidden effect and the campaign (default: drawn from the clock and printed).
    #[arg(long, value_name = "N")]
    seed: Option<u64>,
    /// Output folder: the campaign (measurements.parquet, truth.json, truth.parquet) and report/.
    #[arg(long, value_name = "DIR", default_value = "robocal-demo")]
    out: PathBuf,
    /// Poses in the campaign (two thirds calibrate, one third is held out).
    #[arg(long, value_name = "N", default_value_t = 300)]
    poses: usize,
    /// Print one JSON document (hidden effect, diagnosis, verdict) on stdout.
    #[arg(long)]
    json: bool,
}

/// What a hidden effect adds to the scenario.
#[derive(Clone, Debug)]
enum Injection {
    /// `[effects.compliance]` with this stiffness per joint (N m/rad; inf = rigid).
    Compliance(Vec<f64>),
    /// `[effects.backlash]`, direction mode, with this dead band per joint (rad).
    Backlash(Vec<f64>),
    /// A warm-up by this many kelvin (τ 30 min) and `[effects.thermal]` with aluminium links.
    Thermal(f64),
}

impl Injection {
    fn apply(&self, b: ScenarioBuilder) -> Result<ScenarioBuilder, CliError> {
        let list = |v: &[f64]| Magnitude::List(v.iter().map(|x| Magnitude::Number(*x)).collect());
        Ok(match self {
            Injection::Compliance(k) => b.compliance(list(k)),
            Injection::Backlash(band) => b.backlash(list(band), BacklashMode::Direction),
            Injection::Thermal(delta) => b
                .temperature(TemperatureProfile::WarmUp(WarmUp::new(
                    20.0, *delta, 1800.0,
                )?))
                .thermal(20.0, Magnitude::Number(23e-6), Some(Magnitude::Number(0.0))),
        })
    }
}

/// A hidden effect: its cause, joints (1-based) and what it adds to the scenario.
#[derive(Clone, Debug, serde::Serialize)]
struct Hidden {
    cause: &'static str,
    joints: Vec<usize>,
    description: String,
    #[serde(skip)]
    injection: Injection,
}

/// Distinct joints drawn from `pool`, `count` of them, ascending.
fn draw_joints(rng: &mut rand::rngs::StdRng, pool: &[usize], count: usize) -> Vec<usize> {
    let mut left = pool.to_vec();
    let mut out = Vec::new();
    for _ in 0..count.min(left.len()) {
        let k = rng.random_range(0..left.len());
        out.push(left.remove(k));
    }
    out.sort_unstable();
    out
}

/// One value per joint of the iiwa 7: `value(j)` at `joints`, `rest` elsewhere.
fn per_joint(joints: &[usize], value: impl Fn(usize) -> f64, rest: f64) -> Vec<f64> {
    (1..=7)
        .map(|j| if joints.contains(&j) { value(j) } else { rest })
        .collect()
}

/// Draws what to hide: nothing, compliance, backlash, thermal drift, or compliance and backlash.
fn draw_hidden(rng: &mut rand::rngs::StdRng) -> Vec<Hidden> {
    let compliance = |rng: &mut rand::rngs::StdRng| {
        // Joints whose gravity torque moves the target measurably without payload.
        let count = rng.random_range(1..=2);
        let joints = draw_joints(rng, &[2, 3, 4], count);
        let k: Vec<f64> = joints.iter().map(|_| rng.random_range(5e3..2e4)).collect();
        let stiff = |j: usize| k[joints.iter().position(|x| *x == j).unwrap_or(0)];
        Hidden {
            cause: "joint_compliance",
            description: format!(
                "joint stiffness {} N m/rad",
                joints
                    .iter()
                    .map(|&j| format!("{:.0} at joint {j}", stiff(j)))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
            injection: Injection::Compliance(per_joint(&joints, stiff, f64::INFINITY)),
            joints,
        }
    };
    let backlash = |rng: &mut rand::rngs::StdRng, avoid: &[usize]| {
        let pool: Vec<usize> = (1..=5).filter(|j| !avoid.contains(j)).collect();
        let count = rng.random_range(1..=2);
        let joints = draw_joints(rng, &pool, count);
        let b: Vec<f64> = joints
            .iter()
            .map(|_| rng.random_range(2e-4..6e-4))
            .collect();
        let band = |j: usize| b[joints.iter().position(|x| *x == j).unwrap_or(0)];
        Hidden {
            cause: "gear_backlash",
            description: format!(
                "lost motion {} rad",
                joints
                    .iter()
                    .map(|&j| format!("{:.2e} at joint {j}", band(j)))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
            injection: Injection::Backlash(per_joint(&joints, band, 0.0)),
            joints,
        }
    };
    match rng.random_range(0..5) {
        0 => Vec::new(),
        1 => vec![compliance(rng)],
        2 => vec![backlash(rng, &[])],
        3 => {
            let delta = rng.random_range(5.0..15.0);
            vec![Hidden {
                cause: "thermal_drift",
                joints: Vec::new(),
                description: format!("warm-up by {delta:.1} K (τ 30 min), aluminium links"),
                injection: Injection::Thermal(delta),
            }]
        }
        _ => {
            let c = compliance(rng);
            let b = backlash(rng, &c.joints);
            vec![c, b]
        }
    }
}

fn clock_seed() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs() % 1_000_000)
}

/// Runs `robocal demo`.
pub fn run(args: Args) -> CliResult {
    if args.poses < 60 {
        return Err(CliError::Input(format!(
            "--poses {}: the demo needs at least 60 poses",
            args.poses
        )));
    }
    sim::campaign::check_row_count(Some(args.poses), &format!("--poses {}", args.poses))
        .map_err(CliError::Input)?;
    let seed = args.seed.unwrap_or_else(clock_seed);
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let hidden = draw_hidden(&mut rng);
    let base = Scenario::parse(BASE_SCENARIO, "demo scenario", Path::new("."))?;
    let mut builder = ScenarioBuilder::from_scenario(&base).name("iiwa7_demo");
    for h in &hidden {
        builder = h.injection.apply(builder)?;
    }
    let resolved = builder.resolve(&Overrides {
        seed: Some(seed),
        poses: Some(args.poses),
        noise: None,
    })?;
    if !args.json {
        eprintln!(
            "robocal demo, seed {seed} (run again with --seed {seed} for the same case)\n\
             1. simulating {} poses of the iiwa 7 with geometric errors and a hidden effect",
            args.poses
        );
    }
    let planner = sim::generate::planner_of(&resolved)?;
    let bar = super::generate::progress_bar(planner.rows() as u64, "simulating");
    let tick = |k: u64| {
        if let Some(b) = &bar {
            b.inc(k);
        }
    };
    let summary = sim::generate::write_dataset(&resolved, &args.out, planner, Some(&tick));
    if let Some(b) = &bar {
        b.finish_and_clear();
    }
    let summary = summary.map_err(|e| CliError::Runtime(e.to_string()))?;
    let data = args.out.join("measurements.parquet");
    if !args.json {
        eprintln!(
            "   wrote {} ({} rows; truth in truth.json, never read by the diagnosis)\n\
             2. diagnosing from the measurements alone (calibrate, look at the residuals, try each cause)",
            data.display(),
            summary.rows
        );
    }
    let model = resolved.model.clone();
    let table = read_table(&data, &model)?;
    let name = data.display().to_string();
    let d = run_diagnosis(&model, &table, &name, &options(1.0 / 3.0, 0, 1e-3)?)?;
    let report_dir = args.out.join("report");
    report::write(&report_dir, &d, &d.plots, &name)?;
    let found: Vec<(String, Vec<usize>)> = d
        .findings
        .iter()
        .map(|f| (f.cause.name().to_string(), f.joints.clone()))
        .collect();
    let mut truth: Vec<(String, Vec<usize>)> = hidden
        .iter()
        .map(|h| (h.cause.to_string(), h.joints.clone()))
        .collect();
    truth.sort();
    let mut found_sorted = found.clone();
    found_sorted.sort();
    let matched = truth == found_sorted;
    if args.json {
        return print_json(&json!({
            "seed": seed,
            "hidden": hidden,
            "diagnosis": d,
            "match": matched,
            "report": report_dir.display().to_string(),
        }));
    }
    eprintln!("\n{}", text(&d, &name));
    eprintln!("3. hidden vs found");
    if hidden.is_empty() {
        eprintln!("   hidden: nothing beyond the geometric errors");
    }
    for h in &hidden {
        eprintln!("   hidden: {} ({})", h.cause, h.description);
    }
    if found.is_empty() {
        eprintln!("   found:  nothing beyond the geometric errors");
    }
    for f in &d.findings {
        eprintln!(
            "   found:  {}{}",
            f.cause,
            if f.joints.is_empty() {
                String::new()
            } else {
                format!(" at joints {}", f.joint_list())
            }
        );
    }
    eprintln!(
        "   {}\n\nreport: {}/index.html",
        if matched {
            "=> the diagnosis found exactly what was hidden"
        } else {
            "=> the diagnosis differs from what was hidden (see the report for why)"
        },
        report_dir.display()
    );
    Ok(())
}
