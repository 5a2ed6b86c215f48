//! The compensation's analytic Jacobian (`calib::model::compensate`) against central differences of
//! the model's own prediction, for every part it differentiates: the geometry, joint compliance (the
//! gravity torques' Jacobian), transmission error, backlash and thermal drift (no dependence), and
//! the kernel and polynomial learned corrections, at random configurations with a payload, a
//! temperature and approach directions. Link deflection's bend and the adjoint model are not
//! differentiated (docs/compensate.md) and are not in these models.

use calib::fit::{CalibrationOptions, Dataset, FitRequest, fit};
use calib::model::ModelSpec;
use calib::model::compensate::{Compensator, Target};
use calib::model::extensions::RowContext;
use calib::model::file::CalibratedModel;
use calib::model::predict::Predictor;
use calib::model::robot::Robot;
use nalgebra::Vector3;
use rand::{RngExt, SeedableRng};
use std::path::PathBuf;

fn check(model: &str, data: &sim::measurement_table::MeasurementTable, robot: &Robot) {
    let cal = fit(
        &robot.model,
        &Dataset::all(data, "jacobian"),
        &FitRequest::new(
            &ModelSpec::parse(model).unwrap(),
            &CalibrationOptions::default(),
        ),
    )
    .unwrap();
    let file = CalibratedModel::new(robot, &cal);
    let predictor = Predictor::from_file(&file).unwrap();
    if model.contains("learned") {
        let l = predictor.learned.as_ref().unwrap();
        assert!(
            l.is_active(),
            "{model}: the learned correction must be kept for this check"
        );
    }
    let comp = Compensator::new(&predictor);
    let mut s = comp.scratch();
    let mut rng = rand::rngs::StdRng::seed_from_u64(26);
    let n = robot.model.nq();
    let dir: Vec<i8> = (0..n).map(|j| if j % 2 == 0 { 1 } else { -1 }).collect();
    for case in 0..20 {
        let q: Vec<f64> = robot
            .model
            .joints()
            .iter()
            .map(|j| {
                let l = j.limits.unwrap();
                rng.random_range(l.lower * 0.9..l.upper * 0.9)
            })
            .collect();
        let target = Target {
            p_tracker: Vector3::zeros(),
            r_tracker: None,
            seed_q: &q,
            context: RowContext {
                payload_kg: [0.0, 3.5, 7.0][case % 3],
                dir: Some(&dir),
                temp_c: Some(24.0),
                t_s: Some(900.0),
                branch: None,
            },
            campaign: 0,
        };
        let (_, jac) = comp.prediction_jacobian(&q, &target, &mut s).unwrap();
        let h = 1e-6;
        for k in 0..n {
            let mut qp = q.clone();
            qp[k] += h;
            let (pp, _) = comp.prediction_jacobian(&qp, &target, &mut s).unwrap();
            qp[k] -= 2.0 * h;
            let (pm, _) = comp.prediction_jacobian(&qp, &target, &mut s).unwrap();
            let fd = (pp - pm) / (2.0 * h);
            let an = Vector3::new(jac[(0, k)], jac[(1, k)], jac[(2, k)]);
            assert!(
                (fd - an).norm() <= 1e-7 * (1.0 + fd.norm()),
                "{model}, case {case}, joint {}: analytic {an:?} against central differences {fd:?}",
                k + 1
            );
        }
    }
}

#[test]
fn the_compensation_jacobian_matches_central_differences() {
    let scenario = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenarios/iiwa7_all.toml");
    let out = std::env::temp_dir().join(format!("robocal_comp_jac_{}", std::process::id()));
    let options = robocal::cli::generate::Options {
        seed: Some(11),
        poses: Some(300),
        noise: None,
    };
    robocal::cli::generate::generate(&scenario, &out, &options, &|_| {}).unwrap();
    let data = sim::measurement_table::read(&out.join("measurements.parquet")).unwrap();
    let robot = Robot::load("iiwa7", &sim::ChainSpec::default()).unwrap();
    // The learned corrections are fitted on what the kinematic model leaves of every effect, so
    // that cross-validation keeps them (checked).
    for model in [
        "kinematic+joint_compliance+gear_backlash+thermal_drift+transmission_error",
        // Causes at some of their joints (issue 25): the angle Jacobian of a limited cause sees
        // zeros at the joints left out.
        "kinematic+joint_compliance@2,4,6+gear_backlash@1,3+transmission_error@1,7",
        "kinematic+learned:kernel",
        "kinematic+learned:poly",
    ] {
        check(model, &data, &robot);
    }
    let _ = std::fs::remove_dir_all(out);
}
