//! Branches that load the chain, posed per measurement (issue 25, item 2): a torso that pitches on an
//! elastic joint, a left arm a tracker measures (the chain, `--tip-link left_flange`), and a right
//! arm and a head on movable joints of their own that move from pose to pose
//! (`sim/tests/data/torso_two_arms.urdf`; the scenario's `branches = "random"`). Their 9.5 kg load
//! the torso joint, and where they are decides by how much: up to 19 N m between two poses of the
//! right arm at the same chain configuration (golden/gravity_torso_two_arms_posed.csv). The
//! measurement table gives their joints' values in `q_<joint name>` columns.
//!
//! The stiffnesses are drawn from a seed each run prints (`ROBOCAL_TEST_SEED=… cargo test --release
//! --test diagnose_branches` repeats one); the code under test sees only the measurement file.
//!
//! What must hold:
//! - with the `q_<joint>` columns, diagnose names joint compliance and the torso joint's stiffness
//!   comes back within 3σ of the truth; the arm's two pitch joints within 4σ (two more checks at 3σ
//!   would fail one run in 185 by chance alone);
//! - without them (the same file, columns removed), the table is read with a warning naming the
//!   four branch joints, the torso's stiffness is biased beyond 4σ and the held-out error is more
//!   than 5× that with them: the columns are read, and they matter.
//!
//! Measured over 20 seeds: with the columns, held-out RMS 22–27 µm on a 24 µm noise floor; mean z²
//! 1.15 at the torso (largest |z| 2.33), 1.98 and 1.75 at the arm's pitch joints (largest 3.23).
//! The arm's joints carry no branch load (the branches hang from the torso), and their z² is above
//! 1 without geometric errors too (1.33 and 1.52 over 16 seeds), as the coupled torso's arm drives'
//! (tests/diagnose_coupled.rs, 0.92–1.41): a property of the arm's compliance fit, not of the
//! branches, left open. Without the columns: the torso's compliance 5.3–10.7σ off (10–15 %),
//! held-out RMS 22–65× larger (536–1642 µm).

mod common;

use common::seed;
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use serde_json::Value;
use std::path::{Path, PathBuf};

/// The branch joints of the test robot, as the table names them (`q_<joint>`).
const BRANCH_JOINTS: [&str; 4] = [
    "neck_yaw",
    "neck_pitch",
    "right_shoulder_pitch",
    "right_elbow",
];

fn urdf() -> PathBuf {
    common::repo().join("sim/tests/data/torso_two_arms.urdf")
}

/// A scenario of the torso with joint stiffnesses `k` (N m/rad, chain order) and posed branches.
fn scenario(k: &[f64; 4]) -> String {
    common::torso_scenario(
        "torso_two_arms_blind",
        &urdf(),
        "branches = \"random\"\n",
        k,
    )
}

/// diagnose of `data` on the torso's left arm: the JSON document and stderr.
fn diagnose(data: &Path) -> (Value, String) {
    let (out, err) = common::robocal_ok(&[
        "diagnose",
        "--robot",
        urdf().to_str().unwrap(),
        "--tip-link",
        "left_flange",
        "--data",
        data.to_str().unwrap(),
        "--json",
    ]);
    (serde_json::from_str(&out).unwrap(), err)
}

/// The held-out RMS (m) of the model a diagnose document adopts (its last step).
fn held_out_rms(diag: &Value) -> f64 {
    diag["steps"].as_array().unwrap().last().unwrap()["test_rms_m"]
        .as_f64()
        .unwrap()
}

/// The compliance finding of a diagnose document, or a panic naming the seed.
fn compliance(diag: &Value, seed: u64) -> Value {
    let findings = diag["findings"].as_array().unwrap();
    findings
        .iter()
        .find(|f| f["cause"] == "joint_compliance")
        .unwrap_or_else(|| panic!("seed {seed}: compliance not named: {findings:#?}"))
        .clone()
}

