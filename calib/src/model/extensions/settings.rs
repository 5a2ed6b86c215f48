//! What the regressors of an extended model are made from, besides the parameter values: stored in the
//! model file so that `predict` builds the same regressors on new data.

use super::Cause;
use crate::error::{CalibError, Result};
use serde::{Deserialize, Serialize};
use sim::Model;
use sim::measurement_table::MeasurementTable;
use std::collections::BTreeMap;

/// Which sign the gear backlash regressor uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BacklashSign {
    /// The approach direction (`dir` columns).
    Direction,
    /// The sign of the gravity torque (no `dir` columns).
    GravityTorque,
}

/// What the temperature regressor `ΔT` is made from.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "source")]
pub enum ThermalInput {
    /// `ΔT = temp − t_ref_c` (K) from the `temp` column.
    Temperature {
        /// Reference temperature (°C): the training mean, where the kinematic parameters hold.
        t_ref_c: f64,
    },
    /// No temperature: a first-order warm-up `w(t) = 1 − exp(−t/τ) − w_ref` (dimensionless) from the
    /// `t` column; the parameters are then per unit of warm-up, not per kelvin.
    WarmUp {
        /// Time constant τ (s), identified by a search over candidates.
        tau_s: f64,
        /// Training mean of `1 − exp(−t/τ)`, subtracted for conditioning.
        w_ref: f64,
    },
}

/// Everything besides the parameter values that the regressors need; stored in the model file so that
/// `predict` builds the same regressors on new data. Each cause reads (and, in
/// [`super::CauseModel::configure`], sets) its own fields.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ExtensionSettings {
    /// The causes, sorted.
    pub causes: Vec<Cause>,
    /// Gravity in the robot base frame (m/s²).
    pub gravity_base: [f64; 3],
    /// Payload centre of mass in the flange frame (m); the table gives only its mass.
    pub payload_com_m: [f64; 3],
    /// Sign source of the backlash regressor: the approach direction when the table has `dir`
    /// columns, else the gravity torque (recorded whatever the causes, as model files always have).
    pub backlash_sign: BacklashSign,
    /// Source of `ΔT`, with thermal drift.
    pub thermal: Option<ThermalInput>,
    /// 0-based joints with transmission-error harmonics: those that turn over at least half a
    /// revolution in the training data ([`super::transmission_error::MIN_SPAN_RAD`]).
    #[serde(default)]
    pub transmission_joints: Vec<usize>,
    /// The 0-based joints of each cause limited to some of its joints (`--model cause@2,4`); a cause
    /// absent from the map acts at all its joints (the default: model files written before the
    /// limits existed load unchanged). Parameters of the other joints are absent, not zero.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub joints: BTreeMap<Cause, Vec<usize>>,
    /// The gravity torques as combinations of unknown mass moments, for a robot without inertials
    /// ([`super::lumped_gravity`]): joint compliance then identifies the products of each joint's
    /// compliance with them, link deflection those of each bending compliance. `None` for a robot with its masses.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lumped_gravity: Option<super::lumped_gravity::LumpedGravity>,
}

