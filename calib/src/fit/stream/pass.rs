//! The passes of a streamed fit over the file: the solver's sums at each lane's trial point
//! ([`solve_pass`]), and the residuals at the solution ([`final_pass`]): statistics, the rows'
//! residual norms for the gross-error and outlier searches, and evenly spaced rows.

use super::lane::{Evaluation, Lane, Phase};
use super::source::ChunkSource;
use crate::cancel;
use crate::error::{CalibError, Result};
use crate::fit::problem::{KinematicProblem, NoiseModel, Observations, RowResiduals, ShareRequest};
use crate::model::params::KinematicParams;
use crate::model::predict::Prediction;
use crate::model::stats::{ResidualStats, residual_stats, stats_of_errors};
use sim::Model;
use sim::measurement_table::{Chunk, MeasurementTable};

/// The piece's rows prepared for the solver: source rows numbered file-wide, excluded rows (sorted
/// 0-based rows of the file) at weight 0.
pub(crate) fn observations(
    chunk: &Chunk,
    noise: &NoiseModel,
    name: &str,
    excluded: &[usize],
) -> Result<Observations> {
    let rows: Vec<usize> = (0..chunk.table.len()).collect();
    // Observations name the piece's row: move it to the file's.
    let mut obs = Observations::from_table(&chunk.table, &rows, noise, name)
        .map_err(|e| in_file(e, chunk.first_row))?;
    for r in &mut obs.source_row {
        *r += chunk.first_row;
    }
    let first = excluded.partition_point(|&r| r < chunk.first_row);
    for &r in &excluded[first..] {
        if r >= chunk.first_row + chunk.table.len() {
            break;
        }
        obs.weight[r - chunk.first_row] = 0.0;
    }
    Ok(obs)
}

/// `e` with the row of a piece starting at the file's 0-based row `first_row` in its context
/// moved to the file's row ([`renumber`]); other errors as they are.
pub(crate) fn in_file(e: CalibError, first_row: usize) -> CalibError {
    match e {
        CalibError::BadValue {
            context,
            field,
            value,
            problem,
        } => CalibError::BadValue {
            context: renumber(&context, first_row),
            field,
            value,
            problem,
        },
        other => other,
    }
}

/// `"{name}: row {k}"` with the piece's row `k` moved by `offset`.
fn renumber(context: &str, offset: usize) -> String {
    match context.rsplit_once(": row ") {
        Some((head, k)) => match k.parse::<usize>() {
            Ok(k) => format!("{head}: row {}", k + offset),
            Err(_) => context.to_string(),
        },
        None => context.to_string(),
    }
}

/// Checks that every row's campaign is one `params` registers.
pub(crate) fn check_campaigns(
    obs: &Observations,
    params: &KinematicParams,
    name: &str,
) -> Result<()> {
    obs.campaign_indices_or_error(params, name).map(|_| ())
}

/// What a pass computes besides the lanes' sums: the residuals at `before` and `after`
/// ([`FinalPass`]), with every `stride`th row kept.
#[derive(Clone, Copy)]
pub struct FinalRequest<'a> {
    /// The base-and-target fit's solution.
    pub before: &'a KinematicParams,
    /// The full fit's solution.
    pub after: &'a KinematicParams,
    /// Rows `0, stride, 2·stride, …` are kept.
    pub stride: usize,
    /// Rows of the file: the row norms' room, reserved at once (a growing vector would double its
    /// room, up to twice the 8 bytes a row).
    pub rows: usize,
}

