//! Measurement campaigns (each its own tracker placement, the robot shared), `register`, and the
//! model fitted on every pose with its cross-validated held-out estimate. The truth is evaluated
//! independently of the estimator (`common`: the product of exponentials of the moved screws). Seeds
//! are drawn per run and printed (`ROBOCAL_TEST_SEED=N` repeats one); every threshold is set for a
//! false-alarm probability below 1e-3 per run under a correct covariance.

mod common;

use calib::fit::problem::{NoiseModel, Observations};
use calib::fit::register::{RegisterOptions, register};
use calib::fit::{CalibrationOptions, Dataset, FitRequest, fit};
use calib::model::chain::{Chain, ChainScratch};
use calib::model::params::{KinematicParams, ParamLayout};
use calib::model::predict::Prediction;
use calib::model::spec::ModelSpec;
use calib::validate::{cross_validate, fold_calibrations};
use common::{Truth, concat, moved_tracker, random_configs, with_campaign};
use nalgebra::{DMatrix, DVector, Matrix6, Vector6};
use rand::SeedableRng;
use rand::rngs::StdRng;
use sim::lie::{Pose, adjoint, log_pose};
use sim::{Model, robots};

const SIGMA: f64 = 1e-5;

/// A noisy table of `truth` with a `sigma` column.
fn noisy(
    model: &Model,
    truth: &Truth,
    configs: &[Vec<f64>],
    rng: &mut StdRng,
) -> sim::measurement_table::MeasurementTable {
    common::table_with(model, truth, configs, SIGMA, 1e-4, Some(SIGMA), rng)
}

/// The identifiable combinations' standardised errors `z`: the predictions at `rows` (joint values,
/// campaign index, truth) in each campaign's frame, whitened by the eigenvectors of `J C Jᵀ` (see
/// `recovery.rs`): independent standard normal under a correct covariance.
fn identifiable_z(
    model: &Model,
    params: &KinematicParams,
    cov: &DMatrix<f64>,
    rank: usize,
    rows: &[(Vec<f64>, usize, &Truth)],
) -> Vec<f64> {
    let layout = ParamLayout::for_params(model, params, Vec::new());
    let np = layout.len();
    assert_eq!(cov.nrows(), np);
    let chain = Chain::new(model, params);
    let mut s = ChainScratch::new(model.nq());
    let mut j = DMatrix::zeros(3 * rows.len(), np);
    let mut d = DVector::zeros(3 * rows.len());
    let mut buf = vec![0.0; 3 * np];
    for (k, (q, c, truth)) in rows.iter().enumerate() {
        chain.forward_in(&mut s, q, *c);
        chain.position_jacobian(&s, &layout, &mut buf);
        j.view_mut((3 * k, 0), (3, np))
            .copy_from(&DMatrix::from_row_slice(3, np, &buf));
        let (pt, _) = truth.target(model, q);
        d.fixed_rows_mut::<3>(3 * k).copy_from(&(s.p_tracker - pt));
    }
    let m = &j * cov * j.transpose();
    let eig = m.symmetric_eigen();
    let mut order: Vec<usize> = (0..eig.eigenvalues.len()).collect();
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    assert!(
        eig.eigenvalues[order[rank]] < 1e-8 * eig.eigenvalues[order[rank - 1]],
        "rank of J C Jᵀ"
    );
    order[..rank]
        .iter()
        .map(|&k| eig.eigenvectors.column(k).dot(&d) / eig.eigenvalues[k].sqrt())
        .collect()
}

/// Whitened components `C^{-1/2} δ` of a 6-vector error with covariance `c`.
fn whiten(delta: &Vector6<f64>, c: &Matrix6<f64>) -> Vec<f64> {
    let eig = c.symmetric_eigen();
    (0..6)
        .map(|k| eig.eigenvectors.column(k).dot(delta) / eig.eigenvalues[k].sqrt())
        .collect()
}

/// False-alarm probability of each of the three checks of [`assert_standard_normal`] under a
/// correct covariance: together below 1e-3 per call.
const CHECK_FALSE_ALARM: f64 = 3e-4;

