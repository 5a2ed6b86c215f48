//! The one prediction path of a calibrated model: the kinematic chain at the extended joint values,
//! the growth of the arm, and the learned residual correction.
//!
//! ```text
//! θ = q + Σₑ xₑ gₑ(row)                    (joint-angle terms of the extensions)
//! φᵢ = Σₑ xₑ gₑ(row) e_about               (bending terms, turning the chain at joint i)
//! p_kin = T_tracker_base · T_base_flange(θ, φ) · p_flange
//! p = t_base + (1 + γ) (p_kin − t_base),  γ = Σₑ xₑ gₑ(row)   (growth terms)
//! p_tracker = p + R_c R_0ᵀ r̂(q)            (learned correction, when the model has one)
//! ```
//!
//! The `learned:adjoint` model is no additive correction: it changes the joints' error twists and zero
//! offsets with the configuration ([`crate::model::learned::adjoint`]), so its rows are evaluated by a chain
//! re-prepared for each row (in a per-thread [`AdjointScratch`]).
//!
//! With several measurement campaigns each row is predicted in its campaign `c`'s tracker frame
//! (`T_tracker_base` of `c`, its target); the learned correction `r̂` lives in the first campaign's
//! tracker frame and is turned into campaign `c`'s by `R_c R_0ᵀ` (`R_c` the rotation of `c`'s
//! `T_tracker_base`), so that it is a property of the robot, not of where a tracker stood.
//!
//! [`Prediction`] holds the chain prepared once per parameter point (immutable) and evaluates rows into a
//! [`PredictScratch`] made once per thread, so batches never allocate per row. The solver
//! ([`crate::fit::problem`]), the statistics, outlier detection, `predict`, the sweep and diagnose all go
//! through it.

use crate::error::{CalibError, Result};
use crate::lie3::{log_rotation, quaternion_from_rotation};
use crate::model::chain::{Chain, ChainScratch};
use crate::model::extensions::{ExtensionSettings, Regressors};
use crate::model::file::CalibratedModel;
use crate::model::jacobian::position_jacobian_row;
use crate::model::learned::LearnedResidual;
use crate::model::learned::adjoint::AdjointModel;
use crate::model::observations::Observations;
use crate::model::params::{KinematicParams, ParamLayout};
pub use crate::model::physical_row::{AdjointScratch, PredictScratch, RowPrediction, physical_row};
use crate::model::uncertainty::{PredictionUncertainty, Prior};
use nalgebra::{DMatrix, Matrix3, Vector3};
use rayon::prelude::*;
use sim::Model;
use sim::measurement_table::MeasurementTable;

/// Rows per parallel work item of the batch evaluations.
const CHUNK_ROWS: usize = 2048;

/// A calibrated model ready to predict: parameters, prepared chain, optional learned correction.
#[derive(Clone, Debug)]
pub struct Prediction<'a> {
    params: &'a KinematicParams,
    chain: Chain,
    learned: Option<&'a LearnedResidual>,
    nq: usize,
    /// `R_c R_0ᵀ` per campaign: the learned correction's frame (the first campaign's tracker frame)
    /// to campaign `c`'s.
    learned_frame: Vec<Matrix3<f64>>,
}

