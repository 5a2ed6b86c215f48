//! Pose planning (`calib::fit::plan`): the plan's predictions against calibrations on its poses, the
//! payload choice for compliance, and the cell's constraints against hand-derived cases.

mod common;

use calib::fit::plan::{Candidates, CellConstraints, Constraint, PlanOptions, plan_poses};
use calib::fit::{CalibrationOptions, Dataset, FitRequest, fit};
use calib::model::observations::NoiseModel;
use calib::model::spec::ModelSpec;
use common::{Truth, random_configs, rng, table};
use nalgebra::Vector3;
use sim::robots;

/// Constant noise of `sigma` m per coordinate, as `common::table` draws it.
fn constant_noise(sigma: f64) -> NoiseModel {
    NoiseModel {
        position_sigma_m: sigma,
        position_sigma_per_m: 0.0,
        ..NoiseModel::default()
    }
}

/// The plan predicts the held-out error against the truth of a calibration on its poses: over 20
/// drawn robots (geometric errors of 0.1–1 mm and mrad, unknown base and target, 10 µm noise), the
/// realised RMS error at 100 fresh poses each is the predicted one. The realised mean square is a sum
/// of 20 independent quadratic forms of the estimation error, each with a relative standard
/// deviation of about √(2 / r_eff) ≈ 0.45 here, so the RMS of 20 has a relative standard deviation of
/// about 5 %: the band [0.8, 1.2] is four of them. And the predicted standard deviations of the
/// parameters are the fit's own (the same Jacobian at nearly the same point; within 10 %).
#[test]
fn a_calibration_on_planned_poses_errs_as_the_plan_predicts() {
    let model = robots::load_builtin("iiwa7").unwrap();
    let noise = 1e-5;
    let mut opts = PlanOptions::new(600, 20, 7);
    opts.noise = constant_noise(noise);
    let planned = plan_poses(&model, &opts).unwrap();
    let calibration = CalibrationOptions {
        noise: constant_noise(noise),
        ..CalibrationOptions::default()
    };
    let mut g = rng(409);
    let (mut sq, mut count) = (0.0, 0usize);
    for _ in 0..20 {
        let truth = Truth::random(&model, false, &mut g);
        let t = table(&model, &truth, &planned.selected, noise, 0.0, &mut g);
        let cal = fit(
            &model,
            &Dataset::all(&t, "planned"),
            &FitRequest::kinematic(&calibration),
        )
        .unwrap();
        let chain = calib::model::chain::Chain::new(&model, &cal.params);
        let mut s = calib::model::chain::ChainScratch::new(7);
        for q in random_configs(&model, 100, &mut g) {
            chain.forward(&mut s, &q);
            sq += (s.p_tracker - truth.target(&model, &q).0).norm_squared();
            count += 1;
        }
    }
    let realised = (sq / count as f64).sqrt();
    let ratio = realised / planned.position_sigma_m;
    eprintln!(
        "held-out RMS against the truth: realised {:.2} µm, predicted {:.2} µm (ratio {ratio:.3})",
        realised * 1e6,
        planned.position_sigma_m * 1e6
    );
    assert!((0.8..1.2).contains(&ratio), "ratio {ratio:.3}");
    // The measured residual adds the noise of three coordinates.
    let expected = (planned.position_sigma_m.powi(2) + 3.0 * noise * noise).sqrt();
    assert!((planned.predicted_heldout_rms_m - expected).abs() < 1e-15);
}

