//! Streaming on the command line: `predict` reads, predicts and writes a file piece by piece
//! (`--chunk-rows`), and its output is the whole-table prediction byte for byte, whatever the piece
//! size and the input format; errors name the file-wide row, and a failed run leaves `--out` as it was.

mod common;

use calib::model::file::CalibratedModel;
use calib::model::predict::Predictor;
use common::{repo, robocal_ok, scratch_dir};
use sim::measurement_table as mt;

fn s(p: &std::path::Path) -> String {
    p.display().to_string()
}

#[test]
fn predict_in_pieces_is_the_whole_table_prediction_byte_for_byte() {
    let d = scratch_dir("robocal_cli_stream", "predict");
    let scenario = repo().join("scenarios/iiwa7_kinematic.toml");
    let gen_dir = d.join("gen");
    robocal_ok(&[
        "generate",
        "--scenario",
        &s(&scenario),
        "--out",
        &s(&gen_dir),
        "--seed",
        "5",
        "--poses",
        "300",
    ]);
    let data = gen_dir.join("measurements.parquet");
    let model = d.join("model.json");
    robocal_ok(&[
        "calibrate",
        "--data",
        &s(&data),
        "--out",
        &s(&model),
        "--test-fraction",
        "0.3",
    ]);
    // The whole table through the library: the reference.
    let table = mt::read(&data).unwrap();
    let file = CalibratedModel::load(&model).unwrap();
    let mut predictor = Predictor::from_file(&file).unwrap();
    let reference = predictor.predict_table(&table, "m").unwrap().to_csv();
    assert_eq!(reference.lines().count(), table.len() + 1);
    let csv = d.join("measurements.csv");
    mt::write(&csv, &table).unwrap();
    for input in [&data, &csv] {
        for rows in ["1", "7", "64", "1000000"] {
            let out = d.join(format!("p_{rows}.csv"));
            robocal_ok(&[
                "predict",
                "--model",
                &s(&model),
                "--data",
                &s(input),
                "--out",
                &s(&out),
                "--chunk-rows",
                rows,
            ]);
            let got = std::fs::read_to_string(&out).unwrap();
            assert!(
                got == reference,
                "{}, --chunk-rows {rows}: the output differs from the whole-table prediction",
                input.display()
            );
        }
    }
    // A joint value far outside its limits in row 250: the error names it whatever the pieces, and
    // the existing output is kept.
    let mut bad = table.clone();
    bad.q[249 * bad.n_joints + 1] = 9.0;
    let bad_csv = d.join("bad.csv");
    std::fs::write(&bad_csv, mt::write_csv_string(&bad).unwrap()).unwrap();
    let out = d.join("kept.csv");
    std::fs::write(&out, "precious\n").unwrap();
    for rows in ["16", "1000000"] {
        let o = assert_cmd::Command::new(env!("CARGO_BIN_EXE_robocal"))
            .args([
                "predict",
                "--model",
                &s(&model),
                "--data",
                &s(&bad_csv),
                "--out",
                &s(&out),
                "--chunk-rows",
                rows,
            ])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{err}");
        assert_eq!(err.trim().lines().count(), 1, "{err}");
        assert!(err.contains("row 250") && err.contains("q2"), "{err}");
        assert_eq!(std::fs::read_to_string(&out).unwrap(), "precious\n");
    }
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn calibrate_streamed_and_in_memory_agree_and_refuse_what_streams_cannot_do() {
    let d = scratch_dir("robocal_cli_stream", "calibrate");
    let scenario = repo().join("scenarios/iiwa7_kinematic.toml");
    let gen_dir = d.join("gen");
    robocal_ok(&[
        "generate",
        "--scenario",
        &s(&scenario),
        "--out",
        &s(&gen_dir),
        "--seed",
        "9",
        "--poses",
        "3000",
    ]);
    let data = gen_dir.join("measurements.parquet");
    let run = |mode: &str| {
        let out = d.join(format!("model_{mode}.json"));
        let (stdout, _) = robocal_ok(&[
            "calibrate",
            "--data",
            &s(&data),
            "--out",
            &s(&out),
            "--folds",
            "0",
            "--stream",
            mode,
            "--chunk-rows",
            "700",
            "--json",
        ]);
        let doc: serde_json::Value = serde_json::from_str(&stdout).unwrap();
        (doc, CalibratedModel::load(&out).unwrap())
    };
    let (streamed, _) = run("always");
    let (memory, _) = run("never");
    assert_eq!(streamed["stream"]["rows"], 3000, "{}", streamed["stream"]);
    assert_eq!(streamed["stream"]["chunk_rows"], 700);
    assert!(memory.get("stream").is_none_or(|v| v.is_null()));
    let (rs, rm) = (&streamed["report"], &memory["report"]);
    for key in ["dof", "n_train_rows", "n_train_poses"] {
        assert_eq!(rs[key], rm[key], "{key}");
    }
    assert_eq!(rs["after"]["solver"]["rank"], rm["after"]["solver"]["rank"]);
    // The same minimum: the training RMS to far below the noise's share of a rounding (the two
    // solutions lie within the stopping rule's √(decrease_tol) of it, calib/tests/stream.rs).
    let rms = |r: &serde_json::Value| r["after"]["train"]["rms_m"].as_f64().unwrap();
    assert!(
        (rms(rs) - rms(rm)).abs() <= 1e-6 * rms(rm),
        "streamed {} against in memory {}",
        rms(rs),
        rms(rm)
    );
    // The default validation (5 folds, 5 regions) streams: the same rows held out by other folds
    // (a hash of the pose instead of a shuffled deal), so the held-out RMS agrees with the
    // in-memory validation's to its spread between splits (below 1 % on 9,000 coordinates).
    let validated = |mode: &str| {
        let out = d.join(format!("validated_{mode}.json"));
        let (stdout, _) = robocal_ok(&[
            "calibrate",
            "--data",
            &s(&data),
            "--out",
            &s(&out),
            "--stream",
            mode,
            "--chunk-rows",
            "700",
            "--json",
        ]);
        serde_json::from_str::<serde_json::Value>(&stdout).unwrap()
    };
    let (vs, vm) = (validated("always"), validated("never"));
    assert!(vs["stream"]["validation_passes"].as_u64().unwrap() >= 3);
    assert_eq!(vs["split"], vm["split"]);
    for key in ["folds", "regions", "seed", "kind"] {
        assert_eq!(vs["validation"][key], vm["validation"][key], "{key}");
    }
    assert_eq!(vs["validation"]["per_fold"].as_array().unwrap().len(), 5);
    for part in [&vs["validation"], &vs["validation"]["by_region"]] {
        assert_eq!(part["after"]["n_rows"], 3000, "{part}");
    }
    for (a, b) in [
        (&vs["validation"]["after"], &vm["validation"]["after"]),
        (
            &vs["validation"]["by_region"]["after"],
            &vm["validation"]["by_region"]["after"],
        ),
    ] {
        let (x, y) = (a["rms_m"].as_f64().unwrap(), b["rms_m"].as_f64().unwrap());
        eprintln!("held-out RMS streamed {x:.4e} m, in memory {y:.4e} m");
        assert!((x - y).abs() <= 0.01 * y, "streamed {x} m, in memory {y} m");
    }
    // What streaming cannot do is refused, not done otherwise.
    let out = d.join("refused.json");
    let (code, err) = common::robocal_status(&[
        "calibrate",
        "--data",
        &s(&data),
        "--out",
        &s(&out),
        "--test-fraction",
        "0.2",
        "--stream",
        "always",
    ]);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("--stream always") && err.contains("--test-fraction"),
        "{err}"
    );
    assert!(!out.exists());
    let (code, err) = common::robocal_status(&[
        "calibrate",
        "--data",
        &s(&data),
        "--out",
        &s(&out),
        "--folds",
        "0",
        "--chunk-rows",
        "0",
    ]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("--chunk-rows 0"), "{err}");
}

