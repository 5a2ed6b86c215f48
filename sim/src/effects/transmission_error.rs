//! Transmission error: a link angle that departs from the reported joint angle periodically over each
//! revolution of the joint.
//!
//! # Model
//!
//! The controller reports joint `i` at `qᵢ` (rad); the link side sits at
//!
//! ```text
//! θᵢ = qᵢ + Σₖ Aᵢₖ sin(hₖ qᵢ + φᵢₖ)
//! ```
//!
//! with harmonic orders `hₖ` (cycles per revolution of the joint's own angle, integers ≥ 1; default
//! 1, 2, 3), amplitudes `Aᵢₖ` (rad; negative values are allowed and equal a phase of `φ + π`) and
//! phases `φᵢₖ` (rad). `qᵢ` is the reported angle of the measurement ([`super::Conditions::q`]), so
//! the error is a fixed function of what the controller says, as a gear or encoder error is.
//!
//! It stands for what turns a motor-side encoder reading into a link angle that is off by a periodic
//! amount: the kinematic (transmission) error of a harmonic drive's output over one revolution, the
//! eccentricity of an encoder disc or of a gear to its bearing (one cycle per revolution), and
//! out-of-roundness of a gear (two and more). The shift enters the chain as an angle change, like
//! [`super::gear_backlash`]: it is applied before backlash and compliance, which then act about the
//! shifted angle, and it moves the link-side positions of [`super::TrueTarget::q_link`].
//!
//! # Harmonics beyond the third
//!
//! The estimator's `transmission_error` cause (`calib`) covers orders 1–3. The simulator takes any
//! orders up to [`MAX_ORDER`]: an order of 4 or more is an effect outside the estimator's vocabulary
//! (for the blind tests), as are the high orders of a harmonic drive's wave generator (2 cycles per
//! wave-generator revolution, i.e. twice the gear ratio per output revolution).
//!
//! For a prismatic joint `qᵢ` is in m and order `h` has a period of `2π/h` m; the amplitude is in m.
//!
//! # Magnitudes
//!
//! Harmonic Drive CSF/CSG catalogue, "Positioning Accuracy" (the difference between the largest
//! positive and negative deviation of the output angle over one output revolution): 1.5–2.9·10⁻⁴ rad
//! (0.5–1 arc-min) for ratios of 50 and more in sizes 14–100, 4.4–5.8·10⁻⁴ rad at ratio 30; the
//! amplitude of one harmonic is at most half of that, ≈ 0.7–1.5·10⁻⁴ rad. Encoder eccentricity: an
//! encoder graduation of diameter `D` mounted with eccentricity `e` reads off by `Δφ = ±412 e/D`
//! arc-seconds (`e` in µm, `D` in mm; Heidenhain, "Angle Encoders without Integral Bearing"), so
//! 5 µm on a 50 mm disc gives 41″ ≈ 2·10⁻⁴ rad at one cycle per revolution.

use super::effect::{Effect, Moved, Prepare, ResolveCx, State};
use crate::effect_id::EffectId;
use crate::error::{Result, SimError};
use crate::magnitude::Magnitude;

/// Largest accepted harmonic order (cycles per revolution).
pub const MAX_ORDER: u32 = 1000;
/// Largest accepted amplitude `|Aᵢₖ|` (rad): 10 mrad (34 arc-min) is far beyond any gear or encoder
/// error; more is almost surely a value in degrees.
pub const MAX_AMPLITUDE_RAD: f64 = 0.01;
/// The default harmonic orders: once, twice and three times per revolution.
pub const DEFAULT_ORDERS: [u32; 3] = [1, 2, 3];

/// Per-joint periodic transmission error (see the module docs for the model).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "TransmissionErrorSpec")]
pub struct TransmissionError {
    /// Harmonic orders `hₖ` (cycles per revolution), distinct, 1 … [`MAX_ORDER`].
    harmonics: Vec<u32>,
    /// Amplitude `Aᵢₖ` (rad; m for prismatic joints), one row per joint, one entry per harmonic.
    amplitude_rad: Vec<Vec<f64>>,
    /// Phase `φᵢₖ` (rad), same shape as the amplitudes.
    phase_rad: Vec<Vec<f64>>,
}

