//! Forward kinematics and analytic Jacobians of a [`Model`], writing into a [`Data`].
//!
//! Call [`forward_kinematics`] first; the Jacobian functions read the joint poses it stored.
//! The spatial Jacobian `J_s` (6×n, base frame, rows `[ω; v]`) maps `q̇` to the spatial twist of the
//! flange; the body Jacobian `J_b = Ad(T_base_flange⁻¹) J_s` to its body twist.
//!
//! Inverse kinematics and the reachability filter of the cell are in [`ik`].

pub mod ik;

use crate::lie::{Pose, adjoint_apply, pose_from};
use crate::model::{JointKind, Model};
use nalgebra::{Dyn, Matrix3, Matrix3xX, Matrix6xX, OMatrix, U6, Vector3, Vector6};

/// Per-evaluation workspace for one [`Model`]: made once with [`Data::new`], reused without allocating.
#[derive(Clone, Debug)]
pub struct Data {
    /// `T_base_joint[i]` at the last `q` given to [`forward_kinematics`] (m).
    pub joint_poses: Vec<Pose>,
    /// `T_base_flange` at the last `q` (m).
    pub flange: Pose,
    /// Spatial Jacobian (6×n, base frame, `[ω; v]`, rad/s and m/s per unit `q̇`), filled by
    /// [`spatial_jacobian`].
    pub jacobian: Matrix6xX<f64>,
    /// Joint torques that hold the robot against gravity (n, N m or N), filled by
    /// [`crate::statics::gravity_torques`].
    pub gravity_torque: nalgebra::DVector<f64>,
    /// Centre of mass of each body in its joint frame (m), with the branches off the chain at the
    /// values last given to [`Data::pose_branches`] (at zero, the model's [`crate::Body::com`],
    /// until then). The statics read it.
    pub body_com: Vec<Vector3<f64>>,
    /// Scratch of [`Data::pose_branches`]: each branch joint's frame in its body's frame.
    branch_poses: Vec<Pose>,
    /// Scratch of [`Data::pose_branches`]: each body's first-moment change (kg m).
    branch_shift: Vec<Vector3<f64>>,
}

impl Data {
    /// Allocates the workspace for `model`.
    pub fn new(model: &Model) -> Self {
        let n = model.nq();
        Data {
            joint_poses: vec![Pose::identity(); n],
            flange: model.home_flange(),
            jacobian: OMatrix::<f64, U6, Dyn>::zeros(n),
            gravity_torque: nalgebra::DVector::zeros(n),
            body_com: model.bodies().iter().map(|b| b.com).collect(),
            branch_poses: vec![Pose::identity(); model.branches().len()],
            branch_shift: vec![Vector3::zeros(); n],
        }
    }

    /// Poses the branches off the chain ([`crate::branches`]) at `values` (rad or m, one per
    /// [`Model::branches`] joint; `None`: at zero) for the statics that follow: sets
    /// [`Data::body_com`]. Does not allocate.
    ///
    /// # Panics
    /// If `values` is not one per branch joint of `model`, or `model` is not the one this workspace
    /// was made for.
    pub fn pose_branches(&mut self, model: &Model, values: Option<&[f64]>) {
        for (c, b) in self.body_com.iter_mut().zip(model.bodies()) {
            c.clone_from(&b.com);
        }
        let Some(values) = values else { return };
        if model.branches().is_empty() {
            return;
        }
        model
            .branches()
            .first_moment_shift(values, &mut self.branch_poses, &mut self.branch_shift);
        for ((c, b), s) in self
            .body_com
            .iter_mut()
            .zip(model.bodies())
            .zip(&self.branch_shift)
        {
            if b.mass > 0.0 {
                *c += s / b.mass;
            }
        }
    }
}

/// Frame in which a Jacobian expresses the flange velocity.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Frame {
    /// Spatial twist in the base frame (velocity of the base-origin point moving with the flange).
    Spatial,
    /// Body twist in the flange frame.
    Body,
    /// Angular velocity and velocity of the flange origin, both in base-frame axes.
    LocalWorldAligned,
}

