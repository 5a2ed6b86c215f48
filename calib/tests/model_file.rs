//! The calibrated model file round trip, the predictor, the calibrated URDF, and pose planning.

mod common;

use calib::fit::plan::{PlanOptions, plan_poses};
use calib::fit::{CalibrationOptions, Dataset, FitRequest, fit};
use calib::model::file::CalibratedModel;
use calib::model::predict::Predictor;
use calib::model::robot::Robot;
use calib::model::urdf_export::calibrated_urdf;
use common::{Truth, random_configs, rng, table};
use nalgebra::Point3;
use sim::{ChainSpec, robots};

fn calibrated(
    name: &str,
    orientation: bool,
    seed: u64,
) -> (Robot, Truth, calib::fit::Calibration, rand::rngs::StdRng) {
    let robot = Robot::load(name, &ChainSpec::default()).unwrap();
    let mut g = rng(seed);
    let truth = Truth::random(&robot.model, orientation, &mut g);
    let t = table(
        &robot.model,
        &truth,
        &random_configs(&robot.model, 60, &mut g),
        0.0,
        0.0,
        &mut g,
    );
    let cal = fit(
        &robot.model,
        &Dataset::all(&t, "t"),
        &FitRequest::kinematic(&CalibrationOptions::default()),
    )
    .unwrap();
    (robot, truth, cal, g)
}

#[test]
fn model_file_round_trips_and_predicts_the_truth() {
    for (name, orientation, seed) in [("iiwa7", false, 401), ("wam", true, 402)] {
        let (robot, truth, cal, mut g) = calibrated(name, orientation, seed);
        let text = CalibratedModel::new(&robot, &cal).to_json();
        let file = CalibratedModel::from_json(&text, "model.json").unwrap();
        // Floats round-trip exactly (serde_json's float_roundtrip), so re-serialising gives the same text.
        assert!(file.to_json() == text, "serialisation is not stable");
        let mut pred = Predictor::from_file(&file).unwrap();
        let qs = random_configs(&robot.model, 40, &mut g);
        let t = table(&robot.model, &truth, &qs, 0.0, 0.0, &mut g);
        let out = pred.predict_table(&t, "t").unwrap();
        for (r, q) in qs.iter().enumerate() {
            let (p, rot) = truth.target(&robot.model, q);
            let d = (nalgebra::Vector3::from(out.position[r]) - p).norm();
            assert!(d < 1e-9, "{name}: {d:e}");
            if orientation {
                let qt = calib::lie3::quaternion_from_rotation(&rot);
                let qp = out.orientation.as_ref().unwrap()[r];
                let dot: f64 = (0..4).map(|k| qt[k] * qp[k]).sum();
                assert!(
                    dot.abs() > 1.0 - 1e-15,
                    "{name}: quaternion {qp:?} vs {qt:?}"
                );
            }
        }
        let csv = out.to_csv();
        let header = csv.lines().next().unwrap();
        assert_eq!(
            header,
            if orientation {
                "pose,x,y,z,qw,qx,qy,qz,sigma_m,outside_support"
            } else {
                "pose,x,y,z,sigma_m,outside_support"
            }
        );
        assert_eq!(csv.lines().count(), qs.len() + 1);
    }
}

