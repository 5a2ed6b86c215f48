//! The rapier physics-engine truth (`sim::rapier_truth`) against independent computations:
//!
//! * MuJoCo 4.0 (`golden/settle_iiwa7.csv`, written by `scripts/mujoco_reference.py`, and the live copy
//!   in `$ROBOCAL_GOLDEN_LIVE` when set): rapier, the analytic statics of `sim::effects` and a small
//!   fixed-point solver written here on top of `sim::statics::gravity_torques` must all land on
//!   MuJoCo's settled flange within 1 µm (and on its joint angles within 1 nrad);
//! * closed forms: a spring-loaded pendulum and a vertical spring-loaded slider;
//! * invariances: the rest state does not depend on the time step, on what the workspace settled
//!   before, or on the number of threads.

mod common;

use nalgebra::Vector3;
use sim::effects::{Conditions, Effects, Truth, joint_compliance::JointCompliance};
use sim::rapier_truth::{RapierArm, SettleOptions, settle_many};
use sim::statics::{DEFAULT_GRAVITY, Payload, gravity_torques};
use sim::{ChainSpec, Data, Model, SimError};
use std::collections::BTreeMap;
use std::path::Path;

/// Flange position agreement with MuJoCo required of every computation (m), as set for this truth.
const POSITION_TOL_M: f64 = 1e-6;
/// Link-side joint angle agreement with MuJoCo (rad): all three solve the same equilibrium to far better
/// than this (rapier's rest test stops within ~1e-12 rad, Newton within 1e-14 rad).
const ANGLE_TOL_RAD: f64 = 1e-9;
/// The fixed-point solver of this file stops when its step is below this (rad).
const FIXED_POINT_TOL_RAD: f64 = 1e-15;

fn gravity() -> Vector3<f64> {
    Vector3::from(DEFAULT_GRAVITY)
}

/// One settle case of the golden file: stiffness set and payload.
#[derive(Clone, Debug, PartialEq)]
struct Case {
    k: Vec<f64>,
    payload: Payload,
}

struct Row {
    line: usize,
    case: Case,
    q: Vec<f64>,
    theta: Vec<f64>,
    p: Vector3<f64>,
}

/// Reads `settle_<robot>.csv` by header name.
fn read_settle(path: &Path, n: usize) -> Vec<Row> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| {
        panic!(
            "{}: {e} (run python scripts/mujoco_reference.py --experiment settle)",
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
        assert_eq!(
            v.len(),
            header.len(),
            "{}:{}: columns",
            path.display(),
            ln + 1
        );
        let col = |name: &str| {
            let c = header
                .iter()
                .position(|h| h == name)
                .unwrap_or_else(|| panic!("{}: no column {name}", path.display()));
            v[c]
        };
        let many =
            |prefix: &str| -> Vec<f64> { (1..=n).map(|i| col(&format!("{prefix}{i}"))).collect() };
        rows.push(Row {
            line: ln + 1,
            case: Case {
                k: many("k"),
                payload: Payload {
                    mass: col("payload_kg"),
                    com: [col("payload_x"), col("payload_y"), col("payload_z")],
                },
            },
            q: many("q"),
            theta: many("theta"),
            p: Vector3::new(col("px"), col("py"), col("pz")),
        });
    }
    rows
}

/// Link-side angles from `θ ← q − K⁻¹ τ_g(θ)` iterated to a fixed point, with `τ_g` from
/// `sim::statics::gravity_torques` (independent of `sim::effects` and of rapier). Converges because
/// `‖K⁻¹ ∂τ_g/∂θ‖ < 1` for these stiffnesses (checked by the iteration count bound).
fn fixed_point(model: &Model, data: &mut Data, case: &Case, q: &[f64]) -> Vec<f64> {
    let mut theta = q.to_vec();
    for _ in 0..500 {
        gravity_torques(model, data, &theta, &gravity(), Some(&case.payload)).unwrap();
        let mut step = 0.0f64;
        for i in 0..q.len() {
            let next = q[i] - data.gravity_torque[i] / case.k[i];
            step = step.max((next - theta[i]).abs());
            theta[i] = next;
        }
        if step < FIXED_POINT_TOL_RAD {
            return theta;
        }
    }
    panic!("fixed point did not converge at q = {q:?}");
}