/// Joint poses and flange pose at `q` (rad or m per joint); results in `data`.
///
/// # Panics
/// If `q.len() != model.nq()`; check user input with [`Model::check_q`] first.
pub fn forward_kinematics(model: &Model, data: &mut Data, q: &[f64]) {
    assert_eq!(q.len(), model.nq(), "joint vector length");
    // Columns of R_base_joint and the origin p_base_joint, as plain arrays: the 3×3 updates below
    // are a few dozen multiply-adds per joint and must not go through generic matrix code.
    let mut r = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    let mut p = [0.0; 3];
    for ((joint, &qi), out) in model
        .joints()
        .iter()
        .zip(q)
        .zip(data.joint_poses.iter_mut())
    {
        let po = &joint.origin.translation.vector;
        for (a, pa) in p.iter_mut().enumerate() {
            *pa += r[0][a] * po.x + r[1][a] * po.y + r[2][a] * po.z;
        }
        match (joint.kind, joint.aligned_axis) {
            (JointKind::Revolute | JointKind::Continuous, Some((k, sign))) => {
                // r · R_k(sign q): only the two columns orthogonal to e_k turn.
                let (s, c) = crate::trig::sin_cos(qi);
                let s = sign * s;
                // Constant column indices per axis keep `r` in registers (a run-time index would
                // send it through memory and stall store forwarding).
                match k {
                    0 => turn::<1, 2>(&mut r, s, c),
                    1 => turn::<2, 0>(&mut r, s, c),
                    _ => turn::<0, 1>(&mut r, s, c),
                }
            }
            (JointKind::Revolute | JointKind::Continuous, None) => {
                let (s, c) = crate::trig::sin_cos(qi);
                let [k0, k1, k2] = &joint.rotation_terms;
                r = times(&r, &(k0 + k1 * c + k2 * s));
            }
            (JointKind::Prismatic, _) => {
                r = times(&r, joint.origin.rotation.matrix());
                let d = joint.axis * qi;
                for (a, pa) in p.iter_mut().enumerate() {
                    *pa += r[0][a] * d.x + r[1][a] * d.y + r[2][a] * d.z;
                }
            }
        }
        *out = pose_from(
            Matrix3::new(
                r[0][0], r[1][0], r[2][0], r[0][1], r[1][1], r[2][1], r[0][2], r[1][2], r[2][2],
            ),
            Vector3::new(p[0], p[1], p[2]),
        );
    }
    data.flange = data.joint_poses[model.nq() - 1] * model.flange_offset();
}

/// Turns columns `I` and `J` of `r` (given by its columns) by the angle with sine `s` and cosine `c`:
/// `r · R_k` for the rotation `R_k` about the third axis `k`, with `(k, I, J)` cyclic.
#[inline(always)]
fn turn<const I: usize, const J: usize>(r: &mut [[f64; 3]; 3], s: f64, c: f64) {
    let (ci, cj) = (r[I], r[J]);
    r[I] = [
        ci[0] * c + cj[0] * s,
        ci[1] * c + cj[1] * s,
        ci[2] * c + cj[2] * s,
    ];
    r[J] = [
        cj[0] * c - ci[0] * s,
        cj[1] * c - ci[1] * s,
        cj[2] * c - ci[2] * s,
    ];
}

/// `r · m` for `r` given by its columns.
#[inline]
fn times(r: &[[f64; 3]; 3], m: &Matrix3<f64>) -> [[f64; 3]; 3] {
    std::array::from_fn(|col| {
        std::array::from_fn(|a| {
            r[0][a] * m[(0, col)] + r[1][a] * m[(1, col)] + r[2][a] * m[(2, col)]
        })
    })
}

/// `T_base_flange` at `q` (m); also fills `data` like [`forward_kinematics`].
pub fn flange_pose(model: &Model, data: &mut Data, q: &[f64]) -> Pose {
    forward_kinematics(model, data, q);
    data.flange
}

/// Spatial Jacobian at the configuration of the last [`forward_kinematics`] call, into `data.jacobian`.
pub fn spatial_jacobian(model: &Model, data: &mut Data) {
    for (i, (joint, t)) in model.joints().iter().zip(&data.joint_poses).enumerate() {
        let w = t.rotation * joint.axis;
        let col = if joint.kind.is_rotational() {
            let v = t.translation.vector.cross(&w);
            Vector6::new(w.x, w.y, w.z, v.x, v.y, v.z)
        } else {
            Vector6::new(0.0, 0.0, 0.0, w.x, w.y, w.z)
        };
        data.jacobian.set_column(i, &col);
    }
}

