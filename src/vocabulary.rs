//! The extended vocabulary of hidden effects: the one draw of what a blind diagnosis case hides, used
//! by `robocal demo` and by the blind tests (`tests/diagnose_blind.rs`, whose 1,000-draw confusion
//! matrix is in docs/diagnose.md).
//!
//! A [`Kind`] says what is hidden: nothing, each cause of calib's vocabulary alone, four pairs of
//! them, or one of three effects outside it (one joint's angle error in proportion to another joint's
//! angle, a transmission error of 4 to 6 cycles per revolution, one joint's angle error periodic in
//! another joint's angle), which diagnose must report as unexplained structure without naming a
//! cause. [`draw`] then draws the joints and magnitudes (within published ranges, on the KUKA LBR
//! iiwa 7) from the caller's random generator and adds the effects to the caller's scenario. The
//! caller keeps its seed: the blind test its own, the demo the clock's; nothing here is seeded.
//!
//! The hidden effect never reaches the code under test except through the measurements simulated
//! from the scenario.

use calib::model::extensions::Cause;
use rand::{Rng, RngExt};
use sim::effects::gear_backlash::BacklashMode;
use sim::effects::thermal_drift::{TemperatureProfile, WarmUp};
use sim::effects::transmission_error::{TransmissionError, TransmissionSection};
use sim::scenario::{Magnitude, PayloadSection, ScenarioBuilder};
use std::collections::BTreeMap;

/// Joints of the iiwa 7, the robot the draws are made for.
const JOINTS: usize = 7;

/// What a case hides.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Kind {
    /// Nothing beyond the geometric errors.
    Nothing,
    /// Joint compliance on one or two of joints 2-4.
    Compliance,
    /// Gear backlash on one or two of joints 1-5.
    Backlash,
    /// Thermal drift: a warm-up with aluminium links.
    Thermal,
    /// A transmission error of 1-3 cycles per revolution on one or two of joints 1-4.
    Transmission,
    /// Link deflection across joints 2 and/or 4.
    Deflection,
    /// Link deflection and joint compliance.
    DeflectionAndCompliance,
    /// A transmission error and backlash on other joints.
    TransmissionAndBacklash,
    /// Joint compliance and backlash on other joints.
    ComplianceAndBacklash,
    /// Backlash and thermal drift.
    BacklashAndThermal,
    /// Outside the vocabulary: one joint's angle error in proportion to another joint's angle.
    Coupling,
    /// Outside the vocabulary: a transmission error of 4 to 6 cycles per revolution.
    HigherHarmonic,
    /// Outside the vocabulary: one joint's angle error periodic in another joint's angle
    /// (`coupled_transmission`).
    CoupledTransmission,
}

impl Kind {
    /// Every kind, in the order of the confusion matrix.
    pub const ALL: [Kind; 13] = [
        Kind::Nothing,
        Kind::Compliance,
        Kind::Backlash,
        Kind::Thermal,
        Kind::Transmission,
        Kind::Deflection,
        Kind::DeflectionAndCompliance,
        Kind::TransmissionAndBacklash,
        Kind::ComplianceAndBacklash,
        Kind::BacklashAndThermal,
        Kind::Coupling,
        Kind::HigherHarmonic,
        Kind::CoupledTransmission,
    ];

    /// Whether the hidden effect is outside the causes diagnose knows.
    pub fn outside(self) -> bool {
        matches!(
            self,
            Kind::Coupling | Kind::HigherHarmonic | Kind::CoupledTransmission
        )
    }
}

/// One hidden effect.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct HiddenEffect {
    /// The cause diagnose must name; `None` for an effect outside its vocabulary.
    pub cause: Option<Cause>,
    /// What the effect is, in words (`joint compliance`, `joint coupling`, …).
    pub name: &'static str,
    /// The 1-based joints the cause acts on (what diagnose must name; for an effect outside the
    /// vocabulary, the joint whose angle it disturbs).
    pub joints: Vec<usize>,
    /// Its magnitudes, in words with their units.
    pub description: String,
}

