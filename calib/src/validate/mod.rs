//! Validation of a calibration on poses its fit did not see: k-fold cross-validation by pose, a
//! single split, or another file.
//!
//! The saved model is fitted on every pose; validation says how well that procedure predicts poses it
//! has not seen. In **k-fold cross-validation** the poses (all repeats of a pose together, and, with
//! several campaigns, the poses of each campaign dealt evenly so that every fold's fit registers every
//! campaign) are shuffled with the seed and dealt into `k` folds; each fold is predicted by the model
//! fitted on the other `k − 1` (the same model specification, learned correction included, with its
//! own hyper-parameter search), so every pose is held out exactly once. The folds are fitted in
//! parallel. Their pooled errors estimate what the model fitted on `(k−1)/k` of the poses achieves
//! on new ones — slightly pessimistic for the model fitted on all of them.
//!
//! Reported for the nominal robot (only base and target fitted), the calibrated physical model and,
//! when there is one, the model with its learned correction: the RMS, the mean and the maximum of the
//! position error `|predicted − measured|` over the held-out rows, and the **ISO 9283-style mean**:
//! the mean over held-out poses of `|mean over the pose's repeated measurements of (predicted −
//! measured)|`, the accuracy part of ISO 9283's pose accuracy `AP` (the distance between the
//! barycentre of the attained positions and the commanded one) with the calibrated model's prediction
//! as the command, averaged over the poses. Without repeated measurements it equals the mean; with
//! them it leaves out the repeatability scatter that averaging removes.

use crate::error::{CalibError, Result};
use crate::fit::problem::KinematicProblem;
use crate::fit::{
    Calibration, CalibrationOptions, Dataset, FitRequest, FoldShare, Part, SolveShare, WarmStart,
    fit, observations,
};
use crate::model::params::KinematicParams;
use crate::model::params::ParamLayout;
use crate::model::predict::Prediction;
use nalgebra::DMatrix;
use nalgebra::Vector3;
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rayon::prelude::*;
use sim::Model;
use std::collections::BTreeMap;

/// Default number of folds (`robocal calibrate --folds`).
pub const DEFAULT_FOLDS: usize = 5;

/// Held-out position errors of one model.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct HeldOutStats {
    /// Held-out rows.
    pub n_rows: usize,
    /// Held-out poses.
    pub n_poses: usize,
    /// RMS of the position error norms (m).
    pub rms_m: f64,
    /// Mean position error norm (m).
    pub mean_m: f64,
    /// Largest position error norm (m).
    pub max_m: f64,
    /// ISO 9283-style mean (m): the mean over poses of the norm of the pose's mean error vector.
    pub iso_mean_m: f64,
}

impl HeldOutStats {
    /// The statistics of `errors` (m, `predicted − measured`), one per row, the rows of pose
    /// `pose_key[r]` (campaign, pose) averaged for the ISO mean.
    pub fn of(errors: &[Vector3<f64>], pose_key: &[(i64, i64)]) -> Self {
        assert_eq!(errors.len(), pose_key.len(), "one pose per error");
        let n = errors.len();
        if n == 0 {
            return HeldOutStats::default();
        }
        let (mut sum2, mut sum, mut max) = (0.0, 0.0, 0.0f64);
        let mut per_pose: BTreeMap<(i64, i64), (Vector3<f64>, usize)> = BTreeMap::new();
        for (e, key) in errors.iter().zip(pose_key) {
            let v = e.norm();
            sum2 += v * v;
            sum += v;
            max = max.max(v);
            let entry = per_pose.entry(*key).or_insert((Vector3::zeros(), 0));
            entry.0 += e;
            entry.1 += 1;
        }
        let iso = per_pose
            .values()
            .map(|(s, k)| (s / *k as f64).norm())
            .sum::<f64>()
            / per_pose.len() as f64;
        HeldOutStats {
            n_rows: n,
            n_poses: per_pose.len(),
            rms_m: (sum2 / n as f64).sqrt(),
            mean_m: sum / n as f64,
            max_m: max,
            iso_mean_m: iso,
        }
    }
}

/// One fold of a cross-validation.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FoldStats {
    /// Fold (0-based).
    pub fold: usize,
    /// Poses fitted.
    pub n_train_poses: usize,
    /// The calibrated model (learned correction included, when there is one) on the fold's poses.
    pub held_out: HeldOutStats,
}

