//! Diagnosis: what the kinematic model still gets wrong, which physical cause explains it, and how much
//! the extended model gains on held-out poses.
//!
//! 1. The poses are split into training and test sets ([`split_by_pose`], seeded); every decision is
//!    checked on the test poses, which no fit has seen.
//! 2. The current model (first the kinematic one) is extended by each candidate cause in turn
//!    ([`crate::extensions::Cause`]) and refitted on the training poses. A candidate is **significant**
//!    when both (a) its training `χ²` drops by more than its added identifiable parameters explain
//!    (`Δχ² / (χ²₁/dof₁)` against `χ²` with `Δrank` degrees of freedom, as a normal `z`,
//!    [`significance::chi2_to_z`]) at level `α`, and (b) it predicts the test poses better (a paired
//!    test of the per-pose squared errors, [`significance::paired`]) at level `α_held_out`, each
//!    divided by the number of candidates (Bonferroni), (c) it lowers the test RMS by at least [`DiagnoseOptions::min_gain`],
//!    and (d) it gains more on the test poses than an error periodic in one joint's angle would
//!    ([`unexplained::probes`]): a cause that is really there explains its residual better than a
//!    generic term, and structure that a generic term explains better is no known cause's.
//! 3. The significant candidate with the largest test `z` is adopted; the loop repeats with the
//!    remaining causes until none is significant.
//! 4. The joints of a finding are those whose parameter of that cause is determined on its own and
//!    differs from zero by more than [`DiagnoseOptions::joint_z`] standard deviations.
//! 5. What is left is examined for structure no known cause explains ([`unexplained`]): harmonics of
//!    each joint angle and the learned residual models, again judged on the test poses.
//!
//! The noise floor ([`noise_floor`]) comes from repeated poses when the data have enough of them, else
//! from the `sigma` column or the tracker noise model.

pub mod campaigns;
pub mod noise_floor;
pub mod report;
pub mod screening;
pub mod significance;
pub mod unexplained;

use crate::calibrate::{
    Calibration, CalibrationOptions, Dataset, WarmStart, calibrate_model_from, observations,
};
use crate::error::{CalibError, Result};
use crate::extensions::{Cause, ModelSpec, Regressors, Term, joint_words};
use crate::health::Health;
use crate::learned::LearnedKind;
use crate::predict::Prediction;
use crate::stats::split_by_pose;
use crate::units::Unit;
use nalgebra::Vector3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sim::Model;
use sim::measurement_table::MeasurementTable;
use std::collections::BTreeMap;
use std::sync::OnceLock;

/// Settings of [`diagnose`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DiagnoseOptions {
    /// Fraction of the poses held out (default 1/3).
    pub test_fraction: f64,
    /// Seed of the split and of the learned models' folds.
    pub seed: u64,
    /// Calibration settings.
    pub calibration: CalibrationOptions,
    /// Family-wise false-alarm level of each round's training test (default 1e-3).
    pub alpha: f64,
    /// Family-wise level of each round's held-out test (default 0.05). It guards against a model that
    /// fits the training poses without predicting others; false alarms are held down by `alpha`, the
    /// two tests together by their product.
    pub held_out_alpha: f64,
    /// Smallest relative test-RMS reduction a finding must bring (default 0.02).
    pub min_gain: f64,
    /// A joint is named when its parameter differs from zero by this many standard deviations (default 4).
    pub joint_z: f64,
    /// Causes to try (default: all).
    pub candidates: Vec<Cause>,
    /// Learned models tried on what is left (default `kernel`, `poly`).
    pub learned_kinds: Vec<LearnedKind>,
    /// The noise floor (RMS position error norm, m) when the user knows it better than the data tell,
    /// e.g. a robot's repeatability; `None` estimates it ([`noise_floor::estimate`]).
    pub noise_floor_m: Option<f64>,
    /// Poses (training and test) above which the candidates are tried on a seeded subsample of this
    /// many and the adopted models refitted on every pose (default
    /// [`screening::DEFAULT_SCREEN_POSES`]; 0: every pose throughout).
    #[serde(default = "default_screen_poses")]
    pub screen_poses: usize,
}

fn default_screen_poses() -> usize {
    screening::DEFAULT_SCREEN_POSES
}

impl Default for DiagnoseOptions {
    fn default() -> Self {
        DiagnoseOptions {
            test_fraction: 1.0 / 3.0,
            seed: 0,
            calibration: CalibrationOptions::default(),
            alpha: 1e-3,
            held_out_alpha: 0.05,
            min_gain: 0.02,
            joint_z: 5.0,
            candidates: Cause::ALL.to_vec(),
            learned_kinds: vec![LearnedKind::Kernel, LearnedKind::Poly],
            noise_floor_m: None,
            screen_poses: screening::DEFAULT_SCREEN_POSES,
        }
    }
}

/// One model of the sequence: its fit and held-out errors.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Step {
    /// The model (serialised as its name: `kinematic`, `kinematic+joint_compliance`, …).
    pub model: ModelSpec,
    /// RMS position error on the training poses (m).
    pub train_rms_m: f64,
    /// RMS position error on the test poses (m).
    pub test_rms_m: f64,
    /// Largest position error on the test poses (m).
    pub test_max_m: f64,
}

