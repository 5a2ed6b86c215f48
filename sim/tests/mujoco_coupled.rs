//! The statics of a chain with a coupled joint, against MuJoCo: `golden/coupled_torso_statics.csv`,
//! written by `scripts/mujoco_coupled.py` (and its live copy in `$ROBOCAL_GOLDEN_LIVE` when set; CI
//! re-runs the script). The robot (`sim/tests/data/coupled_torso.urdf`) has a passive waist joint,
//! `torso_pitch_3 = −(torso_pitch_1 + torso_pitch_2)` (its `<robocal:coupling>`), elastic drives, and
//! a right arm and a head that load the torso. MuJoCo holds the coupling by a tendon equality and
//! settles the springs with its own forces; robocal's compliance stage solves `θ = q − A C Aᵀ τ_g(θ)`
//! (virtual work). The link-side angles must agree to 1e-9 rad and the flange to 1e-9 m: both sides
//! are exact equilibria in f64 (MuJoCo's residual is 5e-13 N m, ours a Newton step below 1e-13 rad).
//!
//! The coupling matters: the same springs on an uncoupled chain (the passive joint given a spring of
//! its own) settle centimetres away (checked below), so this test fails if the torque of the passive
//! joint does not go to its drives.

mod common;

use nalgebra::Vector3;
use sim::effects::{Conditions, Effects, joint_compliance::JointCompliance, true_target};
use sim::urdf::{ChainSpec, load_file};
use std::path::Path;

/// Agreement required (rad and m).
const TOLERANCE: f64 = 1e-9;

/// Drive stiffness of the golden file (N m/rad), chain order, with the passive joint's entry (the
/// 4th) not used.
const STIFFNESS: [f64; 8] = [20000.0, 3000.0, 4000.0, 1.0, 2500.0, 2000.0, 1500.0, 800.0];

fn model() -> sim::Model {
    let spec = ChainSpec {
        base_link: None,
        tip_link: Some("left_flange".into()),
    };
    load_file(
        &common::repo_root().join("sim/tests/data/coupled_torso.urdf"),
        &spec,
    )
    .unwrap()
}

/// Checks every row of `path` (`q1..q7, theta1..theta8, x, y, z`); returns the largest difference
/// of the angles (rad) and of the flange (m).
fn check_file(path: &Path) -> (f64, f64) {
    let model = model();
    assert_eq!((model.nq(), model.n_drives()), (8, 7));
    let effects = Effects {
        compliance: Some(JointCompliance::new(STIFFNESS.to_vec()).unwrap()),
        ..Effects::default()
    };
    let g = Vector3::new(0.0, 0.0, -9.81);
    let text = std::fs::read_to_string(path).unwrap();
    let (mut worst_angle, mut worst_flange) = (0.0_f64, 0.0_f64);
    let mut rows = 0;
    let mut q = [0.0; 8];
    for line in text
        .lines()
        .filter(|l| !l.starts_with('#') && !l.starts_with('q'))
    {
        let v: Vec<f64> = line.split(',').map(|x| x.parse().unwrap()).collect();
        assert_eq!(v.len(), 18, "{}: {line}", path.display());
        model.couplings().expand(&v[..7], &mut q);
        let cond = Conditions {
            q: &q,
            dir: None,
            temp_c: 20.0,
            payload: None,
            branch: None,
        };
        let t = true_target(&model, &effects, &cond, &Vector3::zeros(), &g).unwrap();
        for k in 0..8 {
            let d = (t.q_link[k] - v[7 + k]).abs();
            assert!(
                d <= TOLERANCE,
                "{}: q {:?}: joint {} settles at {} rad, MuJoCo {}",
                path.display(),
                &v[..7],
                k + 1,
                t.q_link[k],
                v[7 + k]
            );
            worst_angle = worst_angle.max(d);
        }
        let d = (t.p_base - Vector3::new(v[15], v[16], v[17])).amax();
        assert!(
            d <= TOLERANCE,
            "{}: q {:?}: flange {:?}, MuJoCo {:?}",
            path.display(),
            &v[..7],
            t.p_base,
            &v[15..]
        );
        worst_flange = worst_flange.max(d);
        rows += 1;
    }
    assert!(rows >= 20, "{}: {rows} rows", path.display());
    (worst_angle, worst_flange)
}

