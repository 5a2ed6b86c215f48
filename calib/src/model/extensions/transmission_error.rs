//! Transmission error, as the estimator models it: an angle error periodic in the joint's own angle,
//!
//! ```text
//! θᵢ = qᵢ + Σₖ₌₁..₃ (aᵢₖ sin k qᵢ + bᵢₖ cos k qᵢ)
//! ```
//!
//! `aᵢₖ`, `bᵢₖ` (rad) are the sine and cosine amplitudes of harmonic `k` per revolution of joint `i`:
//! the eccentricity of a gear or an encoder disc (k = 1), the elliptic flexspline of a harmonic drive
//! (k = 2) and their products (k = 3). Six parameters per rotational joint that turns over at least
//! half a revolution ([`MIN_SPAN_RAD`]) in the training data (prismatic joints have none: a lead
//! screw's error is periodic in its pitch, not in a revolution). They are linear in the regressors
//! `sin k qᵢ`, `cos k qᵢ` of the commanded angle, so they enter as joint-angle terms. No harmonic is a
//! geometric error: a constant error twist or zero offset changes the angle about the joint's axis by a
//! constant, never by `sin k qᵢ`.
//!
//! # What the data can tell
//! Over less than a full turn a periodic error is not told from a smooth one: within 340° a first
//! harmonic is 99.5 % a cubic in the angle, and harmonics 1–3 represent `q²` or `q⁴` as well
//! (`scripts/`-free arithmetic in docs/diagnose.md). So this cause stands for *an angle error of a
//! joint that depends on its own angle alone*, smooth at the scale of a third of a turn: gear and
//! encoder eccentricity, a harmonic drive's two-per-revolution error, a wrong gear ratio. Below half
//! a turn even the third harmonic is 80 % a cubic and the amplitudes lose their meaning, so such a
//! joint gets none.
//!
//! # Plausibility bounds
//! `|aᵢₖ|, |bᵢₖ| ≤` [`MAX_AMPLITUDE_RAD`] (5 mrad, either sign: a harmonic has no preferred phase). An
//! amplitude beyond that is no gear's ([`CauseModel::implausible`]): it is what harmonics fitted to
//! something else over part of a turn look like.

use super::{Cause, CauseModel, ExtensionParam, ExtensionSettings, PlotAxis, RowInputs, Term};
use crate::units::Unit;
use sim::Model;
use sim::measurement_table::MeasurementTable;

/// Harmonics per revolution modelled: 1 to this.
pub const HARMONICS: usize = 3;

/// Expected amplitude of one harmonic (rad): harmonic drives have 1 arc-min (2.9e-4 rad) of
/// transmission error peak to peak.
pub const SCALE_RAD: f64 = 1e-4;

/// Smallest span of a joint's angles in the training data (rad) for it to get harmonics: half a turn.
pub const MIN_SPAN_RAD: f64 = std::f64::consts::PI;

/// Largest plausible amplitude of one harmonic (rad): 5 mrad, 17 arc-min, over ten times the
/// transmission error of a harmonic drive or a worn spur gear.
pub const MAX_AMPLITUDE_RAD: f64 = 5e-3;

/// 0-based rotational joints of `model` whose angles span at least [`MIN_SPAN_RAD`] over `rows` of
/// `table`.
pub fn turning_joints(model: &Model, table: &MeasurementTable, rows: &[usize]) -> Vec<usize> {
    (0..model.nq())
        .filter(|&j| model.joints()[j].kind.is_rotational())
        .filter(|&j| span_rad(table, rows, j) >= MIN_SPAN_RAD)
        .collect()
}

