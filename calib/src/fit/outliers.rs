//! Rows whose residual is far beyond the noise, by a robust scale of the residual norms.

use super::report::Outlier;
use crate::fit::problem::{KinematicProblem, Observations};
use crate::model::params::KinematicParams;
use crate::model::predict::Prediction;
use sim::Model;

/// Median of χ² with `d` degrees of freedom, for the robust scale (d = 3 or 6).
pub(super) fn chi2_median(d: usize) -> f64 {
    if d == 6 { 5.348_120 } else { 2.365_974 }
}

fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    let m = v.len() / 2;
    if v.len() % 2 == 1 {
        v[m]
    } else {
        0.5 * (v[m - 1] + v[m])
    }
}

/// Normalised residual norms `t` per row (robust scale), from weighted norms and robust weights.
pub(super) fn normalised_norms(norms: &[f64], weights: &[f64], d: usize) -> Vec<f64> {
    let raw: Vec<f64> = norms
        .iter()
        .zip(weights)
        .map(|(n, w)| if *w > 0.0 { n / w.sqrt() } else { *n })
        .collect();
    let scale = median(raw.clone()) / chi2_median(d).sqrt();
    let scale = if scale > 0.0 { scale } else { 1.0 };
    raw.iter().map(|v| v / scale).collect()
}

/// Gives the rows of `excluded` (1-based table rows) weight 0 in `obs`, as the fit that excluded
/// them did.
pub(super) fn exclude(obs: &mut Observations, excluded: &[Outlier]) {
    for o in excluded {
        if let Some(r) = obs.source_row.iter().position(|&s| s + 1 == o.row) {
            obs.weight[r] = 0.0;
        }
    }
}

/// Rows of `obs` whose normalised residual norm at `params` exceeds `threshold` (see
/// [`super::CalibrationOptions::outlier_threshold`]), worst first. A row must also exceed a tenth of
/// the threshold in units of its own σ: residuals at rounding level (noise-free data) are no outliers
/// however they compare with each other.
pub(super) fn find(
    model: &Model,
    obs: &Observations,
    params: &KinematicParams,
    active: &[usize],
    threshold: f64,
) -> Vec<Outlier> {
    let norms = row_norms(model, obs, params, active);
    find_in(model, obs, params, &norms, threshold)
}

/// The weighted residual norm of every row of `obs` at `params` (noise units).
pub(super) fn row_norms(
    model: &Model,
    obs: &Observations,
    params: &KinematicParams,
    active: &[usize],
) -> Vec<f64> {
    KinematicProblem::new(model, obs, params.clone(), active.to_vec()).row_norms()
}

/// [`find`] from the rows' weighted residual norms `norms` at `params` ([`row_norms`]).
pub(super) fn find_in(
    model: &Model,
    obs: &Observations,
    params: &KinematicParams,
    norms: &[f64],
    threshold: f64,
) -> Vec<Outlier> {
    let t = normalised_norms(norms, &obs.weight, obs.dim());
    let prediction = Prediction::new(model, params);
    let campaign = prediction.campaigns_of(obs);
    let mut s = prediction.scratch();
    let mut outliers = Vec::new();
    for (r, &tv) in t.iter().enumerate() {
        let raw = norms[r] / obs.weight[r].max(f64::MIN_POSITIVE).sqrt();
        if tv > threshold && raw > threshold / 10.0 {
            let c = campaign.get(r).copied().unwrap_or(0);
            let p = prediction.row_in(&obs.ext, r, obs.q_row(r), c, &mut s);
            outliers.push(Outlier {
                row: obs.source_row[r] + 1,
                pose: obs.pose[r],
                normalised_residual: tv,
                error_m: (p - obs.position[r]).norm(),
            });
        }
    }
    outliers.sort_by(|a, b| b.normalised_residual.total_cmp(&a.normalised_residual));
    outliers
}
