//! Joint compliance: elastic joints that sag under gravity and payload.
//!
//! # Model
//!
//! Each joint `i` is a torsional spring of stiffness `kᵢ` (N m/rad; N/m for prismatic joints;
//! `f64::INFINITY` = rigid) between the motor side, at `qᵢ` (after backlash), and the link side, at `θᵢ`.
//! The link settles where every spring balances the holding torque of gravity and payload:
//!
//! ```text
//! K (q − θ) = τ_g(θ)        ⇔        θ = q − K⁻¹ τ_g(θ)
//! ```
//!
//! with `τ_g(θ) = −Σₖ Jₖ(θ)ᵀ mₖ g` (see [`crate::statics`]; the payload of
//! [`super::Conditions::payload`] is one more mass at the flange). This is solved exactly by Newton's
//! method on `F(θ) = θ − q + K⁻¹ τ_g(θ)` with the analytic Jacobian `I + K⁻¹ H(θ)`, where
//! `H = ∂τ_g/∂θ` is the (symmetric) Hessian of the potential energy (refreshed while the steps exceed
//! 10⁻⁶ rad, reused for the last, tiny ones); iteration stops when
//! `max |Δθ| < ` [`TOLERANCE_RAD`] and fails after [`MAX_ITERATIONS`] steps or when the link strays more
//! than [`MAX_DEFLECTION_RAD`] from the motor (no equilibrium near the commanded pose: the joints are
//! too soft for the load). The first-order solution `θ₁ = q − K⁻¹ τ_g(q)` is returned as well; it
//! differs from the exact one by `K⁻¹ H K⁻¹ τ_g`, second order in the compliance.
//!
//! # Geometry of the gravity torques
//!
//! `τ_g` uses the nominal model's inertials (masses, centres of mass in the joint frames) attached to
//! the *real* joint frames: thermally grown link vectors and kinematic offsets, base error included,
//! with gravity given in the nominal base frame. Using the nominal geometry instead would change
//! `τ_g` by `O(ε τ_g)` for geometric errors of relative size `ε` (≈ 10⁻³), and the sag `K⁻¹ τ_g`
//! (≈ 10⁻³ rad) by `O(ε K⁻¹ τ_g)` ≈ 10⁻⁶ rad: a product of two small effects, second order, but
//! micrometres at the flange; the real geometry is what the physical robot feels, so the truth uses it.
//! Centres of mass are not moved by thermal growth (see [`super::thermal_drift`]).

use super::chain::Chain;
use super::effect::{
    ComplianceSolver, Effect, JointSprings, Moved, Needs, Prepare, ResolveCx, State,
};
use super::gravity::{BodyMasses, GravityWork, chain_gravity_hessian, chain_gravity_torques};
use super::rapier_compliance::{RapierCache, RapierCompliance};
use crate::coupled_joints::Couplings;
use crate::effect_id::EffectId;
use crate::error::{Result, SimError};
use crate::lie::Pose;
use crate::statics::Payload;
use nalgebra::Vector3;

/// Convergence threshold on the Newton step, `max |Δθ|` (rad; m for prismatic joints).
pub const TOLERANCE_RAD: f64 = 1e-13;
/// Most Newton steps before the equilibrium is declared not found.
pub const MAX_ITERATIONS: usize = 50;
/// Largest accepted sag `|qᵢ − θᵢ|` (rad or m): beyond it there is no equilibrium near the commanded
/// pose worth the name (a real robot's sag is below 0.01 rad).
pub const MAX_DEFLECTION_RAD: f64 = 0.5;

