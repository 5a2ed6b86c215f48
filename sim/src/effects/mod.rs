//! Injected errors: what makes the real robot miss its commanded pose. One module per physical effect.
//!
//! The analytic truth of one measurement, [`true_target`], applies the effects in this fixed order and
//! records the displacement each one adds to the target position (base frame, m):
//! 1. thermal drift (link growth and joint-zero drift at the pose's temperature),
//! 2. kinematic offsets (adjoint error twists, joint zero offsets, base and tool errors),
//! 3. transmission error (link angle periodic in the joint's own reported angle),
//! 4. joint coupling (link angle error proportional to a reported joint angle),
//! 5. coupled transmission error (link angle error periodic in another joint's reported angle),
//! 6. gear backlash (link-side angle shifted by half the dead band),
//! 7. joint compliance (link-side angle settles where the joint springs balance gravity and payload),
//!    solved analytically or, with [`ComplianceSolver::Rapier`], by the rapier physics engine on the
//!    same real geometry ([`rapier_compliance`]),
//! 8. link deflection (the child side of each joint tilts about two axes across the joint axis under
//!    the moment it carries), settled in one equilibrium with the joint springs ([`link_deflection`]),
//!    by Newton or, with [`ComplianceSolver::Rapier`], by the engine with two spring hinges per
//!    deflecting joint.
//!
//! The contributions are successive increments, so they add up to the total deviation from nominal:
//! with `p₀` the nominal target position and `pₖ` the position with effects 1 … k applied,
//! contribution `k` is `pₖ − pₖ₋₁` and `Σ contributions = p₈ − p₀`. An absent effect contributes
//! exactly zero.
//!
//! # The real robot
//!
//! With `ΔT = temp − T_ref` (K; 0 without thermal drift), the real flange pose is the product of
//! exponentials of the thermally grown chain with kinematic errors (see [`kinematic_offsets`]),
//!
//! ```text
//! T_base_flange = exp([ξ_base]) exp([S₁'] φ₁) D₁ ⋯ exp([Sₙ'] φₙ) Dₙ M' exp([ξ_tool])
//! φᵢ = θᵢ + δqᵢ + βᵢ ΔT,      θᵢ = qᵢ + eᵢ(q) − sᵢ − cᵢ
//! ```
//!
//! where `q` is the motor-side position the controller reports, `eᵢ(q)` the transmission error,
//! joint coupling and coupled transmission error ([`transmission_error`], [`joint_coupling`],
//! [`coupled_transmission`]), `sᵢ` the backlash shift
//! ([`gear_backlash`]), `cᵢ` the compliance sag ([`joint_compliance`]), `δqᵢ` the zero offset
//! ([`kinematic_offsets`]), `βᵢ ΔT` the zero drift ([`thermal_drift`]) and `Dᵢ` the link deflection
//! (identity without it; a rotation about axes through joint `i`'s origin, [`link_deflection`]). `θ`
//! is the link-side position in the controller's joint coordinates, reported as
//! [`TrueTarget::q_link`]. Gravity torques for backlash, compliance and deflection are those of the
//! nominal inertials in this real geometry.
//!
//! # One effect, one file
//!
//! Each effect is one module implementing [`Effect`] (see [`effect`]: its id, its scenario section,
//! its parameters, the columns it needs, how it acts on the pipeline) and one line in the registry of
//! [`crate::effect_id`], which gives [`EffectId`] and, expanded here, the fields of [`Effects`],
//! [`EffectsSection`] and [`Contributions`], and the stage loop of [`Truth::target`] (statically
//! dispatched, in registry order). The registry order is the stage order above.
//!
//! For many measurements, prepare once with [`Truth::new`] and evaluate with [`Truth::target`] and a
//! [`TruthScratch`]: no allocation per pose; [`true_target`] is the one-shot wrapper.
//!
//! ```
//! use nalgebra::Vector3;
//! use sim::effects::{Conditions, Effects, joint_compliance::JointCompliance, true_target};
//! use sim::{Data, forward_kinematics, robots};
//!
//! let model = robots::load_builtin("iiwa7").unwrap();
//! let effects = Effects {
//!     compliance: Some(JointCompliance::uniform(7, 20_000.0).unwrap()),
//!     ..Effects::default()
//! };
//! let q = [0.0, 0.8, 0.0, -0.9, 0.0, 0.5, 0.0];
//! let cond = Conditions { q: &q, dir: None, temp_c: 20.0, payload: None, branch: None };
//! let p_flange = Vector3::new(0.0, 0.0, 0.05);
//! let gravity = Vector3::new(0.0, 0.0, -9.81);
//! let truth = true_target(&model, &effects, &cond, &p_flange, &gravity).unwrap();
//! // The arm sags under its own weight...
//! let mut data = Data::new(&model);
//! forward_kinematics(&model, &mut data, &q);
//! let p_nominal = data.flange * nalgebra::Point3::from(p_flange);
//! assert!(truth.p_base.z < p_nominal.z - 1e-5);
//! // ...and the contributions add up to the whole deviation.
//! let total = truth.contribution.total();
//! assert!((truth.p_base.z - p_nominal.z - total[2]).abs() < 1e-15);
//! ```

