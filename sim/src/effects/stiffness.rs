//! Validation of joint-spring stiffness lists, shared by the compliance effect
//! ([`super::joint_compliance`]) and the rapier truth ([`crate::rapier_truth`]).

use crate::error::{Result, SimError};

/// Effect name in the errors.
pub(crate) const EFFECT: &str = "joint_compliance";

/// A [`SimError::BadEffect`] of the compliance effect.
pub(crate) fn bad(
    field: impl Into<String>,
    value: impl ToString,
    problem: impl Into<String>,
) -> SimError {
    SimError::BadEffect {
        effect: EFFECT,
        field: field.into(),
        value: value.to_string(),
        problem: problem.into(),
    }
}

/// Checks a stiffness list (N m/rad or N/m): every entry > 0, `f64::INFINITY` for a rigid joint.
pub(crate) fn check_values(stiffness_nm_per_rad: &[f64]) -> Result<()> {
    for (i, &k) in stiffness_nm_per_rad.iter().enumerate() {
        if k.is_nan() || k <= 0.0 {
            return Err(bad(
                format!("stiffness_nm_per_rad[{i}]"),
                k,
                "must be > 0 N m/rad (inf = rigid)",
            ));
        }
    }
    Ok(())
}

/// Checks that a stiffness list has one entry per joint of an `nq`-joint robot.
pub(crate) fn check_len(stiffness_nm_per_rad: &[f64], nq: usize) -> Result<()> {
    if stiffness_nm_per_rad.len() != nq {
        return Err(bad(
            "stiffness_nm_per_rad",
            format!("{} entries", stiffness_nm_per_rad.len()),
            format!("the robot has {nq} joints"),
        ));
    }
    Ok(())
}
