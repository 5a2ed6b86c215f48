//! Forward selection over the candidate causes, with the companion rule, and the final judgement of a
//! selection's findings.

#[allow(unused_imports)]
use super::*;

/// What a forward selection ends with.
pub(super) struct Selection {
    /// The final model.
    pub(super) current: Evaluated,
    /// The models fitted, kinematic first.
    pub(super) steps: Vec<Step>,
    /// The causes adopted, in order (joints and evidence filled later, from the final model).
    pub(super) findings: Vec<Finding>,
    /// Pairs `(cause, its companion)` adopted together ([`companion`]): of the two, one that names no
    /// joint is not named.
    pub(super) companions: Vec<(Cause, Cause)>,
}

/// The cause fitted alongside `cause` when it is tried and the other is not in the model yet:
/// joint compliance with link deflection. Bending of a joint about an axis that is the next joint's
/// axis line is that joint's compliance, so link deflection leaves those axes to the compliance
/// ([`crate::model::extensions::link_deflection::modelled_axes`]); fitted without it, a real bending about
/// such an axis makes the other bending parameters take it up with impossible signs, and the
/// compliance alone then takes the wrong joints' names.
pub(super) fn companion(cause: Cause) -> Option<Cause> {
    (cause == Cause::LinkDeflection).then_some(Cause::JointCompliance)
}

/// What a selection adds to across passes.
pub(super) struct Bookkeeping<'b> {
    pub(super) round: &'b mut usize,
    pub(super) trials: &'b mut Vec<Trial>,
    pub(super) health: &'b mut Health,
    pub(super) progress: &'b mut dyn FnMut(&str),
    /// Every model fitted so far by its name (`None`: too few poses), so that a selection run again
    /// after a rejection does not refit what it fitted before (the fits are deterministic).
    pub(super) fits: &'b mut std::collections::BTreeMap<String, Option<Evaluated>>,
    /// The rival probes on each model's residual, by the model's name.
    pub(super) rivals: &'b mut std::collections::BTreeMap<String, Vec<unexplained::Probe>>,
}

/// Forward selection from `start` over `candidates` (each at the 0-based joints `limits` gives for
/// it, else at all its joints; [`narrowed`]): each round extends the current model by every
/// remaining candidate, judges each ([`Trial`]) and adopts the significant one with the largest
/// held-out `z`, until none is significant. Impossible physics does not stop a candidate here: fitted
/// alone, a cause often stands in for another one with a wrong sign somewhere, which the joint fit
/// with that other cause then puts right; [`invalid_finding`] judges the final joint fit.
pub(super) fn select(
    model: &Model,
    split: &Split<'_>,
    start: Evaluated,
    candidates: &[Cause],
    limits: &BTreeMap<Cause, Vec<usize>>,
    options: &DiagnoseOptions,
    book: &mut Bookkeeping<'_>,
) -> Result<Selection> {
    let mut current = start;
    let mut steps = vec![current.step.clone()];
    let mut findings = Vec::new();
    let mut companions = Vec::new();
    loop {
        *book.round += 1;
        let round = *book.round;
        let remaining: Vec<Cause> = candidates
            .iter()
            .copied()
            .filter(|c| !current.spec.causes.contains(c))
            .collect();
        if remaining.is_empty() {
            break;
        }
        let z_crit = significance::normal_upper_quantile(options.alpha / remaining.len() as f64);
        let z_held =
            significance::normal_upper_quantile(options.held_out_alpha / remaining.len() as f64);
        // The rivals no known cause names: angle errors of one joint periodic in its angle or linear
        // in the joint angles. A cause that is really there explains its residual better than such a
        // generic term, except the one that models it (the transmission error, the harmonics).
        let rivals = book
            .rivals
            .entry(current.spec.name())
            .or_insert_with(|| unexplained::probes(model, split, &current, &[], options.seed))
            .clone();
        let specs: Vec<(Cause, ModelSpec)> = remaining
            .iter()
            .map(|&cause| {
                let limit = |c: Cause| limits.get(&c).map(Vec::as_slice);
                let mut spec = current.spec.with_joints(cause, limit(cause));
                if let Some(c) = companion(cause).filter(|c| candidates.contains(c)) {
                    spec = spec.with_joints(c, limit(c));
                }
                (cause, spec)
            })
            .collect();
        fit_candidates(model, split, &specs, options, book)?;
        let mut tried: Vec<(Cause, Evaluated, f64, f64, f64)> = Vec::new();
        for (cause, spec) in specs {
            let cand = match book.fits.get(&spec.name()) {
                Some(Some(c)) => c.clone(),
                _ => continue,
            };
            let tz = significance::paired(&current.pose_sq, &cand.pose_sq).z;
            let trz = train_z(&current.cal, &cand.cal);
            let gain = 1.0 - cand.step.test_rms_m / current.step.test_rms_m;
            let beaten_by = best_rival_probe(&rivals, cause)
                .filter(|p| p.gain >= gain)
                .map(|p| p.name.clone());
            let significant =
                tz > z_held && trz > z_crit && gain >= options.min_gain && beaten_by.is_none();
            book.trials.push(Trial {
                round,
                cause,
                fitted_joints: spec
                    .joints_of(cause)
                    .map(|js| js.iter().map(|j| j + 1).collect()),
                test_rms_m: cand.step.test_rms_m,
                test_z: tz,
                train_z: trz,
                gain,
                significant,
                beaten_by,
                impossible: impossible_parameters(&cand.cal, cause, options.joint_z)
                    .map(|(reason, _)| reason),
                names_nothing: names_nothing(&cand.cal, cause, options.joint_z),
            });
            tried.push((cause, cand, tz, trz, gain));
        }
        let this_round = &book.trials[book.trials.len() - tried.len()..];
        let best = this_round
            .iter()
            .enumerate()
            .filter(|(_, t)| t.significant)
            .max_by(|a, b| a.1.test_z.total_cmp(&b.1.test_z))
            .map(|(k, _)| k);
        let Some(mut k) = best else { break };
        // Parsimony: a significant candidate with fewer parameters whose held-out errors are not
        // significantly worse than the best one's is named instead (the data do not tell the two
        // apart, and the larger model can mimic the smaller: bending of joint 1 about the horizontal
        // axis under joint 2 is joint 2's compliance moved 0.19 m down).
        let added = |i: usize| tried[i].1.cal.layout.len() - current.cal.layout.len();
        let better_than =
            |i: usize, j: usize| significance::paired(&tried[i].1.pose_sq, &tried[j].1.pose_sq).z;
        if let Some(i) = (0..tried.len())
            .filter(|&i| this_round[i].significant && added(i) < added(k))
            .filter(|&i| better_than(i, k) < TIE_Z)
            .min_by(|&a, &b| {
                added(a)
                    .cmp(&added(b))
                    .then(this_round[b].test_z.total_cmp(&this_round[a].test_z))
            })
        {
            k = i;
        }
        let rival = nearest_rival(this_round, k, &rivals, &|i| better_than(k, i));
        let (cause, next, tz, trz, gain) = tried.swap_remove(k);
        let r = explained_correlation(&current.test_err, &next.test_err);
        let finding = Finding {
            cause,
            evidence: String::new(),
            joints: Vec::new(),
            test_rms_m_before: current.step.test_rms_m,
            test_rms_m_after: next.step.test_rms_m,
            gain,
            r,
            test_z: tz,
            train_z: trz,
            parameters: Vec::new(),
            fitted_joints: None,
            rival,
        };
        let added: Vec<Cause> = next
            .spec
            .causes
            .iter()
            .copied()
            .filter(|c| *c != cause && !current.spec.causes.contains(c))
            .collect();
        findings.push(finding.clone());
        for c in added {
            companions.push((cause, c));
            findings.push(Finding {
                cause: c,
                rival: None,
                ..finding.clone()
            });
        }
        steps.push(next.step.clone());
        current = next;
    }
    Ok(Selection {
        current,
        steps,
        findings,
        companions,
    })
}