/// Serialized form of [`TransmissionError`]: `harmonics` defaults to 1, 2, 3 and `phase_rad` to zero.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct TransmissionErrorSpec {
    #[serde(default)]
    harmonics: Option<Vec<u32>>,
    amplitude_rad: Vec<Vec<f64>>,
    #[serde(default)]
    phase_rad: Option<Vec<Vec<f64>>>,
}

impl TryFrom<TransmissionErrorSpec> for TransmissionError {
    type Error = SimError;
    fn try_from(s: TransmissionErrorSpec) -> Result<Self> {
        let harmonics = s.harmonics.unwrap_or_else(|| DEFAULT_ORDERS.to_vec());
        let phase = s.phase_rad.unwrap_or_else(|| {
            s.amplitude_rad
                .iter()
                .map(|row| vec![0.0; row.len()])
                .collect()
        });
        TransmissionError::new(harmonics, s.amplitude_rad, phase)
    }
}

fn check_orders(harmonics: &[u32]) -> Result<()> {
    if harmonics.is_empty() {
        return Err(SimError::bad_effect(
            EffectId::TransmissionError,
            "harmonics",
            "[]",
            "give at least one order (e.g. [1, 2, 3])",
        ));
    }
    for (k, &h) in harmonics.iter().enumerate() {
        if h == 0 || h > MAX_ORDER {
            return Err(SimError::bad_effect(
                EffectId::TransmissionError,
                format!("harmonics[{k}]"),
                h,
                format!("must be a whole number of cycles per revolution, 1 … {MAX_ORDER}"),
            ));
        }
        if harmonics[..k].contains(&h) {
            return Err(SimError::bad_effect(
                EffectId::TransmissionError,
                format!("harmonics[{k}]"),
                h,
                "given twice",
            ));
        }
    }
    Ok(())
}

impl TransmissionError {
    /// Transmission error with harmonic orders `harmonics` (cycles per revolution), amplitudes
    /// `amplitude_rad[i][k]` and phases `phase_rad[i][k]` (rad) of joint `i` and harmonic `k`.
    /// Refuses an empty, repeated or out-of-range order, rows of another length than `harmonics`,
    /// non-finite values and amplitudes above [`MAX_AMPLITUDE_RAD`].
    pub fn new(
        harmonics: Vec<u32>,
        amplitude_rad: Vec<Vec<f64>>,
        phase_rad: Vec<Vec<f64>>,
    ) -> Result<Self> {
        check_orders(&harmonics)?;
        let nh = harmonics.len();
        if phase_rad.len() != amplitude_rad.len() {
            return Err(SimError::bad_effect(
                EffectId::TransmissionError,
                "phase_rad",
                format!("{} rows", phase_rad.len()),
                format!(
                    "needs one row per joint, as amplitude_rad ({})",
                    amplitude_rad.len()
                ),
            ));
        }
        for (i, (a_row, p_row)) in amplitude_rad.iter().zip(&phase_rad).enumerate() {
            for (name, row) in [("amplitude_rad", a_row), ("phase_rad", p_row)] {
                if row.len() != nh {
                    return Err(SimError::bad_effect(
                        EffectId::TransmissionError,
                        format!("{name}[{i}]"),
                        format!("{} entries", row.len()),
                        format!("needs one per harmonic ({nh})"),
                    ));
                }
                if let Some((k, v)) = row.iter().enumerate().find(|(_, v)| !v.is_finite()) {
                    return Err(SimError::bad_effect(
                        EffectId::TransmissionError,
                        format!("{name}[{i}][{k}]"),
                        v,
                        "not finite",
                    ));
                }
            }
            if let Some((k, a)) = a_row
                .iter()
                .enumerate()
                .find(|(_, a)| a.abs() > MAX_AMPLITUDE_RAD)
            {
                return Err(SimError::bad_effect(
                    EffectId::TransmissionError,
                    format!("amplitude_rad[{i}][{k}]"),
                    a,
                    format!(
                        "amplitude above {MAX_AMPLITUDE_RAD} rad; give it in rad, not degrees or arc-min"
                    ),
                ));
            }
        }
        Ok(TransmissionError {
            harmonics,
            amplitude_rad,
            phase_rad,
        })
    }

