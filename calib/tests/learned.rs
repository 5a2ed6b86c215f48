//! Learned residual models (`calib::learned`): exact recovery of polynomials, generalisation to fresh
//! poses for a periodic effect under noise, refusal to learn pure noise, determinism and bad input.
//!
//! All data are drawn here from seeded generators; expectations are closed forms (the generating
//! polynomial, the noise floor `√3 σ` of the 3-D residual norm), never outputs of the code under test.

use calib::learned::{self, LearnedResidual};
use nalgebra::Vector3;
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, Normal};

/// [`learned::fit`] for the kind named `kind`.
fn fit(
    kind: &str,
    q: &[f64],
    n_joints: usize,
    r: &[Vector3<f64>],
    seed: u64,
) -> Result<learned::LearnedResidual, calib::CalibError> {
    let kind = learned::LearnedKind::from_name(kind).expect("a learned kind");
    learned::fit(kind, q, n_joints, r, seed)
}

const N_JOINTS: usize = 7;

/// `rows` joint vectors uniform in ±`range` rad, row-major.
fn draw_q(rng: &mut StdRng, rows: usize, range: f64) -> Vec<f64> {
    (0..rows * N_JOINTS)
        .map(|_| (2.0 * rng.random::<f64>() - 1.0) * range)
        .collect()
}

fn rows(q: &[f64]) -> impl Iterator<Item = &[f64]> {
    q.chunks_exact(N_JOINTS)
}

/// RMS of the 3-D norm of `truth(q) − model(q)` over the rows of `q`.
fn rms_error(model: &LearnedResidual, q: &[f64], truth: &[Vector3<f64>]) -> f64 {
    let sum: f64 = rows(q)
        .zip(truth)
        .map(|(qr, t)| (t - model.predict(qr)).norm_squared())
        .sum();
    (sum / truth.len() as f64).sqrt()
}

fn rms(v: &[Vector3<f64>]) -> f64 {
    (v.iter().map(|r| r.norm_squared()).sum::<f64>() / v.len() as f64).sqrt()
}

/// A degree-2 polynomial in the joint angles (m).
fn quadratic(q: &[f64]) -> Vector3<f64> {
    Vector3::new(
        1e-4 * (0.3 + q[0] - 0.5 * q[1] * q[2] + 0.2 * q[3] * q[3]),
        2e-5 * q[4] * q[6] - 1e-5 * q[0] * q[0] + 3e-6,
        5e-5 * (q[5] - q[1] * q[3]),
    )
}

/// A degree-3 polynomial in the joint angles (m).
fn cubic(q: &[f64]) -> Vector3<f64> {
    quadratic(q)
        + Vector3::new(
            4e-5 * q[2] * q[2] * q[6],
            -2e-5 * q[1] * q[4] * q[5],
            1e-5 * q[3].powi(3),
        )
}

#[test]
fn exact_polynomials_are_recovered_and_cv_picks_their_degree() {
    let mut rng = StdRng::seed_from_u64(11);
    let q = draw_q(&mut rng, 300, 2.0);
    let q_fresh = draw_q(&mut rng, 200, 2.0);
    for (degree, f) in [
        (2usize, quadratic as fn(&[f64]) -> Vector3<f64>),
        (3, cubic),
    ] {
        let r: Vec<Vector3<f64>> = rows(&q).map(f).collect();
        let model = fit("poly", &q, N_JOINTS, &r, 5).unwrap();
        let truth: Vec<Vector3<f64>> = rows(&q_fresh).map(f).collect();
        let err = rms_error(&model, &q_fresh, &truth);
        let max_err = rows(&q_fresh)
            .zip(&truth)
            .map(|(qr, t)| (t - model.predict(qr)).norm())
            .fold(0.0, f64::max);
        eprintln!(
            "degree {degree}: {} | fresh RMS error {err:.2e} m, max {max_err:.2e} m",
            model.describe()
        );
        assert!(
            model
                .describe()
                .contains(&format!("polynomial degree {degree} ")),
            "{}",
            model.describe()
        );
        assert!(
            max_err < 1e-9,
            "degree {degree}: max error {max_err:e} m at fresh poses"
        );
        assert!(model.cv_rms_m() < 1e-9 && model.cv_rms_before_m() > 1e-5);
        // 3 × (features + intercept): 7 + 28 (+ 84) monomials of 7 joints.
        let features = if degree == 2 { 35 } else { 119 };
        assert_eq!(model.n_parameters(), 3 * (features + 1));
    }
}

