//! The analytic truth of one measurement (`sim::effects`) against independent computations: closed
//! forms on a planar two-link arm, and on the iiwa 7 the URDF loader plus `forward_kinematics` on
//! perturbed or scaled URDF text, the product of exponentials term by term, and `statics`.

use nalgebra::{Point3, Vector3, Vector6};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use sim::effects::coupled_transmission::{CoupledTerm, CoupledTransmission};
use sim::effects::gear_backlash::GearBacklash;
use sim::effects::joint_compliance::JointCompliance;
use sim::effects::joint_coupling::{CouplingTerm, JointCoupling};
use sim::effects::kinematic_offsets::KinematicOffsets;
use sim::effects::link_deflection::LinkDeflection;
use sim::effects::thermal_drift::ThermalDrift;
use sim::effects::transmission_error::TransmissionError;
use sim::effects::{Conditions, EffectId, Effects, Truth, true_target};
use sim::kinematics::poe_pose;
use sim::lie::{adjoint_apply, exp_twist, log_pose};
use sim::urdf::load_str;
use sim::{
    ChainSpec, Data, Model, Payload, Pose, SimError, forward_kinematics, gravity_torques, robots,
};

const G: f64 = 9.81;

/// Counts heap allocations made by the current thread (to show that evaluation does not allocate).
struct CountingAlloc;

