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

pub mod gear_backlash;
pub mod joint_compliance;
pub mod thermal_drift;

use crate::error::{CalibError, Result};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use sim::Model;
use sim::measurement_table::MeasurementTable;

/// A physical cause the kinematic model can be extended with.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Cause {
    /// Elastic joints sagging under gravity and payload.
    JointCompliance,
    /// Lost motion in the gears, signed by the approach direction or the gravity load.
    GearBacklash,
    /// Link growth and joint-zero drift with temperature.
    ThermalDrift,
}

impl Cause {
    /// Every cause, in the order diagnose tries them.
    pub const ALL: [Cause; 3] = [
        Cause::JointCompliance,
        Cause::GearBacklash,
        Cause::ThermalDrift,
    ];

    /// The model-name word (`joint_compliance`, `gear_backlash`, `thermal_drift`).
    pub fn name(self) -> &'static str {
        match self {
            Cause::JointCompliance => "joint_compliance",
            Cause::GearBacklash => "gear_backlash",
            Cause::ThermalDrift => "thermal_drift",
        }
    }

    /// The cause named `word`, if any.
    pub fn from_name(word: &str) -> Option<Cause> {
        Cause::ALL.into_iter().find(|c| c.name() == word)
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

/// One parameter of an extension.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ExtensionParam {
    /// The cause it belongs to.
    pub cause: Cause,
    /// Where it enters the chain.
    pub term: Term,
    /// Human name, joints numbered from 1 (e.g. `joint 2 compliance`).
    pub name: String,
    /// Unit of the parameter (e.g. `rad/(N m)`).
    pub unit: String,
    /// Expected magnitude (parameter unit), the column scaling of the solver.
    pub scale: f64,
}

/// One parameter per joint of `model` for `cause`: named `joint i {what}`, in `rotational_unit` (or
/// `prismatic_unit` for a prismatic joint), with expected magnitude `scale`.
pub(crate) fn per_joint_params(
    model: &Model,
    cause: Cause,
    what: &str,
    rotational_unit: &str,
    prismatic_unit: &str,
    scale: f64,
) -> Vec<ExtensionParam> {
    model
        .joints
        .iter()
        .enumerate()
        .map(|(i, j)| ExtensionParam {
            cause,
            term: Term::JointAngle { joint: i },
            name: format!("joint {} {what}", i + 1),
            unit: if j.kind.is_rotational() {
                rotational_unit
            } else {
                prismatic_unit
            }
            .into(),
            scale,
        })
        .collect()
}

/// Parsed `--model` value: `kinematic`, optionally `+cause` words and one `+learned:KIND`.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct ModelSpec {
    /// Physical extensions, sorted, without repeats.
    pub causes: Vec<Cause>,
    /// Learned residual model kind ([`crate::learned::KINDS`]), if any.
    pub learned: Option<String>,
}

impl ModelSpec {
    /// The kinematic model alone.
    pub fn kinematic() -> Self {
        ModelSpec::default()
    }

    /// Parses a `+`-joined model name such as `kinematic+joint_compliance+learned:poly`. The word
    /// `kinematic` may be left out; `auto` is not a model (diagnose decides it) and is refused here.
    pub fn parse(text: &str) -> Result<Self> {
        let mut spec = ModelSpec::default();
        let bad = |problem: String| CalibError::BadValue {
            context: "--model".into(),
            field: "model".into(),
            value: text.to_string(),
            problem,
        };
        if text.trim().is_empty() {
            return Err(bad("empty model name".into()));
        }
        for word in text.split('+').map(str::trim) {
            if word == "kinematic" {
                continue;
            }
            if let Some(kind) = word.strip_prefix("learned:") {
                if !crate::learned::KINDS.contains(&kind) {
                    return Err(bad(format!(
                        "unknown learned model '{kind}' (known: {})",
                        crate::learned::KINDS.join(", ")
                    )));
                }
                if spec.learned.replace(kind.to_string()).is_some() {
                    return Err(bad("at most one learned:KIND part".into()));
                }
                continue;
            }
            match Cause::from_name(word) {
                Some(c) => spec.causes.push(c),
                None => {
                    return Err(bad(format!(
                        "unknown model part '{word}' (known: kinematic, joint_compliance, \
                         gear_backlash, thermal_drift, learned:{})",
                        crate::learned::KINDS.join("|learned:")
                    )));
                }
            }
        }
        spec.causes.sort();
        spec.causes.dedup();
        Ok(spec)
    }

    /// The canonical name: `kinematic`, then the causes, then `learned:KIND`.
    pub fn name(&self) -> String {
        let mut s = String::from("kinematic");
        for c in &self.causes {
            s.push('+');
            s.push_str(c.name());
        }
        if let Some(k) = &self.learned {
            s.push_str("+learned:");
            s.push_str(k);
        }
        s
    }

