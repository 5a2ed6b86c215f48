//! The laser tracker: where it stands, what it measures, and how it errs.
//!
//! # Geometry
//!
//! The tracker has its own frame (`tracker`); the robot base sits in it at `T_tracker_base`. The
//! reflector (a spherically mounted retroreflector, SMR) is fixed to the flange at `p_flange` (flange
//! frame, m). For a real flange pose `T_base_flange` the noise-free target is
//!
//! ```text
//! p_tracker = T_tracker_base · T_base_flange · p_flange          (m, tracker frame)
//! ```
//!
//! With a 6-DoF probe ([`Tracker::six_dof`]) the tracker also reports the probe orientation
//! `R_tracker_probe = R_tracker_base · R_base_flange · R_flange_probe` as a unit quaternion.
//!
//! # Noise
//!
//! A tracker measures in spherical coordinates: a distance `d` along the line of sight (absolute
//! distance meter, ADM) and two angles (azimuth and elevation encoders). The error is therefore
//! anisotropic. With `u = p_tracker / d` the unit line of sight and `e₁, e₂` two unit vectors
//! perpendicular to it (`e₁ = z × u / |z × u|`, horizontal; `e₂ = u × e₁`; `e₁ = x × u / |x × u|` when
//! looking straight up or down), the error added to one measurement is
//!
//! ```text
//! ε = s · (σ_r(d) n_r u + σ_t(d) (n₁ e₁ + n₂ e₂)),   n_r, n₁, n₂ ~ N(0, 1) independent,
//! σ_r(d) = a_r + b_r d,      σ_t(d) = a_t + b_t d,
//! ```
//!
//! with `s` the noise scale (`--noise`; 0 gives exact measurements). A fraction `outlier_rate` of the
//! measurements (each one independently, a Bernoulli draw) also carries a gross error of length
//! `s · outlier_magnitude_m` in a uniformly random direction, as when the beam is briefly broken or the
//! SMR is seated badly.
//!
//! With a 6-DoF probe the measured orientation is `R_meas = exp([δ]) R_true`, `δ ~ N(0, (s σ_o)² I₃)`
//! (rad, tracker frame).
//!
//! # Default magnitudes and their source
//!
//! Leica Absolute Tracker AT960 user manual, section "Laser Tracker Subsystem Specifications" (ISO
//! 10360-10:2021, annex D), maximum permissible errors (MPE): ADM `e_ADM = ±10 µm + 0.3 µm/m`,
//! transverse `e_T = ±15 µm + 6 µm/m`; the same manual states that "typical measurement results are half
//! of the relevant MPE values". We take that typical value as one standard deviation:
//!
//! * radial `σ_r = 5 µm + 0.15 µm/m` ([`DEFAULT_RADIAL_A_M`], [`DEFAULT_RADIAL_B_M_PER_M`]),
//! * transverse, per direction, `σ_t = 7.5 µm + 3 µm/m` ([`DEFAULT_TRANSVERSE_A_M`],
//!   [`DEFAULT_TRANSVERSE_B_M_PER_M`]).
//!
//! At 3 m that is σ_r ≈ 5.5 µm and σ_t ≈ 16.5 µm. (FARO Vantage trackers are specified in the same
//! form and close to these numbers.) The 6-DoF orientation default, [`DEFAULT_ORIENTATION_SIGMA_RAD`]
//! = 8.7e-5 rad (0.005°), is half of the ±0.01° orientation MPE commonly quoted for 6-DoF probes
//! (Leica T-Mac); it is an assumption, not a measured value.
//!
//! # The `sigma` column
//!
//! The measurement table has one scalar `sigma` per row. This module writes the RMS of the per-axis
//! standard deviations, `σ = s · sqrt((σ_r² + 2 σ_t²) / 3)` evaluated at the measured distance, so that
//! `E|ε|² = 3 σ²` for the Gaussian part, as for an isotropic error of standard deviation σ per axis. The
//! exact anisotropic σ_r and σ_t of every row are in `truth.parquet`.

use crate::error::{Result, SimError};
use crate::lie::{Pose, exp_so3, pose_from, rotation_from_rpy};
use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};
use rand::RngExt;
use rand_distr::StandardNormal;

