//! Speed of the analytic truth on the iiwa 7 with every effect on (thermal drift, kinematic offsets,
//! transmission error, joint coupling, coupled transmission error, gravity-mode backlash, joint compliance with a payload, link
//! deflection on every joint). Target (issue 3): ≥ 200,000 poses per second per core, i.e. ≤ 5 µs
//! per pose, on the project's 2-core machine.

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use nalgebra::Vector3;
use sim::effects::coupled_transmission::{CoupledTerm, CoupledTransmission};
use sim::effects::gear_backlash::GearBacklash;
use sim::effects::joint_compliance::JointCompliance;
use sim::effects::joint_coupling::JointCoupling;
use sim::effects::kinematic_offsets::KinematicOffsets;
use sim::effects::link_deflection::LinkDeflection;
use sim::effects::thermal_drift::ThermalDrift;
use sim::effects::transmission_error::TransmissionError;
use sim::effects::{Conditions, Effects, Truth};
use sim::{Payload, robots};
use std::hint::black_box;

fn configs() -> Vec<[f64; 7]> {
    (0..64)
        .map(|k| {
            std::array::from_fn(|i| {
                ((k as f64 + 1.0) * (0.618034 + 0.414214 * i as f64)).fract() * 3.0 - 1.5
            })
        })
        .collect()
}

fn effects() -> Effects {
    let twist = |k: usize, s: f64| -> [f64; 6] {
        std::array::from_fn(|m| s * (((k * 6 + m) as f64 * 0.618_034).fract() - 0.5))
    };
    Effects {
        kinematic: Some(
            KinematicOffsets::new(
                (0..7).map(|k| twist(k, 2e-3)).collect(),
                (0..7).map(|k| 1e-4 * (k as f64 - 3.0)).collect(),
                twist(20, 1e-3),
                twist(21, 1e-3),
            )
            .unwrap(),
        ),
        compliance: Some(
            JointCompliance::new(vec![9.0e3, 7.5e3, 6.0e3, 5.0e3, 4.0e3, 3.0e3, 2.0e3]).unwrap(),
        ),
        backlash: Some(GearBacklash::gravity_uniform(vec![2e-4; 7], 1.0).unwrap()),
        thermal: Some(
            ThermalDrift::uniform(7, 20.0, 23e-6)
                .unwrap()
                .with_zero_drift(vec![2e-6; 7])
                .unwrap(),
        ),
        transmission: Some(
            TransmissionError::new(
                vec![1, 2, 3],
                (0..7).map(|k| vec![8e-5, -3e-5, 1e-5 * k as f64]).collect(),
                (0..7).map(|k| vec![0.1 * k as f64, 1.0, -0.5]).collect(),
            )
            .unwrap(),
        ),
        coupling: Some(JointCoupling::single(6, 4, 2e-4).unwrap()),
        deflection: Some(LinkDeflection::uniform(7, 2e-6).unwrap()),
        coupled_transmission: Some(
            CoupledTransmission::new(vec![CoupledTerm {
                joint: 6,
                source: 5,
                order: 1,
                amplitude_rad: 5e-5,
                phase_rad: 0.3,
            }])
            .unwrap(),
        ),
    }
}

fn bench(c: &mut Criterion) {
    let model = robots::load_builtin("iiwa7").unwrap();
    let truth = Truth::new(&model, &effects()).unwrap();
    let mut scratch = truth.scratch();
    let qs = configs();
    let dirs: Vec<[i8; 7]> = (0..64)
        .map(|k| std::array::from_fn(|i| [-1, 0, 1][(k + i) % 3]))
        .collect();
    let p_flange = Vector3::new(0.01, -0.02, 0.08);
    let gravity = Vector3::new(0.0, 0.0, -9.81);
    let payload = Some(Payload {
        mass: 3.0,
        com: [0.0, 0.0, 0.06],
    });
    // Breakdown: no effects (the stages' bookkeeping reduces to one chain evaluation), geometry only
    // (thermal + kinematic), everything but link deflection, and everything (adds the joint +
    // deflection equilibrium).
    let geometry = Effects {
        compliance: None,
        backlash: None,
        deflection: None,
        transmission: None,
        coupling: None,
        coupled_transmission: None,
        ..effects()
    };
    let no_deflection = Effects {
        deflection: None,
        ..effects()
    };
    let variants = [
        (
            "true_target_no_effects",
            Truth::new(&model, &Effects::default()).unwrap(),
        ),
        (
            "true_target_thermal_kinematic",
            Truth::new(&model, &geometry).unwrap(),
        ),
        (
            "true_target_all_but_deflection",
            Truth::new(&model, &no_deflection).unwrap(),
        ),
    ];
    let mut group = c.benchmark_group("iiwa7");
    group.throughput(Throughput::Elements(1));
    let mut k = 0;
    for (name, t) in &variants {
        let mut sc = t.scratch();
        group.bench_function(*name, |b| {
            b.iter(|| {
                k = (k + 1) % qs.len();
                let cond = Conditions {
                    q: black_box(&qs[k]),
                    dir: Some(&dirs[k]),
                    temp_c: 20.0 + 0.1 * k as f64,
                    payload,
                    branch: None,
                };
                black_box(
                    t.target(&cond, &p_flange, &gravity, &mut sc)
                        .unwrap()
                        .p_base,
                )
            })
        });
    }
    group.bench_function("true_target_all_effects", |b| {
        b.iter(|| {
            k = (k + 1) % qs.len();
            let cond = Conditions {
                q: black_box(&qs[k]),
                dir: Some(&dirs[k]),
                temp_c: 20.0 + 0.1 * k as f64,
                payload,
                branch: None,
            };
            black_box(
                truth
                    .target(&cond, &p_flange, &gravity, &mut scratch)
                    .unwrap()
                    .p_base,
            )
        })
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
