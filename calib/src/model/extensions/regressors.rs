//! The regressors `gₑ(row)` of every extension parameter over a set of rows, and how the extension
//! values act on a row's joint values.

use super::{Cause, ExtensionParam, ExtensionSettings, Term};
use crate::error::{CalibError, Result};
use crate::model::params::KinematicParams;
use nalgebra::Vector3;
use rayon::prelude::*;
use sim::Model;
use sim::measurement_table::MeasurementTable;

/// What one measured row gives the regressors of a cause.
#[derive(Clone, Copy, Debug)]
pub struct RowInputs<'a> {
    /// The robot's joints (kind, axis in the joint frame).
    pub joints: &'a [sim::Joint],
    /// The robot's coupled joints ([`sim::coupled_joints`]; none for most arms).
    pub couplings: &'a sim::coupled_joints::Couplings,
    /// Joint values the controller reports (rad; m for prismatic joints).
    pub q: &'a [f64],
    /// Holding torque of each joint against gravity and payload (N m; N for prismatic joints), at the
    /// link angles of the current estimate; zeros when no cause needs them.
    pub tau: &'a [f64],
    /// Moment of gravity and payload that each joint transmits, about its origin, in its joint frame
    /// (N m; [`super::link_deflection::gravity_moments`]), at the link angles of the current estimate;
    /// zeros when no cause needs them.
    pub moment: &'a [Vector3<f64>],
    /// The joint frames at the link angles the torques are evaluated at, when a cause reads the
    /// torques or the frames ([`super::CauseModel::needs_frames`]).
    pub frames: Option<&'a sim::Data>,
    /// Mass carried at the flange (kg; 0 without payload).
    pub payload_kg: f64,
    /// Approach direction sign of each joint (−1, 0, +1), when the table has `dir` columns.
    pub dir: Option<&'a [i8]>,
    /// Temperature (°C), when the table has a `temp` column.
    pub temp_c: Option<f64>,
    /// Time since the start of the campaign (s), when the table has a `t` column.
    pub t_s: Option<f64>,
}

/// Regressors of every extension parameter for a set of rows.
#[derive(Clone, Debug, PartialEq)]
pub struct Regressors {
    /// The parameters (columns).
    pub params: Vec<ExtensionParam>,
    /// `gₑ(row)`, row-major (rows × params).
    pub coef: Vec<f64>,
    /// Whether any parameter is a [`Term::Bend`].
    pub bends: bool,
    /// The robot's coupled joints, when it has any: a joint-angle term of a driven joint moves the
    /// joints coupled to it ([`apply`]).
    pub couplings: Option<sim::coupled_joints::Couplings>,
}

/// Fixed-point steps of the spring balance in [`Regressors::build`]: the error shrinks by about 10⁻²
/// per step, so four reach 10⁻⁸ of the sag.
pub const EQUILIBRIUM_ITERATIONS: usize = 4;

impl Regressors {
    /// No extension.
    pub fn none() -> Self {
        Regressors {
            params: Vec::new(),
            coef: Vec::new(),
            bends: false,
            couplings: None,
        }
    }

    /// Number of parameters.
    pub fn len(&self) -> usize {
        self.params.len()
    }

    /// True without parameters.
    pub fn is_empty(&self) -> bool {
        self.params.is_empty()
    }

    /// Regressors of row `r` (one per parameter).
    #[inline]
    pub fn row(&self, r: usize) -> &[f64] {
        let n = self.params.len();
        &self.coef[r * n..(r + 1) * n]
    }