#[test]
fn model_file_errors_name_the_key() {
    let (robot, _, cal, _) = calibrated("ur5", false, 403);
    let text = CalibratedModel::new(&robot, &cal).to_json();
    let e = CalibratedModel::from_json("{\"format\": \"other\"}", "m.json")
        .unwrap_err()
        .to_string();
    assert!(e.starts_with("m.json:") && e.contains("format"), "{e}");
    let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
    v["parameters"]["zero_offsets"] = serde_json::json!([0.0, 0.0]);
    let e = CalibratedModel::from_json(&v.to_string(), "m.json")
        .unwrap_err()
        .to_string();
    assert!(e.contains("zero_offsets"), "{e}");
    let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
    v["parameters"]["t_tracker_base"]["rotation"][0][0] = serde_json::json!(2.0);
    let e = CalibratedModel::from_json(&v.to_string(), "m.json")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("t_tracker_base.rotation") && e.contains("not a rotation"),
        "{e}"
    );
    let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
    v["model"] = serde_json::json!("kinematic+joint_compliance");
    let e = CalibratedModel::from_json(&v.to_string(), "m.json")
        .unwrap_err()
        .to_string();
    assert!(e.contains("'model'"), "{e}");
    let e = CalibratedModel::from_json("not json", "m.json")
        .unwrap_err()
        .to_string();
    assert!(e.contains("m.json") && e.contains("not JSON"), "{e}");
    // Finite but implausible values (issue 15: a parameter of 1e308 loaded silently).
    for (path, value, key) in [
        (
            &["parameters", "joint_error_twists"][..],
            3usize,
            "joint_error_twists[1]",
        ),
        (&["parameters", "zero_offsets"][..], 2, "zero_offsets"),
    ] {
        let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
        let mut at = &mut v;
        for p in path {
            at = &mut at[*p];
        }
        if key.starts_with("joint") {
            at[1][value] = serde_json::json!(1e308);
        } else {
            at[value] = serde_json::json!(1e308);
        }
        let e = CalibratedModel::from_json(&v.to_string(), "m.json")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(key) && e.contains("1e308") && e.contains("plausible"),
            "{e}"
        );
    }
    let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
    v["parameters"]["t_tracker_base"]["translation_m"][2] = serde_json::json!(-5e3);
    let e = CalibratedModel::from_json(&v.to_string(), "m.json")
        .unwrap_err()
        .to_string();
    assert!(e.contains("t_tracker_base.translation_m"), "{e}");
    // The embedded robot swapped for another is refused by its checksum; a file without the
    // checksum (older files) still loads.
    assert!(text.contains("urdf_fnv1a64"));
    let other = sim::robots::builtin_urdf("ur10").expect("built-in ur10");
    let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
    v["robot"]["urdf"] = serde_json::json!(other);
    let e = CalibratedModel::from_json(&v.to_string(), "m.json")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("robot.urdf") && e.contains("changed after calibration"),
        "{e}"
    );
    let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
    v["robot"].as_object_mut().unwrap().remove("urdf_fnv1a64");
    assert!(CalibratedModel::from_json(&v.to_string(), "m.json").is_ok());
}

/// The exported URDF, loaded by the URDF reader and evaluated by sim's forward kinematics, with the
/// calibrated base transform and target, reproduces the true robot (noise-free calibration) to 1e-9 m.
#[test]
fn calibrated_urdf_reproduces_the_calibrated_robot() {
    for (name, seed) in [("iiwa7", 404), ("ur5", 405), ("wam", 406), ("ur10", 407)] {
        let (robot, truth, cal, mut g) = calibrated(name, false, seed);
        let out = calibrated_urdf(&CalibratedModel::new(&robot, &cal)).unwrap();
        let urdf = out.text.as_str();
        let spec = ChainSpec {
            base_link: Some(robot.model.base_link().to_string()),
            tip_link: Some(robot.model.tip_link().to_string()),
        };
        let exported = sim::urdf::load_str(urdf, "exported", &spec).unwrap();
        assert_eq!(exported.nq(), robot.model.nq());
        let default_chain = sim::urdf::load_str(urdf, "exported", &ChainSpec::default()).unwrap();
        assert_eq!(
            default_chain.tip_link(),
            robot.model.tip_link(),
            "the tip stays the default leaf"
        );
        let mut data = sim::Data::new(&exported);
        let mut worst = 0.0f64;
        for q in random_configs(&robot.model, 50, &mut g) {
            let t = cal.params.t_tracker_base * sim::flange_pose(&exported, &mut data, &q);
            let p = (t * Point3::from(cal.params.p_flange_target)).coords;
            worst = worst.max((p - truth.target(&robot.model, &q).0).norm());
        }
        eprintln!("{name}: exported URDF vs truth {worst:e} m");
        assert!(worst < 1e-9, "{name}: {worst:e}");
        // And against the calibrated model's own base-frame flange pose (the CLI's self-check).
        let qs = random_configs(&robot.model, 20, &mut g);
        assert!(out.deviation(&robot.model, &cal.params, &qs).unwrap() < 1e-12);
    }
}