thread_local! {
    static ALLOCATIONS: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

unsafe impl std::alloc::GlobalAlloc for CountingAlloc {
    unsafe fn alloc(&self, layout: std::alloc::Layout) -> *mut u8 {
        ALLOCATIONS.with(|c| c.set(c.get() + 1));
        unsafe { std::alloc::System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: std::alloc::Layout) {
        unsafe { std::alloc::System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: CountingAlloc = CountingAlloc;

fn allocations() -> usize {
    ALLOCATIONS.with(|c| c.get())
}

fn gravity() -> Vector3<f64> {
    Vector3::new(0.0, 0.0, -G)
}

/// Planar arm in the x-z plane, both axes +y: joint 1 at height 0.2 m, link 1 of 1 m (2 kg at 0.5 m),
/// link 2 of 0.5 m to the tip (1 kg at 0.25 m). A positive angle about +y lowers +x.
const TWO_LINK: &str = r#"<robot name="two">
  <link name="base"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0 0 0.2"/>
    <axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <link name="l1"><inertial><origin xyz="0.5 0 0"/><mass value="2"/>
    <inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="1 0 0"/>
    <axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <link name="l2"><inertial><origin xyz="0.25 0 0"/><mass value="1"/>
    <inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>
  <joint name="tool" type="fixed"><parent link="l2"/><child link="tip"/><origin xyz="0.5 0 0"/></joint>
  <link name="tip"/>
</robot>"#;

fn two_link() -> Model {
    load_str(TWO_LINK, "two", &ChainSpec::default()).unwrap()
}

/// Rotation about +y by `a` applied to `v`, written out: x' = c x + s z, z' = −s x + c z.
fn ry(a: f64, v: Vector3<f64>) -> Vector3<f64> {
    let (s, c) = a.sin_cos();
    Vector3::new(c * v.x + s * v.z, v.y, -s * v.x + c * v.z)
}

/// Closed-form target position of the planar arm: link vectors `l0` (base to joint 1), `l1`, `l2`
/// (lengths along x, z for l0) and target `p` in the tip frame.
fn planar(a1: f64, a2: f64, l0: f64, l1: f64, l2: f64, p: Vector3<f64>) -> Vector3<f64> {
    Vector3::new(0.0, 0.0, l0)
        + ry(
            a1,
            Vector3::new(l1, 0.0, 0.0) + ry(a2, Vector3::new(l2, 0.0, 0.0) + p),
        )
}

/// Closed-form holding torques of the planar arm (N m), with an optional point payload at the tip
/// origin: τ = ∂V/∂a with V = Σ m g z and z = −x sin(·) along each link.
fn planar_torques(a1: f64, a2: f64, payload: f64) -> [f64; 2] {
    let (c1, c12) = (a1.cos(), (a1 + a2).cos());
    let t2 = -G * (1.0 * 0.25 + payload * 0.5) * c12;
    let t1 = -G * (2.0 * 0.5 * c1 + 1.0 * (c1 + 0.25 * c12) + payload * (c1 + 0.5 * c12));
    [t1, t2]
}

fn cond<'a>(
    q: &'a [f64],
    dir: Option<&'a [i8]>,
    temp_c: f64,
    payload: Option<Payload>,
) -> Conditions<'a> {
    Conditions {
        q,
        dir,
        temp_c,
        payload,
        branch: None,
    }
}

fn close3(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    (a - b).amax()
}

fn arr_close(a: [f64; 3], b: &Vector3<f64>) -> f64 {
    (Vector3::from(a) - b).amax()
}

// ---------------------------------------------------------------------------------------------------
// Two-link arm: every effect against a hand computation.

#[test]
fn planar_thermal_growth_matches_closed_form() {
    let m = two_link();
    let (a0, a1, a2) = (11e-6, 23e-6, 40e-6);
    let beta = [3e-5, -2e-5];
    let th = ThermalDrift::new(20.0, vec![a0, a1, a2], beta.to_vec()).unwrap();
    let effects = Effects {
        thermal: Some(th),
        ..Effects::default()
    };
    let p = Vector3::new(0.1, 0.02, -0.05);
    for (q, temp) in [([0.0, 0.0], 35.0), ([0.4, -1.1], 45.0), ([-0.7, 2.0], 5.0)] {
        let dt = temp - 20.0;
        let t = true_target(&m, &effects, &cond(&q, None, temp, None), &p, &gravity()).unwrap();
        let expect = planar(
            q[0] + beta[0] * dt,
            q[1] + beta[1] * dt,
            0.2 * (1.0 + a0 * dt),
            1.0 * (1.0 + a1 * dt),
            0.5 * (1.0 + a2 * dt),
            p,
        );
        let nominal = planar(q[0], q[1], 0.2, 1.0, 0.5, p);
        assert!(
            close3(&t.p_base, &expect) < 1e-15,
            "{q:?}: {} vs {}",
            t.p_base,
            expect
        );
        assert!(arr_close(t.contribution.thermal, &(expect - nominal)) < 1e-15);
        // A real effect: tens of micrometres.
        assert!((expect - nominal).amax() > 1e-5);
    }
}

#[test]
fn planar_kinematic_offsets_match_closed_form() {
    let m = two_link();
    // Joint 2's axis moved by t = (dx, 0, dz) (pure-translation error twist), zero offsets, a tool
    // translation u (flange frame) and a base rotation by b about +y through the base origin.
    let (dx, dz) = (1.5e-3, -0.8e-3);
    let u = Vector3::new(2e-4, -1e-4, 3e-4);
    let b = 2e-3;
    let dq = [1e-3, -2e-3];
    let kin = KinematicOffsets::new(
        vec![[0.0; 6], [0.0, 0.0, 0.0, dx, 0.0, dz]],
        dq.to_vec(),
        [0.0, b, 0.0, 0.0, 0.0, 0.0],
        [0.0, 0.0, 0.0, u.x, u.y, u.z],
    )
    .unwrap();
    let effects = Effects {
        kinematic: Some(kin),
        ..Effects::default()
    };
    let p = Vector3::new(0.1, 0.02, -0.05);
    for q in [[0.0, 0.0], [0.4, -1.1], [-0.7, 2.0]] {
        let t = true_target(&m, &effects, &cond(&q, None, 20.0, None), &p, &gravity()).unwrap();
        let (a1, a2) = (q[0] + dq[0], q[1] + dq[1]);
        // Home target, then rotate about axis 2 (through (1, 0, 0.2) + t), then about axis 1 (through
        // (0, 0, 0.2)), then the base rotation.
        let home = Vector3::new(1.5, 0.0, 0.2) + p + u;
        let c2 = Vector3::new(1.0 + dx, 0.0, 0.2 + dz);
        let c1 = Vector3::new(0.0, 0.0, 0.2);
        let p2 = c2 + ry(a2, home - c2);
        let p1 = c1 + ry(a1, p2 - c1);
        let expect = ry(b, p1);
        let nominal = planar(q[0], q[1], 0.2, 1.0, 0.5, p);
        assert!(
            close3(&t.p_base, &expect) < 1e-15,
            "{q:?}: {} vs {}",
            t.p_base,
            expect
        );
        assert!(arr_close(t.contribution.kinematic, &(expect - nominal)) < 1e-15);
        assert_eq!(t.contribution.thermal, [0.0; 3]);
    }
}

#[test]
fn planar_backlash_matches_closed_form_in_both_modes() {
    let m = two_link();
    let band = [4e-3, 6e-3];
    let p = Vector3::new(0.0, 0.0, 0.0);
    let q = [0.3, -0.5];
    // Direction mode: θ = q − d b/2.
    let dir_mode = Effects {
        backlash: Some(GearBacklash::direction(band.to_vec()).unwrap()),
        ..Effects::default()
    };
    let dir = [-1i8, 1];
    let t = true_target(
        &m,
        &dir_mode,
        &cond(&q, Some(&dir), 20.0, None),
        &p,
        &gravity(),
    )
    .unwrap();
    let expect = planar(q[0] + band[0] / 2.0, q[1] - band[1] / 2.0, 0.2, 1.0, 0.5, p);
    assert!(close3(&t.p_base, &expect) < 1e-15);
    assert!(
        (t.q_link[0] - (q[0] + 0.002)).abs() < 1e-16
            && (t.q_link[1] - (q[1] - 0.003)).abs() < 1e-16
    );
    // Unknown direction: no shift.
    let t = true_target(&m, &dir_mode, &cond(&q, None, 20.0, None), &p, &gravity()).unwrap();
    assert_eq!(t.contribution.backlash, [0.0; 3]);

    // Gravity mode, threshold 5 N m: |τ1| ≈ 21 N m is above it, |τ2| ≈ 2.4 N m below.
    let tau = planar_torques(q[0], q[1], 0.0);
    assert!(tau[0] < -5.0 && tau[1].abs() < 5.0, "{tau:?}");
    let grav_mode = Effects {
        backlash: Some(GearBacklash::gravity_uniform(band.to_vec(), 5.0).unwrap()),
        ..Effects::default()
    };
    let t = true_target(
        &m,
        &grav_mode,
        &cond(&q, Some(&dir), 20.0, None),
        &p,
        &gravity(),
    )
    .unwrap();
    // Joint 1 is held by a negative torque: gravity turns it positive (down), θ1 = q1 + b1/2, whatever
    // its direction; joint 2 follows the direction rule (moved +: θ2 = q2 − b2/2).
    let expect = planar(q[0] + band[0] / 2.0, q[1] - band[1] / 2.0, 0.2, 1.0, 0.5, p);
    assert!(close3(&t.p_base, &expect) < 1e-15);
    let dir2 = [1i8, 1];
    let t2 = true_target(
        &m,
        &grav_mode,
        &cond(&q, Some(&dir2), 20.0, None),
        &p,
        &gravity(),
    )
    .unwrap();
    assert!(
        close3(&t2.p_base, &expect) < 1e-15,
        "gravity decides joint 1, not the direction"
    );
    // The tip went down.
    let nominal = planar(q[0], q[1], 0.2, 1.0, 0.5, p);
    assert!(t.p_base.z < nominal.z);
}

/// Root of the scalar equation k (q − θ) − τ1(θ) = 0 by bisection (τ1 from the closed form).
fn bisect(f: impl Fn(f64) -> f64, mut lo: f64, mut hi: f64) -> f64 {
    assert!(f(lo) * f(hi) < 0.0);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if f(mid) * f(lo) > 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

#[test]
fn planar_compliance_sag_matches_scalar_root_and_closed_form_torques() {
    let m = two_link();
    let p = Vector3::new(0.05, 0.0, 0.0);
    // Joint 1 soft, joint 2 rigid: a scalar equation with a bisection root.
    let k1 = 2000.0;
    let effects = Effects {
        compliance: Some(JointCompliance::new(vec![k1, f64::INFINITY]).unwrap()),
        ..Effects::default()
    };
    for q in [[0.0, 0.0], [0.4, -1.1], [-0.7, 2.0]] {
        let t = true_target(&m, &effects, &cond(&q, None, 20.0, None), &p, &gravity()).unwrap();
        let f = |th: f64| k1 * (q[0] - th) - planar_torques(th, q[1], 0.0)[0];
        let th1 = bisect(f, q[0] - 0.1, q[0] + 0.1);
        assert!(
            (t.q_link[0] - th1).abs() < 1e-13,
            "{q:?}: {} vs {th1}",
            t.q_link[0]
        );
        assert_eq!(t.q_link[1], q[1]);
        let expect = planar(th1, q[1], 0.2, 1.0, 0.5, p);
        assert!(close3(&t.p_base, &expect) < 1e-12);
        // First order: q − τ(q)/k.
        let first = q[0] - planar_torques(q[0], q[1], 0.0)[0] / k1;
        assert!((t.q_link_first_order[0] - first).abs() < 1e-15);
    }
    // Both joints soft, with a 3 kg payload at the tip: the equilibrium residual with closed-form
    // torques, and the sag goes down (positive angles) for a horizontal arm.
    let k = [1500.0, 800.0];
    let effects = Effects {
        compliance: Some(JointCompliance::new(k.to_vec()).unwrap()),
        ..Effects::default()
    };
    let pl = Payload {
        mass: 3.0,
        com: [0.0, 0.0, 0.0],
    };
    for q in [[0.0, 0.0], [0.4, -1.1], [-0.7, 2.0]] {
        let t = true_target(
            &m,
            &effects,
            &cond(&q, None, 20.0, Some(pl)),
            &p,
            &gravity(),
        )
        .unwrap();
        let th = &t.q_link;
        let tau = planar_torques(th[0], th[1], 3.0);
        for i in 0..2 {
            let res = k[i] * (q[i] - th[i]) - tau[i];
            assert!(res.abs() < 1e-9, "{q:?} joint {i}: residual {res} N m");
        }
        let expect = planar(th[0], th[1], 0.2, 1.0, 0.5, p);
        assert!(close3(&t.p_base, &expect) < 1e-14);
        assert!(
            t.compliance_iterations >= 2 && t.compliance_iterations <= 6,
            "{}",
            t.compliance_iterations
        );
    }
    let t = true_target(
        &m,
        &effects,
        &cond(&[0.0, 0.0], None, 20.0, Some(pl)),
        &p,
        &gravity(),
    )
    .unwrap();
    assert!(t.q_link[0] > 0.0 && t.q_link[1] > 0.0 && t.contribution.compliance[2] < -1e-3);
}

// ---------------------------------------------------------------------------------------------------
// iiwa 7.

fn iiwa() -> Model {
    robots::load_builtin("iiwa7").unwrap()
}

fn iiwa_text() -> &'static str {
    robots::builtin_urdf("iiwa7").unwrap()
}

fn attr<'a>(element: &'a str, name: &str) -> Option<&'a str> {
    let key = format!(" {name}=\"");
    let start = element.find(&key)? + key.len();
    let len = element[start..].find('"')?;
    Some(&element[start..start + len])
}

fn parse3(s: &str) -> [f64; 3] {
    let v: Vec<f64> = s.split_whitespace().map(|x| x.parse().unwrap()).collect();
    [v[0], v[1], v[2]]
}

/// Rewrites the `<origin>` of every `<joint>` (movable and fixed, in file order) with
/// `f(index, xyz, rpy) -> (xyz, rpy)`; inertial origins are left alone.
fn edit_joint_origins(
    text: &str,
    mut f: impl FnMut(usize, [f64; 3], [f64; 3]) -> ([f64; 3], [f64; 3]),
) -> String {
    let mut out = String::new();
    let mut rest = text;
    let mut index = 0;
    while let Some(start) = rest.find("<joint ") {
        out.push_str(&rest[..start]);
        let end = start + rest[start..].find("</joint>").unwrap() + "</joint>".len();
        let block = &rest[start..end];
        let o_start = block.find("<origin").unwrap();
        let o_end = o_start + block[o_start..].find("/>").unwrap() + 2;
        let origin = &block[o_start..o_end];
        let xyz = parse3(attr(origin, "xyz").unwrap_or("0 0 0"));
        let rpy = parse3(attr(origin, "rpy").unwrap_or("0 0 0"));
        let (x, r) = f(index, xyz, rpy);
        out.push_str(&block[..o_start]);
        out.push_str(&format!(
            "<origin xyz=\"{} {} {}\" rpy=\"{} {} {}\"/>",
            x[0], x[1], x[2], r[0], r[1], r[2]
        ));
        out.push_str(&block[o_end..]);
        rest = &rest[end..];
        index += 1;
    }
    out.push_str(rest);
    out
}

fn random_q(rng: &mut StdRng) -> [f64; 7] {
    std::array::from_fn(|_| rng.random::<f64>() * 3.0 - 1.5)
}

fn random_twist(rng: &mut StdRng, rot: f64, trans: f64) -> [f64; 6] {
    std::array::from_fn(|k| (rng.random::<f64>() * 2.0 - 1.0) * if k < 3 { rot } else { trans })
}

fn v6(a: &[f64; 6]) -> Vector6<f64> {
    Vector6::from_column_slice(a)
}

fn fk(model: &Model, q: &[f64]) -> Pose {
    let mut d = Data::new(model);
    forward_kinematics(model, &mut d, q);
    d.flange
}

fn pose_diff(a: &Pose, b: &Pose) -> f64 {
    (a.translation.vector - b.translation.vector)
        .amax()
        .max((a.rotation.matrix() - b.rotation.matrix()).amax())
}

#[test]
fn iiwa_kinematic_offsets_equal_forward_kinematics_of_a_perturbed_urdf() {
    let m = iiwa();
    let mut rng = StdRng::seed_from_u64(31);
    // Perturb every joint origin (7 movable + the fixed flange joint) by ~1 mm and ~1 mrad.
    let text = edit_joint_origins(iiwa_text(), |_, xyz, rpy| {
        (
            std::array::from_fn(|k| xyz[k] + (rng.random::<f64>() - 0.5) * 2e-3),
            std::array::from_fn(|k| rpy[k] + (rng.random::<f64>() - 0.5) * 2e-3),
        )
    });
    let m2 = load_str(&text, "perturbed iiwa7", &ChainSpec::default()).unwrap();
    // The error twists that carry each nominal joint frame onto the perturbed one, and the tool error.
    let twists: Vec<[f64; 6]> = (0..7)
        .map(|i| {
            let xi = log_pose(&(m2.joints()[i].home * m.joints()[i].home.inverse()));
            std::array::from_fn(|k| xi[k])
        })
        .collect();
    let xt = log_pose(&(m.home_flange().inverse() * m2.home_flange()));
    let base = random_twist(&mut rng, 2e-3, 2e-3);
    let dq: Vec<f64> = (0..7).map(|_| (rng.random::<f64>() - 0.5) * 4e-3).collect();
    let kin =
        KinematicOffsets::new(twists, dq.clone(), base, std::array::from_fn(|k| xt[k])).unwrap();
    let effects = Effects {
        kinematic: Some(kin),
        ..Effects::default()
    };
    let truth = Truth::new(&m, &effects).unwrap();
    let mut s = truth.scratch();
    let p = Vector3::new(0.01, -0.03, 0.09);
    for _ in 0..25 {
        let q = random_q(&mut rng);
        let t = truth
            .target(&cond(&q, None, 20.0, None), &p, &gravity(), &mut s)
            .unwrap();
        let qd: Vec<f64> = q.iter().zip(&dq).map(|(a, b)| a + b).collect();
        let expect = exp_twist(&v6(&base)) * fk(&m2, &qd);
        assert!(
            pose_diff(&t.flange, &expect) < 1e-13,
            "{}",
            pose_diff(&t.flange, &expect)
        );
        let pe = (expect * Point3::from(p)).coords;
        let pn = (fk(&m, &q) * Point3::from(p)).coords;
        assert!(close3(&t.p_base, &pe) < 1e-13);
        assert!(arr_close(t.contribution.kinematic, &(pe - pn)) < 1e-13);
        assert!(
            (pe - pn).amax() > 1e-4,
            "a millimetre-sized error is visible"
        );
    }
}

/// Per-link expansion coefficients for the iiwa's 8 links (distinct, so an index slip shows).
const IIWA_ALPHA: [f64; 8] = [10e-6, 12e-6, 23e-6, 17e-6, 23e-6, 30e-6, 8e-6, 23e-6];

fn scaled_iiwa(dt: f64) -> Model {
    let text = edit_joint_origins(iiwa_text(), |k, xyz, rpy| {
        (
            std::array::from_fn(|c| xyz[c] * (1.0 + IIWA_ALPHA[k] * dt)),
            rpy,
        )
    });
    load_str(&text, "scaled iiwa7", &ChainSpec::default()).unwrap()
}

#[test]
fn iiwa_home_flange_grows_by_alpha_delta_t() {
    let m = iiwa();
    let (alpha, dt) = (23e-6, 15.0);
    let effects = Effects {
        thermal: Some(ThermalDrift::uniform(7, 20.0, alpha).unwrap()),
        ..Effects::default()
    };
    let t = true_target(
        &m,
        &effects,
        &cond(&[0.0; 7], None, 20.0 + dt, None),
        &Vector3::zeros(),
        &gravity(),
    )
    .unwrap();
    let dz = 1.266 * alpha * dt; // 0.437 mm
    assert!(
        (t.p_base.z - (1.266 + dz)).abs() < 1e-15,
        "{}",
        t.p_base.z - 1.266
    );
    assert!(t.p_base.x.abs() < 1e-15 && t.p_base.y.abs() < 1e-15);
    assert!((t.contribution.thermal[2] - dz).abs() < 1e-15);
}

#[test]
fn iiwa_thermal_drift_equals_forward_kinematics_of_a_scaled_urdf() {
    let m = iiwa();
    let beta: Vec<f64> = (0..7).map(|i| 1e-6 * (i as f64 - 3.0)).collect();
    let th = ThermalDrift::new(22.0, IIWA_ALPHA.to_vec(), beta.clone()).unwrap();
    let effects = Effects {
        thermal: Some(th),
        ..Effects::default()
    };
    let truth = Truth::new(&m, &effects).unwrap();
    let mut s = truth.scratch();
    let mut rng = StdRng::seed_from_u64(7);
    let p = Vector3::new(0.0, 0.02, 0.1);
    for temp in [12.0, 30.5, 41.0] {
        let dt = temp - 22.0;
        let scaled = scaled_iiwa(dt);
        for _ in 0..10 {
            let q = random_q(&mut rng);
            let t = truth
                .target(&cond(&q, None, temp, None), &p, &gravity(), &mut s)
                .unwrap();
            let qd: Vec<f64> = q.iter().zip(&beta).map(|(a, b)| a + b * dt).collect();
            let expect = fk(&scaled, &qd);
            assert!(
                pose_diff(&t.flange, &expect) < 1e-15,
                "{}",
                pose_diff(&t.flange, &expect)
            );
        }
    }
}

#[test]
fn iiwa_thermal_then_kinematic_equals_product_of_exponentials_of_the_grown_screws() {
    // T = exp(ξ_base) Π exp(Ad(exp ξᵢ) Sᵢᵀ φᵢ) Mᵀ exp(ξ_tool), Sᵢᵀ and Mᵀ from the scaled URDF.
    let m = iiwa();
    let mut rng = StdRng::seed_from_u64(8);
    let twists: Vec<[f64; 6]> = (0..7).map(|_| random_twist(&mut rng, 2e-3, 2e-3)).collect();
    let dq: Vec<f64> = (0..7).map(|_| (rng.random::<f64>() - 0.5) * 2e-3).collect();
    let (base, tool) = (
        random_twist(&mut rng, 1e-3, 1e-3),
        random_twist(&mut rng, 1e-3, 1e-3),
    );
    let beta: Vec<f64> = (0..7).map(|i| 2e-6 * (3.0 - i as f64)).collect();
    let effects = Effects {
        kinematic: Some(KinematicOffsets::new(twists.clone(), dq.clone(), base, tool).unwrap()),
        thermal: Some(ThermalDrift::new(20.0, IIWA_ALPHA.to_vec(), beta.clone()).unwrap()),
        ..Effects::default()
    };
    let truth = Truth::new(&m, &effects).unwrap();
    let mut s = truth.scratch();
    let p = Vector3::new(0.02, 0.0, 0.07);
    for temp in [5.0, 20.0, 38.0] {
        let dt = temp - 20.0;
        let grown = scaled_iiwa(dt);
        let screws: Vec<Vector6<f64>> = grown
            .screws()
            .iter()
            .zip(&twists)
            .map(|(sc, xi)| adjoint_apply(&exp_twist(&v6(xi)), sc))
            .collect();
        let home = grown.home_flange() * exp_twist(&v6(&tool));
        for _ in 0..10 {
            let q = random_q(&mut rng);
            let phi: Vec<f64> = (0..7).map(|i| q[i] + dq[i] + beta[i] * dt).collect();
            let expect = exp_twist(&v6(&base)) * poe_pose(&screws, &home, &phi);
            let t = truth
                .target(&cond(&q, None, temp, None), &p, &gravity(), &mut s)
                .unwrap();
            assert!(
                pose_diff(&t.flange, &expect) < 1e-13,
                "{}",
                pose_diff(&t.flange, &expect)
            );
            // The thermal-only stage matches the scaled URDF.
            let pth = (fk(
                &grown,
                &(0..7).map(|i| q[i] + beta[i] * dt).collect::<Vec<_>>(),
            ) * Point3::from(p))
            .coords;
            let pn = (fk(&m, &q) * Point3::from(p)).coords;
            assert!(arr_close(t.contribution.thermal, &(pth - pn)) < 1e-14);
        }
    }
}

fn iiwa_stiffness() -> Vec<f64> {
    vec![9.0e3, 7.5e3, 6.0e3, 5.0e3, 4.0e3, 3.0e3, 2.0e3]
}

#[test]
fn iiwa_compliance_equilibrium_residual_and_second_order_first_order_error() {
    let m = iiwa();
    let mut d = Data::new(&m);
    let mut rng = StdRng::seed_from_u64(3);
    let pl = Payload {
        mass: 4.0,
        com: [0.01, 0.0, 0.06],
    };
    let p = Vector3::new(0.0, 0.0, 0.05);
    for _ in 0..20 {
        let q = random_q(&mut rng);
        let mut diffs = Vec::new();
        let mut sags = Vec::new();
        for scale in [1.0, 2.0, 4.0] {
            let k: Vec<f64> = iiwa_stiffness().iter().map(|k| k * scale).collect();
            let effects = Effects {
                compliance: Some(JointCompliance::new(k.clone()).unwrap()),
                ..Effects::default()
            };
            let t = true_target(
                &m,
                &effects,
                &cond(&q, None, 20.0, Some(pl)),
                &p,
                &gravity(),
            )
            .unwrap();
            gravity_torques(&m, &mut d, &t.q_link, &gravity(), Some(&pl)).unwrap();
            for i in 0..7 {
                let res = k[i] * (q[i] - t.q_link[i]) - d.gravity_torque[i];
                assert!(res.abs() < 1e-9, "joint {i}: residual {res:e} N m");
            }
            assert!(
                t.compliance_iterations <= 5,
                "{} iterations",
                t.compliance_iterations
            );
            // Target position from forward kinematics at the link-side angles.
            let pe = (fk(&m, &t.q_link) * Point3::from(p)).coords;
            assert!(close3(&t.p_base, &pe) < 1e-15);
            diffs.push(
                t.q_link
                    .iter()
                    .zip(&t.q_link_first_order)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0, f64::max),
            );
            sags.push(
                q.iter()
                    .zip(&t.q_link)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0, f64::max),
            );
        }
        // Sag ∝ 1/k (first order), first-order error ∝ 1/k² (second order): halving the compliance
        // divides them by 2 and 4, up to the next order (relative size ~ sag ≈ 1e-3).
        for w in 0..2 {
            let rs = sags[w] / sags[w + 1];
            let rd = diffs[w] / diffs[w + 1];
            assert!((rs - 2.0).abs() < 0.05, "sag ratio {rs}");
            assert!(
                (rd - 4.0).abs() < 0.2,
                "first-order error ratio {rd} ({diffs:?})"
            );
        }
    }
}

