//! Registering a measurement campaign: the tracker was moved (or the reflector re-seated), the robot
//! was not. Only the campaign's tracker-to-base transform (and, with `target`, its target offset) is
//! fitted to its poses; every robot parameter, extension value and learned correction is kept.
//!
//! With `T_c` the campaign's `T_tracker_base` and `y(q)` the model's target position in the robot's
//! base frame (kinematic chain, extensions, the learned correction turned into the base frame), the
//! prediction is `p = T_c y(q)`. The fit starts from the closed-form rigid fit (Kabsch) of `y` to the
//! measured points and refines `T_c` (and the target) by Levenberg–Marquardt with the analytic Jacobian
//! ([`crate::fit::problem::KinematicProblem`], only the campaign's columns active). The learned correction
//! `R_c R_0ᵀ r̂(q)` turns with `T_c`: it is subtracted from the measurements at the current `R_c`,
//! and the fit repeated until `R_c` settles (the correction is micrometres against metres of lever:
//! two rounds).
//!
//! The registration's covariance is `σ̂² (JᵀWJ)⁻¹` of its own parameters, with `σ̂²` from its
//! residuals when there are degrees of freedom to spare, so its standard deviations hold for a
//! registration from few poses. Its residual is compared with the model's own (held-out when known):
//! a registration that fits much worse than the model did says that the robot changed (a crash, a
//! repaired joint, another payload), not only the tracker.

use crate::error::{CalibError, Result};
use crate::fit::problem::{KinematicProblem, NoiseModel, Observations};
use crate::fit::start::kabsch;
use crate::lm::{LmOptions, LmWorkspace, MinimizationReport, minimize};
use crate::model::extensions::{ExtensionSettings, Regressors};
use crate::model::learned::LearnedResidual;
use crate::model::params::{KinematicParams, ParamLayout, ParameterScales};
use crate::model::predict::Prediction;
use crate::model::stats::{ResidualStats, stats_of_errors};
use nalgebra::{DMatrix, Vector3};
use sim::Model;
use sim::lie::Pose;
use sim::measurement_table::MeasurementTable;

/// Settings of [`register`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RegisterOptions {
    /// Also fit the campaign's own target offset (a re-seated reflector). A model without
    /// per-campaign targets gets one for every campaign (copies of the shared target, so their
    /// predictions do not change).
    pub target: bool,
    /// Refit the registration of this campaign, which the model must know, instead of adding one.
    pub campaign: Option<i64>,
    /// Measurement noise when the table has no `sigma` column.
    pub noise: NoiseModel,
    /// Solver settings.
    pub lm: LmOptions,
    /// Expected parameter magnitudes (column scaling).
    pub scales: ParameterScales,
}

/// A registration's residual is "well above" the model's when their RMS ratio exceeds this and the
/// difference is significant ([`MODEL_CHANGE_Z`]).
pub const MODEL_CHANGE_RATIO: f64 = 1.5;
/// Normal `z` (one-sided, p ≈ 0.001) of the variance ratio beyond which the difference counts.
pub const MODEL_CHANGE_Z: f64 = 3.09;

