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

pub mod campaigns;
pub mod regions;

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
    /// Regions of the leave-one-region-out validation (`--regions`; [`regions`]), when it ran.
    #[serde(default)]
    pub regions: Option<usize>,
    /// The saved model (its learned correction included, within its support) on held-out regions:
    /// what it promises for poses unlike the ones it saw ([`ByRegion::final_stats`]).
    #[serde(default)]
    pub new_region: Option<HeldOutStats>,
    /// The leave-one-region-out validation in detail.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub by_region: Option<ByRegion>,
    /// The saved model on campaigns it did not see, each registered on
    /// [`campaigns::REGISTER_POSES`] of its poses ([`campaigns`]), with several campaigns.
    #[serde(default)]
    pub new_campaign: Option<HeldOutStats>,
    /// The leave-one-campaign-out validation in detail.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub by_campaign: Option<ByCampaign>,
}

/// Leave-one-region-out validation: each region of the configuration space ([`regions`]) predicted
/// by the model fitted on the others.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ByRegion {
    /// Regions.
    pub regions: usize,
    /// Seed of the clustering.
    pub seed: u64,
    /// The nominal robot (base and target fitted).
    pub before: HeldOutStats,
    /// The calibrated physical model.
    pub after: HeldOutStats,
    /// With the learned correction, for a model that has one.
    pub learned: Option<HeldOutStats>,
    /// Per region: its poses, the poses fitted without it, the final model's errors on it.
    pub per_region: Vec<FoldStats>,
    /// Held-out rows not predicted: their campaign had no pose outside the region, so no fit
    /// registered it (the leave-one-campaign-out validation covers them).
    pub n_rows_not_predicted: usize,
}

impl ByRegion {
    /// The final model's errors: with the learned correction when there is one.
    pub fn final_stats(&self) -> &HeldOutStats {
        self.learned.as_ref().unwrap_or(&self.after)
    }
}

