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

/// Left Jacobian of SE(3) at the twist `ξ = [ω; v]` (rad, m; the convention of
/// [`sim::lie::exp_twist`]): `exp([ξ + δ]) ≈ exp([J_l(ξ) δ]) exp([ξ])` for small `δ`.
///
/// In the `[ω; v]` order, `J_l = [[J, 0], [Q, J]]` with the SO(3) left Jacobian
/// `J = I + (1 − cos θ)/θ² [ω] + (θ − sin θ)/θ³ [ω]²` and (Barfoot and Furgale, "Associating
/// uncertainty with three-dimensional poses for use in estimation problems", IEEE T-RO 2014, eq. 102)
///
/// ```text
/// Q = ½[v] + a ([ω][v] + [v][ω] + [ω][v][ω]) + b ([ω]²[v] + [v][ω]² − 3[ω][v][ω])
///       + c ([ω][v][ω]² + [ω]²[v][ω]),
/// a = (θ − sin θ)/θ³,  b = (θ² + 2 cos θ − 2)/(2θ⁴),  c = (2θ − 3 sin θ + θ cos θ)/(2θ⁵)
/// ```
///
/// `θ = |ω|`; below 1e-2 rad the coefficients come from their Taylor series (to `θ⁴`), where the
/// closed forms cancel. Checked against finite differences of the exponential in the tests below.
pub fn se3_left_jacobian(xi: &nalgebra::Vector6<f64>) -> nalgebra::Matrix6<f64> {
    let w = Vector3::new(xi[0], xi[1], xi[2]);
    let v = Vector3::new(xi[3], xi[4], xi[5]);
    let th2 = w.norm_squared();
    let (jb, a, b, c) = if th2 < 1e-4 {
        (
            0.5 - th2 / 24.0 + th2 * th2 / 720.0,
            1.0 / 6.0 - th2 / 120.0 + th2 * th2 / 5040.0,
            1.0 / 24.0 - th2 / 720.0 + th2 * th2 / 40320.0,
            1.0 / 120.0 - th2 / 2520.0 + th2 * th2 / 120960.0,
        )
    } else {
        let th = th2.sqrt();
        let (s, co) = th.sin_cos();
        let half = (0.5 * th).sin();
        (
            2.0 * half * half / th2,
            (th - s) / (th2 * th),
            (th2 + 2.0 * co - 2.0) / (2.0 * th2 * th2),
            (2.0 * th - 3.0 * s + th * co) / (2.0 * th2 * th2 * th),
        )
    };
    let wx = skew(&w);
    let vx = skew(&v);
    let wx2 = wx * wx;
    let j = Matrix3::identity() + wx * jb + wx2 * a;
    let wvw = wx * vx * wx;
    let q = vx * 0.5
        + (wx * vx + vx * wx + wvw) * a
        + (wx2 * vx + vx * wx2 - wvw * 3.0) * b
        + (wvw * wx + wx * wvw) * c;
    let mut out = nalgebra::Matrix6::zeros();
    out.fixed_view_mut::<3, 3>(0, 0).copy_from(&j);
    out.fixed_view_mut::<3, 3>(3, 0).copy_from(&q);
    out.fixed_view_mut::<3, 3>(3, 3).copy_from(&j);
    out
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

#[cfg(test)]
mod se3_tests {
    use super::*;
    use nalgebra::Vector6;
    use sim::lie::{exp_twist, log_pose};

    /// `J_l(ξ) e_k` against the central difference of `log(exp(ξ + h e_k) exp(ξ)⁻¹) / h`, at twists
    /// of every size regime (series, closed form near the switch, large).
    #[test]
    fn se3_left_jacobian_matches_finite_differences() {
        let twists = [
            Vector6::new(1e-5, -2e-5, 3e-6, 1e-3, -2e-3, 5e-4),
            Vector6::new(4e-3, -6e-3, 2e-3, 0.02, -0.01, 0.03),
            Vector6::new(0.011, 0.002, -0.004, 0.1, 0.2, -0.3),
            Vector6::new(0.7, -0.4, 1.1, 0.3, -0.5, 0.2),
        ];
        let h = 1e-6;
        for xi in &twists {
            let j = se3_left_jacobian(xi);
            let t_inv = exp_twist(xi).inverse();
            for k in 0..6 {
                let mut plus = *xi;
                plus[k] += h;
                let mut minus = *xi;
                minus[k] -= h;
                let d = (log_pose(&(exp_twist(&plus) * t_inv))
                    - log_pose(&(exp_twist(&minus) * t_inv)))
                    / (2.0 * h);
                let col = j.column(k);
                let err = (d - col).amax();
                assert!(err < 1e-8, "ξ = {xi:?}, column {k}: {err:e}\n{d}\n{col}");
            }
        }
    }
}
