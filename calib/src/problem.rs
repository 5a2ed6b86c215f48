//! The calibration problem: measurements, their weights, and the kinematic model's residuals and
//! Jacobian as a [`LeastSquaresProblem`].
//!
//! Residuals, per measurement row, are `(p_predicted − p_measured) √w / σ` (3, tracker frame) and, with
//! orientation, `log(R_predicted R_measuredᵀ) √w / σ_rot` (3, tracker frame rotation vector), where `σ`
//! is the row's position standard deviation ([`NoiseModel`]) and `w` a robust weight (1 unless
//! iteratively reweighted). The orientation rows' Jacobian includes the exact `J_l⁻¹` of the
//! logarithm.

use crate::chain::Chain;
use crate::error::{CalibError, Result};
use crate::extensions::{Regressors, Term};
use crate::predict::{PredictScratch, physical_row};
use crate::lie3::{left_jacobian_inverse, log_rotation, rotation_from_quaternion};
use crate::lm::LeastSquaresProblem;
use crate::params::{KinematicParams, ParamLayout};
use nalgebra::{DMatrix, Matrix3, Vector3};
use sim::Model;
use sim::measurement_table::MeasurementTable;

/// Standard deviations of the measurements when the table has no `sigma` column (a laser-tracker model).
///
/// Position: `σ = position_sigma_m + position_sigma_per_m · d`, `d` the distance of the measured point from
/// the tracker frame's origin (the tracker head). The defaults, 7.5 µm + 3 µm/m, are half the maximum
/// permissible error of common laser trackers (e.g. 15 µm + 6 µm/m for the GTS3800 of the real data
/// sets), which manufacturers state at about 2σ. Only ratios of weights change the estimate; the
/// reported covariance uses the variance factor estimated from the residuals, so a wrong absolute level
/// shows up as `χ²/dof ≠ 1`, not as wrong standard deviations.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct NoiseModel {
    /// Constant part of the position standard deviation (m). Default 7.5e-6.
    pub position_sigma_m: f64,
    /// Distance-proportional part (m per m of distance from the tracker). Default 3e-6.
    pub position_sigma_per_m: f64,
    /// Standard deviation of each orientation component (rad), for 6-DoF probes. Default 1e-4
    /// (about 0.006°, half the 0.01° typical of 6-DoF laser-tracker probes).
    pub orientation_sigma_rad: f64,
}

impl Default for NoiseModel {
    fn default() -> Self {
        NoiseModel {
            position_sigma_m: 7.5e-6,
            position_sigma_per_m: 3e-6,
            orientation_sigma_rad: 1e-4,
        }
    }
}

/// Measurement rows prepared for the solver (a subset of a [`MeasurementTable`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Observations {
    /// Joints per row.
    pub n_joints: usize,
    /// Joint positions, row-major (rad or m).
    pub q: Vec<f64>,
    /// Measured target positions, tracker frame (m).
    pub position: Vec<Vector3<f64>>,
    /// Measured target orientations, tracker frame, when the table has them.
    pub orientation: Option<Vec<Matrix3<f64>>>,
    /// Position standard deviation per row (m).
    pub sigma: Vec<f64>,
    /// Orientation standard deviation (rad).
    pub sigma_rotation: f64,
    /// Robust weight per row in (0, 1]; 1 without a robust loss.
    pub weight: Vec<f64>,
    /// Pose id per row.
    pub pose: Vec<i64>,
    /// 0-based index of each row in the source table.
    pub source_row: Vec<usize>,
    /// Regressors of the model extensions per row ([`Regressors::none`] for the kinematic model).
    pub ext: Regressors,
}

