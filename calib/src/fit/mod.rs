//! The calibration procedure: start, base-and-target fit, full kinematic fit, covariance, identifiability,
//! validation, outliers. See the crate documentation for the model.
//!
//! 1. Start: the nominal robot with the target at the flange origin; `T_tracker_base` from the
//!    closed-form rigid fit (Kabsch) of the nominal flange positions to the measured points; with
//!    orientation, `R_flange_target` from the chordal mean of `(R_tracker_base R_base_flange)ᵀ R_measured`.
//! 2. "Before": only the tracker-to-base transform and the target are fitted (nominal joints), the
//!    reference for what calibration gains.
//! 3. "After": every parameter, in the identifiable subspace ([`crate::lm`]). With a robust loss, the
//!    fit is repeated with iteratively reweighted rows (IRLS) until the weights settle.
//! 4. Covariance `σ̂² D V_r Σ_r⁻² V_rᵀ D` with the variance factor `σ̂² = χ²/(m − rank)` estimated from the
//!    residuals (so a wrong absolute noise level does not distort the standard deviations; `χ²/dof`
//!    reports it).
//!
//! One module per job: [`start`] (the closed-form start and the generic rank), [`robust`] (losses and
//! IRLS), [`outliers`], [`extended`] (refits of extended models), [`learned_stage`], [`estimates`]
//! (parameters in reporting form), [`report`] (what it all says) and [`validation`] (held-out
//! errors: k-fold cross-validation by pose, a split, a test file).

mod estimates;
mod extended;
pub mod identifiability;
mod learned_stage;
mod model_file;
mod outliers;
pub mod plan;
pub mod problem;
pub mod register;
pub mod repeats;
pub mod report;
pub mod robust;
pub mod start;
pub mod stream;

pub use crate::model::predict::prediction_and_jacobian;
pub use crate::part::Part;
pub use extended::EQUILIBRIUM_REFITS;
pub use report::{
    CalibrationReport, Correlation, FitStage, LearnedStage, Outlier, ParameterEstimate,
    RobustSummary,
};
pub use robust::RobustLoss;
pub use start::{generic_rank, initial_params};

use crate::error::{CalibError, Result};
use crate::fit::identifiability::{Observability, describe_null_space};
use crate::fit::problem::{KinematicProblem, NoiseModel, Observations};
use crate::lm::{LmOptions, LmWorkspace, SolveHints, Subspace, minimize, minimize_with};
use crate::model::extensions::{ExtensionSettings, Regressors};
use crate::model::learned::LearnedResidual;
use crate::model::params::{KinematicParams, ParamLayout, ParameterScales};
use crate::model::spec::ModelSpec;
use crate::model::stats::residual_stats;
use estimates::{correlations, estimates};
use nalgebra::DMatrix;
use sim::Model;
use sim::measurement_table::MeasurementTable;

/// Settings of [`calibrate`].
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CalibrationOptions {
    /// Expected parameter magnitudes (column scaling).
    pub scales: ParameterScales,
    /// Measurement noise when the table has no `sigma` column.
    pub noise: NoiseModel,
    /// Solver settings.
    pub lm: LmOptions,
    /// Robust loss (IRLS), or `None` for plain least squares (default).
    pub robust: Option<RobustLoss>,
    /// Rows whose normalised residual norm exceeds this are reported as outliers. The normalised norm
    /// `t` is the row's weighted residual norm divided by a robust scale (the median norm over that of
    /// a Gaussian row), so `t²` follows χ² with 3 (6) degrees of freedom for Gaussian rows; `t > 5` then
    /// happens with probability 1.5e-5 (3.4e-4). A row must also exceed a tenth of the threshold in units
    /// of its own σ from the noise model, so that rounding-level residuals of noise-free data are never
    /// outliers. Default 5.
    pub outlier_threshold: f64,
    /// Without a robust loss, rows whose normalised residual norm `t` (as for
    /// [`CalibrationOptions::outlier_threshold`]) exceeds this after the fit are gross errors (a
    /// broken beam, a row from another file): they are excluded (weight 0), named in the report's
    /// `excluded` list and a warning, and the fit is repeated, up to [`GROSS_ERROR_ROUNDS`] times.
    /// Default 25: a Gaussian row exceeds it with probability below 1e-100, and rows of a model that
    /// misses an effect stay far below it (at most 6.8 for the kinematic model on
    /// `scenarios/iiwa7_all.toml`, 12.7 on the real UR10 series B). `f64::INFINITY` keeps every row.
    #[serde(default = "default_gross_error_threshold")]
    pub gross_error_threshold: f64,
    /// Seed of the learned models' cross-validation folds.
    pub learned_seed: u64,
    /// With several campaigns, give each its own target offset (a re-seated reflector) instead of
    /// one shared target. Default false.
    #[serde(default)]
    pub per_campaign_target: bool,
}

