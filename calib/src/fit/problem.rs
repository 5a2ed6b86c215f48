//! The calibration problem: measurements, their weights, and the kinematic model's residuals and
//! Jacobian as a [`LeastSquaresProblem`].
//!
//! Residuals, per measurement row, are `(p_predicted − p_measured) √w / σ` (3, tracker frame) and, with
//! orientation, `log(R_predicted R_measuredᵀ) √w / σ_rot` (3, tracker frame rotation vector), where `σ`
//! is the row's position standard deviation ([`NoiseModel`]) and `w` a robust weight (1 unless
//! iteratively reweighted). The orientation rows' Jacobian includes the exact `J_l⁻¹` of the
//! logarithm.

use crate::lie3::{left_jacobian_inverse, log_rotation};
use crate::lm::LeastSquaresProblem;
use crate::model::chain::Chain;
use crate::model::jacobian::{BendColumns, extension_columns, grow_columns};
use crate::model::params::{KinematicParams, ParamLayout};
use crate::model::physical_row::{PredictScratch, physical_row};
use nalgebra::{DMatrix, Vector3};
use rayon::prelude::*;
use sim::Model;

pub use crate::model::observations::{NoiseModel, Observations};

/// The kinematic calibration problem over `active` parameters of a [`ParamLayout`].
#[derive(Clone, Debug)]
pub struct KinematicProblem<'a> {
    model: &'a Model,
    obs: &'a Observations,
    layout: ParamLayout,
    active: Vec<usize>,
    lin: KinematicParams,
    trial: KinematicParams,
    chain: Chain,
    step_full: Vec<f64>,
    /// The serial path's row workspace (problems of at most [`CHUNK_ROWS`] rows).
    ws: RowScratch,
    /// Campaign index of every row (empty: all in the first campaign).
    campaign: Vec<usize>,
    /// Whether a joint or extension parameter is active (else the joint columns are not needed).
    joint_columns: bool,
    /// The weighted, column-scaled Jacobian of the active parameters at the point of the last
    /// [`LeastSquaresProblem::normal_equations`] (one row of `p` per residual, row-major), for
    /// [`LeastSquaresProblem::scaled_jacobian_transpose_times`] and, while the trial point has not
    /// moved from there ([`Self::kept_jacobian`]), the rank decision.
    jac: Vec<f64>,
    /// The column scales of `jac`.
    jac_scales: Vec<f64>,
    /// Whether `jac` is the Jacobian at the linearisation point (made there, and no step accepted
    /// since).
    jac_at_lin: bool,
    /// Whether the trial point is the linearisation point (the last step set was zero).
    trial_at_lin: bool,
    /// Most Jacobian entries kept ([`KEEP_JACOBIAN_MAX_VALUES`]; tests lower it).
    keep_limit: usize,
}

/// Measurement rows per parallel work item. The partial sums of the normal equations are added in
/// chunk order, so the result does not depend on the number of threads; a problem of at most this
/// many rows is one chunk, summed in row order.
const CHUNK_ROWS: usize = 2048;

/// Measurement rows per parallel work item of [`KinematicProblem::factor_share`]: a chunk's scaled
/// Jacobian (3,072 × 58 for the iiwa 7's positions) stays within the third-level cache, where the
/// blocked Householder QR runs about 1.3 times faster than on chunks of [`CHUNK_ROWS`].
const FACTOR_CHUNK_ROWS: usize = 1024;

/// Most entries (`m · p`, 8 bytes each) of the weighted Jacobian a problem keeps between its normal
/// equations and the products that reuse them (the geodesic acceleration's `D Jᵀ w`, the rank
/// decision's QR): 2²⁴, 128 MiB. A larger problem forms those rows again instead, so that its memory
/// does not grow by `p` numbers per residual (1.4 GB for 10⁶ poses of the iiwa 7): about one more
/// Jacobian pass per iteration, the same numbers up to the summation order of `D Jᵀ w`.
const KEEP_JACOBIAN_MAX_VALUES: usize = 1 << 24;

/// Measurements per block product of [`KinematicProblem::normal_part`].
const NORMAL_BLOCK_ROWS: usize = 32;

/// Workspace of one row's evaluation: made once per chunk of rows, reused without allocating.
#[derive(Clone, Debug)]
struct RowScratch {
    /// The row's evaluation (effective joint values, frames).
    predict: PredictScratch,
    /// Jacobian rows of one measurement (dim × layout.len()), row-major.
    block: Vec<f64>,
    /// Orientation Jacobian before `J_l⁻¹` (3 × layout.len()).
    rot: Vec<f64>,
    /// Active, weighted, scaled Jacobian rows of one measurement (dim × active), row-major.
    rows: Vec<f64>,
    /// Position error of the last row evaluated: prediction − measurement (tracker frame, m).
    error: Vector3<f64>,
}

impl RowScratch {
    fn new(nq: usize, dim: usize, np: usize, active: usize) -> Self {
        RowScratch {
            predict: PredictScratch::new(nq),
            block: vec![0.0; dim * np],
            rot: vec![0.0; 3 * np],
            rows: vec![0.0; dim * active],
            error: Vector3::zeros(),
        }
    }
}

/// One chunk's share of the normal equations: `χ²`, the gradient and the lower triangle of the
/// normal matrix (column-major, p × p).
struct NormalPart {
    cost: f64,
    gradient: Vec<f64>,
    gram: Vec<f64>,
}

fn copy_params(dst: &mut KinematicParams, src: &KinematicParams) {
    dst.joint_error.copy_from_slice(&src.joint_error);
    dst.zero_offset.copy_from_slice(&src.zero_offset);
    dst.t_tracker_base = src.t_tracker_base;
    dst.p_flange_target = src.p_flange_target;
    dst.r_flange_target = src.r_flange_target;
    dst.extension.copy_from_slice(&src.extension);
    dst.campaigns.copy_from_slice(&src.campaigns);
}

