//! Cross-validation of a streamed calibration: k folds by pose and leave-one-region-out, on a file
//! read in pieces, in bounded memory.
//!
//! The in-memory validation ([`super::cross_validate_with_regions`]) holds every row and fits each
//! group's complement. Here nothing is materialised: every row's groups come from the row itself,
//! and every group's two solves (the base-and-target fit, the full fit) are [`Lane`]s carried across
//! passes over the file, as the streamed fit's are ([`crate::fit::stream`]).
//!
//! # Groups from the row ([`StreamGroups`])
//! - **Folds** by pose: a seeded hash (SplitMix64) of the row's campaign and pose id, modulo `k`.
//!   Rows of a pose share its fold. Folds are not dealt as in memory (shuffled and dealt round-robin,
//!   [`super::pose_folds`]): their sizes vary by about `√(poses / k)`, a fraction of a percent on a
//!   stream.
//! - **Regions**: k-means on `(sin q, cos q)` of the poses of the streamed fit's seeded sample
//!   ([`regions::centres`], the in-memory clustering's own steps), and every row to its nearest
//!   centre ([`regions::nearest_centre`]). When the sample is the whole table, these are the
//!   in-memory regions.
//!
//! # Passes
//! 1. **Shares at the solution.** Every group's solves start at the fit on every row (as in memory,
//!    [`crate::fit::WarmStart`]). One pass there evaluates each row once, for both solves, and sums
//!    `χ²`, `D Jᵀr` and the `R` factor per *cell*: a fold and a region at once. A group's start is
//!    the sum of the cells outside it (the factors stacked in cell order), so the pass costs about
//!    what one solve's factor costs, whatever the number of groups.
//! 2. **Solves.** Each further pass evaluates every running lane on its training rows at its trial
//!    point (the factor kept while it predicts, [`crate::fit::stream::lane`]). From the fit on every
//!    row a group's minimum lies within a few of its standard deviations: one Gauss–Newton step
//!    converges, and the second pass confirms it.
//! 3. **Held-out errors.** A last pass predicts every row by its fold's and its region's models
//!    (nominal and calibrated) and sums the statistics ([`HeldOutStats`]), poses counted as runs of
//!    consecutive rows with the same campaign and pose id.
//!
//! A model that leaves residuals of hundreds of noise σ (the kinematic model on a robot with
//! compliance and backlash) makes Gauss–Newton converge linearly: the groups' solves, like the fit's,
//! then take tens of passes (20,000 rows of `iiwa7_all`: the fit 17, the validation 31), and a solve
//! still running at the pass limit is named in a warning. The groups' solves start with the damping
//! the fit on every row ended with ([`Lane::with_damping`]): its steps were trusted there.
//!
//! # What differs from the in-memory validation
//! - The folds (above). [`StreamGroups::labels`] gives the labels of a table in memory, and
//!   [`super::cross_validate_labelled`] the in-memory validation of the same groups: the two agree
//!   within the solvers' stopping rule (`calib/tests/stream.rs`).
//! - The gross errors the streamed fit excluded are left out of every group's training rows; the
//!   in-memory fits of the groups search for their own. Held-out statistics take every row.
//! - Leave-one-campaign-out validation needs the table in memory: with several campaigns a warning
//!   says so.

use super::regions;
use super::stats::{ByRegion, FoldStats, HeldOutSum, Validation};
use crate::error::{CalibError, Result};
use crate::fit::CalibrationOptions;
use crate::fit::problem::{KinematicProblem, Observations, ShareRequest};
use crate::fit::stream::lane::{Evaluation, Lane, Phase};
use crate::fit::stream::pass::{check_campaigns, observations};
use crate::fit::stream::scan::pose_hash;
use crate::fit::stream::{ChunkSource, StreamedCalibration};
use crate::model::extensions::Regressors;
use crate::model::predict::Prediction;
use nalgebra::{DMatrix, Vector3};
use sim::Model;
use sim::measurement_table::MeasurementTable;
use std::collections::BTreeSet;

/// Salt of the fold hash, so that folds and the streamed fit's sample (keyed by row) are not
/// correlated for the same seed.
const FOLD_SALT: u64 = 0x666f_6c64_7368_6173;

/// The folds and regions of a streamed validation, decided row by row (module docs).
#[derive(Clone, Debug)]
pub struct StreamGroups {
    folds: usize,
    regions: usize,
    seed: u64,
    /// Region centres, `dim` values each (fewer than `regions` with fewer distinct poses).
    centres: Vec<f64>,
    dim: usize,
}