/// For joint compliance the plan chooses heavy payloads where they inform the stiffnesses: with
/// 0 or 7 kg to choose from, most poses carry 7 kg, and every determined compliance has a smaller
/// predicted σ than the best plan without payload. Planned poses beat random ones of the same
/// candidates in every stiffness (the random sets draw payloads too).
#[test]
fn compliance_plans_choose_payloads_and_beat_random_poses() {
    let model = robots::load_builtin("iiwa7").unwrap();
    let mut opts = PlanOptions::new(500, 30, 11);
    opts.model = ModelSpec::parse("kinematic+joint_compliance").unwrap();
    opts.payload_com_m = Vector3::new(0.0, 0.0, 0.08);
    let bare = plan_poses(&model, &opts).unwrap();
    assert!(bare.payload_kg.is_none());
    opts.payloads_kg = vec![0.0, 7.0];
    let loaded = plan_poses(&model, &opts).unwrap();
    let payloads = loaded.payload_kg.as_ref().unwrap();
    let heavy = payloads.iter().filter(|m| **m == 7.0).count();
    eprintln!("{heavy} of 30 poses with 7 kg");
    assert!(heavy >= 20, "{payloads:?}");
    let csv = loaded.to_csv();
    assert!(
        csv.starts_with("pose,q1,q2,q3,q4,q5,q6,q7,payload\n0,"),
        "{csv}"
    );
    assert_eq!(csv.lines().count(), 31);
    let mut determined = 0;
    for (a, b) in bare.parameters.iter().zip(&loaded.parameters) {
        assert_eq!(a.name, b.name);
        if !a.name.ends_with("compliance") {
            continue;
        }
        let (Some(sa), Some(sb)) = (a.sigma, b.sigma) else {
            assert!(
                a.sigma.is_none() && b.sigma.is_none(),
                "{}: determined with one plan only",
                a.name
            );
            continue;
        };
        determined += 1;
        let random = b.random_sigma.unwrap();
        eprintln!(
            "{}: σ {sa:.3e} without payload, {sb:.3e} with, random {random:.3e}",
            a.name
        );
        assert!(sb < sa, "{}", a.name);
        assert!(sb < random, "{}", a.name);
    }
    // Joints 2 to 6 carry gravity torques that vary with the pose; 1 and 7 never do.
    assert_eq!(determined, 5);
}

