//! The statics of a chain taken from a tree, against MuJoCo: `golden/gravity_torso_two_arms.csv`,
//! written by `scripts/mujoco_branches.py` (and its live copy in `$ROBOCAL_GOLDEN_LIVE` when set; CI
//! re-runs the script). The robot (`sim/tests/data/torso_two_arms.urdf`) is a pitching torso with a
//! left arm, the measured chain (`--tip-link left_flange`), and a right arm, a head and a camera off
//! the torso; MuJoCo holds every body, robocal's chain model welds the branches to the torso with
//! their joints at zero. The holding torques of the chain's joints must agree to 1e-9 N m.
//!
//! The branches matter: without their 9.5 kg the torso joint's torque differs by tens of N m (checked
//! below), so this test fails if the loader leaves them out.

mod common;

use nalgebra::Vector3;
use sim::urdf::{ChainSpec, load_file, load_str};
use std::path::Path;

/// Agreement required (N m): both sides are exact statics in f64.
const TOLERANCE_NM: f64 = 1e-9;

fn chain_spec() -> ChainSpec {
    ChainSpec {
        base_link: None,
        tip_link: Some("left_flange".into()),
    }
}

fn urdf() -> std::path::PathBuf {
    common::repo_root().join("sim/tests/data/torso_two_arms.urdf")
}

/// Checks every row of `path` (`q1..q4, tau1..tau4`); returns the largest difference (N m).
fn check_file(path: &Path) -> f64 {
    let model = load_file(&urdf(), &chain_spec()).unwrap();
    assert_eq!(model.nq(), 4);
    let g = Vector3::new(0.0, 0.0, -9.81);
    let mut data = sim::Data::new(&model);
    let text = std::fs::read_to_string(path).unwrap();
    let mut worst = 0.0_f64;
    let mut rows = 0;
    for line in text
        .lines()
        .filter(|l| !l.starts_with('#') && !l.starts_with('q'))
    {
        let v: Vec<f64> = line.split(',').map(|x| x.parse().unwrap()).collect();
        assert_eq!(v.len(), 8, "{}: {line}", path.display());
        sim::statics::gravity_torques(&model, &mut data, &v[..4], &g, None).unwrap();
        for k in 0..4 {
            let d = (data.gravity_torque[k] - v[4 + k]).abs();
            assert!(
                d <= TOLERANCE_NM,
                "{}: q {:?}: joint {} holds {} N m, MuJoCo {}",
                path.display(),
                &v[..4],
                k + 1,
                data.gravity_torque[k],
                v[4 + k]
            );
            worst = worst.max(d);
        }
        rows += 1;
    }
    assert!(rows >= 20, "{}: {rows} rows", path.display());
    worst
}

#[test]
fn branch_statics_match_mujoco() {
    let worst = check_file(&common::repo_root().join("golden/gravity_torso_two_arms.csv"));
    eprintln!("largest difference from MuJoCo: {worst:.1e} N m");
    if let Ok(dir) = std::env::var("ROBOCAL_GOLDEN_LIVE") {
        let live = Path::new(&dir).join("gravity_torso_two_arms.csv");
        if live.is_file() {
            check_file(&live);
        }
    }
}

/// The model names the branch joints it holds at zero, and leaving the branches out changes the
/// torso's torque (the golden comparison above is not blind to them).
#[test]
fn the_branches_load_the_torso_and_are_named() {
    let model = load_file(&urdf(), &chain_spec()).unwrap();
    let notes = model.notes().join("\n");
    for joint in [
        "neck_yaw",
        "neck_pitch",
        "right_shoulder_pitch",
        "right_elbow",
    ] {
        assert!(notes.contains(&format!("'{joint}'")), "{notes}");
    }
    // The same robot with the branches cut off (their joints and links removed from the text).
    let text = std::fs::read_to_string(urdf()).unwrap();
    let cut = cut_branches(&text);
    let alone = load_str(&cut, "left arm alone", &chain_spec()).unwrap();
    assert!(alone.notes().is_empty(), "{:?}", alone.notes());
    let g = Vector3::new(0.0, 0.0, -9.81);
    let q = [0.3, -0.5, 0.8, 0.2];
    let (mut a, mut b) = (sim::Data::new(&model), sim::Data::new(&alone));
    sim::statics::gravity_torques(&model, &mut a, &q, &g, None).unwrap();
    sim::statics::gravity_torques(&alone, &mut b, &q, &g, None).unwrap();
    assert!(
        (a.gravity_torque[0] - b.gravity_torque[0]).abs() > 10.0,
        "torso: {} against {} N m",
        a.gravity_torque[0],
        b.gravity_torque[0]
    );
    // The arm's own joints carry only what lies beyond them: the same with or without branches.
    for k in 1..4 {
        assert!((a.gravity_torque[k] - b.gravity_torque[k]).abs() < 1e-12);
    }
}

/// `text` without the elements of the head and right arm (from the comment-free markers of the test
/// URDF: every `<joint>` and `<link>` whose name starts with `neck`, `head` or `right_`).
fn cut_branches(text: &str) -> String {
    let mut out = String::new();
    let mut rest = text;
    loop {
        let next = ["<joint name=\"", "<link name=\""]
            .iter()
            .filter_map(|tag| rest.find(tag).map(|at| (at, *tag)))
            .min();
        let Some((at, tag)) = next else { break };
        let name_start = at + tag.len();
        let name = &rest[name_start..name_start + rest[name_start..].find('"').unwrap()];
        let element = if tag.starts_with("<joint") {
            "</joint>"
        } else {
            "</link>"
        };
        // A self-closing element ends at its first `/>`; others at their closing tag.
        let head_end = at + rest[at..].find('>').unwrap();
        let end = if rest[..head_end].ends_with('/') {
            head_end + 1
        } else {
            head_end + rest[head_end..].find(element).unwrap() + element.len()
        };
        out.push_str(&rest[..at]);
        if !(name.starts_with("neck") || name.starts_with("head") || name.starts_with("right_")) {
            out.push_str(&rest[at..end]);
        }
        rest = &rest[end..];
    }
    out.push_str(rest);
    out
}