#[test]
fn iiwa_compliance_uses_the_real_geometry() {
    // With kinematic errors (from a perturbed URDF), zero offsets and a base rotation, the equilibrium
    // holds for the statics of the perturbed URDF at θ + δq with gravity seen from the real base.
    let m = iiwa();
    let mut rng = StdRng::seed_from_u64(5);
    let text = edit_joint_origins(iiwa_text(), |_, xyz, rpy| {
        (
            std::array::from_fn(|k| xyz[k] + (rng.random::<f64>() - 0.5) * 4e-3),
            std::array::from_fn(|k| rpy[k] + (rng.random::<f64>() - 0.5) * 4e-3),
        )
    });
    let m2 = load_str(&text, "perturbed iiwa7", &ChainSpec::default()).unwrap();
    let twists: Vec<[f64; 6]> = (0..7)
        .map(|i| {
            let xi = log_pose(&(m2.joints()[i].home * m.joints()[i].home.inverse()));
            std::array::from_fn(|k| xi[k])
        })
        .collect();
    let xt = log_pose(&(m.home_flange().inverse() * m2.home_flange()));
    let base = [0.02, -0.03, 0.01, 0.001, 0.002, -0.001];
    let dq: Vec<f64> = (0..7).map(|_| (rng.random::<f64>() - 0.5) * 4e-3).collect();
    let k = iiwa_stiffness();
    let effects = Effects {
        kinematic: Some(
            KinematicOffsets::new(twists, dq.clone(), base, std::array::from_fn(|i| xt[i]))
                .unwrap(),
        ),
        compliance: Some(JointCompliance::new(k.clone()).unwrap()),
        ..Effects::default()
    };
    let r_base = exp_twist(&v6(&base)).rotation;
    let g_robot = r_base.inverse() * gravity();
    let pl = Payload {
        mass: 2.0,
        com: [0.0, 0.03, 0.05],
    };
    let mut d = Data::new(&m2);
    let truth = Truth::new(&m, &effects).unwrap();
    let mut s = truth.scratch();
    for _ in 0..10 {
        let q = random_q(&mut rng);
        let t = truth
            .target(
                &cond(&q, None, 20.0, Some(pl)),
                &Vector3::zeros(),
                &gravity(),
                &mut s,
            )
            .unwrap();
        let th: Vec<f64> = (0..7).map(|i| s.q_link()[i] + dq[i]).collect();
        gravity_torques(&m2, &mut d, &th, &g_robot, Some(&pl)).unwrap();
        for i in 0..7 {
            let res = k[i] * (q[i] - s.q_link()[i]) - d.gravity_torque[i];
            assert!(res.abs() < 1e-9, "joint {i}: residual {res:e} N m");
        }
        // First order: θ₁ = q − K⁻¹ τ_g(q) in the same real geometry.
        let q_real: Vec<f64> = (0..7).map(|i| q[i] + dq[i]).collect();
        gravity_torques(&m2, &mut d, &q_real, &g_robot, Some(&pl)).unwrap();
        for i in 0..7 {
            let first = q[i] - d.gravity_torque[i] / k[i];
            assert!(
                (s.q_link_first_order()[i] - first).abs() < 1e-15,
                "joint {i}"
            );
        }
        // And the nominal-geometry torques would not balance (the check can fail): the base is tilted
        // by 37 mrad.
        let mut dn = Data::new(&m);
        gravity_torques(&m, &mut dn, s.q_link(), &gravity(), Some(&pl)).unwrap();
        let worst = (0..7)
            .map(|i| (k[i] * (q[i] - s.q_link()[i]) - dn.gravity_torque[i]).abs())
            .fold(0.0, f64::max);
        assert!(worst > 1e-3, "{worst}");
        let pe = (exp_twist(&v6(&base)) * fk(&m2, &th)).translation.vector;
        assert!(close3(&t.p_base, &pe) < 1e-13);
    }
}