/// Default radial (distance) noise, constant part: half the AT960 ADM MPE of 10 µm (m, 1σ).
pub const DEFAULT_RADIAL_A_M: f64 = 5e-6;
/// Default radial noise, distance-proportional part: half the AT960 ADM MPE of 0.3 µm/m (m per m).
pub const DEFAULT_RADIAL_B_M_PER_M: f64 = 0.15e-6;
/// Default transverse noise per direction, constant part: half the AT960 transverse MPE of 15 µm (m).
pub const DEFAULT_TRANSVERSE_A_M: f64 = 7.5e-6;
/// Default transverse noise, distance-proportional part: half the AT960 MPE of 6 µm/m (m per m).
pub const DEFAULT_TRANSVERSE_B_M_PER_M: f64 = 3e-6;
/// Default 6-DoF orientation noise per axis (rad, 1σ): 0.005°, half of a ±0.01° MPE.
pub const DEFAULT_ORIENTATION_SIGMA_RAD: f64 = 8.7e-5;
/// Default size of a gross outlier (m).
pub const DEFAULT_OUTLIER_MAGNITUDE_M: f64 = 1e-3;
/// Default reflector position in the flange frame (m): an SMR in a nest 5 cm in front of the flange.
pub const DEFAULT_P_FLANGE_M: [f64; 3] = [0.0, 0.0, 0.05];
/// Default robot base position in the tracker frame (m): about 2.7 m away, 0.2 m below the tracker head.
pub const DEFAULT_BASE_XYZ_M: [f64; 3] = [2.5, 1.0, -0.2];
/// Default robot base orientation in the tracker frame, roll-pitch-yaw (rad): the tracker is levelled
/// (no roll or pitch) and faces the robot (yaw).
pub const DEFAULT_BASE_RPY_RAD: [f64; 3] = [0.0, 0.0, 2.5];

/// Largest noise term accepted (m or m/m): a millimetre-class σ is not a laser tracker, and values such
/// as `15` (µm meant) are refused.
pub const MAX_SIGMA_M: f64 = 1e-2;

/// The tracker's noise model (see the module docs). All σ are one standard deviation.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct NoiseModel {
    /// Radial σ, constant part `a_r` (m).
    pub radial_a_m: f64,
    /// Radial σ, distance-proportional part `b_r` (m per m of distance).
    pub radial_b_m_per_m: f64,
    /// Transverse σ per direction, constant part `a_t` (m).
    pub transverse_a_m: f64,
    /// Transverse σ, distance-proportional part `b_t` (m per m).
    pub transverse_b_m_per_m: f64,
    /// Orientation σ per axis of a 6-DoF probe (rad); unused without one.
    pub orientation_sigma_rad: f64,
    /// Fraction of measurements with a gross error, in [0, 1].
    pub outlier_rate: f64,
    /// Length of a gross error (m).
    pub outlier_magnitude_m: f64,
}

impl Default for NoiseModel {
    /// The Leica AT960 typical values (see the module docs), no outliers.
    fn default() -> Self {
        NoiseModel {
            radial_a_m: DEFAULT_RADIAL_A_M,
            radial_b_m_per_m: DEFAULT_RADIAL_B_M_PER_M,
            transverse_a_m: DEFAULT_TRANSVERSE_A_M,
            transverse_b_m_per_m: DEFAULT_TRANSVERSE_B_M_PER_M,
            orientation_sigma_rad: DEFAULT_ORIENTATION_SIGMA_RAD,
            outlier_rate: 0.0,
            outlier_magnitude_m: DEFAULT_OUTLIER_MAGNITUDE_M,
        }
    }
}

fn bad(field: &str, value: f64, problem: &str) -> SimError {
    SimError::BadCondition {
        field: format!("tracker.{field}"),
        value: value.to_string(),
        problem: problem.into(),
    }
}

impl NoiseModel {
    /// Checks every field: finite, ≥ 0, σ terms ≤ [`MAX_SIGMA_M`], orientation σ ≤ 0.1 rad, outlier
    /// rate in [0, 1], outlier magnitude ≤ 1 m.
    pub fn validate(&self) -> Result<()> {
        for (name, v) in [
            ("radial_a_m", self.radial_a_m),
            ("radial_b_m_per_m", self.radial_b_m_per_m),
            ("transverse_a_m", self.transverse_a_m),
            ("transverse_b_m_per_m", self.transverse_b_m_per_m),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(bad(name, v, "must be finite and ≥ 0"));
            }
            if v > MAX_SIGMA_M {
                return Err(bad(
                    name,
                    v,
                    "is not a laser-tracker noise level; give it in m (7.5 µm = 7.5e-6)",
                ));
            }
        }
        let o = self.orientation_sigma_rad;
        if !(o.is_finite() && (0.0..=0.1).contains(&o)) {
            return Err(bad(
                "orientation_sigma_rad",
                o,
                "must be finite, ≥ 0 and ≤ 0.1 rad",
            ));
        }
        let r = self.outlier_rate;
        if !(r.is_finite() && (0.0..=1.0).contains(&r)) {
            return Err(bad("outlier_rate", r, "must be a fraction in [0, 1]"));
        }
        let m = self.outlier_magnitude_m;
        if !(m.is_finite() && (0.0..=1.0).contains(&m)) {
            return Err(bad(
                "outlier_magnitude_m",
                m,
                "must be finite, ≥ 0 and ≤ 1 m",
            ));
        }
        Ok(())
    }
}

