//! The trap of issue 24, as a user meets it: a campaign measured on a manifold (a grid of positions at
//! one flange orientation, as the UR10's series A is) with an error no cause of the vocabulary
//! explains, then a second campaign at free orientations. Each run draws the hidden effect, its joints
//! and magnitude from a seed it prints (`ROBOCAL_TEST_SEED=… cargo test --test cli_transfer` repeats
//! one); the seed never reaches the code under test, which sees only the measurement files.
//!
//! A third campaign measures 60 poses near the grid's (each joint moved by up to 0.03 rad).
//!
//! What must hold:
//! - `predict` marks most free-orientation rows `outside_support` (their `sigma_m` is 4-6 times the
//!   calibration's: every one of them, in practice), hardly any row of the first campaign and
//!   few near it;
//! - on the rows of the second campaign it keeps inside the support (checked when at least 10
//!   are) and on those near the grid, `auto` is no worse than the best physical model (1.02×);
//! - near the grid, the error lies within ±20 % of what the report promises: between the held-out
//!   poses' mean error (poses like the calibration's) and `validation.new_region.mean_m` (poses
//!   unlike them);
//! - inside the support, the learned gain on the first campaign stays (held-out poses of it).

use common::{repo, robocal_ok as robocal, seed};
use nalgebra::{Matrix3, Vector3};
use rand::{RngExt, SeedableRng};
use sim::measurement_table as mt;
use std::path::{Path, PathBuf};

mod common;

fn dir(name: &str) -> PathBuf {
    common::scratch_dir("robocal_cli_transfer", name)
}

/// A grid of 6 × 6 × 6 target positions 8 cm apart near the flange orientation of a seed pose
/// (each turned from it by up to ±0.12 rad about every axis, drawn from `rng`: about as much as the
/// UR10's series A varies), solved by the nominal robot's inverse kinematics (each from the one
/// before, in snake order, so that the joints move smoothly across the grid), written as a pose
/// file.
fn manifold_poses(path: &Path, rng: &mut rand::rngs::StdRng) -> usize {
    let model = sim::robots::load_builtin("iiwa7").unwrap();
    let seed_q = [0.0, 0.5, 0.0, -1.4, 0.0, 1.2, 0.0];
    let mut data = sim::Data::new(&model);
    sim::forward_kinematics(&model, &mut data, &seed_q);
    let r: Matrix3<f64> = *data.flange.rotation.matrix();
    let reflector = Vector3::new(0.0, 0.0, 0.05);
    let centre = data.flange * nalgebra::Point3::from(reflector);
    let limits: Vec<(f64, f64)> = model
        .joints()
        .iter()
        .map(|j| {
            j.limits
                .as_ref()
                .map_or((-1e9, 1e9), |l| (l.lower, l.upper))
        })
        .collect();
    let mut q = seed_q.to_vec();
    let mut text = String::from("pose,q1,q2,q3,q4,q5,q6,q7,x,y,z\n");
    let mut n = 0;
    for i in 0..6 {
        for jj in 0..6 {
            let j = if i % 2 == 0 { jj } else { 5 - jj };
            for kk in 0..6 {
                let k = if (i * 6 + jj) % 2 == 0 { kk } else { 5 - kk };
                let step = |v: usize| (v as f64 - 2.5) * 0.08;
                let target = centre.coords + Vector3::new(step(i), step(j), step(k));
                let tilt = Vector3::new(
                    rng.random_range(-0.12..0.12),
                    rng.random_range(-0.12..0.12),
                    rng.random_range(-0.12..0.12),
                );
                let r_point = r * *nalgebra::Rotation3::new(tilt).matrix();
                let Some(sol) =
                    sim::kinematics::ik::solve_ik(&model, &q, &reflector, &target, &r_point)
                else {
                    continue;
                };
                if sol
                    .iter()
                    .zip(&limits)
                    .any(|(v, (lo, hi))| *v < lo + 0.05 || *v > hi - 0.05)
                {
                    continue;
                }
                q = sol;
                text.push_str(&format!("{n}"));
                for v in &q {
                    text.push_str(&format!(",{v}"));
                }
                text.push_str(",0,0,0\n");
                n += 1;
            }
        }
    }
    std::fs::write(path, text).unwrap();
    n
}

