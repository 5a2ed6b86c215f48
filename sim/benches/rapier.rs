//! Speed of the rapier physics-engine truth (`sim::rapier_truth`): settled poses per second on one core
//! for the iiwa 7 with a 3 kg payload, for the stiff and the soft joint sets of
//! `golden/settle_iiwa7.csv`, next to the analytic compliance equilibrium (`sim::effects::Truth`) on the
//! same poses, and the generator's truth with its compliance stage settled by rapier
//! (`truth_rapier_*`, `[truth] model = "rapier"`). Target (issue 6): ≥ 1,000 settled poses per second per core with rapier.

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use nalgebra::Vector3;
use sim::effects::joint_compliance::JointCompliance;
use sim::effects::{ComplianceSolver, Conditions, Effects, Truth};
use sim::rapier_truth::{RapierArm, SettleOptions};
use sim::{Payload, robots};
use std::hint::black_box;

/// Commanded poses inside the iiwa's joint limits (deterministic low-discrepancy sequence).
fn configs() -> Vec<[f64; 7]> {
    (0..64)
        .map(|k| {
            std::array::from_fn(|i| {
                ((k as f64 + 1.0) * (0.754877666 + 0.569840291 * i as f64)).fract() * 4.0 - 2.0
            })
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let model = robots::load_builtin("iiwa7").unwrap();
    let gravity = Vector3::new(0.0, 0.0, -9.81);
    let payload = Payload {
        mass: 3.0,
        com: [0.02, -0.01, 0.08],
    };
    let qs = configs();
    let sets = [
        ("stiff", vec![15e3, 15e3, 10e3, 10e3, 6e3, 4e3, 4e3]),
        ("soft", vec![2.5e3, 2.5e3, 2e3, 2e3, 1.5e3, 1e3, 1e3]),
    ];
    let mut group = c.benchmark_group("settle");
    group.throughput(Throughput::Elements(qs.len() as u64));
    group.sample_size(20);
    for (name, k) in &sets {
        let arm = RapierArm::new(
            &model,
            k,
            Some(&payload),
            &gravity,
            SettleOptions::default(),
        )
        .unwrap();
        let mut ws = arm.workspace();
        let steps: usize = qs
            .iter()
            .map(|q| arm.settle(&mut ws, q).unwrap().steps)
            .sum();
        eprintln!(
            "rapier {name}: {:.1} engine steps per settled pose (dt {} s)",
            steps as f64 / qs.len() as f64,
            arm.options().dt
        );
        group.bench_function(format!("rapier_{name}"), |b| {
            b.iter(|| {
                for q in &qs {
                    black_box(arm.settle(&mut ws, black_box(q)).unwrap());
                }
            })
        });
        let effects = Effects {
            compliance: Some(JointCompliance::new(k.clone()).unwrap()),
            ..Effects::default()
        };
        // The generator's path: the analytic truth, and the same truth with its compliance stage
        // settled by rapier (`[truth] model = "rapier"`; the arm is built once and cached per scratch).
        for (label, solver) in [
            ("analytic", ComplianceSolver::Analytic),
            (
                "truth_rapier",
                ComplianceSolver::Rapier(SettleOptions::default()),
            ),
        ] {
            let truth = Truth::with_solver(&model, &effects, solver).unwrap();
            let mut scratch = truth.scratch();
            group.bench_function(format!("{label}_{name}"), |b| {
                b.iter(|| {
                    for q in &qs {
                        let cond = Conditions {
                            q,
                            dir: None,
                            temp_c: 20.0,
                            payload: Some(payload),
                            branch: None,
                        };
                        black_box(
                            truth
                                .target(&cond, &Vector3::zeros(), &gravity, &mut scratch)
                                .unwrap(),
                        );
                    }
                })
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