/// An identified extension parameter, for the report.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FoundParameter {
    /// Its name (e.g. `joint 2 compliance`).
    pub name: String,
    /// Its unit.
    pub unit: Unit,
    /// The estimate.
    pub value: f64,
    /// Its standard deviation (NaN when not determined on its own).
    pub sigma: f64,
    /// How it enters the chain (which joint), for the code; not part of the JSON.
    #[serde(skip)]
    pub term: Option<Term>,
}

/// A cause the data show.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Finding {
    /// The cause (`joint_compliance`, `gear_backlash`, `thermal_drift`, …).
    pub cause: Cause,
    /// 1-based joints it acts on (empty where it is not tied to joints).
    pub joints: Vec<usize>,
    /// One sentence of evidence.
    pub evidence: String,
    /// Test RMS before adopting it (m).
    pub test_rms_m_before: f64,
    /// Test RMS after (m).
    pub test_rms_m_after: f64,
    /// `1 − after/before`.
    pub gain: f64,
    /// Correlation of the residual with what the cause predicts (test poses).
    pub r: f64,
    /// Paired test `z` on the test poses.
    pub test_z: f64,
    /// Training `χ²` drop as a normal `z`.
    pub train_z: f64,
    /// The cause's identified parameters.
    pub parameters: Vec<FoundParameter>,
    /// The nearest rival when it was adopted: the other candidate cause, or the probe for structure no
    /// cause explains, that gained most on the held-out poses in that round.
    #[serde(default)]
    pub rival: Option<Rival>,
}

/// The nearest rival of a finding.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Rival {
    /// A cause's word (`link_deflection`) or a probe's name (`harmonics 1-3 of joint 3`).
    pub name: String,
    /// Its relative test-RMS reduction in that round.
    pub gain: f64,
    /// Why it lost, in words.
    pub why_not: String,
}

/// A cause that would have gained on the held-out poses but whose identified physics is impossible:
/// not adopted, and reported as evidence of an error no known cause explains.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Rejected {
    /// The cause.
    pub cause: Cause,
    /// 1-based joints whose identified parameter is impossible.
    pub joints: Vec<usize>,
    /// What is impossible.
    pub reason: String,
    /// Relative test-RMS reduction it would have brought.
    pub gain: f64,
    /// Paired test `z` on the test poses.
    pub test_z: f64,
    /// The impossible parameters (value at least [`DiagnoseOptions::joint_z`] standard deviations on the
    /// impossible side).
    pub parameters: Vec<FoundParameter>,
    /// One sentence for people.
    pub evidence: String,
}

impl Finding {
    /// The joints as text, e.g. `2, 4` (empty without joints).
    pub fn joint_list(&self) -> String {
        self.joints
            .iter()
            .map(|j| j.to_string())
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// A candidate tried in one round.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Trial {
    /// Round (1-based).
    pub round: usize,
    /// The cause.
    pub cause: Cause,
    /// Test RMS with it (m).
    pub test_rms_m: f64,
    /// Paired test `z`.
    pub test_z: f64,
    /// Training `z`.
    pub train_z: f64,
    /// Relative test RMS reduction.
    pub gain: f64,
    /// Whether it passed every test.
    pub significant: bool,
    /// The unexplained-structure probe that predicts the test poses at least as well, if any: then the
    /// residual is not this cause's, whatever its significance.
    pub beaten_by: Option<String>,
    /// Why its identified physics is impossible, if it is (a negative stiffness or lost motion): then
    /// it is not adopted whatever its significance.
    #[serde(default)]
    pub impossible: Option<String>,
    /// True when no parameter of it is determined on its own and differs from zero by
    /// [`DiagnoseOptions::joint_z`] standard deviations: there is no joint (or growth) to name, so it
    /// is not adopted whatever its gain.
    #[serde(default)]
    pub names_nothing: bool,
}

/// A candidate cause diagnose could not try.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NotTried {
    /// The cause.
    pub cause: Cause,
    /// Why not, in one sentence.
    pub reason: String,
}

/// The full result; its JSON form is the `diagnose --json` contract.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Diagnosis {
    /// Robot name.
    pub robot: String,
    /// Training poses.
    pub n_train: usize,
    /// Test poses.
    pub n_test: usize,
    /// RMS position error (m) that noise alone would leave.
    pub noise_floor_m: f64,
    /// Where the noise floor comes from.
    pub noise_floor_source: String,
    /// The models fitted, kinematic first, each adopted extension after.
    pub steps: Vec<Step>,
    /// The causes found, in the order adopted.
    pub findings: Vec<Finding>,
    /// Structure no known cause explains.
    pub unexplained: unexplained::Unexplained,
    /// The chosen model (what `calibrate --model auto` fits; serialised as its name).
    pub model: ModelSpec,
    /// Every candidate tried.
    pub trials: Vec<Trial>,
    /// Significance level used.
    pub alpha: f64,
    /// Split seed.
    pub seed: u64,
    /// Numerical warnings of every fit diagnose made (the kinematic model and every candidate),
    /// counted: empty when all were clean.
    #[serde(default)]
    pub health: Health,
    /// Candidate causes this robot and table cannot feed (never tried), with the reason: a robot
    /// without inertials cannot be checked for joint compliance, a table without `temp` or `t` for
    /// thermal drift.
    #[serde(default)]
    pub not_tried: Vec<NotTried>,
    /// How the candidates were screened, when on a subsample of the poses (many poses, see
    /// [`screening`]); absent when every pose was used throughout.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub screening: Option<screening::Screening>,
    /// The held-out residual per measurement campaign, with several campaigns.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub campaigns: Option<campaigns::CampaignReport>,
    /// What `--report` draws (not part of the JSON).
    #[serde(skip)]
    pub plots: report::PlotData,
}

