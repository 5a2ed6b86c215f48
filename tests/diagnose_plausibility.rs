//! Diagnose's plausibility bounds and its joint selection within a cause (issue 25, item 4), as a user
//! meets them: campaigns simulated with hidden effects whose joints and magnitudes are drawn from a
//! seed each run prints (`ROBOCAL_TEST_SEED=… cargo test --release --test diagnose_plausibility`
//! repeats one; `ROBOCAL_TEST_KEEP=1` keeps each case's files in the temporary folder). The seed and
//! the truth never reach the code under test, which sees only the measurement files.
//!
//! What must hold:
//! - **A cause at only some of its joints.** Joint compliance at joints 2 and 4, and at joint 6 an
//!   angle-reading error in proportion to its holding torque with the sign no spring has (an angle
//!   sensor that reads the link ahead of its load, as a torque sensor's cross-talk into a link-side
//!   encoder would): the fit of compliance at every joint gives joint 6 a negative compliance, beyond
//!   three standard deviations (checked, so that the case cannot pass vacuously). Diagnose drops
//!   joint 6 from the cause and names compliance at joints 2 and 4 only.
//!
//!   Measured over 79 drawn seeds: joint 6 dropped in 78, taken up by link deflection adopted beside
//!   the compliance in one (then nothing is dropped and no joint-6 compliance is named; also
//!   accepted). The stiffnesses at joints 2 and 4 are printed, not judged in units of their σ here:
//!   the reading error left unexplained at joint 6 (no cause may take it, by construction) leaks into
//!   joint 4's compliance, because the payload loads both joints, and the σ diagnose reports covers
//!   the noise, not that bias (z means −0.3 and +0.4, standard deviations 1.1; 2 seeds in 79 beyond
//!   3σ at joint 4, `ROBOCAL_TEST_SEED=121` and `122`). Where the model is right, the stiffnesses of
//!   a cause limited to some joints come back within their σ: `calib/tests/extensions.rs` (the
//!   subset fit) and the compliance cases of `tests/diagnose_blind.rs`.
//! - **A backlash no gear has.** A half lost motion of 5 mrad (0.29°) at one joint is reported as
//!   implausible (beyond 2 mrad) and not adopted.

use common::seed;
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use serde_json::Value;
use sim::measurement_table as mt;
use std::path::{Path, PathBuf};

mod common;

fn dir(name: &str) -> PathBuf {
    common::scratch_dir("robocal_diagnose_plausibility", name)
}

/// Removes a case's folder, unless `ROBOCAL_TEST_KEEP` is set (then it is kept to look at; a failed
/// case keeps it anyway).
fn cleanup(d: &Path) {
    if std::env::var_os("ROBOCAL_TEST_KEEP").is_none() {
        let _ = std::fs::remove_dir_all(d);
    }
}

/// Runs robocal with `args`; stdout, asserting exit 0.
fn robocal(args: &[&str]) -> String {
    common::robocal_ok(args).0
}

/// Generates the iiwa 7 campaign of the kinematic scenario (drawn geometric errors, 300 random poses)
/// with `extra` TOML sections, seeded by `seed`, into `out`; the measurement file.
fn generate(extra: &str, seed: u64, out: &Path) -> PathBuf {
    let base = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/iiwa7_kinematic.toml"),
    )
    .unwrap();
    let scenario = out.join("scenario.toml");
    std::fs::write(&scenario, format!("{base}\n{extra}")).unwrap();
    let gen_dir = out.join("gen");
    robocal(&[
        "generate",
        "--scenario",
        scenario.to_str().unwrap(),
        "--out",
        gen_dir.to_str().unwrap(),
        "--seed",
        &seed.to_string(),
        "--poses",
        "300",
    ]);
    gen_dir.join("measurements.parquet")
}

/// `(value, sigma)` of the parameter `name` in a list of `{name, value, sigma}` objects.
fn parameter(list: &Value, name: &str) -> (f64, f64) {
    let p = list
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["name"] == name)
        .unwrap_or_else(|| panic!("no parameter '{name}' in {list}"));
    (p["value"].as_f64().unwrap(), p["sigma"].as_f64().unwrap())
}