/// A laser tracker placed in the world, with its reflector on the flange. Made (and validated) by
/// [`Tracker::new`] and [`Tracker::with_six_dof`]; read with the accessors.
#[derive(Clone, Debug, PartialEq)]
pub struct Tracker {
    /// Pose of the robot base in the tracker frame (m).
    t_tracker_base: Pose,
    /// Reflector (target) position in the flange frame (m).
    p_flange: Vector3<f64>,
    /// True when a 6-DoF probe also reports orientation.
    six_dof: bool,
    /// Orientation of the 6-DoF probe in the flange frame (identity when the probe is aligned with it).
    r_flange_probe: Matrix3<f64>,
    /// Noise model at scale 1.
    noise: NoiseModel,
    /// Multiplier `s` on every error term (σ's and the outlier size); 0 = noise-free.
    noise_scale: f64,
}

/// One simulated tracker reading, with what went into it.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Reading {
    /// Noise-free target position (m, tracker frame).
    pub p_true: [f64; 3],
    /// Measured target position `p_true + noise` (m, tracker frame).
    pub p_measured: [f64; 3],
    /// Error added, gross outlier included (m, tracker frame).
    pub noise: [f64; 3],
    /// True when a gross outlier was added.
    pub outlier: bool,
    /// Radial σ at this distance, scaled (m).
    pub sigma_radial_m: f64,
    /// Transverse σ per direction at this distance, scaled (m).
    pub sigma_transverse_m: f64,
    /// The value written in the `sigma` column: `sqrt((σ_r² + 2 σ_t²)/3)` (m, see the module docs).
    pub sigma_m: f64,
    /// Noise-free probe orientation `[w, x, y, z]` (tracker frame; 6-DoF only, else zeros).
    pub orientation_true: [f64; 4],
    /// Measured probe orientation `[w, x, y, z]`, `w ≥ 0` (tracker frame; 6-DoF only, else zeros).
    pub orientation_measured: [f64; 4],
    /// Orientation error `δ` (rad, tracker frame; 6-DoF only, else zeros).
    pub orientation_noise: [f64; 3],
}

/// Unit vectors `(e₁, e₂)` perpendicular to the unit line of sight `u` (see the module docs).
pub fn transverse_basis(u: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let h = Vector3::z().cross(u);
    let n = h.norm();
    let e1 = if n > 1e-9 {
        h / n
    } else {
        Vector3::x().cross(u).normalize()
    };
    (e1, u.cross(&e1))
}

/// `[w, x, y, z]` of a rotation, sign chosen so that `w ≥ 0`.
fn quaternion(r: &Matrix3<f64>) -> [f64; 4] {
    let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(*r));
    let s = if q.w < 0.0 { -1.0 } else { 1.0 };
    [s * q.w, s * q.i, s * q.j, s * q.k]
}

impl Tracker {
    /// A tracker with the robot base at `xyz_m` (m) and roll-pitch-yaw `rpy_rad` (rad, `Rz Ry Rx`) in
    /// the tracker frame, the reflector at `p_flange` (flange frame, m). Validates the noise model,
    /// the scale (finite, ≥ 0) and that every number is finite.
    pub fn new(
        xyz_m: [f64; 3],
        rpy_rad: [f64; 3],
        p_flange: [f64; 3],
        noise: NoiseModel,
        noise_scale: f64,
    ) -> Result<Tracker> {
        for (name, v) in [
            ("xyz_m", xyz_m),
            ("rpy_rad", rpy_rad),
            ("p_flange", p_flange),
        ] {
            if let Some((k, x)) = v.iter().enumerate().find(|(_, x)| !x.is_finite()) {
                return Err(bad(&format!("{name}[{k}]"), *x, "not finite"));
            }
        }
        noise.validate()?;
        if !(noise_scale.is_finite() && noise_scale >= 0.0) {
            return Err(bad("noise_scale", noise_scale, "must be finite and ≥ 0"));
        }
        Ok(Tracker {
            t_tracker_base: pose_from(
                rotation_from_rpy(rpy_rad[0], rpy_rad[1], rpy_rad[2]),
                Vector3::from(xyz_m),
            ),
            p_flange: Vector3::from(p_flange),
            six_dof: false,
            r_flange_probe: Matrix3::identity(),
            noise,
            noise_scale,
        })
    }

