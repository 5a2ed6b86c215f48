//! Structure in the residual that no known cause explains.
//!
//! Probes look at the residual `r = measured − predicted` (tracker frame, m) of a physical model, each
//! fitted on the training poses and judged on the test poses. Three of them are *angle probes*: an
//! angle error of one joint `j`, `r ≈ ∂p/∂qⱼ f(q)`, with `f` linear in a few features (linear least
//! squares):
//!
//! - **harmonics of joint j**: `f = Σₖ aₖ sin k qⱼ + bₖ cos k qⱼ`, `k = 1…3` (6 coefficients): an error
//!   periodic in the joint's own angle, which is what [`crate::model::extensions::Cause::TransmissionError`]
//!   models (eccentric gears and encoders, harmonic-drive kinematic error);
//! - **harmonics 4–6 of joint j**: the same for `k = 4…6`, beyond what any cause models;
//! - **joint j linear in the joint angles**: `f = c₀ + Σᵢ cᵢ qᵢ` over every joint `i` (n + 1
//!   coefficients): one joint's error growing with another's angle (cable wind-up, coupled wrist
//!   drives) or with its own (a wrong gear ratio). Its *drivers* are the joints whose term moves the
//!   angle most over the data (`|cᵢ| · std qᵢ` at least half the largest).
//! - **joint j periodic in the other joints' angles**: `f = Σ_{i≠j} aᵢ sin qᵢ + bᵢ cos qᵢ`
//!   (2(n − 1) coefficients): one joint's error following another joint's turn (a coupled drive or
//!   transmission, the simulator's `coupled_transmission`), which neither the own-angle harmonics nor
//!   the linear probe sees over a joint's full range. Its drivers are the joints whose amplitude
//!   `√(aᵢ² + bᵢ²)` is at least half the largest.
//!
//! The learned residual models ([`crate::model::learned`]: polynomial and kernel ridge regression over all
//! joint angles, cross-validated) are the generic fourth. They see the residual in the tracker frame,
//! where one joint's angle error is that angle times a lever that depends on every joint: a
//! product of `qₖ` with sines and cosines of up to seven angles, which neither a cubic polynomial nor
//! a kernel of first- and second-order interactions learns from a few hundred poses. An angle probe
//! multiplies by the lever `∂p/∂qⱼ` itself, so it needs only the few coefficients of `f`: this is why
//! an error of one joint proportional to another's angle, missed by the learned models at five times
//! the noise floor, is found by the linear probe.
//!
//! Structure is **present** when a probe predicts the test poses better than the physical model by the
//! paired test at level `α` (Bonferroni over all probes) and lowers the test RMS by at least
//! [`super::DiagnoseOptions::min_gain`]. It is reported with what it correlates with, never forced onto
//! a known cause.

use super::significance::{normal_upper_quantile, paired};
use super::{DiagnoseOptions, Evaluated, Split, per_pose, rms};
use crate::error::Result;
use crate::model::extensions::Cause;
use crate::model::learned::LearnedKind;
use nalgebra::{DMatrix, DVector, Vector3};
use serde::{Deserialize, Serialize};
use sim::Model;

/// Harmonics per joint angle of the first harmonic probe (the transmission error's).
pub const HARMONICS: usize = 3;

/// What a probe looks for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ProbeKind {
    /// An angle error of one joint periodic in its own angle, harmonics 1 to [`HARMONICS`].
    Harmonics,
    /// The same, harmonics `HARMONICS + 1` to `2 · HARMONICS`.
    HigherHarmonics,
    /// An angle error of one joint linear in every joint's angle.
    Linear,
    /// An angle error of one joint periodic (one cycle per revolution) in the other joints' angles.
    CrossHarmonics,
    /// A learned model of the tracker-frame residual over all joint angles.
    Learned,
}

impl ProbeKind {
    /// Whether `cause` models what this probe finds (the transmission error models the harmonics of a
    /// joint's own angle), so that the probe is no rival of it.
    pub fn modelled_by(self, cause: Cause) -> bool {
        self == ProbeKind::Harmonics && cause.model().own_angle_harmonics() >= HARMONICS
    }
}