/// A fitted model with its held-out errors.
#[derive(Clone)]
pub(crate) struct Evaluated {
    pub spec: ModelSpec,
    pub cal: Calibration,
    /// `predicted − measured` per training row (m).
    pub train_err: Vec<Vector3<f64>>,
    /// `predicted − measured` per test row (m).
    pub test_err: Vec<Vector3<f64>>,
    /// Sum of squared test errors per test pose (m²).
    pub pose_sq: Vec<f64>,
    /// Extension regressors of the test rows.
    pub test_regs: Regressors,
    pub step: Step,
    /// `∂p/∂qⱼ` of the kinematic chain per training row and joint, made when first asked for.
    train_dirs: OnceLock<Vec<Vector3<f64>>>,
    /// The same per test row.
    test_dirs: OnceLock<Vec<Vector3<f64>>>,
}

impl Evaluated {
    /// `∂p/∂qⱼ` (tracker frame, m/rad) of the fitted kinematic chain at each training row's `q`, for
    /// every joint `j`: entry `k · nq + j` for the `k`-th training row.
    pub(crate) fn train_directions(&self, model: &Model, split: &Split<'_>) -> &[Vector3<f64>] {
        self.train_dirs
            .get_or_init(|| directions(model, &self.cal, &split.train))
    }

    /// The same at each test row.
    pub(crate) fn test_directions(&self, model: &Model, split: &Split<'_>) -> &[Vector3<f64>] {
        self.test_dirs
            .get_or_init(|| directions(model, &self.cal, &split.test))
    }
}

/// `∂p/∂qⱼ` of `cal`'s kinematic chain at the rows of `data` (see [`Evaluated::train_directions`]).
fn directions(model: &Model, cal: &Calibration, data: &Dataset<'_>) -> Vec<Vector3<f64>> {
    let n = model.nq();
    let q: Vec<f64> = data
        .rows
        .iter()
        .flat_map(|&r| data.table.q_row(r).iter().copied())
        .collect();
    let mut out = vec![Vector3::zeros(); q.len()];
    Prediction::new(model, &cal.params).joint_directions(&q, &mut out);
    debug_assert_eq!(out.len(), data.rows.len() * n);
    out
}

fn rms(e: &[Vector3<f64>]) -> f64 {
    if e.is_empty() {
        return 0.0;
    }
    (e.iter().map(|v| v.norm_squared()).sum::<f64>() / e.len() as f64).sqrt()
}

/// Sums `values` per pose id (ids of the same rows), in ascending id order.
pub(crate) fn per_pose(pose: &[i64], values: impl Iterator<Item = f64>) -> Vec<f64> {
    let mut m: BTreeMap<i64, f64> = BTreeMap::new();
    for (id, v) in pose.iter().zip(values) {
        *m.entry(*id).or_default() += v;
    }
    m.into_values().collect()
}

/// The data of one diagnosis: the split and the prepared data sets.
pub(crate) struct Split<'a> {
    pub train: Dataset<'a>,
    pub test: Dataset<'a>,
    pub test_pose: Vec<i64>,
}

/// Where a fit of [`evaluate`] starts.
///
/// A candidate cause starts from the closed form, not at the model it extends: fitted to data with a
/// large error it does not model, that model has bent its weakly determined geometry to absorb the
/// error, and the extended model fitted from there can stop in another local minimum (a blind case
/// with compliance at joint 2: `χ²` 601 from there against 563 from the closed form, which then named
/// link deflection instead).
#[derive(Clone, Copy)]
pub(crate) enum Start<'e> {
    /// The closed-form start.
    Cold,
    /// The solution of the same model on other poses (the screening subsample): its minimum lies
    /// within a few standard deviations.
    Same(&'e Evaluated),
}

