//! Joint coupling: a link angle error proportional to the reported angle of a joint.
//!
//! # Model
//!
//! A list of terms `(i, j, cᵢⱼ)`: the link of joint `i` sits at
//!
//! ```text
//! θᵢ = qᵢ + Σⱼ cᵢⱼ qⱼ
//! ```
//!
//! with `qⱼ` the reported angle of joint `j` ([`super::Conditions::q`], rad or m) and the ratio `cᵢⱼ`
//! (rad/rad; the units of joint `i` per unit of joint `j`). Joints are numbered from 1, as the `q1 …
//! qN` columns. For `j ≠ i` it stands for
//!
//! * cable wind-up: a cable bundle or hose routed through joint `j` and twisted by it pulls on the
//!   transmission of joint `i`;
//! * coupled transmissions: a wrist whose drive shafts pass through the joints before it (the motor of
//!   the last axis sitting behind the previous ones), so that the link angle of `i` moves with `qⱼ`
//!   when the controller's decoupling matrix is slightly off;
//!
//! and for `j = i` a scale error of the joint: a gear ratio or encoder line count other than the one
//! the controller uses (`cᵢᵢ = ratio error / ratio`).
//!
//! The shift enters the chain as an angle change before backlash and compliance, and moves the
//! link-side positions of [`super::TrueTarget::q_link`]. It depends on the configuration only through
//! the reported angles: it is neither periodic in a joint's own angle, nor driven by gravity, the
//! direction of motion or the temperature. The estimator has no cause for it (an effect outside its
//! vocabulary, for the blind tests).
//!
//! # Magnitudes
//!
//! A scale error of 10⁻⁴ (a belt drive whose pulley pitch diameter is off by 0.01 %) moves a link by
//! 0.3 mrad over ±3 rad, 0.3 mm at a metre; a wrist decoupling ratio off by 10⁻³ does ten times that.
//! The cable wind-up reported for the iiwa 7 in issue 12 (an independent generator's data set) left
//! about 5 times the tracker noise floor unexplained, i.e. ratios of order 10⁻⁴.

use super::effect::{Effect, Moved, Prepare, ResolveCx, State};
use super::joint_pairs;
use crate::effect_id::EffectId;
use crate::error::{Result, SimError};
use crate::magnitude::Magnitude;

/// Largest accepted `|cᵢⱼ|` (rad/rad): a 5 % coupling is a different robot, not an error; more is
/// almost surely a value in percent or degrees.
pub const MAX_RATIO: f64 = 0.05;

/// One term of [`JointCoupling`]: joint `joint`'s link angle gains `ratio_rad_per_rad · q_source`.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CouplingTerm {
    /// The joint whose link angle moves (1-based).
    pub joint: usize,
    /// The joint whose reported angle drives it (1-based; `= joint` for a scale error).
    pub source: usize,
    /// `cᵢⱼ` (rad/rad; units of `joint` per unit of `source`).
    pub ratio_rad_per_rad: f64,
}

/// Link angle errors proportional to reported joint angles (see the module docs for the model).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "JointCouplingSpec")]
pub struct JointCoupling {
    /// The terms, in the order given.
    terms: Vec<CouplingTerm>,
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct JointCouplingSpec {
    terms: Vec<CouplingTerm>,
}

impl TryFrom<JointCouplingSpec> for JointCoupling {
    type Error = SimError;
    fn try_from(s: JointCouplingSpec) -> Result<Self> {
        JointCoupling::new(s.terms)
    }
}

impl JointCoupling {
    /// Coupling terms (joints 1-based). Refuses joint number 0, a `(joint, source)` pair given twice,
    /// non-finite ratios and `|ratio|` above [`MAX_RATIO`]. An empty list is no coupling.
    pub fn new(terms: Vec<CouplingTerm>) -> Result<Self> {
        for (k, t) in terms.iter().enumerate() {
            joint_pairs::check_numbered(EffectId::JointCoupling, k, t.joint, t.source)?;
            let r = t.ratio_rad_per_rad;
            if !r.is_finite() {
                return Err(SimError::bad_effect(
                    EffectId::JointCoupling,
                    format!("terms[{k}].ratio_rad_per_rad"),
                    r,
                    "not finite",
                ));
            }
            if r.abs() > MAX_RATIO {
                return Err(SimError::bad_effect(
                    EffectId::JointCoupling,
                    format!("terms[{k}].ratio_rad_per_rad"),
                    r,
                    format!("coupling above {MAX_RATIO} rad/rad; give a ratio, not percent"),
                ));
            }
            if terms[..k]
                .iter()
                .any(|o| o.joint == t.joint && o.source == t.source)
            {
                return Err(SimError::bad_effect(
                    EffectId::JointCoupling,
                    format!("terms[{k}]"),
                    format!("[{}, {}]", t.joint, t.source),
                    "this (joint, source) pair is given twice",
                ));
            }
        }
        Ok(JointCoupling { terms })
    }

    /// One term: joint `joint`'s link angle gains `ratio_rad_per_rad · q_source` (joints 1-based).
    pub fn single(joint: usize, source: usize, ratio_rad_per_rad: f64) -> Result<Self> {
        JointCoupling::new(vec![CouplingTerm {
            joint,
            source,
            ratio_rad_per_rad,
        }])
    }