/// The constraints against cases worked by hand on the iiwa 7 stretched upright (q = 0: every joint
/// origin on the base z axis, the flange on top at height h) with the target 8 cm above the flange.
#[test]
fn constraints_keep_the_cases_worked_by_hand() {
    let model = robots::load_builtin("iiwa7").unwrap();
    let h = model.home_flange().translation.z;
    let upright = Candidates::from_configurations(&model, &[vec![0.0; 7]], "upright");
    let target = Vector3::new(0.0, 0.0, 0.08);
    let broken = |c: CellConstraints| {
        let mut data = sim::kinematics::Data::new(&model);
        c.validate().unwrap();
        c.broken(&model, &mut data, upright.table.q_row(0), &target)
    };
    let tracker = |z: f64| CellConstraints {
        tracker_base_m: Some(Vector3::new(0.0, 0.0, z)),
        line_of_sight_clearance_m: Some(0.05),
        ..CellConstraints::default()
    };
    // From straight above, the beam ends 0.13 m above the target (|target| + clearance), over the
    // flange by 0.21 m: clear.
    assert_eq!(broken(tracker(h + 3.0)), None);
    // From straight below, the beam runs down the robot's axis through every link: blocked.
    assert_eq!(broken(tracker(-3.0)), Some(Constraint::LineOfSight));
    // The skipped stretch grows with the clearance: at 0.22 m it is 0.30 m, and the beam stops
    // 0.38 m above the flange: still clear.
    let mut c = tracker(h + 3.0);
    c.line_of_sight_clearance_m = Some(0.22);
    assert_eq!(broken(c), None);
    // The arm bent at joint 2 by 90°, the upper arm and the wrist horizontal (the target, 8 cm along
    // the flange's z axis, on the arm's axis): a tracker 3 m beyond the target, on that axis, sees
    // it; one 3 m behind the shoulder looks down the arm: blocked.
    let bent = [0.0, std::f64::consts::FRAC_PI_2, 0.0, 0.0, 0.0, 0.0, 0.0];
    let mut data = sim::kinematics::Data::new(&model);
    sim::kinematics::forward_kinematics(&model, &mut data, &bent);
    let shoulder = data.joint_poses[1].translation.vector;
    let p_target = data.flange * nalgebra::Point3::from(target);
    let along = (p_target.coords - shoulder).normalize();
    assert!(along.z.abs() < 1e-9, "the arm is horizontal: {along:?}");
    let at = |tracker: Vector3<f64>| {
        let c = CellConstraints {
            tracker_base_m: Some(tracker),
            line_of_sight_clearance_m: Some(0.05),
            ..CellConstraints::default()
        };
        let mut data = sim::kinematics::Data::new(&model);
        c.broken(&model, &mut data, &bent, &target)
    };
    assert_eq!(at(p_target.coords + 3.0 * along), None);
    assert_eq!(at(shoulder - 3.0 * along), Some(Constraint::LineOfSight));
    // The range: the target is 3 m below a tracker at h + 3.08.
    let mut r = tracker(h + 3.08);
    r.line_of_sight_clearance_m = None;
    r.tracker_range_m = Some((1.0, 2.9));
    assert_eq!(broken(r.clone()), Some(Constraint::TrackerRange));
    r.tracker_range_m = Some((1.0, 3.1));
    assert_eq!(broken(r), None);
    // The floor: joint 2's origin (the first checked) is the lowest at z₂.
    let z2 = {
        let mut data = sim::kinematics::Data::new(&model);
        sim::kinematics::forward_kinematics(&model, &mut data, &[0.0; 7]);
        data.joint_poses[1].translation.z
    };
    let floor = |z: f64| CellConstraints {
        floor_z_m: Some(z),
        ..CellConstraints::default()
    };
    assert_eq!(broken(floor(z2 - 1e-6)), None);
    assert_eq!(broken(floor(z2 + 1e-6)), Some(Constraint::Floor));
    // Joint margins: q = 0 is 2.094 rad (120°) from the nearest limits, those of joints 2, 4 and 6.
    let margin = |m: f64| CellConstraints {
        joint_margin: m,
        ..CellConstraints::default()
    };
    assert_eq!(broken(margin(2.09)), None);
    assert_eq!(broken(margin(2.1)), Some(Constraint::JointMargin));
    // Settings that cannot work are refused, naming the flag.
    let e = CellConstraints {
        tracker_range_m: Some((1.0, 3.0)),
        ..CellConstraints::default()
    }
    .validate()
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("--tracker-range") && e.contains("--tracker X,Y,Z"),
        "{e}"
    );
}

/// Drawn candidates that break constraints are counted per constraint, and the plan keeps none of
/// them; its poses keep every constraint when checked again.
#[test]
fn plans_count_what_each_constraint_left_out_and_keep_the_rest() {
    let model = robots::load_builtin("iiwa7").unwrap();
    let mut opts = PlanOptions::new(800, 25, 5);
    opts.constraints = CellConstraints {
        tracker_base_m: Some(Vector3::new(2.5, 0.0, 0.5)),
        tracker_range_m: Some((1.8, 3.0)),
        line_of_sight_clearance_m: Some(0.05),
        floor_z_m: Some(0.1),
        joint_margin: 0.1,
    };
    let p = plan_poses(&model, &opts).unwrap();
    let left_out: usize = p.rejected.iter().map(|r| r.count).sum();
    eprintln!("{:?}", p.rejected);
    assert_eq!(p.candidates + left_out, 800);
    for c in [
        Constraint::Floor,
        Constraint::TrackerRange,
        Constraint::LineOfSight,
    ] {
        assert!(
            p.rejected.iter().any(|r| r.constraint == c && r.count > 0),
            "{c:?} left nothing out"
        );
    }
    let mut data = sim::kinematics::Data::new(&model);
    for q in &p.selected {
        assert_eq!(
            opts.constraints
                .broken(&model, &mut data, q, &opts.target_offset),
            None
        );
    }
}
