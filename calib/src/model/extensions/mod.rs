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
//!   growth: `x` = expansion coefficient, `g` = `ΔT`);
//! - as a rotation of everything beyond joint `i` about an axis orthogonal to the joint's own, through
//!   the joint's origin, by the angle `Σₑ xₑ gₑ(row)` (link deflection ([`link_deflection`]): `x` =
//!   bending compliance, `g` = the gravity moment the joint transmits about that axis).
//!
//! Joint-angle terms also model the transmission error ([`transmission_error`]: `x` = amplitude of a
//! harmonic of the joint's own angle, `g` = `sin kqᵢ` or `cos kqᵢ`).
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
//! a cause. The Jacobian columns follow from the [`Term`] of each parameter ([`crate::fit::problem`]).

pub mod gear_backlash;
pub mod joint_compliance;
pub mod link_deflection;
pub mod lumped_gravity;
mod regressors;
mod settings;
pub mod thermal_drift;
pub mod transmission_error;

pub use regressors::{
    EQUILIBRIUM_ITERATIONS, Regressors, RowContext, RowInputs, RowRegressors, apply, bends,
};
pub use settings::{BacklashSign, ExtensionSettings, ThermalInput};

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

    /// Fills this cause's part of `settings` for `model` from the training rows `rows` of `table`
    /// (`source` names the table in errors). Default: nothing to set.
    fn configure(
        &self,
        _settings: &mut ExtensionSettings,
        _model: &Model,
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

    /// Whether the regressors read the joint frames at the link angles ([`RowInputs::frames`]) without
    /// the gravity torques (joint compliance of a robot without masses). Default: no.
    fn needs_frames(&self, _settings: &ExtensionSettings) -> bool {
        false
    }

    /// Whether the regressors read the gravity moment each joint transmits
    /// ([`RowInputs::moment`], N m; link deflection). Default: no.
    fn needs_gravity_moment(&self, _settings: &ExtensionSettings) -> bool {
        false
    }

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

    /// What a user should know of these settings on the training rows `rows` of `table`, for the
    /// calibration report's warnings (a joint left without its terms because the data do not
    /// determine them, say). Default: nothing.
    fn notes(
        &self,
        _settings: &ExtensionSettings,
        _model: &Model,
        _table: &MeasurementTable,
        _rows: &[usize],
    ) -> Vec<String> {
        Vec::new()
    }

    /// The regressors `gₑ` of one row into `out` (one per parameter, [`CauseModel::params`] order).
    fn regressors(&self, settings: &ExtensionSettings, row: &RowInputs<'_>, out: &mut [f64]);

    /// What the residual correlates with, for the evidence sentence of a finding, given the named
    /// joints as text (e.g. `joints 2 and 4`): "the gravity torque of joints 2 and 4".
    fn evidence_subject(&self, joints: &str) -> String;

    /// A remark on an identified value `value` (in `unit`, the parameter's) for the evidence, e.g.
    /// the stiffness a compliance implies, with a leading space; default none.
    fn remark(&self, _unit: Unit, _value: f64) -> String {
        String::new()
    }

    /// The x axis of a diagnose plot of a parameter acting through `term`.
    fn plot_axis(&self, term: Term) -> PlotAxis;

    /// Why an identified value `value` (in `param`'s unit) of `param`, one of this cause's
    /// parameters, is physically impossible or implausible, if it is, in a few words that name the
    /// bound: impossible (a negative compliance: no spring turns a joint along its load; a negative
    /// lost motion) or beyond what the physical cause can be (a half lost motion above 2 mrad, which
    /// no precision gear has). Each cause documents its bounds, with their sources, in its file; the
    /// table is in docs/diagnose.md. Diagnose drops a joint whose named parameter is implausible from
    /// the cause, and does not adopt a cause left with none: it reports it as evidence of another
    /// error. Default: every value is plausible.
    fn implausible(&self, _param: &ExtensionParam, _value: f64) -> Option<String> {
        None
    }

    /// What sets this cause apart from the other causes, in a few words completing "the error …"
    /// (e.g. "turns the joint about its own axis in proportion to its gravity torque"): the evidence
    /// sentence of a finding says why this cause and not its nearest rival with it.
    fn signature(&self) -> &'static str;

    /// How this cause's joint-angle terms move with the joints, for the Jacobian of the compensation
    /// ([`crate::model::compensate`]). With `Δθᵢ = Σₑ xₑ gₑ` over this cause's [`Term::JointAngle`]
    /// parameters (values `x`, [`CauseModel::params`] order), adds `∂Δθ/∂q` through the commanded
    /// joint values to `d_dq` and `∂Δθ/∂θ` through the link angles the torques are evaluated at to
    /// `d_dtheta` (both `nq × nq`, row-major, rad per rad). `torque_jacobian` is `∂τ/∂θ` (N m per
    /// rad, `nq × nq` row-major) when a cause reads the torques. Default: no dependence (the terms
    /// read only the direction, the temperature or the time).
    fn angle_jacobian(
        &self,
        _settings: &ExtensionSettings,
        _row: &RowInputs<'_>,
        _torque_jacobian: &[f64],
        _x: &[f64],
        _d_dq: &mut [f64],
        _d_dtheta: &mut [f64],
    ) {
    }

    /// The highest harmonic of the joint's own angle that this cause models as an angle error of that
    /// joint (transmission error: 3), or 0. Diagnose does not hold the probe of an error periodic in
    /// one joint's angle against a cause that models those harmonics itself.
    fn own_angle_harmonics(&self) -> usize {
        0
    }
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
    /// Angle errors periodic in the joint's own angle (gear and encoder eccentricity, harmonic-drive
    /// kinematic error).
    TransmissionError => "transmission_error", transmission_error::TransmissionError;
    /// Links and bearings bending under gravity and payload about the axes orthogonal to a joint's.
    LinkDeflection => "link_deflection", link_deflection::LinkDeflection;
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
    /// Turns everything beyond joint `joint` by `x · g` (rad) about axis `about` (0 = x, 1 = y, 2 = z)
    /// of the joint's frame (the child link's frame, turning with the joint), through the joint's
    /// origin, after the joint's own rotation; the axis is orthogonal to the joint's own.
    Bend {
        /// 0-based joint index.
        joint: usize,
        /// Axis of the joint frame: 0 = x, 1 = y, 2 = z.
        about: usize,
    },
}

impl Term {
    /// The 0-based joint a joint-angle or bending term acts on.
    pub fn joint(self) -> Option<usize> {
        match self {
            Term::JointAngle { joint } | Term::Bend { joint, .. } => Some(joint),
            Term::Growth => None,
        }
    }
}

/// The name of axis `about` (0, 1, 2) of a frame: `x`, `y`, `z`.
pub fn axis_name(about: usize) -> &'static str {
    ["x", "y", "z"].get(about).copied().unwrap_or("?")
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
    /// The 1-based number of the parameter among several of one quantity at one term (the lumped
    /// products of a robot without masses, [`lumped_gravity`]); `None` for the only one.
    pub pattern: Option<usize>,
}