#[test]
fn planned_poses_beat_random_ones_and_are_reproducible() {
    let model = robots::load_builtin("iiwa7").unwrap();
    let opts = PlanOptions::new(600, 20, 7);
    let plan = plan_poses(&model, &opts).unwrap();
    eprintln!(
        "log det {:.2} vs random {:.2} ± {:.2}; σ ratio {:.2}; position σ {:.2e} vs {:.2e}",
        plan.log_det,
        plan.random_log_det_mean,
        plan.random_log_det_std,
        plan.parameter_sigma_ratio,
        plan.position_sigma_m,
        plan.random_position_sigma_m
    );
    assert_eq!(plan.rank, 31);
    assert_eq!(plan.selected.len(), 20);
    assert!(plan.log_det > plan.random_log_det_mean + 3.0 * plan.random_log_det_std);
    assert!(
        plan.parameter_sigma_ratio > 1.0 && plan.position_sigma_m < plan.random_position_sigma_m
    );
    // Selected poses are within the limits and distinct.
    for q in &plan.selected {
        for (v, j) in q.iter().zip(model.joints()) {
            let l = j.limits.unwrap();
            assert!(*v >= l.lower && *v <= l.upper);
        }
    }
    let mut idx = plan.candidate_indices.clone();
    idx.sort();
    idx.dedup();
    assert_eq!(idx.len(), 20);
    // The criterion is what it says: recompute log det of the selection independently (SVD of the
    // stacked scaled Jacobian is not needed: the D-optimal value is invariant to the basis).
    let again = plan_poses(&model, &opts).unwrap();
    assert_eq!(plan.to_csv(), again.to_csv(), "same seed, same bytes");
    assert!(plan.to_csv().starts_with("pose,q1,q2,q3,q4,q5,q6,q7\n0,"));
    // Too few to select.
    let e = plan_poses(&model, &PlanOptions::new(600, 10, 7))
        .unwrap_err()
        .to_string();
    assert!(e.contains("at least 11 poses"), "{e}");
    // A calibration on the planned poses with noise is better on held-out poses than on random ones.
    let mut g = rng(408);
    let (mut err_plan, mut err_rand) = (0.0, 0.0);
    for _ in 0..5 {
        let truth = Truth::random(&model, false, &mut g);
        let test_q = random_configs(&model, 100, &mut g);
        for (poses, acc) in [
            (plan.selected.clone(), &mut err_plan),
            (random_configs(&model, 20, &mut g), &mut err_rand),
        ] {
            let t = table(&model, &truth, &poses, 1e-5, 0.0, &mut g);
            let cal = fit(
                &model,
                &Dataset::all(&t, "t"),
                &FitRequest::kinematic(&CalibrationOptions::default()),
            )
            .unwrap();
            let chain = calib::model::chain::Chain::new(&model, &cal.params);
            let mut s = calib::model::chain::ChainScratch::new(7);
            for q in &test_q {
                chain.forward(&mut s, q);
                *acc += (s.p_tracker - truth.target(&model, q).0).norm_squared();
            }
        }
    }
    eprintln!(
        "held-out RMS: planned {:.2e} m, random {:.2e} m",
        (err_plan / 500.0f64).sqrt(),
        (err_rand / 500.0f64).sqrt()
    );
    assert!(err_plan < err_rand);
}

/// Found by the fuzzing suite (`tests/fuzz.rs`, seed 15, the exit-0 listing of its value
/// mutations, e.g. a covariance entry replaced by 1e308 or −1e308): `predict` does not use the
/// covariance, so such files loaded and predicted without a word. A covariance must be square, finite,
/// symmetric, with variances ≥ 0 and |Cᵢⱼ| ≤ √(Cᵢᵢ Cⱼⱼ); each failure names the entry.
#[test]
fn fuzz_found_covariance_garbage_is_refused_naming_the_entry() {
    let (robot, _, cal, _) = calibrated("ur5", false, 404);
    let text = CalibratedModel::new(&robot, &cal).to_json();
    let base: serde_json::Value = serde_json::from_str(&text).unwrap();
    let refused = |edit: &dyn Fn(&mut serde_json::Value), needles: &[&str]| {
        let mut v = base.clone();
        edit(&mut v);
        let e = CalibratedModel::from_json(&v.to_string(), "m.json")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("m.json:") && !e.contains('\n'), "{e}");
        for n in needles {
            assert!(e.contains(n), "{n}: {e}");
        }
    };
    let m = |v: &mut serde_json::Value, i: usize, j: usize, x: f64| {
        v["covariance"]["matrix"][i][j] = serde_json::json!(x)
    };
    refused(&|v| m(v, 7, 3, 1e308), &["covariance.matrix'[7][3]"]);
    refused(
        &|v| {
            m(v, 7, 3, 1e308);
            m(v, 3, 7, 1e308)
        },
        &["covariance.matrix'[7][3]", "not a covariance"],
    );
    refused(&|v| m(v, 4, 4, -1e-9), &["[4][4]", "a variance is ≥ 0"]);
    refused(
        &|v| {
            v["covariance"]["matrix"]
                .as_array_mut()
                .unwrap()
                .truncate(5)
        },
        &["covariance.matrix", "not"],
    );
    refused(
        &|v| v["covariance"]["variance_factor"] = serde_json::json!(-1.0),
        &["variance_factor"],
    );
    // The covariance as written loads, and so does a model without one.
    assert!(CalibratedModel::from_json(&text, "m.json").is_ok());
    let mut v = base.clone();
    v["covariance"] = serde_json::Value::Null;
    assert!(CalibratedModel::from_json(&v.to_string(), "m.json").is_ok());
}