impl StreamGroups {
    /// `folds` folds (≥ 1) and `regions` regions (0 or 1: none) with `seed`, the regions placed on
    /// the poses of `sample` (a table's rows in table order: each pose's first row counts).
    pub fn new(folds: usize, regions: usize, seed: u64, sample: &MeasurementTable) -> Self {
        let dim = 2 * sample.n_joints;
        let centres = if regions >= 2 && dim > 0 {
            let mut seen = std::collections::HashSet::new();
            let mut points = Vec::new();
            for r in 0..sample.len() {
                if seen.insert(sample.pose_key(r)) {
                    regions::features(sample.q_row(r), &mut points);
                }
            }
            if points.is_empty() {
                Vec::new()
            } else {
                regions::centres(&points, dim, regions, seed)
            }
        } else {
            Vec::new()
        };
        StreamGroups {
            folds: folds.max(1),
            regions: if regions >= 2 { regions } else { 0 },
            seed,
            centres,
            dim,
        }
    }

    /// Folds.
    pub fn folds(&self) -> usize {
        self.folds
    }

    /// Regions (0: no validation by region).
    pub fn regions(&self) -> usize {
        self.regions
    }

    /// The fold of the pose `pose` of campaign `campaign`: a seeded hash of both, modulo the folds.
    pub fn fold(&self, campaign: i64, pose: i64) -> usize {
        let h = pose_hash(self.seed ^ FOLD_SALT, campaign, pose);
        (h % self.folds as u64) as usize
    }

    /// The region of a row with joint values `q` (rad or m): its nearest centre (0 without regions).
    /// `scratch` holds the row's features.
    pub fn region(&self, q: &[f64], scratch: &mut Vec<f64>) -> usize {
        if self.centres.is_empty() {
            return 0;
        }
        scratch.clear();
        regions::features(q, scratch);
        regions::nearest_centre(scratch, &self.centres, self.dim)
    }

    /// The fold and the region of every row of `table`, as a streamed validation gives them: for
    /// [`super::cross_validate_labelled`] on the same table in memory.
    pub fn labels(&self, table: &MeasurementTable) -> (Vec<usize>, Vec<usize>) {
        let mut scratch = Vec::new();
        (0..table.len())
            .map(|r| {
                let (c, p) = table.pose_key(r);
                (self.fold(c, p), self.region(table.q_row(r), &mut scratch))
            })
            .unzip()
    }

    /// The cell (a fold and a region) of every row of a piece: `fold · regions + region`.
    fn cells(&self, table: &MeasurementTable, out: &mut Vec<usize>, scratch: &mut Vec<f64>) {
        let per_fold = self.regions.max(1);
        out.clear();
        for r in 0..table.len() {
            let (c, p) = table.pose_key(r);
            out.push(self.fold(c, p) * per_fold + self.region(table.q_row(r), scratch));
        }
    }
}

/// The two groupings: folds (0) and regions (1).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Grouping {
    Folds,
    Regions,
}

/// A group of a grouping: its two solves and what is known of its rows.
struct Group {
    grouping: Grouping,
    index: usize,
    before: Lane,
    after: Lane,
    /// Campaigns with training rows: held-out rows of others are not predicted.
    campaigns: BTreeSet<i64>,
    /// Poses (runs) fitted.
    train_poses: usize,
}

/// A cell's sums at one stage's point.
#[derive(Clone)]
struct CellSum {
    cost: f64,
    gradient: Vec<f64>,
    factor: Option<DMatrix<f64>>,
    residuals: usize,
}

impl CellSum {
    fn new(p: usize) -> Self {
        CellSum {
            cost: 0.0,
            gradient: vec![0.0; p],
            factor: None,
            residuals: 0,
        }
    }
}

/// What a cell holds besides its sums.
#[derive(Clone, Default)]
struct CellInfo {
    rows: usize,
    campaigns: BTreeSet<i64>,
}

/// A streamed validation and how it ran.
#[derive(Clone, Debug)]
pub struct StreamedValidation {
    /// The validation, as the in-memory one reports it.
    pub validation: Validation,
    /// Passes over the file.
    pub passes: usize,
    /// What the validation could not do, or a group's solve that did not converge.
    pub warnings: Vec<String>,
}

