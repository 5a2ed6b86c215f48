//! Compensation: the joints to command so that the calibrated robot puts the target where it should
//! be. The inverse of the one prediction path ([`crate::model::predict`]), every part of it: the
//! geometry, each cause at the row's payload, temperature or time and approach direction, and the
//! learned correction.
//!
//! # The solve
//! For a target `p*` (tracker frame of the row's campaign, m) and, with a model that has orientation
//! and a target that asks for it, `R*` (tracker frame), find the commanded joints `q` nearest the
//! nominal program's `q₀` with
//!
//! ```text
//! p(q) = p*,   log(R* R(q)ᵀ) = 0          p, R: the calibrated model's prediction (predict's)
//! ```
//!
//! by damped least squares from `q₀`: `Δq = Jᵀ (J Jᵀ + λ² I)⁻¹ e`, the minimum-norm step, so that on
//! a redundant arm (the 7-joint iiwa 7 with a position target: four joints too many) every step moves
//! the joints as little as the target allows and the answer is the solution nearest the seed along
//! the path. `λ` = [`DAMPING_M`] is far below any well-conditioned `J Jᵀ` (0.01–1 m²): it only keeps
//! a singular configuration from giving an infinite step; steps are capped at [`MAX_STEP_RAD`].
//!
//! # The Jacobian, analytic
//! `J = J_θ · ∂θ/∂q + R_c R_0ᵀ ∂r̂/∂q`:
//! - `J_θ`: the chain's joint columns at the effective joint values `θ` (the geometry, with the bends
//!   of link deflection in the frames), scaled by `1 + γ` (thermal growth);
//!   rotation rows: the joint axes;
//! - `∂θ/∂q = (I − ∂Δθ/∂θ)⁻¹ (I + ∂Δθ/∂q)` from each cause's own file
//!   ([`crate::model::extensions::CauseModel::angle_jacobian`]): transmission error (harmonics of the
//!   commanded angle, on the diagonal), joint compliance (`−C ∂τ/∂θ`, the gravity torques' own
//!   Jacobian, [`crate::model::extensions::joint_compliance::torque_jacobian`]); backlash and thermal
//!   drift do not depend on the joints (exact zero);
//! - `∂r̂/∂q`: the kernel and polynomial corrections in closed form
//!   ([`crate::model::learned::LearnedResidual::jacobian`]).
//!
//! Left out (the solve still converges to the model's exact inverse, since every step evaluates the
//! whole prediction; it converges linearly where a derivative is missing, at the rate of the missing
//! term, below 10⁻³): the change of link deflection's bend with the joints (`∂φ/∂q`, a gravity
//! moment's derivative times a bending compliance of ~10⁻⁶ rad/(N m)), and the change of a
//! `learned:adjoint` model's error twists with the joints (its chain is differentiated at the row's
//! parameters).
//!
//! # Failures
//! A row whose solve does not bring the prediction within [`CONVERGED_M`] (and [`CONVERGED_RAD`]) of
//! the target is out of reach; a solution beyond a joint's URDF limits is refused. Both are per-row
//! outcomes ([`Failure`]), the row flagged `converged = 0` and named, never a silent best effort.

use crate::error::{CalibError, Result};
use crate::lie3::log_rotation;
use crate::model::extensions::{Regressors, RowContext, RowRegressors, apply};
use crate::model::physical_row::PredictScratch;
use crate::model::predict::{Prediction, Predictor};
use nalgebra::{DMatrix, DVector, Matrix3, Vector3};
use rayon::prelude::*;
use sim::measurement_table::MeasurementTable;