/// How a calibration was validated, and what it gave.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Validation {
    /// `cross_validation`, `test_fraction` (one split of the data) or `test_data` (another file).
    pub kind: String,
    /// Folds of a cross-validation.
    pub folds: Option<usize>,
    /// Seed of the folds or the split.
    pub seed: Option<u64>,
    /// Held-out errors of the nominal robot (only base and target fitted).
    pub before: HeldOutStats,
    /// Held-out errors of the calibrated physical model.
    pub after: HeldOutStats,
    /// Held-out errors with the learned correction, for a model that has one.
    pub learned: Option<HeldOutStats>,
    /// Per fold, for a cross-validation.
    pub per_fold: Vec<FoldStats>,
    /// Standard deviation of the per-fold RMS (m): how much one fold's estimate varies.
    pub fold_rms_spread_m: Option<f64>,
}

impl Validation {
    /// The final model's held-out errors: with the learned correction when there is one.
    pub fn final_stats(&self) -> &HeldOutStats {
        self.learned.as_ref().unwrap_or(&self.after)
    }

    /// The validation as text for a terminal.
    pub fn text(&self, model: &str) -> String {
        let how = match (self.kind.as_str(), self.folds) {
            ("cross_validation", Some(k)) => format!(
                "{k}-fold cross-validation by pose (seed {}): every pose held out once, predicted by a model \
                 fitted on the other folds",
                self.seed.unwrap_or(0)
            ),
            ("test_fraction", _) => format!(
                "one split by pose (seed {}): the held-out poses predicted by a model fitted on the others",
                self.seed.unwrap_or(0)
            ),
            _ => "the test data, predicted by the saved model".to_string(),
        };
        let mm = |v: f64| format!("{:.4} mm", v * 1e3);
        let w = model.chars().count().max(20);
        let mut s = format!(
            "validation on held-out poses: {how}\n  {:<w$} {:>6} {:>12} {:>12} {:>12} {:>12}\n",
            "model", "poses", "RMS", "mean", "max", "ISO mean"
        );
        let mut row = |name: &str, st: &HeldOutStats| {
            s.push_str(&format!(
                "  {name:<w$} {:>6} {:>12} {:>12} {:>12} {:>12}\n",
                st.n_poses,
                mm(st.rms_m),
                mm(st.mean_m),
                mm(st.max_m),
                mm(st.iso_mean_m)
            ));
        };
        row("nominal+base+target", &self.before);
        let physical = model.split("+learned:").next().unwrap_or(model);
        row(physical, &self.after);
        if let Some(l) = &self.learned {
            row(model, l);
        }
        if let Some(sd) = self.fold_rms_spread_m {
            s.push_str(&format!(
                "  per-fold RMS: {} (spread {:.4} mm)\n",
                self.per_fold
                    .iter()
                    .map(|f| format!("{:.4}", f.held_out.rms_m * 1e3))
                    .collect::<Vec<_>>()
                    .join(", "),
                sd * 1e3
            ));
        }
        s
    }
}

/// Fold of every row of `data` for `k`-fold cross-validation by pose: the poses (campaign, pose id)
/// of each campaign, in order of first appearance, are shuffled with `seed` (one generator, the
/// campaigns in ascending order) and dealt round-robin, the count running on across campaigns, so that
/// folds differ by at most one pose and each campaign is spread evenly. Rows of a pose share its fold.
pub fn pose_folds(data: &Dataset<'_>, k: usize, seed: u64) -> Vec<usize> {
    assert!(k > 0, "at least one fold");
    let table = data.table;
    let mut index: BTreeMap<i64, Vec<(i64, i64)>> = BTreeMap::new();
    let mut seen = std::collections::HashSet::new();
    for &r in &data.rows {
        let key = table.pose_key(r);
        if seen.insert(key) {
            index.entry(key.0).or_default().push(key);
        }
    }
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let mut fold_of: std::collections::HashMap<(i64, i64), usize> = Default::default();
    let mut dealt = 0usize;
    for poses in index.values_mut() {
        poses.shuffle(&mut rng);
        for key in poses.iter() {
            fold_of.insert(*key, dealt % k);
            dealt += 1;
        }
    }
    data.rows
        .iter()
        .map(|&r| fold_of[&table.pose_key(r)])
        .collect()
}

/// The pose key (campaign, pose) of every row of `data`.
fn pose_keys(data: &Dataset<'_>) -> Vec<(i64, i64)> {
    data.rows.iter().map(|&r| data.table.pose_key(r)).collect()
}

/// Held-out errors of the fitted `cal` on `test` (nominal, physical, with the learned correction).
type FoldErrors = (
    Vec<Vector3<f64>>,
    Vec<Vector3<f64>>,
    Option<Vec<Vector3<f64>>>,
);

