//! The model extensions: their Jacobian columns against central differences, their recovery from data
//! the simulator made with its own effect code (within the predicted standard deviations), and the
//! model file carrying them to `predict`.

use calib::fit::problem::KinematicProblem;
use calib::fit::{CalibrationOptions, Dataset, FitRequest, fit, observations};
use calib::lm::LeastSquaresProblem;
use calib::model::extensions::ExtensionSettings;
use calib::model::file::CalibratedModel;
use calib::model::params::KinematicParams;
use calib::model::predict::Predictor;
use calib::model::robot::Robot;
use calib::model::spec::ModelSpec;
use calib::model::stats::position_errors;
use nalgebra::{DMatrix, Vector3};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use sim::measurement_table::{self, MeasurementTable, OptionalColumns, Row};
use sim::robots;
use sim::scenario::{Overrides, Scenario};

/// A table of random configurations with every optional column the extensions read; positions are
/// arbitrary (the Jacobian does not depend on them).
fn table_with_columns(model: &sim::Model, n: usize, seed: u64) -> MeasurementTable {
    let mut g = StdRng::seed_from_u64(seed);
    let cols = OptionalColumns {
        t: true,
        temp: true,
        dir: true,
        payload: true,
        ..OptionalColumns::NONE
    };
    let mut t = MeasurementTable::new(model.nq(), cols);
    for k in 0..n {
        let q: Vec<f64> = model
            .joints()
            .iter()
            .map(|j| {
                let l = j.limits.unwrap();
                g.random_range(l.lower * 0.9..l.upper * 0.9)
            })
            .collect();
        let dir: Vec<i8> = (0..model.nq())
            .map(|_| if g.random::<bool>() { 1 } else { -1 })
            .collect();
        t.push_row(&Row {
            pose: k as i64,
            q: &q,
            position: [
                2.0 + g.random::<f64>(),
                g.random::<f64>(),
                g.random::<f64>(),
            ],
            t: Some(15.0 * k as f64),
            temp: Some(20.0 + g.random_range(0.0..10.0)),
            dir: Some(&dir),
            payload: Some([0.0, 2.0, 5.0][k % 3]),
            ..Row::default()
        })
        .unwrap();
    }
    t
}

#[test]
fn extension_columns_match_central_differences() {
    let model = robots::load_builtin("iiwa7").unwrap();
    let t = table_with_columns(&model, 15, 3);
    let rows: Vec<usize> = (0..t.len()).collect();
    let spec = ModelSpec::parse("kinematic+joint_compliance+gear_backlash+thermal_drift").unwrap();
    let settings =
        ExtensionSettings::for_data(&model, &spec.causes, &spec.joints, &t, &rows, "t").unwrap();
    let data = Dataset::all(&t, "t");
    let n_ext = settings.params(&model).len();
    // Torques at a non-trivial equilibrium, and a linearisation point with every extension non-zero.
    let at: Vec<f64> = (0..n_ext).map(|e| 1e-4 * (1.0 + 0.1 * e as f64)).collect();
    let obs = observations(
        &model,
        &data,
        &CalibrationOptions::default(),
        Some(&settings),
        Some(&KinematicParams::nominal(model.nq(), false).with_extension(at.clone())),
    )
    .unwrap();
    let mut params = KinematicParams::nominal(model.nq(), false).with_extension(at.clone());
    params.p_flange_target = Vector3::new(0.01, 0.02, 0.08);
    params.t_tracker_base =
        sim::lie::exp_twist(&nalgebra::Vector6::new(0.1, 0.2, -0.3, 1.5, 0.5, 0.1));
    let np = calib::model::params::ParamLayout::new(&model, false)
        .with_extensions(obs.ext.params.clone())
        .len();
    let all: Vec<usize> = (0..np).collect();
    let mut prob = KinematicProblem::new(&model, &obs, params, all);
    let m = prob.n_residuals();
    let mut j = DMatrix::zeros(m, np);
    prob.set_params(&vec![0.0; np]);
    prob.jacobian(&mut j);
    let (mut rp, mut rm) = (vec![0.0; m], vec![0.0; m]);
    let kin = np - n_ext;
    // Rounding of residuals of size ‖p‖/σ limits the central differences to about ε‖p‖/(σ h).
    prob.set_params(&vec![0.0; np]);
    prob.residuals(&mut rp);
    let scale = rp.iter().fold(0.0f64, |a, v| a.max(v.abs())) + 2.0e5;
    for k in kin..np {
        let h = 1e-6;
        let mut step = vec![0.0; np];
        step[k] = h;
        prob.set_params(&step);
        prob.residuals(&mut rp);
        step[k] = -h;
        prob.set_params(&step);
        prob.residuals(&mut rm);
        for r in 0..m {
            let fd = (rp[r] - rm[r]) / (2.0 * h);
            assert!(
                (fd - j[(r, k)]).abs() <= 1e-6 * (1.0 + fd.abs()) + 8.0 * f64::EPSILON * scale / h,
                "{}: row {r}: analytic {} vs central difference {fd}",
                obs.ext.params[k - kin].name(),
                j[(r, k)]
            );
        }
    }
}

/// A campaign simulated with `effects` (TOML) on top of drawn geometric errors, 300 poses.
fn simulate(effects: &str, seed: u64, dir: &std::path::Path) -> MeasurementTable {
    simulate_poses(effects, seed, 300, dir)
}

