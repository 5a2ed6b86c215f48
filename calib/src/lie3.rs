//! Small SO(3) helpers the identification needs beyond [`sim::lie`]: rotation-vector exponential and
//! logarithm, the inverse left Jacobian, quaternions and URDF roll-pitch-yaw angles.

use nalgebra::{Matrix3, Quaternion, Rotation3, UnitQuaternion, Vector3};
use sim::lie::skew;

/// `exp([φ])`: the rotation by `|φ|` rad about `φ/|φ|` (Rodrigues; series near zero).
pub fn exp_rotation(phi: &Vector3<f64>) -> Matrix3<f64> {
    let th2 = phi.norm_squared();
    let k = skew(phi);
    let (a, b) = if th2 < 1e-8 {
        (
            1.0 - th2 / 6.0 + th2 * th2 / 120.0,
            0.5 - th2 / 24.0 + th2 * th2 / 720.0,
        )
    } else {
        let th = th2.sqrt();
        let half = (0.5 * th).sin();
        (th.sin() / th, 2.0 * half * half / th2)
    };
    Matrix3::identity() + k * a + k * k * b
}

/// `log(R)`: the rotation vector `φ` (rad, `|φ| ≤ π`) with `exp([φ]) = R`.
pub fn log_rotation(r: &Matrix3<f64>) -> Vector3<f64> {
    let pose = sim::lie::pose_from(*r, Vector3::zeros());
    let xi = sim::lie::log_pose(&pose);
    Vector3::new(xi[0], xi[1], xi[2])
}

/// Inverse of the left Jacobian of SO(3) at `φ`: `log(exp([δ]) exp([φ])) ≈ φ + J_l⁻¹(φ) δ` for small `δ`.
///
/// `J_l⁻¹(φ) = I − ½[φ] + (1/θ² − (1 + cos θ)/(2 θ sin θ)) [φ]²`, `θ = |φ|` (series below 1e-4 rad).
pub fn left_jacobian_inverse(phi: &Vector3<f64>) -> Matrix3<f64> {
    let th2 = phi.norm_squared();
    let k = skew(phi);
    let c = if th2 < 1e-8 {
        1.0 / 12.0 + th2 / 720.0
    } else {
        let th = th2.sqrt();
        1.0 / th2 - (1.0 + th.cos()) / (2.0 * th * th.sin())
    };
    Matrix3::identity() - k * 0.5 + k * k * c
}

/// Left Jacobian of SO(3) at `φ`: `exp([φ + δ]) ≈ exp([J_l(φ) δ]) exp([φ])` for small `δ`.
///
/// `J_l(φ) = I + (1 − cos θ)/θ² [φ] + (θ − sin θ)/θ³ [φ]²`, `θ = |φ|` (series below 1e-4 rad).
pub fn left_jacobian(phi: &Vector3<f64>) -> Matrix3<f64> {
    let th2 = phi.norm_squared();
    let k = skew(phi);
    let (a, b) = if th2 < 1e-8 {
        (0.5 - th2 / 24.0, 1.0 / 6.0 - th2 / 120.0)
    } else {
        let th = th2.sqrt();
        ((1.0 - th.cos()) / th2, (th - th.sin()) / (th2 * th))
    };
    Matrix3::identity() + k * a + k * k * b
}

/// Unit quaternion `[w, x, y, z]` → rotation matrix. The quaternion is normalised first.
pub fn rotation_from_quaternion(q: &[f64; 4]) -> Matrix3<f64> {
    let uq = UnitQuaternion::from_quaternion(Quaternion::new(q[0], q[1], q[2], q[3]));
    *uq.to_rotation_matrix().matrix()
}

/// Rotation matrix → unit quaternion `[w, x, y, z]` with `w ≥ 0`.
pub fn quaternion_from_rotation(r: &Matrix3<f64>) -> [f64; 4] {
    let uq = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(*r));
    let q = uq.quaternion();
    let s = if q.w < 0.0 { -1.0 } else { 1.0 };
    [s * q.w, s * q.i, s * q.j, s * q.k]
}

