//! Link deflection settled together with the joint springs (`sim::effects::link_deflection`) against
//! MuJoCo 4.0: `golden/settle_deflection_iiwa7.csv`, written by `scripts/mujoco_reference.py` (each
//! deflecting joint's child body gets two MuJoCo hinges about `u` and `v` with stiffness 1/c, settled
//! with MuJoCo's own forces), and the live copy in `$ROBOCAL_GOLDEN_LIVE` when set (CI re-runs the
//! script into that folder and compares it with the stored file).
//!
//! Required (issue 12): the flange within 1 µm of MuJoCo's for every row (200 configurations × two
//! compliance sets, one with joint springs, × payloads of 0 and 3 kg). Both sides solve the same
//! equilibrium to rounding, so the agreement is far better; the worst is printed. The rapier truth's
//! multibody with the same hinges (`RapierArm::with_deflection`) is held to the same bounds, its hinge
//! angles against MuJoCo's too.

mod common;

use nalgebra::{Matrix3, Vector3};
use sim::effects::joint_compliance::JointCompliance;
use sim::effects::link_deflection::LinkDeflection;
use sim::effects::{Conditions, Effects, Truth};
use sim::rapier_truth::{RapierArm, SettleOptions};
use sim::statics::{DEFAULT_GRAVITY, Payload};
use std::collections::BTreeMap;
use std::path::Path;

/// Flange position agreement with MuJoCo required by the issue (m).
const POSITION_TOL_M: f64 = 1e-6;
/// Flange orientation agreement, largest entry of `R_ours − R_mujoco`: both solve the same equilibrium
/// to rounding, and the flange rotation of a 1 µm position error at a 1 m arm would be 1e-6.
const ROTATION_TOL: f64 = 1e-6;
/// Joint angle agreement (rad): Newton to 1e-13 rad here, 1e-14 rad on MuJoCo's side.
const ANGLE_TOL_RAD: f64 = 1e-9;

struct Row {
    line: usize,
    k: Vec<f64>,
    c: Vec<[f64; 2]>,
    payload: Payload,
    q: Vec<f64>,
    theta: Vec<f64>,
    /// MuJoCo's hinge angles `[α, β]` per joint (rad).
    defl: Vec<[f64; 2]>,
    p: Vector3<f64>,
    r: Matrix3<f64>,
}

fn read(path: &Path) -> Vec<Row> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| {
        panic!(
            "{}: {e} (run python scripts/mujoco_reference.py --experiment deflection)",
            path.display()
        )
    });
    let mut header: Vec<String> = Vec::new();
    let mut rows = Vec::new();
    for (ln, line) in text.lines().enumerate() {
        if line.starts_with('#') || line.trim().is_empty() {
            continue;
        }
        if header.is_empty() {
            header = line.split(',').map(str::to_string).collect();
            continue;
        }
        let v: Vec<f64> = line
            .split(',')
            .map(|x| {
                x.parse()
                    .unwrap_or_else(|_| panic!("{}:{}: bad number {x}", path.display(), ln + 1))
            })
            .collect();
        assert_eq!(v.len(), header.len(), "{}:{}", path.display(), ln + 1);
        let col = |name: &str| {
            v[header
                .iter()
                .position(|h| h == name)
                .unwrap_or_else(|| panic!("{}: no column {name}", path.display()))]
        };
        let many = |p: &str| -> Vec<f64> { (1..=7).map(|i| col(&format!("{p}{i}"))).collect() };
        let (cu, cv) = (many("cu"), many("cv"));
        rows.push(Row {
            line: ln + 1,
            k: many("k"),
            c: cu.iter().zip(&cv).map(|(u, v)| [*u, *v]).collect(),
            payload: Payload {
                mass: col("payload_kg"),
                com: [col("payload_x"), col("payload_y"), col("payload_z")],
            },
            q: many("q"),
            theta: many("theta"),
            defl: many("alpha")
                .into_iter()
                .zip(many("beta"))
                .map(|(a, b)| [a, b])
                .collect(),
            p: Vector3::new(col("px"), col("py"), col("pz")),
            r: Matrix3::from_fn(|i, j| col(&format!("r{}{}", i + 1, j + 1))),
        });
    }
    rows
}

/// Per row: the flange displacement by link deflection (the truth's `deflection` contribution, m) and
/// the distance of the sim's flange from MuJoCo's (m), grouped by case label.
type Agreement = BTreeMap<String, Vec<(f64, f64)>>;

