//! Branches that load the chain: links off the measured chain (a second arm, a head, a cable
//! carrier) whose mass the chain's joints carry, on movable joints of their own.
//!
//! A chain taken from a tree (`--tip-link`) folds every link hanging off chain body `i` into that
//! body ([`crate::Body`]), posed with the branch's movable joints at zero. When the measurement table
//! gives a branch joint's value (a column `q_<joint name>`), the branch is posed there instead: its
//! masses move, so the body's centre of mass moves, and with it the gravity torque of every chain
//! joint before it. The body's mass does not change.
//!
//! Each [`BranchJoint`] carries the mass that moves with it and with no branch joint further out
//! (its child link and every link fixed below it). For branch values `v`, the joint's frame in its
//! body's joint frame is `T_j(v) = T_parent(v) O_j X_j(v_j)` (`O_j` the URDF origin, `X_j` a rotation
//! about the unit axis by `v_j` rad, or a translation along it by `v_j` m), and the body's first mass
//! moment changes by `Σ_j m_j (T_j(v) c_j − T_j(0) c_j)` (kg m, body frame).
//!
//! Only statics see the pose: the branch's inertia about its body is that at zero wherever it is
//! used (the rapier truth's dynamics).

use crate::joint_kind::{JointKind, JointLimits};
use crate::lie::{Pose, exp_so3, pose_from};
use nalgebra::{Matrix3, Point3, Vector3};

/// A movable joint on a branch off the chain.
#[derive(Clone, Debug, PartialEq)]
pub struct BranchJoint {
    /// URDF joint name; the table column of its value is `q_<name>`.
    pub name: String,
    /// Revolute, continuous or prismatic.
    pub kind: JointKind,
    /// Unit axis in the joint's frame.
    pub axis: Vector3<f64>,
    /// Position limits (rad or m), or `None` for continuous joints and joints without usable ones.
    pub limits: Option<JointLimits>,
    /// The chain body it hangs from (0-based chain joint index).
    pub body: usize,
    /// The branch joint it hangs from (an index into [`Branches::joints`], always smaller than its
    /// own), or `None` when it hangs from the chain body directly.
    pub parent: Option<usize>,
    /// The joint's frame at zero in its parent's frame (the parent branch joint's, or the chain
    /// body's joint frame), every fixed joint in between folded in (m).
    pub origin: Pose,
    /// Mass moving with this joint and no branch joint further out (kg).
    pub mass: f64,
    /// Centre of that mass in this joint's frame (m); zero when `mass` is zero.
    pub com: Vector3<f64>,
}

impl BranchJoint {
    /// The joint's motion `X(v)` at value `v` (rad or m).
    fn motion(&self, v: f64) -> Pose {
        if self.kind.is_rotational() {
            pose_from(exp_so3(&self.axis, v), Vector3::zeros())
        } else {
            pose_from(Matrix3::identity(), self.axis * v)
        }
    }
}

/// The movable joints of a model's branches, with what each moves. Empty for a chain without
/// movable branches (every single-chain URDF).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Branches {
    joints: Vec<BranchJoint>,
    /// `m_j T_j(0) c_j` per joint (kg m, body frame).
    zero_moment: Vec<Vector3<f64>>,
}

impl Branches {
    /// No branch joints.
    pub fn none() -> Branches {
        Branches::default()
    }

    /// The branches of `joints` (parents before children, as [`BranchJoint::parent`] requires).
    ///
    /// # Panics
    /// If a joint's parent is not an earlier joint.
    pub fn new(joints: Vec<BranchJoint>) -> Branches {
        let mut zero: Vec<Pose> = Vec::with_capacity(joints.len());
        let mut zero_moment = Vec::with_capacity(joints.len());
        for (k, j) in joints.iter().enumerate() {
            let parent = j.parent.map_or(Pose::identity(), |p| {
                assert!(p < k, "branch joint '{}': parent after it", j.name);
                zero[p]
            });
            let t = parent * j.origin;
            zero_moment.push((t * Point3::from(j.com)).coords * j.mass);
            zero.push(t);
        }
        Branches {
            joints,
            zero_moment,
        }
    }

    /// The branch joints, parents before children.
    pub fn joints(&self) -> &[BranchJoint] {
        &self.joints
    }

