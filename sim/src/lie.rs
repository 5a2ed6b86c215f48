//! Rigid-body algebra on SE(3): skew matrices, exponentials and adjoints.
//!
//! Twists and screws are 6-vectors ordered `[ω; v]` (angular first, then linear), in the frame stated by
//! the caller. A pose `T_a_b` maps coordinates in frame `b` to frame `a`. Lengths in m, angles in rad.

use nalgebra::{IsometryMatrix3, Matrix3, Matrix6, Rotation3, Translation3, Vector3, Vector6};

/// Rigid transform with a rotation matrix: `T_a_b` maps points in `b` to `a` (m).
pub type Pose = IsometryMatrix3<f64>;

/// The skew-symmetric matrix `[w]` with `[w] x = w × x`.
#[inline]
pub fn skew(w: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -w.z, w.y, w.z, 0.0, -w.x, -w.y, w.x, 0.0)
}

/// Rotation `exp([w] θ)` about the unit axis `w` by `theta` rad (Rodrigues).
#[inline]
pub fn exp_so3(w: &Vector3<f64>, theta: f64) -> Matrix3<f64> {
    let (s, c) = theta.sin_cos();
    let k = skew(w);
    Matrix3::identity() + k * s + k * k * (1.0 - c)
}

/// Exponential of a screw `S = [ω; v]` times `theta`: the pose `exp([S] θ)`.
///
/// For a revolute screw `|ω| = 1` and `theta` is an angle (rad); for a prismatic one `ω = 0`, `|v| = 1`
/// and `theta` is a distance (m). General twists (any `|ω|`) are handled too: the exponential of the
/// twist `S θ` is computed exactly.
pub fn exp_se3(screw: &Vector6<f64>, theta: f64) -> Pose {
    let xi = screw * theta;
    exp_twist(&xi)
}

/// Exponential of the twist `ξ = [ω; v]` (no unit-axis assumption).
pub fn exp_twist(xi: &Vector6<f64>) -> Pose {
    let w = Vector3::new(xi[0], xi[1], xi[2]);
    let v = Vector3::new(xi[3], xi[4], xi[5]);
    let th2 = w.norm_squared();
    let k = skew(&w);
    let k2 = k * k;
    // Coefficients A = sin θ/θ, B = (1-cos θ)/θ², C = (θ - sin θ)/θ³, with series near zero.
    let (a, b, c) = if th2 < 1e-8 {
        (
            1.0 - th2 / 6.0 + th2 * th2 / 120.0,
            0.5 - th2 / 24.0 + th2 * th2 / 720.0,
            1.0 / 6.0 - th2 / 120.0 + th2 * th2 / 5040.0,
        )
    } else {
        let th = th2.sqrt();
        let s = th.sin();
        let half = (0.5 * th).sin();
        // 1 - cos θ = 2 sin²(θ/2) avoids cancellation at small θ.
        (s / th, 2.0 * half * half / th2, (th - s) / (th2 * th))
    };
    let r = Matrix3::identity() + k * a + k2 * b;
    let p = (Matrix3::identity() + k * b + k2 * c) * v;
    Pose::from_parts(Translation3::from(p), Rotation3::from_matrix_unchecked(r))
}

/// Logarithm of a pose: the twist `ξ = [ω; v]` with `exp(ξ) = T` and `|ω| ≤ π` (rad, m).
pub fn log_pose(t: &Pose) -> Vector6<f64> {
    let r = t.rotation.matrix();
    let p = t.translation.vector;
    let w_hat = Vector3::new(
        r[(2, 1)] - r[(1, 2)],
        r[(0, 2)] - r[(2, 0)],
        r[(1, 0)] - r[(0, 1)],
    );
    // atan2 keeps θ accurate near 0 and π, where acos of the trace loses half the digits.
    let th = (0.5 * w_hat.norm()).atan2((r.trace() - 1.0) * 0.5);
    let w = if th < 1e-6 {
        // sin θ ≈ θ: ω ≈ vee(R - Rᵀ)/2, accurate to O(θ³).
        w_hat * (0.5 + th * th / 12.0)
    } else if std::f64::consts::PI - th < 1e-6 {
        // Near π: axis from the symmetric part, sign from the antisymmetric part.
        let b = (r + Matrix3::identity()) * 0.5;
        let mut axis = Vector3::new(
            b[(0, 0)].max(0.0).sqrt(),
            b[(1, 1)].max(0.0).sqrt(),
            b[(2, 2)].max(0.0).sqrt(),
        );
        let i = axis.imax();
        for j in 0..3 {
            if j != i && b[(i, j)] < 0.0 {
                axis[j] = -axis[j];
            }
        }
        if axis.dot(&w_hat) < 0.0 {
            axis = -axis;
        }
        axis.normalize() * th
    } else {
        w_hat * (th / (2.0 * th.sin()))
    };
    let th2 = w.norm_squared();
    let k = skew(&w);
    // V⁻¹ = I - K/2 + d K² with d = (1 - (θ/2) cot(θ/2)) / θ²; series below θ = 0.01.
    let d = if th2 < 1e-4 {
        1.0 / 12.0 + th2 / 720.0 + th2 * th2 / 30240.0
    } else {
        let half = 0.5 * th2.sqrt();
        (1.0 - half / half.tan()) / th2
    };
    let v = (Matrix3::identity() - k * 0.5 + k * k * d) * p;
    Vector6::new(w.x, w.y, w.z, v.x, v.y, v.z)
}

