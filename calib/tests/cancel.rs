//! Cooperative cancellation (`calib::cancel`): a check that says stop ends a calibration and a
//! diagnosis with `CalibError::Cancelled` at the next checkpoint; a check that never does changes
//! nothing (the same report, bit for bit).

use calib::CalibError;
use calib::cancel::with_check;
use calib::fit::{CalibrationOptions, Dataset, FitRequest, fit};
use calib::select::diagnose::{DiagnoseOptions, diagnose};
use sim::measurement_table::{MeasurementTable, OptionalColumns, Row};
use sim::{Data, flange_pose, robots};
use std::cell::Cell;
use std::rc::Rc;

/// 60 poses of a UR5 whose joint 2 sits 0.5 mm off its nominal axis, with a little noise.
fn table() -> (sim::Model, MeasurementTable) {
    let model = robots::load_builtin("ur5").unwrap();
    let mut origin = model.joints()[1].origin;
    origin.translation.vector.x += 5e-4;
    let real = model.with_joint_origin(1, origin).unwrap();
    let mut data = Data::new(&real);
    let mut t = MeasurementTable::new(6, OptionalColumns::NONE);
    for k in 0..60 {
        let q: Vec<f64> = (0..6)
            .map(|j| ((k * 7 + j * 3) as f64 * 0.618).sin() * 2.0)
            .collect();
        let p = flange_pose(&real, &mut data, &q) * nalgebra::Point3::new(0.0, 0.03, 0.05);
        let wiggle = 1e-5 * ((k as f64) * 1.7).sin();
        t.push_row(&Row {
            pose: k,
            q: &q,
            position: [p.x + 1.0 + wiggle, p.y - wiggle, p.z],
            ..Row::default()
        })
        .unwrap();
    }
    (model, t)
}

/// A check that says stop at its `n`-th call, and the count of its calls.
fn stop_at(n: usize) -> (impl Fn() -> bool + 'static, Rc<Cell<usize>>) {
    let calls = Rc::new(Cell::new(0));
    let c = calls.clone();
    (
        move || {
            c.set(c.get() + 1);
            c.get() >= n
        },
        calls,
    )
}

#[test]
fn a_stop_ends_the_calibration_at_the_next_checkpoint() {
    let (model, t) = table();
    let data = Dataset::all(&t, "ur5");
    let options = CalibrationOptions::default();
    let plain = fit(&model, &data, &FitRequest::kinematic(&options)).unwrap();
    // Never stopping: the same calibration, and the loops did poll.
    let (never, calls) = stop_at(usize::MAX);
    let polled = with_check(never, || {
        fit(&model, &data, &FitRequest::kinematic(&options))
    })
    .unwrap();
    assert_eq!(
        serde_json::to_string(&polled.report).unwrap(),
        serde_json::to_string(&plain.report).unwrap()
    );
    let total = calls.get();
    assert!(total >= 4, "{total} checks");
    // Stopping at each of those checks in turn: Cancelled, with no further call to the check.
    for n in 1..=total {
        let (check, calls) = stop_at(n);
        let r = with_check(check, || {
            fit(&model, &data, &FitRequest::kinematic(&options))
        });
        assert!(matches!(r, Err(CalibError::Cancelled)), "stop at check {n}");
        assert_eq!(calls.get(), n);
    }
}

#[test]
fn a_stop_ends_the_diagnosis() {
    let (model, t) = table();
    let options = DiagnoseOptions::default();
    let (check, calls) = stop_at(3);
    let r = with_check(check, || diagnose(&model, &t, "ur5", &options));
    assert!(matches!(r, Err(CalibError::Cancelled)));
    assert_eq!(calls.get(), 3);
}

/// A diagnosis screened on a subsample refits the kinematic model on every pose on a thread of its
/// own beside the screening: a stop at any check ends it with `Cancelled` (that thread stopped and
/// joined: the call returns), and a check that never stops changes nothing. (While rounds run on
/// rayon's threads the calling thread polls its check every 20 ms, so how many checks a diagnosis
/// makes depends on timing: a stop at a late check may come after the last one, and the diagnosis
/// then ends as without it.)
#[test]
fn a_stop_ends_a_screened_diagnosis_and_its_every_pose_refit() {
    let (model, t) = table();
    let options = DiagnoseOptions {
        screen_poses: 30,
        ..DiagnoseOptions::default()
    };
    let plain = diagnose(&model, &t, "ur5", &options).unwrap();
    assert!(plain.screening.is_some(), "screened on a subsample");
    let json = serde_json::to_string(&plain).unwrap();
    let (never, calls) = stop_at(usize::MAX);
    let polled = with_check(never, || diagnose(&model, &t, "ur5", &options)).unwrap();
    assert_eq!(serde_json::to_string(&polled).unwrap(), json);
    let total = calls.get();
    assert!(total >= 8, "{total} checks");
    let mut cancelled = 0;
    for k in 0..8 {
        let n = 1 + k * (total - 1) / 8;
        let (check, calls) = stop_at(n);
        match with_check(check, || diagnose(&model, &t, "ur5", &options)) {
            Err(CalibError::Cancelled) => {
                cancelled += 1;
                assert_eq!(calls.get(), n, "stopped at check {n}, asked again after");
            }
            Ok(d) => assert_eq!(
                serde_json::to_string(&d).unwrap(),
                json,
                "stop at check {n}"
            ),
            Err(e) => panic!("stop at check {n}: {e}"),
        }
    }
    assert!(cancelled >= 4, "{cancelled} of 8 stops ended the diagnosis");
}
