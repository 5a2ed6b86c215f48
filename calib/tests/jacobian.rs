//! The analytic Jacobian of the kinematic error model against central finite differences, and the
//! prepared chain against the product of exponentials of the moved screws.

mod common;

use calib::fit::problem::{KinematicProblem, NoiseModel, Observations};
use calib::lm::LeastSquaresProblem;
use calib::model::chain::{Chain, ChainScratch};
use calib::model::params::{KinematicParams, ParamLayout};
use common::{Truth, random_configs, rng, table};
use nalgebra::DMatrix;
use sim::robots;

fn truth_params(t: &Truth) -> KinematicParams {
    KinematicParams::from_twists(
        &t.twists,
        t.zero_offsets.clone(),
        t.t_tracker_base,
        t.p_flange,
        t.r_flange_target,
    )
}

#[test]
fn chain_equals_product_of_exponentials_of_moved_screws() {
    for name in ["iiwa7", "ur5", "wam"] {
        let model = robots::load_builtin(name).unwrap();
        let mut g = rng(11);
        let truth = Truth::random(&model, true, &mut g);
        let chain = Chain::new(&model, &truth_params(&truth));
        let mut s = ChainScratch::new(model.nq());
        for q in random_configs(&model, 50, &mut g) {
            chain.forward(&mut s, &q);
            let (p, r) = truth.target(&model, &q);
            assert!(
                (s.p_tracker - p).amax() < 1e-12,
                "{name}: {}",
                (s.p_tracker - p).amax()
            );
            assert!((s.r_tracker_target - r).amax() < 1e-13, "{name}");
        }
    }
}

fn check_fd(name: &str, orientation: bool, seed: u64) {
    let model = robots::load_builtin(name).unwrap();
    let mut g = rng(seed);
    let truth = Truth::random(&model, orientation, &mut g);
    let configs = random_configs(&model, 12, &mut g);
    let t = table(&model, &truth, &configs, 0.0, 0.0, &mut g);
    let rows: Vec<usize> = (0..t.len()).collect();
    let obs = Observations::from_table(&t, &rows, &NoiseModel::default(), "test").unwrap();
    // Linearise somewhere else than the truth: other joint errors, the base moved by 5 cm and turned by
    // 0.3 rad, the target turned by 0.3 rad (rotation residuals well away from π, where the logarithm's
    // curvature would make central differences inaccurate).
    let mut other = Truth::random(&model, orientation, &mut g);
    let turn = |w: [f64; 3]| {
        sim::lie::exp_twist(&nalgebra::Vector6::new(w[0], w[1], w[2], 0.03, -0.04, 0.0))
    };
    other.t_tracker_base = turn([0.1, -0.2, 0.2]) * truth.t_tracker_base;
    other.r_flange_target = truth
        .r_flange_target
        .map(|r| r * turn([0.2, 0.2, -0.1]).rotation.matrix());
    let layout = ParamLayout::new(&model, orientation);
    let all: Vec<usize> = (0..layout.len()).collect();
    let mut prob = KinematicProblem::new(&model, &obs, truth_params(&other), all);
    let (m, p) = (prob.n_residuals(), prob.n_params());
    let mut j = DMatrix::zeros(m, p);
    prob.set_params(&vec![0.0; p]);
    prob.jacobian(&mut j);
    let coord_max = (0..obs.len())
        .map(|r| obs.position[r].amax() / obs.sigma[r])
        .fold(0.0, f64::max);
    let mut rp = vec![0.0; m];
    let mut rm = vec![0.0; m];
    for k in 0..p {
        let h = 1e-6;
        let mut step = vec![0.0; p];
        step[k] = h;
        prob.set_params(&step);
        prob.residuals(&mut rp);
        step[k] = -h;
        prob.set_params(&step);
        prob.residuals(&mut rm);
        let col = j.column(k);
        let scale = col.amax().max(1.0);
        let worst = (0..m)
            .map(|i| ((rp[i] - rm[i]) / (2.0 * h) - col[i]).abs())
            .fold(0.0, f64::max);
        // Truncation (h² times the curvature) plus the rounding of coordinates metres away from the
        // tracker, divided by σ ≈ 1e-5 m and by 2h.
        assert!(
            worst < 1e-6 * scale + 4.0 * f64::EPSILON * coord_max / (2.0 * h),
            "{name} orientation={orientation} column {k} ({}): error {worst:e} of {scale:e}",
            layout.name(k)
        );
    }
}

#[test]
fn analytic_jacobian_matches_central_differences_positions() {
    check_fd("iiwa7", false, 21);
    check_fd("ur5", false, 22);
}

#[test]
fn analytic_jacobian_matches_central_differences_with_orientation() {
    check_fd("iiwa7", true, 23);
    check_fd("wam", true, 24);
}

