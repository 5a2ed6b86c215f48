//! The streamed diagnosis ([`calib::select::diagnose::stream`]): a seeded sample of whole poses
//! diagnosed as in memory, and the rest of the file predicted by the models fitted on the sample,
//! against the same computations done in memory. Seeds are drawn per run and printed
//! (`ROBOCAL_TEST_SEED=N` repeats one).

mod common;

use calib::fit::stream::TableSource;
use calib::fit::{Dataset, FitRequest, Part, fit};
use calib::model::spec::ModelSpec;
use calib::select::diagnose::stream::{diagnose_streamed, in_sample};
use calib::select::diagnose::{DiagnoseOptions, diagnose};
use calib::validate::{HeldOutStats, held_out_errors};
use sim::measurement_table::MeasurementTable;

/// `poses` poses of the iiwa 7 with geometric errors, compliance at joints 2 and 4 and backlash at
/// joints 1 and 3, each row written twice (a pose measured twice, the repeats consecutive).
fn data(poses: usize, seed: u64) -> (sim::Model, MeasurementTable) {
    let (model, once) = common::simulate_iiwa7(common::COMPLIANCE_AND_BACKLASH, seed, poses);
    let twice: Vec<usize> = (0..once.len()).flat_map(|r| [r, r]).collect();
    (model, once.select_rows(&twice))
}

#[test]
fn the_streamed_diagnosis_is_the_in_memory_diagnosis_of_its_sample_and_predicts_the_rest() {
    let seed = common::run_seed("diagnose-stream");
    let (model, table) = data(1_600, seed);
    let rows = table.len();
    let options = DiagnoseOptions {
        seed,
        ..DiagnoseOptions::default()
    };
    let sample_rows = 1_600;
    let source = TableSource::new(&table, "t", 500);
    let s = diagnose_streamed(&model, &source, &options, sample_rows, &mut |_| {}).unwrap();
    assert_eq!(s.rows, rows);
    assert_eq!(s.passes, 3);
    let rest = s.rest.as_ref().expect("the sample is half the file");
    // Whole poses: every pose has two rows, in the sample or in the rest.
    assert_eq!(s.sample_rows + rest.rows, rows);
    assert_eq!(s.sample_rows % 2, 0, "a pose split by the sample");
    assert_eq!(
        rest.kinematic.n_poses * 2,
        rest.rows,
        "a pose split by the sample"
    );
    // About the rows asked for: 800 of 1,600 poses, binomial (σ = 20 poses), within 5σ.
    let sampled_poses = s.sample_rows / 2;
    assert!(
        sampled_poses.abs_diff(800) <= 100,
        "{sampled_poses} poses sampled for 800"
    );
    // The same computations in memory, on the sample the hash draws.
    let fraction = sample_rows as f64 / rows as f64;
    let (inside, outside): (Vec<usize>, Vec<usize>) = (0..rows).partition(|&r| {
        let (c, p) = table.pose_key(r);
        in_sample(seed, fraction, c, p)
    });
    assert_eq!(inside.len(), s.sample_rows);
    let sample = table.select_rows(&inside);
    let name = format!("t (a sample of {} rows)", sample.len());
    let memory = diagnose(&model, &sample, &name, &options).unwrap();
    assert_eq!(memory.model, s.diagnosis.model);
    let json = |d: &calib::select::diagnose::Diagnosis| serde_json::to_value(d).unwrap();
    assert_eq!(json(&memory), json(&s.diagnosis), "the sample's diagnosis");
    eprintln!("diagnosis of the sample: {}", memory.model.name());
    assert!(
        memory.model != ModelSpec::kinematic(),
        "the sample shows compliance and backlash"
    );
    let all = Dataset::all(&sample, &name);
    let calibration = &options.calibration;
    let kinematic = fit(
        &model,
        &all,
        &FitRequest::new(&ModelSpec::kinematic(), calibration),
    )
    .unwrap();
    let adopted = fit(&model, &all, &FitRequest::new(&memory.model, calibration)).unwrap();
    let test = Dataset::new(&table, outside.clone(), "t", Part::Test);
    let keys: Vec<(i64, i64)> = outside.iter().map(|&r| table.pose_key(r)).collect();
    let (nominal, k, _) = held_out_errors(&model, &kinematic, &test, calibration).unwrap();
    let (_, a, learned) = held_out_errors(&model, &adopted, &test, calibration).unwrap();
    let expected = [
        ("nominal", HeldOutStats::of(&nominal, &keys), &rest.nominal),
        ("kinematic", HeldOutStats::of(&k, &keys), &rest.kinematic),
        (
            "adopted",
            HeldOutStats::of(learned.as_ref().unwrap_or(&a), &keys),
            &rest.adopted,
        ),
    ];
    for (what, m, st) in expected {
        eprintln!("{what}: in memory {m:?}\n  streamed {st:?}");
        assert_eq!((m.n_rows, m.n_poses), (st.n_rows, st.n_poses), "{what}");
        // The same errors, summed in another order (runs of rows against a map of poses).
        for (x, y) in [
            (m.rms_m, st.rms_m),
            (m.mean_m, st.mean_m),
            (m.max_m, st.max_m),
            (m.iso_mean_m, st.iso_mean_m),
        ] {
            assert!((x - y).abs() <= 1e-12 * y.abs(), "{what}: {x} against {y}");
        }
    }
    assert!(
        rest.gain > 0.5,
        "compliance and backlash explain most of the kinematic model's error: gain {}",
        rest.gain
    );
}
