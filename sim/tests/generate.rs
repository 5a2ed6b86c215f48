//! The generator: tracker noise statistics, determinism (also across thread counts), refusal of bad
//! scenarios, and the content of the written files checked against independent computations.
//!
//! Statistical bounds: every test statistic below is (to a very good approximation, N ≥ 10⁵) normal
//! under the stated model, and is accepted within ±Z standard deviations, Z = 4.89: the two-sided
//! significance is α = 1e-6 per check, so a correct implementation fails a run with probability below
//! 1e-5 over all checks; the seeds are fixed anyway, so the outcome is reproducible.

mod common;

use nalgebra::{Point3, UnitQuaternion, Vector3};
use rand::SeedableRng;
use rand::rngs::Xoshiro256PlusPlus;
use sim::campaign::rng_for;
use sim::generate::{self, parquet_column_names};
use sim::lie::{Pose, pose_from, rotation_from_rpy};
use sim::scenario::{Overrides, Scenario};
use sim::tracker::{NoiseModel, Tracker};
use std::path::{Path, PathBuf};

/// Two-sided normal quantile for α = 1e-6.
const Z: f64 = 4.89;

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("robocal_gen_{}_{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn scenario_path(name: &str) -> PathBuf {
    common::repo_root().join("scenarios").join(name)
}

/// Flange poses at several distances and directions from a tracker at the origin, one looking
/// straight up (the degenerate case of the transverse basis).
fn flange_poses() -> Vec<Pose> {
    [
        (Vector3::new(1.5, 0.0, 0.0), [0.0, 0.0, 0.0]),
        (Vector3::new(-1.0, 2.5, 0.8), [0.3, -0.2, 1.0]),
        (Vector3::new(3.0, -4.0, -1.0), [-1.0, 0.4, 2.0]),
        (Vector3::new(0.0, 0.0, 2.0), [0.0, 0.0, 0.0]),
    ]
    .into_iter()
    .map(|(p, rpy)| pose_from(rotation_from_rpy(rpy[0], rpy[1], rpy[2]), p))
    .collect()
}

/// The test's own σ law (not the code's): σ = a + b d.
fn sigma(a: f64, b: f64, d: f64) -> f64 {
    a + b * d
}

#[test]
fn tracker_noise_has_the_stated_spherical_distribution() {
    let noise = NoiseModel {
        radial_a_m: 5e-6,
        radial_b_m_per_m: 1e-6,
        transverse_a_m: 7.5e-6,
        transverse_b_m_per_m: 3e-6,
        orientation_sigma_rad: 1e-3,
        outlier_rate: 0.0,
        outlier_magnitude_m: 1e-3,
    };
    let scale = 1.7;
    let tracker = Tracker::new([0.0; 3], [0.0; 3], [0.0, 0.0, 0.05], noise, scale)
        .unwrap()
        .with_six_dof([0.1, 0.2, -0.3]);
    let poses = flange_poses();
    let n = 300_000usize;
    // Sums of the standardised components: radial z_r, transverse z_1, z_2 on a basis built here (Gram–
    // Schmidt of the x axis, or y for lines of sight near x), orientation z_o (3 per sample).
    let (mut s_r, mut s_1, mut s_2) = (0.0, 0.0, 0.0);
    let (mut ss_r, mut ss_1, mut ss_2, mut ss_o) = (0.0, 0.0, 0.0, 0.0);
    let (mut c_r1, mut c_r2, mut c_12) = (0.0, 0.0, 0.0);
    let mut q4_r = 0.0;
    for k in 0..n {
        let flange = &poses[k % poses.len()];
        let mut rng = rng_for(99, 7, k as u64);
        let r = tracker.measure(flange, &mut rng);
        let p = (flange * Point3::new(0.0, 0.0, 0.05)).coords;
        assert!((Vector3::from(r.p_true) - p).amax() < 1e-15);
        let d = p.norm();
        let u = p / d;
        let seed_axis = if u.x.abs() < 0.9 {
            Vector3::x()
        } else {
            Vector3::y()
        };
        let b1 = (seed_axis - u * u.dot(&seed_axis)).normalize();
        let b2 = u.cross(&b1);
        let eps = Vector3::from(r.p_measured) - p;
        assert!((eps - Vector3::from(r.noise)).amax() < 1e-15);
        let sr = scale * sigma(5e-6, 1e-6, d);
        let st = scale * sigma(7.5e-6, 3e-6, d);
        let (zr, z1, z2) = (eps.dot(&u) / sr, eps.dot(&b1) / st, eps.dot(&b2) / st);
        s_r += zr;
        s_1 += z1;
        s_2 += z2;
        ss_r += zr * zr;
        ss_1 += z1 * z1;
        ss_2 += z2 * z2;
        c_r1 += zr * z1;
        c_r2 += zr * z2;
        c_12 += z1 * z2;
        q4_r += zr.powi(4);
        // The sigma column: RMS of the three axis σ at the measured distance.
        let dm = Vector3::from(r.p_measured).norm();
        let expect = scale
            * ((sigma(5e-6, 1e-6, dm).powi(2) + 2.0 * sigma(7.5e-6, 3e-6, dm).powi(2)) / 3.0)
                .sqrt();
        assert!(
            (r.sigma_m - expect).abs() < 1e-15,
            "sigma column {} vs {expect}",
            r.sigma_m
        );
        // Orientation: δ = log(q_meas q_true⁻¹) ~ N(0, (s σ_o)² I).
        let q = |a: [f64; 4]| {
            UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(a[0], a[1], a[2], a[3]))
        };
        let delta = (q(r.orientation_measured) * q(r.orientation_true).inverse()).scaled_axis();
        ss_o += delta.norm_squared() / (scale * 1e-3f64).powi(2);
        // The true orientation is R_flange · R_flange_probe (tracker frame = base frame here).
        let r_true = flange.rotation.matrix() * rotation_from_rpy(0.1, 0.2, -0.3);
        assert!((q(r.orientation_true).to_rotation_matrix().matrix() - r_true).amax() < 1e-12);
    }
    let nf = n as f64;
    println!(
        "N = {n}: var ratios radial {:.5}, t1 {:.5}, t2 {:.5}, orientation {:.5} (±{:.5}); \
         means {:.2e} {:.2e} {:.2e}; correlations {:.2e} {:.2e} {:.2e}; E z⁴ {:.4}",
        ss_r / nf,
        ss_1 / nf,
        ss_2 / nf,
        ss_o / (3.0 * nf),
        Z * (2.0 / nf).sqrt(),
        s_r / nf,
        s_1 / nf,
        s_2 / nf,
        c_r1 / nf,
        c_r2 / nf,
        c_12 / nf,
        q4_r / nf
    );
    // Means: Σ z ~ N(0, N).
    for (name, s) in [
        ("radial", s_r),
        ("transverse 1", s_1),
        ("transverse 2", s_2),
    ] {
        assert!(
            s.abs() < Z * nf.sqrt(),
            "{name} mean: Σz = {s}, bound {}",
            Z * nf.sqrt()
        );
    }
    // Variances: Σ z² ~ χ²(N) ≈ N(N, 2N).
    for (name, s) in [
        ("radial", ss_r),
        ("transverse 1", ss_1),
        ("transverse 2", ss_2),
    ] {
        assert!(
            (s - nf).abs() < Z * (2.0 * nf).sqrt(),
            "{name} variance ratio {} (bound ±{})",
            s / nf,
            Z * (2.0 / nf).sqrt()
        );
    }
    // Orientation: Σ |δ|²/σ² ~ χ²(3N).
    assert!(
        (ss_o - 3.0 * nf).abs() < Z * (6.0 * nf).sqrt(),
        "orientation variance ratio {}",
        ss_o / (3.0 * nf)
    );
    // Independence: Σ zᵢ zⱼ has mean 0 and variance N for independent unit normals.
    for (name, c) in [("radial-t1", c_r1), ("radial-t2", c_r2), ("t1-t2", c_12)] {
        assert!(c.abs() < Z * nf.sqrt(), "{name} correlation {}", c / nf);
    }
    // Gaussian shape: E z⁴ = 3, Var z⁴ = 96.
    assert!(
        (q4_r - 3.0 * nf).abs() < Z * (96.0 * nf).sqrt(),
        "radial kurtosis {}",
        q4_r / nf
    );
}

