//! Flange poses and gravity torques against MuJoCo 4.0 (files written by `scripts/mujoco_reference.py`).
//!
//! Reads every `golden/kinematics_*.csv`, and also the files in `$ROBOCAL_GOLDEN_LIVE` when set (CI
//! re-runs the script into that folder, so a change on either side is caught).

mod common;

use nalgebra::{Matrix3, Vector3};
use sim::{ChainSpec, Data, gravity_torques, urdf::load_file};
use std::path::{Path, PathBuf};

/// Flange position agreement (m).
const POSITION_TOL_M: f64 = 1e-9;
/// Flange orientation agreement: angle of `R_oursᵀ R_mujoco` (rad).
const ROTATION_TOL_RAD: f64 = 1e-9;
/// Gravity torque agreement, relative to the configuration's largest torque magnitude.
const TORQUE_REL_TOL: f64 = 1e-9;
/// Robots the script must have written.
const ROBOTS: &[&str] = &[
    "iiwa7",
    "ur5",
    "ur10",
    "wam",
    "iiwa_stack_iiwa7",
    "lbr_stack_iiwa7",
];

struct Golden {
    urdf: PathBuf,
    base: String,
    tip: String,
    rows: Vec<Vec<f64>>,
    header: Vec<String>,
}

fn read_golden(path: &Path) -> Golden {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut urdf = None;
    let (mut base, mut tip) = (String::new(), String::new());
    let mut header = Vec::new();
    let mut rows = Vec::new();
    for line in text.lines() {
        if let Some(c) = line.strip_prefix("# ") {
            if let Some(rest) = c.strip_prefix("urdf: ") {
                let rel = rest.split(" (").next().unwrap();
                urdf = Some(if rest.contains("shared directory") {
                    common::shared_dir().join(rel)
                } else {
                    common::repo_root().join(rel)
                });
            } else if let Some(rest) = c.strip_prefix("root link: ") {
                base = rest.split(' ').next().unwrap().to_string();
                tip = rest.rsplit("tip link: ").next().unwrap().trim().to_string();
            }
        } else if header.is_empty() {
            header = line.split(',').map(str::to_string).collect();
        } else if !line.trim().is_empty() {
            rows.push(line.split(',').map(|v| v.parse::<f64>().unwrap()).collect());
        }
    }
    Golden {
        urdf: urdf.expect("no '# urdf:' line"),
        base,
        tip,
        rows,
        header,
    }
}

fn check_dir(dir: &Path) {
    for robot in ROBOTS {
        let path = dir.join(format!("kinematics_{robot}.csv"));
        assert!(
            path.exists(),
            "{} is missing: run scripts/mujoco_reference.py",
            path.display()
        );
        let g = read_golden(&path);
        let spec = ChainSpec {
            base_link: Some(g.base.clone()),
            tip_link: Some(g.tip.clone()),
        };
        let model = load_file(&g.urdf, &spec).unwrap();
        let n = model.nq();
        assert_eq!(g.header.len(), 2 * n + 12, "{}: columns", path.display());
        assert!(
            g.rows.len() >= 500,
            "{}: only {} rows",
            path.display(),
            g.rows.len()
        );
        let mut data = Data::new(&model);
        let gravity = Vector3::new(0.0, 0.0, -9.81);
        let (mut worst_p, mut worst_r, mut worst_t) = (0.0f64, 0.0f64, 0.0f64);
        for (k, row) in g.rows.iter().enumerate() {
            let q = &row[..n];
            gravity_torques(&model, &mut data, q, &gravity, None).unwrap();
            let p_ref = Vector3::new(row[n], row[n + 1], row[n + 2]);
            let r_ref = Matrix3::from_row_slice(&row[n + 3..n + 12]);
            let dp = (data.flange.translation.vector - p_ref).norm();
            let dr = rotation_angle(&(data.flange.rotation.matrix().transpose() * r_ref));
            let tau_ref = &row[n + 12..];
            let scale = tau_ref
                .iter()
                .fold(0.0f64, |a, t| a.max(t.abs()))
                .max(1e-12);
            let dt = data
                .gravity_torque
                .iter()
                .zip(tau_ref)
                .fold(0.0f64, |a, (x, y)| a.max((x - y).abs()))
                / scale;
            assert!(
                dp < POSITION_TOL_M,
                "{robot} row {k}: position off by {dp:e} m"
            );
            assert!(
                dr < ROTATION_TOL_RAD,
                "{robot} row {k}: rotation off by {dr:e} rad"
            );
            assert!(
                dt < TORQUE_REL_TOL,
                "{robot} row {k}: torque off by {dt:e} (relative)"
            );
            worst_p = worst_p.max(dp);
            worst_r = worst_r.max(dr);
            worst_t = worst_t.max(dt);
        }
        eprintln!(
            "{robot}: {} configurations, worst position {worst_p:.1e} m, rotation {worst_r:.1e} rad, torque {worst_t:.1e} relative",
            g.rows.len()
        );
    }
}

/// Angle of a rotation matrix (rad), accurate near zero (atan2, not acos of the trace).
fn rotation_angle(a: &Matrix3<f64>) -> f64 {
    let v = Vector3::new(
        a[(2, 1)] - a[(1, 2)],
        a[(0, 2)] - a[(2, 0)],
        a[(1, 0)] - a[(0, 1)],
    );
    (0.5 * v.norm()).atan2(0.5 * (a.trace() - 1.0))
}

#[test]
fn flange_pose_and_gravity_torques_match_stored_mujoco_reference() {
    check_dir(&common::repo_root().join("golden"));
}

#[test]
fn flange_pose_and_gravity_torques_match_live_mujoco_run() {
    match std::env::var_os("ROBOCAL_GOLDEN_LIVE") {
        Some(dir) => check_dir(Path::new(&dir)),
        None if std::env::var_os("CI").is_some() => {
            panic!("CI must re-run scripts/mujoco_reference.py and set ROBOCAL_GOLDEN_LIVE")
        }
        None => eprintln!("ROBOCAL_GOLDEN_LIVE not set: only the stored reference was checked"),
    }
}