/// Flange Jacobian in `frame` (6×n, `[ω; v]`) at the last [`forward_kinematics`] configuration.
pub fn frame_jacobian(model: &Model, data: &mut Data, frame: Frame, out: &mut Matrix6xX<f64>) {
    spatial_jacobian(model, data);
    match frame {
        Frame::Spatial => out.copy_from(&data.jacobian),
        Frame::Body => {
            let inv = data.flange.inverse();
            for i in 0..model.nq() {
                let c: Vector6<f64> = data.jacobian.column(i).into();
                out.set_column(i, &adjoint_apply(&inv, &c));
            }
        }
        Frame::LocalWorldAligned => {
            let p = data.flange.translation.vector;
            for i in 0..model.nq() {
                let c = data.jacobian.column(i);
                let w = Vector3::new(c[0], c[1], c[2]);
                let v = Vector3::new(c[3], c[4], c[5]) + w.cross(&p);
                out.set_column(i, &Vector6::new(w.x, w.y, w.z, v.x, v.y, v.z));
            }
        }
    }
}

/// Position (base frame, m) of the point `p_flange` (flange frame, m) at the last configuration, and its
/// position Jacobian (3×n, m per rad or m per m) into `out`.
pub fn point_jacobian(
    model: &Model,
    data: &Data,
    p_flange: &Vector3<f64>,
    out: &mut Matrix3xX<f64>,
) -> Vector3<f64> {
    let p = data.flange * nalgebra::Point3::from(*p_flange);
    for (i, (joint, t)) in model.joints().iter().zip(&data.joint_poses).enumerate() {
        let w = t.rotation * joint.axis;
        let col = if joint.kind.is_rotational() {
            w.cross(&(p.coords - t.translation.vector))
        } else {
            w
        };
        out.set_column(i, &col);
    }
    p.coords
}