#[test]
fn coupled_statics_match_mujoco() {
    let (a, f) = check_file(&common::repo_root().join("golden/coupled_torso_statics.csv"));
    eprintln!("largest difference from MuJoCo: {a:.1e} rad, {f:.1e} m");
    if let Ok(dir) = std::env::var("ROBOCAL_GOLDEN_LIVE") {
        let live = Path::new(&dir).join("coupled_torso_statics.csv");
        if live.is_file() {
            check_file(&live);
        }
    }
}

/// Without the coupling's virtual work (the same chain, every joint driven and the passive one
/// given a spring as stiff as the stiffest drive) the waist settles elsewhere, by far more than the
/// tolerance: the golden comparison is not blind to where the passive joint's torque goes.
#[test]
fn the_passive_torque_goes_to_the_drives() {
    let coupled = model();
    let mut parts = coupled.to_parts();
    parts.couplings.clear();
    let free = sim::Model::new(parts).unwrap();
    let mut k = STIFFNESS;
    k[3] = 20000.0;
    let effects = Effects {
        compliance: Some(JointCompliance::new(k.to_vec()).unwrap()),
        ..Effects::default()
    };
    let g = Vector3::new(0.0, 0.0, -9.81);
    let mut q = [0.0; 8];
    coupled
        .couplings()
        .expand(&[0.3, 0.4, -0.2, 0.5, 0.6, -1.2, 0.4], &mut q);
    let cond = Conditions {
        q: &q,
        dir: None,
        temp_c: 20.0,
        payload: None,
        branch: None,
    };
    let a = true_target(&coupled, &effects, &cond, &Vector3::zeros(), &g).unwrap();
    let b = true_target(&free, &effects, &cond, &Vector3::zeros(), &g).unwrap();
    // The coupled chain keeps its coupling at rest (the passive joint follows its drives' sag).
    assert!((a.q_link[3] + a.q_link[1] + a.q_link[2]).abs() < 1e-12);
    let d = (a.p_base - b.p_base).norm();
    eprintln!("coupled against uncoupled: {d:.3e} m");
    assert!(d > 1e-3, "{d}");
}

/// A drive's backlash turns its link side, and the linkage carries that to the passive joint: with a
/// dead band of 4 mrad at torso_pitch_1 and 6 mrad at torso_pitch_2, approached from below (dir +1,
/// shift −half the band), the passive joint turns by +(2 + 3) mrad; the arm's joints do not move.
#[test]
fn a_drive_backlash_moves_the_passive_joint_through_the_linkage() {
    let model = model();
    let mut band = vec![0.0; 8];
    band[1] = 4e-3;
    band[2] = 6e-3;
    let effects = Effects {
        backlash: Some(sim::effects::gear_backlash::GearBacklash::direction(band).unwrap()),
        ..Effects::default()
    };
    let mut q = [0.0; 8];
    model
        .couplings()
        .expand(&[0.3, 0.4, -0.2, 0.5, 0.6, -1.2, 0.4], &mut q);
    let dir = [1i8; 8];
    let cond = Conditions {
        q: &q,
        dir: Some(&dir),
        temp_c: 20.0,
        payload: None,
        branch: None,
    };
    let t = true_target(
        &model,
        &effects,
        &cond,
        &Vector3::zeros(),
        &Vector3::new(0.0, 0.0, -9.81),
    )
    .unwrap();
    let d: Vec<f64> = t.q_link.iter().zip(&q).map(|(a, b)| a - b).collect();
    assert!(
        (d[1] + 2e-3).abs() < 1e-15 && (d[2] + 3e-3).abs() < 1e-15,
        "{d:?}"
    );
    assert!((d[3] - 5e-3).abs() < 1e-15, "{d:?}");
    assert!(d[4..].iter().chain(&d[..1]).all(|v| *v == 0.0), "{d:?}");
    // The coupling holds on the link side.
    assert!((t.q_link[3] + t.q_link[1] + t.q_link[2]).abs() < 1e-15);
}