/// 50 µm · sin(2 q₃) along a fixed direction plus 10 µm Gaussian noise per component, 400 training
/// poses with q uniform in ±1.5 rad, 1000 fresh poses to judge; three independent data sets.
#[test]
fn periodic_effect_under_noise_is_learned_down_to_the_noise_floor() {
    for seed in [2024, 7, 99] {
        periodic_effect(seed);
    }
}

fn periodic_effect(seed: u64) {
    let sigma = 10e-6;
    let direction = Vector3::new(0.6, 0.0, 0.8);
    let effect = |q: &[f64]| direction * (50e-6 * (2.0 * q[3]).sin());
    let noise = Normal::new(0.0, sigma).unwrap();
    let mut rng = StdRng::seed_from_u64(seed);
    let noisy = |q: &[f64], rng: &mut StdRng| {
        effect(q) + Vector3::new(noise.sample(rng), noise.sample(rng), noise.sample(rng))
    };
    let q = draw_q(&mut rng, 400, 1.5);
    let r: Vec<Vector3<f64>> = rows(&q).map(|qr| noisy(qr, &mut rng)).collect();
    let q_fresh = draw_q(&mut rng, 1000, 1.5);
    let r_fresh: Vec<Vector3<f64>> = rows(&q_fresh).map(|qr| noisy(qr, &mut rng)).collect();
    let truth_fresh: Vec<Vector3<f64>> = rows(&q_fresh).map(effect).collect();
    // Noise floor of the 3-D norm: √3 σ = 17.3 µm; the effect alone has RMS 50/√2 = 35.4 µm, so
    // without correction the held-out RMS is about √(35.4² + 17.3²) = 39.4 µm.
    let floor = 3f64.sqrt() * sigma;
    let before = rms(&r_fresh);
    for (kind, factor) in [("kernel", 1.15), ("poly", 1.3)] {
        let model = fit(kind, &q, N_JOINTS, &r, 7).unwrap();
        let after = rms_error(&model, &q_fresh, &r_fresh);
        let excess = rms_error(&model, &q_fresh, &truth_fresh);
        eprintln!(
            "seed {seed} {kind}: {} | held-out RMS {:.1} µm -> {:.1} µm (noise floor {:.1} µm, ratio {:.3}); error vs noise-free effect {:.1} µm",
            model.describe(),
            before * 1e6,
            after * 1e6,
            floor * 1e6,
            after / floor,
            excess * 1e6
        );
        assert!(model.is_active());
        assert!(
            after < factor * floor,
            "{kind}: held-out RMS {after:e} m vs noise floor {floor:e} m"
        );
        assert!(
            after < 0.6 * before,
            "{kind}: held-out RMS {after:e} m vs {before:e} m without"
        );
        // Cross-validation (fits on 4/5 of the poses) predicts the held-out RMS to within 25 %.
        assert!(
            (model.cv_rms_m() - after).abs() < 0.25 * after,
            "{kind}: CV RMS {:e} m",
            model.cv_rms_m()
        );
    }
}

#[test]
fn pure_noise_is_not_learned() {
    let sigma = 10e-6;
    let noise = Normal::new(0.0, sigma).unwrap();
    let mut rng = StdRng::seed_from_u64(99);
    let draw = |rows: usize, rng: &mut StdRng| -> Vec<Vector3<f64>> {
        (0..rows)
            .map(|_| Vector3::new(noise.sample(rng), noise.sample(rng), noise.sample(rng)))
            .collect()
    };
    let q = draw_q(&mut rng, 300, 1.5);
    let r = draw(300, &mut rng);
    let q_fresh = draw_q(&mut rng, 1000, 1.5);
    let r_fresh = draw(1000, &mut rng);
    let before = rms(&r_fresh);
    for kind in ["kernel", "poly", "poly3"] {
        let model = fit(kind, &q, N_JOINTS, &r, 3).unwrap();
        let after = rms_error(&model, &q_fresh, &r_fresh);
        let size = (rows(&q_fresh)
            .map(|qr| model.predict(qr).norm_squared())
            .sum::<f64>()
            / 1000.0)
            .sqrt();
        eprintln!(
            "{kind}: {} | held-out RMS {:.2} µm -> {:.2} µm, RMS correction {:.2} µm",
            model.describe(),
            before * 1e6,
            after * 1e6,
            size * 1e6
        );
        assert!(
            after <= 1.02 * before,
            "{kind}: {after:e} m vs {before:e} m"
        );
        // Near zero: well below the noise of one residual (√3 σ = 17 µm).
        assert!(
            size < 0.2 * 3f64.sqrt() * sigma,
            "{kind}: RMS correction {size:e} m"
        );
    }
}

