//! Coupled joints from the command line (issue 25, item 1): the measurement table of a robot with a
//! passive joint has one column per driven joint, a table that also gives the passive joint's column
//! must agree with the coupling, the same coupling declared in the URDF or in a `--couplings` file
//! gives the same bytes, a calibrated model keeps it, and what does not handle couplings yet says so.

mod common;

use std::path::{Path, PathBuf};

fn urdf() -> PathBuf {
    common::repo().join("sim/tests/data/coupled_torso.urdf")
}

/// The coupled torso's URDF without its `<robocal:coupling>` element, and the same coupling as a
/// `--couplings` file, in `dir`.
fn declared_beside(dir: &Path) -> (PathBuf, PathBuf) {
    let text = std::fs::read_to_string(urdf()).unwrap();
    let start = text.find("<robocal:coupling").unwrap();
    let end = start + text[start..].find("/>").unwrap() + 2;
    let bare = format!("{}{}", &text[..start], &text[end..]);
    assert!(!bare.contains("<robocal:coupling"));
    let u = dir.join("bare.urdf");
    std::fs::write(&u, bare).unwrap();
    let c = dir.join("couplings.toml");
    std::fs::write(
        &c,
        "[[coupling]]\njoint = \"torso_pitch_3\"\nsources = [\"torso_pitch_1\", \"torso_pitch_2\"]\n\
         multipliers = [-1.0, -1.0]\n",
    )
    .unwrap();
    (u, c)
}

fn scenario(dir: &Path, robot: &str) -> PathBuf {
    let s = dir.join(format!("scenario_{}.toml", robot.len()));
    std::fs::write(
        &s,
        format!(
            "name = \"coupled\"\nseed = 4\n[robot]\n{robot}\ntip_link = \"left_flange\"\n\
             [campaign]\nposes = 60\nsampling = \"random\"\nfloor_z_m = 0.2\n\
             [campaign.payload]\nchoice_kg = [0.0, 2.0]\n\
             [tracker]\nxyz_m = [2.5, 1.0, 0.4]\nrpy_rad = [0.0, 0.0, 2.5]\n\
             [effects.kinematic]\nzero_offset_rad = {{ normal = [0.0, 5e-4] }}\n\
             [effects.compliance]\nstiffness_nm_per_rad = [2e4, 3e3, 4e3, 1.0, 2.5e3, 2e3, 1.5e3, 8e2]\n"
        ),
    )
    .unwrap();
    s
}