/// Distribution checks of `n` independent standard normal `z`, each with false-alarm probability
/// [`CHECK_FALSE_ALARM`] (thresholds from the exact distributions, not a fixed number of σ: a fixed
/// "mean z² within 4 standard errors, none beyond 4.5σ" fails 2.3 times in 1000 at n = 120, because
/// χ²'s right tail is longer than the normal's and 120 values reach 4.5σ 8 times in 10,000):
/// - `n · mean z²` is χ²(n): its Wilson–Hilferty normal equivalent within the two-sided quantile;
/// - the count beyond 3σ is Binomial(n, 0.0027): at most its upper quantile;
/// - the largest `|z|` below the quantile of the maximum of `n` (`P(|z| > t) = CHECK_FALSE_ALARM / n`).
fn assert_standard_normal(zs: &[f64], what: &str) {
    use calib::select::diagnose::significance::{chi2_to_z, normal_quantile};
    let n = zs.len();
    let mean_sq = zs.iter().map(|z| z * z).sum::<f64>() / n as f64;
    let beyond3 = zs.iter().filter(|z| z.abs() > 3.0).count();
    let worst = zs.iter().map(|z| z.abs()).fold(0.0, f64::max);
    let z_mean = chi2_to_z(mean_sq * n as f64, n as f64);
    let z_mean_max = -normal_quantile(CHECK_FALSE_ALARM / 2.0);
    let beyond3_max = binomial_upper_quantile(n, 2.0 * (1.0 - NORMAL_CDF_3), CHECK_FALSE_ALARM);
    let worst_max = -normal_quantile(CHECK_FALSE_ALARM / (2.0 * n as f64));
    eprintln!(
        "{what}: {n} values, mean z² {mean_sq:.3} (χ² as z {z_mean:.2}, limit {z_mean_max:.2}), \
         {beyond3} beyond 3σ (limit {beyond3_max}), max |z| {worst:.2} (limit {worst_max:.2})"
    );
    assert!(z_mean.abs() < z_mean_max, "{what}: mean z² = {mean_sq}");
    assert!(beyond3 <= beyond3_max, "{what}: {beyond3} beyond 3σ");
    assert!(worst < worst_max, "{what}: max |z| = {worst}");
}

/// `Φ(3)`, the standard normal CDF at 3.
const NORMAL_CDF_3: f64 = 0.998_650_101_968_369_9;

/// The smallest `k` with `P(Binomial(n, p) > k) ≤ alpha`.
fn binomial_upper_quantile(n: usize, p: f64, alpha: f64) -> usize {
    let mut pmf = (1.0 - p).powi(n as i32);
    let mut cdf = pmf;
    let mut k = 0;
    while 1.0 - cdf > alpha && k < n {
        pmf *= (n - k) as f64 / (k + 1) as f64 * p / (1.0 - p);
        cdf += pmf;
        k += 1;
    }
    k
}

#[test]
fn two_campaigns_share_the_robot_and_both_registrations_are_within_sigma() {
    let model = robots::load_builtin("ur5").unwrap();
    let mut g = StdRng::seed_from_u64(common::run_seed("two campaigns"));
    let options = CalibrationOptions::default();
    let (mut robot_z, mut registration_z) = (Vec::new(), Vec::new());
    for rep in 0..4 {
        let a = Truth::random(&model, false, &mut g);
        let b = moved_tracker(&a, &mut g);
        let (qa, qb) = (
            random_configs(&model, 80, &mut g),
            random_configs(&model, 60, &mut g),
        );
        let table = concat(
            &with_campaign(&noisy(&model, &a, &qa, &mut g), 3),
            &with_campaign(&noisy(&model, &b, &qb, &mut g), 8),
        );
        let cal = fit(
            &model,
            &Dataset::all(&table, "two"),
            &FitRequest::kinematic(&options),
        )
        .unwrap();
        assert!(cal.report.was_successful(), "rep {rep}");
        assert!(cal.report.health.is_clean(), "{}", cal.report.health);
        assert_eq!(cal.params.campaign_ids, vec![3, 8]);
        // 4R + 3 for the robot and the first registration, 6 for the second.
        assert_eq!(cal.report.observability.rank, 4 * 6 + 3 + 6);
        let rows: Vec<(Vec<f64>, usize, &Truth)> = qa
            .iter()
            .map(|q| (q.clone(), 0, &a))
            .chain(qb.iter().map(|q| (q.clone(), 1, &b)))
            .collect();
        robot_z.extend(identifiable_z(
            &model,
            &cal.params,
            &cal.covariance,
            cal.report.observability.rank,
            &rows,
        ));
        // The registration of campaign 8 relative to campaign 3, T_B T_A⁻¹: free of the gauge that
        // trades the base transforms against a common error twist of all axes. Its left-perturbation
        // error is β_B − Ad(T_rel) β_A in the step parameters.
        let layout = ParamLayout::for_params(&model, &cal.params, Vec::new());
        let est = cal.params.t_tracker_base_of(1) * cal.params.t_tracker_base_of(0).inverse();
        let truth = b.t_tracker_base * a.t_tracker_base.inverse();
        let mut l = DMatrix::zeros(6, layout.len());
        let ad = adjoint(&est);
        for i in 0..6 {
            l[(i, layout.campaign_base(1) + i)] = 1.0;
            for k in 0..6 {
                l[(i, layout.campaign_base(0) + k)] = -ad[(i, k)];
            }
        }
        let c_rel = &l * &cal.covariance * l.transpose();
        let delta = log_pose(&(truth * est.inverse()));
        registration_z.extend(whiten(&delta, &Matrix6::from_fn(|i, j| c_rel[(i, j)])));
    }
    assert_standard_normal(
        &robot_z,
        "robot and registrations (identifiable combinations)",
    );
    assert_standard_normal(&registration_z, "relative registration");
}