#[test]
fn normal_equations_equal_the_jacobian_products() {
    let model = robots::load_builtin("iiwa7").unwrap();
    let mut g = rng(31);
    let truth = Truth::random(&model, true, &mut g);
    let configs = random_configs(&model, 10, &mut g);
    let t = table(&model, &truth, &configs, 1e-5, 1e-4, &mut g);
    let rows: Vec<usize> = (0..t.len()).collect();
    let obs = Observations::from_table(&t, &rows, &NoiseModel::default(), "test").unwrap();
    let layout = ParamLayout::new(&model, true);
    let active: Vec<usize> = (0..layout.len()).filter(|k| k % 3 != 1).collect();
    let mut prob = KinematicProblem::new(&model, &obs, KinematicParams::nominal(7, true), active);
    let (m, p) = (prob.n_residuals(), prob.n_params());
    let scales: Vec<f64> = (0..p).map(|k| 0.5 + k as f64 * 0.01).collect();
    prob.set_params(&vec![0.0; p]);
    let mut j = DMatrix::zeros(m, p);
    prob.jacobian(&mut j);
    let mut r = vec![0.0; m];
    prob.residuals(&mut r);
    let mut gram = DMatrix::zeros(p, p);
    let mut grad = vec![0.0; p];
    let cost = prob.normal_equations(&scales, &mut gram, &mut grad);
    let js = &j * DMatrix::from_diagonal(&nalgebra::DVector::from_vec(scales.clone()));
    let g2 = js.tr_mul(&js);
    let rv = nalgebra::DVector::from_vec(r.clone());
    let gr2 = js.tr_mul(&rv);
    assert!((gram - &g2).amax() <= 1e-12 * g2.amax());
    assert!((nalgebra::DVector::from_vec(grad) - &gr2).amax() <= 1e-12 * gr2.amax());
    assert!((cost - rv.norm_squared()).abs() <= 1e-12 * cost);
}