    /// The regressors of `rows` (0-based) of `table` under `settings`; `source` names the table in
    /// errors.
    ///
    /// Gravity torques are evaluated where the link really is: at the joint angles `θ` that the
    /// extension values of the parameters `at` (in [`ExtensionSettings::params`] order) give,
    /// `θ = q + Σₑ xₑ gₑ(θ)`, solved by fixed-point iteration (each step shrinks the error by the
    /// compliance times the torque's derivative, about 10⁻²). Without `at`, at `q`. Once `at` holds
    /// the estimate, this turns the first-order compliance model into the exact spring balance. The
    /// torques are the nominal robot's (docs/calibrate.md, "The statics' geometry").
    pub fn build(
        model: &Model,
        settings: &ExtensionSettings,
        table: &MeasurementTable,
        rows: &[usize],
        source: &str,
        at: Option<&KinematicParams>,
    ) -> Result<Self> {
        let at: &[f64] = at.map_or(&[], |p| &p.extension);
        let params = settings.params(model);
        let n = params.len();
        let mut coef = vec![0.0; rows.len() * n];
        let bends = params.iter().any(|p| matches!(p.term, Term::Bend { .. }));
        if n > 0 {
            // The branch joints' values of each row, in the model's order, when the table has them.
            let branch = sim::measurement_table::BranchValues::new(table, model);
            // Rows are independent: blocks of them in parallel, each with its own scratch; the first
            // error in row order is returned.
            let blocks: Vec<Result<()>> = coef
                .par_chunks_mut(BUILD_BLOCK_ROWS * n)
                .zip(rows.par_chunks(BUILD_BLOCK_ROWS))
                .map(|(out, rows)| {
                    let mut one = RowRegressors::new(model, settings);
                    let mut values = vec![0.0; branch.as_ref().map_or(0, |b| b.len())];
                    for (k, &r) in rows.iter().enumerate() {
                        let context = RowContext {
                            payload_kg: table.payload.as_ref().map_or(0.0, |p| p[r]),
                            dir: table.dir_row(r),
                            temp_c: table.temp.as_ref().map(|t| t[r]),
                            t_s: table.t.as_ref().map(|t| t[r]),
                            branch: branch.as_ref().map(|b| b.row(table, r, &mut values)),
                        };
                        one.fill(table.q_row(r), &context, at).map_err(|e| {
                            CalibError::BadValue {
                                context: format!("{source}: row {}", r + 1),
                                field: "q1..qN".into(),
                                value: String::new(),
                                problem: format!("gravity torques: {e}"),
                            }
                        })?;
                        out[k * n..(k + 1) * n].copy_from_slice(&one.regressors().coef);
                    }
                    Ok(())
                })
                .collect();
            blocks.into_iter().collect::<Result<()>>()?;
        }
        Ok(Regressors {
            params,
            coef,
            bends,
            couplings: couplings_of(model),
        })
    }
}

/// What a row gives the regressors besides its joint values: the context columns of the measurement
/// table (or of a compensation target).
#[derive(Clone, Copy, Debug, Default)]
pub struct RowContext<'a> {
    /// Mass carried at the flange (kg; 0 without payload).
    pub payload_kg: f64,
    /// Approach direction sign of each joint (−1, 0, +1), when known.
    pub dir: Option<&'a [i8]>,
    /// Robot temperature (°C), when known.
    pub temp_c: Option<f64>,
    /// Time since the start of the campaign (s), when known.
    pub t_s: Option<f64>,
    /// Values of the branch joints off the chain (rad or m, [`sim::Model::branches`] order), when
    /// the table gives them (`q_<joint>` columns); the branches are at zero otherwise.
    pub branch: Option<&'a [f64]>,
}

/// The regressors of one row at a time, with the workspace they need (statics, torques, moments):
/// made once per thread, then [`RowRegressors::fill`]ed row after row without allocating. What
/// [`Regressors::build`] does for a table, and what the compensation does at every step of its solve
/// (the regressors depend on the joints it commands).
#[derive(Clone, Debug)]
pub struct RowRegressors<'m> {
    model: &'m Model,
    settings: &'m ExtensionSettings,
    parts: Vec<CauseColumns>,
    /// A cause's regressors (or values) at all its joints, for a cause limited to some of them.
    full: Vec<f64>,
    needs_tau: bool,
    /// The frames without the torques (forward kinematics at `θ`).
    needs_frames: bool,
    needs_moment: bool,
    moves_links: bool,
    gravity_base: Vector3<f64>,
    data: sim::Data,
    /// Holding torques against gravity and payload at the last `θ` (N m; N for prismatic joints).
    tau: Vec<f64>,
    /// Gravity moments each joint transmits at the last `θ` (N m, joint frame).
    moment: Vec<Vector3<f64>>,
    /// The last row's regressors, as a one-row [`Regressors`].
    one: Regressors,
    /// Link angles `θ` the torques were last evaluated at (rad or m).
    theta: Vec<f64>,
}

