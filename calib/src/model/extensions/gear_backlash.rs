//! Gear backlash, as the estimator models it: `θᵢ = qᵢ − sᵢ hᵢ`.
//!
//! `hᵢ` is half of joint `i`'s lost motion (rad; m for a prismatic joint) and `sᵢ` the side of the dead
//! band the link rests on: the sign of the joint's last motion (`dir` column; the link lags the motor),
//! or, without `dir` columns, the sign of the holding torque `τᵢ` (gravity pulls the link against its
//! holding torque, onto the loaded flank). A joint always approached from the same side cannot be told
//! from a zero offset; the solver reports that and leaves `hᵢ` at zero.
//!
//! # Plausibility bounds
//! `0 ≤ hᵢ ≤` [`MAX_HALF_RAD`] (2 mrad, 0.11°; prismatic joints [`MAX_HALF_M`], 0.5 mm). A negative
//! lost motion is impossible (the link would lead its motor). Precision reducers are specified at
//! about 1 arc-min (0.29 mrad) of lost motion (harmonic drives below that, cycloidal RV reducers
//! 0.5–1 arc-min, precision planetary gears 1–3 arc-min); a half lost motion of 2 mrad is a full
//! 14 arc-min, several times a worn spur gear's. A larger fitted value stands in for another error
//! that flips with the load or the approach direction. Ball screws and racks of linear axes have a few
//! to some tens of µm.

use super::settings::missing_column;
use super::{BacklashSign, Cause, CauseModel, ExtensionParam, ExtensionSettings, PlotAxis};
use super::{RowInputs, Term, per_joint_params};
use crate::error::Result;
use crate::units::Unit;
use sim::Model;
use sim::measurement_table::MeasurementTable;

/// Expected half lost motion (rad): harmonic drives have about 1 arc-min (2.9e-4 rad) of lost motion.
pub const SCALE_RAD: f64 = 1e-4;

/// Largest plausible half lost motion of a rotational joint (rad): 2 mrad, 0.11° (module docs).
pub const MAX_HALF_RAD: f64 = 2e-3;

/// Largest plausible half lost motion of a prismatic joint (m): 0.5 mm.
pub const MAX_HALF_M: f64 = 5e-4;

/// Gear backlash: one half-lost-motion per joint, regressor `−sᵢ`.
pub struct GearBacklash;

impl CauseModel for GearBacklash {
    fn cause(&self) -> Cause {
        Cause::GearBacklash
    }

    fn usable(&self, model: &Model, table: &MeasurementTable) -> std::result::Result<(), String> {
        if table.dir.is_some() {
            return Ok(());
        }
        model.require_inertials().map_err(|e| {
            format!(
                "the table has no dir1..dirN columns, and the gravity torques that would sign the \
                 lost motion instead cannot be computed: {e}"
            )
        })
    }

    fn needs_gravity_torque(&self, settings: &ExtensionSettings) -> bool {
        settings.backlash_sign == BacklashSign::GravityTorque
    }

    fn params(&self, model: &Model, _settings: &ExtensionSettings) -> Vec<ExtensionParam> {
        per_joint_params(
            model,
            Cause::GearBacklash,
            "half lost motion",
            Unit::Radian,
            Unit::Metre,
            SCALE_RAD,
        )
    }

    fn check_table(
        &self,
        settings: &ExtensionSettings,
        table: &MeasurementTable,
        file: &str,
    ) -> Result<()> {
        if settings.backlash_sign == BacklashSign::Direction && table.dir.is_none() {
            return Err(missing_column(
                file,
                "dir1..dirN",
                "gear_backlash (signed by approach direction)",
            ));
        }
        Ok(())
    }

    fn regressors(&self, settings: &ExtensionSettings, row: &RowInputs<'_>, out: &mut [f64]) {
        regressors(settings.backlash_sign, row.dir, row.tau, out);
    }

    fn evidence_subject(&self, joints: &str) -> String {
        format!("the approach direction of {joints}")
    }

    fn implausible(&self, param: &ExtensionParam, value: f64) -> Option<String> {
        let (max, words) = if param.unit == Unit::Metre {
            (MAX_HALF_M, "0.5 mm")
        } else {
            (MAX_HALF_RAD, "2 mrad (0.11°)")
        };
        super::outside_zero_to(
            value,
            max,
            "negative lost motion: a link ahead of its motor",
            || format!("a half lost motion above {words}: no precision gear has that much"),
        )
    }

    fn signature(&self) -> &'static str {
        "flips sign with the side a joint was approached from"
    }

    fn plot_axis(&self, term: Term) -> PlotAxis {
        PlotAxis {
            sign: -1.0,
            label: format!(
                "approach direction of joint {} (−1, +1)",
                term.joint().map_or(0, |j| j + 1)
            ),
        }
    }
}

/// Regressors `−sᵢ` (−1, 0 or +1) of one row, from its approach signs `dir` or its holding torques
/// `tau` (N m), as `sign` says.
fn regressors(sign: BacklashSign, dir: Option<&[i8]>, tau: &[f64], out: &mut [f64]) {
    match (sign, dir) {
        (BacklashSign::Direction, Some(d)) => {
            for (o, &s) in out.iter_mut().zip(d) {
                *o = -f64::from(s);
            }
        }
        _ => {
            for (o, &t) in out.iter_mut().zip(tau) {
                *o = if t > 0.0 {
                    -1.0
                } else if t < 0.0 {
                    1.0
                } else {
                    0.0
                };
            }
        }
    }
}
