//! The shape every injected effect has: the [`Effect`] trait and the contexts its methods see.
//!
//! An effect is one file in `sim/src/effects/` that implements [`Effect`] for its parameter type, and
//! one line in the registry of [`super`]. The trait says
//!
//! * who it is: [`Effect::ID`], its line in the registry ([`crate::effect_id`]), which gives
//!   [`Effect::NAME`] (`gear_backlash`, in summaries and errors) and [`Effect::KEY`]
//!   (`backlash`: the scenario section `[effects.backlash]`, the `truth.json` key `effects.backlash`,
//!   the `truth.parquet` columns `backlash_{x,y,z}` and the fields of [`super::Effects`] and
//!   [`super::Contributions`]);
//! * how it is written in a scenario: [`Effect::Section`], resolved into the effect by
//!   [`Effect::from_section`] (random magnitudes drawn through a [`ResolveCx`]);
//! * what it reads: [`Effect::needs`] (campaign columns `dir`, `temp`, `t`, `payload`, and the
//!   model's inertials; nothing by default) and [`Effect::check_lengths`];
//! * how it acts in the truth pipeline: [`Effect::prepare`] once per robot (an immutable, `Sync`
//!   [`Effect::Stage`]), [`Effect::scratch`] once per thread (by default the empty
//!   workspace, [`Default`]), and [`Effect::act`] per pose on the
//!   pipeline [`State`], without allocating. The stages run in registry order, each one after the
//!   ones before it; the contribution of a stage is the target displacement it causes (see
//!   [`super`]).
//!
//! The pipeline calls every stage by its concrete type (the registry expands to one `if let` per
//! effect): no dynamic dispatch per pose.

use super::chain::Chain;
use super::gravity::{BodyMasses, GravityWork};
use crate::effect_id::EffectId;
use crate::error::{Result, SimError, scenario_err};
use crate::lie::Pose;
use crate::magnitude::Magnitude;
use crate::model::Model;
use crate::springs::SettleOptions;
use crate::statics::Payload;
use nalgebra::Vector3;

/// How the compliance stage of [`super::Truth`] finds the link-side angles where the joint springs
/// balance gravity and payload. Every other stage is the same for both.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum ComplianceSolver {
    /// Newton's method on `K (q − θ) = τ_g(θ)` ([`super::joint_compliance`]).
    #[default]
    Analytic,
    /// The real robot as a rapier multibody with joint springs, settled to rest
    /// ([`super::rapier_compliance`], [`crate::rapier_truth`]). Needs a compliance effect.
    Rapier(SettleOptions),
}

/// What the controller reports and the environment imposes at one measurement.
#[derive(Clone, Copy, Debug)]
pub struct Conditions<'a> {
    /// Motor-side joint positions the controller reports (rad or m), length `model.nq()`.
    pub q: &'a [f64],
    /// Sign of each joint's last motion (−1, 0, +1), or `None` when unknown.
    pub dir: Option<&'a [i8]>,
    /// Robot temperature (°C).
    pub temp_c: f64,
    /// Mass at the flange, if any.
    pub payload: Option<Payload>,
    /// Values of the movable joints of the branches off the chain ([`crate::branches`], rad or m,
    /// [`crate::Model::branches`] order), or `None` for every branch at zero.
    pub branch: Option<&'a [f64]>,
}

/// What an effect reads besides the joint positions: campaign columns and model data.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct Needs {
    /// The approach directions (`dir1..dirN`); without them the effect takes 0 (unknown).
    pub dir: bool,
    /// The robot temperature (`temp`, °C); a non-finite temperature is refused.
    pub temp: bool,
    /// The time stamps (`t`, s).
    pub t: bool,
    /// The payload mass (`payload`, kg) and its centre of mass.
    pub payload: bool,
    /// The model's inertials (masses and centres of mass of the links).
    pub inertials: bool,
}

/// What a stage did to the target (see [`Effect::act`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Moved {
    /// Nothing changed: the stage contributes exactly zero and the pipeline state is as before.
    Unchanged,
    /// The chain angles, the geometry or `ΔT` changed: the pipeline evaluates [`State`]'s chain.
    Changed,
    /// The stage evaluated the chain itself and left the flange pose in [`State`].
    Evaluated,
}

/// Everything an effect sees while it is resolved from its scenario section: the robot, the seed and
/// the names for errors.
#[derive(Clone, Copy, Debug)]
pub struct ResolveCx<'a> {
    pub(crate) model: &'a Model,
    pub(crate) seed: u64,
    pub(crate) file: &'a str,
    pub(crate) section: &'static str,
}