/// `register --stream always` reads the new campaign in pieces and gives the in-memory registration
/// (`--stream never`) within the solver's tolerance: the same tracker pose to 10⁻¹⁰ m and rad (its
/// σ here is micrometres), the same row and pose counts, residual and standard deviations to 10⁻⁶;
/// the JSON says how it streamed. A bad row deep in the file is named by its file-wide row.
#[test]
fn register_streamed_and_in_memory_agree() {
    let d = scratch_dir("robocal_cli_stream", "register");
    let scenario = repo().join("scenarios/iiwa7_kinematic.toml");
    let (first, moved) = (d.join("a"), d.join("b"));
    robocal_ok(&[
        "generate",
        "--scenario",
        &s(&scenario),
        "--out",
        &s(&first),
        "--seed",
        "5",
        "--poses",
        "200",
    ]);
    // The same robot (seed 5 draws the same errors) seen by a tracker moved across the cell.
    let text = std::fs::read_to_string(&scenario).unwrap();
    let moved_text = text.replace("xyz_m = [2.5, 1.0, -0.2]", "xyz_m = [-1.8, 2.2, 0.3]");
    assert_ne!(moved_text, text, "the scenario's tracker placement changed");
    let moved_scenario = d.join("moved.toml");
    std::fs::write(&moved_scenario, moved_text).unwrap();
    robocal_ok(&[
        "generate",
        "--scenario",
        &s(&moved_scenario),
        "--out",
        &s(&moved),
        "--seed",
        "5",
        "--poses",
        "20000",
    ]);
    let model = d.join("model.json");
    robocal_ok(&[
        "calibrate",
        "--data",
        &s(&first.join("measurements.parquet")),
        "--out",
        &s(&model),
        "--folds",
        "0",
    ]);
    let data = moved.join("measurements.parquet");
    let run = |mode: &str| -> serde_json::Value {
        let out = d.join(format!("reg_{mode}.json"));
        let (json, _) = robocal_ok(&[
            "register",
            "--model",
            &s(&model),
            "--data",
            &s(&data),
            "--out",
            &s(&out),
            "--stream",
            mode,
            "--chunk-rows",
            "3000",
            "--json",
        ]);
        serde_json::from_str(&json).unwrap()
    };
    let (memory, streamed) = (run("never"), run("always"));
    assert!(memory.get("stream").is_none());
    assert_eq!(streamed["stream"]["rows"], 20000);
    assert_eq!(streamed["stream"]["chunk_rows"], 3000);
    let (m, st) = (&memory["report"], &streamed["report"]);
    for k in ["n_rows", "n_poses", "campaign"] {
        assert_eq!(m[k], st[k], "{k}");
    }
    let f = |v: &serde_json::Value| v.as_f64().unwrap();
    for i in 0..3 {
        assert!((f(&m["translation_m"][i]) - f(&st["translation_m"][i])).abs() < 1e-10);
        for j in 0..3 {
            assert!((f(&m["rotation"][i][j]) - f(&st["rotation"][i][j])).abs() < 1e-10);
        }
        let (a, b) = (
            f(&m["sigma_translation_m"][i]),
            f(&st["sigma_translation_m"][i]),
        );
        assert!((a - b).abs() <= 1e-6 * a, "σ {a:e} against {b:e}");
    }
    let (a, b) = (f(&m["residual"]["rms_m"]), f(&st["residual"]["rms_m"]));
    assert!(
        (a - b).abs() <= 1e-6 * a,
        "residual RMS {a:e} against {b:e}"
    );
    // A bad row deep in the file: named by its file-wide row.
    let mut table = mt::read(&data).unwrap();
    table.q[17_500 * table.n_joints + 1] = 9.0;
    let bad = d.join("bad.csv");
    std::fs::write(&bad, mt::write_csv_string(&table).unwrap()).unwrap();
    let (code, err) = common::robocal_status(&[
        "register",
        "--model",
        &s(&model),
        "--data",
        &s(&bad),
        "--out",
        &s(&d.join("x.json")),
        "--stream",
        "always",
        "--chunk-rows",
        "3000",
    ]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("row 17501") && err.contains("q2"), "{err}");
    let _ = std::fs::remove_dir_all(&d);
}

