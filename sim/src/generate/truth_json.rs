//! The `truth.json` document: the truth model, every injected parameter, the scenario, the
//! provenance and the summary (see [`super`]).

use super::columns::truth_column_names;
use super::summary::Summary;
use super::{MEASUREMENTS_FILE, TRUTH_PARQUET_FILE, VERSION};
use crate::scenario::{Resolved, TruthModel};
use serde_json::json;
use std::path::Path;

/// A pose as `{xyz_m, rpy_rad, matrix}` for `truth.json`.
fn pose_json(xyz: [f64; 3], rpy: [f64; 3], t: &crate::lie::Pose) -> serde_json::Value {
    let m = t.to_homogeneous();
    json!({
        "xyz_m": xyz, "rpy_rad": rpy,
        "matrix": (0..4).map(|r| (0..4).map(|c| m[(r, c)]).collect::<Vec<_>>()).collect::<Vec<_>>(),
    })
}

/// The `truth.json` document, top-level keys in reading order (nested objects have sorted keys).
#[derive(serde::Serialize)]
pub(super) struct TruthDoc {
    software: serde_json::Value,
    seed: u64,
    overrides: crate::scenario::Overrides,
    scenario_file: String,
    truth_model: TruthModel,
    truth: serde_json::Value,
    robot: serde_json::Value,
    gravity_m_per_s2: [f64; 3],
    effects: serde_json::Value,
    tracker: serde_json::Value,
    campaign: serde_json::Value,
    summary: serde_json::Value,
    files: serde_json::Value,
    scenario: serde_json::Value,
    scenario_text: String,
}

fn to_value<T: serde::Serialize>(v: &T) -> serde_json::Value {
    serde_json::to_value(v).unwrap_or(serde_json::Value::Null)
}

/// How the truth was computed, for `truth.json`: the compliance solver, its settings, its step
/// counts and, for rapier, what the engine's model holds.
fn truth_record(res: &Resolved, summary: &Summary) -> serde_json::Value {
    use crate::effects::joint_compliance as jc;
    let [mean, max] = summary.compliance_steps_mean_max;
    match res.truth_model {
        TruthModel::Analytic => json!({
            "model": res.truth_model,
            "compliance_solver": "Newton on K (q − θ) = τ_g(θ) in the real geometry (sim::effects::joint_compliance)",
            "newton_tolerance_rad": jc::TOLERANCE_RAD,
            "newton_max_iterations": jc::MAX_ITERATIONS,
            "compliance_iterations_mean": mean,
            "compliance_iterations_max": max,
        }),
        TruthModel::Rapier => {
            let o = crate::springs::SettleOptions::default();
            json!({
                "model": res.truth_model,
                "compliance_solver": "rapier multibody with joint springs settled to rest, built per temperature and payload from the real geometry: thermally grown links, kinematic error twists, base and tool errors; nominal inertials in the real joint frames; springs anchored at the motor angles after zero offsets, zero drift and backlash (sim::effects::rapier_compliance)",
                "engine": crate::rapier_truth::ENGINE,
                "settle_options": {
                    "dt_s": o.dt, "damping_ratio": o.damping_ratio, "speed_tol_rad_per_s": o.speed_tol,
                    "residual_tol_nm": o.residual_tol, "max_steps": o.max_steps,
                },
                "engine_steps_mean": mean,
                "engine_steps_max": max,
            })
        }
    }
}

/// The `truth.json` document.
pub(super) fn truth_json(
    res: &Resolved,
    (nq, repeats): (usize, usize),
    summary: &Summary,
) -> TruthDoc {
    let sc = &res.scenario;
    let tr = &res.tracker;
    let file_name = Path::new(&sc.label)
        .file_name()
        .map_or_else(|| sc.label.clone(), |n| n.to_string_lossy().into_owned());
    TruthDoc {
        software: json!({"name": "robocal", "version": VERSION}),
        seed: res.seed,
        overrides: res.overrides,
        scenario_file: file_name,
        truth_model: res.truth_model,
        truth: truth_record(res, summary),
        robot: json!({
            "name": res.model.name(), "source": res.robot_source.source,
            "urdf_fnv1a64": res.robot_source.urdf_fnv1a64,
            "base_link": res.model.base_link(), "tip_link": res.model.tip_link(),
            "joints": res.model.nq(),
            "joint_names": res.model.joints().iter().map(|j| j.name.clone()).collect::<Vec<_>>(),
        }),
        gravity_m_per_s2: [res.gravity.x, res.gravity.y, res.gravity.z],
        effects: to_value(&res.effects),
        tracker: json!({
            "T_tracker_base": pose_json(res.tracker_xyz_m, res.tracker_rpy_rad, tr.t_tracker_base()),
            "reflector_flange_m": [tr.p_flange().x, tr.p_flange().y, tr.p_flange().z],
            "six_dof": tr.six_dof(),
            "R_flange_probe": (0..3).map(|r| (0..3).map(|c| tr.r_flange_probe()[(r, c)]).collect::<Vec<_>>()).collect::<Vec<_>>(),
            "noise_model": tr.noise(),
            "noise_scale": tr.noise_scale(),
            "noise_law": "error = s (σ_r n_r u + σ_t (n1 e1 + n2 e2)), σ_r = radial_a_m + radial_b_m_per_m d, σ_t = transverse_a_m + transverse_b_m_per_m d; u line of sight, e1 = z×u/|z×u|, e2 = u×e1; plus, at outlier_rate, s outlier_magnitude_m in a uniform direction",
            "sigma_column": "sqrt((σ_r² + 2 σ_t²)/3) at the measured distance (RMS of the per-axis σ), scaled by noise_scale; absent when noise_scale = 0",
        }),
        campaign: json!({
            "spec": res.campaign,
            "poses": summary.poses, "repeats": repeats, "rows": summary.rows,
        }),
        summary: to_value(summary),
        files: json!({
            "measurements": MEASUREMENTS_FILE, "truth_rows": TRUTH_PARQUET_FILE,
            "truth_rows_columns": truth_column_names(nq, tr.six_dof()),
        }),
        scenario: to_value(&sc.file),
        scenario_text: sc.text.clone(),
    }
}