#[test]
fn register_recovers_a_moved_tracker_within_its_predicted_sigma() {
    let model = robots::load_builtin("ur5").unwrap();
    let mut g = StdRng::seed_from_u64(common::run_seed("register"));
    let (mut zs, mut factors) = (Vec::new(), Vec::new());
    for rep in 0..20 {
        let a = Truth::random(&model, false, &mut g);
        // The robot known exactly (noise-free calibration): the registration alone is uncertain.
        let qa = random_configs(&model, 60, &mut g);
        let train = common::table(&model, &a, &qa, 0.0, 0.0, &mut g);
        let cal = fit(
            &model,
            &Dataset::all(&train, "a"),
            &FitRequest::kinematic(&CalibrationOptions::default()),
        )
        .unwrap();
        let b = moved_tracker(&a, &mut g);
        let qb = random_configs(&model, 20, &mut g);
        let new = noisy(&model, &b, &qb, &mut g);
        let reg = register(
            &model,
            &cal.params,
            None,
            None,
            None,
            &new,
            "b",
            &RegisterOptions::default(),
        )
        .unwrap();
        assert_eq!(reg.params.campaign_ids, vec![0, 1], "rep {rep}");
        assert_eq!(reg.params.default_campaign, 1);
        assert!(reg.report.solver.was_successful());
        // The estimated robot equals the truth up to a gauge g, T_A,est = T_A g⁻¹; in that gauge the
        // new tracker is T_B T_A⁻¹ T_A,est.
        let expected: Pose =
            b.t_tracker_base * a.t_tracker_base.inverse() * cal.params.t_tracker_base;
        let got = reg.params.t_tracker_base_of(1);
        let delta = log_pose(&(expected * got.inverse()));
        // The reported covariance is scaled by σ̂² = χ²/dof, so `delta` whitened by it follows
        // Student's t with 54 degrees of freedom (mean z² 54/52, tails that a normal check flags
        // several times in 1000 runs). Whitened by the noise model's covariance (σ̂² divided out) it
        // is standard normal; σ̂² itself is checked against its χ²(54)/54 distribution below.
        let vf = reg.report.variance_factor;
        let c = Matrix6::from_fn(|i, j| reg.report.covariance[i][j]) / vf;
        zs.extend(whiten(&delta, &c));
        factors.push(vf);
        // Every robot parameter is kept.
        assert_eq!(reg.params.joint_error, cal.params.joint_error);
        assert_eq!(reg.params.zero_offset, cal.params.zero_offset);
        assert_eq!(reg.params.p_flange_target, cal.params.p_flange_target);
    }
    assert_standard_normal(&zs, "registered tracker pose");
    // 20 poses × 3 coordinates − 6 registration parameters: σ̂² ~ χ²(54)/54, mean 1, variance 2/54.
    let dof = 54.0;
    let mean = factors.iter().sum::<f64>() / factors.len() as f64;
    let se = (2.0 / dof / factors.len() as f64).sqrt();
    eprintln!(
        "variance factor: mean {mean:.3} over {} registrations (σ {se:.3})",
        factors.len()
    );
    assert!((mean - 1.0).abs() < 4.0 * se, "variance factor mean {mean}");
}

