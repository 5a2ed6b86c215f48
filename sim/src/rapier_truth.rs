//! A physics-engine truth for the compliant arm: the robot as a rapier multibody with joint springs,
//! settled to rest under gravity.
//!
//! # What is simulated
//!
//! [`RapierArm::new`] turns a [`Model`] into a rapier (`rapier3d-f64` 0.36) reduced-coordinates
//! multibody:
//!
//! * the base is a fixed rigid body at the identity (the model's base frame is rapier's world frame);
//! * moving body `i` is one dynamic rigid body whose local frame is joint frame `i` of the model, with
//!   the model's mass, centre of mass and inertia tensor (diagonalised here into principal moments and
//!   a principal-axes rotation, which is what rapier stores); an optional payload point mass at the
//!   flange is merged into the last body (parallel-axis theorem);
//! * joint `i` is a multibody revolute (or prismatic) joint whose free axis is the model's joint axis
//!   through the joint-frame origin: `T_parent_child(θ) = origin · Rot(axis, θ)`, exactly the model's
//!   kinematics (see [`crate::kinematics`]);
//! * with [`RapierArm::with_deflection`], link deflection (see [`crate::effects::link_deflection`]):
//!   after joint `i`, up to two more revolute joints about its deflection axes `uᵢ`, `vᵢ` (through the
//!   joint origin, in joint frame `i`), each with a spring of stiffness `1/c` toward 0; the joint's
//!   body before them and the body between them are massless, the link's mass rides on the last;
//! * joint compliance is rapier's passive joint spring (`MultibodyJoint::set_spring`): a generalised
//!   force `−kᵢ (θᵢ − qᵢ)` toward the motor-side commanded angle `qᵢ`, integrated implicitly (rapier adds
//!   `dt² kᵢ` to the mass-matrix diagonal and `−kᵢ dt θ̇ᵢ` to the force). It is a true stiffness in
//!   N m/rad, not rapier's default acceleration-based motor (whose "stiffness" is scaled by the
//!   effective mass). A joint of infinite stiffness is a kinematic degree of freedom held at `qᵢ`;
//! * joint damping `dᵢ = 2 ζ √(kᵢ Iᵢ)` (N m s/rad) with `Iᵢ = 1/(M⁻¹)ᵢᵢ` the joint's apparent inertia at
//!   the commanded pose (rapier's `dof_inverse_inertia`, all other joints free) and `ζ` =
//!   [`SettleOptions::damping_ratio`];
//! * gravity `g` (base frame, m/s², default (0, 0, −9.81)); no colliders, so no contacts; no joint
//!   limits, friction or armature; bodies never sleep.
//!
//! # Settling
//!
//! [`RapierArm::settle`] starts at rest at `θ = q` (the commanded pose) and steps the engine with a
//! fixed step `dt` until the joints stop: the test is on finite differences of the joint positions,
//! `max |θᵢ(k) − θᵢ(k−1)| / dt <` [`SettleOptions::speed_tol`], and then on the static balance computed
//! from rapier's own kinematics, `max |kᵢ (qᵢ − θᵢ) + fᵢ| <` [`SettleOptions::residual_tol`] with
//! `f = Σₖ Jₖᵀ mₖ g` the generalised gravity force from rapier's centre-of-mass Jacobians. It never
//! stops on a step count: after [`SettleOptions::max_steps`] steps it fails with
//! [`SimError::NotSettled`].
//!
//! At rest (`θ̇ = 0`, `θ̈ = 0`) every step of rapier's integrator leaves the state unchanged exactly when
//! `K (q − θ) = τ_g(θ)` with `τ_g = −f` the holding torque: the rest state is the static equilibrium
//! of [`crate::effects::joint_compliance`], whatever `dt` and the damping. Step size and damping only
//! decide how fast it gets there. With the implicit spring, a step much longer than the arm's natural
//! periods (`dt² kᵢ ≫ Iᵢ`) turns each step into a relaxation `θ ← q − K⁻¹ τ_g(θ)` (backward Euler is
//! L-stable): the transient is then not a physical motion, but the rest state is unchanged. The
//! default step (0.1 s; 10–30 steps per pose on the iiwa 7) is chosen for speed on that basis;
//! `tests/rapier_truth.rs` checks that a physical 1 ms step comes to the same rest. The long step
//! converges while gravity stiffens no joint by more than its spring plus twice its damper's `d/dt`
//! (scalar analysis of the step); joints that soft against the load are reported as not settled, and
//! a smaller `dt` settles them.
//!
//! # In the generator
//!
//! `[truth] model = "rapier"` in a scenario makes [`crate::effects::Truth`] settle its compliance stage
//! with this module, on an arm built from the real geometry of each measurement (see
//! [`crate::effects::rapier_compliance`]).
//!
//! # Units and frames
//!
//! SI throughout: joint positions in rad (m for prismatic joints), stiffness in N m/rad (N/m), masses in
//! kg, poses `T_base_flange` in m. Rapier works in f64 with glam types; conversion to and from nalgebra
//! happens only in this module.
//!
//! ```
//! use nalgebra::Vector3;
//! use sim::rapier_truth::{RapierArm, SettleOptions};
//! let model = sim::robots::load_builtin("iiwa7").unwrap();
//! let arm = RapierArm::new(&model, &[1e4; 7], None, &Vector3::new(0.0, 0.0, -9.81),
//!     SettleOptions::default()).unwrap();
//! let mut ws = arm.workspace();
//! let q = [0.0, 0.8, 0.0, -0.9, 0.0, 0.5, 0.0];
//! let s = arm.settle(&mut ws, &q).unwrap();
//! // The shoulder sags under the arm's weight: joint 2 rotates further than commanded.
//! assert!(s.q_link[1] > q[1]);
//! assert!(s.residual < 1e-6);
//! ```

