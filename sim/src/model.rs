//! The immutable robot model: a serial chain in product-of-exponentials form, with inertials.
//!
//! Frames: `base` is the chain's root link frame. Joint frame `i` is the child-link frame of joint `i`
//! (it moves with joint `i`); the joint axis passes through its origin. `flange` is the tip link frame.
//! At q = 0 every joint frame sits at its home pose `T_base_joint_home`.

use crate::branches::Branches;
use crate::coupled_joints::{CoupledJoint, CouplingDecl, Couplings};
pub use crate::joint_kind::{JointKind, JointLimits};
use crate::lie::Pose;
use nalgebra::{Matrix3, Vector3, Vector6};

/// One movable joint of the chain.
#[derive(Clone, Debug)]
pub struct Joint {
    /// URDF joint name.
    pub name: String,
    /// Revolute, continuous or prismatic.
    pub kind: JointKind,
    /// `T_parent_joint`: joint frame in the previous joint frame (or the base for joint 1) at q = 0,
    /// with every fixed joint in between folded in (m).
    pub origin: Pose,
    /// Unit axis in the joint frame.
    pub axis: Vector3<f64>,
    /// `T_base_joint` at q = 0 (m).
    pub home: Pose,
    /// Screw axis `[ω; v]` in the base frame at q = 0: for revolute joints `ω` is the unit axis and
    /// `v = -ω × p` for a point `p` on the axis (m); for prismatic joints `ω = 0` and `v` is the unit axis.
    pub screw: Vector6<f64>,
    /// Position limits, or `None` for continuous joints and joints without usable limits.
    pub limits: Option<JointLimits>,
    /// `[C, A - C, B]` with `A = R_o`, `B = R_o [a]`, `C = R_o a aᵀ` (`R_o` the origin rotation, `a` the
    /// axis), so that the joint's local rotation is `C + cos q (A - C) + sin q B` (Rodrigues, folded).
    pub rotation_terms: [Matrix3<f64>; 3],
    /// `Some((k, sign))` when the origin rotation is exactly the identity and the axis is exactly
    /// `sign · e_k` (k = 0, 1, 2 for x, y, z), as in most URDFs: forward kinematics then turns two
    /// columns instead of multiplying 3×3 matrices. Derived from `origin.rotation` and `axis` like
    /// [`Joint::rotation_terms`]; [`Model::new`] computes both (and `home`, `screw`) for every joint
    /// of a model, so a joint inside a [`Model`] never holds stale ones.
    pub aligned_axis: Option<(usize, f64)>,
}

impl Joint {
    /// A joint with its rotation terms and aligned axis computed from `origin` and the unit `axis`;
    /// `home` and `screw` (which depend on the joints before it) are the identity and zero until
    /// [`Model::new`] places the joint in a chain.
    pub fn new(
        name: String,
        kind: JointKind,
        origin: Pose,
        axis: Vector3<f64>,
        limits: Option<JointLimits>,
    ) -> Joint {
        Joint {
            name,
            kind,
            origin,
            axis,
            home: Pose::identity(),
            screw: Vector6::zeros(),
            limits,
            rotation_terms: Joint::rotation_terms_for(&origin, &axis),
            aligned_axis: Joint::aligned_axis_for(&origin, &axis),
        }
    }

    /// See [`Joint::aligned_axis`].
    pub fn aligned_axis_for(origin: &Pose, axis: &Vector3<f64>) -> Option<(usize, f64)> {
        if *origin.rotation.matrix() != Matrix3::identity() {
            return None;
        }
        (0..3).find_map(|k| {
            let mut unit = Vector3::zeros();
            unit[k] = 1.0;
            if *axis == unit {
                Some((k, 1.0))
            } else if *axis == -unit {
                Some((k, -1.0))
            } else {
                None
            }
        })
    }

