//! Speed of the hot kinematics on the iiwa 7. Targets (issue 2): flange pose ≤ 150 ns, flange pose plus
//! position Jacobian ≤ 300 ns on the project's 2-core machine.

use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::{Matrix3xX, Vector3};
use sim::{Data, forward_kinematics, kinematics::point_jacobian, robots};
use std::hint::black_box;

fn configs() -> Vec<[f64; 7]> {
    (0..64)
        .map(|k| {
            std::array::from_fn(|i| {
                ((k as f64 + 1.0) * (0.618034 + 0.414214 * i as f64)).fract() * 4.0 - 2.0
            })
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let model = robots::load_builtin("iiwa7").unwrap();
    let mut data = Data::new(&model);
    let qs = configs();
    let mut k = 0;
    c.bench_function("iiwa7/flange_pose", |b| {
        b.iter(|| {
            k = (k + 1) % qs.len();
            forward_kinematics(&model, &mut data, black_box(&qs[k]));
            black_box(data.flange.translation.x)
        })
    });
    let mut jac = Matrix3xX::zeros(7);
    let tool = Vector3::new(0.0, 0.0, 0.05);
    c.bench_function("iiwa7/flange_pose_and_position_jacobian", |b| {
        b.iter(|| {
            k = (k + 1) % qs.len();
            forward_kinematics(&model, &mut data, black_box(&qs[k]));
            black_box(point_jacobian(&model, &data, &tool, &mut jac))
        })
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