#[test]
fn outliers_come_at_the_stated_rate_with_the_stated_size_in_uniform_directions() {
    let rate = 0.01;
    let magnitude = 1e-3;
    let noise = NoiseModel {
        outlier_rate: rate,
        outlier_magnitude_m: magnitude,
        ..NoiseModel::default()
    };
    let tracker = Tracker::new([2.0, 0.5, -0.3], [0.0, 0.0, 1.0], [0.0; 3], noise, 1.0).unwrap();
    let flange = pose_from(
        rotation_from_rpy(0.0, 0.0, 0.0),
        Vector3::new(0.5, 0.2, 0.7),
    );
    let n = 300_000usize;
    let mut count = 0usize;
    let mut sum_dir = Vector3::zeros();
    for k in 0..n {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(k as u64 ^ 0xabcdef);
        let r = tracker.measure(&flange, &mut rng);
        if r.outlier {
            count += 1;
            let e = Vector3::from(r.noise);
            // Gaussian part: σ ≤ 16 µm per axis here, so |e| lies within 1 mm ± 6 · 3 · 16 µm.
            assert!(
                (e.norm() - magnitude).abs() < 3e-4,
                "outlier of {} m",
                e.norm()
            );
            sum_dir += e.normalize();
        } else {
            assert!(Vector3::from(r.noise).norm() < 2e-4);
        }
    }
    // Binomial(N, p): mean Np, sd sqrt(Np(1 − p)).
    let (nf, c) = (n as f64, count as f64);
    let sd = (nf * rate * (1.0 - rate)).sqrt();
    println!(
        "{count} outliers in {n} (expected {} ± {:.0} at Z = {Z})",
        nf * rate,
        Z * sd
    );
    assert!(
        (c - nf * rate).abs() < Z * sd,
        "{count} outliers, expected {} ± {}",
        nf * rate,
        Z * sd
    );
    // Uniform directions: each component of a uniform unit vector has mean 0 and variance 1/3 (the
    // Gaussian part shifts it by < 2 %, far below the bound).
    for k in 0..3 {
        assert!(
            sum_dir[k].abs() < Z * (c / 3.0).sqrt() + 0.02 * c,
            "direction bias {}",
            sum_dir[k] / c
        );
    }
}

fn resolve(name: &str, overrides: Overrides) -> sim::scenario::Resolved {
    Scenario::load(&scenario_path(name))
        .unwrap()
        .resolve(&overrides)
        .unwrap()
}

fn generate_in_pool(threads: usize, res: &sim::scenario::Resolved, dir: &Path) {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(|| generate::generate(res, dir, None).unwrap());
}

fn files(dir: &Path) -> Vec<Vec<u8>> {
    ["measurements.parquet", "truth.parquet", "truth.json"]
        .iter()
        .map(|f| std::fs::read(dir.join(f)).unwrap())
        .collect()
}

