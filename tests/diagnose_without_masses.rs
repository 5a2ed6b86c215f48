//! `robocal diagnose` on a robot described without masses, as most users have it (a vendor's
//! kinematics or a DH table): the UR5's URDF stripped of its inertials. The campaign is simulated on
//! the real UR5 (with its masses) with compliance at drawn joints and stiffnesses; diagnose sees only
//! the measurements and the description without masses. It must name joint compliance at exactly
//! the drawn joints (identified as lumped products of compliance and mass moments), try link
//! deflection as lumped products too (and not name it), and bring the held-out error to within
//! 1.5× the noise floor.
//!
//! The seed is drawn per run and printed (`ROBOCAL_TEST_SEED` sets it); it reaches only the
//! scenario given to `robocal generate`.

use common::{repo, robocal_ok as robocal, scratch_dir, seed};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use serde_json::Value;

mod common;

#[test]
fn diagnose_names_compliance_on_a_robot_without_masses() {
    let seed = seed();
    eprintln!("seed {seed}");
    let mut rng = StdRng::seed_from_u64(seed);
    // Compliance at joint 2, joint 3 or both (the UR5's joints with large gravity torques), with
    // stiffnesses within the range of harmonic-drive arms.
    let joints: Vec<usize> = match rng.random_range(0..3) {
        0 => vec![2],
        1 => vec![3],
        _ => vec![2, 3],
    };
    let mut stiffness = vec!["inf".to_string(); 6];
    for &j in &joints {
        stiffness[j - 1] = format!("{:e}", rng.random_range(5e3..2e4));
    }
    let d = scratch_dir("robocal_nomass", &seed.to_string());
    let base = std::fs::read_to_string(repo().join("scenarios/ur5_kinematic.toml")).unwrap();
    let scenario = d.join("ur5_compliance.toml");
    std::fs::write(
        &scenario,
        format!(
            "{base}\n[effects.compliance]\nstiffness_nm_per_rad = [{}]\n",
            stiffness.join(", ")
        ),
    )
    .unwrap();
    let urdf = d.join("ur5_without_masses.urdf");
    std::fs::write(
        &urdf,
        sim::urdf_text::without_inertials(sim::robots::builtin_urdf("ur5").unwrap()),
    )
    .unwrap();
    let out = d.join("campaign");
    robocal(&[
        "generate",
        "--scenario",
        scenario.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--seed",
        &(seed % 1_000_000).to_string(),
        "--poses",
        "300",
    ]);
    let (json, _) = robocal(&[
        "diagnose",
        "--robot",
        urdf.to_str().unwrap(),
        "--data",
        out.join("measurements.parquet").to_str().unwrap(),
        "--json",
    ]);
    let diag: Value = serde_json::from_str(&json).unwrap();
    let findings = diag["findings"].as_array().unwrap();
    let named: Vec<(String, Value)> = findings
        .iter()
        .map(|f| {
            (
                f["cause"].as_str().unwrap().to_string(),
                f["joints"].clone(),
            )
        })
        .collect();
    assert_eq!(
        named,
        vec![("joint_compliance".to_string(), serde_json::json!(joints))],
        "seed {seed}: stiffness {stiffness:?}"
    );
    let compliance = &findings[0];
    let parameters = compliance["parameters"].as_array().unwrap();
    assert!(
        parameters.iter().all(|p| p["name"]
            .as_str()
            .unwrap()
            .contains("compliance × mass moment")),
        "seed {seed}: lumped products, not stiffnesses: {parameters:#?}"
    );
    let not_tried: Vec<&str> = diag["not_tried"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| n["cause"].as_str().unwrap())
        .collect();
    assert!(
        !not_tried.contains(&"link_deflection") && !not_tried.contains(&"joint_compliance"),
        "seed {seed}: {not_tried:?}"
    );
    assert!(
        diag["trials"]
            .as_array()
            .unwrap()
            .iter()
            .any(|t| t["cause"] == "link_deflection"),
        "seed {seed}: link deflection is tried as lumped products"
    );
    let floor = diag["noise_floor_m"].as_f64().unwrap();
    let after = diag["steps"].as_array().unwrap().last().unwrap()["test_rms_m"]
        .as_f64()
        .unwrap();
    assert!(
        after <= 1.5 * floor,
        "seed {seed}: held-out RMS {after:.3e} m against the noise floor {floor:.3e} m"
    );
    let _ = std::fs::remove_dir_all(&d);
}