/// Potential energy of the iiwa's bodies at `q` (J), from forward kinematics: V = −Σ m gᵀ c.
fn potential(m: &Model, q: &[f64]) -> f64 {
    let mut d = Data::new(m);
    forward_kinematics(m, &mut d, q);
    d.joint_poses
        .iter()
        .zip(m.bodies())
        .map(|(t, b)| -b.mass * gravity().dot(&(t * Point3::from(b.com)).coords))
        .sum()
}

#[test]
fn iiwa_backlash_signs_in_both_modes() {
    let m = iiwa();
    let band = vec![1e-3, 2e-3, 1.5e-3, 3e-3, 1e-3, 2e-3, 4e-3];
    let q = [0.3, 0.9, -0.4, -1.2, 0.5, 0.8, 0.1];
    let p = Vector3::new(0.0, 0.0, 0.1);
    // Direction mode: θ = q − d b/2.
    let dir = [1i8, -1, 0, 1, -1, 1, 0];
    let effects = Effects {
        backlash: Some(GearBacklash::direction(band.clone()).unwrap()),
        ..Effects::default()
    };
    let t = true_target(
        &m,
        &effects,
        &cond(&q, Some(&dir), 20.0, None),
        &p,
        &gravity(),
    )
    .unwrap();
    let th: Vec<f64> = (0..7)
        .map(|i| q[i] - f64::from(dir[i]) * band[i] / 2.0)
        .collect();
    assert_eq!(t.q_link, th);
    assert!(close3(&t.p_base, &(fk(&m, &th) * Point3::from(p)).coords) < 1e-15);

    // Gravity mode, threshold 1 N m: the link drops onto the loaded flank. Independent sign check:
    // every joint above the threshold moves so that the potential energy falls.
    let effects = Effects {
        backlash: Some(GearBacklash::gravity_uniform(band.clone(), 1.0).unwrap()),
        ..Effects::default()
    };
    let t = true_target(
        &m,
        &effects,
        &cond(&q, Some(&dir), 20.0, None),
        &p,
        &gravity(),
    )
    .unwrap();
    let mut d = Data::new(&m);
    gravity_torques(&m, &mut d, &q, &gravity(), None).unwrap();
    let v0 = potential(&m, &q);
    let mut loaded = 0;
    for i in 0..7 {
        let tau = d.gravity_torque[i];
        let shift = q[i] - t.q_link[i];
        if tau.abs() > 1.0 {
            loaded += 1;
            assert!((shift.abs() - band[i] / 2.0).abs() < 1e-15, "joint {i}");
            let mut qi = q;
            qi[i] = t.q_link[i];
            assert!(
                potential(&m, &qi) < v0,
                "joint {i} (τ = {tau}) moved against gravity"
            );
        } else {
            assert!(
                (shift - f64::from(dir[i]) * band[i] / 2.0).abs() < 1e-15,
                "joint {i} below threshold"
            );
        }
    }
    assert!(loaded >= 3, "the pose loads several joints ({loaded})");
    assert!(potential(&m, &t.q_link) < v0);
}