    /// The same model with `cause` added.
    pub fn with(&self, cause: Cause) -> Self {
        let mut s = self.clone();
        s.causes.push(cause);
        s.causes.sort();
        s.causes.dedup();
        s
    }
}

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
/// `predict` builds the same regressors on new data.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ExtensionSettings {
    /// The causes, sorted.
    pub causes: Vec<Cause>,
    /// Gravity in the robot base frame (m/s²).
    pub gravity_base: [f64; 3],
    /// Payload centre of mass in the flange frame (m); the table gives only its mass.
    pub payload_com_m: [f64; 3],
    /// Sign source of the backlash regressor.
    pub backlash_sign: BacklashSign,
    /// Source of `ΔT`, with thermal drift.
    pub thermal: Option<ThermalInput>,
}

impl ExtensionSettings {
    /// Settings for `causes` on training rows `rows` of `table`: backlash signed by `dir` when the table
    /// has it, temperature from `temp` (else a warm-up with time constant `tau_s` from `t`).
    ///
    /// Errors: thermal drift asked for on a table with neither `temp` nor `t`, or compliance on a robot
    /// without inertials.
    pub fn for_data(
        model: &Model,
        causes: &[Cause],
        table: &MeasurementTable,
        rows: &[usize],
        tau_s: Option<f64>,
        source: &str,
    ) -> Result<Self> {
        let mut causes = causes.to_vec();
        causes.sort();
        causes.dedup();
        let needs_statics = causes.contains(&Cause::JointCompliance)
            || (causes.contains(&Cause::GearBacklash) && table.dir.is_none());
        if needs_statics && let Err(e) = model.require_inertials() {
            return Err(CalibError::BadValue {
                context: source.to_string(),
                field: "robot".into(),
                value: model.name.clone(),
                problem: format!("the extension needs gravity torques: {e}"),
            });
        }
        let thermal = if causes.contains(&Cause::ThermalDrift) {
            Some(thermal_drift::input_for(table, rows, tau_s, source)?)
        } else {
            None
        };
        Ok(ExtensionSettings {
            causes,
            gravity_base: sim::statics::DEFAULT_GRAVITY,
            payload_com_m: [0.0; 3],
            backlash_sign: if table.dir.is_some() {
                BacklashSign::Direction
            } else {
                BacklashSign::GravityTorque
            },
            thermal,
        })
    }

    /// Checks that `table` has the columns these settings read (`temp` or `t` for thermal drift, `dir`
    /// for direction-signed backlash); `file` names it in the error.
    pub fn check_table(&self, table: &MeasurementTable, file: &str) -> Result<()> {
        let missing = |col: &str, why: &str| CalibError::BadValue {
            context: file.to_string(),
            field: col.to_string(),
            value: "absent".into(),
            problem: format!("the model's {why} reads this column"),
        };
        if self.causes.contains(&Cause::GearBacklash)
            && self.backlash_sign == BacklashSign::Direction
            && table.dir.is_none()
        {
            return Err(missing(
                "dir1..dirN",
                "gear_backlash (signed by approach direction)",
            ));
        }
        match self.thermal {
            Some(ThermalInput::Temperature { .. }) if table.temp.is_none() => {
                Err(missing("temp", "thermal_drift"))
            }
            Some(ThermalInput::WarmUp { .. }) if table.t.is_none() => {
                Err(missing("t", "thermal_drift (warm-up from time)"))
            }
            _ => Ok(()),
        }
    }

    /// The parameters of every cause, in order.
    pub fn params(&self, model: &Model) -> Vec<ExtensionParam> {
        let mut out = Vec::new();
        for c in &self.causes {
            match c {
                Cause::JointCompliance => out.extend(joint_compliance::params(model)),
                Cause::GearBacklash => out.extend(gear_backlash::params(model)),
                Cause::ThermalDrift => out.extend(thermal_drift::params(model, self)),
            }
        }
        out
    }
}

/// Regressors of every extension parameter for a set of rows.
#[derive(Clone, Debug, PartialEq)]
pub struct Regressors {
    /// The parameters (columns).
    pub params: Vec<ExtensionParam>,
    /// `gₑ(row)`, row-major (rows × params).
    pub coef: Vec<f64>,
}

impl Regressors {
    /// No extension.
    pub fn none() -> Self {
        Regressors {
            params: Vec::new(),
            coef: Vec::new(),
        }
    }

    /// Number of parameters.
    pub fn len(&self) -> usize {
        self.params.len()
    }

    /// True without parameters.
    pub fn is_empty(&self) -> bool {
        self.params.is_empty()
    }

    /// Regressors of row `r` (one per parameter).
    #[inline]
    pub fn row(&self, r: usize) -> &[f64] {
        let n = self.params.len();
        &self.coef[r * n..(r + 1) * n]
    }

