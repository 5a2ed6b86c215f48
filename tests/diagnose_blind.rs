//! Blind tests of `robocal diagnose`: each case draws, from a seed kept here, which effect is hidden (or
//! none, or two at once), on which joints and how large (within published ranges), builds the scenario
//! in code ([`sim::scenario::ScenarioBuilder`]), simulates its campaign as `robocal generate` does,
//! runs `robocal diagnose --json` on the measurements alone as a user would, and checks the named causes, their joints and that the final held-out RMS is within 1.5× the noise
//! floor. The hidden effect never reaches the code under test except through the measurement file.
//!
//! `ROBOCAL_BLIND_SEED=N` draws other cases; `ROBOCAL_BLIND_CASES=K` runs K of them (default 30).

use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use serde_json::Value;
use sim::campaign::DirectionRule;
use sim::effects::gear_backlash::BacklashMode;
use sim::effects::thermal_drift::{TemperatureProfile, WarmUp};
use sim::scenario::{
    Draw, KinematicSection, Magnitude, Overrides, PayloadSection, SamplingKind, ScenarioBuilder,
};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

const DEFAULT_SEED: u64 = 0x5eed_b11d;
const DEFAULT_CASES: usize = 30;

/// The base campaign: the iiwa 7 with drawn geometric errors, 300 random poses, a typical tracker.
fn base() -> ScenarioBuilder {
    let list = |v: [f64; 3]| Magnitude::List(v.iter().map(|x| Magnitude::Number(*x)).collect());
    ScenarioBuilder::builtin("iiwa7")
        .label("blind scenario")
        .name("blind")
        .description("blind diagnose case")
        .seed(1)
        .poses(300)
        .repeats(1)
        .sampling(SamplingKind::Random)
        .seconds_per_pose(15.0)
        .directions(DirectionRule::Move)
        .joint_margin_rad(0.05)
        .floor_z_m(0.05)
        .min_axis_distance_m(0.10)
        .tracker_placement(list([2.5, 1.0, -0.2]), list([0.0, 0.0, 2.5]))
        .reflector_m([0.0, 0.0, 0.05])
        .radial_sigma(5e-6, 0.15e-6)
        .transverse_sigma(7.5e-6, 3e-6)
        .outlier_rate(0.0)
        .kinematic(KinematicSection {
            joint_rotation_rad: Some(Magnitude::Draw(Draw::Normal([0.0, 3e-4]))),
            joint_translation_m: Some(Magnitude::Draw(Draw::Normal([0.0, 2e-4]))),
            zero_offset_rad: Some(Magnitude::Draw(Draw::Normal([0.0, 5e-4]))),
            ..KinematicSection::default()
        })
}

/// One hidden case.
#[derive(Clone, Debug)]
struct Case {
    seed: u64,
    /// cause -> 1-based joints.
    hidden: BTreeMap<String, Vec<usize>>,
    description: String,
    scenario: ScenarioBuilder,
}

fn pick(rng: &mut StdRng, pool: &[usize], count: usize) -> Vec<usize> {
    let mut left = pool.to_vec();
    let mut out: Vec<usize> = (0..count.min(left.len()))
        .map(|_| left.remove(rng.random_range(0..left.len())))
        .collect();
    out.sort_unstable();
    out
}

/// One magnitude per joint of the iiwa 7: `values` at `joints` (in order), `rest` elsewhere.
fn array(joints: &[usize], values: &[f64], rest: f64) -> Magnitude {
    Magnitude::List(
        (1..=7)
            .map(|j| {
                Magnitude::Number(match joints.iter().position(|x| *x == j) {
                    Some(k) => values[k],
                    None => rest,
                })
            })
            .collect(),
    )
}