impl Observations {
    /// Takes `rows` (0-based) of `table`; `source` names the table in errors. Sigma comes from the
    /// `sigma` column when present (it must be > 0), otherwise from `noise`.
    pub fn from_table(
        table: &MeasurementTable,
        rows: &[usize],
        noise: &NoiseModel,
        source: &str,
    ) -> Result<Self> {
        let n = table.n_joints;
        let mut q = Vec::with_capacity(rows.len() * n);
        let mut position = Vec::with_capacity(rows.len());
        let mut sigma = Vec::with_capacity(rows.len());
        let mut orientation = table
            .orientation
            .as_ref()
            .map(|_| Vec::with_capacity(rows.len()));
        for &r in rows {
            q.extend_from_slice(table.q_row(r));
            let p = Vector3::from(table.position[r]);
            position.push(p);
            let s = match &table.sigma {
                Some(col) => {
                    let s = col[r];
                    if !(s > 0.0 && s.is_finite()) {
                        return Err(CalibError::BadValue {
                            context: format!("{source}: row {}", r + 1),
                            field: "sigma".into(),
                            value: format!("{s:?}"),
                            problem: "a measurement cannot be exact: give its 1-sigma uncertainty in m (> 0)"
                                .into(),
                        });
                    }
                    s
                }
                None => noise.position_sigma_m + noise.position_sigma_per_m * p.norm(),
            };
            sigma.push(s);
            if let (Some(o), Some(qu)) = (orientation.as_mut(), table.unit_orientation(r)) {
                o.push(rotation_from_quaternion(&qu));
            }
        }
        Ok(Observations {
            n_joints: n,
            q,
            position,
            orientation,
            sigma,
            sigma_rotation: noise.orientation_sigma_rad,
            weight: vec![1.0; rows.len()],
            pose: rows.iter().map(|&r| table.pose[r]).collect(),
            source_row: rows.to_vec(),
            ext: Regressors::none(),
        })
    }

    /// Number of measurement rows.
    #[inline]
    pub fn len(&self) -> usize {
        self.position.len()
    }

    /// True without rows.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.position.is_empty()
    }

    /// Residuals per row: 3, or 6 with orientation.
    #[inline]
    pub fn dim(&self) -> usize {
        if self.orientation.is_some() { 6 } else { 3 }
    }

    /// Joint positions of row `r` (rad or m).
    #[inline]
    pub fn q_row(&self, r: usize) -> &[f64] {
        &self.q[r * self.n_joints..(r + 1) * self.n_joints]
    }

    /// Number of distinct pose ids.
    pub fn n_poses(&self) -> usize {
        let mut ids = self.pose.clone();
        ids.sort_unstable();
        ids.dedup();
        ids.len()
    }
}

/// Turns the kinematic position Jacobian of `p_kin` into that of the grown prediction
/// `p = t + (1 + γ)(p_kin − t)` (`t` the base origin, tracker frame): every column that moves `p_kin`
/// only is multiplied by `1 + γ`; the base twist moves `p` rigidly, `[−[p], I]` at the final `p` (m).
fn grow_columns(layout: &ParamLayout, growth: f64, p: &Vector3<f64>, block: &mut [f64]) {
    let np = layout.len();
    let kb = layout.base();
    let ec_cross_p = [
        Vector3::new(0.0, -p.z, p.y),
        Vector3::new(p.z, 0.0, -p.x),
        Vector3::new(-p.y, p.x, 0.0),
    ];
    for row in 0..3 {
        let cols = &mut block[row * np..row * np + layout.kinematic_len()];
        for (k, v) in cols.iter_mut().enumerate() {
            if !(kb..kb + 6).contains(&k) {
                *v *= 1.0 + growth;
            }
        }
        for c in 0..3 {
            cols[kb + c] = ec_cross_p[c][row];
            cols[kb + 3 + c] = if row == c { 1.0 } else { 0.0 };
        }
    }
}

