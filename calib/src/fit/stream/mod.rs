//! The kinematic calibration of a measurement table read in pieces: tracker streams of 10⁷ rows in
//! bounded memory.
//!
//! # Passes
//! 1. **Scan** ([`scan`]): the rows are counted, the campaigns listed, and a seeded sample of
//!    [`StreamOptions::sample_rows`] rows is drawn (by a hash of the row number: the same sample
//!    however the file is cut into pieces).
//! 2. **Start**: the in-memory fit ([`crate::fit::fit`]) of the sample, every stage of it: the
//!    closed-form registration, the base-and-target fit ("before") and the full fit. Its solution
//!    lies within a few standard deviations *of the sample* from the minimum on every row.
//! 3. **Solve** ([`lane`]): two Levenberg–Marquardt solves carried across passes, the
//!    base-and-target fit from the sample's "before" and the full fit from the sample's solution.
//!    Each pass evaluates both at their trial points: `χ²` and `D Jᵀr`, and where a lane asks for it
//!    the `R` factor of the scaled Jacobian, summed piece by piece in file order (each piece's
//!    factor from a blocked Householder QR, stacked into the running factor: a tall-skinny QR whose
//!    result does not depend on the number of threads). The factor, two thirds of a pass's work, is
//!    computed at the start and kept while the steps go as it predicts (a chord method,
//!    [`lane`]'s docs). From the sample's start one Gauss–Newton step converges, so the solve takes
//!    two passes: the first with the factor, the second without.
//! 4. **Residuals** ([`pass::FinalPass`]): statistics at "before" and at the solution, every row's
//!    residual norm (8 bytes a row: the only memory that grows with the rows), the rows of largest
//!    norm with their pose and error, and evenly spaced rows for the model file's predicted σ. A
//!    pass without factors is expected to end both solves, so it computes these at the points the
//!    solves end at if it does (from the same evaluation of each row); only when a solve goes on is
//!    that work thrown away, and a last pass computes them at the solution.
//!    Gross errors (beyond [`CalibrationOptions::gross_error_threshold`] of the robust scale) are
//!    excluded and the full fit resumed, up to [`super::GROSS_ERROR_ROUNDS`] times, as in memory.
//!
//! The file is decoded one piece ahead, on a thread of its own ([`FileSource`]). Measured on the
//! 2-core machine (`scripts/bench_streaming.sh`, iiwa 7, 10⁷ rows): 3 passes, about 3 s for the
//! scan, 34 s for the pass with the factor and 11 s for the last one.
//!
//! # What differs from the in-memory fit
//! - The minimum is the same, reached by another path: both solves stop when the full Gauss–Newton
//!   step would lower `χ²` by at most `decrease_tol + relative_decrease_tol · χ²`
//!   ([`crate::lm::LmOptions`]), so the two solutions differ by at most twice the square root of
//!   that in the norm `‖J D δ‖` (noise units), which bounds every parameter's difference in units of
//!   its standard deviation: `|δₖ|/σₖ ≤ ‖J δ‖/σ̂` (tested on 10⁵ rows).
//! - Sums are in piece order: `χ²`, statistics and the factor agree with the in-memory ones to
//!   rounding.
//! - The covariance and the rank decision come from the factor where it was last computed
//!   ([`StreamedCalibration::factor_at`]), one step from the solution, where the in-memory fit
//!   takes it at its solution: they agree to first order in how far apart those points sit (the
//!   Jacobian's columns turn by that, in radians and metres over the arm's reach).
//! - The null-space report names the joints that do not move from the sample's rows.
//! - Poses are counted as runs of consecutive rows with the same campaign and pose id (a stream's
//!   repeats of a pose follow each other).
//! - Outliers are listed from the [`pass::MAX_CANDIDATES`] rows of largest residual (a warning says
//!   when more rows qualify).
//! - The kinematic model only, without a robust loss. Cross-validation by folds and regions streams
//!   too ([`crate::validate::stream`]); a split, another file or leave-one-campaign-out need the
//!   table in memory.

pub mod lane;
pub mod pass;
pub mod register;
pub mod scan;
pub mod source;

pub use source::{ChunkSource, FileSource, TableSource};

