//! Link deflection: the child side of a joint tilts under the gravity-and-payload moment the joint
//! carries across its axis (bearing and link compliance).
//!
//! # Model
//!
//! A joint carries the whole moment of gravity and payload beyond it. Its component along the joint
//! axis is held by the drive (and, with [`super::joint_compliance`], twists the joint spring); the two
//! components across the axis are held by the output bearing and the link structure, which give a
//! little. Joint `i` has compliances `cᵢᵤ`, `cᵢᵥ` (rad/(N m); 0 = rigid) about two axes `uᵢ`, `vᵢ`
//! orthogonal to its axis `aᵢ`, through the joint origin, in joint frame `i` (the child link's frame,
//! which turns with the joint). The child side is rotated by small angles `αᵢ` about `uᵢ`, then `βᵢ`
//! about `vᵢ`:
//!
//! ```text
//! T_base_joint[i] = T_base_joint[i−1] · Oᵢ · Rot(aᵢ, θᵢ) · Rot(uᵢ, αᵢ) · Rot(vᵢ, βᵢ)
//! ```
//!
//! (`Oᵢ` the joint origin; `vᵢ` is turned by `αᵢ` with the frame, as two hinges in series; the link's
//! centre of mass, the next joint origin and the flange hang on the last frame). The angles settle
//! where the bearing springs balance the moment `Mᵢ = Σ_beyond m (c − pᵢ) × g` (payload included):
//!
//! ```text
//! αᵢ = cᵢᵤ uᵢ · Mᵢ,     βᵢ = cᵢᵥ vᵢ · Mᵢ      (axes and M in the base frame, at the deflected pose)
//! ```
//!
//! # The axes
//!
//! For a joint with unit axis `a` in its joint frame: `e` is the coordinate axis of that frame least
//! aligned with `a` (the smallest `|aₖ|`; the first of x, y, z on ties), `u = (e − (e·a) a)/|…|` and
//! `v = a × u`; so `(u, v, a)` is right-handed. For the iiwa 7: axes +z (joints 1, 3, 5, 7) give
//! `u = x`, `v = y`; axis +y (joints 2, 6) gives `u = x`, `v = −z`; axis −y (joint 4) gives `u = x`,
//! `v = +z`. [`deflection_axes`] computes them.
//!
//! # One equilibrium with the joint springs
//!
//! The moments depend on the deflected configuration, and so do the joint holding torques: the joint
//! springs and the deflection springs settle together. The angles `x = (θ, α, β)` of the chain with
//! two hinges per deflecting joint solve
//!
//! ```text
//! x = x₀ − C τ_g(x),      x₀ = (anchor, 0, 0),   C = diag(joint compliance, cᵤ, cᵥ)
//! ```
//!
//! where `τ_g` are the holding torques of that chain: exactly the joint-compliance equilibrium
//! ([`super::joint_compliance`]) on a longer chain, solved by the same Newton's method with the same
//! analytic Hessian. Without joint compliance the joints are rigid (their compliance is 0, `θ` stays
//! at the anchor). This stage runs after the joint-compliance stage: its contribution is what the
//! deflection adds to the joint sag alone (the joint angles move too, by the change of the joint
//! torques), so compliance and deflection together give the joint equilibrium of both. It is the
//! last stage: the geometry it settles is not a chain of the model's joints, and a stage after it
//! would re-evaluate the chain without it.
//!
//! With `[truth] model = "rapier"` the engine settles it instead: the multibody gets the two hinges
//! after each deflecting joint, with springs `1/cᵤ`, `1/cᵥ` toward zero
//! ([`crate::rapier_truth::RapierArm::with_deflection`]), and settles joints and hinges together
//! from rest at the joint springs' anchors, on the real geometry of the measurement (as the compliance
//! stage does, [`super::rapier_compliance`]). The joint frames in the state then stay those of the
//! stage before (no stage follows).
//!
//! # Magnitudes
//!
//! Harmonic Drive CSF/CSG catalogue, "Specifications for Cross Roller Bearing": the moment stiffness of
//! the units' output bearings is of order 10⁵–10⁶ N m/rad for sizes 14–32; the link tubes and flanges
//! of a lightweight arm add a similar compliance. `cᵤ, cᵥ` of 10⁻⁶–5·10⁻⁶ rad/(N m) at the shoulder
//! and elbow, where the iiwa 7 carries up to ≈ 60 N m across its axes, give 0.1–0.3 mrad: 0.1–0.3 mm at
//! the flange.