/// Largest number of solver steps per target.
pub const MAX_ITERATIONS: usize = 100;
/// A target is reached when the predicted position is within this distance (m).
pub const CONVERGED_M: f64 = 1e-9;
/// A target orientation is reached within this angle (rad).
pub const CONVERGED_RAD: f64 = 1e-9;
/// The solve stops once the position error is below this (m) (and the angle below the same in rad).
const STOP: f64 = 1e-13;
/// Damping `λ` of the least-squares step (m).
pub const DAMPING_M: f64 = 1e-7;
/// The damping `λ²` (m²) beyond which a target that no step brings closer is given up: steps of
/// 10⁻⁴ of the gradient's.
const MAX_DAMPING2: f64 = 1e4;
/// Largest joint step per iteration (rad or m, Euclidean norm over the joints).
pub const MAX_STEP_RAD: f64 = 0.3;
/// Rows per parallel work item.
const CHUNK_ROWS: usize = 32;

/// Whether the learned correction applies at row `q`: outside the support of the configurations it
/// was fitted on the correction is off (and a compensation there inverts the physical model only).
pub fn outside_support(predictor: &Predictor, q: &[f64]) -> bool {
    predictor
        .learned
        .as_ref()
        .is_some_and(|l| l.outside_support(q))
}

/// What a target row asks for.
#[derive(Clone, Debug)]
pub struct Target<'a> {
    /// Where the target should be (tracker frame of `campaign`, m).
    pub p_tracker: Vector3<f64>,
    /// The target orientation asked for (tracker frame of `campaign`), if any.
    pub r_tracker: Option<Matrix3<f64>>,
    /// The nominal program's joints: the seed, and what the answer stays nearest to (rad or m).
    pub seed_q: &'a [f64],
    /// The row's payload, approach directions, temperature and time.
    pub context: RowContext<'a>,
    /// Campaign index (the model's registration the target is in).
    pub campaign: usize,
}

/// Why a row has no compensated joints.
#[derive(Clone, Debug, PartialEq)]
pub enum Failure {
    /// The solve stopped short of the target: out of the calibrated robot's reach (or at a singular
    /// configuration).
    OutOfReach {
        /// The distance left (m).
        residual_m: f64,
        /// The angle left (rad), with an orientation target.
        residual_rad: Option<f64>,
    },
    /// The solution lies beyond a joint's URDF limits.
    JointLimit {
        /// 0-based joint.
        joint: usize,
        /// The joint value (rad or m).
        value: f64,
        /// Lower limit (rad or m).
        lower: f64,
        /// Upper limit (rad or m).
        upper: f64,
    },
}

impl std::fmt::Display for Failure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Failure::OutOfReach {
                residual_m,
                residual_rad,
            } => {
                write!(
                    f,
                    "out of reach: the nearest solution found misses the target by {residual_m:.3e} m"
                )?;
                if let Some(r) = residual_rad {
                    write!(f, " and {r:.3e} rad")?;
                }
                Ok(())
            }
            Failure::JointLimit {
                joint,
                value,
                lower,
                upper,
            } => write!(
                f,
                "beyond the joint limits: q{} = {value:.6} is outside [{lower}, {upper}]",
                joint + 1
            ),
        }
    }
}

/// One row's answer.
#[derive(Clone, Debug, PartialEq)]
pub struct Solution {
    /// The joints to command (rad or m).
    pub q: Vec<f64>,
    /// The miss the model still predicts at `q` (m).
    pub residual_m: f64,
    /// The orientation miss the model still predicts (rad), with an orientation target.
    pub residual_rad: Option<f64>,
    /// Solver steps taken.
    pub iterations: usize,
    /// Why the row has no answer, if it has none.
    pub failure: Option<Failure>,
}

impl Solution {
    /// Whether the target is reached within the joint limits.
    pub fn converged(&self) -> bool {
        self.failure.is_none()
    }
}

/// The calibrated model prepared for compensation: immutable; solves write into a
/// [`CompensateScratch`] made once per thread.
#[derive(Debug)]
pub struct Compensator<'a> {
    predictor: &'a Predictor,
    prediction: Prediction<'a>,
    nq: usize,
}