impl<'a> KinematicProblem<'a> {
    /// The problem at `start`; `active` lists the [`ParamLayout`] indices to solve for (the others stay).
    ///
    /// # Panics
    /// If `start` or `obs` do not fit `model`, an active index is out of range, or a row's campaign is
    /// not one of `start`'s.
    pub fn new(
        model: &'a Model,
        obs: &'a Observations,
        start: KinematicParams,
        active: Vec<usize>,
    ) -> Self {
        let layout = ParamLayout::for_params(model, &start, obs.ext.params.clone());
        let campaign = if obs.campaign.is_none() && start.default_campaign == 0 {
            Vec::new()
        } else {
            obs.campaign_indices(&start)
                .unwrap_or_else(|(r, id)| panic!("row {r}: campaign {id} is not registered"))
        };
        assert_eq!(obs.n_joints, model.nq(), "joint count of the observations");
        assert!(active.iter().all(|&k| k < layout.len()), "active index");
        assert_eq!(
            start.r_flange_target.is_some(),
            obs.orientation.is_some(),
            "orientation parameters"
        );
        assert_eq!(start.extension.len(), obs.ext.len(), "extension parameters");
        let np = layout.len();
        let dim = obs.dim();
        let joint_columns = active
            .iter()
            .any(|&k| k < layout.base() || k >= layout.kinematic_len());
        KinematicProblem {
            model,
            obs,
            chain: Chain::new(model, &start),
            trial: start.clone(),
            lin: start,
            step_full: vec![0.0; np],
            ws: RowScratch::new(model.nq(), dim, np, active.len()),
            active,
            joint_columns,
            layout,
            campaign,
            jac: Vec::new(),
            jac_scales: Vec::new(),
            jac_at_lin: false,
            trial_at_lin: true,
            keep_limit: KEEP_JACOBIAN_MAX_VALUES,
        }
    }

    /// The kept `J D` (row-major, one row of `p` per residual) when it is the Jacobian at the trial
    /// point with the column scales `scales`: the same numbers a new evaluation would give.
    fn kept_jacobian(&self, scales: &[f64]) -> Option<&[f64]> {
        let fresh = self.trial_at_lin
            && self.jac_at_lin
            && self.jac_scales == scales
            && self.jac.len() == self.n_residuals() * self.active.len();
        fresh.then_some(&self.jac[..])
    }

    /// The parameter layout.
    pub fn layout(&self) -> &ParamLayout {
        &self.layout
    }

    /// The active parameter indices.
    pub fn active(&self) -> &[usize] {
        &self.active
    }

    /// The linearisation point (the solution after a solve).
    pub fn params(&self) -> &KinematicParams {
        &self.lin
    }

    /// `D Jᵀ W` (active parameters × `w.len()`): the scaled Jacobian of the weighted residuals at the
    /// trial point, transposed, times each of the columns `w` (each as long as the residuals), in one
    /// pass over the rows in parallel chunks, without forming `J`; summed in chunk order (the same
    /// sums on any number of threads).
    pub fn scaled_jacobian_transpose_times_columns(
        &mut self,
        scales: &[f64],
        w: &[&[f64]],
    ) -> DMatrix<f64> {
        let (d, np, p, k) = (
            self.obs.dim(),
            self.layout.len(),
            self.active.len(),
            w.len(),
        );
        let parts = self.map_chunks(|this, c, ws| {
            let mut out = DMatrix::zeros(p, k);
            let mut part = NormalPart {
                cost: 0.0,
                gradient: vec![0.0; p],
                gram: Vec::new(),
            };
            for r in c * CHUNK_ROWS..((c + 1) * CHUNK_ROWS).min(this.obs.len()) {
                this.gather_row(r, d, np, p, scales, ws, &mut part);
                for row in 0..d {
                    let jr = &ws.rows[row * p..(row + 1) * p];
                    for (col, wc) in w.iter().enumerate() {
                        let x = wc[r * d + row];
                        if x != 0.0 {
                            out.column_mut(col)
                                .iter_mut()
                                .zip(jr)
                                .for_each(|(o, j)| *o += j * x);
                        }
                    }
                }
            }
            out
        });
        parts
            .into_iter()
            .fold(DMatrix::zeros(p, k), |acc, part| acc + part)
    }

    /// Consumes the problem, returning the linearisation point.
    pub fn into_params(self) -> KinematicParams {
        self.lin
    }

    fn scratch(&self) -> RowScratch {
        RowScratch::new(
            self.model.nq(),
            self.obs.dim(),
            self.layout.len(),
            self.active.len(),
        )
    }

    /// `work(self, chunk, scratch)` for every chunk of [`CHUNK_ROWS`] rows, results in chunk order: a
    /// problem of one chunk runs on this thread with the problem's own scratch (handing it to the
    /// pool costs more than small problems take), a larger one in parallel with a scratch per chunk.
    fn map_chunks<T: Send>(
        &mut self,
        work: impl Fn(&Self, usize, &mut RowScratch) -> T + Sync,
    ) -> Vec<T> {
        let chunks = self.obs.len().div_ceil(CHUNK_ROWS);
        if chunks <= 1 {
            let mut ws = std::mem::replace(&mut self.ws, RowScratch::new(0, 0, 0, 0));
            let out = (0..chunks).map(|c| work(self, c, &mut ws)).collect();
            self.ws = ws;
            return out;
        }
        let this = &*self;
        (0..chunks)
            .into_par_iter()
            .map(|c| work(this, c, &mut this.scratch()))
            .collect()
    }