/// The errors of `cal`'s nominal, physical and learned models on `test`.
pub fn held_out_errors(
    model: &Model,
    cal: &Calibration,
    test: &Dataset<'_>,
    options: &CalibrationOptions,
) -> Result<FoldErrors> {
    let obs = observations(
        model,
        test,
        options,
        cal.extensions.as_ref(),
        &cal.params.extension,
    )?;
    obs.campaign_indices_or_error(&cal.params, &test.name)?;
    // The nominal model's extension values are zero: the regressors do not move it.
    let before = Prediction::new(model, &cal.before).errors(&obs);
    let after = Prediction::new(model, cal.physical.as_ref().unwrap_or(&cal.params)).errors(&obs);
    let learned = cal.learned.as_ref().map(|l| {
        Prediction::new(model, &cal.params)
            .with_learned(Some(l))
            .errors(&obs)
    });
    Ok((before, after, learned))
}

/// Validation of `final_cal` (fitted on `data`) on the separate `test` set: its own errors there.
pub fn on_test_set(
    model: &Model,
    final_cal: &Calibration,
    test: &Dataset<'_>,
    options: &CalibrationOptions,
    kind: &str,
    seed: Option<u64>,
) -> Result<Validation> {
    let (before, after, learned) = held_out_errors(model, final_cal, test, options)?;
    let keys = pose_keys(test);
    Ok(Validation {
        kind: kind.into(),
        folds: None,
        seed,
        before: HeldOutStats::of(&before, &keys),
        after: HeldOutStats::of(&after, &keys),
        learned: learned.map(|e| HeldOutStats::of(&e, &keys)),
        per_fold: Vec::new(),
        fold_rms_spread_m: None,
    })
}

/// `k`-fold cross-validation by pose ([`pose_folds`], seed `seed`) of `request`'s model on `data`,
/// folds fitted in parallel. Each fold's fit starts from the closed form, or, with `all` (the
/// calibration of the same model on every row of `data`: what `calibrate` saves), at `all`: the same
/// minima, reached in fewer iterations, without the fold reports' training statistics (see
/// [`WarmStart`]). Errors: fewer poses than folds, or a fold whose training poses cannot determine
/// the model (named with the fold: [`Part::FoldTraining`]).
pub fn cross_validate(
    model: &Model,
    data: &Dataset<'_>,
    request: &FitRequest<'_>,
    k: usize,
    seed: u64,
    all: Option<&Calibration>,
) -> Result<Validation> {
    cross_validate_from(model, data, request, k, seed, all.map(WarmStart::near))
}

/// Every fold's [`FoldShare`] at `start`'s "before" and physical parameters, from one pass over
/// the rows of `data` for each (`fold_of` per row, `k` folds): fold `f`'s is the sum of the other
/// folds' shares, in fold order. `None` where the folds cannot start there (see [`WarmStart`]),
/// with a robust loss (its reweighting starts elsewhere), or for an extended model.
fn fold_shares(
    model: &Model,
    data: &Dataset<'_>,
    request: &FitRequest<'_>,
    fold_of: &[usize],
    k: usize,
    start: &WarmStart<'_>,
) -> Result<Option<Vec<FoldShare>>> {
    let options = request.options();
    if !request.model().causes.is_empty() || options.robust.is_some() {
        return Ok(None);
    }
    let obs = observations(model, data, options, None, &[])?;
    if !start.fits(&obs) {
        return Ok(None);
    }
    let layout = ParamLayout::for_params(model, start.physical, obs.ext.params.clone());
    let scales = options.scales.vector(&layout);
    let stage = |params: &KinematicParams, active: Vec<usize>| -> Vec<SolveShare> {
        let p = active.len();
        let stage_scales: Vec<f64> = active.iter().map(|&k| scales[k]).collect();
        let mut problem = KinematicProblem::new(model, &obs, params.clone(), active);
        let parts = problem.group_parts(&stage_scales, fold_of, k);
        (0..k)
            .map(|f| {
                let others = || parts.iter().enumerate().filter(move |(g, _)| *g != f);
                let mut gram = DMatrix::zeros(p, p);
                let mut gradient = vec![0.0; p];
                let mut cost = 0.0;
                for (_, part) in others() {
                    cost += part.cost;
                    for (t, v) in gradient.iter_mut().zip(&part.gradient) {
                        *t += v;
                    }
                    for (t, v) in gram.as_mut_slice().iter_mut().zip(&part.gram) {
                        *t += v;
                    }
                }
                for a in 0..p {
                    for b in a + 1..p {
                        gram[(a, b)] = gram[(b, a)];
                    }
                }
                let factors: Vec<DMatrix<f64>> = others()
                    .flat_map(|(_, part)| part.factors.iter().cloned())
                    .collect();
                SolveShare {
                    cost,
                    gram,
                    gradient,
                    factor: crate::linalg::stacked_r_factor(&factors, p),
                }
            })
            .collect()
    };
    crate::cancel::checkpoint()?;
    let before = stage(start.before, layout.base_and_target());
    crate::cancel::checkpoint()?;
    let after = stage(start.physical, (0..layout.len()).collect());
    let shares = before
        .into_iter()
        .zip(after)
        .map(|(before, after)| FoldShare { before, after })
        .collect();
    Ok(Some(shares))
}