/// Per-thread workspace of a [`Compensator`].
#[derive(Debug)]
pub struct CompensateScratch<'a> {
    regs: Option<RowRegressors<'a>>,
    none: Regressors,
    ps: PredictScratch,
    theta: Vec<f64>,
    dtheta_dq: Vec<f64>,
    work: Vec<f64>,
    learned: Vec<Vector3<f64>>,
    /// Position (rows 0–2) and rotation (3–5) derivatives with respect to `θ`, per joint.
    j_theta: Vec<[f64; 6]>,
    /// The growth factor `γ` of the last evaluation.
    growth: f64,
}

impl<'a> Compensator<'a> {
    /// A compensator for `predictor`'s model.
    pub fn new(predictor: &'a Predictor) -> Self {
        Compensator {
            predictor,
            prediction: Prediction::new(&predictor.model, &predictor.params)
                .with_learned(predictor.learned.as_ref()),
            nq: predictor.model.nq(),
        }
    }

    /// A workspace for [`Compensator::solve`].
    pub fn scratch(&self) -> CompensateScratch<'a> {
        let n = self.nq;
        CompensateScratch {
            regs: self
                .predictor
                .extensions
                .as_ref()
                .map(|s| RowRegressors::new(&self.predictor.model, s)),
            none: Regressors::none(),
            ps: self.prediction.scratch(),
            theta: vec![0.0; n],
            dtheta_dq: vec![0.0; n * n],
            work: vec![0.0; 3 * n * n],
            learned: vec![Vector3::zeros(); n],
            j_theta: vec![[0.0; 6]; n],
            growth: 0.0,
        }
    }

    /// The model's prediction at `q` for `target`'s context and campaign: the position (tracker
    /// frame, m) and orientation, the prediction's Jacobian with respect to `q` left in `jac` when
    /// asked (`rows × nq`, row-major: 3 position rows, m/rad; 3 rotation rows, rad/rad, with an
    /// orientation target).
    fn evaluate(
        &self,
        q: &[f64],
        target: &Target<'_>,
        s: &mut CompensateScratch<'a>,
        jac: Option<&mut [f64]>,
    ) -> std::result::Result<(Vector3<f64>, Matrix3<f64>), String> {
        let c = target.campaign;
        let x = &self.predictor.params.extension;
        let regs = match s.regs.as_mut() {
            Some(rr) => {
                rr.fill(q, &target.context, x)?;
                rr.regressors()
            }
            None => &s.none,
        };
        let learned = self.prediction.learned();
        let adjoint = learned.is_some_and(|l| l.adjoint().is_some());
        let (p, growth) = if adjoint {
            let p = self.prediction.row_in(regs, 0, q, c, &mut s.ps);
            (p, apply(regs, x, 0, q, &mut s.theta))
        } else {
            let rp = self.prediction.physical_in(regs, 0, q, c, &mut s.ps);
            let p = match learned {
                Some(l) => rp.p_tracker + self.prediction.learned_in(l, q, c),
                None => rp.p_tracker,
            };
            (p, rp.growth)
        };
        let r = s.ps.chain.r_tracker_target;
        s.growth = growth;
        if let Some(jac) = jac {
            self.jacobian(q, target, s, jac);
        }
        Ok((p, r))
    }

    /// The Jacobian of the prediction with respect to `q` (see [`Compensator::evaluate`]) at the row
    /// last evaluated into `s` (at `q`).
    fn jacobian(
        &self,
        q: &[f64],
        target: &Target<'_>,
        s: &mut CompensateScratch<'a>,
        jac: &mut [f64],
    ) {
        let n = self.nq;
        let c = target.campaign;
        let x = &self.predictor.params.extension;
        let growth = s.growth;
        let learned = self.prediction.learned();
        let adjoint = learned.is_some_and(|l| l.adjoint().is_some());
        let chain = match (adjoint, s.ps.adjoint.as_ref()) {
            (true, Some(a)) => &a.chain,
            _ => self.prediction.chain(),
        };
        for (j, col) in s.j_theta.iter_mut().enumerate() {
            let d = chain.joint_direction(&s.ps.chain, j) * (1.0 + growth);
            let w = if chain.is_rotational(j) {
                chain.axis_now(&s.ps.chain, j)
            } else {
                Vector3::zeros()
            };
            *col = [d.x, d.y, d.z, w.x, w.y, w.z];
        }
        match s.regs.as_mut() {
            Some(rr) => rr.angle_jacobian(q, &target.context, x, &mut s.work, &mut s.dtheta_dq),
            None => {
                s.dtheta_dq.fill(0.0);
                for j in 0..n {
                    s.dtheta_dq[j * n + j] = 1.0;
                }
            }
        }
        let rows = jac.len() / n;
        for row in 0..rows {
            for k in 0..n {
                let mut v = 0.0;
                for (j, col) in s.j_theta.iter().enumerate() {
                    v += col[row] * s.dtheta_dq[j * n + k];
                }
                jac[row * n + k] = v;
            }
        }
        if let Some(l) = learned
            && !adjoint
            && l.jacobian(q, &mut s.learned)
        {
            let frame = self.prediction.learned_frame(c);
            for (k, d) in s.learned.iter().enumerate() {
                let d = frame * d;
                for row in 0..3 {
                    jac[row * n + k] += d[row];
                }
            }
        }
    }

    /// The model's prediction (tracker frame, m) at `q` for `target`'s context and campaign, and its
    /// analytic Jacobian with respect to `q` (3 × nq, m/rad; 6 × nq with an orientation target, the
    /// rotation rows in rad/rad): what each solver step uses, for checks against finite differences.
    /// Errors as [`Compensator::solve`].
    pub fn prediction_jacobian(
        &self,
        q: &[f64],
        target: &Target<'_>,
        s: &mut CompensateScratch<'a>,
    ) -> std::result::Result<(Vector3<f64>, DMatrix<f64>), String> {
        let rows = if target.r_tracker.is_some() { 6 } else { 3 };
        let mut jac = vec![0.0; rows * self.nq];
        let (p, _) = self.evaluate(q, target, s, Some(&mut jac))?;
        Ok((p, DMatrix::from_row_slice(rows, self.nq, &jac)))
    }

    /// The joints nearest `target.seed_q` at which the calibrated model puts the target at
    /// `target.p_tracker` (and `target.r_tracker`). Errors only for a model that cannot evaluate
    /// (a robot without the inertial data its causes need): the message, for the caller to name
    /// the row.
    pub fn solve(
        &self,
        target: &Target<'_>,
        s: &mut CompensateScratch<'a>,
    ) -> std::result::Result<Solution, String> {
        let n = self.nq;
        let rows = if target.r_tracker.is_some() { 6 } else { 3 };
        let mut q = target.seed_q.to_vec();
        let mut trial = q.clone();
        let mut jac = vec![0.0; rows * n];
        let mut e = DVector::zeros(rows);
        let mut e_trial = DVector::zeros(rows);
        // The error at `q`: position (m) and rotation vector (rad) into `e`; its two norms.
        let error = |p: Vector3<f64>, r: Matrix3<f64>, e: &mut DVector<f64>| -> (f64, f64) {
            let ep = target.p_tracker - p;
            e.fixed_rows_mut::<3>(0).copy_from(&ep);
            let mut rad = 0.0;
            if let Some(rt) = &target.r_tracker {
                let er = log_rotation(&(rt * r.transpose()));
                rad = er.norm();
                e.fixed_rows_mut::<3>(3).copy_from(&er);
            }
            (ep.norm(), rad)
        };
        let (p, r) = self.evaluate(&q, target, s, Some(&mut jac))?;
        let (mut err_m, mut err_rad) = error(p, r, &mut e);
        let mut iterations = 0;
        // Levenberg–Marquardt damping: a step that does not reduce the error is retried with ten
        // times the damping (shorter, towards the gradient); an accepted one relaxes it again.
        let mut lambda2 = DAMPING_M * DAMPING_M;
        while (err_m >= STOP || err_rad >= STOP)
            && iterations < MAX_ITERATIONS
            && lambda2 < MAX_DAMPING2
            && (err_m + err_rad).is_finite()
        {
            let jm = DMatrix::from_row_slice(rows, n, &jac);
            let mut a = &jm * jm.transpose();
            for i in 0..rows {
                a[(i, i)] += lambda2;
            }
            let Some(y) = a.cholesky().map(|ch| ch.solve(&e)) else {
                lambda2 *= 10.0;
                iterations += 1;
                continue;
            };
            let mut dq = jm.transpose() * y;
            let norm = dq.norm();
            if norm > MAX_STEP_RAD {
                dq *= MAX_STEP_RAD / norm;
            }
            for ((t, qi), d) in trial.iter_mut().zip(&q).zip(dq.iter()) {
                *t = qi + d;
            }
            iterations += 1;
            let (p, r) = self.evaluate(&trial, target, s, None)?;
            let (m, rad) = error(p, r, &mut e_trial);
            if m * m + rad * rad < err_m * err_m + err_rad * err_rad {
                std::mem::swap(&mut q, &mut trial);
                std::mem::swap(&mut e, &mut e_trial);
                // The Jacobian only where another step follows.
                if m >= STOP || rad >= STOP {
                    self.jacobian(&q, target, s, &mut jac);
                }
                (err_m, err_rad) = (m, rad);
                lambda2 = (lambda2 * 0.1).max(DAMPING_M * DAMPING_M);
            } else {
                lambda2 *= 10.0;
            }
        }
        let residual_rad = target.r_tracker.is_some().then_some(err_rad);
        let mut failure = None;
        if !(err_m <= CONVERGED_M && err_rad <= CONVERGED_RAD) {
            failure = Some(Failure::OutOfReach {
                residual_m: err_m,
                residual_rad,
            });
        } else {
            for (j, (joint, &v)) in self.predictor.model.joints().iter().zip(&q).enumerate() {
                if let Some(l) = &joint.limits
                    && !(l.lower..=l.upper).contains(&v)
                {
                    failure = Some(Failure::JointLimit {
                        joint: j,
                        value: v,
                        lower: l.lower,
                        upper: l.upper,
                    });
                    break;
                }
            }
        }
        Ok(Solution {
            q,
            residual_m: err_m,
            residual_rad,
            iterations,
            failure,
        })
    }
}

