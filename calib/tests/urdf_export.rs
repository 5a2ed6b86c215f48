//! The calibrated URDF as a drop-in replacement (issue 15 item 6): the user's file with only the
//! chain's joint origins changed and a comment added; its forward kinematics, with the base and target
//! transforms its comment gives, equal the calibrated robot.
//!
//! The expected positions come from `common::Truth::target` (product of exponentials on screws moved
//! by `Ad(exp ξ)`, `sim::kinematics::poe_pose`), never from `calib::model::chain` or the exporter; the file
//! is read back by sim's URDF reader and evaluated by sim's forward kinematics (the chain of URDF
//! frames). MuJoCo does the same from Python in `scripts/check_urdf_out.py`.

mod common;

use calib::model::file::{CalibratedModel, EmbeddedRobot, ModelParameters, PoseJson};
use calib::model::urdf_export::{COMMENT_MARKER, calibrated_urdf};
use common::{Truth, random_configs, rng};
use nalgebra::{Matrix3, Point3, Vector3};
use sim::lie::{Pose, pose_from, rotation_from_rpy};
use sim::{ChainSpec, Model, urdf};
use std::path::PathBuf;

fn shared_dir() -> PathBuf {
    std::env::var_os("ROBOCAL_SHARED").map_or_else(
        || PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared"),
        PathBuf::from,
    )
}

/// The six URDFs: the four built-ins and the two third-party iiwa 7 exports.
fn urdfs() -> Vec<(String, String)> {
    let mut v: Vec<(String, String)> = ["iiwa7", "ur5", "ur10", "wam"]
        .iter()
        .map(|n| {
            (
                n.to_string(),
                sim::robots::builtin_urdf(n).unwrap().to_string(),
            )
        })
        .collect();
    for f in ["iiwa_stack_iiwa7.urdf", "lbr_stack_iiwa7.urdf"] {
        let p = shared_dir().join("data/robots").join(f);
        let text = std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        v.push((f.to_string(), text));
    }
    v
}

fn rows(m: &Matrix3<f64>) -> [[f64; 3]; 3] {
    [0, 1, 2].map(|i| [m[(i, 0)], m[(i, 1)], m[(i, 2)]])
}

/// A model file holding `truth` exactly (no calibration needed: the export is a function of the
/// parameters).
fn model_file(text: &str, model: &Model, truth: &Truth, model_name: &str) -> CalibratedModel {
    CalibratedModel {
        format: calib::model::file::FORMAT.into(),
        format_version: calib::model::file::FORMAT_VERSION,
        software: "test".into(),
        model: model_name.parse().unwrap(),
        robot: EmbeddedRobot {
            name: model.name().to_string(),
            source: "test".into(),
            base_link: model.base_link().to_string(),
            tip_link: model.tip_link().to_string(),
            urdf: text.to_string(),
            urdf_fnv1a64: None,
            couplings: Vec::new(),
        },
        parameters: ModelParameters {
            joint_error_twists: truth
                .twists
                .iter()
                .map(|t| [t[0], t[1], t[2], t[3], t[4], t[5]])
                .collect(),
            zero_offsets: truth.zero_offsets.clone(),
            t_tracker_base: PoseJson {
                translation_m: truth.t_tracker_base.translation.vector.into(),
                rotation: rows(truth.t_tracker_base.rotation.matrix()),
            },
            p_flange_target_m: truth.p_flange.into(),
            r_flange_target: truth.r_flange_target.as_ref().map(rows),
            campaign: 0,
            campaigns: Vec::new(),
            default_campaign: None,
        },
        covariance: None,
        extensions: None,
        learned: None,
        fit: None,
    }
}

fn floats(s: &str) -> [f64; 3] {
    let v: Vec<f64> = s.split_whitespace().map(|x| x.parse().unwrap()).collect();
    [v[0], v[1], v[2]]
}

/// The `<origin>` the comment gives after `key:`, as a pose (rpy zero when absent).
fn comment_origin(text: &str, key: &str) -> Pose {
    let line = text
        .lines()
        .find_map(|l| l.trim().strip_prefix(&format!("{key}: ")))
        .unwrap_or_else(|| panic!("no '{key}:' line"));
    let attr = |name: &str| {
        line.split(&format!("{name}=\""))
            .nth(1)
            .map(|s| floats(s.split('"').next().unwrap()))
    };
    let xyz = attr("xyz").unwrap();
    let rpy = attr("rpy").unwrap_or([0.0; 3]);
    pose_from(
        rotation_from_rpy(rpy[0], rpy[1], rpy[2]),
        Vector3::from(xyz),
    )
}

