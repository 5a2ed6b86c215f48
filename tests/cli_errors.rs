//! The one exit-code rule of the command line (`shared/spec/cli.md`, `src/error.rs`): an output that
//! cannot be written is a runtime failure (exit 1), bad input or usage exits 2, each with one line on
//! stderr naming the file or the flag.

use std::path::{Path, PathBuf};

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("robocal_cli_err_{}_{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Runs robocal; returns the exit code and stderr.
fn robocal(args: &[&str]) -> (Option<i32>, String) {
    let o = assert_cmd::Command::new(env!("CARGO_BIN_EXE_robocal"))
        .args(args)
        .output()
        .expect("run robocal");
    (
        o.status.code(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

/// Asserts exit `code` with exactly one line on stderr that contains every `needle`.
fn check(args: &[&str], code: i32, needles: &[&str]) -> String {
    let (c, e) = robocal(args);
    assert_eq!(c, Some(code), "{args:?}: {e}");
    assert_eq!(e.trim().lines().count(), 1, "{args:?}: not one line: {e}");
    assert!(e.starts_with("error: "), "{args:?}: {e}");
    assert!(!e.contains("panicked"), "{args:?}: {e}");
    for n in needles {
        assert!(e.contains(n), "{args:?}: error does not name {n}: {e}");
    }
    e
}

/// A small generated campaign (noise-free iiwa 7, `poses` poses).
fn data(d: &Path, poses: &str) -> PathBuf {
    let out = d.join(format!("data{poses}"));
    let scenario = repo().join("scenarios/iiwa7_kinematic.toml");
    let (c, e) = robocal(&[
        "generate",
        "--scenario",
        scenario.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--poses",
        poses,
    ]);
    assert_eq!(c, Some(0), "{e}");
    out.join("measurements.parquet")
}

#[test]
fn outputs_that_cannot_be_written_exit_1() {
    let d = dir("write");
    let data = data(&d, "40");
    let data = data.to_str().unwrap();
    // A regular file where a folder should be: nothing can be created below it.
    let blocker = d.join("file");
    std::fs::write(&blocker, "x").unwrap();
    let below = |name: &str| blocker.join(name).to_str().unwrap().to_string();
    let scenario = repo().join("scenarios/iiwa7_clean.toml");
    let (model, pred, report, plan) = (
        below("m.json"),
        below("p.csv"),
        below("report"),
        below("plan.csv"),
    );
    let gen_out = below("gen");
    check(
        &[
            "generate",
            "--scenario",
            scenario.to_str().unwrap(),
            "--out",
            &gen_out,
            "--poses",
            "5",
        ],
        1,
        &[&gen_out],
    );
    check(
        &["calibrate", "--data", data, "--out", &model],
        1,
        &[&model],
    );
    let good_model = d.join("m.json");
    let good = good_model.to_str().unwrap();
    let (c, e) = robocal(&["calibrate", "--data", data, "--out", good]);
    assert_eq!(c, Some(0), "{e}");
    check(
        &["predict", "--model", good, "--data", data, "--out", &pred],
        1,
        &[&pred],
    );
    check(
        &["diagnose", "--data", data, "--report", &report],
        1,
        &[&report],
    );
    check(
        &[
            "plan-poses",
            "--candidates",
            "100",
            "--select",
            "20",
            "--out",
            &plan,
        ],
        1,
        &[&plan],
    );
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn bad_input_and_unknown_flag_values_exit_2() {
    let d = dir("input");
    let data = data(&d, "40");
    let data = data.to_str().unwrap();
    let out = d.join("m.json");
    let out = out.to_str().unwrap();
    // Inputs that are not there: named, exit 2.
    let missing = d.join("absent.json");
    let missing = missing.to_str().unwrap();
    check(
        &["predict", "--model", missing, "--data", data, "--out", out],
        2,
        &[missing, "cannot read"],
    );
    check(
        &[
            "calibrate",
            "--robot",
            "/nonexistent/robot.urdf",
            "--data",
            data,
            "--out",
            out,
        ],
        2,
        &["/nonexistent/robot.urdf"],
    );
    check(
        &["calibrate", "--data", missing, "--out", out],
        2,
        &[missing],
    );
    // A flag value that is not one of its values: a usage error on one line, listing the values.
    check(
        &[
            "calibrate",
            "--data",
            data,
            "--out",
            out,
            "--robust",
            "tukey",
        ],
        2,
        &["--robust", "tukey", "huber, cauchy"],
    );
    check(
        &[
            "sweep",
            "--scenario",
            "x.toml",
            "--noise",
            "1",
            "--poses",
            "30",
            "--reps",
            "1",
            "--out",
            out,
            "--selection",
            "best",
        ],
        2,
        &["--selection", "best", "random, planned"],
    );
    // Too few poses for the model itself: the typed error, without a hint about validation.
    let few = self::data(&d, "8");
    let e = check(
        &["calibrate", "--data", few.to_str().unwrap(), "--out", out],
        2,
        &["8 distinct poses", "at least 11 distinct poses"],
    );
    assert!(!e.contains("--folds"), "{e}");
    assert!(!Path::new(out).exists());
    // Enough for the model on every pose (11), too few for a fold's 4/5 of them: the hint says so.
    let twelve = self::data(&d, "12");
    check(
        &[
            "calibrate",
            "--data",
            twelve.to_str().unwrap(),
            "--out",
            out,
        ],
        2,
        &[
            "fold",
            "distinct poses",
            "--folds 5 fits each fold on 4/5 of the poses",
        ],
    );
    // The same with an explicit split.
    check(
        &[
            "calibrate",
            "--data",
            twelve.to_str().unwrap(),
            "--out",
            out,
            "--test-fraction",
            "0.3",
        ],
        2,
        &[
            "training set",
            "--test-fraction 0.3 held out part of the poses",
        ],
    );
    assert!(!Path::new(out).exists());
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn the_robust_losses_are_accepted_by_name() {
    let d = dir("robust");
    let data = data(&d, "40");
    for loss in ["huber", "cauchy"] {
        let out = d.join(format!("{loss}.json"));
        let (c, e) = robocal(&[
            "calibrate",
            "--data",
            data.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--robust",
            loss,
        ]);
        assert_eq!(c, Some(0), "{loss}: {e}");
        assert!(out.is_file());
    }
    let _ = std::fs::remove_dir_all(&d);
}

/// Fuzzing case 16900 (seed 15, the suite's first version): `fk` with as many `--q` values as the URDF should have, on a URDF
/// whose chain came out shorter, named the flag and the robot but not the file. The error names the
/// `--robot` argument it loaded.
#[test]
fn fuzz_case_16900_a_joint_count_error_names_the_robot_file() {
    let d = dir("fk_count");
    let urdf = d.join("six.urdf");
    std::fs::copy(repo().join("sim/robots/ur5.urdf"), &urdf).unwrap();
    let urdf = urdf.to_str().unwrap();
    check(
        &["fk", "--robot", urdf, "--q", "0,0,0,0,0,0,0"],
        2,
        &["--q", "expected 6 joint values, got 7", urdf],
    );
    let _ = std::fs::remove_dir_all(&d);
}

/// The fuzzing audit's subnormal `sigma` (3 of 6,000 mutated tables): a `sigma` cell of 4.9e-324 m
/// made `calibrate` run on both cores for minutes. A `sigma` below 1 nm (no tracker has it) is now a
/// one-line error naming the file, the row and `sigma`, as one above 1 m is (read before any work).
#[test]
fn fuzz_subnormal_sigma_is_refused_at_once() {
    let d = dir("subnormal_sigma");
    let table = sim::measurement_table::read(&data(&d, "30")).unwrap();
    let mut text = String::from("pose,q1,q2,q3,q4,q5,q6,q7,x,y,z,sigma\n");
    for r in 0..table.len() {
        let q: Vec<String> = table.q_row(r).iter().map(|v| format!("{v:?}")).collect();
        let p = table.position[r];
        let sigma = if r == 6 { "4.9e-324" } else { "1e-5" };
        text += &format!(
            "{},{},{:?},{:?},{:?},{sigma}\n",
            table.pose[r],
            q.join(","),
            p[0],
            p[1],
            p[2]
        );
    }
    let csv = d.join("subnormal.csv");
    std::fs::write(&csv, text).unwrap();
    let csv = csv.to_str().unwrap();
    let out = d.join("model.json");
    let out = out.to_str().unwrap();
    let needles = [csv, "row 7 (line 8), column sigma", "below 1e-9 m"];
    check(&["calibrate", "--data", csv, "--out", out], 2, &needles);
    assert!(!Path::new(out).exists());
    check(&["diagnose", "--data", csv, "--json"], 2, &needles);
    let _ = std::fs::remove_dir_all(&d);
}