/// What a registration found.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RegistrationReport {
    /// The campaign id registered.
    pub campaign: i64,
    /// Whether an existing campaign's registration was replaced (else one was added).
    pub replaced: bool,
    /// Rows and distinct poses used.
    pub n_rows: usize,
    /// Distinct poses used.
    pub n_poses: usize,
    /// Position errors of the registered model on those rows (m).
    pub residual: ResidualStats,
    /// The model's own RMS error (held-out when the model file has it, else on its calibration
    /// rows; m).
    pub model_rms_m: Option<f64>,
    /// `residual.rms_m / model_rms_m`.
    pub ratio: Option<f64>,
    /// The registered `T_tracker_base`: translation (m) and rotation matrix rows.
    pub translation_m: [f64; 3],
    /// Its rotation, row by row.
    pub rotation: [[f64; 3]; 3],
    /// Covariance of the registration's left-perturbation twist `β = [ω; v]` (tracker frame; rad,
    /// m), `T ← exp([β]) T`, 6 × 6 row by row: the uncertainty of the registered tracker pose.
    pub covariance: [[f64; 6]; 6],
    /// Standard deviation of the base origin's position in the tracker frame (m, per axis).
    pub sigma_translation_m: [f64; 3],
    /// Standard deviation of the rotation about each tracker axis (rad).
    pub sigma_rotation_rad: [f64; 3],
    /// The target fitted with `target` (flange frame, m).
    pub target_m: Option<[f64; 3]>,
    /// The variance factor `σ̂²` (dimensionless) that scales `covariance`: χ²/dof of the
    /// registration's weighted residuals, or 1 when no degrees of freedom are left. Under a correct
    /// noise model it is χ²(dof)/dof distributed, so the standardised errors of a registration from
    /// few poses follow Student's t, not the normal.
    pub variance_factor: f64,
    /// Where the variance factor comes from.
    pub variance_factor_source: String,
    /// Solver outcome of the last round.
    pub solver: MinimizationReport,
    /// What a user should know (the robot changed, few poses, a replaced registration).
    pub warnings: Vec<String>,
}

impl RegistrationReport {
    /// The report as text for a terminal.
    pub fn text(&self) -> String {
        let um = |v: f64| v * 1e6;
        let mut s = format!(
            "{} campaign {} from {} rows ({} poses): residual RMS {:.1} µm, mean {:.1} µm, max {:.1} µm",
            if self.replaced {
                "re-registered"
            } else {
                "registered"
            },
            self.campaign,
            self.n_rows,
            self.n_poses,
            um(self.residual.rms_m),
            um(self.residual.mean_m),
            um(self.residual.max_m)
        );
        if let (Some(m), Some(r)) = (self.model_rms_m, self.ratio) {
            s.push_str(&format!(" ({r:.2}× the model's {:.1} µm)", um(m)));
        }
        s.push('\n');
        let t = self.translation_m;
        s.push_str(&format!(
            "T_tracker_base: translation ({:.6}, {:.6}, {:.6}) m ± ({:.1}, {:.1}, {:.1}) µm; rotation σ \
             ({:.1}, {:.1}, {:.1}) µrad\n",
            t[0],
            t[1],
            t[2],
            um(self.sigma_translation_m[0]),
            um(self.sigma_translation_m[1]),
            um(self.sigma_translation_m[2]),
            um(self.sigma_rotation_rad[0]),
            um(self.sigma_rotation_rad[1]),
            um(self.sigma_rotation_rad[2])
        ));
        if let Some(p) = self.target_m {
            s.push_str(&format!(
                "target (flange frame): ({:.6}, {:.6}, {:.6}) m\n",
                p[0], p[1], p[2]
            ));
        }
        for w in &self.warnings {
            s.push_str(&format!("warning: {w}\n"));
        }
        s
    }
}

/// The model with the campaign registered, and what the registration found.
#[derive(Clone, Debug)]
pub struct Registration {
    /// The model's parameters with the campaign registered; rows that name no campaign default to
    /// it ([`KinematicParams::default_campaign`]).
    pub params: KinematicParams,
    /// The report.
    pub report: RegistrationReport,
    /// Covariance of the registration's parameters, in the layout of `params` at the campaign's
    /// indices ([`Registration::indices`]), physical units.
    pub covariance: DMatrix<f64>,
    /// The layout indices of the fitted parameters (base twist, then the target's).
    pub indices: Vec<usize>,
}