/// Bit-for-bit equality of two parameter points.
fn assert_same_params(a: &KinematicParams, b: &KinematicParams, what: &str) {
    let bits = |p: &KinematicParams| -> Vec<u64> {
        let mut v: Vec<f64> = Vec::new();
        for g in &p.joint_error {
            v.extend(g.to_homogeneous().iter());
        }
        v.extend(&p.zero_offset);
        v.extend(p.t_tracker_base.to_homogeneous().iter());
        v.extend(p.p_flange_target.iter());
        v.extend(&p.extension);
        v.iter().map(|x| x.to_bits()).collect()
    };
    assert_eq!(bits(a), bits(b), "{what}: parameters differ");
}

#[test]
fn a_campaign_column_with_one_value_gives_exactly_the_result_of_no_column() {
    let model = robots::load_builtin("iiwa7").unwrap();
    let mut g = StdRng::seed_from_u64(common::run_seed("one campaign"));
    let truth = Truth::random(&model, false, &mut g);
    let plain = noisy(&model, &truth, &random_configs(&model, 60, &mut g), &mut g);
    let tagged = with_campaign(&plain, 7);
    let test_plain = noisy(&model, &truth, &random_configs(&model, 20, &mut g), &mut g);
    let test_tagged = with_campaign(&test_plain, 7);
    let options = CalibrationOptions::default();
    for spec in [
        "kinematic",
        "kinematic+joint_compliance",
        "kinematic+learned:poly",
        "kinematic+learned:adjoint",
    ] {
        let spec: ModelSpec = spec.parse().unwrap();
        let a = fit(
            &model,
            &Dataset::all(&plain, "d"),
            &FitRequest::new(&spec, &options).judged_on(Some(&Dataset::all(&test_plain, "t"))),
        )
        .unwrap();
        let b = fit(
            &model,
            &Dataset::all(&tagged, "d"),
            &FitRequest::new(&spec, &options).judged_on(Some(&Dataset::all(&test_tagged, "t"))),
        )
        .unwrap();
        let what = spec.name();
        assert_same_params(&a.params, &b.params, &what);
        assert_same_params(&a.before, &b.before, &what);
        assert_eq!(b.params.campaign_ids, vec![7]);
        assert_eq!(
            a.covariance.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            b.covariance.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            "{what}: covariance"
        );
        assert_eq!(
            serde_json::to_string(&a.report).unwrap(),
            serde_json::to_string(&b.report).unwrap(),
            "{what}: report"
        );
        assert_eq!(a.learned, b.learned, "{what}: learned correction");
        // Predictions, with and without the column.
        let oa = Observations::from_table(
            &test_plain,
            &(0..20).collect::<Vec<_>>(),
            &NoiseModel::default(),
            "t",
        )
        .unwrap();
        let ob = Observations::from_table(
            &test_tagged,
            &(0..20).collect::<Vec<_>>(),
            &NoiseModel::default(),
            "t",
        )
        .unwrap();
        if a.extensions.is_none() {
            let ea = Prediction::new(&model, &a.params)
                .with_learned(a.learned.as_ref())
                .errors(&oa);
            let eb = Prediction::new(&model, &b.params)
                .with_learned(b.learned.as_ref())
                .errors(&ob);
            let bits = |e: &[nalgebra::Vector3<f64>]| -> Vec<u64> {
                e.iter()
                    .flat_map(|v| v.iter().map(|x| x.to_bits()))
                    .collect()
            };
            assert_eq!(bits(&ea), bits(&eb), "{what}: predictions");
        }
    }
    // Cross-validation folds by pose are the same too.
    let va = cross_validate(
        &model,
        &Dataset::all(&plain, "d"),
        &FitRequest::new(&ModelSpec::kinematic(), &options),
        5,
        1,
        None,
    )
    .unwrap();
    let vb = cross_validate(
        &model,
        &Dataset::all(&tagged, "d"),
        &FitRequest::new(&ModelSpec::kinematic(), &options),
        5,
        1,
        None,
    )
    .unwrap();
    assert_eq!(va, vb);
}