/// Most rounds of [`CalibrationOptions::gross_error_threshold`]'s exclusion.
pub const GROSS_ERROR_ROUNDS: usize = 3;

fn default_gross_error_threshold() -> f64 {
    25.0
}

impl Default for CalibrationOptions {
    fn default() -> Self {
        CalibrationOptions {
            scales: ParameterScales::default(),
            noise: NoiseModel::default(),
            lm: LmOptions::default(),
            robust: None,
            outlier_threshold: 5.0,
            gross_error_threshold: default_gross_error_threshold(),
            learned_seed: 0,
            per_campaign_target: false,
        }
    }
}

/// Some rows of a measurement table.
#[derive(Clone, Debug)]
pub struct Dataset<'a> {
    /// The table.
    pub table: &'a MeasurementTable,
    /// 0-based rows to use.
    pub rows: Vec<usize>,
    /// Name for messages: the file, then the part (`file (training set)`).
    pub name: String,
    /// Which part of the file's rows these are.
    pub part: Part,
}

impl<'a> Dataset<'a> {
    /// Every row of `table`.
    pub fn all(table: &'a MeasurementTable, name: &str) -> Self {
        Dataset {
            table,
            rows: (0..table.len()).collect(),
            name: name.to_string(),
            part: Part::All,
        }
    }

    /// The rows `rows` (0-based) of `table`, read from `file`, as its part `part`.
    pub fn new(table: &'a MeasurementTable, rows: Vec<usize>, file: &str, part: Part) -> Self {
        Dataset {
            table,
            rows,
            name: format!("{file}{}", part.suffix()),
            part,
        }
    }

    /// The rows `rows` (0-based rows of the table) of this data set's file, as its part `part`.
    pub fn part(&self, rows: Vec<usize>, part: Part) -> Self {
        Dataset {
            table: self.table,
            rows,
            name: format!("{}{}", self.name, part.suffix()),
            part,
        }
    }
}

/// A calibration: the estimate, its covariance and the report.
#[derive(Clone, Debug)]
pub struct Calibration {
    /// The calibrated parameters.
    pub params: KinematicParams,
    /// The nominal robot with only base and target fitted (the "before" model).
    pub before: KinematicParams,
    /// Their layout.
    pub layout: ParamLayout,
    /// Covariance of a step at the solution ([`ParamLayout`] order, physical units).
    pub covariance: DMatrix<f64>,
    /// The SVD split of the final scaled Jacobian.
    pub subspace: Subspace,
    /// The report.
    pub report: CalibrationReport,
    /// Settings of the model extensions (what their regressors are made from), if any.
    pub extensions: Option<ExtensionSettings>,
    /// The learned residual correction fitted after the physical model, if asked for.
    pub learned: Option<LearnedResidual>,
    /// The physical fit's parameters, when the learned stage changed `params` (`learned:adjoint`
    /// refits the registrations with its coefficients): what the physical model alone predicts.
    pub physical: Option<KinematicParams>,
}

/// What [`fit`] fits, where it starts, what it is judged on and what it leaves out: the one request
/// of the one fit entry point.
///
/// ```
/// # use calib::fit::{CalibrationOptions, FitRequest};
/// # use calib::model::ModelSpec;
/// let options = CalibrationOptions::default();
/// let kinematic = FitRequest::kinematic(&options);
/// let extended = FitRequest::new(&ModelSpec::parse("kinematic+joint_compliance").unwrap(), &options);
/// assert!(kinematic.model().causes.is_empty() && !extended.model().causes.is_empty());
/// ```
#[derive(Clone, Debug)]
pub struct FitRequest<'a> {
    model: ModelSpec,
    options: CalibrationOptions,
    test: Option<&'a Dataset<'a>>,
    warm: Option<WarmStart<'a>>,
    lean: bool,
}

impl<'a> FitRequest<'a> {
    /// The model `spec` (kinematic, causes identified jointly with it, then an optional learned
    /// correction) with `options`, from the closed-form start, judged on nothing but its own rows.
    pub fn new(spec: &ModelSpec, options: &CalibrationOptions) -> Self {
        FitRequest {
            model: spec.clone(),
            options: *options,
            test: None,
            warm: None,
            lean: false,
        }
    }

