//! Compensation checked against the simulator's truth, as a user would run it: generate a campaign
//! with a hidden effect, calibrate with its cause, compensate a nominal joint program of poses the
//! calibration never saw (`robocal compensate --program`), then let `robocal generate` evaluate the
//! commanded joints on the hidden robot (a `[campaign.file]` campaign of the program, noise 0) and
//! measure the miss.
//!
//! The targets are computed here, independently of the code under test: the program run on the
//! hidden robot (noise 0) gives where it really puts the target; the nominal robot (sim's forward
//! kinematics) registered to those positions by least squares (tracker-to-base transform and target
//! offset: what a user who places the nominal robot in the cell with a tracker does) gives where the
//! program meant to put it. Those targets go to `robocal compensate` with `x, y, z` (tracker frame)
//! and the program's joints as seeds. ISO 9283 positioning accuracy
//! `AP = |barycentre of the attained positions − commanded target|` per pose (one noise-free
//! measurement per pose, so the barycentre is the attained position); its mean over the program's
//! poses is compared with the calibration's own held-out mean error (5-fold cross-validation). The
//! same program compensated with `--program` (targets registered to the calibrated model instead) is
//! measured against the same targets.
//!
//! The generator's seed is drawn per run and printed (`ROBOCAL_COMPENSATE_SEED` sets it); it reaches
//! only `robocal generate`, never the calibration or the compensation.

use common::{repo, robocal_ok as robocal};
use nalgebra::{Matrix3, Vector3};
use sim::measurement_table::{self as mt, MeasurementTable};
use std::path::{Path, PathBuf};

mod common;

/// The target: after compensation the mean AP on the truth is at most this many times the model's
/// held-out mean prediction error (issue 26).
const RATIO_TARGET: f64 = 1.2;
/// Poses the calibration sees.
const TRAIN_POSES: usize = 200;
/// Poses of the nominal program (never seen by the calibration).
const PROGRAM_POSES: usize = 100;

fn dir(name: &str) -> PathBuf {
    common::scratch_dir("robocal_comp", name)
}

fn seed() -> u64 {
    let s = std::env::var("ROBOCAL_COMPENSATE_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| {
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .unwrap()
                .subsec_nanos() as u64
                % 1_000_000
        });
    eprintln!("compensate_truth: generator seed {s} (ROBOCAL_COMPENSATE_SEED={s} repeats it)");
    s
}

/// The scenario `name` with its campaign replaced by the pose file `poses` (`n` poses).
fn file_scenario(d: &Path, name: &str, poses: &Path, n: usize) -> PathBuf {
    let text = std::fs::read_to_string(repo().join(format!("scenarios/{name}.toml"))).unwrap();
    let mut out = String::new();
    for line in text.lines() {
        let key = line.split('=').next().unwrap_or("").trim();
        match key {
            "sampling" | "joint_margin_rad" | "floor_z_m" | "min_axis_distance_m" => continue,
            "poses" => out.push_str(&format!("poses = {n}\n")),
            _ => {
                out.push_str(line);
                out.push('\n');
            }
        }
    }
    out.push_str(&format!(
        "\n[campaign.file]\npath = \"{}\"\n",
        poses.display()
    ));
    let path = d.join(format!(
        "{}.toml",
        poses.file_stem().unwrap().to_str().unwrap()
    ));
    std::fs::write(&path, out).unwrap();
    path
}

/// A pose file of `rows` of `t`: `pose, q1..qN` and the context columns, no x, y, z.
fn write_program(
    path: &Path,
    t: &MeasurementTable,
    rows: &[usize],
    targets: Option<&[Vector3<f64>]>,
) {
    let n = t.n_joints;
    let mut s = String::from("pose");
    if targets.is_some() {
        s.push_str(",x,y,z");
    }
    for j in 1..=n {
        s.push_str(&format!(",q{j}"));
    }
    s.push_str(",t,temp,payload");
    if t.dir.is_some() {
        for j in 1..=n {
            s.push_str(&format!(",dir{j}"));
        }
    }
    s.push('\n');
    for (k, &r) in rows.iter().enumerate() {
        s.push_str(&k.to_string());
        if let Some(p) = targets {
            s.push_str(&format!(",{:?},{:?},{:?}", p[k].x, p[k].y, p[k].z));
        }
        for v in t.q_row(r) {
            s.push_str(&format!(",{v:?}"));
        }
        s.push_str(&format!(
            ",{:?},{:?},{:?}",
            t.t.as_ref().unwrap()[r],
            t.temp.as_ref().unwrap()[r],
            t.payload.as_ref().map_or(0.0, |p| p[r])
        ));
        if let Some(d) = t.dir_row(r) {
            for v in d {
                s.push_str(&format!(",{v}"));
            }
        }
        s.push('\n');
    }
    std::fs::write(path, s).unwrap();
}

