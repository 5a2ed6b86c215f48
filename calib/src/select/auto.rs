//! `--model auto`: the physical model diagnose chooses, then the learned residual when it pays.
//!
//! Physics first, learning for the rest (the hybrid of learning-based calibration): diagnose names the
//! causes on its own held-out poses ([`crate::select::diagnose`]). A learned correction is added only when
//!
//! 1. diagnose finds structure no known cause explains (`unexplained.present`), and
//! 2. on diagnose's own split, the physical model plus the learned correction (its hyper-parameters
//!    cross-validated on the training poses) predicts the held-out poses better than the physical model
//!    alone: the paired test of the per-pose squared errors at level `α` (Bonferroni over the learned
//!    kinds tried) and a relative RMS gain of at least [`crate::select::diagnose::DiagnoseOptions::min_gain`];
//!    the kind with the largest gain wins;
//! 3. with several campaigns, it does not make a campaign it did not see worse: for each campaign,
//!    the model is fitted on the others, the campaign registered on [`LOCO_REGISTER_POSES`] of its
//!    poses (seeded, [`crate::fit::register::register`]) with and without the learned correction, and
//!    the rest of its poses predicted; the pooled paired test must not find it worse at level `α`. A
//!    correction that learned where a tracker stood rather than how the robot bends fails here.
//!
//! A learned correction is applied only within its **support** ([`crate::model::learned::support`]),
//! the configurations it was fitted on: it is kept for them, never beyond. The physical causes
//! diagnose adopts must transfer to unseen regions of the configuration space
//! ([`crate::select::diagnose`], step 5), and the saved model's `validation.new_region` says what it
//! promises for poses unlike the ones it saw.
//!
//! What `auto` then saves is refitted on every pose ([`crate::validate::fit_and_validate`]).

use crate::error::{CalibError, Result};
use crate::fit::{CalibrationOptions, Dataset, FitRequest, Part, fit};
use crate::model::learned::LearnedKind;
use crate::model::spec::ModelSpec;
use crate::model::stats::split_by_pose;
use crate::select::diagnose::significance::{normal_upper_quantile, paired};
use crate::select::diagnose::{DiagnoseOptions, Diagnosis};
use crate::validate::campaigns::leave_campaign_out;
use crate::validate::held_out_errors;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use sim::Model;
use sim::measurement_table::MeasurementTable;
use std::collections::BTreeMap;

/// Learned kinds `auto` tries on diagnose's split.
pub const AUTO_LEARNED_KINDS: [LearnedKind; 3] =
    [LearnedKind::Kernel, LearnedKind::Poly, LearnedKind::Adjoint];

/// Poses of an unseen campaign used to register it in the leave-one-campaign-out test.
pub const LOCO_REGISTER_POSES: usize = crate::validate::campaigns::REGISTER_POSES;

/// One learned kind on diagnose's held-out poses.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LearnedTrial {
    /// The kind.
    pub kind: LearnedKind,
    /// Held-out RMS of the physical model (m).
    pub test_rms_m_before: f64,
    /// Held-out RMS with the correction (m).
    pub test_rms_m_after: f64,
    /// `1 − after/before`.
    pub gain: f64,
    /// Paired test `z` over the held-out poses.
    pub z: f64,
    /// Whether it passed (significant and gain large enough).
    pub passed: bool,
}

/// The leave-one-campaign-out test of a learned correction.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CampaignOutTest {
    /// The kind tested.
    pub kind: LearnedKind,
    /// Poses predicted (over all left-out campaigns).
    pub n_poses: usize,
    /// RMS of the physical model on the left-out campaigns' predicted poses (m).
    pub rms_m_before: f64,
    /// RMS with the correction (m).
    pub rms_m_after: f64,
    /// `1 − after/before`.
    pub gain: f64,
    /// Paired test `z`.
    pub z: f64,
    /// Whether it passed.
    pub passed: bool,
}

/// What `auto` chose.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AutoChoice {
    /// The model to fit on every pose.
    pub spec: ModelSpec,
    /// The physical model diagnose chose.
    pub physical: ModelSpec,
    /// Every learned kind tried on diagnose's split (none when diagnose found no unexplained
    /// structure).
    pub trials: Vec<LearnedTrial>,
    /// The leave-one-campaign-out test, with several campaigns and a candidate.
    pub campaign_out: Option<CampaignOutTest>,
    /// One sentence: what was chosen and why.
    pub note: String,
}

/// Sum of squared errors per pose (campaign, pose), poses in key order.
fn per_pose(errors: &[Vector3<f64>], keys: &[(i64, i64)]) -> Vec<f64> {
    let mut m: BTreeMap<(i64, i64), f64> = BTreeMap::new();
    for (e, k) in errors.iter().zip(keys) {
        *m.entry(*k).or_default() += e.norm_squared();
    }
    m.into_values().collect()
}

fn rms(e: &[Vector3<f64>]) -> f64 {
    if e.is_empty() {
        return 0.0;
    }
    (e.iter().map(|v| v.norm_squared()).sum::<f64>() / e.len() as f64).sqrt()
}

