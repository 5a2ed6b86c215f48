//! The one prediction path of a calibrated model: the kinematic chain at the extended joint values,
//! the growth of the arm, and the learned residual correction.
//!
//! ```text
//! θ = q + Σₑ xₑ gₑ(row)                    (joint-angle terms of the extensions)
//! φᵢ = Σₑ xₑ gₑ(row) e_about               (bending terms, turning the chain at joint i)
//! p_kin = T_tracker_base · T_base_flange(θ, φ) · p_flange
//! p = t_base + (1 + γ) (p_kin − t_base),  γ = Σₑ xₑ gₑ(row)   (growth terms)
//! p_tracker = p + r̂(q)                     (learned correction, when the model has one)
//! ```
//!
//! [`Prediction`] holds the chain prepared once per parameter point (immutable) and evaluates rows into a
//! [`PredictScratch`] made once per thread, so batches never allocate per row. The solver
//! ([`crate::problem`]), the statistics, outlier detection, `predict`, the sweep and diagnose all go
//! through it.

use crate::chain::{Chain, ChainScratch};
use crate::error::{CalibError, Result};
use crate::extensions::{Regressors, apply, bends};
use crate::learned::LearnedResidual;
use crate::lie3::log_rotation;
use crate::observations::Observations;
use crate::params::{KinematicParams, ParamLayout};
use nalgebra::{DMatrix, Matrix3, Vector3};
use rayon::prelude::*;
use sim::Model;

/// Rows per parallel work item of the batch evaluations.
const CHUNK_ROWS: usize = 2048;

/// One row's physical prediction (no learned correction).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RowPrediction {
    /// Predicted target position, tracker frame (m), growth applied.
    pub p_tracker: Vector3<f64>,
    /// `p_kin − t_tracker_base` (m): the lever that the growth multiplies.
    pub lever: Vector3<f64>,
    /// The growth factor `γ` (dimensionless; 0 without growth terms).
    pub growth: f64,
}

/// Per-evaluation workspace of a [`Prediction`]: made once, reused without allocating.
#[derive(Clone, Debug)]
pub struct PredictScratch {
    /// The chain's frames at the last row (tracker frame), with `r_tracker_target`.
    pub chain: ChainScratch,
    /// Effective joint values `θ` of the last row (rad or m).
    pub theta: Vec<f64>,
    /// Bending rotation vector of each joint at the last row (rad, joint frame; link deflection).
    pub bend: Vec<Vector3<f64>>,
}

impl PredictScratch {
    /// Workspace for a robot of `n` joints.
    pub fn new(n: usize) -> Self {
        PredictScratch {
            chain: ChainScratch::new(n),
            theta: vec![0.0; n],
            bend: vec![Vector3::zeros(); n],
        }
    }
}

/// The physical prediction of row `r` (regressors `regs`, joint values `q`) by `chain`, prepared at
/// `params`, into `s`: the one evaluation every path uses.
#[inline]
pub fn physical_row(
    chain: &Chain,
    params: &KinematicParams,
    regs: &Regressors,
    r: usize,
    q: &[f64],
    s: &mut PredictScratch,
) -> RowPrediction {
    let growth = apply(regs, &params.extension, r, q, &mut s.theta);
    if bends(regs, &params.extension, r, &mut s.bend) {
        chain.forward_bent(&mut s.chain, &s.theta, &s.bend);
    } else {
        chain.forward(&mut s.chain, &s.theta);
    }
    let lever = s.chain.p_tracker - params.t_tracker_base.translation.vector;
    RowPrediction {
        p_tracker: s.chain.p_tracker + growth * lever,
        lever,
        growth,
    }
}

/// A calibrated model ready to predict: parameters, prepared chain, optional learned correction.
#[derive(Clone, Debug)]
pub struct Prediction<'a> {
    params: &'a KinematicParams,
    chain: Chain,
    learned: Option<&'a LearnedResidual>,
    nq: usize,
}

impl<'a> Prediction<'a> {
    /// The physical model `params` of `model` (no learned correction).
    pub fn new(model: &Model, params: &'a KinematicParams) -> Self {
        Prediction {
            params,
            chain: Chain::new(model, params),
            learned: None,
            nq: model.nq(),
        }
    }

