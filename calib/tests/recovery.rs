//! Recovery of injected kinematic errors from synthetic measurements (truth from `common`, evaluated
//! with the product of exponentials of the moved screws).

mod common;

use calib::fit::{CalibrationOptions, Dataset, FitRequest, fit};
use common::{Truth, random_configs, rng, table};
use sim::robots;

#[test]
fn noise_free_errors_are_recovered_to_1e9_m_on_held_out_poses() {
    for (name, orientation, seed) in [
        ("iiwa7", false, 101),
        ("ur5", false, 102),
        ("wam", true, 103),
        ("iiwa7", true, 104),
    ] {
        let model = robots::load_builtin(name).unwrap();
        let mut g = rng(seed);
        let truth = Truth::random(&model, orientation, &mut g);
        let train = table(
            &model,
            &truth,
            &random_configs(&model, 60, &mut g),
            0.0,
            0.0,
            &mut g,
        );
        let test_q = random_configs(&model, 40, &mut g);
        let cal = fit(
            &model,
            &Dataset::all(&train, "train"),
            &FitRequest::kinematic(&CalibrationOptions::default()),
        )
        .unwrap();
        eprintln!("{}", cal.report.text());
        assert!(
            cal.report.was_successful(),
            "{name}: {:?}",
            cal.report.after.solver
        );
        assert!(
            cal.report.health.is_clean(),
            "{name}: {}",
            cal.report.health
        );
        let chain = calib::model::chain::Chain::new(&model, &cal.params);
        let mut s = calib::model::chain::ChainScratch::new(model.nq());
        let mut worst = 0.0f64;
        let mut worst_rot = 0.0f64;
        for q in &test_q {
            chain.forward(&mut s, q);
            let (p, r) = truth.target(&model, q);
            worst = worst.max((s.p_tracker - p).norm());
            if orientation {
                worst_rot = worst_rot.max((s.r_tracker_target - r).amax());
            }
        }
        eprintln!("{name}: worst held-out error {worst:e} m, rotation {worst_rot:e}");
        assert!(worst < 1e-9, "{name}: held-out error {worst:e} m");
        assert!(
            worst_rot < 1e-9,
            "{name}: held-out rotation error {worst_rot:e}"
        );
    }
}