/// Fits `spec` on the training poses and predicts the test poses. A fit that starts at another fit
/// ([`Start`]) has a lean report ([`WarmStart`]): the same minimum, in a few iterations.
pub(crate) fn evaluate(
    model: &Model,
    split: &Split<'_>,
    spec: &ModelSpec,
    options: &DiagnoseOptions,
    start: Start<'_>,
) -> Result<Evaluated> {
    let from = match start {
        Start::Cold => None,
        Start::Same(c) => Some(c),
    };
    let warm = from.map(|c| WarmStart {
        before: &c.cal.before,
        physical: c.cal.physical.as_ref().unwrap_or(&c.cal.params),
        extensions: &c.cal.layout.extensions,
        shared: None,
        lean: true,
        payload_com_m: c.cal.extensions.as_ref().map(|s| s.payload_com_m),
    });
    let cal = calibrate_model_from(
        model,
        &split.train,
        Some(&split.test),
        spec,
        &options.calibration,
        warm,
    )?;
    let ext = cal.extensions.as_ref();
    let at = &cal.params.extension;
    let train_obs = observations(model, &split.train, &options.calibration, ext, at)?;
    let test_obs = observations(model, &split.test, &options.calibration, ext, at)?;
    let prediction = Prediction::new(model, &cal.params);
    // With several campaigns, in the first one's tracker frame (the robot's, for the probes).
    let train_err = prediction.reference_errors(&train_obs);
    let test_err = prediction.reference_errors(&test_obs);
    let pose_sq = per_pose(&split.test_pose, test_err.iter().map(|e| e.norm_squared()));
    let step = Step {
        model: spec.clone(),
        train_rms_m: rms(&train_err),
        test_rms_m: rms(&test_err),
        test_max_m: test_err.iter().map(|e| e.norm()).fold(0.0, f64::max),
    };
    Ok(Evaluated {
        spec: spec.clone(),
        cal,
        train_err,
        test_err,
        pose_sq,
        test_regs: test_obs.ext,
        step,
        train_dirs: OnceLock::new(),
        test_dirs: OnceLock::new(),
    })
}

/// Smallest lever `|∂p/∂qⱼ|` (m/rad) of a row to be drawn in a joint-angle residual plot: below it the
/// projection amplifies the noise more than it shows.
const MIN_PLOT_LEVER_M: f64 = 0.15;

/// The residual `−err` of each test row of `current` as the angle of joint `j` (µrad) that would
/// explain it (NaN, not drawn, where the joint's lever is below [`MIN_PLOT_LEVER_M`]).
fn as_joint_angle_urad(
    model: &Model,
    split: &Split<'_>,
    current: &Evaluated,
    err: &[Vector3<f64>],
    j: usize,
) -> Vec<f64> {
    let n = model.nq();
    let dirs = current.test_directions(model, split);
    err.iter()
        .enumerate()
        .map(|(k, e)| {
            let d = dirs[k * n + j];
            let n2 = d.norm_squared();
            if n2 >= MIN_PLOT_LEVER_M * MIN_PLOT_LEVER_M {
                -e.dot(&d) / n2 * 1e6
            } else {
                f64::NAN
            }
        })
        .collect()
}