/// A path as a command-line argument.
fn arg(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn the_coupling_in_the_urdf_or_beside_it_gives_the_same_bytes_and_the_model_keeps_it() {
    let d = common::scratch_dir("robocal_cli_couplings", "beside");
    let (bare, couplings) = declared_beside(&d);
    let in_urdf = common::generate(
        &scenario(&d, &format!("urdf = \"{}\"", urdf().display())),
        &d.join("a"),
        &[],
    );
    let beside = common::generate(
        &scenario(
            &d,
            &format!(
                "urdf = \"{}\"\ncouplings = \"{}\"",
                bare.display(),
                couplings.display()
            ),
        ),
        &d.join("b"),
        &[],
    );
    assert_eq!(
        std::fs::read(&in_urdf).unwrap(),
        std::fs::read(&beside).unwrap()
    );
    // Seven joint columns: the passive joint has none.
    let t = sim::measurement_table::read(&in_urdf).unwrap();
    assert_eq!(t.n_joints, 7);
    // Calibrated with the coupling beside the URDF, the model embeds it: predict needs no flag.
    let model = d.join("model.json");
    let (code, err) = common::robocal_status(&[
        "calibrate",
        "--robot",
        arg(&bare),
        "--tip-link",
        "left_flange",
        "--couplings",
        arg(&couplings),
        "--data",
        arg(&beside),
        "--model",
        "joint_compliance",
        "--out",
        arg(&model),
    ]);
    assert_eq!(code, Some(0), "{err}");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&model).unwrap()).unwrap();
    assert_eq!(json["robot"]["couplings"][0]["joint"], "torso_pitch_3");
    // One compliance per drive: joints 2, 3 and 5–8 (and the vertical yaw's, 1), none at joint 4.
    let names: Vec<&str> = json["extensions"]["names"]
        .as_array()
        .expect("the model file lists its extension parameters")
        .iter()
        .map(|p| p.as_str().unwrap())
        .collect();
    assert!(names.contains(&"joint 2 compliance"), "{names:?}");
    assert!(
        names.iter().all(|n| !n.starts_with("joint 4 ")),
        "a compliance of the passive joint: {names:?}"
    );
    let pred = d.join("pred.csv");
    let (code, err) = common::robocal_status(&[
        "predict",
        "--model",
        arg(&model),
        "--data",
        arg(&beside),
        "--out",
        arg(&pred),
    ]);
    assert_eq!(code, Some(0), "{err}");
    // Without the coupling the same data is a table of the wrong robot.
    let wrong = d.join("wrong.json");
    let (code, err) = common::robocal_status(&[
        "calibrate",
        "--robot",
        arg(&bare),
        "--tip-link",
        "left_flange",
        "--data",
        arg(&beside),
        "--out",
        arg(&wrong),
    ]);
    assert_eq!(code, Some(2), "{err}");
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn a_table_of_every_joint_must_agree_with_the_coupling_and_other_counts_are_refused() {
    let d = common::scratch_dir("robocal_cli_couplings", "columns");
    let data = common::generate(
        &scenario(&d, &format!("urdf = \"{}\"", urdf().display())),
        &d.join("g"),
        &[],
    );
    let t = sim::measurement_table::read(&data).unwrap();
    let model = common::load_chain(&urdf(), "left_flange");
    // Every chain joint, the passive one computed: accepted.
    let full = sim::measurement_table::couple(t.clone(), &model, &data).unwrap();
    assert_eq!(full.n_joints, 8);
    let ok = d.join("full.parquet");
    sim::measurement_table::write(&ok, &full).unwrap();
    let urdf = urdf();
    // `calibrate` of the torso on `data` into `out` (in the scratch folder), with `extra` flags.
    let calibrate = |data: &Path, out: &str, extra: &[&str]| {
        let out = d.join(out);
        let mut a = vec![
            "calibrate",
            "--robot",
            arg(&urdf),
            "--tip-link",
            "left_flange",
            "--data",
            arg(data),
            "--out",
            arg(&out),
        ];
        a.extend_from_slice(extra);
        common::robocal_status(&a)
    };
    let (code, err) = calibrate(&ok, "full.json", &[]);
    assert_eq!(code, Some(0), "{err}");
    // The passive joint's column off its coupling at row 17: the row and column are named.
    let mut off = full.clone();
    off.q[16 * 8 + 3] += 0.01;
    let bad = d.join("off.csv");
    sim::measurement_table::write(&bad, &off).unwrap();
    let (code, err) = calibrate(&bad, "off.json", &[]);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("row 17") && err.contains("q4") && err.contains("torso_pitch_3"),
        "{err}"
    );
    assert!(!d.join("off.json").exists());
    // Six joint columns: neither the drives nor the chain.
    let mut six = t.clone();
    six.n_joints = 6;
    six.q = t.q.chunks_exact(7).flat_map(|r| r[..6].to_vec()).collect();
    six.dir = None;
    let short = d.join("six.csv");
    sim::measurement_table::write(&short, &six).unwrap();
    let (code, err) = calibrate(&short, "six.json", &[]);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("6 joint columns") && err.contains("7 driven joints"),
        "{err}"
    );
    // Streaming and compensation do not handle coupled joints yet: they say so.
    let (code, err) = calibrate(&data, "stream.json", &["--stream", "always"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("coupled joints"), "{err}");
    let (full_model, q) = (d.join("full.json"), d.join("q.csv"));
    let (code, err) = common::robocal_status(&[
        "compensate",
        "--model",
        arg(&full_model),
        "--targets",
        arg(&data),
        "--out",
        arg(&q),
    ]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("coupled joints"), "{err}");
    let _ = std::fs::remove_dir_all(&d);
}
