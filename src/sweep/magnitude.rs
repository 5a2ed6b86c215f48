//! The magnitude axis of a sweep (`robocal sweep --magnitude LIST [--magnitude-of CAUSE]`): the
//! scenario's injected effects, every number resolved, scaled by a factor `m ≥ 0`.
//!
//! What scaling means for each effect (every size of the effect times `m`, nothing else changed):
//!
//! | effect | scaled | kept |
//! |---|---|---|
//! | `thermal_drift` | link growth α (1/K), joint-zero drift β (rad/K) | reference temperature |
//! | `kinematic_offsets` | joint, base and tool error twists (rad, m), zero offsets (rad) | |
//! | `transmission_error` | amplitudes (rad) | harmonic orders, phases |
//! | `joint_coupling` | ratios (rad/rad) | pairs |
//! | `coupled_transmission_error` | amplitudes (rad) | pairs, orders, phases |
//! | `gear_backlash` | dead bands (rad) | flank rule, torque thresholds (N m) |
//! | `joint_compliance` | compliance `1/k` (stiffness `k` divided by `m`, N m/rad) | rigid joints |
//! | `link_deflection` | bending compliances (rad/(N m)) | |
//!
//! `m = 0` removes the effect (it is absent, as if its section were not in the scenario), so that the
//! truth has no such effect at all; `m = 1` is the scenario as written. A scaled effect goes through
//! its constructor's checks again: a factor that drives it beyond what the simulator accepts (a dead
//! band above 0.1 rad, say) is an error naming the effect.

use crate::error::CliError;
use sim::effects::{
    EffectId, Effects, coupled_transmission::CoupledTransmission, gear_backlash::BacklashMode,
    gear_backlash::GearBacklash, joint_compliance::JointCompliance, joint_coupling::JointCoupling,
    kinematic_offsets::KinematicOffsets, link_deflection::LinkDeflection,
    thermal_drift::ThermalDrift, transmission_error::TransmissionError,
};

/// The effect named `word`: its name (`gear_backlash`) or its scenario key (`backlash`).
pub fn effect_named(word: &str) -> Option<EffectId> {
    EffectId::ALL
        .iter()
        .copied()
        .find(|e| e.name() == word || e.key() == word)
}

/// The names of every effect, for error messages.
pub fn effect_names() -> String {
    EffectId::ALL
        .iter()
        .map(|e| e.name())
        .collect::<Vec<_>>()
        .join(", ")
}

fn times(v: &[f64], m: f64) -> Vec<f64> {
    v.iter().map(|x| x * m).collect()
}

/// `effects` with every effect (or only `only`) scaled by `m ≥ 0` (see the module docs); `m = 0`
/// removes it. Errors when a scaled effect is refused by its constructor.
pub fn scaled(effects: &Effects, m: f64, only: Option<EffectId>) -> Result<Effects, CliError> {
    let mut out = effects.clone();
    let applies = |id: EffectId| only.is_none_or(|o| o == id);
    let err = |id: EffectId, e: sim::SimError| {
        CliError::Input(format!("--magnitude {m}: {} scaled: {e}", id.name()))
    };
    macro_rules! scale {
        ($key:ident, $id:expr, |$e:ident| $body:expr) => {
            if applies($id) {
                out.$key = match (&effects.$key, m == 0.0) {
                    (Some(_), true) | (None, _) => None,
                    (Some($e), false) => Some($body.map_err(|e| err($id, e))?),
                };
            }
        };
    }
    scale!(thermal, EffectId::ThermalDrift, |e| ThermalDrift::new(
        e.t_ref_c(),
        times(e.alpha_per_k(), m),
        times(e.beta_rad_per_k(), m)
    ));
    scale!(kinematic, EffectId::KinematicOffsets, |e| {
        let tw = |t: [f64; 6]| t.map(|x| x * m);
        KinematicOffsets::new(
            e.joint_twists().iter().map(|t| tw(*t)).collect(),
            times(e.zero_offsets(), m),
            tw(e.base_twist()),
            tw(e.tool_twist()),
        )
    });
    scale!(transmission, EffectId::TransmissionError, |e| {
        TransmissionError::new(
            e.harmonics().to_vec(),
            e.amplitude_rad().iter().map(|a| times(a, m)).collect(),
            e.phase_rad().to_vec(),
        )
    });
    scale!(coupling, EffectId::JointCoupling, |e| {
        let mut terms = e.terms().to_vec();
        terms.iter_mut().for_each(|t| t.ratio_rad_per_rad *= m);
        JointCoupling::new(terms)
    });
    scale!(coupled_transmission, EffectId::CoupledTransmission, |e| {
        let mut terms = e.terms().to_vec();
        terms.iter_mut().for_each(|t| t.amplitude_rad *= m);
        CoupledTransmission::new(terms)
    });
    scale!(backlash, EffectId::GearBacklash, |e| match e.mode() {
        BacklashMode::Direction => GearBacklash::direction(times(e.dead_band_rad(), m)),
        BacklashMode::Gravity => {
            GearBacklash::gravity(times(e.dead_band_rad(), m), e.threshold_nm().to_vec())
        }
    });
    scale!(compliance, EffectId::JointCompliance, |e| {
        JointCompliance::new(e.stiffness_nm_per_rad().iter().map(|k| k / m).collect())
    });
    scale!(deflection, EffectId::LinkDeflection, |e| {
        LinkDeflection::new(
            e.compliance_rad_per_nm()
                .iter()
                .map(|c| [c[0] * m, c[1] * m])
                .collect(),
        )
    });
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn effects() -> Effects {
        Effects {
            compliance: Some(JointCompliance::new(vec![f64::INFINITY, 1e4, 5e3]).unwrap()),
            backlash: Some(GearBacklash::direction(vec![0.0, 4e-4, 2e-4]).unwrap()),
            ..Effects::default()
        }
    }

    #[test]
    fn scaling_multiplies_sizes_and_zero_removes_the_effect() {
        let e = effects();
        let two = scaled(&e, 2.0, None).unwrap();
        assert_eq!(
            two.compliance.as_ref().unwrap().stiffness_nm_per_rad(),
            &[f64::INFINITY, 5e3, 2.5e3]
        );
        assert_eq!(
            two.backlash.as_ref().unwrap().dead_band_rad(),
            &[0.0, 8e-4, 4e-4]
        );
        assert_eq!(scaled(&e, 1.0, None).unwrap(), e);
        let none = scaled(&e, 0.0, None).unwrap();
        assert_eq!(none, Effects::default());
        let only = scaled(&e, 0.0, Some(EffectId::GearBacklash)).unwrap();
        assert!(only.backlash.is_none());
        assert_eq!(only.compliance, e.compliance);
    }

    #[test]
    fn effects_are_named_by_name_or_key() {
        assert_eq!(effect_named("gear_backlash"), Some(EffectId::GearBacklash));
        assert_eq!(effect_named("backlash"), Some(EffectId::GearBacklash));
        assert_eq!(
            effect_named("joint_compliance"),
            Some(EffectId::JointCompliance)
        );
        assert_eq!(effect_named("stiffness"), None);
        assert!(effect_names().contains("link_deflection"));
    }
}
