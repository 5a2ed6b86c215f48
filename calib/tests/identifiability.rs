//! Degenerate and too-small pose sets, outliers, and identifiable-parameter counts against the closed
//! form 4R + 2P + 3 (positions) / + 6 (poses) of Everett and Hollerbach for a serial chain with unknown base
//! and target.

mod common;

use calib::CalibError;
use calib::fit::{CalibrationOptions, Dataset, FitRequest, RobustLoss, fit};
use common::{Truth, random_configs, rng, table};
use sim::measurement_table::MeasurementTable;
use sim::robots;

/// The kinematic calibration of every row of `t` with the default options.
fn fit_kinematic(model: &sim::Model, t: &MeasurementTable) -> calib::fit::Calibration {
    fit(
        model,
        &Dataset::all(t, "t"),
        &FitRequest::kinematic(&CalibrationOptions::default()),
    )
    .unwrap()
}

#[test]
fn identifiable_count_matches_the_closed_form() {
    for (name, orientation) in [
        ("iiwa7", false),
        ("ur5", false),
        ("wam", true),
        ("ur10", true),
    ] {
        let model = robots::load_builtin(name).unwrap();
        let mut g = rng(301);
        let truth = Truth::random(&model, orientation, &mut g);
        let t = table(
            &model,
            &truth,
            &random_configs(&model, 50, &mut g),
            0.0,
            0.0,
            &mut g,
        );
        let cal = fit_kinematic(&model, &t);
        let revolute = model
            .joints()
            .iter()
            .filter(|j| j.kind.is_rotational())
            .count();
        let prismatic = model.nq() - revolute;
        let expected = 4 * revolute + 2 * prismatic + if orientation { 6 } else { 3 };
        assert_eq!(cal.report.observability.rank, expected, "{name}");
        assert!(
            cal.report.unidentifiable.data_specific.is_empty(),
            "{name}: {:?}",
            cal.report.unidentifiable.data_specific
        );
        // Every null direction is named by a structural pattern.
        assert!(
            cal.report
                .unidentifiable
                .directions
                .iter()
                .all(|d| d.kind.is_structural())
        );
    }
}

#[test]
fn joint_1_that_never_moves_is_named_and_the_rest_is_still_recovered() {
    let model = robots::load_builtin("iiwa7").unwrap();
    let mut g = rng(302);
    let truth = Truth::random(&model, false, &mut g);
    let mut configs = random_configs(&model, 60, &mut g);
    for q in &mut configs {
        q[0] = 0.3;
    }
    let t = table(&model, &truth, &configs, 0.0, 0.0, &mut g);
    let cal = fit_kinematic(&model, &t);
    assert!(cal.report.was_successful());
    assert!(cal.report.health.is_clean(), "{}", cal.report.health);
    let text = cal.report.text();
    eprintln!("{text}");
    let specific = &cal.report.unidentifiable.data_specific;
    assert_eq!(specific.len(), 1, "{specific:?}");
    assert!(
        specific[0].contains("joint 1") && specific[0].contains("does not move"),
        "{}",
        specific[0]
    );
    // A joint that never moves is a fixed transform: the 4 parameters of its axis line merge into the
    // tracker-to-base transform.
    assert_eq!(cal.report.observability.rank, 31 - 4);
    assert!(
        cal.report
            .warnings
            .iter()
            .any(|w| w.contains("joint 1") && w.contains("does not move"))
    );
    // Poses of the same kind (q1 = 0.3) are still predicted exactly.
    let chain = calib::model::chain::Chain::new(&model, &cal.params);
    let mut s = calib::model::chain::ChainScratch::new(7);
    for mut q in random_configs(&model, 30, &mut g) {
        q[0] = 0.3;
        chain.forward(&mut s, &q);
        let (p, _) = truth.target(&model, &q);
        assert!((s.p_tracker - p).norm() < 1e-9);
    }
}

