//! `robocal sweep --score diagnose`: what a run hid and what diagnose named.
//!
//! *Hidden* are the estimator's causes whose simulated effect the run injected with a non-zero size,
//! each at the joints where its size is non-zero (compliance: a finite stiffness; backlash: a dead
//! band > 0; transmission error: an amplitude > 0; link deflection: a bending compliance > 0; thermal
//! drift: no joints, the cause as a whole). Effects the estimator has no cause for (kinematic offsets,
//! which every model fits, joint coupling, coupled transmission error) are not hidden causes.
//! Bending about an axis that is the next joint's axis line is that joint's compliance to any
//! measurement, and the estimator names it so (one error, one name:
//! [`calib::model::extensions::link_deflection::aliased_with_next_joint`]): it is hidden as
//! compliance at the next joint.
//!
//! *Named* are diagnose's findings, each cause at the joints it names (the joints whose parameters
//! differ from zero on their own, `cause@2,4`, every one listed), not the joints of the model it
//! fits: diagnose fits a cause at every joint it does not drop, and names those the data show. A
//! finding with no joint significant on its own names the cause at no joint in particular (`cause`
//! without `@`).
//!
//! A run is *detected* when diagnose names exactly the hidden causes, none at a joint where nothing is
//! hidden (the allowed compliance above aside); it may leave out hidden joints (a compliance at a joint that carries no gravity torque, such
//! as a vertical first joint, cannot be seen). A *false alarm* is a named cause that is not hidden, or
//! one named at a joint where it is not hidden.

use calib::model::extensions::{Cause, link_deflection};
use calib::model::spec::ModelSpec;
use calib::select::diagnose::Diagnosis;
use nalgebra::Vector3;
use sim::effects::Effects;

/// What a run hid, for the judge: the causes diagnose must name, and the causes at joints it may
/// name without a false alarm.
#[derive(Clone, Debug, PartialEq)]
pub struct Hidden {
    /// Each hidden cause at its joints with a non-zero size (the `hidden` column).
    pub required: ModelSpec,
    /// `required`, and compliance at the joint after each joint that bends about that joint's axis
    /// line (the estimator models that bend as the next joint's compliance, and diagnose may fit it
    /// beside the deflection it names).
    pub allowed: ModelSpec,
}

/// The hidden causes of `effects` on a robot with joints `joints` under gravity `gravity` (base
/// frame, m/s²), each cause at its joints with a non-zero size (at all of them when all are). A bend
/// about the next joint's axis line is that joint's compliance: required as compliance when the
/// joint bends about no other axis, allowed as compliance besides its deflection when it does.
pub fn hidden(effects: &Effects, joints: &[sim::Joint], gravity: &Vector3<f64>) -> Hidden {
    let nq = joints.len();
    // Bending per joint, split into what the estimator calls deflection and what it calls the
    // next joint's compliance.
    let mut bends = vec![false; nq];
    let mut aliased = vec![false; nq];
    if let Some(d) = &effects.deflection {
        for (i, c) in d.compliance_rad_per_nm().iter().enumerate().take(nq) {
            let Some(axes) = link_deflection::bending_axes(&joints[i].axis) else {
                bends[i] |= c[0] > 0.0 || c[1] > 0.0;
                continue;
            };
            for (slot, about) in axes.into_iter().enumerate() {
                if c[slot] <= 0.0 {
                    continue;
                }
                if link_deflection::aliased_with_next_joint(joints, i, about, gravity) {
                    aliased[i] = true;
                } else {
                    bends[i] = true;
                }
            }
        }
    }
    let stiff: Vec<bool> = match &effects.compliance {
        Some(c) => c
            .stiffness_nm_per_rad()
            .iter()
            .map(|k| k.is_finite())
            .collect(),
        None => vec![false; nq],
    };
    // Compliance at joint j: hidden, or the bend of joint j − 1 about j's axis.
    let compliance = |also: &dyn Fn(usize) -> bool| -> Vec<bool> {
        (0..nq)
            .map(|j| stiff.get(j) == Some(&true) || (j > 0 && also(j - 1)))
            .collect()
    };
    let mut others: Vec<(Cause, Vec<bool>)> = Vec::new();
    if let Some(b) = &effects.backlash {
        others.push((
            Cause::GearBacklash,
            b.dead_band_rad().iter().map(|d| *d > 0.0).collect(),
        ));
    }
    if let Some(t) = &effects.transmission {
        others.push((
            Cause::TransmissionError,
            t.amplitude_rad()
                .iter()
                .map(|a| a.iter().any(|x| *x != 0.0))
                .collect(),
        ));
    }
    others.push((Cause::LinkDeflection, bends.clone()));
    let thermal = effects.thermal.as_ref().is_some_and(|t| {
        t.alpha_per_k().iter().any(|a| *a != 0.0) || t.beta_rad_per_k().iter().any(|b| *b != 0.0)
    });
    let spec_of = |compliance: Vec<bool>| -> ModelSpec {
        let mut spec = ModelSpec::kinematic();
        let causes = std::iter::once((Cause::JointCompliance, compliance)).chain(others.clone());
        for (cause, nonzero) in causes {
            let at: Vec<usize> = (0..nq).filter(|&j| nonzero.get(j) == Some(&true)).collect();
            if at.is_empty() {
                continue;
            }
            spec = if at.len() == nq {
                spec.with(cause)
            } else {
                spec.with_joints(cause, Some(&at))
            };
        }
        if thermal {
            spec = spec.with(Cause::ThermalDrift);
        }
        spec
    };
    Hidden {
        required: spec_of(compliance(&|i| aliased[i] && !bends[i])),
        allowed: spec_of(compliance(&|i| aliased[i])),
    }
}