/// Fits every model of `specs` that `book` has not fitted yet, from the closed form, in parallel
/// (each fit is deterministic and independent of the others, so the outcome does not depend on the
/// order or the number of threads), and files each under its name (`None`: too few poses). The first
/// other error, in the order of `specs`, is returned. A caller's cancellation check
/// ([`crate::cancel`]) is polled on its thread while the fits run and stops them at their next
/// checkpoint.
pub(super) fn fit_candidates(
    model: &Model,
    split: &Split<'_>,
    specs: &[(Cause, ModelSpec)],
    options: &DiagnoseOptions,
    book: &mut Bookkeeping<'_>,
) -> Result<()> {
    crate::cancel::checkpoint()?;
    let mut todo: Vec<&ModelSpec> = Vec::new();
    for (_, spec) in specs {
        if !book.fits.contains_key(&spec.name()) && !todo.iter().any(|t| t.name() == spec.name()) {
            todo.push(spec);
        }
    }
    match todo.as_slice() {
        [] => return Ok(()),
        [one] => (book.progress)(&one.name()),
        many => (book.progress)(&format!(
            "{} candidates in parallel: {}",
            many.len(),
            many.iter().map(|s| s.name()).collect::<Vec<_>>().join("; ")
        )),
    }
    let jobs: Vec<(&ModelSpec, Start<'_>)> = todo.iter().map(|s| (*s, Start::Cold)).collect();
    let fitted = evaluate_in_parallel(model, split, &jobs, options);
    crate::cancel::checkpoint()?;
    for (spec, fit) in todo.iter().zip(fitted) {
        match fit {
            Ok(c) => {
                book.health.merge(&c.cal.report.health);
                book.fits.insert(spec.name(), Some(c));
            }
            Err(CalibError::TooFewPoses { .. }) => {
                book.fits.insert(spec.name(), None);
            }
            Err(e) => return Err(e),
        }
    }
    Ok(())
}

/// [`evaluate`] of each `(spec, start)` of `jobs`, in parallel on rayon's threads, results in the
/// order of `jobs` (each fit is deterministic and independent of the others: the same results on any
/// number of threads); a caller's cancellation check ([`crate::cancel`]) is relayed to the fits.
pub(super) fn evaluate_in_parallel(
    model: &Model,
    split: &Split<'_>,
    jobs: &[(&ModelSpec, Start<'_>)],
    options: &DiagnoseOptions,
) -> Vec<Result<Evaluated>> {
    crate::cancel::relayed(|relay| {
        jobs.par_iter()
            .map(|(spec, start)| relay.run(|| evaluate(model, split, spec, options, *start)))
            .collect()
    })
}

/// True when no parameter of `cause` in `cal` is determined on its own and differs from zero by
/// more than `joint_z` standard deviations: nothing to name.
pub(super) fn names_nothing(cal: &Calibration, cause: Cause, joint_z: f64) -> bool {
    !cause_parameters(cal, cause)
        .iter()
        .any(|(p, _, alone)| *alone && p.sigma > 0.0 && (p.value / p.sigma).abs() > joint_z)
}

/// The first cause adopted by `sel` that does not hold in the final joint fit, one whose named
/// parameters are impossible, as a rejection.
pub(super) fn invalid_finding(sel: &Selection, options: &DiagnoseOptions) -> Option<Rejected> {
    let cal = &sel.current.cal;
    sel.findings.iter().find_map(|f| {
        let cause = f.cause;
        let (reason, params) = impossible_parameters(cal, cause, options.joint_z)?;
        let joints = joints_of(&params);
        let values = if params.is_empty() {
            String::new()
        } else {
            format!(" ({})", parameter_values(cause, &params))
        };
        Some(Rejected {
            cause,
            evidence: format!(
                "{cause}{} would gain {:.0} % on the held-out poses (z = {:.1}), but its fit needs \
                 {reason}{values}: not adopted, it stands in for an error no known cause explains",
                if joints.is_empty() {
                    String::new()
                } else {
                    format!(" at {}", joint_words(&joints))
                },
                100.0 * f.gain,
                f.test_z,
            ),
            joints,
            reason,
            gain: f.gain,
            test_z: f.test_z,
            parameters: params,
        })
    })
}

/// Joint selection within a cause: when the final joint fit of `sel` names an implausible parameter
/// of the cause of `rejection` at some joints ([`invalid_finding`]), the cause limited to its other
/// joints that the fit names (determined on their own, beyond [`DiagnoseOptions::joint_z`] standard
/// deviations, and plausible): the joints dropped are the implausible and the insignificant ones, in
/// one step. `None` when nothing is left to keep, when an implausible parameter is not tied to a joint
/// (the arm's growth), or when the cause already acts at no more than those joints: then the whole
/// cause is rejected. Only a cause that would otherwise be rejected is refitted, so the selection
/// costs nothing more when every adopted cause is plausible.
pub(super) fn narrowed(
    sel: &Selection,
    rejection: &Rejected,
    options: &DiagnoseOptions,
) -> Option<JointSelection> {
    let cause = rejection.cause;
    let spec = &sel.current.spec;
    if rejection
        .parameters
        .iter()
        .any(|p| p.term.and_then(Term::joint).is_none())
    {
        return None;
    }
    let bad: Vec<usize> = joints_of(&rejection.parameters);
    let params = cause_parameters(&sel.current.cal, cause);
    let named: Vec<FoundParameter> = params
        .iter()
        .filter(|(p, _, alone)| {
            *alone && p.sigma > 0.0 && (p.value / p.sigma).abs() > options.joint_z
        })
        .map(|(p, _, _)| p.clone())
        .collect();
    let kept: Vec<usize> = joints_of(&named)
        .into_iter()
        .filter(|j| !bad.contains(j))
        .collect();
    let before: Vec<usize> =
        joints_of(&params.iter().map(|(p, _, _)| p.clone()).collect::<Vec<_>>());
    if kept.is_empty() || kept.len() >= before.len() {
        return None;
    }
    let dropped: Vec<usize> = before
        .iter()
        .copied()
        .filter(|j| !kept.contains(j))
        .collect();
    let insignificant: Vec<usize> = dropped
        .iter()
        .copied()
        .filter(|j| !bad.contains(j))
        .collect();
    let now = spec.with_joints(cause, Some(&kept.iter().map(|j| j - 1).collect::<Vec<_>>()));
    let evidence = format!(
        "{cause} fitted at {} needs {} at {} ({}): {} dropped{}, and {cause} refitted at {} \
         ({} instead of {})",
        joint_words(&before),
        rejection.reason,
        joint_words(&bad),
        parameter_values(cause, &rejection.parameters),
        joint_words(&bad),
        if insignificant.is_empty() {
            String::new()
        } else {
            format!(" with the insignificant {}", joint_words(&insignificant))
        },
        joint_words(&kept),
        now.name(),
        spec.name()
    );
    Some(JointSelection {
        cause,
        kept,
        dropped,
        implausible: bad,
        reason: rejection.reason.clone(),
        parameters: rejection.parameters.clone(),
        evidence,
    })
}
