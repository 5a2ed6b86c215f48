//! Synthetic data for the calib tests, built independently of the estimator: the truth is evaluated with
//! `sim::kinematics::poe_pose` on screws moved by `Ad(exp ξ)` (never with `calib::model::chain`).
#![allow(dead_code)]

use nalgebra::{Matrix3, Point3, Vector3, Vector6};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, Normal};
use sim::Model;
use sim::lie::{Pose, adjoint_apply, exp_twist};
use sim::measurement_table::{MeasurementTable, OptionalColumns, Row};

/// A hidden "real robot": error twists, zero offsets, base transform and target.
#[derive(Clone, Debug)]
pub struct Truth {
    pub twists: Vec<Vector6<f64>>,
    pub zero_offsets: Vec<f64>,
    pub t_tracker_base: Pose,
    pub p_flange: Vector3<f64>,
    pub r_flange_target: Option<Matrix3<f64>>,
}

/// A uniformly random value in [lo, hi] with a random sign.
fn signed(rng: &mut StdRng, lo: f64, hi: f64) -> f64 {
    let m = lo + (hi - lo) * rng.random::<f64>();
    if rng.random::<bool>() { m } else { -m }
}

/// Random unit vector.
fn unit(rng: &mut StdRng) -> Vector3<f64> {
    let n = Normal::new(0.0, 1.0).unwrap();
    Vector3::new(n.sample(rng), n.sample(rng), n.sample(rng)).normalize()
}

impl Truth {
    /// Errors of 0.1–1 mm and 0.1–1 mrad per joint twist (rotation and translation parts of random
    /// direction), zero offsets of 0.1–1 mrad, a tracker 2–4 m away at an arbitrary rotation, a target
    /// 5–15 cm from the flange.
    pub fn random(model: &Model, orientation: bool, rng: &mut StdRng) -> Self {
        let n = model.nq();
        let twists = (0..n)
            .map(|_| {
                let w = unit(rng) * signed(rng, 1e-4, 1e-3).abs();
                let v = unit(rng) * signed(rng, 1e-4, 1e-3).abs();
                Vector6::new(w.x, w.y, w.z, v.x, v.y, v.z)
            })
            .collect();
        let zero_offsets = (0..n).map(|_| signed(rng, 1e-4, 1e-3)).collect();
        let rot = unit(rng) * (3.0 * rng.random::<f64>());
        let trans = unit(rng) * (2.0 + 2.0 * rng.random::<f64>());
        let t_tracker_base = exp_twist(&Vector6::new(rot.x, rot.y, rot.z, 0.0, 0.0, 0.0))
            * Pose::from_parts(trans.into(), nalgebra::Rotation3::identity());
        let p_flange = unit(rng) * (0.05 + 0.1 * rng.random::<f64>());
        let r_flange_target = orientation.then(|| {
            let w = unit(rng) * 2.0 * rng.random::<f64>();
            *exp_twist(&Vector6::new(w.x, w.y, w.z, 0.0, 0.0, 0.0))
                .rotation
                .matrix()
        });
        Truth {
            twists,
            zero_offsets,
            t_tracker_base,
            p_flange,
            r_flange_target,
        }
    }

    /// The real screws `Ad(exp ξᵢ) Sᵢ`.
    pub fn screws(&self, model: &Model) -> Vec<Vector6<f64>> {
        model
            .joints()
            .iter()
            .zip(&self.twists)
            .map(|(j, xi)| adjoint_apply(&exp_twist(xi), &j.screw))
            .collect()
    }

    /// True target pose in the tracker frame at controller joint values `q` (product of exponentials).
    pub fn target(&self, model: &Model, q: &[f64]) -> (Vector3<f64>, Matrix3<f64>) {
        let th: Vec<f64> = q
            .iter()
            .zip(&self.zero_offsets)
            .map(|(a, b)| a + b)
            .collect();
        let t = self.t_tracker_base
            * sim::kinematics::poe_pose(&self.screws(model), &model.home_flange(), &th);
        let p = (t * Point3::from(self.p_flange)).coords;
        let r = t.rotation.matrix() * self.r_flange_target.unwrap_or_else(Matrix3::identity);
        (p, r)
    }
}