use crate::error::{Result, SimError};
use crate::lie::{Pose, pose_from};
use crate::model::{JointKind, Model};
pub use crate::springs::SettleOptions;
use crate::springs::{deflection as deflection_compliance, stiffness};
use crate::statics::Payload;
use nalgebra::{Matrix3, Quaternion, Rotation3, UnitQuaternion, Vector3};
use rapier3d_f64::prelude as rp;
use rayon::prelude::*;

/// The engine and version this module is built against (recorded in `truth.json`).
pub const ENGINE: &str = "rapier3d-f64 0.36";

/// Largest accepted sag `|qᵢ − θᵢ|` during settling (rad or m): beyond it the joints are too soft for
/// the load (no equilibrium near the commanded pose) and settling fails.
pub const MAX_DEFLECTION_RAD: f64 = 0.5;

/// The arm at rest after [`RapierArm::settle`].
#[derive(Clone, Debug, PartialEq)]
pub struct Settled {
    /// Link-side joint positions `θ` at rest (rad or m), in the model's joint coordinates.
    pub q_link: Vec<f64>,
    /// Deflection angles `[α, β]` about each joint's `u` and `v` axes at rest (rad; 0 without a hinge,
    /// see [`RapierArm::with_deflection`]).
    pub deflection_rad: Vec<[f64; 2]>,
    /// `T_base_flange` at rest, from rapier's own forward kinematics (m).
    pub flange: Pose,
    /// Engine steps taken.
    pub steps: usize,
    /// Static balance at rest, `max |kᵢ (qᵢ − θᵢ) + fᵢ|` over the compliant joints and hinges (N m or
    /// N; a hinge's `qᵢ` is 0), with `f` the generalised gravity force from rapier's Jacobians.
    pub residual: f64,
    /// Joint speed of the last step, `max |Δθ| / dt` (rad/s or m/s).
    pub speed: f64,
}

/// Mass properties of one rapier body, in its joint frame.
#[derive(Clone, Debug)]
struct BodySpec {
    mass: f64,
    com: Vector3<f64>,
    /// Principal moments about the centre of mass (kg m²).
    principal: Vector3<f64>,
    /// Rotation whose columns are the principal axes (joint-frame coordinates).
    axes: Matrix3<f64>,
}

/// The model prepared for rapier: immutable and shared; each thread settles with its own
/// [`RapierWorkspace`].
///
/// Its degrees of freedom are the model's joints and, with [`RapierArm::with_deflection`], the
/// deflection hinges after them (see [`crate::effects::link_deflection`]): each a multibody joint
/// with one free axis, in chain order, moving one body each (a hinge's parent body and the joint's own
/// body before its hinges are massless).
#[derive(Clone, Debug)]
pub struct RapierArm {
    kinds: Vec<JointKind>,
    /// Stiffness per degree of freedom (N m/rad or N/m; infinite = rigid).
    stiffness: Vec<f64>,
    bodies: Vec<BodySpec>,
    /// `(local_frame1 in the parent body, local_frame2 in the child body)` per degree of freedom; the
    /// free axis is the frames' x axis.
    frames: Vec<(Pose, Pose)>,
    /// Index of each model joint's degree of freedom.
    joint_dof: Vec<usize>,
    /// Indices of each model joint's `u` and `v` hinges (`None`: rigid about that axis).
    hinge_dof: Vec<[Option<usize>; 2]>,
    flange_offset: Pose,
    gravity: Vector3<f64>,
    options: SettleOptions,
}