impl<'m> RowRegressors<'m> {
    /// A workspace for the regressors of `settings` on `model`.
    pub fn new(model: &'m Model, settings: &'m ExtensionSettings) -> Self {
        let params = settings.params(model);
        let n = params.len();
        let needs_moment = settings.needs_gravity_moment();
        let needs_tau = settings.needs_gravity_torque() || needs_moment;
        let needs_frames = !needs_tau && settings.needs_frames();
        let parts: Vec<CauseColumns> = settings
            .causes
            .iter()
            .map(|&cause| {
                let all = cause.model().params(model, settings);
                let keep: Vec<usize> = (0..all.len())
                    .filter(|&k| settings.acts_at(cause, all[k].term))
                    .collect();
                CauseColumns {
                    cause,
                    full: all.len(),
                    keep: (keep.len() < all.len()).then_some(keep),
                }
            })
            .collect();
        let widest = parts.iter().map(|p| p.full).max().unwrap_or(0);
        // Only joint-angle terms move the links the torques are evaluated at.
        let moves_links = params
            .iter()
            .any(|p| matches!(p.term, Term::JointAngle { .. }));
        let bends = params.iter().any(|p| matches!(p.term, Term::Bend { .. }));
        RowRegressors {
            model,
            settings,
            parts,
            full: vec![0.0; widest],
            needs_tau,
            needs_frames,
            needs_moment,
            moves_links,
            gravity_base: Vector3::from(settings.gravity_base),
            data: sim::Data::new(model),
            tau: vec![0.0; model.nq()],
            moment: vec![Vector3::zeros(); model.nq()],
            one: Regressors {
                params,
                coef: vec![0.0; n],
                bends,
                couplings: couplings_of(model),
            },
            theta: vec![0.0; model.nq()],
        }
    }

    /// The row's payload (`context.payload_kg` at the settings' centre of mass), if it has one.
    fn payload(&self, context: &RowContext<'_>) -> Option<sim::statics::Payload> {
        (context.payload_kg > 0.0).then_some(sim::statics::Payload {
            mass: context.payload_kg,
            com: self.settings.payload_com_m,
        })
    }

