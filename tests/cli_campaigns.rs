//! Campaigns on the command line, as a user would run them: two tracker placements of one generated
//! robot (the same scenario with the tracker moved, concatenated here with a `campaign` column),
//! `calibrate` on both, `predict` in each row's campaign, `register` of a moved tracker from 20 poses,
//! one-line errors for campaigns a model does not know, version-1 model files, and the warning that the
//! robot changed.

use sim::measurement_table::{self as mt, MeasurementTable};
use std::path::{Path, PathBuf};

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("robocal_cli_camp_{}_{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Runs robocal; returns the exit code, stdout and stderr.
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

fn ok(args: &[&str]) -> (String, String) {
    let (c, out, err) = robocal(args);
    assert_eq!(c, Some(0), "{args:?}: {err}");
    (out, err)
}

/// Exit 2 with one line naming every needle.
fn refused(args: &[&str], needles: &[&str]) {
    let (c, _, e) = robocal(args);
    assert_eq!(c, Some(2), "{args:?}: {e}");
    assert_eq!(e.trim().lines().count(), 1, "{args:?}: not one line: {e}");
    for n in needles {
        assert!(e.contains(n), "{args:?}: error does not name {n}: {e}");
    }
}

/// `iiwa7_kinematic.toml` with the tracker at `xyz`, `rpy`, generated with `seed` and `poses`: the same
/// seed draws the same robot errors wherever the tracker stands.
fn campaign(
    d: &Path,
    name: &str,
    xyz: &str,
    rpy: &str,
    seed: &str,
    poses: &str,
) -> MeasurementTable {
    let text = std::fs::read_to_string(repo().join("scenarios/iiwa7_kinematic.toml")).unwrap();
    let text = text
        .replace("xyz_m = [2.5, 1.0, -0.2]", &format!("xyz_m = {xyz}"))
        .replace("rpy_rad = [0.0, 0.0, 2.5]", &format!("rpy_rad = {rpy}"));
    let scenario = d.join(format!("{name}.toml"));
    std::fs::write(&scenario, text).unwrap();
    let out = d.join(name);
    ok(&[
        "generate",
        "--scenario",
        scenario.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--seed",
        seed,
        "--poses",
        poses,
    ]);
    mt::read(&out.join("measurements.parquet")).unwrap()
}

fn with_campaign(t: &MeasurementTable, id: i64) -> MeasurementTable {
    let mut t = t.clone();
    t.campaign = Some(vec![id; t.len()]);
    t
}

fn concat(a: &MeasurementTable, b: &MeasurementTable) -> MeasurementTable {
    let mut t = a.clone();
    for r in 0..b.len() {
        t.push_row(&b.row(r)).unwrap();
    }
    t
}

/// RMS distance (m) between the predicted `pred.csv` and the measured positions of `table`.
fn rms_against(pred: &Path, table: &MeasurementTable) -> f64 {
    // `pose,x,y,z` (and an orientation, not used here).
    let text = std::fs::read_to_string(pred).unwrap();
    let rows: Vec<[f64; 3]> = text
        .lines()
        .skip(1)
        .map(|l| {
            let v: Vec<f64> = l
                .split(',')
                .skip(1)
                .take(3)
                .map(|x| x.parse().unwrap())
                .collect();
            [v[0], v[1], v[2]]
        })
        .collect();
    assert_eq!(rows.len(), table.len());
    let s: f64 = rows
        .iter()
        .zip(&table.position)
        .map(|(p, m)| (0..3).map(|k| (p[k] - m[k]).powi(2)).sum::<f64>())
        .sum();
    (s / rows.len() as f64).sqrt()
}

#[test]
fn two_campaigns_calibrate_predict_and_register() {
    let d = dir("two");
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let a = campaign(&d, "a", "[2.5, 1.0, -0.2]", "[0.0, 0.0, 2.5]", "5", "80");
    let b = campaign(&d, "b", "[-1.2, 2.6, 0.4]", "[0.1, -0.05, -1.0]", "5", "60");
    // The same robot: the tracker moved by metres.
    assert!((a.position[0][0] - b.position[0][0]).abs() > 0.5);
    let both = d.join("ab.csv");
    mt::write(&both, &concat(&with_campaign(&a, 1), &with_campaign(&b, 2))).unwrap();
    let model = d.join("m.json");
    let (out, _) = ok(&[
        "calibrate",
        "--data",
        &s(&both),
        "--out",
        &s(&model),
        "--json",
    ]);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let held = v["validation"]["after"]["rms_m"].as_f64().unwrap();
    // Tracker noise of about 10 µm per axis: held-out errors of tens of µm, not millimetres.
    assert!(held < 60e-6, "held-out RMS {held:e}");
    let file: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&model).unwrap()).unwrap();
    assert_eq!(file["parameters"]["campaign"], 1);
    assert_eq!(file["parameters"]["campaigns"][0]["id"], 2);
    // predict uses each row's campaign.
    let pred = d.join("p.csv");
    ok(&[
        "predict",
        "--model",
        &s(&model),
        "--data",
        &s(&both),
        "--out",
        &s(&pred),
    ]);
    let all = concat(&with_campaign(&a, 1), &with_campaign(&b, 2));
    assert!(rms_against(&pred, &all) < 60e-6);
    // A campaign the model does not know: one line, exit 2.
    let other = d.join("c9.csv");
    mt::write(&other, &with_campaign(&b, 9)).unwrap();
    refused(
        &[
            "predict",
            "--model",
            &s(&model),
            "--data",
            &s(&other),
            "--out",
            &s(&d.join("p9.csv")),
        ],
        &["c9.csv: row 1", "campaign = 9", "knows campaigns 1, 2"],
    );

    // Calibrate on A alone, register B from 20 poses, predict the rest of B.
    let a_only = d.join("a.csv");
    mt::write(&a_only, &a).unwrap();
    let model_a = d.join("ma.json");
    ok(&["calibrate", "--data", &s(&a_only), "--out", &s(&model_a)]);
    let reg_rows: Vec<usize> = (0..20).collect();
    let rest_rows: Vec<usize> = (20..b.len()).collect();
    let b_reg = d.join("b20.csv");
    let b_rest = d.join("brest.csv");
    mt::write(&b_reg, &b.select_rows(&reg_rows)).unwrap();
    mt::write(&b_rest, &b.select_rows(&rest_rows)).unwrap();
    let model_ab = d.join("mab.json");
    let (out, _) = ok(&[
        "register",
        "--model",
        &s(&model_a),
        "--data",
        &s(&b_reg),
        "--out",
        &s(&model_ab),
        "--json",
    ]);
    let r: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(r["report"]["campaign"], 1);
    assert!(
        r["report"]["warnings"].as_array().unwrap().is_empty(),
        "{r}"
    );
    let pred = d.join("pb.csv");
    ok(&[
        "predict",
        "--model",
        &s(&model_ab),
        "--data",
        &s(&b_rest),
        "--out",
        &s(&pred),
    ]);
    let rest = b.select_rows(&rest_rows);
    let e = rms_against(&pred, &rest);
    eprintln!(
        "rest of B after registering 20 poses: RMS {:.1} µm",
        e * 1e6
    );
    assert!(e < 60e-6, "{e:e}");
    // register --campaign names a campaign to refit: unknown ones are one-line errors; a table
    // of a registered campaign without --campaign is refused too.
    refused(
        &[
            "register",
            "--model",
            &s(&model_ab),
            "--data",
            &s(&b_reg),
            "--out",
            &s(&d.join("x.json")),
            "--campaign",
            "9",
        ],
        &["--campaign", "9", "knows campaigns 0, 1"],
    );
    let b_tagged = d.join("b_tagged.csv");
    mt::write(&b_tagged, &with_campaign(&b.select_rows(&reg_rows), 1)).unwrap();
    refused(
        &[
            "register",
            "--model",
            &s(&model_ab),
            "--data",
            &s(&b_tagged),
            "--out",
            &s(&d.join("x.json")),
        ],
        &[
            "campaign = 1",
            "already registers campaign 1",
            "--campaign 1",
        ],
    );
    // A version-1 model file (before campaigns) still loads and predicts the same.
    let mut v1: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&model_a).unwrap()).unwrap();
    v1["format_version"] = 1.into();
    let params = v1["parameters"].as_object_mut().unwrap();
    params.remove("campaign");
    params.remove("default_campaign");
    v1.as_object_mut().unwrap().remove("fit");
    let old = d.join("v1.json");
    std::fs::write(&old, serde_json::to_string_pretty(&v1).unwrap()).unwrap();
    let (p_new, p_old) = (d.join("new.csv"), d.join("old.csv"));
    for (m, p) in [(&model_a, &p_new), (&old, &p_old)] {
        ok(&[
            "predict",
            "--model",
            &s(m),
            "--data",
            &s(&a_only),
            "--out",
            &s(p),
        ]);
    }
    assert_eq!(
        std::fs::read(&p_new).unwrap(),
        std::fs::read(&p_old).unwrap()
    );
    v1["format_version"] = 9.into();
    std::fs::write(&old, serde_json::to_string_pretty(&v1).unwrap()).unwrap();
    refused(
        &[
            "predict",
            "--model",
            &s(&old),
            "--data",
            &s(&a_only),
            "--out",
            &s(&p_old),
        ],
        &["format_version", "9", "reads 1 and 2"],
    );
    // Another robot (other kinematic errors: another seed) behind the moved tracker: the registration
    // fits far worse than the model, and register says the robot changed.
    let c = campaign(&d, "c", "[-1.2, 2.6, 0.4]", "[0.1, -0.05, -1.0]", "6", "20");
    let changed = d.join("changed.csv");
    mt::write(&changed, &c).unwrap();
    let (_, err) = ok(&[
        "register",
        "--model",
        &s(&model_a),
        "--data",
        &s(&changed),
        "--out",
        &s(&d.join("changed.json")),
    ]);
    assert!(err.contains("the robot has changed"), "{err}");
    let _ = std::fs::remove_dir_all(&d);
}

/// `generate` with a `[campaign.file]` pose table whose joint value lies outside the robot's limits
/// (q1 = 9 rad on the iiwa 7): exit 2, one line naming the table, the row and the joint column, and
/// no dataset written.
#[test]
fn a_campaign_file_with_a_joint_outside_its_limits_is_refused() {
    let d = dir("file_limits");
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let scenario = d.join("file.toml");
    std::fs::write(
        &scenario,
        "[robot]\nname = \"iiwa7\"\n[campaign]\n[campaign.file]\npath = \"poses.csv\"\n",
    )
    .unwrap();
    std::fs::write(
        d.join("poses.csv"),
        "pose,q1,q2,q3,q4,q5,q6,q7,x,y,z\n\
         0,0.1,0.2,0.3,-0.4,0.5,0.6,0.7,1,2,3\n\
         1,9,0.2,0.3,-0.4,0.5,0.6,0.7,1,2,3\n",
    )
    .unwrap();
    let out = d.join("out");
    refused(
        &["generate", "--scenario", &s(&scenario), "--out", &s(&out)],
        &["poses.csv", "row 2", "column q1", "outside the limits"],
    );
    assert!(!out.join("measurements.parquet").exists());
    let _ = std::fs::remove_dir_all(&d);
}