/// Per-joint stiffness (see the module docs for the model).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "JointComplianceSpec")]
pub struct JointCompliance {
    /// Stiffness of each joint (N m/rad; N/m for prismatic joints), > 0; `inf` = rigid. Serialized as a
    /// number, or the string `"inf"` for a rigid joint (JSON has no infinity).
    #[serde(serialize_with = "serialize_stiffness")]
    stiffness_nm_per_rad: Vec<f64>,
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct JointComplianceSpec {
    stiffness_nm_per_rad: Vec<StiffnessEntry>,
}

/// A stiffness as written in a file: a number, or `"inf"` / `"rigid"`.
#[derive(serde::Serialize, serde::Deserialize)]
#[serde(untagged)]
enum StiffnessEntry {
    Number(f64),
    Word(String),
}

fn serialize_stiffness<S: serde::Serializer>(
    k: &[f64],
    s: S,
) -> std::result::Result<S::Ok, S::Error> {
    use serde::Serialize;
    k.iter()
        .map(|&v| {
            if v == f64::INFINITY {
                StiffnessEntry::Word("inf".into())
            } else {
                StiffnessEntry::Number(v)
            }
        })
        .collect::<Vec<_>>()
        .serialize(s)
}

impl TryFrom<JointComplianceSpec> for JointCompliance {
    type Error = SimError;
    fn try_from(s: JointComplianceSpec) -> Result<Self> {
        let mut k = Vec::with_capacity(s.stiffness_nm_per_rad.len());
        for (i, e) in s.stiffness_nm_per_rad.into_iter().enumerate() {
            k.push(match e {
                StiffnessEntry::Number(v) => v,
                StiffnessEntry::Word(w) => match w.to_ascii_lowercase().as_str() {
                    "inf" | "infinity" | "rigid" => f64::INFINITY,
                    _ => {
                        return Err(SimError::bad_effect(
                            EffectId::JointCompliance,
                            format!("stiffness_nm_per_rad[{i}]"),
                            format!("'{w}'"),
                            "must be a number (N m/rad) or \"inf\" for a rigid joint",
                        ));
                    }
                },
            });
        }
        JointCompliance::new(k)
    }
}

impl JointCompliance {
    /// Joint springs of stiffness `stiffness_nm_per_rad` (N m/rad or N/m, one per joint): each > 0, or
    /// `f64::INFINITY` for a rigid joint. Refuses NaN, zero and negative values.
    pub fn new(stiffness_nm_per_rad: Vec<f64>) -> Result<Self> {
        crate::springs::stiffness::check_values(&stiffness_nm_per_rad)?;
        Ok(JointCompliance {
            stiffness_nm_per_rad,
        })
    }

    /// The same stiffness (N m/rad) for all `nq` joints.
    pub fn uniform(nq: usize, stiffness_nm_per_rad: f64) -> Result<Self> {
        JointCompliance::new(vec![stiffness_nm_per_rad; nq])
    }

    /// Stiffness of each joint (N m/rad or N/m; infinite = rigid).
    pub fn stiffness_nm_per_rad(&self) -> &[f64] {
        &self.stiffness_nm_per_rad
    }

    /// Compliance `1/kᵢ` of each joint (rad/(N m) or m/N; 0 = rigid).
    pub fn compliance(&self) -> Vec<f64> {
        self.stiffness_nm_per_rad.iter().map(|k| 1.0 / k).collect()
    }