    /// The terms.
    pub fn terms(&self) -> &[CouplingTerm] {
        &self.terms
    }

    /// Checks that every joint number fits a robot with `nq` joints.
    pub fn check_fits(&self, nq: usize) -> Result<()> {
        joint_pairs::check_fits(
            EffectId::JointCoupling,
            self.terms.iter().map(|t| (t.joint, t.source)),
            nq,
        )
    }
}

/// The constructor's field as the scenario section writes it ([`joint_pairs::section_field`]).
fn section_field(e: SimError) -> SimError {
    joint_pairs::section_field(e, &["ratio_rad_per_rad"])
}

/// `[effects.coupling]`.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CouplingSection {
    /// Switch (default on).
    pub enabled: Option<bool>,
    /// `[joint, source]` pairs, joints numbered from 1: `joint`'s link angle gains `ratio · q_source`.
    pub pairs: Vec<[usize; 2]>,
    /// Ratio of each pair (rad/rad), shape `[len(pairs)]`.
    pub ratio_rad_per_rad: Magnitude,
}

impl Effect for JointCoupling {
    const ID: EffectId = EffectId::JointCoupling;
    type Section = CouplingSection;
    type Stage = JointCoupling;
    type Scratch = ();

    fn enabled(section: &CouplingSection) -> bool {
        section.enabled.unwrap_or(true)
    }

    fn from_section(c: &CouplingSection, cx: &ResolveCx<'_>) -> Result<Self> {
        let ratios = cx.draw(&c.ratio_rad_per_rad, "ratio_rad_per_rad", &[c.pairs.len()])?;
        let terms = c
            .pairs
            .iter()
            .zip(ratios)
            .map(|(&[joint, source], ratio_rad_per_rad)| CouplingTerm {
                joint,
                source,
                ratio_rad_per_rad,
            })
            .collect();
        let coupling = cx.checked(JointCoupling::new(terms).map_err(section_field))?;
        cx.checked(coupling.check_fits(cx.nq()).map_err(section_field))?;
        Ok(coupling)
    }

    fn check_lengths(&self, nq: usize) -> Result<()> {
        self.check_fits(nq)
    }

    fn prepare(&self, _cx: &Prepare<'_>) -> Result<JointCoupling> {
        Ok(self.clone())
    }

    /// Link-side angles shifted by the coupling terms: `φᵢ += cᵢⱼ qⱼ` (reported angles), and the same
    /// on the link-side positions.
    #[inline]
    fn act<'t>(stage: &'t JointCoupling, st: &mut State<'t, '_>, _: &mut ()) -> Result<Moved> {
        let mut moved = false;
        for t in &stage.terms {
            let d = t.ratio_rad_per_rad * st.cond.q[t.source - 1];
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

    fn term(joint: usize, source: usize, r: f64) -> CouplingTerm {
        CouplingTerm {
            joint,
            source,
            ratio_rad_per_rad: r,
        }
    }

    #[test]
    fn constructor_refuses_bad_terms_naming_the_field() {
        let e = JointCoupling::new(vec![term(0, 1, 1e-4)]).unwrap_err();
        assert!(e.to_string().contains("terms[0].joint"), "{e}");
        let e = JointCoupling::new(vec![term(2, 0, 1e-4)]).unwrap_err();
        assert!(e.to_string().contains("terms[0].source"), "{e}");
        let e = JointCoupling::new(vec![term(2, 1, 1e-4), term(3, 1, 0.5)]).unwrap_err();
        assert!(
            e.to_string().contains("terms[1].ratio_rad_per_rad")
                && e.to_string().contains("percent"),
            "{e}"
        );
        let e = JointCoupling::new(vec![term(2, 1, f64::NAN)]).unwrap_err();
        assert!(e.to_string().contains("terms[0].ratio_rad_per_rad"), "{e}");
        let e = JointCoupling::new(vec![term(2, 1, 1e-4), term(2, 1, 2e-4)]).unwrap_err();
        assert!(
            e.to_string().contains("terms[1]") && e.to_string().contains("twice"),
            "{e}"
        );
        let c = JointCoupling::new(vec![term(2, 1, 1e-4), term(8, 1, 1e-4)]).unwrap();
        let e = c.check_fits(7).unwrap_err();
        assert!(e.to_string().contains("terms[1].joint") && e.to_string().contains("7 joints"));
        assert!(c.check_fits(8).is_ok());
    }

    #[test]
    fn serde_round_trips_and_validates() {
        let c = JointCoupling::new(vec![term(3, 2, 2e-4), term(5, 5, -1e-4)]).unwrap();
        let s = serde_json::to_string(&c).unwrap();
        assert_eq!(
            s,
            r#"{"terms":[{"joint":3,"source":2,"ratio_rad_per_rad":0.0002},{"joint":5,"source":5,"ratio_rad_per_rad":-0.0001}]}"#
        );
        assert_eq!(serde_json::from_str::<JointCoupling>(&s).unwrap(), c);
        let e = serde_json::from_str::<JointCoupling>(
            r#"{"terms":[{"joint":0,"source":2,"ratio_rad_per_rad":0.0}]}"#,
        )
        .unwrap_err();
        assert!(e.to_string().contains("terms[0].joint"), "{e}");
    }
}