fn draw(rng: &mut StdRng, seed: u64) -> Case {
    let mut hidden = BTreeMap::new();
    let mut scenario = base();
    let mut description = Vec::new();
    // Which effects: none, one of three, or two at once.
    let kind = rng.random_range(0..7);
    let (compliance, backlash, thermal) = match kind {
        0 => (false, false, false),
        1 | 2 => (true, false, false),
        3 => (false, true, false),
        4 => (false, false, true),
        5 => (true, true, false),
        _ => (false, true, true),
    };
    let mut used = Vec::new();
    if compliance {
        // Harmonic-drive joints of lightweight arms: 5e3 to 2e4 N m/rad, on joints whose gravity
        // torque moves the target by much more than the noise without payload (2, 3, 4).
        let count = rng.random_range(1..=2);
        let joints = pick(rng, &[2, 3, 4], count);
        let k: Vec<f64> = joints.iter().map(|_| rng.random_range(5e3..2e4)).collect();
        scenario = scenario.compliance(array(&joints, &k, f64::INFINITY));
        description.push(format!(
            "compliance {joints:?} k = {:?} N m/rad",
            k.iter().map(|v| format!("{v:.0}")).collect::<Vec<_>>()
        ));
        // Half of the compliance cases carry a gripper-like payload whose centre of mass the table
        // does not give (only its mass): up to 7 kg (the iiwa 7's rating), 0-10 cm from the flange.
        if rng.random::<bool>() {
            let m = rng.random_range(2.0..7.0);
            let com = [
                rng.random_range(-0.02..0.02),
                rng.random_range(-0.02..0.02),
                rng.random_range(0.0..0.1),
            ];
            scenario = scenario.payload(PayloadSection {
                mass_kg: None,
                choice_kg: Some(vec![0.0, m / 2.0, m]),
                com_m: Some(com),
            });
            description.push(format!("payload ≤ {m:.1} kg at {com:.3?} m"));
        }
        used.extend(joints.iter().copied());
        hidden.insert("joint_compliance".to_string(), joints);
    }
    if backlash {
        // Lost motion of 0.7 to 2 arc-min (2e-4 to 6e-4 rad) on joints 1-5 (joints 6 and 7 move the
        // reflector by less than the noise for that play).
        let pool: Vec<usize> = (1..=5).filter(|j| !used.contains(j)).collect();
        let count = rng.random_range(1..=2);
        let joints = pick(rng, &pool, count);
        let b: Vec<f64> = joints
            .iter()
            .map(|_| rng.random_range(2e-4..6e-4))
            .collect();
        scenario = scenario.backlash(array(&joints, &b, 0.0), BacklashMode::Direction);
        description.push(format!(
            "backlash {joints:?} b = {:?} rad",
            b.iter().map(|v| format!("{v:.2e}")).collect::<Vec<_>>()
        ));
        hidden.insert("gear_backlash".to_string(), joints);
    }
    if thermal {
        // A warm-up of 5 to 15 K with a 20-40 min time constant, aluminium links.
        let delta = rng.random_range(5.0..15.0);
        let tau = rng.random_range(1200.0..2400.0);
        scenario = scenario
            .temperature(TemperatureProfile::WarmUp(
                WarmUp::new(20.0, delta, tau).unwrap(),
            ))
            .thermal(20.0, Magnitude::Number(23e-6), Some(Magnitude::Number(0.0)));
        description.push(format!("thermal ΔT = {delta:.1} K, τ = {tau:.0} s"));
        hidden.insert("thermal_drift".to_string(), Vec::new());
    }
    if description.is_empty() {
        description.push("nothing beyond geometry".into());
    }
    Case {
        seed,
        hidden,
        description: description.join(" + "),
        scenario,
    }
}

fn robocal(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_robocal"))
        .args(args)
        .output()
        .expect("run robocal")
}

