//! Injected errors: what makes the real robot miss its commanded pose. One module per physical effect.
//!
//! The analytic truth of one measurement, [`true_target`], applies the effects in this fixed order and
//! records the displacement each one adds to the target position (base frame, m):
//! 1. thermal drift (link growth and joint-zero drift at the pose's temperature),
//! 2. kinematic offsets (adjoint error twists, joint zero offsets, base and tool errors),
//! 3. gear backlash (link-side angle shifted by half the dead band),
//! 4. joint compliance (link-side angle settles where the joint springs balance gravity and payload),
//!    solved analytically or, with [`ComplianceSolver::Rapier`], by the rapier physics engine on the
//!    same real geometry ([`rapier_compliance`]).
//!
//! The contributions are successive increments, so they add up to the total deviation from nominal:
//! with `p₀` the nominal target position and `pₖ` the position with effects 1 … k applied,
//! contribution `k` is `pₖ − pₖ₋₁` and `Σ contributions = p₄ − p₀`. An absent effect contributes
//! exactly zero.
//!
//! # The real robot
//!
//! With `ΔT = temp − T_ref` (K; 0 without thermal drift), the real flange pose is the product of
//! exponentials of the thermally grown chain with kinematic errors (see [`kinematic_offsets`]),
//!
//! ```text
//! T_base_flange = exp([ξ_base]) exp([S₁'] φ₁) ⋯ exp([Sₙ'] φₙ) M' exp([ξ_tool])
//! φᵢ = θᵢ + δqᵢ + βᵢ ΔT,      θᵢ = qᵢ − sᵢ − cᵢ
//! ```
//!
//! where `q` is the motor-side position the controller reports, `sᵢ` the backlash shift
//! ([`gear_backlash`]), `cᵢ` the compliance sag ([`joint_compliance`]), `δqᵢ` the zero offset
//! ([`kinematic_offsets`]) and `βᵢ ΔT` the zero drift ([`thermal_drift`]). `θ` is the link-side position
//! in the controller's joint coordinates, reported as [`TrueTarget::q_link`]. Gravity torques for
//! backlash and compliance are those of the nominal inertials in this real geometry.
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
//! let cond = Conditions { q: &q, dir: None, temp_c: 20.0, payload: None };
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

use crate::error::{Result, SimError};
use crate::lie::Pose;
use crate::model::Model;
use crate::statics::Payload;
use joint_compliance::{Equilibrium, GravityWork, chain_gravity_torques};
use kinematic_offsets::Chain;
use nalgebra::{Point3, Vector3};

pub mod gear_backlash;
pub mod joint_compliance;
pub mod kinematic_offsets;
pub mod rapier_compliance;
pub mod thermal_drift;

/// How the compliance stage (4) of [`Truth`] finds the link-side angles where the joint springs
/// balance gravity and payload. Every other stage is the same for both.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum ComplianceSolver {
    /// Newton's method on `K (q − θ) = τ_g(θ)` ([`joint_compliance`]).
    #[default]
    Analytic,
    /// The real robot as a rapier multibody with joint springs, settled to rest
    /// ([`rapier_compliance`], [`crate::rapier_truth`]). Needs a compliance effect.
    Rapier(crate::rapier_truth::SettleOptions),
}

/// Every effect injected into one simulated robot; `None` = effect absent. Unknown keys are refused
/// when deserializing, so a misspelt effect is an error rather than silently absent.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Effects {
    /// Geometric errors.
    pub kinematic: Option<kinematic_offsets::KinematicOffsets>,
    /// Joint stiffness.
    pub compliance: Option<joint_compliance::JointCompliance>,
    /// Gear lost motion.
    pub backlash: Option<gear_backlash::GearBacklash>,
    /// Temperature-driven growth and drift.
    pub thermal: Option<thermal_drift::ThermalDrift>,
}

impl Effects {
    /// Checks that every effect fits `model` (list lengths) and that the model has the inertials that
    /// compliance and gravity-mode backlash need.
    pub fn check_fits(&self, model: &Model) -> Result<()> {
        let n = model.nq();
        if let Some(k) = &self.kinematic {
            k.check_fits(n)?;
        }
        if let Some(t) = &self.thermal {
            t.check_fits(n)?;
        }
        if let Some(b) = &self.backlash {
            b.check_fits(n)?;
            if b.mode() == gear_backlash::BacklashMode::Gravity {
                model.require_inertials()?;
            }
        }
        if let Some(c) = &self.compliance {
            c.check_fits(n)?;
            model.require_inertials()?;
        }
        Ok(())
    }