    /// Checks that the length fits a robot with `nq` joints.
    pub fn check_fits(&self, nq: usize) -> Result<()> {
        crate::springs::stiffness::check_len(&self.stiffness_nm_per_rad, nq)
    }
}

/// LU factorization with partial pivoting of the row-major n×n matrix `a`, in place (unit lower
/// factor below the diagonal, upper factor above it, reciprocal pivots on it); `piv[k]` is the row
/// swapped into position `k`. False if `a` is singular to working precision.
fn lu_factor(a: &mut [f64], piv: &mut [usize], n: usize) -> bool {
    for col in 0..n {
        let mut p_row = col;
        for row in col + 1..n {
            if a[row * n + col].abs() > a[p_row * n + col].abs() {
                p_row = row;
            }
        }
        piv[col] = p_row;
        let p = a[p_row * n + col];
        if !p.is_finite() || p.abs() <= 1e-300 {
            return false;
        }
        if p_row != col {
            for k in 0..n {
                a.swap(p_row * n + k, col * n + k);
            }
        }
        let inv = 1.0 / p;
        a[col * n + col] = inv;
        let (upper, lower) = a.split_at_mut((col + 1) * n);
        let pivot_row = &upper[col * n..];
        for row in lower.chunks_exact_mut(n) {
            let f = row[col] * inv;
            row[col] = f;
            for k in col + 1..n {
                row[k] -= f * pivot_row[k];
            }
        }
    }
    true
}

/// Solves `A x = b` in place (b becomes x) with the factors of [`lu_factor`].
fn lu_solve(a: &[f64], piv: &[usize], b: &mut [f64], n: usize) {
    // The factorization swapped whole rows (multipliers included): permute b first, then substitute.
    for (col, &p) in piv.iter().enumerate().take(n) {
        b.swap(col, p);
    }
    for col in 0..n {
        let bc = b[col];
        for row in col + 1..n {
            b[row] -= a[row * n + col] * bc;
        }
    }
    for col in (0..n).rev() {
        let row = &a[col * n..(col + 1) * n];
        let mut s = b[col];
        for k in col + 1..n {
            s -= row[k] * b[k];
        }
        b[col] = s * row[col];
    }
}

/// Steps larger than this (rad or m) refresh the Newton matrix; below it the last factorization is
/// reused (its change over such a step is ~10⁻⁸ of itself, so convergence stays immediate).
pub(crate) const REFRESH_STEP_RAD: f64 = 1e-6;

/// When [`Equilibrium::newton`] refreshes its matrix, and how it finishes.
#[derive(Clone, Copy, Debug)]
pub(crate) struct NewtonSchedule {
    /// Steps larger than this (rad or m) refresh the Newton matrix; smaller ones reuse the last
    /// factorization (chord steps).
    pub refresh_step: f64,
    /// After the last step (below [`TOLERANCE_RAD`]), move the flange pose by that step to first
    /// order instead of evaluating the chain again: the flange turns by `δω = Σ wⱼ Δⱼ` and its origin
    /// moves by `Σ wⱼ × (p_flange − pⱼ) Δⱼ` (`wⱼ × …` replaced by `wⱼ` for a prismatic joint), with the
    /// axes `wⱼ` and origins `pⱼ` of the last evaluation. What is left is of order `|Δ|² < 10⁻²⁶`; the
    /// joint frames in `poses` stay those of the last evaluation (within the step of the root).
    pub first_order_finish: bool,
}

impl NewtonSchedule {
    /// The compliance solve's schedule: refresh after steps above [`REFRESH_STEP_RAD`], evaluate the
    /// chain at the root.
    pub const COMPLIANCE: NewtonSchedule = NewtonSchedule {
        refresh_step: REFRESH_STEP_RAD,
        first_order_finish: false,
    };
}

/// Everything the equilibrium solve reads.
pub(crate) struct Equilibrium<'a> {
    /// The real chain.
    pub chain: &'a Chain,
    /// Temperature offset `ΔT` (K) the chain is evaluated at.
    pub dt: f64,
    /// Nominal inertials.
    pub bodies: &'a BodyMasses,
    /// Payload at the flange.
    pub payload: Option<&'a Payload>,
    /// Gravity, base frame (m/s²).
    pub gravity: &'a Vector3<f64>,
    /// `1/kᵢ` (rad/(N m) or m/N; 0 = rigid; 0 at coupled joints).
    pub compliance: &'a [f64],
    /// The chain's coupled joints, when it has any: the springs are then the drives', and the sag is
    /// `A C Aᵀ τ` (virtual work, [`crate::coupled_joints`]).
    pub couplings: Option<&'a Couplings>,
}

