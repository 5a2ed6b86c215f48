//! `robocal generate` end to end through the built binary: every shipped scenario, the exit codes of
//! bad input, determinism across runs and the overrides.

use std::path::{Path, PathBuf};
use std::process::Command;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn out_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("robocal_cli_gen_{}_{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

fn robocal(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_robocal"))
        .args(args)
        .output()
        .expect("run robocal")
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// The contract's columns for `nq` joints (shared/spec/measurements.md).
fn contract(nq: usize) -> Vec<String> {
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
fn every_shipped_scenario_generates_a_valid_dataset() {
    let mut scenarios: Vec<PathBuf> = std::fs::read_dir(repo().join("scenarios"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    scenarios.sort();
    let expected = [
        "iiwa7_all",
        "iiwa7_backlash",
        "iiwa7_clean",
        "iiwa7_compliance",
        "iiwa7_compliance_rapier",
        "iiwa7_deflection",
        "iiwa7_kinematic",
        "iiwa7_thermal",
        "iiwa7_transmission",
        "ur5_kinematic",
    ];
    for name in expected {
        assert!(
            scenarios.iter().any(|p| p.file_stem().unwrap() == name),
            "scenarios/{name}.toml is missing"
        );
    }
    for s in &scenarios {
        let stem = s.file_stem().unwrap().to_string_lossy().into_owned();
        let out = out_dir(&stem);
        let o = robocal(&[
            "generate",
            "--scenario",
            s.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--poses",
            "25",
        ]);
        assert!(o.status.success(), "{stem}: {}", text(&o.stderr));
        assert!(
            o.stdout.is_empty(),
            "{stem}: stdout must stay empty without --json"
        );
        let err = text(&o.stderr);
        assert!(err.contains("generated 25 poses"), "{stem}: {err}");
        let m = out.join("measurements.parquet");
        let table = sim::measurement_table::read(&m).unwrap();
        assert_eq!(table.n_poses(), 25, "{stem}");
        let names = sim::generate::parquet_column_names(&m).unwrap();
        // The contract's columns, and the branch joints' values (`q_<joint>`, robocal's extension:
        // what the controller reports, never truth).
        let mut allowed = contract(table.n_joints);
        allowed.extend(table.branch_names().iter().map(|n| format!("q_{n}")));
        for n in &names {
            assert!(
                allowed.contains(n),
                "{stem}: measurements hold non-contract column '{n}'"
            );
        }
        let truth_names = sim::generate::parquet_column_names(&out.join("truth.parquet")).unwrap();
        assert!(truth_names.iter().any(|n| n == "p_tracker_x"));
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("truth.json")).unwrap())
                .unwrap();
        assert_eq!(json["campaign"]["poses"], 25);
        assert!(json["scenario_text"].as_str().unwrap().contains("[robot]"));
        let _ = std::fs::remove_dir_all(out);
    }
}

#[test]
fn same_seed_gives_identical_files_and_overrides_apply() {
    let s = repo().join("scenarios/iiwa7_all.toml");
    let s = s.to_str().unwrap();
    let (a, b, c) = (out_dir("a"), out_dir("b"), out_dir("c"));
    let run = |dir: &Path, extra: &[&str]| {
        let mut args = vec![
            "generate",
            "--scenario",
            s,
            "--out",
            dir.to_str().unwrap(),
            "--poses",
            "40",
        ];
        args.extend_from_slice(extra);
        let o = robocal(&args);
        assert!(o.status.success(), "{}", text(&o.stderr));
        o
    };
    run(&a, &["--seed", "5"]);
    run(&b, &["--seed", "5"]);
    for f in ["measurements.parquet", "truth.parquet", "truth.json"] {
        assert_eq!(
            std::fs::read(a.join(f)).unwrap(),
            std::fs::read(b.join(f)).unwrap(),
            "{f}"
        );
    }
    // --noise 0: measured = true positions, no sigma column.
    let o = run(&c, &["--seed", "5", "--noise", "0", "--json"]);
    let v: serde_json::Value =
        serde_json::from_slice(&o.stdout).expect("one JSON document on stdout");
    assert_eq!(v["noise_scale"], 0.0);
    assert_eq!(v["poses"], 40);
    let table = sim::measurement_table::read(&c.join("measurements.parquet")).unwrap();
    assert!(table.sigma.is_none());
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(c.join("truth.json")).unwrap()).unwrap();
    assert_eq!(json["seed"], 5);
    assert_eq!(json["overrides"]["noise"], 0.0);
    // With the same seed the robot and campaign are the same, so the noise-free run gives the true
    // positions: the noisy run differs from them by tracker noise only (σ of 5-20 µm per axis at
    // 2-3 m, no outliers in this scenario), never by a different robot (millimetres).
    let noisy = sim::measurement_table::read(&a.join("measurements.parquet")).unwrap();
    assert_eq!(noisy.q, table.q);
    let d2: Vec<f64> = noisy
        .position
        .iter()
        .zip(&table.position)
        .map(|(p, q)| (0..3).map(|k| (p[k] - q[k]).powi(2)).sum::<f64>())
        .collect();
    let rms = (d2.iter().sum::<f64>() / d2.len() as f64).sqrt();
    assert!(rms > 1e-5 && rms < 6e-5, "RMS noise {rms} m");
    assert!(d2.iter().all(|&x| x.sqrt() < 2e-4));
    for d in [a, b, c] {
        let _ = std::fs::remove_dir_all(d);
    }
}

#[test]
fn bad_input_exits_2_naming_the_key_and_write_failures_exit_1() {
    let dir = out_dir("bad");
    std::fs::create_dir_all(&dir).unwrap();
    let bad = dir.join("bad.toml");
    std::fs::write(
        &bad,
        "[robot]\nname = \"iiwa7\"\n[effects.backlash]\ndead_band = 3e-4\n",
    )
    .unwrap();
    let o = robocal(&[
        "generate",
        "--scenario",
        bad.to_str().unwrap(),
        "--out",
        dir.join("o").to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2));
    let e = text(&o.stderr);
    assert!(
        e.contains("dead_band") && e.contains("unknown field") && e.lines().count() == 1,
        "{e}"
    );
    // Negative noise multiplier.
    let good = repo().join("scenarios/iiwa7_clean.toml");
    let o = robocal(&[
        "generate",
        "--scenario",
        good.to_str().unwrap(),
        "--out",
        dir.join("o").to_str().unwrap(),
        "--noise",
        "-1",
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(text(&o.stderr).contains("--noise"));
    // Missing scenario file.
    let o = robocal(&[
        "generate",
        "--scenario",
        dir.join("nope.toml").to_str().unwrap(),
        "--out",
        dir.join("o").to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2));
    // Output "folder" that is a file: cannot write, a runtime failure.
    let blocker = dir.join("file");
    std::fs::write(&blocker, "x").unwrap();
    let o = robocal(&[
        "generate",
        "--scenario",
        good.to_str().unwrap(),
        "--out",
        blocker.to_str().unwrap(),
        "--poses",
        "5",
    ]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o.stderr));
    let _ = std::fs::remove_dir_all(dir);
}

/// Noise-free positions of the shipped rapier scenario and of its analytic twin (same seed and
/// campaign, so the same poses) agree within 1 µm; `truth.json` says which truth made each; a truth
/// model that does not exist is bad input naming the key.
#[test]
fn rapier_truth_scenario_matches_its_analytic_twin_and_a_bad_truth_model_exits_2() {
    let (a, r) = (out_dir("twin_analytic"), out_dir("twin_rapier"));
    for (name, out) in [("iiwa7_compliance", &a), ("iiwa7_compliance_rapier", &r)] {
        let s = repo().join(format!("scenarios/{name}.toml"));
        let o = robocal(&[
            "generate",
            "--scenario",
            s.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--poses",
            "8",
            "--noise",
            "0",
        ]);
        assert!(o.status.success(), "{name}: {}", text(&o.stderr));
    }
    let read = |d: &Path| sim::measurement_table::read(&d.join("measurements.parquet")).unwrap();
    let (ta, tr) = (read(&a), read(&r));
    assert_eq!(ta.q, tr.q, "the twins must command the same poses");
    assert_eq!(tr.len(), 8);
    for (k, (pa, pr)) in ta.position.iter().zip(&tr.position).enumerate() {
        let d =
            ((pa[0] - pr[0]).powi(2) + (pa[1] - pr[1]).powi(2) + (pa[2] - pr[2]).powi(2)).sqrt();
        assert!(d < 1e-6, "pose {k}: rapier and analytic differ by {d:e} m");
    }
    let model = |d: &Path| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(d.join("truth.json")).unwrap()).unwrap()
    };
    assert_eq!(model(&a)["truth_model"], "analytic");
    assert_eq!(model(&r)["truth_model"], "rapier");
    assert_eq!(model(&r)["truth"]["engine"], "rapier3d-f64 0.36");

    let bad = a.join("bad.toml");
    std::fs::write(
        &bad,
        "[robot]\nname = \"iiwa7\"\n[effects.compliance]\nstiffness_nm_per_rad = 1e4\n\
         [truth]\nmodel = \"mujoco\"\n",
    )
    .unwrap();
    let o = robocal(&[
        "generate",
        "--scenario",
        bad.to_str().unwrap(),
        "--out",
        a.join("o").to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2));
    let e = text(&o.stderr);
    assert!(
        e.contains("bad.toml")
            && e.contains("[truth] model")
            && e.contains("mujoco")
            && e.lines().count() == 1,
        "{e}"
    );
    for d in [a, r] {
        let _ = std::fs::remove_dir_all(d);
    }
}