    /// Turns on 6-DoF orientation output with the probe at roll-pitch-yaw `probe_rpy_rad` (rad) in the
    /// flange frame.
    #[must_use]
    pub fn with_six_dof(mut self, probe_rpy_rad: [f64; 3]) -> Tracker {
        self.six_dof = true;
        self.r_flange_probe =
            rotation_from_rpy(probe_rpy_rad[0], probe_rpy_rad[1], probe_rpy_rad[2]);
        self
    }

    /// Pose of the robot base in the tracker frame, `T_tracker_base` (m).
    pub fn t_tracker_base(&self) -> &Pose {
        &self.t_tracker_base
    }

    /// Reflector (target) position in the flange frame (m).
    pub fn p_flange(&self) -> &Vector3<f64> {
        &self.p_flange
    }

    /// True when a 6-DoF probe also reports orientation.
    pub fn six_dof(&self) -> bool {
        self.six_dof
    }

    /// Orientation of the 6-DoF probe in the flange frame, `R_flange_probe`.
    pub fn r_flange_probe(&self) -> &Matrix3<f64> {
        &self.r_flange_probe
    }

    /// Noise model at scale 1.
    pub fn noise(&self) -> &NoiseModel {
        &self.noise
    }

    /// Multiplier `s` on every error term; 0 = noise-free.
    pub fn noise_scale(&self) -> f64 {
        self.noise_scale
    }

    /// Scaled `(σ_r, σ_t)` (m) at distance `d` (m).
    #[inline]
    pub fn sigmas(&self, d: f64) -> (f64, f64) {
        let n = &self.noise;
        (
            self.noise_scale * (n.radial_a_m + n.radial_b_m_per_m * d),
            self.noise_scale * (n.transverse_a_m + n.transverse_b_m_per_m * d),
        )
    }

    /// The `sigma` column value at distance `d` (m): `sqrt((σ_r² + 2 σ_t²)/3)`, scaled.
    #[inline]
    pub fn row_sigma(&self, d: f64) -> f64 {
        let (r, t) = self.sigmas(d);
        ((r * r + 2.0 * t * t) / 3.0).sqrt()
    }

    /// Noise-free target position in the tracker frame (m) for the real flange pose `t_base_flange`.
    #[inline]
    pub fn target(&self, t_base_flange: &Pose) -> Vector3<f64> {
        (self.t_tracker_base * (t_base_flange * nalgebra::Point3::from(self.p_flange))).coords
    }