#[test]
fn the_all_pose_model_meets_its_predicted_accuracy_and_the_folds_agree_with_a_true_held_out_set() {
    let model = robots::load_builtin("iiwa7").unwrap();
    let mut g = StdRng::seed_from_u64(common::run_seed("all poses"));
    let options = CalibrationOptions::default();
    let (mut err2, mut pred2, mut n_held) = (0.0, 0.0, 0usize);
    let mut deviations = Vec::new();
    // Ten calibrations for the accuracy bar (its ratio then has a standard deviation of about 0.05),
    // the first three also cross-validated.
    for rep in 0..10 {
        let truth = Truth::random(&model, false, &mut g);
        let table = noisy(&model, &truth, &random_configs(&model, 150, &mut g), &mut g);
        let data = Dataset::all(&table, "all");
        let cal = fit(&model, &data, &FitRequest::kinematic(&options)).unwrap();
        assert!(cal.report.was_successful(), "rep {rep}");
        // Held-out poses against the noise-free truth: the error the covariance predicts.
        let held = random_configs(&model, 100, &mut g);
        for q in &held {
            let (p, _, jq) = calib::fit::prediction_and_jacobian(&model, &cal.params, q).unwrap();
            let (pt, _) = truth.target(&model, q);
            err2 += (p - pt).norm_squared();
            let jp = jq.rows(0, 3);
            pred2 += (jp * &cal.covariance * jp.transpose()).trace();
            n_held += 1;
        }
        if rep >= 3 {
            continue;
        }
        // The 5-fold estimate against a true held-out set measured like the data.
        let v = cross_validate(
            &model,
            &data,
            &FitRequest::new(&ModelSpec::kinematic(), &options),
            5,
            rep,
            None,
        )
        .unwrap();
        let test = noisy(&model, &truth, &random_configs(&model, 300, &mut g), &mut g);
        let obs = Observations::from_table(
            &test,
            &(0..test.len()).collect::<Vec<_>>(),
            &NoiseModel::default(),
            "test",
        )
        .unwrap();
        let e = Prediction::new(&model, &cal.params).errors(&obs);
        let true_rms = (e.iter().map(|v| v.norm_squared()).sum::<f64>() / e.len() as f64).sqrt();
        let spread = v.fold_rms_spread_m.unwrap();
        // Standard error of an RMS of n 3-D errors: RMS / √(2 · 3n).
        let se_true = true_rms / (6.0 * e.len() as f64).sqrt();
        let se_cv = spread / 5f64.sqrt();
        let tolerance = 4.0 * (se_cv * se_cv + se_true * se_true).sqrt();
        eprintln!(
            "rep {rep}: cross-validated RMS {:.2} µm (folds {:?} µm, spread {:.2} µm), true held-out {:.2} µm",
            v.after.rms_m * 1e6,
            v.per_fold
                .iter()
                .map(|f| (f.held_out.rms_m * 1e8).round() / 100.0)
                .collect::<Vec<_>>(),
            spread * 1e6,
            true_rms * 1e6
        );
        deviations.push((v.after.rms_m - true_rms).abs() / tolerance);
    }
    let ratio = (err2 / pred2).sqrt();
    eprintln!(
        "all-pose model: held-out error against the truth {:.2} µm RMS, {ratio:.3} × the covariance's prediction",
        (err2 / n_held as f64).sqrt() * 1e6
    );
    assert!(ratio <= 1.2, "held-out error {ratio:.3} × predicted");
    assert!(ratio >= 0.8, "held-out error only {ratio:.3} × predicted");
    for (rep, d) in deviations.iter().enumerate() {
        assert!(
            *d <= 1.0,
            "rep {rep}: the folds' RMS is {d:.2} tolerances from the true held-out RMS"
        );
    }
}