use super::identifiability::{Observability, describe_null_space};
use super::report::{CalibrationReport, FitStage, Outlier};
use super::{Calibration, Dataset, FitRequest, GROSS_ERROR_ROUNDS};
use crate::error::{CalibError, Result};
use crate::fit::problem::Observations;
use crate::model::spec::ModelSpec;
use lane::{Lane, Phase};
use sim::Model;
use sim::measurement_table::MeasurementTable;

/// Settings of a streamed fit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StreamOptions {
    /// Rows of the sample the solve starts from. Default [`DEFAULT_SAMPLE_ROWS`].
    pub sample_rows: usize,
    /// Seed of the sample.
    pub seed: u64,
    /// Most passes of each solve. Default [`DEFAULT_MAX_PASSES`].
    pub max_passes: usize,
}

/// Rows of the sample a streamed fit starts from: 16,384, whose fit lies within about
/// `√(N / 16,384)` of its own standard deviations from the minimum on `N` rows (25 on 10⁷ rows),
/// well within the region where one Gauss–Newton step converges.
pub const DEFAULT_SAMPLE_ROWS: usize = 16_384;

/// Most evaluations of a streamed solve: two suffice from the sample's start.
pub const DEFAULT_MAX_PASSES: usize = 30;

impl Default for StreamOptions {
    fn default() -> Self {
        StreamOptions {
            sample_rows: DEFAULT_SAMPLE_ROWS,
            seed: 0,
            max_passes: DEFAULT_MAX_PASSES,
        }
    }
}

/// A streamed calibration and what it read.
#[derive(Clone, Debug)]
pub struct StreamedCalibration {
    /// The calibration, as [`crate::fit::fit`] reports one.
    pub calibration: Calibration,
    /// Rows of the table.
    pub rows: usize,
    /// Passes over the table, the scan included.
    pub passes: usize,
    /// Rows of the sample the solve started from.
    pub sample_rows: usize,
    /// Every `⌈rows / 10,000⌉`th row of the table from the first: the rows
    /// [`crate::model::file::CalibratedModel::record_calibration_sigma`] takes on the whole table.
    pub spaced_rows: MeasurementTable,
    /// The parameters at which the `R` factor behind the covariance and the rank decision was
    /// computed (the solution, or a point one step or a few before it).
    pub factor_at: crate::model::params::KinematicParams,
    /// The seeded sample of rows the solve started from, in table order (a streamed validation
    /// places its regions on its poses).
    pub sample: MeasurementTable,
    /// The rows excluded as gross errors (0-based rows of the file, ascending).
    pub excluded_rows: Vec<usize>,
    /// The Marquardt damping the full fit's solve ended with.
    pub final_damping: f64,
}