    /// [`Self::map_chunks`] with `dst`, the chunk's part of `out` (`width` values per row), handed to
    /// `work` as well.
    fn map_chunks_into<T: Send>(
        &mut self,
        out: &mut [f64],
        width: usize,
        work: impl Fn(&Self, usize, &mut [f64], &mut RowScratch) -> T + Sync,
    ) -> Vec<T> {
        if self.obs.len() <= CHUNK_ROWS {
            let mut ws = std::mem::replace(&mut self.ws, RowScratch::new(0, 0, 0, 0));
            let out = vec![work(self, 0, out, &mut ws)];
            self.ws = ws;
            return out;
        }
        let this = &*self;
        out.par_chunks_mut(CHUNK_ROWS * width)
            .enumerate()
            .map(|(c, dst)| work(this, c, dst, &mut this.scratch()))
            .collect()
    }

    /// `work(self, chunk, dst, scratch)` for every chunk of rows, `dst` the chunk's part of `out`
    /// (`width` values per row); on this thread or in parallel as in [`Self::map_chunks`].
    fn fill_chunks(
        &mut self,
        out: &mut [f64],
        width: usize,
        work: impl Fn(&Self, usize, &mut [f64], &mut RowScratch) + Sync,
    ) {
        if self.obs.len() <= CHUNK_ROWS {
            let mut ws = std::mem::replace(&mut self.ws, RowScratch::new(0, 0, 0, 0));
            work(self, 0, out, &mut ws);
            self.ws = ws;
            return;
        }
        let this = &*self;
        out.par_chunks_mut(CHUNK_ROWS * width)
            .enumerate()
            .for_each(|(c, dst)| work(this, c, dst, &mut this.scratch()));
    }

    /// Fills `ws.block` with the weighted residuals' Jacobian of row `r` and returns the weighted
    /// residuals (first `dim` entries used) at the trial point.
    fn row_block(&self, r: usize, with_jacobian: bool, ws: &mut RowScratch) -> [f64; 6] {
        let obs = self.obs;
        let campaign = self.campaign.get(r).copied().unwrap_or(0);
        let pred = physical_row(
            &self.chain,
            &self.trial,
            &obs.ext,
            r,
            obs.q_row(r),
            campaign,
            &mut ws.predict,
        );
        let (p, lever, growth) = (pred.p_tracker, pred.lever, pred.growth);
        let sw = obs.weight[r].sqrt();
        let sp = sw / obs.sigma[r];
        let dp = p - obs.position[r];
        ws.error = dp;
        let mut res = [dp.x * sp, dp.y * sp, dp.z * sp, 0.0, 0.0, 0.0];
        let np = self.layout.len();
        if with_jacobian {
            self.chain.position_jacobian_of(
                &ws.predict.chain,
                &self.layout,
                self.joint_columns,
                &mut ws.block[..3 * np],
            );
            if growth != 0.0 {
                grow_columns(&self.layout, campaign, growth, &p, &mut ws.block[..3 * np]);
            }
            let bend = BendColumns {
                chain: &self.chain,
                scratch: &ws.predict,
                grown: 1.0 + growth,
                position: true,
            };
            extension_columns(
                &self.layout,
                obs.ext.row(r),
                &lever,
                &bend,
                &mut ws.block[..3 * np],
            );
            for v in &mut ws.block[..3 * np] {
                *v *= sp;
            }
        }
        if let Some(meas) = &obs.orientation {
            let so = sw / obs.sigma_rotation;
            let e = log_rotation(&(ws.predict.chain.r_tracker_target * meas[r].transpose()));
            res[3] = e.x * so;
            res[4] = e.y * so;
            res[5] = e.z * so;
            if with_jacobian {
                self.chain
                    .orientation_jacobian(&ws.predict.chain, &self.layout, &mut ws.rot);
                let bend = BendColumns {
                    chain: &self.chain,
                    scratch: &ws.predict,
                    grown: 1.0,
                    position: false,
                };
                extension_columns(
                    &self.layout,
                    obs.ext.row(r),
                    &Vector3::zeros(),
                    &bend,
                    &mut ws.rot,
                );
                let jl = left_jacobian_inverse(&e);
                for row in 0..3 {
                    for k in 0..np {
                        ws.block[(3 + row) * np + k] = so
                            * (jl[(row, 0)] * ws.rot[k]
                                + jl[(row, 1)] * ws.rot[np + k]
                                + jl[(row, 2)] * ws.rot[2 * np + k]);
                    }
                }
            }
        }
        res
    }

    /// Per-row weighted residual norms `‖rᵣ‖` at the linearisation point (noise units), one per row.
    pub fn row_norms(&mut self) -> Vec<f64> {
        let zero = vec![0.0; self.active.len()];
        self.set_params(&zero);
        let d = self.obs.dim();
        let mut out = vec![0.0; self.obs.len()];
        self.fill_chunks(&mut out, 1, |this, c, dst, ws| {
            for (k, v) in dst.iter_mut().enumerate() {
                let res = this.row_block(c * CHUNK_ROWS + k, false, ws);
                *v = res[..d].iter().map(|v| v * v).sum::<f64>().sqrt();
            }
        });
        out
    }

