//! Coupled transmission error: a link angle error periodic in the angle of *another* joint.
//!
//! # Model
//!
//! A list of terms `(i, j, h, A, φ)` with `j ≠ i`: the link of joint `i` sits at
//!
//! ```text
//! θᵢ = qᵢ + Σ A sin(h qⱼ + φ)
//! ```
//!
//! with `qⱼ` the reported angle of joint `j` ([`super::Conditions::q`]), `h` a whole number of cycles
//! per revolution of joint `j`, `A` (rad) and `φ` (rad). Joints are numbered from 1.
//!
//! It stands for the drive train of a joint that passes through another one: wrists whose last axes
//! are driven through gears or belts carried by the axis before them (the motors sit behind, in the
//! forearm), so that a gear turned by joint `j`'s motion carries its run-out (eccentricity, one cycle
//! per revolution) or its tooth-to-tooth error into joint `i`'s link angle. The error depends on the
//! configuration through another joint's angle only: it is neither periodic in the joint's own angle
//! (that is [`super::transmission_error`], which the estimator covers), nor linear in an angle
//! ([`super::joint_coupling`]), nor driven by gravity, the direction of motion or temperature. The
//! estimator has no cause for it: an effect outside its vocabulary, for the blind tests.
//!
//! The shift enters the chain as an angle change with the transmission error (before backlash and
//! compliance) and moves the link-side positions of [`super::TrueTarget::q_link`].
//!
//! # Magnitudes
//!
//! A gear of pitch radius `r` mounted with run-out `e` turns its mate with an angular error of about
//! `e/r` once per revolution: fine-pitch gears hold run-out to 10–30 µm (ISO 1328-2 radial run-out
//! tolerances of accuracy grades 5–7 at these sizes), so 10 µm on a 20 mm gear is 5·10⁻⁴ rad at that
//! gear. Behind the joint's main reduction it is divided by its ratio; a gear on the output side
//! passes it on in full. Amplitudes of 10⁻⁵–10⁻⁴ rad at the link cover the two cases.

use super::effect::{Effect, Moved, Prepare, ResolveCx, State};
use super::joint_pairs;
use super::transmission_error::{MAX_AMPLITUDE_RAD, MAX_ORDER};
use crate::effect_id::EffectId;
use crate::error::{Result, SimError};
use crate::magnitude::Magnitude;

/// One term of [`CoupledTransmission`]: joint `joint`'s link angle gains
/// `amplitude_rad · sin(order · q_source + phase_rad)`.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CoupledTerm {
    /// The joint whose link angle moves (1-based).
    pub joint: usize,
    /// The joint whose reported angle drives it (1-based, not `joint`).
    pub source: usize,
    /// Cycles per revolution of the source joint (1 … [`MAX_ORDER`]).
    pub order: u32,
    /// Amplitude (rad).
    pub amplitude_rad: f64,
    /// Phase (rad).
    pub phase_rad: f64,
}

