//! The immutable robot model: a serial chain in product-of-exponentials form, with inertials.
//!
//! Frames: `base` is the chain's root link frame. Joint frame `i` is the child-link frame of joint `i`
//! (it moves with joint `i`); the joint axis passes through its origin. `flange` is the tip link frame.
//! At q = 0 every joint frame sits at its home pose `T_base_joint_home`.

use crate::lie::Pose;
use nalgebra::{Matrix3, Vector3, Vector6};

/// Kind of a movable joint.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum JointKind {
    /// Rotation about the axis within limits; `q` in rad.
    Revolute,
    /// Rotation about the axis without limits; `q` in rad.
    Continuous,
    /// Translation along the axis; `q` in m.
    Prismatic,
}

impl JointKind {
    /// True for revolute and continuous joints.
    pub fn is_rotational(self) -> bool {
        !matches!(self, JointKind::Prismatic)
    }
    /// Unit of `q` for this joint: `rad` or `m`.
    pub fn unit(self) -> &'static str {
        if self.is_rotational() { "rad" } else { "m" }
    }
}

/// Position and effort limits of one joint from the URDF.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct JointLimits {
    /// Lower position limit (rad or m).
    pub lower: f64,
    /// Upper position limit (rad or m).
    pub upper: f64,
    /// Velocity limit (rad/s or m/s); 0 when the URDF gives none.
    pub velocity: f64,
    /// Effort limit (N m or N); 0 when the URDF gives none.
    pub effort: f64,
}

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
    /// [`Joint::rotation_terms`]; recompute both with [`Joint::refresh_derived`] after changing them.
    pub aligned_axis: Option<(usize, f64)>,
}

impl Joint {
    /// Recomputes [`Joint::rotation_terms`] and [`Joint::aligned_axis`] from `origin` and `axis`.
    pub fn refresh_derived(&mut self) {
        self.rotation_terms = Joint::rotation_terms_for(&self.origin, &self.axis);
        self.aligned_axis = Joint::aligned_axis_for(&self.origin, &self.axis);
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
/// Built once (from a URDF, see [`crate::urdf`]) and shared by reference; evaluations write into a
/// [`crate::Data`].
#[derive(Clone, Debug)]
pub struct Model {
    /// Robot name from the URDF.
    pub name: String,
    /// Root link of the chain (the base frame).
    pub base_link: String,
    /// Tip link of the chain (the flange frame).
    pub tip_link: String,
    /// Movable joints from base to tip.
    pub joints: Vec<Joint>,
    /// One body per joint: `bodies[i]` moves with `joints[i]`.
    pub bodies: Vec<Body>,
    /// `T_last_flange`: flange in the last joint frame (m).
    pub flange_offset: Pose,
    /// `M = T_base_flange` at q = 0 (m).
    pub home_flange: Pose,
    /// Links of moving bodies that carry no mass (no `<inertial>`); statics refuse to run while non-empty.
    pub massless_links: Vec<String>,
    /// Things the loader tolerated but a user should know (e.g. off-chain movable joints ignored).
    pub notes: Vec<String>,
}

impl Model {
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
