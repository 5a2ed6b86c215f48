//! Gravity torques of the chain, with an optional payload at the flange.
//!
//! The gravity torque `τ_g(q)` is what the joints must apply to hold the robot still:
//! `τ_g = -Σ_k J_k(q)ᵀ m_k g`, with `J_k` the position Jacobian of body `k`'s centre of mass. This is
//! MuJoCo's `qfrc_bias` at zero velocity. Units: N m for rotational joints, N for prismatic ones.

use crate::kinematics::{Data, forward_kinematics};
use crate::model::Model;
use nalgebra::Vector3;

/// MuJoCo's and most simulators' default gravity, base frame (m/s²). Standard gravity is 9.80665.
pub const DEFAULT_GRAVITY: [f64; 3] = [0.0, 0.0, -9.81];

/// A point mass carried at the flange.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Payload {
    /// Mass (kg).
    pub mass: f64,
    /// Centre of mass in the flange frame (m).
    pub com: [f64; 3],
}

/// Gravity torques at `q` for `gravity` (base frame, m/s²) into `data.gravity_torque`; also runs
/// forward kinematics. The branches off the chain are where [`Data::pose_branches`] last put them
/// (at zero by default). Fails if a moving body has no inertial data.
///
/// # Panics
/// If `q.len() != model.nq()`.
pub fn gravity_torques(
    model: &Model,
    data: &mut Data,
    q: &[f64],
    gravity: &Vector3<f64>,
    payload: Option<&Payload>,
) -> crate::error::Result<()> {
    model.require_inertials()?;
    forward_kinematics(model, data, q);
    // Walk from the tip: accumulate mass and first moment Σ m c of everything beyond joint i.
    let mut mass = 0.0;
    let mut moment = Vector3::zeros();
    if let Some(pl) = payload {
        let c = data.flange * nalgebra::Point3::from(Vector3::from(pl.com));
        mass += pl.mass;
        moment += c.coords * pl.mass;
    }
    for i in (0..model.nq()).rev() {
        let t = &data.joint_poses[i];
        let body = &model.bodies()[i];
        let c = t * nalgebra::Point3::from(data.body_com[i]);
        mass += body.mass;
        moment += c.coords * body.mass;
        let joint = &model.joints()[i];
        let w = t.rotation * joint.axis;
        data.gravity_torque[i] = if joint.kind.is_rotational() {
            // Torque of gravity about the axis through the joint origin, negated.
            -w.dot(&(moment - t.translation.vector * mass).cross(gravity))
        } else {
            -w.dot(&(gravity * mass))
        };
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::urdf::{ChainSpec, load_str};

    /// Two horizontal links, hand-computable: joint 1 at the origin about y, joint 2 at x = 1 about y.
    const TWO_LINK: &str = r#"<robot name="two">
      <link name="base"/>
      <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
        <axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
      <link name="l1"><inertial><origin xyz="0.5 0 0"/><mass value="2"/>
        <inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>
      <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="1 0 0"/>
        <axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
      <link name="l2"><inertial><origin xyz="0.25 0 0"/><mass value="1"/>
        <inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>
      <joint name="tool" type="fixed"><parent link="l2"/><child link="tip"/><origin xyz="0.5 0 0"/></joint>
      <link name="tip"/>
    </robot>"#;

    #[test]
    fn two_link_gravity_torque_matches_hand_values() {
        let m = load_str(TWO_LINK, "two", &ChainSpec::default()).unwrap();
        let mut d = Data::new(&m);
        let g = Vector3::new(0.0, 0.0, -9.81);
        // Horizontal: τ2 = m2 g x2 = 1·9.81·0.25; τ1 = 2·9.81·0.5 + 1·9.81·1.25.
        // Rotation about +y by a positive angle lowers +x (z = -x sin q), so holding needs a negative torque.
        gravity_torques(&m, &mut d, &[0.0, 0.0], &g, None).unwrap();
        assert!((d.gravity_torque[1] - -(9.81 * 0.25)).abs() < 1e-12);
        assert!((d.gravity_torque[0] - -(9.81 * (1.0 + 1.25))).abs() < 1e-12);
        // Payload 3 kg at the tip (x = 1.5): adds 3 g 1.5 to τ1 and 3 g 0.5 to τ2.
        let pl = Payload {
            mass: 3.0,
            com: [0.0, 0.0, 0.0],
        };
        gravity_torques(&m, &mut d, &[0.0, 0.0], &g, Some(&pl)).unwrap();
        assert!((d.gravity_torque[1] - -(9.81 * (0.25 + 1.5))).abs() < 1e-12);
        assert!((d.gravity_torque[0] - -(9.81 * (2.25 + 4.5))).abs() < 1e-12);
        // Link 1 pointing straight down (q1 = π/2 about +y sends +x to -z): no torque on joint 1 or 2.
        gravity_torques(&m, &mut d, &[std::f64::consts::FRAC_PI_2, 0.0], &g, None).unwrap();
        assert!(d.gravity_torque.amax() < 1e-12);
    }

    #[test]
    fn gravity_torque_is_minus_gradient_of_potential_energy() {
        // τ_g = ∂V/∂q with V = -Σ m gᵀ c: a check independent of the Jacobian formula.
        let m = crate::robots::load_builtin("iiwa7").unwrap();
        let mut d = Data::new(&m);
        let g = Vector3::from(DEFAULT_GRAVITY);
        let pl = Payload {
            mass: 1.7,
            com: [0.01, -0.02, 0.08],
        };
        let potential = |d: &mut Data, q: &[f64]| {
            forward_kinematics(&m, d, q);
            let mut v = 0.0;
            for (t, b) in d.joint_poses.iter().zip(m.bodies()) {
                v -= b.mass * g.dot(&(t * nalgebra::Point3::from(b.com)).coords);
            }
            v - pl.mass * g.dot(&(d.flange * nalgebra::Point3::from(Vector3::from(pl.com))).coords)
        };
        let q = [0.3, -0.7, 1.1, 1.4, -0.5, 0.9, 0.2];
        gravity_torques(&m, &mut d, &q, &g, Some(&pl)).unwrap();
        let tau = d.gravity_torque.clone();
        let h = 1e-6;
        for i in 0..7 {
            let (mut qp, mut qm) = (q, q);
            qp[i] += h;
            qm[i] -= h;
            let fd = (potential(&mut d, &qp) - potential(&mut d, &qm)) / (2.0 * h);
            assert!(
                (fd - tau[i]).abs() < 1e-7 * (1.0 + tau[i].abs()),
                "joint {i}: {fd} vs {}",
                tau[i]
            );
        }
    }
}