/// Per-thread rapier world of a [`RapierArm`], made with [`RapierArm::workspace`].
///
/// Settling resets every joint position, velocity, spring and damper, so a result does not depend on
/// what the workspace settled before.
pub struct RapierWorkspace {
    world: rp::PhysicsWorld,
    /// Rigid body of each degree of freedom's child, base to tip.
    links: Vec<rp::RigidBodyHandle>,
    /// Handle of each multibody joint (the child body's handle); all belong to one multibody.
    joints: Vec<rp::MultibodyJointHandle>,
    /// Multibody link id of each moving body.
    link_ids: Vec<usize>,
    /// Generalised-coordinate index (rapier's assembly id) of each degree of freedom.
    dofs: Vec<usize>,
    /// Position of each degree of freedom (rad or m).
    theta: Vec<f64>,
    prev: Vec<f64>,
    /// Spring reference of each degree of freedom: the commanded joint angle, 0 for a hinge.
    anchor: Vec<f64>,
    disp: Vec<f64>,
}

impl std::fmt::Debug for RapierWorkspace {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RapierWorkspace")
            .field("links", &self.links.len())
            .field("dt", &self.world.integration_parameters.dt)
            .finish()
    }
}

// ---------------------------------------------------------------------------------------------------
// nalgebra ↔ glam at the boundary.

fn to_rp_vec(v: &Vector3<f64>) -> rp::Vector {
    rp::Vector::new(v.x, v.y, v.z)
}

fn to_rp_rot(r: &Matrix3<f64>) -> rp::Rotation {
    let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(*r));
    rp::Rotation::from_xyzw(q.i, q.j, q.k, q.w)
}

fn to_rp_pose(p: &Pose) -> rp::Pose {
    rp::Pose::from_parts(
        to_rp_vec(&p.translation.vector),
        to_rp_rot(p.rotation.matrix()),
    )
}

fn from_rp_pose(p: &rp::Pose) -> Pose {
    let q = p.rotation;
    let r = UnitQuaternion::new_unchecked(Quaternion::new(q.w, q.x, q.y, q.z)).to_rotation_matrix();
    let t = p.translation;
    pose_from(*r.matrix(), Vector3::new(t.x, t.y, t.z))
}

/// A rotation whose x axis is the unit vector `a`.
fn frame_with_x_along(a: &Vector3<f64>) -> Matrix3<f64> {
    let x = a.normalize();
    // Seed with the coordinate axis least aligned with x.
    let seed = if x.x.abs() <= x.y.abs() && x.x.abs() <= x.z.abs() {
        Vector3::x()
    } else if x.y.abs() <= x.z.abs() {
        Vector3::y()
    } else {
        Vector3::z()
    };
    let y = (seed - x * x.dot(&seed)).normalize();
    let z = x.cross(&y);
    Matrix3::from_columns(&[x, y, z])
}

/// Mass, centre of mass and inertia about it (joint frame) of `body` plus a point mass.
fn merge_point_mass(
    mass: f64,
    com: &Vector3<f64>,
    inertia: &Matrix3<f64>,
    m_p: f64,
    c_p: &Vector3<f64>,
) -> (f64, Vector3<f64>, Matrix3<f64>) {
    if m_p == 0.0 {
        return (mass, *com, *inertia);
    }
    let m = mass + m_p;
    let c = (com * mass + c_p * m_p) / m;
    // Parallel-axis theorem: I_c = Σ I_own + m (|d|² E − d dᵀ), d = own centre − combined centre.
    let shift = |d: Vector3<f64>, mk: f64| {
        (Matrix3::identity() * d.norm_squared() - d * d.transpose()) * mk
    };
    let i = inertia + shift(com - c, mass) + shift(c_p - c, m_p);
    (m, c, i)
}