impl Equilibrium<'_> {
    /// The sag `M v` into `out` for joint torques `v` (N m): `M = C` for a chain of driven joints,
    /// `A C Aᵀ` with coupled joints (the drives feel `Aᵀ v`, their sag moves the coupled joints
    /// through the linkage). `out` may not alias `v`.
    #[inline]
    fn sag(&self, v: &[f64], out: &mut [f64]) {
        match self.couplings {
            None => {
                for ((o, c), t) in out.iter_mut().zip(self.compliance).zip(v) {
                    *o = c * t;
                }
            }
            Some(cp) => {
                out.copy_from_slice(v);
                cp.to_drives(out);
                for (o, c) in out.iter_mut().zip(self.compliance) {
                    *o *= c;
                }
                cp.propagate(out);
            }
        }
    }

    /// The first-order solution `θ₁ = q_motor − K⁻¹ τ_g(q_motor)` (rad or m) into `first`, with
    /// `poses` and `flange` the chain evaluated at `q_motor`.
    pub fn first_order(
        &self,
        q_motor: &[f64],
        first: &mut [f64],
        poses: &[Pose],
        flange: &Pose,
        ws: &mut GravityWork,
    ) {
        chain_gravity_torques(
            self.chain,
            poses,
            flange,
            self.bodies,
            self.payload,
            self.gravity,
            ws,
        );
        self.sag(&ws.tau, &mut ws.sag);
        for (i, f) in first.iter_mut().enumerate() {
            *f = q_motor[i] - ws.sag[i];
        }
    }

    /// `flange` moved by the last step `ws.step` to first order (see
    /// [`NewtonSchedule::first_order_finish`]); `ws.w` and `poses` are those of the last evaluation.
    fn moved_by_step(&self, flange: &Pose, poses: &[Pose], ws: &GravityWork) -> Pose {
        let pf = flange.translation.vector;
        let (mut dw, mut dp) = (Vector3::zeros(), Vector3::zeros());
        for (j, (joint, pose)) in self.chain.joints.iter().zip(poses).enumerate() {
            let (w, d) = (ws.w[j], ws.step[j]);
            if joint.rotational {
                dw += w * d;
                dp += w.cross(&(pf - pose.translation.vector)) * d;
            } else {
                dp += w * d;
            }
        }
        let r = flange.rotation.matrix();
        crate::lie::pose_from(r + crate::lie::skew(&dw) * r, pf + dp)
    }

    /// Solves `θ = q_motor − K⁻¹ τ_g(θ)` (chain angles, rad or m) into `theta`, and the first-order
    /// solution into `first`. On entry `poses` and `flange` must hold the chain evaluated at `q_motor`
    /// (the caller has them already; this saves one evaluation). Returns the Newton steps taken and the
    /// flange pose at `theta`; `poses` holds the joint frames at `theta` afterwards.
    pub fn solve(
        &self,
        q_motor: &[f64],
        theta: &mut [f64],
        first: &mut [f64],
        poses: &mut [Pose],
        flange: Pose,
        ws: &mut GravityWork,
    ) -> Result<(usize, Pose)> {
        theta.copy_from_slice(q_motor);
        self.newton(
            q_motor,
            theta,
            Some(first),
            poses,
            flange,
            ws,
            NewtonSchedule::COMPLIANCE,
        )
    }

    /// Newton's method on `F(θ) = θ − q_motor + K⁻¹ τ_g(θ)` from the initial guess in `theta` (chain
    /// angles, rad or m; the root on return). On entry `poses` and `flange` must hold the chain
    /// evaluated at that guess. When `first` is given it receives `q_motor − K⁻¹ τ_g(guess)` (the
    /// first-order solution when the guess is `q_motor`). The Newton matrix is computed at the first
    /// step and again after every step larger than `schedule.refresh_step` (rad or m); in between the
    /// last factorization is reused (a chord step: it changes the convergence rate, never the root).
    /// Stops when a step is below [`TOLERANCE_RAD`]. Returns the Newton steps taken and the flange pose at the root; `poses`
    /// holds the joint frames at the root afterwards.
    #[allow(clippy::too_many_arguments)]
    pub fn newton(
        &self,
        q_motor: &[f64],
        theta: &mut [f64],
        mut first: Option<&mut [f64]>,
        poses: &mut [Pose],
        mut flange: Pose,
        ws: &mut GravityWork,
        schedule: NewtonSchedule,
    ) -> Result<(usize, Pose)> {
        let n = self.chain.nq();
        let mut last_step = f64::NAN;
        for it in 1..=MAX_ITERATIONS {
            if it > 1 {
                flange = self.chain.eval(theta, self.dt, poses);
            }
            chain_gravity_torques(
                self.chain,
                poses,
                &flange,
                self.bodies,
                self.payload,
                self.gravity,
                ws,
            );
            self.sag(&ws.tau, &mut ws.sag);
            if it == 1
                && let Some(first) = first.as_deref_mut()
            {
                for i in 0..n {
                    first[i] = q_motor[i] - ws.sag[i];
                }
            }
            if it == 1 || last_step > schedule.refresh_step {
                chain_gravity_hessian(self.chain, self.gravity, ws);
                match self.couplings {
                    None => {
                        for i in 0..n {
                            let c = self.compliance[i];
                            for j in 0..n {
                                let delta = if i == j { 1.0 } else { 0.0 };
                                ws.jac[i * n + j] = delta + c * ws.hess[i * n + j];
                            }
                        }
                    }
                    Some(_) => {
                        // I + A C Aᵀ H, column by column (H symmetric: its column j is its row j).
                        for j in 0..n {
                            // `ws.step` is free until the right-hand side below.
                            self.sag(&ws.hess[j * n..(j + 1) * n], &mut ws.step);
                            for (i, c) in ws.step.iter().enumerate() {
                                let delta = if i == j { 1.0 } else { 0.0 };
                                ws.jac[i * n + j] = delta + c;
                            }
                        }
                    }
                }
                if !lu_factor(&mut ws.jac, &mut ws.piv, n) {
                    return Err(SimError::ComplianceDiverged {
                        reason: format!(
                            "the stiffness matrix K + ∂τ_g/∂θ is singular at step {it} (a joint buckles under the load)"
                        ),
                    });
                }
            }
            for i in 0..n {
                ws.step[i] = -(theta[i] - q_motor[i] + ws.sag[i]);
            }
            lu_solve(&ws.jac, &ws.piv, &mut ws.step, n);
            let mut step = 0.0f64;
            for i in 0..n {
                theta[i] += ws.step[i];
                step = step.max(ws.step[i].abs());
                let sag = (q_motor[i] - theta[i]).abs();
                if !sag.is_finite() || sag > MAX_DEFLECTION_RAD {
                    return Err(SimError::ComplianceDiverged {
                        reason: format!(
                            "joint {} sags {sag:.3e} rad (> {MAX_DEFLECTION_RAD} rad) at step {it}: stiffness too low for the load",
                            i + 1
                        ),
                    });
                }
            }
            last_step = step;
            if step < TOLERANCE_RAD {
                if schedule.first_order_finish {
                    return Ok((it, self.moved_by_step(&flange, poses, ws)));
                }
                let flange = self.chain.eval(theta, self.dt, poses);
                return Ok((it, flange));
            }
        }
        Err(SimError::ComplianceDiverged {
            reason: format!(
                "no convergence in {MAX_ITERATIONS} Newton steps (last step {last_step:.3e} rad > {TOLERANCE_RAD:e})"
            ),
        })
    }
}