impl ResolveCx<'_> {
    /// The robot the effect is resolved for.
    pub fn model(&self) -> &Model {
        self.model
    }

    /// Number of joints.
    pub fn nq(&self) -> usize {
        self.model.nq()
    }

    /// The scenario key of `field` of this effect's section: `effects.<KEY>.<field>`.
    pub fn key(&self, field: &str) -> String {
        format!("effects.{}.{field}", self.section)
    }

    /// Draws magnitude `m` of `field` into `shape.iter().product()` numbers (see
    /// [`Magnitude::resolve`]; the stream is keyed by the full scenario key).
    pub fn draw(&self, m: &Magnitude, field: &str, shape: &[usize]) -> Result<Vec<f64>> {
        m.resolve(self.seed, self.file, &self.key(field), shape)
    }

    /// As [`ResolveCx::draw`], zeros when `m` is absent.
    pub fn draw_or_zero(
        &self,
        m: &Option<Magnitude>,
        field: &str,
        shape: &[usize],
    ) -> Result<Vec<f64>> {
        match m {
            Some(m) => self.draw(m, field, shape),
            None => Ok(vec![0.0; shape.iter().product()]),
        }
    }

    /// An error about `field` of this section (`field` empty: the section itself).
    pub fn err(&self, field: &str, message: String) -> SimError {
        let key = if field.is_empty() {
            format!("effects.{}", self.section)
        } else {
            self.key(field)
        };
        scenario_err(self.file, &key, message)
    }

    /// Fails unless the model has inertials, naming `field` and saying who needs them (`why`).
    pub fn require_inertials(&self, field: &str, why: &str) -> Result<()> {
        self.model
            .require_inertials()
            .map_err(|e| self.err(field, format!("{e}; {why} needs them")))
    }

    /// Converts an effect constructor's error into one naming the scenario key
    /// (`effects.<KEY>.<field>: value …: problem`).
    pub fn checked<T>(&self, r: Result<T>) -> Result<T> {
        r.map_err(|e| match e {
            SimError::BadEffect {
                field,
                value,
                problem,
                ..
            } => self.err(&field, format!("value {value}: {problem}")),
            other => self.err("", other.to_string()),
        })
    }
}

/// What [`Effect::prepare`] sees: the nominal robot, the link growth of the thermally grown chain and
/// the compliance solver.
#[derive(Clone, Copy, Debug)]
pub struct Prepare<'a> {
    pub(crate) model: &'a Model,
    /// Link growth per kelvin (1/K, links 0 … n) of the chain every stage evaluates, if any effect
    /// gives one ([`Effect::link_growth_per_k`]).
    pub(crate) growth: Option<&'a [f64]>,
    pub(crate) solver: ComplianceSolver,
    /// Joint stiffness (N m/rad or N/m; infinite = rigid) of the compliance effect, if present: what
    /// a stage that settles in the same equilibrium with the physics engine needs up front.
    pub(crate) joint_stiffness: Option<&'a [f64]>,
}

impl Prepare<'_> {
    /// The nominal robot.
    pub fn model(&self) -> &Model {
        self.model
    }

    /// The compliance solver in use.
    pub fn solver(&self) -> ComplianceSolver {
        self.solver
    }
}

/// The truth pipeline at one stage of one pose: the geometry, `ΔT` and the chain angles so far, and
/// the last evaluation of the chain. Stages change it in place; see [`Effect::act`].
pub struct State<'t, 's> {
    /// The measurement.
    pub(crate) cond: &'s Conditions<'s>,
    /// Gravity in the base frame (m/s²).
    pub(crate) gravity: &'s Vector3<f64>,
    /// Mass (kg) and centre of mass (joint frame, m) of each moving body (nominal inertials).
    pub(crate) bodies: &'t BodyMasses,
    /// The chain the stages evaluate: the thermally grown nominal chain, until a stage swaps in its
    /// own (kinematic offsets: the real chain).
    pub(crate) geom: &'t Chain,
    /// `ΔT` (K) the chain is evaluated at (0 until thermal drift sets it).
    pub(crate) dt: f64,
    /// Chain angles so far (rad or m): `q` plus zero drift and offsets, minus link-side shifts.
    pub(crate) angles: &'s mut [f64],
    /// Joint frames of `geom` at `angles` and `dt`, from the last evaluation (base frame, m).
    pub(crate) poses: &'s mut [Pose],
    /// `T_base_flange` of the last evaluation (m).
    pub(crate) flange: Pose,
    /// Gravity-torque workspace.
    pub(crate) work: &'s mut GravityWork,
    /// Link-side positions in the controller's coordinates (rad or m): `q` minus every link-side shift
    /// so far (backlash shift, compliance sag), subtracted stage by stage.
    pub(crate) q_link: &'s mut [f64],
    /// As `q_link` with the first-order compliance sag.
    pub(crate) q_link_first: &'s mut [f64],
    /// Iterations of the iterative stages, summed (Newton steps or engine steps; 0 if none ran).
    pub(crate) iterations: usize,
    /// The joint springs of the compliance stage, once it has run: what a later stage that settles
    /// in the same static equilibrium (link deflection) needs. `None` = rigid joints.
    pub(crate) springs: Option<JointSprings<'t>>,
    /// Motor-side anchor of the joint springs (chain angles before the compliance stage, rad or m);
    /// set by the compliance stage, meaningful while [`State::springs`] is `Some`.
    pub(crate) anchor: &'s mut [f64],
}