    /// The same with the learned correction `learned` added to every position.
    pub fn with_learned(mut self, learned: Option<&'a LearnedResidual>) -> Self {
        self.learned = learned;
        self
    }

    /// The parameters.
    pub fn params(&self) -> &KinematicParams {
        self.params
    }

    /// The prepared chain.
    pub fn chain(&self) -> &Chain {
        &self.chain
    }

    /// A workspace for [`Prediction::row`].
    pub fn scratch(&self) -> PredictScratch {
        PredictScratch::new(self.nq)
    }

    /// Row `r` (regressors `regs`, controller joint values `q`): the physical prediction, into `s`.
    #[inline]
    pub fn physical(
        &self,
        regs: &Regressors,
        r: usize,
        q: &[f64],
        s: &mut PredictScratch,
    ) -> RowPrediction {
        physical_row(&self.chain, self.params, regs, r, q, s)
    }

    /// Predicted target position of row `r` (tracker frame, m), learned correction included; the
    /// predicted orientation is left in `s.chain.r_tracker_target`.
    #[inline]
    pub fn row(
        &self,
        regs: &Regressors,
        r: usize,
        q: &[f64],
        s: &mut PredictScratch,
    ) -> Vector3<f64> {
        let p = self.physical(regs, r, q, s).p_tracker;
        match self.learned {
            Some(l) => p + l.predict(q),
            None => p,
        }
    }

    /// Jacobian of the chain's target position at the row last evaluated into `s` with respect to a
    /// step of every kinematic parameter of `layout` (3 × [`ParamLayout::len`], row-major; m per unit).
    /// It differentiates the chain at the effective joint values `θ`: for a kinematic model (no
    /// extensions, as in the sweep) that is the whole prediction's Jacobian; extension and learned
    /// terms are not differentiated.
    pub fn position_jacobian(&self, s: &PredictScratch, layout: &ParamLayout, out: &mut [f64]) {
        self.chain.position_jacobian(&s.chain, layout, out);
    }

    /// Predicted positions (tracker frame, m) and, when `orientation` is given, orientations of every
    /// row of `q` (row-major, `nq` per row) with regressors `regs`; parallel over chunks of rows.
    pub fn positions(
        &self,
        q: &[f64],
        regs: &Regressors,
        position: &mut [Vector3<f64>],
        orientation: Option<&mut [Matrix3<f64>]>,
    ) {
        self.evaluate(q, regs, position, orientation, true);
    }

    /// [`Prediction::positions`], with or without the learned correction.
    fn evaluate(
        &self,
        q: &[f64],
        regs: &Regressors,
        position: &mut [Vector3<f64>],
        orientation: Option<&mut [Matrix3<f64>]>,
        learned: bool,
    ) {
        let n = self.nq;
        assert_eq!(q.len(), position.len() * n, "joint values per row");
        let rows = position.len();
        let work =
            |start: usize, pos: &mut [Vector3<f64>], mut rot: Option<&mut [Matrix3<f64>]>| {
                let mut s = self.scratch();
                for (k, p) in pos.iter_mut().enumerate() {
                    let r = start + k;
                    let qr = &q[r * n..(r + 1) * n];
                    *p = if learned {
                        self.row(regs, r, qr, &mut s)
                    } else {
                        self.physical(regs, r, qr, &mut s).p_tracker
                    };
                    if let Some(o) = rot.as_deref_mut() {
                        o[k] = s.chain.r_tracker_target;
                    }
                }
            };
        if rows <= CHUNK_ROWS {
            work(0, position, orientation);
            return;
        }
        match orientation {
            Some(o) => position
                .par_chunks_mut(CHUNK_ROWS)
                .zip(o.par_chunks_mut(CHUNK_ROWS))
                .enumerate()
                .for_each(|(c, (pos, rot))| work(c * CHUNK_ROWS, pos, Some(rot))),
            None => position
                .par_chunks_mut(CHUNK_ROWS)
                .enumerate()
                .for_each(|(c, pos)| work(c * CHUNK_ROWS, pos, None)),
        }
    }

