//! Leave-one-campaign-out: what a user gets who calibrates once and measures again another day.
//!
//! With several campaigns (tracker set-ups) in the data, each campaign `c` in turn is left out: the
//! model is fitted on the other campaigns, campaign `c` is registered on [`REGISTER_POSES`] of its
//! poses (drawn with the seed; [`crate::fit::register::register`], as `robocal register` does), and
//! the rest of its poses are predicted. The registration fits only where the tracker stood; everything
//! the robot is comes from the other campaigns.

use crate::error::Result;
use crate::fit::register::{RegisterOptions, register};
use crate::fit::{CalibrationOptions, Dataset, FitRequest, Part, fit, observations};
use crate::model::predict::Prediction;
use nalgebra::Vector3;
use rand::SeedableRng;
use rand::seq::SliceRandom;
use sim::Model;

/// Poses of a left-out campaign that register it (at most half of its poses).
pub const REGISTER_POSES: usize = 20;

/// Errors of the left-out campaigns' predicted poses.
#[derive(Clone, Debug, Default)]
pub struct CampaignOut {
    /// Pose key (campaign, pose) per predicted row.
    pub keys: Vec<(i64, i64)>,
    /// `predicted − measured` of the physical model (the campaign's tracker frame, m), per row.
    pub physical: Vec<Vector3<f64>>,
    /// The same with the learned correction, for a model that has one.
    pub learned: Option<Vec<Vector3<f64>>>,
    /// Campaigns predicted (those with at least 6 poses: 3 to register, the rest predicted).
    pub n_campaigns: usize,
}

/// [`CampaignOut`] of `request`'s model on `data` (its rows' campaigns; seed `seed` draws the
/// registration poses), or `None` with fewer than two campaigns. `options` are the registration's
/// noise model and solver settings.
pub fn leave_campaign_out(
    model: &Model,
    data: &Dataset<'_>,
    request: &FitRequest<'_>,
    seed: u64,
) -> Result<Option<CampaignOut>> {
    let table = data.table;
    let mut ids: Vec<i64> = data
        .rows
        .iter()
        .filter_map(|&r| table.campaign_of(r))
        .collect();
    ids.sort_unstable();
    ids.dedup();
    if ids.len() < 2 {
        return Ok(None);
    }
    let options: &CalibrationOptions = request.options();
    let mut out = CampaignOut::default();
    let mut learned_all: Vec<Vector3<f64>> = Vec::new();
    let mut has_learned = false;
    for id in ids {
        crate::cancel::checkpoint()?;
        let (left_out, inside): (Vec<usize>, Vec<usize>) = data
            .rows
            .iter()
            .partition(|&&r| table.campaign_of(r) == Some(id));
        let train = data.part(inside, Part::WithoutCampaign(id));
        let cal = fit(model, &train, &request.clone().judged_on(None))?;
        // Register on REGISTER_POSES of the campaign's poses (seeded), predict the rest.
        let mut poses: Vec<i64> = left_out.iter().map(|&r| table.pose[r]).collect();
        poses.sort_unstable();
        poses.dedup();
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed ^ (id as u64).wrapping_mul(0x9e37));
        poses.shuffle(&mut rng);
        let k = REGISTER_POSES.min(poses.len() / 2);
        let chosen: std::collections::HashSet<i64> = poses[..k].iter().copied().collect();
        let (reg_rows, rest): (Vec<usize>, Vec<usize>) = left_out
            .iter()
            .partition(|&&r| chosen.contains(&table.pose[r]));
        if rest.is_empty() || k < 3 {
            continue;
        }
        let reg_table = table.select_rows(&reg_rows);
        let reg_name = format!("{} (campaign {id}, registration poses)", data.name);
        let rest_set = data.part(rest, Part::CampaignPredicted(id));
        let reg_options = RegisterOptions {
            noise: options.noise,
            ..RegisterOptions::default()
        };
        let physical = cal.physical.as_ref().unwrap_or(&cal.params);
        let errors = |params: &crate::model::params::KinematicParams,
                      learned: Option<&crate::model::learned::LearnedResidual>|
         -> Result<Vec<Vector3<f64>>> {
            let reg = register(
                model,
                params,
                cal.extensions.as_ref(),
                learned,
                None,
                &reg_table,
                &reg_name,
                &reg_options,
            )?;
            let obs = observations(
                model,
                &rest_set,
                options,
                cal.extensions.as_ref(),
                Some(&reg.params),
            )?;
            Ok(Prediction::new(model, &reg.params)
                .with_learned(learned)
                .errors(&obs))
        };
        out.physical.extend(errors(physical, None)?);
        if let Some(l) = cal.learned.as_ref() {
            has_learned = true;
            learned_all.extend(errors(&cal.params, Some(l))?);
        }
        out.keys
            .extend(rest_set.rows.iter().map(|&r| table.pose_key(r)));
        out.n_campaigns += 1;
    }
    if has_learned {
        out.learned = Some(learned_all);
    }
    Ok(Some(out))
}