// ---------------------------------------------------------------------------------------------------
// Identities and bookkeeping.

fn all_effects(m: &Model, rng: &mut StdRng) -> Effects {
    Effects {
        kinematic: Some(
            KinematicOffsets::new(
                (0..7).map(|_| random_twist(rng, 2e-3, 2e-3)).collect(),
                (0..7).map(|_| (rng.random::<f64>() - 0.5) * 2e-3).collect(),
                random_twist(rng, 1e-3, 1e-3),
                random_twist(rng, 1e-3, 1e-3),
            )
            .unwrap(),
        ),
        compliance: Some(JointCompliance::new(iiwa_stiffness()).unwrap()),
        backlash: Some(GearBacklash::gravity_uniform(vec![5e-4; m.nq()], 2.0).unwrap()),
        thermal: Some(
            ThermalDrift::uniform(m.nq(), 20.0, 23e-6)
                .unwrap()
                .with_zero_drift(vec![3e-6; 7])
                .unwrap(),
        ),
        transmission: Some(
            TransmissionError::new(
                vec![1, 2, 3, 7],
                (0..7)
                    .map(|_| (0..4).map(|_| (rng.random::<f64>() - 0.5) * 4e-4).collect())
                    .collect(),
                (0..7)
                    .map(|_| (0..4).map(|_| (rng.random::<f64>() - 0.5) * 6.0).collect())
                    .collect(),
            )
            .unwrap(),
        ),
        coupling: Some(
            JointCoupling::new(vec![
                CouplingTerm {
                    joint: 6,
                    source: 4,
                    ratio_rad_per_rad: 3e-4,
                },
                CouplingTerm {
                    joint: 2,
                    source: 2,
                    ratio_rad_per_rad: -2e-4,
                },
            ])
            .unwrap(),
        ),
        deflection: Some(
            LinkDeflection::new(
                (0..7)
                    .map(|_| [rng.random::<f64>() * 4e-6, rng.random::<f64>() * 4e-6])
                    .collect(),
            )
            .unwrap(),
        ),
        coupled_transmission: Some(
            CoupledTransmission::new(vec![CoupledTerm {
                joint: 6,
                source: 5,
                order: 2,
                amplitude_rad: 2e-4,
                phase_rad: rng.random::<f64>() * 6.0,
            }])
            .unwrap(),
        ),
    }
}

#[test]
fn no_effects_give_exactly_the_nominal_forward_kinematics() {
    let m = iiwa();
    let mut rng = StdRng::seed_from_u64(1);
    let p = Vector3::new(0.01, 0.02, 0.03);
    let truth = Truth::new(&m, &Effects::default()).unwrap();
    let mut s = truth.scratch();
    for _ in 0..20 {
        let q = random_q(&mut rng);
        let dir = [1i8; 7];
        let t = truth
            .target(&cond(&q, Some(&dir), 55.0, None), &p, &gravity(), &mut s)
            .unwrap();
        let f = fk(&m, &q);
        assert_eq!(t.flange, f);
        assert_eq!(t.p_base, (f * Point3::from(p)).coords);
        assert_eq!(t.contribution, Default::default());
        assert_eq!(s.q_link(), &q[..]);
        assert_eq!(t.compliance_iterations, 0);
    }
    // Present but zero-valued effects: nominal to rounding.
    let zero = Effects {
        kinematic: Some(KinematicOffsets::zero(7)),
        compliance: None,
        backlash: Some(GearBacklash::direction(vec![0.0; 7]).unwrap()),
        thermal: Some(ThermalDrift::uniform(7, 20.0, 23e-6).unwrap()),
        transmission: Some(
            TransmissionError::new(vec![1, 2, 3], vec![vec![0.0; 3]; 7], vec![vec![0.4; 3]; 7])
                .unwrap(),
        ),
        coupling: Some(JointCoupling::single(3, 1, 0.0).unwrap()),
        deflection: Some(LinkDeflection::uniform(7, 0.0).unwrap()),
        coupled_transmission: Some(CoupledTransmission::new(vec![]).unwrap()),
    };
    let truth = Truth::new(&m, &zero).unwrap();
    let mut s = truth.scratch();
    for _ in 0..20 {
        let q = random_q(&mut rng);
        let t = truth
            .target(&cond(&q, Some(&[1; 7]), 20.0, None), &p, &gravity(), &mut s)
            .unwrap();
        assert!(close3(&t.p_base, &(fk(&m, &q) * Point3::from(p)).coords) < 1e-15);
    }
}

#[test]
fn contributions_sum_to_the_total_and_the_prepared_path_equals_the_one_shot() {
    let m = iiwa();
    let mut rng = StdRng::seed_from_u64(2);
    let effects = all_effects(&m, &mut rng);
    let truth = Truth::new(&m, &effects).unwrap();
    let mut s = truth.scratch();
    let p = Vector3::new(0.01, -0.02, 0.08);
    let pl = Some(Payload {
        mass: 3.0,
        com: [0.0, 0.0, 0.06],
    });
    for k in 0..30 {
        let q = random_q(&mut rng);
        let dir: [i8; 7] = std::array::from_fn(|i| [-1, 0, 1][(k + i) % 3]);
        let c = cond(&q, Some(&dir), 25.0 + k as f64, pl);
        let t = truth.target(&c, &p, &gravity(), &mut s).unwrap();
        let pn = (fk(&m, &q) * Point3::from(p)).coords;
        let total = t.contribution.total();
        assert!(arr_close(total, &(t.p_base - pn)) < 1e-15);
        for (name, v) in [
            ("thermal", t.contribution.thermal),
            ("kinematic", t.contribution.kinematic),
            ("transmission", t.contribution.transmission),
            ("coupling", t.contribution.coupling),
            ("coupled_transmission", t.contribution.coupled_transmission),
            ("backlash", t.contribution.backlash),
            ("compliance", t.contribution.compliance),
            ("deflection", t.contribution.deflection),
        ] {
            let n = Vector3::from(v).norm();
            assert!(n > 1e-6 && n < 5e-2, "{name}: {n} m");
        }
        let one = true_target(&m, &effects, &c, &p, &gravity()).unwrap();
        assert_eq!(one.p_base, t.p_base);
        assert_eq!(one.flange, t.flange);
        assert_eq!(one.q_link, s.q_link());
        assert_eq!(one.q_link_first_order, s.q_link_first_order());
    }
}

// ---------------------------------------------------------------------------------------------------
// Bad input: errors, never panics.

const NO_INERTIALS: &str = r#"<robot name="bare">
  <link name="base"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <link name="l1"/>
</robot>"#;