/// Where the targets of a table are.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Targets {
    /// `x, y, z` (and `qw..qz`) in the tracker frame of the row's campaign.
    Tracker,
    /// `x, y, z` (and `qw..qz`) in the robot's base frame.
    Base,
    /// A nominal joint program (no `x, y, z`): each row's target is where the nominal robot puts the
    /// target at the row's joints, registered to the calibrated robot over the program's rows of its
    /// campaign ([`nominal_registration`]). Positions only: an orientation target is not derived.
    Program,
}

/// The compensated rows of a table.
#[derive(Clone, Debug, PartialEq)]
pub struct Compensations {
    /// Joints per row.
    pub nq: usize,
    /// Pose id per row.
    pub pose: Vec<i64>,
    /// Every row's solution (its joints are the best found when it failed).
    pub solutions: Vec<Solution>,
    /// Per row: outside the learned correction's support ([`outside_support`]).
    pub outside_support: Vec<bool>,
    /// Context columns passed through, so the output is a pose file of the same program: names and
    /// per-row values.
    pub context: Vec<(String, Vec<f64>)>,
}

impl Compensations {
    /// Rows whose target was not reached, with why (0-based row).
    pub fn failures(&self) -> impl Iterator<Item = (usize, &Failure)> {
        self.solutions
            .iter()
            .enumerate()
            .filter_map(|(r, s)| s.failure.as_ref().map(|f| (r, f)))
    }