/// The rows `rows` of `obs`, in order (the kinematic model: no regressors).
fn subset(obs: &Observations, rows: &[usize]) -> Observations {
    let n = obs.n_joints;
    let mut q = Vec::with_capacity(rows.len() * n);
    for &r in rows {
        q.extend_from_slice(obs.q_row(r));
    }
    Observations {
        n_joints: n,
        q,
        position: rows.iter().map(|&r| obs.position[r]).collect(),
        orientation: obs
            .orientation
            .as_ref()
            .map(|o| rows.iter().map(|&r| o[r]).collect()),
        sigma: rows.iter().map(|&r| obs.sigma[r]).collect(),
        sigma_rotation: obs.sigma_rotation,
        weight: rows.iter().map(|&r| obs.weight[r]).collect(),
        pose: rows.iter().map(|&r| obs.pose[r]).collect(),
        source_row: rows.iter().map(|&r| obs.source_row[r]).collect(),
        ext: Regressors::none(),
        campaign: obs
            .campaign
            .as_ref()
            .map(|c| rows.iter().map(|&r| c[r]).collect()),
    }
}

/// What every pass needs: the model, the file, the settings and the fit on every row.
struct Setup<'a> {
    model: &'a Model,
    source: &'a dyn ChunkSource,
    options: &'a CalibrationOptions,
    full: &'a StreamedCalibration,
    groups: StreamGroups,
    /// Regions per fold in the cell numbering (1 without regions).
    per_fold: usize,
}

impl Setup<'_> {
    fn cells(&self) -> usize {
        self.groups.folds * self.per_fold
    }

    /// The group of cell `c` in `grouping`.
    fn group_of(&self, grouping: Grouping, c: usize) -> usize {
        match grouping {
            Grouping::Folds => c / self.per_fold,
            Grouping::Regions => c % self.per_fold,
        }
    }

    /// Every piece of the file with its rows prepared (`excluded` rows at weight 0) and their
    /// cells, in file order; `label` and the rows so far go to `progress`.
    fn each_piece(
        &self,
        excluded: &[usize],
        label: &str,
        progress: &mut dyn FnMut(&str),
        mut work: impl FnMut(&sim::measurement_table::Chunk, &Observations, &[usize]) -> Result<()>,
    ) -> Result<()> {
        let (mut cells, mut scratch) = (Vec::new(), Vec::new());
        let mut rows = 0;
        for chunk in self.source.pass()? {
            crate::cancel::checkpoint()?;
            let chunk = chunk?;
            let obs = observations(&chunk, &self.options.noise, self.source.name(), excluded)?;
            self.groups.cells(&chunk.table, &mut cells, &mut scratch);
            work(&chunk, &obs, &cells)?;
            rows += chunk.table.len();
            progress(&format!("{label}: {rows} rows"));
        }
        Ok(())
    }
}

/// The first pass: every cell's sums at the fit's two solutions, what the cells hold, and the pose
/// runs of each group.
struct Shares {
    before: Vec<CellSum>,
    after: Vec<CellSum>,
    info: Vec<CellInfo>,
    /// Pose runs in each fold (0) and region (1).
    runs_in: [Vec<usize>; 2],
    /// Pose runs in the file.
    runs: usize,
}

