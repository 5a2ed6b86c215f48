//! Thermal drift: links grow with temperature and joint zeros drift.
//!
//! # Model
//!
//! The nominal model is exact at the reference temperature `T_ref` (°C). At the robot temperature `T`
//! (°C, [`super::Conditions::temp_c`]) let `ΔT = T − T_ref` (K). Then
//!
//! * **link growth**: every link vector grows with its link's linear expansion coefficient `α_k` (1/K):
//!   ```text
//!   ℓ_k(T) = (1 + α_k ΔT) ℓ_k,     k = 0 … n
//!   ```
//!   where `ℓ_k` is the translation of the frame after link `k` in link `k`'s frame: for `k < n` the
//!   origin translation of joint `k + 1` (URDF `<origin xyz>` with fixed joints folded in; `k = 0` is the
//!   base link, from the base frame to joint 1), and for `k = n` the flange offset `T_last_flange`.
//!   Rotations of the joint origins do not change (isotropic expansion keeps angles). Centres of mass
//!   are not moved: the shift is `α ΔT` times a centre-of-mass offset (≈ 20 µm for 0.1 m at 10 K),
//!   which changes gravity torques by ~2·10⁻⁴ of themselves and compliance sag by well under 1 nm.
//! * **joint-zero drift**: the angle of joint `i` gains `β_i ΔT` (`β_i` in rad/K, m/K for prismatic
//!   joints), as when an encoder or its mounting moves with temperature.
//!
//! Because `ℓ_k(T)` is affine in `ΔT`, so is every joint-frame origin of the grown chain; the prepared
//! truth ([`super::Truth`]) stores each origin as `p₀ + ΔT dp` and needs no work per temperature.
//!
//! Temperature as a function of time comes from the campaign; [`WarmUp`] (first-order warm-up) and
//! [`TemperatureSchedule`] (piecewise linear) turn time stamps (s) into temperatures (°C).
//!
//! `α` has `n + 1` entries (links 0 … n), `β` has `n` (joints 1 … n, 0-based in the vectors).

use super::effect::{Effect, Moved, Needs, Prepare, ResolveCx, State};
use crate::effect_id::EffectId;
use crate::error::{Result, SimError};

/// Linear expansion coefficient of aluminium alloys (1/K), the default link material.
pub const ALUMINIUM_ALPHA_PER_K: f64 = 23e-6;

/// Largest accepted |α| (1/K); no structural material comes near it, and `23` meaning ppm/K is refused.
pub const MAX_ABS_ALPHA_PER_K: f64 = 1e-3;

/// Link growth and joint-zero drift with temperature (see the module docs for the model).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "ThermalDriftSpec")]
pub struct ThermalDrift {
    /// Reference temperature at which the nominal model is exact (°C).
    t_ref_c: f64,
    /// Linear expansion coefficient of each link 0 … n (1/K), `n + 1` entries.
    alpha_per_k: Vec<f64>,
    /// Joint-zero drift of each joint (rad/K, m/K for prismatic joints), `n` entries.
    beta_rad_per_k: Vec<f64>,
}

/// Serialized form of [`ThermalDrift`]; `beta_rad_per_k` may be left out (no zero drift).
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct ThermalDriftSpec {
    t_ref_c: f64,
    alpha_per_k: Vec<f64>,
    #[serde(default)]
    beta_rad_per_k: Option<Vec<f64>>,
}

impl TryFrom<ThermalDriftSpec> for ThermalDrift {
    type Error = SimError;
    fn try_from(s: ThermalDriftSpec) -> Result<Self> {
        let n = s.alpha_per_k.len().saturating_sub(1);
        let beta = s.beta_rad_per_k.unwrap_or_else(|| vec![0.0; n]);
        ThermalDrift::new(s.t_ref_c, s.alpha_per_k, beta)
    }
}

