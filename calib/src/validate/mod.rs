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
pub mod gauss_newton;
mod groups;
pub mod regions;
mod stats;
pub mod stream;

pub use groups::fold_calibrations;
use groups::*;
pub use stats::{ByCampaign, ByRegion, FoldStats, HeldOutStats, HeldOutSum, Validation};

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
        Some(&cal.params),
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
    let stats = pooled.stats(keys);
    Validation::cross_validation(k, seed, stats, pooled.per_group)
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
    let groups = Groups::new(&fold_of, k, Grouping::Folds);
    let pooled = pooled_alone(model, data, request, &groups, start, &keys)?;
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
    cross_validate_labelled(
        model,
        data,
        request,
        (&fold_of, k),
        Some((&region_of, regions)),
        seed,
        all,
    )
}

/// Cross-validation of `request`'s model on `data` with the folds and regions given as labels, one
/// per row of `data` (`folds.0[i] < folds.1`, the same for `regions`): each fold, and each region,
/// predicted by the model fitted on the others, started at `all` (the model on every row) and
/// sharing one pass over the rows there; then, with several campaigns, leave-one-campaign-out.
/// [`cross_validate_with_regions`] with its own folds and regions; a streamed validation's groups
/// ([`stream::StreamGroups::labels`]) give the in-memory validation of the same groups. `seed` is
/// reported, and seeds the leave-one-campaign-out draw. Errors: a label out of range or a label
/// count other than the rows', fewer than two groups, or a group whose complement cannot determine
/// the model.
pub fn cross_validate_labelled(
    model: &Model,
    data: &Dataset<'_>,
    request: &FitRequest<'_>,
    folds: (&[usize], usize),
    regions: Option<(&[usize], usize)>,
    seed: u64,
    all: Option<&Calibration>,
) -> Result<Validation> {
    let keys = pose_keys(data);
    let check_labels = |(of, k): (&[usize], usize), flag: &str| -> Result<()> {
        if of.len() != data.rows.len() || of.iter().any(|&g| g >= k) || k < 2 {
            return Err(CalibError::BadValue {
                context: data.name.clone(),
                field: flag.into(),
                value: format!("{} labels of {k} groups", of.len()),
                problem: format!(
                    "a label below {k} for each of the {} rows, and at least 2 groups",
                    data.rows.len()
                ),
            });
        }
        Ok(())
    };
    check_labels(folds, "--folds")?;
    let (fold_of, k) = folds;
    let fold_groups = Groups::new(fold_of, k, Grouping::Folds);
    let start = all.map(WarmStart::near);
    let mut v = match regions {
        None => {
            let pooled = pooled_alone(model, data, request, &fold_groups, start, &keys)?;
            folds_validation(pooled, &keys, k, seed)
        }
        Some(regions) => {
            check_labels(regions, "--regions")?;
            let (region_of, r) = regions;
            let by_region = Groups::new(region_of, r, Grouping::Regions);
            let shares = shares_for(
                model,
                data,
                request,
                &[&fold_groups, &by_region],
                start.as_ref(),
            )?;
            let share = |j: usize| shares.as_ref().map(|s| s[j].as_slice());
            // Both groupings' fits at once: ten fits keep two cores busier than two rounds of five.
            let (pooled_folds, pooled_regions) = crate::cancel::relayed(|relay| {
                rayon::join(
                    || {
                        relay.run(|| {
                            pooled(model, data, request, &fold_groups, start, share(0), &keys)
                        })
                    },
                    || {
                        relay.run(|| {
                            pooled(model, data, request, &by_region, start, share(1), &keys)
                        })
                    },
                )
            });
            let mut v = folds_validation(pooled_folds?, &keys, k, seed);
            let reg = regions_validation(pooled_regions?, &keys, r, seed);
            v.set_regions(reg);
            v
        }
    };
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
    let groups = Groups::new(&region_of, k, Grouping::Regions);
    let pooled = pooled_alone(
        model,
        data,
        request,
        &groups,
        all.map(WarmStart::near),
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
            self.set_regions(validate_by_region(model, data, &request, k, seed, all)?);
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