/// `(compliance − truth) / σ` of chain joint `joint` (1-based).
fn z(finding: &Value, joint: usize, k: &[f64; 4], seed: u64) -> f64 {
    let (c, s) = common::parameter(&finding["parameters"], &format!("joint {joint} compliance"))
        .unwrap_or_else(|| panic!("seed {seed}: no compliance of joint {joint}: {finding:#}"));
    let truth = 1.0 / k[joint - 1];
    let z = (c - truth) / s;
    eprintln!(
        "joint {joint}: compliance {c:.5e} ± {s:.1e}, truth {truth:.5e} (stiffness {:.0}; z = {z:.2})",
        k[joint - 1]
    );
    z
}

#[test]
fn posed_branches_load_the_torso_where_the_table_says() {
    let seed = seed();
    eprintln!("diagnose_branches: seed {seed} (ROBOCAL_TEST_SEED={seed} repeats this run)");
    let mut rng = StdRng::seed_from_u64(seed);
    // Stiffnesses (N m/rad): the torso 4,000–12,000, the arm's two pitch joints 2,000–8,000, the
    // wrist (about x, little torque) rigid.
    let k = [
        rng.random_range(4e3..1.2e4),
        rng.random_range(2e3..8e3),
        rng.random_range(2e3..8e3),
        f64::INFINITY,
    ];
    let d = common::scratch_dir("robocal_diagnose_branches", "torso");
    let sc = d.join("scenario.toml");
    std::fs::write(&sc, scenario(&k)).unwrap();
    let seed_arg = rng.random_range(1..u32::MAX as u64).to_string();
    let data = common::generate(&sc, &d.join("gen"), &["--seed", &seed_arg]);
    let table = sim::measurement_table::read(&data).unwrap();
    assert_eq!(table.n_joints, 4);
    assert_eq!(
        table.branch_names(),
        BRANCH_JOINTS,
        "the generator's columns"
    );

    // With the branch columns: compliance named, stiffnesses within their σ.
    let (diag, err) = diagnose(&data);
    assert!(!err.contains("no q_<joint> column"), "{err}");
    let posed = compliance(&diag, seed);
    let (posed_rms, floor) = (held_out_rms(&diag), diag["noise_floor_m"].as_f64().unwrap());
    eprintln!(
        "posed: held-out RMS {:.1} µm (noise floor {:.1} µm)",
        posed_rms * 1e6,
        floor * 1e6
    );
    assert!(
        posed_rms < 1.5 * floor,
        "seed {seed}: held-out {posed_rms:e} m against a noise floor of {floor:e} m"
    );
    for (joint, limit) in [(1, 3.0), (2, 4.0), (3, 4.0)] {
        let z = z(&posed, joint, &k, seed);
        assert!(
            z.abs() < limit,
            "seed {seed}: joint {joint}'s compliance is {z:.2}σ from the truth"
        );
    }

    // The same file without them: a warning names every branch joint, and the torso's stiffness,
    // fitted with the branches at zero, is far from the truth.
    let mut bare = table.clone();
    bare.branch = None;
    let bare_path = d.join("without_branch_columns.csv");
    sim::measurement_table::write(&bare_path, &bare).unwrap();
    let (diag, err) = diagnose(&bare_path);
    for joint in BRANCH_JOINTS {
        assert!(
            err.contains(&format!("'{joint}'")) && err.contains("no q_<joint> column"),
            "{err}"
        );
    }
    let at_zero = compliance(&diag, seed);
    let z1 = z(&at_zero, 1, &k, seed);
    let rms = held_out_rms(&diag);
    eprintln!("branches at zero: held-out RMS {:.1} µm", rms * 1e6);
    assert!(
        z1.abs() > 4.0 && rms > 5.0 * posed_rms,
        "seed {seed}: with the branches at zero the torso's compliance is {z1:.2}σ off and the \
         held-out RMS {rms:e} m (against {posed_rms:e} m): the columns would not matter"
    );
    let _ = std::fs::remove_dir_all(&d);
}

