//! The residual per measurement campaign: with several campaigns (tracker placements), which one the
//! final model fits worse than the others.
//!
//! For each campaign `c`, the per-pose squared errors of the final model on the held-out poses of `c`
//! are compared with those of the other campaigns by Welch's `z`; a campaign **differs** when its
//! mean squared error is larger at level `α` (one-sided, Bonferroni over the campaigns) and its RMS is
//! at least [`MIN_RATIO`] times the others'. A campaign that differs was measured worse (a tracker
//! too far or badly warmed up, a loose reflector) or of a robot that changed between campaigns.

use super::significance::normal_upper_quantile;
use super::{Evaluated, Split};
use serde::{Deserialize, Serialize};
use sim::measurement_table::MeasurementTable;
use std::collections::{BTreeMap, HashMap};

/// One id per row of `rows` naming its pose: the `pose` column, or with a `campaign` column a running
/// id per (campaign, pose), since campaigns may number their poses independently.
pub(crate) fn pose_ids(table: &MeasurementTable, rows: &[usize]) -> Vec<i64> {
    match &table.campaign {
        None => rows.iter().map(|&r| table.pose[r]).collect(),
        Some(_) => {
            let mut ids = HashMap::new();
            rows.iter()
                .map(|&r| {
                    let next = ids.len() as i64;
                    *ids.entry(table.pose_key(r)).or_insert(next)
                })
                .collect()
        }
    }
}

/// Smallest RMS ratio (campaign against the others) for a campaign to be named.
pub const MIN_RATIO: f64 = 1.2;

/// One campaign's held-out residual.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CampaignResidual {
    /// Campaign id.
    pub campaign: i64,
    /// Held-out poses of the campaign.
    pub n_test_poses: usize,
    /// RMS position error of the final model on them (m).
    pub test_rms_m: f64,
    /// RMS over the other campaigns' held-out poses (m).
    pub others_rms_m: f64,
    /// Welch `z` of its per-pose squared errors against the others' (positive: worse).
    pub z: f64,
    /// Whether it differs significantly (worse).
    pub differs: bool,
}

/// The residual per campaign, for data with several campaigns.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CampaignReport {
    /// Per campaign, ascending id.
    pub campaigns: Vec<CampaignResidual>,
    /// A sentence naming the campaigns that differ, or saying none does.
    pub note: String,
}

/// The per-campaign report of `current`'s held-out errors, or `None` with fewer than two campaigns
/// among the held-out poses.
pub(crate) fn report(split: &Split<'_>, current: &Evaluated, alpha: f64) -> Option<CampaignReport> {
    let table = split.test.table;
    table.campaign.as_ref()?;
    // Sum of squared errors per held-out pose, grouped by campaign.
    let mut per_pose: BTreeMap<(i64, i64), f64> = BTreeMap::new();
    for (e, &r) in current.test_err.iter().zip(&split.test.rows) {
        *per_pose.entry(table.pose_key(r)).or_default() += e.norm_squared();
    }
    let mut by_campaign: BTreeMap<i64, Vec<f64>> = BTreeMap::new();
    for ((c, _), v) in per_pose {
        by_campaign.entry(c).or_default().push(v);
    }
    if by_campaign.len() < 2 {
        return None;
    }
    let z_crit = normal_upper_quantile(alpha / by_campaign.len() as f64);
    let rows_of = |c: i64| {
        split
            .test
            .rows
            .iter()
            .zip(&current.test_err)
            .filter(move |(r, _)| table.campaign_of(**r) == Some(c))
            .map(|(_, e)| e.norm_squared())
    };
    let stats = |v: &[f64]| {
        let n = v.len() as f64;
        let mean = v.iter().sum::<f64>() / n;
        let var = if v.len() > 1 {
            v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)
        } else {
            0.0
        };
        (mean, var, n)
    };
    let mut out = Vec::new();
    for (&c, mine) in &by_campaign {
        let others: Vec<f64> = by_campaign
            .iter()
            .filter(|(k, _)| **k != c)
            .flat_map(|(_, v)| v.iter().copied())
            .collect();
        let (m1, v1, n1) = stats(mine);
        let (m2, v2, n2) = stats(&others);
        let se = (v1 / n1 + v2 / n2).sqrt();
        let z = if se > 0.0 { (m1 - m2) / se } else { 0.0 };
        let rms = |it: &mut dyn Iterator<Item = f64>| {
            let (s, n) = it.fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
            if n > 0 { (s / n as f64).sqrt() } else { 0.0 }
        };
        let test_rms_m = rms(&mut rows_of(c));
        let others_rms_m = rms(&mut by_campaign
            .keys()
            .filter(|k| **k != c)
            .flat_map(|&k| rows_of(k)));
        out.push(CampaignResidual {
            campaign: c,
            n_test_poses: mine.len(),
            test_rms_m,
            others_rms_m,
            z,
            differs: z > z_crit && test_rms_m >= MIN_RATIO * others_rms_m,
        });
    }
    let named: Vec<String> = out
        .iter()
        .filter(|c| c.differs)
        .map(|c| {
            format!(
                "campaign {} ({:.1} µm RMS against {:.1} µm for the others, z = {:.1})",
                c.campaign,
                c.test_rms_m * 1e6,
                c.others_rms_m * 1e6,
                c.z
            )
        })
        .collect();
    let note = if named.is_empty() {
        format!(
            "the {} campaigns fit alike (no campaign's held-out residual is significantly larger)",
            out.len()
        )
    } else {
        format!(
            "{} fits worse than the others: measured worse (tracker, reflector) or the robot changed \
             between campaigns",
            named.join("; ")
        )
    };
    Some(CampaignReport {
        campaigns: out,
        note,
    })
}