#[test]
fn extensions_are_recovered_within_their_predicted_standard_deviations() {
    let model = robots::load_builtin("iiwa7").unwrap();
    let mut z2 = Vec::new();
    for seed in [1u64, 2, 3] {
        let mut g = StdRng::seed_from_u64(seed ^ 0xe47);
        let k: Vec<f64> = (0..3).map(|_| g.random_range(5e3..2e4)).collect();
        let b: Vec<f64> = (0..2).map(|_| g.random_range(2e-4..6e-4)).collect();
        let delta = g.random_range(5.0..15.0);
        let effects = format!(
            "[effects.compliance]\nstiffness_nm_per_rad = [inf, {:e}, {:e}, {:e}, inf, inf, inf]\n\
             [effects.backlash]\ndead_band_rad = [{:e}, 0.0, 0.0, 0.0, {:e}, 0.0, 0.0]\nmode = \"direction\"\n\
             [effects.thermal]\nt_ref_c = 20.0\nalpha_per_k = 23e-6\nbeta_rad_per_k = 0.0\n\
             [campaign.temperature]\nwarm_up = {{ t0_c = 20.0, delta_c = {delta}, tau_s = 1800.0 }}\n",
            k[0], k[1], k[2], b[0], b[1]
        );
        let dir = std::env::temp_dir().join(format!("robocal_ext_{}_{seed}", std::process::id()));
        let t = simulate(&effects, seed, &dir);
        let spec =
            ModelSpec::parse("kinematic+joint_compliance+gear_backlash+thermal_drift").unwrap();
        let cal = fit(
            &model,
            &Dataset::all(&t, "sim"),
            &FitRequest::new(&spec, &CalibrationOptions::default()),
        )
        .unwrap();
        assert!(
            cal.report.health.is_clean(),
            "seed {seed}: {}",
            cal.report.health
        );
        // The truth in the estimator's parameters: compliance 1/k, half the dead band, α, no drift.
        let truth = |name: &str| -> f64 {
            match name {
                "joint 2 compliance" => 1.0 / k[0],
                "joint 3 compliance" => 1.0 / k[1],
                "joint 4 compliance" => 1.0 / k[2],
                "joint 1 half lost motion" => b[0] / 2.0,
                "joint 5 half lost motion" => b[1] / 2.0,
                "link growth" => 23e-6,
                _ => 0.0,
            }
        };
        let sub = &cal.subspace;
        for (e, p) in cal.layout.extensions.iter().enumerate() {
            let kk = cal.layout.extension(e);
            let null_share = sub
                .v
                .row(kk)
                .columns(sub.rank, sub.n_params() - sub.rank)
                .norm();
            if null_share > 0.1 {
                continue; // joint 1 compliance (no torque), joint 7 backlash (no lever)…
            }
            let sigma = cal.covariance[(kk, kk)].sqrt();
            let z = (cal.params.extension[e] - truth(&p.name())) / sigma;
            assert!(
                z.abs() < 4.0,
                "seed {seed}: {} = {:.4e} ± {sigma:.1e}, truth {:.4e} (z = {z:.2})",
                p.name(),
                cal.params.extension[e],
                truth(&p.name())
            );
            z2.push(z * z);
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
    let mean = z2.iter().sum::<f64>() / z2.len() as f64;
    // For n standard normal z the mean of z² has standard deviation √(2/n) ≈ 0.19 here.
    assert!(
        (0.4..1.8).contains(&mean),
        "mean z² = {mean:.2} over {} parameters: the standard deviations do not describe the errors",
        z2.len()
    );
}

#[test]
fn the_model_file_carries_extensions_and_learned_correction_to_predict() {
    let model = robots::load_builtin("iiwa7").unwrap();
    let dir = std::env::temp_dir().join(format!("robocal_ext_file_{}", std::process::id()));
    let t = simulate(
        "[effects.compliance]\nstiffness_nm_per_rad = [inf, 1.2e4, inf, 9e3, inf, inf, inf]\n\
         [effects.backlash]\ndead_band_rad = [0.0, 0.0, 4e-4, 0.0, 0.0, 0.0, 0.0]\nmode = \"direction\"\n",
        5,
        &dir,
    );
    let spec = ModelSpec::parse("kinematic+joint_compliance+gear_backlash+learned:poly1").unwrap();
    let data = Dataset::all(&t, "sim");
    let options = CalibrationOptions::default();
    let cal = fit(&model, &data, &FitRequest::new(&spec, &options)).unwrap();
    assert_eq!(cal.report.model, spec);
    let robot = Robot::load("iiwa7", &sim::ChainSpec::default()).unwrap();
    let text = CalibratedModel::new(&robot, &cal).to_json();
    let file = CalibratedModel::from_json(&text, "model.json").unwrap();
    assert_eq!(
        file.model.name(),
        "kinematic+joint_compliance+gear_backlash+learned:poly1"
    );
    let mut pred = Predictor::from_file(&file).unwrap();
    let out = pred.predict_table(&t, "sim").unwrap();
    // The predictor must reproduce the fit: measured + error of the physical model + the correction.
    let obs = observations(
        &model,
        &data,
        &options,
        cal.extensions.as_ref(),
        Some(&cal.params),
    )
    .unwrap();
    let err = position_errors(&model, &cal.params, &obs);
    let learned = cal.learned.as_ref().unwrap();
    for (r, e) in err.iter().enumerate() {
        let expect = obs.position[r] + e + learned.predict(t.q_row(r));
        let got = Vector3::from(out.position[r]);
        assert!((got - expect).norm() < 1e-12, "row {r}: {got} vs {expect}");
    }
    // Without the columns the model reads, predict refuses with the column's name.
    let mut no_dir = t.clone();
    no_dir.dir = None;
    let e = pred
        .predict_table(&no_dir, "poses.csv")
        .unwrap_err()
        .to_string();
    assert!(e.contains("poses.csv") && e.contains("dir"), "{e}");
    // A model file whose name and extensions disagree is refused.
    let bad = text.replace(
        "\"model\": \"kinematic+joint_compliance+gear_backlash+learned:poly1\"",
        "\"model\": \"kinematic+learned:poly1\"",
    );
    let e = CalibratedModel::from_json(&bad, "m.json")
        .unwrap_err()
        .to_string();
    assert!(e.contains("m.json") && e.contains("extensions"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A cause limited to some joints (`joint_compliance@2,4`): only their parameters are in the fit
/// (the others absent, not zero), they recover the truth within their standard deviations, and the
/// model file carries the limit to `predict`, which rebuilds the same regressors. A file written
/// before the limits existed (no `joints` key) loads as the cause at every joint.
#[test]
fn a_cause_at_some_of_its_joints_fits_only_those_and_round_trips() {
    let model = robots::load_builtin("iiwa7").unwrap();
    let dir = std::env::temp_dir().join(format!("robocal_ext_subset_{}", std::process::id()));
    let (k2, k4) = (1.2e4, 9e3);
    let t = simulate(
        &format!(
            "[effects.compliance]\nstiffness_nm_per_rad = [inf, {k2:e}, inf, {k4:e}, inf, inf, inf]\n"
        ),
        11,
        &dir,
    );
    let spec = ModelSpec::parse("joint_compliance@4,2").unwrap();
    assert_eq!(spec.name(), "kinematic+joint_compliance@2,4");
    let data = Dataset::all(&t, "sim");
    let options = CalibrationOptions::default();
    let cal = fit(&model, &data, &FitRequest::new(&spec, &options)).unwrap();
    let names: Vec<String> = cal.layout.extensions.iter().map(|p| p.name()).collect();
    assert_eq!(names, ["joint 2 compliance", "joint 4 compliance"]);
    for (e, truth) in [(0, 1.0 / k2), (1, 1.0 / k4)] {
        let kk = cal.layout.extension(e);
        let sigma = cal.covariance[(kk, kk)].sqrt();
        let z = (cal.params.extension[e] - truth) / sigma;
        assert!(z.abs() < 4.0, "{}: z = {z:.2}", names[e]);
    }
    let robot = Robot::load("iiwa7", &sim::ChainSpec::default()).unwrap();
    let text = CalibratedModel::new(&robot, &cal).to_json();
    let file = CalibratedModel::from_json(&text, "model.json").unwrap();
    assert_eq!(file.model, spec);
    assert_eq!(file.to_json(), text, "serialisation is not stable");
    let mut pred = Predictor::from_file(&file).unwrap();
    let out = pred.predict_table(&t, "sim").unwrap();
    let obs = observations(
        &model,
        &data,
        &options,
        cal.extensions.as_ref(),
        Some(&cal.params),
    )
    .unwrap();
    let err = position_errors(&model, &cal.params, &obs);
    for (r, e) in err.iter().enumerate() {
        let expect = obs.position[r] + e;
        let got = Vector3::from(out.position[r]);
        assert!((got - expect).norm() < 1e-12, "row {r}: {got} vs {expect}");
    }
    // The name and the stored joints must agree.
    let bad = text.replace(
        "\"model\": \"kinematic+joint_compliance@2,4\"",
        "\"model\": \"kinematic+joint_compliance@2\"",
    );
    let e = CalibratedModel::from_json(&bad, "m.json")
        .unwrap_err()
        .to_string();
    assert!(e.contains("m.json") && e.contains("joints"), "{e}");
    // An older file, without the limit: the cause at every joint (the values no longer match the
    // parameters, which the predictor refuses, but the settings load as all joints).
    let full = ModelSpec::parse("joint_compliance").unwrap();
    let cal_full = fit(&model, &data, &FitRequest::new(&full, &options)).unwrap();
    let text_full = CalibratedModel::new(&robot, &cal_full).to_json();
    assert!(
        !text_full.contains("\"joints\""),
        "no joints key without limits"
    );
    let old = CalibratedModel::from_json(&text_full, "old.json").unwrap();
    assert!(old.model.joints.is_empty());
    assert_eq!(
        old.extensions
            .as_ref()
            .unwrap()
            .settings
            .params(&model)
            .len(),
        model.nq()
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn thermal_drift_from_time_stamps_alone_finds_the_warm_up() {
    // A 12 K warm-up with τ = 30 min, but the table keeps only the time stamps: the estimator must
    // pick the time constant from its candidates and explain the growth as well as with temperatures.
    let model = robots::load_builtin("iiwa7").unwrap();
    let dir = std::env::temp_dir().join(format!("robocal_ext_warm_{}", std::process::id()));
    let mut t = simulate(
        "[effects.thermal]\nt_ref_c = 20.0\nalpha_per_k = 23e-6\nbeta_rad_per_k = 0.0\n\
         [campaign.temperature]\nwarm_up = { t0_c = 20.0, delta_c = 12.0, tau_s = 1800.0 }\n",
        9,
        &dir,
    );
    let with_temp = fit(
        &model,
        &Dataset::all(&t, "sim"),
        &FitRequest::new(
            &ModelSpec::parse("kinematic+thermal_drift").unwrap(),
            &CalibrationOptions::default(),
        ),
    )
    .unwrap();
    t.temp = None;
    let cal = fit(
        &model,
        &Dataset::all(&t, "sim"),
        &FitRequest::new(
            &ModelSpec::parse("kinematic+thermal_drift").unwrap(),
            &CalibrationOptions::default(),
        ),
    )
    .unwrap();
    match cal.extensions.as_ref().unwrap().thermal {
        Some(calib::model::extensions::ThermalInput::WarmUp { tau_s, .. }) => {
            assert!((1200.0..=2700.0).contains(&tau_s), "τ = {tau_s} s")
        }
        other => panic!("expected a warm-up from time stamps, got {other:?}"),
    }
    let (a, b) = (
        with_temp.report.after.train.rms_m,
        cal.report.after.train.rms_m,
    );
    assert!(
        b < 1.05 * a,
        "time stamps only: {b:e} m vs with temperature {a:e} m"
    );
    // The growth per unit of warm-up is α ΔT = 23e-6 · 12 K.
    let e = cal
        .layout
        .extensions
        .iter()
        .position(|p| p.name() == "link growth")
        .unwrap();
    let growth = cal.params.extension[e];
    assert!(
        (growth / (23e-6 * 12.0) - 1.0).abs() < 0.1,
        "growth per warm-up {growth:e}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn compliance_is_recovered_from_the_physics_engine_truth() {
    // The truth is rapier3d's multibody settled under gravity and payload (sim's rapier truth), not the
    // spring balance the estimator solves: an independent physics, so agreement within the predicted σ
    // checks the estimator's statics, equilibrium and payload handling at once.
    let model = robots::load_builtin("iiwa7").unwrap();
    let dir = std::env::temp_dir().join(format!("robocal_ext_rapier_{}", std::process::id()));
    let k = [1.5e4, 1.0e4, 8.0e3];
    let t = simulate(
        &format!(
            "[effects.compliance]\nstiffness_nm_per_rad = [inf, {:e}, inf, {:e}, inf, {:e}, inf]\n\
             [campaign.payload]\nchoice_kg = [0.0, 3.0, 6.0]\ncom_m = [0.0, 0.01, 0.06]\n\
             [truth]\nmodel = \"rapier\"\n",
            k[0], k[1], k[2]
        ),
        4,
        &dir,
    );
    let cal = fit(
        &model,
        &Dataset::all(&t, "rapier"),
        &FitRequest::new(
            &ModelSpec::parse("kinematic+joint_compliance").unwrap(),
            &CalibrationOptions::default(),
        ),
    )
    .unwrap();
    assert!(cal.report.health.is_clean(), "{}", cal.report.health);
    let com = cal.extensions.as_ref().unwrap().payload_com_m;
    assert!(
        (com[1] - 0.01).abs() < 2e-3 && (com[2] - 0.06).abs() < 2e-3,
        "payload centre of mass {com:?} m"
    );
    for (joint, stiffness) in [(2usize, k[0]), (4, k[1]), (6, k[2])] {
        let name = format!("joint {joint} compliance");
        let e = cal
            .layout
            .extensions
            .iter()
            .position(|p| p.name() == name)
            .unwrap();
        let kk = cal.layout.extension(e);
        let sigma = cal.covariance[(kk, kk)].sqrt();
        let z = (cal.params.extension[e] - 1.0 / stiffness) / sigma;
        assert!(
            z.abs() < 4.0,
            "{name}: {:.5e} ± {sigma:.1e} rad/(N m), rapier truth {:.5e} (z = {z:.2})",
            cal.params.extension[e],
            1.0 / stiffness
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Recovers `spec` from a campaign the simulator made with `effects`; `truth(name)` is the value of
/// each named extension parameter (0 where the simulator put nothing). Every parameter determined on
/// its own must lie within 4 of its standard deviations of the truth; returns their z².
fn recovered_z2(effects: &str, spec: &str, seed: u64, truth: &dyn Fn(&str) -> f64) -> Vec<f64> {
    let model = robots::load_builtin("iiwa7").unwrap();
    let dir = std::env::temp_dir().join(format!("robocal_ext_new_{}_{seed}", std::process::id()));
    let t = simulate(effects, seed, &dir);
    let cal = fit(
        &model,
        &Dataset::all(&t, "sim"),
        &FitRequest::new(
            &ModelSpec::parse(spec).unwrap(),
            &CalibrationOptions::default(),
        ),
    )
    .unwrap();
    assert!(
        cal.report.health.is_clean(),
        "seed {seed}: {}",
        cal.report.health
    );
    let z2 = determined_z2(&cal, seed, &|p| truth(&p.name()));
    assert!(
        z2.len() >= 6,
        "seed {seed}: only {} parameters determined",
        z2.len()
    );
    let _ = std::fs::remove_dir_all(&dir);
    z2
}

/// The z² of every extension parameter of `cal` determined on its own (less than 0.1 of its unit
/// vector in the null space), against `truth`; each must lie within 4 of its standard deviations.
fn determined_z2(
    cal: &calib::fit::Calibration,
    seed: u64,
    truth: &dyn Fn(&calib::model::extensions::ExtensionParam) -> f64,
) -> Vec<f64> {
    let sub = &cal.subspace;
    let mut z2 = Vec::new();
    for (e, p) in cal.layout.extensions.iter().enumerate() {
        let kk = cal.layout.extension(e);
        let null_share = sub
            .v
            .row(kk)
            .columns(sub.rank, sub.n_params() - sub.rank)
            .norm();
        if null_share > 0.1 {
            continue;
        }
        let sigma = cal.covariance[(kk, kk)].sqrt();
        let want = truth(p);
        let z = (cal.params.extension[e] - want) / sigma;
        assert!(
            z.abs() < 4.0,
            "seed {seed}: {} = {:.4e} ± {sigma:.1e}, truth {want:.4e} (z = {z:.2})",
            p.name(),
            cal.params.extension[e],
        );
        z2.push(z * z);
    }
    z2
}

/// Transmission error (harmonics 1-3 of three joints' angles, drawn amplitudes and phases) and link
/// deflection with joint compliance and a payload (one equilibrium in the simulator) are recovered
/// within their predicted standard deviations. The simulator writes `A sin(k q + φ)`; the estimator's
/// sine and cosine amplitudes are `A cos φ` and `A sin φ`. Its deflection compliances `(c_u, c_v)`
/// are about x and about the joint frame's other axis (y for joints about z, z for joints about y).
#[test]
fn transmission_error_and_link_deflection_are_recovered_within_their_standard_deviations() {
    let mut z2 = Vec::new();
    for seed in [11u64, 12] {
        let mut g = StdRng::seed_from_u64(seed ^ 0x7e);
        // Transmission error on joints 1, 3 and 5 (turning ±170°), 30-150 µrad per harmonic.
        let amp: Vec<[f64; 3]> = (0..3)
            .map(|_| [0; 3].map(|_| g.random_range(3e-5..1.5e-4)))
            .collect();
        let phase: Vec<[f64; 3]> = (0..3)
            .map(|_| [0; 3].map(|_| g.random_range(-3.1..3.1)))
            .collect();
        let row = |v: Option<&[f64; 3]>| match v {
            Some(a) => format!("[{:e}, {:e}, {:e}]", a[0], a[1], a[2]),
            None => "[0.0, 0.0, 0.0]".into(),
        };
        let rows = |v: &[[f64; 3]]| {
            (1..=7)
                .map(|j| row([1, 3, 5].iter().position(|x| *x == j).map(|k| &v[k])))
                .collect::<Vec<_>>()
                .join(", ")
        };
        let effects = format!(
            "[effects.transmission]\nharmonics = [1, 2, 3]\namplitude_rad = [{}]\nphase_rad = [{}]\n",
            rows(&amp),
            rows(&phase)
        );
        let truth = |name: &str| -> f64 {
            for (k, j) in [1, 3, 5].iter().enumerate() {
                for h in 0..3 {
                    let (a, f) = (amp[k][h], phase[k][h]);
                    let q = if h == 0 {
                        "q".to_string()
                    } else {
                        format!("{}q", h + 1)
                    };
                    if name == format!("joint {j} transmission error sin {q}") {
                        return a * f.cos();
                    }
                    if name == format!("joint {j} transmission error cos {q}") {
                        return a * f.sin();
                    }
                }
            }
            0.0
        };
        z2.extend(recovered_z2(
            &effects,
            "kinematic+transmission_error",
            seed,
            &truth,
        ));

        // Deflection across joints 2, 3 and 4 (1-5e-6 rad/(N m) per axis), compliance at joints 2
        // and 4 (5e3-2e4 N m/rad), a payload of up to 6 kg. Joints 2 and 4 bend about x only: their
        // z axes are the axes of joints 3 and 5, where bending is those joints' compliance.
        let c: Vec<[f64; 2]> = (0..3)
            .map(|_| [0; 2].map(|_| g.random_range(1e-6..5e-6)))
            .collect();
        let k: Vec<f64> = (0..2).map(|_| g.random_range(5e3..2e4)).collect();
        let effects = format!(
            "[effects.deflection]\ncompliance_rad_per_nm = [[0.0, 0.0], [{:e}, 0.0], [{:e}, {:e}], \
             [{:e}, 0.0], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0]]\n\
             [effects.compliance]\nstiffness_nm_per_rad = [inf, {:e}, inf, {:e}, inf, inf, inf]\n\
             [campaign.payload]\nchoice_kg = [0.0, 3.0, 6.0]\ncom_m = [0.0, 0.0, 0.06]\n",
            c[0][0], c[1][0], c[1][1], c[2][0], k[0], k[1]
        );
        let truth = |name: &str| -> f64 {
            match name {
                "joint 2 bending compliance about x" => c[0][0],
                "joint 3 bending compliance about x" => c[1][0],
                "joint 3 bending compliance about y" => c[1][1],
                "joint 4 bending compliance about x" => c[2][0],
                "joint 2 compliance" => 1.0 / k[0],
                "joint 4 compliance" => 1.0 / k[1],
                _ => 0.0,
            }
        };
        z2.extend(recovered_z2(
            &effects,
            "kinematic+joint_compliance+link_deflection",
            seed,
            &truth,
        ));
    }
    let mean = z2.iter().sum::<f64>() / z2.len() as f64;
    eprintln!("mean z² = {mean:.2} over {} parameters", z2.len());
    // For n standard normal z the mean of z² has standard deviation √(2/n).
    assert!(
        (0.4..1.8).contains(&mean),
        "mean z² = {mean:.2} over {} parameters: the standard deviations do not describe the errors",
        z2.len()
    );
}

/// The payload's centre of mass in the flange frame (m) in the run with payloads.
const PAYLOAD_COM_M: [f64; 3] = [0.01, -0.02, 0.08];

/// The mass moments `φ = (m L, m c)` (kg m; joint frames) of the iiwa 7's bodies beyond 0-based
/// joint `i`, in the order of [`calib::model::extensions::lumped_gravity`]'s combinations.
fn true_moments(full: &sim::Model, length_m: f64, i: usize) -> Vec<f64> {
    full.bodies()[i..]
        .iter()
        .flat_map(|b| {
            let s = b.com * b.mass;
            [b.mass * length_m, s.x, s.y, s.z]
        })
        .collect()
}

/// `|g| v · φ` (N m): a combination `v` of the true mass moments beyond 0-based joint `i`.
fn combined_moment(full: &sim::Model, length_m: f64, i: usize, v: &[f64]) -> f64 {
    let g = Vector3::from(sim::statics::DEFAULT_GRAVITY).norm();
    let phi = true_moments(full, length_m, i);
    g * v.iter().zip(&phi).map(|(a, b)| a * b).sum::<f64>()
}

/// What a lumped recovery measured in one run.
struct LumpedRun {
    /// `z²` of every determined extension parameter.
    z2: Vec<f64>,
    /// Held-out RMS (m) of the fit without masses and of the fit with them.
    rms_without: f64,
    rms_with: f64,
}

/// One run of a lumped recovery: `effects` simulated on the iiwa 7 (`poses` poses, two thirds for
/// training), fitted with `spec` on the iiwa 7 with its masses and stripped of them; each
/// determined extension parameter of the fit without masses is compared with `truth` (the
/// parameter and the fit's lumped bases) within 4σ, the report must say `says`, and the held-out
/// RMS of the two fits must agree within 5 %.
fn lumped_recovery(
    seed: u64,
    poses: usize,
    effects: &str,
    spec: &str,
    payload: bool,
    says: &str,
    truth: &dyn Fn(
        &calib::model::extensions::ExtensionParam,
        &calib::model::extensions::lumped_gravity::LumpedGravity,
    ) -> f64,
) -> LumpedRun {
    let full = robots::load_builtin("iiwa7").unwrap();
    let text = sim::urdf_text::without_inertials(robots::builtin_urdf("iiwa7").unwrap());
    let bare = sim::urdf::load_str(&text, "iiwa7 without masses", &Default::default()).unwrap();
    assert!(bare.require_inertials().is_err());
    let dir = std::env::temp_dir().join(format!("robocal_ext_bare_{}_{seed}", std::process::id()));
    let t = simulate_poses(effects, seed, poses, &dir);
    let n_rows = t.len();
    let train = Dataset::new(
        &t,
        (0..n_rows * 2 / 3).collect(),
        "sim",
        calib::part::Part::Training,
    );
    let test = Dataset::new(
        &t,
        (n_rows * 2 / 3..n_rows).collect(),
        "sim",
        calib::part::Part::Test,
    );
    let spec = ModelSpec::parse(spec).unwrap();
    let options = CalibrationOptions::default();
    let request = FitRequest::new(&spec, &options);
    let with_masses = fit(&full, &train, &request).unwrap();
    let lumped = fit(&bare, &train, &request).unwrap();
    assert!(
        lumped.report.health.is_clean(),
        "seed {seed}: {}",
        lumped.report.health
    );
    let settings = lumped.extensions.as_ref().unwrap();
    let basis = settings.lumped_gravity.as_ref().expect("the lumped model");
    assert_eq!(basis.payload_compliance, payload);
    assert!(
        lumped.report.warnings.iter().any(|w| w.contains(says)),
        "the report says what is identified: {:?}",
        lumped.report.warnings
    );
    let z2 = determined_z2(&lumped, seed, &|p| truth(p, basis));
    let rms = |cal: &calib::fit::Calibration, model: &sim::Model| -> f64 {
        let (_, after, _) = calib::validate::held_out_errors(model, cal, &test, &options).unwrap();
        (after.iter().map(|e| e.norm_squared()).sum::<f64>() / after.len() as f64).sqrt()
    };
    let run = LumpedRun {
        rms_without: rms(&lumped, &bare),
        rms_with: rms(&with_masses, &full),
        z2,
    };
    println!(
        "seed {seed}: {} parameters determined, largest |z| {:.2}; held-out RMS {:.2} µm without \
         masses, {:.2} µm with; rank {} without masses, {} with",
        run.z2.len(),
        run.z2.iter().fold(0.0_f64, |a, b| a.max(b.sqrt())),
        run.rms_without * 1e6,
        run.rms_with * 1e6,
        lumped.subspace.rank,
        with_masses.subspace.rank
    );
    assert!(
        (run.rms_without / run.rms_with - 1.0).abs() <= 0.05,
        "seed {seed}: held-out RMS {:.2} µm without masses, {:.2} µm with",
        run.rms_without * 1e6,
        run.rms_with * 1e6
    );
    let _ = std::fs::remove_dir_all(&dir);
    run
}

/// The mean of the `z²` of several runs, checked to be that of standard normal errors: for n ≈ 90
/// of them its standard deviation is √(2/n) ≈ 0.15 (more with the products' correlations).
fn assert_mean_z2(runs: &[LumpedRun]) {
    let z2: Vec<f64> = runs.iter().flat_map(|r| r.z2.iter().copied()).collect();
    let mean = z2.iter().sum::<f64>() / z2.len() as f64;
    println!("mean z² {mean:.2} over {} parameters", z2.len());
    assert!(
        (0.5..1.6).contains(&mean),
        "mean z² = {mean:.2} over {} parameters",
        z2.len()
    );
}

/// A robot without masses (the iiwa 7's URDF stripped of its inertials) with compliance at drawn
/// joints and stiffnesses: the lumped products `βᵢₖ = cᵢ |g| vᵢₖ · φᵢ` (the true compliance times
/// the true mass moments `φ = (m L, m c)` of the bodies beyond the joint, combined as the fit's
/// basis says) are recovered within their σ, and on held-out poses the fit predicts as well as the
/// fit that knows the masses (within 5 %). With payload masses that change over the data, each
/// joint's compliance is identified too, within its σ.
///
/// "Within σ" is judged as a family: about 100 determined parameters over the two runs (joint 2
/// alone has 12 products), so a bound of 3σ on each, a 0.27 % tail, would fail by chance in about
/// one draw in four; each lies within 4σ (6e-5 a parameter, 0.6 % for the family) and their mean z²
/// is that of standard normal errors. Measured at these seeds: 42 and 60 parameters determined,
/// the largest |z| 2.65 and 3.24, mean z² 1.10; held-out RMS 23.36 µm without the masses against
/// 23.50 µm with them, and 24.22 against 24.21 µm with payloads.
#[test]
fn compliance_of_a_robot_without_masses_is_recovered_as_lumped_products() {
    let full = robots::load_builtin("iiwa7").unwrap();
    let g = Vector3::from(sim::statics::DEFAULT_GRAVITY);
    let mut runs = Vec::new();
    for (seed, payload) in [(21u64, false), (22, true)] {
        let mut rng = StdRng::seed_from_u64(seed ^ 0x1a3b);
        // Compliance at two of joints 2, 3, 4 and 6, stiffness 5e3-2e4 N m/rad.
        let mut joints = vec![2usize, 3, 4, 6];
        let drop = rng.random_range(0..4);
        joints.remove(drop);
        let drop = rng.random_range(0..3);
        joints.remove(drop);
        let mut stiffness = vec!["inf".to_string(); 7];
        let mut compliance = [0.0; 7];
        for &j in &joints {
            let k: f64 = rng.random_range(5e3..2e4);
            stiffness[j - 1] = format!("{k:e}");
            compliance[j - 1] = 1.0 / k;
        }
        let mut effects = format!(
            "[effects.compliance]\nstiffness_nm_per_rad = [{}]\n",
            stiffness.join(", ")
        );
        if payload {
            effects.push_str(&format!(
                "[campaign.payload]\nchoice_kg = [0.0, 3.5, 7.0]\ncom_m = {PAYLOAD_COM_M:?}\n"
            ));
        }
        // The truth in the estimator's parameters.
        let truth = |p: &calib::model::extensions::ExtensionParam,
                     basis: &calib::model::extensions::lumped_gravity::LumpedGravity|
         -> f64 {
            let i = p.term.joint().unwrap();
            let com_axis = calib::model::extensions::joint_compliance::PAYLOAD_COM_QUANTITIES
                .iter()
                .position(|q| *q == p.quantity);
            match (p.pattern, com_axis) {
                (None, Some(a)) => compliance[i] * g.norm() * PAYLOAD_COM_M[a],
                (None, None) => compliance[i],
                (Some(k), _) => {
                    compliance[i]
                        * combined_moment(&full, basis.length_m, i, &basis.combinations[i][k - 1])
                }
            }
        };
        let run = lumped_recovery(
            seed,
            600,
            &effects,
            "kinematic+joint_compliance",
            payload,
            "not the stiffnesses",
            &truth,
        );
        assert!(
            run.z2.len() >= 8,
            "seed {seed}: only {} determined",
            run.z2.len()
        );
        runs.push(run);
    }
    assert_mean_z2(&runs);
}

/// Poses of the lumped deflection test (two thirds for training). Without masses every bending axis
/// has up to a dozen products where the robot with masses has one compliance: at seed 31 the fit
/// has rank `p₁` = 130 against `p₀` = 44. Their own estimation noise raises the held-out RMS by
/// about `√((1 + p₁/N) / (1 + p₀/N)) − 1` (`N` training coordinates): 3.4 % at 400 training poses
/// (measured 5.1 %), which is the price of not knowing the masses, not a fault of the model. At
/// 600 training poses it is 2.3 % (seed 31) and 3.6 % (seed 32, rank 183 against 47), and the 5 %
/// of the issue measures the model again.
const POSES_FOR_LUMPED_DEFLECTION: usize = 900;

/// Link deflection of a robot without masses: bending at drawn axes of joints 2 to 6 (1-5e-6
/// rad/(N m)) with compliance at joints 2 and 4, fitted with compliance and deflection on the
/// iiwa 7 stripped of its inertials. The lumped bending products `βₐₖ = c_a |g| vₐₖ · φ` are
/// recovered within 4σ (judged as a family, as above), and the held-out error equals that of the
/// fit with the true masses within 5 %; with payload masses that change over the data, each
/// bending compliance and its products with the payload's centre of mass too.
///
/// Measured at these seeds: 52 and 84 parameters determined, the largest |z| 2.20 and 2.55, mean
/// z² 0.89 over 136; held-out RMS 25.10 µm without the masses against 24.23 µm with them, and
/// 24.33 against 23.88 µm with payloads.
#[test]
fn link_deflection_of_a_robot_without_masses_is_recovered_as_lumped_products() {
    use calib::model::extensions::{Term, link_deflection};
    let full = robots::load_builtin("iiwa7").unwrap();
    let g = Vector3::from(sim::statics::DEFAULT_GRAVITY);
    let mut runs = Vec::new();
    for (seed, payload) in [(31u64, false), (32, true)] {
        let mut rng = StdRng::seed_from_u64(seed ^ 0x5d1f);
        // Bending compliance (joint frame axes u, v) at each joint: of the modelled axes of joints
        // 2-6, each drawn present with probability one half, 1-5e-6 rad/(N m).
        let mut bend = [[0.0f64; 2]; 7];
        let mut drawn = Vec::new();
        for (i, row) in bend.iter_mut().enumerate().take(6).skip(1) {
            let axes = link_deflection::bending_axes(&full.joints()[i].axis).unwrap();
            for about in link_deflection::modelled_axes(full.joints(), i, &g) {
                if rng.random_bool(0.5) {
                    let slot = axes.iter().position(|a| *a == about).unwrap();
                    row[slot] = rng.random_range(1e-6..5e-6);
                    drawn.push((i, about));
                }
            }
        }
        let k: Vec<f64> = (0..2).map(|_| rng.random_range(5e3..2e4)).collect();
        let rows: Vec<String> = bend
            .iter()
            .map(|r| format!("[{:e}, {:e}]", r[0], r[1]))
            .collect();
        let mut effects = format!(
            "[effects.deflection]\ncompliance_rad_per_nm = [{}]\n\
             [effects.compliance]\nstiffness_nm_per_rad = [inf, {:e}, inf, {:e}, inf, inf, inf]\n",
            rows.join(", "),
            k[0],
            k[1]
        );
        if payload {
            effects.push_str(&format!(
                "[campaign.payload]\nchoice_kg = [0.0, 3.5, 7.0]\ncom_m = {PAYLOAD_COM_M:?}\n"
            ));
        }
        let compliance = |i: usize| match i {
            1 => 1.0 / k[0],
            3 => 1.0 / k[1],
            _ => 0.0,
        };
        let truth = |p: &calib::model::extensions::ExtensionParam,
                     basis: &calib::model::extensions::lumped_gravity::LumpedGravity|
         -> f64 {
            let (c, i, combos) = match p.term {
                Term::Bend { joint, about } => {
                    let axes = link_deflection::bending_axes(&full.joints()[joint].axis).unwrap();
                    let slot = axes.iter().position(|a| *a == about).unwrap();
                    let combos = &basis.bend_basis(joint, about).unwrap().combinations;
                    (bend[joint][slot], joint, combos)
                }
                _ => {
                    let i = p.term.joint().unwrap();
                    (compliance(i), i, &basis.combinations[i])
                }
            };
            let com_axis = calib::model::extensions::joint_compliance::PAYLOAD_COM_QUANTITIES
                .iter()
                .chain(&link_deflection::PAYLOAD_COM_QUANTITIES)
                .position(|q| *q == p.quantity)
                .map(|a| a % 3);
            match (p.pattern, com_axis) {
                (None, Some(a)) => c * g.norm() * PAYLOAD_COM_M[a],
                (None, None) => c,
                (Some(k), _) => c * combined_moment(&full, basis.length_m, i, &combos[k - 1]),
            }
        };
        let run = lumped_recovery(
            seed,
            POSES_FOR_LUMPED_DEFLECTION,
            &effects,
            "kinematic+joint_compliance+link_deflection",
            payload,
            "not the compliances",
            &truth,
        );
        assert!(
            !drawn.is_empty() && run.z2.len() >= 8,
            "seed {seed}: drawn {drawn:?}, {} determined",
            run.z2.len()
        );
        runs.push(run);
    }
    assert_mean_z2(&runs);
}

/// A campaign simulated with `effects` (TOML) on top of drawn geometric errors, `poses` poses.
fn simulate_poses(
    effects: &str,
    seed: u64,
    poses: usize,
    dir: &std::path::Path,
) -> MeasurementTable {
    let base = include_str!("../../scenarios/iiwa7_kinematic.toml");
    let text = format!("{base}\n{effects}");
    let sc = Scenario::parse(&text, "extension test", std::path::Path::new(".")).unwrap();
    let res = sc
        .resolve(&Overrides {
            seed: Some(seed),
            poses: Some(poses),
            noise: None,
        })
        .unwrap();
    sim::generate::generate(&res, dir, None).unwrap();
    measurement_table::read(&dir.join("measurements.parquet")).unwrap()
}