    /// True when no effect is present.
    pub fn is_empty(&self) -> bool {
        self.kinematic.is_none()
            && self.compliance.is_none()
            && self.backlash.is_none()
            && self.thermal.is_none()
    }
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
    /// Link-side joint positions after backlash and compliance (rad or m), in the controller's joint
    /// coordinates: `q − backlash shift − compliance sag` (zero offsets and zero drift not included).
    pub q_link: Vec<f64>,
    /// Link-side positions from the first-order compliance solution, for comparison (rad or m).
    pub q_link_first_order: Vec<f64>,
    /// Newton iterations the compliance equilibrium took, or rapier engine steps with
    /// [`ComplianceSolver::Rapier`] (0 without compliance).
    pub compliance_iterations: usize,
}

/// Displacements of the target point by each effect (base frame, m).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Contributions {
    /// Thermal drift.
    pub thermal: [f64; 3],
    /// Kinematic offsets.
    pub kinematic: [f64; 3],
    /// Gear backlash.
    pub backlash: [f64; 3],
    /// Joint compliance.
    pub compliance: [f64; 3],
}

impl Contributions {
    /// Sum of the four contributions: the total deviation from the nominal target position (base
    /// frame, m).
    pub fn total(&self) -> [f64; 3] {
        std::array::from_fn(|k| {
            self.thermal[k] + self.kinematic[k] + self.backlash[k] + self.compliance[k]
        })
    }
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
    /// [`ComplianceSolver::Rapier`] (0 without compliance).
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
    /// Grown chain with kinematic offsets, when there are any.
    real: Option<Chain>,
    thermal: Option<thermal_drift::ThermalDrift>,
    zero_offsets: Option<Vec<f64>>,
    backlash: Option<gear_backlash::GearBacklash>,
    /// `1/kᵢ` per joint (rad/(N m) or m/N).
    compliance: Option<Vec<f64>>,
    /// Mass (kg) and centre of mass (joint frame, m) of each moving body.
    bodies: Vec<(f64, Vector3<f64>)>,
    /// The rapier compliance stage, when the truth was made with [`ComplianceSolver::Rapier`].
    rapier: Option<rapier_compliance::RapierCompliance>,
}

/// Per-thread workspace of a [`Truth`]: made with [`Truth::scratch`], reused for every pose.
#[derive(Clone, Debug)]
pub struct TruthScratch {
    poses: Vec<Pose>,
    /// Chain angles before backlash: `q + β ΔT + δq` (rad or m).
    phi0: Vec<f64>,
    /// Backlash shift `sᵢ` (rad or m).
    shift: Vec<f64>,
    /// Chain angles after backlash (rad or m).
    phib: Vec<f64>,
    /// Chain angles after compliance (rad or m).
    theta: Vec<f64>,
    /// First-order chain angles after compliance (rad or m).
    first: Vec<f64>,
    q_link: Vec<f64>,
    q_link_first: Vec<f64>,
    work: GravityWork,
    /// Joint frames for a consistency check in debug builds.
    check_poses: Vec<Pose>,
    /// Prepared rapier arms (rapier compliance only).
    rapier: rapier_compliance::RapierCache,
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
    /// engine to settle) and for bad [`crate::rapier_truth::SettleOptions`].
    pub fn with_solver(
        model: &Model,
        effects: &Effects,
        solver: ComplianceSolver,
    ) -> Result<Truth> {
        effects.check_fits(model)?;
        let rapier = match solver {
            ComplianceSolver::Analytic => None,
            ComplianceSolver::Rapier(options) => {
                let c = effects.compliance.as_ref().ok_or_else(|| SimError::BadEffect {
                    effect: "joint_compliance",
                    field: "stiffness_nm_per_rad".into(),
                    value: "absent".into(),
                    problem: "the rapier truth settles the compliant joints: give a compliance effect"
                        .into(),
                })?;
                Some(rapier_compliance::RapierCompliance::new(
                    model,
                    c.stiffness_nm_per_rad(),
                    options,
                )?)
            }
        };
        let alpha = effects.thermal.as_ref().map(|t| t.alpha_per_k());
        let grown = Chain::grown(model, alpha);
        let real = effects
            .kinematic
            .as_ref()
            .map(|k| Chain::real(model, alpha, k));
        Ok(Truth {
            nq: model.nq(),
            grown,
            real,
            thermal: effects.thermal.clone(),
            zero_offsets: effects
                .kinematic
                .as_ref()
                .map(|k| k.zero_offsets().to_vec()),
            backlash: effects.backlash.clone(),
            compliance: effects.compliance.as_ref().map(|c| c.compliance()),
            bodies: model.bodies.iter().map(|b| (b.mass, b.com)).collect(),
            rapier,
        })
    }