    /// Precomputes [`Joint::rotation_terms`] from the origin and unit axis.
    pub fn rotation_terms_for(origin: &Pose, axis: &Vector3<f64>) -> [Matrix3<f64>; 3] {
        let a = origin.rotation.matrix();
        let b = a * crate::lie::skew(axis);
        let c = a * (axis * axis.transpose());
        [c, a - c, b]
    }
}

/// Mass properties of the rigid body moved by one joint (its child link with every link fixed to it).
#[derive(Clone, Debug, PartialEq)]
pub struct Body {
    /// Mass (kg).
    pub mass: f64,
    /// Centre of mass in the joint frame (m).
    pub com: Vector3<f64>,
    /// Inertia tensor about the centre of mass, axes of the joint frame (kg m²).
    pub inertia: Matrix3<f64>,
    /// URDF links merged into this body.
    pub links: Vec<String>,
}

/// An immutable serial-chain robot model.
///
/// Built once (from a URDF, see [`crate::urdf`], or from its parts with [`Model::new`]) and shared
/// by reference; evaluations write into a [`crate::Data`]. Its fields are private: [`Model::new`]
/// computes every derived quantity (each joint's home pose, screw axis, rotation terms and aligned
/// axis, the home flange pose, the massless links) from the parts, and the mutators
/// ([`Model::with_joint_origin`], [`Model::with_flange_offset`]) make a new model the same way, so
/// that no derived quantity can go stale.
#[derive(Clone, Debug)]
pub struct Model {
    name: String,
    base_link: String,
    tip_link: String,
    joints: Vec<Joint>,
    bodies: Vec<Body>,
    flange_offset: Pose,
    home_flange: Pose,
    massless_links: Vec<String>,
    notes: Vec<String>,
    couplings: Couplings,
    branches: Branches,
}

/// What a [`Model`] is made of: everything [`Model::new`] does not derive.
#[derive(Clone, Debug)]
pub struct ModelParts {
    /// Robot name.
    pub name: String,
    /// Root link of the chain (the base frame).
    pub base_link: String,
    /// Tip link of the chain (the flange frame).
    pub tip_link: String,
    /// Movable joints from base to tip. Their `name`, `kind`, `origin`, `axis` (unit) and `limits`
    /// are used; `home`, `screw`, `rotation_terms` and `aligned_axis` are recomputed.
    pub joints: Vec<Joint>,
    /// One body per joint: `bodies[i]` moves with `joints[i]`.
    pub bodies: Vec<Body>,
    /// `T_last_flange`: flange in the last joint frame (m).
    pub flange_offset: Pose,
    /// Things the loader tolerated but a user should know (e.g. off-chain movable joints ignored).
    pub notes: Vec<String>,
    /// Coupled (passive) joints of the chain ([`crate::coupled_joints`]); empty for a chain whose
    /// every joint is driven.
    pub couplings: Vec<CoupledJoint>,
    /// Movable joints of branches off the chain ([`crate::branches`]): their masses are in
    /// `bodies` at zero, and move with the joints' values from a measurement table.
    pub branches: Branches,
}