/// One pass: every running lane evaluated at its trial point (with the `R` factor where the lane
/// wants it), and, when asked, the residuals at `final_at`'s points, in file order. `progress` hears
/// the rows done.
#[allow(clippy::too_many_arguments)]
pub fn solve_pass(
    model: &Model,
    source: &dyn ChunkSource,
    noise: &NoiseModel,
    excluded: &[usize],
    lanes: &mut [&mut Lane],
    final_at: Option<FinalRequest>,
    label: &str,
    progress: &mut dyn FnMut(&str),
) -> Result<Option<FinalPass>> {
    let running: Vec<usize> = (0..lanes.len())
        .filter(|&k| lanes[k].phase == Phase::Running)
        .collect();
    let mut sums: Vec<Evaluation> = running
        .iter()
        .map(|&k| Evaluation::empty(lanes[k].active.len(), lanes[k].wants_factor()))
        .collect();
    let mut fin = final_at.map(|f| FinalSums::new(model, f, excluded.len()));
    // A lane evaluated at a point where the residuals are asked for gives them (one evaluation of
    // each row instead of two): 0 for `before`, 1 for `after`.
    let gives_rows = |k: usize| -> Option<usize> {
        let f = final_at?;
        let lane = &lanes[k];
        if lane.active.len() == lane.layout.len() && &lane.trial == f.after {
            Some(1)
        } else if &lane.trial == f.before {
            Some(0)
        } else {
            None
        }
    };
    let roles: Vec<Option<usize>> = running.iter().map(|&k| gives_rows(k)).collect();
    let mut rows = 0;
    for chunk in source.pass()? {
        cancel::checkpoint()?;
        let chunk = chunk?;
        let obs = observations(&chunk, noise, source.name(), excluded)?;
        let mut at_points: [Option<RowResiduals>; 2] = [None, None];
        for ((sum, &k), role) in sums.iter_mut().zip(&running).zip(&roles) {
            let lane = &lanes[k];
            check_campaigns(&obs, &lane.trial, source.name())?;
            let mut prob =
                KinematicProblem::new(model, &obs, lane.trial.clone(), lane.active.clone());
            let want = ShareRequest {
                factor: sum.factor.is_some(),
                rows: role.is_some(),
            };
            let share = prob.factor_share(&lane.scales, want);
            sum.add(
                share.cost,
                &share.gradient,
                share.factor,
                obs.len() * obs.dim(),
            );
            if let (Some(role), Some(rows)) = (role, share.rows) {
                at_points[*role] = Some(rows);
            }
        }
        if let Some(fin) = fin.as_mut() {
            let [at_before, at_after] = at_points;
            fin.add(
                model,
                &chunk,
                &obs,
                excluded,
                source.name(),
                at_before.as_ref(),
                at_after.as_ref(),
            )?;
        }
        rows += chunk.table.len();
        progress(&format!("{label}: {rows} rows"));
    }
    for (sum, &k) in sums.into_iter().zip(&running) {
        lanes[k].take(sum);
    }
    Ok(fin.map(FinalSums::finish))
}

/// Running sums of [`ResidualStats`] over pieces.
#[derive(Clone, Debug, Default)]
pub struct StatsSum {
    n: usize,
    sum2: f64,
    sum: f64,
    vector: [f64; 3],
    max_m: f64,
    max_row: usize,
    sum2_rad: Option<f64>,
    max_rad: Option<f64>,
}

impl StatsSum {
    /// Adds a piece's statistics (its `max_row` file-wide).
    pub fn add(&mut self, s: &ResidualStats) {
        let n = s.n as f64;
        self.n += s.n;
        self.sum2 += s.rms_m * s.rms_m * n;
        self.sum += s.mean_m * n;
        for k in 0..3 {
            self.vector[k] += s.mean_vector_m[k] * n;
        }
        if s.max_m > self.max_m {
            self.max_m = s.max_m;
            self.max_row = s.max_row;
        }
        if let (Some(r), Some(m)) = (s.rms_rad, s.max_rad) {
            *self.sum2_rad.get_or_insert(0.0) += r * r * n;
            let mx = self.max_rad.get_or_insert(0.0);
            *mx = mx.max(m);
        }
    }

