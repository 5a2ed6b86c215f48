//! A finding's parameters, the impossible ones, and the evidence a user reads: the gain, the test, the
//! nearest rival.

#[allow(unused_imports)]
use super::*;

/// Training `χ²` drop of `big` over `small` as a normal `z`, with the variance factor of `big`.
///
/// The degrees of freedom are the identifiable parameters `big` adds. When its rank does not grow
/// (the models are not nested: adding joint compliance to link deflection hands the bending about the
/// next joint's axis to the compliance, and weakly determined combinations fall below the rank
/// threshold differently), they are the parameters it adds, a conservative count.
pub(super) fn train_z(small: &Calibration, big: &Calibration) -> f64 {
    let c0 = small.report.after.solver.cost_final;
    let c1 = big.report.after.solver.cost_final;
    let added = big.layout.len().saturating_sub(small.layout.len());
    let k = match big.subspace.rank.saturating_sub(small.subspace.rank) {
        0 => added,
        k => k,
    } as f64;
    let vf = if big.report.dof > 0 {
        c1 / big.report.dof as f64
    } else {
        1.0
    };
    if k == 0.0 || vf <= 0.0 {
        return 0.0;
    }
    significance::chi2_to_z((c0 - c1) / vf, k)
}

/// Correlation between the residual `−before` and the change `after − before` of the prediction.
pub(super) fn explained_correlation(before: &[Vector3<f64>], after: &[Vector3<f64>]) -> f64 {
    let (mut num, mut a2, mut b2) = (0.0, 0.0, 0.0);
    for (b, a) in before.iter().zip(after) {
        let d = a - b;
        num += (-b).dot(&d);
        a2 += b.norm_squared();
        b2 += d.norm_squared();
    }
    if a2 > 0.0 && b2 > 0.0 {
        num / (a2 * b2).sqrt()
    } else {
        0.0
    }
}

/// Largest share of an extension parameter (scaled units) in the null space for it to count as
/// determined on its own.
pub const MAX_NULL_SHARE: f64 = 0.1;

/// The extension parameters of `cause` in `cal`, with standard deviations where determined alone.
pub(super) fn cause_parameters(
    cal: &Calibration,
    cause: Cause,
) -> Vec<(FoundParameter, Term, bool)> {
    let layout = &cal.layout;
    layout
        .extensions
        .iter()
        .enumerate()
        .filter(|(_, p)| p.cause == cause)
        .map(|(e, p)| {
            let k = layout.extension(e);
            // Determined when at most a tenth of it (in scaled units) lies in the unidentifiable or
            // weakly determined subspace; its standard deviation then holds to that accuracy.
            let sub = &cal.subspace;
            let null_share = sub
                .v
                .row(k)
                .columns(sub.rank, sub.n_params() - sub.rank)
                .norm();
            let alone = null_share <= MAX_NULL_SHARE;
            let sigma = if alone {
                cal.covariance[(k, k)].max(0.0).sqrt()
            } else {
                f64::NAN
            };
            (
                FoundParameter {
                    name: p.name(),
                    unit: p.unit,
                    value: cal.params.extension[e],
                    sigma,
                    term: Some(p.term),
                },
                p.term,
                alone,
            )
        })
        .collect()
}

/// The named parameters of `cause` in `cal` (determined on their own and beyond `joint_z` standard
/// deviations from zero) whose value is physically impossible or implausible
/// ([`crate::model::extensions::CauseModel::implausible`]), with the reason of the first.
pub(super) fn impossible_parameters(
    cal: &Calibration,
    cause: Cause,
    joint_z: f64,
) -> Option<(String, Vec<FoundParameter>)> {
    let model = cause.model();
    let mut reason = None;
    let own = cal.layout.extensions.iter().filter(|p| p.cause == cause);
    let bad: Vec<FoundParameter> = cause_parameters(cal, cause)
        .into_iter()
        .zip(own)
        .filter(|((p, _, alone), _)| *alone && p.sigma > 0.0 && (p.value / p.sigma).abs() > joint_z)
        .filter_map(|((p, _, _), param)| {
            let why = model.implausible(param, p.value)?;
            reason.get_or_insert(why);
            Some(p)
        })
        .collect();
    reason.map(|r| (r, bad))
}

/// 1-based joints of the parameters `params`, ascending, each once.
pub(super) fn joints_of(params: &[FoundParameter]) -> Vec<usize> {
    let set: std::collections::BTreeSet<usize> = params
        .iter()
        .filter_map(|p| p.term.and_then(Term::joint).map(|j| j + 1))
        .collect();
    set.into_iter().collect()
}