/// `[effects.compliance]`.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ComplianceSection {
    /// Switch (default on).
    pub enabled: Option<bool>,
    /// Joint stiffness (N m/rad; N/m for prismatic joints), shape `[n]`.
    pub stiffness_nm_per_rad: crate::magnitude::Magnitude,
}

/// The prepared compliance stage: `1/kᵢ` per joint and, with [`ComplianceSolver::Rapier`], the
/// rapier arm builder.
#[derive(Clone, Debug)]
pub struct ComplianceStage {
    /// `1/kᵢ` per joint (rad/(N m) or m/N; 0 at coupled joints).
    compliance: Vec<f64>,
    /// The model's coupled joints, when it has any.
    couplings: Option<Couplings>,
    rapier: Option<RapierCompliance>,
}

impl ComplianceStage {
    /// The rapier settle options, when the stage settles in the physics engine.
    pub fn rapier_options(&self) -> Option<crate::springs::SettleOptions> {
        self.rapier.as_ref().map(|r| *r.options())
    }
}

/// Per-thread workspace of the compliance stage.
#[derive(Clone, Debug, Default)]
pub struct ComplianceScratch {
    /// Chain angles after compliance (rad or m).
    theta: Vec<f64>,
    /// First-order chain angles after compliance (rad or m).
    first: Vec<f64>,
    /// Joint frames for a consistency check in debug builds.
    check_poses: Vec<Pose>,
    /// Prepared rapier arms (rapier compliance only).
    rapier: RapierCache,
}

