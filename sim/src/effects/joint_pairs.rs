//! What the two effects driven by another joint's angle share ([`super::joint_coupling`],
//! [`super::coupled_transmission`]): terms that name a `joint` and a `source` joint (1-based), their
//! checks, and the translation of the constructor's field names into the scenario section's keys.

use crate::effect_id::EffectId;
use crate::error::{Result, SimError};

/// Checks that term `k`'s `joint` and `source` are numbered from 1.
pub(crate) fn check_numbered(
    effect: EffectId,
    k: usize,
    joint: usize,
    source: usize,
) -> Result<()> {
    for (name, j) in [("joint", joint), ("source", source)] {
        if j == 0 {
            return Err(SimError::bad_effect(
                effect,
                format!("terms[{k}].{name}"),
                0,
                "joints are numbered from 1",
            ));
        }
    }
    Ok(())
}

/// Checks that every term's `(joint, source)` fits a robot with `nq` joints.
pub(crate) fn check_fits(
    effect: EffectId,
    pairs: impl IntoIterator<Item = (usize, usize)>,
    nq: usize,
) -> Result<()> {
    for (k, (joint, source)) in pairs.into_iter().enumerate() {
        for (name, j) in [("joint", joint), ("source", source)] {
            if j > nq {
                return Err(SimError::bad_effect(
                    effect,
                    format!("terms[{k}].{name}"),
                    j,
                    format!("the robot has {nq} joints"),
                ));
            }
        }
    }
    Ok(())
}

/// The constructor's field `terms[k].joint`, `.source` or `terms[k]` as the scenario section writes
/// it (`pairs[k]`), and `terms[k].NAME` for `NAME` in `value_fields` as `NAME[k]`.
pub(crate) fn section_field(e: SimError, value_fields: &[&str]) -> SimError {
    match e {
        SimError::BadEffect {
            effect,
            field,
            value,
            problem,
        } => {
            let (index, rest) = field
                .strip_prefix("terms[")
                .and_then(|f| f.split_once(']'))
                .unwrap_or(("", ""));
            let field = match rest.strip_prefix('.') {
                Some(name) if value_fields.contains(&name) => format!("{name}[{index}]"),
                _ if !index.is_empty() => format!("pairs[{index}]"),
                _ => field,
            };
            SimError::BadEffect {
                effect,
                field,
                value,
                problem,
            }
        }
        other => other,
    }
}