    /// The kinematic model alone (joint error twists, zero offsets, registration and target).
    pub fn kinematic(options: &CalibrationOptions) -> Self {
        Self::new(&ModelSpec::kinematic(), options)
    }

    /// Also judge the fit on `test` (never fitted): its report's `before.test` and `after.test`.
    /// `None` judges it on nothing.
    pub fn judged_on(mut self, test: Option<&'a Dataset<'a>>) -> Self {
        self.test = test;
        self
    }

    /// Start at `near`, a calibration of the same model on the same campaigns (all poses, where this
    /// fit takes a part of them, or a subsample of them): the same minimum as from the closed form,
    /// in fewer iterations. The fit also skips what such a fit's caller does not read (the training
    /// residual statistics and the outlier list of its report; see [`WarmStart`]). A fit whose rows
    /// lack one of `near`'s campaigns starts from the closed form after all.
    pub fn starting_at(mut self, near: &'a Calibration) -> Self {
        self.warm = Some(WarmStart::near(near));
        self.lean = true;
        self
    }

    /// A start prepared by the caller (the folds' shared normal equations).
    pub(crate) fn with_warm(mut self, warm: Option<WarmStart<'a>>) -> Self {
        self.lean = warm.is_some_and(|w| w.lean);
        self.warm = warm;
        self
    }

    /// The model fitted.
    pub fn model(&self) -> &ModelSpec {
        &self.model
    }

    /// The settings.
    pub fn options(&self) -> &CalibrationOptions {
        &self.options
    }

    /// The rows the fit is judged on, if any.
    pub fn test(&self) -> Option<&'a Dataset<'a>> {
        self.test
    }
}

/// Fits `request`'s model of the robot `model` to the rows of `data`: the one way to calibrate.
///
/// The stages, each a named function of this floor: the closed-form start ([`start`], Kabsch), the
/// base-and-target fit (the "before" model), the fit of every parameter with the gross-error
/// exclusion ([`outliers`]) or a robust loss ([`robust`]), the equilibrium refits of an extended
/// model ([`extended`]) and the learned stage ([`learned_stage`]).
///
/// Extensions take their regressor settings from the training rows ([`ExtensionSettings::for_data`]);
/// a cause that offers alternative settings is searched over them, keeping the one with the smallest
/// training `χ²` (thermal drift from time stamps alone: the warm-up time constants
/// [`crate::model::extensions::thermal_drift::WARM_UP_TAUS_S`]).
///
/// Errors only for unusable input: a joint count that does not fit the robot, a `sigma` ≤ 0, too
/// few distinct poses for the identifiable parameters ([`CalibError::TooFewPoses`], which names
/// [`Dataset::part`]), an extension the data cannot feed (thermal drift without `temp` or `t`,
/// compliance on a robot without inertials). A degenerate pose set is not an error: the report names
/// what it cannot identify.
pub fn fit(model: &Model, data: &Dataset<'_>, request: &FitRequest<'_>) -> Result<Calibration> {
    let spec = &request.model;
    let options = &request.options;
    let test = request.test;
    let warm = request.warm;
    let mut cal = if spec.causes.is_empty() {
        let stage = Stage {
            test,
            options,
            extensions: None,
            at: None,
            warm,
            same_before: None,
        };
        kinematic_fit(model, data, &stage)?
    } else {
        spec.check_joints(model.nq())?;
        let mut settings = ExtensionSettings::for_data(
            model,
            &spec.causes,
            &spec.joints,
            data.table,
            &data.rows,
            &data.name,
        )?;
        if let Some(com) = warm.and_then(|f| f.payload_com_m) {
            settings.payload_com_m = com;
        }
        let mut cal = extended::best_extended_fit(model, data, test, options, &settings, warm)?;
        if !request.lean {
            for c in &spec.causes {
                let notes = c.model().notes(&settings, model, data.table, &data.rows);
                cal.report.warnings.extend(notes);
            }
        }
        cal
    };
    cal.report.model = spec.clone();
    if let Some(kind) = spec.learned {
        crate::cancel::checkpoint()?;
        learned_stage::add_learned(model, &mut cal, kind, data, test, options)?;
    }
    Ok(cal)
}