fn check_file(path: &Path) -> Agreement {
    let mut agreement = Agreement::new();
    let model = sim::robots::load_builtin("iiwa7").unwrap();
    let rows = read(path);
    assert!(rows.len() >= 800, "{}: {} rows", path.display(), rows.len());
    let mut cases: BTreeMap<String, Vec<&Row>> = BTreeMap::new();
    for r in &rows {
        cases
            .entry(format!("{:?} {:?} {:?}", r.k, r.c, r.payload))
            .or_default()
            .push(r);
    }
    assert_eq!(cases.len(), 4, "two compliance sets × two payloads");
    assert!(
        rows.iter().any(|r| r.k.iter().all(|k| k.is_finite()))
            && rows.iter().any(|r| r.k.iter().all(|k| k.is_infinite())),
        "one set with joint springs, one with rigid joints"
    );
    let g = Vector3::from(DEFAULT_GRAVITY);
    let (mut worst_p, mut worst_r, mut worst_th) = (0.0f64, 0.0f64, 0.0f64);
    let mut worst_line = 0;
    let (mut worst_rapier, mut rapier_steps) = ((0.0f64, 0.0f64), 0usize);
    for group in cases.values() {
        let first = group[0];
        // Rigid joints: no compliance effect at all (the deflection stage holds them at q).
        let compliance = first
            .k
            .iter()
            .any(|k| k.is_finite())
            .then(|| JointCompliance::new(first.k.clone()).unwrap());
        let effects = Effects {
            compliance,
            deflection: Some(LinkDeflection::new(first.c.clone()).unwrap()),
            ..Effects::default()
        };
        let truth = Truth::new(&model, &effects).unwrap();
        let mut s = truth.scratch();
        let arm = RapierArm::with_deflection(
            &model,
            &first.k,
            &first.c,
            Some(&first.payload),
            &g,
            SettleOptions::default(),
        )
        .unwrap();
        let mut ws = arm.workspace();
        let label = format!(
            "{}, {} kg",
            if effects.compliance.is_some() {
                "joint springs + deflection at 2, 4, 6"
            } else {
                "rigid joints, deflection everywhere"
            },
            first.payload.mass
        );
        let points = agreement.entry(label).or_default();
        for r in group {
            let cond = Conditions {
                q: &r.q,
                dir: None,
                temp_c: 20.0,
                payload: Some(r.payload),
                branch: None,
            };
            let t = truth.target(&cond, &Vector3::zeros(), &g, &mut s).unwrap();
            let dp = (t.flange.translation.vector - r.p).norm();
            let dr = (t.flange.rotation.matrix() - r.r).amax();
            let dth = s
                .q_link()
                .iter()
                .zip(&r.theta)
                .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
            assert!(
                dp < POSITION_TOL_M && dr < ROTATION_TOL && dth < ANGLE_TOL_RAD,
                "{}:{}: flange off MuJoCo by {dp:e} m (rotation {dr:e}), joints by {dth:e} rad",
                path.display(),
                r.line
            );
            points.push((Vector3::from(t.contribution.deflection).norm(), dp));
            // The rapier multibody with the same hinges, settled from rest.
            let sr = arm.settle(&mut ws, &r.q).unwrap();
            let rp = (sr.flange.translation.vector - r.p).norm();
            let rth = sr
                .q_link
                .iter()
                .zip(&r.theta)
                .chain(
                    sr.deflection_rad
                        .iter()
                        .flatten()
                        .zip(r.defl.iter().flatten()),
                )
                .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
            assert!(
                rp < POSITION_TOL_M && rth < ANGLE_TOL_RAD,
                "{}:{}: rapier flange off MuJoCo by {rp:e} m, joints or hinges by {rth:e} rad",
                path.display(),
                r.line
            );
            worst_rapier = (worst_rapier.0.max(rp), worst_rapier.1.max(rth));
            rapier_steps += sr.steps;
            if dp > worst_p {
                worst_line = r.line;
            }
            worst_p = worst_p.max(dp);
            worst_r = worst_r.max(dr);
            worst_th = worst_th.max(dth);
        }
    }
    eprintln!(
        "{}: {} rows; worst difference to MuJoCo: flange {worst_p:.2e} m (line {worst_line}), \
         rotation {worst_r:.2e}, joints {worst_th:.2e} rad; rapier (mean {:.1} steps): flange {:.2e} m, \
         joints and hinges {:.2e} rad",
        path.display(),
        rows.len(),
        rapier_steps as f64 / rows.len() as f64,
        worst_rapier.0,
        worst_rapier.1
    );
    agreement
}

#[test]
fn joint_and_deflection_settle_agrees_with_mujoco_on_every_row() {
    check_file(&common::repo_root().join("golden/settle_deflection_iiwa7.csv"));
    match std::env::var_os("ROBOCAL_GOLDEN_LIVE") {
        Some(dir) => {
            check_file(&Path::new(&dir).join("settle_deflection_iiwa7.csv"));
        }
        None if std::env::var_os("CI").is_some() => {
            panic!("CI must re-run scripts/mujoco_reference.py and set ROBOCAL_GOLDEN_LIVE")
        }
        None => eprintln!("ROBOCAL_GOLDEN_LIVE not set: only the stored reference was checked"),
    }
}

/// Writes `docs/figures/deflection_mujoco.svg` (the figure of docs/physics_truth.md) from the stored
/// reference: `cargo test -p sim --test mujoco_deflection -- --ignored write_figure`.
#[test]
#[ignore = "writes the documentation figure"]
fn write_figure() {
    let agreement = check_file(&common::repo_root().join("golden/settle_deflection_iiwa7.csv"));
    // Exact agreement (0 m) cannot sit on a log axis: drawn at 1e-17 m, below every nonzero value.
    let floor = 1e-17;
    let mut series: Vec<plot::Series> = agreement
        .into_iter()
        .map(|(label, points)| plot::Series {
            label,
            points: points.into_iter().map(|(x, d)| (x, d.max(floor))).collect(),
            style: plot::Style::Markers,
        })
        .collect();
    series.push(plot::Series {
        label: "required (issue 12): 1 µm".into(),
        points: vec![(1e-6, 1e-6), (1e-3, 1e-6)],
        style: plot::Style::Dashed,
    });
    let fig = plot::Plot {
        title: "Link deflection with joint springs: sim vs MuJoCo 4.0, 800 settled iiwa 7 poses"
            .into(),
        x_label: "flange displacement by link deflection (m)".into(),
        y_label: "|flange(sim) − flange(MuJoCo)| (m); 0 drawn at 1e-17".into(),
        log_x: true,
        log_y: true,
        series,
    };
    let out = common::repo_root().join("docs/figures/deflection_mujoco.svg");
    std::fs::create_dir_all(out.parent().unwrap()).unwrap();
    sim::io::write_atomic(&out, fig.to_svg(760, 460).as_bytes()).unwrap();
    eprintln!("wrote {}", out.display());
}