/// Plots of a finding: per named joint (and the growth), against the parameter's regressor, the
/// partial residual (the adopted model's residual plus this term's own contribution: what the data
/// show of the term) and the adopted model's residual. A joint with several joint-angle parameters of
/// the cause (the harmonics of a transmission error) is drawn against its angle, with the identified
/// curve; a bending parameter as the residual's rotation about its axis, against the bending moment.
fn finding_plots(
    model: &Model,
    split: &Split<'_>,
    after: &Evaluated,
    cause: Cause,
    joints: &[usize],
    growth: bool,
) -> Vec<report::RegressorPlot> {
    let layout = &after.cal.layout;
    let n_test = split.test.rows.len();
    let regressor =
        |e: usize| -> Vec<f64> { (0..n_test).map(|r| after.test_regs.row(r)[e]).collect() };
    let mut out = Vec::new();
    for &j in joints {
        let angle_params: Vec<usize> = (0..layout.extensions.len())
            .filter(|&e| {
                let p = &layout.extensions[e];
                p.cause == cause && p.term == Term::JointAngle { joint: j - 1 }
            })
            .collect();
        if angle_params.is_empty() {
            continue;
        }
        let resid = as_joint_angle_urad(model, split, after, &after.test_err, j - 1);
        // This joint's angle change by the cause per test row (µrad).
        let contribution: Vec<f64> = (0..n_test)
            .map(|r| {
                angle_params
                    .iter()
                    .map(|&e| after.cal.params.extension[e] * after.test_regs.row(r)[e] * 1e6)
                    .sum()
            })
            .collect();
        let before: Vec<f64> = resid
            .iter()
            .zip(&contribution)
            .map(|(r, c)| r + c)
            .collect();
        let base = report::RegressorPlot {
            file: format!("{}_joint{j}", cause.name()),
            title: format!("{}: joint {j}", cause.name()),
            y_label: format!("residual as joint {j} angle (µrad)"),
            before,
            after: resid,
            ..Default::default()
        };
        if let [e] = angle_params[..] {
            let axis = cause.model().plot_axis(layout.extensions[e].term);
            out.push(report::RegressorPlot {
                x_label: axis.label,
                x: regressor(e).iter().map(|v| axis.sign * v).collect(),
                slope: axis.sign * after.cal.params.extension[e] * 1e6,
                ..base
            });
        } else {
            let q: Vec<f64> = split
                .test
                .rows
                .iter()
                .map(|&r| split.test.table.q_row(r)[j - 1])
                .collect();
            let mut curve: Vec<(f64, f64)> = q.iter().copied().zip(contribution).collect();
            curve.sort_by(|a, b| a.0.total_cmp(&b.0));
            out.push(report::RegressorPlot {
                x_label: cause
                    .model()
                    .plot_axis(Term::JointAngle { joint: j - 1 })
                    .label,
                x: q,
                curve,
                ..base
            });
        }
    }
    let prediction = Prediction::new(model, &after.cal.params);
    let mut scratch = prediction.scratch();
    for (e, p) in layout.extensions.iter().enumerate() {
        if p.cause != cause {
            continue;
        }
        let value = after.cal.params.extension[e];
        let g = regressor(e);
        match p.term {
            Term::Bend { joint, about } if joints.contains(&(joint + 1)) => {
                // The residual as the rotation about this bending axis that would explain it (µrad).
                let local = Vector3::ith(about, 1.0);
                let resid: Vec<f64> = (0..n_test)
                    .map(|r| {
                        let q = split.test.table.q_row(split.test.rows[r]);
                        prediction.physical(&after.test_regs, r, q, &mut scratch);
                        let s = &scratch;
                        let (w, o) =
                            prediction
                                .chain()
                                .bend_axis(&s.chain, joint, &local, &s.bend[joint]);
                        let d = w.cross(&(s.chain.p_tracker - o));
                        let n2 = d.norm_squared();
                        if n2 >= MIN_PLOT_LEVER_M * MIN_PLOT_LEVER_M {
                            -after.test_err[r].dot(&d) / n2 * 1e6
                        } else {
                            f64::NAN
                        }
                    })
                    .collect();
                let axis = cause.model().plot_axis(p.term);
                out.push(report::RegressorPlot {
                    file: format!(
                        "{}_joint{}_{}",
                        cause.name(),
                        joint + 1,
                        crate::extensions::axis_name(about)
                    ),
                    title: format!(
                        "{}: joint {} about {}",
                        cause.name(),
                        joint + 1,
                        crate::extensions::axis_name(about)
                    ),
                    x_label: axis.label,
                    y_label: format!(
                        "residual as bending of joint {} about {} (µrad)",
                        joint + 1,
                        crate::extensions::axis_name(about)
                    ),
                    x: g.iter().map(|v| axis.sign * v).collect(),
                    before: resid
                        .iter()
                        .zip(&g)
                        .map(|(r, g)| r + value * g * 1e6)
                        .collect(),
                    after: resid,
                    slope: axis.sign * value * 1e6,
                    curve: Vec::new(),
                });
            }
            Term::Growth if growth => {
                let t = after.cal.params.t_tracker_base.translation.vector;
                let rel = |err: &[Vector3<f64>]| -> Vec<f64> {
                    split
                        .test
                        .rows
                        .iter()
                        .zip(err)
                        .map(|(&r, e)| {
                            let lever = Vector3::from(split.test.table.position[r]) - t;
                            -e.dot(&lever) / lever.norm_squared() * 1e6
                        })
                        .collect()
                };
                out.push(report::RegressorPlot {
                    file: format!("{}_growth", cause.name()),
                    title: format!("{}: link growth", cause.name()),
                    x_label: cause.model().plot_axis(p.term).label,
                    y_label: "residual as growth (ppm)".into(),
                    before: rel(&after.test_err)
                        .iter()
                        .zip(&g)
                        .map(|(r, g)| r + value * g * 1e6)
                        .collect(),
                    after: rel(&after.test_err),
                    x: g,
                    slope: value * 1e6,
                    curve: Vec::new(),
                });
            }
            _ => {}
        }
    }
    out
}