/// The joint springs a compliance stage settled, as later stages see them.
#[derive(Clone, Copy, Debug)]
pub(crate) struct JointSprings<'t> {
    /// `1/kᵢ` per joint (rad/(N m) or m/N; 0 = rigid).
    pub compliance: &'t [f64],
}

/// One injected physical effect (see the module docs). Implemented by the parameter type of each
/// effect (e.g. [`super::gear_backlash::GearBacklash`]); every method but [`Effect::act`] runs once
/// per scenario or robot, `act` once per pose and stage.
pub trait Effect:
    Clone
    + std::fmt::Debug
    + PartialEq
    + serde::Serialize
    + serde::de::DeserializeOwned
    + Send
    + Sync
    + 'static
{
    /// Its typed identity: its line in the registry ([`crate::effect_id`]), which the registry
    /// checks.
    const ID: EffectId;
    /// Name in summaries and errors (`gear_backlash`): [`EffectId::name`] of [`Effect::ID`].
    const NAME: &'static str = Self::ID.name();
    /// Key of the scenario section, the `truth.json` entry and the `truth.parquet` columns
    /// (`backlash`): [`EffectId::key`] of [`Effect::ID`].
    const KEY: &'static str = Self::ID.key();
    /// The scenario section `[effects.<KEY>]` as written (magnitudes not yet drawn).
    type Section: Clone
        + std::fmt::Debug
        + PartialEq
        + serde::Serialize
        + serde::de::DeserializeOwned;
    /// What [`Effect::prepare`] makes once per robot: immutable, shared by every thread.
    type Stage: Clone + std::fmt::Debug + Send + Sync;
    /// Per-thread workspace of the stage (`()` for a stage that needs none).
    type Scratch: Clone + std::fmt::Debug + Default + Send;

    /// False when the section says `enabled = false`.
    fn enabled(section: &Self::Section) -> bool;

    /// Resolves a section into the effect: draws every magnitude through `cx` and validates. Errors
    /// name the scenario file and key.
    fn from_section(section: &Self::Section, cx: &ResolveCx<'_>) -> Result<Self>;

    /// What this effect reads besides the joint positions; by default nothing (`Needs::default()`).
    fn needs(&self) -> Needs {
        Needs::default()
    }

    /// Checks that the parameter lists fit a robot with `nq` joints.
    fn check_lengths(&self, nq: usize) -> Result<()>;

    /// Link growth per kelvin (1/K, links 0 … n) this effect gives the chain every stage evaluates;
    /// `None` (the default) for an effect that does not change the nominal geometry with temperature.
    fn link_growth_per_k(&self) -> Option<&[f64]> {
        None
    }

    /// Prepares the stage for fast evaluation (once per robot).
    fn prepare(&self, cx: &Prepare<'_>) -> Result<Self::Stage>;

    /// A per-thread workspace for a robot with `nq` joints; by default the empty one
    /// ([`Default`]), for a stage that needs no workspace.
    fn scratch(stage: &Self::Stage, nq: usize) -> Self::Scratch {
        let _ = (stage, nq);
        Self::Scratch::default()
    }

    /// Applies the effect at one pose: changes `state` (chain angles, geometry, `ΔT`, link-side
    /// positions) and says whether the target moved. Must not allocate.
    fn act<'t>(
        stage: &'t Self::Stage,
        state: &mut State<'t, '_>,
        scratch: &mut Self::Scratch,
    ) -> Result<Moved>;
}