#[test]
fn too_few_poses_is_an_error_naming_the_count_needed() {
    let model = robots::load_builtin("iiwa7").unwrap();
    let mut g = rng(303);
    let truth = Truth::random(&model, false, &mut g);
    let t = table(
        &model,
        &truth,
        &random_configs(&model, 8, &mut g),
        1e-5,
        0.0,
        &mut g,
    );
    let err = fit(
        &model,
        &Dataset::all(&t, "few.csv"),
        &FitRequest::kinematic(&CalibrationOptions::default()),
    )
    .unwrap_err();
    let msg = err.to_string();
    eprintln!("{msg}");
    // 31 identifiable combinations (4·7 + 3) need 32 equations: 11 poses of 3.
    match err {
        CalibError::TooFewPoses {
            poses,
            identifiable,
            needed,
            ..
        } => {
            assert_eq!((poses, identifiable, needed), (8, 31, 11));
        }
        other => panic!("wrong error {other:?}"),
    }
    assert!(
        msg.contains("few.csv")
            && msg.contains("at least 11 distinct poses")
            && msg.contains("31 identifiable")
    );
    // Repeated measurements of the same poses do not help.
    let mut rep = t.clone();
    for r in 0..t.len() {
        rep.push_row(&t.row(r)).unwrap();
    }
    assert!(matches!(
        fit(
            &model,
            &Dataset::all(&rep, "rep"),
            &FitRequest::kinematic(&CalibrationOptions::default())
        ),
        Err(CalibError::TooFewPoses { poses: 8, .. })
    ));
    // Nor do new pose ids at the same joint values: 40 ids at one configuration are one pose.
    let mut same = MeasurementTable::new(t.n_joints, t.columns());
    for k in 0..40 {
        let mut row = t.row(0);
        row.pose = 1000 + k;
        same.push_row(&row).unwrap();
    }
    let err = fit(
        &model,
        &Dataset::all(&same, "same.csv"),
        &FitRequest::kinematic(&CalibrationOptions::default()),
    )
    .unwrap_err();
    assert!(
        matches!(err, CalibError::TooFewPoses { poses: 1, .. }),
        "{err}"
    );
    assert!(
        err.to_string()
            .contains("1 distinct poses give 3 equations"),
        "{err}"
    );
    // Exactly enough is accepted.
    let t = table(
        &model,
        &truth,
        &random_configs(&model, 11, &mut g),
        1e-5,
        0.0,
        &mut g,
    );
    assert!(
        fit(
            &model,
            &Dataset::all(&t, "ok"),
            &FitRequest::kinematic(&CalibrationOptions::default())
        )
        .is_ok()
    );
}

#[test]
fn gross_errors_are_reported_as_outliers_and_a_robust_loss_ignores_them() {
    let model = robots::load_builtin("iiwa7").unwrap();
    let mut g = rng(304);
    let truth = Truth::random(&model, false, &mut g);
    let mut t = common::table_with(
        &model,
        &truth,
        &random_configs(&model, 120, &mut g),
        1e-5,
        0.0,
        Some(1e-5),
        &mut g,
    );
    let bad = [7usize, 50, 99];
    for &r in &bad {
        t.position[r][1] += 1e-3; // 1 mm = 100 σ
    }
    let test_q = random_configs(&model, 50, &mut g);
    let held_out = |params: &calib::model::params::KinematicParams| {
        let chain = calib::model::chain::Chain::new(&model, params);
        let mut s = calib::model::chain::ChainScratch::new(7);
        let e2: f64 = test_q
            .iter()
            .map(|q| {
                chain.forward(&mut s, q);
                (s.p_tracker - truth.target(&model, q).0).norm_squared()
            })
            .sum();
        (e2 / test_q.len() as f64).sqrt()
    };
    // Plain least squares: every row kept (the default excludes gross errors, see the next test).
    let keep_all = CalibrationOptions {
        gross_error_threshold: f64::INFINITY,
        ..Default::default()
    };
    let plain = fit(
        &model,
        &Dataset::all(&t, "t"),
        &FitRequest::kinematic(&keep_all),
    )
    .unwrap();
    assert!(plain.report.excluded.is_empty());
    let rows: Vec<usize> = plain.report.outliers.iter().map(|o| o.row - 1).collect();
    let mut sorted = rows.clone();
    sorted.sort();
    assert_eq!(sorted, bad.to_vec(), "{:?}", plain.report.outliers);
    let options = CalibrationOptions {
        robust: Some(RobustLoss::HUBER),
        ..Default::default()
    };
    let robust = fit(
        &model,
        &Dataset::all(&t, "t"),
        &FitRequest::kinematic(&options),
    )
    .unwrap();
    assert!(robust.report.was_successful());
    assert!(robust.report.health.is_clean(), "{}", robust.report.health);
    assert_eq!(robust.report.robust.as_ref().unwrap().downweighted_rows, 3);
    let (e_plain, e_robust) = (held_out(&plain.params), held_out(&robust.params));
    eprintln!("held-out RMS: plain {e_plain:e} m, robust {e_robust:e} m");
    // Three 1 mm errors among 360 equations pull the plain fit by tens of µm; the robust one stays
    // near the noise-limited 5 µm of the clean data.
    assert!(
        e_robust < 0.5 * e_plain && e_robust < 1e-5,
        "plain {e_plain:e}, robust {e_robust:e}"
    );
}