#[test]
fn same_seed_gives_identical_models() {
    let mut rng = StdRng::seed_from_u64(5);
    let q = draw_q(&mut rng, 120, 1.0);
    let noise = Normal::new(0.0, 5e-6).unwrap();
    let r: Vec<Vector3<f64>> = rows(&q)
        .map(|qr| {
            Vector3::new(3e-5 * qr[1].sin(), 0.0, 2e-5 * qr[0] * qr[2])
                + Vector3::repeat(noise.sample(&mut rng))
        })
        .collect();
    for kind in learned::KINDS {
        let a = fit(kind, &q, N_JOINTS, &r, 42).unwrap();
        let b = fit(kind, &q, N_JOINTS, &r, 42).unwrap();
        assert_eq!(
            serde_json::to_string(&a).unwrap(),
            serde_json::to_string(&b).unwrap(),
            "{kind}"
        );
        assert_eq!(a.kind().name(), *kind);
        // The serialised model predicts the same bits.
        let c: LearnedResidual = serde_json::from_str(&serde_json::to_string(&a).unwrap()).unwrap();
        for qr in rows(&q).take(10) {
            assert_eq!(a.predict(qr), c.predict(qr));
        }
    }
}

#[test]
fn bad_input_is_an_error_naming_the_problem() {
    let q = vec![0.1; 20 * N_JOINTS];
    let r = vec![Vector3::new(1e-5, 0.0, 0.0); 20];
    let message = |e: calib::CalibError| e.to_string();
    let e = message(calib::extensions::ModelSpec::parse("kinematic+learned:spline").unwrap_err());
    assert!(e.contains("learned") && e.contains("spline"), "{e}");
    assert_eq!(learned::LearnedKind::from_name("spline"), None);
    let e = message(fit("poly", &q[..q.len() - 1], N_JOINTS, &r, 0).unwrap_err());
    assert!(e.contains("q") && e.contains("139"), "{e}");
    let e = message(fit("kernel", &q[..9 * N_JOINTS], N_JOINTS, &r[..9], 0).unwrap_err());
    assert!(e.contains("rows") && e.contains("9"), "{e}");
    let mut q_nan = q.clone();
    q_nan[3 * N_JOINTS + 2] = f64::NAN;
    let e = message(fit("poly", &q_nan, N_JOINTS, &r, 0).unwrap_err());
    assert!(e.contains("row 3, joint 2") && e.contains("NaN"), "{e}");
    let mut r_inf = r.clone();
    r_inf[4].z = f64::INFINITY;
    let e = message(fit("kernel", &q, N_JOINTS, &r_inf, 0).unwrap_err());
    assert!(e.contains("row 4, z"), "{e}");
    assert!(fit("poly", &q, 0, &r, 0).is_err());
    // Wrong length at prediction: NaN, no panic.
    let model = fit("poly1", &q, N_JOINTS, &r, 0).unwrap();
    assert!(model.predict(&[0.0; 3]).x.is_nan());
}