/// Link angle errors periodic in other joints' angles (see the module docs for the model).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "CoupledTransmissionSpec")]
pub struct CoupledTransmission {
    /// The terms, in the order given.
    terms: Vec<CoupledTerm>,
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct CoupledTransmissionSpec {
    terms: Vec<CoupledTerm>,
}

impl TryFrom<CoupledTransmissionSpec> for CoupledTransmission {
    type Error = SimError;
    fn try_from(s: CoupledTransmissionSpec) -> Result<Self> {
        CoupledTransmission::new(s.terms)
    }
}

impl CoupledTransmission {
    /// Coupled transmission error terms (joints 1-based). Refuses joint number 0, a source equal to
    /// its joint (the joint's own angle is [`super::transmission_error`]), an order outside 1 …
    /// [`MAX_ORDER`], non-finite values, amplitudes above [`MAX_AMPLITUDE_RAD`] and a `(joint,
    /// source, order)` given twice.
    pub fn new(terms: Vec<CoupledTerm>) -> Result<Self> {
        for (k, t) in terms.iter().enumerate() {
            let f = |name: &str| format!("terms[{k}].{name}");
            joint_pairs::check_numbered(EffectId::CoupledTransmission, k, t.joint, t.source)?;
            if t.source == t.joint {
                return Err(SimError::bad_effect(
                    EffectId::CoupledTransmission,
                    f("source"),
                    t.source,
                    "is the joint itself: an error periodic in the joint's own angle is [effects.transmission]",
                ));
            }
            if t.order == 0 || t.order > MAX_ORDER {
                return Err(SimError::bad_effect(
                    EffectId::CoupledTransmission,
                    f("order"),
                    t.order,
                    format!("must be a whole number of cycles per revolution, 1 … {MAX_ORDER}"),
                ));
            }
            if !t.amplitude_rad.is_finite() {
                return Err(SimError::bad_effect(
                    EffectId::CoupledTransmission,
                    f("amplitude_rad"),
                    t.amplitude_rad,
                    "not finite",
                ));
            }
            if t.amplitude_rad.abs() > MAX_AMPLITUDE_RAD {
                return Err(SimError::bad_effect(
                    EffectId::CoupledTransmission,
                    f("amplitude_rad"),
                    t.amplitude_rad,
                    format!("amplitude above {MAX_AMPLITUDE_RAD} rad; give it in rad, not degrees"),
                ));
            }
            if !t.phase_rad.is_finite() {
                return Err(SimError::bad_effect(
                    EffectId::CoupledTransmission,
                    f("phase_rad"),
                    t.phase_rad,
                    "not finite",
                ));
            }
            if terms[..k]
                .iter()
                .any(|o| o.joint == t.joint && o.source == t.source && o.order == t.order)
            {
                return Err(SimError::bad_effect(
                    EffectId::CoupledTransmission,
                    format!("terms[{k}]"),
                    format!("[{}, {}] order {}", t.joint, t.source, t.order),
                    "given twice",
                ));
            }
        }
        Ok(CoupledTransmission { terms })
    }

    /// The terms.
    pub fn terms(&self) -> &[CoupledTerm] {
        &self.terms
    }

    /// Checks that every joint number fits a robot with `nq` joints.
    pub fn check_fits(&self, nq: usize) -> Result<()> {
        joint_pairs::check_fits(
            EffectId::CoupledTransmission,
            self.terms.iter().map(|t| (t.joint, t.source)),
            nq,
        )
    }
}

/// The constructor's field as the scenario section writes it ([`joint_pairs::section_field`]).
fn section_field(e: SimError) -> SimError {
    joint_pairs::section_field(e, &["order", "amplitude_rad", "phase_rad"])
}

/// `[effects.coupled_transmission]`.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CoupledTransmissionSection {
    /// Switch (default on).
    pub enabled: Option<bool>,
    /// `[joint, source]` pairs, joints numbered from 1, `source ≠ joint`.
    pub pairs: Vec<[usize; 2]>,
    /// Cycles per revolution of the source joint, one per pair; default 1 for every pair.
    pub order: Option<Vec<u32>>,
    /// Amplitude of each pair (rad), shape `[len(pairs)]`.
    pub amplitude_rad: Magnitude,
    /// Phase of each pair (rad), shape `[len(pairs)]`; default 0.
    pub phase_rad: Option<Magnitude>,
}

impl Effect for CoupledTransmission {
    const ID: EffectId = EffectId::CoupledTransmission;
    type Section = CoupledTransmissionSection;
    type Stage = CoupledTransmission;
    type Scratch = ();

    fn enabled(section: &CoupledTransmissionSection) -> bool {
        section.enabled.unwrap_or(true)
    }

    fn from_section(c: &CoupledTransmissionSection, cx: &ResolveCx<'_>) -> Result<Self> {
        let n = c.pairs.len();
        let order = c.order.clone().unwrap_or_else(|| vec![1; n]);
        if order.len() != n {
            return Err(cx.err(
                "order",
                format!("{} entries, expected one per pair ({n})", order.len()),
            ));
        }
        let amplitude = cx.draw(&c.amplitude_rad, "amplitude_rad", &[n])?;
        let phase = cx.draw_or_zero(&c.phase_rad, "phase_rad", &[n])?;
        let terms = (0..n)
            .map(|k| CoupledTerm {
                joint: c.pairs[k][0],
                source: c.pairs[k][1],
                order: order[k],
                amplitude_rad: amplitude[k],
                phase_rad: phase[k],
            })
            .collect();
        let effect = cx.checked(CoupledTransmission::new(terms).map_err(section_field))?;
        cx.checked(effect.check_fits(cx.nq()).map_err(section_field))?;
        Ok(effect)
    }