    /// Chunk `c`'s share of the normal equations (rows `c · CHUNK_ROWS ..`), scaled by `scales`.
    ///
    /// The scaled Jacobian rows of [`NORMAL_BLOCK_ROWS`] measurements are gathered (as columns of
    /// `Bᵀ`, p × rows) and added to the normal matrix as one product `Bᵀ B` (a cache-blocked matrix
    /// product instead of a pass over the normal matrix per measurement); every entry of the
    /// matrix is filled (the lower triangle is what is read).
    fn normal_part(
        &self,
        c: usize,
        scales: &[f64],
        ws: &mut RowScratch,
        part: &mut NormalPart,
        mut jac: Option<&mut [f64]>,
    ) {
        let d = self.obs.dim();
        let np = self.layout.len();
        let p = self.active.len();
        let rows = c * CHUNK_ROWS..((c + 1) * CHUNK_ROWS).min(self.obs.len());
        if p == 0 {
            for r in rows {
                self.add_row_normal(r, d, np, p, scales, ws, part);
            }
            return;
        }
        let first = rows.start;
        let width = NORMAL_BLOCK_ROWS * d;
        let mut bt = DMatrix::<f64>::zeros(p, width);
        let mut b = DMatrix::<f64>::zeros(width, p);
        let mut filled = 0;
        let mut flush = |bt: &DMatrix<f64>, filled: usize, gram: &mut [f64]| {
            let cols = bt.columns(0, filled);
            b.rows_mut(0, filled).tr_copy_from(&cols);
            let mut g = nalgebra::DMatrixViewMut::from_slice(gram, p, p);
            g.gemm(1.0, &cols, &b.rows(0, filled), 1.0);
        };
        for r in rows {
            self.gather_row(r, d, np, p, scales, ws, part);
            if let Some(jac) = jac.as_deref_mut() {
                jac[(r - first) * d * p..(r - first + 1) * d * p]
                    .copy_from_slice(&ws.rows[..d * p]);
            }
            for row in 0..d {
                bt.column_mut(filled)
                    .copy_from_slice(&ws.rows[row * p..(row + 1) * p]);
                filled += 1;
            }
            if filled == width {
                flush(&bt, filled, &mut part.gram);
                filled = 0;
            }
        }
        if filled > 0 {
            flush(&bt, filled, &mut part.gram);
        }
    }

    /// Row `r`'s share of `χ²` and of the gradient added to `part`; leaves its active, scaled
    /// Jacobian rows in `ws.rows` (d × p, row-major) for the normal matrix and its position error in
    /// `ws.error`. Returns its weighted residuals (the first `d`).
    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn gather_row(
        &self,
        r: usize,
        d: usize,
        np: usize,
        p: usize,
        scales: &[f64],
        ws: &mut RowScratch,
        part: &mut NormalPart,
    ) -> [f64; 6] {
        let res = self.row_block(r, true, ws);
        for (row, &e) in res.iter().enumerate().take(d) {
            let base = row * np;
            part.cost += e * e;
            let dst = &mut ws.rows[row * p..(row + 1) * p];
            for ((x, &k), &s) in dst.iter_mut().zip(&self.active).zip(scales) {
                *x = ws.block[base + k] * s;
            }
            for (g, &j) in part.gradient.iter_mut().zip(dst.iter()) {
                *g += j * e;
            }
        }
        res
    }

    /// Row `r`'s share of the normal equations added to `part` (`d` residuals, `np` layout and `p`
    /// active parameters); leaves its active, scaled Jacobian rows in `ws.rows` (d × p, row-major).
    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn add_row_normal(
        &self,
        r: usize,
        d: usize,
        np: usize,
        p: usize,
        scales: &[f64],
        ws: &mut RowScratch,
        part: &mut NormalPart,
    ) {
        self.gather_row(r, d, np, p, scales, ws, part);
        let gs = &mut part.gram;
        {
            // Lower triangle of the rank-d update, one pass over the normal matrix per measurement.
            if d == 3 {
                let (r0, rest) = ws.rows.split_at(p);
                let (r1, r2) = rest.split_at(p);
                for a in 0..p {
                    let (x0, x1, x2) = (r0[a], r1[a], r2[a]);
                    let col = &mut gs[a * p + a..(a + 1) * p];
                    for (((g, &y0), &y1), &y2) in
                        col.iter_mut().zip(&r0[a..]).zip(&r1[a..]).zip(&r2[a..])
                    {
                        *g += x0 * y0 + x1 * y1 + x2 * y2;
                    }
                }
            } else {
                for row in 0..d {
                    let jr = &ws.rows[row * p..(row + 1) * p];
                    for a in 0..p {
                        let ja = jr[a];
                        let col = &mut gs[a * p + a..(a + 1) * p];
                        for (g, &jb) in col.iter_mut().zip(&jr[a..]) {
                            *g += ja * jb;
                        }
                    }
                }
            }
        }
    }