impl ThermalDrift {
    /// Thermal drift with reference temperature `t_ref_c` (°C), per-link expansion coefficients
    /// `alpha_per_k` (1/K, links 0 … n: `n + 1` entries) and per-joint zero drift `beta_rad_per_k`
    /// (rad/K, `n` entries). Refuses non-finite values, |α| ≥ [`MAX_ABS_ALPHA_PER_K`] and lengths that do
    /// not differ by one.
    pub fn new(t_ref_c: f64, alpha_per_k: Vec<f64>, beta_rad_per_k: Vec<f64>) -> Result<Self> {
        if !t_ref_c.is_finite() {
            return Err(SimError::bad_effect(
                EffectId::ThermalDrift,
                "t_ref_c",
                t_ref_c,
                "must be a finite temperature (°C)",
            ));
        }
        if alpha_per_k.len() != beta_rad_per_k.len() + 1 {
            return Err(SimError::bad_effect(
                EffectId::ThermalDrift,
                "alpha_per_k",
                format!("{} entries", alpha_per_k.len()),
                format!(
                    "needs one entry per link (joints + 1 = {}, as beta_rad_per_k has {})",
                    beta_rad_per_k.len() + 1,
                    beta_rad_per_k.len()
                ),
            ));
        }
        for (k, &a) in alpha_per_k.iter().enumerate() {
            if !a.is_finite() {
                return Err(SimError::bad_effect(
                    EffectId::ThermalDrift,
                    format!("alpha_per_k[{k}]"),
                    a,
                    "not finite",
                ));
            }
            if a.abs() >= MAX_ABS_ALPHA_PER_K {
                return Err(SimError::bad_effect(
                    EffectId::ThermalDrift,
                    format!("alpha_per_k[{k}]"),
                    a,
                    "is not a plausible expansion coefficient; give it in 1/K (aluminium: 23e-6)",
                ));
            }
        }
        for (i, &b) in beta_rad_per_k.iter().enumerate() {
            if !b.is_finite() {
                return Err(SimError::bad_effect(
                    EffectId::ThermalDrift,
                    format!("beta_rad_per_k[{i}]"),
                    b,
                    "not finite",
                ));
            }
        }
        Ok(ThermalDrift {
            t_ref_c,
            alpha_per_k,
            beta_rad_per_k,
        })
    }

    /// The same coefficient `alpha_per_k` (1/K) for every link of an `nq`-joint robot, no zero drift.
    pub fn uniform(nq: usize, t_ref_c: f64, alpha_per_k: f64) -> Result<Self> {
        ThermalDrift::new(t_ref_c, vec![alpha_per_k; nq + 1], vec![0.0; nq])
    }

    /// Replaces the per-joint zero drift (rad/K, `n` entries).
    pub fn with_zero_drift(self, beta_rad_per_k: Vec<f64>) -> Result<Self> {
        ThermalDrift::new(self.t_ref_c, self.alpha_per_k, beta_rad_per_k)
    }

    /// Reference temperature (°C).
    pub fn t_ref_c(&self) -> f64 {
        self.t_ref_c
    }

    /// Expansion coefficient of each link 0 … n (1/K).
    pub fn alpha_per_k(&self) -> &[f64] {
        &self.alpha_per_k
    }

    /// Zero drift of each joint (rad/K or m/K).
    pub fn beta_rad_per_k(&self) -> &[f64] {
        &self.beta_rad_per_k
    }

    /// `ΔT = temp_c − T_ref` (K).
    #[inline]
    pub fn delta_k(&self, temp_c: f64) -> f64 {
        temp_c - self.t_ref_c
    }

    /// Checks that the lengths fit a robot with `nq` joints.
    pub fn check_fits(&self, nq: usize) -> Result<()> {
        if self.beta_rad_per_k.len() != nq {
            return Err(SimError::bad_effect(
                EffectId::ThermalDrift,
                "beta_rad_per_k",
                format!("{} entries", self.beta_rad_per_k.len()),
                format!("the robot has {nq} joints"),
            ));
        }
        Ok(())
    }
}

/// First-order warm-up: `T(t) = T0 + dT (1 − exp(−t/τ))` (°C, t in s); `T(t) = T0` for `t < 0`.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "WarmUpSpec")]
pub struct WarmUp {
    /// Temperature at `t = 0` (°C).
    pub t0_c: f64,
    /// Rise from `t = 0` to the steady state (K).
    pub delta_c: f64,
    /// Time constant (s), > 0.
    pub tau_s: f64,
}

/// Serialized form of [`WarmUp`], validated on the way in.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct WarmUpSpec {
    t0_c: f64,
    delta_c: f64,
    tau_s: f64,
}