impl<'a> Prediction<'a> {
    /// The physical model `params` of `model` (no learned correction).
    pub fn new(model: &Model, params: &'a KinematicParams) -> Self {
        let r0 = params.t_tracker_base.rotation.matrix().transpose();
        Prediction {
            params,
            chain: Chain::new(model, params),
            learned: None,
            nq: model.nq(),
            learned_frame: (0..params.n_campaigns())
                .map(|c| params.t_tracker_base_of(c).rotation.matrix() * r0)
                .collect(),
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

    /// The learned correction, if any.
    pub fn learned(&self) -> Option<&'a LearnedResidual> {
        self.learned
    }

    /// `R_c R_0ᵀ` of campaign `c`: the learned correction's frame (the first campaign's tracker frame)
    /// to campaign `c`'s.
    pub fn learned_frame(&self, c: usize) -> &Matrix3<f64> {
        &self.learned_frame[c]
    }

    /// The prepared chain.
    pub fn chain(&self) -> &Chain {
        &self.chain
    }

    /// A workspace for [`Prediction::row`].
    pub fn scratch(&self) -> PredictScratch {
        let mut s = PredictScratch::new(self.nq);
        if let Some(a) = self.learned.and_then(|l| l.adjoint()) {
            s.adjoint = Some(AdjointScratch::new(
                &self.chain,
                self.params,
                a.n_features(),
            ));
        }
        s
    }

    /// Row `r` of an adjoint model `a`: the chain at the row's error twists and zero offsets.
    fn adjoint_row(
        &self,
        a: &AdjointModel,
        regs: &Regressors,
        r: usize,
        q: &[f64],
        campaign: usize,
        s: &mut PredictScratch,
    ) -> Vector3<f64> {
        let mut ad = s
            .adjoint
            .take()
            .unwrap_or_else(|| AdjointScratch::new(&self.chain, self.params, a.n_features()));
        a.prepare(
            &mut ad,
            self.params,
            q,
            self.learned.map_or(1.0, |l| l.weight(q)),
        );
        let p = physical_row(&ad.chain, &ad.params, regs, r, q, campaign, s).p_tracker;
        s.adjoint = Some(ad);
        p
    }

    /// Row `r` (regressors `regs`, controller joint values `q`): the physical prediction in the first
    /// campaign's tracker frame, into `s`.
    #[inline]
    pub fn physical(
        &self,
        regs: &Regressors,
        r: usize,
        q: &[f64],
        s: &mut PredictScratch,
    ) -> RowPrediction {
        physical_row(&self.chain, self.params, regs, r, q, 0, s)
    }

    /// [`Prediction::physical`] in campaign `campaign`'s (index) tracker frame.
    #[inline]
    pub fn physical_in(
        &self,
        regs: &Regressors,
        r: usize,
        q: &[f64],
        campaign: usize,
        s: &mut PredictScratch,
    ) -> RowPrediction {
        physical_row(&self.chain, self.params, regs, r, q, campaign, s)
    }

    /// Predicted target position of row `r` (first campaign's tracker frame, m), learned correction
    /// included; the predicted orientation is left in `s.chain.r_tracker_target`.
    #[inline]
    pub fn row(
        &self,
        regs: &Regressors,
        r: usize,
        q: &[f64],
        s: &mut PredictScratch,
    ) -> Vector3<f64> {
        self.row_in(regs, r, q, 0, s)
    }

    /// [`Prediction::row`] in campaign `campaign`'s (index) tracker frame.
    #[inline]
    pub fn row_in(
        &self,
        regs: &Regressors,
        r: usize,
        q: &[f64],
        campaign: usize,
        s: &mut PredictScratch,
    ) -> Vector3<f64> {
        if let Some(a) = self.learned.and_then(|l| l.adjoint()) {
            return self.adjoint_row(a, regs, r, q, campaign, s);
        }
        let p = self.physical_in(regs, r, q, campaign, s).p_tracker;
        match self.learned {
            Some(l) => p + self.learned_in(l, q, campaign),
            None => p,
        }
    }

    /// The learned correction at `q` in campaign `campaign`'s tracker frame (m).
    #[inline]
    pub(crate) fn learned_in(
        &self,
        l: &LearnedResidual,
        q: &[f64],
        campaign: usize,
    ) -> Vector3<f64> {
        if campaign == 0 {
            l.predict(q)
        } else {
            self.learned_frame[campaign] * l.predict(q)
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
    /// Every row is in the first campaign's tracker frame.
    pub fn positions(
        &self,
        q: &[f64],
        regs: &Regressors,
        position: &mut [Vector3<f64>],
        orientation: Option<&mut [Matrix3<f64>]>,
    ) {
        self.evaluate(q, &[], regs, position, orientation, true);
    }

    /// [`Prediction::positions`] with each row in its campaign's tracker frame: `campaign` holds
    /// one campaign index per row (empty: all in the first).
    pub fn positions_in(
        &self,
        q: &[f64],
        campaign: &[usize],
        regs: &Regressors,
        position: &mut [Vector3<f64>],
        orientation: Option<&mut [Matrix3<f64>]>,
    ) {
        self.evaluate(q, campaign, regs, position, orientation, true);
    }

    /// [`Prediction::positions_in`], with or without the learned correction.
    fn evaluate(
        &self,
        q: &[f64],
        campaign: &[usize],
        regs: &Regressors,
        position: &mut [Vector3<f64>],
        orientation: Option<&mut [Matrix3<f64>]>,
        learned: bool,
    ) {
        let n = self.nq;
        assert_eq!(q.len(), position.len() * n, "joint values per row");
        assert!(
            campaign.is_empty() || campaign.len() == position.len(),
            "one campaign per row"
        );
        let rows = position.len();
        let work =
            |start: usize, pos: &mut [Vector3<f64>], mut rot: Option<&mut [Matrix3<f64>]>| {
                let mut s = self.scratch();
                for (k, p) in pos.iter_mut().enumerate() {
                    let r = start + k;
                    let qr = &q[r * n..(r + 1) * n];
                    let c = campaign.get(r).copied().unwrap_or(0);
                    *p = if learned {
                        self.row_in(regs, r, qr, c, &mut s)
                    } else {
                        self.physical_in(regs, r, qr, c, &mut s).p_tracker
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

    /// The campaign index of every row of `obs` (empty when all are in the first campaign).
    ///
    /// # Panics
    /// If a row's campaign is not one of the parameters' (callers check with
    /// [`Observations::campaign_indices_or_error`] first).
    pub fn campaigns_of(&self, obs: &Observations) -> Vec<usize> {
        if obs.campaign.is_none() && self.params.default_campaign == 0 {
            return Vec::new();
        }
        obs.campaign_indices(self.params)
            .unwrap_or_else(|(r, id)| panic!("row {r}: campaign {id} is not registered"))
    }

    /// Position errors `predicted − measured` (tracker frame of each row's campaign, m), one per row
    /// of `obs` (its regressors [`Observations::ext`]): the physical error, plus the learned correction
    /// when there is one.
    pub fn errors(&self, obs: &Observations) -> Vec<Vector3<f64>> {
        let campaign = self.campaigns_of(obs);
        let mut out = vec![Vector3::zeros(); obs.len()];
        if self.learned.is_some_and(|l| l.adjoint().is_some()) {
            self.evaluate(&obs.q, &campaign, &obs.ext, &mut out, None, true);
            for (e, m) in out.iter_mut().zip(&obs.position) {
                *e -= m;
            }
            return out;
        }
        self.evaluate(&obs.q, &campaign, &obs.ext, &mut out, None, false);
        for (r, (e, m)) in out.iter_mut().zip(&obs.position).enumerate() {
            *e -= m;
            if let Some(l) = self.learned {
                let c = campaign.get(r).copied().unwrap_or(0);
                *e += self.learned_in(l, obs.q_row(r), c);
            }
        }
        out
    }

    /// [`Prediction::errors`] turned into the first campaign's tracker frame (`R_0 R_cᵀ` for a row
    /// of campaign `c`; the same as `errors` with one campaign): errors of several campaigns in one
    /// frame, the robot's, for comparing them with joint directions or a learned correction.
    pub fn reference_errors(&self, obs: &Observations) -> Vec<Vector3<f64>> {
        let mut e = self.errors(obs);
        let campaign = self.campaigns_of(obs);
        if !campaign.is_empty() {
            for (v, &c) in e.iter_mut().zip(&campaign) {
                if c != 0 {
                    *v = self.learned_frame[c].transpose() * *v;
                }
            }
        }
        e
    }

    /// Orientation error angles `|log(R_predicted R_measuredᵀ)|` (rad), one per row of `obs`, when it
    /// has orientation measurements.
    pub fn orientation_errors(&self, obs: &Observations) -> Option<Vec<f64>> {
        let meas = obs.orientation.as_ref()?;
        let campaign = self.campaigns_of(obs);
        let mut pos = vec![Vector3::zeros(); obs.len()];
        let mut rot = vec![Matrix3::identity(); obs.len()];
        self.positions_in(&obs.q, &campaign, &obs.ext, &mut pos, Some(&mut rot));
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
        self.joint_directions_in(q, &[], out);
    }

    /// [`Prediction::joint_directions`] with each row in its campaign's tracker frame (`campaign`:
    /// one index per row, or empty for all in the first).
    pub fn joint_directions_in(&self, q: &[f64], campaign: &[usize], out: &mut [Vector3<f64>]) {
        let n = self.nq;
        assert_eq!(q.len(), out.len(), "one direction per joint value");
        let work = |start: usize, dst: &mut [Vector3<f64>]| {
            let mut s = ChainScratch::new(n);
            for (k, d) in dst.chunks_mut(n).enumerate() {
                let r = start + k;
                let c = campaign.get(r).copied().unwrap_or(0);
                self.chain.forward_in(&mut s, &q[r * n..(r + 1) * n], c);
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
/// uncertainty `J C Jᵀ` with [`crate::fit::Calibration::covariance`].
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
    let layout = ParamLayout::for_params(model, params, Vec::new());
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

/// Evaluates a calibrated model.
#[derive(Clone, Debug)]
pub struct Predictor {
    /// The robot.
    pub model: Model,
    /// The parameters.
    pub params: KinematicParams,
    /// Settings of the model extensions, if any.
    pub extensions: Option<ExtensionSettings>,
    /// Learned residual correction, if any.
    pub learned: Option<LearnedResidual>,
    /// The prediction's standard deviation from the parameter covariance (with a prior on the
    /// undetermined directions), when the model file has a covariance.
    pub uncertainty: Option<PredictionUncertainty>,
    /// The model's held-out RMS error (m), when it was validated: a row whose `sigma_m` exceeds
    /// [`SIGMA_OUTSIDE`] times it is outside the model's support.
    pub held_out_rms_m: Option<f64>,
    /// The 95th percentile of `sigma_m` over the calibration rows (m), when the model file has it: a
    /// row whose `sigma_m` exceeds [`SIGMA_BEYOND_CALIBRATION`] times it (and [`SIGMA_MATTERS`] times
    /// the held-out error) is outside the support.
    pub calibration_sigma_m: Option<f64>,
    chain: Chain,
    scratch: ChainScratch,
}

/// A row whose predicted standard deviation exceeds this many times the model's held-out RMS error
/// is marked `outside_support`: the calibration data did not determine its prediction.
pub const SIGMA_OUTSIDE: f64 = 3.0;

/// A row whose predicted standard deviation exceeds this many times the 95th percentile of the
/// calibration rows', and [`SIGMA_MATTERS`] times the held-out RMS error, is marked
/// `outside_support`: its prediction rests on parameter combinations the calibration poses
/// determined far less well than at any pose its validation tested, by enough to change its error.
/// (Measured on the trap of `tests/cli_transfer.rs`: at free orientations after a calibration at
/// one, every row's `sigma_m` is 4 to 6 times the calibration's and 1.5 to 3 times the held-out
/// error, and its error 2 to 8 times the promise, while [`SIGMA_OUTSIDE`] let a tenth of those rows
/// through. On the UR10, series B's `sigma_m` is 6 to 9 times series A's, but a quarter of A's
/// held-out error, and B's error is what A promised: those rows stay inside.)
pub const SIGMA_BEYOND_CALIBRATION: f64 = 3.0;

/// The `sigma_m`, in units of the held-out RMS error, at which the prediction's own uncertainty,
/// added in quadrature, raises the error by 20 %: `√(1.2² − 1)`.
pub const SIGMA_MATTERS: f64 = 0.663_324_958_071_079_9;

/// Predictions for the rows of a table.
#[derive(Clone, Debug, PartialEq)]
pub struct Predictions {
    /// Pose id per row.
    pub pose: Vec<i64>,
    /// Predicted target position per row (tracker frame, m).
    pub position: Vec<[f64; 3]>,
    /// Predicted target orientation per row (unit quaternion `[qw, qx, qy, qz]`, tracker frame), when the
    /// model has orientation.
    pub orientation: Option<Vec<[f64; 4]>>,
    /// Predicted standard deviation of each row's position (m; [`crate::model::uncertainty`]), when
    /// the model has a covariance.
    pub sigma_m: Option<Vec<f64>>,
    /// Whether each row is outside the model's support: beyond the configurations its learned
    /// correction was fitted on (the correction is not applied in full there), or with a `sigma_m`
    /// above [`SIGMA_OUTSIDE`] times the held-out RMS error, or above both [`SIGMA_MATTERS`] times
    /// it and [`SIGMA_BEYOND_CALIBRATION`] times the calibration rows' (95th percentile).
    pub outside_support: Vec<bool>,
}

impl Predictions {
    /// CSV text `pose,x,y,z[,qw,qx,qy,qz][,sigma_m],outside_support` (the flag as `0` or `1`):
    /// [`Predictions::csv_header`] then [`Predictions::csv_rows`].
    pub fn to_csv(&self) -> String {
        let mut s = self.csv_header();
        s.push_str(&self.csv_rows());
        s
    }

    /// The CSV header line of [`Predictions::to_csv`], with its line end.
    pub fn csv_header(&self) -> String {
        let mut header: Vec<String> = ["pose", "x", "y", "z"].map(String::from).to_vec();
        if self.orientation.is_some() {
            header.extend(["qw", "qx", "qy", "qz"].map(String::from));
        }
        if self.sigma_m.is_some() {
            header.push("sigma_m".into());
        }
        header.push("outside_support".into());
        let mut s = header.join(",");
        s.push('\n');
        s
    }

    /// The CSV data lines of [`Predictions::to_csv`] (no header): predictions made piece by piece
    /// append to one file.
    pub fn csv_rows(&self) -> String {
        let mut s = String::with_capacity(self.pose.len() * 96);
        for r in 0..self.pose.len() {
            s.push_str(&self.pose[r].to_string());
            let mut push = |v: f64| {
                s.push(',');
                s.push_str(&format!("{v:?}"));
            };
            self.position[r].iter().for_each(|&v| push(v));
            if let Some(o) = &self.orientation {
                o[r].iter().for_each(|&v| push(v));
            }
            if let Some(sd) = &self.sigma_m {
                push(sd[r]);
            }
            s.push_str(if self.outside_support[r] {
                ",1\n"
            } else {
                ",0\n"
            });
        }
        s
    }

    /// Rows outside the support.
    pub fn n_outside_support(&self) -> usize {
        self.outside_support.iter().filter(|&&o| o).count()
    }
}

impl Predictor {
    /// A predictor for `model` with `params`.
    pub fn new(model: Model, params: KinematicParams) -> Self {
        let chain = Chain::new(&model, &params);
        let scratch = ChainScratch::new(model.nq());
        Predictor {
            model,
            params,
            extensions: None,
            learned: None,
            uncertainty: None,
            held_out_rms_m: None,
            calibration_sigma_m: None,
            chain,
            scratch,
        }
    }

    /// The layout of the predictor's parameters (its extensions included).
    fn layout(&self) -> ParamLayout {
        let ext = self
            .extensions
            .as_ref()
            .map(|s| s.params(&self.model))
            .unwrap_or_default();
        ParamLayout::for_params(&self.model, &self.params, ext)
    }

    /// Sets the prediction uncertainty from `m`'s covariance with `prior` on the directions the
    /// calibration did not determine; none when the file has no covariance or its parameter names
    /// are not the model's.
    pub fn set_prior(&mut self, m: &CalibratedModel, prior: &Prior) {
        let layout = self.layout();
        self.uncertainty = m.covariance.as_ref().and_then(|c| {
            let names_agree = c.parameters.len() == layout.len()
                && c.parameters
                    .iter()
                    .enumerate()
                    .all(|(k, n)| *n == layout.name(k));
            if !names_agree {
                return None;
            }
            let p = layout.len();
            let matrix = DMatrix::from_fn(p, p, |i, j| c.matrix[i][j]);
            PredictionUncertainty::new(&layout, &matrix, prior)
        });
    }

    /// A predictor for a model file.
    pub fn from_file(m: &CalibratedModel) -> Result<Self> {
        let mut p = Predictor::new(m.robot_model()?, m.params());
        p.extensions = m.extensions.as_ref().map(|e| e.settings.clone());
        p.learned = m.learned.clone();
        p.held_out_rms_m = m.fit.as_ref().and_then(|f| f.held_out_rms_m);
        p.calibration_sigma_m = m.fit.as_ref().and_then(|f| f.calibration_sigma_m);
        if let Some(s) = &p.extensions
            && s.params(&p.model).len() != p.params.extension.len()
        {
            return Err(CalibError::ModelFile {
                file: "model".into(),
                message: format!(
                    "key 'extensions' has {} values; its causes need {}",
                    p.params.extension.len(),
                    s.params(&p.model).len()
                ),
            });
        }
        p.set_prior(m, &Prior::default());
        Ok(p)
    }

    /// Target position (tracker frame, m) and orientation (tracker frame) at the controller's `q`, for the
    /// kinematic part of the model only (extensions need a row's payload, directions and temperature:
    /// use [`Predictor::predict_table`]), learned correction included.
    ///
    /// # Panics
    /// If `q` has the wrong length (check tables with [`Predictor::predict_table`]).
    pub fn predict(&mut self, q: &[f64]) -> (Vector3<f64>, Matrix3<f64>) {
        let c = self.params.default_campaign;
        if self.learned.as_ref().is_some_and(|l| l.adjoint().is_some()) {
            let p = Prediction::new(&self.model, &self.params).with_learned(self.learned.as_ref());
            let mut s = p.scratch();
            let pos = p.row_in(&Regressors::none(), 0, q, c, &mut s);
            return (pos, s.chain.r_tracker_target);
        }
        self.chain.forward_in(&mut self.scratch, q, c);
        // The learned correction lives in the first campaign's tracker frame.
        let frame = self.params.t_tracker_base_of(c).rotation.matrix()
            * self.params.t_tracker_base.rotation.matrix().transpose();
        let p = self.scratch.p_tracker
            + frame
                * self
                    .learned
                    .as_ref()
                    .map_or(Vector3::zeros(), |l| l.predict(q));
        (p, self.scratch.r_tracker_target)
    }

    /// The campaign index of every row of `table` (each row's `campaign`, or the model's default
    /// campaign without the column); an id the model does not register is a one-line error naming
    /// `file` and the row.
    pub fn campaigns_of(&self, table: &MeasurementTable, file: &str) -> Result<Vec<usize>> {
        let p = &self.params;
        match &table.campaign {
            None => Ok(vec![p.default_campaign; table.len()]),
            Some(ids) => ids
                .iter()
                .enumerate()
                .map(|(r, &id)| {
                    p.campaign_index(id).ok_or_else(|| CalibError::BadValue {
                        context: format!("{file}: row {}", r + 1),
                        field: "campaign".into(),
                        value: id.to_string(),
                        problem: format!(
                            "the model knows campaigns {}: this campaign's tracker registration is \
                             unknown (register it with `robocal register`)",
                            p.campaign_ids
                                .iter()
                                .map(|c| c.to_string())
                                .collect::<Vec<_>>()
                                .join(", ")
                        ),
                    })
                })
                .collect(),
        }
    }

    /// Predictions for every row of `table` (its x, y, z are ignored); `file` names it in errors.
    /// A table of a robot with coupled joints may give the driven joints only
    /// ([`sim::measurement_table::couple`]).
    pub fn predict_table(&mut self, table: &MeasurementTable, file: &str) -> Result<Predictions> {
        let table =
            &*sim::measurement_table::whole_chain(table, &self.model, std::path::Path::new(file))?;
        let (campaign, regs) = self.inputs(table, file)?;
        let orientation = self.params.r_flange_target.is_some();
        let mut out = Predictions {
            pose: table.pose.clone(),
            position: Vec::with_capacity(table.len()),
            orientation: orientation.then(|| Vec::with_capacity(table.len())),
            sigma_m: None,
            outside_support: Vec::new(),
        };
        let mut position = vec![Vector3::zeros(); table.len()];
        let mut rotation = orientation.then(|| vec![Matrix3::identity(); table.len()]);
        Prediction::new(&self.model, &self.params)
            .with_learned(self.learned.as_ref())
            .positions_in(
                &table.q,
                &campaign,
                &regs,
                &mut position,
                rotation.as_deref_mut(),
            );
        out.position = position.iter().map(|p| (*p).into()).collect();
        out.orientation = rotation.map(|r| r.iter().map(quaternion_from_rotation).collect());
        out.sigma_m = self.sigmas(table, &regs, &campaign);
        out.outside_support = (0..table.len())
            .into_par_iter()
            .map(|r| {
                let beyond_learned = self
                    .learned
                    .as_ref()
                    .is_some_and(|l| l.outside_support(table.q_row(r)));
                let beyond_sigma = match (&out.sigma_m, self.held_out_rms_m) {
                    (Some(sd), Some(h)) => {
                        sd[r] > SIGMA_OUTSIDE * h
                            || (sd[r] > SIGMA_MATTERS * h
                                && self
                                    .calibration_sigma_m
                                    .is_some_and(|c| sd[r] > SIGMA_BEYOND_CALIBRATION * c))
                    }
                    _ => false,
                };
                beyond_learned || beyond_sigma
            })
            .collect();
        Ok(out)
    }

    /// What every row of `table` needs besides its joint values: its campaign's index and the
    /// regressors of the model's extensions. Errors for a table of another robot or without the
    /// columns the extensions read; `file` names it.
    fn inputs(&self, table: &MeasurementTable, file: &str) -> Result<(Vec<usize>, Regressors)> {
        if table.n_joints != self.model.nq() {
            return Err(CalibError::BadValue {
                context: file.to_string(),
                field: "q1..qN".into(),
                value: format!("{} joint columns", table.n_joints),
                problem: format!(
                    "the model's robot '{}' has {} joints",
                    self.model.name(),
                    self.model.nq()
                ),
            });
        }
        let campaign = self.campaigns_of(table, file)?;
        let rows: Vec<usize> = (0..table.len()).collect();
        let regs = match &self.extensions {
            Some(s) => {
                s.check_table(table, file)?;
                Regressors::build(&self.model, s, table, &rows, file, Some(&self.params))?
            }
            None => Regressors::none(),
        };
        Ok((campaign, regs))
    }

    /// Every row's predicted standard deviation `sigma_m` (m) alone, as [`Predictor::predict_table`]
    /// gives it, without the positions; `None` when the predictor has no uncertainty.
    pub fn sigma_table(&self, table: &MeasurementTable, file: &str) -> Result<Option<Vec<f64>>> {
        if self.uncertainty.is_none() {
            return Ok(None);
        }
        let table =
            &*sim::measurement_table::whole_chain(table, &self.model, std::path::Path::new(file))?;
        let (campaign, regs) = self.inputs(table, file)?;
        Ok(self.sigmas(table, &regs, &campaign))
    }

    /// Every row's predicted standard deviation (m), when the predictor has an uncertainty. The
    /// Jacobian is the physical model's ([`crate::model::jacobian::position_jacobian_row`]); a
    /// learned correction's own uncertainty is not in it.
    fn sigmas(
        &self,
        table: &MeasurementTable,
        regs: &Regressors,
        campaign: &[usize],
    ) -> Option<Vec<f64>> {
        let u = self.uncertainty.as_ref()?;
        let layout = self.layout();
        let np = layout.len();
        let prediction = Prediction::new(&self.model, &self.params);
        let chain = prediction.chain();
        let mut out = vec![0.0; table.len()];
        out.par_chunks_mut(CHUNK_ROWS)
            .enumerate()
            .for_each(|(c, dst)| {
                let mut s = PredictScratch::new(self.model.nq());
                let mut jac = vec![0.0; 3 * np];
                let mut reference = vec![0.0; 3 * np];
                for (k, sd) in dst.iter_mut().enumerate() {
                    let r = c * CHUNK_ROWS + k;
                    let cr = campaign.get(r).copied().unwrap_or(0);
                    let q = table.q_row(r);
                    let coef = if regs.is_empty() {
                        &[][..]
                    } else {
                        regs.row(r)
                    };
                    let pred = physical_row(chain, &self.params, regs, r, q, cr, &mut s);
                    position_jacobian_row(chain, &layout, &s, &pred, cr, coef, &mut jac);
                    if cr == 0 {
                        reference.copy_from_slice(&jac);
                    } else {
                        let pred = physical_row(chain, &self.params, regs, r, q, 0, &mut s);
                        position_jacobian_row(chain, &layout, &s, &pred, 0, coef, &mut reference);
                    }
                    *sd = u.sigma(&jac, &reference);
                }
            });
        Some(out)
    }
}