    /// The regressors of `rows` (0-based) of `table` under `settings`; `source` names the table in
    /// errors.
    ///
    /// Gravity torques are evaluated where the link really is: at the joint angles `θ` that the
    /// extension values `at` (in [`ExtensionSettings::params`] order) give, `θ = q + Σₑ xₑ gₑ(θ)`,
    /// solved by fixed-point iteration (each step shrinks the error by the compliance times the
    /// torque's derivative, about 10⁻²). With `at` empty, at `q`. Once `at` holds the estimate, this
    /// turns the first-order compliance model into the exact spring balance.
    pub fn build(
        model: &Model,
        settings: &ExtensionSettings,
        table: &MeasurementTable,
        rows: &[usize],
        source: &str,
        at: &[f64],
    ) -> Result<Self> {
        let params = settings.params(model);
        let n = params.len();
        let mut coef = vec![0.0; rows.len() * n];
        let mut data = sim::Data::new(model);
        let mut tau = vec![0.0; model.nq()];
        let needs_tau = settings.causes.contains(&Cause::JointCompliance)
            || (settings.causes.contains(&Cause::GearBacklash)
                && settings.backlash_sign == BacklashSign::GravityTorque);
        let g = Vector3::from(settings.gravity_base);
        let widths: Vec<usize> = settings
            .causes
            .iter()
            .map(|c| params.iter().filter(|p| p.cause == *c).count())
            .collect();
        let iterations = if needs_tau && at.len() == n && at.iter().any(|x| *x != 0.0) {
            EQUILIBRIUM_ITERATIONS
        } else {
            1
        };
        // One row's regressors, to evaluate θ with [`apply`] between the fixed-point steps.
        let mut one = Regressors {
            params,
            coef: vec![0.0; n],
        };
        let mut theta = vec![0.0; model.nq()];
        for (k, &r) in rows.iter().enumerate() {
            let q = table.q_row(r);
            theta.copy_from_slice(q);
            for it in 0..iterations {
                if needs_tau {
                    let mass = table.payload.as_ref().map_or(0.0, |p| p[r]);
                    let payload = (mass > 0.0).then_some(sim::statics::Payload {
                        mass,
                        com: settings.payload_com_m,
                    });
                    sim::statics::gravity_torques(model, &mut data, &theta, &g, payload.as_ref())
                        .map_err(|e| CalibError::BadValue {
                        context: format!("{source}: row {}", r + 1),
                        field: "q1..qN".into(),
                        value: String::new(),
                        problem: format!("gravity torques: {e}"),
                    })?;
                    tau.copy_from_slice(data.gravity_torque.as_slice());
                }
                fill_row(settings, &widths, table, r, &tau, &mut one.coef);
                if it + 1 < iterations {
                    apply(&one, at, 0, q, &mut theta);
                }
            }
            coef[k * n..(k + 1) * n].copy_from_slice(&one.coef);
        }
        Ok(Regressors {
            params: one.params,
            coef,
        })
    }
}

/// Fixed-point steps of the spring balance in [`Regressors::build`]: the error shrinks by about 10⁻²
/// per step, so four reach 10⁻⁸ of the sag.
pub const EQUILIBRIUM_ITERATIONS: usize = 4;

/// The regressors of row `r` of `table` into `out`, from its holding torques `tau` (N m); `widths` is
/// the parameter count of each cause of `settings`.
fn fill_row(
    settings: &ExtensionSettings,
    widths: &[usize],
    table: &MeasurementTable,
    r: usize,
    tau: &[f64],
    out: &mut [f64],
) {
    let mut col = 0;
    for (c, &width) in settings.causes.iter().zip(widths) {
        let dst = &mut out[col..col + width];
        match c {
            Cause::JointCompliance => joint_compliance::regressors(tau, dst),
            Cause::GearBacklash => {
                gear_backlash::regressors(settings.backlash_sign, table.dir_row(r), tau, dst)
            }
            Cause::ThermalDrift => thermal_drift::regressors(settings, table, r, dst),
        }
        col += width;
    }
}

/// Effective joint values of row `r`: `q` plus every joint-angle term, into `q_out`; returns the growth
/// factor `x · g` (0 without growth).
#[inline]
pub fn apply(regs: &Regressors, values: &[f64], r: usize, q: &[f64], q_out: &mut [f64]) -> f64 {
    q_out.copy_from_slice(q);
    let mut growth = 0.0;
    if regs.is_empty() {
        return growth;
    }
    for ((p, &x), &g) in regs.params.iter().zip(values).zip(regs.row(r)) {
        match p.term {
            Term::JointAngle { joint } => q_out[joint] += x * g,
            Term::Growth => growth += x * g,
        }
    }
    growth
}

/// Evaluates `chain` (prepared at `params`) for row `r` of data with joint values `q` and extension
/// regressors `regs`, into `scratch`; returns the predicted target position (tracker frame, m) with the
/// growth applied, and the growth lever `p − t_tracker_base` (m) the growth multiplies. `q_buf` is
/// scratch for the effective joint values.
#[inline]
pub fn predict_row(
    chain: &crate::chain::Chain,
    scratch: &mut crate::chain::ChainScratch,
    params: &crate::params::KinematicParams,
    regs: &Regressors,
    r: usize,
    q: &[f64],
    q_buf: &mut [f64],
) -> (Vector3<f64>, Vector3<f64>, f64) {
    let growth = apply(regs, &params.extension, r, q, q_buf);
    chain.forward(scratch, q_buf);
    let lever = scratch.p_tracker - params.t_tracker_base.translation.vector;
    (scratch.p_tracker + growth * lever, lever, growth)
}