/// The learned stage of `--model auto` for `table` (named `name`) after `diagnosis`, made with
/// `options` (its split, seed, levels): the physical model diagnose adopted, with the learned kind
/// of `kinds` that gains on diagnose's held-out poses, if one does. [`super::choose`] runs both.
pub fn with_learned(
    model: &Model,
    table: &MeasurementTable,
    name: &str,
    diagnosis: &Diagnosis,
    options: &DiagnoseOptions,
    kinds: &[LearnedKind],
) -> Result<AutoChoice> {
    let physical = ModelSpec {
        learned: None,
        ..diagnosis.model.clone()
    };
    let mut choice = AutoChoice {
        spec: physical.clone(),
        physical: physical.clone(),
        trials: Vec::new(),
        campaign_out: None,
        note: String::new(),
    };
    if !diagnosis.unexplained.present {
        choice.note = format!(
            "{}: diagnose found no structure that a learned correction could take",
            physical.name()
        );
        return Ok(choice);
    }
    // Diagnose's own split.
    let (tr, te) = split_by_pose(table, options.test_fraction, options.seed);
    let train = Dataset::new(table, tr, name, Part::Training);
    let test = Dataset::new(table, te, name, Part::Test);
    let keys: Vec<(i64, i64)> = test.rows.iter().map(|&r| table.pose_key(r)).collect();
    let z_crit = normal_upper_quantile(options.alpha / kinds.len().max(1) as f64);
    let calibration = CalibrationOptions {
        learned_seed: options.seed,
        ..options.calibration
    };
    for &kind in kinds {
        let spec = ModelSpec {
            learned: Some(kind),
            ..physical.clone()
        };
        let cal = match fit(model, &train, &FitRequest::new(&spec, &calibration)) {
            Ok(c) => c,
            Err(CalibError::BadValue { .. } | CalibError::TooFewPoses { .. }) => continue,
            Err(e) => return Err(e),
        };
        let (_, before, after) = held_out_errors(model, &cal, &test, &calibration)?;
        let Some(after) = after else { continue };
        let (b, a) = (rms(&before), rms(&after));
        let gain = if b > 0.0 { 1.0 - a / b } else { 0.0 };
        let z = paired(&per_pose(&before, &keys), &per_pose(&after, &keys)).z;
        choice.trials.push(LearnedTrial {
            kind,
            test_rms_m_before: b,
            test_rms_m_after: a,
            gain,
            z,
            passed: z > z_crit && gain >= options.min_gain,
        });
    }
    let best = choice
        .trials
        .iter()
        .filter(|t| t.passed)
        .max_by(|a, b| a.gain.total_cmp(&b.gain))
        .cloned();
    let Some(best) = best else {
        choice.note = format!(
            "{}: unexplained structure, but no learned correction predicts diagnose's held-out poses \
             significantly better",
            physical.name()
        );
        return Ok(choice);
    };
    let with = ModelSpec {
        learned: Some(best.kind),
        ..physical.clone()
    };
    let campaigns = table.campaign_ids();
    if campaigns.len() > 1 {
        let test = campaign_out(model, table, name, &with, &calibration, options.seed)?;
        // The correction is applied only inside its support (`crate::model::learned::support`):
        // on a campaign whose poses lie elsewhere it is off. It fails only where it is applied and
        // makes the unseen campaigns worse: it learned where a tracker stood.
        let passed = test.z > -normal_upper_quantile(options.alpha);
        let t = CampaignOutTest { passed, ..test };
        let note = if passed {
            format!(
                "{}: learned:{} predicts diagnose's held-out poses {:.0} % better and campaigns it did not \
                 see no worse ({:+.0} %; it is applied only within the configurations it was fitted on)",
                with.name(),
                best.kind,
                100.0 * best.gain,
                100.0 * t.gain
            )
        } else {
            format!(
                "{}: learned:{} predicts diagnose's held-out poses {:.0} % better, but makes campaigns it \
                 did not see worse ({:+.0} %, z = {:.1}): it learned the campaigns, not the robot",
                physical.name(),
                best.kind,
                100.0 * best.gain,
                100.0 * t.gain,
                t.z
            )
        };
        choice.campaign_out = Some(t);
        choice.note = note;
        if !passed {
            return Ok(choice);
        }
    } else {
        choice.note = format!(
            "{}: learned:{} predicts diagnose's held-out poses {:.0} % better (z = {:.1})",
            with.name(),
            best.kind,
            100.0 * best.gain,
            best.z
        );
    }
    choice.spec = with;
    Ok(choice)
}

/// The leave-one-campaign-out test of the model `spec` (with its learned correction) on `table`
/// ([`crate::validate::campaigns::leave_campaign_out`]).
fn campaign_out(
    model: &Model,
    table: &MeasurementTable,
    name: &str,
    spec: &ModelSpec,
    options: &CalibrationOptions,
    seed: u64,
) -> Result<CampaignOutTest> {
    let kind = spec.learned.expect("a learned kind");
    let data = Dataset::all(table, name);
    let out = leave_campaign_out(model, &data, &FitRequest::new(spec, options), seed)?
        .unwrap_or_default();
    let learned = out.learned.unwrap_or_default();
    let (b, a) = (rms(&out.physical), rms(&learned));
    let before = per_pose(&out.physical, &out.keys);
    Ok(CampaignOutTest {
        kind,
        n_poses: before.len(),
        rms_m_before: b,
        rms_m_after: a,
        gain: if b > 0.0 { 1.0 - a / b } else { 0.0 },
        z: paired(&before, &per_pose(&learned, &out.keys)).z,
        passed: false,
    })
}
