//! How the rapier physics engine is stepped until the arm is at rest ([`crate::rapier_truth`]): the
//! settings, chosen by the scenario's `[truth]` (through [`crate::effects::ComplianceSolver::Rapier`])
//! and validated before the engine runs.

use crate::error::{Result, SimError};

/// How [`crate::rapier_truth::RapierArm::settle`] steps the engine and decides that the arm is at rest.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SettleOptions {
    /// Engine time step (s), > 0. One rapier step = one substep (`num_solver_iterations = 1`).
    pub dt: f64,
    /// Damping ratio `ζ` of each joint's damper `2 ζ √(k I)` (dimensionless, ≥ 0).
    pub damping_ratio: f64,
    /// Rest test on joint speed: `max |Δθ| / dt` below this (rad/s or m/s), > 0.
    pub speed_tol: f64,
    /// Rest test on the static balance `max |k (q − θ) + f|` (N m or N), > 0.
    pub residual_tol: f64,
    /// Step budget (> 0): settling fails with [`SimError::NotSettled`] when it is used up.
    pub max_steps: usize,
}

impl Default for SettleOptions {
    /// `dt` = 0.1 s, `ζ` = 1, speed below 1e-10 rad/s, residual below 1e-9 N m, at most 10 000 steps.
    fn default() -> Self {
        SettleOptions {
            dt: 0.1,
            damping_ratio: 1.0,
            speed_tol: 1e-10,
            residual_tol: 1e-9,
            max_steps: 10_000,
        }
    }
}

impl SettleOptions {
    /// Checks every setting: finite and in its domain (fails with [`SimError::BadSettleOption`]).
    pub(crate) fn check(&self) -> Result<()> {
        let bad = |field: &str, value: String, problem: &str| SimError::BadSettleOption {
            field: field.into(),
            value,
            problem: problem.into(),
        };
        if !(self.dt.is_finite() && self.dt > 0.0) {
            return Err(bad("dt", self.dt.to_string(), "must be finite and > 0 s"));
        }
        if !(self.damping_ratio.is_finite() && self.damping_ratio >= 0.0) {
            return Err(bad(
                "damping_ratio",
                self.damping_ratio.to_string(),
                "must be finite and ≥ 0",
            ));
        }
        if !(self.speed_tol.is_finite() && self.speed_tol > 0.0) {
            return Err(bad(
                "speed_tol",
                self.speed_tol.to_string(),
                "must be finite and > 0 rad/s",
            ));
        }
        if !(self.residual_tol.is_finite() && self.residual_tol > 0.0) {
            return Err(bad(
                "residual_tol",
                self.residual_tol.to_string(),
                "must be finite and > 0 N m",
            ));
        }
        if self.max_steps == 0 {
            return Err(bad("max_steps", "0".into(), "must be > 0"));
        }
        Ok(())
    }
}