/// What a probe achieves on the test poses.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Probe {
    /// `harmonics 1-3 of joint J`, `harmonics 4-6 of joint J`, `joint J linear in the joint angles` or
    /// `learned:KIND`.
    pub name: String,
    /// What it looks for.
    #[serde(default = "learned_kind")]
    pub kind: ProbeKind,
    /// 1-based joint whose angle error it models, for an angle probe.
    pub joint: Option<usize>,
    /// For the linear probe: the 1-based joints whose angles drive the error most.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub drivers: Vec<usize>,
    /// Test RMS after subtracting the probe's prediction (m).
    pub test_rms_m: f64,
    /// `1 − after/before` on the test RMS.
    pub gain: f64,
    /// Paired test `z` on the test poses.
    pub z: f64,
}

fn learned_kind() -> ProbeKind {
    ProbeKind::Learned
}

impl Probe {
    /// What the structure it finds correlates with, in words: "the angle of joint 3",
    /// "the angle error of joint 4 grows with the angle of joint 2", "the joint angles (learned:kernel)".
    pub fn subject(&self) -> String {
        let j = self.joint.unwrap_or(0);
        match self.kind {
            ProbeKind::Harmonics => {
                format!("the angle of joint {j} (harmonics 1 to {HARMONICS} per revolution)")
            }
            ProbeKind::HigherHarmonics => format!(
                "the angle of joint {j} (harmonics {} to {} per revolution, beyond the transmission error's)",
                HARMONICS + 1,
                2 * HARMONICS
            ),
            ProbeKind::Linear => {
                let others: Vec<usize> = self.drivers.iter().copied().filter(|d| *d != j).collect();
                let own = self.drivers.contains(&j);
                match (others.is_empty(), own) {
                    (true, _) => format!(
                        "the angle of joint {j} itself, linearly: an angle error in proportion to the angle (a scale error)"
                    ),
                    (false, false) => format!(
                        "the angle of {}: joint {j}'s angle error grows with it (coupling, cable wind-up)",
                        crate::model::extensions::joint_words(&others)
                    ),
                    (false, true) => format!(
                        "the angles of joint {j} and {}: joint {j}'s angle error grows with them",
                        crate::model::extensions::joint_words(&others)
                    ),
                }
            }
            ProbeKind::CrossHarmonics => format!(
                "the angle of {}: joint {j}'s angle error is periodic in it (a coupled drive or transmission)",
                crate::model::extensions::joint_words(&self.drivers)
            ),
            ProbeKind::Learned => format!("the joint angles ({})", self.name),
        }
    }
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
    /// The probe that explains most, if any is significant: an angle probe before a learned one.
    pub correlates_with: Option<Probe>,
    /// The best learned model on the test poses (significant or not).
    pub learned: Option<Probe>,
    /// Every probe.
    pub probes: Vec<Probe>,
    /// Causes that would have gained on the held-out poses but were not adopted because their
    /// identified physics is impossible (a negative stiffness or lost motion): evidence of an error
    /// they stand in for, which no known cause explains.
    #[serde(default)]
    pub rejected: Vec<super::Rejected>,
}

/// `[sin k q, cos k q]` for `k` in `harmonics` (angle `q` in rad) into `out`.
fn harmonic_features(q: f64, harmonics: std::ops::RangeInclusive<usize>, out: &mut [f64]) {
    for (i, k) in harmonics.enumerate() {
        let (s, c) = (k as f64 * q).sin_cos();
        out[2 * i] = s;
        out[2 * i + 1] = c;
    }
}

/// Fits `residual` (m, one per training row) as an angle error of one joint, `r ≈ d · Σ_c w_c f_c`,
/// `d` the rows' `∂p/∂qⱼ` (tracker frame, m/rad) and `f` their features (row-major, `width` per
/// row), and returns the coefficients (rad per feature unit), or `None` when the features are
/// degenerate over the data. A tiny ridge holds a joint that hardly moves.
fn fit_angle_error(
    dir: &[Vector3<f64>],
    features: &[f64],
    width: usize,
    residual: &[Vector3<f64>],
) -> Option<DVector<f64>> {
    let mut gram = DMatrix::<f64>::zeros(width, width);
    let mut rhs = DVector::zeros(width);
    for ((d, f), r) in dir.iter().zip(features.chunks_exact(width)).zip(residual) {
        let (dd, dr) = (d.norm_squared(), d.dot(r));
        for a in 0..width {
            rhs[a] += f[a] * dr;
            for b in 0..=a {
                gram[(a, b)] += f[a] * f[b] * dd;
            }
        }
    }
    for a in 0..width {
        for b in a + 1..width {
            gram[(a, b)] = gram[(b, a)];
        }
    }
    let lambda = 1e-9 * gram.trace().max(1e-300);
    for c in 0..width {
        gram[(c, c)] += lambda;
    }
    Some(gram.cholesky()?.solve(&rhs))
}