/// Uniform random configurations within the joint limits (±π for joints without limits).
pub fn random_configs(model: &Model, n: usize, rng: &mut StdRng) -> Vec<Vec<f64>> {
    (0..n)
        .map(|_| {
            model
                .joints()
                .iter()
                .map(|j| {
                    let (lo, hi) = j
                        .limits
                        .map_or((-std::f64::consts::PI, std::f64::consts::PI), |l| {
                            (l.lower, l.upper)
                        });
                    lo + (hi - lo) * rng.random::<f64>()
                })
                .collect()
        })
        .collect()
}

/// A measurement table of `configs` (pose ids 0..), measured on `truth` with isotropic Gaussian position
/// noise `noise_m` (and orientation noise `noise_rad` about a random axis when `orientation`).
pub fn table(
    model: &Model,
    truth: &Truth,
    configs: &[Vec<f64>],
    noise_m: f64,
    noise_rad: f64,
    rng: &mut StdRng,
) -> MeasurementTable {
    table_with(model, truth, configs, noise_m, noise_rad, None, rng)
}

/// Like [`table`], with a `sigma` column of value `sigma` when given.
pub fn table_with(
    model: &Model,
    truth: &Truth,
    configs: &[Vec<f64>],
    noise_m: f64,
    noise_rad: f64,
    sigma: Option<f64>,
    rng: &mut StdRng,
) -> MeasurementTable {
    let orientation = truth.r_flange_target.is_some();
    let cols = OptionalColumns {
        orientation,
        sigma: sigma.is_some(),
        ..OptionalColumns::NONE
    };
    let mut t = MeasurementTable::new(model.nq(), cols);
    let n = Normal::new(0.0, 1.0).unwrap();
    for (k, q) in configs.iter().enumerate() {
        let (p, r) = truth.target(model, q);
        let pm = p + Vector3::new(n.sample(rng), n.sample(rng), n.sample(rng)) * noise_m;
        let o = orientation.then(|| {
            let w = Vector3::new(n.sample(rng), n.sample(rng), n.sample(rng)) * noise_rad;
            let rm = exp_twist(&Vector6::new(w.x, w.y, w.z, 0.0, 0.0, 0.0))
                .rotation
                .matrix()
                * r;
            let uq = nalgebra::UnitQuaternion::from_rotation_matrix(
                &nalgebra::Rotation3::from_matrix_unchecked(rm),
            );
            [uq.w, uq.i, uq.j, uq.k]
        });
        t.push_row(&Row {
            pose: k as i64,
            q,
            position: [pm.x, pm.y, pm.z],
            orientation: o,
            sigma,
            ..Row::default()
        })
        .unwrap();
    }
    t
}

/// A seeded RNG; the seed is printed so that a failure can be reproduced.
pub fn rng(seed: u64) -> StdRng {
    eprintln!("seed {seed}");
    StdRng::seed_from_u64(seed)
}

/// A seed drawn for this run (from the clock), or `ROBOCAL_TEST_SEED` when set; printed with `what`
/// so that a failure can be reproduced (`ROBOCAL_TEST_SEED=N cargo test …`).
pub fn run_seed(what: &str) -> u64 {
    let seed = std::env::var("ROBOCAL_TEST_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| {
            let t = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_nanos() as u64);
            // Mix the clock so that tests started in the same instant differ.
            t ^ (what.len() as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15)
        });
    eprintln!("{what}: seed {seed} (ROBOCAL_TEST_SEED={seed} reproduces it)");
    seed
}