#[test]
fn bad_input_is_refused_with_a_one_line_error() {
    let bare = load_str(NO_INERTIALS, "bare", &ChainSpec::default()).unwrap();
    let e = Truth::new(
        &bare,
        &Effects {
            compliance: Some(JointCompliance::uniform(1, 1e4).unwrap()),
            ..Effects::default()
        },
    )
    .unwrap_err();
    assert!(matches!(e, SimError::MissingInertial { .. }), "{e}");
    let e = Truth::new(
        &bare,
        &Effects {
            backlash: Some(GearBacklash::gravity_uniform(vec![1e-3], 1.0).unwrap()),
            ..Effects::default()
        },
    )
    .unwrap_err();
    assert!(matches!(e, SimError::MissingInertial { .. }), "{e}");
    // Direction-mode backlash needs no masses.
    assert!(
        Truth::new(
            &bare,
            &Effects {
                backlash: Some(GearBacklash::direction(vec![1e-3]).unwrap()),
                ..Effects::default()
            }
        )
        .is_ok()
    );

    let m = iiwa();
    let e = Truth::new(
        &m,
        &Effects {
            compliance: Some(JointCompliance::uniform(6, 1e4).unwrap()),
            ..Effects::default()
        },
    )
    .unwrap_err();
    assert!(
        e.to_string().contains("stiffness_nm_per_rad") && e.to_string().contains("7 joints"),
        "{e}"
    );
    let e = Truth::new(
        &m,
        &Effects {
            thermal: Some(ThermalDrift::uniform(6, 20.0, 23e-6).unwrap()),
            ..Effects::default()
        },
    )
    .unwrap_err();
    assert!(e.to_string().contains("beta_rad_per_k"), "{e}");

    let mut rng = StdRng::seed_from_u64(4);
    let effects = all_effects(&m, &mut rng);
    let truth = Truth::new(&m, &effects).unwrap();
    let mut s = truth.scratch();
    let p = Vector3::zeros();
    let q = [0.1; 7];
    let check = |c: Conditions<'_>,
                 p: &Vector3<f64>,
                 g: &Vector3<f64>,
                 s: &mut sim::effects::TruthScratch| {
        let e = truth.target(&c, p, g, s).unwrap_err();
        let text = e.to_string();
        assert!(!text.contains('\n'), "{text}");
        text
    };
    assert!(check(cond(&q[..6], None, 20.0, None), &p, &gravity(), &mut s).contains("expected 7"));
    let mut qn = q;
    qn[2] = f64::NAN;
    assert!(check(cond(&qn, None, 20.0, None), &p, &gravity(), &mut s).contains("joint 3"));
    assert!(
        check(
            cond(&q, Some(&[0, 0, 2, 0, 0, 0, 0]), 20.0, None),
            &p,
            &gravity(),
            &mut s
        )
        .contains("dir[2]")
    );
    assert!(check(cond(&q, Some(&[0; 6]), 20.0, None), &p, &gravity(), &mut s).contains("dir"));
    assert!(check(cond(&q, None, f64::NAN, None), &p, &gravity(), &mut s).contains("temp_c"));
    let neg = Payload {
        mass: -1.0,
        com: [0.0; 3],
    };
    assert!(
        check(cond(&q, None, 20.0, Some(neg)), &p, &gravity(), &mut s).contains("payload.mass")
    );
    let bad_p = Vector3::new(0.0, f64::INFINITY, 0.0);
    assert!(check(cond(&q, None, 20.0, None), &bad_p, &gravity(), &mut s).contains("p_flange[1]"));
    let bad_g = Vector3::new(f64::NAN, 0.0, -9.81);
    assert!(check(cond(&q, None, 20.0, None), &p, &bad_g, &mut s).contains("gravity[0]"));

    // Soft joints and a heavy payload: no equilibrium near the pose, an error rather than garbage.
    let soft = Effects {
        compliance: Some(JointCompliance::uniform(7, 20.0).unwrap()),
        ..Effects::default()
    };
    let heavy = Payload {
        mass: 50.0,
        com: [0.0, 0.0, 0.1],
    };
    let q = [0.0, 1.2, 0.0, 0.0, 0.0, 0.0, 0.0];
    let e = true_target(
        &m,
        &soft,
        &cond(&q, None, 20.0, Some(heavy)),
        &p,
        &gravity(),
    )
    .unwrap_err();
    assert!(matches!(e, SimError::ComplianceDiverged { .. }), "{e}");
    assert!(!e.to_string().contains('\n'));
}

#[test]
fn effects_read_from_toml_and_refuse_typos_and_bad_values() {
    let text = r#"
        [kinematic]
        joint_twists = [[0, 0, 0, 1e-3, 0, 0], [0, 1e-3, 0, 0, 0, 0]]
        zero_offsets = [1e-4, -2e-4]
        [compliance]
        stiffness_nm_per_rad = [5000.0, inf]
        [backlash]
        dead_band_rad = [1e-3, 2e-3]
        mode = "gravity"
        threshold_nm = 2.0
        [thermal]
        t_ref_c = 20.0
        alpha_per_k = [23e-6, 23e-6, 23e-6]
    "#;
    let e: Effects = toml::from_str(text).unwrap();
    assert_eq!(
        e.compliance.as_ref().unwrap().stiffness_nm_per_rad()[1],
        f64::INFINITY
    );
    assert_eq!(e.kinematic.as_ref().unwrap().base_twist(), [0.0; 6]);
    assert_eq!(e.thermal.as_ref().unwrap().beta_rad_per_k(), &[0.0, 0.0]);
    let m = two_link();
    let t = true_target(
        &m,
        &e,
        &cond(&[0.1, 0.2], None, 30.0, None),
        &Vector3::zeros(),
        &gravity(),
    )
    .unwrap();
    assert!(t.compliance_iterations > 0);
    // Round trip through JSON (the truth file), infinity included.
    let json = serde_json::to_string(&e).unwrap();
    assert_eq!(serde_json::from_str::<Effects>(&json).unwrap(), e);

    let typo = toml::from_str::<Effects>("[complience]\nstiffness_nm_per_rad = [1.0]").unwrap_err();
    assert!(typo.to_string().contains("complience"), "{typo}");
    let bad = toml::from_str::<Effects>(
        "[backlash]\ndead_band_rad = [1e-3, -1e-3]\nmode = \"direction\"",
    )
    .unwrap_err();
    assert!(bad.to_string().contains("dead_band_rad[1]"), "{bad}");
    let bad =
        toml::from_str::<Effects>("[kinematic]\njoint_twists = [[0, 0, 5, 0, 0, 0]]").unwrap_err();
    assert!(bad.to_string().contains("joint_twists[0]"), "{bad}");
}

#[test]
fn prepared_evaluation_does_not_allocate() {
    let m = iiwa();
    let mut rng = StdRng::seed_from_u64(9);
    let effects = all_effects(&m, &mut rng);
    let truth = Truth::new(&m, &effects).unwrap();
    let mut s = truth.scratch();
    let qs: Vec<[f64; 7]> = (0..50).map(|_| random_q(&mut rng)).collect();
    let dir = [1i8, -1, 0, 1, -1, 0, 1];
    let pl = Some(Payload {
        mass: 2.0,
        com: [0.0, 0.0, 0.05],
    });
    let p = Vector3::new(0.0, 0.0, 0.05);
    let g = gravity();
    let before = allocations();
    let mut iterations = 0;
    for (k, q) in qs.iter().enumerate() {
        let c = cond(q, Some(&dir), 20.0 + k as f64 * 0.3, pl);
        iterations += truth
            .target(&c, &p, &g, &mut s)
            .unwrap()
            .compliance_iterations;
    }
    assert_eq!(allocations() - before, 0);
    assert!(iterations >= 100);
}

#[test]
fn truth_is_shareable_across_threads() {
    fn send_sync<T: Send + Sync>() {}
    send_sync::<Truth>();
    send_sync::<sim::effects::TruthScratch>();
}

// ---------------------------------------------------------------------------------------------------
// Transmission error, joint coupling and link deflection.

