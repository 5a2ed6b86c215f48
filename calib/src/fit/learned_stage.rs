//! The learned residual correction fitted after the physical model.

use super::report::LearnedStage;
use super::{Calibration, CalibrationOptions, Dataset, observations};
use crate::error::Result;
use crate::fit::problem::Observations;
use crate::model::learned::LearnedKind;
use crate::model::predict::Prediction;
use crate::model::stats::stats_of_errors;
use nalgebra::Vector3;
use sim::Model;

/// Fits the learned correction `kind` to the training residuals of `cal` and records its statistics.
pub(super) fn add_learned(
    model: &Model,
    cal: &mut Calibration,
    kind: LearnedKind,
    train: &Dataset<'_>,
    test: Option<&Dataset<'_>>,
    options: &CalibrationOptions,
) -> Result<()> {
    let at = cal.params.clone();
    let obs = observations(model, train, options, cal.extensions.as_ref(), Some(&at))?;
    // In the first campaign's tracker frame, where the correction lives.
    let learned = match kind {
        LearnedKind::Adjoint => {
            // Identified through the chain, with the registrations refitted alongside.
            let (l, params) =
                crate::model::learned::fit_adjoint(model, &cal.params, &obs, options.learned_seed)?;
            cal.physical = Some(std::mem::replace(&mut cal.params, params));
            l
        }
        _ => {
            let residual: Vec<Vector3<f64>> = Prediction::new(model, &cal.params)
                .reference_errors(&obs)
                .iter()
                .map(|e| -e)
                .collect();
            crate::model::learned::fit(kind, &obs.q, model.nq(), &residual, options.learned_seed)?
        }
    };
    let corrected = Prediction::new(model, &cal.params).with_learned(Some(&learned));
    let stats_with = |o: &Observations| stats_of_errors(&corrected.errors(o), o);
    let test_stats = match test {
        Some(t) if !t.rows.is_empty() => Some(stats_with(&observations(
            model,
            t,
            options,
            cal.extensions.as_ref(),
            Some(&at),
        )?)),
        _ => None,
    };
    let stage = LearnedStage {
        description: learned.describe(),
        active: learned.is_active(),
        train: stats_with(&obs),
        test: test_stats,
    };
    cal.report.learned = Some(stage);
    cal.learned = Some(learned);
    Ok(())
}