    /// The regressors of the row at the controller's joints `q` with `context`, the gravity torques
    /// taken where the links are under the extension values `at` (see [`Regressors::build`]); the
    /// result is [`RowRegressors::regressors`]. Errors: a robot without the inertial data the
    /// torques need (the message of [`sim::statics::gravity_torques`]).
    pub fn fill(
        &mut self,
        q: &[f64],
        context: &RowContext<'_>,
        at: &[f64],
    ) -> std::result::Result<(), String> {
        let n = self.one.params.len();
        let iterations = if (self.needs_tau || self.needs_frames)
            && self.moves_links
            && at.len() == n
            && at.iter().any(|x| *x != 0.0)
        {
            EQUILIBRIUM_ITERATIONS
        } else {
            1
        };
        self.theta.copy_from_slice(q);
        if self.needs_tau && !self.model.branches().is_empty() {
            self.data.pose_branches(self.model, context.branch);
        }
        for it in 0..iterations {
            if self.needs_tau {
                let payload = self.payload(context);
                sim::statics::gravity_torques(
                    self.model,
                    &mut self.data,
                    &self.theta,
                    &self.gravity_base,
                    payload.as_ref(),
                )
                .map_err(|e| e.to_string())?;
                self.tau
                    .copy_from_slice(self.data.gravity_torque.as_slice());
                if self.needs_moment {
                    super::link_deflection::gravity_moments(
                        self.model,
                        &self.data,
                        &self.gravity_base,
                        payload.as_ref(),
                        &mut self.moment,
                    );
                }
            } else if self.needs_frames {
                sim::kinematics::forward_kinematics(self.model, &mut self.data, &self.theta);
            }
            let inputs = RowInputs {
                joints: self.model.joints(),
                couplings: self.model.couplings(),
                q,
                tau: &self.tau,
                moment: &self.moment,
                frames: (self.needs_tau || self.needs_frames).then_some(&self.data),
                payload_kg: context.payload_kg,
                dir: context.dir,
                temp_c: context.temp_c,
                t_s: context.t_s,
            };
            let mut col = 0;
            for part in &self.parts {
                let width = part.width();
                let out = &mut self.one.coef[col..col + width];
                match &part.keep {
                    None => part.cause.model().regressors(self.settings, &inputs, out),
                    Some(keep) => {
                        let full = &mut self.full[..part.full];
                        part.cause.model().regressors(self.settings, &inputs, full);
                        for (o, &k) in out.iter_mut().zip(keep) {
                            *o = full[k];
                        }
                    }
                }
                col += width;
            }
            if it + 1 < iterations {
                apply(&self.one, at, 0, q, &mut self.theta);
            }
        }
        Ok(())
    }

    /// `∂θ/∂q` (rad per rad, `nq × nq` row-major, into `out`) of the effective joint values
    /// `θ = q + Δθ(q, θ)` at the last [`RowRegressors::fill`]ed row (joint values `q`, `context`) under
    /// the extension values `x`: `(I − ∂Δθ/∂θ)⁻¹ (I + ∂Δθ/∂q)`, each cause adding its pieces
    /// ([`super::CauseModel::angle_jacobian`]). `work` is scratch of at least `3 nq²` values.
    pub fn angle_jacobian(
        &mut self,
        q: &[f64],
        context: &RowContext<'_>,
        x: &[f64],
        work: &mut [f64],
        out: &mut [f64],
    ) {
        let n = self.model.nq();
        let (d_dq, rest) = work.split_at_mut(n * n);
        let (d_dtheta, torque_jac) = rest.split_at_mut(n * n);
        let torque_jac = &mut torque_jac[..n * n];
        d_dq.fill(0.0);
        d_dtheta.fill(0.0);
        torque_jac.fill(0.0);
        if self.needs_tau {
            let payload = self.payload(context);
            super::joint_compliance::torque_jacobian(
                self.model,
                &self.data,
                &self.gravity_base,
                payload.as_ref(),
                torque_jac,
            );
        }
        let inputs = RowInputs {
            joints: self.model.joints(),
            couplings: self.model.couplings(),
            q,
            tau: &self.tau,
            moment: &self.moment,
            frames: (self.needs_tau || self.needs_frames).then_some(&self.data),
            payload_kg: context.payload_kg,
            dir: context.dir,
            temp_c: context.temp_c,
            t_s: context.t_s,
        };
        let mut col = 0;
        for part in &self.parts {
            let width = part.width();
            let x = &x[col..col + width];
            // A cause limited to some joints sees zeros at the others (their parameters are absent).
            let x = match &part.keep {
                None => x,
                Some(keep) => {
                    let full = &mut self.full[..part.full];
                    full.fill(0.0);
                    for (&v, &k) in x.iter().zip(keep) {
                        full[k] = v;
                    }
                    &self.full[..part.full]
                }
            };
            part.cause.model().angle_jacobian(
                self.settings,
                &inputs,
                torque_jac,
                x,
                d_dq,
                d_dtheta,
            );
            col += width;
        }
        // out = (I − D_θ)⁻¹ (I + D_q), by LU of the small matrix.
        let a = nalgebra::DMatrix::from_fn(n, n, |i, j| {
            f64::from(u8::from(i == j)) - d_dtheta[i * n + j]
        });
        let b =
            nalgebra::DMatrix::from_fn(n, n, |i, j| f64::from(u8::from(i == j)) + d_dq[i * n + j]);
        let sol = a.lu().solve(&b).unwrap_or(b);
        for i in 0..n {
            for j in 0..n {
                out[i * n + j] = sol[(i, j)];
            }
        }
    }