/// Every column of an extended model, with every cause at once (the bending and transmission-error
/// terms among them) and at a linearisation point where every extension value is non-zero (bends of
/// up to 0.02 rad, so that the left Jacobian of the bend matters), against central differences:
/// positions alone and with orientation, and with two campaigns (the rows alternate between two tracker
/// placements, each with its own target: the bends are the robot's, the registration the row's).
#[test]
fn extended_jacobian_matches_central_differences() {
    use calib::fit::{CalibrationOptions, Dataset, observations};
    use calib::model::extensions::ExtensionSettings;
    use calib::model::spec::ModelSpec;
    use rand::RngExt;
    use sim::measurement_table::{MeasurementTable, OptionalColumns, Row};
    for (name, orientation, seed, two_campaigns) in [
        ("iiwa7", false, 41, false),
        ("iiwa7", true, 42, false),
        ("ur5", true, 43, false),
        ("iiwa7", true, 44, true),
    ] {
        let model = robots::load_builtin(name).unwrap();
        let mut g = rng(seed);
        let truth = Truth::random(&model, orientation, &mut g);
        let configs = random_configs(&model, 12, &mut g);
        let cols = OptionalColumns {
            orientation,
            temp: true,
            dir: true,
            payload: true,
            campaign: two_campaigns,
            ..OptionalColumns::NONE
        };
        let mut t = MeasurementTable::new(model.nq(), cols);
        for (k, q) in configs.iter().enumerate() {
            let (p, r) = truth.target(&model, q);
            let uq = nalgebra::UnitQuaternion::from_rotation_matrix(
                &nalgebra::Rotation3::from_matrix_unchecked(r),
            );
            let dir: Vec<i8> = (0..model.nq())
                .map(|_| if g.random::<bool>() { 1 } else { -1 })
                .collect();
            t.push_row(&Row {
                pose: k as i64,
                q,
                position: [p.x, p.y, p.z],
                orientation: orientation.then_some([uq.w, uq.i, uq.j, uq.k]),
                temp: Some(20.0 + g.random_range(0.0..10.0)),
                dir: Some(&dir),
                payload: Some([0.0, 2.0, 5.0][k % 3]),
                campaign: two_campaigns.then_some(3 * (k % 2) as i64),
                ..Row::default()
            })
            .unwrap();
        }
        let rows: Vec<usize> = (0..t.len()).collect();
        let spec = ModelSpec::parse(
            "kinematic+joint_compliance+gear_backlash+thermal_drift+transmission_error+link_deflection",
        )
        .unwrap();
        let mut settings =
            ExtensionSettings::for_data(&model, &spec.causes, &spec.joints, &t, &rows, "t")
                .unwrap();
        settings.payload_com_m = [0.01, -0.02, 0.06];
        let n_ext = settings.params(&model).len();
        let at: Vec<f64> = settings
            .params(&model)
            .iter()
            .enumerate()
            .map(|(e, p)| p.scale * (3.0 + 0.1 * e as f64) * if e % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        let obs = observations(
            &model,
            &Dataset::all(&t, "t"),
            &CalibrationOptions::default(),
            Some(&settings),
            // Torques on the nominal robot, at the extension values `at`.
            Some(
                &calib::model::params::KinematicParams::nominal(model.nq(), false)
                    .with_extension(at.clone()),
            ),
        )
        .unwrap();
        let mut params = truth_params(&truth).with_extension(at.clone());
        params.t_tracker_base =
            sim::lie::exp_twist(&nalgebra::Vector6::new(0.1, -0.2, 0.2, 0.03, -0.04, 0.0))
                * params.t_tracker_base;
        if two_campaigns {
            let moved =
                sim::lie::exp_twist(&nalgebra::Vector6::new(-0.3, 0.1, 0.6, 0.5, 0.2, -0.1))
                    * params.t_tracker_base;
            params = params.with_campaigns(&[0, 3], &[moved], true);
            params.campaigns[0].p_flange_target =
                Some(params.p_flange_target + nalgebra::Vector3::new(0.01, -0.02, 0.005));
        }
        let layout = ParamLayout::for_params(&model, &params, obs.ext.params.clone());
        assert_eq!(layout.n_campaigns(), if two_campaigns { 2 } else { 1 });
        assert_eq!(
            layout.len(),
            layout.kinematic_len() + n_ext,
            "{name}: parameters"
        );
        let all: Vec<usize> = (0..layout.len()).collect();
        let mut prob = KinematicProblem::new(&model, &obs, params, all);
        let (m, p) = (prob.n_residuals(), prob.n_params());
        let mut j = DMatrix::zeros(m, p);
        prob.set_params(&vec![0.0; p]);
        prob.jacobian(&mut j);
        let coord_max = (0..obs.len())
            .map(|r| obs.position[r].amax() / obs.sigma[r])
            .fold(0.0, f64::max);
        let (mut rp, mut rm) = (vec![0.0; m], vec![0.0; m]);
        let mut bends_seen = 0;
        for k in 0..p {
            // A step of 1e-2 of the parameter's scale: small against its curvature, large against
            // rounding (extension scales are 1e-6 to 1e-4, kinematic ones 1e-4 to 1).
            let h = if k >= layout.kinematic_len() {
                1e-2 * layout.extensions[k - layout.kinematic_len()].scale
            } else {
                1e-6
            };
            let mut step = vec![0.0; p];
            step[k] = h;
            prob.set_params(&step);
            prob.residuals(&mut rp);
            step[k] = -h;
            prob.set_params(&step);
            prob.residuals(&mut rm);
            let col = j.column(k);
            let scale = col.amax().max(1.0);
            let worst = (0..m)
                .map(|i| ((rp[i] - rm[i]) / (2.0 * h) - col[i]).abs())
                .fold(0.0, f64::max);
            assert!(
                worst < 1e-6 * scale + 4.0 * f64::EPSILON * coord_max / (2.0 * h),
                "{name} orientation={orientation} column {k} ({}): error {worst:e} of {scale:e}",
                if k >= layout.kinematic_len() {
                    layout.extensions[k - layout.kinematic_len()].name()
                } else {
                    layout.name(k)
                }
            );
            if k >= layout.kinematic_len()
                && matches!(
                    layout.extensions[k - layout.kinematic_len()].term,
                    calib::model::extensions::Term::Bend { .. }
                )
                && col.amax() > 1.0
            {
                bends_seen += 1;
            }
        }
        assert!(
            bends_seen >= 2 * (model.nq() - 2),
            "{name}: only {bends_seen} bend columns moved the target"
        );
    }
}

/// A bent chain is the robot whose links are turned by the bends: `Chain::forward_bent` with nominal
/// parameters against `sim`'s forward kinematics of a model in which each link's frame is turned by
/// its joint's bend after the joint's rotation: the next joint's origin (or the flange offset)
/// becomes `exp([φᵢ]) Oᵢ₊₁`.
#[test]
fn bent_chain_equals_the_robot_with_turned_links() {
    use calib::lie3::exp_rotation;
    use nalgebra::Vector3;
    use sim::lie::{Pose, pose_from};
    for name in ["iiwa7", "ur5", "wam"] {
        let model = robots::load_builtin(name).unwrap();
        let mut g = rng(51);
        let params = KinematicParams::nominal(model.nq(), false);
        let chain = Chain::new(&model, &params);
        let mut s = ChainScratch::new(model.nq());
        let n = model.nq();
        for q in random_configs(&model, 20, &mut g) {
            let bend: Vec<Vector3<f64>> = (0..n)
                .map(|i| Vector3::new(1e-3 * (i as f64 - 2.0), -2e-3, 5e-4 * i as f64) * q[0].cos())
                .collect();
            let turn = |b: &Vector3<f64>| -> Pose { pose_from(exp_rotation(b), Vector3::zeros()) };
            let mut bent = model.clone();
            for i in 1..n {
                let origin = turn(&bend[i - 1]) * model.joints()[i].origin;
                bent = bent.with_joint_origin(i, origin).unwrap();
            }
            let bent = bent
                .with_flange_offset(turn(&bend[n - 1]) * model.flange_offset())
                .unwrap();
            let mut data = sim::Data::new(&bent);
            let flange = sim::flange_pose(&bent, &mut data, &q);
            chain.forward_bent(&mut s, &q, 0, &bend);
            assert!(
                (s.p_tracker - flange.translation.vector).amax() < 1e-14,
                "{name}: {}",
                (s.p_tracker - flange.translation.vector).amax()
            );
            assert!(
                (s.t_tracker_flange.rotation.matrix() - flange.rotation.matrix()).amax() < 1e-14
            );
        }
    }
}