impl ExtensionParam {
    /// Human name, joints numbered from 1 (e.g. `joint 2 compliance`, `link growth`).
    pub fn name(&self) -> String {
        match self.term {
            Term::JointAngle { joint } => match self.pattern {
                Some(k) => format!("joint {} {} {k}", joint + 1, self.quantity),
                None => format!("joint {} {}", joint + 1, self.quantity),
            },
            Term::Bend { joint, about } => match self.pattern {
                Some(k) => format!(
                    "joint {} {} {k} about {}",
                    joint + 1,
                    self.quantity,
                    axis_name(about)
                ),
                None => format!(
                    "joint {} {} about {}",
                    joint + 1,
                    self.quantity,
                    axis_name(about)
                ),
            },
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
        .joints()
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
            pattern: None,
        })
        .collect()
}

/// Why a value that physics keeps within `[0, max]` is implausible, for
/// [`CauseModel::implausible`]: `negative` below zero, `above()` beyond `max`, `None` within.
pub(crate) fn outside_zero_to(
    value: f64,
    max: f64,
    negative: &str,
    above: impl FnOnce() -> String,
) -> Option<String> {
    if value < 0.0 {
        Some(negative.to_string())
    } else if value > max {
        Some(above())
    } else {
        None
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Every parameter of every cause on the iiwa 7 (with temperatures, every joint turning): its
    /// expected magnitude is plausible, ten thousand times it is not (with a reason), and a negative
    /// value of a compliance or a lost motion is impossible.
    #[test]
    fn expected_magnitudes_are_plausible_and_far_beyond_them_is_not() {
        let model = sim::robots::load_builtin("iiwa7").unwrap();
        let settings = ExtensionSettings {
            causes: Cause::ALL.to_vec(),
            gravity_base: sim::statics::DEFAULT_GRAVITY,
            payload_com_m: [0.0; 3],
            backlash_sign: BacklashSign::Direction,
            thermal: Some(ThermalInput::Temperature { t_ref_c: 20.0 }),
            transmission_joints: (0..model.nq()).collect(),
            joints: Default::default(),
            lumped_gravity: None,
        };
        let params = settings.params(&model);
        for c in Cause::ALL {
            assert!(params.iter().any(|p| p.cause == *c), "{c} has parameters");
        }
        for p in &params {
            let m = p.cause.model();
            assert_eq!(m.implausible(p, p.scale), None, "{}", p.name());
            let why = m.implausible(p, 1e4 * p.scale);
            assert!(why.is_some_and(|w| !w.is_empty()), "{}", p.name());
            if matches!(
                p.cause,
                Cause::JointCompliance | Cause::GearBacklash | Cause::LinkDeflection
            ) {
                assert!(m.implausible(p, -p.scale).is_some(), "{}", p.name());
            }
        }
    }

    /// The bound of the issue: a half lost motion of 5 mrad is no precision gear's, 1 mrad is.
    #[test]
    fn a_backlash_of_five_milliradians_is_implausible() {
        let model = sim::robots::load_builtin("iiwa7").unwrap();
        let p = &per_joint_params(
            &model,
            Cause::GearBacklash,
            "half lost motion",
            Unit::Radian,
            Unit::Metre,
            1e-4,
        )[1];
        let backlash = Cause::GearBacklash.model();
        let why = backlash.implausible(p, 5e-3).unwrap();
        assert!(why.contains("2 mrad"), "{why}");
        assert_eq!(backlash.implausible(p, 1e-3), None);
        assert!(backlash.implausible(p, -1e-4).is_some());
    }
}
