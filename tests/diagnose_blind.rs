//! Blind tests of `robocal diagnose`: each case draws, from a seed kept here, which effect is hidden (or
//! none, or two at once), on which joints and how large (within published ranges), builds the scenario
//! in code ([`sim::scenario::ScenarioBuilder`]), simulates its campaign as `robocal generate` does,
//! runs `robocal diagnose --json` on the measurements alone as a user would, and checks the named
//! causes, their joints and that the final held-out RMS is within 1.5× the noise floor. The hidden
//! effect never reaches the code under test except through the measurement file.
//!
//! The draws cover the whole vocabulary (each cause alone, deflection with compliance, transmission
//! error with backlash, compliance with backlash, backlash with thermal drift) and three effects
//! outside it, which must come back as unexplained structure with no finding: one joint's angle error
//! proportional to another joint's angle (`joint_coupling`), a transmission error of 4 to 6 cycles
//! per revolution (beyond the three harmonics the estimator models), and one joint's angle error
//! periodic in another joint's angle (`coupled_transmission`).
//!
//! `ROBOCAL_BLIND_SEED=N` draws other cases; `ROBOCAL_BLIND_CASES=K` runs K of them (default 52: every
//! kind 4 times); `ROBOCAL_BLIND_KEEP=DIR` keeps each case's campaign in `DIR/caseK` to look at. The ignored test `confusion_matrix` runs `ROBOCAL_BLIND_CASES` (default 1,000) and
//! writes the matrix of hidden against named causes for docs/diagnose.md
//! (`scripts/blind_confusion.sh`).

use rand::rngs::StdRng;
use rand::seq::SliceRandom;
use rand::{RngExt, SeedableRng};
use serde_json::Value;
use sim::campaign::DirectionRule;
use sim::effects::gear_backlash::BacklashMode;
use sim::effects::thermal_drift::{TemperatureProfile, WarmUp};
use sim::effects::transmission_error::{TransmissionError, TransmissionSection};
use sim::scenario::{
    Draw, KinematicSection, Magnitude, Overrides, PayloadSection, SamplingKind, ScenarioBuilder,
};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

const DEFAULT_SEED: u64 = 0x5eed_b11d;
const DEFAULT_CASES: usize = 52;

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

/// What a case hides.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
enum Kind {
    Nothing,
    Compliance,
    Backlash,
    Thermal,
    Transmission,
    Deflection,
    DeflectionAndCompliance,
    TransmissionAndBacklash,
    ComplianceAndBacklash,
    BacklashAndThermal,
    /// Outside the vocabulary: one joint's angle error in proportion to another joint's angle.
    Coupling,
    /// Outside the vocabulary: a transmission error of 4 to 6 cycles per revolution.
    HigherHarmonic,
    /// Outside the vocabulary: one joint's angle error periodic in ANOTHER joint's angle
    /// (`coupled_transmission`).
    CoupledTransmission,
}

impl Kind {
    const ALL: [Kind; 13] = [
        Kind::Nothing,
        Kind::Compliance,
        Kind::Backlash,
        Kind::Thermal,
        Kind::Transmission,
        Kind::Deflection,
        Kind::DeflectionAndCompliance,
        Kind::TransmissionAndBacklash,
        Kind::ComplianceAndBacklash,
        Kind::BacklashAndThermal,
        Kind::Coupling,
        Kind::HigherHarmonic,
        Kind::CoupledTransmission,
    ];

    /// Whether the hidden effect is outside the causes diagnose knows.
    fn outside(self) -> bool {
        matches!(
            self,
            Kind::Coupling | Kind::HigherHarmonic | Kind::CoupledTransmission
        )
    }
}