/// Bad branch columns are told apart from good ones: a value beyond its joint's limits is an error
/// naming the file, row and column (exit 2); a column naming no branch joint is a warning, and not
/// read.
#[test]
fn branch_columns_are_checked_against_the_robot() {
    let d = common::scratch_dir("robocal_diagnose_branches", "checks");
    let sc = d.join("scenario.toml");
    let k = [8e3, 4e3, 4e3, f64::INFINITY];
    std::fs::write(&sc, scenario(&k).replace("poses = 300", "poses = 40")).unwrap();
    let data = common::generate(&sc, &d.join("gen"), &[]);
    let table = sim::measurement_table::read(&data).unwrap();
    let calibrate = |path: &Path| {
        common::robocal_status(&[
            "calibrate",
            "--robot",
            urdf().to_str().unwrap(),
            "--tip-link",
            "left_flange",
            "--data",
            path.to_str().unwrap(),
            "--out",
            d.join("model.json").to_str().unwrap(),
        ])
    };

    // right_elbow's limits are ±2.6 rad: 3.0 at row 7 is 0.4 rad beyond.
    let mut beyond = table.clone();
    let b = beyond.branch.as_mut().unwrap();
    let at = b.names.iter().position(|n| n == "right_elbow").unwrap();
    let width = b.names.len();
    b.values[6 * width + at] = 3.0;
    let path = d.join("beyond.csv");
    sim::measurement_table::write(&path, &beyond).unwrap();
    let (code, err) = calibrate(&path);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("beyond.csv")
            && err.contains("row 7")
            && err.contains("q_right_elbow")
            && err.contains("outside the limits"),
        "{err}"
    );

    // A column naming no branch joint: read with a warning that names it and the robot's branch
    // joints.
    let mut unknown = table.clone();
    unknown.branch.as_mut().unwrap().names[at] = "right_elbo".into();
    let path = d.join("unknown.csv");
    sim::measurement_table::write(&path, &unknown).unwrap();
    let (code, err) = calibrate(&path);
    assert_eq!(code, Some(0), "{err}");
    assert!(
        err.contains("q_right_elbo ") || err.contains("q_right_elbo name"),
        "{err}"
    );
    assert!(
        err.contains("'right_elbow'") && err.contains("not read"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&d);
}

/// `branches = "random"` draws each branch joint per pose within its limits (the same for a pose's
/// repeats, and the same bytes from the same seed); on a robot without branch joints it is a
/// scenario error naming the key, exit 2.
#[test]
fn the_generator_poses_the_branches_per_pose() {
    let d = common::scratch_dir("robocal_diagnose_branches", "generator");
    let sc = d.join("scenario.toml");
    let k = [8e3, 4e3, 4e3, f64::INFINITY];
    let text = scenario(&k)
        .replace("poses = 300", "poses = 30")
        .replace("[campaign]\n", "[campaign]\nrepeats = 2\n");
    std::fs::write(&sc, &text).unwrap();
    let a = common::generate(&sc, &d.join("a"), &[]);
    let b = common::generate(&sc, &d.join("b"), &[]);
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
    let table = sim::measurement_table::read(&a).unwrap();
    let model = common::load_chain(&urdf(), "left_flange");
    for (k, joint) in model.branches().joints().iter().enumerate() {
        let l = joint.limits.unwrap();
        let v: Vec<f64> = (0..table.len())
            .map(|r| table.branch_row(r).unwrap()[k])
            .collect();
        assert!(v.iter().all(|x| (l.lower..=l.upper).contains(x)), "{v:?}");
        for pair in v.chunks(2) {
            assert_eq!(pair[0], pair[1], "a pose's repeats share its branch pose");
        }
        let (lo, hi) = v
            .iter()
            .fold((f64::MAX, f64::MIN), |(a, b), x| (a.min(*x), b.max(*x)));
        assert!(
            hi - lo > 0.5 * (l.upper - l.lower),
            "{}: {lo}..{hi}",
            joint.name
        );
    }
    // The iiwa 7 has no branch to pose.
    let iiwa = common::repo().join("scenarios/iiwa7_compliance.toml");
    let text = std::fs::read_to_string(&iiwa)
        .unwrap()
        .replace("[campaign]\n", "[campaign]\nbranches = \"random\"\n");
    let sc = d.join("iiwa7.toml");
    std::fs::write(&sc, text).unwrap();
    let (code, err) = common::robocal_status(&[
        "generate",
        "--scenario",
        sc.to_str().unwrap(),
        "--out",
        d.join("iiwa").to_str().unwrap(),
    ]);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("campaign.branches") && err.contains("no movable joint off its chain"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&d);
}