/// `n` poses near the grid's (`grid`, a pose file of [`manifold_poses`]): grid configurations drawn
/// from `rng`, each joint moved by up to ±`by` rad, written as a pose file. Poses like the
/// calibration's that are not among them.
fn near_poses(grid: &Path, path: &Path, n: usize, by: f64, rng: &mut rand::rngs::StdRng) {
    let text = std::fs::read_to_string(grid).unwrap();
    let rows: Vec<Vec<f64>> = text
        .lines()
        .skip(1)
        .map(|l| {
            l.split(',')
                .skip(1)
                .take(7)
                .map(|v| v.parse().unwrap())
                .collect()
        })
        .collect();
    let mut out = String::from("pose,q1,q2,q3,q4,q5,q6,q7,x,y,z\n");
    for k in 0..n {
        let q = &rows[rng.random_range(0..rows.len())];
        out.push_str(&format!("{k}"));
        for v in q {
            out.push_str(&format!(",{}", v + rng.random_range(-by..by)));
        }
        out.push_str(",0,0,0\n");
    }
    std::fs::write(path, out).unwrap();
}

/// Mean position error (m) of `pred` (a predict output) against the measured `table`, over the
/// rows `keep` says (all when `None`).
fn mean_error(pred: &Path, table: &mt::MeasurementTable, keep: Option<&[bool]>) -> (f64, usize) {
    let text = std::fs::read_to_string(pred).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let (cx, cy, cz) = (col("x"), col("y"), col("z"));
    let (mut sum, mut n) = (0.0, 0);
    for (r, line) in lines.enumerate() {
        if keep.is_some_and(|k| !k[r]) {
            continue;
        }
        let v: Vec<f64> = line.split(',').map(|s| s.parse().unwrap()).collect();
        let p = Vector3::new(v[cx], v[cy], v[cz]);
        debug_assert!(p.iter().all(|x| x.is_finite()));
        sum += (p - Vector3::from(table.position[r])).norm();
        n += 1;
    }
    (if n > 0 { sum / n as f64 } else { f64::NAN }, n)
}

/// The `outside_support` column of a predict output.
fn outside(pred: &Path) -> Vec<bool> {
    let text = std::fs::read_to_string(pred).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let c = header.iter().position(|h| *h == "outside_support").unwrap();
    lines.map(|l| l.split(',').nth(c).unwrap() == "1").collect()
}

