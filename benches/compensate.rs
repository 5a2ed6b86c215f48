//! Speed of `compensate` (issue 26): 1,000 targets of a nominal joint program compensated with the
//! full model of the iiwa 7 (geometry, joint compliance, gear backlash, thermal drift, transmission
//! error and link deflection, and a learned polynomial correction), each with its payload,
//! temperature, time and approach directions. Target: ≤ 20 ms on the project's 2-core machine.
//!
//! The model is fitted once, outside the timing, on a campaign `robocal generate` makes from
//! `scenarios/iiwa7_all.toml` (seed 7, 300 poses); the program is 1,000 other poses of the same
//! scenario (seed 8).

use calib::fit::{CalibrationOptions, Dataset, FitRequest, fit};
use calib::model::ModelSpec;
use calib::model::compensate::{Targets, compensate_table};
use calib::model::file::CalibratedModel;
use calib::model::predict::Predictor;
use calib::model::robot::Robot;
use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;
use std::path::{Path, PathBuf};

/// The full model of the bench.
const MODEL: &str = "kinematic+joint_compliance+gear_backlash+thermal_drift+transmission_error+link_deflection+learned:poly";

fn campaign(out: &Path, seed: u64, poses: usize) -> sim::measurement_table::MeasurementTable {
    let scenario = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenarios/iiwa7_all.toml");
    let options = robocal::cli::generate::Options {
        seed: Some(seed),
        poses: Some(poses),
        noise: None,
    };
    robocal::cli::generate::generate(&scenario, out, &options, &|_| {}).expect("generate");
    sim::measurement_table::read(&out.join("measurements.parquet")).expect("read")
}

fn bench(c: &mut Criterion) {
    let dir = std::env::temp_dir().join(format!("robocal_bench_compensate_{}", std::process::id()));
    let train = campaign(&dir.join("train"), 7, 300);
    let program = campaign(&dir.join("program"), 8, 1000);
    let robot = Robot::load("iiwa7", &sim::ChainSpec::default()).expect("robot");
    let spec = ModelSpec::parse(MODEL).expect("model");
    let cal = fit(
        &robot.model,
        &Dataset::all(&train, "bench"),
        &FitRequest::new(&spec, &CalibrationOptions::default()),
    )
    .expect("fit");
    let file = CalibratedModel::new(&robot, &cal);
    let predictor = Predictor::from_file(&file).expect("predictor");
    // Every target reached, or the bench measures failures.
    let check = compensate_table(&predictor, &program, "program", Targets::Program).unwrap();
    assert_eq!(check.failures().count(), 0, "every target reached");
    let mut g = c.benchmark_group("compensate");
    g.sample_size(20);
    g.bench_function("iiwa7_full_model_1000_targets", |b| {
        b.iter(|| {
            black_box(
                compensate_table(&predictor, black_box(&program), "program", Targets::Program)
                    .unwrap(),
            )
        })
    });
    g.finish();
    let _ = std::fs::remove_dir_all(dir);
}

criterion_group!(benches, bench);
criterion_main!(benches);
