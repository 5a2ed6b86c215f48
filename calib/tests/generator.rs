//! Calibration on the generator's output (`sim::generate`, the project's source of truth): the kinematic
//! scenario, noise-free and with its laser-tracker noise.

use calib::fit::{CalibrationOptions, Dataset, FitRequest, Part, fit, prediction_and_jacobian};
use calib::model::stats::split_by_pose;
use nalgebra::Vector3;
use sim::scenario::{Overrides, Scenario};
use std::path::Path;

fn generated(
    noise: f64,
    seed: u64,
) -> (
    sim::Model,
    sim::measurement_table::MeasurementTable,
    Vec<[f64; 3]>,
) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/iiwa7_kinematic.toml");
    let res = Scenario::load(&path)
        .unwrap()
        .resolve(&Overrides {
            seed: Some(seed),
            poses: Some(200),
            noise: Some(noise),
        })
        .unwrap();
    let plan = sim::generate::plan_of(&res).unwrap();
    let truth = sim::effects::Truth::new(&res.model, &res.effects).unwrap();
    let out =
        sim::generate::simulate(&truth, &res.tracker, &res.gravity, &plan, res.seed, None).unwrap();
    let table = sim::generate::measurement_table(&plan, &out, &res.tracker);
    let p_true = out.rows.iter().map(|r| r.reading.p_true).collect();
    (res.model, table, p_true)
}

#[test]
fn noise_free_generated_kinematic_errors_are_recovered_to_1e9_m() {
    let (model, table, p_true) = generated(0.0, 11);
    let (train, test) = split_by_pose(&table, 0.3, 1);
    let cal = fit(
        &model,
        &Dataset::new(&table, train, "train", Part::All),
        &FitRequest::kinematic(&CalibrationOptions::default()),
    )
    .unwrap();
    assert!(cal.report.was_successful());
    assert!(cal.report.health.is_clean(), "{}", cal.report.health);
    let mut worst = 0.0f64;
    for &r in &test {
        let (p, _, _) = prediction_and_jacobian(&model, &cal.params, table.q_row(r)).unwrap();
        worst = worst.max((p - Vector3::from(p_true[r])).norm());
    }
    eprintln!(
        "generator, noise-free: worst held-out error {worst:e} m over {} poses",
        test.len()
    );
    assert!(worst < 1e-9, "{worst:e}");
}

#[test]
fn noisy_generated_data_held_out_error_matches_the_covariance() {
    let (mut err2, mut pred2, mut n) = (0.0, 0.0, 0);
    for seed in 21..26 {
        let (model, table, p_true) = generated(1.0, seed);
        let (train, test) = split_by_pose(&table, 0.3, seed);
        let cal = fit(
            &model,
            &Dataset::new(&table, train, "train", Part::All),
            &FitRequest::kinematic(&CalibrationOptions::default()),
        )
        .unwrap();
        assert!(cal.report.was_successful());
        assert!(cal.report.health.is_clean(), "{}", cal.report.health);
        for &r in &test {
            let (p, _, j) = prediction_and_jacobian(&model, &cal.params, table.q_row(r)).unwrap();
            err2 += (p - Vector3::from(p_true[r])).norm_squared();
            pred2 += (&j * &cal.covariance * j.transpose()).trace();
            n += 1;
        }
    }
    let ratio = (err2 / pred2).sqrt();
    eprintln!(
        "generator, tracker noise: held-out RMS error {:.2} µm, {ratio:.3} × the covariance's prediction ({n} poses)",
        (err2 / n as f64).sqrt() * 1e6
    );
    // The tracker's noise is anisotropic (radial vs transverse) while the sigma column gives one σ per
    // row, so the covariance is approximate: within 25 %.
    assert!((0.75..=1.25).contains(&ratio), "{ratio}");
}