use super::chain::{Chain, ChainJoint};
use super::effect::{ComplianceSolver, Effect, Moved, Needs, Prepare, ResolveCx, State};
use super::gravity::GravityWork;
use super::joint_compliance::{Equilibrium, NewtonSchedule};
use super::rapier_compliance::{RapierCache, RapierCompliance};
use crate::effect_id::EffectId;
use crate::error::{Result, SimError};
use crate::lie::Pose;
use crate::magnitude::Magnitude;
use crate::model::Joint;
use nalgebra::{Matrix3, Vector3};

/// Steps larger than this (rad) refresh the Newton matrix of the joint + deflection solve. It starts
/// from the joint sag alone, so its first step is the deflection itself (≈ 10⁻⁴ rad) and the matrix
/// changes by `C ∂H/∂x Δx` (≈ 10⁻⁴ · 10² · 10⁻⁴ = 10⁻⁶ of itself): the first factorization serves
/// every later (chord) step, which converge at that rate. Only a soft arm, whose steps exceed this,
/// pays for more factorizations.
pub const REFRESH_STEP_RAD: f64 = 1e-2;

pub use crate::springs::deflection::{MAX_COMPLIANCE_RAD_PER_NM, deflection_axes};
use crate::springs::deflection::{check_len, check_values};

/// Per-joint compliance across the joint axis (see the module docs for the model).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "LinkDeflectionSpec")]
pub struct LinkDeflection {
    /// `[cᵤ, cᵥ]` of each joint (rad/(N m)), ≥ 0; 0 = rigid about that axis.
    compliance_rad_per_nm: Vec<[f64; 2]>,
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct LinkDeflectionSpec {
    compliance_rad_per_nm: Vec<[f64; 2]>,
}

impl TryFrom<LinkDeflectionSpec> for LinkDeflection {
    type Error = SimError;
    fn try_from(s: LinkDeflectionSpec) -> Result<Self> {
        LinkDeflection::new(s.compliance_rad_per_nm)
    }
}

impl LinkDeflection {
    /// Deflection with compliances `[cᵤ, cᵥ]` per joint (rad/(N m)). Refuses negative, non-finite
    /// and values above [`MAX_COMPLIANCE_RAD_PER_NM`].
    pub fn new(compliance_rad_per_nm: Vec<[f64; 2]>) -> Result<Self> {
        check_values(&compliance_rad_per_nm)?;
        Ok(LinkDeflection {
            compliance_rad_per_nm,
        })
    }

    /// The same compliance `c` (rad/(N m)) about both axes of all `nq` joints.
    pub fn uniform(nq: usize, c: f64) -> Result<Self> {
        LinkDeflection::new(vec![[c, c]; nq])
    }

    /// `[cᵤ, cᵥ]` of each joint (rad/(N m)).
    pub fn compliance_rad_per_nm(&self) -> &[[f64; 2]] {
        &self.compliance_rad_per_nm
    }

    /// Checks that the length fits a robot with `nq` joints.
    pub fn check_fits(&self, nq: usize) -> Result<()> {
        check_len(&self.compliance_rad_per_nm, nq)
    }
}

/// `[effects.deflection]`.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DeflectionSection {
    /// Switch (default on).
    pub enabled: Option<bool>,
    /// Compliance about `u` and `v` of each joint (rad/(N m)), shape `[n][2]`; 0 = rigid.
    pub compliance_rad_per_nm: Magnitude,
}

