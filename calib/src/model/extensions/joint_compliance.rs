//! Joint compliance, as the estimator models it: `θᵢ = qᵢ − cᵢ τᵢ(q)`.
//!
//! `cᵢ` is joint `i`'s compliance (rad/(N m); m/N for a prismatic joint) and `τᵢ(q)` the torque (N m)
//! the joint applies to hold the nominal arm and the payload still at the commanded `q` against gravity
//! ([`sim::statics::gravity_torques`]). This is the first-order solution of the spring balance
//! `K (q − θ) = τ(θ)`; the exact one differs by `C H C τ` (`H = ∂τ/∂θ`), second order in the compliance:
//! below 0.1 µrad for the iiwa 7's 1e-4 rad/(N m) and 50 N m.
//! A joint whose torque does not change over the data (joint 1 of an upright arm) cannot be identified;
//! the solver says so and leaves its compliance at zero.

use super::per_joint_params;
use super::{Cause, CauseModel, ExtensionParam, ExtensionSettings, PlotAxis, RowInputs, Term};
use crate::units::Unit;
use sim::Model;
use sim::measurement_table::MeasurementTable;

/// Expected compliance (rad/(N m)): harmonic-drive joints of lightweight arms are 5e3–2e4 N m/rad.
pub const SCALE_RAD_PER_NM: f64 = 1e-4;

/// Joint compliance: one compliance per joint, regressor `−τᵢ`.
pub struct JointCompliance;

impl CauseModel for JointCompliance {
    fn cause(&self) -> Cause {
        Cause::JointCompliance
    }

    fn usable(&self, model: &Model, _table: &MeasurementTable) -> std::result::Result<(), String> {
        model
            .require_inertials()
            .map_err(|e| format!("the gravity torques it needs cannot be computed: {e}"))
    }

    fn needs_gravity_torque(&self, _settings: &ExtensionSettings) -> bool {
        true
    }

    fn needs_equilibrium(&self) -> bool {
        true
    }

    fn params(&self, model: &Model, _settings: &ExtensionSettings) -> Vec<ExtensionParam> {
        per_joint_params(
            model,
            Cause::JointCompliance,
            "compliance",
            Unit::RadianPerNewtonMetre,
            Unit::MetrePerNewton,
            SCALE_RAD_PER_NM,
        )
    }

    /// Regressors `−τᵢ` (N m) from the row's gravity torques.
    fn regressors(&self, _settings: &ExtensionSettings, row: &RowInputs<'_>, out: &mut [f64]) {
        for (o, t) in out.iter_mut().zip(row.tau) {
            *o = -t;
        }
    }

    fn evidence_subject(&self, joints: &str) -> String {
        format!("the gravity torque of {joints}")
    }

    fn remark(&self, value: f64) -> String {
        if value > 0.0 {
            format!(" (stiffness {:.0} N m/rad)", 1.0 / value)
        } else {
            " (negative: no spring; it stands in for another error)".to_string()
        }
    }

    fn impossible(&self, value: f64) -> Option<&'static str> {
        (value < 0.0).then_some("negative compliance: no spring turns a joint along its load")
    }

    fn signature(&self) -> &'static str {
        "turns a joint about its own axis in proportion to its gravity torque"
    }

    fn plot_axis(&self, term: Term) -> PlotAxis {
        PlotAxis {
            sign: -1.0,
            label: format!(
                "holding torque of joint {} (N m)",
                term.joint().map_or(0, |j| j + 1)
            ),
        }
    }
}