impl Model {
    /// A model from its parts, with every derived quantity computed: joint `i`'s home pose
    /// `T_base_joint = O₁ ⋯ Oᵢ` and screw axis ([`Joint::screw`]), its rotation terms and aligned axis
    /// ([`Joint::rotation_terms`], [`Joint::aligned_axis`]), the home flange pose `M = T_base_joint_n
    /// T_last_flange`, and the massless links (the first link of each body of zero mass).
    ///
    /// # Errors
    /// [`crate::SimError::Structure`] for a chain without joints or a body count that is not the
    /// joint count; [`crate::SimError::BadValue`] for a non-finite origin or axis, or an axis that is
    /// not of unit length.
    pub fn new(parts: ModelParts) -> crate::error::Result<Model> {
        let ModelParts {
            name,
            base_link,
            tip_link,
            mut joints,
            bodies,
            flange_offset,
            notes,
            couplings,
            branches,
        } = parts;
        let structure = |message: String| crate::error::SimError::Structure {
            source_name: name.clone(),
            message,
        };
        if joints.is_empty() {
            return Err(structure(format!(
                "no movable joint between base link '{base_link}' and tip link '{tip_link}'"
            )));
        }
        if bodies.len() != joints.len() {
            return Err(structure(format!(
                "{} bodies for {} joints: one body per joint is needed",
                bodies.len(),
                joints.len()
            )));
        }
        for j in &joints {
            let bad = |field: &'static str, value: f64, problem: &'static str| {
                crate::error::SimError::BadValue {
                    source_name: name.clone(),
                    element: "joint",
                    name: j.name.clone(),
                    field,
                    value,
                    problem,
                }
            };
            let o = j.origin.to_homogeneous();
            if let Some(v) = o.iter().find(|v| !v.is_finite()) {
                return Err(bad("origin", *v, "not finite"));
            }
            if let Some(v) = j.axis.iter().find(|v| !v.is_finite()) {
                return Err(bad("axis xyz", *v, "not finite"));
            }
            if (j.axis.norm() - 1.0).abs() > 1e-9 {
                return Err(bad("axis xyz", j.axis.norm(), "not of unit length"));
            }
        }
        let mut home = Pose::identity();
        for j in &mut joints {
            home *= j.origin;
            j.home = home;
            let w = home.rotation * j.axis;
            let p = home.translation.vector;
            j.screw = if j.kind.is_rotational() {
                let v = -w.cross(&p);
                Vector6::new(w.x, w.y, w.z, v.x, v.y, v.z)
            } else {
                Vector6::new(0.0, 0.0, 0.0, w.x, w.y, w.z)
            };
            j.rotation_terms = Joint::rotation_terms_for(&j.origin, &j.axis);
            j.aligned_axis = Joint::aligned_axis_for(&j.origin, &j.axis);
        }
        let couplings =
            Couplings::new(couplings, joints.len(), &|i| joints[i].name.clone(), &name)?;
        let home_flange = home * flange_offset;
        let massless_links = bodies
            .iter()
            .filter(|b| b.mass <= 0.0)
            .map(|b| b.links.first().cloned().unwrap_or_default())
            .collect();
        Ok(Model {
            name,
            base_link,
            tip_link,
            joints,
            bodies,
            flange_offset,
            home_flange,
            massless_links,
            notes,
            couplings,
            branches,
        })
    }

    /// The parts of this model (to change some and make a new one with [`Model::new`]).
    pub fn to_parts(&self) -> ModelParts {
        ModelParts {
            name: self.name.clone(),
            base_link: self.base_link.clone(),
            tip_link: self.tip_link.clone(),
            joints: self.joints.clone(),
            bodies: self.bodies.clone(),
            flange_offset: self.flange_offset,
            notes: self.notes.clone(),
            couplings: self.couplings.list().to_vec(),
            branches: self.branches.clone(),
        }
    }

    /// This model with the couplings `decls` (by joint name) added to its own ([`Model::new`]).
    ///
    /// # Errors
    /// A name that is not a movable joint of the chain, a joint coupled twice, what
    /// [`Couplings::new`] refuses.
    pub fn with_couplings(&self, decls: &[CouplingDecl]) -> crate::error::Result<Model> {
        let mut parts = self.to_parts();
        parts.couplings.extend(Couplings::resolve(
            decls,
            &self.joint_names(),
            false,
            &self.name,
        )?);
        Model::new(parts)
    }

    /// Movable joints of branches off the chain whose masses load it ([`crate::branches`]).
    pub fn branches(&self) -> &Branches {
        &self.branches
    }

    /// The coupled joints of the chain and its driven joints ([`crate::coupled_joints`]).
    pub fn couplings(&self) -> &Couplings {
        &self.couplings
    }

    /// Number of driven joints: the joint columns `q1 … qD` of a measurement table (the chain's
    /// joints less its coupled ones).
    pub fn n_drives(&self) -> usize {
        self.couplings.n_drives()
    }