/// The prepared deflection stage: the layout of the chain with deflection hinges.
#[derive(Clone, Debug)]
pub struct DeflectionStage {
    /// Index in the long chain of each joint of the model.
    joint_index: Vec<usize>,
    /// Index in the long chain of the frame joint `i`'s link hangs on (its last hinge).
    frame_index: Vec<usize>,
    /// The long chain with its hinges; the model's joints are copied in per pose (the geometry the
    /// stages evaluate may differ from truth to truth).
    template: Chain,
    /// Compliance of each unknown of the long chain, hinges set, joints 0 (set per pose).
    compliance: Vec<f64>,
    /// Mass (kg) and centre of mass (m, in the frame it hangs on) per joint of the long chain.
    bodies: Vec<(f64, Vector3<f64>)>,
    /// With [`ComplianceSolver::Rapier`]: the rapier arms with deflection hinges.
    rapier: Option<RapierCompliance>,
}

/// Per-thread workspace of the deflection stage.
#[derive(Clone, Debug, Default)]
pub struct DeflectionScratch {
    /// Prepared rapier arms (rapier truth only).
    rapier: RapierCache,
    chain: Chain,
    compliance: Vec<f64>,
    anchor: Vec<f64>,
    x: Vec<f64>,
    poses: Vec<Pose>,
    work: GravityWork,
    /// [`DeflectionStage::bodies`] with each joint's body as the state has it (branches posed).
    bodies: Vec<(f64, Vector3<f64>)>,
}

/// A hinge about `axis` (unit, in the frame before it) at the origin of that frame.
fn hinge(axis: Vector3<f64>) -> ChainJoint {
    let coordinate_hinge = (0..3).find_map(|k| {
        let e = Vector3::ith(k, 1.0);
        if axis == e {
            Some((k, 1.0))
        } else if axis == -e {
            Some((k, -1.0))
        } else {
            None
        }
    });
    ChainJoint {
        rotational: true,
        axis,
        terms: Joint::rotation_terms_for(&Pose::identity(), &axis),
        origin_rot: Matrix3::identity(),
        p0: Vector3::zeros(),
        dp: Vector3::zeros(),
        coordinate_hinge,
    }
}

impl Effect for LinkDeflection {
    const ID: EffectId = EffectId::LinkDeflection;
    type Section = DeflectionSection;
    type Stage = DeflectionStage;
    type Scratch = DeflectionScratch;

    fn enabled(section: &DeflectionSection) -> bool {
        section.enabled.unwrap_or(true)
    }

