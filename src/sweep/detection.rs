//! `robocal sweep --score diagnose`: what a run hid and what diagnose named.
//!
//! *Hidden* are the estimator's causes whose simulated effect the run injected with a non-zero size,
//! each at the joints where its size is non-zero (compliance: a finite stiffness; backlash: a dead
//! band > 0; transmission error: an amplitude > 0; link deflection: a bending compliance > 0; thermal
//! drift: no joints, the cause as a whole). Effects the estimator has no cause for (kinematic offsets,
//! which every model fits, joint coupling, coupled transmission error) are not hidden causes.
//!
//! *Named* is the model diagnose adopts, its causes at their joints (`cause@2,4`, or all joints).
//!
//! A run is *detected* when diagnose names exactly the hidden causes, none at a joint where nothing is
//! hidden; it may leave out hidden joints (a compliance at a joint that carries no gravity torque, such
//! as a vertical first joint, cannot be seen). A *false alarm* is a named cause that is not hidden, or
//! one named at a joint where it is not hidden.

use calib::model::extensions::Cause;
use calib::model::spec::ModelSpec;
use sim::effects::Effects;

/// The hidden causes of `effects` on a robot with `nq` joints, as a model specification: each cause
/// at its joints with a non-zero size (at all of them when all are).
pub fn hidden(effects: &Effects, nq: usize) -> ModelSpec {
    let mut spec = ModelSpec::kinematic();
    let mut add = |cause: Cause, nonzero: Vec<bool>| {
        let joints: Vec<usize> = (0..nq).filter(|&j| nonzero.get(j) == Some(&true)).collect();
        if joints.is_empty() {
            return;
        }
        spec = if joints.len() == nq {
            spec.with(cause)
        } else {
            spec.with_joints(cause, Some(&joints))
        };
    };
    if let Some(c) = &effects.compliance {
        add(
            Cause::JointCompliance,
            c.stiffness_nm_per_rad()
                .iter()
                .map(|k| k.is_finite())
                .collect(),
        );
    }
    if let Some(b) = &effects.backlash {
        add(
            Cause::GearBacklash,
            b.dead_band_rad().iter().map(|d| *d > 0.0).collect(),
        );
    }
    if let Some(t) = &effects.transmission {
        add(
            Cause::TransmissionError,
            t.amplitude_rad()
                .iter()
                .map(|a| a.iter().any(|x| *x != 0.0))
                .collect(),
        );
    }
    if let Some(d) = &effects.deflection {
        add(
            Cause::LinkDeflection,
            d.compliance_rad_per_nm()
                .iter()
                .map(|c| c[0] > 0.0 || c[1] > 0.0)
                .collect(),
        );
    }
    if let Some(t) = &effects.thermal
        && (t.alpha_per_k().iter().any(|a| *a != 0.0)
            || t.beta_rad_per_k().iter().any(|b| *b != 0.0))
    {
        spec = spec.with(Cause::ThermalDrift);
    }
    spec
}

/// The 0-based joints `cause` acts at in `spec` (every joint of the robot when not limited).
fn joints(spec: &ModelSpec, cause: Cause, nq: usize) -> Vec<usize> {
    spec.joints_of(cause)
        .map_or_else(|| (0..nq).collect(), <[usize]>::to_vec)
}

/// `(detected, false_alarm)` of `named` against `hidden` on a robot with `nq` joints (module docs).
/// Thermal drift has no joints: it is compared as a cause.
pub fn judge(hidden: &ModelSpec, named: &ModelSpec, nq: usize) -> (bool, bool) {
    let beyond = |c: Cause| {
        c != Cause::ThermalDrift && {
            let h = joints(hidden, c, nq);
            joints(named, c, nq).iter().any(|j| !h.contains(j))
        }
    };
    let false_alarm = named
        .causes
        .iter()
        .any(|c| !hidden.causes.contains(c) || beyond(*c));
    let detected = !false_alarm && hidden.causes.iter().all(|c| named.causes.contains(c));
    (detected, false_alarm)
}

#[cfg(test)]
mod tests {
    use super::*;
    use sim::effects::{gear_backlash::GearBacklash, joint_compliance::JointCompliance};

    #[test]
    fn hidden_causes_are_the_nonzero_effects_at_their_joints() {
        let inf = f64::INFINITY;
        let e = Effects {
            compliance: Some(JointCompliance::new(vec![1e4; 7]).unwrap()),
            backlash: Some(
                GearBacklash::direction(vec![0.0, 4e-4, 0.0, 2e-4, 0.0, 0.0, 0.0]).unwrap(),
            ),
            ..Effects::default()
        };
        assert_eq!(
            hidden(&e, 7).name(),
            "kinematic+joint_compliance+gear_backlash@2,4"
        );
        let rigid = Effects {
            compliance: Some(JointCompliance::new(vec![inf; 7]).unwrap()),
            ..Effects::default()
        };
        assert_eq!(hidden(&rigid, 7).name(), "kinematic");
        assert_eq!(hidden(&Effects::default(), 7).name(), "kinematic");
    }

    #[test]
    fn detection_needs_every_hidden_cause_and_nothing_beyond_its_joints() {
        let m = |s: &str| ModelSpec::parse(s).unwrap();
        let hidden = m("joint_compliance+gear_backlash@2,4");
        // Every cause, joints within the hidden ones (joint 1's compliance left out): detected.
        assert_eq!(
            judge(&hidden, &m("joint_compliance@2,3,4+gear_backlash@2,4"), 7),
            (true, false)
        );
        // A hidden cause missing: neither.
        assert_eq!(judge(&hidden, &m("joint_compliance"), 7), (false, false));
        // Backlash named at joint 5, where none is hidden: a false alarm.
        assert_eq!(
            judge(&hidden, &m("joint_compliance+gear_backlash@2,5"), 7),
            (false, true)
        );
        // A cause not hidden: a false alarm; nothing hidden, nothing named: detected.
        assert_eq!(
            judge(&m("kinematic"), &m("transmission_error"), 7),
            (false, true)
        );
        assert_eq!(judge(&m("kinematic"), &m("kinematic"), 7), (true, false));
    }
}