    /// Position errors `predicted − measured` (tracker frame, m), one per row of `obs` (its regressors
    /// [`Observations::ext`]): the physical error, plus the learned correction when there is one.
    pub fn errors(&self, obs: &Observations) -> Vec<Vector3<f64>> {
        let mut out = vec![Vector3::zeros(); obs.len()];
        self.evaluate(&obs.q, &obs.ext, &mut out, None, false);
        for (r, (e, m)) in out.iter_mut().zip(&obs.position).enumerate() {
            *e -= m;
            if let Some(l) = self.learned {
                *e += l.predict(obs.q_row(r));
            }
        }
        out
    }

    /// Orientation error angles `|log(R_predicted R_measuredᵀ)|` (rad), one per row of `obs`, when it
    /// has orientation measurements.
    pub fn orientation_errors(&self, obs: &Observations) -> Option<Vec<f64>> {
        let meas = obs.orientation.as_ref()?;
        let mut pos = vec![Vector3::zeros(); obs.len()];
        let mut rot = vec![Matrix3::identity(); obs.len()];
        self.positions(&obs.q, &obs.ext, &mut pos, Some(&mut rot));
        Some(
            rot.iter()
                .zip(meas)
                .map(|(r, m)| log_rotation(&(r * m.transpose())).norm())
                .collect(),
        )
    }

    /// `∂p_tracker/∂qⱼ` of the kinematic chain at the controller's joint values (tracker frame; m/rad,
    /// m/m for prismatic joints) for every row of `q` (row-major, `nq` per row) and every joint:
    /// `out[r · nq + j]`. Extensions and the learned correction are not applied (the lever of each
    /// joint, for projecting residuals onto joint angles).
    pub fn joint_directions(&self, q: &[f64], out: &mut [Vector3<f64>]) {
        let n = self.nq;
        assert_eq!(q.len(), out.len(), "one direction per joint value");
        let work = |start: usize, dst: &mut [Vector3<f64>]| {
            let mut s = ChainScratch::new(n);
            for (k, d) in dst.chunks_mut(n).enumerate() {
                let r = start + k;
                self.chain.forward(&mut s, &q[r * n..(r + 1) * n]);
                for (j, dj) in d.iter_mut().enumerate() {
                    *dj = self.chain.joint_direction(&s, j);
                }
            }
        };
        out.par_chunks_mut(CHUNK_ROWS * n)
            .enumerate()
            .for_each(|(c, dst)| work(c * CHUNK_ROWS, dst));
    }
}

/// Predicted target pose of the kinematic model `params` at `q` (tracker frame: position in m, rotation
/// matrix) and the Jacobian of the prediction with respect to a step of every parameter
/// ([`ParamLayout::len`] columns, physical units): 3 position rows (m per unit), plus, when the model has
/// target orientation, 3 rows of the tracker-frame rotation vector (rad per unit). For prediction
/// uncertainty `J C Jᵀ` with [`crate::calibrate::Calibration::covariance`].
///
/// Errors ([`CalibError::Misuse`]) for a model with extension parameters: their columns need a
/// measured row's torques, directions and temperature, which `q` alone does not give.
pub fn prediction_and_jacobian(
    model: &Model,
    params: &KinematicParams,
    q: &[f64],
) -> Result<(Vector3<f64>, Matrix3<f64>, DMatrix<f64>)> {
    if !params.extension.is_empty() {
        return Err(CalibError::Misuse(format!(
            "prediction_and_jacobian is for the kinematic model; this one has {} extension parameters",
            params.extension.len()
        )));
    }
    let layout = ParamLayout::new(model, params.r_flange_target.is_some());
    let np = layout.len();
    let chain = Chain::new(model, params);
    let mut s = ChainScratch::new(model.nq());
    chain.forward(&mut s, q);
    let rows = if layout.orientation { 6 } else { 3 };
    let mut buf = vec![0.0; rows * np];
    chain.position_jacobian(&s, &layout, &mut buf[..3 * np]);
    if layout.orientation {
        chain.orientation_jacobian(&s, &layout, &mut buf[3 * np..]);
    }
    Ok((
        s.p_tracker,
        s.r_tracker_target,
        DMatrix::from_row_slice(rows, np, &buf),
    ))
}