    /// Number of branch joints.
    pub fn len(&self) -> usize {
        self.joints.len()
    }

    /// True without branch joints.
    pub fn is_empty(&self) -> bool {
        self.joints.is_empty()
    }

    /// Index of the branch joint `name`.
    pub fn index_of(&self, name: &str) -> Option<usize> {
        self.joints.iter().position(|j| j.name == name)
    }

    /// The change of each chain body's first mass moment (kg m, in the body's joint frame) when the
    /// branch joints go from zero to `values` (rad or m, [`Branches::joints`] order), into
    /// `shift` (one per chain body; overwritten). `poses` is scratch of one pose per branch joint.
    /// Does not allocate.
    ///
    /// # Panics
    /// If `values` or `poses` is not one per branch joint, or `shift` has fewer entries than the
    /// bodies the branches hang from.
    pub fn first_moment_shift(
        &self,
        values: &[f64],
        poses: &mut [Pose],
        shift: &mut [Vector3<f64>],
    ) {
        assert_eq!(values.len(), self.joints.len(), "branch values");
        assert_eq!(poses.len(), self.joints.len(), "branch pose scratch");
        shift.fill(Vector3::zeros());
        for (k, j) in self.joints.iter().enumerate() {
            let parent = j.parent.map_or(Pose::identity(), |p| poses[p]);
            let t = parent * j.origin * j.motion(values[k]);
            poses[k] = t;
            if j.mass != 0.0 {
                shift[j.body] += (t * Point3::from(j.com)).coords * j.mass - self.zero_moment[k];
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn joint(
        name: &str,
        parent: Option<usize>,
        origin: Vector3<f64>,
        axis: Vector3<f64>,
    ) -> BranchJoint {
        BranchJoint {
            name: name.into(),
            kind: JointKind::Revolute,
            axis,
            limits: None,
            body: 0,
            parent,
            origin: pose_from(Matrix3::identity(), origin),
            mass: 1.0,
            com: Vector3::new(0.5, 0.0, 0.0),
        }
    }

    /// Two links in a plane, by hand: a shoulder at (0, 0, 1) about z with its 1 kg centre 0.5 m out
    /// along x, an elbow 1 m out about z with its 1 kg centre 0.5 m beyond. At 90° and −90° the
    /// elbow's centre is at (0.5, 1, 1): the shoulder's at (0, 0.5, 1).
    #[test]
    fn two_link_branch_moves_its_masses_by_hand() {
        let z = Vector3::z();
        let b = Branches::new(vec![
            joint("shoulder", None, Vector3::new(0.0, 0.0, 1.0), z),
            joint("elbow", Some(0), Vector3::new(1.0, 0.0, 0.0), z),
        ]);
        let mut poses = vec![Pose::identity(); 2];
        let mut shift = vec![Vector3::zeros(); 1];
        let h = std::f64::consts::FRAC_PI_2;
        b.first_moment_shift(&[h, -h], &mut poses, &mut shift);
        // At zero: centres (0.5, 0, 1) and (1.5, 0, 1); posed: (0, 0.5, 1) and (0.5, 1, 1).
        let want = Vector3::new(0.0 + 0.5 - 0.5 - 1.5, 0.5 + 1.0, 0.0);
        assert!((shift[0] - want).norm() < 1e-15, "{:?}", shift[0]);
        // At zero nothing moves.
        b.first_moment_shift(&[0.0, 0.0], &mut poses, &mut shift);
        assert!(shift[0].norm() < 1e-15);
    }

    /// A prismatic branch joint moves its mass along its axis by its value.
    #[test]
    fn prismatic_branch_slides_its_mass() {
        let mut j = joint("slide", None, Vector3::zeros(), Vector3::y());
        j.kind = JointKind::Prismatic;
        j.mass = 2.0;
        let b = Branches::new(vec![j]);
        let mut poses = vec![Pose::identity(); 1];
        let mut shift = vec![Vector3::zeros(); 1];
        b.first_moment_shift(&[0.25], &mut poses, &mut shift);
        assert!((shift[0] - Vector3::new(0.0, 0.5, 0.0)).norm() < 1e-15);
    }
}