/// Leave-one-campaign-out validation ([`campaigns`]).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ByCampaign {
    /// Campaigns predicted.
    pub n_campaigns: usize,
    /// Poses of each that registered it.
    pub register_poses: usize,
    /// The calibrated physical model on the predicted poses.
    pub after: HeldOutStats,
    /// With the learned correction, for a model that has one.
    pub learned: Option<HeldOutStats>,
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
        if let Some(r) = &self.by_region {
            s.push_str(&format!(
                "validation on held-out regions: {} regions of the configuration space (k-means on \
                 sin q, cos q; seed {}), each predicted by a model fitted on the others\n",
                r.regions, r.seed
            ));
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
            row("nominal+base+target", &r.before);
            row(physical, &r.after);
            if let Some(l) = &r.learned {
                row(model, l);
            }
            if r.n_rows_not_predicted > 0 {
                s.push_str(&format!(
                    "  {} held-out rows not predicted: their campaign lies inside one region\n",
                    r.n_rows_not_predicted
                ));
            }
        }
        if let Some(c) = &self.by_campaign {
            s.push_str(&format!(
                "validation on unseen campaigns: each of {} campaigns predicted by a model fitted on \
                 the others, registered on {} of its poses\n",
                c.n_campaigns, c.register_poses
            ));
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
            row(physical, &c.after);
            if let Some(l) = &c.learned {
                row(model, l);
            }
        }
        if let Some(promise) = self.promise_text() {
            s.push_str(&promise);
        }
        s
    }

    /// How far to trust the figures: the promise for poses unlike the calibration's, against the
    /// held-out poses' figure.
    pub fn promise_text(&self) -> Option<String> {
        let region = self.new_region.as_ref()?;
        let poses = self.final_stats();
        let mm = |v: f64| format!("{:.4} mm", v * 1e3);
        let ratio = if poses.mean_m > 0.0 {
            region.mean_m / poses.mean_m
        } else {
            1.0
        };
        let mut s = format!(
            "promise: {} mean on poses like the calibration's (held-out poses), {} on poses unlike them \
             (held-out regions)",
            mm(poses.mean_m),
            mm(region.mean_m)
        );
        if let Some(c) = &self.new_campaign {
            s.push_str(&format!(", {} on a new campaign", mm(c.mean_m)));
        }
        s.push_str(if ratio > 1.25 {
            ". The model is worth less away from its poses: expect the held-out-region figure where \
             you did not measure, and measure there to do better.\n"
        } else {
            ". The two agree: the figure holds across the workspace the regions span.\n"
        });
        Some(s)
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
        regions: None,
        new_region: None,
        by_region: None,
        new_campaign: None,
        by_campaign: None,
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

/// Every group's [`FoldShare`] at `start`'s "before" and physical parameters, for each grouping
/// of `groupings` (a group per row of `data` and the number of groups: the folds, the regions), from
/// one pass over the rows of `data` per stage: the rows are grouped by their groups in every grouping
/// at once, and group `f` of a grouping takes the sum of the combined groups outside it, in combined
/// order (the `R` factors stacked per combined group first). `None` where the groups cannot start
/// there (see [`WarmStart`]), with a robust loss (its reweighting starts elsewhere), or for an
/// extended model.
fn fold_shares(
    model: &Model,
    data: &Dataset<'_>,
    request: &FitRequest<'_>,
    groupings: &[(&[usize], usize)],
    start: &WarmStart<'_>,
) -> Result<Option<Vec<Vec<FoldShare>>>> {
    let options = request.options();
    if !request.model().causes.is_empty() || options.robust.is_some() {
        return Ok(None);
    }
    let obs = observations(model, data, options, None, &[])?;
    if !start.fits(&obs) {
        return Ok(None);
    }
    // The combined group of every row: its groups as the digits of a mixed-radix number.
    let total: usize = groupings.iter().map(|(_, k)| k).product();
    let digit = |c: usize, j: usize| -> usize {
        let stride: usize = groupings[j + 1..].iter().map(|(_, k)| k).product();
        (c / stride) % groupings[j].1
    };
    let combined: Vec<usize> = (0..data.rows.len())
        .map(|i| groupings.iter().fold(0, |acc, (g, k)| acc * k + g[i]))
        .collect();
    let layout = ParamLayout::for_params(model, start.physical, obs.ext.params.clone());
    let scales = options.scales.vector(&layout);
    let stage = |params: &KinematicParams, active: Vec<usize>| -> Vec<Vec<SolveShare>> {
        let p = active.len();
        let stage_scales: Vec<f64> = active.iter().map(|&k| scales[k]).collect();
        let mut problem = KinematicProblem::new(model, &obs, params.clone(), active);
        let parts = problem.group_parts(&stage_scales, &combined, total);
        let merged: Vec<Option<DMatrix<f64>>> = parts
            .par_iter()
            .map(|part| {
                (!part.factors.is_empty())
                    .then(|| crate::linalg::stacked_r_factor(&part.factors, p))
            })
            .collect();
        groupings
            .iter()
            .enumerate()
            .map(|(j, (_, k))| {
                (0..*k)
                    .map(|f| {
                        let others = || (0..total).filter(move |&c| digit(c, j) != f);
                        let mut gram = DMatrix::zeros(p, p);
                        let mut gradient = vec![0.0; p];
                        let mut cost = 0.0;
                        for c in others() {
                            let part = &parts[c];
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
                        let factors: Vec<DMatrix<f64>> =
                            others().filter_map(|c| merged[c].clone()).collect();
                        SolveShare {
                            cost,
                            gram,
                            gradient,
                            factor: crate::linalg::stacked_r_factor(&factors, p),
                        }
                    })
                    .collect()
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
        .map(|(before, after)| {
            before
                .into_iter()
                .zip(after)
                .map(|(before, after)| FoldShare { before, after })
                .collect()
        })
        .collect();
    Ok(Some(shares))
}

/// How the rows are grouped for a cross-validation: what a group's parts are called.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Grouping {
    /// Folds by pose ([`pose_folds`]).
    Folds,
    /// Regions of the configuration space ([`region_of_rows`]).
    Regions,
}

impl Grouping {
    /// The training and held-out parts of group `f` (0-based).
    fn parts(self, f: usize) -> (Part, Part) {
        match self {
            Grouping::Folds => (Part::FoldTraining(f + 1), Part::FoldHeldOut(f + 1)),
            Grouping::Regions => (Part::RegionTraining(f + 1), Part::RegionHeldOut(f + 1)),
        }
    }
}

/// The training and held-out rows of group `f` (`fold_of` per row of `data`): the training rows as
/// table rows, the held-out ones as indices into `data.rows`. With several campaigns, held-out rows
/// of a campaign with no training row are left out of both (no fit registers that campaign); their
/// count is the third value.
fn fold_rows(data: &Dataset<'_>, fold_of: &[usize], f: usize) -> (Vec<usize>, Vec<usize>, usize) {
    let mut train = Vec::new();
    let mut test = Vec::new();
    for (i, &r) in data.rows.iter().enumerate() {
        if fold_of[i] == f {
            test.push(i);
        } else {
            train.push(r);
        }
    }
    let table = data.table;
    if table.campaign.is_none() {
        return (train, test, 0);
    }
    let known: std::collections::HashSet<Option<i64>> =
        train.iter().map(|&r| table.campaign_of(r)).collect();
    let before = test.len();
    test.retain(|&i| known.contains(&table.campaign_of(data.rows[i])));
    let dropped = before - test.len();
    (train, test, dropped)
}

/// One group's fit and its held-out errors.
struct GroupFit {
    cal: Calibration,
    errors: FoldErrors,
    /// Held-out rows, as indices into `data.rows`.
    test: Vec<usize>,
    /// Held-out rows not predicted ([`fold_rows`]).
    dropped: usize,
}

/// Fits group `f` of `data` (`fold_of` per row) and predicts its held-out rows.
fn fit_fold(
    model: &Model,
    data: &Dataset<'_>,
    request: &FitRequest<'_>,
    fold_of: &[usize],
    f: usize,
    grouping: Grouping,
    start: Option<WarmStart<'_>>,
) -> Result<GroupFit> {
    let (train, test, dropped) = fold_rows(data, fold_of, f);
    let (train_part, test_part) = grouping.parts(f);
    let train_set = data.part(train, train_part);
    let test_set = data.part(test.iter().map(|&i| data.rows[i]).collect(), test_part);
    let fold_request = request.clone().judged_on(None).with_warm(start);
    let cal = fit(model, &train_set, &fold_request)?;
    let errors = held_out_errors(model, &cal, &test_set, request.options())?;
    Ok(GroupFit {
        cal,
        errors,
        test,
        dropped,
    })
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
    let groups = Groups {
        of: &fold_of,
        k,
        grouping: Grouping::Folds,
    };
    let start = all.map(WarmStart::near);
    let shares = shares_for(model, data, request, &[&groups], start.as_ref())?;
    fit_folds(
        model,
        data,
        request,
        &groups,
        start,
        shares.as_ref().map(|s| s[0].as_slice()),
    )
    .into_iter()
    .map(|r| r.map(|g| g.cal))
    .collect()
}

/// A grouping of the rows of a data set for a cross-validation.
struct Groups<'g> {
    /// Group per row.
    of: &'g [usize],
    /// Number of groups.
    k: usize,
    /// What the groups are.
    grouping: Grouping,
}

/// [`fold_shares`] of every grouping of `groups` at `start`, or `None` without a start or where
/// they cannot start there.
fn shares_for(
    model: &Model,
    data: &Dataset<'_>,
    request: &FitRequest<'_>,
    groups: &[&Groups<'_>],
    start: Option<&WarmStart<'_>>,
) -> Result<Option<Vec<Vec<FoldShare>>>> {
    match start {
        Some(s) => {
            let groupings: Vec<(&[usize], usize)> = groups.iter().map(|g| (g.of, g.k)).collect();
            fold_shares(model, data, request, &groupings, s)
        }
        None => Ok(None),
    }
}

/// Every group's [`fit_fold`], in parallel, in group order; with `start`, and with `shares` (one
/// per group: the pass over every row that the groups share, [`fold_shares`]) when given.
fn fit_folds(
    model: &Model,
    data: &Dataset<'_>,
    request: &FitRequest<'_>,
    groups: &Groups<'_>,
    start: Option<WarmStart<'_>>,
    shares: Option<&[FoldShare]>,
) -> Vec<Result<GroupFit>> {
    crate::cancel::relayed(|relay| {
        (0..groups.k)
            .into_par_iter()
            .map(|f| {
                let start = start.map(|s| WarmStart {
                    shared: shares.map(|v| &v[f]),
                    ..s
                });
                relay.run(|| fit_fold(model, data, request, groups.of, f, groups.grouping, start))
            })
            .collect()
    })
}

/// The pooled held-out errors of a grouped cross-validation, per row of `data` (rows left out by
/// [`fold_rows`] are not in `rows`).
struct Pooled {
    /// Indices into `data.rows` of the predicted rows, in row order.
    rows: Vec<usize>,
    before: Vec<Vector3<f64>>,
    after: Vec<Vector3<f64>>,
    learned: Option<Vec<Vector3<f64>>>,
    per_group: Vec<FoldStats>,
    dropped: usize,
}

impl Pooled {
    /// The statistics of the nominal, physical and learned errors over the predicted rows.
    fn stats(&self, keys: &[(i64, i64)]) -> (HeldOutStats, HeldOutStats, Option<HeldOutStats>) {
        let keys: Vec<(i64, i64)> = self.rows.iter().map(|&i| keys[i]).collect();
        (
            HeldOutStats::of(&self.before, &keys),
            HeldOutStats::of(&self.after, &keys),
            self.learned.as_ref().map(|l| HeldOutStats::of(l, &keys)),
        )
    }
}

/// Fits every group of `groups` (started and sharing as [`fit_folds`]) and pools the held-out
/// errors; `keys` is the pose key of every row of `data`.
fn pooled(
    model: &Model,
    data: &Dataset<'_>,
    request: &FitRequest<'_>,
    groups: &Groups<'_>,
    start: Option<WarmStart<'_>>,
    shares: Option<&[FoldShare]>,
    keys: &[(i64, i64)],
) -> Result<Pooled> {
    let k = groups.k;
    let results = fit_folds(model, data, request, groups, start, shares);
    let n = data.rows.len();
    let (mut before, mut after) = (vec![Vector3::zeros(); n], vec![Vector3::zeros(); n]);
    let mut learned: Option<Vec<Vector3<f64>>> = None;
    let mut predicted = vec![false; n];
    let mut per_group = Vec::with_capacity(k);
    let mut dropped = 0;
    for (f, res) in results.into_iter().enumerate() {
        let GroupFit {
            cal,
            errors: (b, a, l),
            test: idx,
            dropped: d,
        } = res?;
        dropped += d;
        if idx.is_empty() {
            continue;
        }
        let group_keys: Vec<(i64, i64)> = idx.iter().map(|&i| keys[i]).collect();
        per_group.push(FoldStats {
            fold: f,
            n_train_poses: cal.report.n_train_poses,
            held_out: HeldOutStats::of(l.as_ref().unwrap_or(&a), &group_keys),
        });
        for (j, &i) in idx.iter().enumerate() {
            before[i] = b[j];
            after[i] = a[j];
            predicted[i] = true;
        }
        if let Some(l) = l {
            let all = learned.get_or_insert_with(|| vec![Vector3::zeros(); n]);
            for (j, &i) in idx.iter().enumerate() {
                all[i] = l[j];
            }
        }
    }
    let rows: Vec<usize> = (0..n).filter(|&i| predicted[i]).collect();
    let pick = |v: Vec<Vector3<f64>>| -> Vec<Vector3<f64>> { rows.iter().map(|&i| v[i]).collect() };
    Ok(Pooled {
        before: pick(before),
        after: pick(after),
        learned: learned.map(pick),
        rows,
        per_group,
        dropped,
    })
}

/// Checks that `data` has at least `k ≥ 2` poses for `k` groups of `flag`.
fn check_groups(
    data: &Dataset<'_>,
    keys: &[(i64, i64)],
    k: usize,
    flag: &str,
    what: &str,
) -> Result<()> {
    let n_poses = keys.iter().collect::<std::collections::HashSet<_>>().len();
    if k < 2 || n_poses < k {
        return Err(CalibError::BadValue {
            context: data.name.clone(),
            field: flag.into(),
            value: k.to_string(),
            problem: format!("{what} ({n_poses} poses)"),
        });
    }
    Ok(())
}

/// The validation of `k` folds (seed `seed`) from their pooled errors.
fn folds_validation(pooled: Pooled, keys: &[(i64, i64)], k: usize, seed: u64) -> Validation {
    let (before, after, learned) = pooled.stats(keys);
    let per_fold = pooled.per_group;
    let rms: Vec<f64> = per_fold.iter().map(|f| f.held_out.rms_m).collect();
    let mean = rms.iter().sum::<f64>() / k as f64;
    let spread = (rms.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (k - 1) as f64).sqrt();
    Validation {
        kind: "cross_validation".into(),
        folds: Some(k),
        seed: Some(seed),
        before,
        after,
        learned,
        per_fold,
        fold_rms_spread_m: Some(spread),
        regions: None,
        new_region: None,
        by_region: None,
        new_campaign: None,
        by_campaign: None,
    }
}

/// The leave-one-region-out validation of `k` regions (seed `seed`) from their pooled errors.
fn regions_validation(pooled: Pooled, keys: &[(i64, i64)], k: usize, seed: u64) -> ByRegion {
    let (before, after, learned) = pooled.stats(keys);
    ByRegion {
        regions: k,
        seed,
        before,
        after,
        learned,
        per_region: pooled.per_group,
        n_rows_not_predicted: pooled.dropped,
    }
}

const FOLDS_NEED: &str = "cross-validation needs at least 2 folds and a pose per fold";
const REGIONS_NEED: &str = "validation by region needs at least 2 regions and a pose per region";

fn cross_validate_from(
    model: &Model,
    data: &Dataset<'_>,
    request: &FitRequest<'_>,
    k: usize,
    seed: u64,
    start: Option<WarmStart<'_>>,
) -> Result<Validation> {
    let keys = pose_keys(data);
    check_groups(data, &keys, k, "--folds", FOLDS_NEED)?;
    let fold_of = pose_folds(data, k, seed);
    let groups = Groups {
        of: &fold_of,
        k,
        grouping: Grouping::Folds,
    };
    let shares = shares_for(model, data, request, &[&groups], start.as_ref())?;
    let pooled = pooled(
        model,
        data,
        request,
        &groups,
        start,
        shares.as_ref().map(|s| s[0].as_slice()),
        &keys,
    )?;
    Ok(folds_validation(pooled, &keys, k, seed))
}

/// `k`-fold cross-validation by pose and leave-one-region-out validation with `regions` regions
/// (both seed `seed`) of `request`'s model on `data`, every fit started at `all` (the model on every
/// row) and the folds and regions sharing one pass over the rows there; then, with several
/// campaigns, leave-one-campaign-out ([`validate_by_campaign`]).
pub fn cross_validate_with_regions(
    model: &Model,
    data: &Dataset<'_>,
    request: &FitRequest<'_>,
    k: usize,
    regions: usize,
    seed: u64,
    all: Option<&Calibration>,
) -> Result<Validation> {
    if regions < 2 {
        let mut v = cross_validate(model, data, request, k, seed, all)?;
        v.add_transfer(model, data, request, 0, seed, all)?;
        return Ok(v);
    }
    let keys = pose_keys(data);
    check_groups(data, &keys, k, "--folds", FOLDS_NEED)?;
    check_groups(data, &keys, regions, "--regions", REGIONS_NEED)?;
    let fold_of = pose_folds(data, k, seed);
    let region_of = region_of_rows(data, regions, seed);
    let folds = Groups {
        of: &fold_of,
        k,
        grouping: Grouping::Folds,
    };
    let by_region = Groups {
        of: &region_of,
        k: regions,
        grouping: Grouping::Regions,
    };
    let start = all.map(WarmStart::near);
    let shares = shares_for(model, data, request, &[&folds, &by_region], start.as_ref())?;
    let share = |j: usize| shares.as_ref().map(|s| s[j].as_slice());
    // Both groupings' fits at once: ten fits keep two cores busier than two rounds of five.
    let (pooled_folds, pooled_regions) = crate::cancel::relayed(|relay| {
        rayon::join(
            || relay.run(|| pooled(model, data, request, &folds, start, share(0), &keys)),
            || relay.run(|| pooled(model, data, request, &by_region, start, share(1), &keys)),
        )
    });
    let mut v = folds_validation(pooled_folds?, &keys, k, seed);
    let r = regions_validation(pooled_regions?, &keys, regions, seed);
    v.regions = Some(regions);
    v.new_region = Some(r.final_stats().clone());
    v.by_region = Some(r);
    v.add_transfer(model, data, request, 0, seed, all)?;
    Ok(v)
}

/// Region (0..`k`) of every row of `data`: the poses clustered by [`regions::kmeans`] on
/// `(sin q, cos q)` of each pose's first row, seed `seed`; rows of a pose share its region.
pub fn region_of_rows(data: &Dataset<'_>, k: usize, seed: u64) -> Vec<usize> {
    let table = data.table;
    let mut index: std::collections::HashMap<(i64, i64), usize> = Default::default();
    let mut points = Vec::new();
    let pose_of: Vec<usize> = data
        .rows
        .iter()
        .map(|&r| {
            let next = index.len();
            *index.entry(table.pose_key(r)).or_insert_with(|| {
                regions::features(table.q_row(r), &mut points);
                next
            })
        })
        .collect();
    let dim = 2 * table.n_joints;
    let region = regions::kmeans(&points, dim.max(1), k, seed);
    pose_of.iter().map(|&p| region[p]).collect()
}

/// Leave-one-region-out validation of `request`'s model on `data`: `k` regions ([`region_of_rows`],
/// seed `seed`), each predicted by the model fitted on the others, started at `all` (the model on
/// every row) when given, as [`cross_validate`] does. Errors: fewer poses than regions, or a region
/// whose complement cannot determine the model ([`Part::RegionTraining`]).
pub fn validate_by_region(
    model: &Model,
    data: &Dataset<'_>,
    request: &FitRequest<'_>,
    k: usize,
    seed: u64,
    all: Option<&Calibration>,
) -> Result<ByRegion> {
    let keys = pose_keys(data);
    check_groups(data, &keys, k, "--regions", REGIONS_NEED)?;
    let region_of = region_of_rows(data, k, seed);
    let groups = Groups {
        of: &region_of,
        k,
        grouping: Grouping::Regions,
    };
    let start = all.map(WarmStart::near);
    let shares = shares_for(model, data, request, &[&groups], start.as_ref())?;
    let pooled = pooled(
        model,
        data,
        request,
        &groups,
        start,
        shares.as_ref().map(|s| s[0].as_slice()),
        &keys,
    )?;
    Ok(regions_validation(pooled, &keys, k, seed))
}

/// Leave-one-campaign-out validation ([`campaigns::leave_campaign_out`]) as statistics, or `None`
/// with fewer than two campaigns.
pub fn validate_by_campaign(
    model: &Model,
    data: &Dataset<'_>,
    request: &FitRequest<'_>,
    seed: u64,
) -> Result<Option<ByCampaign>> {
    let Some(out) = campaigns::leave_campaign_out(model, data, request, seed)? else {
        return Ok(None);
    };
    if out.n_campaigns == 0 {
        return Ok(None);
    }
    Ok(Some(ByCampaign {
        n_campaigns: out.n_campaigns,
        register_poses: campaigns::REGISTER_POSES,
        after: HeldOutStats::of(&out.physical, &out.keys),
        learned: out.learned.as_ref().map(|l| HeldOutStats::of(l, &out.keys)),
    }))
}

impl Validation {
    /// Adds the leave-one-region-out validation (`k` regions, seed `seed`) and, with several
    /// campaigns, the leave-one-campaign-out one, of `request`'s model on `data`, `all` its fit on
    /// every row.
    pub fn add_transfer(
        &mut self,
        model: &Model,
        data: &Dataset<'_>,
        request: &FitRequest<'_>,
        k: usize,
        seed: u64,
        all: Option<&Calibration>,
    ) -> Result<()> {
        let request = request.clone().judged_on(None);
        if k >= 2 {
            let r = validate_by_region(model, data, &request, k, seed, all)?;
            self.regions = Some(k);
            self.new_region = Some(r.final_stats().clone());
            self.by_region = Some(r);
        }
        if let Some(c) = validate_by_campaign(model, data, &request, seed)? {
            self.new_campaign = Some(c.learned.clone().unwrap_or_else(|| c.after.clone()));
            self.by_campaign = Some(c);
        }
        Ok(())
    }
}

/// How to validate a calibration ([`fit_and_validate`]).
#[derive(Clone, Debug)]
pub enum ValidationPlan<'a> {
    /// No validation (`--folds 0`).
    None,
    /// k-fold cross-validation by pose ([`cross_validate`]), then by region and campaign
    /// ([`Validation::add_transfer`]).
    Folds {
        /// Number of folds (≥ 2).
        k: usize,
        /// Seed of the folds and the regions.
        seed: u64,
        /// Regions held out in turn (0: none).
        regions: usize,
    },
    /// One split by pose ([`crate::model::stats::split_by_pose`]): the held-out poses predicted by a model
    /// fitted on the others.
    Split {
        /// Fraction of the poses held out, in (0, 1).
        fraction: f64,
        /// Seed of the split and the regions.
        seed: u64,
        /// Regions held out in turn (0: none).
        regions: usize,
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
        ValidationPlan::Folds { k, seed, regions } => Some(cross_validate_with_regions(
            model,
            data,
            &request.clone().judged_on(None),
            *k,
            *regions,
            *seed,
            Some(&cal),
        )?),
        ValidationPlan::Split { fraction, seed, .. } => {
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
    let validation = match (validation, plan) {
        (Some(mut v), ValidationPlan::Split { seed, regions, .. }) => {
            v.add_transfer(model, data, request, *regions, *seed, Some(&cal))?;
            Some(v)
        }
        (v, _) => v,
    };
    Ok((cal, validation))
}