/// Where the nominal robot puts the target at `q` (rows of `t`), registered to `attained` (tracker
/// frame, m) by least squares over the rotation and translation of `T_tracker_base` and the target
/// in the flange frame, by Gauss–Newton from the scenario's nominal tracker pose `(r0, t0)` and
/// `p0` (the test's own: it shares nothing with calib).
fn registered_nominal(
    t: &MeasurementTable,
    rows: &[usize],
    attained: &MeasurementTable,
    (r0, t0, p0): (Matrix3<f64>, Vector3<f64>, Vector3<f64>),
) -> Vec<Vector3<f64>> {
    let robot = sim::robots::load_builtin("iiwa7").unwrap();
    let mut data = sim::Data::new(&robot);
    let flange: Vec<(Matrix3<f64>, Vector3<f64>)> = rows
        .iter()
        .map(|&r| {
            sim::kinematics::forward_kinematics(&robot, &mut data, t.q_row(r));
            (
                *data.flange.rotation.matrix(),
                data.flange.translation.vector,
            )
        })
        .collect();
    let (mut rot, mut tr, mut p) = (r0, t0, p0);
    let m = rows.len();
    for _ in 0..50 {
        let mut jac = nalgebra::DMatrix::zeros(3 * m, 9);
        let mut res = nalgebra::DVector::zeros(3 * m);
        for (i, (rf, tf)) in flange.iter().enumerate() {
            let x = rot * (rf * p + tf);
            let e = Vector3::from(attained.position[i]) - x - tr;
            for a in 0..3 {
                res[3 * i + a] = e[a];
                // d(exp(ω) x)/dω = −[x]×
                let unit = Vector3::ith(a, 1.0);
                let d = unit.cross(&x);
                for b in 0..3 {
                    jac[(3 * i + b, a)] = d[b];
                }
                jac[(3 * i + a, 3 + a)] = 1.0;
                let dp = rot * rf * unit;
                for b in 0..3 {
                    jac[(3 * i + b, 6 + a)] = dp[b];
                }
            }
        }
        let step = (jac.transpose() * &jac)
            .cholesky()
            .expect("the program poses determine the registration")
            .solve(&(jac.transpose() * res));
        let w = Vector3::new(step[0], step[1], step[2]);
        rot = nalgebra::Rotation3::new(w).matrix() * rot;
        tr += Vector3::new(step[3], step[4], step[5]);
        p += Vector3::new(step[6], step[7], step[8]);
        if step.norm() < 1e-15 {
            break;
        }
    }
    flange
        .iter()
        .map(|(rf, tf)| rot * (rf * p + tf) + tr)
        .collect()
}

/// The scenario's tracker pose (`T_tracker_base`: rotation, translation m) and reflector (flange
/// frame, m) as `truth.json` states them: the start of the registration.
fn scenario_registration(truth: &Path) -> (Matrix3<f64>, Vector3<f64>, Vector3<f64>) {
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(truth).unwrap()).unwrap();
    let tr = &v["tracker"];
    let num = |x: &serde_json::Value| x.as_f64().unwrap();
    let m = &tr["T_tracker_base"]["matrix"];
    let rot = Matrix3::from_fn(|i, j| num(&m[i][j]));
    let t = Vector3::from_fn(|i, _| num(&m[i][3]));
    let p = Vector3::from_fn(|i, _| num(&tr["reflector_flange_m"][i]));
    (rot, t, p)
}

/// One case's figures (m).
struct Case {
    name: String,
    model: String,
    held_out_mean_m: f64,
    ap_before_mean_m: f64,
    ap_before_max_m: f64,
    ap_after_mean_m: f64,
    ap_after_max_m: f64,
    /// Mean AP of the `--program` compensation against the same targets.
    ap_program_mean_m: f64,
}

/// Mean and max of the distances between the attained positions (noise-free measurements of `t`) and
/// `targets`.
fn ap(t: &MeasurementTable, targets: &[Vector3<f64>]) -> (f64, f64) {
    assert_eq!(t.len(), targets.len());
    let d: Vec<f64> = t
        .position
        .iter()
        .zip(targets)
        .map(|(p, c)| (Vector3::from(*p) - c).norm())
        .collect();
    (
        d.iter().sum::<f64>() / d.len() as f64,
        d.iter().cloned().fold(0.0, f64::max),
    )
}

