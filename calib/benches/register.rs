//! Speed of `register` (issue 13): a calibrated UR10-sized model, a moved tracker registered from 20
//! position measurements (10 µm noise). Target: under 5 ms on the project's 2-core machine.

#[path = "../tests/common/mod.rs"]
mod common;

use calib::fit::register::{RegisterOptions, register};
use calib::fit::{CalibrationOptions, Dataset, FitRequest, fit};
use criterion::{Criterion, criterion_group, criterion_main};
use rand::SeedableRng;
use sim::robots;
use std::hint::black_box;

fn bench(c: &mut Criterion) {
    for robot in ["iiwa7", "ur10"] {
        let model = robots::load_builtin(robot).unwrap();
        let mut g = rand::rngs::StdRng::seed_from_u64(2026);
        let truth = common::Truth::random(&model, false, &mut g);
        let configs = common::random_configs(&model, 200, &mut g);
        let table = common::table(&model, &truth, &configs, 1e-5, 0.0, &mut g);
        let cal = fit(
            &model,
            &Dataset::all(&table, "bench"),
            &FitRequest::kinematic(&CalibrationOptions::default()),
        )
        .unwrap();
        let moved = common::moved_tracker(&truth, &mut g);
        let new = common::table(
            &model,
            &moved,
            &common::random_configs(&model, 20, &mut g),
            1e-5,
            0.0,
            &mut g,
        );
        let options = RegisterOptions::default();
        c.bench_function(&format!("{robot}/register_20_positions"), |b| {
            b.iter(|| {
                black_box(
                    register(
                        &model,
                        &cal.params,
                        None,
                        None,
                        Some(1e-5),
                        &new,
                        "new",
                        &options,
                    )
                    .unwrap(),
                )
            })
        });
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