    /// The compliance solver in use.
    pub fn solver(&self) -> ComplianceSolver {
        match &self.rapier {
            Some(r) => ComplianceSolver::Rapier(*r.options()),
            None => ComplianceSolver::Analytic,
        }
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
            phi0: vec![0.0; n],
            shift: vec![0.0; n],
            phib: vec![0.0; n],
            theta: vec![0.0; n],
            first: vec![0.0; n],
            q_link: vec![0.0; n],
            q_link_first: vec![0.0; n],
            work: GravityWork::new(n),
            check_poses: vec![Pose::identity(); n],
            rapier: rapier_compliance::RapierCache::default(),
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
        if self.thermal.is_some() && !cond.temp_c.is_finite() {
            return Err(cond_err(
                "temp_c",
                cond.temp_c,
                "not finite (thermal drift needs a temperature)",
            ));
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
        let n = self.nq;
        let s = scratch;
        let q = cond.q;
        let payload = cond.payload.as_ref();
        let mut contribution = Contributions::default();

        // 0. Nominal.
        let mut flange = self.grown.eval(q, 0.0, &mut s.poses);
        let mut p = point(&flange, p_flange);

        // 1. Thermal drift: grown links, drifted zeros.
        s.phi0.copy_from_slice(q);
        let mut dt = 0.0;
        if let Some(th) = &self.thermal {
            dt = th.delta_k(cond.temp_c);
            for (a, b) in s.phi0.iter_mut().zip(th.beta_rad_per_k()) {
                *a += b * dt;
            }
            flange = self.grown.eval(&s.phi0, dt, &mut s.poses);
            let p1 = point(&flange, p_flange);
            contribution.thermal = arr(p1 - p);
            p = p1;
        }

        // 2. Kinematic offsets: real screws, zero offsets, base and tool errors.
        let geom = self.real.as_ref().unwrap_or(&self.grown);
        if let Some(dq) = &self.zero_offsets {
            for (a, b) in s.phi0.iter_mut().zip(dq) {
                *a += b;
            }
            flange = geom.eval(&s.phi0, dt, &mut s.poses);
            let p2 = point(&flange, p_flange);
            contribution.kinematic = arr(p2 - p);
            p = p2;
        }
        // `s.poses` and `flange` now hold `geom` at `phi0` and `dt` (whichever stages ran).

        // 3. Backlash.
        s.phib.copy_from_slice(&s.phi0);
        s.shift.fill(0.0);
        if let Some(bl) = &self.backlash {
            let by_gravity = bl.mode() == gear_backlash::BacklashMode::Gravity;
            if by_gravity {
                chain_gravity_torques(
                    geom,
                    &s.poses,
                    &flange,
                    &self.bodies,
                    payload,
                    gravity,
                    &mut s.work,
                );
            }
            let mut moved = false;
            for i in 0..n {
                let dir = cond.dir.map_or(0, |d| d[i]);
                let tau = if by_gravity { s.work.tau[i] } else { 0.0 };
                let sh = bl.shift(i, dir, tau);
                s.shift[i] = sh;
                s.phib[i] -= sh;
                moved |= sh != 0.0;
            }
            if moved {
                flange = geom.eval(&s.phib, dt, &mut s.poses);
                let p3 = point(&flange, p_flange);
                contribution.backlash = arr(p3 - p);
                p = p3;
            }
        }

        // 4. Compliance.
        let mut iterations = 0;
        if let Some(c) = &self.compliance {
            let eq = Equilibrium {
                chain: geom,
                dt,
                bodies: &self.bodies,
                payload,
                gravity,
                compliance: c,
            };
            // `s.poses` and `flange` hold `geom` at `phib` here (from whichever stage ran last).
            debug_assert_eq!(
                geom.eval(&s.phib, dt, &mut s.check_poses),
                flange,
                "stage bookkeeping: the last evaluation must be at the post-backlash angles"
            );
            let (it, f) = match &self.rapier {
                None => eq.solve(
                    &s.phib,
                    &mut s.theta,
                    &mut s.first,
                    &mut s.poses,
                    flange,
                    &mut s.work,
                )?,
                Some(r) => {
                    // First-order solution from the analytic statics at the anchor angles, for the
                    // `q_link_first_order` comparison; the rest state comes from the engine.
                    eq.first_order(&s.phib, &mut s.first, &s.poses, &flange, &mut s.work);
                    r.settle(
                        geom,
                        dt,
                        payload,
                        gravity,
                        &s.phib,
                        &mut s.theta,
                        &mut s.rapier,
                    )?
                }
            };
            iterations = it;
            flange = f;
            let p4 = point(&flange, p_flange);
            contribution.compliance = arr(p4 - p);
            p = p4;
        } else {
            s.theta.copy_from_slice(&s.phib);
            s.first.copy_from_slice(&s.phib);
        }
        // Six parallel vectors: indexing reads clearer than a five-fold zip.
        #[allow(clippy::needless_range_loop)]
        for i in 0..n {
            s.q_link[i] = q[i] - s.shift[i] - (s.phib[i] - s.theta[i]);
            s.q_link_first[i] = q[i] - s.shift[i] - (s.phib[i] - s.first[i]);
        }
        Ok(TruePoint {
            flange,
            p_base: p,
            contribution,
            compliance_iterations: iterations,
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
) -> crate::Result<TrueTarget> {
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