/// A joint-angle error periodic in q₃ seen through a configuration-dependent lever arm (the realistic
/// case: the tracker-frame residual of a joint error is its Jacobian column times the error), 10 µm noise,
/// 400 poses. Neither model reaches the noise floor here; the kernel model (pairwise joint terms) gets
/// much closer than the polynomial in q.
#[test]
fn interacting_effect_is_reduced() {
    let sigma = 10e-6;
    let effect = |q: &[f64]| {
        let lever = 0.4 + 0.2 * q[4].cos();
        Vector3::new(q[0].cos(), q[0].sin(), 0.3 * q[2].sin()) * (lever * 2e-4 * (2.0 * q[3]).sin())
    };
    let noise = Normal::new(0.0, sigma).unwrap();
    let mut rng = StdRng::seed_from_u64(1);
    let noisy = |q: &[f64], rng: &mut StdRng| {
        effect(q) + Vector3::new(noise.sample(rng), noise.sample(rng), noise.sample(rng))
    };
    let q = draw_q(&mut rng, 400, 1.5);
    let r: Vec<Vector3<f64>> = rows(&q).map(|qr| noisy(qr, &mut rng)).collect();
    let q_fresh = draw_q(&mut rng, 1000, 1.5);
    let r_fresh: Vec<Vector3<f64>> = rows(&q_fresh).map(|qr| noisy(qr, &mut rng)).collect();
    let floor = 3f64.sqrt() * sigma;
    let before = rms(&r_fresh);
    for (kind, max_ratio) in [("kernel", 0.45), ("poly", 0.7)] {
        let model = fit(kind, &q, N_JOINTS, &r, 7).unwrap();
        let after = rms_error(&model, &q_fresh, &r_fresh);
        eprintln!(
            "{kind}: {} | held-out RMS {:.1} µm -> {:.1} µm (noise floor {:.1} µm)",
            model.describe(),
            before * 1e6,
            after * 1e6,
            floor * 1e6
        );
        assert!(
            after < max_ratio * before,
            "{kind}: {after:e} m vs {before:e} m without"
        );
    }
}

#[test]
fn kernel_matches_its_hand_computed_value() {
    // z = (0, 0), z' = (1, 0), ℓ = 1: k₁ = e^{−1/2}, k₂ = 1; first order (k₁ + k₂)/2, second order k₁k₂/1,
    // full exp(−1/(2·2·1)) = e^{−1/4}; the mean of the three terms.
    let h = (-0.5f64).exp();
    let expected = ((h + 1.0) / 2.0 + h + (-0.25f64).exp()) / 3.0;
    assert!((learned::kernel::kernel(&[0.0, 0.0], &[1.0, 0.0], 1.0) - expected).abs() < 1e-15);
    assert!(
        (learned::kernel::kernel(&[0.3, -2.0, 1.0], &[0.3, -2.0, 1.0], 0.7) - 1.0).abs() < 1e-15
    );
    // One joint: (k₁ + full)/2 with full = k₁.
    assert!((learned::kernel::kernel(&[0.0], &[2.0], 1.0) - (-2.0f64).exp()).abs() < 1e-15);
}

#[test]
fn a_joint_that_never_moves_is_harmless() {
    let mut rng = StdRng::seed_from_u64(8);
    let mut q = draw_q(&mut rng, 150, 1.5);
    for row in q.chunks_exact_mut(N_JOINTS) {
        row[6] = 0.25;
    }
    let r: Vec<Vector3<f64>> = rows(&q).map(quadratic_without_joint_6).collect();
    for kind in learned::KINDS {
        let model = fit(kind, &q, N_JOINTS, &r, 1).unwrap();
        let p = model.predict(&q[..N_JOINTS]);
        assert!(p.iter().all(|v| v.is_finite()), "{kind}: {p}");
        assert!(
            model.cv_rms_m() < 0.5 * model.cv_rms_before_m(),
            "{kind}: {}",
            model.describe()
        );
    }
}

fn quadratic_without_joint_6(q: &[f64]) -> Vector3<f64> {
    Vector3::new(
        1e-4 * (q[0] - 0.5 * q[1] * q[2]),
        2e-5 * q[4],
        5e-5 * (q[5] - q[1] * q[3]),
    )
}

/// More rows than a kernel model holds: a seeded subsample, said so. Ignored by default (about 10 s in
/// the test profile, 3 s optimised): `cargo test --release -p calib --test learned -- --ignored`.
#[test]
#[ignore]
fn kernel_subsamples_large_data_sets() {
    let mut rng = StdRng::seed_from_u64(4);
    let q = draw_q(&mut rng, 1200, 1.5);
    let r: Vec<Vector3<f64>> = rows(&q).map(quadratic).collect();
    let model = fit("kernel", &q, N_JOINTS, &r, 2).unwrap();
    assert!(
        model.describe().contains("subsample of 1000 of 1200 poses"),
        "{}",
        model.describe()
    );
    let q_fresh = draw_q(&mut rng, 300, 1.5);
    let truth: Vec<Vector3<f64>> = rows(&q_fresh).map(quadratic).collect();
    let before = rms(&truth);
    let after = rms_error(&model, &q_fresh, &truth);
    eprintln!(
        "{} | fresh RMS {:.2} µm -> {:.2} µm",
        model.describe(),
        before * 1e6,
        after * 1e6
    );
    assert!(after < 0.1 * before);
}
