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
