//! Gear backlash: lost motion between motor and link.
//!
//! # Model
//!
//! Joint `i`'s gear has a dead band of width `b_i` (rad; m for prismatic joints). The controller reports
//! the motor-side position `q_i`; the link sits on one of the two tooth flanks, at `q_i ± b_i/2`. Which
//! flank is chosen by the mode:
//!
//! * **direction** ([`BacklashMode::Direction`]): the driving flank pushed the link during the last
//!   motion, so the link lags the motor by half the dead band against that motion:
//!   ```text
//!   θ_i = q_i − d_i b_i/2,   d_i ∈ {−1, 0, +1} the sign of the last motion (0 or unknown: θ_i = q_i)
//!   ```
//! * **gravity** ([`BacklashMode::Gravity`]): where the gravity load is large enough to take up the play,
//!   the link rests on the loaded flank whatever the direction of approach. `τ_g,i` (N m, see
//!   [`crate::statics`]) is the torque the joint applies to *hold* the link, so gravity itself acts on the
//!   link with `−τ_g,i`; freed by the play, the link turns in the direction of `−τ_g,i` until the other
//!   flank catches it:
//!   ```text
//!   θ_i = q_i − sign(τ_g,i) b_i/2      if |τ_g,i| > threshold_i,
//!   θ_i = q_i − d_i b_i/2               otherwise (direction rule).
//!   ```
//!   Example: a horizontal arm on a +y axis (positive rotation lowers it) needs `τ_g < 0` to be held, so
//!   `θ = q + b/2`: the link drops by half the play. `τ_g` includes the payload and is evaluated at the
//!   angles before backlash (after thermal drift and kinematic offsets), in the same geometry as the
//!   rest of the truth (see [`super::joint_compliance`]).
//!
//! The shift enters the chain as an angle change, `θ` replacing `q` in the product of exponentials.

use super::effect::{Effect, Moved, Needs, Prepare, ResolveCx, State};
use super::gravity::chain_gravity_torques;
use crate::effect_id::EffectId;
use crate::error::{Result, SimError};

/// Largest accepted dead band (rad): gears with more lost motion than 0.1 rad (5.7°) are not modelled,
/// and a value in degrees is refused.
pub const MAX_DEAD_BAND_RAD: f64 = 0.1;

/// Which flank the link rests on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BacklashMode {
    /// Against the direction of the last motion.
    Direction,
    /// On the flank loaded by gravity where the holding torque exceeds the threshold, else by direction.
    Gravity,
}

/// Per-joint gear backlash (see the module docs for the model).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "GearBacklashSpec")]
pub struct GearBacklash {
    /// Dead band of each joint (rad; m for prismatic joints), ≥ 0.
    dead_band_rad: Vec<f64>,
    /// Flank rule.
    mode: BacklashMode,
    /// Holding-torque magnitude above which gravity decides the flank (N m; N for prismatic joints),
    /// one per joint; empty (and not serialized) in direction mode.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    threshold_nm: Vec<f64>,
}

/// Serialized form of [`GearBacklash`]. `threshold_nm` is a list (per joint) or one number (all joints).
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct GearBacklashSpec {
    dead_band_rad: Vec<f64>,
    mode: BacklashMode,
    #[serde(default)]
    threshold_nm: Option<Threshold>,
}

#[derive(serde::Deserialize)]
#[serde(untagged)]
enum Threshold {
    One(f64),
    PerJoint(Vec<f64>),
}

impl TryFrom<GearBacklashSpec> for GearBacklash {
    type Error = SimError;
    fn try_from(s: GearBacklashSpec) -> Result<Self> {
        match (s.mode, s.threshold_nm) {
            (BacklashMode::Direction, None) => GearBacklash::direction(s.dead_band_rad),
            (BacklashMode::Direction, Some(_)) => Err(SimError::bad_effect(
                EffectId::GearBacklash,
                "threshold_nm",
                "given",
                "only used in gravity mode; remove it or set mode = \"gravity\"",
            )),
            (BacklashMode::Gravity, Some(Threshold::One(t))) => {
                GearBacklash::gravity_uniform(s.dead_band_rad, t)
            }
            (BacklashMode::Gravity, Some(Threshold::PerJoint(t))) => {
                GearBacklash::gravity(s.dead_band_rad, t)
            }
            (BacklashMode::Gravity, None) => Err(SimError::bad_effect(
                EffectId::GearBacklash,
                "threshold_nm",
                "missing",
                "gravity mode needs a holding-torque threshold (N m), one number or one per joint",
            )),
        }
    }
}

