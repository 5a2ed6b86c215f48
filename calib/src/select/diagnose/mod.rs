//! Diagnosis: what the kinematic model still gets wrong, which physical cause explains it, and how much
//! the extended model gains on held-out poses.
//!
//! 1. The poses are split into training and test sets ([`split_by_pose`], seeded); every decision is
//!    checked on the test poses, which no fit has seen.
//! 2. The current model (first the kinematic one) is extended by each candidate cause in turn
//!    ([`crate::model::extensions::Cause`]) and refitted on the training poses. A candidate is **significant**
//!    when both (a) its training `χ²` drops by more than its added identifiable parameters explain
//!    (`Δχ² / (χ²₁/dof₁)` against `χ²` with `Δrank` degrees of freedom, as a normal `z`,
//!    [`significance::chi2_to_z`]) at level `α`, and (b) it predicts the test poses better (a paired
//!    test of the per-pose squared errors, [`significance::paired`]) at level `α_held_out`, each
//!    divided by the number of candidates (Bonferroni), (c) it lowers the test RMS by at least [`DiagnoseOptions::min_gain`],
//!    and (d) it gains more on the test poses than an error periodic in one joint's angle would
//!    ([`unexplained::probes`]): a cause that is really there explains its residual better than a
//!    generic term, and structure that a generic term explains better is no known cause's.
//! 3. The significant candidate with the largest test `z` is adopted; the loop repeats with the
//!    remaining causes until none is significant.
//! 4. The joints of a finding are those whose parameter of that cause is determined on its own and
//!    differs from zero by more than [`DiagnoseOptions::joint_z`] standard deviations.
//!    A parameter named there must also lie within its cause's plausibility bounds
//!    ([`crate::model::extensions::CauseModel::implausible`]): a cause with an implausible named
//!    parameter at some joints is refitted without them and without its insignificant joints
//!    (`cause@kept`, `selection::narrowed`) and the selection runs again; a cause left with nothing
//!    plausible is rejected (reported as evidence of another error).
//! 5. Every adopted cause must also transfer to **unseen regions** of the configuration space
//!    ([`transfer`]): the final model fitted without each region in turn must predict it better
//!    than the same model without the cause. One that does not is rejected, and the selection runs
//!    again without it.
//! 6. What is left is examined for structure no known cause explains ([`unexplained`]): harmonics of
//!    each joint angle and the learned residual models, again judged on the test poses.
//!
//! The noise floor ([`noise_floor`]) comes from repeated poses when the data have enough of them, else
//! from the `sigma` column or the tracker noise model.

pub mod campaigns;
mod confirm;
mod diagnosis;
mod evaluate;
mod evidence;
pub mod noise_floor;
mod options;
mod plots;
pub mod report;
pub mod screening;
mod selection;
pub mod significance;
pub mod stream;
mod transfer;
pub mod unexplained;

use confirm::*;
pub use diagnosis::{
    Diagnosis, Finding, FoundParameter, JointSelection, NotTried, Rejected, Rival, Step, Trial,
};
use evaluate::*;
use evidence::*;
pub use evidence::{MAX_NULL_SHARE, TIE_Z};
pub use options::DiagnoseOptions;
use plots::*;
use selection::*;

use crate::error::{CalibError, Result};
use crate::fit::{Calibration, CalibrationOptions, Dataset, FitRequest, Part, fit, observations};
use crate::health::Health;
use crate::model::extensions::{Cause, Regressors, Term, joint_words};
use crate::model::learned::LearnedKind;
use crate::model::predict::Prediction;
use crate::model::spec::ModelSpec;
use crate::model::stats::split_by_pose;
use crate::units::Unit;
use nalgebra::Vector3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sim::Model;
use sim::measurement_table::MeasurementTable;
use std::collections::BTreeMap;
use std::sync::OnceLock;