/// Where a fit starts when a nearby calibration of the same model is known, instead of the closed-form
/// start: a cross-validation fold's fit ([`validation::cross_validate`]) at the calibration on every
/// pose, and diagnose's refit on every pose at its fit on a subsample (the first fit of an
/// extended model; each of its equilibrium refits then starts at the refit before). The minimum
/// lies within a few standard deviations of the start: Levenberg–Marquardt from there reaches the
/// same minimum as from the closed-form start (the convergence test is the same), in fewer
/// iterations, and without the Kabsch start. (Not the solution of another model: an extended model
/// started at a kinematic fit that absorbed a large unmodelled error can stop in another local
/// minimum, see `diagnose::Start`.) A lean fit also leaves out what its caller does not use: the
/// report's training residual statistics and its outlier list (the gross-error exclusion, which
/// changes the fit, stays).
#[derive(Clone, Copy, Debug)]
pub(crate) struct WarmStart<'a> {
    /// The calibration on every pose ("before": nominal joints, base and target fitted).
    pub before: &'a KinematicParams,
    /// Its physical parameters (before any learned stage changed them): where the full fit starts.
    pub physical: &'a KinematicParams,
    /// What `physical.extension` holds ([`ParamLayout::extensions`] of its calibration; empty for
    /// the kinematic model). A parameter of the fit's own extensions that is not among them starts
    /// at zero.
    pub extensions: &'a [crate::model::extensions::ExtensionParam],
    /// Leave out the training residual statistics and the outlier list of the report.
    pub lean: bool,
    /// The payload's centre of mass in the flange frame (m) that the calibration it starts from
    /// estimated ([`ExtensionSettings::payload_com_m`]), where an extended model's refits start.
    pub payload_com_m: Option<[f64; 3]>,
    /// The fold's normal equations and `R` factor at `physical`, when one pass over every row made
    /// them ([`validation`]'s fold shares).
    pub shared: Option<&'a FoldShare>,
}

/// A fold's shared work for its two solves: the base-and-target fit at the all-pose "before"
/// parameters and the full fit at the all-pose solution.
#[derive(Clone, Debug)]
pub(crate) struct FoldShare {
    /// For the base-and-target fit (its active parameters only).
    pub before: SolveShare,
    /// For the fit of every parameter.
    pub after: SolveShare,
}

/// A fold's normal equations and `R` factor of its scaled Jacobian at a solve's start (every
/// training row at weight 1, [`CalibrationOptions::scales`] of the active parameters), summed from
/// the other folds' shares of one pass over every row: the start and the rank decision of its
/// Levenberg–Marquardt solve ([`crate::lm::SolveHints`]).
#[derive(Clone, Debug)]
pub(crate) struct SolveShare {
    /// `χ²` at the start.
    pub cost: f64,
    /// `D JᵀJ D` (p × p, full).
    pub gram: DMatrix<f64>,
    /// `D Jᵀr`.
    pub gradient: Vec<f64>,
    /// `R` of the scaled Jacobian (p × p).
    pub factor: DMatrix<f64>,
}

impl SolveShare {
    /// The hints of a solve of `p` parameters (none when the factor is not square: too few rows).
    fn hints(&self, p: usize) -> SolveHints<'_> {
        if self.factor.nrows() == p && self.factor.ncols() == p && self.gradient.len() == p {
            SolveHints {
                initial: Some((self.cost, &self.gram, &self.gradient)),
                factor: Some(&self.factor),
            }
        } else {
            SolveHints::default()
        }
    }
}

impl<'a> WarmStart<'a> {
    /// Where a fit of a part of `cal`'s rows starts: at `cal`, lean.
    pub(crate) fn near(cal: &'a Calibration) -> Self {
        WarmStart {
            before: &cal.before,
            physical: cal.physical.as_ref().unwrap_or(&cal.params),
            extensions: &cal.layout.extensions,
            shared: None,
            lean: true,
            payload_com_m: cal.extensions.as_ref().map(|s| s.payload_com_m),
        }
    }

    /// Whether the fit of `obs` can start here: the same campaigns and orientation as the
    /// calibration it starts from. A fold without a campaign's poses starts from the closed form
    /// instead.
    pub(crate) fn fits(&self, obs: &Observations) -> bool {
        self.before.campaign_ids == obs.campaign_ids()
            && self.physical.campaign_ids == self.before.campaign_ids
            && self.before.r_flange_target.is_some() == obs.orientation.is_some()
            && self.physical.extension.len() == self.extensions.len()
    }

    /// The values of the extension parameters `params` at the start: each one's value in
    /// `physical` where it is there (the same cause, term and quantity), else zero.
    pub(crate) fn extension_for(
        &self,
        params: &[crate::model::extensions::ExtensionParam],
    ) -> Vec<f64> {
        params
            .iter()
            .map(|p| {
                self.extensions
                    .iter()
                    .position(|q| {
                        q.cause == p.cause
                            && q.term == p.term
                            && q.quantity == p.quantity
                            && q.pattern == p.pattern
                    })
                    .map_or(0.0, |k| self.physical.extension[k])
            })
            .collect()
    }