#[test]
fn compliance_at_two_joints_is_named_there_when_a_third_fits_negative() {
    let seed = seed();
    eprintln!("diagnose_plausibility: seed {seed} (ROBOCAL_TEST_SEED={seed} repeats this run)");
    let mut rng = StdRng::seed_from_u64(seed);
    // Lightweight-robot joint stiffnesses (N m/rad), and the joint-6 reading error (rad per N m of
    // holding torque): some tens of µrad at the torques of a 7 kg payload, which the fit at every
    // joint takes for a compliance of −1e-5 to −2e-5 rad/(N m), 10 to 20 standard deviations below
    // zero. (Ten times larger, the error left unmodelled once joint 6 is dropped would bias the
    // stiffnesses of joints 2 and 4 by three standard deviations: the residual would no longer be
    // noise, which the 3σ criterion assumes.)
    let k2 = rng.random_range(5e3..2e4);
    let k4 = rng.random_range(5e3..2e4);
    let e6 = rng.random_range(1e-5..2e-5);
    let d = dir("subset");
    let generated = generate(
        &format!(
            "[campaign.payload]\nchoice_kg = [0.0, 3.5, 7.0]\ncom_m = [0.0, 0.0, 0.08]\n\
             [effects.compliance]\nstiffness_nm_per_rad = [inf, {k2:e}, inf, {k4:e}, inf, inf, inf]\n"
        ),
        rng.random_range(1..u32::MAX as u64),
        &d,
    );
    // The reading error: joint 6 reports q₆ − e₆ τ₆(q), so the link sits at the reported angle plus
    // e₆ τ₆ (τ₆ the nominal arm's holding torque with the row's payload, N m): to the estimator a
    // compliance of −e₆.
    let mut table = mt::read(&generated).unwrap();
    let model = sim::robots::load_builtin("iiwa7").unwrap();
    let mut data = sim::Data::new(&model);
    let g = nalgebra::Vector3::from(sim::statics::DEFAULT_GRAVITY);
    let nq = model.nq();
    for r in 0..table.len() {
        let q = table.q_row(r).to_vec();
        let payload = table.payload.as_ref().map(|p| p[r]).filter(|m| *m > 0.0);
        let payload = payload.map(|mass| sim::statics::Payload {
            mass,
            com: [0.0, 0.0, 0.08],
        });
        sim::statics::gravity_torques(&model, &mut data, &q, &g, payload.as_ref()).unwrap();
        let tau6 = data.gravity_torque[5];
        table.q[r * nq + 5] = q[5] - e6 * tau6;
    }
    let measurements = d.join("measurements.parquet");
    mt::write(&measurements, &table).unwrap();
    let data_arg = measurements.to_str().unwrap();
    // The fit of compliance at every joint: joint 6's compliance is negative beyond 3σ.
    let model_out = d.join("full.json");
    let cal: Value = serde_json::from_str(&robocal(&[
        "calibrate",
        "--robot",
        "iiwa7",
        "--data",
        data_arg,
        "--model",
        "joint_compliance",
        "--out",
        model_out.to_str().unwrap(),
        "--json",
    ]))
    .unwrap();
    let (c6, s6) = parameter(&cal["report"]["parameters"], "joint 6 compliance");
    eprintln!("joint 6 compliance at every joint: {c6:.3e} ± {s6:.1e} rad/(N m)");
    assert!(
        c6 < -3.0 * s6,
        "seed {seed}: the full fit's joint 6 compliance {c6:.3e} ± {s6:.1e} is not negative beyond \
         3σ: the case tests nothing"
    );
    // Diagnose names compliance at joints 2 and 4 only, having dropped joint 6.
    let diag: Value = serde_json::from_str(&robocal(&[
        "diagnose", "--robot", "iiwa7", "--data", data_arg, "--json",
    ]))
    .unwrap();
    let findings = diag["findings"].as_array().unwrap();
    let compliance = findings
        .iter()
        .find(|f| f["cause"] == "joint_compliance")
        .unwrap_or_else(|| panic!("seed {seed}: compliance not named: {findings:#?}"));
    assert_eq!(
        compliance["joints"],
        serde_json::json!([2, 4]),
        "seed {seed}: {compliance:#}"
    );
    for f in findings {
        let joints = f["joints"].as_array().unwrap();
        assert!(
            f["cause"] != "joint_compliance" || !joints.contains(&6.into()),
            "seed {seed}: {f:#}"
        );
    }
    // How joint 6 left: dropped from the cause for its negative compliance, the cause refitted at
    // joints 2 and 4 (the joint selection; 39 of 40 seeds), or taken up, with the compliance at
    // every joint, by link deflection adopted beside it (its bending about joint 6 stands in for the
    // reading error; then no compliance parameter of joint 6 is named, and nothing is dropped).
    let model = diag["model"].as_str().unwrap();
    let dropped = diag["joint_selection"].as_array();
    if compliance["fitted_joints"].is_null() {
        assert!(
            model.contains("+joint_compliance+link_deflection") && dropped.is_none(),
            "seed {seed}: compliance at every joint without deflection beside it: {model}"
        );
        eprintln!("joint 6 taken up by link deflection: {model}");
    } else {
        assert_eq!(
            compliance["fitted_joints"],
            serde_json::json!([2, 4]),
            "seed {seed}: {compliance:#}"
        );
        assert!(
            model.contains("joint_compliance@2,4"),
            "seed {seed}: {model}"
        );
        let dropped = dropped.unwrap_or_else(|| panic!("seed {seed}: no joint selection"));
        assert!(
            dropped.iter().any(|s| s["cause"] == "joint_compliance"
                && s["implausible"].as_array().unwrap().contains(&6.into())),
            "seed {seed}: joint 6 not dropped for its negative compliance: {dropped:#?}"
        );
    }
    // Printed, not judged in σ: the unexplained joint-6 error biases joint 4's (see the header).
    for (joint, k) in [(2, k2), (4, k4)] {
        let (c, s) = parameter(
            &compliance["parameters"],
            &format!("joint {joint} compliance"),
        );
        let z = (c - 1.0 / k) / s;
        eprintln!(
            "joint {joint}: compliance {c:.4e} ± {s:.1e}, truth {:.4e} (z = {z:.2})",
            1.0 / k
        );
        assert!(
            c > 0.0,
            "seed {seed}: joint {joint}'s named compliance {c:.4e} is not positive"
        );
    }
    cleanup(&d);
}