fn work_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("robocal_blind_{}_{tag}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Simulates the campaign of `scenario` with `seed` into `dir/data` (as `robocal generate --seed`
/// does); returns the measurement file, the only thing diagnose gets.
fn generate(dir: &Path, scenario: &ScenarioBuilder, seed: u64) -> PathBuf {
    let res = scenario
        .clone()
        .resolve(&Overrides {
            seed: Some(seed),
            ..Overrides::default()
        })
        .unwrap_or_else(|e| panic!("scenario: {e}"));
    let out = dir.join("data");
    sim::generate::generate(&res, &out, None).unwrap_or_else(|e| panic!("generate failed: {e}"));
    out.join("measurements.parquet")
}

fn diagnose(data: &Path) -> Value {
    let o = robocal(&["diagnose", "--data", data.to_str().unwrap(), "--json"]);
    assert!(
        o.status.success(),
        "diagnose failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    serde_json::from_slice(&o.stdout).expect("one JSON document on stdout")
}

fn found(d: &Value) -> BTreeMap<String, Vec<usize>> {
    d["findings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| {
            (
                f["cause"].as_str().unwrap().to_string(),
                f["joints"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|j| j.as_u64().unwrap() as usize)
                    .collect(),
            )
        })
        .collect()
}

fn final_test_rms(d: &Value) -> f64 {
    d["steps"].as_array().unwrap().last().unwrap()["test_rms_m"]
        .as_f64()
        .unwrap()
}

/// Runs `cases` on two worker threads; returns one line per failed case.
fn run_cases(cases: &[Case]) -> Vec<String> {
    let next = std::sync::atomic::AtomicUsize::new(0);
    let failures = std::sync::Mutex::new(Vec::new());
    std::thread::scope(|s| {
        for _ in 0..2 {
            s.spawn(|| {
                loop {
                    let k = next.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
                    let Some(case) = cases.get(k) else { break };
                    let dir = work_dir(&format!("case{k}"));
                    let data = generate(&dir, &case.scenario, case.seed);
                    let d = diagnose(&data);
                    let got = found(&d);
                    let floor = d["noise_floor_m"].as_f64().unwrap();
                    let rms = final_test_rms(&d);
                    let mut problems = Vec::new();
                    if got != case.hidden {
                        problems.push(format!("found {got:?}"));
                    }
                    if rms > 1.5 * floor {
                        problems.push(format!(
                            "final test RMS {:.1} µm > 1.5 × noise floor {:.1} µm",
                            rms * 1e6,
                            floor * 1e6
                        ));
                    }
                    if !problems.is_empty() {
                        failures.lock().unwrap().push(format!(
                            "case {k} (seed {}, hidden {}): {}",
                            case.seed,
                            case.description,
                            problems.join("; ")
                        ));
                    }
                    let _ = std::fs::remove_dir_all(&dir);
                }
            });
        }
    });
    failures.into_inner().unwrap()
}

#[test]
fn diagnose_names_the_hidden_cause_and_its_joints() {
    let seed = std::env::var("ROBOCAL_BLIND_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(DEFAULT_SEED);
    let n = std::env::var("ROBOCAL_BLIND_CASES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(DEFAULT_CASES);
    let mut rng = StdRng::seed_from_u64(seed);
    let cases: Vec<Case> = (0..n)
        .map(|_| {
            let s = rng.random::<u32>() as u64;
            draw(&mut rng, s)
        })
        .collect();
    // Every kind of case must be among the draws, or the test would not test them.
    let kinds: std::collections::BTreeSet<Vec<String>> = cases
        .iter()
        .map(|c| c.hidden.keys().cloned().collect())
        .collect();
    if n >= DEFAULT_CASES {
        assert!(kinds.len() >= 5, "the draws cover too few kinds: {kinds:?}");
    }
    let failures = run_cases(&cases);
    assert!(
        failures.is_empty(),
        "{} of {n} blind cases failed (ROBOCAL_BLIND_SEED={seed}):\n{}",
        failures.len(),
        failures.join("\n")
    );
}

/// An error periodic in one joint's angle (as from an eccentric gear) is no known cause: diagnose must
/// leave the findings empty and report it as unexplained, correlated with that joint.
#[test]
fn a_periodic_joint_error_comes_back_as_unexplained() {
    let mut rng = StdRng::seed_from_u64(
        std::env::var("ROBOCAL_BLIND_SEED")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(DEFAULT_SEED)
            ^ 0x9e37,
    );
    let joint = [1usize, 2, 3, 4][rng.random_range(0..4)];
    let amplitude = rng.random_range(1.5e-4..3e-4); // rad
    let phase = rng.random_range(0.0..std::f64::consts::TAU);
    let dir = work_dir("periodic");
    let data = generate(&dir, &base(), rng.random::<u32>() as u64);
    // The real link angle is q + A sin(2 q + φ): the controller reports q_true − A sin(2 q_true + φ).
    let mut table = sim::measurement_table::read(&data).unwrap();
    let n = table.n_joints;
    for r in 0..table.len() {
        let q = &mut table.q[r * n + joint - 1];
        *q -= amplitude * (2.0 * *q + phase).sin();
    }
    let csv = dir.join("periodic.csv");
    sim::measurement_table::write(&csv, &table).unwrap();
    let d = diagnose(&csv);
    let u = &d["unexplained"];
    assert!(
        found(&d).is_empty(),
        "forced onto a known cause: {:?} (joint {joint}, A = {amplitude:.2e} rad)",
        found(&d)
    );
    assert_eq!(u["present"], Value::Bool(true), "{u}");
    assert_eq!(
        u["correlates_with"]["joint"].as_u64(),
        Some(joint as u64),
        "{u}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