/// The kinematic calibration of every row of `source` (module docs), with `options` (no robust
/// loss) and `stream`'s sample. `progress` hears each pass's rows. Errors as [`crate::fit::fit`]'s,
/// and for a robust loss.
pub fn calibrate(
    model: &Model,
    source: &dyn ChunkSource,
    options: &super::CalibrationOptions,
    stream: &StreamOptions,
    progress: &mut dyn FnMut(&str),
) -> Result<StreamedCalibration> {
    if options.robust.is_some() {
        return Err(CalibError::BadValue {
            context: source.name().to_string(),
            field: "robust".into(),
            value: "a robust loss".into(),
            problem: "the streamed fit has no robust loss (its gross-error rounds exclude broken \
                      rows)"
                .into(),
        });
    }
    let scan = scan::scan(source, stream.sample_rows, stream.seed, progress)?;
    if scan.n_joints != model.nq() {
        return Err(CalibError::BadValue {
            context: source.name().to_string(),
            field: "q1..qN".into(),
            value: format!("{} joint columns", scan.n_joints),
            problem: format!("robot '{}' has {} joints", model.name(), model.nq()),
        });
    }
    let name = source.name();
    let sample_name = format!("{name} (a sample of {} rows)", scan.sample.len());
    progress(&format!("fitting a sample of {} rows", scan.sample.len()));
    let start = super::fit(
        model,
        &Dataset::all(&scan.sample, &sample_name),
        &FitRequest::kinematic(options),
    )?;
    let layout = start.layout.clone();
    let p = layout.len();
    let scales = options.scales.vector(&layout);
    let bt = layout.base_and_target();
    let mut before = Lane::new(
        layout.clone(),
        start.before.clone(),
        bt.clone(),
        bt.iter().map(|&k| scales[k]).collect(),
        &options.lm,
        stream.max_passes,
    );
    // The full fit's lane over every parameter, from `from`.
    let full_lane = |from| {
        Lane::new(
            layout.clone(),
            from,
            (0..p).collect(),
            scales.as_slice().to_vec(),
            &options.lm,
            stream.max_passes,
        )
    };
    let mut after = full_lane(start.params.clone());
    let stride = scan
        .rows
        .div_ceil(super::model_file::SIGMA_SAMPLE_ROWS)
        .max(1);
    let mut passes = 1;
    let mut excluded_rows: Vec<usize> = Vec::new();
    let mut excluded: Vec<Outlier> = Vec::new();
    let mut first_after: Option<crate::lm::MinimizationReport> = None;
    let dim = if scan.orientation { 6 } else { 3 };
    let mut round = 0;
    let mut last = loop {
        let mut fin = loop {
            if before.phase == Phase::Done && after.phase == Phase::Done {
                let fin = pass::final_pass(
                    model,
                    source,
                    &options.noise,
                    &excluded_rows,
                    &before.lin,
                    &after.lin,
                    stride,
                    scan.rows,
                    progress,
                )?;
                passes += 1;
                break fin;
            }
            // A pass without factors is expected to end both solves: it computes the residuals
            // at the points they end at if it does, which saves the final pass.
            let speculate = !before.wants_factor() && !after.wants_factor();
            let (end_before, end_after) = (before.next_point().clone(), after.next_point().clone());
            let request = speculate.then_some(pass::FinalRequest {
                before: &end_before,
                after: &end_after,
                stride,
                rows: scan.rows,
            });
            let label = format!("pass {}", passes + 1);
            let fin = pass::solve_pass(
                model,
                source,
                &options.noise,
                &excluded_rows,
                &mut [&mut before, &mut after],
                request,
                &label,
                progress,
            )?;
            passes += 1;
            let ended_there = before.phase == Phase::Done
                && after.phase == Phase::Done
                && before.lin == end_before
                && after.lin == end_after;
            if let (Some(fin), true) = (fin, ended_there) {
                break fin;
            }
        };
        if round == GROSS_ERROR_ROUNDS || !after.report.was_successful() {
            break fin;
        }
        let scale = robust_scale(&mut fin.norms, dim);
        let gross: Vec<&pass::Candidate> = fin
            .candidates
            .iter()
            .filter(|c| {
                c.norm / scale > options.gross_error_threshold
                    && c.norm > options.gross_error_threshold / 10.0
            })
            .collect();
        if gross.is_empty() {
            break fin;
        }
        for c in gross {
            excluded_rows.push(c.row);
            excluded.push(Outlier {
                row: c.row + 1,
                pose: c.pose,
                normalised_residual: c.norm / scale,
                error_m: c.error_m,
            });
        }
        excluded_rows.sort_unstable();
        // The full fit resumes from its solution without the excluded rows.
        let resumed = full_lane(after.lin.clone());
        let done = std::mem::replace(&mut after, resumed);
        first_after.get_or_insert(done.report);
        round += 1;
    };
    let mut report_after = after.report.clone();
    if let Some(first) = first_after {
        report_after.cost_initial = first.cost_initial;
        report_after.iterations += first.iterations;
        report_after.evaluations += first.evaluations;
        let mut health = first.health;
        health.merge(&report_after.health);
        report_after.health = health;
    }
    // Each excluded row's error against the final fit.
    for o in &mut excluded {
        if let Ok(k) = excluded_rows.binary_search(&(o.row - 1)) {
            o.error_m = last.excluded[k].1;
            o.pose = last.excluded[k].0;
        }
    }
    let sub = after.subspace().ok_or_else(|| CalibError::BadValue {
        context: name.to_string(),
        field: "rows".into(),
        value: scan.rows.to_string(),
        problem: "the streamed fit evaluated no point".into(),
    })?;
    let gram = after.gram().expect("evaluated");
    let params = after.lin.clone();
    let mut warnings = Vec::new();
    if !before.report.was_successful() {
        warnings.push(format!(
            "the base-and-target fit did not converge ({})",
            before.report.termination
        ));
    }
    if !report_after.was_successful() {
        warnings.push(format!(
            "the kinematic fit did not converge: {}",
            report_after.termination
        ));
    }
    let m = (scan.rows - excluded.len()) * dim;
    let dof = m.saturating_sub(sub.rank);
    let chi2 = report_after.cost_final;
    let (variance_factor, source_of_variance) = super::variance_factor(dof, chi2, &mut warnings);
    let covariance = sub.covariance(variance_factor);
    let observability = Observability::from_subspace(&sub);
    let sample_rows: Vec<usize> = (0..scan.sample.len()).collect();
    let sample_obs =
        Observations::from_table(&scan.sample, &sample_rows, &options.noise, &sample_name)?;
    let null = describe_null_space(model, &params, &gram, &sub, &sample_obs);
    super::quality_warnings(
        &observability,
        &null,
        variance_factor,
        scan.sample.sigma.is_some(),
        dof,
        chi2,
        &mut warnings,
    );
    for o in &excluded {
        warnings.push(super::gross_error_warning(o));
    }
    let scale = robust_scale(&mut last.norms, dim);
    let threshold = options.outlier_threshold;
    let outliers: Vec<Outlier> = last
        .candidates
        .iter()
        .filter(|c| c.norm / scale > threshold && c.norm > threshold / 10.0)
        .map(|c| Outlier {
            row: c.row + 1,
            pose: c.pose,
            normalised_residual: c.norm / scale,
            error_m: c.error_m,
        })
        .collect();
    if outliers.len() == pass::MAX_CANDIDATES {
        warnings.push(format!(
            "more than {} rows are outliers (beyond {threshold} times the robust residual scale): the \
             report lists the {} largest",
            pass::MAX_CANDIDATES,
            pass::MAX_CANDIDATES
        ));
    }
    let sigma_rms = (last.sigma2 / scan.rows as f64).sqrt();
    let parameters = super::estimates(&layout, &params, &covariance, &sub);
    let strong_correlations = super::correlations(&layout, &covariance, &null);
    let mut health = before.report.health;
    health.merge(&report_after.health);
    let report = CalibrationReport {
        robot: model.name().to_string(),
        model: ModelSpec::kinematic(),
        n_train_rows: scan.rows,
        n_train_poses: scan.pose_runs,
        n_test_rows: 0,
        n_test_poses: 0,
        before: FitStage {
            parameters: "tracker-to-base transform and target (nominal joints)".into(),
            train: last.before.stats(),
            test: None,
            solver: before.report.clone(),
        },
        after: FitStage {
            parameters: "kinematic error model (joint error twists and zero offsets, base, target)"
                .into(),
            train: last.after.stats(),
            test: None,
            solver: report_after,
        },
        dof,
        chi2_per_dof: if dof > 0 { chi2 / dof as f64 } else { f64::NAN },
        variance_factor_source: source_of_variance.into(),
        sigma_hat_m: sigma_rms * variance_factor.sqrt(),
        parameters,
        strong_correlations,
        observability,
        unidentifiable: null,
        outliers,
        excluded,
        robust: None,
        learned: None,
        repeatability: scan.repeatability,
        warnings,
        health,
    };
    Ok(StreamedCalibration {
        calibration: Calibration {
            params,
            before: before.lin.clone(),
            layout,
            covariance,
            subspace: sub,
            report,
            extensions: None,
            learned: None,
            physical: None,
        },
        rows: scan.rows,
        passes,
        sample_rows: scan.sample.len(),
        spaced_rows: last.spaced,
        factor_at: after
            .factor_at()
            .cloned()
            .unwrap_or_else(|| after.lin.clone()),
        sample: scan.sample,
        excluded_rows,
        final_damping: after.damping(),
    })
}

/// The robust scale of weighted residual norms of rows of `dim` residuals: their median over the
/// median of `√χ²(dim)` (1 when the median is 0), as the in-memory outlier search takes it. Reorders
/// `norms` (a selection in place: a copy would double the 8 bytes a row).
fn robust_scale(norms: &mut [f64], dim: usize) -> f64 {
    let v = norms;
    if v.is_empty() {
        return 1.0;
    }
    let m = v.len() / 2;
    let median = if v.len() % 2 == 1 {
        *v.select_nth_unstable_by(m, f64::total_cmp).1
    } else {
        let hi = *v.select_nth_unstable_by(m, f64::total_cmp).1;
        let lo = v[..m].iter().copied().fold(f64::NEG_INFINITY, f64::max);
        0.5 * (lo + hi)
    };
    let scale = median / super::outliers::chi2_median(dim).sqrt();
    if scale > 0.0 { scale } else { 1.0 }
}