impl Effect for JointCompliance {
    const ID: EffectId = EffectId::JointCompliance;
    type Section = ComplianceSection;
    type Stage = ComplianceStage;
    type Scratch = ComplianceScratch;

    fn enabled(section: &ComplianceSection) -> bool {
        section.enabled.unwrap_or(true)
    }

    fn from_section(c: &ComplianceSection, cx: &ResolveCx<'_>) -> Result<Self> {
        cx.require_inertials("", "compliance")?;
        let k = cx.draw(&c.stiffness_nm_per_rad, "stiffness_nm_per_rad", &[cx.nq()])?;
        cx.checked(JointCompliance::new(k))
    }

    fn needs(&self) -> Needs {
        Needs {
            payload: true,
            inertials: true,
            ..Needs::default()
        }
    }

    fn check_lengths(&self, nq: usize) -> Result<()> {
        self.check_fits(nq)
    }

    /// With coupled joints ([`crate::coupled_joints`]) the springs are the drives': a coupled
    /// joint's own stiffness is not used (it has no drive; its compliance is 0), and its torque goes
    /// to its sources by virtual work. The rapier solver has no coupled joints.
    fn prepare(&self, cx: &Prepare<'_>) -> Result<ComplianceStage> {
        let couplings = cx.model.couplings();
        let mut compliance = self.compliance();
        for c in couplings.list() {
            compliance[c.joint] = 0.0;
        }
        let rapier = match cx.solver {
            ComplianceSolver::Analytic => None,
            ComplianceSolver::Rapier(_) if !couplings.is_empty() => {
                return Err(SimError::ComplianceDiverged {
                    reason: "the rapier solver does not model coupled joints: use the analytic \
                             compliance solver for this robot"
                        .into(),
                });
            }
            ComplianceSolver::Rapier(options) => Some(RapierCompliance::new(
                cx.model,
                &self.stiffness_nm_per_rad,
                options,
            )?),
        };
        Ok(ComplianceStage {
            compliance,
            couplings: (!couplings.is_empty()).then(|| couplings.clone()),
            rapier,
        })
    }

    fn scratch(_stage: &ComplianceStage, nq: usize) -> ComplianceScratch {
        ComplianceScratch {
            theta: vec![0.0; nq],
            first: vec![0.0; nq],
            check_poses: vec![Pose::identity(); nq],
            rapier: RapierCache::default(),
        }
    }