/// Product-of-exponentials forward kinematics `exp([S₁]q₁) ⋯ exp([Sₙ]qₙ) M` for arbitrary screws
/// (base frame, `[ω; v]`) and home pose `M` (m). Slower than [`forward_kinematics`]; meant for error
/// models whose screws differ from the nominal ones.
pub fn poe_pose(screws: &[Vector6<f64>], home: &Pose, q: &[f64]) -> Pose {
    assert_eq!(screws.len(), q.len(), "joint vector length");
    let mut t = Pose::identity();
    for (s, &qi) in screws.iter().zip(q) {
        t *= crate::lie::exp_se3(s, qi);
    }
    t * home
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robots;

    fn configs(model: &Model, n: usize) -> Vec<Vec<f64>> {
        // Deterministic low-discrepancy configurations within ±2 rad (no RNG dependency needed here).
        (0..n)
            .map(|k| {
                (0..model.nq())
                    .map(|i| {
                        ((k as f64 + 1.0) * (0.754877666 + 0.569840291 * i as f64)).fract() * 4.0
                            - 2.0
                    })
                    .collect()
            })
            .collect()
    }

    /// A model changed through its mutators keeps its derived quantities in step: the home poses and
    /// screw axes (product of exponentials) give the same flange as the chain of joint frames, with
    /// a turned and shifted joint origin and flange offset on the UR5 (whose origins are not aligned
    /// with the axes, so the rotation terms matter too).
    #[test]
    fn a_changed_model_recomputes_its_derived_quantities() {
        let m = robots::load_builtin("ur5").unwrap();
        let turn = crate::lie::pose_from(
            *nalgebra::Rotation3::from_euler_angles(0.01, -0.02, 0.03).matrix(),
            Vector3::new(1e-3, -2e-3, 5e-4),
        );
        let changed = m
            .with_joint_origin(2, turn * m.joints()[2].origin)
            .unwrap()
            .with_flange_offset(turn * m.flange_offset())
            .unwrap();
        assert!(
            (changed.joints()[2].home.translation.vector - m.joints()[2].home.translation.vector)
                .amax()
                > 1e-4
        );
        let mut d = Data::new(&changed);
        for q in configs(&changed, 20) {
            let a = flange_pose(&changed, &mut d, &q);
            let b = poe_pose(&changed.screws(), &changed.home_flange(), &q);
            assert!((a.translation.vector - b.translation.vector).amax() < 1e-14);
            assert!((a.rotation.matrix() - b.rotation.matrix()).amax() < 1e-14);
        }
        assert!(matches!(
            m.with_joint_origin(6, Pose::identity()),
            Err(crate::error::SimError::JointCount {
                expected: 6,
                got: 7
            })
        ));
        let mut parts = m.to_parts();
        parts.bodies.pop();
        let e = crate::model::Model::new(parts).unwrap_err().to_string();
        assert!(e.contains("5 bodies for 6 joints"), "{e}");
        let mut parts = m.to_parts();
        parts.joints[1].axis *= 2.0;
        let e = crate::model::Model::new(parts).unwrap_err().to_string();
        assert!(e.contains("axis xyz") && e.contains("unit length"), "{e}");
    }

    #[test]
    fn product_of_exponentials_equals_chain_of_urdf_frames() {
        let m = robots::load_builtin("iiwa7").unwrap();
        let mut d = Data::new(&m);
        for q in configs(&m, 50) {
            let a = flange_pose(&m, &mut d, &q);
            let b = poe_pose(&m.screws(), &m.home_flange(), &q);
            assert!((a.translation.vector - b.translation.vector).amax() < 1e-14);
            assert!((a.rotation.matrix() - b.rotation.matrix()).amax() < 1e-14);
        }
    }

    #[test]
    fn jacobians_match_finite_differences_and_each_other() {
        let m = robots::load_builtin("iiwa7").unwrap();
        let mut d = Data::new(&m);
        let n = m.nq();
        let mut jb = Matrix6xX::zeros(n);
        let mut jl = Matrix6xX::zeros(n);
        let mut jp = Matrix3xX::zeros(n);
        let tool = Vector3::new(0.03, -0.02, 0.11);
        let h = 1e-6;
        for q in configs(&m, 20) {
            let t0 = flange_pose(&m, &mut d, &q);
            frame_jacobian(&m, &mut d, Frame::Body, &mut jb);
            frame_jacobian(&m, &mut d, Frame::LocalWorldAligned, &mut jl);
            let p0 = point_jacobian(&m, &d, &tool, &mut jp);
            let js = d.jacobian.clone();
            for i in 0..n {
                let mut qp = q.clone();
                let mut qm = q.clone();
                qp[i] += h;
                qm[i] -= h;
                let tp = flange_pose(&m, &mut d, &qp);
                let tm = flange_pose(&m, &mut d, &qm);
                // Spatial twist: log(T(q+h) T(q-h)⁻¹) / 2h; body twist: log(T(q-h)⁻¹ T(q+h)) / 2h.
                let xs = crate::lie::log_pose(&(tp * tm.inverse())) / (2.0 * h);
                let xb = crate::lie::log_pose(&(tm.inverse() * tp)) / (2.0 * h);
                assert!((xs - js.column(i)).amax() < 1e-8, "spatial col {i}");
                assert!((xb - jb.column(i)).amax() < 1e-8, "body col {i}");
                let dp = (tp.translation.vector - tm.translation.vector) / (2.0 * h);
                assert!(
                    (dp - jl.fixed_view::<3, 1>(3, i)).amax() < 1e-8,
                    "lwa col {i}"
                );
                let pp = tp * nalgebra::Point3::from(tool);
                let pm = tm * nalgebra::Point3::from(tool);
                assert!(
                    ((pp - pm) / (2.0 * h) - jp.column(i)).amax() < 1e-8,
                    "point col {i}"
                );
            }
            // Identity: Ad(T⁻¹) J_s = J_b.
            let inv = t0.inverse();
            for i in 0..n {
                let c: Vector6<f64> = js.column(i).into();
                assert!((adjoint_apply(&inv, &c) - jb.column(i)).amax() < 1e-14);
            }
            assert!((p0 - (t0 * nalgebra::Point3::from(tool)).coords).amax() < 1e-15);
        }
    }

    #[test]
    fn iiwa7_flange_at_home_is_1266_mm_above_base() {
        let m = robots::load_builtin("iiwa7").unwrap();
        let t = m.home_flange();
        assert!((t.translation.vector - Vector3::new(0.0, 0.0, 1.266)).amax() < 1e-15);
        assert!((t.rotation.matrix() - Matrix3::identity()).amax() < 1e-15);
    }
}