/// What a case hides, as drawn by [`draw`].
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Hidden {
    /// The kind drawn.
    pub kind: Kind,
    /// The effects added to the scenario, in the order they were drawn.
    pub effects: Vec<HiddenEffect>,
    /// For an effect outside the vocabulary: the 1-based joint whose angle it disturbs.
    pub outside_joint: Option<usize>,
    /// Causes a measurement cannot tell from the hidden ones, which diagnose may name besides, with
    /// their 1-based joints: bending of joint i about the axis line of joint i + 1 is joint i + 1's
    /// compliance (iiwa joints 2 and 4 about z; see calib's link_deflection).
    pub aliases: BTreeMap<Cause, Vec<usize>>,
}

impl Hidden {
    /// The hidden causes of the vocabulary and their 1-based joints (empty for an effect outside
    /// it: nothing may be named).
    pub fn causes(&self) -> BTreeMap<Cause, Vec<usize>> {
        self.effects
            .iter()
            .filter_map(|e| e.cause.map(|c| (c, e.joints.clone())))
            .collect()
    }

    /// Every effect in one line: `name (description) + …`, or `nothing beyond geometry`.
    pub fn description(&self) -> String {
        if self.effects.is_empty() {
            return "nothing beyond geometry".into();
        }
        self.effects
            .iter()
            .map(|e| format!("{} ({})", e.name, e.description))
            .collect::<Vec<_>>()
            .join(" + ")
    }
}

/// Distinct joints drawn from `pool`, `count` of them, ascending.
fn pick<R: Rng + ?Sized>(rng: &mut R, pool: &[usize], count: usize) -> Vec<usize> {
    let mut left = pool.to_vec();
    let mut out: Vec<usize> = (0..count.min(left.len()))
        .map(|_| left.remove(rng.random_range(0..left.len())))
        .collect();
    out.sort_unstable();
    out
}

/// One magnitude per joint: `values` at `joints` (in order), `rest` elsewhere.
fn array(joints: &[usize], values: &[f64], rest: f64) -> Magnitude {
    Magnitude::List(
        (1..=JOINTS)
            .map(|j| {
                Magnitude::Number(match joints.iter().position(|x| *x == j) {
                    Some(k) => values[k],
                    None => rest,
                })
            })
            .collect(),
    )
}

/// One row of numbers per joint: `rows[k]` at `joints[k]`, zeros (of the same width) elsewhere.
fn table_per_joint(joints: &[usize], rows: &[Vec<f64>], width: usize) -> Magnitude {
    Magnitude::List(
        (1..=JOINTS)
            .map(|j| {
                let row = match joints.iter().position(|x| *x == j) {
                    Some(k) => rows[k].clone(),
                    None => vec![0.0; width],
                };
                Magnitude::List(row.into_iter().map(Magnitude::Number).collect())
            })
            .collect(),
    )
}

/// `a, b and c` of the items' texts.
fn list<T: std::fmt::Display>(items: &[T]) -> String {
    let words: Vec<String> = items.iter().map(|i| i.to_string()).collect();
    match words.split_last() {
        None => String::new(),
        Some((last, [])) => last.clone(),
        Some((last, rest)) => format!("{} and {last}", rest.join(", ")),
    }
}