    /// The link side settles where the springs balance gravity and payload, anchored at the angles
    /// after backlash: `φ ← θ` with `K (φ − θ) = τ_g(θ)`. With the rapier solver the flange comes from
    /// the engine and the joint frames in the state stay those of the anchor angles. The springs and
    /// their anchor are left in the state for a later stage that settles in the same equilibrium
    /// ([`super::link_deflection`]).
    fn act<'t>(
        stage: &'t ComplianceStage,
        st: &mut State<'t, '_>,
        sc: &mut ComplianceScratch,
    ) -> Result<Moved> {
        let payload = st.cond.payload.as_ref();
        let eq = Equilibrium {
            chain: st.geom,
            dt: st.dt,
            bodies: st.bodies,
            payload,
            gravity: st.gravity,
            compliance: &stage.compliance,
            couplings: stage.couplings.as_ref(),
        };
        // The state holds the chain evaluated at the anchor angles (from whichever stage ran last).
        debug_assert_eq!(
            st.geom.eval(st.angles, st.dt, &mut sc.check_poses),
            st.flange,
            "stage bookkeeping: the last evaluation must be at the post-backlash angles"
        );
        let (it, f) = match &stage.rapier {
            None => eq.solve(
                st.angles,
                &mut sc.theta,
                &mut sc.first,
                st.poses,
                st.flange,
                st.work,
            )?,
            Some(r) => {
                // First-order solution from the analytic statics at the anchor angles, for the
                // `q_link_first_order` comparison; the rest state comes from the engine.
                eq.first_order(st.angles, &mut sc.first, st.poses, &st.flange, st.work);
                r.settle(
                    st.geom,
                    st.dt,
                    payload,
                    st.gravity,
                    st.angles,
                    &mut sc.theta,
                    &mut sc.rapier,
                )?
            }
        };
        for i in 0..st.angles.len() {
            st.q_link[i] -= st.angles[i] - sc.theta[i];
            st.q_link_first[i] -= st.angles[i] - sc.first[i];
        }
        st.anchor.copy_from_slice(st.angles);
        st.springs = Some(JointSprings {
            compliance: &stage.compliance,
        });
        st.angles.copy_from_slice(&sc.theta);
        st.flange = f;
        st.iterations += it;
        Ok(Moved::Evaluated)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematics::Data;
    use crate::robots;
    use crate::statics::{DEFAULT_GRAVITY, gravity_torques};

    fn bodies(m: &crate::model::Model) -> Vec<(f64, Vector3<f64>)> {
        m.bodies().iter().map(|b| (b.mass, b.com)).collect()
    }

    #[test]
    fn chain_torques_match_statics_and_hessian_matches_finite_differences() {
        let m = robots::load_builtin("iiwa7").unwrap();
        let chain = Chain::grown(&m, None);
        let b = bodies(&m);
        let g = Vector3::from(DEFAULT_GRAVITY);
        let pl = Payload {
            mass: 2.3,
            com: [0.02, -0.01, 0.07],
        };
        let mut ws = GravityWork::new(7);
        let mut poses = vec![Pose::identity(); 7];
        let mut d = Data::new(&m);
        let q = [0.3, -0.7, 1.1, 1.4, -0.5, 0.9, 0.2];
        let f = chain.eval(&q, 0.0, &mut poses);
        chain_gravity_torques(&chain, &poses, &f, &b, Some(&pl), &g, &mut ws);
        gravity_torques(&m, &mut d, &q, &g, Some(&pl)).unwrap();
        for i in 0..7 {
            assert!((ws.tau[i] - d.gravity_torque[i]).abs() < 1e-12, "joint {i}");
        }
        chain_gravity_hessian(&chain, &g, &mut ws);
        let hess = ws.hess.clone();
        let h = 1e-6;
        for j in 0..7 {
            let (mut qp, mut qm) = (q, q);
            qp[j] += h;
            qm[j] -= h;
            gravity_torques(&m, &mut d, &qp, &g, Some(&pl)).unwrap();
            let tp = d.gravity_torque.clone();
            gravity_torques(&m, &mut d, &qm, &g, Some(&pl)).unwrap();
            for i in 0..7 {
                let fd = (tp[i] - d.gravity_torque[i]) / (2.0 * h);
                assert!(
                    (fd - hess[i * 7 + j]).abs() < 1e-7,
                    "H[{i}][{j}]: fd {fd} vs {}",
                    hess[i * 7 + j]
                );
            }
        }
    }

    #[test]
    fn lu_factors_solve_pivoting_systems_and_are_reusable() {
        // [[0, 2], [3, 1]] x = [4, 5] → x = [1, 2] (hand solution; needs the row swap).
        let mut a = [0.0, 2.0, 3.0, 1.0];
        let mut piv = [0; 2];
        let mut b = [4.0, 5.0];
        assert!(lu_factor(&mut a, &mut piv, 2));
        lu_solve(&a, &piv, &mut b, 2);
        assert!((b[0] - 1.0).abs() < 1e-15 && (b[1] - 2.0).abs() < 1e-15);
        // Reused factors, second right-hand side: [2, 7] → x = [2, 1].
        let mut b = [2.0, 7.0];
        lu_solve(&a, &piv, &mut b, 2);
        assert!((b[0] - 2.0).abs() < 1e-15 && (b[1] - 1.0).abs() < 1e-15);
        // 3×3 with pivoting at two levels: A = [[1, 2, 3], [4, 5, 6], [7, 8, 10]], x = [1, -1, 2]
        // gives b = A x = [5, 11, 19] (by hand).
        let mut a = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 10.0];
        let mut piv = [0; 3];
        let mut b = [5.0, 11.0, 19.0];
        assert!(lu_factor(&mut a, &mut piv, 3));
        lu_solve(&a, &piv, &mut b, 3);
        assert!(
            (b[0] - 1.0).abs() < 1e-14 && (b[1] + 1.0).abs() < 1e-14 && (b[2] - 2.0).abs() < 1e-14,
            "{b:?}"
        );
        let mut a = [1.0, 2.0, 2.0, 4.0];
        assert!(!lu_factor(&mut a, &mut [0; 2], 2));
    }

    #[test]
    fn constructor_refuses_bad_stiffness_naming_the_field() {
        for k in [0.0, -5.0, f64::NAN, f64::NEG_INFINITY] {
            let e = JointCompliance::new(vec![1e4, k]).unwrap_err();
            assert!(e.to_string().contains("stiffness_nm_per_rad[1]"), "{e}");
        }
        assert!(JointCompliance::new(vec![1e4, f64::INFINITY]).is_ok());
        assert!(
            JointCompliance::uniform(3, 1e4)
                .unwrap()
                .check_fits(7)
                .is_err()
        );
    }

    #[test]
    fn infinite_stiffness_survives_json_and_toml() {
        let c = JointCompliance::new(vec![5000.0, f64::INFINITY]).unwrap();
        let s = serde_json::to_string(&c).unwrap();
        assert_eq!(s, r#"{"stiffness_nm_per_rad":[5000.0,"inf"]}"#);
        assert_eq!(serde_json::from_str::<JointCompliance>(&s).unwrap(), c);
        let t: JointCompliance = toml::from_str("stiffness_nm_per_rad = [5000.0, inf]").unwrap();
        assert_eq!(t, c);
        let r: JointCompliance =
            toml::from_str(r#"stiffness_nm_per_rad = [5000.0, "rigid"]"#).unwrap();
        assert_eq!(r, c);
        let e = toml::from_str::<JointCompliance>(r#"stiffness_nm_per_rad = [5000.0, "stiff"]"#)
            .unwrap_err();
        assert!(e.to_string().contains("stiffness_nm_per_rad[1]"), "{e}");
        let e = toml::from_str::<JointCompliance>("stiffness_nm_per_rad = [-1.0]").unwrap_err();
        assert!(e.to_string().contains("stiffness_nm_per_rad[0]"), "{e}");
    }
}