/// `diagnose --stream always` diagnoses a seeded sample of whole poses and predicts the rest: the
/// JSON keeps the diagnose contract and adds `stream` (rows, sample, the rest's statistics); the
/// text says what came from the sample; a sample below the smallest is refused, exit 2.
#[test]
fn diagnose_streams_through_a_sample_and_predicts_the_rest() {
    let d = scratch_dir("robocal_cli_stream", "diagnose");
    let gen_dir = d.join("gen");
    robocal_ok(&[
        "generate",
        "--scenario",
        &s(&repo().join("scenarios/iiwa7_all.toml")),
        "--out",
        &s(&gen_dir),
        "--seed",
        "5",
        "--poses",
        "3000",
    ]);
    let data = gen_dir.join("measurements.parquet");
    let (stdout, _) = robocal_ok(&[
        "diagnose",
        "--data",
        &s(&data),
        "--stream",
        "always",
        "--sample-rows",
        "1500",
        "--chunk-rows",
        "700",
        "--json",
    ]);
    let doc: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    let st = &doc["stream"];
    assert_eq!(st["rows"], 3000, "{st}");
    assert_eq!(st["passes"], 3);
    let sample = st["sample_rows"].as_u64().unwrap();
    let rest = &st["rest"];
    assert_eq!(sample + rest["rows"].as_u64().unwrap(), 3000);
    // Half the poses, binomial: σ = 27 poses; within 5σ.
    assert!(sample.abs_diff(1500) <= 137, "{sample} rows sampled");
    assert_eq!(rest["model"], doc["model"]);
    // The contract's fields are there, for the sample.
    for key in ["findings", "steps", "model", "unexplained"] {
        assert!(doc.get(key).is_some(), "{key}");
    }
    assert_eq!(
        doc["n_train"].as_u64().unwrap() + doc["n_test"].as_u64().unwrap(),
        sample
    );
    let (k, a) = (
        rest["kinematic"]["rms_m"].as_f64().unwrap(),
        rest["adopted"]["rms_m"].as_f64().unwrap(),
    );
    assert!(
        a < k,
        "the adopted model predicts the rest better: {a} against {k}"
    );
    let (_, err) = robocal_ok(&[
        "diagnose",
        "--data",
        &s(&data),
        "--stream",
        "always",
        "--sample-rows",
        "1500",
    ]);
    assert!(
        err.contains("streamed: diagnosed on a seeded sample"),
        "{err}"
    );
    assert!(err.contains("the rest of the stream"), "{err}");
    let (code, err) = common::robocal_status(&[
        "diagnose",
        "--data",
        &s(&data),
        "--stream",
        "always",
        "--sample-rows",
        "10",
    ]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("--sample-rows 10"), "{err}");
    std::fs::remove_dir_all(&d).unwrap();
}
