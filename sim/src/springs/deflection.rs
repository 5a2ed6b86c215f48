//! Validation and axes of link-deflection compliances, shared by the deflection effect
//! ([`crate::effects::link_deflection`]) and the rapier truth ([`crate::rapier_truth`]), which builds the
//! same bending hinges. A leaf module, so that neither of the two imports the other.

use crate::effect_id::EffectId;
use crate::error::{Result, SimError};
use nalgebra::Vector3;

/// Largest accepted compliance (rad/(N m)): 10⁻³ is already a bearing a few N m bend by a
/// milliradian; more is almost surely a stiffness (N m/rad) given where a compliance is expected.
pub const MAX_COMPLIANCE_RAD_PER_NM: f64 = 1e-3;

/// The deflection axes `(u, v)` of a joint with unit axis `a` (joint frame): `u` is the joint-frame
/// coordinate axis least aligned with `a`, made orthogonal to it, and `v = a × u`.
pub fn deflection_axes(a: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let a = a.normalize();
    let mut k = 0;
    for j in 1..3 {
        if a[j].abs() < a[k].abs() {
            k = j;
        }
    }
    let e = Vector3::ith(k, 1.0);
    let u = (e - a * a.dot(&e)).normalize();
    (u, a.cross(&u))
}

/// Checks compliances `[cᵤ, cᵥ]` per joint (rad/(N m)): finite, ≥ 0 and at most
/// [`MAX_COMPLIANCE_RAD_PER_NM`].
pub(crate) fn check_values(compliance_rad_per_nm: &[[f64; 2]]) -> Result<()> {
    for (i, c) in compliance_rad_per_nm.iter().enumerate() {
        for (k, &v) in c.iter().enumerate() {
            if !(v.is_finite() && v >= 0.0) {
                return Err(SimError::bad_effect(
                    EffectId::LinkDeflection,
                    format!("compliance_rad_per_nm[{i}][{k}]"),
                    v,
                    "must be finite and ≥ 0 rad/(N m) (0 = rigid)",
                ));
            }
            if v > MAX_COMPLIANCE_RAD_PER_NM {
                return Err(SimError::bad_effect(
                    EffectId::LinkDeflection,
                    format!("compliance_rad_per_nm[{i}][{k}]"),
                    v,
                    format!(
                        "compliance above {MAX_COMPLIANCE_RAD_PER_NM} rad/(N m); give a compliance, not a stiffness"
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// Checks that a compliance list has one entry per joint of an `nq`-joint robot.
pub(crate) fn check_len(compliance_rad_per_nm: &[[f64; 2]], nq: usize) -> Result<()> {
    if compliance_rad_per_nm.len() != nq {
        return Err(SimError::bad_effect(
            EffectId::LinkDeflection,
            "compliance_rad_per_nm",
            format!("{} entries", compliance_rad_per_nm.len()),
            format!("the robot has {nq} joints"),
        ));
    }
    Ok(())
}