#[test]
fn planar_transmission_error_and_coupling_match_closed_form() {
    let m = two_link();
    let p = Vector3::new(0.05, 0.0, 0.02);
    // Joint 1: orders 1 and 2; joint 2: order 5 (beyond the estimator's 1–3).
    let te = TransmissionError::new(
        vec![1, 2, 5],
        vec![vec![2e-4, -1e-4, 0.0], vec![0.0, 0.0, 5e-5]],
        vec![vec![0.3, 1.1, 0.0], vec![0.0, 0.0, -0.4]],
    )
    .unwrap();
    let effects = Effects {
        transmission: Some(te),
        ..Effects::default()
    };
    for q in [[0.0, 0.0], [0.4, -1.1], [-2.7, 2.0]] {
        let t = true_target(&m, &effects, &cond(&q, None, 20.0, None), &p, &gravity()).unwrap();
        // By hand: θ₁ = q₁ + 2e-4 sin(q₁ + 0.3) − 1e-4 sin(2 q₁ + 1.1), θ₂ = q₂ + 5e-5 sin(5 q₂ − 0.4).
        let th1 = q[0] + 2e-4 * (q[0] + 0.3).sin() - 1e-4 * (2.0 * q[0] + 1.1).sin();
        let th2 = q[1] + 5e-5 * (5.0 * q[1] - 0.4).sin();
        assert!((t.q_link[0] - th1).abs() < 1e-16 && (t.q_link[1] - th2).abs() < 1e-16);
        let expect = planar(th1, th2, 0.2, 1.0, 0.5, p);
        assert!(close3(&t.p_base, &expect) < 1e-15);
        let nominal = planar(q[0], q[1], 0.2, 1.0, 0.5, p);
        assert!(arr_close(t.contribution.transmission, &(expect - nominal)) < 1e-15);
        assert_eq!(t.contribution.coupling, [0.0; 3]);
    }
    // Coupled transmission error: joint 2 gains 4e-5 sin(2 q₁ + 0.7), joint 1 nothing.
    let effects = Effects {
        coupled_transmission: Some(
            CoupledTransmission::new(vec![CoupledTerm {
                joint: 2,
                source: 1,
                order: 2,
                amplitude_rad: 4e-5,
                phase_rad: 0.7,
            }])
            .unwrap(),
        ),
        ..Effects::default()
    };
    for q in [[0.0, 0.5], [0.4, -1.1], [-2.7, 2.0]] {
        let t = true_target(&m, &effects, &cond(&q, None, 20.0, None), &p, &gravity()).unwrap();
        let th2 = q[1] + 4e-5 * (2.0 * q[0] + 0.7).sin();
        assert!(t.q_link[0] == q[0] && (t.q_link[1] - th2).abs() < 1e-16);
        let expect = planar(q[0], th2, 0.2, 1.0, 0.5, p);
        let nominal = planar(q[0], q[1], 0.2, 1.0, 0.5, p);
        assert!(arr_close(t.contribution.coupled_transmission, &(expect - nominal)) < 1e-15);
        assert!(close3(&t.p_base, &expect) < 1e-15);
    }
    // Coupling: joint 2 gains 3e-4 q₁, joint 1 a scale error of −2e-4.
    let effects = Effects {
        coupling: Some(
            JointCoupling::new(vec![
                CouplingTerm {
                    joint: 2,
                    source: 1,
                    ratio_rad_per_rad: 3e-4,
                },
                CouplingTerm {
                    joint: 1,
                    source: 1,
                    ratio_rad_per_rad: -2e-4,
                },
            ])
            .unwrap(),
        ),
        ..Effects::default()
    };
    for q in [[0.0, 0.5], [0.4, -1.1], [-2.7, 2.0]] {
        let t = true_target(&m, &effects, &cond(&q, None, 20.0, None), &p, &gravity()).unwrap();
        let (th1, th2) = (q[0] * (1.0 - 2e-4), q[1] + 3e-4 * q[0]);
        assert!((t.q_link[0] - th1).abs() < 1e-16 && (t.q_link[1] - th2).abs() < 1e-16);
        let expect = planar(th1, th2, 0.2, 1.0, 0.5, p);
        assert!(close3(&t.p_base, &expect) < 1e-15);
        let nominal = planar(q[0], q[1], 0.2, 1.0, 0.5, p);
        assert!(arr_close(t.contribution.coupling, &(expect - nominal)) < 1e-15);
        if q[0] == 0.0 {
            assert_eq!(t.contribution.coupling, [0.0; 3], "q₁ = 0: nothing moves");
        }
    }
}

/// Joint 1 about z at height 0.2 m (link 1: 1 kg at 0.15 m up its axis), joint 2 about y 0.3 m above
/// it, link 2 of 1 m along x (2 kg at 0.5 m) to the tip.
const ZY_ARM: &str = r#"<robot name="zy">
  <link name="base"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0 0 0.2"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <link name="l1"><inertial><origin xyz="0 0 0.15"/><mass value="1"/>
    <inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0 0 0.3"/>
    <axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <link name="l2"><inertial><origin xyz="0.5 0 0"/><mass value="2"/>
    <inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>
  <joint name="tool" type="fixed"><parent link="l2"/><child link="tip"/><origin xyz="1 0 0"/></joint>
  <link name="tip"/>
</robot>"#;

/// Rotation about +z by `a` applied to `v`.
fn rz(a: f64, v: Vector3<f64>) -> Vector3<f64> {
    let (s, c) = a.sin_cos();
    Vector3::new(c * v.x - s * v.y, s * v.x + c * v.y, v.z)
}

#[test]
fn zy_arm_deflection_and_joint_compliance_settle_together_as_derived_by_hand() {
    // Joint 1's axis is z: its deflection axes are u = x, v = y. Everything hangs in the x-z plane of
    // link 1's frame, so the moment across joint 1 is about v only (α = 0) and tilts the whole arm by
    // β about y, a rotation that adds to joint 2's angle: with φ = θ₂ + β the angle of link 2 below
    // the horizontal, the holding torque of joint 2 is τ₂ = −g m₂ l cos φ, joint 1 (vertical) holds
    // nothing (θ₁ = q₁ whatever its stiffness), and the moment about y at joint 1's origin is
    // M = g [m₁ h₁ sin β + m₂ (l cos φ + h sin β)] (the lever of a point (x, 0, z) is x cos β + z sin β).
    // Equilibrium: θ₂ = q₂ + g m₂ l cos φ / k₂ and β = c M.
    let m = load_str(ZY_ARM, "zy", &ChainSpec::default()).unwrap();
    let (m1, h1, m2, l, h) = (1.0, 0.15, 2.0, 0.5, 0.3);
    let p = Vector3::new(0.05, 0.0, 0.0);
    let c = 4e-4; // rad/(N m): soft, so that the coupling is far above rounding
    for (k2, q) in [
        (f64::INFINITY, [0.3, 0.0]),
        (800.0, [0.3, 0.0]),
        (800.0, [-1.2, 0.7]),
        (1500.0, [2.0, -0.9]),
    ] {
        let effects = Effects {
            compliance: Some(JointCompliance::new(vec![2000.0, k2]).unwrap()),
            deflection: Some(LinkDeflection::new(vec![[c, c], [0.0, 0.0]]).unwrap()),
            ..Effects::default()
        };
        let t = true_target(&m, &effects, &cond(&q, None, 20.0, None), &p, &gravity()).unwrap();
        // The two equations by fixed-point iteration (a contraction: c g m l ≈ 4e-3, g m l / k ≈ 0.01).
        let (mut th2, mut beta) = (q[1], 0.0f64);
        for _ in 0..200 {
            let phi = th2 + beta;
            th2 = q[1] + G * m2 * l * phi.cos() / k2;
            beta = c * G * (m1 * h1 * beta.sin() + m2 * (l * phi.cos() + h * beta.sin()));
        }
        assert!(beta > 1e-3, "a real tilt: {beta}");
        assert!(
            (t.q_link[0] - q[0]).abs() < 1e-15,
            "vertical joint 1 holds nothing"
        );
        assert!(
            (t.q_link[1] - th2).abs() < 1e-13,
            "{} vs {th2}",
            t.q_link[1]
        );
        // Tip: base height, then Rz(q₁) Ry(β) [(0, 0, h) + Ry(θ₂) (1 m + p)].
        let arm = Vector3::new(0.0, 0.0, h) + ry(th2, Vector3::new(1.0, 0.0, 0.0) + p);
        let expect = Vector3::new(0.0, 0.0, 0.2) + rz(q[0], ry(beta, arm));
        assert!(
            close3(&t.p_base, &expect) < 1e-13,
            "{}",
            close3(&t.p_base, &expect)
        );
        // The joint sag alone (no tilt) is the compliance contribution; the rest is the deflection's.
        let th2_alone = if k2.is_finite() {
            bisect(
                |th| k2 * (q[1] - th) + G * m2 * l * th.cos(),
                q[1] - 0.2,
                q[1] + 0.2,
            )
        } else {
            q[1]
        };
        let alone = Vector3::new(0.0, 0.0, 0.2)
            + rz(
                q[0],
                Vector3::new(0.0, 0.0, h) + ry(th2_alone, Vector3::new(1.0, 0.0, 0.0) + p),
            );
        let nominal = Vector3::new(0.0, 0.0, 0.2)
            + rz(
                q[0],
                Vector3::new(0.0, 0.0, h) + ry(q[1], Vector3::new(1.0, 0.0, 0.0) + p),
            );
        assert!(arr_close(t.contribution.compliance, &(alone - nominal)) < 1e-13);
        assert!(arr_close(t.contribution.deflection, &(expect - alone)) < 1e-13);
    }
}

#[test]
fn planar_arm_does_not_deflect_across_parallel_horizontal_axes() {
    // Both axes +y, gravity in the arm's plane: the moments are about y only, so the deflection
    // about u = x and v = −z is zero and the joints settle as without it.
    let m = two_link();
    let p = Vector3::new(0.05, 0.0, 0.0);
    let k = vec![1500.0, 800.0];
    let with = Effects {
        compliance: Some(JointCompliance::new(k.clone()).unwrap()),
        deflection: Some(LinkDeflection::uniform(2, 1e-4).unwrap()),
        ..Effects::default()
    };
    let without = Effects {
        compliance: Some(JointCompliance::new(k).unwrap()),
        ..Effects::default()
    };
    for q in [[0.0, 0.0], [0.4, -1.1]] {
        let a = true_target(&m, &with, &cond(&q, None, 20.0, None), &p, &gravity()).unwrap();
        let b = true_target(&m, &without, &cond(&q, None, 20.0, None), &p, &gravity()).unwrap();
        assert!(close3(&a.p_base, &b.p_base) < 1e-15);
        assert!(Vector3::from(a.contribution.deflection).amax() < 1e-15);
    }
}