    /// The start of the full fit of `obs`: `physical` with [`WarmStart::extension_for`] its
    /// extension parameters.
    fn params_for(&self, obs: &Observations) -> KinematicParams {
        let mut params = self.physical.clone();
        params.extension = self.extension_for(&obs.ext.params);
        params
    }
}

/// The rows of `data` prepared for the solver, with the extensions' regressors under `extensions`,
/// torques evaluated at the extension values of `at` ([`Regressors::build`]).
pub fn observations(
    model: &Model,
    data: &Dataset<'_>,
    options: &CalibrationOptions,
    extensions: Option<&ExtensionSettings>,
    at: Option<&KinematicParams>,
) -> Result<Observations> {
    let mut obs = Observations::from_table(data.table, &data.rows, &options.noise, &data.name)?;
    if let Some(s) = extensions {
        obs.ext = Regressors::build(model, s, data.table, &data.rows, &data.name, at)?;
    }
    Ok(obs)
}

/// Fewest distinct configurations a campaign needs in the training rows: three points fix a rigid
/// transform.
pub const MIN_CAMPAIGN_POSES: usize = 3;

/// Every campaign of `obs` has at least [`MIN_CAMPAIGN_POSES`] distinct configurations.
fn check_campaign_poses(obs: &Observations, name: &str) -> Result<()> {
    let Some(campaign) = &obs.campaign else {
        return Ok(());
    };
    for id in obs.campaign_ids() {
        let mut configs: Vec<Vec<u64>> = (0..obs.len())
            .filter(|&r| campaign[r] == id)
            .map(|r| obs.q_row(r).iter().map(|v| v.to_bits()).collect())
            .collect();
        configs.sort_unstable();
        configs.dedup();
        if configs.len() < MIN_CAMPAIGN_POSES {
            return Err(CalibError::BadValue {
                context: name.to_string(),
                field: "campaign".into(),
                value: id.to_string(),
                problem: format!(
                    "campaign {id} has {} distinct poses here: at least {MIN_CAMPAIGN_POSES} are needed to \
                     register its tracker",
                    configs.len()
                ),
            });
        }
    }
    Ok(())
}

/// One kinematic fit's inputs besides the robot and the rows: what it is judged on, its settings, the
/// extensions and the extension values their torques are evaluated at, where it starts, and the
/// base-and-target fit it may take over.
#[derive(Clone, Copy)]
pub(crate) struct Stage<'a> {
    /// Rows the fit is judged on (never fitted).
    pub test: Option<&'a Dataset<'a>>,
    /// Settings.
    pub options: &'a CalibrationOptions,
    /// The extensions fitted jointly with the kinematic parameters, if any.
    pub extensions: Option<&'a ExtensionSettings>,
    /// The parameters whose extension values the extensions' torques are evaluated at
    /// ([`Regressors::build`]; `None`: extensions at zero).
    pub at: Option<&'a KinematicParams>,
    /// Where the fit starts ([`WarmStart`]); `None`: the closed form.
    pub warm: Option<WarmStart<'a>>,
    /// The base-and-target fit of an earlier calibration of the same rows (an equilibrium refit:
    /// that fit uses nominal joints and every extension at zero, so it does not change between
    /// refits).
    pub same_before: Option<(&'a KinematicParams, &'a FitStage)>,
}