    /// The statistics of every piece added.
    pub fn stats(&self) -> ResidualStats {
        let n = self.n as f64;
        if self.n == 0 {
            return ResidualStats::default();
        }
        ResidualStats {
            n: self.n,
            rms_m: (self.sum2 / n).sqrt(),
            mean_m: self.sum / n,
            max_m: self.max_m,
            max_row: self.max_row,
            mean_vector_m: self.vector.map(|v| v / n),
            rms_rad: self.sum2_rad.map(|s| (s / n).sqrt()),
            max_rad: self.max_rad,
        }
    }
}

/// A row whose residual norm is among the largest of the pass.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Candidate {
    /// Weighted residual norm (noise units).
    pub norm: f64,
    /// 0-based row of the file.
    pub row: usize,
    /// Pose id.
    pub pose: i64,
    /// Position error norm (m).
    pub error_m: f64,
}

/// Most rows [`final_pass`] keeps as outlier candidates: the largest residual norms.
pub const MAX_CANDIDATES: usize = 4096;

/// What the residuals at the solution give.
pub struct FinalPass {
    /// Statistics at the "before" parameters.
    pub before: StatsSum,
    /// Statistics at the solution.
    pub after: StatsSum,
    /// Every row's weighted residual norm at the solution (0 for excluded rows), file order (the
    /// robust scale reorders them: only their median is used).
    pub norms: Vec<f64>,
    /// The rows of largest norm (at most [`MAX_CANDIDATES`]), largest first.
    pub candidates: Vec<Candidate>,
    /// The excluded rows' (0-based) pose id and position error at the solution, in their order.
    pub excluded: Vec<(i64, f64)>,
    /// Rows `0, stride, 2·stride, …` of the file.
    pub spaced: MeasurementTable,
    /// Σ σ² of the rows' position standard deviations (m²).
    pub sigma2: f64,
}

/// The residuals at `before` and `after` on every row of `source` (`excluded` rows at weight 0),
/// and its rows `0, stride, …` (`rows`: the file's): a pass with no lane to evaluate.
#[allow(clippy::too_many_arguments)]
pub fn final_pass(
    model: &Model,
    source: &dyn ChunkSource,
    noise: &NoiseModel,
    excluded: &[usize],
    before: &KinematicParams,
    after: &KinematicParams,
    stride: usize,
    rows: usize,
    progress: &mut dyn FnMut(&str),
) -> Result<FinalPass> {
    let request = FinalRequest {
        before,
        after,
        stride,
        rows,
    };
    let fin = solve_pass(
        model,
        source,
        noise,
        excluded,
        &mut [],
        Some(request),
        "residuals at the solution",
        progress,
    )?;
    Ok(fin.expect("asked for"))
}

/// [`FinalPass`] piece by piece.
struct FinalSums<'a> {
    out: FinalPass,
    request: FinalRequest<'a>,
    prediction: Prediction<'a>,
    heap: std::collections::BinaryHeap<std::cmp::Reverse<HeapItem>>,
}

impl<'a> FinalSums<'a> {
    fn new(model: &'a Model, request: FinalRequest<'a>, excluded: usize) -> Self {
        FinalSums {
            out: FinalPass {
                before: StatsSum::default(),
                after: StatsSum::default(),
                norms: Vec::with_capacity(request.rows),
                candidates: Vec::new(),
                excluded: vec![(0, 0.0); excluded],
                spaced: MeasurementTable::new(0, Default::default()),
                sigma2: 0.0,
            },
            request,
            prediction: Prediction::new(model, request.after),
            heap: std::collections::BinaryHeap::new(),
        }
    }