/// The iiwa 7's URDF with two revolute joints (massless links between) after every joint `i` whose
/// deflection compliance is given: `u`, `v` of the module docs written out for its axes (+z: x, y;
/// +y: x, −z; −y: x, +z), both hinges at the joint origin.
fn iiwa_with_hinges(deflecting: &[bool; 7]) -> Model {
    let axes = [
        ([1, 0, 0], [0, 1, 0]),
        ([1, 0, 0], [0, 0, -1]),
        ([1, 0, 0], [0, 1, 0]),
        ([1, 0, 0], [0, 0, 1]),
        ([1, 0, 0], [0, 1, 0]),
        ([1, 0, 0], [0, 0, -1]),
        ([1, 0, 0], [0, 1, 0]),
    ];
    let mut text = iiwa_text().to_string();
    let mut extra = String::new();
    for i in 0..7 {
        if !deflecting[i] {
            continue;
        }
        let link = format!("iiwa7_link_{}", i + 1);
        let child = format!("<child link=\"{link}\"/>");
        assert_eq!(text.matches(&child).count(), 1);
        text = text.replace(&child, &format!("<child link=\"{link}_du\"/>"));
        let (u, v) = axes[i];
        for (name, from, to, a) in [
            ("u", format!("{link}_du"), format!("{link}_dv"), u),
            ("v", format!("{link}_dv"), link.clone(), v),
        ] {
            extra.push_str(&format!(
                "<link name=\"{from}\"/><joint name=\"A{}_{name}\" type=\"revolute\"><parent link=\"{from}\"/>\
                 <child link=\"{to}\"/><axis xyz=\"{} {} {}\"/>\
                 <limit lower=\"-1\" upper=\"1\" effort=\"1\" velocity=\"1\"/></joint>\n",
                i + 1,
                a[0],
                a[1],
                a[2]
            ));
        }
    }
    let text = text.replace("</robot>", &format!("{extra}</robot>"));
    load_str(&text, "iiwa7_hinged", &ChainSpec::default()).unwrap()
}

/// Holding torques of `model` at `x` from its forward kinematics, straight from the definition
/// `τₖ = −wₖ · (Σ_{bodies beyond k} m (c − pₖ)) × g` (bodies of mass 0 skipped), payload at the flange.
fn holding_torques(model: &Model, x: &[f64], pl: &Payload) -> Vec<f64> {
    let mut d = Data::new(model);
    forward_kinematics(model, &mut d, x);
    let g = gravity();
    let mut points: Vec<(usize, f64, Vector3<f64>)> = Vec::new();
    for (b, body) in model.bodies().iter().enumerate() {
        if body.mass > 0.0 {
            points.push((
                b,
                body.mass,
                (d.joint_poses[b] * Point3::from(body.com)).coords,
            ));
        }
    }
    let pc = (d.flange * Point3::from(Vector3::from(pl.com))).coords;
    points.push((model.nq() - 1, pl.mass, pc));
    (0..model.nq())
        .map(|k| {
            let t = &d.joint_poses[k];
            let w = t.rotation * model.joints()[k].axis;
            let mut r = Vector3::zeros();
            for (b, mass, c) in &points {
                if *b >= k {
                    r += (c - t.translation.vector) * *mass;
                }
            }
            -w.dot(&r.cross(&g))
        })
        .collect()
}

#[test]
fn iiwa_joint_and_deflection_equilibrium_holds_on_the_urdf_with_hinges() {
    // The settled joint angles with the hinge angles (found here, given the joints, by their own
    // fixed point) put the hinged URDF in equilibrium: every joint spring and every bearing spring
    // balances its holding torque (computed here from the URDF's forward kinematics) to rounding,
    // and the hinged URDF's flange is the truth's.
    let m = iiwa();
    let cd: [[f64; 2]; 7] = [
        [2e-6, 3e-6],
        [4e-6, 5e-6],
        [0.0, 0.0],
        [3e-6, 6e-6],
        [0.0, 0.0],
        [8e-6, 2e-6],
        [0.0, 0.0],
    ];
    let deflecting = cd.map(|c| c[0] > 0.0);
    let hinged = iiwa_with_hinges(&deflecting);
    assert_eq!(hinged.nq(), 15);
    let mut rng = StdRng::seed_from_u64(12);
    let pl = Payload {
        mass: 3.0,
        com: [0.02, -0.01, 0.08],
    };
    let p = Vector3::new(0.0, 0.0, 0.05);
    for with_joints in [false, true] {
        let k = iiwa_stiffness();
        let effects = Effects {
            compliance: with_joints.then(|| JointCompliance::new(k.clone()).unwrap()),
            deflection: Some(LinkDeflection::new(cd.to_vec()).unwrap()),
            ..Effects::default()
        };
        let truth = Truth::new(&m, &effects).unwrap();
        let mut s = truth.scratch();
        let mut worst = 0.0f64;
        for _ in 0..20 {
            let q = random_q(&mut rng);
            let t = truth
                .target(&cond(&q, None, 20.0, Some(pl)), &p, &gravity(), &mut s)
                .unwrap();
            // Unknowns of the hinged URDF: each joint, then its u and v hinges.
            let mut x = Vec::new();
            let mut hinge_c = Vec::new();
            for i in 0..7 {
                x.push(s.q_link()[i]);
                hinge_c.push(None);
                if deflecting[i] {
                    x.extend([0.0, 0.0]);
                    hinge_c.extend([Some(cd[i][0]), Some(cd[i][1])]);
                }
            }
            for _ in 0..100 {
                let tau = holding_torques(&hinged, &x, &pl);
                for (k, c) in hinge_c.iter().enumerate() {
                    if let Some(c) = c {
                        x[k] = -c * tau[k];
                    }
                }
            }
            let tau = holding_torques(&hinged, &x, &pl);
            let mut joint = 0;
            for (kx, c) in hinge_c.iter().enumerate() {
                let res = match c {
                    Some(c) => -x[kx] / c - tau[kx],
                    None => {
                        let r = if with_joints {
                            k[joint] * (q[joint] - x[kx]) - tau[kx]
                        } else {
                            q[joint] - x[kx]
                        };
                        joint += 1;
                        r
                    }
                };
                // Bearing stiffness up to 5e5 N m/rad times an angle rounding of 1e-16 rad.
                assert!(res.abs() < 1e-9, "unknown {kx}: residual {res:e}");
                worst = worst.max(res.abs());
            }
            let fh = fk(&hinged, &x);
            assert!(
                pose_diff(&fh, &t.flange) < 1e-14,
                "{}",
                pose_diff(&fh, &t.flange)
            );
            assert!(close3(&t.p_base, &(fh * Point3::from(p)).coords) < 1e-14);
            assert!(Vector3::from(t.contribution.deflection).norm() > 1e-5);
        }
        eprintln!("joints {with_joints}: worst equilibrium residual {worst:.1e}");
    }
}

#[test]
fn each_absent_new_effect_contributes_exactly_zero_and_the_rest_still_sum() {
    let m = iiwa();
    let mut rng = StdRng::seed_from_u64(21);
    let all = all_effects(&m, &mut rng);
    let p = Vector3::new(0.01, -0.02, 0.08);
    let pl = Some(Payload {
        mass: 3.0,
        com: [0.0, 0.0, 0.06],
    });
    for id in [
        EffectId::TransmissionError,
        EffectId::JointCoupling,
        EffectId::CoupledTransmission,
        EffectId::LinkDeflection,
    ] {
        let mut e = all.clone();
        match id {
            EffectId::TransmissionError => e.transmission = None,
            EffectId::JointCoupling => e.coupling = None,
            EffectId::CoupledTransmission => e.coupled_transmission = None,
            _ => e.deflection = None,
        }
        let truth = Truth::new(&m, &e).unwrap();
        let mut s = truth.scratch();
        for k in 0..5 {
            let q = random_q(&mut rng);
            let dir = [1i8, -1, 0, 1, -1, 0, 1];
            let t = truth
                .target(
                    &cond(&q, Some(&dir), 22.0 + k as f64, pl),
                    &p,
                    &gravity(),
                    &mut s,
                )
                .unwrap();
            assert_eq!(t.contribution.get(id), [0.0; 3], "{id:?}");
            let pn = (fk(&m, &q) * Point3::from(p)).coords;
            assert!(arr_close(t.contribution.total(), &(t.p_base - pn)) < 1e-15);
        }
    }
}