/// One hidden case.
#[derive(Clone, Debug)]
struct Case {
    seed: u64,
    kind: Kind,
    /// cause -> 1-based joints (empty for an effect outside the vocabulary: nothing may be named).
    hidden: BTreeMap<String, Vec<usize>>,
    /// For an effect outside the vocabulary: the 1-based joint whose angle it disturbs.
    outside_joint: Option<usize>,
    /// Names a measurement cannot tell from the hidden ones, which diagnose may give besides: bending
    /// of joint i about the axis line of joint i + 1 is joint i + 1's compliance (iiwa joints 2 and 4
    /// about z; see calib's link_deflection).
    aliases: BTreeMap<String, Vec<usize>>,
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

/// One row of numbers per joint of the iiwa 7: `rows[k]` at `joints[k]`, zeros (of the same width)
/// elsewhere.
fn table_per_joint(joints: &[usize], rows: &[Vec<f64>], width: usize) -> Magnitude {
    Magnitude::List(
        (1..=7)
            .map(|j| {
                let row = match joints.iter().position(|x| *x == j) {
                    Some(k) => rows[k].clone(),
                    None => vec![0.0; width],
                };
                Magnitude::List(row.into_iter().map(Magnitude::Number).collect())
            })
            .collect(),
    )
}

/// A transmission error at `joints` with harmonic `orders`: each amplitude 30-150 µrad with a random
/// phase, the largest at least 100 µrad (harmonic drives: about 1 arc-min peak to peak), on joints
/// 1-4 (joints 5-7 move the reflector by less than the noise for that).
fn transmission(
    rng: &mut StdRng,
    scenario: ScenarioBuilder,
    joints: &[usize],
    orders: Vec<u32>,
) -> (ScenarioBuilder, String) {
    let k = orders.len();
    let amp: Vec<Vec<f64>> = joints
        .iter()
        .map(|_| {
            let mut a: Vec<f64> = (0..k).map(|_| rng.random_range(3e-5..1.5e-4)).collect();
            let top = rng.random_range(0..k);
            a[top] = rng.random_range(1e-4..2e-4);
            a
        })
        .collect();
    let phase: Vec<Vec<f64>> = joints
        .iter()
        .map(|_| {
            (0..k)
                .map(|_| rng.random_range(-std::f64::consts::PI..std::f64::consts::PI))
                .collect()
        })
        .collect();
    let section = TransmissionSection {
        enabled: None,
        harmonics: Some(orders.clone()),
        amplitude_rad: table_per_joint(joints, &amp, k),
        phase_rad: Some(table_per_joint(joints, &phase, k)),
    };
    let text = format!(
        "transmission error {joints:?} orders {orders:?} amplitudes {:?} rad",
        amp.iter()
            .map(|a| a.iter().map(|v| format!("{v:.1e}")).collect::<Vec<_>>())
            .collect::<Vec<_>>()
    );
    (scenario.effect::<TransmissionError>(section), text)
}

fn draw(rng: &mut StdRng, seed: u64, kind: Kind) -> Case {
    let mut hidden = BTreeMap::new();
    let mut scenario = base();
    let mut description = Vec::new();
    let mut outside_joint = None;
    let mut aliases = BTreeMap::new();
    let (compliance, backlash, thermal, te, deflection) = match kind {
        Kind::Nothing | Kind::Coupling | Kind::HigherHarmonic | Kind::CoupledTransmission => {
            (false, false, false, false, false)
        }
        Kind::Compliance => (true, false, false, false, false),
        Kind::Backlash => (false, true, false, false, false),
        Kind::Thermal => (false, false, true, false, false),
        Kind::Transmission => (false, false, false, true, false),
        Kind::Deflection => (false, false, false, false, true),
        Kind::DeflectionAndCompliance => (true, false, false, false, true),
        Kind::TransmissionAndBacklash => (false, true, false, true, false),
        Kind::ComplianceAndBacklash => (true, true, false, false, false),
        Kind::BacklashAndThermal => (false, true, true, false, false),
    };
    let mut used = Vec::new();
    // A gripper-like payload whose centre of mass (0-10 cm from the flange) the table does not give,
    // only its mass: up to 7 kg (the iiwa 7's rating). Half of the cases with a gravity-driven cause.
    let payload = |rng: &mut StdRng, scenario: ScenarioBuilder, description: &mut Vec<String>| {
        if !rng.random::<bool>() {
            return scenario;
        }
        let m = rng.random_range(2.0..7.0);
        let com = [
            rng.random_range(-0.02..0.02),
            rng.random_range(-0.02..0.02),
            rng.random_range(0.0..0.1),
        ];
        description.push(format!("payload ≤ {m:.1} kg at {com:.3?} m"));
        scenario.payload(PayloadSection {
            mass_kg: None,
            choice_kg: Some(vec![0.0, m / 2.0, m]),
            com_m: Some(com),
        })
    };
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
        if !deflection {
            scenario = payload(rng, scenario, &mut description);
        }
        hidden.insert("joint_compliance".to_string(), joints);
    }
    if deflection {
        // Bearing and link compliance across the shoulder and elbow (joints 2 and 4). The moment
        // stiffness of Harmonic Drive output bearings is 1e5 to 1e6 N m/rad for sizes 14 to 32 (see
        // sim's link_deflection), and the link tubes add about as much: 2e-6 to 5e-6 rad/(N m) per
        // axis at the shoulder (a large unit, up to 60 N m across its axis), 5e-6 to 1e-5 at the
        // elbow (a smaller unit carrying 10 to 30 N m), which bend the arm by 0.05 to 0.3 mrad.
        let count = rng.random_range(1..=2);
        let joints = pick(rng, &[2, 4], count);
        let c: Vec<Vec<f64>> = joints
            .iter()
            .map(|&j| {
                let range = if j == 2 { 2e-6..5e-6 } else { 5e-6..1e-5 };
                vec![
                    rng.random_range(range.clone()),
                    rng.random_range(range.clone()),
                ]
            })
            .collect();
        scenario = scenario.link_deflection(table_per_joint(&joints, &c, 2));
        description.push(format!(
            "deflection {joints:?} c = {:?} rad/(N m)",
            c.iter()
                .map(|a| a.iter().map(|v| format!("{v:.1e}")).collect::<Vec<_>>())
                .collect::<Vec<_>>()
        ));
        scenario = payload(rng, scenario, &mut description);
        aliases.insert(
            "joint_compliance".to_string(),
            joints.iter().map(|j| j + 1).collect(),
        );
        hidden.insert("link_deflection".to_string(), joints);
    }
    if te {
        let count = rng.random_range(1..=2);
        let joints = pick(rng, &[1, 2, 3, 4], count);
        let (sc, text) = transmission(rng, scenario, &joints, vec![1, 2, 3]);
        scenario = sc;
        description.push(text);
        used.extend(joints.iter().copied());
        hidden.insert("transmission_error".to_string(), joints);
    }
    if backlash {
        // Lost motion of 0.7 to 2 arc-min (2e-4 to 6e-4 rad) on joints 1-5 (joints 6 and 7 move the
        // reflector by less than the noise for that play).
        let avoid: Vec<usize> = hidden.values().flatten().copied().collect();
        let pool: Vec<usize> = (1..=5).filter(|j| !avoid.contains(j)).collect();
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
    match kind {
        Kind::Coupling => {
            // Cable wind-up or a coupled drive: joint i's angle error grows with joint j's angle,
            // 50 to 200 µrad per rad (0.1 to 0.4 mrad over a joint's range), i on joints 1-4.
            let i = rng.random_range(1..=4);
            let others: Vec<usize> = (1..=6).filter(|j| *j != i).collect();
            let j = others[rng.random_range(0..others.len())];
            let c = rng.random_range(5e-5..2e-4) * if rng.random::<bool>() { 1.0 } else { -1.0 };
            scenario =
                scenario.joint_coupling(vec![[i, j]], Magnitude::List(vec![Magnitude::Number(c)]));
            description.push(format!(
                "coupling: joint {i} gains {c:.2e} rad per rad of joint {j}"
            ));
            outside_joint = Some(i);
        }
        Kind::HigherHarmonic => {
            let joint = rng.random_range(1..=4);
            let order = rng.random_range(4..=6);
            let (sc, text) = transmission(rng, scenario, &[joint], vec![order]);
            scenario = sc;
            description.push(text);
            outside_joint = Some(joint);
        }
        Kind::CoupledTransmission => {
            // A drive whose error follows another joint's motor (a coupled wrist, a cable routed
            // through the previous joint): joint i's angle error A sin(q_j + φ), A 150-300 µrad (as
            // the periodic error below), i on joints 1-4, j any other of joints 1-6. Smaller errors
            // are under the probes' level on 100 held-out poses: 121 µrad at joint 4 gave z = 2.7
            // against the 3.9 of α = 0.001 over 30 probes (the probe found the right joints). Not
            // a neighbouring joint j = i ± 1: joint i's axis seen from link i − 2 turns with q(i−1),
            // so a rotation error of joint i − 1 (a kinematic twist) makes an angle error of joint
            // i in sin and cos of q(i−1), and the kinematic fit takes up most of such an error (joint
            // 4 in q3: 61 µm RMS injected, 30 µm left beside 23 µm of noise; joint 3 in q4, whose
            // axis lines up with joint 5's at q4 = 0: 84 µm injected, 33 µm left), under the
            // probes' level: see docs/diagnose.md, Limits.
            let i = rng.random_range(1..=4);
            let others: Vec<usize> = (1..=6usize).filter(|j| j.abs_diff(i) >= 2).collect();
            let j = others[rng.random_range(0..others.len())];
            let a = rng.random_range(1.5e-4..3e-4);
            let phase = rng.random_range(-std::f64::consts::PI..std::f64::consts::PI);
            scenario = scenario.coupled_transmission(
                vec![[i, j]],
                Magnitude::List(vec![Magnitude::Number(a)]),
                Magnitude::List(vec![Magnitude::Number(phase)]),
            );
            description.push(format!(
                "coupled transmission: joint {i} gains {a:.2e} rad sin(q{j} {phase:+.2})"
            ));
            outside_joint = Some(i);
        }
        _ => {}
    }
    let _ = used;
    if description.is_empty() {
        description.push("nothing beyond geometry".into());
    }
    Case {
        seed,
        kind,
        hidden,
        outside_joint,
        aliases,
        description: description.join(" + "),
        scenario,
    }
}

/// `n` cases from `seed`: the kinds in a shuffled cycle (every kind once in each run of 13), the
/// rest of each case drawn.
fn cases(seed: u64, n: usize) -> Vec<Case> {
    let mut rng = StdRng::seed_from_u64(seed);
    let mut kinds = Vec::new();
    while kinds.len() < n {
        let mut cycle = Kind::ALL.to_vec();
        cycle.shuffle(&mut rng);
        kinds.extend(cycle);
    }
    kinds
        .into_iter()
        .take(n)
        .map(|kind| {
            let s = rng.random::<u32>() as u64;
            draw(&mut rng, s, kind)
        })
        .collect()
}

/// Runs `robocal` (the one built with this test, or `ROBOCAL_BIN`: a long study runs a copy, so that
/// rebuilding meanwhile does not change the program under study).
fn robocal(args: &[&str]) -> std::process::Output {
    let bin = std::env::var_os("ROBOCAL_BIN")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_BIN_EXE_robocal")));
    Command::new(bin).args(args).output().expect("run robocal")
}

/// A fresh folder for one case; with `ROBOCAL_BLIND_KEEP` set, under that folder and kept.
fn work_dir(tag: &str) -> PathBuf {
    let d = match std::env::var_os("ROBOCAL_BLIND_KEEP") {
        Some(keep) => PathBuf::from(keep).join(tag),
        None => std::env::temp_dir().join(format!("robocal_blind_{}_{tag}", std::process::id())),
    };
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

/// What diagnose said about one case.
#[derive(Clone, Debug)]
struct Outcome {
    kind: Kind,
    named: BTreeMap<String, Vec<usize>>,
    unexplained: bool,
    /// One line per failed check (empty when the case passes).
    problems: Vec<String>,
}

/// Whether `got` names exactly the hidden causes and joints, give or take the case's aliases. Link
/// deflection may name fewer joints than were hidden (never others): the bending axes of neighbouring
/// joints are nearly parallel lines (joint 1's x and y and joint 2's x, 0.19 m apart at q2 = 0), so a
/// realistic bending is often not told apart between neighbours, and diagnose then names only the
/// joints whose parameters are determined on their own.
///
/// A hidden link deflection also counts as named when only its alias is: joint compliance at a joint
/// after a bending one (and not itself hidden). That bending is, to any measurement, that joint's
/// compliance; when the bending about the other axis moves the target by less than the noise (small
/// moments across it without payload), the alias is all the data show, and naming only it is right
/// (the final held-out RMS must still be within 1.5× the noise floor).
fn matches_hidden(got: &BTreeMap<String, Vec<usize>>, case: &Case) -> bool {
    let hidden_named = case.hidden.iter().all(|(cause, joints)| {
        let alias_named = || {
            let hidden_compliance = case.hidden.get("joint_compliance");
            case.aliases.get("joint_compliance").is_some_and(|a| {
                got.get("joint_compliance").is_some_and(|g| {
                    g.iter()
                        .any(|j| a.contains(j) && !hidden_compliance.is_some_and(|h| h.contains(j)))
                })
            })
        };
        if cause == "link_deflection" {
            got.contains_key(cause) || alias_named()
        } else {
            got.get(cause)
                .is_some_and(|g| joints.iter().all(|j| g.contains(j)))
        }
    });
    let nothing_else = got.iter().all(|(cause, g)| {
        let allowed: Vec<usize> = case
            .hidden
            .get(cause)
            .into_iter()
            .chain(case.aliases.get(cause))
            .flatten()
            .copied()
            .collect();
        (case.hidden.contains_key(cause) || case.aliases.contains_key(cause))
            && g.iter().all(|j| allowed.contains(j))
    });
    hidden_named && nothing_else
}

/// Diagnoses one case and checks it: a case inside the vocabulary must name exactly the hidden
/// causes and joints and end within 1.5× the noise floor; one outside it must name nothing and report
/// unexplained structure correlated with the joint it disturbs.
fn run_case(k: usize, case: &Case) -> Outcome {
    let dir = work_dir(&format!("case{k}"));
    let data = generate(&dir, &case.scenario, case.seed);
    let d = diagnose(&data);
    let got = found(&d);
    let floor = d["noise_floor_m"].as_f64().unwrap();
    let rms = final_test_rms(&d);
    let u = &d["unexplained"];
    let unexplained = u["present"] == Value::Bool(true);
    let mut problems = Vec::new();
    if !matches_hidden(&got, case) {
        problems.push(format!("found {got:?}"));
    }
    if case.kind.outside() {
        if !unexplained {
            problems.push(format!("no unexplained structure reported: {}", u["note"]));
        }
        let joint = u["correlates_with"]["joint"].as_u64().map(|j| j as usize);
        if joint != case.outside_joint {
            problems.push(format!(
                "unexplained structure correlates with {} (joint {joint:?}), not joint {:?}",
                u["correlates_with"]["name"], case.outside_joint
            ));
        }
    } else if rms > 1.5 * floor {
        problems.push(format!(
            "final test RMS {:.1} µm > 1.5 × noise floor {:.1} µm",
            rms * 1e6,
            floor * 1e6
        ));
    }
    if std::env::var_os("ROBOCAL_BLIND_KEEP").is_none() {
        let _ = std::fs::remove_dir_all(&dir);
    }
    Outcome {
        kind: case.kind,
        named: got,
        unexplained,
        problems,
    }
}

/// Runs `cases` on two worker threads; returns their outcomes in order.
fn run_cases(cases: &[Case]) -> Vec<Outcome> {
    let next = std::sync::atomic::AtomicUsize::new(0);
    let out = std::sync::Mutex::new(vec![None; cases.len()]);
    std::thread::scope(|s| {
        for _ in 0..2 {
            s.spawn(|| {
                loop {
                    let k = next.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
                    let Some(case) = cases.get(k) else { break };
                    let o = run_case(k, case);
                    out.lock().unwrap()[k] = Some(o);
                }
            });
        }
    });
    out.into_inner()
        .unwrap()
        .into_iter()
        .map(|o| o.expect("every case ran"))
        .collect()
}

fn env_or<T: std::str::FromStr>(name: &str, default: T) -> T {
    std::env::var(name)
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(default)
}

#[test]
fn diagnose_names_the_hidden_cause_and_its_joints() {
    let seed = env_or("ROBOCAL_BLIND_SEED", DEFAULT_SEED);
    let n = env_or("ROBOCAL_BLIND_CASES", DEFAULT_CASES);
    let mut cases = cases(seed, n);
    // `ROBOCAL_BLIND_ONLY=K` reruns case K alone (with ROBOCAL_BLIND_KEEP to look at it).
    if let Some(k) = std::env::var("ROBOCAL_BLIND_ONLY")
        .ok()
        .and_then(|s| s.parse().ok())
    {
        cases = vec![cases.swap_remove(k)];
    }
    let start = std::time::Instant::now();
    let outcomes = run_cases(&cases);
    eprintln!(
        "{n} blind cases in {:.1} s (ROBOCAL_BLIND_SEED={seed})",
        start.elapsed().as_secs_f64()
    );
    let failures: Vec<String> = cases
        .iter()
        .zip(&outcomes)
        .enumerate()
        .filter(|(_, (_, o))| !o.problems.is_empty())
        .map(|(k, (c, o))| {
            format!(
                "case {k} (seed {}, {:?}: {}): {}",
                c.seed,
                c.kind,
                c.description,
                o.problems.join("; ")
            )
        })
        .collect();
    assert!(
        failures.is_empty(),
        "{} of {n} blind cases failed (ROBOCAL_BLIND_SEED={seed}):\n{}",
        failures.len(),
        failures.join("\n")
    );
}

/// The cause words, in the column order of the confusion matrix.
const CAUSES: [&str; 5] = [
    "joint_compliance",
    "gear_backlash",
    "thermal_drift",
    "transmission_error",
    "link_deflection",
];

/// The confusion matrix of `ROBOCAL_BLIND_CASES` (default 1,000) cases from `ROBOCAL_BLIND_SEED`: per
/// hidden kind, how often each cause was named, how often nothing was, how often unexplained
/// structure was reported, and how often the case passed every check; written as Markdown to
/// `ROBOCAL_CONFUSION_OUT` (default `target/blind_confusion.md`) with every failed case listed.
#[test]
#[ignore = "a long study (about an hour on two cores): scripts/blind_confusion.sh"]
fn confusion_matrix() {
    let seed = env_or("ROBOCAL_BLIND_SEED", DEFAULT_SEED);
    let n = env_or("ROBOCAL_BLIND_CASES", 1000usize);
    let out = std::env::var("ROBOCAL_CONFUSION_OUT").unwrap_or_else(|_| {
        concat!(env!("CARGO_MANIFEST_DIR"), "/target/blind_confusion.md").into()
    });
    let cases = cases(seed, n);
    let start = std::time::Instant::now();
    let outcomes = run_cases(&cases);
    let mut md = format!(
        "{n} blind cases, seed {seed:#x}, {:.0} s on this machine\n\n| hidden | cases | {} | nothing named | unexplained reported | all checks pass |\n|---|---|{}---|---|---|\n",
        start.elapsed().as_secs_f64(),
        CAUSES.join(" | "),
        "---|".repeat(CAUSES.len())
    );
    for kind in Kind::ALL {
        let of: Vec<&Outcome> = outcomes.iter().filter(|o| o.kind == kind).collect();
        if of.is_empty() {
            continue;
        }
        let count = |f: &dyn Fn(&Outcome) -> bool| of.iter().filter(|o| f(o)).count();
        let cols: Vec<String> = CAUSES
            .iter()
            .map(|c| count(&|o| o.named.contains_key(*c)).to_string())
            .collect();
        md.push_str(&format!(
            "| {kind:?} | {} | {} | {} | {} | {} |\n",
            of.len(),
            cols.join(" | "),
            count(&|o| o.named.is_empty()),
            count(&|o| o.unexplained),
            count(&|o| o.problems.is_empty()),
        ));
    }
    md.push_str("\nFailed cases:\n\n");
    for (k, (c, o)) in cases.iter().zip(&outcomes).enumerate() {
        if !o.problems.is_empty() {
            md.push_str(&format!(
                "- case {k} (seed {}, {:?}: {}): {}\n",
                c.seed,
                c.kind,
                c.description,
                o.problems.join("; ")
            ));
        }
    }
    sim::io::write_atomic(std::path::Path::new(&out), md.as_bytes()).unwrap();
    eprintln!("{md}");
}

/// A periodic joint-angle error injected by editing the table (not by the simulator's effect code):
/// the controller reports `q_true − A sin(2 q_true + φ)`. That is a transmission error of the joint's
/// own angle: diagnose must name it, at that joint.
#[test]
fn a_periodic_joint_error_made_outside_the_simulator_is_named_transmission_error() {
    let mut rng = StdRng::seed_from_u64(env_or("ROBOCAL_BLIND_SEED", DEFAULT_SEED) ^ 0x9e37);
    let joint = [1usize, 2, 3, 4][rng.random_range(0..4)];
    let amplitude = rng.random_range(1.5e-4..3e-4); // rad
    let phase = rng.random_range(0.0..std::f64::consts::TAU);
    let dir = work_dir("periodic");
    let data = generate(&dir, &base(), rng.random::<u32>() as u64);
    let mut table = sim::measurement_table::read(&data).unwrap();
    let n = table.n_joints;
    for r in 0..table.len() {
        let q = &mut table.q[r * n + joint - 1];
        *q -= amplitude * (2.0 * *q + phase).sin();
    }
    let csv = dir.join("periodic.csv");
    sim::measurement_table::write(&csv, &table).unwrap();
    let d = diagnose(&csv);
    let expect: BTreeMap<String, Vec<usize>> =
        [("transmission_error".to_string(), vec![joint])].into();
    assert_eq!(
        found(&d),
        expect,
        "joint {joint}, A = {amplitude:.2e} rad: {}",
        d["unexplained"]["note"]
    );
    let _ = std::fs::remove_dir_all(&dir);
}