    /// Harmonic orders (cycles per revolution).
    pub fn harmonics(&self) -> &[u32] {
        &self.harmonics
    }

    /// Amplitudes, one row per joint (rad or m).
    pub fn amplitude_rad(&self) -> &[Vec<f64>] {
        &self.amplitude_rad
    }

    /// Phases, one row per joint (rad).
    pub fn phase_rad(&self) -> &[Vec<f64>] {
        &self.phase_rad
    }

    /// The shift `θᵢ − qᵢ = Σₖ Aᵢₖ sin(hₖ qᵢ + φᵢₖ)` of joint `i` (0-based) at reported angle `q`
    /// (rad or m).
    pub fn shift(&self, i: usize, q: f64) -> f64 {
        let mut s = 0.0;
        for ((&h, &a), &p) in self
            .harmonics
            .iter()
            .zip(&self.amplitude_rad[i])
            .zip(&self.phase_rad[i])
        {
            if a != 0.0 {
                s += a * crate::trig::sin_cos(f64::from(h) * q + p).0;
            }
        }
        s
    }

    /// Checks that the lengths fit a robot with `nq` joints.
    pub fn check_fits(&self, nq: usize) -> Result<()> {
        if self.amplitude_rad.len() != nq {
            return Err(SimError::bad_effect(
                EffectId::TransmissionError,
                "amplitude_rad",
                format!("{} rows", self.amplitude_rad.len()),
                format!("the robot has {nq} joints"),
            ));
        }
        Ok(())
    }
}

/// `[effects.transmission]`.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TransmissionSection {
    /// Switch (default on).
    pub enabled: Option<bool>,
    /// Harmonic orders (cycles per revolution of the joint); default `[1, 2, 3]`.
    pub harmonics: Option<Vec<u32>>,
    /// Amplitude of each harmonic (rad), shape `[n][len(harmonics)]`.
    pub amplitude_rad: Magnitude,
    /// Phase of each harmonic (rad), shape `[n][len(harmonics)]`; default 0.
    pub phase_rad: Option<Magnitude>,
}

/// The prepared stage: the nonzero terms only.
#[derive(Clone, Debug)]
pub struct TransmissionStage {
    effect: TransmissionError,
    /// Joints with at least one nonzero amplitude (0-based).
    joints: Vec<usize>,
}

fn rows(flat: Vec<f64>, n: usize, nh: usize) -> Vec<Vec<f64>> {
    (0..n)
        .map(|i| flat[i * nh..(i + 1) * nh].to_vec())
        .collect()
}

impl Effect for TransmissionError {
    const ID: EffectId = EffectId::TransmissionError;
    type Section = TransmissionSection;
    type Stage = TransmissionStage;
    type Scratch = ();

    fn enabled(section: &TransmissionSection) -> bool {
        section.enabled.unwrap_or(true)
    }

    fn from_section(t: &TransmissionSection, cx: &ResolveCx<'_>) -> Result<Self> {
        let n = cx.nq();
        let harmonics = t
            .harmonics
            .clone()
            .unwrap_or_else(|| DEFAULT_ORDERS.to_vec());
        cx.checked(check_orders(&harmonics))?;
        let nh = harmonics.len();
        let a = cx.draw(&t.amplitude_rad, "amplitude_rad", &[n, nh])?;
        let p = cx.draw_or_zero(&t.phase_rad, "phase_rad", &[n, nh])?;
        cx.checked(TransmissionError::new(
            harmonics,
            rows(a, n, nh),
            rows(p, n, nh),
        ))
    }

    fn check_lengths(&self, nq: usize) -> Result<()> {
        self.check_fits(nq)
    }

    fn prepare(&self, _cx: &Prepare<'_>) -> Result<TransmissionStage> {
        let joints = (0..self.amplitude_rad.len())
            .filter(|&i| self.amplitude_rad[i].iter().any(|&a| a != 0.0))
            .collect();
        Ok(TransmissionStage {
            effect: self.clone(),
            joints,
        })
    }

