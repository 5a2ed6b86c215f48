//! `learned:adjoint` (`calib::learned::adjoint`): its analytic Jacobian against central differences of
//! its own predictions, and the recovery of a joint axis that tilts with the configuration, simulated
//! here with the product of exponentials of per-row screws (`sim::kinematics::poe_pose`, never
//! `calib::chain`). Seeds are drawn per run and printed.

mod common;

use calib::calibrate::{CalibrationOptions, Dataset, calibrate, calibrate_model};
use calib::extensions::ModelSpec;
use calib::learned::adjoint::{empty_model, residuals_and_jacobian};
use calib::predict::Prediction;
use calib::problem::{NoiseModel, Observations};
use common::{Truth, random_configs};
use nalgebra::{Point3, Vector3, Vector6};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, Normal};
use sim::lie::{adjoint_apply, exp_twist};
use sim::measurement_table::{MeasurementTable, OptionalColumns, Row};
use sim::robots;

#[test]
fn adjoint_jacobian_matches_central_differences() {
    let model = robots::load_builtin("ur5").unwrap();
    let mut g = StdRng::seed_from_u64(common::run_seed("adjoint jacobian"));
    let truth = Truth::random(&model, false, &mut g);
    let configs = random_configs(&model, 30, &mut g);
    let table = common::table(&model, &truth, &configs, 1e-5, 0.0, &mut g);
    let cal = calibrate(
        &model,
        &Dataset::all(&table, "t"),
        None,
        &CalibrationOptions::default(),
    )
    .unwrap();
    let rows: Vec<usize> = (0..table.len()).collect();
    let obs = Observations::from_table(&table, &rows, &NoiseModel::default(), "t").unwrap();
    for degree in [1, 2] {
        let mut m = empty_model(&obs, degree);
        // Coefficients of 0.1–1 mrad (or mm) per feature unit: twists of a few mrad over the data.
        for c in &mut m.coefficients {
            *c = (2.0 * g.random::<f64>() - 1.0) * 1e-3;
        }
        let (_, jac) = residuals_and_jacobian(&model, &cal.params, &obs, &m);
        let h = 1e-7;
        let mut worst = 0.0f64;
        // Every coefficient of degree 1, a seeded sample of degree 2's.
        let columns: Vec<usize> = if degree == 1 {
            (0..m.n_coefficients()).collect()
        } else {
            (0..60)
                .map(|_| g.random_range(0..m.n_coefficients()))
                .collect()
        };
        let scale = jac.amax();
        for &k in &columns {
            let mut plus = m.clone();
            plus.coefficients[k] += h;
            let mut minus = m.clone();
            minus.coefficients[k] -= h;
            let (rp, _) = residuals_and_jacobian(&model, &cal.params, &obs, &plus);
            let (rm, _) = residuals_and_jacobian(&model, &cal.params, &obs, &minus);
            for r in 0..obs.len() {
                let fd = (rp[r] - rm[r]) / (2.0 * h);
                for a in 0..3 {
                    worst = worst.max((fd[a] - jac[(3 * r + a, k)]).abs() / scale);
                }
            }
        }
        eprintln!("degree {degree}: largest difference {worst:e} of the largest entry");
        assert!(worst < 1e-6, "degree {degree}: {worst:e}");
    }
}

#[test]
fn adjoint_recovers_an_axis_that_tilts_with_the_configuration() {
    let model = robots::load_builtin("ur5").unwrap();
    let mut g = StdRng::seed_from_u64(common::run_seed("adjoint recovery"));
    let truth = Truth::random(&model, false, &mut g);
    // Joint 3's axis tilts about x by 0.4 mrad per radian of joint 2, and slides 0.2 mm per radian of
    // joint 3 (an elastic shoulder, a cam in a bearing): error twists linear in the joint values.
    let tilt = |q: &[f64]| -> Vec<Vector6<f64>> {
        let mut t = truth.twists.clone();
        t[2] += Vector6::new(4e-4 * q[1], 0.0, 0.0, 0.0, 0.0, 2e-4 * q[2]);
        t
    };
    let target = |q: &[f64]| -> Vector3<f64> {
        let screws: Vec<Vector6<f64>> = model
            .joints
            .iter()
            .zip(tilt(q))
            .map(|(j, xi)| adjoint_apply(&exp_twist(&xi), &j.screw))
            .collect();
        let th: Vec<f64> = q
            .iter()
            .zip(&truth.zero_offsets)
            .map(|(a, b)| a + b)
            .collect();
        let t = truth.t_tracker_base * sim::kinematics::poe_pose(&screws, &model.home_flange, &th);
        (t * Point3::from(truth.p_flange)).coords
    };
    let noise = Normal::new(0.0, 5e-6).unwrap();
    let mut table = MeasurementTable::new(model.nq(), OptionalColumns::NONE);
    for (k, q) in random_configs(&model, 400, &mut g).iter().enumerate() {
        let p = target(q);
        table
            .push_row(&Row {
                pose: k as i64,
                q,
                position: [
                    p.x + noise.sample(&mut g),
                    p.y + noise.sample(&mut g),
                    p.z + noise.sample(&mut g),
                ],
                ..Row::default()
            })
            .unwrap();
    }
    let options = CalibrationOptions::default();
    let data = Dataset::all(&table, "tilt");
    let physical = calibrate_model(&model, &data, None, &ModelSpec::kinematic(), &options).unwrap();
    let spec: ModelSpec = "kinematic+learned:adjoint".parse().unwrap();
    let adj = calibrate_model(&model, &data, None, &spec, &options).unwrap();
    let learned = adj.learned.as_ref().unwrap();
    eprintln!("{}", learned.describe());
    assert!(learned.is_active(), "{}", learned.describe());
    // Held-out poses against the noise-free truth.
    let held = random_configs(&model, 200, &mut g);
    let mut t = MeasurementTable::new(model.nq(), OptionalColumns::NONE);
    for (k, q) in held.iter().enumerate() {
        let p = target(q);
        t.push_row(&Row {
            pose: k as i64,
            q,
            position: [p.x, p.y, p.z],
            ..Row::default()
        })
        .unwrap();
    }
    let obs = Observations::from_table(
        &t,
        &(0..t.len()).collect::<Vec<_>>(),
        &NoiseModel::default(),
        "held",
    )
    .unwrap();
    let rms = |e: Vec<Vector3<f64>>| {
        (e.iter().map(|v| v.norm_squared()).sum::<f64>() / e.len() as f64).sqrt()
    };
    let before = rms(Prediction::new(&model, &physical.params).errors(&obs));
    let after = rms(Prediction::new(&model, &adj.params)
        .with_learned(Some(learned))
        .errors(&obs));
    eprintln!(
        "held-out error against the truth: kinematic {:.2} µm, with learned:adjoint {:.2} µm",
        before * 1e6,
        after * 1e6
    );
    // The tilt moves the target by up to a few hundred µm; degree 1 represents it up to second-order
    // terms (the product of two sub-mrad twists over a metre: below a µm), so what is left is the
    // noise's share, a few µm.
    assert!(before > 30e-6, "the tilt is visible: {before:e}");
    assert!(after < before / 5.0, "{after:e} against {before:e}");
}