    /// CSV text: `pose, q1..qN, residual_m, outside_support, converged`, then the context columns
    /// of the input (`t, temp, dir1..dirN, payload, campaign`, those it has).
    pub fn to_csv(&self) -> String {
        let mut s = String::from("pose");
        for j in 1..=self.nq {
            s.push_str(&format!(",q{j}"));
        }
        s.push_str(",residual_m,outside_support,converged");
        for (name, _) in &self.context {
            s.push(',');
            s.push_str(name);
        }
        s.push('\n');
        for (r, sol) in self.solutions.iter().enumerate() {
            s.push_str(&self.pose[r].to_string());
            for v in &sol.q {
                s.push_str(&format!(",{v:?}"));
            }
            s.push_str(&format!(
                ",{:?},{},{}",
                sol.residual_m,
                u8::from(self.outside_support[r]),
                u8::from(sol.converged())
            ));
            for (name, values) in &self.context {
                let v = values[r];
                if name.starts_with("dir") || name == "campaign" {
                    s.push_str(&format!(",{}", v as i64));
                } else {
                    s.push_str(&format!(",{v:?}"));
                }
            }
            s.push('\n');
        }
        s
    }
}

/// Compensates every row of `table` (`file` names it in errors) with `predictor`'s model: the
/// targets per `targets`, the seeds its joint values, the context its columns.
///
/// # Errors
/// A table the model cannot read (joint count, a column a cause reads, an unknown campaign, an
/// orientation the model has not), a row the model cannot evaluate: one line naming the file, the row
/// and the column. Unreached targets are not errors: see [`Compensations::failures`].
pub fn compensate_table(
    predictor: &Predictor,
    table: &MeasurementTable,
    file: &str,
    targets: Targets,
) -> Result<Compensations> {
    let model = &predictor.model;
    let n = model.nq();
    if !model.couplings().is_empty() {
        return Err(CalibError::BadValue {
            context: file.to_string(),
            field: "robot".into(),
            value: model.name().to_string(),
            problem: "has coupled joints: compensation, which solves for every chain joint, does \
                      not yet solve for the driven joints alone"
                .into(),
        });
    }
    if table.n_joints != n {
        return Err(CalibError::BadValue {
            context: file.to_string(),
            field: "q1..qN".into(),
            value: format!("{} joint columns", table.n_joints),
            problem: format!("the model's robot '{}' has {n} joints", model.name()),
        });
    }
    if let Some(s) = &predictor.extensions {
        s.check_table(table, file)?;
    }
    let orientation = predictor.params.r_flange_target.is_some();
    if table.orientation.is_some() && !orientation && targets != Targets::Program {
        return Err(CalibError::BadValue {
            context: file.to_string(),
            field: "qw".into(),
            value: String::new(),
            problem: "the model has no target orientation (it was calibrated on positions only): \
                      drop the qw, qx, qy, qz columns"
                .into(),
        });
    }
    let campaign = predictor.campaigns_of(table, file)?;
    let params = &predictor.params;
    // The targets, tracker frame of each row's campaign.
    let mut p_target = Vec::with_capacity(table.len());
    let mut r_target: Vec<Option<Matrix3<f64>>> = Vec::with_capacity(table.len());
    for r in 0..table.len() {
        let c = campaign[r];
        let t_tb = params.t_tracker_base_of(c);
        match targets {
            Targets::Tracker | Targets::Base => {
                let p = Vector3::from(table.position[r]);
                let rot = table.orientation.as_ref().map(|o| {
                    let [w, x, y, z] = o[r];
                    *nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
                        w, x, y, z,
                    ))
                    .to_rotation_matrix()
                    .matrix()
                });
                if targets == Targets::Base {
                    p_target.push((t_tb * nalgebra::Point3::from(p)).coords);
                    r_target.push(rot.map(|m| t_tb.rotation.matrix() * m));
                } else {
                    p_target.push(p);
                    r_target.push(rot);
                }
            }
            Targets::Program => {
                p_target.push(Vector3::zeros());
                r_target.push(None);
            }
        }
    }
    if targets == Targets::Program {
        program_targets(predictor, table, file, &campaign, &mut p_target)?;
    }
    let compensator = Compensator::new(predictor);
    let rows: Vec<usize> = (0..table.len()).collect();
    let branch = sim::measurement_table::BranchValues::new(table, &predictor.model);
    let chunks: Vec<Result<Vec<Solution>>> = rows
        .par_chunks(CHUNK_ROWS)
        .map(|chunk| {
            let mut s = compensator.scratch();
            let mut values = vec![0.0; branch.as_ref().map_or(0, |b| b.len())];
            chunk
                .iter()
                .map(|&r| {
                    let target = Target {
                        p_tracker: p_target[r],
                        r_tracker: r_target[r],
                        seed_q: table.q_row(r),
                        context: RowContext {
                            payload_kg: table.payload.as_ref().map_or(0.0, |p| p[r]),
                            dir: table.dir_row(r),
                            temp_c: table.temp.as_ref().map(|t| t[r]),
                            t_s: table.t.as_ref().map(|t| t[r]),
                            branch: branch.as_ref().map(|b| b.row(table, r, &mut values)),
                        },
                        campaign: campaign[r],
                    };
                    compensator
                        .solve(&target, &mut s)
                        .map_err(|e| CalibError::BadValue {
                            context: format!("{file}: row {}", r + 1),
                            field: "q1..qN".into(),
                            value: String::new(),
                            problem: format!("the model cannot be evaluated here: {e}"),
                        })
                })
                .collect()
        })
        .collect();
    let mut solutions = Vec::with_capacity(table.len());
    for c in chunks {
        solutions.extend(c?);
    }
    let outside = solutions
        .iter()
        .map(|s| outside_support(predictor, &s.q))
        .collect();
    Ok(Compensations {
        nq: n,
        pose: table.pose.clone(),
        solutions,
        outside_support: outside,
        context: context_columns(table),
    })
}