/// With Gaussian noise, the estimate's errors must match its covariance: every identifiable combination
/// within its predicted σ (tested as a distribution), and held-out prediction errors against the
/// noise-free truth as large as the covariance predicts.
///
/// The identifiable combinations are read off the predictions at the training poses (gauge-free: the
/// truth's parameters differ from the estimate's by null-space directions, predictions do not): with
/// `J` the Jacobian of those predictions and `C` the estimate's covariance, `M = J C Jᵀ` has rank r; its
/// eigenvectors `e_k` (eigenvalues `λ_k > 0`) are the identifiable combinations, and for a correct
/// covariance `z_k = e_kᵀ (p_estimated − p_true) / √λ_k` are independent standard normal.
fn noisy_recovery(name: &str, orientation: bool, reps: usize, seed: u64) {
    let model = robots::load_builtin(name).unwrap();
    let mut g = rng(seed);
    let sigma = 1e-5;
    let options = CalibrationOptions::default();
    let (mut zs, mut held_err2, mut held_pred2) = (Vec::new(), 0.0, 0.0);
    for rep in 0..reps {
        let truth = Truth::random(&model, orientation, &mut g);
        let configs = random_configs(&model, 100, &mut g);
        let train = common::table_with(
            &model,
            &truth,
            &configs,
            sigma,
            options.noise.orientation_sigma_rad,
            Some(sigma),
            &mut g,
        );
        let cal = fit(
            &model,
            &Dataset::all(&train, "train"),
            &FitRequest::kinematic(&options),
        )
        .unwrap();
        assert!(
            cal.report.was_successful(),
            "rep {rep}: {:?}",
            cal.report.after.solver
        );
        assert!(
            cal.report.health.is_clean(),
            "rep {rep}: {}",
            cal.report.health
        );
        let c = &cal.covariance;
        // Identifiable combinations at the training poses.
        let np = c.nrows();
        let dim = if orientation { 6 } else { 3 };
        let mut j = nalgebra::DMatrix::zeros(dim * configs.len(), np);
        let mut d = nalgebra::DVector::zeros(dim * configs.len());
        for (k, q) in configs.iter().enumerate() {
            let (p, rot, jq) = calib::fit::prediction_and_jacobian(&model, &cal.params, q).unwrap();
            j.view_mut((dim * k, 0), (dim, np)).copy_from(&jq);
            let (pt, rt) = truth.target(&model, q);
            d.fixed_rows_mut::<3>(dim * k).copy_from(&(p - pt));
            if orientation {
                // Rotation error as a tracker-frame rotation vector, log(R_est R_trueᵀ).
                let e = sim::lie::log_pose(&sim::lie::pose_from(
                    rot * rt.transpose(),
                    nalgebra::Vector3::zeros(),
                ));
                d.fixed_rows_mut::<3>(dim * k + 3)
                    .copy_from(&e.fixed_rows::<3>(0));
            }
        }
        let m = &j * c * j.transpose();
        let eig = m.symmetric_eigen();
        let r = cal.report.observability.rank;
        let mut order: Vec<usize> = (0..eig.eigenvalues.len()).collect();
        order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
        // The covariance has exactly r non-zero directions in prediction space.
        assert!(
            eig.eigenvalues[order[r]] < 1e-8 * eig.eigenvalues[order[r - 1]],
            "rank of J C Jᵀ"
        );
        for &k in &order[..r] {
            zs.push(eig.eigenvectors.column(k).dot(&d) / eig.eigenvalues[k].sqrt());
        }
        // Held-out poses: error against the noise-free truth vs trace(J C Jᵀ).
        for q in random_configs(&model, 100, &mut g) {
            let (p, _, jq) = calib::fit::prediction_and_jacobian(&model, &cal.params, &q).unwrap();
            let (pt, _) = truth.target(&model, &q);
            held_err2 += (p - pt).norm_squared();
            let jp = jq.rows(0, 3);
            held_pred2 += (jp * c * jp.transpose()).trace();
        }
    }
    let n = zs.len();
    let beyond3 = zs.iter().filter(|z| z.abs() > 3.0).count();
    let mean_sq = zs.iter().map(|z| z * z).sum::<f64>() / n as f64;
    let worst = zs.iter().map(|z| z.abs()).fold(0.0, f64::max);
    let ratio = (held_err2 / held_pred2).sqrt();
    eprintln!(
        "{name} orientation={orientation}: {n} identifiable combinations, {beyond3} beyond 3σ (expected {:.1}), \
         mean z² {mean_sq:.3}, max |z| {worst:.2}; held-out RMS error / predicted = {ratio:.3} \
         (RMS error {:.2} µm)",
        n as f64 * 0.0027,
        (held_err2 / (100.0 * reps as f64)).sqrt() * 1e6
    );
    // Under a correct covariance: P(|z| > 3) = 0.27 %; more than 1 % of n beyond 3σ has probability
    // below 1e-3 for n ≥ 300; mean z² has standard deviation √(2/n), so ±0.3 is beyond 4σ for n ≥ 300;
    // max |z| > 4.5 has probability n · 6.8e-6 < 1 %.
    assert!(n >= 300);
    assert!(
        beyond3 as f64 <= 0.01 * n as f64 + 1.0,
        "{beyond3} of {n} combinations beyond 3σ"
    );
    assert!((mean_sq - 1.0).abs() < 0.3, "mean z² = {mean_sq}");
    assert!(worst < 4.5, "max |z| = {worst}");
    assert!(
        ratio <= 1.2,
        "held-out error is {ratio:.3} × what the covariance predicts"
    );
    assert!(
        ratio >= 0.8,
        "held-out error is only {ratio:.3} × what the covariance predicts (too pessimistic)"
    );
}

#[test]
fn noisy_positions_recover_identifiable_combinations_within_predicted_sigma() {
    noisy_recovery("iiwa7", false, 10, 201);
}

#[test]
fn noisy_poses_with_orientation_recover_identifiable_combinations_within_predicted_sigma() {
    noisy_recovery("ur5", true, 10, 202);
}