impl GearBacklash {
    fn check_band(dead_band_rad: &[f64]) -> Result<()> {
        for (i, &b) in dead_band_rad.iter().enumerate() {
            if !(b.is_finite() && b >= 0.0) {
                return Err(SimError::bad_effect(
                    EffectId::GearBacklash,
                    format!("dead_band_rad[{i}]"),
                    b,
                    "must be finite and ≥ 0",
                ));
            }
            if b > MAX_DEAD_BAND_RAD {
                return Err(SimError::bad_effect(
                    EffectId::GearBacklash,
                    format!("dead_band_rad[{i}]"),
                    b,
                    format!(
                        "more than {MAX_DEAD_BAND_RAD} rad of play; give it in rad, not degrees"
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Backlash with the direction rule: dead bands `dead_band_rad` (rad or m, ≥ 0, one per joint).
    pub fn direction(dead_band_rad: Vec<f64>) -> Result<Self> {
        Self::check_band(&dead_band_rad)?;
        Ok(GearBacklash {
            dead_band_rad,
            mode: BacklashMode::Direction,
            threshold_nm: Vec::new(),
        })
    }

    /// Backlash with the gravity rule and a per-joint holding-torque threshold (N m or N, ≥ 0).
    pub fn gravity(dead_band_rad: Vec<f64>, threshold_nm: Vec<f64>) -> Result<Self> {
        Self::check_band(&dead_band_rad)?;
        if threshold_nm.len() != dead_band_rad.len() {
            return Err(SimError::bad_effect(
                EffectId::GearBacklash,
                "threshold_nm",
                format!("{} entries", threshold_nm.len()),
                format!(
                    "needs one per joint, as dead_band_rad ({})",
                    dead_band_rad.len()
                ),
            ));
        }
        for (i, &t) in threshold_nm.iter().enumerate() {
            if !(t.is_finite() && t >= 0.0) {
                return Err(SimError::bad_effect(
                    EffectId::GearBacklash,
                    format!("threshold_nm[{i}]"),
                    t,
                    "must be finite and ≥ 0 N m",
                ));
            }
        }
        Ok(GearBacklash {
            dead_band_rad,
            mode: BacklashMode::Gravity,
            threshold_nm,
        })
    }

    /// Backlash with the gravity rule and one threshold (N m) for every joint.
    pub fn gravity_uniform(dead_band_rad: Vec<f64>, threshold_nm: f64) -> Result<Self> {
        let n = dead_band_rad.len();
        Self::gravity(dead_band_rad, vec![threshold_nm; n])
    }

    /// Dead band of each joint (rad or m).
    pub fn dead_band_rad(&self) -> &[f64] {
        &self.dead_band_rad
    }

    /// Flank rule.
    pub fn mode(&self) -> BacklashMode {
        self.mode
    }

    /// Per-joint gravity thresholds (N m or N); empty in direction mode.
    pub fn threshold_nm(&self) -> &[f64] {
        &self.threshold_nm
    }

    /// Checks that the lengths fit a robot with `nq` joints.
    pub fn check_fits(&self, nq: usize) -> Result<()> {
        if self.dead_band_rad.len() != nq {
            return Err(SimError::bad_effect(
                EffectId::GearBacklash,
                "dead_band_rad",
                format!("{} entries", self.dead_band_rad.len()),
                format!("the robot has {nq} joints"),
            ));
        }
        Ok(())
    }

    /// The shift `q_i − θ_i` (rad or m) of joint `i` (0-based): `dir` the sign of its last motion (−1, 0,
    /// +1; 0 = unknown), `tau_g` its holding torque (N m or N; used in gravity mode only).
    #[inline]
    pub fn shift(&self, i: usize, dir: i8, tau_g: f64) -> f64 {
        let half = 0.5 * self.dead_band_rad[i];
        let side = match self.mode {
            BacklashMode::Gravity if tau_g.abs() > self.threshold_nm[i] => tau_g.signum(),
            _ => f64::from(dir.signum()),
        };
        side * half
    }
}

/// `[effects.backlash]`.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BacklashSection {
    /// Switch (default on).
    pub enabled: Option<bool>,
    /// Dead band (rad; m for prismatic joints), shape `[n]`.
    pub dead_band_rad: crate::magnitude::Magnitude,
    /// Flank rule; default `direction`.
    pub mode: Option<BacklashMode>,
    /// Gravity-mode holding-torque threshold (N m), shape `[n]`.
    pub threshold_nm: Option<crate::magnitude::Magnitude>,
}

impl Effect for GearBacklash {
    const ID: EffectId = EffectId::GearBacklash;
    type Section = BacklashSection;
    type Stage = GearBacklash;
    type Scratch = ();

    fn enabled(section: &BacklashSection) -> bool {
        section.enabled.unwrap_or(true)
    }

    fn from_section(b: &BacklashSection, cx: &ResolveCx<'_>) -> Result<Self> {
        let n = cx.nq();
        let band = cx.draw(&b.dead_band_rad, "dead_band_rad", &[n])?;
        let mode = b.mode.unwrap_or(BacklashMode::Direction);
        let bl = match (mode, &b.threshold_nm) {
            (BacklashMode::Direction, None) => GearBacklash::direction(band),
            (BacklashMode::Direction, Some(_)) => {
                return Err(cx.err("threshold_nm", "only used with mode = \"gravity\"".into()));
            }
            (BacklashMode::Gravity, None) => {
                return Err(cx.err(
                    "threshold_nm",
                    "mode = \"gravity\" needs a holding-torque threshold (N m)".into(),
                ));
            }
            (BacklashMode::Gravity, Some(t)) => {
                cx.require_inertials("mode", "gravity-mode backlash")?;
                let t = cx.draw(t, "threshold_nm", &[n])?;
                GearBacklash::gravity(band, t)
            }
        };
        cx.checked(bl)
    }

    fn needs(&self) -> Needs {
        let gravity = self.mode == BacklashMode::Gravity;
        Needs {
            dir: true,
            payload: gravity,
            inertials: gravity,
            ..Needs::default()
        }
    }

    fn check_lengths(&self, nq: usize) -> Result<()> {
        self.check_fits(nq)
    }

    fn prepare(&self, _cx: &Prepare<'_>) -> Result<GearBacklash> {
        Ok(self.clone())
    }

    /// Link-side angle shifted by half the dead band: `φᵢ −= sᵢ` (gravity torques, in gravity mode,
    /// from the last evaluation: the angles before backlash).
    #[inline]
    fn act<'t>(stage: &'t GearBacklash, st: &mut State<'t, '_>, _: &mut ()) -> Result<Moved> {
        let by_gravity = stage.mode == BacklashMode::Gravity;
        if by_gravity {
            chain_gravity_torques(
                st.geom,
                st.poses,
                &st.flange,
                st.bodies,
                st.cond.payload.as_ref(),
                st.gravity,
                st.work,
            );
        }
        let mut moved = false;
        for i in 0..st.angles.len() {
            let dir = st.cond.dir.map_or(0, |d| d[i]);
            let tau = if by_gravity { st.work.tau[i] } else { 0.0 };
            let sh = stage.shift(i, dir, tau);
            st.angles[i] -= sh;
            st.q_link[i] -= sh;
            st.q_link_first[i] -= sh;
            moved |= sh != 0.0;
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

    #[test]
    fn shift_follows_the_documented_signs() {
        let d = GearBacklash::direction(vec![0.002, 0.004]).unwrap();
        assert_eq!(d.shift(0, 1, -50.0), 0.001); // moved +: link lags, θ = q − b/2
        assert_eq!(d.shift(1, -1, 50.0), -0.002);
        assert_eq!(d.shift(1, 0, 50.0), 0.0);
        let g = GearBacklash::gravity(vec![0.002, 0.004], vec![1.0, 10.0]).unwrap();
        // |τ| above threshold: θ = q − sign(τ) b/2 regardless of direction.
        assert_eq!(g.shift(0, 1, -5.0), -0.001);
        assert_eq!(g.shift(0, -1, 5.0), 0.001);
        // Below threshold: direction rule.
        assert_eq!(g.shift(1, 1, -5.0), 0.002);
        assert_eq!(g.shift(1, 0, -5.0), 0.0);
    }

    #[test]
    fn constructors_refuse_bad_values_naming_the_field() {
        let e = GearBacklash::direction(vec![0.001, -0.001]).unwrap_err();
        assert!(e.to_string().contains("dead_band_rad[1]"), "{e}");
        let e = GearBacklash::direction(vec![f64::NAN]).unwrap_err();
        assert!(e.to_string().contains("dead_band_rad[0]"), "{e}");
        let e = GearBacklash::direction(vec![0.5]).unwrap_err();
        assert!(e.to_string().contains("degrees"), "{e}");
        let e = GearBacklash::gravity(vec![0.001, 0.001], vec![1.0]).unwrap_err();
        assert!(e.to_string().contains("threshold_nm"), "{e}");
        let e = GearBacklash::gravity_uniform(vec![0.001], -1.0).unwrap_err();
        assert!(e.to_string().contains("threshold_nm[0]"), "{e}");
        assert!(
            GearBacklash::direction(vec![0.001; 3])
                .unwrap()
                .check_fits(7)
                .is_err()
        );
    }

    #[test]
    fn deserializing_validates_and_round_trips() {
        let g = GearBacklash::gravity(vec![0.001, 0.002], vec![3.0, 4.0]).unwrap();
        let s = serde_json::to_string(&g).unwrap();
        assert_eq!(serde_json::from_str::<GearBacklash>(&s).unwrap(), g);
        let d = GearBacklash::direction(vec![0.001]).unwrap();
        let s = serde_json::to_string(&d).unwrap();
        assert!(!s.contains("threshold_nm"), "{s}");
        assert_eq!(serde_json::from_str::<GearBacklash>(&s).unwrap(), d);
        let u: GearBacklash = serde_json::from_str(
            r#"{"dead_band_rad": [0.001, 0.002], "mode": "gravity", "threshold_nm": 2.5}"#,
        )
        .unwrap();
        assert_eq!(u.threshold_nm(), &[2.5, 2.5]);
        let e = serde_json::from_str::<GearBacklash>(
            r#"{"dead_band_rad": [0.001], "mode": "gravity"}"#,
        )
        .unwrap_err();
        assert!(e.to_string().contains("threshold_nm"), "{e}");
    }
}