/// The adjoint `Ad_T` (6×6) mapping twists `[ω; v]` in frame `b` to frame `a` for `T = T_a_b`.
pub fn adjoint(t: &Pose) -> Matrix6<f64> {
    let r = t.rotation.matrix();
    let pr = skew(&t.translation.vector) * r;
    let mut ad = Matrix6::zeros();
    ad.fixed_view_mut::<3, 3>(0, 0).copy_from(r);
    ad.fixed_view_mut::<3, 3>(3, 0).copy_from(&pr);
    ad.fixed_view_mut::<3, 3>(3, 3).copy_from(r);
    ad
}

/// Applies `Ad_T` to one twist without forming the 6×6 matrix.
#[inline]
pub fn adjoint_apply(t: &Pose, xi: &Vector6<f64>) -> Vector6<f64> {
    let r = t.rotation.matrix();
    let w = r * Vector3::new(xi[0], xi[1], xi[2]);
    let v = t.translation.vector.cross(&w) + r * Vector3::new(xi[3], xi[4], xi[5]);
    Vector6::new(w.x, w.y, w.z, v.x, v.y, v.z)
}

/// Rotation from URDF roll-pitch-yaw (rad): `R = Rz(yaw) Ry(pitch) Rx(roll)`.
pub fn rotation_from_rpy(roll: f64, pitch: f64, yaw: f64) -> Matrix3<f64> {
    let (sr, cr) = roll.sin_cos();
    let (sp, cp) = pitch.sin_cos();
    let (sy, cy) = yaw.sin_cos();
    Matrix3::new(
        cy * cp,
        cy * sp * sr - sy * cr,
        cy * sp * cr + sy * sr,
        sy * cp,
        sy * sp * sr + cy * cr,
        sy * sp * cr - cy * sr,
        -sp,
        cp * sr,
        cp * cr,
    )
}

/// Builds a pose from a rotation matrix and a translation (m) without re-orthonormalising.
#[inline]
pub fn pose_from(r: Matrix3<f64>, p: Vector3<f64>) -> Pose {
    Pose::from_parts(Translation3::from(p), Rotation3::from_matrix_unchecked(r))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: &Pose, b: &Pose, tol: f64) -> bool {
        (a.rotation.matrix() - b.rotation.matrix()).amax() < tol
            && (a.translation.vector - b.translation.vector).amax() < tol
    }

    #[test]
    fn exp_of_pure_rotation_about_offset_axis_matches_hand_value() {
        // Rotation by 90° about the z axis through (1, 0, 0): the origin goes to (1, -1, 0).
        let w = Vector3::z();
        let q = Vector3::new(1.0, 0.0, 0.0);
        let v = -w.cross(&q);
        let s = Vector6::new(w.x, w.y, w.z, v.x, v.y, v.z);
        let t = exp_se3(&s, std::f64::consts::FRAC_PI_2);
        assert!((t.translation.vector - Vector3::new(1.0, -1.0, 0.0)).amax() < 1e-15);
        assert!((t.rotation.matrix() - exp_so3(&w, std::f64::consts::FRAC_PI_2)).amax() < 1e-15);
    }

    #[test]
    fn log_inverts_exp_including_small_and_near_pi_angles() {
        for (k, th) in [
            1e-12,
            1e-7,
            1e-3,
            0.5,
            2.0,
            3.0,
            std::f64::consts::PI - 1e-8,
        ]
        .iter()
        .enumerate()
        {
            let w = Vector3::new(0.3, -0.5 + k as f64 * 0.1, 0.8).normalize() * *th;
            let xi = Vector6::new(w.x, w.y, w.z, 0.2, -0.1, 0.4 + k as f64);
            let t = exp_twist(&xi);
            let back = log_pose(&t);
            assert!(
                (back - xi).amax() < 1e-9,
                "theta {th}: {} {}",
                back.transpose(),
                xi.transpose()
            );
            let e = exp_twist(&back);
            assert!(
                close(&e, &t, 1e-12),
                "theta {th}: {} {}",
                (e.rotation.matrix() - t.rotation.matrix()).amax(),
                (e.translation.vector - t.translation.vector).amax()
            );
        }
    }

    #[test]
    fn adjoint_satisfies_conjugation_identity() {
        // exp(Ad_T ξ) = T exp(ξ) T⁻¹
        let t = exp_twist(&Vector6::new(0.4, -0.2, 0.9, 0.1, 0.7, -0.3));
        let xi = Vector6::new(-0.3, 0.5, 0.1, 0.2, -0.4, 0.6);
        let lhs = exp_twist(&(adjoint(&t) * xi));
        let rhs = t * exp_twist(&xi) * t.inverse();
        assert!(close(&lhs, &rhs, 1e-14));
        assert!((adjoint_apply(&t, &xi) - adjoint(&t) * xi).amax() < 1e-15);
    }

    #[test]
    fn rpy_matches_product_of_elementary_rotations() {
        let (r, p, y) = (0.3, -1.1, 2.5);
        let expect =
            exp_so3(&Vector3::z(), y) * exp_so3(&Vector3::y(), p) * exp_so3(&Vector3::x(), r);
        assert!((rotation_from_rpy(r, p, y) - expect).amax() < 1e-15);
    }
}