/// The span (rad) of joint `j`'s angles (0-based) over `rows` of `table`: largest minus smallest.
fn span_rad(table: &MeasurementTable, rows: &[usize], j: usize) -> f64 {
    let (lo, hi) = rows
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &r| {
            let v = table.q_row(r)[j];
            (lo.min(v), hi.max(v))
        });
    (hi - lo).max(0.0)
}

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

    fn usable(&self, model: &Model, table: &MeasurementTable) -> std::result::Result<(), String> {
        let all: Vec<usize> = (0..table.len()).collect();
        if turning_joints(model, table, &all).is_empty() {
            return Err(format!(
                "no rotational joint turns over half a revolution in the data ({:.0}°): an error \
                 periodic in its angle cannot be told from a smooth one",
                MIN_SPAN_RAD.to_degrees()
            ));
        }
        Ok(())
    }

    /// The joints that turn over half a revolution in the training rows.
    fn configure(
        &self,
        settings: &mut ExtensionSettings,
        model: &Model,
        table: &MeasurementTable,
        rows: &[usize],
        _source: &str,
    ) -> crate::error::Result<()> {
        settings.transmission_joints = turning_joints(model, table, rows);
        Ok(())
    }

    /// The rotational joints left without harmonics, with the span they turn through, and the
    /// harmonic joints that turn through less than a full revolution, whose first harmonic is then
    /// told from a smooth error only by its curvature (it predicts beyond the span they turned
    /// through as a smooth error would not).
    fn notes(
        &self,
        settings: &ExtensionSettings,
        model: &Model,
        table: &MeasurementTable,
        rows: &[usize],
    ) -> Vec<String> {
        let spans = |joints: &[usize]| {
            let word = if joints.len() == 1 { "joint" } else { "joints" };
            let list = joints
                .iter()
                .map(|&j| format!("{} ({:.1}°)", j + 1, span_rad(table, rows, j).to_degrees()))
                .collect::<Vec<_>>()
                .join(", ");
            format!("{word} {list}")
        };
        // Only the joints the model names (`transmission_error@…` limits them).
        let named =
            |j: usize| settings.acts_at(Cause::TransmissionError, Term::JointAngle { joint: j });
        let left_out: Vec<usize> = (0..model.nq())
            .filter(|&j| model.joints()[j].kind.is_rotational() && named(j))
            .filter(|j| !settings.transmission_joints.contains(j))
            .collect();
        let part_turn: Vec<usize> = settings
            .transmission_joints
            .iter()
            .copied()
            .filter(|&j| named(j) && span_rad(table, rows, j) < 2.0 * std::f64::consts::PI)
            .collect();
        let mut notes = Vec::new();
        if !left_out.is_empty() {
            notes.push(format!(
                "transmission_error: no harmonics at {} (their angles span less than half a \
                 revolution, {:.0}°, in the training data, where an error periodic in the angle is \
                 not told from a smooth one)",
                spans(&left_out),
                MIN_SPAN_RAD.to_degrees()
            ));
        }
        if !part_turn.is_empty() {
            notes.push(format!(
                "transmission_error: the angles of {} span less than a full revolution in \
                 the training data: their harmonics are determined over that span only, and \
                 predict angles beyond it as extrapolations (check validation.new_region)",
                spans(&part_turn)
            ));
        }
        notes
    }

    fn needs_gravity_torque(&self, _settings: &ExtensionSettings) -> bool {
        false
    }

    fn params(&self, _model: &Model, settings: &ExtensionSettings) -> Vec<ExtensionParam> {
        settings
            .transmission_joints
            .iter()
            .flat_map(|&i| {
                QUANTITIES.iter().map(move |&quantity| ExtensionParam {
                    cause: Cause::TransmissionError,
                    term: Term::JointAngle { joint: i },
                    quantity,
                    unit: Unit::Radian,
                    scale: SCALE_RAD,
                    pattern: None,
                })
            })
            .collect()
    }

    /// `sin k qᵢ`, `cos k qᵢ` (dimensionless) of each harmonic joint's commanded angle.
    fn regressors(&self, settings: &ExtensionSettings, row: &RowInputs<'_>, out: &mut [f64]) {
        for (&j, o) in settings
            .transmission_joints
            .iter()
            .zip(out.chunks_exact_mut(2 * HARMONICS))
        {
            harmonics(row.q[j], o);
        }
    }

    /// `∂Δθⱼ/∂qⱼ = Σₖ k (aⱼₖ cos k qⱼ − bⱼₖ sin k qⱼ)`: exact, on the diagonal.
    fn angle_jacobian(
        &self,
        settings: &ExtensionSettings,
        row: &RowInputs<'_>,
        _torque_jacobian: &[f64],
        x: &[f64],
        d_dq: &mut [f64],
        _d_dtheta: &mut [f64],
    ) {
        let n = row.q.len();
        for (&j, xs) in settings
            .transmission_joints
            .iter()
            .zip(x.chunks_exact(2 * HARMONICS))
        {
            let mut d = 0.0;
            for k in 1..=HARMONICS {
                let (sn, cs) = (k as f64 * row.q[j]).sin_cos();
                let (a, b) = (xs[2 * (k - 1)], xs[2 * (k - 1) + 1]);
                d += k as f64 * (a * cs - b * sn);
            }
            d_dq[j * n + j] += d;
        }
    }

    fn implausible(&self, _param: &ExtensionParam, value: f64) -> Option<String> {
        (value.abs() > MAX_AMPLITUDE_RAD)
            .then(|| "a harmonic amplitude beyond 5 mrad: no gear errs by that much".into())
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

    /// The report names the joints left without harmonics and those fitted over part of a turn,
    /// with their spans, and says nothing of a joint that turned through a full revolution.
    #[test]
    fn notes_name_the_joints_by_the_span_they_turned() {
        use sim::measurement_table::{OptionalColumns, Row};
        let model = sim::robots::load_builtin("iiwa7").unwrap();
        let mut table = MeasurementTable::new(7, OptionalColumns::NONE);
        // Joint 1 over a full turn (−π to π), joint 2 over 200°, joint 3 over 90°, the rest fixed.
        let n = 101;
        for pose in 0..n {
            let t = pose as f64 / (n - 1) as f64;
            let q = [
                -std::f64::consts::PI + t * std::f64::consts::TAU,
                (t - 0.5) * 200f64.to_radians(),
                (t - 0.5) * 90f64.to_radians(),
                0.0,
                0.0,
                0.0,
                0.0,
            ];
            table
                .push_row(&Row {
                    pose: pose as i64,
                    q: &q,
                    position: [0.0; 3],
                    ..Row::default()
                })
                .unwrap();
        }
        let rows: Vec<usize> = (0..n).collect();
        let settings = ExtensionSettings::for_data(
            &model,
            &[Cause::TransmissionError],
            &std::collections::BTreeMap::new(),
            &table,
            &rows,
            "test",
        )
        .unwrap();
        assert_eq!(settings.transmission_joints, vec![0, 1]);
        let notes = TransmissionError.notes(&settings, &model, &table, &rows);
        assert_eq!(notes.len(), 2, "{notes:?}");
        assert!(
            notes[0].contains(
                "no harmonics at joints 3 (90.0°), 4 (0.0°), 5 (0.0°), 6 (0.0°), 7 (0.0°)"
            ),
            "{}",
            notes[0]
        );
        assert!(
            notes[1].contains("the angles of joint 2 (200.0°) span less than a full revolution"),
            "{}",
            notes[1]
        );
        // Limited to joints 1 and 3 (`transmission_error@1,3`): joint 3 is too short, joint 1 a full
        // turn; the joints left out by the user are not reported.
        let limited = ExtensionSettings::for_data(
            &model,
            &[Cause::TransmissionError],
            &[(Cause::TransmissionError, vec![0, 2])]
                .into_iter()
                .collect(),
            &table,
            &rows,
            "test",
        )
        .unwrap();
        let notes = TransmissionError.notes(&limited, &model, &table, &rows);
        assert_eq!(
            notes,
            vec![
                "transmission_error: no harmonics at joint 3 (90.0°) (their angles span less than \
                 half a revolution, 180°, in the training data, where an error periodic in the angle \
                 is not told from a smooth one)"
                    .to_string()
            ]
        );
    }
}