/// The training and held-out rows of fold `f` (`fold_of` per row of `data`): the training rows as
/// table rows, the held-out ones as indices into `data.rows`.
fn fold_rows(data: &Dataset<'_>, fold_of: &[usize], f: usize) -> (Vec<usize>, Vec<usize>) {
    let mut train = Vec::new();
    let mut test = Vec::new();
    for (i, &r) in data.rows.iter().enumerate() {
        if fold_of[i] == f {
            test.push(i);
        } else {
            train.push(r);
        }
    }
    (train, test)
}

/// Fits fold `f` of `data` (`fold_of` per row) and predicts its held-out rows: the fold's
/// calibration, the errors, and the held-out rows as indices into `data.rows`.
fn fit_fold(
    model: &Model,
    data: &Dataset<'_>,
    request: &FitRequest<'_>,
    fold_of: &[usize],
    f: usize,
    start: Option<WarmStart<'_>>,
) -> Result<(Calibration, FoldErrors, Vec<usize>)> {
    let (train, test) = fold_rows(data, fold_of, f);
    let train_set = data.part(train, Part::FoldTraining(f + 1));
    let test_set = data.part(
        test.iter().map(|&i| data.rows[i]).collect(),
        Part::FoldHeldOut(f + 1),
    );
    let fold_request = request.clone().judged_on(None).with_warm(start);
    let cal = fit(model, &train_set, &fold_request)?;
    let errors = held_out_errors(model, &cal, &test_set, request.options())?;
    Ok((cal, errors, test))
}

/// The calibrations of the `k` folds of [`cross_validate`] (seed `seed`), in fold order, each from
/// the closed-form start, or, with `all` (the calibration of `spec` on every row of `data`), started
/// there as [`cross_validate`] with `all` does: for inspection and for checking that both reach the same
/// minima. A fold started at `all` has no training statistics or outliers in its report, and, when
/// its rank decision came from the shared factor, its subspace and covariance are those at `all`'s
/// solution.
pub fn fold_calibrations(
    model: &Model,
    data: &Dataset<'_>,
    request: &FitRequest<'_>,
    k: usize,
    seed: u64,
    all: Option<&Calibration>,
) -> Result<Vec<Calibration>> {
    let fold_of = pose_folds(data, k, seed);
    fit_folds(model, data, request, &fold_of, k, all.map(WarmStart::near))?
        .into_iter()
        .map(|r| r.map(|(cal, ..)| cal))
        .collect()
}

/// Every fold's [`fit_fold`] (`fold_of` per row, `k` folds), in parallel, in fold order; with
/// `start`, after the pass over every row that the folds share ([`fold_shares`]).
#[allow(clippy::type_complexity)]
fn fit_folds(
    model: &Model,
    data: &Dataset<'_>,
    request: &FitRequest<'_>,
    fold_of: &[usize],
    k: usize,
    start: Option<WarmStart<'_>>,
) -> Result<Vec<Result<(Calibration, FoldErrors, Vec<usize>)>>> {
    let shares = match &start {
        Some(s) => fold_shares(model, data, request, fold_of, k, s)?,
        None => None,
    };
    Ok(crate::cancel::relayed(|relay| {
        (0..k)
            .into_par_iter()
            .map(|f| {
                let start = start.map(|s| WarmStart {
                    shared: shares.as_ref().map(|v| &v[f]),
                    ..s
                });
                relay.run(|| fit_fold(model, data, request, fold_of, f, start))
            })
            .collect()
    }))
}

