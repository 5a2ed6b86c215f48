//! Model extensions: physical causes beyond the kinematic model, identified jointly with it.
//!
//! Every extension is linear in its parameters and enters the kinematic chain in one of two ways
//! ([`Term`]):
//!
//! - as a change of a joint angle, `θᵢ = qᵢ + δqᵢ + Σₑ xₑ gₑ(row)` for the parameters `e` acting on joint
//!   `i`: joint compliance ([`joint_compliance`]: `x` = compliance, `g` = −gravity torque), gear
//!   backlash ([`gear_backlash`]: `x` = half the lost motion, `g` = −approach sign) and joint-zero drift
//!   ([`thermal_drift`]: `x` = drift per kelvin, `g` = `ΔT`);
//! - as a growth of the whole arm about the base origin, `p_base ← (1 + x g) p_base` (thermal link
//!   growth: `x` = expansion coefficient, `g` = `ΔT`).
//!
//! The regressors `gₑ(row)` depend only on the measured row (joint values, payload, direction signs,
//! temperature or time) and on the nominal robot, so they are computed once per data set
//! ([`Regressors::build`]). The estimator's equations are its own: they share nothing with the
//! simulator's effect code (see CONTRIBUTING.md).
//!
//! # One cause, one file
//! Each cause is a unit struct in its own module implementing [`CauseModel`]: its parameters (with
//! typed [`Unit`]s), the columns it reads, its table checks, its regressors, the words of its evidence
//! and the axis of its diagnose plot. The registry [`causes!`] below turns one line per cause into the
//! typed identity [`Cause`] and its dispatch ([`Cause::model`]); nothing else in the estimator matches on
//! a cause. The Jacobian columns follow from the [`Term`] of each parameter ([`crate::problem`]).

pub mod gear_backlash;
pub mod joint_compliance;
mod regressors;
mod settings;
mod spec;
pub mod thermal_drift;

pub use regressors::{EQUILIBRIUM_ITERATIONS, Regressors, RowInputs, apply};
pub use settings::{BacklashSign, ExtensionSettings, ThermalInput};
pub use spec::{ModelChoice, ModelSpec};

use crate::error::Result;
use crate::units::Unit;
use serde::{Deserialize, Serialize};
use sim::Model;
use sim::measurement_table::MeasurementTable;

/// What a physical cause of the estimator is: one implementation per file of this folder.
///
/// Implementations are stateless unit structs; everything that depends on the data lives in
/// [`ExtensionSettings`] (stored in the model file, so `predict` rebuilds the same regressors).
pub trait CauseModel: Sync {
    /// The cause's typed identity.
    fn cause(&self) -> Cause;

    /// Whether `model` and `table` can feed this cause at all (diagnose tries only those, and reports
    /// the others with the reason): e.g. thermal drift needs a `temp` or `t` column, compliance needs
    /// the robot's inertials. `Err` says why not, in one sentence.
    fn usable(&self, model: &Model, table: &MeasurementTable) -> std::result::Result<(), String>;

    /// Fills this cause's part of `settings` from the training rows `rows` of `table` (`source` names
    /// the table in errors). Default: nothing to set.
    fn configure(
        &self,
        _settings: &mut ExtensionSettings,
        _table: &MeasurementTable,
        _rows: &[usize],
        _source: &str,
    ) -> Result<()> {
        Ok(())
    }

    /// Other settings to try, a search over a hyperparameter the regressors cannot be linear in (the
    /// warm-up time constant of thermal drift without temperatures); the calibration keeps the one
    /// with the smallest training `χ²`. Default: none.
    fn alternatives(
        &self,
        _settings: &ExtensionSettings,
        _table: &MeasurementTable,
        _rows: &[usize],
    ) -> Vec<ExtensionSettings> {
        Vec::new()
    }

    /// Whether the regressors read the gravity torques (N m) under `settings`.
    fn needs_gravity_torque(&self, settings: &ExtensionSettings) -> bool;

    /// Whether the regressors depend on where the link really is, so that the calibration refits with
    /// the torques at the estimated equilibrium (joint compliance). Default: no.
    fn needs_equilibrium(&self) -> bool {
        false
    }

    /// The parameters, in order, for `model` under `settings`.
    fn params(&self, model: &Model, settings: &ExtensionSettings) -> Vec<ExtensionParam>;

    /// Checks that `table` has the columns these settings read; `file` names it in the error.
    /// Default: nothing beyond the joint values.
    fn check_table(
        &self,
        _settings: &ExtensionSettings,
        _table: &MeasurementTable,
        _file: &str,
    ) -> Result<()> {
        Ok(())
    }