    /// Adds a piece (its rows prepared as `obs`), with the residuals at `before` and `after` where
    /// a lane's evaluation gave them (else they are computed here).
    #[allow(clippy::too_many_arguments)]
    fn add(
        &mut self,
        model: &Model,
        chunk: &Chunk,
        obs: &Observations,
        excluded: &[usize],
        name: &str,
        at_before: Option<&RowResiduals>,
        at_after: Option<&RowResiduals>,
    ) -> Result<()> {
        let FinalRequest {
            before,
            after,
            stride,
            ..
        } = self.request;
        let out = &mut self.out;
        check_campaigns(obs, before, name)?;
        check_campaigns(obs, after, name)?;
        // Statistics from the lanes' errors when there is no orientation to add.
        let stats = |params: &KinematicParams, given: Option<&RowResiduals>| match given {
            Some(rows) if obs.orientation.is_none() => stats_of_errors(&rows.errors, obs),
            _ => residual_stats(model, params, obs),
        };
        out.before.add(&stats(before, at_before));
        out.after.add(&stats(after, at_after));
        let computed;
        let norms: &[f64] = match at_after {
            Some(rows) => &rows.norms,
            None => {
                computed = KinematicProblem::new(model, obs, after.clone(), Vec::new()).row_norms();
                &computed
            }
        };
        let prediction = &self.prediction;
        let campaign = prediction.campaigns_of(obs);
        let mut scratch = prediction.scratch();
        let mut error_of = |r: usize| {
            let c = campaign.get(r).copied().unwrap_or(0);
            (prediction.row_in(&obs.ext, r, obs.q_row(r), c, &mut scratch) - obs.position[r]).norm()
        };
        let heap = &mut self.heap;
        for (r, &norm) in norms.iter().enumerate() {
            let item = HeapItem {
                norm,
                row: chunk.first_row + r,
            };
            if heap.len() < MAX_CANDIDATES {
                heap.push(std::cmp::Reverse(item));
            } else if heap.peek().is_some_and(|s| s.0 < item) {
                heap.pop();
                heap.push(std::cmp::Reverse(item));
            } else {
                continue;
            }
            // Kept: its pose and error now, while the row is at hand.
            out.candidates.push(Candidate {
                norm,
                row: chunk.first_row + r,
                pose: obs.pose[r],
                error_m: error_of(r),
            });
        }
        let first = excluded.partition_point(|&r| r < chunk.first_row);
        for (k, &r) in excluded.iter().enumerate().skip(first) {
            if r >= chunk.first_row + chunk.table.len() {
                break;
            }
            let local = r - chunk.first_row;
            out.excluded[k] = (obs.pose[local], error_of(local));
        }
        out.norms.extend_from_slice(norms);
        out.sigma2 += obs.sigma.iter().map(|s| s * s).sum::<f64>();
        let first_spaced = chunk.first_row.div_ceil(stride) * stride;
        if out.spaced.n_joints == 0 {
            out.spaced = chunk.table.empty_like(0);
        }
        let mut r = first_spaced;
        while r < chunk.first_row + chunk.table.len() {
            out.spaced.push_row(&chunk.table.row(r - chunk.first_row))?;
            r += stride;
        }
        // Candidates no longer in the heap are dropped now and then (bounded memory).
        if out.candidates.len() > 4 * MAX_CANDIDATES {
            keep_heap(&mut out.candidates, heap);
        }
        Ok(())
    }

    fn finish(mut self) -> FinalPass {
        keep_heap(&mut self.out.candidates, &self.heap);
        self.out
            .candidates
            .sort_by(|a, b| b.norm.total_cmp(&a.norm).then(a.row.cmp(&b.row)));
        self.out
    }
}

/// A row's norm, ordered by norm and then by row (earlier rows rank higher on ties).
#[derive(Clone, Copy, Debug, PartialEq)]
struct HeapItem {
    norm: f64,
    row: usize,
}

impl Eq for HeapItem {}

impl PartialOrd for HeapItem {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for HeapItem {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.norm
            .total_cmp(&other.norm)
            .then(other.row.cmp(&self.row))
    }
}

/// Keeps the candidates whose rows are still in `heap`.
fn keep_heap(
    candidates: &mut Vec<Candidate>,
    heap: &std::collections::BinaryHeap<std::cmp::Reverse<HeapItem>>,
) {
    let mut rows: Vec<usize> = heap.iter().map(|h| h.0.row).collect();
    rows.sort_unstable();
    candidates.retain(|c| rows.binary_search(&c.row).is_ok());
}
