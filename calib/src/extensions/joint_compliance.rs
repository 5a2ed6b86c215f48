//! Joint compliance, as the estimator models it: `θᵢ = qᵢ − cᵢ τᵢ(q)`.
//!
//! `cᵢ` is joint `i`'s compliance (rad/(N m); m/N for a prismatic joint) and `τᵢ(q)` the torque (N m)
//! the joint applies to hold the nominal arm and the payload still at the commanded `q` against gravity
//! ([`sim::statics::gravity_torques`]). This is the first-order solution of the spring balance
//! `K (q − θ) = τ(θ)`; the exact one differs by `C H C τ` (`H = ∂τ/∂θ`), second order in the compliance:
//! below 0.1 µrad for the iiwa 7's 1e-4 rad/(N m) and 50 N m.
//! A joint whose torque does not change over the data (joint 1 of an upright arm) cannot be identified;
//! the solver says so and leaves its compliance at zero.

use super::{Cause, ExtensionParam, per_joint_params};
use sim::Model;

/// Expected compliance (rad/(N m)): harmonic-drive joints of lightweight arms are 5e3–2e4 N m/rad.
pub const SCALE_RAD_PER_NM: f64 = 1e-4;

/// One compliance per joint.
pub fn params(model: &Model) -> Vec<ExtensionParam> {
    per_joint_params(
        model,
        Cause::JointCompliance,
        "compliance",
        "rad/(N m)",
        "m/N",
        SCALE_RAD_PER_NM,
    )
}

/// Regressors `−τᵢ` (N m) of one row from its gravity torques `tau` (N m, one per joint).
pub fn regressors(tau: &[f64], out: &mut [f64]) {
    for (o, t) in out.iter_mut().zip(tau) {
        *o = -t;
    }
}