impl TryFrom<WarmUpSpec> for WarmUp {
    type Error = SimError;
    fn try_from(s: WarmUpSpec) -> Result<Self> {
        WarmUp::new(s.t0_c, s.delta_c, s.tau_s)
    }
}

impl WarmUp {
    /// A validated warm-up law: finite `t0_c` (°C) and `delta_c` (K), finite `tau_s > 0` (s).
    pub fn new(t0_c: f64, delta_c: f64, tau_s: f64) -> Result<Self> {
        let w = WarmUp {
            t0_c,
            delta_c,
            tau_s,
        };
        w.validate()?;
        Ok(w)
    }

    /// Checks the fields (for values built as a struct literal or deserialized).
    pub fn validate(&self) -> Result<()> {
        if !self.t0_c.is_finite() {
            return Err(SimError::bad_effect(
                EffectId::ThermalDrift,
                "warm_up.t0_c",
                self.t0_c,
                "not finite",
            ));
        }
        if !self.delta_c.is_finite() {
            return Err(SimError::bad_effect(
                EffectId::ThermalDrift,
                "warm_up.delta_c",
                self.delta_c,
                "not finite",
            ));
        }
        if !(self.tau_s.is_finite() && self.tau_s > 0.0) {
            return Err(SimError::bad_effect(
                EffectId::ThermalDrift,
                "warm_up.tau_s",
                self.tau_s,
                "must be a finite time constant > 0 s",
            ));
        }
        Ok(())
    }

    /// Temperature (°C) at time `t_s` (s since the start of the campaign).
    pub fn temp_at(&self, t_s: f64) -> f64 {
        if t_s <= 0.0 {
            return self.t0_c;
        }
        // -expm1(-x) = 1 - exp(-x), accurate for small x.
        self.t0_c + self.delta_c * -(-t_s / self.tau_s).exp_m1()
    }
}

/// Piecewise-linear temperature schedule `[(t_s, temp_c)]`, constant before the first and after the
/// last point.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "Vec<(f64, f64)>", into = "Vec<(f64, f64)>")]
pub struct TemperatureSchedule {
    /// `(t_s, temp_c)` with strictly increasing times (s) and temperatures (°C).
    points: Vec<(f64, f64)>,
}

impl TryFrom<Vec<(f64, f64)>> for TemperatureSchedule {
    type Error = SimError;
    fn try_from(points: Vec<(f64, f64)>) -> Result<Self> {
        TemperatureSchedule::new(points)
    }
}

impl From<TemperatureSchedule> for Vec<(f64, f64)> {
    fn from(s: TemperatureSchedule) -> Self {
        s.points
    }
}

impl TemperatureSchedule {
    /// A schedule from `(t_s, temp_c)` points: at least one, all finite, times strictly increasing.
    pub fn new(points: Vec<(f64, f64)>) -> Result<Self> {
        if points.is_empty() {
            return Err(SimError::bad_effect(
                EffectId::ThermalDrift,
                "schedule",
                "[]",
                "needs at least one (t_s, temp_c) point",
            ));
        }
        for (k, &(t, c)) in points.iter().enumerate() {
            if !t.is_finite() {
                return Err(SimError::bad_effect(
                    EffectId::ThermalDrift,
                    format!("schedule[{k}].t_s"),
                    t,
                    "not finite",
                ));
            }
            if !c.is_finite() {
                return Err(SimError::bad_effect(
                    EffectId::ThermalDrift,
                    format!("schedule[{k}].temp_c"),
                    c,
                    "not finite",
                ));
            }
            if k > 0 && t <= points[k - 1].0 {
                return Err(SimError::bad_effect(
                    EffectId::ThermalDrift,
                    format!("schedule[{k}].t_s"),
                    t,
                    format!(
                        "times must increase strictly (previous {})",
                        points[k - 1].0
                    ),
                ));
            }
        }
        Ok(TemperatureSchedule { points })
    }

    /// The `(t_s, temp_c)` points.
    pub fn points(&self) -> &[(f64, f64)] {
        &self.points
    }

