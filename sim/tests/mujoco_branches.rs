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

/// Checks every row of `path` (`q1..q4`, then the branch joints' `q_<joint>` columns when the file
/// poses the branches, then `tau1..tau4`); returns the largest difference (N m).
fn check_file(path: &Path) -> f64 {
    let model = load_file(&urdf(), &chain_spec()).unwrap();
    assert_eq!(model.nq(), 4);
    let g = Vector3::new(0.0, 0.0, -9.81);
    let mut data = sim::Data::new(&model);
    let text = std::fs::read_to_string(path).unwrap();
    let header: Vec<&str> = text
        .lines()
        .find(|l| l.starts_with('q'))
        .unwrap()
        .split(',')
        .collect();
    // Where each branch joint's value is in a row (the model's order), when the file has them.
    let branch_at: Vec<usize> = model
        .branches()
        .joints()
        .iter()
        .filter_map(|j| header.iter().position(|h| *h == format!("q_{}", j.name)))
        .collect();
    let posed = !branch_at.is_empty();
    if posed {
        assert_eq!(branch_at.len(), model.branches().len(), "{header:?}");
    }
    let width = 8 + branch_at.len();
    let tau_at = 4 + branch_at.len();
    let mut values = vec![0.0; model.branches().len()];
    let mut worst = 0.0_f64;
    let mut rows = 0;
    for line in text
        .lines()
        .filter(|l| !l.starts_with('#') && !l.starts_with('q'))
    {
        let v: Vec<f64> = line.split(',').map(|x| x.parse().unwrap()).collect();
        assert_eq!(v.len(), width, "{}: {line}", path.display());
        for (value, &at) in values.iter_mut().zip(&branch_at) {
            *value = v[at];
        }
        data.pose_branches(&model, posed.then_some(values.as_slice()));
        sim::statics::gravity_torques(&model, &mut data, &v[..4], &g, None).unwrap();
        for k in 0..4 {
            let d = (data.gravity_torque[k] - v[tau_at + k]).abs();
            assert!(
                d <= TOLERANCE_NM,
                "{}: row {line}: joint {} holds {} N m, MuJoCo {}",
                path.display(),
                k + 1,
                data.gravity_torque[k],
                v[tau_at + k]
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
    for file in [
        "gravity_torso_two_arms.csv",
        "gravity_torso_two_arms_posed.csv",
    ] {
        let worst = check_file(&common::repo_root().join("golden").join(file));
        eprintln!("{file}: largest difference from MuJoCo: {worst:.1e} N m");
        if let Ok(dir) = std::env::var("ROBOCAL_GOLDEN_LIVE") {
            let live = Path::new(&dir).join(file);
            if live.is_file() {
                check_file(&live);
            }
        }
    }
}

/// The posed file is not blind to the branches' pose: with the branches left at zero instead, the
/// torso's torque misses MuJoCo's by more than 1 N m in every row (the smallest is 1.08 N m), so
/// a model that ignored `q_<joint>` values would fail [`branch_statics_match_mujoco`].
#[test]
fn the_posed_file_needs_the_branch_pose() {
    let model = load_file(&urdf(), &chain_spec()).unwrap();
    let text = std::fs::read_to_string(
        common::repo_root().join("golden/gravity_torso_two_arms_posed.csv"),
    )
    .unwrap();
    let g = Vector3::new(0.0, 0.0, -9.81);
    let mut data = sim::Data::new(&model);
    let mut rows = 0;
    for line in text
        .lines()
        .filter(|l| !l.starts_with('#') && !l.starts_with('q'))
    {
        let v: Vec<f64> = line.split(',').map(|x| x.parse().unwrap()).collect();
        sim::statics::gravity_torques(&model, &mut data, &v[..4], &g, None).unwrap();
        let miss = (data.gravity_torque[0] - v[8]).abs();
        assert!(
            miss > 1.0,
            "row {line}: branches at zero miss by only {miss} N m"
        );
        rows += 1;
    }
    assert_eq!(rows, 24);
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

/// The branches as the loader reads them: each movable joint off the chain, the chain body it hangs
/// from, the branch joint before it, and the mass that moves with it (its child link and every link
/// welded below it), by hand from the URDF.
#[test]
fn branch_joints_carry_the_masses_that_move_with_them() {
    let model = load_file(&urdf(), &chain_spec()).unwrap();
    let b = model.branches();
    let names: Vec<&str> = b.joints().iter().map(|j| j.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "neck_yaw",
            "neck_pitch",
            "right_shoulder_pitch",
            "right_elbow"
        ]
    );
    // (body, parent, mass kg): the neck 0.8, the head 3.5, the upper arm 2.6, the forearm 1.7 with
    // the gripper's 0.9 welded to it.
    let want = [
        (0, None, 0.8),
        (0, Some(0), 3.5),
        (0, None, 2.6),
        (0, Some(2), 2.6),
    ];
    for (j, (body, parent, mass)) in b.joints().iter().zip(want) {
        assert_eq!((j.body, j.parent), (body, parent), "{}", j.name);
        assert!((j.mass - mass).abs() < 1e-12, "{}: {} kg", j.name, j.mass);
    }
    // The forearm's centre, in the elbow's frame: (1.7 (0.01, 0, −0.12) + 0.9 (0, 0, −0.34)) / 2.6.
    let c = b.joints()[3].com;
    let want = Vector3::new(0.017, 0.0, -0.204 - 0.306) / 2.6;
    assert!((c - want).norm() < 1e-15, "{c:?}");
    // Posed at zero, the bodies are the loader's.
    let mut data = sim::Data::new(&model);
    data.pose_branches(&model, Some(&[0.0; 4]));
    for (c, body) in data.body_com.iter().zip(model.bodies()) {
        assert!((c - body.com).norm() < 1e-15);
    }
}

/// The simulator's truth carries the posed branches into its compliance equilibrium: the link-side
/// angles it settles at satisfy `θ = q − C τ_g(θ)` with the torques of the posed robot (the statics
/// checked against MuJoCo above), and differ from those of the robot with its branches at zero.
#[test]
fn the_truth_settles_with_the_branches_where_the_row_puts_them() {
    use sim::effects::{Conditions, Effects, Truth, joint_compliance::JointCompliance};
    let model = load_file(&urdf(), &chain_spec()).unwrap();
    let stiffness = [6000.0, 3000.0, 2500.0, 2000.0];
    let effects = Effects {
        compliance: Some(JointCompliance::new(stiffness.to_vec()).unwrap()),
        ..Effects::default()
    };
    let truth = Truth::new(&model, &effects).unwrap();
    let mut scratch = truth.scratch();
    let g = Vector3::new(0.0, 0.0, -9.81);
    let mut data = sim::Data::new(&model);
    let q = [0.3, -0.5, 0.8, 0.2];
    let branch = [0.7, -0.4, 1.9, -1.2];
    let cond = Conditions {
        q: &q,
        dir: None,
        temp_c: 20.0,
        payload: None,
        branch: Some(&branch),
    };
    truth
        .target(&cond, &Vector3::zeros(), &g, &mut scratch)
        .unwrap();
    let theta = scratch.q_link().to_vec();
    data.pose_branches(&model, Some(&branch));
    sim::statics::gravity_torques(&model, &mut data, &theta, &g, None).unwrap();
    for k in 0..4 {
        let want = q[k] - data.gravity_torque[k] / stiffness[k];
        assert!(
            (theta[k] - want).abs() < 1e-12,
            "joint {}: {} against {want}",
            k + 1,
            theta[k]
        );
    }
    let at_zero = Conditions {
        branch: None,
        ..cond
    };
    truth
        .target(&at_zero, &Vector3::zeros(), &g, &mut scratch)
        .unwrap();
    let moved = (scratch.q_link()[0] - theta[0]).abs();
    assert!(moved > 1e-4, "the torso settles only {moved} rad apart");
    // A value per branch joint, finite: anything else is refused by name.
    let short = Conditions {
        branch: Some(&branch[..3]),
        ..cond
    };
    let e = truth
        .target(&short, &Vector3::zeros(), &g, &mut scratch)
        .unwrap_err()
        .to_string();
    assert!(e.contains("branch") && e.contains("(4)"), "{e}");
    let nan = [0.0, f64::NAN, 0.0, 0.0];
    let bad = Conditions {
        branch: Some(&nan),
        ..cond
    };
    let e = truth
        .target(&bad, &Vector3::zeros(), &g, &mut scratch)
        .unwrap_err()
        .to_string();
    assert!(e.contains("q_neck_pitch"), "{e}");
}
