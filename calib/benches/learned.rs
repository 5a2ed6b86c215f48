//! Speed of the learned residual models (issue 5) on 7 joints: a cross-validated fit ("poly" over
//! degrees 1–3 and the λ grid; "kernel" over the length-scale × λ grid) from 400 and 1000 poses, and
//! one prediction.

use calib::model::learned;
use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::Vector3;
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use std::hint::black_box;

fn data(rows: usize) -> (Vec<f64>, Vec<Vector3<f64>>) {
    let mut rng = StdRng::seed_from_u64(1);
    let q: Vec<f64> = (0..rows * 7)
        .map(|_| 3.0 * rng.random::<f64>() - 1.5)
        .collect();
    let r = q
        .chunks_exact(7)
        .map(|q| {
            let noise = Vector3::new(
                rng.random::<f64>(),
                rng.random::<f64>(),
                rng.random::<f64>(),
            ) * 2e-5;
            Vector3::new(3e-5, 0.0, 4e-5) * (2.0 * q[3]).sin() + noise
        })
        .collect();
    (q, r)
}

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("learned");
    g.sample_size(10);
    for rows in [400usize, 1000] {
        let (q, r) = data(rows);
        for kind in [learned::LearnedKind::Poly, learned::LearnedKind::Kernel] {
            g.bench_function(format!("fit_{kind}_{rows}_poses"), |b| {
                b.iter(|| black_box(learned::fit(kind, &q, 7, &r, 3).unwrap()))
            });
            let model = learned::fit(kind, &q, 7, &r, 3).unwrap();
            g.bench_function(format!("predict_{kind}_{rows}_poses"), |b| {
                b.iter(|| black_box(model.predict(black_box(&q[7..14]))))
            });
        }
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