/// Diagnoses `table` (all rows; `name` names it in messages) for `model`.
///
/// Errors: input the calibration refuses (too few poses, a bad `sigma`), or too few poses to hold out
/// a test set.
pub fn diagnose(
    model: &Model,
    table: &MeasurementTable,
    name: &str,
    options: &DiagnoseOptions,
) -> Result<Diagnosis> {
    diagnose_with_progress(model, table, name, options, &mut |_| {})
}

/// [`diagnose`], calling `progress` with a short line before each fit.
pub fn diagnose_with_progress(
    model: &Model,
    table: &MeasurementTable,
    name: &str,
    options: &DiagnoseOptions,
    progress: &mut dyn FnMut(&str),
) -> Result<Diagnosis> {
    let (train_rows, test_rows) = split_by_pose(table, options.test_fraction, options.seed);
    if test_rows.is_empty() {
        return Err(CalibError::BadValue {
            context: name.to_string(),
            field: "pose".into(),
            value: format!("{} poses", table.rows_by_pose().len()),
            problem: "diagnose needs poses to hold out: give more poses or a larger test fraction"
                .into(),
        });
    }
    let split = Split {
        test_pose: campaigns::pose_ids(table, &test_rows),
        train: Dataset::new(table, train_rows, name, Part::Training),
        test: Dataset::new(table, test_rows, name, Part::Test),
    };
    let mut usable: Vec<Cause> = Vec::new();
    let mut not_tried: Vec<NotTried> = Vec::new();
    for &c in &options.candidates {
        match c.model().usable(model, table) {
            Ok(()) => usable.push(c),
            Err(reason) => not_tried.push(NotTried { cause: c, reason }),
        }
    }
    // With many poses the candidates are screened on a subsample ([`screening`]).
    let sub = screening::subsample(&split, options.screen_poses, options.seed);
    let screen = sub.as_ref().unwrap_or(&split);
    progress("kinematic");
    let kinematic = evaluate(model, screen, &ModelSpec::kinematic(), options, Start::Cold)?;
    let mut health = kinematic.cal.report.health;
    let mut trials = Vec::new();
    // Forward selection, then the adopted causes checked in their joint fit: one whose named
    // parameters are impossible there (or that names nothing) is rejected, and the selection runs
    // again without it (it may have stood in for another cause), until every adopted cause holds.
    let mut rejected: Vec<Rejected> = Vec::new();
    // Joint selection within a cause: a cause whose final fit names an implausible parameter at some
    // joints is limited to its other named joints ([`narrowed`]) and the selection runs again.
    let mut limits: BTreeMap<Cause, Vec<usize>> = BTreeMap::new();
    let mut joint_selection: Vec<JointSelection> = Vec::new();
    let mut round = 0;
    let mut fits = std::collections::BTreeMap::new();
    let mut rival_probes = std::collections::BTreeMap::new();
    let mut transfer_rms = std::collections::BTreeMap::new();
    // Screened on a subsample: the kinematic model (the first step of every selection) is refitted
    // on every pose on a thread of its own while the candidates are screened, where the rounds leave
    // cores idle (a round waits for its slowest candidate). A selection that fails or is cancelled
    // stops it at its next checkpoint.
    let every_pose_relay = crate::cancel::Relay::new();
    let (selection, kinematic_every_pose) = std::thread::scope(|scope| {
        let every_pose = sub.as_ref().map(|_| {
            progress("kinematic (every pose, beside the screening)");
            let (split, kinematic, relay) = (&split, &kinematic, &every_pose_relay);
            scope.spawn(move || {
                relay.run(|| {
                    evaluate(
                        model,
                        split,
                        &ModelSpec::kinematic(),
                        options,
                        Start::Same(kinematic),
                    )
                })
            })
        });
        let selection = (|| -> Result<Selection> {
            loop {
                let candidates: Vec<Cause> = usable
                    .iter()
                    .copied()
                    .filter(|c| rejected.iter().all(|r| r.cause != *c))
                    .collect();
                let sel = select(
                    model,
                    screen,
                    kinematic.clone(),
                    &candidates,
                    &limits,
                    options,
                    &mut Bookkeeping {
                        round: &mut round,
                        trials: &mut trials,
                        health: &mut health,
                        progress,
                        fits: &mut fits,
                        rivals: &mut rival_probes,
                    },
                )?;
                match invalid_finding(&sel, options) {
                    None => match transfer::not_transferring(
                        model,
                        screen,
                        &sel,
                        options,
                        &mut transfer::TransferMemo {
                            fits: &fits,
                            kinematic: &kinematic,
                            rms: &mut transfer_rms,
                        },
                    )? {
                        None => return Ok(sel),
                        Some(r) => rejected.push(r),
                    },
                    Some(r) => match narrowed(&sel, &r, options) {
                        Some(js) => {
                            limits.insert(js.cause, js.kept.iter().map(|j| j - 1).collect());
                            joint_selection.push(js);
                        }
                        None => rejected.push(r),
                    },
                }
            }
        })();
        if selection.is_err() {
            every_pose_relay.stop();
        }
        let kinematic_every_pose = every_pose.map(|h| match h.join() {
            Ok(fit) => fit,
            Err(panic) => std::panic::resume_unwind(panic),
        });
        (selection, kinematic_every_pose)
    });
    let Selection {
        current,
        steps,
        mut findings,
        companions,
    } = selection?;
    // Screened on a subsample: the adopted models refitted on every pose, and the findings' figures
    // from those fits.
    let (current, steps, kinematic) = match &sub {
        None => (current, steps, kinematic),
        Some(_) => {
            let fits_all = confirm_on_every_pose(
                model,
                &split,
                &steps,
                &fits,
                &kinematic,
                kinematic_every_pose.expect("fitted beside the screening")?,
                options,
                progress,
                &mut health,
            )?;
            refigure_findings(&mut findings, &fits_all);
            let steps = fits_all.iter().map(|e| e.step.clone()).collect();
            let mut fits_all = fits_all.into_iter();
            let kinematic = fits_all.next().expect("the kinematic step");
            let current = fits_all.last().unwrap_or_else(|| kinematic.clone());
            (current, steps, kinematic)
        }
    };
    let mut plots = report::PlotData {
        test_errors_kinematic_m: kinematic.test_err.iter().map(|e| e.norm()).collect(),
        ..Default::default()
    };
    drop(kinematic);
    // Joints, values and evidence from the final model, where every adopted cause is fitted jointly
    // (a cause adopted early may have taken up part of a later one before that was in the model).
    for f in &mut findings {
        let cause = f.cause;
        let params = cause_parameters(&current.cal, cause);
        let z_of = |p: &FoundParameter| {
            if p.sigma > 0.0 {
                (p.value / p.sigma).abs()
            } else {
                0.0
            }
        };
        let named: Vec<FoundParameter> = params
            .iter()
            .filter(|(p, term, alone)| {
                matches!(term, Term::JointAngle { .. } | Term::Bend { .. })
                    && *alone
                    && z_of(p) > options.joint_z
            })
            .map(|(p, _, _)| p.clone())
            .collect();
        f.joints = joints_of(&named);
        f.fitted_joints = current
            .spec
            .joints_of(cause)
            .map(|js| js.iter().map(|j| j + 1).collect());
        let growth = params
            .iter()
            .any(|(p, term, alone)| *term == Term::Growth && *alone && z_of(p) > options.joint_z);
        f.parameters = params.into_iter().map(|(p, _, _)| p).collect();
        f.evidence = evidence(
            cause,
            &f.joints,
            &f.parameters,
            f.r,
            growth,
            f.rival.as_ref(),
            options.joint_z,
        );
        plots.regressors.extend(finding_plots(
            model, &split, &current, cause, &f.joints, growth,
        ));
    }
    // Of a cause and its companion adopted together, one that names no joint on its own is not named
    // (the companion first: when both name none, the cause stays as adopted).
    for &(cause, comp) in &companions {
        let joints_of_cause = |c: Cause| {
            findings
                .iter()
                .find(|f| f.cause == c)
                .map(|f| f.joints.is_empty())
        };
        if joints_of_cause(comp) == Some(true) {
            findings.retain(|f| f.cause != comp);
        } else if joints_of_cause(cause) == Some(true) {
            // Named without a joint only when the final model without it is worse on both tests.
            let reduced = current.spec.without(cause);
            progress(&reduced.name());
            let without = match (fits.get(&reduced.name()), &sub) {
                (Some(Some(c)), None) => c.clone(),
                (Some(Some(c)), Some(_)) => {
                    evaluate(model, &split, &reduced, options, Start::Same(c))?
                }
                _ => evaluate(model, &split, &reduced, options, Start::Cold)?,
            };
            let tz = significance::paired(&without.pose_sq, &current.pose_sq).z;
            let trz = train_z(&without.cal, &current.cal);
            if tz > significance::normal_upper_quantile(options.held_out_alpha)
                && trz > significance::normal_upper_quantile(options.alpha)
            {
                continue;
            }
            let why_not = format!(
                "not {cause}, fitted with it: none of its parameters differs from zero by more \
                 than {} standard deviations on its own, and the final model without it predicts \
                 the held-out poses as well (z = {tz:.1}, training z = {trz:.1}), so only {comp} \
                 is named",
                options.joint_z
            );
            let gain = findings
                .iter()
                .find(|f| f.cause == cause)
                .map_or(0.0, |f| f.gain);
            findings.retain(|f| f.cause != cause);
            if let Some(f) = findings.iter_mut().find(|f| f.cause == comp) {
                f.rival = Some(Rival {
                    name: cause.to_string(),
                    gain,
                    why_not,
                });
                f.evidence = evidence(
                    comp,
                    &f.joints,
                    &f.parameters,
                    f.r,
                    false,
                    f.rival.as_ref(),
                    options.joint_z,
                );
            }
        }
    }
    drop(fits);
    let (noise_floor_m, noise_floor_source) = match options.noise_floor_m {
        Some(v) => (v, "given (--noise-floor)".to_string()),
        None => noise_floor::estimate(table, &split.test.rows, &options.calibration.noise),
    };
    crate::cancel::checkpoint()?;
    progress("unexplained structure");
    let unexplained = unexplained::analyse(
        model,
        &split,
        &current,
        noise_floor_m,
        options,
        rejected,
        &joint_selection,
    )?;
    plots.test_errors_final_m = current.test_err.iter().map(|e| e.norm()).collect();
    if let Some(j) = unexplained.correlates_with.as_ref().and_then(|p| p.joint) {
        plots.unexplained = Some(report::RegressorPlot {
            file: format!("unexplained_joint{j}"),
            title: format!("unexplained: residual against the angle of joint {j}"),
            x_label: format!("q{j} (rad)"),
            y_label: format!("residual as joint {j} angle (µrad)"),
            x: split
                .test
                .rows
                .iter()
                .map(|&r| table.q_row(r)[j - 1])
                .collect(),
            before: as_joint_angle_urad(model, &split, &current, &current.test_err, j - 1),
            after: Vec::new(),
            slope: 0.0,
            curve: Vec::new(),
        });
    }
    Ok(Diagnosis {
        robot: model.name().to_string(),
        n_train: split
            .train
            .rows
            .iter()
            .map(|&r| table.pose_key(r))
            .collect::<std::collections::BTreeSet<_>>()
            .len(),
        n_test: split
            .test_pose
            .iter()
            .collect::<std::collections::BTreeSet<_>>()
            .len(),
        noise_floor_m,
        noise_floor_source,
        steps,
        findings,
        unexplained,
        model: current.spec.clone(),
        trials,
        joint_selection,
        not_tried,
        campaigns: campaigns::report(&split, &current, options.alpha),
        screening: sub.as_ref().map(screening::record),
        alpha: options.alpha,
        seed: options.seed,
        health,
        plots,
    })
}