/// Principal moments and axes (columns, a proper rotation) of a symmetric inertia tensor.
fn principal_axes(inertia: &Matrix3<f64>) -> (Vector3<f64>, Matrix3<f64>) {
    let sym = (inertia + inertia.transpose()) * 0.5;
    let eig = sym.symmetric_eigen();
    let mut axes = eig.eigenvectors;
    let mut moments = eig.eigenvalues;
    if axes.determinant() < 0.0 {
        axes.swap_columns(1, 2);
        moments.swap_rows(1, 2);
    }
    (moments.map(|v| v.max(0.0)), axes)
}

impl RapierArm {
    /// Prepares `model` for rapier.
    ///
    /// * `stiffness_nm_per_rad`: one per joint (N m/rad; N/m for prismatic joints), > 0, `f64::INFINITY`
    ///   for a rigid joint;
    /// * `payload`: point mass at a point of the flange frame, merged into the last body;
    /// * `gravity`: base frame (m/s²).
    ///
    /// Fails for a stiffness list of the wrong length or with a non-positive entry, a model without
    /// inertials, a bad payload or gravity (non-finite; negative mass) or bad [`SettleOptions`].
    pub fn new(
        model: &Model,
        stiffness_nm_per_rad: &[f64],
        payload: Option<&Payload>,
        gravity: &Vector3<f64>,
        options: SettleOptions,
    ) -> Result<RapierArm> {
        let none = vec![[0.0; 2]; model.nq()];
        RapierArm::with_deflection(
            model,
            stiffness_nm_per_rad,
            &none,
            payload,
            gravity,
            options,
        )
    }

