//! Transmission error, as the estimator models it: an angle error periodic in the joint's own angle,
//!
//! ```text
//! θᵢ = qᵢ + Σₖ₌₁..₃ (aᵢₖ sin k qᵢ + bᵢₖ cos k qᵢ)
//! ```
//!
//! `aᵢₖ`, `bᵢₖ` (rad) are the sine and cosine amplitudes of harmonic `k` per revolution of joint `i`:
//! the eccentricity of a gear or an encoder disc (k = 1), the elliptic flexspline of a harmonic drive
//! (k = 2) and their products (k = 3). Six parameters per rotational joint (prismatic joints have none:
//! a lead screw's error is periodic in its pitch, not in a revolution). They are linear in the
//! regressors `sin k qᵢ`, `cos k qᵢ` of the commanded angle, so they enter as joint-angle terms. No
//! harmonic is a geometric error: a constant error twist or zero offset changes the angle about the
//! joint's axis by a constant, never by `sin k qᵢ`, so each is identifiable when the joint moves over
//! enough of a turn (a joint that hardly moves leaves them in the solver's null space).

use super::{Cause, CauseModel, ExtensionParam, ExtensionSettings, PlotAxis, RowInputs, Term};
use crate::units::Unit;
use sim::Model;
use sim::measurement_table::MeasurementTable;

/// Harmonics per revolution modelled: 1 to this.
pub const HARMONICS: usize = 3;

/// Expected amplitude of one harmonic (rad): harmonic drives have 1 arc-min (2.9e-4 rad) of
/// transmission error peak to peak.
pub const SCALE_RAD: f64 = 1e-4;

/// Parameter names, in order: sine and cosine of each harmonic.
const QUANTITIES: [&str; 2 * HARMONICS] = [
    "transmission error sin q",
    "transmission error cos q",
    "transmission error sin 2q",
    "transmission error cos 2q",
    "transmission error sin 3q",
    "transmission error cos 3q",
];

/// Transmission error: `2 · HARMONICS` amplitudes per rotational joint.
pub struct TransmissionError;

impl CauseModel for TransmissionError {
    fn cause(&self) -> Cause {
        Cause::TransmissionError
    }

    fn usable(&self, model: &Model, _table: &MeasurementTable) -> std::result::Result<(), String> {
        if model.joints.iter().any(|j| j.kind.is_rotational()) {
            Ok(())
        } else {
            Err("the robot has no rotational joint".into())
        }
    }

    fn needs_gravity_torque(&self, _settings: &ExtensionSettings) -> bool {
        false
    }

    fn params(&self, model: &Model, _settings: &ExtensionSettings) -> Vec<ExtensionParam> {
        model
            .joints
            .iter()
            .enumerate()
            .filter(|(_, j)| j.kind.is_rotational())
            .flat_map(|(i, _)| {
                QUANTITIES.iter().map(move |&quantity| ExtensionParam {
                    cause: Cause::TransmissionError,
                    term: Term::JointAngle { joint: i },
                    quantity,
                    unit: Unit::Radian,
                    scale: SCALE_RAD,
                })
            })
            .collect()
    }

    /// `sin k qᵢ`, `cos k qᵢ` (dimensionless) of each rotational joint's commanded angle.
    fn regressors(&self, _settings: &ExtensionSettings, row: &RowInputs<'_>, out: &mut [f64]) {
        let mut k = 0;
        for (&q, joint) in row.q.iter().zip(row.joints) {
            if !joint.kind.is_rotational() {
                continue;
            }
            harmonics(q, &mut out[k..k + 2 * HARMONICS]);
            k += 2 * HARMONICS;
        }
    }

    fn evidence_subject(&self, joints: &str) -> String {
        format!("the angle of {joints}, periodically (harmonics 1 to {HARMONICS} per revolution)")
    }

    fn signature(&self) -> &'static str {
        "is periodic in the joint's own angle"
    }

    fn own_angle_harmonics(&self) -> usize {
        HARMONICS
    }

    fn plot_axis(&self, term: Term) -> PlotAxis {
        PlotAxis {
            sign: 1.0,
            label: format!("q{} (rad)", term.joint().map_or(0, |j| j + 1)),
        }
    }
}

/// `[sin q, cos q, sin 2q, cos 2q, …]` up to [`HARMONICS`] into `out` (angle `q` in rad).
pub fn harmonics(q: f64, out: &mut [f64]) {
    let (s1, c1) = q.sin_cos();
    let (mut s, mut c) = (s1, c1);
    for k in 0..HARMONICS {
        out[2 * k] = s;
        out[2 * k + 1] = c;
        // sin((k+1)q + q), cos((k+1)q + q) by the addition theorems: one sin_cos per row.
        (s, c) = (s * c1 + c * s1, c * c1 - s * s1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn harmonics_match_the_library_sines() {
        let mut out = [0.0; 2 * HARMONICS];
        for q in [-3.0, -1.2, 0.0, 0.4, 2.9] {
            harmonics(q, &mut out);
            for k in 0..HARMONICS {
                let kq = (k + 1) as f64 * q;
                assert!((out[2 * k] - kq.sin()).abs() < 1e-14);
                assert!((out[2 * k + 1] - kq.cos()).abs() < 1e-14);
            }
        }
    }
}