/// The kinematic fit (with `stage.extensions` fitted jointly) of `train`: every stage from the
/// closed-form start to the report.
pub(crate) fn kinematic_fit(
    model: &Model,
    train: &Dataset<'_>,
    stage: &Stage<'_>,
) -> Result<Calibration> {
    let Stage {
        test,
        options,
        extensions,
        at,
        warm: fold,
        same_before,
    } = *stage;
    // A lean fit: no training statistics or outlier list in its report.
    let lean = fold.is_some_and(|f| f.lean);
    for d in std::iter::once(train).chain(test) {
        if d.table.n_joints != model.nq() {
            return Err(CalibError::BadValue {
                context: d.name.clone(),
                field: "q1..qN".into(),
                value: format!("{} joint columns", d.table.n_joints),
                problem: format!("robot '{}' has {} joints", model.name(), model.nq()),
            });
        }
    }
    if train.rows.is_empty() {
        return Err(CalibError::BadValue {
            context: train.name.clone(),
            field: "rows".into(),
            value: "0".into(),
            problem: "no rows to calibrate on".into(),
        });
    }
    crate::cancel::checkpoint()?;
    let mut obs = observations(model, train, options, extensions, at)?;
    let test_obs = match test {
        Some(t) if !t.rows.is_empty() => Some(observations(model, t, options, extensions, at)?),
        _ => None,
    };
    let orientation = obs.orientation.is_some();
    if let Some(t) = &test_obs
        && t.orientation.is_some() != orientation
    {
        return Err(CalibError::BadValue {
            context: test.map(|t| t.name.clone()).unwrap_or_default(),
            field: "qw, qx, qy, qz".into(),
            value: if orientation { "absent" } else { "present" }.into(),
            problem:
                "the test data must have orientation columns exactly when the training data do"
                    .into(),
        });
    }
    // The start: closed-form registration of every campaign (a fold: the calibration on every
    // pose, when its campaigns are the fold's).
    let warm = fold.filter(|f| f.fits(&obs));
    let mut start = match warm {
        Some(f) => f.before.clone(),
        None => {
            let mut start = initial_params(model, &obs);
            if options.per_campaign_target {
                start = start.with_own_targets();
            }
            start
        }
    };
    start.extension = vec![0.0; obs.ext.len()];
    if let (Some(t), Some(d)) = (&test_obs, test) {
        t.campaign_indices_or_error(&start, &d.name)?;
    }
    check_campaign_poses(&obs, &train.name)?;
    let layout = ParamLayout::for_params(model, &start, obs.ext.params.clone());
    let p = layout.len();
    let dim = obs.dim();
    let n_poses = obs.n_poses();
    // Poses count by configuration: ids at identical joint values add no equations.
    let n_configurations = obs.n_configurations();
    let equations = n_configurations * dim;
    if equations <= p {
        // Each campaign after the first adds its registration (and target) to the generic rank.
        let r = generic_rank(model, orientation, options) + layout.kinematic_len()
            - ParamLayout::new(model, orientation).kinematic_len();
        if equations < r + 1 {
            return Err(CalibError::TooFewPoses {
                context: train.name.clone(),
                part: train.part,
                robot: model.name().to_string(),
                joints: model.nq(),
                poses: n_configurations,
                equations,
                identifiable: r,
                needed: (r + 1).div_ceil(dim),
            });
        }
    }
    let scales = options.scales.vector(&layout);
    let mut warnings = Vec::new();

    // Before: base and target only.
    let (before_params, before) = match same_before {
        Some((params, stage)) => (params.clone(), stage.clone()),
        None => base_and_target(
            model,
            &obs,
            test_obs.as_ref(),
            start,
            &layout,
            &scales,
            stage,
        )?,
    };
    if !before.solver.was_successful() {
        warnings.push(format!(
            "the base-and-target fit did not converge ({})",
            before.solver.termination
        ));
    }

    // After: everything, optionally with IRLS.
    let all: Vec<usize> = (0..p).collect();
    let mut ws = LmWorkspace::new(obs.len() * dim, p);
    // A fold without a robust loss starts at the all-pose solution (IRLS starts from "before").
    let mut params = match warm {
        Some(f) if options.robust.is_none() => f.params_for(&obs),
        _ => before_params.clone(),
    };
    let mut robust_summary = None;
    let mut excluded: Vec<Outlier> = Vec::new();
    // The rows' residual norms at the final parameters and weights, when the last gross-error
    // search had them (the outlier search below needs the same).
    let mut final_norms: Option<Vec<f64>> = None;
    let (report, sub) = match options.robust {
        None => {
            // A fold's first solve starts where its shared work was done (weights 1, no exclusion).
            let hints = match warm.and_then(|f| f.shared) {
                Some(s) => s.after.hints(p),
                None => SolveHints::default(),
            };
            let (out, norms) = full_fit(
                model,
                &mut obs,
                &mut params,
                &all,
                scales.as_slice(),
                options,
                &mut ws,
                &hints,
                &mut excluded,
                &mut warnings,
            );
            final_norms = norms;
            out
        }
        Some(loss) => {
            let fit = robust::solve(
                model,
                &mut obs,
                &mut params,
                &all,
                scales.as_slice(),
                &options.lm,
                loss,
                &mut ws,
            );
            if let Some(w) = fit.warning {
                warnings.push(w);
            }
            robust_summary = Some(fit.summary);
            (fit.report, fit.subspace)
        }
    };
    // A solve stopped by the caller (Ctrl-C in Python) ends the calibration here.
    crate::cancel::checkpoint()?;
    if !report.was_successful() {
        warnings.push(format!(
            "the kinematic fit did not converge: {}",
            report.termination
        ));
    }
    let m = (obs.len() - excluded.len()) * dim;
    let dof = m.saturating_sub(sub.rank);
    let chi2 = report.cost_final;
    let (variance_factor, source) = variance_factor(dof, chi2, &mut warnings);
    let covariance = sub.covariance(variance_factor);
    crate::cancel::checkpoint()?;
    let observability = Observability::from_subspace(&sub);
    let null = describe_null_space(model, &params, ws.gram(), &sub, &obs);
    quality_warnings(
        &observability,
        &null,
        variance_factor,
        train.table.sigma.is_some(),
        dof,
        chi2,
        &mut warnings,
    );

    crate::cancel::checkpoint()?;
    let outliers = match &final_norms {
        _ if lean => Vec::new(),
        Some(norms) => outliers::find_in(model, &obs, &params, norms, options.outlier_threshold),
        None => outliers::find(model, &obs, &params, &all, options.outlier_threshold),
    };

    let sigma_rms = (obs.sigma.iter().map(|s| s * s).sum::<f64>() / obs.len() as f64).sqrt();
    let parameters = estimates(&layout, &params, &covariance, &sub);
    let strong_correlations = correlations(&layout, &covariance, &null);
    let mut health = before.solver.health;
    health.merge(&report.health);
    let after = FitStage {
        parameters: "kinematic error model (joint error twists and zero offsets, base, target)"
            .into(),
        train: if lean {
            Default::default()
        } else {
            residual_stats(model, &params, &obs)
        },
        test: test_obs.as_ref().map(|t| residual_stats(model, &params, t)),
        solver: report,
    };
    let report = CalibrationReport {
        robot: model.name().to_string(),
        model: ModelSpec::kinematic(),
        n_train_rows: obs.len(),
        n_train_poses: n_poses,
        n_test_rows: test_obs.as_ref().map_or(0, |t| t.len()),
        n_test_poses: test_obs.as_ref().map_or(0, |t| t.n_poses()),
        before,
        after,
        dof,
        chi2_per_dof: if dof > 0 { chi2 / dof as f64 } else { f64::NAN },
        variance_factor_source: source.into(),
        sigma_hat_m: sigma_rms * variance_factor.sqrt(),
        parameters,
        strong_correlations,
        observability,
        unidentifiable: null,
        outliers,
        excluded,
        robust: robust_summary,
        learned: None,
        repeatability: if lean {
            None
        } else {
            repeats::of_rows(train.table, &train.rows)
        },
        warnings,
        health,
    };
    Ok(Calibration {
        params,
        before: before_params,
        layout,
        covariance,
        subspace: sub,
        report,
        extensions: extensions.cloned(),
        learned: None,
        physical: None,
    })
}