fn check_settle_file(path: &Path) {
    let model = sim::robots::load_builtin("iiwa7").unwrap();
    let n = model.nq();
    let rows = read_settle(path, n);
    assert!(
        rows.len() >= 800,
        "{}: only {} rows",
        path.display(),
        rows.len()
    );
    let mut cases: BTreeMap<String, Vec<&Row>> = BTreeMap::new();
    for r in &rows {
        cases.entry(format!("{:?}", r.case)).or_default().push(r);
    }
    assert_eq!(cases.len(), 4, "two stiffness sets × two payloads");
    assert!(
        rows.iter().any(|r| r.case.payload.mass == 3.0)
            && rows.iter().any(|r| r.case.payload.mass == 0.0)
    );
    let mut data = Data::new(&model);
    let mut worst = [(0.0f64, 0.0f64); 3]; // (position m, angle rad) for rapier, analytic, fixed point
    let mut steps = 0usize;
    for group in cases.values() {
        let case = &group[0].case;
        let arm = RapierArm::new(
            &model,
            &case.k,
            Some(&case.payload),
            &gravity(),
            SettleOptions::default(),
        )
        .unwrap();
        let mut ws = arm.workspace();
        let effects = Effects {
            compliance: Some(JointCompliance::new(case.k.clone()).unwrap()),
            ..Effects::default()
        };
        let truth = Truth::new(&model, &effects).unwrap();
        let mut scratch = truth.scratch();
        for r in group {
            let s = arm.settle(&mut ws, &r.q).unwrap();
            steps += s.steps;
            let cond = Conditions {
                q: &r.q,
                dir: None,
                temp_c: 20.0,
                payload: Some(case.payload),
                branch: None,
            };
            let a = truth
                .target(&cond, &Vector3::zeros(), &gravity(), &mut scratch)
                .unwrap();
            let fp = fixed_point(&model, &mut data, case, &r.q);
            sim::forward_kinematics(&model, &mut data, &fp);
            let results = [
                (s.flange.translation.vector, s.q_link.clone()),
                (a.flange.translation.vector, scratch.q_link().to_vec()),
                (data.flange.translation.vector, fp),
            ];
            let names = ["rapier", "analytic", "fixed point"];
            for ((w, (p, th)), name) in worst.iter_mut().zip(&results).zip(names) {
                let dp = (p - r.p).norm();
                let dth = th
                    .iter()
                    .zip(&r.theta)
                    .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
                assert!(
                    dp < POSITION_TOL_M && dth < ANGLE_TOL_RAD,
                    "{}:{}: {name}: flange off MuJoCo by {dp:e} m, joints by {dth:e} rad",
                    path.display(),
                    r.line
                );
                w.0 = w.0.max(dp);
                w.1 = w.1.max(dth);
            }
        }
    }
    eprintln!(
        "{}: {} rows; worst flange / joint difference to MuJoCo: rapier {:.2e} m / {:.2e} rad \
         (mean {:.1} steps), analytic {:.2e} m / {:.2e} rad, fixed point {:.2e} m / {:.2e} rad",
        path.display(),
        rows.len(),
        worst[0].0,
        worst[0].1,
        steps as f64 / rows.len() as f64,
        worst[1].0,
        worst[1].1,
        worst[2].0,
        worst[2].1
    );
}

#[test]
fn rapier_analytic_and_mujoco_agree_on_every_settled_pose() {
    check_settle_file(&common::repo_root().join("golden/settle_iiwa7.csv"));
    if let Some(dir) = std::env::var_os("ROBOCAL_GOLDEN_LIVE") {
        check_settle_file(&Path::new(&dir).join("settle_iiwa7.csv"));
    }
}

/// A pendulum: joint about +y at the origin, a point-like link of mass `m` with its centre at
/// (`l`, 0, 0), flange at (`2l`, 0, 0).
fn pendulum(m: f64, l: f64) -> Model {
    let urdf = format!(
        r#"<robot name="pendulum">
      <link name="base"/>
      <joint name="j1" type="revolute"><parent link="base"/><child link="arm"/>
        <axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
      <link name="arm"><inertial><origin xyz="{l} 0 0"/><mass value="{m}"/>
        <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.02"/></inertial></link>
      <joint name="tool" type="fixed"><parent link="arm"/><child link="tip"/><origin xyz="{} 0 0"/></joint>
      <link name="tip"/>
    </robot>"#,
        2.0 * l
    );
    sim::urdf::load_str(&urdf, "pendulum", &ChainSpec::default()).unwrap()
}