fn shares(setup: &Setup<'_>, progress: &mut dyn FnMut(&str)) -> Result<Shares> {
    let cal = &setup.full.calibration;
    let layout = &cal.layout;
    let scales = setup.options.scales.vector(layout);
    let bt = layout.base_and_target();
    let all: Vec<usize> = (0..layout.len()).collect();
    let bt_scales: Vec<f64> = bt.iter().map(|&k| scales[k]).collect();
    let all_scales: Vec<f64> = scales.as_slice().to_vec();
    let n_cells = setup.cells();
    let mut out = Shares {
        before: vec![CellSum::new(bt.len()); n_cells],
        after: vec![CellSum::new(all.len()); n_cells],
        info: vec![CellInfo::default(); n_cells],
        runs_in: [vec![0; setup.groups.folds], vec![0; setup.per_fold]],
        runs: 0,
    };
    let mut last_key: Option<(i64, i64)> = None;
    let name = setup.source.name();
    setup.each_piece(
        &setup.full.excluded_rows,
        "validation, shares at the solution",
        progress,
        |chunk, obs, cells| {
            check_campaigns(obs, &cal.params, name)?;
            for (r, &c) in cells.iter().enumerate() {
                let key = chunk.table.pose_key(r);
                out.info[c].rows += 1;
                out.info[c].campaigns.insert(key.0);
                if last_key != Some(key) {
                    out.runs += 1;
                    out.runs_in[0][c / setup.per_fold] += 1;
                    out.runs_in[1][c % setup.per_fold] += 1;
                    last_key = Some(key);
                }
            }
            for (params, active, stage_scales, sums) in [
                (&cal.before, &bt, &bt_scales, &mut out.before),
                (&cal.params, &all, &all_scales, &mut out.after),
            ] {
                let p = active.len();
                let mut problem =
                    KinematicProblem::new(setup.model, obs, params.clone(), active.clone());
                let parts = problem.group_parts(stage_scales, cells, n_cells);
                for (sum, part) in sums.iter_mut().zip(parts) {
                    sum.cost += part.cost;
                    for (t, v) in sum.gradient.iter_mut().zip(&part.gradient) {
                        *t += v;
                    }
                    if !part.factors.is_empty() {
                        let mut stack: Vec<DMatrix<f64>> = sum.factor.take().into_iter().collect();
                        stack.extend(part.factors);
                        sum.factor = Some(crate::linalg::stacked_r_factor(&stack, p));
                    }
                }
            }
            let d = obs.dim();
            for &c in cells {
                out.before[c].residuals += d;
                out.after[c].residuals += d;
            }
            Ok(())
        },
    )?;
    Ok(out)
}

/// The groupings a validation has, with their group counts.
fn groupings(setup: &Setup<'_>) -> Vec<(Grouping, usize)> {
    let mut g = vec![(Grouping::Folds, setup.groups.folds)];
    if setup.groups.regions >= 2 {
        g.push((Grouping::Regions, setup.groups.regions));
    }
    g
}

impl Grouping {
    fn index(self) -> usize {
        match self {
            Grouping::Folds => 0,
            Grouping::Regions => 1,
        }
    }

    fn flag(self) -> &'static str {
        match self {
            Grouping::Folds => "--folds",
            Grouping::Regions => "--regions",
        }
    }

    fn name(self, g: usize) -> String {
        match self {
            Grouping::Folds => format!("fold {}", g + 1),
            Grouping::Regions => format!("region {}", g + 1),
        }
    }
}

/// Every group with held-out rows, its two lanes started from the sums of the cells outside it
/// (their first evaluation: a step, or the end).
fn start_groups(setup: &Setup<'_>, shares: &Shares, max_passes: usize) -> Result<Vec<Group>> {
    let cal = &setup.full.calibration;
    let layout = &cal.layout;
    let scales = setup.options.scales.vector(layout);
    let bt = layout.base_and_target();
    let all: Vec<usize> = (0..layout.len()).collect();
    let n_cells = setup.cells();
    let mut out = Vec::new();
    for (grouping, k) in groupings(setup) {
        for g in 0..k {
            let (inside, outside): (Vec<usize>, Vec<usize>) =
                (0..n_cells).partition(|&c| setup.group_of(grouping, c) == g);
            let rows = |cells: &[usize]| cells.iter().map(|&c| shares.info[c].rows).sum::<usize>();
            if rows(&inside) == 0 {
                continue;
            }
            if rows(&outside) == 0 {
                return Err(CalibError::BadValue {
                    context: setup.source.name().to_string(),
                    field: grouping.flag().into(),
                    value: k.to_string(),
                    problem: format!(
                        "{} holds every row: nothing is left to fit it on",
                        grouping.name(g)
                    ),
                });
            }
            let start = |sums: &[CellSum], p: usize| {
                let mut e = Evaluation::empty(p, false);
                let mut factors = Vec::new();
                for &c in &outside {
                    e.add(sums[c].cost, &sums[c].gradient, None, sums[c].residuals);
                    factors.extend(sums[c].factor.clone());
                }
                e.factor = Some(crate::linalg::stacked_r_factor(&factors, p));
                e
            };
            let lane = |from: &crate::model::params::KinematicParams, active: &[usize]| {
                Lane::new(
                    layout.clone(),
                    from.clone(),
                    active.to_vec(),
                    active.iter().map(|&k| scales[k]).collect(),
                    &setup.options.lm,
                    max_passes,
                )
            };
            let mut before = lane(&cal.before, &bt);
            before.take(start(&shares.before, bt.len()));
            let mut after = lane(&cal.params, &all).with_damping(setup.full.final_damping);
            after.take(start(&shares.after, all.len()));
            out.push(Group {
                grouping,
                index: g,
                before,
                after,
                campaigns: outside
                    .iter()
                    .flat_map(|&c| shares.info[c].campaigns.iter().copied())
                    .collect(),
                train_poses: shares.runs - shares.runs_in[grouping.index()][g],
            });
        }
    }
    Ok(out)
}

