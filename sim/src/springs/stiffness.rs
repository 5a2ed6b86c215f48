//! Validation of joint-spring stiffness lists, shared by the compliance effect
//! ([`crate::effects::joint_compliance`]) and the rapier truth ([`crate::rapier_truth`]).

use crate::effect_id::EffectId;
use crate::error::{Result, SimError};

/// Checks a stiffness list (N m/rad or N/m): every entry > 0, `f64::INFINITY` for a rigid joint.
pub(crate) fn check_values(stiffness_nm_per_rad: &[f64]) -> Result<()> {
    for (i, &k) in stiffness_nm_per_rad.iter().enumerate() {
        if k.is_nan() || k <= 0.0 {
            return Err(SimError::bad_effect(
                EffectId::JointCompliance,
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
        return Err(SimError::bad_effect(
            EffectId::JointCompliance,
            "stiffness_nm_per_rad",
            format!("{} entries", stiffness_nm_per_rad.len()),
            format!("the robot has {nq} joints"),
        ));
    }
    Ok(())
}