/// One line listing campaign ids.
fn id_list(ids: &[i64]) -> String {
    ids.iter()
        .map(|c| c.to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

/// Registers the campaign measured in `table` (every row; `name` names it in errors) for the model
/// `params` of `model` (with its extension settings and learned correction); `model_rms_m` is the
/// model's own RMS error, for the warning that the robot changed.
///
/// Errors (one line each): a table whose `campaign` column holds several ids, a campaign the model
/// already registers (without [`RegisterOptions::campaign`]), a [`RegisterOptions::campaign`] the
/// model does not know or that the table contradicts, a table without the columns the model's
/// extensions read, and fewer than 3 distinct poses (6 with `target`).
#[allow(clippy::too_many_arguments)]
pub fn register(
    model: &Model,
    params: &KinematicParams,
    extensions: Option<&ExtensionSettings>,
    learned: Option<&LearnedResidual>,
    model_rms_m: Option<f64>,
    table: &MeasurementTable,
    name: &str,
    options: &RegisterOptions,
) -> Result<Registration> {
    let bad = |field: &str, value: String, problem: String| CalibError::BadValue {
        context: name.to_string(),
        field: field.into(),
        value,
        problem,
    };
    if table.n_joints != model.nq() {
        return Err(bad(
            "q1..qN",
            format!("{} joint columns", table.n_joints),
            format!(
                "the model's robot '{}' has {} joints",
                model.name(),
                model.nq()
            ),
        ));
    }
    let in_table = table.campaign_ids();
    if in_table.len() > 1 {
        return Err(bad(
            "campaign",
            id_list(&in_table),
            "register fits one campaign at a time: give the rows of one campaign".into(),
        ));
    }
    let (id, replaced) = match options.campaign {
        Some(c) => {
            if params.campaign_index(c).is_none() {
                return Err(CalibError::BadValue {
                    context: "--campaign".into(),
                    field: "campaign".into(),
                    value: c.to_string(),
                    problem: format!(
                        "the model knows campaigns {}; without --campaign, register adds the data as a \
                         new campaign",
                        id_list(&params.campaign_ids)
                    ),
                });
            }
            if let Some(&t) = in_table.first()
                && t != c
            {
                return Err(bad(
                    "campaign",
                    t.to_string(),
                    format!(
                        "--campaign {c} asks to re-register campaign {c}, but the rows are of campaign {t}"
                    ),
                ));
            }
            (c, true)
        }
        None => match in_table.first() {
            Some(&t) if params.campaign_index(t).is_some() => {
                return Err(bad(
                    "campaign",
                    t.to_string(),
                    format!(
                        "the model already registers campaign {t} (it knows {}); --campaign {t} refits \
                         its registration",
                        id_list(&params.campaign_ids)
                    ),
                ));
            }
            Some(&t) => (t, false),
            None => (
                params.campaign_ids.iter().max().copied().unwrap_or(0) + 1,
                false,
            ),
        },
    };
    let rows: Vec<usize> = (0..table.len()).collect();
    let mut obs = Observations::from_table(table, &rows, &options.noise, name)?;
    if obs.orientation.is_some() != params.r_flange_target.is_some() {
        return Err(bad(
            "qw, qx, qy, qz",
            if obs.orientation.is_some() {
                "present"
            } else {
                "absent"
            }
            .into(),
            "the data must have orientation columns exactly when the model has a target orientation"
                .into(),
        ));
    }
    if let Some(s) = extensions {
        s.check_table(table, name)?;
        obs.ext = Regressors::build(model, s, table, &rows, name, Some(params))?;
    }
    let needed = if options.target { 6 } else { 3 };
    if obs.n_configurations() < needed {
        return Err(bad(
            "pose",
            format!("{} distinct poses", obs.n_configurations()),
            format!(
                "at least {needed} are needed to register a campaign{}",
                if options.target {
                    " with its target"
                } else {
                    ""
                }
            ),
        ));
    }
    // The learned correction of each row in the first campaign's frame, and the model's target in
    // that frame (for the closed-form start).
    let n = obs.len();
    let base_model = Prediction::new(model, params).with_learned(learned);
    let mut s = base_model.scratch();
    let mut correction = Vec::with_capacity(n);
    let mut in_first = Vec::with_capacity(n);
    for r in 0..n {
        let physical = base_model
            .physical_in(&obs.ext, r, obs.q_row(r), 0, &mut s)
            .p_tracker;
        let full = base_model.row_in(&obs.ext, r, obs.q_row(r), 0, &mut s);
        correction.push(full - physical);
        in_first.push(full);
    }
    // The parameters with the campaign: added (closed-form start), or the existing one refitted.
    let t0_inv = params.t_tracker_base.inverse();
    let y: Vec<Vector3<f64>> = in_first
        .iter()
        .map(|p| (t0_inv * nalgebra::Point3::from(*p)).coords)
        .collect();
    let start = kabsch(&y, &obs.position);
    let mut reg = params.clone();
    let c = match reg.campaign_index(id) {
        Some(c) => {
            if c == 0 {
                reg.t_tracker_base = start;
            } else {
                reg.campaigns[c - 1].t_tracker_base = start;
            }
            c
        }
        None => {
            let mut ids = reg.campaign_ids.clone();
            ids.push(id);
            let mut starts: Vec<Pose> = reg.campaigns.iter().map(|c| c.t_tracker_base).collect();
            starts.push(start);
            let own = reg.has_campaign_targets();
            let old = reg.campaigns.clone();
            reg = reg.with_campaigns(&ids, &starts, own);
            for (new, old) in reg.campaigns.iter_mut().zip(&old) {
                *new = *old;
            }
            ids.len() - 1
        }
    };
    if options.target && !reg.has_campaign_targets() {
        if reg.n_campaigns() == 1 {
            return Err(bad(
                "--target",
                String::new(),
                "a model of one campaign fits its target in calibrate; register --target gives a further \
                 campaign its own target"
                    .into(),
            ));
        }
        reg = reg.with_own_targets();
    }
    if c == 0 && learned.is_some() {
        return Err(bad(
            "--campaign",
            id.to_string(),
            "the learned correction is expressed in the first campaign's tracker frame, which must stay: \
             register the moved tracker as a new campaign instead"
                .into(),
        ));
    }
    if options.target && c == 0 {
        return Err(bad(
            "--target",
            String::new(),
            "the first campaign's target is the shared one, fitted with the robot; re-register it without \
             --target"
                .into(),
        ));
    }
    reg.default_campaign = c;
    obs.campaign = Some(vec![id; n]);
    let layout = ParamLayout::for_params(model, &reg, obs.ext.params.clone());
    let mut active: Vec<usize> = (layout.campaign_base(c)..layout.campaign_base(c) + 6).collect();
    if options.target {
        let t = layout.campaign_target_position(c);
        active.extend(t..t + 3);
        if let Some(o) = layout.campaign_target_orientation(c) {
            active.extend(o..o + 3);
        }
    }
    let all_scales = options.scales.vector(&layout);
    let scales: Vec<f64> = active.iter().map(|&k| all_scales[k]).collect();
    let measured = obs.position.clone();
    let dim = obs.dim();
    let mut ws = LmWorkspace::new(n * dim, active.len());
    let mut solve = None;
    for _ in 0..5 {
        let frame = reg.t_tracker_base_of(c).rotation.matrix()
            * params.t_tracker_base.rotation.matrix().transpose();
        for ((p, m), l) in obs.position.iter_mut().zip(&measured).zip(&correction) {
            *p = m - frame * l;
        }
        let before = *reg.t_tracker_base_of(c);
        let mut prob = KinematicProblem::new(model, &obs, reg.clone(), active.clone());
        let out = minimize(&mut prob, &scales, &options.lm, &mut ws);
        reg = prob.into_params();
        solve = Some(out);
        let moved = (reg.t_tracker_base_of(c).rotation.matrix() - before.rotation.matrix()).amax();
        if learned.is_none() || moved < 1e-13 {
            break;
        }
    }
    let (report, sub) = solve.expect("at least one round");
    obs.position = measured;
    let residual = {
        let errors = Prediction::new(model, &reg)
            .with_learned(learned)
            .errors(&obs);
        stats_of_errors(&errors, &obs)
    };
    Ok(finish(
        Solved {
            params: reg,
            campaign: id,
            index: c,
            replaced,
            active,
            solver: report,
            subspace: sub,
            residual,
            n_poses: obs.n_poses(),
            n_residuals: n * dim,
        },
        model_rms_m,
        options,
    ))
}

/// A registration solved: what [`finish`] turns into its report.
pub(crate) struct Solved {
    /// The parameters with the campaign registered.
    pub params: KinematicParams,
    /// The campaign id.
    pub campaign: i64,
    /// Its index among the parameters' campaigns.
    pub index: usize,
    /// Whether an existing registration was replaced.
    pub replaced: bool,
    /// The fitted layout indices.
    pub active: Vec<usize>,
    /// The solver's outcome.
    pub solver: MinimizationReport,
    /// The rank decision at the solution (active parameters).
    pub subspace: crate::lm::Subspace,
    /// Position errors of the registered model on the rows.
    pub residual: ResidualStats,
    /// Distinct poses.
    pub n_poses: usize,
    /// Scalar residuals `m`.
    pub n_residuals: usize,
}

/// The report, covariance and warnings of a solved registration (in memory or streamed).
pub(crate) fn finish(
    solved: Solved,
    model_rms_m: Option<f64>,
    options: &RegisterOptions,
) -> Registration {
    let Solved {
        params: reg,
        campaign: id,
        index: c,
        replaced,
        active,
        solver: report,
        subspace: sub,
        residual,
        n_poses,
        n_residuals: m,
    } = solved;
    let mut warnings = Vec::new();
    let dof = m.saturating_sub(sub.rank);
    let (vf, source) = if dof > 0 {
        (report.cost_final / dof as f64, "residuals (χ²/dof)")
    } else {
        warnings.push(
            "as many equations as registration parameters: its standard deviations assume the noise model"
                .into(),
        );
        (1.0, "noise model (no degrees of freedom left)")
    };
    if sub.rank < active.len() {
        warnings.push(format!(
            "{} of the {} registration parameters are not determined by these poses (too few, or all alike)",
            active.len() - sub.rank,
            active.len()
        ));
    }
    let cov = sub.covariance(vf);
    let ratio = model_rms_m.filter(|m| *m > 0.0).map(|m| residual.rms_m / m);
    if let (Some(r), Some(mr)) = (ratio, model_rms_m) {
        // The variance ratio against 1, as a normal z with the registration's degrees of freedom.
        let z = (r * r - 1.0) * (dof.max(1) as f64 / 2.0).sqrt();
        if r > MODEL_CHANGE_RATIO && z > MODEL_CHANGE_Z {
            warnings.push(format!(
                "the registration residual ({:.1} µm RMS) is {r:.1}× the model's ({:.1} µm): the robot \
                 has changed, not only the tracker (recalibrate it, or check the data)",
                residual.rms_m * 1e6,
                mr * 1e6
            ));
        }
    }
    if replaced {
        warnings.push(format!("campaign {id}'s registration was replaced"));
    }
    // The base twist's covariance (the first 6 active parameters) and the σ of the origin.
    let mut beta = [[0.0; 6]; 6];
    for (i, row) in beta.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = cov[(i, j)];
        }
    }
    let base = *reg.t_tracker_base_of(c);
    let t = base.translation.vector;
    // The origin moves by ω × t + v = −[t] ω + v.
    let mut jt = nalgebra::Matrix3x6::zeros();
    jt.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&(-sim::lie::skew(&t)));
    jt.fixed_view_mut::<3, 3>(0, 3)
        .copy_from(&nalgebra::Matrix3::identity());
    let b6 = nalgebra::Matrix6::from_fn(|i, j| beta[i][j]);
    let ct = jt * b6 * jt.transpose();
    let sigma_translation_m = [0, 1, 2].map(|a| ct[(a, a)].max(0.0).sqrt());
    let sigma_rotation_rad = [0, 1, 2].map(|a| beta[a][a].max(0.0).sqrt());
    let r = base.rotation.matrix();
    let report = RegistrationReport {
        campaign: id,
        replaced,
        n_rows: residual.n,
        n_poses,
        residual,
        model_rms_m,
        ratio,
        translation_m: t.into(),
        rotation: [0, 1, 2].map(|i| [r[(i, 0)], r[(i, 1)], r[(i, 2)]]),
        covariance: beta,
        sigma_translation_m,
        sigma_rotation_rad,
        target_m: options.target.then(|| (*reg.p_flange_target_of(c)).into()),
        variance_factor: vf,
        variance_factor_source: source.into(),
        solver: report,
        warnings,
    };
    Registration {
        params: reg,
        report,
        covariance: cov,
        indices: active,
    }
}