/// The "after" stage without a robust loss: every parameter of `all` fitted from `params` (with the
/// solve's `hints`), then the gross-error rounds ([`GROSS_ERROR_ROUNDS`]): rows beyond
/// [`CalibrationOptions::gross_error_threshold`] are excluded ([`outliers::exclude`], added to
/// `excluded` with their error against the final fit and a warning) and the fit repeated. Returns the
/// solve's report and subspace, and the rows' residual norms at the final fit when the last search had
/// them.
#[allow(clippy::too_many_arguments)]
fn full_fit(
    model: &Model,
    obs: &mut Observations,
    params: &mut KinematicParams,
    all: &[usize],
    scales: &[f64],
    options: &CalibrationOptions,
    ws: &mut LmWorkspace,
    hints: &SolveHints<'_>,
    excluded: &mut Vec<Outlier>,
    warnings: &mut Vec<String>,
) -> ((crate::lm::MinimizationReport, Subspace), Option<Vec<f64>>) {
    let mut prob = KinematicProblem::new(model, obs, params.clone(), all.to_vec());
    let mut out = minimize_with(&mut prob, scales, &options.lm, ws, hints);
    let mut final_norms = None;
    *params = prob.into_params();
    for _ in 0..GROSS_ERROR_ROUNDS {
        let norms = outliers::row_norms(model, obs, params, all);
        let gross = outliers::find_in(model, obs, params, &norms, options.gross_error_threshold);
        if gross.is_empty() {
            final_norms = Some(norms);
            break;
        }
        outliers::exclude(obs, &gross);
        excluded.extend(gross);
        let first = out.0.clone();
        let mut prob = KinematicProblem::new(model, obs, params.clone(), all.to_vec());
        out = minimize(&mut prob, scales, &options.lm, ws);
        *params = prob.into_params();
        out.0.cost_initial = first.cost_initial;
        out.0.iterations += first.iterations;
        out.0.evaluations += first.evaluations;
        let mut health = first.health;
        health.merge(&out.0.health);
        out.0.health = health;
    }
    // Each excluded row's error against the final fit, and its warning.
    let prediction = crate::model::predict::Prediction::new(model, params);
    let campaign = prediction.campaigns_of(obs);
    let mut scratch = prediction.scratch();
    for o in excluded.iter_mut() {
        if let Some(r) = obs.source_row.iter().position(|&s| s + 1 == o.row) {
            let c = campaign.get(r).copied().unwrap_or(0);
            let p = prediction.row_in(&obs.ext, r, obs.q_row(r), c, &mut scratch);
            o.error_m = (p - obs.position[r]).norm();
        }
        warnings.push(gross_error_warning(o));
    }
    (out, final_norms)
}