/// Passes until every group's lanes are done: each running lane evaluated on its training rows at
/// its trial point. Returns the passes taken.
fn solve(
    setup: &Setup<'_>,
    groups: &mut [Group],
    passes_before: usize,
    progress: &mut dyn FnMut(&str),
) -> Result<usize> {
    let mut passes = 0;
    let running = |l: &Lane| l.phase == Phase::Running;
    while groups
        .iter()
        .any(|g| running(&g.before) || running(&g.after))
    {
        let mut sums: Vec<[Option<Evaluation>; 2]> = groups
            .iter()
            .map(|g| {
                [&g.before, &g.after].map(|l| {
                    running(l).then(|| Evaluation::empty(l.active.len(), l.wants_factor()))
                })
            })
            .collect();
        let label = format!("validation, pass {}", passes_before + passes + 1);
        setup.each_piece(
            &setup.full.excluded_rows,
            &label,
            progress,
            |_, obs, cells| {
                for (group, sum) in groups.iter().zip(sums.iter_mut()) {
                    if sum.iter().all(Option::is_none) {
                        continue;
                    }
                    let train: Vec<usize> = (0..cells.len())
                        .filter(|&r| setup.group_of(group.grouping, cells[r]) != group.index)
                        .collect();
                    let sub = subset(obs, &train);
                    for (lane, e) in [&group.before, &group.after]
                        .into_iter()
                        .zip(sum.iter_mut())
                    {
                        let Some(e) = e else { continue };
                        let mut problem = KinematicProblem::new(
                            setup.model,
                            &sub,
                            lane.trial.clone(),
                            lane.active.clone(),
                        );
                        let want = ShareRequest {
                            factor: e.factor.is_some(),
                            rows: false,
                        };
                        let share = problem.factor_share(&lane.scales, want);
                        e.add(
                            share.cost,
                            &share.gradient,
                            share.factor,
                            sub.len() * sub.dim(),
                        );
                    }
                }
                Ok(())
            },
        )?;
        passes += 1;
        for (group, [b, a]) in groups.iter_mut().zip(sums) {
            if let Some(b) = b {
                group.before.take(b);
            }
            if let Some(a) = a {
                group.after.take(a);
            }
        }
    }
    Ok(passes)
}

/// A held-out row's group (index into the groups) and its errors by the group's nominal and
/// calibrated models (m).
type HeldOutRow = Option<(usize, Vector3<f64>, Vector3<f64>)>;

/// What the last pass sums: per grouping the pooled nominal (0) and calibrated (1) errors and the
/// rows not predicted; per group its calibrated errors.
struct HeldOut {
    pooled: Vec<[HeldOutSum; 2]>,
    per_group: Vec<HeldOutSum>,
    dropped: Vec<usize>,
}

/// The last pass: every row predicted by its groups' models.
fn held_out(
    setup: &Setup<'_>,
    groups: &[Group],
    progress: &mut dyn FnMut(&str),
) -> Result<HeldOut> {
    let groupings = groupings(setup);
    let mut out = HeldOut {
        pooled: vec![Default::default(); groupings.len()],
        per_group: vec![HeldOutSum::default(); groups.len()],
        dropped: vec![0; groupings.len()],
    };
    let predictions: Vec<[Prediction; 2]> = groups
        .iter()
        .map(|g| {
            [
                Prediction::new(setup.model, &g.before.lin),
                Prediction::new(setup.model, &g.after.lin),
            ]
        })
        .collect();
    let mut errors: Vec<HeldOutRow> = Vec::new();
    setup.each_piece(
        &[],
        "validation, held-out errors",
        progress,
        |chunk, obs, cells| {
            let n = obs.len();
            for (j, &(grouping, _)) in groupings.iter().enumerate() {
                errors.clear();
                errors.resize(n, None);
                for (gi, group) in groups.iter().enumerate() {
                    if group.grouping != grouping {
                        continue;
                    }
                    let (known, unknown): (Vec<usize>, Vec<usize>) = (0..n)
                        .filter(|&r| setup.group_of(grouping, cells[r]) == group.index)
                        .partition(|&r| {
                            group
                                .campaigns
                                .contains(&chunk.table.campaign_of(r).unwrap_or(0))
                        });
                    out.dropped[j] += unknown.len();
                    let sub = subset(obs, &known);
                    let [nominal, calibrated] = &predictions[gi];
                    let (eb, ea) = (nominal.errors(&sub), calibrated.errors(&sub));
                    for (i, &r) in known.iter().enumerate() {
                        errors[r] = Some((gi, eb[i], ea[i]));
                    }
                }
                for (r, e) in errors.iter().enumerate() {
                    if let Some((gi, eb, ea)) = e {
                        let key = chunk.table.pose_key(r);
                        out.pooled[j][0].add(key, eb);
                        out.pooled[j][1].add(key, ea);
                        out.per_group[*gi].add(key, ea);
                    }
                }
            }
            Ok(())
        },
    )?;
    Ok(out)
}

