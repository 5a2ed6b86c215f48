//! Does an adopted cause transfer to poses unlike the ones it was fitted on?
//!
//! A cause is adopted because it predicts diagnose's held-out poses better. Those poses are drawn
//! from the same distribution as the training poses: on data that lie on a low-dimensional manifold
//! (a grid at one flange orientation) a term that only fits the manifold passes that test. The
//! transfer test holds out **regions** of the configuration space instead
//! ([`crate::validate::validate_by_region`], the training poses clustered into
//! [`DiagnoseOptions::regions`] regions): the final model, and the final model without the cause,
//! each fitted on all regions but one and predicting that one. A cause whose removal does not make
//! the held-out regions worse (RMS) does not transfer: it is rejected, as a cause whose parameters
//! are impossible is, and the selection runs again without it.

#[allow(unused_imports)]
use super::*;
use crate::validate::gauss_newton::region_rms_gauss_newton;
use crate::validate::validate_by_region;

/// The leave-one-region-out RMS (m) of `spec` on the training poses of `split`: from `start` (its fit
/// on those poses) by Gauss–Newton steps when it has one ([`region_rms_gauss_newton`], which agrees
/// with the regions' full fits to 10⁻⁵ of the RMS at a fraction of their cost), else by the full fits.
fn region_rms(
    model: &Model,
    split: &Split<'_>,
    spec: &ModelSpec,
    options: &DiagnoseOptions,
    start: Option<&Calibration>,
) -> Result<f64> {
    let request = FitRequest::new(spec, &options.calibration);
    if let Some(all) = start
        && let Some(rms) = region_rms_gauss_newton(
            model,
            &split.train,
            &request,
            options.regions,
            options.seed,
            all,
        )?
    {
        return Ok(rms);
    }
    let r = validate_by_region(
        model,
        &split.train,
        &request,
        options.regions,
        options.seed,
        start,
    )?;
    Ok(r.final_stats().rms_m)
}

/// What the transfer test knows between the selection's reruns: the models fitted on the training
/// poses (by name, to start the regions' fits at), and the leave-one-region-out RMS of every model
/// tested (`None`: too few poses to hold out regions).
pub(super) struct TransferMemo<'m> {
    pub(super) fits: &'m std::collections::BTreeMap<String, Option<Evaluated>>,
    pub(super) kinematic: &'m Evaluated,
    pub(super) rms: &'m mut std::collections::BTreeMap<String, Option<f64>>,
}

impl TransferMemo<'_> {
    /// Computes the leave-one-region-out RMS of every model of `specs` not yet known, in parallel,
    /// each region's fit started at the model's fit on the training poses when the selection made
    /// one.
    fn compute(
        &mut self,
        model: &Model,
        split: &Split<'_>,
        specs: &[ModelSpec],
        options: &DiagnoseOptions,
    ) -> Result<()> {
        let todo: Vec<&ModelSpec> = specs
            .iter()
            .filter(|s| !self.rms.contains_key(&s.name()))
            .collect();
        let (fits, kinematic) = (self.fits, self.kinematic);
        let results: Vec<Result<Option<f64>>> = crate::cancel::relayed(|relay| {
            todo.par_iter()
                .map(|spec| {
                    relay.run(|| {
                        let start = if spec.causes.is_empty() && spec.learned.is_none() {
                            Some(&kinematic.cal)
                        } else {
                            fits.get(&spec.name())
                                .and_then(|f| f.as_ref())
                                .map(|e| &e.cal)
                        };
                        match region_rms(model, split, spec, options, start) {
                            Ok(v) => Ok(Some(v)),
                            // Too few poses to hold out regions: the test cannot be made.
                            Err(CalibError::BadValue { .. } | CalibError::TooFewPoses { .. }) => {
                                Ok(None)
                            }
                            Err(e) => Err(e),
                        }
                    })
                })
                .collect()
        });
        for (spec, r) in todo.iter().zip(results) {
            self.rms.insert(spec.name(), r?);
        }
        Ok(())
    }
}

/// The first adopted cause of `sel` that does not transfer to held-out regions, as a rejection;
/// `None` when every one does, when there are none, or with `options.regions` < 2.
pub(super) fn not_transferring(
    model: &Model,
    split: &Split<'_>,
    sel: &Selection,
    options: &DiagnoseOptions,
    memo: &mut TransferMemo<'_>,
) -> Result<Option<Rejected>> {
    if options.regions < 2 || sel.findings.is_empty() {
        return Ok(None);
    }
    // A cause adopted with its companion (deflection with compliance) is tested with it: the two
    // stand for one bending, and without the companion the cause takes it up alone. The companion
    // itself is not tested on its own.
    let companion_of = |cause: Cause| {
        sel.companions
            .iter()
            .find(|(c, _)| *c == cause)
            .map(|(_, comp)| *comp)
    };
    let is_companion = |cause: Cause| sel.companions.iter().any(|(_, comp)| *comp == cause);
    let reduced = |cause: Cause| {
        let r = sel.current.spec.without(cause);
        match companion_of(cause) {
            Some(comp) => r.without(comp),
            None => r,
        }
    };
    let tested: Vec<&Finding> = sel
        .findings
        .iter()
        .filter(|f| !is_companion(f.cause))
        .collect();
    let mut specs = vec![sel.current.spec.clone()];
    specs.extend(tested.iter().map(|f| reduced(f.cause)));
    memo.compute(model, split, &specs, options)?;
    // Too few poses to hold out regions: the test cannot be made, the selection stands.
    let Some(with) = memo.rms[&sel.current.spec.name()] else {
        return Ok(None);
    };
    for f in tested {
        let Some(without) = memo.rms[&reduced(f.cause).name()] else {
            continue;
        };
        if with < without {
            continue;
        }
        let regional = if without > 0.0 {
            1.0 - with / without
        } else {
            0.0
        };
        return Ok(Some(Rejected {
            cause: f.cause,
            joints: Vec::new(),
            reason: format!(
                "a gain that does not transfer to unseen regions of the configuration space \
                 ({:+.1} % on {} held-out regions)",
                100.0 * regional,
                options.regions
            ),
            gain: f.gain,
            test_z: f.test_z,
            parameters: Vec::new(),
            evidence: format!(
                "{} would gain {:.0} % on the held-out poses (z = {:.1}), but fitted without each of \
                 {} regions of the configuration space it predicts them no better ({:.1} µm RMS with \
                 it, {:.1} µm without): not adopted, it fits where the poses lie, not how the robot \
                 errs",
                f.cause,
                100.0 * f.gain,
                f.test_z,
                options.regions,
                with * 1e6,
                without * 1e6
            ),
        }));
    }
    Ok(None)
}