    /// Simulates one reading of the reflector on the real flange at `t_base_flange` (m, base frame),
    /// drawing from `rng`: three standard normals (radial, e₁, e₂), one uniform for the outlier test,
    /// then, for an outlier, three normals for its direction, and with a 6-DoF probe three normals for
    /// the orientation error. Does not allocate.
    pub fn measure<R: rand::Rng + ?Sized>(&self, t_base_flange: &Pose, rng: &mut R) -> Reading {
        let p = self.target(t_base_flange);
        let d = p.norm();
        let u = if d > 0.0 { p / d } else { Vector3::z() };
        let (e1, e2) = transverse_basis(&u);
        let (sr, st) = self.sigmas(d);
        let nr: f64 = rng.sample(StandardNormal);
        let n1: f64 = rng.sample(StandardNormal);
        let n2: f64 = rng.sample(StandardNormal);
        let mut eps = u * (sr * nr) + e1 * (st * n1) + e2 * (st * n2);
        let draw: f64 = rng.random();
        let mut outlier = false;
        if draw < self.noise.outlier_rate && self.noise_scale > 0.0 {
            let mut dir = Vector3::zeros();
            // A standard normal 3-vector has a uniformly distributed direction.
            while dir.norm_squared() < 1e-12 {
                dir = Vector3::new(
                    rng.sample(StandardNormal),
                    rng.sample(StandardNormal),
                    rng.sample(StandardNormal),
                );
            }
            eps += dir.normalize() * (self.noise_scale * self.noise.outlier_magnitude_m);
            outlier = true;
        }
        let measured = p + eps;
        let mut reading = Reading {
            p_true: [p.x, p.y, p.z],
            p_measured: [measured.x, measured.y, measured.z],
            noise: [eps.x, eps.y, eps.z],
            outlier,
            sigma_radial_m: sr,
            sigma_transverse_m: st,
            sigma_m: self.row_sigma(measured.norm()),
            ..Reading::default()
        };
        if self.six_dof {
            let r_true = self.t_tracker_base.rotation.matrix()
                * t_base_flange.rotation.matrix()
                * self.r_flange_probe;
            let so = self.noise_scale * self.noise.orientation_sigma_rad;
            let delta = Vector3::new(
                so * rng.sample::<f64, _>(StandardNormal),
                so * rng.sample::<f64, _>(StandardNormal),
                so * rng.sample::<f64, _>(StandardNormal),
            );
            let angle = delta.norm();
            let r_meas = if angle > 0.0 {
                exp_so3(&(delta / angle), angle) * r_true
            } else {
                r_true
            };
            reading.orientation_true = quaternion(&r_true);
            reading.orientation_measured = quaternion(&r_meas);
            reading.orientation_noise = [delta.x, delta.y, delta.z];
        }
        reading
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn transverse_basis_is_orthonormal_and_horizontal() {
        for u in [
            Vector3::new(1.0, 2.0, 0.5).normalize(),
            Vector3::z(),
            -Vector3::z(),
            Vector3::new(0.0, 0.0, 1.0 + 1e-12).normalize(),
        ] {
            let (a, b) = transverse_basis(&u);
            assert!((a.norm() - 1.0).abs() < 1e-14 && (b.norm() - 1.0).abs() < 1e-14);
            assert!(a.dot(&u).abs() < 1e-14 && b.dot(&u).abs() < 1e-14 && a.dot(&b).abs() < 1e-14);
        }
        // Not looking vertically: e₁ is horizontal (the azimuth direction).
        let (a, _) = transverse_basis(&Vector3::new(1.0, 2.0, 0.5).normalize());
        assert!(a.z.abs() < 1e-15);
    }

    #[test]
    fn sigmas_follow_the_affine_law_and_the_column_is_their_rms() {
        let t = Tracker::new(
            [3.0, 0.0, 0.0],
            [0.0; 3],
            [0.0; 3],
            NoiseModel::default(),
            2.0,
        )
        .unwrap();
        let (r, s) = t.sigmas(4.0);
        // Hand values: 2·(5 µm + 0.15 µm/m · 4 m) = 11.2 µm; 2·(7.5 µm + 3 µm/m · 4 m) = 39 µm.
        assert!((r - 11.2e-6).abs() < 1e-18);
        assert!((s - 39e-6).abs() < 1e-18);
        assert!(
            (t.row_sigma(4.0) - ((11.2e-6f64.powi(2) + 2.0 * 39e-6f64.powi(2)) / 3.0).sqrt()).abs()
                < 1e-18
        );
    }

    #[test]
    fn zero_scale_gives_the_exact_target() {
        let t = Tracker::new(
            [2.0, 1.0, 0.0],
            [0.1, -0.2, 0.3],
            [0.0, 0.0, 0.05],
            NoiseModel {
                outlier_rate: 1.0,
                ..NoiseModel::default()
            },
            0.0,
        )
        .unwrap()
        .with_six_dof([0.0, 0.0, 0.0]);
        let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(1);
        let flange = pose_from(
            rotation_from_rpy(0.3, 0.2, 0.1),
            Vector3::new(0.4, 0.1, 0.6),
        );
        let r = t.measure(&flange, &mut rng);
        assert_eq!(r.p_true, r.p_measured);
        assert!(!r.outlier);
        assert_eq!(r.orientation_true, r.orientation_measured);
        // Hand check of the frame chain: p = R_tb (R_bf p_f + t_bf) + t_tb.
        let rt = rotation_from_rpy(0.1, -0.2, 0.3);
        let rf = rotation_from_rpy(0.3, 0.2, 0.1);
        let p = rt * (rf * Vector3::new(0.0, 0.0, 0.05) + Vector3::new(0.4, 0.1, 0.6))
            + Vector3::new(2.0, 1.0, 0.0);
        assert!((Vector3::from(r.p_true) - p).amax() < 1e-15);
    }

    #[test]
    fn bad_noise_values_are_refused_with_the_field() {
        let e = Tracker::new(
            [0.0; 3],
            [0.0; 3],
            [0.0; 3],
            NoiseModel {
                transverse_a_m: 15.0,
                ..NoiseModel::default()
            },
            1.0,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("transverse_a_m"), "{e}");
        let e = Tracker::new(
            [0.0; 3],
            [0.0; 3],
            [0.0; 3],
            NoiseModel {
                outlier_rate: 1.5,
                ..NoiseModel::default()
            },
            1.0,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("outlier_rate"), "{e}");
    }
}
