//! The select floor: which model to adopt. [`diagnose`] names what the kinematic model misses and
//! the cause that explains it; [`auto`] adds the learned correction where it transfers; [`choose`] is
//! the one call the command line and Python make for `--model auto`.
//!
//! It imports the floors below: `validate`, `fit`, `model` and the ground floor.

pub mod auto;
pub mod diagnose;

pub use auto::AutoChoice;

use crate::error::Result;
use crate::model::learned::LearnedKind;
use diagnose::{DiagnoseOptions, Diagnosis, diagnose_with_progress};
use sim::Model;
use sim::measurement_table::MeasurementTable;

/// The model of `--model auto` for `table` (named `name` in messages) on the robot `model`: the
/// diagnosis with `options` (the physical causes that explain the residual and transfer to held-out
/// poses), then the learned kind of `kinds` that still gains on diagnose's held-out poses
/// ([`auto::with_learned`]). `progress` hears what is being fitted. What the caller saves is then
/// fitted on every pose (`crate::validate::fit_and_validate`).
pub fn choose(
    model: &Model,
    table: &MeasurementTable,
    name: &str,
    options: &DiagnoseOptions,
    kinds: &[LearnedKind],
    progress: &mut dyn FnMut(&str),
) -> Result<(Diagnosis, AutoChoice)> {
    let diagnosis = diagnose_with_progress(model, table, name, options, progress)?;
    progress("--model auto: testing the learned residual on diagnose's held-out poses");
    let choice = auto::with_learned(model, table, name, &diagnosis, options, kinds)?;
    Ok((diagnosis, choice))
}