#[test]
fn per_campaign_targets_follow_a_reseated_reflector() {
    let model = robots::load_builtin("ur5").unwrap();
    let mut g = StdRng::seed_from_u64(common::run_seed("per-campaign target"));
    let a = Truth::random(&model, false, &mut g);
    // Campaign B: the tracker moved and the reflector re-seated 3 mm away.
    let mut b = moved_tracker(&a, &mut g);
    b.p_flange += nalgebra::Vector3::new(2e-3, -1e-3, 2e-3);
    let (qa, qb) = (
        random_configs(&model, 80, &mut g),
        random_configs(&model, 60, &mut g),
    );
    let table = concat(
        &with_campaign(&noisy(&model, &a, &qa, &mut g), 1),
        &with_campaign(&noisy(&model, &b, &qb, &mut g), 2),
    );
    let data = Dataset::all(&table, "reseated");
    let shared = fit(
        &model,
        &data,
        &FitRequest::kinematic(&CalibrationOptions::default()),
    )
    .unwrap();
    let own = fit(
        &model,
        &data,
        &FitRequest::kinematic(&CalibrationOptions {
            per_campaign_target: true,
            ..CalibrationOptions::default()
        }),
    )
    .unwrap();
    let (rs, ro) = (
        shared.report.after.train.rms_m,
        own.report.after.train.rms_m,
    );
    eprintln!(
        "shared target: {:.1} µm RMS; a target per campaign: {:.1} µm",
        rs * 1e6,
        ro * 1e6
    );
    // Own targets: the noise (√3 · 10 µm) to within the fitted parameters' share.
    assert!(ro < 20e-6, "{ro:e}");
    // A shared target cannot follow the reflector: far above the noise.
    assert!(rs > 3.0 * ro, "{rs:e} against {ro:e}");
    // Three more identifiable combinations: the second target.
    assert_eq!(
        own.report.observability.rank,
        shared.report.observability.rank + 3
    );
    // The second campaign's own target is where the reflector went, relative to the first's: the
    // targets alone are not identifiable, their difference is, up to the turn about the last axis that
    // its zero offset trades with both (a mrad on 3 mm: a few µm).
    let d = own.params.p_flange_target_of(1) - own.params.p_flange_target_of(0);
    let want = b.p_flange - a.p_flange;
    assert!((d - want).norm() < 50e-6, "{d} against {want}");
}