#[test]
fn a_backlash_of_five_milliradians_is_reported_as_implausible_not_adopted() {
    let seed = seed();
    eprintln!("diagnose_plausibility: seed {seed} (ROBOCAL_TEST_SEED={seed} repeats this run)");
    let mut rng = StdRng::seed_from_u64(seed ^ 0xbac1);
    // One of joints 1-4, a full lost motion of 10 mrad (half 5 mrad), signed by the approach
    // direction.
    let joint = rng.random_range(1..=4usize);
    let mut band = [0.0; 7];
    band[joint - 1] = 1e-2;
    let d = dir("backlash");
    let measurements = generate(
        &format!("[effects.backlash]\ndead_band_rad = {band:?}\nmode = \"direction\"\n"),
        rng.random_range(1..u32::MAX as u64),
        &d,
    );
    let diag: Value = serde_json::from_str(&robocal(&[
        "diagnose",
        "--robot",
        "iiwa7",
        "--data",
        measurements.to_str().unwrap(),
        "--json",
    ]))
    .unwrap();
    let findings = diag["findings"].as_array().unwrap();
    assert!(
        findings.iter().all(|f| f["cause"] != "gear_backlash"),
        "seed {seed}: a 5 mrad backlash at joint {joint} was adopted: {findings:#?}"
    );
    let rejected = diag["unexplained"]["rejected"].as_array().unwrap();
    let r = rejected
        .iter()
        .find(|r| r["cause"] == "gear_backlash")
        .unwrap_or_else(|| panic!("seed {seed}: backlash not reported as implausible: {diag:#}"));
    assert!(
        r["reason"].as_str().unwrap().contains("2 mrad")
            && r["joints"].as_array().unwrap().contains(&joint.into()),
        "seed {seed}: {r:#}"
    );
    cleanup(&d);
}