    /// Per group of rows (`group[r] < k` for every row), at the trial point with the column scales
    /// `scales`: the group's share of the normal equations ([`LeastSquaresProblem::normal_equations`]:
    /// `χ²`, the lower triangle of `D JᵀJ D` column-major, `D Jᵀr`) and the `R` factors of its scaled
    /// Jacobian rows, one per chunk of [`CHUNK_ROWS`] rows that has some (stack them with
    /// [`crate::linalg::stacked_r_factor`]). One evaluation of each row serves both. Chunks run in
    /// parallel; every sum and list is in chunk order, so the result does not depend on the number
    /// of threads. The groups of cross-validation folds share their work this way.
    pub(crate) fn group_parts(
        &mut self,
        scales: &[f64],
        group: &[usize],
        k: usize,
    ) -> Vec<GroupPart> {
        assert_eq!(group.len(), self.obs.len(), "a group for every row");
        let d = self.obs.dim();
        let np = self.layout.len();
        let p = self.active.len();
        let n = self.obs.len();
        let zero = vec![0.0; p];
        self.set_params(&zero);
        let empty = || NormalPart {
            cost: 0.0,
            gradient: vec![0.0; p],
            gram: vec![0.0; p * p],
        };
        let this = &*self;
        let chunks: Vec<Vec<(NormalPart, Option<DMatrix<f64>>)>> = (0..n.div_ceil(CHUNK_ROWS))
            .into_par_iter()
            .map(|c| {
                let rows = c * CHUNK_ROWS..((c + 1) * CHUNK_ROWS).min(n);
                let mut ws = this.scratch();
                let mut count = vec![0usize; k];
                for r in rows.clone() {
                    count[group[r]] += 1;
                }
                let mut jac: Vec<DMatrix<f64>> =
                    count.iter().map(|&m| DMatrix::zeros(m * d, p)).collect();
                let mut at = vec![0usize; k];
                let mut parts: Vec<NormalPart> = (0..k).map(|_| empty()).collect();
                for r in rows {
                    let g = group[r];
                    this.add_row_normal(r, d, np, p, scales, &mut ws, &mut parts[g]);
                    for row in 0..d {
                        for a in 0..p {
                            jac[g][(at[g], a)] = ws.rows[row * p + a];
                        }
                        at[g] += 1;
                    }
                }
                parts
                    .into_iter()
                    .zip(jac)
                    .zip(&count)
                    .map(|((part, mut j), &m)| {
                        (part, (m > 0).then(|| crate::linalg::householder_r(&mut j)))
                    })
                    .collect()
            })
            .collect();
        let mut out: Vec<GroupPart> = (0..k)
            .map(|_| GroupPart {
                cost: 0.0,
                gram: vec![0.0; p * p],
                gradient: vec![0.0; p],
                factors: Vec::new(),
            })
            .collect();
        for chunk in chunks {
            for (o, (part, r)) in out.iter_mut().zip(chunk) {
                o.cost += part.cost;
                for (t, v) in o.gradient.iter_mut().zip(&part.gradient) {
                    *t += v;
                }
                for (t, v) in o.gram.iter_mut().zip(&part.gram) {
                    *t += v;
                }
                o.factors.extend(r);
            }
        }
        out
    }

    /// At the trial point, with the column scales `scales`: `χ²`, `D Jᵀr`, with `want.factor` the
    /// `R` factor of the scaled Jacobian (p × p, or fewer rows when there are fewer residuals than
    /// parameters), and with `want.rows` every row's position error and weighted residual norm, from
    /// one evaluation of each row. Chunks of [`FACTOR_CHUNK_ROWS`] rows run in parallel, each
    /// factored by Householder QR; sums and the stacked factor are in chunk order, so the result
    /// does not depend on the number of threads. What a pass of the streamed fit
    /// ([`crate::fit::stream`]) takes from each piece of a file; without the factor it costs the
    /// rows' Jacobians only, about a third of the pass with it.
    pub(crate) fn factor_share(&mut self, scales: &[f64], want: ShareRequest) -> Share {
        let d = self.obs.dim();
        let np = self.layout.len();
        let p = self.active.len();
        let n = self.obs.len();
        let this = &*self;
        type Piece = (NormalPart, Option<DMatrix<f64>>, RowResiduals);
        let chunks: Vec<Piece> = (0..n.div_ceil(FACTOR_CHUNK_ROWS))
            .into_par_iter()
            .map(|c| {
                let rows = c * FACTOR_CHUNK_ROWS..((c + 1) * FACTOR_CHUNK_ROWS).min(n);
                let mut ws = this.scratch();
                let mut part = NormalPart {
                    cost: 0.0,
                    gradient: vec![0.0; p],
                    gram: Vec::new(),
                };
                let mut out = RowResiduals::default();
                let height = if want.factor { rows.len() * d } else { 0 };
                // Column-major, filled row by row from the scratch's row-major rows.
                let mut j = vec![0.0; height * p];
                for (k, r) in rows.enumerate() {
                    let res = this.gather_row(r, d, np, p, scales, &mut ws, &mut part);
                    if want.rows {
                        out.errors.push(ws.error);
                        out.norms
                            .push(res[..d].iter().map(|v| v * v).sum::<f64>().sqrt());
                    }
                    if want.factor {
                        for row in 0..d {
                            let at = k * d + row;
                            for (a, &x) in ws.rows[row * p..(row + 1) * p].iter().enumerate() {
                                j[a * height + at] = x;
                            }
                        }
                    }
                }
                let factor = want.factor.then(|| {
                    let mut j = DMatrix::from_vec(height, p, j);
                    crate::linalg::householder_r(&mut j)
                });
                (part, factor, out)
            })
            .collect();
        let mut share = Share {
            cost: 0.0,
            gradient: vec![0.0; p],
            factor: None,
            rows: want.rows.then(RowResiduals::default),
        };
        let mut factors = Vec::with_capacity(chunks.len());
        for (part, factor, rows) in chunks {
            share.cost += part.cost;
            for (t, v) in share.gradient.iter_mut().zip(&part.gradient) {
                *t += v;
            }
            factors.extend(factor);
            if let Some(all) = share.rows.as_mut() {
                all.errors.extend(rows.errors);
                all.norms.extend(rows.norms);
            }
        }
        share.factor = want
            .factor
            .then(|| crate::linalg::stacked_r_factor(&factors, p));
        share
    }
}

/// What [`KinematicProblem::factor_share`] computes besides `χ²` and `D Jᵀr`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct ShareRequest {
    /// The `R` factor of the scaled Jacobian.
    pub factor: bool,
    /// Every row's position error and weighted residual norm.
    pub rows: bool,
}

/// A piece's share of a streamed pass ([`KinematicProblem::factor_share`]).
#[derive(Clone, Debug)]
pub(crate) struct Share {
    /// `χ²` (noise units).
    pub cost: f64,
    /// `D Jᵀr`.
    pub gradient: Vec<f64>,
    /// `R` of the scaled Jacobian, when asked for.
    pub factor: Option<DMatrix<f64>>,
    /// The rows' residuals, when asked for.
    pub rows: Option<RowResiduals>,
}