/// The lines of `out` that differ from `input`, after the comment block is taken out; each must be an
/// `<origin .../>` line, and there must be as many as joints were changed.
fn changed_lines(input: &str, out: &str) -> Vec<(String, String)> {
    let start = out
        .find(&format!("<!-- {COMMENT_MARKER}"))
        .expect("comment");
    let end = start + out[start..].find("-->").unwrap() + 3;
    // The block was inserted after the <robot> start tag with a line break before it.
    let without = format!(
        "{}{}",
        &out[..start].trim_end_matches([' ', '\n']),
        &out[end..]
    );
    let (a, b): (Vec<&str>, Vec<&str>) = (input.lines().collect(), without.lines().collect());
    assert_eq!(a.len(), b.len(), "line count changed");
    a.iter()
        .zip(&b)
        .filter(|(x, y)| x != y)
        .map(|(x, y)| (x.to_string(), y.to_string()))
        .collect()
}

/// The file's tip position, through the comment's transforms, against the truth at `configs`.
fn worst_target_error(text: &str, model: &Model, truth: &Truth, configs: &[Vec<f64>]) -> f64 {
    let spec = ChainSpec {
        base_link: Some(model.base_link().to_string()),
        tip_link: Some(model.tip_link().to_string()),
    };
    let written = urdf::load_str(text, "written", &spec).unwrap();
    let base = comment_origin(text, "T_tracker_base");
    let target = comment_origin(text, "T_tip_target");
    let mut data = sim::Data::new(&written);
    let mut worst = 0.0f64;
    for q in configs {
        let t = base * sim::flange_pose(&written, &mut data, q) * target;
        let p = (t * Point3::origin()).coords;
        let (expected, r) = truth.target(model, q);
        worst = worst.max((p - expected).norm());
        if truth.r_flange_target.is_some() {
            worst = worst.max((t.rotation.matrix() - r).amax());
        }
    }
    worst
}

#[test]
fn only_the_chain_origins_change_and_the_file_is_the_calibrated_robot() {
    for (k, (name, text)) in urdfs().into_iter().enumerate() {
        let model = urdf::load_str(&text, &name, &ChainSpec::default()).unwrap();
        let mut g = rng(900 + k as u64);
        let truth = Truth::random(&model, k % 2 == 1, &mut g);
        let file = model_file(&text, &model, &truth, "kinematic");
        let out = calibrated_urdf(&file).unwrap();
        assert!(out.warnings.is_empty(), "{name}: {:?}", out.warnings);
        // Every movable joint and the fixed flange joint after the last one moved, nothing else.
        let chain = urdf::chain_joints(&text, &name, &ChainSpec::default()).unwrap();
        let last = chain.iter().rposition(|c| c.movable).unwrap();
        let expected_changed: Vec<String> = chain
            .iter()
            .enumerate()
            .filter(|(i, c)| c.movable || *i == last + 1)
            .map(|(_, c)| c.name.clone())
            .collect();
        assert_eq!(out.changed, expected_changed, "{name}");
        let diff = changed_lines(&text, &out.text);
        assert_eq!(diff.len(), out.changed.len(), "{name}: {diff:#?}");
        for (before, after) in &diff {
            assert!(
                before.trim_start().starts_with("<origin")
                    && after.trim_start().starts_with("<origin"),
                "{name}: {before} -> {after}"
            );
        }
        // The comment names the changed joints and both transforms.
        assert!(out.text.contains(&out.changed.join(", ")), "{name}");
        // Forward kinematics of the written file equal the truth.
        let configs = random_configs(&model, 300, &mut g);
        let worst = worst_target_error(&out.text, &model, &truth, &configs);
        eprintln!("{name}: written URDF vs truth {worst:.1e} m");
        assert!(worst < 1e-12, "{name}: {worst:e}");
        // The file loads back with the default chain, and a second export replaces the comment.
        let again = urdf::load_str(&out.text, "written", &ChainSpec::default()).unwrap();
        assert_eq!(
            (again.tip_link(), again.nq()),
            (model.tip_link(), model.nq())
        );
        let twice = calibrated_urdf(&model_file(&out.text, &model, &truth, "kinematic")).unwrap();
        assert_eq!(twice.text.matches(COMMENT_MARKER).count(), 1, "{name}");
        // The CLI's own check agrees.
        let params = file.params();
        assert!(out.deviation(&model, &params, &configs[..20]).unwrap() < 1e-12);
    }
}

/// The nominal robot changes no origin: the file is the input plus the comment.
#[test]
fn the_nominal_robot_changes_only_the_comment() {
    let text = sim::robots::builtin_urdf("iiwa7").unwrap();
    let model = urdf::load_str(text, "iiwa7", &ChainSpec::default()).unwrap();
    let mut truth = Truth::random(&model, false, &mut rng(3));
    truth.twists.iter_mut().for_each(|t| t.fill(0.0));
    truth.zero_offsets.fill(0.0);
    let out = calibrated_urdf(&model_file(text, &model, &truth, "kinematic")).unwrap();
    assert!(out.changed.is_empty());
    assert!(changed_lines(text, &out.text).is_empty());
    assert!(
        out.text
            .contains("(none: the calibrated robot is the nominal one)")
    );
}