    /// Prepares `model` for rapier as [`RapierArm::new`], with link deflection: after joint `i`, a
    /// hinge about `uᵢ` and one about `vᵢ` (the axes of [`crate::effects::link_deflection`], through
    /// the joint origin, in joint frame `i`) with springs of stiffness `1/cᵢᵤ`, `1/cᵢᵥ` toward zero;
    /// a compliance of 0 leaves that hinge out (rigid). `deflection_rad_per_nm` has one `[cᵤ, cᵥ]`
    /// per joint (rad/(N m), finite, ≥ 0). The joint's body before its hinges and the body between the
    /// hinges are massless; the link's mass rides on the last.
    pub fn with_deflection(
        model: &Model,
        stiffness_nm_per_rad: &[f64],
        deflection_rad_per_nm: &[[f64; 2]],
        payload: Option<&Payload>,
        gravity: &Vector3<f64>,
        options: SettleOptions,
    ) -> Result<RapierArm> {
        let n = model.nq();
        stiffness::check_values(stiffness_nm_per_rad)?;
        stiffness::check_len(stiffness_nm_per_rad, n)?;
        deflection_compliance::check_values(deflection_rad_per_nm)?;
        deflection_compliance::check_len(deflection_rad_per_nm, n)?;
        model.require_inertials()?;
        options.check()?;
        let cond = |field: String, value: String, problem: &str| SimError::BadCondition {
            field,
            value,
            problem: problem.into(),
        };
        if let Some((k, v)) = gravity.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(cond(format!("gravity[{k}]"), v.to_string(), "not finite"));
        }
        if let Some(pl) = payload {
            if !(pl.mass.is_finite() && pl.mass >= 0.0) {
                return Err(cond(
                    "payload.mass".into(),
                    pl.mass.to_string(),
                    "must be finite and ≥ 0 kg",
                ));
            }
            if let Some((k, v)) = pl.com.iter().enumerate().find(|(_, v)| !v.is_finite()) {
                return Err(cond(
                    format!("payload.com[{k}]"),
                    v.to_string(),
                    "not finite",
                ));
            }
        }
        let massless = BodySpec {
            mass: 0.0,
            com: Vector3::zeros(),
            principal: Vector3::zeros(),
            axes: Matrix3::identity(),
        };
        let mut arm = RapierArm {
            kinds: Vec::new(),
            stiffness: Vec::new(),
            bodies: Vec::new(),
            frames: Vec::new(),
            joint_dof: Vec::with_capacity(n),
            hinge_dof: Vec::with_capacity(n),
            flange_offset: model.flange_offset(),
            gravity: *gravity,
            options,
        };
        for (i, (b, j)) in model.bodies().iter().zip(model.joints()).enumerate() {
            let (mut mass, mut com, mut inertia) = (b.mass, b.com, b.inertia);
            if i + 1 == n
                && let Some(pl) = payload
            {
                let c_p = model.flange_offset() * nalgebra::Point3::from(Vector3::from(pl.com));
                (mass, com, inertia) = merge_point_mass(mass, &com, &inertia, pl.mass, &c_p.coords);
            }
            let (principal, axes) = principal_axes(&inertia);
            let f2 = pose_from(frame_with_x_along(&j.axis), Vector3::zeros());
            arm.joint_dof.push(arm.kinds.len());
            arm.kinds.push(j.kind);
            arm.stiffness.push(stiffness_nm_per_rad[i]);
            arm.frames.push((j.origin * f2, f2));
            arm.bodies.push(massless.clone());
            let (u, v) = deflection_compliance::deflection_axes(&j.axis);
            let mut hinges = [None; 2];
            for ((axis, &c), h) in [u, v]
                .iter()
                .zip(&deflection_rad_per_nm[i])
                .zip(&mut hinges)
            {
                if c > 0.0 {
                    let f = pose_from(frame_with_x_along(axis), Vector3::zeros());
                    *h = Some(arm.kinds.len());
                    arm.kinds.push(JointKind::Revolute);
                    arm.stiffness.push(1.0 / c);
                    arm.frames.push((f, f));
                    arm.bodies.push(massless.clone());
                }
            }
            arm.hinge_dof.push(hinges);
            *arm.bodies.last_mut().expect("a body per degree of freedom") = BodySpec {
                mass,
                com,
                principal,
                axes,
            };
        }
        Ok(arm)
    }

    /// Number of joints.
    pub fn nq(&self) -> usize {
        self.joint_dof.len()
    }

    /// Number of degrees of freedom: joints and deflection hinges.
    fn ndof(&self) -> usize {
        self.kinds.len()
    }

    /// The settle options in use.
    pub fn options(&self) -> &SettleOptions {
        &self.options
    }

    /// Spatial axis index (rapier's 6-DoF layout: 0..3 linear, 3..6 angular) of joint `i`'s free DoF.
    fn axis(&self, i: usize) -> usize {
        if self.kinds[i].is_rotational() { 3 } else { 0 }
    }

    /// Builds the rapier world for this arm (one per thread).
    pub fn workspace(&self) -> RapierWorkspace {
        let mut world = rp::PhysicsWorld::new();
        world.gravity = to_rp_vec(&self.gravity);
        world.integration_parameters.dt = self.options.dt;
        world.integration_parameters.num_solver_iterations = 1;
        world.integration_parameters.num_internal_pgs_iterations = 1;
        world.integration_parameters.max_ccd_substeps = 0;
        world.integration_parameters.normalized_max_linear_velocity = f64::MAX;
        let base = world.insert_body(rp::RigidBodyBuilder::fixed().can_sleep(false));
        let mut parent = base;
        let mut links = Vec::with_capacity(self.ndof());
        let mut joints = Vec::with_capacity(self.ndof());
        for (i, b) in self.bodies.iter().enumerate() {
            let mp = rp::MassProperties::with_principal_inertia_frame(
                to_rp_vec(&b.com),
                b.mass,
                to_rp_vec(&b.principal),
                to_rp_rot(&b.axes),
            );
            let body = world.insert_body(
                rp::RigidBodyBuilder::dynamic()
                    .additional_mass_properties(mp)
                    .can_sleep(false),
            );
            let locked = if self.kinds[i].is_rotational() {
                rp::JointAxesMask::LOCKED_REVOLUTE_AXES
            } else {
                rp::JointAxesMask::LOCKED_PRISMATIC_AXES
            };
            let (f1, f2) = &self.frames[i];
            let data = rp::GenericJointBuilder::new(locked)
                .local_frame1(to_rp_pose(f1))
                .local_frame2(to_rp_pose(f2))
                .build();
            let rigid = self.stiffness[i] == f64::INFINITY;
            let handle = if rigid {
                world
                    .multibody_joints
                    .insert_kinematic(parent, body, data, true)
            } else {
                world.multibody_joints.insert(parent, body, data, true)
            }
            .expect("a serial chain never closes a loop");
            links.push(body);
            joints.push(handle);
            parent = body;
        }
        // A zero-length step applies the insertions (mass properties, multibody assembly) without
        // moving anything.
        let dt = world.integration_parameters.dt;
        world.integration_parameters.dt = 0.0;
        world.step();
        world.integration_parameters.dt = dt;
        let n = self.ndof();
        let (mb, _) = world.multibody_joints.get(joints[0]).expect("joint");
        let link_ids: Vec<usize> = joints
            .iter()
            .map(|h| world.multibody_joints.get(*h).expect("joint").1)
            .collect();
        let dofs = link_ids
            .iter()
            .map(|&id| mb.link(id).expect("link").assembly_id())
            .collect();
        RapierWorkspace {
            world,
            links,
            joints,
            link_ids,
            dofs,
            theta: vec![0.0; n],
            prev: vec![0.0; n],
            anchor: vec![0.0; n],
            disp: vec![0.0; n],
        }
    }

    /// Reads the positions of every degree of freedom into `out`.
    fn read_theta(&self, ws: &RapierWorkspace, out: &mut [f64]) {
        let (mb, _) = ws.world.multibody_joints.get(ws.joints[0]).expect("joint");
        for (i, (&id, o)) in ws.link_ids.iter().zip(out).enumerate() {
            *o = mb.link(id).expect("link").joint().coords()[self.axis(i)];
        }
    }

    /// Settles the arm commanded to `q_cmd` (motor side, rad or m) from rest at `θ = q_cmd`; see the
    /// module docs for the rest test. Fails for a bad `q_cmd` (length, non-finite) and when the arm does
    /// not come to rest ([`SimError::NotSettled`]).
    pub fn settle(&self, ws: &mut RapierWorkspace, q_cmd: &[f64]) -> Result<Settled> {
        let n = self.nq();
        if q_cmd.len() != n {
            return Err(SimError::JointCount {
                expected: n,
                got: q_cmd.len(),
            });
        }
        if let Some((i, v)) = q_cmd.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(SimError::NonFiniteJoint {
                joint: i + 1,
                value: *v,
            });
        }
        ws.anchor.fill(0.0);
        for (&d, &q) in self.joint_dof.iter().zip(q_cmd) {
            ws.anchor[d] = q;
        }
        self.reset(ws);
        let dt = self.options.dt;
        let mut speed = f64::INFINITY;
        ws.prev.copy_from_slice(&ws.anchor);
        for step in 1..=self.options.max_steps {
            ws.world.step();
            let mut theta = std::mem::take(&mut ws.theta);
            self.read_theta(ws, &mut theta);
            ws.theta = theta;
            let mut dmax = 0.0f64;
            for (d, ((th, prev), q)) in ws.theta.iter().zip(&ws.prev).zip(&ws.anchor).enumerate() {
                dmax = dmax.max((th - prev).abs());
                let sag = (th - q).abs();
                if !sag.is_finite() || sag > MAX_DEFLECTION_RAD {
                    return Err(SimError::NotSettled {
                        reason: format!(
                            "{} sags {sag:.3e} (> {MAX_DEFLECTION_RAD}) at step {step}: stiffness too low for the load",
                            self.dof_name(d)
                        ),
                    });
                }
            }
            speed = dmax / dt;
            ws.prev.copy_from_slice(&ws.theta);
            if speed < self.options.speed_tol {
                let residual = self.residual(ws);
                if residual < self.options.residual_tol {
                    let last = ws.world.bodies[*ws.links.last().expect("links")].position();
                    let at = |d: Option<usize>| d.map_or(0.0, |d| ws.theta[d]);
                    return Ok(Settled {
                        q_link: self.joint_dof.iter().map(|&d| ws.theta[d]).collect(),
                        deflection_rad: self
                            .hinge_dof
                            .iter()
                            .map(|[u, v]| [at(*u), at(*v)])
                            .collect(),
                        flange: from_rp_pose(last) * self.flange_offset,
                        steps: step,
                        residual,
                        speed,
                    });
                }
            }
        }
        let residual = self.residual(ws);
        Err(SimError::NotSettled {
            reason: format!(
                "{} steps of {} s: joint speed {speed:.3e} rad/s (tolerance {:e}), torque residual {residual:.3e} N m (tolerance {:e})",
                self.options.max_steps, dt, self.options.speed_tol, self.options.residual_tol
            ),
        })
    }

    /// `joint 3` or `joint 3's u hinge` for degree of freedom `d` (1-based joints), for errors.
    fn dof_name(&self, d: usize) -> String {
        if let Some(i) = self.joint_dof.iter().position(|&j| j == d) {
            return format!("joint {}", i + 1);
        }
        for (i, h) in self.hinge_dof.iter().enumerate() {
            if let Some(k) = h.iter().position(|&x| x == Some(d)) {
                return format!("joint {}'s {} hinge", i + 1, ["u", "v"][k]);
            }
        }
        format!("degree of freedom {d}")
    }

    /// Puts the arm at rest at its anchors (`ws.anchor`: the commanded joint angles, 0 for the
    /// hinges), springs toward them, dampers sized there.
    fn reset(&self, ws: &mut RapierWorkspace) {
        let q = &ws.anchor;
        let rp::PhysicsWorld {
            bodies,
            multibody_joints,
            ..
        } = &mut ws.world;
        // Joint positions: coords + (−coords) is exactly 0, and 0 + q is exactly q.
        let (mb, _) = multibody_joints.get_mut(ws.joints[0]).expect("joint");
        for (i, (&id, &a)) in ws.link_ids.iter().zip(&ws.dofs).enumerate() {
            ws.disp[a] = -mb.link(id).expect("link").joint().coords()[self.axis(i)];
        }
        mb.apply_displacements(&ws.disp);
        for (i, (&id, &a)) in ws.link_ids.iter().zip(&ws.dofs).enumerate() {
            ws.disp[a] = q[i];
            if self.stiffness[i].is_finite() {
                let link = mb.link_mut(id).expect("link");
                link.joint.set_spring(self.axis(i), self.stiffness[i], q[i]);
            }
        }
        mb.apply_displacements(&ws.disp);
        mb.generalized_velocity_mut().fill(0.0);
        mb.forward_kinematics(bodies, false);
        mb.update_rigid_bodies(bodies, true);
        let inv_inertia = mb.dof_inverse_inertia(bodies);
        for (&a, &k) in ws.dofs.iter().zip(&self.stiffness) {
            mb.damping_mut()[a] = if k.is_finite() && inv_inertia[a] > 0.0 {
                2.0 * self.options.damping_ratio * (k / inv_inertia[a]).sqrt()
            } else {
                0.0
            };
        }
        for h in &ws.links {
            let rb = &mut bodies[*h];
            rb.set_linvel(rp::Vector::ZERO, false);
            rb.set_angvel(rp::Vector::ZERO, false);
        }
    }

    /// `max |kᵢ (qᵢ − θᵢ) + fᵢ|` over the compliant degrees of freedom (`qᵢ` their anchors), with
    /// `f = Σₖ Jₖᵀ (mₖ g)` from rapier's centre-of-mass Jacobians at the current pose (N m or N).
    fn residual(&self, ws: &RapierWorkspace) -> f64 {
        let q = &ws.anchor;
        let (mb, _) = ws.world.multibody_joints.get(ws.joints[0]).expect("joint");
        let g = self.gravity;
        let mut worst = 0.0f64;
        for (i, &a) in ws.dofs.iter().enumerate() {
            if !self.stiffness[i].is_finite() {
                continue;
            }
            let mut f = 0.0;
            for (&id, body) in ws.link_ids.iter().zip(&self.bodies) {
                let jac = mb.body_jacobian(id);
                f += body.mass * (jac[(0, a)] * g.x + jac[(1, a)] * g.y + jac[(2, a)] * g.z);
            }
            worst = worst.max((self.stiffness[i] * (q[i] - ws.theta[i]) + f).abs());
        }
        worst
    }
}