#[test]
fn a_manifold_campaign_does_not_mislead_about_free_orientations() {
    let seed = seed();
    eprintln!("cli_transfer: seed {seed} (ROBOCAL_TEST_SEED={seed} repeats this run)");
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let d = dir("trap");
    let poses = d.join("grid.csv");
    // A grid whose tilts lose too many points to the joint limits is drawn again (about one in 200).
    let n_grid = (0..5)
        .map(|_| manifold_poses(&poses, &mut rng))
        .find(|&n| n >= 150)
        .expect("five grids in a row lost more than 66 of 216 points to IK");
    // The hidden effect, outside the vocabulary: joint i's angle gains c · q_j (cable wind-up), or
    // A sin(q_j + φ) (a drive turned through another joint).
    let i = rng.random_range(1..=4usize);
    let j = loop {
        let j = rng.random_range(1..=6usize);
        if j != i {
            break j;
        }
    };
    let effect = if rng.random::<bool>() {
        let c = rng.random_range(2e-4..4e-4) * if rng.random::<bool>() { 1.0 } else { -1.0 };
        format!("[effects.coupling]\npairs = [[{i}, {j}]]\nratio_rad_per_rad = [{c}]\n")
    } else {
        let a = rng.random_range(2e-4..4e-4);
        let phase = rng.random_range(-3.1..3.1);
        format!(
            "[effects.coupled_transmission]\npairs = [[{i}, {j}]]\norder = [1]\namplitude_rad = [{a}]\nphase_rad = [{phase}]\n"
        )
    };
    let robot_seed = rng.random_range(0..1_000_000u64).to_string();
    let base = std::fs::read_to_string(repo().join("scenarios/iiwa7_kinematic.toml")).unwrap();
    let grid_text = format!(
        "{}\n[campaign.file]\npath = \"{}\"\n",
        base.replace("sampling = \"random\"", "sampling = \"file\""),
        poses.display()
    );
    let write = |name: &str, text: &str| {
        let p = d.join(name);
        std::fs::write(&p, format!("{text}\n{effect}")).unwrap();
        p
    };
    let generate = |scenario: &Path, out: &str, n: usize| {
        let out = d.join(out);
        robocal(&[
            "generate",
            "--scenario",
            scenario.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--seed",
            &robot_seed,
            "--poses",
            &n.to_string(),
        ]);
        out.join("measurements.parquet")
    };
    let a = generate(&write("grid.toml", &grid_text), "a", n_grid);
    let b = generate(&write("free.toml", &base), "b", 300);
    // Poses near the grid's, off it by up to 0.03 rad per joint (a tenth of its nearest-neighbour
    // spacing in joint space).
    let near_file = d.join("near.csv");
    near_poses(&poses, &near_file, 60, 0.03, &mut rng);
    let near_text = format!(
        "{}\n[campaign.file]\npath = \"{}\"\n",
        base.replace("sampling = \"random\"", "sampling = \"file\""),
        near_file.display()
    );
    let c = generate(&write("near.toml", &near_text), "c", 60);
    let table_a = mt::read(&a).unwrap();
    let table_b = mt::read(&b).unwrap();
    let table_c = mt::read(&c).unwrap();
    let (s, a_s) = (d.to_str().unwrap(), a.to_str().unwrap());
    let model = |name: &str| format!("{s}/{name}.json");
    let pred = |name: &str| PathBuf::from(format!("{s}/{name}.csv"));
    // `predict` of the model file `name` on the table `data` into the output `out` (`pred(out)`).
    let predict = |name: &str, data: &Path, out: &str| {
        robocal(&[
            "predict",
            "--model",
            &model(name),
            "--data",
            data.to_str().unwrap(),
            "--out",
            pred(out).to_str().unwrap(),
        ]);
    };
    // auto on the manifold, and the physical models a user could have chosen instead.
    let (auto_json, _) = robocal(&[
        "calibrate",
        "--data",
        a_s,
        "--model",
        "auto",
        "--out",
        &model("auto"),
        "--json",
    ]);
    let report: serde_json::Value = serde_json::from_str(&auto_json).unwrap();
    let promise = report["validation"]["new_region"]["mean_m"]
        .as_f64()
        .unwrap();
    let v = &report["validation"];
    let like = v["learned"]["mean_m"]
        .as_f64()
        .or(v["after"]["mean_m"].as_f64())
        .unwrap();
    let physical = report["auto"]["physical"]
        .as_str()
        .unwrap_or("kinematic")
        .to_string();
    eprintln!(
        "cli_transfer: hidden {}; auto chose {} (physical {physical}); promise on new regions {:.1} µm",
        effect.replace('\n', " "),
        report["model"],
        promise * 1e6
    );
    let mut physical_models = vec!["kinematic".to_string()];
    if physical != "kinematic" {
        physical_models.push(physical);
    }
    for (k, m) in physical_models.iter().enumerate() {
        let name = format!("physical{k}");
        robocal(&[
            "calibrate",
            "--data",
            a_s,
            "--model",
            m,
            "--out",
            &model(&name),
        ]);
        predict(&name, &b, &name);
        let (e, _) = mean_error(&pred(&name), &table_b, None);
        eprintln!("cli_transfer: {m} on the free campaign: {:.1} µm", e * 1e6);
        predict(&name, &c, &format!("{name}_c"));
    }
    predict("auto", &b, "auto_b");
    predict("auto", &a, "auto_a");
    let out_b = outside(&pred("auto_b"));
    let out_a = outside(&pred("auto_a"));
    let share = |v: &[bool]| v.iter().filter(|&&o| o).count() as f64 / v.len() as f64;
    eprintln!(
        "cli_transfer: outside_support on the free campaign {:.0} %, on the grid {:.1} %",
        100.0 * share(&out_b),
        100.0 * share(&out_a)
    );
    assert!(
        share(&out_b) > 0.5,
        "seed {seed}: most free-orientation rows outside the support"
    );
    assert!(
        share(&out_a) < 0.05,
        "seed {seed}: hardly any grid row outside the support"
    );
    // Where predict keeps a row inside the support, auto is no worse than the best physical model
    // and keeps its promise. (On every row of the free campaign it may be: a cause adopted on the
    // manifold, where it transfers between regions, can be wrong off it; predict marks those rows.)
    let inside: Vec<bool> = out_b.iter().map(|o| !o).collect();
    let (auto_b, n_kept) = mean_error(&pred("auto_b"), &table_b, Some(&inside));
    let (auto_all, _) = mean_error(&pred("auto_b"), &table_b, None);
    let best_inside = physical_models
        .iter()
        .enumerate()
        .map(|(k, _)| mean_error(&pred(&format!("physical{k}")), &table_b, Some(&inside)).0)
        .fold(f64::INFINITY, f64::min);
    eprintln!(
        "cli_transfer: auto on the free campaign: {:.1} µm on every row, {:.1} µm on the {n_kept} rows \
         inside the support (best physical model there {:.1} µm, promise {:.1} µm)",
        auto_all * 1e6,
        auto_b * 1e6,
        best_inside * 1e6,
        promise * 1e6
    );
    if n_kept >= 10 {
        assert!(
            auto_b <= 1.02 * best_inside,
            "seed {seed}: auto {:.1} µm inside the support, the best physical model {:.1} µm",
            auto_b * 1e6,
            best_inside * 1e6
        );
    }
    // Poses near the calibration's: predict keeps them inside the support, and there the error is
    // the promise.
    predict("auto", &c, "auto_c");
    let out_c = outside(&pred("auto_c"));
    let inside_c: Vec<bool> = out_c.iter().map(|o| !o).collect();
    let (auto_c, n_c) = mean_error(&pred("auto_c"), &table_c, Some(&inside_c));
    let best_c = (0..physical_models.len())
        .map(|k| mean_error(&pred(&format!("physical{k}_c")), &table_c, Some(&inside_c)).0)
        .fold(f64::INFINITY, f64::min);
    eprintln!(
        "cli_transfer: near the grid: {:.0} % outside the support; {:.1} µm on the {n_c} rows inside \
         (best physical model there {:.1} µm), promise {:.1} µm (ratio {:.2}), held-out poses {:.1} µm \
         (ratio {:.2})",
        100.0 * share(&out_c),
        auto_c * 1e6,
        best_c * 1e6,
        promise * 1e6,
        auto_c / promise,
        like * 1e6,
        auto_c / like
    );
    assert!(
        share(&out_c) < 0.2,
        "seed {seed}: poses near the calibration's marked outside the support"
    );
    assert!(
        auto_c <= 1.02 * best_c,
        "seed {seed}: auto {:.1} µm near the grid, the best physical model {:.1} µm",
        auto_c * 1e6,
        best_c * 1e6
    );
    // The report promises the held-out poses' error for poses like the calibration's and the
    // held-out regions' for poses unlike them; rows near the grid lie between the two (measured
    // over 48 seeds: 0.87-1.09 of the first, 0.70-1.04 of the second).
    assert!(
        auto_c >= 0.8 * like.min(promise) && auto_c <= 1.2 * like.max(promise),
        "seed {seed}: {:.1} µm near the grid, outside 0.8 x {:.1} .. 1.2 x {:.1} µm promised",
        auto_c * 1e6,
        like.min(promise) * 1e6,
        like.max(promise) * 1e6
    );
    // Inside the support the learned gain stays: 30 % of the grid held out.
    let (split_json, _) = robocal(&[
        "calibrate",
        "--data",
        a_s,
        "--model",
        "auto",
        "--test-fraction",
        "0.3",
        "--out",
        &model("auto_split"),
        "--json",
    ]);
    let split: serde_json::Value = serde_json::from_str(&split_json).unwrap();
    let v = &split["validation"];
    if let Some(learned) = v["learned"]["mean_m"].as_f64() {
        let after = v["after"]["mean_m"].as_f64().unwrap();
        eprintln!(
            "cli_transfer: held-out grid poses: physical {:.1} µm, with the learned correction {:.1} µm",
            after * 1e6,
            learned * 1e6
        );
        assert!(
            learned < after,
            "seed {seed}: the learned gain inside the support is lost"
        );
    }
    let _ = table_a;
    if std::env::var("ROBOCAL_KEEP").is_err() {
        let _ = std::fs::remove_dir_all(&d);
    }
}
