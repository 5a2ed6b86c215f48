//! Inverse kinematics (damped least squares) and the reachability filter of the cell: which joint
//! positions put a target where it is wanted, and which poses the robot can take.

use super::{Data, forward_kinematics, point_jacobian, spatial_jacobian};
use crate::lie::{Pose, log_pose, pose_from};
use crate::model::Model;
use nalgebra::{DMatrix, DVector, Matrix3, Matrix3xX, Vector3};

/// Which poses a robot can take in the cell (evaluated with the nominal kinematics).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Reachability {
    /// Floor height in the base frame (m): joint frames 2 … n, the flange and the target stay above it.
    pub floor_z_m: f64,
    /// Smallest distance of the target from the base z axis (m).
    pub min_axis_distance_m: f64,
}

impl Default for Reachability {
    /// Floor 5 cm above the base plane, target at least 10 cm from the base axis.
    fn default() -> Self {
        Reachability {
            floor_z_m: 0.05,
            min_axis_distance_m: 0.10,
        }
    }
}

/// True when the nominal robot at the configuration in `data` (after [`forward_kinematics`]) passes
/// `reach` with the target at `p_flange` (flange frame, m).
pub fn reachable(data: &Data, p_flange: &Vector3<f64>, reach: &Reachability) -> bool {
    let floor = reach.floor_z_m;
    if data
        .joint_poses
        .iter()
        .skip(1)
        .any(|t| t.translation.z <= floor)
    {
        return false;
    }
    if data.flange.translation.z <= floor {
        return false;
    }
    let p = data.flange * nalgebra::Point3::from(*p_flange);
    p.z > floor && p.x.hypot(p.y) >= reach.min_axis_distance_m
}

/// Damped-least-squares inverse kinematics: joint positions near `q_seed` that put the point
/// `p_flange` (flange frame, m) at `target_base` (base frame, m) with the flange rotation `r_target`
/// (base frame). Steps `Δq = Jᵀ (J Jᵀ + λ² I)⁻¹ e` with the 6-row error `e = [log(R_target Rᵀ); Δp]`
/// until `|e| < 1e-12` (rad and m), at most 500 steps; `λ = 1e-3`. Returns `None` if it does not
/// converge.
pub fn solve_ik(
    model: &Model,
    q_seed: &[f64],
    p_flange: &Vector3<f64>,
    target_base: &Vector3<f64>,
    r_target: &Matrix3<f64>,
) -> Option<Vec<f64>> {
    let n = model.nq();
    let mut data = Data::new(model);
    let mut q = q_seed.to_vec();
    let mut jp = Matrix3xX::zeros(n);
    let lambda2 = 1e-6;
    for _ in 0..500 {
        forward_kinematics(model, &mut data, &q);
        let p = point_jacobian(model, &data, p_flange, &mut jp);
        spatial_jacobian(model, &mut data);
        let r = data.flange.rotation.matrix();
        let dr: Pose = pose_from(r_target * r.transpose(), Vector3::zeros());
        let w = log_pose(&dr);
        let dp = target_base - p;
        let e = DVector::from_vec(vec![w[0], w[1], w[2], dp.x, dp.y, dp.z]);
        if e.norm() < 1e-12 {
            return Some(q);
        }
        let mut j = DMatrix::zeros(6, n);
        for c in 0..n {
            for k in 0..3 {
                j[(k, c)] = data.jacobian[(k, c)];
                j[(3 + k, c)] = jp[(k, c)];
            }
        }
        let a = &j * j.transpose() + DMatrix::identity(6, 6) * lambda2;
        let y = a.lu().solve(&e)?;
        let dq = j.transpose() * y;
        for (qi, d) in q.iter_mut().zip(dq.iter()) {
            *qi += d;
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robots;

    #[test]
    fn ik_reaches_the_target_and_keeps_the_orientation() {
        let m = robots::load_builtin("iiwa7").unwrap();
        let seed = [0.1, 0.6, 0.0, -1.2, 0.0, 0.8, 0.0];
        let pf = Vector3::new(0.0, 0.0, 0.05);
        let mut d = Data::new(&m);
        forward_kinematics(&m, &mut d, &seed);
        let r0 = *d.flange.rotation.matrix();
        let p0 = (d.flange * nalgebra::Point3::from(pf)).coords;
        let target = p0 + Vector3::new(0.08, -0.05, 0.06);
        let q = solve_ik(&m, &seed, &pf, &target, &r0).unwrap();
        forward_kinematics(&m, &mut d, &q);
        let p = (d.flange * nalgebra::Point3::from(pf)).coords;
        assert!((p - target).norm() < 1e-11);
        assert!((d.flange.rotation.matrix() - r0).amax() < 1e-11);
    }
}