/// Fills the extension columns of a 3-row Jacobian block (row-major, `layout.len()` columns) whose
/// kinematic columns are set: a joint-angle term is the joint's zero-offset column times its regressor,
/// the growth term `lever` times its regressor.
fn extension_columns(
    layout: &ParamLayout,
    coef: &[f64],
    lever: &Vector3<f64>,
    rows: usize,
    block: &mut [f64],
) {
    let np = layout.len();
    for (e, (p, &g)) in layout.extensions.iter().zip(coef).enumerate() {
        let ke = layout.extension(e);
        for row in 0..rows {
            block[row * np + ke] = match p.term {
                Term::JointAngle { joint } => block[row * np + layout.zero_offset(joint)] * g,
                Term::Growth => lever[row] * g,
            };
        }
    }
}

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
    /// The current row's evaluation (effective joint values, frames).
    scratch: PredictScratch,
    step_full: Vec<f64>,
    /// Jacobian rows of one measurement (dim × layout.len()), row-major.
    block: Vec<f64>,
    /// Orientation Jacobian before `J_l⁻¹` (3 × layout.len()).
    rot: Vec<f64>,
    /// Active, weighted, scaled Jacobian rows of one measurement (dim × active), row-major.
    rows: Vec<f64>,
}

fn copy_params(dst: &mut KinematicParams, src: &KinematicParams) {
    dst.joint_error.copy_from_slice(&src.joint_error);
    dst.zero_offset.copy_from_slice(&src.zero_offset);
    dst.t_tracker_base = src.t_tracker_base;
    dst.p_flange_target = src.p_flange_target;
    dst.r_flange_target = src.r_flange_target;
    dst.extension.copy_from_slice(&src.extension);
}