    /// The regressors `gₑ` of one row into `out` (one per parameter, [`CauseModel::params`] order).
    fn regressors(&self, settings: &ExtensionSettings, row: &RowInputs<'_>, out: &mut [f64]);

    /// What the residual correlates with, for the evidence sentence of a finding, given the named
    /// joints as text (e.g. `joints 2 and 4`): "the gravity torque of joints 2 and 4".
    fn evidence_subject(&self, joints: &str) -> String;

    /// A remark on an identified value `value` (parameter unit) for the evidence, e.g. the stiffness a
    /// compliance implies, with a leading space; default none.
    fn remark(&self, _value: f64) -> String {
        String::new()
    }

    /// The x axis of a diagnose plot of a parameter acting through `term`.
    fn plot_axis(&self, term: Term) -> PlotAxis;
}

/// The x axis of a finding's plot: the regressor times `sign`, labelled `label`.
#[derive(Clone, Debug, PartialEq)]
pub struct PlotAxis {
    /// Sign applied to the regressor so that the axis shows the physical quantity (e.g. the holding
    /// torque where the regressor is its negative).
    pub sign: f64,
    /// Axis label with its unit.
    pub label: String,
}

/// The registry: one line per cause, `Variant => "word", module::Type;`. It defines [`Cause`] (the
/// typed identity, serialised as its word) and its dispatch to the cause's [`CauseModel`].
macro_rules! causes {
    ($( $(#[$doc:meta])* $variant:ident => $word:literal, $module:ident :: $ty:ident; )*) => {
        /// A physical cause the kinematic model can be extended with.
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
        #[serde(rename_all = "snake_case")]
        pub enum Cause {
            $( $(#[$doc])* $variant, )*
        }

        impl Cause {
            /// Every cause, in the order diagnose tries them.
            pub const ALL: &'static [Cause] = &[$( Cause::$variant, )*];

            /// The model-name word (`joint_compliance`, `gear_backlash`, `thermal_drift`).
            pub fn name(self) -> &'static str {
                match self {
                    $( Cause::$variant => $word, )*
                }
            }

            /// What the cause is and does.
            pub fn model(self) -> &'static dyn CauseModel {
                match self {
                    $( Cause::$variant => &$module::$ty, )*
                }
            }
        }
    };
}

causes! {
    /// Elastic joints sagging under gravity and payload.
    JointCompliance => "joint_compliance", joint_compliance::JointCompliance;
    /// Lost motion in the gears, signed by the approach direction or the gravity load.
    GearBacklash => "gear_backlash", gear_backlash::GearBacklash;
    /// Link growth and joint-zero drift with temperature.
    ThermalDrift => "thermal_drift", thermal_drift::ThermalDrift;
}

impl Cause {
    /// The cause named `word`, if any.
    pub fn from_name(word: &str) -> Option<Cause> {
        Cause::ALL.iter().copied().find(|c| c.name() == word)
    }
}

impl std::fmt::Display for Cause {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.pad(self.name())
    }
}

/// How one extension parameter enters the chain.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Term {
    /// Adds `x · g` to the angle of joint `joint` (0-based; rad, or m for a prismatic joint).
    JointAngle {
        /// 0-based joint index.
        joint: usize,
    },
    /// Scales the target's base-frame position by `1 + x · g` (growth of every link about the base).
    Growth,
}

impl Term {
    /// The 0-based joint a joint-angle term acts on.
    pub fn joint(self) -> Option<usize> {
        match self {
            Term::JointAngle { joint } => Some(joint),
            Term::Growth => None,
        }
    }
}

/// One parameter of an extension: its typed identity (cause, term, quantity), unit and scale.
#[derive(Clone, Debug, PartialEq)]
pub struct ExtensionParam {
    /// The cause it belongs to.
    pub cause: Cause,
    /// Where it enters the chain.
    pub term: Term,
    /// What it is, e.g. `compliance`, `half lost motion`, `link growth`.
    pub quantity: &'static str,
    /// Unit of the parameter.
    pub unit: Unit,
    /// Expected magnitude (parameter unit), the column scaling of the solver.
    pub scale: f64,
}

impl ExtensionParam {
    /// Human name, joints numbered from 1 (e.g. `joint 2 compliance`, `link growth`).
    pub fn name(&self) -> String {
        match self.term {
            Term::JointAngle { joint } => format!("joint {} {}", joint + 1, self.quantity),
            Term::Growth => self.quantity.to_string(),
        }
    }
}

/// One parameter per joint of `model` for `cause`: `quantity` of each joint, in `rotational_unit` (or
/// `prismatic_unit` for a prismatic joint), with expected magnitude `scale`.
pub(crate) fn per_joint_params(
    model: &Model,
    cause: Cause,
    quantity: &'static str,
    rotational_unit: Unit,
    prismatic_unit: Unit,
    scale: f64,
) -> Vec<ExtensionParam> {
    model
        .joints
        .iter()
        .enumerate()
        .map(|(i, j)| ExtensionParam {
            cause,
            term: Term::JointAngle { joint: i },
            quantity,
            unit: if j.kind.is_rotational() {
                rotational_unit
            } else {
                prismatic_unit
            },
            scale,
        })
        .collect()
}

/// The joints as words: `joint 2`, `joints 2 and 4`, `joints 1, 2 and 4` (1-based numbers given).
pub fn joint_words(joints: &[usize]) -> String {
    let s: Vec<String> = joints.iter().map(|x| x.to_string()).collect();
    match s.len() {
        0 => String::new(),
        1 => format!("joint {}", s[0]),
        _ => format!(
            "joints {} and {}",
            s[..s.len() - 1].join(", "),
            s[s.len() - 1]
        ),
    }
}