/// The angle error `d · Σ_c w_c f_c` (m) of each row.
fn angle_error(
    dir: &[Vector3<f64>],
    features: &[f64],
    width: usize,
    coef: &DVector<f64>,
) -> Vec<Vector3<f64>> {
    dir.iter()
        .zip(features.chunks_exact(width))
        .map(|(d, f)| d * f.iter().zip(coef.iter()).map(|(a, b)| a * b).sum::<f64>())
        .collect()
}

/// The probes on the residual of `current`: per joint its harmonics 1–3 and 4–6 and its angle linear
/// in the joint angles, then the learned models `learned_kinds` (folds drawn from `seed`), each fitted
/// on the training rows and judged on the test poses.
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
    let mut judge = |name: String,
                     kind: ProbeKind,
                     joint: Option<usize>,
                     drivers: Vec<usize>,
                     correction: &[Vector3<f64>]| {
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
            kind,
            joint,
            drivers,
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
    // The linear probe's features: 1 and every joint angle, centred by the training means (the
    // coefficients then say how much each angle drives the error).
    let rows_train = split.train.rows.len();
    let mean: Vec<f64> = (0..n)
        .map(|i| q_train.iter().skip(i).step_by(n).sum::<f64>() / rows_train.max(1) as f64)
        .collect();
    let spread: Vec<f64> = (0..n)
        .map(|i| {
            (q_train
                .iter()
                .skip(i)
                .step_by(n)
                .map(|v| (v - mean[i]).powi(2))
                .sum::<f64>()
                / rows_train.max(1) as f64)
                .sqrt()
        })
        .collect();
    let linear_features = |q: &[f64]| -> Vec<f64> {
        q.chunks_exact(n)
            .flat_map(|row| std::iter::once(1.0).chain(row.iter().zip(&mean).map(|(v, m)| v - m)))
            .collect()
    };
    let (lin_train, lin_test) = (linear_features(&q_train), linear_features(&q_test));
    for j in 0..n {
        let (dir_train, dir_test) = (directions(train_dirs, j), directions(test_dirs, j));
        let qj = |q: &[f64]| q.iter().skip(j).step_by(n).copied().collect::<Vec<f64>>();
        let (qj_train, qj_test) = (qj(&q_train), qj(&q_test));
        let mut probe = |name: String,
                         kind: ProbeKind,
                         width: usize,
                         f_train: &[f64],
                         f_test: &[f64],
                         drivers: &dyn Fn(&DVector<f64>) -> Vec<usize>| {
            let (correction, drivers) = match fit_angle_error(&dir_train, f_train, width, &residual)
            {
                Some(coef) => (angle_error(&dir_test, f_test, width, &coef), drivers(&coef)),
                None => (vec![Vector3::zeros(); qj_test.len()], Vec::new()),
            };
            judge(name, kind, Some(j + 1), drivers, &correction);
        };
        for (kind, range) in [
            (ProbeKind::Harmonics, 1..=HARMONICS),
            (ProbeKind::HigherHarmonics, HARMONICS + 1..=2 * HARMONICS),
        ] {
            let width = 2 * HARMONICS;
            let features = |q: &[f64]| -> Vec<f64> {
                let mut out = vec![0.0; q.len() * width];
                for (v, o) in q.iter().zip(out.chunks_exact_mut(width)) {
                    harmonic_features(*v, range.clone(), o);
                }
                out
            };
            probe(
                format!(
                    "harmonics {}-{} of joint {}",
                    range.start(),
                    range.end(),
                    j + 1
                ),
                kind,
                width,
                &features(&qj_train),
                &features(&qj_test),
                &|_| Vec::new(),
            );
        }
        // One cycle per revolution of every other joint's angle.
        let cross_width = 2 * (n - 1);
        let cross_features = |q: &[f64]| -> Vec<f64> {
            let mut out = Vec::with_capacity(q.len() / n * cross_width);
            for row in q.chunks_exact(n) {
                for (i, v) in row.iter().enumerate() {
                    if i != j {
                        let (s, c) = v.sin_cos();
                        out.extend([s, c]);
                    }
                }
            }
            out
        };
        probe(
            format!("joint {} periodic in the other joints' angles", j + 1),
            ProbeKind::CrossHarmonics,
            cross_width,
            &cross_features(&q_train),
            &cross_features(&q_test),
            &|coef| {
                let others: Vec<usize> = (0..n).filter(|&i| i != j).collect();
                let amp: Vec<f64> = (0..n - 1)
                    .map(|k| coef[2 * k].hypot(coef[2 * k + 1]))
                    .collect();
                let top = amp.iter().copied().fold(0.0, f64::max);
                (0..n - 1)
                    .filter(|&k| top > 0.0 && amp[k] >= 0.5 * top)
                    .map(|k| others[k] + 1)
                    .collect()
            },
        );
        probe(
            format!("joint {} linear in the joint angles", j + 1),
            ProbeKind::Linear,
            n + 1,
            &lin_train,
            &lin_test,
            &|coef| {
                let effect: Vec<f64> = (0..n).map(|i| (coef[i + 1] * spread[i]).abs()).collect();
                let top = effect.iter().copied().fold(0.0, f64::max);
                (0..n)
                    .filter(|&i| top > 0.0 && effect[i] >= 0.5 * top)
                    .map(|i| i + 1)
                    .collect()
            },
        );
    }
    for &kind in learned_kinds {
        let Ok(l) = crate::model::learned::fit(kind, &q_train, n, &residual, seed) else {
            continue;
        };
        let c: Vec<Vector3<f64>> = (0..split.test.rows.len())
            .map(|r| l.predict(&q_test[r * n..(r + 1) * n]))
            .collect();
        judge(
            format!("learned:{kind}"),
            ProbeKind::Learned,
            None,
            Vec::new(),
            &c,
        );
    }
    probes
}