#[test]
fn same_seed_same_bytes_across_thread_counts_and_a_new_seed_changes_them() {
    let ov = Overrides {
        poses: Some(300),
        ..Overrides::default()
    };
    let res = resolve("iiwa7_all.toml", ov);
    let (a, b, c) = (temp_dir("det_a"), temp_dir("det_b"), temp_dir("det_c"));
    generate_in_pool(1, &res, &a);
    generate_in_pool(2, &res, &b);
    let fa = files(&a);
    assert_eq!(fa, files(&b), "1 thread and 2 threads differ");
    // Again from a fresh parse: nothing depends on state left over.
    let res2 = resolve("iiwa7_all.toml", ov);
    generate_in_pool(2, &res2, &c);
    assert_eq!(fa, files(&c));
    // Another seed: different robot draws and noise.
    let res3 = resolve(
        "iiwa7_all.toml",
        Overrides {
            seed: Some(2),
            ..ov
        },
    );
    generate_in_pool(2, &res3, &c);
    let fc = files(&c);
    assert_ne!(fa[0], fc[0]);
    assert_ne!(fa[1], fc[1]);
    for d in [a, b, c] {
        let _ = std::fs::remove_dir_all(d);
    }
}

/// The contract's column names for `nq` joints.
fn contract_columns(nq: usize) -> Vec<String> {
    let mut v: Vec<String> = vec!["pose".into()];
    v.extend((1..=nq).map(|j| format!("q{j}")));
    v.extend(
        [
            "x", "y", "z", "qw", "qx", "qy", "qz", "t", "temp", "payload", "sigma",
        ]
        .map(String::from),
    );
    v.extend((1..=nq).map(|j| format!("dir{j}")));
    v
}

#[test]
fn written_files_agree_with_independent_computations_and_hold_no_truth_in_measurements() {
    let res = resolve(
        "iiwa7_all.toml",
        Overrides {
            poses: Some(120),
            ..Overrides::default()
        },
    );
    let dir = temp_dir("content");
    generate::generate(&res, &dir, None).unwrap();
    // Measurements: contract columns only.
    let names = parquet_column_names(&dir.join("measurements.parquet")).unwrap();
    let allowed = contract_columns(7);
    for n in &names {
        assert!(
            allowed.contains(n),
            "measurements.parquet has a non-contract column '{n}'"
        );
    }
    for required in [
        "pose", "q1", "q7", "x", "y", "z", "t", "temp", "dir1", "dir7", "payload", "sigma",
    ] {
        assert!(names.iter().any(|n| n == required), "missing {required}");
    }
    let table = sim::measurement_table::read(&dir.join("measurements.parquet")).unwrap();
    assert_eq!(table.len(), 120);
    let model = sim::robots::load_builtin("iiwa7").unwrap();
    let warnings =
        sim::measurement_table::check_against_model(&table, &model, Path::new("m")).unwrap();
    assert!(warnings.is_empty(), "{warnings:?}");

    // Truth rows, read through the generic Arrow reader.
    let f = std::fs::File::open(dir.join("truth.parquet")).unwrap();
    let reader = parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(f)
        .unwrap()
        .build()
        .unwrap();
    let batches: Vec<_> = reader.map(|b| b.unwrap()).collect();
    let batch = arrow_select_concat(&batches);
    let col = |name: &str| -> Vec<f64> {
        use arrow_array::cast::AsArray;
        batch
            .column_by_name(name)
            .unwrap_or_else(|| panic!("no column {name}"))
            .as_primitive::<arrow_array::types::Float64Type>()
            .values()
            .to_vec()
    };
    // T_tracker_base from truth.json's matrix (not from the code's Tracker).
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("truth.json")).unwrap()).unwrap();
    let m = &json["tracker"]["T_tracker_base"]["matrix"];
    let t = |r: usize, c: usize| m[r][c].as_f64().unwrap();
    assert_eq!(json["software"]["version"], env!("CARGO_PKG_VERSION"));
    assert_eq!(json["seed"], 1);
    let mut data = sim::Data::new(&model);
    let p_flange = Vector3::new(0.0, 0.0, 0.05);
    let (px, py, pz) = (col("p_base_x"), col("p_base_y"), col("p_base_z"));
    let (tx, ty, tz) = (col("p_tracker_x"), col("p_tracker_y"), col("p_tracker_z"));
    let (nx, ny, nz) = (col("noise_x"), col("noise_y"), col("noise_z"));
    let (mx, my, mz) = (
        col("p_nominal_base_x"),
        col("p_nominal_base_y"),
        col("p_nominal_base_z"),
    );
    let sum3 = |a: &str| {
        [
            col(&format!("{a}_x")),
            col(&format!("{a}_y")),
            col(&format!("{a}_z")),
        ]
    };
    // Every registered effect has its columns; those of the scenario's effects (the keys of
    // truth.json's `effects`) must each move the target.
    let keys: Vec<&str> = sim::effects::EffectId::ALL
        .iter()
        .map(|id| id.key())
        .collect();
    let effects: Vec<[Vec<f64>; 3]> = keys.iter().map(|k| sum3(k)).collect();
    let present: Vec<&String> = json["effects"]
        .as_object()
        .unwrap()
        .iter()
        .filter(|(_, v)| !v.is_null())
        .map(|(k, _)| k)
        .collect();
    assert!(present.len() >= 4, "{present:?}");
    for r in 0..table.len() {
        let pb = [px[r], py[r], pz[r]];
        // p_tracker = T_tracker_base p_base.
        for i in 0..3 {
            let v = t(i, 0) * pb[0] + t(i, 1) * pb[1] + t(i, 2) * pb[2] + t(i, 3);
            assert!((v - [tx[r], ty[r], tz[r]][i]).abs() < 1e-12);
        }
        // Measured = true + noise.
        let meas = table.position[r];
        assert!((meas[0] - tx[r] - nx[r]).abs() < 1e-15);
        assert!((meas[1] - ty[r] - ny[r]).abs() < 1e-15);
        assert!((meas[2] - tz[r] - nz[r]).abs() < 1e-15);
        // The nominal target is the nominal forward kinematics at the commanded q.
        let f = sim::flange_pose(&model, &mut data, table.q_row(r));
        let pn = (f * Point3::from(p_flange)).coords;
        assert!((pn - Vector3::new(mx[r], my[r], mz[r])).amax() < 1e-12);
        // Contributions add up to the deviation from nominal.
        for i in 0..3 {
            let s: f64 = effects.iter().map(|e| e[i][r]).sum();
            assert!((pb[i] - [mx[r], my[r], mz[r]][i] - s).abs() < 1e-12);
        }
        // Every effect is on in this scenario and moves the target by at least 1 nm somewhere.
    }
    for (k, e) in effects.iter().enumerate() {
        if !present.iter().any(|p| p.as_str() == keys[k]) {
            assert!(e.iter().all(|c| c.iter().all(|v| *v == 0.0)), "{}", keys[k]);
            continue;
        }
        let rms = ((0..table.len())
            .map(|r| e[0][r].powi(2) + e[1][r].powi(2) + e[2][r].powi(2))
            .sum::<f64>()
            / table.len() as f64)
            .sqrt();
        assert!(rms > 1e-6, "effect {} RMS {rms}", keys[k]);
    }
    // The campaign respected the reachability filter (checked with the nominal model here).
    for r in 0..table.len() {
        sim::forward_kinematics(&model, &mut data, table.q_row(r));
        for jp in data.joint_poses.iter().skip(1) {
            assert!(jp.translation.z > 0.05);
        }
        let p = (data.flange * Point3::from(p_flange)).coords;
        assert!(p.z > 0.05 && p.x.hypot(p.y) >= 0.10);
        for (j, q) in model.joints().iter().zip(table.q_row(r)) {
            let l = j.limits.unwrap();
            assert!(*q >= l.lower + 0.05 - 1e-12 && *q <= l.upper - 0.05 + 1e-12);
        }
    }
    // Warm-up: temp = 20 + 10 (1 − exp(−t/1800)), t = 15 s per pose.
    let temp = table.temp.as_ref().unwrap();
    let ts = table.t.as_ref().unwrap();
    for r in 0..table.len() {
        assert_eq!(ts[r], 15.0 * r as f64);
        assert!((temp[r] - (20.0 + 10.0 * (1.0 - (-ts[r] / 1800.0).exp()))).abs() < 1e-12);
    }
    let _ = std::fs::remove_dir_all(dir);
}