/// `k`-fold cross-validation by pose and, with `regions ≥ 2`, leave-one-region-out validation (seed
/// `seed`) of the kinematic model on every row of `source`, in bounded memory (module docs). `full`
/// is the streamed fit of the same rows with `options` (the saved model): every group's solves start
/// there, `max_passes` evaluations each at most. `progress` hears each pass's rows. Errors: fewer
/// than 2 folds, a group with every row, a bad row (named by its row of the file).
#[allow(clippy::too_many_arguments)]
pub fn validate_streamed(
    model: &Model,
    source: &dyn ChunkSource,
    options: &CalibrationOptions,
    full: &StreamedCalibration,
    folds: usize,
    regions: usize,
    seed: u64,
    max_passes: usize,
    progress: &mut dyn FnMut(&str),
) -> Result<StreamedValidation> {
    if folds < 2 {
        return Err(CalibError::BadValue {
            context: source.name().to_string(),
            field: "--folds".into(),
            value: folds.to_string(),
            problem: "cross-validation needs at least 2 folds".into(),
        });
    }
    let groups = StreamGroups::new(folds, regions, seed, &full.sample);
    let setup = Setup {
        model,
        source,
        options,
        full,
        per_fold: groups.regions.max(1),
        groups,
    };
    let shares = shares(&setup, progress)?;
    let mut groups = start_groups(&setup, &shares, max_passes)?;
    let solve_passes = solve(&setup, &mut groups, 1, progress)?;
    let held = held_out(&setup, &groups, progress)?;
    let passes = 1 + solve_passes + 1;

    let mut warnings = Vec::new();
    for g in &groups {
        for (lane, what) in [(&g.before, "base-and-target"), (&g.after, "kinematic")] {
            if !lane.report.was_successful() {
                warnings.push(format!(
                    "validation: the {what} fit without {} did not converge ({})",
                    g.grouping.name(g.index),
                    lane.report.termination
                ));
            }
        }
    }
    let mut per: [Vec<FoldStats>; 2] = [Vec::new(), Vec::new()];
    for (group, sum) in groups.iter().zip(held.per_group) {
        per[group.grouping.index()].push(FoldStats {
            fold: group.index,
            n_train_poses: group.train_poses,
            held_out: sum.finish(),
        });
    }
    let [per_fold, per_region] = per;
    let mut pooled = held.pooled.into_iter();
    let [fold_before, fold_after] = pooled.next().expect("the folds");
    let mut validation = Validation::cross_validation(
        folds,
        seed,
        (fold_before.finish(), fold_after.finish(), None),
        per_fold,
    );
    if let Some([region_before, region_after]) = pooled.next() {
        validation.set_regions(ByRegion {
            regions,
            seed,
            before: region_before.finish(),
            after: region_after.finish(),
            learned: None,
            per_region,
            n_rows_not_predicted: held.dropped[1],
        });
    }
    if held.dropped[0] > 0 {
        warnings.push(format!(
            "validation: {} held-out rows not predicted: their campaign has no pose in the other folds",
            held.dropped[0]
        ));
    }
    if full.calibration.params.campaign_ids.len() > 1 {
        warnings.push(
            "validation on unseen campaigns (leave-one-campaign-out) needs the table in memory \
             (--stream never); `robocal register` measures a new campaign's error"
                .into(),
        );
    }
    Ok(StreamedValidation {
        validation,
        passes,
        warnings,
    })
}