/// The critical `z` of the probes' held-out test: `α` over the number of probes (Bonferroni).
pub(crate) fn probe_z_crit(alpha: f64, probes: usize) -> f64 {
    normal_upper_quantile(alpha / probes.max(1) as f64)
}

/// Examines the residual of `current` (the final physical model); `rejected` are the causes not
/// adopted for impossible or implausible physics, `dropped` the joints dropped from a cause for the
/// same reason (both evidence of an error no known cause explains).
pub(crate) fn analyse(
    model: &Model,
    split: &Split<'_>,
    current: &Evaluated,
    noise_floor_m: f64,
    options: &DiagnoseOptions,
    rejected: Vec<super::Rejected>,
    dropped: &[super::JointSelection],
) -> Result<Unexplained> {
    let before = rms(&current.test_err);
    let probes = probes(model, split, current, &options.learned_kinds, options.seed);
    let z_crit = probe_z_crit(options.alpha, probes.len());
    let significant = |p: &&Probe| p.z > z_crit && p.gain >= options.min_gain;
    let best_of =
        |it: &mut dyn Iterator<Item = &Probe>| it.max_by(|a, b| a.gain.total_cmp(&b.gain)).cloned();
    let angle = best_of(
        &mut probes
            .iter()
            .filter(|p| p.kind != ProbeKind::Learned)
            .filter(significant),
    );
    let learned = best_of(&mut probes.iter().filter(|p| p.kind == ProbeKind::Learned));
    let learned_significant = learned.as_ref().filter(significant).cloned();
    let present = angle.is_some()
        || learned_significant.is_some()
        || !rejected.is_empty()
        || !dropped.is_empty();
    let ratio = before / noise_floor_m;
    let mut note = if angle.is_some() || learned_significant.is_some() {
        let mut s = format!(
            "the residual ({:.1} µm RMS, {ratio:.2}× the noise floor) has structure no known cause explains",
            before * 1e6
        );
        if let Some(h) = &angle {
            s.push_str(&format!(
                "; it varies with {} (the probe `{}` removes {:.0} % of the test RMS)",
                h.subject(),
                h.name,
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
    } else if present {
        format!(
            "the residual ({:.1} µm RMS, {ratio:.2}× the noise floor) holds an error no known cause \
             explains, though no probe finds its structure",
            before * 1e6
        )
    } else if ratio <= 1.25 {
        "residual is at the noise floor".to_string()
    } else {
        format!(
            "residual is {ratio:.2}× the noise floor but shows no structure in the joint angles that held-out \
             poses confirm (noise floor underestimated, or an effect beyond the probes)"
        )
    };
    for d in dropped {
        note.push_str(&format!(
            "; {}: the error it stood in for at {} is no known cause's",
            d.evidence,
            crate::model::extensions::joint_words(&d.implausible)
        ));
    }
    for r in &rejected {
        note.push_str(&format!("; {}", r.evidence));
    }
    Ok(Unexplained {
        present,
        test_rms_m: before,
        note,
        correlates_with: angle.or(learned_significant),
        learned,
        probes,
        rejected,
    })
}