/// The folds of `calibrate`'s cross-validation start at the all-pose solution and share one pass
/// over every row there (their first normal equations and, when no singular value is near the
/// threshold, their rank decision). Against folds fitted from the closed-form start (the reference):
/// the same rank, every predicted position within 1e-3 of its standard deviation and of the noise,
/// the held-out statistics within the largest change of a prediction (a bound for them); and the
/// same bytes on one thread and on two.
#[test]
fn warm_folds_reach_the_cold_folds_minima_and_do_not_depend_on_the_thread_count() {
    let model = robots::load_builtin("iiwa7").unwrap();
    let mut g = StdRng::seed_from_u64(common::run_seed("warm folds"));
    let options = CalibrationOptions::default();
    let truth = Truth::random(&model, false, &mut g);
    let one = noisy(&model, &truth, &random_configs(&model, 300, &mut g), &mut g);
    let moved = moved_tracker(&truth, &mut g);
    let other = noisy(&model, &moved, &random_configs(&model, 200, &mut g), &mut g);
    let two = concat(&with_campaign(&one, 1), &with_campaign(&other, 4));
    let spec = ModelSpec::kinematic();
    for (what, table) in [("one campaign", &one), ("two campaigns", &two)] {
        let data = Dataset::all(table, what);
        let all = fit(&model, &data, &FitRequest::new(&spec, &options)).unwrap();
        let cold = fold_calibrations(&model, &data, &FitRequest::new(&spec, &options), 5, 3, None)
            .unwrap();
        let warm = fold_calibrations(
            &model,
            &data,
            &FitRequest::new(&spec, &options),
            5,
            3,
            Some(&all),
        )
        .unwrap();
        // The parametrisation is redundant (null directions keep their start's values): what must
        // agree is what the data determine, the predictions, in units of their standard deviation.
        let configs = random_configs(&model, 100, &mut g);
        let mut worst = 0.0f64;
        for (f, (c, w)) in cold.iter().zip(&warm).enumerate() {
            assert!(
                c.report.was_successful() && w.report.was_successful(),
                "{what} fold {f}"
            );
            assert_eq!(c.subspace.rank, w.subspace.rank, "{what} fold {f}: rank");
            for q in &configs {
                let (pc, _, jq) =
                    calib::fit::prediction_and_jacobian(&model, &c.params, q).unwrap();
                let (pw, _, _) = calib::fit::prediction_and_jacobian(&model, &w.params, q).unwrap();
                let jp = jq.rows(0, 3);
                let cov = jp * &c.covariance * jp.transpose();
                for i in 0..3 {
                    worst = worst.max((pc[i] - pw[i]).abs() / cov[(i, i)].sqrt());
                }
            }
        }
        eprintln!("{what}: largest warm − cold fold prediction difference {worst:.2e} σ");
        assert!(
            worst <= 1e-3,
            "{what}: a fold's prediction moved {worst:.2e} σ"
        );
        let vc =
            cross_validate(&model, &data, &FitRequest::new(&spec, &options), 5, 3, None).unwrap();
        let pool = |n: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .unwrap()
        };
        let vw = pool(2)
            .install(|| {
                cross_validate(
                    &model,
                    &data,
                    &FitRequest::new(&spec, &options),
                    5,
                    3,
                    Some(&all),
                )
            })
            .unwrap();
        let v1 = pool(1)
            .install(|| {
                cross_validate(
                    &model,
                    &data,
                    &FitRequest::new(&spec, &options),
                    5,
                    3,
                    Some(&all),
                )
            })
            .unwrap();
        assert_eq!(v1, vw, "{what}: one thread and two");
        // |RMS(a) − RMS(b)| ≤ RMS(a − b) ≤ max |a − b| (and so for the mean, the max and the ISO
        // mean): the statistics differ by at most the largest change of a prediction. The solver
        // stops where a full Gauss–Newton step would lower χ² by at most `tol = decrease_tol +
        // relative_decrease_tol · χ²`, i.e. within √tol (whitened, RSS over all rows) of the
        // minimum: two solves of one problem predict any row within 2 σ √tol of each other.
        let obs = Observations::from_table(
            table,
            &(0..table.len()).collect::<Vec<_>>(),
            &NoiseModel::default(),
            what,
        )
        .unwrap();
        let largest = |a: &KinematicParams, b: &KinematicParams| {
            let (ea, eb) = (
                Prediction::new(&model, a).errors(&obs),
                Prediction::new(&model, b).errors(&obs),
            );
            ea.iter()
                .zip(&eb)
                .map(|(x, y)| (x - y).norm())
                .fold(0.0, f64::max)
        };
        let lm = &options.lm;
        let bound =
            |chi2: f64| 2.0 * SIGMA * (lm.decrease_tol + lm.relative_decrease_tol * chi2).sqrt();
        let (mut d_before, mut d_after) = (0.0f64, 0.0f64);
        for (f, (c, w)) in cold.iter().zip(&warm).enumerate() {
            let db = largest(&c.before, &w.before);
            let da = largest(&c.params, &w.params);
            let chi2 = |cal: &calib::fit::Calibration, before: bool| {
                let stage = if before {
                    &cal.report.before
                } else {
                    &cal.report.after
                };
                stage.solver.cost_final
            };
            let bb = bound(chi2(c, true).max(chi2(w, true)));
            let ba = bound(chi2(c, false).max(chi2(w, false)));
            eprintln!(
                "{what} fold {f}: warm − cold prediction change {db:.1e} m (bound {bb:.1e}) before, \
                 {da:.1e} m (bound {ba:.1e}) after"
            );
            assert!(
                db <= bb && da <= ba,
                "{what} fold {f}: predictions moved beyond the tolerance"
            );
            d_before = d_before.max(db);
            d_after = d_after.max(da);
        }
        let within =
            |a: &calib::validate::HeldOutStats, b: &calib::validate::HeldOutStats, d: f64| {
                assert_eq!((a.n_rows, a.n_poses), (b.n_rows, b.n_poses));
                for (x, y) in [
                    (a.rms_m, b.rms_m),
                    (a.mean_m, b.mean_m),
                    (a.max_m, b.max_m),
                    (a.iso_mean_m, b.iso_mean_m),
                ] {
                    assert!(
                        (x - y).abs() <= d + 1e-12 * x.abs(),
                        "{what}: held-out {x:e} (cold) vs {y:e} (warm), bound {d:e}"
                    );
                }
            };
        within(&vc.before, &vw.before, d_before);
        within(&vc.after, &vw.after, d_after);
        for (fc, fw) in vc.per_fold.iter().zip(&vw.per_fold) {
            within(&fc.held_out, &fw.held_out, d_after);
        }
    }
}
