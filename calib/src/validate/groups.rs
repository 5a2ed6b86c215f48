//! Fitting the groups of a cross-validation (folds by pose, regions) in parallel, started at the
//! fit on every row and sharing one pass over the rows there, and pooling their held-out errors.

#[allow(unused_imports)]
use super::*;

/// Every group's [`FoldShare`] at `start`'s "before" and physical parameters, for each grouping
/// of `groupings` (a group per row of `data` and the number of groups: the folds, the regions), from
/// one pass over the rows of `data` per stage: the rows are grouped by their groups in every grouping
/// at once, and group `f` of a grouping takes the sum of the combined groups outside it, in combined
/// order (the `R` factors stacked per combined group first). `None` where the groups cannot start
/// there (see [`WarmStart`]), with a robust loss (its reweighting starts elsewhere), or for an
/// extended model.
pub(super) fn fold_shares(
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
    let obs = observations(model, data, options, None, None)?;
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
pub(super) enum Grouping {
    /// Folds by pose ([`pose_folds`]).
    Folds,
    /// Regions of the configuration space ([`region_of_rows`]).
    Regions,
}

impl Grouping {
    /// The training and held-out parts of group `f` (0-based).
    pub(super) fn parts(self, f: usize) -> (Part, Part) {
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
pub(super) fn fold_rows(
    data: &Dataset<'_>,
    fold_of: &[usize],
    f: usize,
) -> (Vec<usize>, Vec<usize>, usize) {
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
pub(super) struct GroupFit {
    pub(super) cal: Calibration,
    pub(super) errors: FoldErrors,
    /// Held-out rows, as indices into `data.rows`.
    pub(super) test: Vec<usize>,
    /// Held-out rows not predicted ([`fold_rows`]).
    pub(super) dropped: usize,
}

/// Fits group `f` of `data` (`fold_of` per row) and predicts its held-out rows.
pub(super) fn fit_fold(
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
    let groups = Groups::new(&fold_of, k, Grouping::Folds);
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
pub(super) struct Groups<'g> {
    /// Group per row.
    pub(super) of: &'g [usize],
    /// Number of groups.
    pub(super) k: usize,
    /// What the groups are.
    pub(super) grouping: Grouping,
}

impl<'g> Groups<'g> {
    /// `k` groups of `grouping`, `of` per row.
    pub(super) fn new(of: &'g [usize], k: usize, grouping: Grouping) -> Self {
        Groups { of, k, grouping }
    }
}

/// [`pooled`] of one grouping, after its own [`fold_shares`] at `start`.
pub(super) fn pooled_alone(
    model: &Model,
    data: &Dataset<'_>,
    request: &FitRequest<'_>,
    groups: &Groups<'_>,
    start: Option<WarmStart<'_>>,
    keys: &[(i64, i64)],
) -> Result<Pooled> {
    let shares = shares_for(model, data, request, &[groups], start.as_ref())?;
    pooled(
        model,
        data,
        request,
        groups,
        start,
        shares.as_ref().map(|s| s[0].as_slice()),
        keys,
    )
}

/// [`fold_shares`] of every grouping of `groups` at `start`, or `None` without a start or where
/// they cannot start there.
pub(super) fn shares_for(
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
pub(super) fn fit_folds(
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
pub(super) struct Pooled {
    /// Indices into `data.rows` of the predicted rows, in row order.
    pub(super) rows: Vec<usize>,
    pub(super) before: Vec<Vector3<f64>>,
    pub(super) after: Vec<Vector3<f64>>,
    pub(super) learned: Option<Vec<Vector3<f64>>>,
    pub(super) per_group: Vec<FoldStats>,
    pub(super) dropped: usize,
}

impl Pooled {
    /// The statistics of the nominal, physical and learned errors over the predicted rows.
    pub(super) fn stats(
        &self,
        keys: &[(i64, i64)],
    ) -> (HeldOutStats, HeldOutStats, Option<HeldOutStats>) {
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
pub(super) fn pooled(
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