use crate::error::{Result, SimError, scenario_err};
use crate::lie::Pose;
use crate::model::Model;
use chain::Chain;
use gravity::GravityWork;
use nalgebra::{Point3, Vector3};

pub mod chain;
pub mod coupled_transmission;
pub mod effect;
pub mod gear_backlash;
pub(crate) mod gravity;
pub mod joint_compliance;
pub mod joint_coupling;
mod joint_pairs;
pub mod kinematic_offsets;
pub mod link_deflection;
pub mod rapier_compliance;
pub mod thermal_drift;
pub mod transmission_error;

pub use crate::effect_id::EffectId;
pub use effect::{ComplianceSolver, Conditions, Effect, Moved, Needs, Prepare, ResolveCx, State};

/// Generates, from the registry ([`crate::effect_id`]: one line per effect, `key: Type => Id =
/// "name"`, in stage order), the containers and the statically dispatched stage loop.
macro_rules! registry {
    ($( $(#[$doc:meta])* $key:ident : $ty:ty => $id:ident = $name:literal ),+ $(,)?) => {
        // Each effect's own id is its registry line's.
        $( const _: () = assert!(
            matches!(<$ty as Effect>::ID, EffectId::$id),
            concat!("Effect::ID of ", stringify!($ty), " is not EffectId::", stringify!($id)),
        ); )+

        /// Every effect injected into one simulated robot; `None` = effect absent. Unknown keys are
        /// refused when deserializing, so a misspelt effect is an error rather than silently absent.
        #[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
        #[serde(deny_unknown_fields)]
        pub struct Effects {
            $( $(#[$doc])* pub $key: Option<$ty>, )+
        }

        /// `[effects]` of a scenario file: one section per effect, as written (see
        /// [`Effect::Section`]).
        #[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
        #[serde(deny_unknown_fields)]
        pub struct EffectsSection {
            $( $(#[$doc])* pub $key: Option<<$ty as Effect>::Section>, )+
        }

        /// Displacements of the target point by each effect (base frame, m).
        #[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
        pub struct Contributions {
            $( $(#[$doc])* pub $key: [f64; 3], )+
        }

        impl Contributions {
            /// The displacement by effect `id` (base frame, m).
            pub fn get(&self, id: EffectId) -> [f64; 3] {
                match id {
                    $( EffectId::$id => self.$key, )+
                }
            }
        }

        impl Effects {
            /// True when effect `id` is present.
            pub fn contains(&self, id: EffectId) -> bool {
                match id {
                    $( EffectId::$id => self.$key.is_some(), )+
                }
            }

            /// What the present effects read, together.
            pub fn needs(&self) -> Needs {
                let mut n = Needs::default();
                $( if let Some(e) = &self.$key {
                    let m = Effect::needs(e);
                    n.dir |= m.dir;
                    n.temp |= m.temp;
                    n.t |= m.t;
                    n.payload |= m.payload;
                    n.inertials |= m.inertials;
                } )+
                n
            }

            /// Checks that every effect fits `model` (list lengths) and that the model has the
            /// inertials the effects need ([`Needs::inertials`]).
            pub fn check_fits(&self, model: &Model) -> Result<()> {
                $( if let Some(e) = &self.$key {
                    Effect::check_lengths(e, model.nq())?;
                    if Effect::needs(e).inertials {
                        model.require_inertials()?;
                    }
                } )+
                Ok(())
            }

            /// Link growth per kelvin of the chain every stage evaluates (the first effect that
            /// gives one, [`Effect::link_growth_per_k`]).
            fn link_growth_per_k(&self) -> Option<&[f64]> {
                let mut g = None;
                $( if g.is_none() {
                    g = self.$key.as_ref().and_then(|e| Effect::link_growth_per_k(e));
                } )+
                g
            }

            /// Resolves the `[effects]` sections of scenario `file` for `model`, drawing from
            /// `seed` (sections with `enabled = false` are left out), and checks the result
            /// against the robot. Errors name the file and the key.
            pub fn from_sections(
                sections: &EffectsSection,
                model: &Model,
                seed: u64,
                file: &str,
            ) -> Result<Effects> {
                let mut effects = Effects::default();
                $( if let Some(s) = sections.$key.as_ref().filter(|s| <$ty as Effect>::enabled(s)) {
                    let cx = ResolveCx { model, seed, file, section: <$ty as Effect>::KEY };
                    effects.$key = Some(<$ty as Effect>::from_section(s, &cx)?);
                } )+
                effects
                    .check_fits(model)
                    .map_err(|e| scenario_err(file, "effects", e.to_string()))?;
                Ok(effects)
            }
        }

        $( impl Registered for $ty {
            fn get(effects: &Effects) -> Option<&Self> {
                effects.$key.as_ref()
            }
            fn slot(effects: &mut Effects) -> &mut Option<Self> {
                &mut effects.$key
            }
            fn section_slot(sections: &mut EffectsSection) -> &mut Option<Self::Section> {
                &mut sections.$key
            }
        } )+

        /// The prepared stage of each present effect.
        #[derive(Clone, Debug)]
        struct Stages {
            $( $key: Option<<$ty as Effect>::Stage>, )+
        }

        /// The per-thread workspace of each present stage.
        #[derive(Clone, Debug)]
        struct StageScratch {
            $( $key: Option<<$ty as Effect>::Scratch>, )+
        }

        impl Stages {
            fn prepare(effects: &Effects, cx: &Prepare<'_>) -> Result<Stages> {
                Ok(Stages {
                    $( $key: match &effects.$key {
                        Some(e) => Some(Effect::prepare(e, cx)?),
                        None => None,
                    }, )+
                })
            }

            fn scratch(&self, nq: usize) -> StageScratch {
                StageScratch {
                    $( $key: self.$key.as_ref().map(|s| <$ty as Effect>::scratch(s, nq)), )+
                }
            }

            /// Runs every present stage in order on `st`, recording each one's displacement of the
            /// target `p_flange` (flange frame) in `contribution`; `p` is the target so far. With
            /// `couplings`, a stage's change of a drive's angle moves the joints coupled to it
            /// through the linkage (`before` holds the angles before the stage); joint compliance
            /// solves the coupled balance itself.
            #[inline]
            #[allow(clippy::too_many_arguments)]
            fn run<'t>(
                &'t self,
                st: &mut State<'t, '_>,
                scratch: &mut StageScratch,
                p_flange: &Vector3<f64>,
                contribution: &mut Contributions,
                p: &mut Vector3<f64>,
                couplings: Option<&crate::coupled_joints::Couplings>,
                before: &mut [f64],
            ) -> Result<()> {
                $( if let (Some(stage), Some(scr)) = (&self.$key, scratch.$key.as_mut()) {
                    if couplings.is_some() {
                        before.copy_from_slice(st.angles);
                    }
                    let mut moved = <$ty as Effect>::act(stage, st, scr)?;
                    if let Some(c) = couplings
                        && <$ty as Effect>::ID != EffectId::JointCompliance
                        && moved != Moved::Unchanged
                    {
                        let mut carried = false;
                        for cj in c.list() {
                            let d: f64 = cj
                                .sources
                                .iter()
                                .map(|&(s, a)| a * (st.angles[s] - before[s]))
                                .sum();
                            if d != 0.0 {
                                st.angles[cj.joint] += d;
                                st.q_link[cj.joint] += d;
                                st.q_link_first[cj.joint] += d;
                                carried = true;
                            }
                        }
                        if carried {
                            moved = Moved::Changed;
                        }
                    }
                    if moved != Moved::Unchanged {
                        if moved == Moved::Changed {
                            st.flange = st.geom.eval(st.angles, st.dt, st.poses);
                        }
                        let pk = point(&st.flange, p_flange);
                        contribution.$key = arr(pk - *p);
                        *p = pk;
                    }
                } )+
                Ok(())
            }
        }
    };
}

/// An effect of the registry: where it sits in [`Effects`] and [`EffectsSection`] (its typed id is
/// [`Effect::ID`]). Implemented by the registry for every effect.
pub trait Registered: Effect {
    /// Its entry in `effects`.
    fn get(effects: &Effects) -> Option<&Self>;
    /// Its entry in `effects`, to set.
    fn slot(effects: &mut Effects) -> &mut Option<Self>;
    /// Its section in `sections`, to set.
    fn section_slot(sections: &mut EffectsSection) -> &mut Option<Self::Section>;
}

impl Contributions {
    /// Sum of the contributions: the total deviation from the nominal target position (base frame,
    /// m), summed in stage order.
    pub fn total(&self) -> [f64; 3] {
        let (first, rest) = EffectId::ALL
            .split_first()
            .expect("the registry is not empty");
        let mut t = self.get(*first);
        for id in rest {
            let c = self.get(*id);
            for k in 0..3 {
                t[k] += c[k];
            }
        }
        t
    }
}

impl Effects {
    /// True when no effect is present.
    pub fn is_empty(&self) -> bool {
        !EffectId::ALL.iter().any(|id| self.contains(*id))
    }

    /// Effect `E`, if present.
    pub fn get<E: Registered>(&self) -> Option<&E> {
        E::get(self)
    }

    /// These effects with `effect` added (or replaced).
    #[must_use]
    pub fn with<E: Registered>(mut self, effect: E) -> Effects {
        *E::slot(&mut self) = Some(effect);
        self
    }

    /// The present effects, in stage order.
    pub fn ids(&self) -> impl Iterator<Item = EffectId> + '_ {
        EffectId::ALL
            .iter()
            .copied()
            .filter(|id| self.contains(*id))
    }
}

/// The noise-free truth of one measurement.
#[derive(Clone, Debug, PartialEq)]
pub struct TrueTarget {
    /// `T_base_flange` of the real robot (m).
    pub flange: Pose,
    /// Target position in the base frame (m).
    pub p_base: Vector3<f64>,
    /// Displacement added by each effect, in the order of the module docs (base frame, m).
    pub contribution: Contributions,
    /// Link-side joint positions (rad or m), in the controller's joint coordinates: `q + transmission
    /// error + coupling − backlash shift − compliance sag` (the sag of the joint equilibrium with link
    /// deflection when it is present; zero offsets and zero drift not included).
    pub q_link: Vec<f64>,
    /// Link-side positions from the first-order compliance solution, for comparison (rad or m).
    pub q_link_first_order: Vec<f64>,
    /// Newton iterations the compliance equilibrium took, or rapier engine steps with
    /// [`ComplianceSolver::Rapier`], plus the Newton iterations of the joint + deflection equilibrium
    /// with link deflection (0 without compliance and deflection).
    pub compliance_iterations: usize,
}

/// The truth of one measurement without the per-joint vectors (those stay in the [`TruthScratch`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TruePoint {
    /// `T_base_flange` of the real robot (m).
    pub flange: Pose,
    /// Target position in the base frame (m).
    pub p_base: Vector3<f64>,
    /// Displacement added by each effect (base frame, m).
    pub contribution: Contributions,
    /// Newton iterations the compliance equilibrium took, or rapier engine steps with
    /// [`ComplianceSolver::Rapier`], plus the Newton iterations of the joint + deflection equilibrium
    /// with link deflection (0 without compliance and deflection).
    pub compliance_iterations: usize,
}

/// The real robot prepared for fast evaluation: made once per robot and [`Effects`] with
/// [`Truth::new`], then shared (it is immutable and `Sync`) by every thread, each with its own
/// [`TruthScratch`].
#[derive(Clone, Debug)]
pub struct Truth {
    nq: usize,
    /// Nominal chain with thermal growth coefficients (exactly nominal at ΔT = 0).
    grown: Chain,
    /// The prepared stage of every present effect.
    stages: Stages,
    /// What the present effects read.
    needs: Needs,
    /// Mass (kg) and centre of mass (joint frame, m) of each moving body, branches at zero.
    bodies: Vec<(f64, Vector3<f64>)>,
    /// The branches off the chain, posed per measurement ([`Conditions::branch`]).
    branches: crate::branches::Branches,
    solver: ComplianceSolver,
    /// The robot's coupled joints, when it has any: a stage's change of a drive's angle moves the
    /// joints coupled to it ([`crate::coupled_joints`]).
    couplings: Option<crate::coupled_joints::Couplings>,
}

/// Per-thread workspace of a [`Truth`]: made with [`Truth::scratch`], reused for every pose.
#[derive(Clone, Debug)]
pub struct TruthScratch {
    poses: Vec<Pose>,
    /// Chain angles of the pipeline (rad or m).
    angles: Vec<f64>,
    q_link: Vec<f64>,
    q_link_first: Vec<f64>,
    /// Motor-side anchor of the joint springs (see [`State`]).
    anchor: Vec<f64>,
    /// The angles before a stage, with coupled joints.
    before: Vec<f64>,
    work: GravityWork,
    stages: StageScratch,
    /// The bodies with the branches posed ([`Conditions::branch`]).
    posed: Vec<(f64, Vector3<f64>)>,
    /// Branch joint frames and first-moment shifts ([`crate::branches::Branches::first_moment_shift`]).
    branch_poses: Vec<Pose>,
    branch_shift: Vec<Vector3<f64>>,
}

impl TruthScratch {
    /// Link-side joint positions of the last [`Truth::target`] call (rad or m; see
    /// [`TrueTarget::q_link`]).
    pub fn q_link(&self) -> &[f64] {
        &self.q_link
    }

    /// First-order link-side positions of the last [`Truth::target`] call (rad or m).
    pub fn q_link_first_order(&self) -> &[f64] {
        &self.q_link_first
    }
}

fn cond_err(field: impl Into<String>, value: impl ToString, problem: &str) -> SimError {
    SimError::BadCondition {
        field: field.into(),
        value: value.to_string(),
        problem: problem.into(),
    }
}

#[inline]
fn point(t: &Pose, p: &Vector3<f64>) -> Vector3<f64> {
    (t * Point3::from(*p)).coords
}

#[inline]
fn arr(v: Vector3<f64>) -> [f64; 3] {
    [v.x, v.y, v.z]
}

impl Truth {
    /// Prepares the real robot with the analytic compliance solve: validates `effects` against `model`
    /// (see [`Effects::check_fits`]) and precomputes the real chain (real screws, thermal growth per
    /// kelvin). Same as [`Truth::with_solver`] with [`ComplianceSolver::Analytic`].
    pub fn new(model: &Model, effects: &Effects) -> Result<Truth> {
        Truth::with_solver(model, effects, ComplianceSolver::Analytic)
    }

    /// Prepares the real robot as [`Truth::new`], with the compliance stage computed by `solver`.
    /// [`ComplianceSolver::Rapier`] fails without a compliance effect (there is nothing for the
    /// engine to settle) and for bad [`crate::springs::SettleOptions`].
    pub fn with_solver(
        model: &Model,
        effects: &Effects,
        solver: ComplianceSolver,
    ) -> Result<Truth> {
        effects.check_fits(model)?;
        if matches!(solver, ComplianceSolver::Rapier(_)) && effects.compliance.is_none() {
            return Err(SimError::bad_effect(
                EffectId::JointCompliance,
                "stiffness_nm_per_rad",
                "absent",
                "the rapier truth settles the compliant joints: give a compliance effect",
            ));
        }
        let growth = effects.link_growth_per_k();
        let cx = Prepare {
            model,
            growth,
            solver,
            joint_stiffness: effects
                .compliance
                .as_ref()
                .map(joint_compliance::JointCompliance::stiffness_nm_per_rad),
        };
        let stages = Stages::prepare(effects, &cx)?;
        Ok(Truth {
            nq: model.nq(),
            grown: Chain::grown(model, growth),
            stages,
            needs: effects.needs(),
            bodies: model.bodies().iter().map(|b| (b.mass, b.com)).collect(),
            branches: model.branches().clone(),
            solver,
            couplings: (!model.couplings().is_empty()).then(|| model.couplings().clone()),
        })
    }

    /// The compliance solver in use.
    pub fn solver(&self) -> ComplianceSolver {
        self.solver
    }

    /// Number of joints.
    pub fn nq(&self) -> usize {
        self.nq
    }

    /// A workspace for [`Truth::target`].
    pub fn scratch(&self) -> TruthScratch {
        let n = self.nq;
        TruthScratch {
            poses: vec![Pose::identity(); n],
            angles: vec![0.0; n],
            q_link: vec![0.0; n],
            q_link_first: vec![0.0; n],
            anchor: vec![0.0; n],
            before: vec![0.0; n],
            work: GravityWork::new(n),
            stages: self.stages.scratch(n),
            posed: self.bodies.clone(),
            branch_poses: vec![Pose::identity(); self.branches.len()],
            branch_shift: vec![Vector3::zeros(); n],
        }
    }

    fn check(
        &self,
        cond: &Conditions<'_>,
        p_flange: &Vector3<f64>,
        gravity: &Vector3<f64>,
    ) -> Result<()> {
        let n = self.nq;
        if cond.q.len() != n {
            return Err(SimError::JointCount {
                expected: n,
                got: cond.q.len(),
            });
        }
        if let Some((i, v)) = cond.q.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(SimError::NonFiniteJoint {
                joint: i + 1,
                value: *v,
            });
        }
        if let Some(d) = cond.dir {
            if d.len() != n {
                return Err(cond_err(
                    "dir",
                    format!("{} entries", d.len()),
                    &format!("needs one per joint ({n})"),
                ));
            }
            if let Some((i, v)) = d.iter().enumerate().find(|(_, v)| !(-1..=1).contains(*v)) {
                return Err(cond_err(format!("dir[{i}]"), v, "must be -1, 0 or +1"));
            }
        }
        if self.needs.temp && !cond.temp_c.is_finite() {
            return Err(cond_err(
                "temp_c",
                cond.temp_c,
                "not finite (thermal drift needs a temperature)",
            ));
        }
        if let Some(b) = cond.branch {
            if b.len() != self.branches.len() {
                return Err(cond_err(
                    "branch",
                    format!("{} values", b.len()),
                    &format!(
                        "needs one per branch joint off the chain ({})",
                        self.branches.len()
                    ),
                ));
            }
            if let Some((k, v)) = b.iter().enumerate().find(|(_, v)| !v.is_finite()) {
                return Err(cond_err(
                    format!("q_{}", self.branches.joints()[k].name),
                    v,
                    "not finite",
                ));
            }
            if matches!(self.solver, ComplianceSolver::Rapier(_)) && b.iter().any(|v| *v != 0.0) {
                return Err(cond_err(
                    "branch",
                    "posed",
                    "the rapier truth holds the branches off the chain at zero: pose them with the \
                     analytic solver",
                ));
            }
        }
        if let Some(pl) = &cond.payload {
            if !(pl.mass.is_finite() && pl.mass >= 0.0) {
                return Err(cond_err(
                    "payload.mass",
                    pl.mass,
                    "must be finite and ≥ 0 kg",
                ));
            }
            if let Some((k, v)) = pl.com.iter().enumerate().find(|(_, v)| !v.is_finite()) {
                return Err(cond_err(format!("payload.com[{k}]"), v, "not finite"));
            }
        }
        if let Some((k, v)) = gravity.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(cond_err(format!("gravity[{k}]"), v, "not finite"));
        }
        if let Some((k, v)) = p_flange.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(cond_err(format!("p_flange[{k}]"), v, "not finite"));
        }
        Ok(())
    }

    /// Noise-free target position of the real robot at `cond`: `p_flange` is the target in the flange
    /// frame (m), `gravity` the gravity vector in the base frame (m/s²). Writes the link-side positions
    /// into `scratch` ([`TruthScratch::q_link`]). Does not allocate.
    ///
    /// Fails for bad conditions (wrong joint count, non-finite values, `dir` outside −1…1) and when the
    /// compliance equilibrium is not found.
    pub fn target(
        &self,
        cond: &Conditions<'_>,
        p_flange: &Vector3<f64>,
        gravity: &Vector3<f64>,
        scratch: &mut TruthScratch,
    ) -> Result<TruePoint> {
        self.check(cond, p_flange, gravity)?;
        let s = scratch;
        let q = cond.q;
        let mut contribution = Contributions::default();
        // 0. Nominal.
        let flange = self.grown.eval(q, 0.0, &mut s.poses);
        let mut p = point(&flange, p_flange);
        s.angles.copy_from_slice(q);
        s.q_link.copy_from_slice(q);
        s.q_link_first.copy_from_slice(q);
        let bodies = match cond.branch {
            Some(values) if !self.branches.is_empty() => {
                self.branches
                    .first_moment_shift(values, &mut s.branch_poses, &mut s.branch_shift);
                for ((out, (m, c)), shift) in
                    s.posed.iter_mut().zip(&self.bodies).zip(&s.branch_shift)
                {
                    *out = (*m, if *m > 0.0 { c + shift / *m } else { *c });
                }
                &s.posed
            }
            _ => &self.bodies,
        };
        let mut st = State {
            cond,
            gravity,
            bodies,
            geom: &self.grown,
            dt: 0.0,
            angles: &mut s.angles,
            poses: &mut s.poses,
            flange,
            work: &mut s.work,
            q_link: &mut s.q_link,
            q_link_first: &mut s.q_link_first,
            iterations: 0,
            springs: None,
            anchor: &mut s.anchor,
        };
        // 1 … n. The effects, in registry order.
        self.stages.run(
            &mut st,
            &mut s.stages,
            p_flange,
            &mut contribution,
            &mut p,
            self.couplings.as_ref(),
            &mut s.before,
        )?;
        Ok(TruePoint {
            flange: st.flange,
            p_base: p,
            contribution,
            compliance_iterations: st.iterations,
        })
    }
}

/// Noise-free target position of the real robot for one measurement.
///
/// `p_flange` is the target (reflector) position in the flange frame (m); `gravity` the gravity vector in
/// the base frame (m/s²). Fails for bad input (wrong joint count, compliance without inertials, an
/// equilibrium that does not converge). Prepares the robot on every call; for many poses use
/// [`Truth`].
pub fn true_target(
    model: &Model,
    effects: &Effects,
    cond: &Conditions<'_>,
    p_flange: &Vector3<f64>,
    gravity: &Vector3<f64>,
) -> crate::error::Result<TrueTarget> {
    let truth = Truth::new(model, effects)?;
    let mut scratch = truth.scratch();
    let t = truth.target(cond, p_flange, gravity, &mut scratch)?;
    Ok(TrueTarget {
        flange: t.flange,
        p_base: t.p_base,
        contribution: t.contribution,
        q_link: scratch.q_link,
        q_link_first_order: scratch.q_link_first,
        compliance_iterations: t.compliance_iterations,
    })
}

// The registry's lines (one per effect, in stage order) are in `crate::effect_id`; adding an effect
// is one new module above and one line there.
crate::effect_id::for_each_effect!(registry);