    /// Temperature (°C) at time `t_s` (s): linear between points, constant outside them.
    pub fn temp_at(&self, t_s: f64) -> f64 {
        let p = &self.points;
        let k = p.partition_point(|&(t, _)| t <= t_s);
        if k == 0 {
            return p[0].1;
        }
        if k == p.len() {
            return p[k - 1].1;
        }
        let (t0, c0) = p[k - 1];
        let (t1, c1) = p[k];
        c0 + (c1 - c0) * ((t_s - t0) / (t1 - t0))
    }
}

/// How the robot temperature evolves over a campaign.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TemperatureProfile {
    /// Constant temperature (°C).
    Constant(f64),
    /// First-order warm-up.
    WarmUp(WarmUp),
    /// Piecewise-linear schedule.
    Schedule(TemperatureSchedule),
}

impl TemperatureProfile {
    /// Checks the profile's values.
    pub fn validate(&self) -> Result<()> {
        match self {
            TemperatureProfile::Constant(c) if !c.is_finite() => Err(SimError::bad_effect(
                EffectId::ThermalDrift,
                "constant",
                c,
                "not finite",
            )),
            TemperatureProfile::Constant(_) | TemperatureProfile::Schedule(_) => Ok(()),
            TemperatureProfile::WarmUp(w) => w.validate(),
        }
    }

    /// Temperature (°C) at time `t_s` (s since the start of the campaign).
    pub fn temp_at(&self, t_s: f64) -> f64 {
        match self {
            TemperatureProfile::Constant(c) => *c,
            TemperatureProfile::WarmUp(w) => w.temp_at(t_s),
            TemperatureProfile::Schedule(s) => s.temp_at(t_s),
        }
    }
}

/// `[effects.thermal]`.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ThermalSection {
    /// Switch (default on).
    pub enabled: Option<bool>,
    /// Temperature at which the nominal model is exact (°C); default 20.
    pub t_ref_c: Option<f64>,
    /// Link expansion coefficients (1/K), shape `[n + 1]`.
    pub alpha_per_k: crate::magnitude::Magnitude,
    /// Joint-zero drift (rad/K), shape `[n]`; default 0.
    pub beta_rad_per_k: Option<crate::magnitude::Magnitude>,
}

impl Effect for ThermalDrift {
    const ID: EffectId = EffectId::ThermalDrift;
    type Section = ThermalSection;
    type Stage = ThermalDrift;
    type Scratch = ();

    fn enabled(section: &ThermalSection) -> bool {
        section.enabled.unwrap_or(true)
    }

    fn from_section(t: &ThermalSection, cx: &ResolveCx<'_>) -> Result<Self> {
        let n = cx.nq();
        let alpha = cx.draw(&t.alpha_per_k, "alpha_per_k", &[n + 1])?;
        let beta = cx.draw_or_zero(&t.beta_rad_per_k, "beta_rad_per_k", &[n])?;
        cx.checked(ThermalDrift::new(t.t_ref_c.unwrap_or(20.0), alpha, beta))
    }

    fn needs(&self) -> Needs {
        Needs {
            temp: true,
            ..Needs::default()
        }
    }

    fn check_lengths(&self, nq: usize) -> Result<()> {
        self.check_fits(nq)
    }

    fn link_growth_per_k(&self) -> Option<&[f64]> {
        Some(&self.alpha_per_k)
    }

    fn prepare(&self, _cx: &Prepare<'_>) -> Result<ThermalDrift> {
        Ok(self.clone())
    }

