//! Speed of the generator's per-measurement work (analytic truth with every effect on, plus the
//! tracker reading), without planning or file I/O, on the shipped `iiwa7_all` scenario (thermal
//! warm-up, kinematic offsets, direction backlash, joint compliance with a varying payload).
//! Target (issue 3): ≥ 200,000 measured poses per second on one core, and near-linear scaling on two
//! (the `threads_2` throughput about twice `threads_1`).

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use sim::effects::Truth;
use sim::generate::{plan_of, simulate};
use sim::scenario::{Overrides, Scenario};
use std::hint::black_box;
use std::path::PathBuf;

fn bench(c: &mut Criterion) {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenarios/iiwa7_all.toml");
    let rows = 20_000;
    let res = Scenario::load(&path)
        .unwrap()
        .resolve(&Overrides {
            poses: Some(rows),
            ..Overrides::default()
        })
        .unwrap();
    let plan = plan_of(&res).unwrap();
    let truth = Truth::new(&res.model, &res.effects).unwrap();
    let mut group = c.benchmark_group("generate_iiwa7_all");
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

criterion_group!(benches, bench);
criterion_main!(benches);