/// The robot description the calibration is given.
#[derive(Clone, Copy, PartialEq)]
enum Description {
    /// The scenario's built-in robot, with its masses.
    Builtin,
    /// The same robot's URDF without its inertials (a DH table's information): compliance is
    /// identified as lumped products.
    WithoutMasses,
}

fn run_case(scenario: &str, model: &str, description: Description, seed: u64) -> Case {
    let name = match description {
        Description::Builtin => scenario.to_string(),
        Description::WithoutMasses => format!("{scenario} (robot without masses)"),
    };
    let d = dir(&name.replace([' ', '(', ')'], "_"));
    let seed_s = seed.to_string();
    let all = d.join("all");
    let total = (TRAIN_POSES + 3 * PROGRAM_POSES).to_string();
    robocal(&[
        "generate",
        "--scenario",
        repo()
            .join(format!("scenarios/{scenario}.toml"))
            .to_str()
            .unwrap(),
        "--out",
        all.to_str().unwrap(),
        "--seed",
        &seed_s,
        "--poses",
        &total,
    ]);
    let table = mt::read(&all.join("measurements.parquet")).unwrap();
    // The first poses calibrate; the rest are the program.
    let mut train = MeasurementTable {
        n_joints: table.n_joints,
        ..Default::default()
    };
    train.t = table.t.as_ref().map(|_| Vec::new());
    train.temp = table.temp.as_ref().map(|_| Vec::new());
    train.dir = table.dir.as_ref().map(|_| Vec::new());
    train.payload = table.payload.as_ref().map(|_| Vec::new());
    train.sigma = table.sigma.as_ref().map(|_| Vec::new());
    for r in 0..TRAIN_POSES {
        train.push_row(&table.row(r)).unwrap();
    }
    let train_path = d.join("train.parquet");
    mt::write(&train_path, &train).unwrap();
    let model_path = d.join("model.json");
    let bare = d.join("iiwa7_without_masses.urdf");
    let mut args = vec![
        "calibrate",
        "--data",
        train_path.to_str().unwrap(),
        "--model",
        model,
        "--out",
        model_path.to_str().unwrap(),
        "--json",
    ];
    if description == Description::WithoutMasses {
        let urdf = sim::robots::builtin_urdf("iiwa7").unwrap();
        std::fs::write(&bare, sim::urdf_text::without_inertials(urdf)).unwrap();
        args.extend(["--robot", bare.to_str().unwrap()]);
    }
    let (json, _) = robocal(&args);
    let report: serde_json::Value = serde_json::from_str(&json).unwrap();
    let held_out = report["validation"]["after"]["mean_m"]
        .as_f64()
        .unwrap_or_else(|| panic!("no validation.after.mean_m in {json}"));
    // The program: poses after the training ones, away from the iiwa 7's singular configurations
    // (shoulder q2 = 0, stretched elbow q4 = 0, wrist q6 = 0), where a program does not work and a
    // target the nominal robot reaches may be out of the real one's reach.
    let program_rows: Vec<usize> = (TRAIN_POSES..table.len())
        .filter(|&r| {
            let q = table.q_row(r);
            q[1].abs() >= 0.2 && q[3].abs() >= 0.3 && q[5].abs() >= 0.3
        })
        .take(PROGRAM_POSES)
        .collect();
    assert_eq!(program_rows.len(), PROGRAM_POSES, "too few program poses");
    let program = d.join("program.csv");
    write_program(&program, &table, &program_rows, None);
    // The program on the hidden robot, without noise.
    let truth = |poses: &Path, name: &str| -> MeasurementTable {
        let sc = file_scenario(&d, scenario, poses, PROGRAM_POSES);
        let out = d.join(name);
        robocal(&[
            "generate",
            "--scenario",
            sc.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--seed",
            &seed_s,
            "--noise",
            "0",
        ]);
        // The same hidden robot as the calibration data's.
        let a: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(all.join("truth.json")).unwrap())
                .unwrap();
        let b: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("truth.json")).unwrap())
                .unwrap();
        assert_eq!(a["effects"], b["effects"], "{name}: another hidden robot");
        assert_eq!(
            a["tracker"]["T_tracker_base"],
            b["tracker"]["T_tracker_base"]
        );
        let t = mt::read(&out.join("measurements.parquet")).unwrap();
        // The truth evaluated the program's own context.
        for (r, &src) in program_rows.iter().enumerate() {
            let pl = |t: &MeasurementTable, r: usize| t.payload.as_ref().map_or(0.0, |p| p[r]);
            assert_eq!(pl(&t, r), pl(&table, src), "{name}: payload of row {r}");
            assert_eq!(
                t.temp.as_ref().unwrap()[r],
                table.temp.as_ref().unwrap()[src]
            );
            assert_eq!(t.t.as_ref().unwrap()[r], table.t.as_ref().unwrap()[src]);
            assert_eq!(
                t.dir_row(r),
                table.dir_row(src),
                "{name}: directions of row {r}"
            );
        }
        t
    };
    let before = truth(&program, "before");
    for (r, &src) in program_rows.iter().enumerate() {
        assert_eq!(before.q_row(r), table.q_row(src));
    }
    let targets = registered_nominal(
        &table,
        &program_rows,
        &before,
        scenario_registration(&all.join("truth.json")),
    );
    let target_file = d.join("targets.csv");
    write_program(&target_file, &table, &program_rows, Some(&targets));
    let compensate = |input: &Path, out: &Path, program: bool| {
        let mut args = vec![
            "compensate",
            "--model",
            model_path.to_str().unwrap(),
            "--targets",
            input.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ];
        if program {
            args.push("--program");
        }
        robocal(&args);
    };
    let compensated = d.join("compensated.csv");
    compensate(&target_file, &compensated, false);
    let compensated_program = d.join("compensated_program.csv");
    compensate(&program, &compensated_program, true);
    let after = truth(&compensated, "after");
    let after_program = truth(&compensated_program, "after_program");
    let (bm, bx) = ap(&before, &targets);
    let (am, ax) = ap(&after, &targets);
    let (pm, _) = ap(&after_program, &targets);
    Case {
        name,
        model: model.to_string(),
        held_out_mean_m: held_out,
        ap_before_mean_m: bm,
        ap_before_max_m: bx,
        ap_after_mean_m: am,
        ap_after_max_m: ax,
        ap_program_mean_m: pm,
    }
}