    fn check_lengths(&self, nq: usize) -> Result<()> {
        self.check_fits(nq)
    }

    fn prepare(&self, _cx: &Prepare<'_>) -> Result<CoupledTransmission> {
        Ok(self.clone())
    }

    /// Link-side angles shifted by the terms: `φᵢ += A sin(h qⱼ + φ)` (reported angles), and the same
    /// on the link-side positions.
    #[inline]
    fn act<'t>(
        stage: &'t CoupledTransmission,
        st: &mut State<'t, '_>,
        _: &mut (),
    ) -> Result<Moved> {
        let mut moved = false;
        for t in &stage.terms {
            if t.amplitude_rad == 0.0 {
                continue;
            }
            let arg = f64::from(t.order) * st.cond.q[t.source - 1] + t.phase_rad;
            let d = t.amplitude_rad * crate::trig::sin_cos(arg).0;
            let i = t.joint - 1;
            st.angles[i] += d;
            st.q_link[i] += d;
            st.q_link_first[i] += d;
            moved |= d != 0.0;
        }
        Ok(if moved {
            Moved::Changed
        } else {
            Moved::Unchanged
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn term(joint: usize, source: usize, order: u32, a: f64) -> CoupledTerm {
        CoupledTerm {
            joint,
            source,
            order,
            amplitude_rad: a,
            phase_rad: 0.2,
        }
    }

    #[test]
    fn constructor_refuses_bad_terms_naming_the_field() {
        let cases = [
            (term(0, 1, 1, 1e-4), "terms[0].joint"),
            (term(2, 0, 1, 1e-4), "terms[0].source"),
            (term(2, 2, 1, 1e-4), "[effects.transmission]"),
            (term(2, 1, 0, 1e-4), "terms[0].order"),
            (term(2, 1, 1, 0.5), "degrees"),
            (term(2, 1, 1, f64::NAN), "terms[0].amplitude_rad"),
        ];
        for (t, want) in cases {
            let e = CoupledTransmission::new(vec![t]).unwrap_err().to_string();
            assert!(e.contains(want), "{e}");
        }
        let e = CoupledTransmission::new(vec![term(2, 1, 1, 1e-4), term(2, 1, 1, 2e-4)])
            .unwrap_err()
            .to_string();
        assert!(e.contains("terms[1]") && e.contains("twice"), "{e}");
        assert!(CoupledTransmission::new(vec![term(2, 1, 1, 1e-4), term(2, 1, 2, 2e-4)]).is_ok());
        let c = CoupledTransmission::new(vec![term(6, 8, 1, 1e-4)]).unwrap();
        assert!(
            c.check_fits(7)
                .unwrap_err()
                .to_string()
                .contains("terms[0].source")
        );
    }

    #[test]
    fn section_fields_name_the_scenario_keys() {
        let e = section_field(CoupledTransmission::new(vec![term(2, 1, 1, 0.5)]).unwrap_err());
        assert!(e.to_string().contains("amplitude_rad[0]"), "{e}");
        let e = section_field(CoupledTransmission::new(vec![term(2, 2, 1, 1e-4)]).unwrap_err());
        assert!(e.to_string().contains("pairs[0]"), "{e}");
    }

    #[test]
    fn serde_round_trips_and_validates() {
        let c = CoupledTransmission::new(vec![term(6, 5, 2, 3e-5)]).unwrap();
        let s = serde_json::to_string(&c).unwrap();
        assert_eq!(serde_json::from_str::<CoupledTransmission>(&s).unwrap(), c);
        let e = serde_json::from_str::<CoupledTransmission>(
            r#"{"terms":[{"joint":3,"source":3,"order":1,"amplitude_rad":0.0,"phase_rad":0.0}]}"#,
        )
        .unwrap_err();
        assert!(e.to_string().contains("terms[0].source"), "{e}");
    }
}