/// Root of a scalar monotone function on [lo, hi] by bisection.
fn bisect(f: impl Fn(f64) -> f64, mut lo: f64, mut hi: f64) -> f64 {
    assert!(f(lo) * f(hi) < 0.0);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if f(lo) * f(mid) <= 0.0 {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    0.5 * (lo + hi)
}

#[test]
fn pendulum_settles_where_spring_balances_gravity() {
    // Rotating +x about +y by θ gives (cos θ, 0, −sin θ): the centre of mass is at height −l sin θ, the
    // potential is V = −m g l sin θ and the holding torque τ_g = V'(θ) = −m g l cos θ. With a payload
    // mₚ at the flange (distance 2l) add −mₚ g 2l cos θ. Equilibrium: k (q − θ) = τ_g(θ).
    let (m, l, k, g, mp) = (4.0, 0.4, 300.0, 9.81, 1.5);
    let model = pendulum(m, l);
    let pl = Payload {
        mass: mp,
        com: [0.0; 3],
    };
    for (q, with_payload) in [(0.0, false), (0.3, true), (-1.2, false), (2.0, true)] {
        let moment = m * l + if with_payload { mp * 2.0 * l } else { 0.0 };
        let expected = bisect(|t| k * (q - t) + moment * g * t.cos(), q - 1.0, q + 1.0);
        let arm = RapierArm::new(
            &model,
            &[k],
            with_payload.then_some(&pl),
            &Vector3::new(0.0, 0.0, -g),
            SettleOptions::default(),
        )
        .unwrap();
        let s = arm.settle(&mut arm.workspace(), &[q]).unwrap();
        assert!(
            (s.q_link[0] - expected).abs() < 1e-11,
            "q = {q}: rapier {} vs closed form {expected}",
            s.q_link[0]
        );
        let tip = Vector3::new(2.0 * l * expected.cos(), 0.0, -2.0 * l * expected.sin());
        assert!((s.flange.translation.vector - tip).norm() < 1e-11);
        assert!(s.residual < 1e-9 && s.steps > 1);
    }
}

#[test]
fn vertical_slider_sags_by_weight_over_stiffness() {
    // A prismatic joint along +z carrying 2 kg (and a 0.5 kg payload): θ = q − (m + mₚ) g / k.
    let urdf = r#"<robot name="slider">
      <link name="base"/>
      <joint name="z" type="prismatic"><parent link="base"/><child link="carriage"/>
        <origin xyz="0.1 0 0.2"/><axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
      <link name="carriage"><inertial><origin xyz="0.05 0 0"/><mass value="2"/>
        <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
    </robot>"#;
    let model = sim::urdf::load_str(urdf, "slider", &ChainSpec::default()).unwrap();
    let pl = Payload {
        mass: 0.5,
        com: [0.3, 0.0, 0.0],
    };
    let arm = RapierArm::new(
        &model,
        &[5000.0],
        Some(&pl),
        &gravity(),
        SettleOptions::default(),
    )
    .unwrap();
    let s = arm.settle(&mut arm.workspace(), &[0.25]).unwrap();
    let expected = 0.25 - 2.5 * 9.81 / 5000.0;
    assert!(
        (s.q_link[0] - expected).abs() < 1e-12,
        "{} vs {expected}",
        s.q_link[0]
    );
    assert!((s.flange.translation.vector - Vector3::new(0.1, 0.0, 0.2 + expected)).norm() < 1e-12);
}

/// Seeded commanded poses inside the iiwa's limits (deterministic low-discrepancy sequence).
fn poses(n: usize) -> Vec<Vec<f64>> {
    (0..n)
        .map(|k| {
            (0..7)
                .map(|i| {
                    ((k as f64 + 1.0) * (0.754877666 + 0.569840291 * i as f64)).fract() * 4.0 - 2.0
                })
                .collect()
        })
        .collect()
}

#[test]
fn rigid_joints_tilted_gravity_and_payload_match_the_analytic_statics() {
    let model = sim::robots::load_builtin("iiwa7").unwrap();
    let k = vec![
        f64::INFINITY,
        8000.0,
        6000.0,
        5000.0,
        3000.0,
        2000.0,
        f64::INFINITY,
    ];
    let pl = Payload {
        mass: 2.0,
        com: [0.05, 0.02, 0.1],
    };
    let g = Vector3::new(0.8, -0.5, -9.7);
    let arm = RapierArm::new(&model, &k, Some(&pl), &g, SettleOptions::default()).unwrap();
    let mut ws = arm.workspace();
    let effects = Effects {
        compliance: Some(JointCompliance::new(k.clone()).unwrap()),
        ..Effects::default()
    };
    let truth = Truth::new(&model, &effects).unwrap();
    let mut scratch = truth.scratch();
    for q in poses(20) {
        let s = arm.settle(&mut ws, &q).unwrap();
        let cond = Conditions {
            q: &q,
            dir: None,
            temp_c: 20.0,
            payload: Some(pl),
            branch: None,
        };
        let a = truth
            .target(&cond, &Vector3::zeros(), &g, &mut scratch)
            .unwrap();
        assert_eq!(
            s.q_link[0], q[0],
            "a rigid joint stays where it is commanded"
        );
        assert_eq!(s.q_link[6], q[6]);
        let dp = (s.flange.translation.vector - a.flange.translation.vector).norm();
        let dr = (s.flange.rotation.matrix() - a.flange.rotation.matrix()).amax();
        assert!(dp < 1e-10 && dr < 1e-10, "q = {q:?}: {dp:e} m, {dr:e}");
    }
}

#[test]
fn rest_state_does_not_depend_on_time_step_history_or_threads() {
    let model = sim::robots::load_builtin("iiwa7").unwrap();
    let k = [2500.0, 2500.0, 2000.0, 2000.0, 1500.0, 1000.0, 1000.0];
    let pl = Payload {
        mass: 3.0,
        com: [0.02, -0.01, 0.08],
    };
    let qs = poses(12);
    // A physical 1 ms step (thousands of steps of a real damped motion) comes to the same rest.
    let fine = SettleOptions {
        dt: 1e-3,
        max_steps: 100_000,
        ..SettleOptions::default()
    };
    let arm = RapierArm::new(&model, &k, Some(&pl), &gravity(), SettleOptions::default()).unwrap();
    let arm_fine = RapierArm::new(&model, &k, Some(&pl), &gravity(), fine).unwrap();
    let mut ws = arm.workspace();
    let mut ws_fine = arm_fine.workspace();
    for q in &qs[..3] {
        let a = arm.settle(&mut ws, q).unwrap();
        let b = arm_fine.settle(&mut ws_fine, q).unwrap();
        assert!(b.steps > 10 * a.steps, "{} vs {} steps", b.steps, a.steps);
        let d = a
            .q_link
            .iter()
            .zip(&b.q_link)
            .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
        assert!(
            d < 1e-11,
            "dt 0.05 s and 1 ms rest states differ by {d:e} rad"
        );
    }
    // History: a fresh workspace gives the same bits as one that settled other poses first.
    let reused: Vec<_> = qs.iter().map(|q| arm.settle(&mut ws, q).unwrap()).collect();
    for (q, r) in qs.iter().zip(&reused).rev() {
        assert_eq!(&arm.settle(&mut arm.workspace(), q).unwrap(), r);
    }
    // Threads: settle_many (rayon) gives the same bits in the same order.
    let many = settle_many(
        &model,
        &k,
        Some(&pl),
        &gravity(),
        SettleOptions::default(),
        &qs,
    )
    .unwrap();
    assert_eq!(many, reused);
}

#[test]
fn bad_input_and_failure_to_settle_are_one_line_errors() {
    let model = sim::robots::load_builtin("iiwa7").unwrap();
    let g = gravity();
    let opts = SettleOptions::default();
    let err = |r: Result<RapierArm, SimError>| r.unwrap_err().to_string();
    assert!(
        err(RapierArm::new(&model, &[1e4; 6], None, &g, opts)).contains("stiffness_nm_per_rad")
    );
    let mut c = [[2e-6; 2]; 7];
    c[2][1] = -1e-6;
    assert!(
        err(RapierArm::with_deflection(
            &model, &[1e4; 7], &c, None, &g, opts
        ))
        .contains("compliance_rad_per_nm[2][1]")
    );
    assert!(
        err(RapierArm::with_deflection(
            &model,
            &[1e4; 7],
            &[[2e-6; 2]; 3],
            None,
            &g,
            opts
        ))
        .contains("the robot has 7 joints")
    );
    let mut k = [1e4; 7];
    k[3] = -1.0;
    assert!(
        err(RapierArm::new(&model, &k, None, &g, opts)).contains("stiffness_nm_per_rad[3] = -1")
    );
    let bad_pl = Payload {
        mass: f64::NAN,
        com: [0.0; 3],
    };
    assert!(
        err(RapierArm::new(&model, &[1e4; 7], Some(&bad_pl), &g, opts)).contains("payload.mass")
    );
    let e = err(RapierArm::new(
        &model,
        &[1e4; 7],
        None,
        &Vector3::new(0.0, f64::INFINITY, 0.0),
        opts,
    ));
    assert!(e.contains("gravity[1]"), "{e}");
    for (o, field) in [
        (SettleOptions { dt: 0.0, ..opts }, "dt = 0"),
        (
            SettleOptions {
                damping_ratio: -1.0,
                ..opts
            },
            "damping_ratio",
        ),
        (
            SettleOptions {
                speed_tol: f64::NAN,
                ..opts
            },
            "speed_tol",
        ),
        (
            SettleOptions {
                residual_tol: 0.0,
                ..opts
            },
            "residual_tol",
        ),
        (
            SettleOptions {
                max_steps: 0,
                ..opts
            },
            "max_steps",
        ),
    ] {
        let e = err(RapierArm::new(&model, &[1e4; 7], None, &g, o));
        assert!(e.contains(field) && !e.contains('\n'), "{e}");
    }
    let arm = RapierArm::new(&model, &[1e4; 7], None, &g, opts).unwrap();
    let mut ws = arm.workspace();
    assert!(
        arm.settle(&mut ws, &[0.0; 6])
            .unwrap_err()
            .to_string()
            .contains("expected 7")
    );
    let e = arm
        .settle(&mut ws, &[0.0, f64::NAN, 0.0, 0.0, 0.0, 0.0, 0.0])
        .unwrap_err();
    assert!(e.to_string().contains("joint 2"), "{e}");
    // A step budget that cannot be met, and joints far too soft for the arm: errors, never a pose.
    let q = [0.0, 1.0, 0.0, -1.0, 0.0, 0.5, 0.0];
    let short = RapierArm::new(
        &model,
        &[1e4; 7],
        None,
        &g,
        SettleOptions {
            max_steps: 3,
            ..opts
        },
    )
    .unwrap();
    let e = short.settle(&mut short.workspace(), &q).unwrap_err();
    assert!(
        matches!(e, SimError::NotSettled { .. }) && e.to_string().contains("3 steps"),
        "{e}"
    );
    let soft = RapierArm::new(&model, &[1.0; 7], None, &g, opts).unwrap();
    let e = soft.settle(&mut soft.workspace(), &q).unwrap_err();
    assert!(
        matches!(e, SimError::NotSettled { .. }) && e.to_string().contains("sags"),
        "{e}"
    );
    let e = settle_many(&model, &[1.0; 7], None, &g, opts, &[q]).unwrap_err();
    assert!(
        e.to_string().contains("q_cmds[0]: joint") && e.to_string().contains("sags"),
        "{e}"
    );
    let poses = [
        q.to_vec(),
        q.to_vec(),
        vec![0.0; 8],
        q.to_vec(),
        vec![0.0; 6],
    ];
    let e = settle_many(&model, &[1e4; 7], None, &g, opts, &poses).unwrap_err();
    assert!(e.to_string().contains("q_cmds[2] = 8 values"), "{e}");
    let mut bad = [0.0; 7];
    bad[4] = f64::INFINITY;
    let e = settle_many(&model, &[1e4; 7], None, &g, opts, &[bad]).unwrap_err();
    assert!(e.to_string().contains("q_cmds[0][4] = inf"), "{e}");
}

#[test]
fn arm_is_shareable_and_workspaces_can_move_between_threads() {
    fn shareable<T: Send + Sync>() {}
    fn movable<T: Send>() {}
    shareable::<RapierArm>();
    movable::<sim::rapier_truth::RapierWorkspace>();
}