/// The same hidden robot seen from another tracker placement: a new `T_tracker_base` 2–4 m away at
/// an arbitrary rotation, every robot parameter and the target unchanged.
pub fn moved_tracker(truth: &Truth, rng: &mut StdRng) -> Truth {
    let rot = unit(rng) * (3.0 * rng.random::<f64>());
    let trans = unit(rng) * (2.0 + 2.0 * rng.random::<f64>());
    Truth {
        t_tracker_base: exp_twist(&Vector6::new(rot.x, rot.y, rot.z, 0.0, 0.0, 0.0))
            * Pose::from_parts(trans.into(), nalgebra::Rotation3::identity()),
        ..truth.clone()
    }
}

/// `table` with a `campaign` column of value `id` on every row.
pub fn with_campaign(table: &MeasurementTable, id: i64) -> MeasurementTable {
    let mut t = table.clone();
    t.campaign = Some(vec![id; t.len()]);
    t
}

/// The rows of `b` appended to those of `a` (same columns).
pub fn concat(a: &MeasurementTable, b: &MeasurementTable) -> MeasurementTable {
    let mut t = a.clone();
    for r in 0..b.len() {
        t.push_row(&b.row(r)).unwrap();
    }
    t
}

/// `|δₖ|/σₖ ≤ ‖J D δ‖/σ̂` for every parameter: the distance of two solutions in the fit's noise
/// metric, which bounds each parameter's difference in its standard deviations.
pub fn distance_in_sigmas(a: &calib::fit::Calibration, b: &calib::fit::Calibration) -> f64 {
    let delta = a.params.difference(&a.layout, &b.params);
    a.subspace.step_in_sigmas(&delta, a.report.chi2_per_dof)
}

/// The stopping rule's bound on a solution's distance from the exact minimum, `√pred` with
/// `pred ≤ decrease_tol + relative_decrease_tol · χ²` (noise units), in units of `σ̂`.
pub fn stopping_bound(
    c: &calib::fit::Calibration,
    options: &calib::fit::CalibrationOptions,
) -> f64 {
    let chi2 = c.report.after.solver.cost_final;
    (options.lm.decrease_tol + options.lm.relative_decrease_tol * chi2).sqrt()
        / c.report.chi2_per_dof.sqrt()
}

/// Compliance at joints 2 and 4 (12,000 and 8,000 N m/rad) and backlash at joints 1 and 3 (0.4 and
/// 0.3 mrad, by the direction of approach): the `[effects]` of the diagnose benchmark's data.
pub const COMPLIANCE_AND_BACKLASH: &str = "[effects.compliance]\n\
    stiffness_nm_per_rad = [inf, 1.2e4, inf, 8e3, inf, inf, inf]\n\
    [effects.backlash]\ndead_band_rad = [4e-4, 0.0, 3e-4, 0.0, 0.0, 0.0, 0.0]\nmode = \"direction\"\n";

/// `poses` poses of the iiwa 7 with drawn geometric errors (scenarios/iiwa7_kinematic.toml) and
/// `effects` (TOML), simulated by sim with `seed`: the robot and the measurement table.
pub fn simulate_iiwa7(effects: &str, seed: u64, poses: usize) -> (Model, MeasurementTable) {
    use sim::scenario::{Overrides, Scenario};
    let base = include_str!("../../../scenarios/iiwa7_kinematic.toml");
    let text = format!("{base}\n{effects}");
    let sc = Scenario::parse(&text, "calib test", std::path::Path::new(".")).unwrap();
    let res = sc
        .resolve(&Overrides {
            seed: Some(seed),
            poses: Some(poses),
            noise: None,
        })
        .unwrap();
    static RUN: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let dir = std::env::temp_dir().join(format!(
        "robocal_calib_test_{}_{}",
        std::process::id(),
        RUN.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
    ));
    sim::generate::generate(&res, &dir, None).unwrap();
    let table = sim::measurement_table::read(&dir.join("measurements.parquet")).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
    (res.model, table)
}