    fn from_section(d: &DeflectionSection, cx: &ResolveCx<'_>) -> Result<Self> {
        cx.require_inertials("", "link deflection")?;
        let n = cx.nq();
        let c = cx.draw(&d.compliance_rad_per_nm, "compliance_rad_per_nm", &[n, 2])?;
        cx.checked(LinkDeflection::new(
            c.chunks_exact(2).map(|p| [p[0], p[1]]).collect(),
        ))
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

    fn prepare(&self, cx: &Prepare<'_>) -> Result<DeflectionStage> {
        if !cx.model.couplings().is_empty() {
            return Err(SimError::bad_effect(
                EffectId::LinkDeflection,
                "compliance_rad_per_nm",
                "given",
                "link deflection is not simulated on a robot with coupled joints (its equilibrium \
                 would need the drives' springs through the coupling)",
            ));
        }
        let rapier = match (cx.solver, cx.joint_stiffness) {
            (ComplianceSolver::Analytic, _) => None,
            (ComplianceSolver::Rapier(options), Some(k)) => {
                Some(RapierCompliance::with_deflection(
                    cx.model,
                    k,
                    &self.compliance_rad_per_nm,
                    options,
                )?)
            }
            (ComplianceSolver::Rapier(_), None) => {
                return Err(SimError::bad_effect(
                    EffectId::LinkDeflection,
                    "compliance_rad_per_nm",
                    "given",
                    "the rapier truth settles joints and deflection together: give [effects.compliance] too",
                ));
            }
        };
        let model = cx.model;
        let mut joints = Vec::new();
        let mut compliance = Vec::new();
        let mut bodies = Vec::new();
        let mut joint_index = Vec::new();
        let mut frame_index = Vec::new();
        for (i, (j, c)) in model
            .joints()
            .iter()
            .zip(&self.compliance_rad_per_nm)
            .enumerate()
        {
            let (u, v) = deflection_axes(&j.axis);
            joint_index.push(joints.len());
            // The model's joint: a placeholder, copied from the stages' geometry per pose.
            joints.push(hinge(j.axis));
            compliance.push(0.0);
            bodies.push((0.0, Vector3::zeros()));
            for (axis, &ck) in [u, v].into_iter().zip(c) {
                if ck > 0.0 {
                    joints.push(hinge(axis));
                    compliance.push(ck);
                    bodies.push((0.0, Vector3::zeros()));
                }
            }
            let last = joints.len() - 1;
            frame_index.push(last);
            bodies[last] = (model.bodies()[i].mass, model.bodies()[i].com);
        }
        let f = &model.flange_offset();
        let template = Chain {
            base: None,
            joints,
            flange_rot: *f.rotation.matrix(),
            flange_p0: f.translation.vector,
            flange_dp: Vector3::zeros(),
        };
        Ok(DeflectionStage {
            joint_index,
            frame_index,
            template,
            compliance,
            bodies,
            rapier,
        })
    }

    fn scratch(stage: &DeflectionStage, _nq: usize) -> DeflectionScratch {
        let m = stage.template.nq();
        DeflectionScratch {
            rapier: RapierCache::default(),
            chain: stage.template.clone(),
            compliance: stage.compliance.clone(),
            anchor: vec![0.0; m],
            x: vec![0.0; m],
            poses: vec![Pose::identity(); m],
            work: GravityWork::new(m),
            bodies: stage.bodies.clone(),
        }
    }

    /// Settles joints and deflection hinges together (see the module docs), from the joint angles
    /// of the stages before (the joint sag alone, with joint compliance) and zero deflection.
    fn act<'t>(
        stage: &'t DeflectionStage,
        st: &mut State<'t, '_>,
        sc: &mut DeflectionScratch,
    ) -> Result<Moved> {
        if stage.template.nq() == stage.joint_index.len() {
            // No hinge (every compliance 0): the joints are settled already.
            return Ok(Moved::Unchanged);
        }
        // Each joint's body as the state has it: with the branches off the chain posed.
        for (&f, b) in stage.frame_index.iter().zip(st.bodies) {
            sc.bodies[f] = *b;
        }
        if let Some(r) = &stage.rapier {
            // The engine settles joints and hinges from rest at the joint springs' anchors (set by
            // the compliance stage, which a rapier truth always has).
            let theta = &mut sc.x[..st.angles.len()];
            let (steps, flange) = r.settle(
                st.geom,
                st.dt,
                st.cond.payload.as_ref(),
                st.gravity,
                st.anchor,
                theta,
                &mut sc.rapier,
            )?;
            for (i, &th) in theta.iter().enumerate() {
                st.q_link[i] -= st.angles[i] - th;
                st.angles[i] = th;
            }
            st.flange = flange;
            st.iterations += steps;
            return Ok(Moved::Evaluated);
        }
        let g = st.geom;
        sc.chain.base = g.base;
        sc.chain.flange_rot = g.flange_rot;
        sc.chain.flange_p0 = g.flange_p0;
        sc.chain.flange_dp = g.flange_dp;
        sc.anchor.fill(0.0);
        sc.x.fill(0.0);
        for (i, &e) in stage.joint_index.iter().enumerate() {
            sc.chain.joints[e] = g.joints[i];
            sc.x[e] = st.angles[i];
            match st.springs {
                Some(springs) => {
                    sc.anchor[e] = st.anchor[i];
                    sc.compliance[e] = springs.compliance[i];
                }
                None => {
                    sc.anchor[e] = st.angles[i];
                    sc.compliance[e] = 0.0;
                }
            }
        }
        // The long chain at zero deflection is the chain the state was last evaluated on (at these
        // angles, by the stage before): its frames are the state's, each hinge frame that of its
        // joint. Copying them saves an evaluation.
        debug_assert_eq!(
            st.geom
                .eval(st.angles, st.dt, &mut sc.poses[..st.angles.len()]),
            st.flange,
            "stage bookkeeping: the state must hold the chain evaluated at its angles"
        );
        let mut joint = 0;
        for (e, pose) in sc.poses.iter_mut().enumerate() {
            if joint + 1 < stage.joint_index.len() && stage.joint_index[joint + 1] == e {
                joint += 1;
            }
            *pose = st.poses[joint];
        }
        let flange = st.flange;
        let eq = Equilibrium {
            chain: &sc.chain,
            dt: st.dt,
            bodies: &sc.bodies,
            payload: st.cond.payload.as_ref(),
            gravity: st.gravity,
            compliance: &sc.compliance,
            couplings: None,
        };
        let (it, flange) = eq
            .newton(
                &sc.anchor,
                &mut sc.x,
                None,
                &mut sc.poses,
                flange,
                &mut sc.work,
                NewtonSchedule {
                    refresh_step: REFRESH_STEP_RAD,
                    first_order_finish: true,
                },
            )
            .map_err(|e| match e {
                SimError::ComplianceDiverged { reason } => SimError::ComplianceDiverged {
                    reason: format!(
                        "joints with link deflection (unknowns numbered joint by joint, each deflecting joint followed by its u and v hinges): {reason}"
                    ),
                },
                other => other,
            })?;
        for (i, (&e, &f)) in stage.joint_index.iter().zip(&stage.frame_index).enumerate() {
            let theta = sc.x[e];
            st.q_link[i] -= st.angles[i] - theta;
            st.angles[i] = theta;
            st.poses[i] = sc.poses[f];
        }
        st.flange = flange;
        st.iterations += it;
        Ok(Moved::Evaluated)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::effects::gravity::{chain_gravity_hessian, chain_gravity_torques};
    use crate::statics::{DEFAULT_GRAVITY, Payload};

    #[test]
    fn axes_complete_the_joint_axis_as_documented() {
        let cases = [
            (Vector3::z(), Vector3::x(), Vector3::y()),
            (Vector3::y(), Vector3::x(), -Vector3::z()),
            (-Vector3::y(), Vector3::x(), Vector3::z()),
            (Vector3::x(), Vector3::y(), Vector3::z()),
        ];
        for (a, u, v) in cases {
            let (gu, gv) = deflection_axes(&a);
            assert!(
                (gu - u).amax() < 1e-15 && (gv - v).amax() < 1e-15,
                "{a}: {gu} {gv}"
            );
        }
        let a = Vector3::new(0.3, -0.4, 0.5).normalize();
        let (u, v) = deflection_axes(&a);
        assert!(u.dot(&a).abs() < 1e-15 && v.dot(&a).abs() < 1e-15 && u.dot(&v).abs() < 1e-15);
        assert!((u.cross(&v) - a).amax() < 1e-15);
    }

    #[test]
    fn coordinate_hinges_evaluate_as_the_general_rotation() {
        let m = crate::robots::load_builtin("iiwa7").unwrap();
        let real = Chain::grown(&m, None);
        let mut fast = real.clone();
        for (k, j) in fast.joints.iter_mut().enumerate() {
            *j = hinge(j.axis);
            assert_eq!(
                j.coordinate_hinge.map(|h| h.0),
                Some([2, 1, 2, 1, 2, 1, 2][k])
            );
        }
        fast.joints
            .extend([hinge(Vector3::x()), hinge(-Vector3::z())]);
        let mut slow = fast.clone();
        for j in &mut slow.joints {
            j.coordinate_hinge = None;
        }
        let x = [0.3, -1.2, 2.0, 0.7, -0.4, 1.1, -2.5, 3e-4, -2e-4];
        let (mut pf, mut ps) = (vec![Pose::identity(); 9], vec![Pose::identity(); 9]);
        let (ff, fs) = (fast.eval(&x, 0.0, &mut pf), slow.eval(&x, 0.0, &mut ps));
        for (a, b) in pf.iter().zip(&ps).chain([(&ff, &fs)]) {
            assert!((a.rotation.matrix() - b.rotation.matrix()).amax() < 1e-15);
            assert!((a.translation.vector - b.translation.vector).amax() < 1e-15);
        }
    }

    #[test]
    fn constructor_refuses_bad_values_naming_the_field() {
        let e = LinkDeflection::new(vec![[1e-6, 0.0], [0.0, -1e-6]]).unwrap_err();
        assert!(e.to_string().contains("compliance_rad_per_nm[1][1]"), "{e}");
        let e = LinkDeflection::new(vec![[f64::NAN, 0.0]]).unwrap_err();
        assert!(e.to_string().contains("compliance_rad_per_nm[0][0]"), "{e}");
        let e = LinkDeflection::new(vec![[2.5e5, 0.0]]).unwrap_err();
        assert!(e.to_string().contains("not a stiffness"), "{e}");
        assert!(
            LinkDeflection::uniform(3, 1e-6)
                .unwrap()
                .check_fits(7)
                .is_err()
        );
        let d = LinkDeflection::uniform(2, 1e-6).unwrap();
        let s = serde_json::to_string(&d).unwrap();
        assert_eq!(s, r#"{"compliance_rad_per_nm":[[1e-6,1e-6],[1e-6,1e-6]]}"#);
        assert_eq!(serde_json::from_str::<LinkDeflection>(&s).unwrap(), d);
    }

    /// The Newton matrix of the long chain uses `chain_gravity_hessian`: on a chain with hinges (zero
    /// masses on the intermediate frames, hinges at the joint origins) it must be the derivative of
    /// the torques, checked by central differences.
    #[test]
    fn long_chain_hessian_matches_finite_differences() {
        let m = crate::robots::load_builtin("iiwa7").unwrap();
        let d = LinkDeflection::new(vec![
            [2e-6, 3e-6],
            [1e-6, 0.0],
            [0.0, 4e-6],
            [2e-6, 2e-6],
            [1e-6, 1e-6],
            [0.0, 0.0],
            [3e-6, 1e-6],
        ])
        .unwrap();
        let cx = Prepare {
            model: &m,
            growth: None,
            solver: ComplianceSolver::Analytic,
            joint_stiffness: None,
        };
        let stage = d.prepare(&cx).unwrap();
        let mut sc = LinkDeflection::scratch(&stage, 7);
        let real = Chain::grown(&m, None);
        for (i, &e) in stage.joint_index.iter().enumerate() {
            sc.chain.joints[e] = real.joints[i];
        }
        let n = sc.chain.nq();
        assert_eq!(n, 7 + 10);
        let g = Vector3::from(DEFAULT_GRAVITY);
        let pl = Payload {
            mass: 2.0,
            com: [0.01, 0.02, 0.07],
        };
        let mut x: Vec<f64> = (0..n).map(|k| 0.1 * (k as f64 + 1.0).sin()).collect();
        let torques = |x: &[f64], sc: &mut DeflectionScratch| -> Vec<f64> {
            let f = sc.chain.eval(x, 0.0, &mut sc.poses);
            chain_gravity_torques(
                &sc.chain,
                &sc.poses,
                &f,
                &stage.bodies,
                Some(&pl),
                &g,
                &mut sc.work,
            );
            sc.work.tau.clone()
        };
        torques(&x, &mut sc);
        chain_gravity_hessian(&sc.chain, &g, &mut sc.work);
        let hess = sc.work.hess.clone();
        let h = 1e-6;
        for j in 0..n {
            let x0 = x[j];
            x[j] = x0 + h;
            let tp = torques(&x, &mut sc);
            x[j] = x0 - h;
            let tm = torques(&x, &mut sc);
            x[j] = x0;
            for i in 0..n {
                let fd = (tp[i] - tm[i]) / (2.0 * h);
                assert!(
                    (fd - hess[i * n + j]).abs() < 1e-7 * (1.0 + fd.abs()),
                    "H[{i}][{j}]: fd {fd} vs {}",
                    hess[i * n + j]
                );
            }
        }
    }
}