    /// Link-side angle shifted by the periodic error of the reported angle: `φᵢ += Σₖ Aᵢₖ sin(hₖ qᵢ +
    /// φᵢₖ)`, and the same on the link-side positions.
    #[inline]
    fn act<'t>(stage: &'t TransmissionStage, st: &mut State<'t, '_>, _: &mut ()) -> Result<Moved> {
        let mut moved = false;
        for &i in &stage.joints {
            let d = stage.effect.shift(i, st.cond.q[i]);
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

    #[test]
    fn shift_is_the_documented_sum_of_sines() {
        let t = TransmissionError::new(
            vec![1, 2, 3],
            vec![vec![1e-4, 0.0, -2e-5], vec![0.0; 3]],
            vec![vec![0.3, 1.0, -0.7], vec![0.0; 3]],
        )
        .unwrap();
        let q = 0.9_f64;
        // By hand: 1e-4 sin(0.9 + 0.3) − 2e-5 sin(2.7 − 0.7) = 1e-4 sin 1.2 − 2e-5 sin 2.0.
        let want = 1e-4 * 1.2_f64.sin() - 2e-5 * 2.0_f64.sin();
        assert!((t.shift(0, q) - want).abs() < 1e-19, "{}", t.shift(0, q));
        assert_eq!(t.shift(1, q), 0.0);
        // Order 5 at q = π/10: sin(π/2) = 1.
        let t5 = TransmissionError::new(vec![5], vec![vec![3e-5]], vec![vec![0.0]]).unwrap();
        assert!((t5.shift(0, std::f64::consts::PI / 10.0) - 3e-5).abs() < 1e-20);
    }

    #[test]
    fn constructor_refuses_bad_values_naming_the_field() {
        let ok = || vec![vec![1e-4, 0.0, 0.0]];
        let e = TransmissionError::new(vec![1, 2, 2], ok(), ok()).unwrap_err();
        assert!(e.to_string().contains("harmonics[2]"), "{e}");
        let e = TransmissionError::new(vec![0, 1, 2], ok(), ok()).unwrap_err();
        assert!(e.to_string().contains("harmonics[0]"), "{e}");
        let e = TransmissionError::new(vec![], vec![vec![]], vec![vec![]]).unwrap_err();
        assert!(e.to_string().contains("harmonics"), "{e}");
        let e = TransmissionError::new(vec![1, 2, 3], vec![vec![0.0, 0.5, 0.0]], ok()).unwrap_err();
        assert!(
            e.to_string().contains("amplitude_rad[0][1]") && e.to_string().contains("degrees"),
            "{e}"
        );
        let e = TransmissionError::new(vec![1, 2, 3], ok(), vec![vec![0.0, f64::NAN, 0.0]])
            .unwrap_err();
        assert!(e.to_string().contains("phase_rad[0][1]"), "{e}");
        let e = TransmissionError::new(vec![1, 2], ok(), ok()).unwrap_err();
        assert!(e.to_string().contains("amplitude_rad[0]"), "{e}");
        let e = TransmissionError::new(vec![1, 2, 3], ok(), vec![]).unwrap_err();
        assert!(e.to_string().contains("phase_rad"), "{e}");
        assert!(
            TransmissionError::new(vec![1, 2, 3], ok(), ok())
                .unwrap()
                .check_fits(7)
                .is_err()
        );
    }

    #[test]
    fn deserializing_fills_defaults_validates_and_round_trips() {
        let t: TransmissionError =
            serde_json::from_str(r#"{"amplitude_rad": [[1e-4, 0, 2e-5]]}"#).unwrap();
        assert_eq!(t.harmonics(), &[1, 2, 3]);
        assert_eq!(t.phase_rad(), &[vec![0.0; 3]]);
        let s = serde_json::to_string(&t).unwrap();
        assert_eq!(serde_json::from_str::<TransmissionError>(&s).unwrap(), t);
        let e = serde_json::from_str::<TransmissionError>(r#"{"amplitude_rad": [[1.0, 0, 0]]}"#)
            .unwrap_err();
        assert!(e.to_string().contains("amplitude_rad[0][0]"), "{e}");
    }
}