/// Training `χ²` drop of `big` over `small` as a normal `z`, with the variance factor of `big`.
///
/// The degrees of freedom are the identifiable parameters `big` adds. When its rank does not grow
/// (the models are not nested: adding joint compliance to link deflection hands the bending about the
/// next joint's axis to the compliance, and weakly determined combinations fall below the rank
/// threshold differently), they are the parameters it adds, a conservative count.
fn train_z(small: &Calibration, big: &Calibration) -> f64 {
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
fn explained_correlation(before: &[Vector3<f64>], after: &[Vector3<f64>]) -> f64 {
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
fn cause_parameters(cal: &Calibration, cause: Cause) -> Vec<(FoundParameter, Term, bool)> {
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

/// The parameters of `cause` in `cal` whose value is physically impossible by more than `joint_z`
/// standard deviations (and determined on their own), with the reason of the first.
fn impossible_parameters(
    cal: &Calibration,
    cause: Cause,
    joint_z: f64,
) -> Option<(String, Vec<FoundParameter>)> {
    let model = cause.model();
    let mut reason = None;
    let bad: Vec<FoundParameter> = cause_parameters(cal, cause)
        .into_iter()
        .filter(|(p, _, alone)| {
            *alone
                && p.sigma > 0.0
                && (p.value / p.sigma).abs() > joint_z
                && model.impossible(p.value).is_some()
        })
        .map(|(p, _, _)| {
            reason.get_or_insert(model.impossible(p.value).unwrap_or_default());
            p
        })
        .collect();
    reason.map(|r| (r.to_string(), bad))
}

/// 1-based joints of the parameters `params`, ascending, each once.
fn joints_of(params: &[FoundParameter]) -> Vec<usize> {
    let set: std::collections::BTreeSet<usize> = params
        .iter()
        .filter_map(|p| p.term.and_then(Term::joint).map(|j| j + 1))
        .collect();
    set.into_iter().collect()
}

/// The parameters as `name value ± sigma unit`, joined by `; `.
fn parameter_values(cause: Cause, params: &[FoundParameter]) -> String {
    params
        .iter()
        .map(|p| {
            format!(
                "{} {:.3e} ± {:.1e} {}{}",
                p.name,
                p.value,
                p.sigma,
                p.unit,
                cause.model().remark(p.value)
            )
        })
        .collect::<Vec<_>>()
        .join("; ")
}

/// The evidence sentence of a finding of `cause` at `joints` (1-based; with `growth` when the link
/// growth is named too): what the residual correlates with, the values of the parameters that name
/// them (beyond `joint_z` standard deviations), and why not the nearest rival.
fn evidence(
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
            "residual correlates with {} (r = {r:.2}); identified {}",
            model.evidence_subject(&joint_words(joints)),
            parameter_values(cause, &named)
        )
    };
    if let Some(rv) = rival {
        s.push_str(&format!("; {}", rv.why_not));
    }
    s
}

/// The probe of `rivals` with the largest held-out gain that `cause` does not model itself.
fn best_rival_probe(rivals: &[unexplained::Probe], cause: Cause) -> Option<&unexplained::Probe> {
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
fn nearest_rival(
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

/// What a forward selection ends with.
struct Selection {
    /// The final model.
    current: Evaluated,
    /// The models fitted, kinematic first.
    steps: Vec<Step>,
    /// The causes adopted, in order (joints and evidence filled later, from the final model).
    findings: Vec<Finding>,
    /// Pairs `(cause, its companion)` adopted together ([`companion`]): of the two, one that names no
    /// joint is not named.
    companions: Vec<(Cause, Cause)>,
}

/// The cause fitted alongside `cause` when it is tried and the other is not in the model yet:
/// joint compliance with link deflection. Bending of a joint about an axis that is the next joint's
/// axis line is that joint's compliance, so link deflection leaves those axes to the compliance
/// ([`crate::extensions::link_deflection::modelled_axes`]); fitted without it, a real bending about
/// such an axis makes the other bending parameters take it up with impossible signs, and the
/// compliance alone then takes the wrong joints' names.
fn companion(cause: Cause) -> Option<Cause> {
    (cause == Cause::LinkDeflection).then_some(Cause::JointCompliance)
}

/// What a selection adds to across passes.
struct Bookkeeping<'b> {
    round: &'b mut usize,
    trials: &'b mut Vec<Trial>,
    health: &'b mut Health,
    progress: &'b mut dyn FnMut(&str),
    /// Every model fitted so far by its name (`None`: too few poses), so that a selection run again
    /// after a rejection does not refit what it fitted before (the fits are deterministic).
    fits: &'b mut std::collections::BTreeMap<String, Option<Evaluated>>,
    /// The rival probes on each model's residual, by the model's name.
    rivals: &'b mut std::collections::BTreeMap<String, Vec<unexplained::Probe>>,
}

/// Forward selection from `start` over `candidates`: each round extends the current model by every
/// remaining candidate, judges each ([`Trial`]) and adopts the significant one with the largest
/// held-out `z`, until none is significant. Impossible physics does not stop a candidate here: fitted
/// alone, a cause often stands in for another one with a wrong sign somewhere, which the joint fit
/// with that other cause then puts right; [`invalid_finding`] judges the final joint fit.
fn select(
    model: &Model,
    split: &Split<'_>,
    start: Evaluated,
    candidates: &[Cause],
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
                let mut spec = current.spec.with(cause);
                if let Some(c) = companion(cause).filter(|c| candidates.contains(c)) {
                    spec = spec.with(c);
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
fn fit_candidates(
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
fn evaluate_in_parallel(
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
fn names_nothing(cal: &Calibration, cause: Cause, joint_z: f64) -> bool {
    !cause_parameters(cal, cause)
        .iter()
        .any(|(p, _, alone)| *alone && p.sigma > 0.0 && (p.value / p.sigma).abs() > joint_z)
}

/// The first cause adopted by `sel` that does not hold in the final joint fit, one whose named
/// parameters are impossible, as a rejection.
fn invalid_finding(sel: &Selection, options: &DiagnoseOptions) -> Option<Rejected> {
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

/// The models of a selection made on a subsample (`steps`, kinematic first), each refitted on every
/// pose of `split`, starting at its fit on the subsample (`fits` by name; `kinematic` for the first):
/// `kinematic_every_pose` for the kinematic model (refitted beside the screening), the others here.
/// The refits are independent of each other and run in parallel ([`fit_candidates`]' way: results in
/// the order of `steps`, the first error returned, a caller's cancellation relayed to the fits).
#[allow(clippy::too_many_arguments)]
fn confirm_on_every_pose(
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
fn refigure_findings(findings: &mut [Finding], all: &[Evaluated]) {
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

/// Diagnoses `table` (all rows; `name` names it in messages) for `model`.
///
/// Errors: input the calibration refuses (too few poses, a bad `sigma`), or too few poses to hold out
/// a test set.
pub fn diagnose(
    model: &Model,
    table: &MeasurementTable,
    name: &str,
    options: &DiagnoseOptions,
) -> Result<Diagnosis> {
    diagnose_with_progress(model, table, name, options, &mut |_| {})
}

/// [`diagnose`], calling `progress` with a short line before each fit.
pub fn diagnose_with_progress(
    model: &Model,
    table: &MeasurementTable,
    name: &str,
    options: &DiagnoseOptions,
    progress: &mut dyn FnMut(&str),
) -> Result<Diagnosis> {
    let (train_rows, test_rows) = split_by_pose(table, options.test_fraction, options.seed);
    if test_rows.is_empty() {
        return Err(CalibError::BadValue {
            context: name.to_string(),
            field: "pose".into(),
            value: format!("{} poses", table.rows_by_pose().len()),
            problem: "diagnose needs poses to hold out: give more poses or a larger test fraction"
                .into(),
        });
    }
    let split = Split {
        test_pose: campaigns::pose_ids(table, &test_rows),
        train: Dataset {
            table,
            rows: train_rows,
            name: format!("{name} (training set)"),
        },
        test: Dataset {
            table,
            rows: test_rows,
            name: format!("{name} (test set)"),
        },
    };
    let mut usable: Vec<Cause> = Vec::new();
    let mut not_tried: Vec<NotTried> = Vec::new();
    for &c in &options.candidates {
        match c.model().usable(model, table) {
            Ok(()) => usable.push(c),
            Err(reason) => not_tried.push(NotTried { cause: c, reason }),
        }
    }
    // With many poses the candidates are screened on a subsample ([`screening`]).
    let sub = screening::subsample(&split, options.screen_poses, options.seed);
    let screen = sub.as_ref().unwrap_or(&split);
    progress("kinematic");
    let kinematic = evaluate(model, screen, &ModelSpec::kinematic(), options, Start::Cold)?;
    let mut health = kinematic.cal.report.health;
    let mut trials = Vec::new();
    // Forward selection, then the adopted causes checked in their joint fit: one whose named
    // parameters are impossible there (or that names nothing) is rejected, and the selection runs
    // again without it (it may have stood in for another cause), until every adopted cause holds.
    let mut rejected: Vec<Rejected> = Vec::new();
    let mut round = 0;
    let mut fits = std::collections::BTreeMap::new();
    let mut rival_probes = std::collections::BTreeMap::new();
    // Screened on a subsample: the kinematic model (the first step of every selection) is refitted
    // on every pose on a thread of its own while the candidates are screened, where the rounds leave
    // cores idle (a round waits for its slowest candidate). A selection that fails or is cancelled
    // stops it at its next checkpoint.
    let every_pose_relay = crate::cancel::Relay::new();
    let (selection, kinematic_every_pose) = std::thread::scope(|scope| {
        let every_pose = sub.as_ref().map(|_| {
            progress("kinematic (every pose, beside the screening)");
            let (split, kinematic, relay) = (&split, &kinematic, &every_pose_relay);
            scope.spawn(move || {
                relay.run(|| {
                    evaluate(
                        model,
                        split,
                        &ModelSpec::kinematic(),
                        options,
                        Start::Same(kinematic),
                    )
                })
            })
        });
        let selection = (|| -> Result<Selection> {
            loop {
                let candidates: Vec<Cause> = usable
                    .iter()
                    .copied()
                    .filter(|c| rejected.iter().all(|r| r.cause != *c))
                    .collect();
                let sel = select(
                    model,
                    screen,
                    kinematic.clone(),
                    &candidates,
                    options,
                    &mut Bookkeeping {
                        round: &mut round,
                        trials: &mut trials,
                        health: &mut health,
                        progress,
                        fits: &mut fits,
                        rivals: &mut rival_probes,
                    },
                )?;
                match invalid_finding(&sel, options) {
                    None => return Ok(sel),
                    Some(r) => rejected.push(r),
                }
            }
        })();
        if selection.is_err() {
            every_pose_relay.stop();
        }
        let kinematic_every_pose = every_pose.map(|h| match h.join() {
            Ok(fit) => fit,
            Err(panic) => std::panic::resume_unwind(panic),
        });
        (selection, kinematic_every_pose)
    });
    let Selection {
        current,
        steps,
        mut findings,
        companions,
    } = selection?;
    // Screened on a subsample: the adopted models refitted on every pose, and the findings' figures
    // from those fits.
    let (current, steps, kinematic) = match &sub {
        None => (current, steps, kinematic),
        Some(_) => {
            let fits_all = confirm_on_every_pose(
                model,
                &split,
                &steps,
                &fits,
                &kinematic,
                kinematic_every_pose.expect("fitted beside the screening")?,
                options,
                progress,
                &mut health,
            )?;
            refigure_findings(&mut findings, &fits_all);
            let steps = fits_all.iter().map(|e| e.step.clone()).collect();
            let mut fits_all = fits_all.into_iter();
            let kinematic = fits_all.next().expect("the kinematic step");
            let current = fits_all.last().unwrap_or_else(|| kinematic.clone());
            (current, steps, kinematic)
        }
    };
    let mut plots = report::PlotData {
        test_errors_kinematic_m: kinematic.test_err.iter().map(|e| e.norm()).collect(),
        ..Default::default()
    };
    drop(kinematic);
    // Joints, values and evidence from the final model, where every adopted cause is fitted jointly
    // (a cause adopted early may have taken up part of a later one before that was in the model).
    for f in &mut findings {
        let cause = f.cause;
        let params = cause_parameters(&current.cal, cause);
        let z_of = |p: &FoundParameter| {
            if p.sigma > 0.0 {
                (p.value / p.sigma).abs()
            } else {
                0.0
            }
        };
        let named: Vec<FoundParameter> = params
            .iter()
            .filter(|(p, term, alone)| {
                matches!(term, Term::JointAngle { .. } | Term::Bend { .. })
                    && *alone
                    && z_of(p) > options.joint_z
            })
            .map(|(p, _, _)| p.clone())
            .collect();
        f.joints = joints_of(&named);
        let growth = params
            .iter()
            .any(|(p, term, alone)| *term == Term::Growth && *alone && z_of(p) > options.joint_z);
        f.parameters = params.into_iter().map(|(p, _, _)| p).collect();
        f.evidence = evidence(
            cause,
            &f.joints,
            &f.parameters,
            f.r,
            growth,
            f.rival.as_ref(),
            options.joint_z,
        );
        plots.regressors.extend(finding_plots(
            model, &split, &current, cause, &f.joints, growth,
        ));
    }
    // Of a cause and its companion adopted together, one that names no joint on its own is not named
    // (the companion first: when both name none, the cause stays as adopted).
    for &(cause, comp) in &companions {
        let joints_of_cause = |c: Cause| {
            findings
                .iter()
                .find(|f| f.cause == c)
                .map(|f| f.joints.is_empty())
        };
        if joints_of_cause(comp) == Some(true) {
            findings.retain(|f| f.cause != comp);
        } else if joints_of_cause(cause) == Some(true) {
            // Named without a joint only when the final model without it is worse on both tests.
            let mut reduced = current.spec.clone();
            reduced.causes.retain(|c| *c != cause);
            progress(&reduced.name());
            let without = match (fits.get(&reduced.name()), &sub) {
                (Some(Some(c)), None) => c.clone(),
                (Some(Some(c)), Some(_)) => {
                    evaluate(model, &split, &reduced, options, Start::Same(c))?
                }
                _ => evaluate(model, &split, &reduced, options, Start::Cold)?,
            };
            let tz = significance::paired(&without.pose_sq, &current.pose_sq).z;
            let trz = train_z(&without.cal, &current.cal);
            if tz > significance::normal_upper_quantile(options.held_out_alpha)
                && trz > significance::normal_upper_quantile(options.alpha)
            {
                continue;
            }
            let why_not = format!(
                "not {cause}, fitted with it: none of its parameters differs from zero by more \
                 than {} standard deviations on its own, and the final model without it predicts \
                 the held-out poses as well (z = {tz:.1}, training z = {trz:.1}), so only {comp} \
                 is named",
                options.joint_z
            );
            let gain = findings
                .iter()
                .find(|f| f.cause == cause)
                .map_or(0.0, |f| f.gain);
            findings.retain(|f| f.cause != cause);
            if let Some(f) = findings.iter_mut().find(|f| f.cause == comp) {
                f.rival = Some(Rival {
                    name: cause.to_string(),
                    gain,
                    why_not,
                });
                f.evidence = evidence(
                    comp,
                    &f.joints,
                    &f.parameters,
                    f.r,
                    false,
                    f.rival.as_ref(),
                    options.joint_z,
                );
            }
        }
    }
    drop(fits);
    let (noise_floor_m, noise_floor_source) = match options.noise_floor_m {
        Some(v) => (v, "given (--noise-floor)".to_string()),
        None => noise_floor::estimate(table, &split.test.rows, &options.calibration.noise),
    };
    crate::cancel::checkpoint()?;
    progress("unexplained structure");
    let unexplained =
        unexplained::analyse(model, &split, &current, noise_floor_m, options, rejected)?;
    plots.test_errors_final_m = current.test_err.iter().map(|e| e.norm()).collect();
    if let Some(j) = unexplained.correlates_with.as_ref().and_then(|p| p.joint) {
        plots.unexplained = Some(report::RegressorPlot {
            file: format!("unexplained_joint{j}"),
            title: format!("unexplained: residual against the angle of joint {j}"),
            x_label: format!("q{j} (rad)"),
            y_label: format!("residual as joint {j} angle (µrad)"),
            x: split
                .test
                .rows
                .iter()
                .map(|&r| table.q_row(r)[j - 1])
                .collect(),
            before: as_joint_angle_urad(model, &split, &current, &current.test_err, j - 1),
            after: Vec::new(),
            slope: 0.0,
            curve: Vec::new(),
        });
    }
    Ok(Diagnosis {
        robot: model.name().to_string(),
        n_train: split
            .train
            .rows
            .iter()
            .map(|&r| table.pose_key(r))
            .collect::<std::collections::BTreeSet<_>>()
            .len(),
        n_test: split
            .test_pose
            .iter()
            .collect::<std::collections::BTreeSet<_>>()
            .len(),
        noise_floor_m,
        noise_floor_source,
        steps,
        findings,
        unexplained,
        model: current.spec.clone(),
        trials,
        not_tried,
        campaigns: campaigns::report(&split, &current, options.alpha),
        screening: sub.as_ref().map(screening::record),
        alpha: options.alpha,
        seed: options.seed,
        health,
        plots,
    })
}