impl RapierArm {
    /// Settles the arm at every commanded pose of `q_cmds` (rad or m per joint), in parallel (rayon, one
    /// [`RapierWorkspace`] per worker). Results are in the order of `q_cmds` and bit-identical whatever
    /// the number of threads (a settle does not depend on what its workspace did before). Fails on the
    /// lowest-index pose that fails, naming it (`q_cmds[k]`, 0-based).
    pub fn settle_all<Q: AsRef<[f64]> + Sync>(&self, q_cmds: &[Q]) -> Result<Vec<Settled>> {
        let results: Vec<Result<Settled>> = q_cmds
            .par_iter()
            .map_init(|| self.workspace(), |ws, q| self.settle(ws, q.as_ref()))
            .collect();
        let mut out = Vec::with_capacity(results.len());
        for (k, r) in results.into_iter().enumerate() {
            let pose_err = |field: String, value: String, problem: String| SimError::BadCondition {
                field,
                value,
                problem,
            };
            match r {
                Ok(s) => out.push(s),
                Err(SimError::NotSettled { reason }) => {
                    return Err(SimError::NotSettled {
                        reason: format!("q_cmds[{k}]: {reason}"),
                    });
                }
                Err(SimError::JointCount { expected, got }) => {
                    return Err(pose_err(
                        format!("q_cmds[{k}]"),
                        format!("{got} values"),
                        format!("the robot has {expected} joints"),
                    ));
                }
                Err(SimError::NonFiniteJoint { joint, value }) => {
                    return Err(pose_err(
                        format!("q_cmds[{k}][{}]", joint - 1),
                        value.to_string(),
                        "not finite".into(),
                    ));
                }
                Err(e) => return Err(e),
            }
        }
        Ok(out)
    }
}