impl<'a> KinematicProblem<'a> {
    /// The problem at `start`; `active` lists the [`ParamLayout`] indices to solve for (the others stay).
    ///
    /// # Panics
    /// If `start` or `obs` do not fit `model`, or an active index is out of range.
    pub fn new(
        model: &'a Model,
        obs: &'a Observations,
        start: KinematicParams,
        active: Vec<usize>,
    ) -> Self {
        let layout = ParamLayout::new(model, obs.orientation.is_some())
            .with_extensions(obs.ext.params.clone());
        assert_eq!(obs.n_joints, model.nq(), "joint count of the observations");
        assert!(active.iter().all(|&k| k < layout.len()), "active index");
        assert_eq!(
            start.r_flange_target.is_some(),
            layout.orientation,
            "orientation parameters"
        );
        assert_eq!(start.extension.len(), obs.ext.len(), "extension parameters");
        let np = layout.len();
        let dim = obs.dim();
        KinematicProblem {
            model,
            obs,
            chain: Chain::new(model, &start),
            scratch: PredictScratch::new(model.nq()),
            trial: start.clone(),
            lin: start,
            step_full: vec![0.0; np],
            block: vec![0.0; dim * np],
            rot: vec![0.0; 3 * np],
            rows: vec![0.0; dim * active.len()],
            active,
            layout,
        }
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

    /// Consumes the problem, returning the linearisation point.
    pub fn into_params(self) -> KinematicParams {
        self.lin
    }

    /// Fills `self.block` with the weighted residuals' Jacobian of row `r` and returns the weighted
    /// residuals (first `dim` entries used) at the trial point.
    fn row_block(&mut self, r: usize, with_jacobian: bool) -> [f64; 6] {
        let obs = self.obs;
        let pred = physical_row(
            &self.chain,
            &self.trial,
            &obs.ext,
            r,
            obs.q_row(r),
            &mut self.scratch,
        );
        let (p, lever, growth) = (pred.p_tracker, pred.lever, pred.growth);
        let sw = obs.weight[r].sqrt();
        let sp = sw / obs.sigma[r];
        let dp = p - obs.position[r];
        let mut res = [dp.x * sp, dp.y * sp, dp.z * sp, 0.0, 0.0, 0.0];
        let np = self.layout.len();
        if with_jacobian {
            self.chain.position_jacobian(
                &self.scratch.chain,
                &self.layout,
                &mut self.block[..3 * np],
            );
            if growth != 0.0 {
                grow_columns(&self.layout, growth, &p, &mut self.block[..3 * np]);
            }
            extension_columns(
                &self.layout,
                obs.ext.row(r),
                &lever,
                3,
                &mut self.block[..3 * np],
            );
            for v in &mut self.block[..3 * np] {
                *v *= sp;
            }
        }
        if let Some(meas) = &obs.orientation {
            let so = sw / obs.sigma_rotation;
            let e = log_rotation(&(self.scratch.chain.r_tracker_target * meas[r].transpose()));
            res[3] = e.x * so;
            res[4] = e.y * so;
            res[5] = e.z * so;
            if with_jacobian {
                self.chain
                    .orientation_jacobian(&self.scratch.chain, &self.layout, &mut self.rot);
                extension_columns(
                    &self.layout,
                    obs.ext.row(r),
                    &Vector3::zeros(),
                    3,
                    &mut self.rot,
                );
                let jl = left_jacobian_inverse(&e);
                for row in 0..3 {
                    for k in 0..np {
                        self.block[(3 + row) * np + k] = so
                            * (jl[(row, 0)] * self.rot[k]
                                + jl[(row, 1)] * self.rot[np + k]
                                + jl[(row, 2)] * self.rot[2 * np + k]);
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
        (0..self.obs.len())
            .map(|r| {
                let res = self.row_block(r, false);
                res[..d].iter().map(|v| v * v).sum::<f64>().sqrt()
            })
            .collect()
    }
}

impl LeastSquaresProblem for KinematicProblem<'_> {
    fn n_params(&self) -> usize {
        self.active.len()
    }

    fn n_residuals(&self) -> usize {
        self.obs.len() * self.obs.dim()
    }

    fn set_params(&mut self, step: &[f64]) {
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
    }

    fn residuals(&mut self, out: &mut [f64]) {
        let d = self.obs.dim();
        for r in 0..self.obs.len() {
            let res = self.row_block(r, false);
            out[r * d..(r + 1) * d].copy_from_slice(&res[..d]);
        }
    }

    fn jacobian(&mut self, out: &mut DMatrix<f64>) {
        let d = self.obs.dim();
        let np = self.layout.len();
        for r in 0..self.obs.len() {
            self.row_block(r, true);
            for row in 0..d {
                for (a, &k) in self.active.iter().enumerate() {
                    out[(r * d + row, a)] = self.block[row * np + k];
                }
            }
        }
    }

    fn normal_equations(
        &mut self,
        scales: &[f64],
        gram: &mut DMatrix<f64>,
        gradient: &mut [f64],
    ) -> f64 {
        let d = self.obs.dim();
        let np = self.layout.len();
        let p = self.active.len();
        gram.fill(0.0);
        gradient.fill(0.0);
        let mut cost = 0.0;
        for r in 0..self.obs.len() {
            let res = self.row_block(r, true);
            // Gather the active, scaled rows of this measurement (d × p, row-major).
            for (row, &e) in res.iter().enumerate().take(d) {
                let base = row * np;
                cost += e * e;
                let dst = &mut self.rows[row * p..(row + 1) * p];
                for ((x, &k), &s) in dst.iter_mut().zip(&self.active).zip(scales) {
                    *x = self.block[base + k] * s;
                }
                for (g, &j) in gradient.iter_mut().zip(dst.iter()) {
                    *g += j * e;
                }
            }
            // Lower triangle of the rank-d update, one pass over the normal matrix per measurement.
            let gs = gram.as_mut_slice();
            if d == 3 {
                let (r0, rest) = self.rows.split_at(p);
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
                    let jr = &self.rows[row * p..(row + 1) * p];
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
        // Mirror the lower triangle.
        for a in 0..p {
            for b in a + 1..p {
                gram[(a, b)] = gram[(b, a)];
            }
        }
        cost
    }
}
