//! Speed of the generator's per-measurement work (analytic truth with every effect on, plus the
//! tracker reading), without planning or file I/O, on the shipped `iiwa7_all` scenario (thermal
//! warm-up, kinematic offsets, direction backlash, joint compliance with a varying payload), and on the
//! same scenario with the effects of issue 12 added from code (`iiwa7_all_issue12`: transmission error
//! and link deflection as in `iiwa7_transmission.toml` and `iiwa7_deflection.toml`, a joint coupling
//! and a coupled transmission error).
//! Target (issue 3): ≥ 200,000 measured poses per second on one core, and near-linear scaling on two
//! (the `threads_2` throughput about twice `threads_1`).

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use sim::effects::Truth;
use sim::generate::{plan_of, simulate};
use sim::scenario::{Magnitude, Overrides, Scenario, ScenarioBuilder};
use std::hint::black_box;
use std::path::PathBuf;

fn scenarios() -> [(&'static str, Scenario); 2] {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenarios");
    let all = Scenario::load(&dir.join("iiwa7_all.toml")).unwrap();
    let sections = |name: &str| Scenario::load(&dir.join(name)).unwrap().file.effects;
    let transmission = sections("iiwa7_transmission.toml").transmission.unwrap();
    let deflection = sections("iiwa7_deflection.toml").deflection.unwrap();
    let issue12 = ScenarioBuilder::from_scenario(&all)
        .effect::<sim::effects::transmission_error::TransmissionError>(transmission)
        .effect::<sim::effects::link_deflection::LinkDeflection>(deflection)
        .joint_coupling(vec![[6, 4]], Magnitude::Number(2e-4))
        .coupled_transmission(
            vec![[6, 5]],
            Magnitude::Number(5e-5),
            Magnitude::Number(0.3),
        )
        .build()
        .unwrap();
    [
        ("generate_iiwa7_all", all),
        ("generate_iiwa7_all_issue12", issue12),
    ]
}

fn bench(c: &mut Criterion) {
    let rows = 20_000;
    for (group_name, scenario) in scenarios() {
        let res = scenario
            .resolve(&Overrides {
                poses: Some(rows),
                ..Overrides::default()
            })
            .unwrap();
        let plan = plan_of(&res).unwrap();
        let truth = Truth::new(&res.model, &res.effects).unwrap();
        let mut group = c.benchmark_group(group_name);
        group.throughput(Throughput::Elements(plan.len() as u64));
        group.sample_size(20);
        for threads in [1usize, 2] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            group.bench_function(format!("simulate_threads_{threads}"), |b| {
                b.iter(|| {
                    pool.install(|| {
                        black_box(
                            simulate(&truth, &res.tracker, &res.gravity, &plan, res.seed, None)
                                .unwrap(),
                        )
                    })
                })
            });
        }
        group.finish();
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