    /// Grown links (the chain every stage evaluates carries `α`; here `ΔT` is set) and drifted zeros
    /// `φᵢ += βᵢ ΔT`.
    #[inline]
    fn act<'t>(stage: &'t ThermalDrift, st: &mut State<'t, '_>, _: &mut ()) -> Result<Moved> {
        let dt = stage.delta_k(st.cond.temp_c);
        for (a, b) in st.angles.iter_mut().zip(&stage.beta_rad_per_k) {
            *a += b * dt;
        }
        st.dt = dt;
        Ok(Moved::Changed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn warm_up_reaches_63_percent_after_one_time_constant() {
        let w = WarmUp::new(20.0, 8.0, 1800.0).unwrap();
        // 1 - e^-1 = 0.6321205588285577 (hand value).
        assert!((w.temp_at(1800.0) - (20.0 + 8.0 * 0.632_120_558_828_557_7)).abs() < 1e-12);
        assert_eq!(w.temp_at(0.0), 20.0);
        assert_eq!(w.temp_at(-5.0), 20.0);
        assert!((w.temp_at(1e9) - 28.0).abs() < 1e-12);
        assert!(WarmUp::new(20.0, 8.0, 0.0).is_err());
        assert!(WarmUp::new(f64::NAN, 8.0, 1.0).is_err());
    }

    #[test]
    fn schedule_interpolates_linearly_and_holds_outside() {
        let s = TemperatureSchedule::new(vec![(0.0, 20.0), (100.0, 25.0), (300.0, 24.0)]).unwrap();
        assert_eq!(s.temp_at(-1.0), 20.0);
        assert!((s.temp_at(50.0) - 22.5).abs() < 1e-15);
        assert_eq!(s.temp_at(100.0), 25.0);
        assert!((s.temp_at(200.0) - 24.5).abs() < 1e-15);
        assert_eq!(s.temp_at(1000.0), 24.0);
        assert!(TemperatureSchedule::new(vec![]).is_err());
        let e = TemperatureSchedule::new(vec![(0.0, 20.0), (0.0, 21.0)]).unwrap_err();
        assert!(e.to_string().contains("schedule[1].t_s"), "{e}");
    }

    #[test]
    fn constructor_refuses_bad_values_naming_the_field() {
        let e = ThermalDrift::new(20.0, vec![23e-6, f64::NAN, 0.0], vec![0.0, 0.0]).unwrap_err();
        assert!(e.to_string().contains("alpha_per_k[1]"), "{e}");
        let e = ThermalDrift::new(20.0, vec![23.0; 3], vec![0.0; 2]).unwrap_err();
        assert!(e.to_string().contains("alpha_per_k[0]"), "{e}");
        let e = ThermalDrift::new(20.0, vec![23e-6; 3], vec![0.0; 3]).unwrap_err();
        assert!(e.to_string().contains("alpha_per_k"), "{e}");
        assert!(ThermalDrift::new(f64::INFINITY, vec![0.0; 2], vec![0.0]).is_err());
        let e = ThermalDrift::uniform(2, 20.0, 23e-6)
            .unwrap()
            .with_zero_drift(vec![0.0, f64::NAN])
            .unwrap_err();
        assert!(e.to_string().contains("beta_rad_per_k[1]"), "{e}");
        assert!(
            ThermalDrift::uniform(2, 20.0, 23e-6)
                .unwrap()
                .check_fits(3)
                .is_err()
        );
    }

    #[test]
    fn deserializing_validates_and_round_trips() {
        let t = ThermalDrift::uniform(2, 20.0, 23e-6)
            .unwrap()
            .with_zero_drift(vec![1e-6, -2e-6])
            .unwrap();
        let s = serde_json::to_string(&t).unwrap();
        assert_eq!(serde_json::from_str::<ThermalDrift>(&s).unwrap(), t);
        let bad = r#"{"t_ref_c": 20, "alpha_per_k": [23, 0, 0]}"#;
        let e = serde_json::from_str::<ThermalDrift>(bad).unwrap_err();
        assert!(e.to_string().contains("alpha_per_k[0]"), "{e}");
        let no_beta: ThermalDrift =
            serde_json::from_str(r#"{"t_ref_c": 20, "alpha_per_k": [1e-5, 1e-5, 1e-5]}"#).unwrap();
        assert_eq!(no_beta.beta_rad_per_k(), &[0.0, 0.0]);
        let prof: TemperatureProfile =
            serde_json::from_str(r#"{"schedule": [[0, 20], [10, 21]]}"#).unwrap();
        assert!((prof.temp_at(5.0) - 20.5).abs() < 1e-15);
        assert!(
            serde_json::from_str::<TemperatureProfile>(r#"{"schedule": [[10, 20], [0, 21]]}"#)
                .is_err()
        );
        let bad_tau = r#"{"warm_up": {"t0_c": 20, "delta_c": 5, "tau_s": -1}}"#;
        let e = serde_json::from_str::<TemperatureProfile>(bad_tau).unwrap_err();
        assert!(e.to_string().contains("tau_s"), "{e}");
    }
}