/// Every row's residuals at a point, in row order.
#[derive(Clone, Debug, Default)]
pub(crate) struct RowResiduals {
    /// Position error, prediction − measurement (tracker frame, m).
    pub errors: Vec<Vector3<f64>>,
    /// Weighted residual norm (noise units; 0 at weight 0).
    pub norms: Vec<f64>,
}

/// One group's share of the normal equations and its `R` factors ([`KinematicProblem::group_parts`]).
#[derive(Clone, Debug)]
pub(crate) struct GroupPart {
    /// `χ²` of the group's rows.
    pub cost: f64,
    /// Lower triangle of the group's `D JᵀJ D` (p × p, column-major).
    pub gram: Vec<f64>,
    /// The group's `D Jᵀr`.
    pub gradient: Vec<f64>,
    /// `R` factors of the group's scaled Jacobian rows, one per chunk of rows that has some.
    pub factors: Vec<DMatrix<f64>>,
}

impl LeastSquaresProblem for KinematicProblem<'_> {
    fn n_params(&self) -> usize {
        self.active.len()
    }

    fn n_residuals(&self) -> usize {
        self.obs.len() * self.obs.dim()
    }

    fn set_params(&mut self, step: &[f64]) {
        self.trial_at_lin = step.iter().all(|s| *s == 0.0);
        copy_params(&mut self.trial, &self.lin);
        self.step_full.fill(0.0);
        for (&k, &s) in self.active.iter().zip(step) {
            self.step_full[k] = s;
        }
        self.trial.retract(&self.layout, &self.step_full);
        self.chain.update(self.model, &self.trial);
    }

    fn accept(&mut self) {
        copy_params(&mut self.lin, &self.trial);
        self.jac_at_lin &= self.trial_at_lin;
        self.trial_at_lin = true;
    }

    fn residuals(&mut self, out: &mut [f64]) {
        let d = self.obs.dim();
        self.fill_chunks(out, d, |this, c, dst, ws| {
            for (k, v) in dst.chunks_exact_mut(d).enumerate() {
                let res = this.row_block(c * CHUNK_ROWS + k, false, ws);
                v.copy_from_slice(&res[..d]);
            }
        });
    }

    fn jacobian(&mut self, out: &mut DMatrix<f64>) {
        let d = self.obs.dim();
        let np = self.layout.len();
        let p = self.active.len();
        let n = self.obs.len();
        // Row-major blocks per chunk, then scattered into the column-major `out`.
        let blocks = self.map_chunks(|this, c, ws| {
            let rows = c * CHUNK_ROWS..((c + 1) * CHUNK_ROWS).min(n);
            let mut dst = vec![0.0; rows.len() * d * p];
            for (k, r) in rows.enumerate() {
                this.row_block(r, true, ws);
                for row in 0..d {
                    for (a, &col) in this.active.iter().enumerate() {
                        dst[(k * d + row) * p + a] = ws.block[row * np + col];
                    }
                }
            }
            dst
        });
        for (c, block) in blocks.iter().enumerate() {
            let first = c * CHUNK_ROWS * d;
            for (i, row) in block.chunks_exact(p).enumerate() {
                for (a, &v) in row.iter().enumerate() {
                    out[(first + i, a)] = v;
                }
            }
        }
    }

    fn scaled_factor(&mut self, scales: &[f64]) -> DMatrix<f64> {
        let d = self.obs.dim();
        let np = self.layout.len();
        let p = self.active.len();
        let m = self.obs.len() * d;
        if !crate::linalg::is_tall(m, p) {
            if let Some(jd) = self.kept_jacobian(scales) {
                // Already scaled: unit scales multiply by 1, the same numbers.
                let j = DMatrix::from_row_slice(m, p, jd);
                return crate::lm::Subspace::square_factor(&j, &vec![1.0; p]);
            }
            let mut j = DMatrix::zeros(m, p);
            self.jacobian(&mut j);
            return crate::lm::Subspace::square_factor(&j, scales);
        }
        // The blocks of rows of the tall-skinny QR, each made from the measurements it overlaps: the
        // same matrices as cutting the whole Jacobian, without forming it.
        // With the Jacobian the last normal equations left, the blocks are copied from it.
        let kept = self.kept_jacobian(scales);
        let block = crate::linalg::tsqr_block_rows(p);
        let this = &*self;
        let factors: Vec<DMatrix<f64>> = (0..m.div_ceil(block))
            .into_par_iter()
            .map(|b| {
                let (first, last) = (b * block, ((b + 1) * block).min(m));
                if let Some(jd) = kept {
                    let mut out =
                        DMatrix::from_row_slice(last - first, p, &jd[first * p..last * p]);
                    return crate::linalg::householder_r(&mut out);
                }
                let mut ws = this.scratch();
                let mut out = DMatrix::zeros(last - first, p);
                for r in first / d..last.div_ceil(d) {
                    this.row_block(r, true, &mut ws);
                    for row in 0..d {
                        let k = r * d + row;
                        if k < first || k >= last {
                            continue;
                        }
                        for (a, &col) in this.active.iter().enumerate() {
                            out[(k - first, a)] = ws.block[row * np + col] * scales[a];
                        }
                    }
                }
                crate::linalg::householder_r(&mut out)
            })
            .collect();
        crate::linalg::stacked_r_factor(&factors, p)
    }

    /// From the Jacobian kept by the last [`LeastSquaresProblem::normal_equations`] when the trial
    /// point is still there with the same `scales` (how the solver calls it); else formed anew.
    fn scaled_jacobian_transpose_times(&mut self, scales: &[f64], w: &[f64], out: &mut [f64]) {
        let p = self.active.len();
        if let Some(jd) = self.kept_jacobian(scales) {
            let jt = nalgebra::DMatrixView::from_slice(jd, p, w.len());
            let mut o = nalgebra::DVectorViewMut::from_slice(out, p);
            o.gemv(
                1.0,
                &jt,
                &nalgebra::DVectorView::from_slice(w, w.len()),
                0.0,
            );
            return;
        }
        // Row by row, without forming `J` (m × p).
        let column = self.scaled_jacobian_transpose_times_columns(scales, &[w]);
        out.copy_from_slice(column.as_slice());
    }

    fn normal_equations(
        &mut self,
        scales: &[f64],
        gram: &mut DMatrix<f64>,
        gradient: &mut [f64],
    ) -> f64 {
        let p = self.active.len();
        let empty = || NormalPart {
            cost: 0.0,
            gradient: vec![0.0; p],
            gram: vec![0.0; p * p],
        };
        let parts = if self.n_residuals() * p <= self.keep_limit {
            let mut jac = std::mem::take(&mut self.jac);
            jac.resize(self.n_residuals() * p, 0.0);
            self.jac_scales.clear();
            self.jac_scales.extend_from_slice(scales);
            self.jac_at_lin = self.trial_at_lin;
            let parts = self.map_chunks_into(&mut jac, self.obs.dim() * p, |this, c, dst, ws| {
                let mut part = empty();
                this.normal_part(c, scales, ws, &mut part, Some(dst));
                part
            });
            self.jac = jac;
            parts
        } else {
            // Too large to keep: the products that would read it form its rows again.
            self.jac = Vec::new();
            self.jac_scales.clear();
            self.jac_at_lin = false;
            self.map_chunks(|this, c, ws| {
                let mut part = empty();
                this.normal_part(c, scales, ws, &mut part, None);
                part
            })
        };
        // Added in chunk order: the same sums on any number of threads (one chunk: row order).
        let mut parts = parts.into_iter();
        let mut total = parts.next().unwrap_or_else(empty);
        for part in parts {
            total.cost += part.cost;
            for (t, v) in total.gradient.iter_mut().zip(&part.gradient) {
                *t += v;
            }
            for (t, v) in total.gram.iter_mut().zip(&part.gram) {
                *t += v;
            }
        }
        gram.as_mut_slice().copy_from_slice(&total.gram);
        gradient.copy_from_slice(&total.gradient);
        // Mirror the lower triangle.
        for a in 0..p {
            for b in a + 1..p {
                gram[(a, b)] = gram[(b, a)];
            }
        }
        total.cost
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lm::LeastSquaresProblem;
    use crate::model::observations::NoiseModel;
    use rand::{RngExt, SeedableRng};
    use sim::measurement_table::{MeasurementTable, OptionalColumns};

    /// A problem too large to keep its Jacobian ([`KEEP_JACOBIAN_MAX_VALUES`], lowered to 0 here)
    /// gives the normal equations and the rank decision's factor bit for bit, `D Jᵀ w` to rounding,
    /// and a solve to the same minimum (its predictions within 1e-9 of the noise σ): 5,000 rows of
    /// random data, three chunks.
    #[test]
    fn a_problem_that_does_not_keep_its_jacobian_gives_the_same_numbers() {
        let model = sim::robots::load_builtin("iiwa7").unwrap();
        let mut rng = rand::rngs::StdRng::seed_from_u64(12);
        let n = 5000;
        let mut table = MeasurementTable::new(7, OptionalColumns::default());
        let truth = {
            let mut t = KinematicParams::nominal(7, false);
            t.zero_offset = (0..7).map(|_| rng.random_range(-1e-3..1e-3)).collect();
            t
        };
        let chain = crate::model::chain::Chain::new(&model, &truth);
        let mut cs = crate::model::chain::ChainScratch::new(7);
        for r in 0..n {
            let q: Vec<f64> = (0..7).map(|_| rng.random_range(-1.5..1.5)).collect();
            chain.forward_in(&mut cs, &q, 0);
            table.pose.push(r as i64);
            table.q.extend(&q);
            let p = cs.p_tracker;
            table.position.push([
                p.x + rng.random_range(-1e-5..1e-5),
                p.y + rng.random_range(-1e-5..1e-5),
                p.z + rng.random_range(-1e-5..1e-5),
            ]);
        }
        let noise = NoiseModel::default();
        let rows: Vec<usize> = (0..n).collect();
        let obs = Observations::from_table(&table, &rows, &noise, "t").unwrap();
        let params = KinematicParams::nominal(7, false);
        let layout = ParamLayout::for_params(&model, &params, Vec::new());
        let p = layout.len();
        let scales: Vec<f64> = (0..p).map(|k| 1.0 + 0.1 * k as f64).collect();
        let mut kept = KinematicProblem::new(&model, &obs, params.clone(), (0..p).collect());
        let mut formed = KinematicProblem::new(&model, &obs, params.clone(), (0..p).collect());
        formed.keep_limit = 0;
        let (mut g1, mut g2) = (DMatrix::zeros(p, p), DMatrix::zeros(p, p));
        let (mut b1, mut b2) = (vec![0.0; p], vec![0.0; p]);
        kept.set_params(&vec![0.0; p]);
        formed.set_params(&vec![0.0; p]);
        let c1 = kept.normal_equations(&scales, &mut g1, &mut b1);
        let c2 = formed.normal_equations(&scales, &mut g2, &mut b2);
        assert!(!kept.jac.is_empty() && formed.jac.is_empty());
        assert_eq!(c1.to_bits(), c2.to_bits());
        assert_eq!(g1, g2);
        assert_eq!(b1, b2);
        assert_eq!(kept.scaled_factor(&scales), formed.scaled_factor(&scales));
        let w: Vec<f64> = (0..3 * n).map(|k| ((k * 37) % 101) as f64 - 50.0).collect();
        let (mut o1, mut o2) = (vec![0.0; p], vec![0.0; p]);
        kept.scaled_jacobian_transpose_times(&scales, &w, &mut o1);
        formed.scaled_jacobian_transpose_times(&scales, &w, &mut o2);
        let omax = o1.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for a in 0..p {
            assert!((o1[a] - o2[a]).abs() <= 1e-12 * omax, "D Jᵀ w [{a}]");
        }
        // Solved to the minimum both ways (with the parameters' own scales): the same predictions.
        let physical: Vec<f64> = crate::model::params::ParameterScales::default()
            .vector(&layout)
            .iter()
            .copied()
            .collect();
        let solve = |mut prob: KinematicProblem| {
            let mut ws = crate::lm::LmWorkspace::new(prob.n_residuals(), p);
            let (report, _) =
                crate::lm::minimize(&mut prob, &physical, &Default::default(), &mut ws);
            assert!(report.was_successful(), "{report:?}");
            prob.into_params()
        };
        let (a, b) = (solve(kept), solve(formed));
        let (ca, cb) = (
            crate::model::chain::Chain::new(&model, &a),
            crate::model::chain::Chain::new(&model, &b),
        );
        let mut sb = crate::model::chain::ChainScratch::new(7);
        for r in (0..n).step_by(50) {
            ca.forward_in(&mut cs, table.q_row(r), 0);
            cb.forward_in(&mut sb, table.q_row(r), 0);
            assert!(
                (cs.p_tracker - sb.p_tracker).norm() < 1e-9 * 1e-5,
                "row {r}"
            );
        }
    }

    /// Each group's share of [`KinematicProblem::group_parts`] against the normal equations of a
    /// problem on that group's rows alone (what a fold computes for itself), and the groups' sum
    /// against the problem on every row; each group's stacked `R` factors against its normal matrix
    /// (`RᵀR = D JᵀJ D`). 5,000 rows: three chunks, summed and stacked in order.
    #[test]
    fn group_parts_add_up_to_each_groups_own_normal_equations() {
        let model = sim::robots::load_builtin("iiwa7").unwrap();
        let mut rng = rand::rngs::StdRng::seed_from_u64(11);
        let n = 5000;
        let mut table = MeasurementTable::new(7, OptionalColumns::default());
        for r in 0..n {
            table.pose.push(r as i64);
            for _ in 0..7 {
                table.q.push(rng.random_range(-1.5..1.5));
            }
            table.position.push([
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            ]);
        }
        let noise = NoiseModel::default();
        let all_rows: Vec<usize> = (0..n).collect();
        let obs = Observations::from_table(&table, &all_rows, &noise, "t").unwrap();
        let params = KinematicParams::nominal(7, false);
        let layout = ParamLayout::for_params(&model, &params, Vec::new());
        let p = layout.len();
        let scales: Vec<f64> = (0..p).map(|k| 1.0 + 0.1 * k as f64).collect();
        let k = 3;
        let group: Vec<usize> = (0..n).map(|r| (r * 7 + r / 11) % k).collect();
        let mut problem = KinematicProblem::new(&model, &obs, params.clone(), (0..p).collect());
        let parts = problem.group_parts(&scales, &group, k);
        // The normal equations of `rows` alone.
        let own = |rows: &[usize]| {
            let o = Observations::from_table(&table, rows, &noise, "t").unwrap();
            let mut pr = KinematicProblem::new(&model, &o, params.clone(), (0..p).collect());
            let mut gram = DMatrix::zeros(p, p);
            let mut gradient = vec![0.0; p];
            pr.set_params(&vec![0.0; p]);
            let cost = pr.normal_equations(&scales, &mut gram, &mut gradient);
            (cost, gram, gradient)
        };
        let close = |a: f64, b: f64, scale: f64| (a - b).abs() <= 1e-11 * scale;
        let (mut sum_cost, mut sum_grad, mut sum_gram) = (0.0, vec![0.0; p], vec![0.0; p * p]);
        for (g, part) in parts.iter().enumerate() {
            let rows: Vec<usize> = (0..n).filter(|&r| group[r] == g).collect();
            let (cost, gram, gradient) = own(&rows);
            let gmax = gram.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            assert!(close(part.cost, cost, cost), "group {g}: χ²");
            let grad_max = gradient.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            for a in 0..p {
                assert!(
                    close(part.gradient[a], gradient[a], grad_max),
                    "group {g}: gradient {a}"
                );
                for b in a..p {
                    assert!(
                        close(part.gram[a * p + b], gram[(b, a)], gmax),
                        "group {g}: ({b}, {a})"
                    );
                }
            }
            let r = crate::linalg::stacked_r_factor(&part.factors, p);
            let rtr = r.transpose() * &r;
            for a in 0..p {
                for b in 0..p {
                    assert!(
                        (rtr[(a, b)] - gram[(a, b)]).abs() <= 1e-10 * gmax,
                        "group {g}: RᵀR ({a}, {b})"
                    );
                }
            }
            sum_cost += part.cost;
            for (s, v) in sum_grad.iter_mut().zip(&part.gradient) {
                *s += v;
            }
            for (s, v) in sum_gram.iter_mut().zip(&part.gram) {
                *s += v;
            }
        }
        let (cost, gram, gradient) = own(&all_rows);
        let gmax = gram.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(close(sum_cost, cost, cost));
        let grad_max = gradient.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for a in 0..p {
            assert!(close(sum_grad[a], gradient[a], grad_max));
            for b in a..p {
                assert!(close(sum_gram[a * p + b], gram[(b, a)], gmax));
            }
        }
    }
}
