//! What the CLI tests that draw their cases from a seed share: the seed, a scratch folder and a
//! `robocal` run that must succeed.
#![allow(dead_code)]

use std::path::PathBuf;

/// The repository (the root package's folder).
pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// An empty folder `<temp>/<prefix>_<process id>_<name>` (emptied when it exists).
pub fn scratch_dir(prefix: &str, name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("{prefix}_{}_{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Runs robocal with `args`, asserting exit 0 (the message has stderr); `(stdout, stderr)`.
pub fn robocal_ok(args: &[&str]) -> (String, String) {
    let o = assert_cmd::Command::new(env!("CARGO_BIN_EXE_robocal"))
        .args(args)
        .output()
        .expect("run robocal");
    let (out, err) = (
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    );
    assert_eq!(o.status.code(), Some(0), "{args:?}: {err}");
    (out, err)
}

/// Runs robocal with `args`, whatever its exit; `(exit code, stderr)`.
pub fn robocal_status(args: &[&str]) -> (Option<i32>, String) {
    let o = assert_cmd::Command::new(env!("CARGO_BIN_EXE_robocal"))
        .args(args)
        .output()
        .expect("run robocal");
    (
        o.status.code(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

/// The run's seed: `ROBOCAL_TEST_SEED`, or drawn from the clock.
pub fn seed() -> u64 {
    std::env::var("ROBOCAL_TEST_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| {
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .unwrap()
                .as_nanos() as u64
        })
}

/// Runs `robocal generate --scenario SCENARIO --out OUT` with `extra` flags (asserting exit 0);
/// the measurement file it wrote.
pub fn generate(scenario: &std::path::Path, out: &std::path::Path, extra: &[&str]) -> PathBuf {
    let mut args = vec![
        "generate",
        "--scenario",
        scenario.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    robocal_ok(&args);
    out.join("measurements.parquet")
}

/// `(value, sigma)` of the parameter `name` in a list of `{name, value, sigma}` objects (a
/// finding's `parameters`); sigma NaN when the data do not determine it.
pub fn parameter(list: &serde_json::Value, name: &str) -> Option<(f64, f64)> {
    let p = list.as_array()?.iter().find(|p| p["name"] == name)?;
    Some((
        p["value"].as_f64()?,
        p["sigma"].as_f64().unwrap_or(f64::NAN),
    ))
}

/// The chain from the root of the URDF `urdf` to its link `tip`.
pub fn load_chain(urdf: &std::path::Path, tip: &str) -> sim::Model {
    sim::urdf::load_file(
        urdf,
        &sim::ChainSpec {
            base_link: None,
            tip_link: Some(tip.into()),
        },
    )
    .unwrap()
}

/// A blind scenario of a humanoid torso's left arm (`tip_link = "left_flange"` of `urdf`): 300 random
/// poses with approach directions, payloads of 0, 1.5 and 3 kg, a laser tracker's noise, drawn
/// geometric errors and joint stiffnesses `stiffness` (N m/rad, chain order; the scenario writes
/// infinity as it reads it). `campaign` adds lines to `[campaign]` (e.g. `branches = "random"`).
pub fn torso_scenario(
    name: &str,
    urdf: &std::path::Path,
    campaign: &str,
    stiffness: &[f64],
) -> String {
    format!(
        r#"name = "{name}"
seed = 1
[robot]
urdf = "{urdf}"
tip_link = "left_flange"
[campaign]
poses = 300
sampling = "random"
directions = "move"
{campaign}joint_margin_rad = 0.05
floor_z_m = 0.2
min_axis_distance_m = 0.10
[campaign.payload]
choice_kg = [0.0, 1.5, 3.0]
com_m = [0.0, 0.0, -0.05]
[tracker]
xyz_m = [2.5, 1.0, 0.4]
rpy_rad = [0.0, 0.0, 2.5]
reflector_m = [0.0, 0.0, -0.03]
radial_sigma_a_m = 5e-6
radial_sigma_b_m_per_m = 0.15e-6
transverse_sigma_a_m = 7.5e-6
transverse_sigma_b_m_per_m = 3e-6
[effects.kinematic]
joint_rotation_rad = {{ normal = [0.0, 3e-4] }}
joint_translation_m = {{ normal = [0.0, 2e-4] }}
zero_offset_rad = {{ normal = [0.0, 5e-4] }}
[effects.compliance]
stiffness_nm_per_rad = {stiffness:?}
"#,
        urdf = urdf.display(),
    )
}
