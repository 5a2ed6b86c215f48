//! Speed of measurement-table I/O on 10⁶ rows of 7 joints with t, temp and sigma (17-digit floats, as
//! the generator writes them). Target: reading the CSV well under 1 s in release mode on the project's
//! 2-core machine.

use criterion::{Criterion, criterion_group, criterion_main};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use sim::measurement_table::{self as mt, MeasurementTable, OptionalColumns, Row};
use std::hint::black_box;

const ROWS: usize = 1_000_000;

fn table() -> MeasurementTable {
    let mut rng = StdRng::seed_from_u64(1);
    let cols = OptionalColumns {
        t: true,
        temp: true,
        sigma: true,
        ..OptionalColumns::NONE
    };
    let mut t = MeasurementTable::with_capacity(7, cols, ROWS);
    let mut q = [0.0; 7];
    for r in 0..ROWS {
        // Three measurements per pose, at its joint values (the table's contract since issue 15).
        if r % 3 == 0 {
            q.iter_mut()
                .for_each(|v| *v = rng.random::<f64>() * 4.0 - 2.0);
        }
        t.push_row(&Row {
            pose: (r / 3) as i64,
            q: &q,
            position: [
                rng.random::<f64>() - 0.5,
                rng.random::<f64>() - 0.5,
                rng.random::<f64>(),
            ],
            t: Some(r as f64 * 0.5),
            temp: Some(20.0 + rng.random::<f64>()),
            sigma: Some(1e-5),
            ..Default::default()
        })
        .unwrap();
    }
    t
}

fn bench(c: &mut Criterion) {
    let dir = std::env::temp_dir().join(format!("robocal_bench_mt_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let csv = dir.join("m.csv");
    let pq = dir.join("m.parquet");
    let t = table();
    mt::write(&csv, &t).unwrap();
    mt::write(&pq, &t).unwrap();
    let mut g = c.benchmark_group("measurement_table_1e6_rows");
    g.sample_size(10);
    g.bench_function("read_csv", |b| {
        b.iter(|| black_box(mt::read(&csv).unwrap().len()))
    });
    g.bench_function("read_parquet", |b| {
        b.iter(|| black_box(mt::read(&pq).unwrap().len()))
    });
    g.bench_function("write_csv", |b| {
        b.iter(|| mt::write(&csv, black_box(&t)).unwrap())
    });
    g.bench_function("write_parquet", |b| {
        b.iter(|| mt::write(&pq, black_box(&t)).unwrap())
    });
    g.finish();
    std::fs::remove_dir_all(&dir).unwrap();
}

criterion_group!(benches, bench);
criterion_main!(benches);