/// What diagnose named: each finding's cause with the 0-based joints it names (those whose
/// parameters differ from zero on their own; empty when the cause as a whole is significant but no
/// joint of it on its own, and for thermal drift).
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Named {
    /// Cause and named joints, in the findings' order.
    pub causes: Vec<(Cause, Vec<usize>)>,
}

impl Named {
    /// What `d` names (module docs).
    pub fn of(d: &Diagnosis) -> Named {
        Named {
            causes: d
                .findings
                .iter()
                .map(|f| {
                    let at = f
                        .joints
                        .iter()
                        .filter(|&&j| j >= 1)
                        .map(|j| j - 1)
                        .collect();
                    (f.cause, at)
                })
                .collect(),
        }
    }

    /// The `named` column: `kinematic`, then `+cause@J,K` per finding with its named joints
    /// (1-based, all listed), or `+cause` when it names none.
    pub fn name(&self) -> String {
        let mut s = String::from("kinematic");
        for (c, at) in &self.causes {
            s.push('+');
            s.push_str(c.name());
            if !at.is_empty() {
                let list: Vec<String> = at.iter().map(|j| (j + 1).to_string()).collect();
                s.push('@');
                s.push_str(&list.join(","));
            }
        }
        s
    }
}

/// The 0-based joints `cause` acts at in `spec` (every joint of the robot when not limited).
fn joints(spec: &ModelSpec, cause: Cause, nq: usize) -> Vec<usize> {
    spec.joints_of(cause)
        .map_or_else(|| (0..nq).collect(), <[usize]>::to_vec)
}

