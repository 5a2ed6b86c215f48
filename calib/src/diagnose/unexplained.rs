//! Structure in the residual that no known cause explains.
//!
//! Two probes look at the residual `r = measured − predicted` (tracker frame, m) of the final physical
//! model, each fitted on the training poses and judged on the test poses:
//!
//! - **harmonics of one joint angle**: per joint `j`, an angle error periodic in that joint's angle,
//!   `r ≈ ∂p/∂qⱼ Σₖ (aₖ sin k qⱼ + bₖ cos k qⱼ)`, `k = 1…3` (6 coefficients, linear least squares):
//!   gear eccentricity and encoder errors live here;
//! - **the learned residual models** ([`crate::learned`]: polynomial and kernel ridge regression over
//!   all joint angles, cross-validated).
//!
//! Structure is **present** when a probe predicts the test poses better than the physical model by the
//! paired test at level `α` (Bonferroni over all probes) and lowers the test RMS by at least
//! [`super::DiagnoseOptions::min_gain`]. It is reported with what it correlates with, never forced onto
//! a known cause.

use super::significance::{normal_upper_quantile, paired};
use super::{DiagnoseOptions, Evaluated, Split, per_pose, rms};
use crate::error::Result;
use crate::learned::LearnedKind;
use nalgebra::{DMatrix, DVector, Vector3};
use serde::{Deserialize, Serialize};
use sim::Model;

/// Harmonics per joint angle.
pub const HARMONICS: usize = 3;

/// What a probe achieves on the test poses.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Probe {
    /// `harmonics of joint J` or `learned:KIND`.
    pub name: String,
    /// 1-based joint, for a harmonic probe.
    pub joint: Option<usize>,
    /// Test RMS after subtracting the probe's prediction (m).
    pub test_rms_m: f64,
    /// `1 − after/before` on the test RMS.
    pub gain: f64,
    /// Paired test `z` on the test poses.
    pub z: f64,
}

/// The `unexplained` block of the diagnosis.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Unexplained {
    /// Whether structure is left that held-out poses confirm.
    pub present: bool,
    /// Test RMS of the final physical model (m).
    pub test_rms_m: f64,
    /// A sentence for people.
    pub note: String,
    /// The probe that explains most, if any is significant.
    pub correlates_with: Option<Probe>,
    /// The best learned model on the test poses (significant or not).
    pub learned: Option<Probe>,
    /// Every probe.
    pub probes: Vec<Probe>,
}

/// Harmonic features of joint angle `q` (rad).
fn harmonic_features(q: f64, out: &mut [f64]) {
    for k in 0..HARMONICS {
        let (s, c) = ((k + 1) as f64 * q).sin_cos();
        out[2 * k] = s;
        out[2 * k + 1] = c;
    }
}

/// Rows of the joint-angle harmonic regression for one measurement: `∂p/∂qⱼ · [sin(k qⱼ), cos(k qⱼ)]`
/// (3 × 2·[`HARMONICS`], m/rad), into `out` row-major.
fn harmonic_rows(direction: &Vector3<f64>, qj: f64, feat: &mut [f64], out: &mut [f64]) {
    harmonic_features(qj, feat);
    let f = feat.len();
    for axis in 0..3 {
        for (c, v) in feat.iter().enumerate() {
            out[axis * f + c] = direction[axis] * v;
        }
    }
}

/// Fits `residual` (m, one per training row) as an angle error of joint `j` periodic in its angle,
/// `r ≈ ∂p/∂qⱼ Σₖ (aₖ sin k qⱼ + bₖ cos k qⱼ)`, and returns the predicted residual of the test rows.
/// `dir_*` are the rows' `∂p/∂qⱼ` (tracker frame, m/rad), `qj_*` their angles of joint `j` (rad).
fn harmonic_probe(
    dir_train: &[Vector3<f64>],
    qj_train: &[f64],
    residual: &[Vector3<f64>],
    dir_test: &[Vector3<f64>],
    qj_test: &[f64],
) -> Vec<Vector3<f64>> {
    let f = 2 * HARMONICS;
    let m = residual.len();
    let mut a = DMatrix::zeros(3 * m, f);
    let mut b = DVector::zeros(3 * m);
    let mut feat = vec![0.0; f];
    let mut rows = vec![0.0; 3 * f];
    for r in 0..m {
        harmonic_rows(&dir_train[r], qj_train[r], &mut feat, &mut rows);
        for axis in 0..3 {
            for c in 0..f {
                a[(3 * r + axis, c)] = rows[axis * f + c];
            }
            b[3 * r + axis] = residual[r][axis];
        }
    }
    // Tiny ridge against a joint that hardly moves (its features are then nearly collinear).
    let mut gram = a.tr_mul(&a);
    let lambda = 1e-9 * gram.trace().max(1e-300);
    for c in 0..f {
        gram[(c, c)] += lambda;
    }
    let Some(chol) = gram.cholesky() else {
        return vec![Vector3::zeros(); qj_test.len()];
    };
    let coef = chol.solve(&a.tr_mul(&b));
    dir_test
        .iter()
        .zip(qj_test)
        .map(|(d, &q)| {
            harmonic_rows(d, q, &mut feat, &mut rows);
            Vector3::from_fn(|axis, _| (0..f).map(|c| rows[axis * f + c] * coef[c]).sum())
        })
        .collect()
}

