//! The simulator's truth in the estimator's parameters: what value each extension parameter of a
//! calibrated model (named as in the model file, `joint 2 compliance`) should have for the effects a
//! run injected (the scenario's resolved effects, as `robocal generate` writes them to `truth.json`).
//!
//! The simulator and the estimator write each cause in their own terms (CONTRIBUTING.md: they share
//! no code), so the mapping is stated here, cause by cause, as `calib/tests/extensions.rs` checks it:
//!
//! | cause | estimator parameter | truth |
//! |---|---|---|
//! | `joint_compliance` | `joint i compliance` (rad/(N m)) | `1/kᵢ` (0 for a rigid joint) |
//! | `gear_backlash` | `joint i half lost motion` (rad) | half the dead band `bᵢ/2`, when both sides take the flank from the approach direction |
//! | `transmission_error` | `joint i transmission error sin kq`, `cos kq` (rad) | `A cos φ`, `A sin φ` of the simulator's `A sin(k q + φ)` (0 for a harmonic it lacks) |
//! | `link_deflection` | `joint i bending compliance about x/y/z` (rad/(N m)) | `cᵤ` or `cᵥ`, whichever of the simulator's axes `u`, `v` is that axis |
//! | `thermal_drift` | `link growth`, `joint i zero drift` | not mapped (the simulator grows each link by its own α, the estimator the arm by one) |
//!
//! A cause the run did not inject has the truth 0 for every parameter (the effect is absent). Where
//! no mapping holds (thermal drift injected, backlash with the gravity flank rule on either side, a
//! bending axis that is not one of the simulator's), the truth is `None` and the parameter's `z` is
//! left empty (NaN), never guessed.

use calib::model::extensions::{BacklashSign, Cause, ExtensionParam, ExtensionSettings, Term};
use sim::effects::Effects;
use sim::effects::gear_backlash::BacklashMode;