fn cross_validate_from(
    model: &Model,
    data: &Dataset<'_>,
    request: &FitRequest<'_>,
    k: usize,
    seed: u64,
    start: Option<WarmStart<'_>>,
) -> Result<Validation> {
    let keys = pose_keys(data);
    let n_poses = keys.iter().collect::<std::collections::HashSet<_>>().len();
    if k < 2 || n_poses < k {
        return Err(CalibError::BadValue {
            context: data.name.clone(),
            field: "--folds".into(),
            value: k.to_string(),
            problem: format!(
                "cross-validation needs at least 2 folds and a pose per fold ({n_poses} poses)"
            ),
        });
    }
    let fold_of = pose_folds(data, k, seed);
    let results: Vec<Result<(FoldErrors, Vec<usize>, usize)>> =
        fit_folds(model, data, request, &fold_of, k, start)?
            .into_iter()
            .map(|r| r.map(|(cal, errors, test)| (errors, test, cal.report.n_train_poses)))
            .collect();
    let n = data.rows.len();
    let (mut before, mut after) = (vec![Vector3::zeros(); n], vec![Vector3::zeros(); n]);
    let mut learned: Option<Vec<Vector3<f64>>> = None;
    let mut per_fold = Vec::with_capacity(k);
    for (f, res) in results.into_iter().enumerate() {
        let ((b, a, l), idx, n_train_poses) = res?;
        let fold_keys: Vec<(i64, i64)> = idx.iter().map(|&i| keys[i]).collect();
        per_fold.push(FoldStats {
            fold: f,
            n_train_poses,
            held_out: HeldOutStats::of(l.as_ref().unwrap_or(&a), &fold_keys),
        });
        for (j, &i) in idx.iter().enumerate() {
            before[i] = b[j];
            after[i] = a[j];
        }
        if let Some(l) = l {
            let all = learned.get_or_insert_with(|| vec![Vector3::zeros(); n]);
            for (j, &i) in idx.iter().enumerate() {
                all[i] = l[j];
            }
        }
    }
    let rms: Vec<f64> = per_fold.iter().map(|f| f.held_out.rms_m).collect();
    let mean = rms.iter().sum::<f64>() / k as f64;
    let spread = (rms.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (k - 1) as f64).sqrt();
    Ok(Validation {
        kind: "cross_validation".into(),
        folds: Some(k),
        seed: Some(seed),
        before: HeldOutStats::of(&before, &keys),
        after: HeldOutStats::of(&after, &keys),
        learned: learned.map(|e| HeldOutStats::of(&e, &keys)),
        per_fold,
        fold_rms_spread_m: Some(spread),
    })
}

/// How to validate a calibration ([`fit_and_validate`]).
#[derive(Clone, Debug)]
pub enum ValidationPlan<'a> {
    /// No validation (`--folds 0`).
    None,
    /// k-fold cross-validation by pose ([`cross_validate`]).
    Folds {
        /// Number of folds (≥ 2).
        k: usize,
        /// Seed of the folds.
        seed: u64,
    },
    /// One split by pose ([`crate::model::stats::split_by_pose`]): the held-out poses predicted by a model
    /// fitted on the others.
    Split {
        /// Fraction of the poses held out, in (0, 1).
        fraction: f64,
        /// Seed of the split.
        seed: u64,
    },
    /// Another file, predicted by the saved model.
    TestData(Dataset<'a>),
}

/// Fits `request`'s model on every row of `data` (the model to save) and validates it by `plan`.
/// With [`ValidationPlan::TestData`] the final calibration's report also carries the test set's
/// errors (its `before.test`, `after.test`).
pub fn fit_and_validate(
    model: &Model,
    data: &Dataset<'_>,
    request: &FitRequest<'_>,
    plan: &ValidationPlan<'_>,
) -> Result<(Calibration, Option<Validation>)> {
    let options = request.options();
    let test = match plan {
        ValidationPlan::TestData(t) => Some(t),
        _ => None,
    };
    let cal = fit(model, data, &request.clone().judged_on(test))?;
    let validation = match plan {
        ValidationPlan::None => None,
        ValidationPlan::TestData(t) => {
            Some(on_test_set(model, &cal, t, options, "test_data", None)?)
        }
        ValidationPlan::Folds { k, seed } => Some(cross_validate(
            model,
            data,
            &request.clone().judged_on(None),
            *k,
            *seed,
            Some(&cal),
        )?),
        ValidationPlan::Split { fraction, seed } => {
            let sub = data.table.select_rows(&data.rows);
            let (tr, te) = crate::model::stats::split_by_pose(&sub, *fraction, *seed);
            let train = data.part(tr.iter().map(|&i| data.rows[i]).collect(), Part::Training);
            let test = data.part(te.iter().map(|&i| data.rows[i]).collect(), Part::Test);
            let split = fit(model, &train, &request.clone().judged_on(None))?;
            Some(on_test_set(
                model,
                &split,
                &test,
                options,
                "test_fraction",
                Some(*seed),
            )?)
        }
    };
    Ok((cal, validation))
}