impl ExtensionSettings {
    /// Settings for `causes` (each at the 0-based `joints` given for it, else at all its joints) on
    /// training rows `rows` of `table`: each cause configures its part
    /// ([`super::CauseModel::configure`]).
    ///
    /// Errors: compliance (or any cause that needs gravity torques) on a robot without inertials, or
    /// what a cause's configuration refuses (thermal drift on a table with neither `temp` nor `t`).
    pub fn for_data(
        model: &Model,
        causes: &[Cause],
        joints: &BTreeMap<Cause, Vec<usize>>,
        table: &MeasurementTable,
        rows: &[usize],
        source: &str,
    ) -> Result<Self> {
        let mut causes = causes.to_vec();
        causes.sort();
        causes.dedup();
        let joints = joints
            .iter()
            .filter(|(c, _)| causes.contains(c))
            .map(|(c, j)| (*c, j.clone()))
            .collect();
        let mut settings = ExtensionSettings {
            causes,
            gravity_base: sim::statics::DEFAULT_GRAVITY,
            payload_com_m: [0.0; 3],
            backlash_sign: if table.dir.is_some() {
                BacklashSign::Direction
            } else {
                BacklashSign::GravityTorque
            },
            thermal: None,
            transmission_joints: Vec::new(),
            joints,
            lumped_gravity: None,
        };
        let mut refused = None;
        for c in settings.causes.clone() {
            if let Err(e) = c
                .model()
                .configure(&mut settings, model, table, rows, source)
            {
                refused.get_or_insert(e);
            }
        }
        if (settings.needs_gravity_torque() || settings.needs_gravity_moment())
            && let Err(e) = model.require_inertials()
        {
            return Err(CalibError::BadValue {
                context: source.to_string(),
                field: "robot".into(),
                value: model.name().to_string(),
                problem: format!("the extension needs gravity torques: {e}"),
            });
        }
        match refused {
            Some(e) => Err(e),
            None => Ok(settings),
        }
    }

    /// Whether any cause's regressors read the gravity torques.
    pub fn needs_gravity_torque(&self) -> bool {
        self.causes
            .iter()
            .any(|c| c.model().needs_gravity_torque(self))
    }

    /// Whether any cause's regressors read the joint frames at the link angles without the torques.
    pub fn needs_frames(&self) -> bool {
        self.causes.iter().any(|c| c.model().needs_frames(self))
    }

    /// Whether any cause's regressors read the gravity moments the joints transmit.
    pub fn needs_gravity_moment(&self) -> bool {
        self.causes
            .iter()
            .any(|c| c.model().needs_gravity_moment(self))
    }

    /// Whether any cause's regressors depend on the link angles (refits at the equilibrium).
    pub fn needs_equilibrium(&self) -> bool {
        self.causes.iter().any(|c| c.model().needs_equilibrium())
    }

    /// Checks that `table` has the columns these settings read (`temp` or `t` for thermal drift, `dir`
    /// for direction-signed backlash); `file` names it in the error.
    pub fn check_table(&self, table: &MeasurementTable, file: &str) -> Result<()> {
        for c in &self.causes {
            c.model().check_table(self, table, file)?;
        }
        Ok(())
    }

    /// The parameters of every cause, in order: each cause's [`super::CauseModel::params`] at the
    /// joints it acts at ([`ExtensionSettings::acts_at`]).
    pub fn params(&self, model: &Model) -> Vec<super::ExtensionParam> {
        self.causes
            .iter()
            .flat_map(|c| {
                c.model()
                    .params(model, self)
                    .into_iter()
                    .filter(|p| self.acts_at(*c, p.term))
            })
            .collect()
    }

    /// Whether a parameter of `cause` entering through `term` is in the model: always for a term not
    /// tied to a joint (the arm's growth), else when the cause is not limited to some joints or its
    /// joints include the term's.
    pub fn acts_at(&self, cause: Cause, term: super::Term) -> bool {
        match (self.joints.get(&cause), term.joint()) {
            (Some(joints), Some(j)) => joints.contains(&j),
            _ => true,
        }
    }

    /// The settings to try besides these ([`super::CauseModel::alternatives`]), for the rows `rows` of
    /// `table`.
    pub fn alternatives(&self, table: &MeasurementTable, rows: &[usize]) -> Vec<ExtensionSettings> {
        self.causes
            .iter()
            .flat_map(|c| c.model().alternatives(self, table, rows))
            .collect()
    }
}

/// The error for a column that a cause of the model reads but `file` lacks.
pub(crate) fn missing_column(file: &str, col: &str, why: &str) -> CalibError {
    CalibError::BadValue {
        context: file.to_string(),
        field: col.to_string(),
        value: "absent".into(),
        problem: format!("the model's {why} reads this column"),
    }
}
