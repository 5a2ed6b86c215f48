//! Gear backlash, as the estimator models it: `θᵢ = qᵢ − sᵢ hᵢ`.
//!
//! `hᵢ` is half of joint `i`'s lost motion (rad; m for a prismatic joint) and `sᵢ` the side of the dead
//! band the link rests on: the sign of the joint's last motion (`dir` column; the link lags the motor),
//! or, without `dir` columns, the sign of the holding torque `τᵢ` (gravity pulls the link against its
//! holding torque, onto the loaded flank). A joint always approached from the same side cannot be told
//! from a zero offset; the solver reports that and leaves `hᵢ` at zero.

use super::{BacklashSign, Cause, ExtensionParam, per_joint_params};
use sim::Model;

/// Expected half lost motion (rad): harmonic drives have about 1 arc-min (2.9e-4 rad) of lost motion.
pub const SCALE_RAD: f64 = 1e-4;

/// One half-lost-motion per joint.
pub fn params(model: &Model) -> Vec<ExtensionParam> {
    per_joint_params(
        model,
        Cause::GearBacklash,
        "half lost motion",
        "rad",
        "m",
        SCALE_RAD,
    )
}

/// Regressors `−sᵢ` (−1, 0 or +1) of one row, from its approach signs `dir` or its holding torques
/// `tau` (N m), as `sign` says.
pub fn regressors(sign: BacklashSign, dir: Option<&[i8]>, tau: &[f64], out: &mut [f64]) {
    match (sign, dir) {
        (BacklashSign::Direction, Some(d)) => {
            for (o, &s) in out.iter_mut().zip(d) {
                *o = -f64::from(s);
            }
        }
        _ => {
            for (o, &t) in out.iter_mut().zip(tau) {
                *o = if t > 0.0 {
                    -1.0
                } else if t < 0.0 {
                    1.0
                } else {
                    0.0
                };
            }
        }
    }
}
