//! The adopted models refitted on every pose after a selection on part of them (the screening).

#[allow(unused_imports)]
use super::*;

/// The models of a selection made on a subsample (`steps`, kinematic first), each refitted on every
/// pose of `split`, starting at its fit on the subsample (`fits` by name; `kinematic` for the first):
/// `kinematic_every_pose` for the kinematic model (refitted beside the screening), the others here.
/// The refits are independent of each other and run in parallel ([`fit_candidates`]' way: results in
/// the order of `steps`, the first error returned, a caller's cancellation relayed to the fits).
#[allow(clippy::too_many_arguments)]
pub(super) fn confirm_on_every_pose(
    model: &Model,
    split: &Split<'_>,
    steps: &[Step],
    fits: &BTreeMap<String, Option<Evaluated>>,
    kinematic: &Evaluated,
    kinematic_every_pose: Evaluated,
    options: &DiagnoseOptions,
    progress: &mut dyn FnMut(&str),
    health: &mut Health,
) -> Result<Vec<Evaluated>> {
    crate::cancel::checkpoint()?;
    health.merge(&kinematic_every_pose.cal.report.health);
    let starts: Vec<(&ModelSpec, Start<'_>)> = steps[1..]
        .iter()
        .map(|step| {
            let screened = match fits.get(&step.model.name()) {
                Some(Some(c)) => c,
                _ => kinematic,
            };
            let start = if screened.spec == step.model {
                Start::Same(screened)
            } else {
                Start::Cold
            };
            (&step.model, start)
        })
        .collect();
    if !starts.is_empty() {
        progress(&format!(
            "{} (every pose)",
            starts
                .iter()
                .map(|(m, _)| m.name())
                .collect::<Vec<_>>()
                .join("; ")
        ));
    }
    let fitted = evaluate_in_parallel(model, split, &starts, options);
    crate::cancel::checkpoint()?;
    let mut out = Vec::with_capacity(steps.len());
    out.push(kinematic_every_pose);
    for e in fitted {
        let e = e?;
        health.merge(&e.cal.report.health);
        out.push(e);
    }
    Ok(out)
}

/// The figures of `findings` (adopted in the order of the models `all`, kinematic first, each fitted
/// on every pose) from those fits: test RMS before and after, gain, correlation, paired and training
/// `z`. A finding belongs to the first model that holds its cause.
pub(super) fn refigure_findings(findings: &mut [Finding], all: &[Evaluated]) {
    for f in findings.iter_mut() {
        let Some(k) = (1..all.len()).find(|&k| all[k].spec.causes.contains(&f.cause)) else {
            continue;
        };
        let (before, after) = (&all[k - 1], &all[k]);
        f.test_rms_m_before = before.step.test_rms_m;
        f.test_rms_m_after = after.step.test_rms_m;
        f.gain = 1.0 - after.step.test_rms_m / before.step.test_rms_m;
        f.r = explained_correlation(&before.test_err, &after.test_err);
        f.test_z = significance::paired(&before.pose_sq, &after.pose_sq).z;
        f.train_z = train_z(&before.cal, &after.cal);
    }
}