/// The probes on the residual of `current`: harmonics of each joint angle, then the learned models
/// `learned_kinds` (folds drawn from `seed`), each fitted on the training rows and judged on the test
/// poses.
pub(crate) fn probes(
    model: &Model,
    split: &Split<'_>,
    current: &Evaluated,
    learned_kinds: &[LearnedKind],
    seed: u64,
) -> Vec<Probe> {
    let n = model.nq();
    let gather = |rows: &[usize]| -> Vec<f64> {
        rows.iter()
            .flat_map(|&r| split.train.table.q_row(r).iter().copied())
            .collect()
    };
    let q_train = gather(&split.train.rows);
    let q_test = gather(&split.test.rows);
    let residual: Vec<Vector3<f64>> = current.train_err.iter().map(|e| -e).collect();
    let before = rms(&current.test_err);
    let mut probes = Vec::new();
    let mut judge = |name: String, joint: Option<usize>, correction: &[Vector3<f64>]| {
        let after: Vec<Vector3<f64>> = current
            .test_err
            .iter()
            .zip(correction)
            .map(|(e, c)| e + c)
            .collect();
        let sq = per_pose(&split.test_pose, after.iter().map(|e| e.norm_squared()));
        let test_rms_m = rms(&after);
        probes.push(Probe {
            name,
            joint,
            test_rms_m,
            gain: if before > 0.0 {
                1.0 - test_rms_m / before
            } else {
                0.0
            },
            z: paired(&current.pose_sq, &sq).z,
        });
    };
    let (train_dirs, test_dirs) = (
        current.train_directions(model, split),
        current.test_directions(model, split),
    );
    let directions = |dirs: &[Vector3<f64>], j: usize| -> Vec<Vector3<f64>> {
        dirs.iter().skip(j).step_by(n).copied().collect()
    };
    for j in 0..n {
        let qj = |q: &[f64]| q.iter().skip(j).step_by(n).copied().collect::<Vec<f64>>();
        let c = harmonic_probe(
            &directions(train_dirs, j),
            &qj(&q_train),
            &residual,
            &directions(test_dirs, j),
            &qj(&q_test),
        );
        judge(format!("harmonics of joint {}", j + 1), Some(j + 1), &c);
    }
    for &kind in learned_kinds {
        let Ok(l) = crate::learned::fit(kind, &q_train, n, &residual, seed) else {
            continue;
        };
        let c: Vec<Vector3<f64>> = (0..split.test.rows.len())
            .map(|r| l.predict(&q_test[r * n..(r + 1) * n]))
            .collect();
        judge(format!("learned:{kind}"), None, &c);
    }
    probes
}

/// Examines the residual of `current` (the final physical model).
pub(crate) fn analyse(
    model: &Model,
    split: &Split<'_>,
    current: &Evaluated,
    noise_floor_m: f64,
    options: &DiagnoseOptions,
) -> Result<Unexplained> {
    let before = rms(&current.test_err);
    let probes = probes(model, split, current, &options.learned_kinds, options.seed);
    let z_crit = normal_upper_quantile(options.alpha / probes.len().max(1) as f64);
    let significant = |p: &&Probe| p.z > z_crit && p.gain >= options.min_gain;
    let best_of =
        |it: &mut dyn Iterator<Item = &Probe>| it.max_by(|a, b| a.gain.total_cmp(&b.gain)).cloned();
    let harmonic = best_of(
        &mut probes
            .iter()
            .filter(|p| p.joint.is_some())
            .filter(significant),
    );
    let learned = best_of(&mut probes.iter().filter(|p| p.joint.is_none()));
    let learned_significant = learned.as_ref().filter(significant).cloned();
    let present = harmonic.is_some() || learned_significant.is_some();
    let ratio = before / noise_floor_m;
    let note = if present {
        let mut s = format!(
            "the residual ({:.1} µm RMS, {ratio:.2}× the noise floor) has structure no known cause explains",
            before * 1e6
        );
        if let Some(h) = &harmonic {
            s.push_str(&format!(
                "; it varies with the angle of joint {} (harmonics up to {HARMONICS}/rev remove {:.0} % of the test RMS)",
                h.joint.unwrap_or(0),
                100.0 * h.gain
            ));
        }
        match (&learned_significant, &learned) {
            (Some(l), _) => s.push_str(&format!(
                "; the {} model captures it: test RMS {:.1} µm ({:.0} % less)",
                l.name,
                l.test_rms_m * 1e6,
                100.0 * l.gain
            )),
            (None, Some(l)) => s.push_str(&format!(
                "; the learned models do not capture it (best {}: {:.0} % less)",
                l.name,
                100.0 * l.gain
            )),
            _ => {}
        }
        s
    } else if ratio <= 1.25 {
        "residual is at the noise floor".to_string()
    } else {
        format!(
            "residual is {ratio:.2}× the noise floor but shows no structure in the joint angles that held-out \
             poses confirm (noise floor underestimated, or an effect beyond the probes)"
        )
    };
    Ok(Unexplained {
        present,
        test_rms_m: before,
        note,
        correlates_with: harmonic.or(learned_significant),
        learned,
        probes,
    })
}