/// A URDF that exercises every case of the export: fixed joints between movable joints (their
/// origins stay, the next movable joint's origin absorbs them), joints without `<origin>` (one is
/// added), a prismatic and a continuous joint, a base link below the root (the joint above it is
/// untouched), links off the chain, a transmission naming a joint, and a tip link that is the last
/// movable joint's child: the flange cannot be placed by an origin, which is warned about and carried
/// by the comment's target transform.
#[test]
fn fixed_joints_missing_origins_and_a_tip_without_flange_joint() {
    let text = r#"<?xml version="1.0"?>
<robot name="odd">
  <link name="world"/>
  <link name="base"/>
  <link name="l1"/>
  <link name="l1b"/>
  <link name="l2"/>
  <link name="l3"/>
  <link name="camera"><visual><geometry><mesh filename="package://x/cam.dae"/></geometry></visual></link>
  <joint name="mount" type="fixed">
    <parent link="world"/>
    <child link="base"/>
    <origin xyz="1 2 0" rpy="0 0 0.3"/>
  </joint>
  <joint name="j1" type="revolute">
    <parent link="base"/>
    <child link="l1"/>
    <axis xyz="0 0 1"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/>
  </joint>
  <joint name="weld" type="fixed">
    <parent link="l1"/>
    <child link="l1b"/>
    <origin xyz="0.1 0 0.3" rpy="0.2 -0.1 0.4"/>
  </joint>
  <joint name="slide" type="prismatic">
    <parent link="l1b"/>
    <child link="l2"/>
    <origin xyz="0 0.05 0.1"/>
    <axis xyz="1 0 0"/>
    <limit lower="0" upper="0.5" effort="1" velocity="1"/>
  </joint>
  <joint name="spin" type="continuous">
    <parent link="l2"/>
    <child link="l3"/>
    <origin xyz="0.2 0 0" rpy="1.5707963267948966 0 0"/>
    <axis xyz="0 1 0"/>
  </joint>
  <joint name="cam" type="fixed">
    <parent link="l1"/>
    <child link="camera"/>
    <origin xyz="0 0.1 0"/>
  </joint>
  <transmission name="t1"><joint name="j1"><hardwareInterface>x</hardwareInterface></joint></transmission>
</robot>
"#;
    let spec = ChainSpec {
        base_link: Some("base".into()),
        tip_link: None,
    };
    let model = urdf::load_str(text, "odd", &spec).unwrap();
    assert_eq!((model.nq(), model.tip_link()), (3, "l3"));
    for orientation in [false, true] {
        let mut g = rng(41 + u64::from(orientation));
        let truth = Truth::random(&model, orientation, &mut g);
        let out = calibrated_urdf(&model_file(text, &model, &truth, "kinematic")).unwrap();
        assert_eq!(out.changed, ["j1", "slide", "spin"]);
        assert_eq!(out.warnings.len(), 1);
        assert!(
            out.warnings[0]
                .contains("the tip link 'l3' is the child of the last movable joint 'spin'"),
            "{}",
            out.warnings[0]
        );
        assert!(out.text.contains("Warning: the tip link 'l3'"));
        assert!(out.t_tip_flange.translation.vector.norm() > 1e-6);
        // 'mount' (above the base), 'weld' (between movable joints) and 'cam' (off the chain) kept.
        for kept in [
            "<origin xyz=\"1 2 0\" rpy=\"0 0 0.3\"/>",
            "<origin xyz=\"0.1 0 0.3\" rpy=\"0.2 -0.1 0.4\"/>",
            "<origin xyz=\"0 0.1 0\"/>",
            "<transmission name=\"t1\"><joint name=\"j1\"><hardwareInterface>x</hardwareInterface></joint></transmission>",
            "package://x/cam.dae",
        ] {
            assert!(out.text.contains(kept), "{kept}");
        }
        // j1 had no <origin>: one was added as its first child, indented like the next one.
        assert!(
            out.text
                .contains("<joint name=\"j1\" type=\"revolute\">\n    <origin xyz=\""),
            "{}",
            out.text
        );
        let configs = random_configs(&model, 200, &mut g);
        let worst = worst_target_error(&out.text, &model, &truth, &configs);
        eprintln!("odd robot (orientation {orientation}): {worst:.1e}");
        assert!(worst < 1e-12, "{worst:e}");
        let params = model_file(text, &model, &truth, "kinematic").params();
        assert!(out.deviation(&model, &params, &configs[..20]).unwrap() < 1e-12);
    }
}

/// A model with parts a URDF cannot hold is exported with its kinematic part and a warning.
#[test]
fn a_model_with_extensions_is_exported_with_a_warning() {
    let text = sim::robots::builtin_urdf("ur5").unwrap();
    let model = urdf::load_str(text, "ur5", &ChainSpec::default()).unwrap();
    let truth = Truth::random(&model, false, &mut rng(5));
    let out = calibrated_urdf(&model_file(
        text,
        &model,
        &truth,
        "kinematic+joint_compliance",
    ))
    .unwrap();
    assert_eq!(out.warnings.len(), 1);
    assert!(
        out.warnings[0].contains("'kinematic+joint_compliance' has parts a URDF cannot express")
    );
    assert!(
        out.text
            .contains("Warning: the model 'kinematic+joint_compliance'")
    );
}