/// `(detected, false_alarm)` of `named` against `hidden` on a robot with `nq` joints (module docs):
/// a false alarm names a cause, or a joint of one, beyond `hidden.allowed`; a detection has none and
/// names every cause of `hidden.required` (at some of its joints, or at none in particular).
pub fn judge(hidden: &Hidden, named: &Named, nq: usize) -> (bool, bool) {
    let allowed = &hidden.allowed;
    let false_alarm = named.causes.iter().any(|(c, at)| {
        !allowed.causes.contains(c) || {
            let h = joints(allowed, *c, nq);
            at.iter().any(|j| !h.contains(j))
        }
    });
    let detected = !false_alarm
        && hidden
            .required
            .causes
            .iter()
            .all(|c| named.causes.iter().any(|(n, _)| n == c));
    (detected, false_alarm)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Effects of link deflection alone, with bending compliances `c` (rad/(N m), per joint about
    /// its frame's two bending axes).
    fn bending(c: [[f64; 2]; 7]) -> Effects {
        Effects {
            deflection: Some(
                sim::effects::link_deflection::LinkDeflection::new(c.to_vec()).unwrap(),
            ),
            ..Effects::default()
        }
    }

    /// Every cause of `spec` at its joints (all of them when it is not limited), as named.
    fn of_spec(spec: &ModelSpec, nq: usize) -> Named {
        Named {
            causes: spec
                .causes
                .iter()
                .map(|&c| {
                    let at = if c == Cause::ThermalDrift {
                        Vec::new()
                    } else {
                        joints(spec, c, nq)
                    };
                    (c, at)
                })
                .collect(),
        }
    }

    use sim::effects::{gear_backlash::GearBacklash, joint_compliance::JointCompliance};

    #[test]
    fn hidden_causes_are_the_nonzero_effects_at_their_joints() {
        let iiwa = sim::robots::load_builtin("iiwa7").unwrap();
        let g = Vector3::from(sim::statics::DEFAULT_GRAVITY);
        let inf = f64::INFINITY;
        let e = Effects {
            compliance: Some(JointCompliance::new(vec![1e4; 7]).unwrap()),
            backlash: Some(
                GearBacklash::direction(vec![0.0, 4e-4, 0.0, 2e-4, 0.0, 0.0, 0.0]).unwrap(),
            ),
            ..Effects::default()
        };
        assert_eq!(
            hidden(&e, iiwa.joints(), &g).required.name(),
            "kinematic+joint_compliance+gear_backlash@2,4"
        );
        let rigid = Effects {
            compliance: Some(JointCompliance::new(vec![inf; 7]).unwrap()),
            ..Effects::default()
        };
        assert_eq!(
            hidden(&rigid, iiwa.joints(), &g).required.name(),
            "kinematic"
        );
        assert_eq!(
            hidden(&Effects::default(), iiwa.joints(), &g)
                .required
                .name(),
            "kinematic"
        );
    }

    /// Bending of joints 2 and 4 about z (their frames' z axes run along the upper arm and the
    /// forearm, the axes of joints 3 and 5) is compliance of joints 3 and 5: allowed beside the
    /// deflection the joints' x bends require (`scenarios/iiwa7_deflection.toml`'s layout), required
    /// when a joint bends about that axis alone.
    #[test]
    fn a_bend_about_the_next_joints_axis_is_hidden_as_its_compliance() {
        let iiwa = sim::robots::load_builtin("iiwa7").unwrap();
        let g = Vector3::from(sim::statics::DEFAULT_GRAVITY);
        let c = 3e-6;
        let e = bending([
            [0.0, 0.0],
            [c, c],
            [0.0, 0.0],
            [c, c],
            [0.0, 0.0],
            [c, c],
            [0.0, 0.0],
        ]);
        let h = hidden(&e, iiwa.joints(), &g);
        assert_eq!(h.required.name(), "kinematic+link_deflection@2,4,6");
        assert_eq!(
            h.allowed.name(),
            "kinematic+joint_compliance@3,5+link_deflection@2,4,6"
        );
        // Joint 2 about x alone: deflection only.
        let e = bending([
            [0.0, 0.0],
            [c, 0.0],
            [0.0, 0.0],
            [0.0, 0.0],
            [0.0, 0.0],
            [0.0, 0.0],
            [0.0, 0.0],
        ]);
        let h = hidden(&e, iiwa.joints(), &g);
        assert_eq!(h.required, h.allowed);
        assert_eq!(h.required.name(), "kinematic+link_deflection@2");
        // Joint 2 about z alone: that is joint 3's compliance, required as such.
        let e = bending([
            [0.0, 0.0],
            [0.0, c],
            [0.0, 0.0],
            [0.0, 0.0],
            [0.0, 0.0],
            [0.0, 0.0],
            [0.0, 0.0],
        ]);
        let h = hidden(&e, iiwa.joints(), &g);
        assert_eq!(h.required, h.allowed);
        assert_eq!(h.required.name(), "kinematic+joint_compliance@3");
    }

    #[test]
    fn detection_needs_every_hidden_cause_and_nothing_beyond_its_joints() {
        let m = |s: &str| ModelSpec::parse(s).unwrap();
        let n = |s: &str| of_spec(&ModelSpec::parse(s).unwrap(), 7);
        let exactly = |s: &str| Hidden {
            required: m(s),
            allowed: m(s),
        };
        let hidden = exactly("joint_compliance+gear_backlash@2,4");
        // Every cause, joints within the hidden ones (joint 1's compliance left out): detected.
        assert_eq!(
            judge(&hidden, &n("joint_compliance@2,3,4+gear_backlash@2,4"), 7),
            (true, false)
        );
        // A hidden cause missing: neither.
        assert_eq!(judge(&hidden, &n("joint_compliance"), 7), (false, false));
        // Backlash named at joint 5, where none is hidden: a false alarm.
        assert_eq!(
            judge(&hidden, &n("joint_compliance+gear_backlash@2,5"), 7),
            (false, true)
        );
        // A cause not hidden: a false alarm; nothing hidden, nothing named: detected.
        assert_eq!(
            judge(&exactly("kinematic"), &n("transmission_error"), 7),
            (false, true)
        );
        assert_eq!(
            judge(&exactly("kinematic"), &n("kinematic"), 7),
            (true, false)
        );
        // Compliance allowed beside a deflection (a bend about the next joint's axis), not
        // required: naming the deflection alone, or with that compliance, is a detection; with
        // compliance elsewhere, a false alarm.
        let bend = Hidden {
            required: m("link_deflection@2"),
            allowed: m("joint_compliance@3+link_deflection@2"),
        };
        assert_eq!(judge(&bend, &n("link_deflection@2"), 7), (true, false));
        // A finding that names no joint in particular: the cause named, no joint beyond.
        let unlocated = Named {
            causes: vec![(Cause::LinkDeflection, Vec::new())],
        };
        assert_eq!(unlocated.name(), "kinematic+link_deflection");
        assert_eq!(judge(&bend, &unlocated, 7), (true, false));
        assert_eq!(
            n("joint_compliance+gear_backlash@2,4").name(),
            "kinematic+joint_compliance@1,2,3,4,5,6,7+gear_backlash@2,4"
        );
        assert_eq!(
            judge(&bend, &n("joint_compliance@3+link_deflection@2"), 7),
            (true, false)
        );
        assert_eq!(
            judge(&bend, &n("joint_compliance@4+link_deflection@2"), 7),
            (false, true)
        );
    }
}