/// One-call physics-engine truth: prepares `model` with joint stiffness `stiffness_nm_per_rad`
/// (N m/rad, `inf` = rigid), `payload` at the flange and `gravity` (base frame, m/s²) — see
/// [`RapierArm::new`] — and settles it at every commanded pose of `q_cmds` (see
/// [`RapierArm::settle_all`]).
pub fn settle_many<Q: AsRef<[f64]> + Sync>(
    model: &Model,
    stiffness_nm_per_rad: &[f64],
    payload: Option<&Payload>,
    gravity: &Vector3<f64>,
    options: SettleOptions,
    q_cmds: &[Q],
) -> Result<Vec<Settled>> {
    RapierArm::new(model, stiffness_nm_per_rad, payload, gravity, options)?.settle_all(q_cmds)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn point_mass_merge_matches_hand_parallel_axis_values() {
        // 2 kg at the origin with I = diag(1, 2, 3), plus 1 kg at x = 0.3: combined centre x = 0.1;
        // the body moves 0.1 and the point 0.2 off it, so I_yy = 2 + 2·0.01 + 1·0.04, same on zz.
        let (m, c, i) = merge_point_mass(
            2.0,
            &Vector3::zeros(),
            &Matrix3::from_diagonal(&Vector3::new(1.0, 2.0, 3.0)),
            1.0,
            &Vector3::new(0.3, 0.0, 0.0),
        );
        assert_eq!(m, 3.0);
        assert!((c - Vector3::new(0.1, 0.0, 0.0)).amax() < 1e-16);
        let expect = Matrix3::from_diagonal(&Vector3::new(1.0, 2.06, 3.06));
        assert!((i - expect).amax() < 1e-15, "{i}");
    }

    #[test]
    fn rapier_mass_properties_rebuild_every_iiwa_inertia_tensor() {
        let model = crate::robots::load_builtin("iiwa7").unwrap();
        for b in model.bodies() {
            let (principal, axes) = principal_axes(&b.inertia);
            assert!((axes.determinant() - 1.0).abs() < 1e-14);
            let mp = rp::MassProperties::with_principal_inertia_frame(
                to_rp_vec(&b.com),
                b.mass,
                to_rp_vec(&principal),
                to_rp_rot(&axes),
            );
            let r = mp.reconstruct_inertia_matrix();
            let rebuilt = Matrix3::from_column_slice(&r.to_cols_array());
            assert!(
                (rebuilt - b.inertia).amax() < 1e-15 * (1.0 + b.inertia.amax()) * 10.0,
                "{:?}: {}",
                b.links,
                (rebuilt - b.inertia).amax()
            );
            assert!((mp.mass() - b.mass).abs() < 1e-15 * b.mass);
        }
    }

    #[test]
    fn frames_and_pose_conversions_are_exact_rotations() {
        for a in [
            Vector3::new(0.0, 0.0, 1.0),
            Vector3::new(0.0, -1.0, 0.0),
            Vector3::new(0.3, -0.4, 0.5).normalize(),
        ] {
            let r = frame_with_x_along(&a);
            assert!((r.column(0) - a).amax() < 1e-15);
            assert!((r.transpose() * r - Matrix3::identity()).amax() < 1e-15);
            assert!((r.determinant() - 1.0).abs() < 1e-15);
        }
        let p = crate::lie::exp_twist(&nalgebra::Vector6::new(0.4, -1.1, 2.0, 0.3, -0.2, 0.9));
        let back = from_rp_pose(&to_rp_pose(&p));
        assert!((back.rotation.matrix() - p.rotation.matrix()).amax() < 1e-15);
        assert!((back.translation.vector - p.translation.vector).amax() < 1e-16);
    }
}
