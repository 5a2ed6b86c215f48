//! Robust losses against outliers, by iteratively reweighted least squares (IRLS).

use super::outliers::normalised_norms;
use super::report::RobustSummary;
use crate::fit::problem::{KinematicProblem, Observations};
use crate::health::Health;
use crate::lm::{LmOptions, LmWorkspace, MinimizationReport, Subspace, minimize};
use crate::model::params::KinematicParams;
use sim::Model;

/// A robust loss on the normalised residual norm `t` of a row (see [`CalibrationOptions::robust`]).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case", tag = "loss")]
pub enum RobustLoss {
    /// Weight 1 up to `c`, then `c / t`.
    Huber {
        /// Threshold in units of `t`.
        c: f64,
    },
    /// Weight `1 / (1 + (t/c)²)`.
    Cauchy {
        /// Scale in units of `t`.
        c: f64,
    },
}

impl RobustLoss {
    /// Huber with `c = 3.5`: about 1 % of Gaussian 3-D rows are down-weighted (`√χ²₃(0.99) = 3.37`).
    pub const HUBER: RobustLoss = RobustLoss::Huber { c: 3.5 };
    /// Cauchy with `c = 3.5`.
    pub const CAUCHY: RobustLoss = RobustLoss::Cauchy { c: 3.5 };

    /// The IRLS weight of a row with normalised residual norm `t`.
    pub fn weight(&self, t: f64) -> f64 {
        match *self {
            RobustLoss::Huber { c } => {
                if t <= c {
                    1.0
                } else {
                    c / t
                }
            }
            RobustLoss::Cauchy { c } => 1.0 / (1.0 + (t / c) * (t / c)),
        }
    }
}

/// Outcome of [`solve`].
pub(super) struct RobustFit {
    /// The final solve's report: `χ²` before the first (unweighted) round, iterations and numerical
    /// health of all rounds.
    pub report: MinimizationReport,
    /// The SVD split of the final solve.
    pub subspace: Subspace,
    /// Rounds and down-weighted rows.
    pub summary: RobustSummary,
    /// Set when the weights had not settled after the last round.
    pub warning: Option<String>,
}

/// Most reweighting rounds.
const MAX_ROUNDS: usize = 30;
/// The weights have settled when none changes by more than this between rounds.
const WEIGHT_TOLERANCE: f64 = 1e-3;

/// IRLS: solves for the `active` parameters from `params`, reweights the rows of `obs` by `loss` of
/// their normalised residual norms ([`super::outliers::normalised_norms`]), and repeats until the
/// weights settle (or [`MAX_ROUNDS`], or a solve fails); then a final solve with the settled weights,
/// for a consistent covariance. Leaves the weights in `obs.weight` and the solution in `params`.
#[allow(clippy::too_many_arguments)]
pub(super) fn solve(
    model: &Model,
    obs: &mut Observations,
    params: &mut KinematicParams,
    active: &[usize],
    scales: &[f64],
    lm: &LmOptions,
    loss: RobustLoss,
    ws: &mut LmWorkspace,
) -> RobustFit {
    let dim = obs.dim();
    let mut rounds = 0;
    let mut first_cost = None;
    let mut total_iterations = 0;
    let mut health = Health::new();
    loop {
        rounds += 1;
        let mut prob = KinematicProblem::new(model, obs, params.clone(), active.to_vec());
        let out = minimize(&mut prob, scales, lm, ws);
        first_cost.get_or_insert(out.0.cost_initial);
        total_iterations += out.0.iterations;
        health.merge(&out.0.health);
        let norms = prob.row_norms();
        *params = prob.into_params();
        let t = normalised_norms(&norms, &obs.weight, dim);
        let new: Vec<f64> = t.iter().map(|v| loss.weight(*v)).collect();
        let change = new
            .iter()
            .zip(&obs.weight)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        obs.weight = new;
        if change < WEIGHT_TOLERANCE || rounds >= MAX_ROUNDS || !out.0.was_successful() {
            let warning = (change >= WEIGHT_TOLERANCE).then(|| {
                format!(
                    "robust reweighting stopped after {rounds} rounds with weights still changing \
                     by {change:.1e}"
                )
            });
            let mut prob = KinematicProblem::new(model, obs, params.clone(), active.to_vec());
            let (mut report, subspace) = minimize(&mut prob, scales, lm, ws);
            *params = prob.into_params();
            report.cost_initial = first_cost.unwrap_or(report.cost_initial);
            report.iterations += total_iterations;
            health.merge(&report.health);
            report.health = health;
            return RobustFit {
                report,
                subspace,
                summary: RobustSummary {
                    loss,
                    rounds,
                    downweighted_rows: obs.weight.iter().filter(|w| **w < 0.5).count(),
                },
                warning,
            };
        }
    }
}
