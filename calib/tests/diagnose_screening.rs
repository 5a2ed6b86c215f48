//! Screening on a subsample (`DiagnoseOptions::screen_poses`): on a table larger than the subsample,
//! diagnose names the same causes at the same joints as when every candidate is fitted on every pose,
//! and every figure it reports of the adopted models (steps, gains, paired and training `z`) is that
//! of the fits on every pose, not of the subsample.

mod common;

use calib::select::diagnose::{DiagnoseOptions, diagnose};

/// 600 poses of the iiwa 7 with geometric errors, compliance at joints 2 and 4 and backlash at
/// joints 1 and 3 (the diagnose benchmark's data, twice the poses).
fn data() -> (sim::Model, sim::measurement_table::MeasurementTable) {
    common::simulate_iiwa7(common::COMPLIANCE_AND_BACKLASH, 11, 600)
}

#[test]
fn a_subsample_names_the_same_causes_and_reports_the_fits_on_every_pose() {
    let (model, table) = data();
    let every = diagnose(
        &model,
        &table,
        "every pose",
        &DiagnoseOptions {
            screen_poses: 0,
            ..DiagnoseOptions::default()
        },
    )
    .unwrap();
    let screened = diagnose(
        &model,
        &table,
        "screened",
        &DiagnoseOptions {
            screen_poses: 300,
            ..DiagnoseOptions::default()
        },
    )
    .unwrap();
    assert!(every.screening.is_none());
    let s = screened
        .screening
        .as_ref()
        .expect("screened on a subsample");
    assert_eq!(s.n_train + s.n_test, 300);
    // The full split's pose counts, not the subsample's.
    assert_eq!(
        (screened.n_train, screened.n_test),
        (every.n_train, every.n_test)
    );
    let named = |d: &calib::select::diagnose::Diagnosis| -> Vec<(String, Vec<usize>)> {
        d.findings
            .iter()
            .map(|f| (f.cause.name().to_string(), f.joints.clone()))
            .collect()
    };
    assert_eq!(
        named(&every),
        vec![
            ("joint_compliance".to_string(), vec![2, 4]),
            ("gear_backlash".to_string(), vec![1, 3])
        ]
    );
    assert_eq!(named(&screened), named(&every));
    assert_eq!(screened.model, every.model);
    // The same models fitted on the same poses from other starts: the same minima, to the solver's
    // convergence tolerance (χ² decrease below 1e-10 of χ²).
    let close = |a: f64, b: f64, what: &str| {
        assert!(
            (a - b).abs() <= 1e-6 * a.abs().max(b.abs()),
            "{what}: {a} (every pose) against {b} (screened)"
        )
    };
    assert_eq!(screened.steps.len(), every.steps.len());
    for (a, b) in every.steps.iter().zip(&screened.steps) {
        assert_eq!(a.model, b.model);
        close(a.train_rms_m, b.train_rms_m, "training RMS");
        close(a.test_rms_m, b.test_rms_m, "test RMS");
    }
    for (a, b) in every.findings.iter().zip(&screened.findings) {
        close(a.gain, b.gain, "gain");
        close(a.test_z, b.test_z, "paired z");
        close(a.train_z, b.train_z, "training z");
        close(a.r, b.r, "correlation");
    }
}
