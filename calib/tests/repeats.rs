//! Repeated measurements of a pose (issue 28, item 2): their scatter is reported as the measured
//! repeatability, the same in memory and streamed, and it estimates the injected noise within its
//! own standard deviation; the fit on every repeat is the fit on the poses' means with `σ/√n`.
//! Seeds are drawn per run and printed (`ROBOCAL_TEST_SEED=N` repeats one).

mod common;

use calib::fit::stream::{StreamOptions, TableSource, calibrate};
use calib::fit::{CalibrationOptions, Dataset, FitRequest, fit};
use common::{Truth, distance_in_sigmas, random_configs, stopping_bound, table_with};
use sim::measurement_table::{MeasurementTable, Row};
use sim::robots;

const NOISE_M: f64 = 1e-5;
const POSES: usize = 300;
const REPEATS: usize = 4;

/// `POSES` random poses of a hidden iiwa 7, each measured `REPEATS` times in a row (one pose id),
/// position noise `NOISE_M` per axis, `sigma` column `NOISE_M`.
fn repeated(seed: u64) -> MeasurementTable {
    let model = robots::load_builtin("iiwa7").unwrap();
    let mut rng = common::rng(seed);
    let truth = Truth::random(&model, false, &mut rng);
    let configs: Vec<Vec<f64>> = random_configs(&model, POSES, &mut rng)
        .into_iter()
        .flat_map(|q| std::iter::repeat_n(q, REPEATS))
        .collect();
    let mut t = table_with(
        &model,
        &truth,
        &configs,
        NOISE_M,
        0.0,
        Some(NOISE_M),
        &mut rng,
    );
    for (r, p) in t.pose.iter_mut().enumerate() {
        *p = (r / REPEATS) as i64;
    }
    t
}

/// Each pose's mean position, `sigma` divided by `√n`.
fn means(t: &MeasurementTable) -> MeasurementTable {
    let mut out = MeasurementTable::new(t.n_joints, t.columns());
    for (pose, rows) in t.rows_by_pose() {
        let n = rows.len() as f64;
        let mut x = [0.0; 3];
        for &r in &rows {
            for (m, v) in x.iter_mut().zip(t.position[r]) {
                *m += v / n;
            }
        }
        out.push_row(&Row {
            pose,
            q: t.q_row(rows[0]),
            position: x,
            sigma: Some(NOISE_M / n.sqrt()),
            ..Row::default()
        })
        .unwrap();
    }
    out
}

#[test]
fn repeats_give_the_noise_as_repeatability_and_the_fit_of_their_means() {
    let seed = common::run_seed("repeats");
    let model = robots::load_builtin("iiwa7").unwrap();
    let table = repeated(seed);
    let options = CalibrationOptions::default();
    let all = fit(
        &model,
        &Dataset::all(&table, "t"),
        &FitRequest::kinematic(&options),
    )
    .unwrap();
    let r = all.report.repeatability.expect("repeats");
    assert_eq!((r.repeats, r.poses), (POSES * (REPEATS - 1), POSES));
    // s² = Σ|x − x̄|² / (3 · repeats) estimates σ² with 3 · repeats degrees of freedom: its
    // standard deviation is σ² √(2 / (3 · repeats)).
    let dof = 3.0 * r.repeats as f64;
    let z = (r.per_axis_m().powi(2) / NOISE_M.powi(2) - 1.0) / (2.0 / dof).sqrt();
    eprintln!(
        "repeatability {:.3} µm per axis against {:.3} µm injected: z = {z:.2}",
        r.per_axis_m() * 1e6,
        NOISE_M * 1e6
    );
    assert!(z.abs() <= 4.0, "z = {z}");
    assert!(all.report.text().contains("repeatability:"));

    // The poses' means with σ/√n: the same minimum, within what the stopping rule allows.
    let averaged = means(&table);
    let mean_fit = fit(
        &model,
        &Dataset::all(&averaged, "means"),
        &FitRequest::kinematic(&options),
    )
    .unwrap();
    assert_eq!(mean_fit.report.repeatability, None);
    let bound = stopping_bound(&all, &options) + stopping_bound(&mean_fit, &options);
    let moved = distance_in_sigmas(&all, &mean_fit);
    eprintln!("fits of every repeat and of the means {moved:.2e} σ apart (bound {bound:.2e})");
    assert!(
        moved <= bound,
        "{moved} σ apart, the stopping rule allows {bound}"
    );

    // Streamed: the same scatter, the repeats of a pose following each other.
    let stream = StreamOptions {
        sample_rows: 400,
        seed,
        ..StreamOptions::default()
    };
    let source = TableSource::new(&table, "t", 250);
    let streamed = calibrate(&model, &source, &options, &stream, &mut |_| {}).unwrap();
    let s = streamed.calibration.report.repeatability.expect("repeats");
    assert_eq!((s.repeats, s.poses), (r.repeats, r.poses));
    assert!((s.rms_m - r.rms_m).abs() <= 1e-12 * r.rms_m, "{s:?} {r:?}");
}