/// The true value of `p` (its unit) under the injected `effects` on `model`, with the estimator's
/// `settings`; `None` when the simulator's effect cannot be written in this parameter (module docs).
pub fn truth_of(
    model: &sim::Model,
    effects: &Effects,
    settings: &ExtensionSettings,
    p: &ExtensionParam,
) -> Option<f64> {
    match p.cause {
        Cause::JointCompliance => {
            let joint = p.term.joint()?;
            let Some(c) = &effects.compliance else {
                return Some(0.0);
            };
            let k = *c.stiffness_nm_per_rad().get(joint)?;
            Some(if k.is_infinite() { 0.0 } else { 1.0 / k })
        }
        Cause::GearBacklash => {
            let joint = p.term.joint()?;
            let Some(b) = &effects.backlash else {
                return Some(0.0);
            };
            let same_rule = b.mode() == BacklashMode::Direction
                && settings.backlash_sign == BacklashSign::Direction;
            same_rule.then_some(*b.dead_band_rad().get(joint)? / 2.0)
        }
        Cause::TransmissionError => {
            let joint = p.term.joint()?;
            let Some(t) = &effects.transmission else {
                return Some(0.0);
            };
            let rest = p.quantity.strip_prefix("transmission error ")?;
            let (func, arg) = rest.split_once(' ')?;
            let order: u32 = match arg.strip_suffix('q')? {
                "" => 1,
                n => n.parse().ok()?,
            };
            let Some(h) = t.harmonics().iter().position(|&k| k == order) else {
                return Some(0.0);
            };
            let a = *t.amplitude_rad().get(joint)?.get(h)?;
            let phi = *t.phase_rad().get(joint)?.get(h)?;
            match func {
                "sin" => Some(a * phi.cos()),
                "cos" => Some(a * phi.sin()),
                _ => None,
            }
        }
        Cause::LinkDeflection => {
            let Term::Bend { joint, about } = p.term else {
                return None;
            };
            let Some(d) = &effects.deflection else {
                return Some(0.0);
            };
            let c = *d.compliance_rad_per_nm().get(joint)?;
            let axis = model.joints().get(joint)?.axis;
            let (u, v) = sim::effects::link_deflection::deflection_axes(&axis);
            let e = nalgebra::Vector3::ith(about, 1.0);
            if u.dot(&e).abs() > 1.0 - 1e-9 {
                Some(c[0])
            } else if v.dot(&e).abs() > 1.0 - 1e-9 {
                Some(c[1])
            } else {
                None
            }
        }
        Cause::ThermalDrift => effects.thermal.is_none().then_some(0.0),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use calib::model::extensions::ThermalInput;
    use sim::effects::{
        gear_backlash::GearBacklash, joint_compliance::JointCompliance,
        link_deflection::LinkDeflection, transmission_error::TransmissionError,
    };

    fn settings(model: &sim::Model) -> ExtensionSettings {
        ExtensionSettings {
            causes: Cause::ALL.to_vec(),
            gravity_base: sim::statics::DEFAULT_GRAVITY,
            payload_com_m: [0.0; 3],
            backlash_sign: BacklashSign::Direction,
            thermal: Some(ThermalInput::Temperature { t_ref_c: 20.0 }),
            transmission_joints: (0..model.nq()).collect(),
            joints: Default::default(),
            lumped_gravity: None,
        }
    }

    /// Every parameter of every cause on the iiwa 7 gets a truth (0 without effects), and the
    /// injected values land where `calib/tests/extensions.rs` expects them.
    #[test]
    fn injected_values_map_to_the_estimators_parameters() {
        let model = sim::robots::load_builtin("iiwa7").unwrap();
        let s = settings(&model);
        let params = s.params(&model);
        for p in &params {
            assert_eq!(
                truth_of(&model, &Effects::default(), &s, p),
                Some(0.0),
                "{}",
                p.name()
            );
        }
        let inf = f64::INFINITY;
        let mut amp = vec![vec![0.0; 2]; 7];
        let mut phase = vec![vec![0.0; 2]; 7];
        amp[2] = vec![1e-4, 2e-5];
        phase[2] = vec![0.5, -1.0];
        let mut c = vec![[0.0; 2]; 7];
        c[2] = [3e-6, 4e-6];
        c[1] = [1e-6, 2e-6];
        let effects = Effects {
            compliance: Some(
                JointCompliance::new(vec![inf, 1e4, inf, 8e3, inf, inf, inf]).unwrap(),
            ),
            backlash: Some(
                GearBacklash::direction(vec![0.0, 0.0, 0.0, 0.0, 6e-4, 0.0, 0.0]).unwrap(),
            ),
            transmission: Some(TransmissionError::new(vec![1, 3], amp, phase).unwrap()),
            deflection: Some(LinkDeflection::new(c).unwrap()),
            ..Effects::default()
        };
        let truth = |name: &str| {
            let p = params.iter().find(|p| p.name() == name).unwrap();
            truth_of(&model, &effects, &s, p)
        };
        assert_eq!(truth("joint 2 compliance"), Some(1e-4));
        assert_eq!(truth("joint 1 compliance"), Some(0.0));
        assert_eq!(truth("joint 5 half lost motion"), Some(3e-4));
        assert_eq!(
            truth("joint 3 transmission error sin q"),
            Some(1e-4 * 0.5f64.cos())
        );
        assert_eq!(
            truth("joint 3 transmission error cos 3q"),
            Some(2e-5 * (-1.0f64).sin())
        );
        assert_eq!(truth("joint 3 transmission error sin 2q"), Some(0.0));
        assert_eq!(truth("joint 3 bending compliance about x"), Some(3e-6));
        assert_eq!(truth("joint 3 bending compliance about y"), Some(4e-6));
        // Joint 2 turns about y: its v axis is ∓z.
        if let Some(p) = params
            .iter()
            .find(|p| p.name() == "joint 2 bending compliance about z")
        {
            assert_eq!(truth_of(&model, &effects, &s, p), Some(2e-6));
        }
        // Backlash under the gravity rule has no mapping.
        let gravity = Effects {
            backlash: Some(GearBacklash::gravity_uniform(vec![6e-4; 7], 1.0).unwrap()),
            ..Effects::default()
        };
        let p = params
            .iter()
            .find(|p| p.name() == "joint 5 half lost motion")
            .unwrap();
        assert_eq!(truth_of(&model, &gravity, &s, p), None);
    }
}
