//! The regressors `gₑ(row)` of every extension parameter over a set of rows, and how the extension
//! values act on a row's joint values.

use super::{Cause, ExtensionParam, ExtensionSettings, Term};
use crate::error::{CalibError, Result};
use nalgebra::Vector3;
use rayon::prelude::*;
use sim::Model;
use sim::measurement_table::MeasurementTable;

/// What one measured row gives the regressors of a cause.
#[derive(Clone, Copy, Debug)]
pub struct RowInputs<'a> {
    /// The robot's joints (kind, axis in the joint frame).
    pub joints: &'a [sim::Joint],
    /// Joint values the controller reports (rad; m for prismatic joints).
    pub q: &'a [f64],
    /// Holding torque of each joint against gravity and payload (N m; N for prismatic joints), at the
    /// link angles of the current estimate; zeros when no cause needs them.
    pub tau: &'a [f64],
    /// Moment of gravity and payload that each joint transmits, about its origin, in its joint frame
    /// (N m; [`super::link_deflection::gravity_moments`]), at the link angles of the current estimate;
    /// zeros when no cause needs them.
    pub moment: &'a [Vector3<f64>],
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
    /// extension values `at` (in [`ExtensionSettings::params`] order) give, `θ = q + Σₑ xₑ gₑ(θ)`,
    /// solved by fixed-point iteration (each step shrinks the error by the compliance times the
    /// torque's derivative, about 10⁻²). With `at` empty, at `q`. Once `at` holds the estimate, this
    /// turns the first-order compliance model into the exact spring balance.
    pub fn build(
        model: &Model,
        settings: &ExtensionSettings,
        table: &MeasurementTable,
        rows: &[usize],
        source: &str,
        at: &[f64],
    ) -> Result<Self> {
        let params = settings.params(model);
        let n = params.len();
        let mut coef = vec![0.0; rows.len() * n];
        let needs_moment = settings.needs_gravity_moment();
        let needs_tau = settings.needs_gravity_torque() || needs_moment;
        let g = Vector3::from(settings.gravity_base);
        let widths: Vec<(Cause, usize)> = settings
            .causes
            .iter()
            .map(|c| (*c, params.iter().filter(|p| p.cause == *c).count()))
            .collect();
        // Only joint-angle terms move the links the torques are evaluated at.
        let moves_links = params
            .iter()
            .any(|p| matches!(p.term, Term::JointAngle { .. }));
        let iterations =
            if needs_tau && moves_links && at.len() == n && at.iter().any(|x| *x != 0.0) {
                EQUILIBRIUM_ITERATIONS
            } else {
                1
            };
        let bends = params.iter().any(|p| matches!(p.term, Term::Bend { .. }));
        if n > 0 {
            // Rows are independent: blocks of them in parallel, each with its own scratch; the first
            // error in row order is returned.
            let blocks: Vec<Result<()>> = coef
                .par_chunks_mut(BUILD_BLOCK_ROWS * n)
                .zip(rows.par_chunks(BUILD_BLOCK_ROWS))
                .map(|(out, rows)| {
                    let mut data = sim::Data::new(model);
                    let mut tau = vec![0.0; model.nq()];
                    let mut moment = vec![Vector3::zeros(); model.nq()];
                    // One row's regressors, to evaluate θ with [`apply`] between the fixed-point
                    // steps.
                    let mut one = Regressors {
                        params: params.clone(),
                        coef: vec![0.0; n],
                        bends,
                    };
                    let mut theta = vec![0.0; model.nq()];
                    for (k, &r) in rows.iter().enumerate() {
                        let q = table.q_row(r);
                        theta.copy_from_slice(q);
                        for it in 0..iterations {
                            if needs_tau {
                                let mass = table.payload.as_ref().map_or(0.0, |p| p[r]);
                                let payload = (mass > 0.0).then_some(sim::statics::Payload {
                                    mass,
                                    com: settings.payload_com_m,
                                });
                                sim::statics::gravity_torques(
                                    model,
                                    &mut data,
                                    &theta,
                                    &g,
                                    payload.as_ref(),
                                )
                                .map_err(|e| {
                                    CalibError::BadValue {
                                        context: format!("{source}: row {}", r + 1),
                                        field: "q1..qN".into(),
                                        value: String::new(),
                                        problem: format!("gravity torques: {e}"),
                                    }
                                })?;
                                tau.copy_from_slice(data.gravity_torque.as_slice());
                                if needs_moment {
                                    super::link_deflection::gravity_moments(
                                        model,
                                        &data,
                                        &g,
                                        payload.as_ref(),
                                        &mut moment,
                                    );
                                }
                            }
                            let inputs = RowInputs {
                                joints: model.joints(),
                                q,
                                tau: &tau,
                                moment: &moment,
                                dir: table.dir_row(r),
                                temp_c: table.temp.as_ref().map(|t| t[r]),
                                t_s: table.t.as_ref().map(|t| t[r]),
                            };
                            let mut col = 0;
                            for &(c, width) in &widths {
                                c.model().regressors(
                                    settings,
                                    &inputs,
                                    &mut one.coef[col..col + width],
                                );
                                col += width;
                            }
                            if it + 1 < iterations {
                                apply(&one, at, 0, q, &mut theta);
                            }
                        }
                        out[k * n..(k + 1) * n].copy_from_slice(&one.coef);
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
        })
    }
}

/// Rows per parallel block of [`Regressors::build`].
const BUILD_BLOCK_ROWS: usize = 256;

/// Effective joint values of row `r`: `q` plus every joint-angle term, into `q_out`; returns the growth
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
    growth
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