    /// This model with joint `i`'s (0-based) origin `T_parent_joint` replaced by `origin` (m), every
    /// derived quantity recomputed ([`Model::new`]).
    ///
    /// # Errors
    /// [`crate::SimError::JointCount`] for `i` beyond the joints; what [`Model::new`] refuses.
    pub fn with_joint_origin(&self, i: usize, origin: Pose) -> crate::error::Result<Model> {
        if i >= self.nq() {
            return Err(crate::error::SimError::JointCount {
                expected: self.nq(),
                got: i + 1,
            });
        }
        let mut parts = self.to_parts();
        parts.joints[i].origin = origin;
        Model::new(parts)
    }

    /// This model with the flange offset `T_last_flange` replaced by `flange_offset` (m), the home
    /// flange pose recomputed.
    ///
    /// # Errors
    /// What [`Model::new`] refuses.
    pub fn with_flange_offset(&self, flange_offset: Pose) -> crate::error::Result<Model> {
        let mut parts = self.to_parts();
        parts.flange_offset = flange_offset;
        Model::new(parts)
    }

    /// Robot name from the URDF.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Root link of the chain (the base frame).
    pub fn base_link(&self) -> &str {
        &self.base_link
    }

    /// Tip link of the chain (the flange frame).
    pub fn tip_link(&self) -> &str {
        &self.tip_link
    }

    /// Movable joints from base to tip.
    pub fn joints(&self) -> &[Joint] {
        &self.joints
    }

    /// Names of the movable joints, base to tip.
    pub fn joint_names(&self) -> Vec<&str> {
        self.joints.iter().map(|j| j.name.as_str()).collect()
    }

    /// One body per joint: `bodies()[i]` moves with `joints()[i]`.
    pub fn bodies(&self) -> &[Body] {
        &self.bodies
    }

    /// `T_last_flange`: flange in the last joint frame (m).
    pub fn flange_offset(&self) -> Pose {
        self.flange_offset
    }

    /// `M = T_base_flange` at q = 0 (m).
    pub fn home_flange(&self) -> Pose {
        self.home_flange
    }

    /// Links of moving bodies that carry no mass (no `<inertial>`); statics refuse to run while
    /// non-empty.
    pub fn massless_links(&self) -> &[String] {
        &self.massless_links
    }

    /// Things the loader tolerated but a user should know (e.g. off-chain movable joints ignored).
    pub fn notes(&self) -> &[String] {
        &self.notes
    }

    /// Number of movable joints.
    #[inline]
    pub fn nq(&self) -> usize {
        self.joints.len()
    }

    /// Total mass of the moving bodies (kg).
    pub fn moving_mass(&self) -> f64 {
        self.bodies.iter().map(|b| b.mass).sum()
    }

    /// Fails with [`crate::error::SimError::MissingInertial`] if some moving body has no mass.
    pub fn require_inertials(&self) -> crate::error::Result<()> {
        if self.massless_links.is_empty() {
            Ok(())
        } else {
            Err(crate::error::SimError::MissingInertial {
                robot: self.name.clone(),
                links: self.massless_links.join(", "),
            })
        }
    }

    /// Checks the length and finiteness of a joint vector.
    pub fn check_q(&self, q: &[f64]) -> crate::error::Result<()> {
        if q.len() != self.nq() {
            return Err(crate::error::SimError::JointCount {
                expected: self.nq(),
                got: q.len(),
            });
        }
        if let Some((i, v)) = q.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(crate::error::SimError::NonFiniteJoint {
                joint: i + 1,
                value: *v,
            });
        }
        Ok(())
    }

    /// Screw axes of all joints in the base frame at q = 0 (`[ω; v]`, see [`Joint::screw`]).
    pub fn screws(&self) -> Vec<Vector6<f64>> {
        self.joints.iter().map(|j| j.screw).collect()
    }
}
