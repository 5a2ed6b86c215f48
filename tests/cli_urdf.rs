//! URDFs at the command line (issue 15): an ambiguous chain is one line listing the leaves, exit 2;
//! `--urdf-out` writes the user's URDF with the calibrated origins, the same bytes from `calibrate`
//! and `predict`, and warns about what a URDF cannot express. The file's geometry is checked against
//! independent computations in `calib/tests/urdf_export.rs` and `scripts/check_urdf_out.py` (MuJoCo).

use std::path::{Path, PathBuf};

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("robocal_cli_urdf_{}_{name}", std::process::id()));
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

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// `robocal generate` of a shipped scenario into `d/gen`; the measurement file.
fn generate(d: &Path, scenario: &str, poses: &str) -> PathBuf {
    let gen_dir = d.join("gen");
    let scenario = repo().join("scenarios").join(scenario);
    let args = [
        "generate",
        "--scenario",
        s(&scenario),
        "--out",
        s(&gen_dir),
        "--poses",
        poses,
    ];
    let (c, e) = robocal(&args);
    assert_eq!(c, Some(0), "{e}");
    gen_dir.join("measurements.parquet")
}

const INERTIAL: &str = r#"<inertial><mass value="1"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>"#;

/// A two-joint arm with `tool0` and `ft_frame` both off the last link.
fn two_tool_frames() -> String {
    let link = |n: &str| format!(r#"<link name="{n}">{INERTIAL}</link>"#);
    let rev = |n: &str, p: &str, c: &str| {
        format!(
            r#"<joint name="{n}" type="revolute"><parent link="{p}"/><child link="{c}"/><origin xyz="0 0 0.3"/><axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>"#
        )
    };
    let fixed = |n: &str, p: &str, c: &str, z: f64| {
        format!(
            r#"<joint name="{n}" type="fixed"><parent link="{p}"/><child link="{c}"/><origin xyz="0 0 {z}"/></joint>"#
        )
    };
    format!(
        "<robot name=\"two_tools\">{}{}{}{}{}{}{}{}{}</robot>",
        link("base"),
        link("l1"),
        link("l2"),
        link("tool0"),
        link("ft_frame"),
        rev("j1", "base", "l1"),
        rev("j2", "l1", "l2"),
        fixed("tool0_joint", "l2", "tool0", 0.1),
        fixed("ft_joint", "l2", "ft_frame", 0.02),
    )
}

#[test]
fn an_ambiguous_tip_is_one_line_listing_the_leaves_until_tip_link_chooses() {
    let d = dir("ambiguous");
    let urdf = d.join("two_tools.urdf");
    std::fs::write(&urdf, two_tool_frames()).unwrap();
    for cmd in [
        vec!["info", "--robot", s(&urdf)],
        vec!["fk", "--robot", s(&urdf), "--q", "0,0"],
    ] {
        let (c, e) = robocal(&cmd);
        assert_eq!(c, Some(2), "{cmd:?}: {e}");
        assert_eq!(e.trim().lines().count(), 1, "{e}");
        assert!(
            e.contains(s(&urdf))
                && e.contains("leaf links 'ft_frame', 'tool0' hang off 'l2'")
                && e.contains("--tip-link"),
            "{e}"
        );
    }
    let (c, e) = robocal(&[
        "fk",
        "--robot",
        s(&urdf),
        "--q",
        "0,0",
        "--tip-link",
        "tool0",
    ]);
    assert_eq!(c, Some(0), "{e}");
    assert!(e.contains("tool0"), "{e}");
    let _ = std::fs::remove_dir_all(&d);
}

/// `calibrate --urdf-out` and `predict --urdf-out` write the same bytes for the same model; the file
/// is the built-in URDF with the comment block and changed origins, and loads back.
#[test]
fn calibrate_and_predict_write_the_same_calibrated_urdf() {
    let d = dir("same");
    let data = generate(&d, "ur5_kinematic.toml", "40");
    let (model, from_cal, from_pred, pred) = (
        d.join("model.json"),
        d.join("cal.urdf"),
        d.join("pred.urdf"),
        d.join("pred.csv"),
    );
    let (c, e) = robocal(&[
        "calibrate",
        "--robot",
        "ur5",
        "--data",
        s(&data),
        "--out",
        s(&model),
        "--urdf-out",
        s(&from_cal),
    ]);
    assert_eq!(c, Some(0), "{e}");
    assert!(!e.lines().any(|l| l.contains("cal.urdf: ")), "{e}");
    let (c, e) = robocal(&[
        "predict",
        "--model",
        s(&model),
        "--data",
        s(&data),
        "--out",
        s(&pred),
        "--urdf-out",
        s(&from_pred),
    ]);
    assert_eq!(c, Some(0), "{e}");
    let a = std::fs::read_to_string(&from_cal).unwrap();
    assert_eq!(a, std::fs::read_to_string(&from_pred).unwrap());
    let original = std::fs::read_to_string(repo().join("sim/robots/ur5.urdf")).unwrap();
    assert!(a.contains("<!-- robocal-calibration") && a.contains("T_tracker_base: <origin"));
    // Same number of lines plus the comment block; every other differing line is an <origin>.
    let block = a.lines().skip_while(|l| !l.contains("robocal-calibration"));
    let block_len = block.take_while(|l| l.trim() != "-->").count() + 1;
    assert_eq!(a.lines().count(), original.lines().count() + block_len);
    let (c, e) = robocal(&["info", "--robot", s(&from_cal)]);
    assert_eq!(c, Some(0), "{e}");
    let _ = std::fs::remove_dir_all(&d);
}

/// A model with joint compliance: the URDF holds its kinematic part, and robocal says how far that is
/// from the full model on the table (the sag of a loaded iiwa is tenths of a millimetre and more).
#[test]
fn a_compliance_model_warns_with_the_gap_on_the_table() {
    let d = dir("compliance");
    let data = generate(&d, "iiwa7_compliance.toml", "80");
    let (model, urdf) = (d.join("model.json"), d.join("cal.urdf"));
    let (c, e) = robocal(&[
        "calibrate",
        "--data",
        s(&data),
        "--model",
        "kinematic+joint_compliance",
        "--out",
        s(&model),
        "--urdf-out",
        s(&urdf),
    ]);
    assert_eq!(c, Some(0), "{e}");
    let warn: Vec<&str> = e.lines().filter(|l| l.contains("cal.urdf: ")).collect();
    assert_eq!(warn.len(), 2, "{e}");
    assert!(warn[0].contains("'kinematic+joint_compliance' has parts a URDF cannot express"));
    let mm: f64 = warn[1]
        .split("by up to ")
        .nth(1)
        .and_then(|x| x.strip_suffix(" mm"))
        .and_then(|x| x.parse().ok())
        .unwrap_or_else(|| panic!("{}", warn[1]));
    assert!(mm > 0.01, "{}", warn[1]);
    let text = std::fs::read_to_string(&urdf).unwrap();
    assert!(text.contains("Warning: the model 'kinematic+joint_compliance'"));
    let _ = std::fs::remove_dir_all(&d);
}
