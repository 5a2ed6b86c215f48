//! `robocal compensate` on the command line: targets the model already reaches at the seed give the
//! seed back, the base frame and the tracker frame give the same joints, an unreachable target is
//! flagged, named and exits 1 (the output still written), and bad input is one line, exit 2.

use std::path::{Path, PathBuf};

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("robocal_cli_comp_{}_{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn robocal(args: &[&str]) -> (Option<i32>, String, String) {
    let o = assert_cmd::Command::new(env!("CARGO_BIN_EXE_robocal"))
        .args(args)
        .output()
        .expect("run robocal");
    (
        o.status.code(),
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

/// A calibrated iiwa 7 model (kinematic + compliance) and its data, in `d`.
fn model(d: &Path) -> (PathBuf, PathBuf) {
    let data = d.join("data");
    let (c, _, e) = robocal(&[
        "generate",
        "--scenario",
        repo().join("scenarios/iiwa7_all.toml").to_str().unwrap(),
        "--out",
        data.to_str().unwrap(),
        "--seed",
        "5",
        "--poses",
        "120",
    ]);
    assert_eq!(c, Some(0), "{e}");
    let m = d.join("m.json");
    let table = data.join("measurements.parquet");
    let (c, _, e) = robocal(&[
        "calibrate",
        "--data",
        table.to_str().unwrap(),
        "--model",
        "kinematic+joint_compliance+gear_backlash+thermal_drift",
        "--folds",
        "0",
        "--out",
        m.to_str().unwrap(),
    ]);
    assert_eq!(c, Some(0), "{e}");
    (m, table)
}

/// Rows of a CSV file as (header, rows of fields).
fn read_csv(p: &Path) -> (Vec<String>, Vec<Vec<String>>) {
    let text = std::fs::read_to_string(p).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap().split(',').map(String::from).collect();
    let rows = lines
        .map(|l| l.split(',').map(String::from).collect())
        .collect();
    (header, rows)
}

fn col(header: &[String], name: &str) -> usize {
    header.iter().position(|h| h == name).unwrap()
}

#[test]
fn compensate_from_the_command_line() {
    let d = dir("all");
    let (m, table) = model(&d);
    let t = sim::measurement_table::read(&table).unwrap();
    // Targets where the model itself puts the target at the seed (robocal predict): the answer is
    // the seed, to the solver's precision.
    let cfg = d.join("cfg.csv");
    let first = t.select_rows(&(0..30).collect::<Vec<_>>());
    sim::measurement_table::write(&cfg, &first).unwrap();
    let pred = d.join("pred.csv");
    let (c, _, e) = robocal(&[
        "predict",
        "--model",
        m.to_str().unwrap(),
        "--data",
        cfg.to_str().unwrap(),
        "--out",
        pred.to_str().unwrap(),
    ]);
    assert_eq!(c, Some(0), "{e}");
    let (_, p) = read_csv(&pred);
    let mut targets = first.clone();
    for (r, row) in p.iter().enumerate() {
        targets.position[r] = [1, 2, 3].map(|k| row[k].parse().unwrap());
    }
    let tfile = d.join("targets.csv");
    sim::measurement_table::write(&tfile, &targets).unwrap();
    let out = d.join("q.csv");
    let (c, _, e) = robocal(&[
        "compensate",
        "--model",
        m.to_str().unwrap(),
        "--targets",
        tfile.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(c, Some(0), "{e}");
    let (h, rows) = read_csv(&out);
    for (r, row) in rows.iter().enumerate() {
        for j in 0..7 {
            let q: f64 = row[col(&h, &format!("q{}", j + 1))].parse().unwrap();
            assert!(
                (q - first.q_row(r)[j]).abs() < 1e-9,
                "row {r} joint {j}: {q} against the seed {}",
                first.q_row(r)[j]
            );
        }
        assert_eq!(row[col(&h, "converged")], "1");
        assert_eq!(row[col(&h, "outside_support")], "0");
        // The context is passed through.
        let payload: f64 = row[col(&h, "payload")].parse().unwrap();
        assert_eq!(payload, first.payload.as_ref().unwrap()[r]);
    }

    // The same targets in the base frame: T_tracker_base⁻¹ p, from the model file's registration.
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&m).unwrap()).unwrap();
    let tb = &json["parameters"]["t_tracker_base"];
    let rot = nalgebra::Matrix3::from_fn(|i, j| tb["rotation"][i][j].as_f64().unwrap());
    let tr = nalgebra::Vector3::from_fn(|i, _| tb["translation_m"][i].as_f64().unwrap());
    let mut base = targets.clone();
    // A target 2 cm away from where the model puts it at the seed, so that the joints change.
    for p in base.position.iter_mut() {
        let v = rot.transpose() * (nalgebra::Vector3::from(*p) - tr)
            + nalgebra::Vector3::new(0.02, 0.0, 0.0);
        *p = v.into();
    }
    let mut tracker = base.clone();
    for p in tracker.position.iter_mut() {
        *p = (rot * nalgebra::Vector3::from(*p) + tr).into();
    }
    let bfile = d.join("base.csv");
    let tfile2 = d.join("tracker.csv");
    sim::measurement_table::write(&bfile, &base).unwrap();
    sim::measurement_table::write(&tfile2, &tracker).unwrap();
    let (ob, ot) = (d.join("qb.csv"), d.join("qt.csv"));
    for (input, out, frame) in [(&bfile, &ob, "base"), (&tfile2, &ot, "tracker")] {
        let (c, _, e) = robocal(&[
            "compensate",
            "--model",
            m.to_str().unwrap(),
            "--targets",
            input.to_str().unwrap(),
            "--frame",
            frame,
            "--out",
            out.to_str().unwrap(),
        ]);
        assert_eq!(c, Some(0), "{frame}: {e}");
    }
    let ((h, rb), (_, rt)) = (read_csv(&ob), read_csv(&ot));
    let mut moved = 0.0f64;
    for (r, (a, b)) in rb.iter().zip(&rt).enumerate() {
        for j in 1..=7 {
            let (qa, qb): (f64, f64) = (
                a[col(&h, &format!("q{j}"))].parse().unwrap(),
                b[col(&h, &format!("q{j}"))].parse().unwrap(),
            );
            assert!(
                (qa - qb).abs() < 1e-9,
                "row {r} q{j}: base {qa} tracker {qb}"
            );
            moved = moved.max((qa - first.q_row(r)[j - 1]).abs());
        }
    }
    assert!(
        moved > 1e-3,
        "the 2 cm targets moved the joints by only {moved} rad"
    );

    // A target 5 m away: out of reach, named, flagged, exit 1, the output written.
    let mut far = targets.clone();
    far.position[3] = [10.0, 10.0, 10.0];
    let ffile = d.join("far.csv");
    sim::measurement_table::write(&ffile, &far).unwrap();
    let fout = d.join("far_q.csv");
    let (c, _, e) = robocal(&[
        "compensate",
        "--model",
        m.to_str().unwrap(),
        "--targets",
        ffile.to_str().unwrap(),
        "--out",
        fout.to_str().unwrap(),
    ]);
    assert_eq!(c, Some(1), "{e}");
    assert!(e.contains("far.csv: row 4 (pose 3): out of reach"), "{e}");
    let (h, rows) = read_csv(&fout);
    for (r, row) in rows.iter().enumerate() {
        assert_eq!(
            row[col(&h, "converged")],
            if r == 3 { "0" } else { "1" },
            "row {r}"
        );
    }

    // Bad input: targets without x, y, z (and no --program); an orientation the model has not.
    let (c, _, e) = robocal(&[
        "compensate",
        "--model",
        m.to_str().unwrap(),
        "--targets",
        out.to_str().unwrap(),
        "--out",
        d.join("x.csv").to_str().unwrap(),
    ]);
    assert_eq!(c, Some(2), "{e}");
    assert_eq!(e.trim().lines().count(), 1, "{e}");
    assert!(e.contains("q.csv") && e.contains("'x'"), "{e}");
    let mut oriented = targets.clone();
    oriented.orientation = Some(vec![[1.0, 0.0, 0.0, 0.0]; oriented.len()]);
    let ofile = d.join("oriented.csv");
    sim::measurement_table::write(&ofile, &oriented).unwrap();
    let (c, _, e) = robocal(&[
        "compensate",
        "--model",
        m.to_str().unwrap(),
        "--targets",
        ofile.to_str().unwrap(),
        "--out",
        d.join("o.csv").to_str().unwrap(),
    ]);
    assert_eq!(c, Some(2), "{e}");
    assert_eq!(e.trim().lines().count(), 1, "{e}");
    assert!(e.contains("oriented.csv") && e.contains("qw"), "{e}");
    let _ = std::fs::remove_dir_all(d);
}