/// URDF roll-pitch-yaw (rad) of a rotation, `R = Rz(yaw) Ry(pitch) Rx(roll)`, the inverse of
/// [`sim::lie::rotation_from_rpy`]. Pitch comes from `atan2` (accurate near ±π/2); exactly at ±π/2
/// yaw is set to 0 and roll takes the whole remaining rotation.
pub fn rpy_from_rotation(r: &Matrix3<f64>) -> [f64; 3] {
    let cp = (r[(0, 0)] * r[(0, 0)] + r[(1, 0)] * r[(1, 0)]).sqrt();
    let pitch = (-r[(2, 0)]).atan2(cp);
    if cp > 1e-12 {
        let yaw = r[(1, 0)].atan2(r[(0, 0)]);
        let roll = r[(2, 1)].atan2(r[(2, 2)]);
        [roll, pitch, yaw]
    } else {
        // Gimbal lock: with yaw = 0, R = [[0, sp sr, sp cr], [0, cr, -sr], [-sp, 0, 0]].
        let roll = (-r[(1, 2)]).atan2(r[(1, 1)]);
        [roll, pitch, 0.0]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use sim::lie::rotation_from_rpy;

    #[test]
    fn rpy_round_trips_including_gimbal_lock() {
        let half_pi = std::f64::consts::FRAC_PI_2;
        for (r, p, y) in [
            (0.3, -1.1, 2.5),
            (0.0, half_pi, 0.0),
            (1.0, -half_pi, 0.0),
            (0.2, half_pi - 1e-4, -0.7),
            (3.0, 0.1, -3.0),
        ] {
            let m = rotation_from_rpy(r, p, y);
            let [r2, p2, y2] = rpy_from_rotation(&m);
            let back = rotation_from_rpy(r2, p2, y2);
            assert!(
                (back - m).amax() < 1e-15,
                "{r} {p} {y}: {}",
                (back - m).amax()
            );
        }
    }

    #[test]
    fn left_jacobian_matches_finite_differences_and_inverts() {
        for phi in [
            Vector3::new(0.4, -0.3, 0.9),
            Vector3::new(2e-5, 1e-5, -3e-5),
        ] {
            let j = left_jacobian(&phi);
            let h = 1e-6;
            for k in 0..3 {
                let mut d = Vector3::zeros();
                d[k] = h;
                // exp([φ ± h eₖ]) exp([−φ]) = exp([±h J_l eₖ]) to first order.
                let lp = log_rotation(&(exp_rotation(&(phi + d)) * exp_rotation(&-phi)));
                let lm = log_rotation(&(exp_rotation(&(phi - d)) * exp_rotation(&-phi)));
                assert!(((lp - lm) / (2.0 * h) - j.column(k)).amax() < 1e-9);
            }
            assert!((j * left_jacobian_inverse(&phi) - Matrix3::identity()).amax() < 1e-14);
        }
    }

    #[test]
    fn left_jacobian_inverse_matches_finite_differences() {
        let phi = Vector3::new(0.4, -0.3, 0.9);
        let j = left_jacobian_inverse(&phi);
        let h = 1e-6;
        for k in 0..3 {
            let mut d = Vector3::zeros();
            d[k] = h;
            let rp = exp_rotation(&d) * exp_rotation(&phi);
            let rm = exp_rotation(&-d) * exp_rotation(&phi);
            let col = (log_rotation(&rp) - log_rotation(&rm)) / (2.0 * h);
            assert!((col - j.column(k)).amax() < 1e-9);
        }
    }

    #[test]
    fn quaternion_round_trip() {
        let r = exp_rotation(&Vector3::new(0.5, -1.0, 2.0));
        let q = quaternion_from_rotation(&r);
        assert!((rotation_from_quaternion(&q) - r).amax() < 1e-15);
        // Hand value: 90° about z is [cos 45°, 0, 0, sin 45°].
        let q = quaternion_from_rotation(&exp_rotation(&Vector3::new(0.0, 0.0, half())));
        let s = 0.5f64.sqrt();
        assert!((q[0] - s).abs() < 1e-15 && (q[3] - s).abs() < 1e-15);
        fn half() -> f64 {
            std::f64::consts::FRAC_PI_2
        }
    }
}