    /// The last [`RowRegressors::fill`]ed row's regressors: a one-row [`Regressors`] (row 0).
    pub fn regressors(&self) -> &Regressors {
        &self.one
    }

    /// The statics of the last evaluation (joint frames and torques at the last `θ`), when the
    /// regressors read torques.
    pub fn statics(&self) -> Option<&sim::Data> {
        self.needs_tau.then_some(&self.data)
    }

    /// The holding torques of the last evaluation (N m; zeros when no cause reads them).
    pub fn torques(&self) -> &[f64] {
        &self.tau
    }

    /// The gravity moments of the last evaluation (N m, joint frames; zeros when no cause reads them).
    pub fn moments(&self) -> &[Vector3<f64>] {
        &self.moment
    }
}

/// Where one cause's regressors go in a row: all its [`super::CauseModel::params`] (`full` of them),
/// or, for a cause limited to some joints, those at positions `keep` of them.
#[derive(Clone, Debug)]
struct CauseColumns {
    cause: Cause,
    full: usize,
    keep: Option<Vec<usize>>,
}

impl CauseColumns {
    /// The columns this cause has in the model.
    fn width(&self) -> usize {
        self.keep.as_ref().map_or(self.full, Vec::len)
    }
}

/// Rows per parallel block of [`Regressors::build`].
const BUILD_BLOCK_ROWS: usize = 256;

/// Effective joint values of row `r`: `q` plus every joint-angle term (a driven joint's term moving
/// the joints coupled to it by their multipliers), into `q_out`; returns the growth
/// factor `x · g` (0 without growth). Bending terms are left to [`bends`].
#[inline]
pub fn apply(regs: &Regressors, values: &[f64], r: usize, q: &[f64], q_out: &mut [f64]) -> f64 {
    q_out.copy_from_slice(q);
    let mut growth = 0.0;
    if regs.is_empty() {
        return growth;
    }
    for ((p, &x), &g) in regs.params.iter().zip(values).zip(regs.row(r)) {
        match p.term {
            Term::JointAngle { joint } => q_out[joint] += x * g,
            Term::Growth => growth += x * g,
            Term::Bend { .. } => {}
        }
    }
    if let Some(c) = &regs.couplings {
        // A driven joint's change of link angle moves the joints coupled to it.
        for cj in c.list() {
            q_out[cj.joint] += cj
                .sources
                .iter()
                .map(|&(s, a)| a * (q_out[s] - q[s]))
                .sum::<f64>();
        }
    }
    growth
}

/// `Some` couplings of `model` when it has any.
fn couplings_of(model: &Model) -> Option<sim::coupled_joints::Couplings> {
    (!model.couplings().is_empty()).then(|| model.couplings().clone())
}

/// The bending rotation vector of each joint in row `r` (rad, joint frame: `φᵢ = Σₑ xₑ gₑ e_about`
/// over the [`Term::Bend`] terms of joint `i`) into `out` (one per joint); returns whether the model
/// has bending terms at all (`out` is then untouched).
#[inline]
pub fn bends(regs: &Regressors, values: &[f64], r: usize, out: &mut [Vector3<f64>]) -> bool {
    if !regs.bends {
        return false;
    }
    out.fill(Vector3::zeros());
    for ((p, &x), &g) in regs.params.iter().zip(values).zip(regs.row(r)) {
        if let Term::Bend { joint, about } = p.term {
            out[joint][about] += x * g;
        }
    }
    true
}