/// By default a gross error (far beyond any model error: 1 mm = 100 σ here) is excluded from the fit,
/// named by row in the report and a warning, and the fit is as good as without it; a moderate error
/// (5 σ to 25 σ of the robust scale) is only reported.
#[test]
fn gross_errors_are_excluded_by_default_and_named() {
    let model = robots::load_builtin("iiwa7").unwrap();
    let mut g = rng(305);
    let truth = Truth::random(&model, false, &mut g);
    let mut t = common::table_with(
        &model,
        &truth,
        &random_configs(&model, 120, &mut g),
        1e-5,
        0.0,
        Some(1e-5),
        &mut g,
    );
    let gross = [12usize, 80];
    for &r in &gross {
        t.position[r][0] -= 1e-3; // 1 mm = 100 σ
    }
    let moderate = 33usize;
    t.position[moderate][2] += 1.2e-4; // 12 σ
    let test_q = random_configs(&model, 50, &mut g);
    let held_out = |params: &calib::model::params::KinematicParams| {
        let chain = calib::model::chain::Chain::new(&model, params);
        let mut s = calib::model::chain::ChainScratch::new(7);
        let e2: f64 = test_q
            .iter()
            .map(|q| {
                chain.forward(&mut s, q);
                (s.p_tracker - truth.target(&model, q).0).norm_squared()
            })
            .sum();
        (e2 / test_q.len() as f64).sqrt()
    };
    let cal = fit_kinematic(&model, &t);
    assert!(cal.report.was_successful());
    assert!(cal.report.health.is_clean(), "{}", cal.report.health);
    let mut excluded: Vec<usize> = cal.report.excluded.iter().map(|o| o.row - 1).collect();
    excluded.sort();
    assert_eq!(excluded, gross.to_vec(), "{:?}", cal.report.excluded);
    for o in &cal.report.excluded {
        assert!(
            o.normalised_residual > 25.0 && (0.9e-3..1.1e-3).contains(&o.error_m),
            "{o:?}"
        );
        assert!(
            cal.report
                .warnings
                .iter()
                .any(|w| w.starts_with(&format!("row {} (pose {}) excluded", o.row, o.pose))),
            "{:?}",
            cal.report.warnings
        );
    }
    let reported: Vec<usize> = cal.report.outliers.iter().map(|o| o.row - 1).collect();
    assert_eq!(reported, vec![moderate], "{:?}", cal.report.outliers);
    // Degrees of freedom count the rows kept: 118 rows × 3 minus the identifiable combinations.
    assert_eq!(cal.report.dof, 118 * 3 - cal.subspace.rank);
    assert!(
        (0.6..1.5).contains(&cal.report.chi2_per_dof),
        "{}",
        cal.report.chi2_per_dof
    );
    let e = held_out(&cal.params);
    assert!(e < 1e-5, "held-out RMS {e:e} m");
}

/// A coupled joint (the torso's passive `torso_pitch_3 = −(torso_pitch_1 + torso_pitch_2)`) never
/// moves on its own: two combinations of error parameters that the closed form 4R + 3 counts as
/// identifiable (35 for 8 revolute joints) are not, whatever the poses. The report names them as
/// the coupling's (structural), not as this pose set's failing; the same poses with the passive
/// joint moved on its own determine all 35.
#[test]
fn a_coupling_is_named_for_what_it_makes_inseparable() {
    let spec = sim::ChainSpec {
        base_link: None,
        tip_link: Some("left_flange".into()),
    };
    let urdf = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../sim/tests/data/coupled_torso.urdf");
    let model = sim::urdf::load_file(&urdf, &spec).unwrap();
    let mut g = rng(303);
    let truth = Truth::random(&model, false, &mut g);
    let mut configs = random_configs(&model, 80, &mut g);
    for q in &mut configs {
        model.couplings().apply(q);
    }
    let t = table(&model, &truth, &configs, 0.0, 0.0, &mut g);
    let cal = fit_kinematic(&model, &t);
    let null = &cal.report.unidentifiable;
    assert_eq!(cal.report.observability.rank, 33);
    assert!(null.data_specific.is_empty(), "{:?}", null.data_specific);
    let coupling = null
        .directions
        .iter()
        .filter(|d| {
            matches!(
                d.kind,
                calib::fit::identifiability::NullKind::Coupling { joint: 4 }
            )
        })
        .count();
    assert_eq!(coupling, 2, "{:#?}", null.summary);
    assert!(
        null.summary
            .iter()
            .any(|s| s.contains("the coupling of joint 4 to joints 2 and 3")),
        "{:?}",
        null.summary
    );
    // The same poses with the passive joint moving on its own: every combination determined.
    let mut free = model.to_parts();
    free.couplings.clear();
    let free = sim::Model::new(free).unwrap();
    let mut moved = configs.clone();
    for (k, q) in moved.iter_mut().enumerate() {
        q[3] += 0.3 * ((k as f64 * 0.618).fract() * 2.0 - 1.0);
    }
    let t = table(&free, &truth, &moved, 0.0, 0.0, &mut g);
    let cal = fit_kinematic(&free, &t);
    assert_eq!(cal.report.observability.rank, 35);
}