/// `2 N m/rad at joint 3, 5 N m/rad at joint 4` of per-joint values (with their units).
fn at_joints(joints: &[usize], values: &[String]) -> String {
    joints
        .iter()
        .zip(values)
        .map(|(j, v)| format!("{v} at joint {j}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// A transmission error at `joints` with harmonic `orders`: each amplitude 30-150 µrad with a random
/// phase, the largest at least 100 µrad (harmonic drives: about 1 arc-min peak to peak), on joints
/// 1-4 (joints 5-7 move the reflector by less than the noise for that). Returns the scenario and the
/// description.
fn transmission<R: Rng + ?Sized>(
    rng: &mut R,
    scenario: ScenarioBuilder,
    joints: &[usize],
    orders: Vec<u32>,
) -> (ScenarioBuilder, String) {
    let k = orders.len();
    let amp: Vec<Vec<f64>> = joints
        .iter()
        .map(|_| {
            let mut a: Vec<f64> = (0..k).map(|_| rng.random_range(3e-5..1.5e-4)).collect();
            let top = rng.random_range(0..k);
            a[top] = rng.random_range(1e-4..2e-4);
            a
        })
        .collect();
    let phase: Vec<Vec<f64>> = joints
        .iter()
        .map(|_| {
            (0..k)
                .map(|_| rng.random_range(-std::f64::consts::PI..std::f64::consts::PI))
                .collect()
        })
        .collect();
    let section = TransmissionSection {
        enabled: None,
        harmonics: Some(orders.clone()),
        amplitude_rad: table_per_joint(joints, &amp, k),
        phase_rad: Some(table_per_joint(joints, &phase, k)),
    };
    let urad = |a: &Vec<f64>| {
        let a: Vec<String> = a.iter().map(|v| format!("{:.0}", v * 1e6)).collect();
        format!("{} µrad", a.join("/"))
    };
    let text = format!(
        "{} cycles per revolution, amplitudes {}",
        list(&orders),
        at_joints(joints, &amp.iter().map(urad).collect::<Vec<_>>())
    );
    (scenario.effect::<TransmissionError>(section), text)
}

/// A gripper-like payload whose centre of mass (0-10 cm from the flange) the table does not give,
/// only its mass: up to 7 kg (the iiwa 7's rating), in half of the draws. Returns the scenario and
/// what to add to the description.
fn payload<R: Rng + ?Sized>(rng: &mut R, scenario: ScenarioBuilder) -> (ScenarioBuilder, String) {
    if !rng.random::<bool>() {
        return (scenario, String::new());
    }
    let m = rng.random_range(2.0..7.0);
    let com = [
        rng.random_range(-0.02..0.02),
        rng.random_range(-0.02..0.02),
        rng.random_range(0.0..0.1),
    ];
    let text = format!(
        "; payload up to {m:.1} kg, centre of mass at [{:.3}, {:.3}, {:.3}] m from the flange",
        com[0], com[1], com[2]
    );
    let scenario = scenario.payload(PayloadSection {
        mass_kg: None,
        choice_kg: Some(vec![0.0, m / 2.0, m]),
        com_m: Some(com),
    });
    (scenario, text)
}

/// Draws the joints and magnitudes of a `kind` of hidden effect from `rng` and adds its effects to
/// `scenario` (built for the iiwa 7: seven joints, joints 2-4 carrying gravity torque); returns the
/// scenario and what was hidden. The draws use only `rng`, in a fixed order, so the same generator
/// state gives the same case. Errors are the scenario builder's (none for the ranges drawn here).
pub fn draw<R: Rng + ?Sized>(
    rng: &mut R,
    kind: Kind,
    mut scenario: ScenarioBuilder,
) -> sim::Result<(ScenarioBuilder, Hidden)> {
    let mut effects = Vec::new();
    let mut outside_joint = None;
    let mut aliases = BTreeMap::new();
    let (compliance, backlash, thermal, te, deflection) = match kind {
        Kind::Nothing | Kind::Coupling | Kind::HigherHarmonic | Kind::CoupledTransmission => {
            (false, false, false, false, false)
        }
        Kind::Compliance => (true, false, false, false, false),
        Kind::Backlash => (false, true, false, false, false),
        Kind::Thermal => (false, false, true, false, false),
        Kind::Transmission => (false, false, false, true, false),
        Kind::Deflection => (false, false, false, false, true),
        Kind::DeflectionAndCompliance => (true, false, false, false, true),
        Kind::TransmissionAndBacklash => (false, true, false, true, false),
        Kind::ComplianceAndBacklash => (true, true, false, false, false),
        Kind::BacklashAndThermal => (false, true, true, false, false),
    };
    if compliance {
        // Harmonic-drive joints of lightweight arms: 5e3 to 2e4 N m/rad, on joints whose gravity
        // torque moves the target by much more than the noise without payload (2, 3, 4).
        let count = rng.random_range(1..=2);
        let joints = pick(rng, &[2, 3, 4], count);
        let k: Vec<f64> = joints.iter().map(|_| rng.random_range(5e3..2e4)).collect();
        scenario = scenario.compliance(array(&joints, &k, f64::INFINITY));
        let mut description = format!(
            "stiffness {}",
            at_joints(
                &joints,
                &k.iter()
                    .map(|v| format!("{v:.0} N m/rad"))
                    .collect::<Vec<_>>()
            )
        );
        if !deflection {
            let (s, text) = payload(rng, scenario);
            scenario = s;
            description += &text;
        }
        effects.push(HiddenEffect {
            cause: Some(Cause::JointCompliance),
            name: "joint compliance",
            joints,
            description,
        });
    }
    if deflection {
        // Bearing and link compliance across the shoulder and elbow (joints 2 and 4). The moment
        // stiffness of Harmonic Drive output bearings is 1e5 to 1e6 N m/rad for sizes 14 to 32 (see
        // sim's link_deflection), and the link tubes add about as much: 2e-6 to 5e-6 rad/(N m) per
        // axis at the shoulder (a large unit, up to 60 N m across its axis), 5e-6 to 1e-5 at the
        // elbow (a smaller unit carrying 10 to 30 N m), which bend the arm by 0.05 to 0.3 mrad.
        let count = rng.random_range(1..=2);
        let joints = pick(rng, &[2, 4], count);
        let c: Vec<Vec<f64>> = joints
            .iter()
            .map(|&j| {
                let range = if j == 2 { 2e-6..5e-6 } else { 5e-6..1e-5 };
                vec![
                    rng.random_range(range.clone()),
                    rng.random_range(range.clone()),
                ]
            })
            .collect();
        scenario = scenario.link_deflection(table_per_joint(&joints, &c, 2));
        let mut description = format!(
            "bending compliance {} about the two axes across the joint",
            at_joints(
                &joints,
                &c.iter()
                    .map(|a| format!("{:.1e}/{:.1e} rad/(N m)", a[0], a[1]))
                    .collect::<Vec<_>>()
            )
        );
        let (s, text) = payload(rng, scenario);
        scenario = s;
        description += &text;
        aliases.insert(
            Cause::JointCompliance,
            joints.iter().map(|j| j + 1).collect(),
        );
        effects.push(HiddenEffect {
            cause: Some(Cause::LinkDeflection),
            name: "link deflection",
            joints,
            description,
        });
    }
    if te {
        let count = rng.random_range(1..=2);
        let joints = pick(rng, &[1, 2, 3, 4], count);
        let (s, description) = transmission(rng, scenario, &joints, vec![1, 2, 3]);
        scenario = s;
        effects.push(HiddenEffect {
            cause: Some(Cause::TransmissionError),
            name: "transmission error",
            joints,
            description,
        });
    }
    if backlash {
        // Lost motion of 0.7 to 2 arc-min (2e-4 to 6e-4 rad) on joints 1-5 (joints 6 and 7 move the
        // reflector by less than the noise for that play), not on a joint already hidden.
        let avoid: Vec<usize> = effects.iter().flat_map(|e| e.joints.clone()).collect();
        let pool: Vec<usize> = (1..=5).filter(|j| !avoid.contains(j)).collect();
        let count = rng.random_range(1..=2);
        let joints = pick(rng, &pool, count);
        let b: Vec<f64> = joints
            .iter()
            .map(|_| rng.random_range(2e-4..6e-4))
            .collect();
        scenario = scenario.backlash(array(&joints, &b, 0.0), BacklashMode::Direction);
        let description = format!(
            "lost motion {}",
            at_joints(
                &joints,
                &b.iter()
                    .map(|v| format!("{:.0} µrad", v * 1e6))
                    .collect::<Vec<_>>()
            )
        );
        effects.push(HiddenEffect {
            cause: Some(Cause::GearBacklash),
            name: "gear backlash",
            joints,
            description,
        });
    }
    if thermal {
        // A warm-up of 5 to 15 K with a 20-40 min time constant, aluminium links.
        let delta = rng.random_range(5.0..15.0);
        let tau = rng.random_range(1200.0..2400.0);
        let warm_up = WarmUp::new(20.0, delta, tau)?;
        scenario = scenario
            .temperature(TemperatureProfile::WarmUp(warm_up))
            .thermal(20.0, Magnitude::Number(23e-6), Some(Magnitude::Number(0.0)));
        effects.push(HiddenEffect {
            cause: Some(Cause::ThermalDrift),
            name: "thermal drift",
            joints: Vec::new(),
            description: format!(
                "warm-up by {delta:.1} K with a time constant of {:.0} min, aluminium links",
                tau / 60.0
            ),
        });
    }
    match kind {
        Kind::Coupling => {
            // Cable wind-up or a coupled drive: joint i's angle error grows with joint j's angle,
            // 50 to 200 µrad per rad (0.1 to 0.4 mrad over a joint's range), i on joints 1-4.
            let i = rng.random_range(1..=4);
            let others: Vec<usize> = (1..=6).filter(|j| *j != i).collect();
            let j = others[rng.random_range(0..others.len())];
            let c = rng.random_range(5e-5..2e-4) * if rng.random::<bool>() { 1.0 } else { -1.0 };
            scenario =
                scenario.joint_coupling(vec![[i, j]], Magnitude::List(vec![Magnitude::Number(c)]));
            effects.push(HiddenEffect {
                cause: None,
                name: "joint coupling",
                joints: vec![i],
                description: format!(
                    "joint {i}'s angle gains {:.0} µrad per rad of joint {j}'s (cable wind-up)",
                    c * 1e6
                ),
            });
            outside_joint = Some(i);
        }
        Kind::HigherHarmonic => {
            let joint = rng.random_range(1..=4);
            let order = rng.random_range(4..=6);
            let (s, description) = transmission(rng, scenario, &[joint], vec![order]);
            scenario = s;
            effects.push(HiddenEffect {
                cause: None,
                name: "transmission error beyond 3 cycles per revolution",
                joints: vec![joint],
                description,
            });
            outside_joint = Some(joint);
        }
        Kind::CoupledTransmission => {
            // A drive whose error follows another joint's motor (a coupled wrist, a cable routed
            // through the previous joint): joint i's angle error A sin(q_j + φ), A 150-300 µrad (as
            // the periodic error below), i on joints 1-4, j any other of joints 1-6. Smaller errors
            // are under the probes' level on 100 held-out poses: 121 µrad at joint 4 gave z = 2.7
            // against the 3.9 of α = 0.001 over 30 probes (the probe found the right joints). Not
            // a neighbouring joint j = i ± 1: joint i's axis seen from link i − 2 turns with q(i−1),
            // so a rotation error of joint i − 1 (a kinematic twist) makes an angle error of joint
            // i in sin and cos of q(i−1), and the kinematic fit takes up most of such an error (joint
            // 4 in q3: 61 µm RMS injected, 30 µm left beside 23 µm of noise; joint 3 in q4, whose
            // axis lines up with joint 5's at q4 = 0: 84 µm injected, 33 µm left), under the
            // probes' level: see docs/diagnose.md, Limits.
            let i = rng.random_range(1..=4);
            let others: Vec<usize> = (1..=6usize).filter(|j| j.abs_diff(i) >= 2).collect();
            let j = others[rng.random_range(0..others.len())];
            let a = rng.random_range(1.5e-4..3e-4);
            let phase = rng.random_range(-std::f64::consts::PI..std::f64::consts::PI);
            scenario = scenario.coupled_transmission(
                vec![[i, j]],
                Magnitude::List(vec![Magnitude::Number(a)]),
                Magnitude::List(vec![Magnitude::Number(phase)]),
            );
            effects.push(HiddenEffect {
                cause: None,
                name: "coupled transmission",
                joints: vec![i],
                description: format!(
                    "joint {i}'s angle error {:.0} µrad × sin(q{j} {phase:+.2} rad), periodic in \
                     another joint's angle (a coupled drive)",
                    a * 1e6
                ),
            });
            outside_joint = Some(i);
        }
        _ => {}
    }
    let hidden = Hidden {
        kind,
        effects,
        outside_joint,
        aliases,
    };
    Ok((scenario, hidden))
}