/// Every cause of the vocabulary, one scenario each, and all of them at once; compliance also on the
/// robot without masses.
const CASES: &[(&str, &str, Description)] = &[
    ("iiwa7_kinematic", "kinematic", Description::Builtin),
    (
        "iiwa7_compliance",
        "kinematic+joint_compliance",
        Description::Builtin,
    ),
    (
        "iiwa7_compliance",
        "kinematic+joint_compliance",
        Description::WithoutMasses,
    ),
    (
        "iiwa7_backlash",
        "kinematic+gear_backlash",
        Description::Builtin,
    ),
    (
        "iiwa7_thermal",
        "kinematic+thermal_drift",
        Description::Builtin,
    ),
    (
        "iiwa7_transmission",
        "kinematic+transmission_error",
        Description::Builtin,
    ),
    (
        "iiwa7_deflection",
        "kinematic+link_deflection",
        Description::Builtin,
    ),
    (
        "iiwa7_all",
        "kinematic+joint_compliance+gear_backlash+thermal_drift",
        Description::Builtin,
    ),
];

#[test]
fn compensation_reaches_the_targets_on_the_hidden_robot() {
    let seed = seed();
    let mut table = String::from(
        "| scenario | model | held-out mean error (calibrate, 5-fold) | AP before: mean (max) | AP after: mean (max) | after / held-out | `--program`: AP after, mean |\n|---|---|---|---|---|---|---|\n",
    );
    let mut failures = Vec::new();
    for &(scenario, model, description) in CASES {
        let c = run_case(scenario, model, description, seed);
        let ratio = c.ap_after_mean_m / c.held_out_mean_m;
        table.push_str(&format!(
            "| `{}` | `{}` | {:.1} µm | {:.1} µm ({:.1}) | {:.1} µm ({:.1}) | {:.2} | {:.1} µm |\n",
            c.name,
            c.model,
            c.held_out_mean_m * 1e6,
            c.ap_before_mean_m * 1e6,
            c.ap_before_max_m * 1e6,
            c.ap_after_mean_m * 1e6,
            c.ap_after_max_m * 1e6,
            ratio,
            c.ap_program_mean_m * 1e6
        ));
        if ratio.is_nan() || ratio > RATIO_TARGET {
            failures.push(format!(
                "{}: AP after {:.2e} m is {ratio:.2}× the held-out error {:.2e} m",
                c.name, c.ap_after_mean_m, c.held_out_mean_m
            ));
        }
        if c.ap_after_mean_m.is_nan() || c.ap_after_mean_m >= c.ap_before_mean_m {
            failures.push(format!("{}: compensation did not reduce the miss", c.name));
        }
    }
    println!("generator seed {seed}\n{table}");
    assert!(failures.is_empty(), "seed {seed}: {failures:#?}\n{table}");
}