/// The parameters as `name value ± sigma unit`, joined by `; `.
pub(super) fn parameter_values(cause: Cause, params: &[FoundParameter]) -> String {
    params
        .iter()
        .map(|p| {
            format!(
                "{} {:.3e} ± {:.1e} {}{}",
                p.name,
                p.value,
                p.sigma,
                p.unit,
                cause.model().remark(p.unit, p.value)
            )
        })
        .collect::<Vec<_>>()
        .join("; ")
}

/// The evidence sentence of a finding of `cause` at `joints` (1-based; with `growth` when the link
/// growth is named too): what the residual correlates with, how many parameters name them (beyond
/// `joint_z` standard deviations; their values go to the report's parameter table, not into the
/// sentence), and why not the nearest rival.
pub(super) fn evidence(
    cause: Cause,
    joints: &[usize],
    params: &[FoundParameter],
    r: f64,
    growth: bool,
    rival: Option<&Rival>,
    joint_z: f64,
) -> String {
    let model = cause.model();
    let named: Vec<FoundParameter> = params
        .iter()
        .filter(|p| p.sigma > 0.0 && (p.value / p.sigma).abs() > joint_z)
        .filter(|p| match p.term {
            Some(Term::JointAngle { joint } | Term::Bend { joint, .. }) => {
                joints.contains(&(joint + 1))
            }
            Some(Term::Growth) => growth,
            None => false,
        })
        .cloned()
        .collect();
    let mut s = if named.is_empty() {
        format!(
            "residual correlates with {} (r = {r:.2}); no joint's parameter is determined on its own \
             beyond {joint_z} standard deviations (their effects are not told apart), so no joint is named",
            model.evidence_subject("its joints"),
        )
    } else {
        format!(
            "residual correlates with {} (r = {r:.2}); {} of its parameters {} determined beyond \
             {joint_z} standard deviations (their values are in the finding's parameter table)",
            model.evidence_subject(&joint_words(joints)),
            named.len(),
            if named.len() == 1 { "is" } else { "are" },
        )
    };
    if let Some(rv) = rival {
        s.push_str(&format!("; {}", rv.why_not));
    }
    s
}

/// The probe of `rivals` with the largest held-out gain that `cause` does not model itself.
pub(super) fn best_rival_probe(
    rivals: &[unexplained::Probe],
    cause: Cause,
) -> Option<&unexplained::Probe> {
    rivals
        .iter()
        .filter(|p| !p.kind.modelled_by(cause))
        .max_by(|a, b| a.gain.total_cmp(&b.gain))
}

/// A larger candidate must predict the held-out poses better than a smaller significant one by this
/// paired `z` (one-sided 5 %) to be named instead of it.
pub const TIE_Z: f64 = 1.645;

/// The nearest rival of the candidate `this_round[k]` adopted in a round: the other candidate or the
/// rival probe with the largest held-out gain, with why it lost in words; `better_than(i)` is the
/// paired `z` by which candidate `i`'s held-out errors exceed the adopted one's.
pub(super) fn nearest_rival(
    this_round: &[Trial],
    k: usize,
    rivals: &[unexplained::Probe],
    better_than: &dyn Fn(usize) -> f64,
) -> Option<Rival> {
    let won = &this_round[k];
    let pct = |g: f64| format!("{:.0} %", 100.0 * g);
    let signature = won.cause.model().signature();
    let other = this_round
        .iter()
        .enumerate()
        .filter(|(i, _)| *i != k)
        .max_by(|a, b| a.1.gain.total_cmp(&b.1.gain));
    let probe = best_rival_probe(rivals, won.cause);
    match (other, probe) {
        (Some((i, t)), p) if p.is_none_or(|p| t.gain >= p.gain) => {
            let why = match &t.impossible {
                _ if t.gain > won.gain => format!(
                    "not {}, its nearest rival: that gains {} on the held-out poses against {} here, \
                     no better to a paired test (z = {:.1}) and with more parameters, so the simpler \
                     is named; the data hardly tell them apart",
                    t.cause,
                    pct(t.gain),
                    pct(won.gain),
                    better_than(i)
                ),
                Some(reason) => format!(
                    "not {}, its nearest rival: that would gain {} on the held-out poses against {} \
                     here, but its fit needs {reason}",
                    t.cause,
                    pct(t.gain),
                    pct(won.gain)
                ),
                None => format!(
                    "not {}, its nearest rival: that gains {} on the held-out poses against {} here, \
                     and this error {signature}",
                    t.cause,
                    pct(t.gain),
                    pct(won.gain)
                ),
            };
            Some(Rival {
                name: t.cause.name().to_string(),
                gain: t.gain,
                why_not: why,
            })
        }
        (_, Some(p)) => Some(Rival {
            name: p.name.clone(),
            gain: p.gain,
            why_not: format!(
                "not an error outside the known causes: the nearest probe for one ({}) gains {} on \
                 the held-out poses against {} here",
                p.name,
                pct(p.gain),
                pct(won.gain)
            ),
        }),
        _ => None,
    }
}
