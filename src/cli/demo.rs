//! `robocal demo`: the whole loop on the embedded iiwa 7. A hidden effect is drawn (a kind of the
//! extended vocabulary, then its joints and magnitudes by [`crate::vocabulary::draw`], the blind
//! tests' sampler), a campaign is simulated with it, and `diagnose` (which sees only the measurement file) has to find it; the findings
//! are printed beside the truth and a report is written.

use super::diagnose::{options, run_diagnosis, text};
use super::shared::read_table;
use super::shared::{CliError, CliResult, print_json};
use crate::report;
use crate::vocabulary::{self, Kind};
use rand::{RngExt, SeedableRng};
use serde_json::json;
use sim::scenario::{Overrides, Scenario, ScenarioBuilder};
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

/// `2, 3` of 1-based joints.
fn joint_list(joints: &[usize]) -> String {
    joints
        .iter()
        .map(|j| j.to_string())
        .collect::<Vec<_>>()
        .join(", ")
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
    let kind = Kind::ALL[rng.random_range(0..Kind::ALL.len())];
    let base = Scenario::parse(BASE_SCENARIO, "demo scenario", Path::new("."))?;
    let builder = ScenarioBuilder::from_scenario(&base).name("iiwa7_demo");
    let (builder, hidden) = vocabulary::draw(&mut rng, kind, builder)?;
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
        .causes()
        .into_iter()
        .map(|(c, j)| (c.name().to_string(), j))
        .collect();
    truth.sort();
    let mut found_sorted = found.clone();
    found_sorted.sort();
    let outside = kind.outside();
    // Outside the vocabulary the right answer is no finding and unexplained structure.
    let matched = truth == found_sorted && (!outside || d.unexplained.present);
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
    if hidden.effects.is_empty() {
        eprintln!("   hidden: nothing beyond the geometric errors");
    }
    for h in &hidden.effects {
        eprintln!(
            "   hidden: {}{} ({}){}",
            h.cause.map_or(h.name, |c| c.name()),
            if h.cause.is_some() && !h.joints.is_empty() {
                let s = if h.joints.len() > 1 { "s" } else { "" };
                format!(" at joint{s} {}", joint_list(&h.joints))
            } else {
                String::new()
            },
            h.description,
            if h.cause.is_none() {
                " — outside the causes diagnose knows: it must come back unexplained"
            } else {
                ""
            }
        );
    }
    if found.is_empty() {
        eprintln!(
            "   found:  no known cause{}",
            if d.unexplained.present {
                "; unexplained structure reported"
            } else {
                ""
            }
        );
    }
    for f in &d.findings {
        eprintln!(
            "   found:  {}{}",
            f.cause,
            if f.joints.is_empty() {
                String::new()
            } else {
                let s = if f.joints.len() > 1 { "s" } else { "" };
                format!(" at joint{s} {}", f.joint_list())
            }
        );
    }
    for f in &d.findings {
        if let Some(r) = &f.rival {
            eprintln!(
                "   {} beat its nearest rival {} ({:.0} % against {:.0} % on held-out poses)",
                f.cause,
                r.name,
                100.0 * f.gain,
                100.0 * r.gain
            );
        }
    }
    eprintln!(
        "   {}\n\nreport: {}/index.html (every candidate tried, the rivals and the plots)",
        if matched {
            "=> the diagnosis found exactly what was hidden"
        } else {
            "=> the diagnosis differs from what was hidden (see the report for why)"
        },
        report_dir.display()
    );
    Ok(())
}