/// `σ̂² = χ²/dof` and where it comes from; with no degrees of freedom left, 1 (the noise model) and a
/// warning.
fn variance_factor(dof: usize, chi2: f64, warnings: &mut Vec<String>) -> (f64, &'static str) {
    if dof > 0 {
        (chi2 / dof as f64, "residuals (χ²/dof)")
    } else {
        warnings.push(
            "no redundancy left (as many equations as identifiable parameters): standard deviations \
             assume the noise model is exact"
                .into(),
        );
        (1.0, "noise model (no degrees of freedom left)")
    }
}

/// The warnings of a fit's quality: what this pose set cannot identify, weakly determined
/// combinations, and a `sigma` column (`sigma_column`) that does not match the residuals.
fn quality_warnings(
    observability: &Observability,
    null: &identifiability::NullSpaceReport,
    variance_factor: f64,
    sigma_column: bool,
    dof: usize,
    chi2: f64,
    warnings: &mut Vec<String>,
) {
    for line in &null.data_specific {
        warnings.push(format!("not identifiable from this pose set: {line}"));
    }
    if observability.weak_combinations > 0 {
        warnings.push(format!(
            "{} identifiable combinations are weakly determined (σ_k < 1: the data know them less well \
             than their expected magnitude); the worst has σ {:.2e} in units of its expected magnitude",
            observability.weak_combinations,
            observability.worst_combination_sigma * variance_factor.sqrt()
        ));
    }
    if sigma_column && dof > 0 && !(0.25..=4.0).contains(&(chi2 / dof as f64)) {
        warnings.push(format!(
            "χ²/dof = {:.3}: the sigma column does not match the residuals (a model error, or sigma in \
             the wrong unit)",
            chi2 / dof as f64
        ));
    }
}

/// The warning of a row excluded as a gross error (`o.error_m` against the final fit).
fn gross_error_warning(o: &Outlier) -> String {
    format!(
        "row {} (pose {}) excluded from the fit as a gross error: {:.4} mm off the fit of \
         the other rows, {:.0} times the robust residual scale when found (a broken beam or \
         a wrong row? fix it, or use --robust to down-weight instead)",
        o.row,
        o.pose,
        o.error_m * 1e3,
        o.normalised_residual
    )
}

/// The "before" stage: the tracker-to-base transform and the target fitted with nominal joints
/// (every extension at zero), from `start`; the reference for what calibration gains.
fn base_and_target(
    model: &Model,
    obs: &Observations,
    test_obs: Option<&Observations>,
    start: KinematicParams,
    layout: &ParamLayout,
    scales: &nalgebra::DVector<f64>,
    stage: &Stage<'_>,
) -> Result<(KinematicParams, FitStage)> {
    let options = stage.options;
    let warm = stage.warm.filter(|f| f.fits(obs));
    let lean = stage.warm.is_some_and(|f| f.lean);
    let dim = obs.dim();
    let bt = layout.base_and_target();
    let bt_scales: Vec<f64> = bt.iter().map(|&k| scales[k]).collect();
    let mut ws = LmWorkspace::new(obs.len() * dim, bt.len());
    let mut prob = KinematicProblem::new(model, obs, start, bt);
    let hints = match warm.and_then(|f| f.shared) {
        Some(s) => s.before.hints(bt_scales.len()),
        None => SolveHints::default(),
    };
    let (before_report, _) = minimize_with(&mut prob, &bt_scales, &options.lm, &mut ws, &hints);
    let before_params = prob.into_params();
    crate::cancel::checkpoint()?;
    let before = FitStage {
        parameters: "tracker-to-base transform and target (nominal joints)".into(),
        train: if lean {
            Default::default()
        } else {
            residual_stats(model, &before_params, obs)
        },
        test: test_obs.map(|t| residual_stats(model, &before_params, t)),
        solver: before_report,
    };
    Ok((before_params, before))
}