fn arrow_select_concat(b: &[arrow_array::RecordBatch]) -> arrow_array::RecordBatch {
    assert_eq!(b.len(), 1, "one row group expected for a small file");
    b[0].clone()
}

fn bad(text: &str, dir: &Path) -> String {
    let path = dir.join("bad.toml");
    std::fs::write(&path, text).unwrap();
    match Scenario::load(&path).and_then(|s| s.resolve(&Overrides::default())) {
        Ok(_) => panic!("accepted:\n{text}"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn bad_scenarios_are_refused_naming_the_key() {
    let dir = temp_dir("bad");
    let e = bad(
        "[robot]\nname = \"iiwa7\"\n[effects.compliance]\nstifness_nm_per_rad = 5e4\n",
        &dir,
    );
    assert!(
        e.contains("bad.toml") && e.contains("stifness_nm_per_rad") && e.contains("line 4"),
        "{e}"
    );
    assert!(e.contains("unknown field"), "{e}");
    let e = bad(
        "[robot]\nname = \"iiwa7\"\n[effects.compliance]\nstiffness_nm_per_rad = [1e4, 1e4, -5e3, 1e4, 1e4, 1e4, 1e4]\n",
        &dir,
    );
    assert!(
        e.contains("effects.compliance.stiffness_nm_per_rad[2]") && e.contains("-5000"),
        "{e}"
    );
    let e = bad(
        "[robot]\nname = \"iiwa7\"\n[effects.compliance]\nstiffness_nm_per_rad = { normal = [0.0, 1e4] }\n",
        &dir,
    );
    assert!(
        e.contains("effects.compliance.stiffness_nm_per_rad["),
        "{e}"
    );
    let e = bad(
        "[robot]\nname = \"iiwa7\"\n[tracker]\nradial_sigma_a_m = \"five\"\n",
        &dir,
    );
    assert!(
        e.contains("radial_sigma_a_m") && e.contains("line 4"),
        "{e}"
    );
    let e = bad(
        "[robot]\nname = \"iiwa7\"\n[effects.backlash]\ndead_band_rad = 1.0\n",
        &dir,
    );
    assert!(
        e.contains("effects.backlash.dead_band_rad[0]") && e.contains("degrees"),
        "{e}"
    );
    let e = bad(
        "[robot]\nname = \"iiwa7\"\n[effects.kinematic]\nzero_offset_rad = [0.0, 0.0]\n",
        &dir,
    );
    assert!(
        e.contains("effects.kinematic.zero_offset_rad") && e.contains("2 entries, expected 7"),
        "{e}"
    );
    let e = bad(
        "[robot]\nname = \"iiwa7\"\n[truth]\nmodel = \"rapier\"\n",
        &dir,
    );
    assert!(
        e.contains("truth.model") && e.contains("[effects.compliance]"),
        "{e}"
    );
    let e = bad(
        "[robot]\nname = \"iiwa7\"\n[tracker]\nxyz_m = [2500.0, 0.0, 0.0]\n",
        &dir,
    );
    assert!(
        e.contains("tracker.xyz_m") && e.contains("millimetres"),
        "{e}"
    );
    let e = bad(
        "[robot]\nname = \"iiwa7\"\n[campaign]\nsampling = \"grid\"\n",
        &dir,
    );
    assert!(e.contains("campaign.grid"), "{e}");
    // Compliance on a robot without inertials: a tiny massless URDF beside the scenario.
    std::fs::write(
        dir.join("massless.urdf"),
        r#"<robot name="massless"><link name="base"/>
        <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 1 0"/>
          <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
        <link name="l1"/>
        <joint name="tool" type="fixed"><parent link="l1"/><child link="tip"/><origin xyz="0.5 0 0"/></joint>
        <link name="tip"/></robot>"#,
    )
    .unwrap();
    let e = bad(
        "[robot]\nurdf = \"massless.urdf\"\n[effects.compliance]\nstiffness_nm_per_rad = 1e4\n",
        &dir,
    );
    assert!(
        e.contains("effects.compliance") && e.contains("inertial"),
        "{e}"
    );
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn draws_follow_the_seed_and_fixed_values_do_not() {
    let a = resolve("iiwa7_all.toml", Overrides::default());
    let b = resolve("iiwa7_all.toml", Overrides::default());
    let c = resolve(
        "iiwa7_all.toml",
        Overrides {
            seed: Some(77),
            ..Overrides::default()
        },
    );
    assert_eq!(a.effects, b.effects);
    let k = |r: &sim::scenario::Resolved| {
        r.effects
            .compliance
            .as_ref()
            .unwrap()
            .stiffness_nm_per_rad()
            .to_vec()
    };
    assert_ne!(k(&a), k(&c));
    // Drawn stiffness lies in the stated uniform ranges.
    let ranges = [
        (1.2e4, 1.8e4),
        (1.2e4, 1.8e4),
        (8e3, 1.2e4),
        (8e3, 1.2e4),
        (6e3, 9e3),
        (4e3, 6e3),
        (4e3, 6e3),
    ];
    for (v, (lo, hi)) in k(&c).iter().zip(ranges) {
        assert!(*v >= lo && *v <= hi);
    }
    // Fixed values stay fixed: the dead band is 1 arc-min whatever the seed.
    let band = |r: &sim::scenario::Resolved| {
        r.effects
            .backlash
            .as_ref()
            .unwrap()
            .dead_band_rad()
            .to_vec()
    };
    assert_eq!(band(&a), vec![2.909e-4; 7]);
    assert_eq!(band(&c), vec![2.909e-4; 7]);
}

#[test]
fn iso9283_campaign_visits_the_five_points_with_the_seed_orientation() {
    let dir = temp_dir("iso");
    let text = "[robot]\nname = \"iiwa7\"\n[campaign]\nposes = 10\n[campaign.iso9283]\ncube_side_m = 0.3\n\
                seed_q = [0.0, 0.4, 0.0, -1.6, 0.0, 1.1, 0.0]\n";
    std::fs::write(dir.join("iso.toml"), text).unwrap();
    let res = Scenario::load(&dir.join("iso.toml"))
        .unwrap()
        .resolve(&Overrides::default())
        .unwrap();
    let plan = generate::plan_of(&res).unwrap();
    assert_eq!(plan.n_poses, 10);
    let model = &res.model;
    let mut data = sim::Data::new(model);
    let pf = Point3::new(0.0, 0.0, 0.05);
    let seed = [0.0, 0.4, 0.0, -1.6, 0.0, 1.1, 0.0];
    let t0 = sim::flange_pose(model, &mut data, &seed);
    let c = (t0 * pf).coords;
    // Hand-derived points: centre, and ±0.4 L along (1,1,1) and (1,−1,−1)... from the corners.
    let h = 0.4 * 0.3;
    let expect = [
        c,
        c + Vector3::new(-h, -h, -h),
        c + Vector3::new(h, -h, -h),
        c + Vector3::new(h, h, h),
        c + Vector3::new(-h, h, h),
    ];
    for k in 0..10 {
        let f = sim::flange_pose(model, &mut data, plan.q_row(k));
        assert!(
            ((f * pf).coords - expect[k % 5]).norm() < 1e-10,
            "P{}",
            k % 5 + 1
        );
        assert!((f.rotation.matrix() - t0.rotation.matrix()).amax() < 1e-10);
    }
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn grid_and_file_campaigns_use_the_stated_joint_positions() {
    let dir = temp_dir("grid_file");
    // Grid: 2 values on joints 2 and 4 (limits ±2.0944 shrunk by 0.1), 1 (the midpoint, 0) elsewhere.
    let text = "[robot]\nname = \"iiwa7\"\n[campaign]\njoint_margin_rad = 0.1\nfloor_z_m = -10.0\n\
                min_axis_distance_m = 0.0\n[campaign.grid]\npoints_per_joint = [1, 2, 1, 2, 1, 1, 1]\n";
    std::fs::write(dir.join("grid.toml"), text).unwrap();
    let res = Scenario::load(&dir.join("grid.toml"))
        .unwrap()
        .resolve(&Overrides::default())
        .unwrap();
    let plan = generate::plan_of(&res).unwrap();
    let e = 2.0943951023931953 - 0.1;
    let expect = [[-e, -e], [-e, e], [e, -e], [e, e]];
    assert_eq!(plan.n_poses, 4);
    for (k, (a, b)) in expect.iter().map(|v| (v[0], v[1])).enumerate() {
        let q = plan.q_row(k);
        assert!(
            (q[1] - a).abs() < 1e-15 && (q[3] - b).abs() < 1e-15,
            "{q:?}"
        );
        for i in [0, 2, 4, 5, 6] {
            assert!(q[i].abs() < 1e-15);
        }
    }
    // File: a pose id reused at other joint values is refused, naming both rows.
    let text = "[robot]\nname = \"iiwa7\"\n[campaign]\nposes = 5\nrepeats = 2\n[campaign.file]\npath = \"poses.csv\"\n";
    std::fs::write(dir.join("file.toml"), text).unwrap();
    let reused = "pose,q1,q2,q3,q4,q5,q6,q7,x,y,z\n\
                  7,0.1,0.2,0.3,0.4,0.5,0.6,0.7,1,2,3\n\
                  7,9,9,9,9,9,9,9,1,2,3\n";
    std::fs::write(dir.join("poses.csv"), reused).unwrap();
    let reused_res = Scenario::load(&dir.join("file.toml"))
        .unwrap()
        .resolve(&Overrides::default())
        .unwrap();
    let err = generate::plan_of(&reused_res).unwrap_err().to_string();
    assert!(
        err.contains("poses.csv") && err.contains("row 2") && err.contains("in row 1"),
        "{err}"
    );
    // The q of the first row of each pose id (repeats share it), in order of appearance, cycled to
    // 5 poses.
    let csv = "pose,q1,q2,q3,q4,q5,q6,q7,x,y,z\n\
               7,0.1,0.2,0.3,0.4,0.5,0.6,0.7,1,2,3\n\
               7,0.1,0.2,0.3,0.4,0.5,0.6,0.7,1,2,3\n\
               3,-0.1,-0.2,-0.3,-0.4,-0.5,-0.6,-0.7,1,2,3\n";
    std::fs::write(dir.join("poses.csv"), csv).unwrap();
    let res = Scenario::load(&dir.join("file.toml"))
        .unwrap()
        .resolve(&Overrides::default())
        .unwrap();
    let plan = generate::plan_of(&res).unwrap();
    assert_eq!((plan.n_poses, plan.len()), (5, 10));
    let a = [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7];
    let b = a.map(|v: f64| -v);
    for (k, want) in [a, b, a, b, a].iter().enumerate() {
        assert_eq!(plan.q_row(2 * k), want);
        assert_eq!(plan.q_row(2 * k + 1), want);
    }
    // A joint program (no x, y, z) with context columns: each pose takes the file's payload,
    // temperature, time and directions (cycled with the poses; a repeat adds seconds_per_repeat,
    // 1 s by default), not the campaign's rules.
    let csv = "pose,q1,q2,q3,q4,q5,q6,q7,payload,temp,t,dir1,dir2,dir3,dir4,dir5,dir6,dir7\n\
               7,0.1,0.2,0.3,0.4,0.5,0.6,0.7,2.5,31.5,100,1,-1,1,-1,1,-1,0\n\
               3,-0.1,-0.2,-0.3,-0.4,-0.5,-0.6,-0.7,0,18,7,-1,-1,-1,1,1,1,1\n";
    std::fs::write(dir.join("poses.csv"), csv).unwrap();
    let res = Scenario::load(&dir.join("file.toml"))
        .unwrap()
        .resolve(&Overrides::default())
        .unwrap();
    let plan = generate::plan_of(&res).unwrap();
    assert_eq!((plan.n_poses, plan.len()), (5, 10));
    for k in 0..5 {
        let (mass, temp, t, dir): (f64, f64, f64, [i8; 7]) = if k % 2 == 0 {
            (2.5, 31.5, 100.0, [1, -1, 1, -1, 1, -1, 0])
        } else {
            (0.0, 18.0, 7.0, [-1, -1, -1, 1, 1, 1, 1])
        };
        for r in [2 * k, 2 * k + 1] {
            assert_eq!(plan.payload_kg[r], mass, "row {r}");
            assert_eq!(plan.temp_c[r], temp, "row {r}");
            assert_eq!(plan.t_s[r], t + (r % 2) as f64, "row {r}");
            assert_eq!(plan.dir_row(r), Some(&dir[..]), "row {r}");
        }
    }
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn six_dof_probe_adds_orientation_close_to_the_truth() {
    let dir = temp_dir("sixdof");
    let text = "seed = 4\n[robot]\nname = \"iiwa7\"\n[campaign]\nposes = 200\n[tracker]\nsix_dof = true\n\
                orientation_sigma_rad = 1e-4\nprobe_rpy_rad = [0.0, 0.5, 0.0]\n";
    std::fs::write(dir.join("s.toml"), text).unwrap();
    let res = Scenario::load(&dir.join("s.toml"))
        .unwrap()
        .resolve(&Overrides::default())
        .unwrap();
    generate::generate(&res, &dir.join("out"), None).unwrap();
    let table = sim::measurement_table::read(&dir.join("out/measurements.parquet")).unwrap();
    let o = table.orientation.as_ref().expect("qw..qz columns");
    // Nominal robot (no effects): the true probe orientation is R_tracker_base R_base_flange(q) R_probe,
    // computed here from truth.json's matrix and the nominal kinematics.
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("out/truth.json")).unwrap())
            .unwrap();
    let m = &json["tracker"]["T_tracker_base"]["matrix"];
    let r_tb = nalgebra::Matrix3::from_fn(|r, c| m[r][c].as_f64().unwrap());
    let mut data = sim::Data::new(&res.model);
    let mut ss = 0.0;
    for (r, qo) in o.iter().enumerate() {
        let f = sim::flange_pose(&res.model, &mut data, table.q_row(r));
        let r_true = r_tb * f.rotation.matrix() * rotation_from_rpy(0.0, 0.5, 0.0);
        let q = nalgebra::Quaternion::new(qo[0], qo[1], qo[2], qo[3]);
        let rm = UnitQuaternion::from_quaternion(q).to_rotation_matrix();
        let rt = nalgebra::Rotation3::from_matrix_unchecked(r_true);
        ss += (rm * rt.inverse()).scaled_axis().norm_squared() / 1e-8;
    }
    // Σ|δ|²/σ² ~ χ²(3N), N = 200: mean 600, sd √1200.
    let nf = 3.0 * table.len() as f64;
    assert!(
        (ss - nf).abs() < Z * (2.0 * nf).sqrt(),
        "orientation χ² {ss} for {nf} dof"
    );
    let _ = std::fs::remove_dir_all(dir);
}

/// Streaming (issue 15): the files do not depend on how the rows are chunked, on the number of
/// threads, or on how the summary's median is selected (in memory, or by the radix selection that
/// reads `truth.parquet` back); and they are those of the in-memory path, row for row. A campaign
/// with repeats that straddle chunks (the `move` direction state and the payload draw carry over),
/// outliers and a 6-DoF probe; every effect of the simulator, those of issue 12 (transmission error,
/// coupling, coupled transmission, link deflection settled with the joint springs) included.
#[test]
fn streamed_files_do_not_depend_on_chunks_threads_or_the_median_method() {
    use generate::StreamOptions;
    let text = std::fs::read_to_string(scenario_path("iiwa7_all.toml"))
        .unwrap()
        .replace("repeats = 1\n", "repeats = 3\n")
        .replace("outlier_rate = 0.0", "outlier_rate = 0.1\nsix_dof = true")
        + "[effects.transmission]\nharmonics = [1, 2]\n\
           amplitude_rad = { normal = [0.0, 8e-5] }\nphase_rad = { uniform = [-3.0, 3.0] }\n\
           [effects.coupling]\npairs = [[6, 4], [2, 2]]\nratio_rad_per_rad = [2e-4, -1e-4]\n\
           [effects.coupled_transmission]\npairs = [[6, 5]]\namplitude_rad = 5e-5\n\
           [effects.deflection]\ncompliance_rad_per_nm = [[0, 0], [3e-6, 3e-6], [0, 0], \
           [4e-6, 4e-6], [0, 0], [5e-6, 5e-6], [0, 0]]\n";
    let res = Scenario::parse(
        &text,
        "streamed.toml",
        &common::repo_root().join("scenarios"),
    )
    .unwrap()
    .resolve(&Overrides {
        poses: Some(157),
        ..Overrides::default()
    })
    .unwrap();
    let dir = temp_dir("streamed");
    let run = |threads: usize, options: StreamOptions, name: &str| {
        let out = dir.join(name);
        let ticks = std::sync::atomic::AtomicU64::new(0);
        let tick = |k: u64| {
            ticks.fetch_add(k, std::sync::atomic::Ordering::Relaxed);
        };
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                let planner = generate::planner_of(&res).unwrap();
                generate::write_dataset_with(&res, &out, planner, Some(&tick), &options).unwrap()
            });
        // The progress callbacks count every row once.
        assert_eq!(ticks.into_inner(), 471, "{name}");
        files(&out)
    };
    let reference = run(2, StreamOptions::default(), "default");
    for (threads, chunk_rows, median_in_memory_rows) in [
        (1, 1, 0),
        (2, 2, usize::MAX),
        (2, 5, 0),
        (1, 64, 100),
        (2, 470, 0),
    ] {
        let options = StreamOptions {
            chunk_rows,
            median_in_memory_rows,
        };
        let name = format!("t{threads}_c{chunk_rows}_m{median_in_memory_rows}");
        assert!(
            run(threads, options, &name) == reference,
            "{name}: other bytes than the default run"
        );
    }
    // The in-memory path (plan, simulate, table) gives the same measurement rows.
    let plan = generate::plan_of(&res).unwrap();
    assert_eq!(plan.len(), 471);
    let truth = sim::effects::Truth::new(&res.model, &res.effects).unwrap();
    let sim_rows =
        generate::simulate(&truth, &res.tracker, &res.gravity, &plan, res.seed, None).unwrap();
    let table = generate::measurement_table(&plan, &sim_rows, &res.tracker);
    let in_memory = dir.join("in_memory.parquet");
    sim::measurement_table::write(&in_memory, &table).unwrap();
    assert!(std::fs::read(&in_memory).unwrap() == reference[0]);
    // The summary's median is the middle of the sorted target distances, computed here from the
    // truth file's p_tracker columns.
    let doc: serde_json::Value = serde_json::from_slice(&reference[2]).unwrap();
    let f = std::fs::File::open(dir.join("default/truth.parquet")).unwrap();
    let batch = parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(f)
        .unwrap()
        .build()
        .unwrap()
        .next()
        .unwrap()
        .unwrap();
    let col = |n: &str| -> Vec<f64> {
        use arrow_array::cast::AsArray;
        batch
            .column_by_name(n)
            .unwrap()
            .as_primitive::<arrow_array::types::Float64Type>()
            .values()
            .to_vec()
    };
    // Every effect of the scenario moved the target (so each went through the chunks above).
    for key in [
        "thermal",
        "kinematic",
        "transmission",
        "coupling",
        "coupled_transmission",
        "backlash",
        "compliance",
        "deflection",
    ] {
        let moved = col(&format!("{key}_x"))
            .iter()
            .filter(|v| v.abs() > 1e-7)
            .count();
        assert!(
            moved > 400,
            "{key}: {moved} of 471 rows moved by over 0.1 µm in x"
        );
    }
    let (x, y, z) = (col("p_tracker_x"), col("p_tracker_y"), col("p_tracker_z"));
    let mut d: Vec<f64> = (0..x.len())
        .map(|i| Vector3::new(x[i], y[i], z[i]).norm())
        .collect();
    d.sort_by(f64::total_cmp);
    let median = doc["summary"]["median_distance_m"].as_f64().unwrap();
    assert!(
        (median - d[d.len() / 2]).abs() < 1e-15,
        "{median} {}",
        d[d.len() / 2]
    );
    assert_eq!(doc["summary"]["rows"], 471);
    assert_eq!(doc["campaign"]["repeats"], 3);
    let _ = std::fs::remove_dir_all(&dir);
}

/// Found while extending the fuzzing suite: a scenario whose temperature profile or payload gives
/// values the measurement table refuses (1e15 °C, 5,000 kg) failed only when the table was written,
/// with an error naming the hidden staging folder (`.out.tmp-PID-N/measurements.parquet`). They are
/// scenario errors naming the file and the key, before anything is written; an error about a staged
/// table names the user's folder.
#[test]
fn impossible_temperatures_and_payloads_are_scenario_errors() {
    let dir = temp_dir("impossible");
    let text = std::fs::read_to_string(scenario_path("ur5_kinematic.toml")).unwrap();
    assert!(!text.contains("[campaign.temperature]") && !text.contains("[campaign.payload]"));
    for (extra, key, value) in [
        (
            "[campaign.temperature]\nconstant = 1e15\n",
            "campaign.temperature",
            "1e15 °C at pose 0",
        ),
        (
            "[campaign.temperature]\nschedule = [[0.0, 20.0], [100.0, -300.0]]\n",
            "campaign.temperature",
            // T(t) = 20 − 3.2 t °C falls below −273.15 °C after t = 91.6 s; poses come every 15 s.
            "-3e2 °C at pose 7 (t = 105 s)",
        ),
        (
            "[campaign.payload]\nmass_kg = 5000.0\n",
            "campaign.payload",
            "5000 kg",
        ),
    ] {
        let path = dir.join("hot.toml");
        std::fs::write(&path, format!("{text}\n{extra}")).unwrap();
        let res = Scenario::load(&path).and_then(|s| {
            s.resolve(&Overrides {
                poses: Some(20),
                ..Overrides::default()
            })
        });
        let out = dir.join("out");
        let e = res
            .and_then(|r| generate::generate(&r, &out, None))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("hot.toml") && e.contains(key) && e.contains(value),
            "{e}"
        );
        assert!(!e.contains(".tmp-"), "{e}");
        assert!(!out.exists());
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Fuzzing case 8805 (seed 15): `seconds_per_pose = 1e308` made the third pose's time infinite, and
/// the run failed when the table was written, naming the output file instead of the scenario key.
/// It is a scenario error naming the key, before any work; huge but finite times still generate.
#[test]
fn fuzz_case_8805_a_campaign_too_long_to_time_is_a_scenario_error() {
    let dir = temp_dir("case_8805");
    let text = std::fs::read_to_string(scenario_path("ur5_kinematic.toml")).unwrap();
    assert!(text.contains("seconds_per_pose = 15.0"));
    let run = |spp: &str, poses: usize| {
        let path = dir.join("long.toml");
        std::fs::write(
            &path,
            text.replace(
                "seconds_per_pose = 15.0",
                &format!("seconds_per_pose = {spp}"),
            ),
        )
        .unwrap();
        Scenario::load(&path)
            .and_then(|s| {
                s.resolve(&Overrides {
                    poses: Some(poses),
                    ..Overrides::default()
                })
            })
            .and_then(|r| generate::generate(&r, &dir.join("out"), None))
    };
    let e = run("1e308", 12).unwrap_err().to_string();
    assert!(
        e.contains("long.toml")
            && e.contains("campaign.seconds_per_pose")
            && e.contains("t = inf s"),
        "{e}"
    );
    assert!(!dir.join("out").exists());
    // One pose is measured at t = 0 whatever the spacing; 1e300 s apart, twelve poses are finite.
    assert!(run("1e308", 1).is_ok());
    assert!(run("1e300", 12).is_ok());
    let _ = std::fs::remove_dir_all(&dir);
}

/// A `[campaign.file]` pose table with a joint value outside the robot's limits (q1 = 9 rad on the
/// iiwa 7, whose joint 1 stops at ±2.97 rad) is refused before anything is planned: one line naming
/// the file, the 1-based data row and the joint column. The same table within the limits plans.
#[test]
fn a_campaign_file_with_a_joint_outside_its_limits_is_refused() {
    let dir = temp_dir("file_limits");
    let text = "[robot]\nname = \"iiwa7\"\n[campaign]\n[campaign.file]\npath = \"poses.csv\"\n";
    std::fs::write(dir.join("file.toml"), text).unwrap();
    let outside = "pose,q1,q2,q3,q4,q5,q6,q7,x,y,z\n\
                   0,0.1,0.2,0.3,-0.4,0.5,0.6,0.7,1,2,3\n\
                   1,9,0.2,0.3,-0.4,0.5,0.6,0.7,1,2,3\n";
    std::fs::write(dir.join("poses.csv"), outside).unwrap();
    let res = Scenario::load(&dir.join("file.toml"))
        .unwrap()
        .resolve(&Overrides::default())
        .unwrap();
    let err = generate::plan_of(&res).unwrap_err();
    assert!(
        matches!(&err, sim::SimError::Table { row: Some(2), column: Some(c), .. } if c == "q1"),
        "{err:?}"
    );
    let msg = err.to_string();
    assert_eq!(msg.lines().count(), 1, "{msg}");
    assert!(
        msg.contains("poses.csv: row 2")
            && msg.contains("column q1")
            && msg.contains("9.0 rad is outside the limits"),
        "{msg}"
    );
    // The generator refuses it too, and writes nothing.
    let out = dir.join("out");
    assert!(generate::generate(&res, &out, None).is_err());
    assert!(!out.join(generate::MEASUREMENTS_FILE).exists());
    // Within the limits the same table plans, one pose per id.
    std::fs::write(dir.join("poses.csv"), outside.replace("1,9,", "1,0.9,")).unwrap();
    let res = Scenario::load(&dir.join("file.toml"))
        .unwrap()
        .resolve(&Overrides::default())
        .unwrap();
    let plan = generate::plan_of(&res).unwrap();
    assert_eq!(plan.n_poses, 2);
    assert_eq!(plan.q_row(1)[0], 0.9);
    let _ = std::fs::remove_dir_all(dir);
}