/// The targets of a nominal joint program: where the nominal robot puts the target at each row's
/// joints, placed in the tracker frame by the registration of the nominal robot to the calibrated
/// one ([`nominal_registration`]) over the program's rows of each campaign, into `p_target`.
fn program_targets(
    predictor: &Predictor,
    table: &MeasurementTable,
    file: &str,
    campaign: &[usize],
    p_target: &mut [Vector3<f64>],
) -> Result<()> {
    let model = &predictor.model;
    let params = &predictor.params;
    let rows: Vec<usize> = (0..table.len()).collect();
    let regs = match &predictor.extensions {
        Some(s) => Regressors::build(model, s, table, &rows, file, Some(params))?,
        None => Regressors::none(),
    };
    let mut predicted = vec![Vector3::zeros(); table.len()];
    Prediction::new(model, params)
        .with_learned(predictor.learned.as_ref())
        .positions_in(&table.q, campaign, &regs, &mut predicted, None);
    let mut data = sim::Data::new(model);
    let flange: Vec<sim::lie::Pose> = (0..table.len())
        .map(|r| {
            sim::kinematics::forward_kinematics(model, &mut data, table.q_row(r));
            data.flange
        })
        .collect();
    for c in 0..params.n_campaigns() {
        let rows: Vec<usize> = (0..table.len()).filter(|&r| campaign[r] == c).collect();
        if rows.is_empty() {
            continue;
        }
        let t_tb = params.t_tracker_base_of(c);
        let (rot, t, p_ft) = nominal_registration(
            rows.iter().map(|&r| (&flange[r], &predicted[r])),
            *t_tb.rotation.matrix(),
            t_tb.translation.vector,
            *params.p_flange_target_of(c),
        );
        for &r in &rows {
            let f = &flange[r];
            p_target[r] = rot * (f.rotation * p_ft + f.translation.vector) + t;
        }
    }
    Ok(())
}

