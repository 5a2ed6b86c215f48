//! Speed of a full kinematic identification. Target (issue 4): the iiwa 7 from 200 position
//! measurements (10 µm noise) in at most 5 ms on the project's 2-core machine: start, base-and-target
//! fit, full fit, covariance, observability and the named null space.

#[path = "../tests/common/mod.rs"]
mod common;

use calib::fit::{CalibrationOptions, Dataset, FitRequest, fit};
use criterion::{Criterion, criterion_group, criterion_main};
use rand::SeedableRng;
use sim::robots;
use std::hint::black_box;

fn bench(c: &mut Criterion) {
    let model = robots::load_builtin("iiwa7").unwrap();
    let mut g = rand::rngs::StdRng::seed_from_u64(2024);
    let truth = common::Truth::random(&model, false, &mut g);
    let configs = common::random_configs(&model, 200, &mut g);
    let table = common::table(&model, &truth, &configs, 1e-5, 0.0, &mut g);
    let data = Dataset::all(&table, "bench");
    let options = CalibrationOptions::default();
    c.bench_function("iiwa7/identify_200_positions", |b| {
        b.iter(|| black_box(fit(&model, &data, &FitRequest::kinematic(&options)).unwrap()))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