/// The registration of the nominal robot to the calibrated one: `T_tracker_base = (R, t)` and the
/// target in the flange frame `p_ft` (m) minimising `Σ |R (T_base_flange(qᵢ) p_ft) + t − p̂ᵢ|²` over
/// the rows `(T_base_flange(qᵢ)` of the nominal robot, `p̂ᵢ` the calibrated prediction, tracker frame
/// m), by Gauss–Newton from the model's own registration `(r0, t0, p0)`: a rotation step `ω` moves a
/// point by `ω × R x`, `t` by itself, `p_ft` by `R R_base_flange`. Directions the rows do not
/// determine (one pose, or all poses at one flange orientation) keep their start value (pseudo-
/// inverse).
///
/// Why not the model's registration itself: with the nominal robot it is not meaningful. A calibration
/// determines the robot only up to combinations the data cannot see (a turn of the target about the
/// last joint and that joint's zero offset; the base's place and the first joint's error twist), so
/// its `T_tracker_base` and `p_flange_target` are one choice among equivalent ones, and the nominal
/// robot placed by them can be centimetres from the calibrated one. Registered by least squares, the
/// nominal program's targets are the ones a user who placed the nominal robot in the cell with the
/// tracker would have, whatever the calibration's choice.
pub fn nominal_registration<'p>(
    rows: impl Iterator<Item = (&'p sim::lie::Pose, &'p Vector3<f64>)> + Clone,
    r0: Matrix3<f64>,
    t0: Vector3<f64>,
    p0: Vector3<f64>,
) -> (Matrix3<f64>, Vector3<f64>, Vector3<f64>) {
    let (mut rot, mut t, mut p_ft) = (r0, t0, p0);
    let mut last_step = f64::INFINITY;
    for _ in 0..30 {
        // Normal equations `JᵀJ δ = Jᵀe`, accumulated row by row (9 unknowns).
        let mut jtj = nalgebra::SMatrix::<f64, 9, 9>::zeros();
        let mut jte = nalgebra::SVector::<f64, 9>::zeros();
        for (f, p_hat) in rows.clone() {
            let x = rot * (f.rotation * p_ft + f.translation.vector);
            let e = p_hat - (x + t);
            let mut j = nalgebra::SMatrix::<f64, 3, 9>::zeros();
            // ω × x = −[x] ω.
            let skew = Matrix3::new(0.0, x.z, -x.y, -x.z, 0.0, x.x, x.y, -x.x, 0.0);
            j.fixed_view_mut::<3, 3>(0, 0).copy_from(&skew);
            j.fixed_view_mut::<3, 3>(0, 3)
                .copy_from(&Matrix3::identity());
            j.fixed_view_mut::<3, 3>(0, 6)
                .copy_from(&(rot * f.rotation.matrix()));
            jtj += j.transpose() * j;
            jte += j.transpose() * e;
        }
        let svd = jtj.svd(true, true);
        let Ok(step) = svd.solve(&jte, 1e-12 * svd.singular_values.max()) else {
            break;
        };
        rot = crate::lie3::exp_rotation(&step.fixed_rows::<3>(0).into_owned()) * rot;
        t += step.fixed_rows::<3>(3);
        p_ft += step.fixed_rows::<3>(6);
        // Gauss–Newton converges quadratically from a start this close; the normal equations hold
        // the step to about 1e-8 of the first, so stop there.
        let norm = step.norm();
        if norm < 1e-12 || norm > 0.5 * last_step {
            break;
        }
        last_step = norm;
    }
    (rot, t, p_ft)
}

/// The context columns of `table` it has, by name, as numbers per row.
fn context_columns(table: &MeasurementTable) -> Vec<(String, Vec<f64>)> {
    let mut out = Vec::new();
    if let Some(t) = &table.t {
        out.push(("t".to_string(), t.clone()));
    }
    if let Some(t) = &table.temp {
        out.push(("temp".to_string(), t.clone()));
    }
    if let Some(d) = &table.dir {
        let n = table.n_joints;
        for j in 0..n {
            out.push((
                format!("dir{}", j + 1),
                (0..table.len()).map(|r| f64::from(d[r * n + j])).collect(),
            ));
        }
    }
    if let Some(p) = &table.payload {
        out.push(("payload".to_string(), p.clone()));
    }
    if let Some(c) = &table.campaign {
        out.push((
            "campaign".to_string(),
            c.iter().map(|&v| v as f64).collect(),
        ));
    }
    out
}
