//! Registering a campaign measured in a stream of any length, in bounded memory.
//!
//! 1. **Scan** ([`super::scan`]): rows counted, campaigns listed, a seeded sample drawn.
//! 2. **Start**: the in-memory registration ([`crate::fit::register::register`]) of the sample,
//!    with every check it makes (one campaign, known or new; the columns the model's causes read;
//!    enough poses).
//! 3. **Gauss–Newton passes** over every row, at the current registration: per piece the rows'
//!    weighted residuals and Jacobian of the registration's parameters (the fit's own
//!    [`KinematicProblem`], only the campaign's columns active), summed into the Gram matrix of the
//!    scaled Jacobian augmented with the residuals, `[J D, r]ᵀ [J D, r]`, in file order; with the
//!    learned correction, each row's correction turned into the campaign's frame as in memory. The
//!    rank decision is the SVD of its Cholesky factor (at most 12 parameters, a condition of about 10:
//!    the Gram matrix loses nothing that matters), and the step the Gauss–Newton step on the
//!    identifiable directions. The passes stop when the step would lower `χ²` by no more than the
//!    solver's own tolerance ([`crate::lm::LmOptions::decrease_tol`] and
//!    [`crate::lm::LmOptions::relative_decrease_tol`]), as the in-memory solve does; that pass's
//!    statistics are the solution's. From the sample's start one step converges: two passes.
//!
//! Memory: one piece of rows and the sample. The result agrees with the in-memory registration of
//! the whole table within the solver's tolerance, in units of the parameters' standard deviations
//! (`calib/tests/stream.rs`).

use super::{ChunkSource, StreamOptions, scan};
use crate::cancel;
use crate::error::{CalibError, Result};
use crate::fit::problem::{KinematicProblem, Observations};
use crate::fit::register::{RegisterOptions, Registration, Solved, finish, register};
use crate::lm::{LeastSquaresProblem, MinimizationReport, Subspace, TerminationReason};
use crate::model::extensions::{ExtensionSettings, Regressors};
use crate::model::learned::LearnedResidual;
use crate::model::params::{KinematicParams, ParamLayout};
use crate::model::predict::Prediction;
use crate::model::stats::ResidualStats;
use nalgebra::{DMatrix, DVector, Vector3};
use sim::Model;

/// A registration of a stream and how it was reached.
#[derive(Clone, Debug)]
pub struct StreamedRegistration {
    /// The registration, as [`register`] gives it for the whole table.
    pub registration: Registration,
    /// Rows of the stream.
    pub rows: usize,
    /// Rows of the sample the start was fitted on.
    pub sample_rows: usize,
    /// Passes over the rows after the scan.
    pub passes: usize,
}

/// What one pass over every row sums at a registration.
struct PassSums {
    /// `[J D, r]ᵀ [J D, r]` (active + 1 square).
    gram: DMatrix<f64>,
    /// Scalar residuals.
    m: usize,
    /// Rows, and the sums of the error norms, their squares and the error vectors; the largest.
    n: usize,
    sum: f64,
    sum2: f64,
    sum_vector: Vector3<f64>,
    max: f64,
    max_row: usize,
    /// Poses, as runs of consecutive rows of one pose id.
    pose_runs: usize,
}

/// Registers the campaign of `source` for the model (see the module docs); the arguments are those
/// of [`register`], the rows coming from `source` in pieces.
#[allow(clippy::too_many_arguments)]
pub fn register_streamed(
    model: &Model,
    params: &KinematicParams,
    extensions: Option<&ExtensionSettings>,
    learned: Option<&LearnedResidual>,
    model_rms_m: Option<f64>,
    source: &dyn ChunkSource,
    options: &RegisterOptions,
    stream: &StreamOptions,
    progress: &mut dyn FnMut(&str),
) -> Result<StreamedRegistration> {
    let name = source.name().to_string();
    let scanned = scan::scan(source, stream.sample_rows, stream.seed, progress)?;
    let start = register(
        model,
        params,
        extensions,
        learned,
        model_rms_m,
        &scanned.sample,
        &format!("{name} (sample)"),
        options,
    )?;
    let id = start.report.campaign;
    let mut reg = start.params.clone();
    let c = reg
        .campaign_index(id)
        .expect("the registration holds its campaign");
    let active = start.indices.clone();
    let replaced = start.report.replaced;
    let layout = ParamLayout::for_params(
        model,
        &reg,
        extensions.map_or_else(Vec::new, |s| s.params(model)),
    );
    let scales: Vec<f64> = {
        let all = options.scales.vector(&layout);
        active.iter().map(|&k| all[k]).collect()
    };
    let base_model = Prediction::new(model, params).with_learned(learned);
    let mut passes = 0;
    let mut cost_initial = None;
    loop {
        passes += 1;
        let sums = pass(
            model,
            params,
            &reg,
            extensions,
            learned,
            &base_model,
            source,
            &active,
            &scales,
            options,
            id,
        )?;
        progress(&format!("registering {name}: pass {passes}"));
        let a = active.len();
        let jj = sums.gram.view((0, 0), (a, a)).into_owned();
        let g = sums.gram.view((0, a), (a, 1)).into_owned();
        let chi2 = sums.gram[(a, a)];
        cost_initial.get_or_insert(chi2);
        let factor = match jj.clone().cholesky() {
            Some(ch) => ch.l().transpose(),
            None => symmetric_root(&jj),
        };
        let sub = Subspace::from_factor(
            &factor,
            &scales,
            options.lm.rank_rtol,
            options.lm.min_singular_value,
            sums.m,
        );
        // The Gauss–Newton step on the identifiable directions (scaled coordinates): with
        // `J D = U S Vᵀ`, `δ = −Σₖ vₖ (vₖᵀ D Jᵀ r) / sₖ²`; its predicted decrease `Σₖ (vₖᵀ D Jᵀ r)² / sₖ²`.
        let mut step = DVector::zeros(a);
        let mut predicted = 0.0;
        for k in 0..sub.rank {
            let v = sub.v.column(k);
            let proj = v.dot(&g.column(0));
            let s2 = sub.singular_values[k] * sub.singular_values[k];
            step -= v * (proj / s2);
            predicted += proj * proj / s2;
        }
        let converged =
            predicted <= options.lm.decrease_tol + options.lm.relative_decrease_tol * chi2;
        if converged || passes >= stream.max_passes {
            let residual = sums.stats();
            let solver = MinimizationReport {
                termination: if converged {
                    TerminationReason::Converged
                } else {
                    TerminationReason::MaxIterations
                },
                iterations: passes,
                evaluations: passes,
                cost_initial: cost_initial.unwrap_or(chi2),
                cost_final: chi2,
                predicted_decrease: predicted,
                n_residuals: sums.m,
                n_params: a,
                rank: sub.rank,
                health: Default::default(),
            };
            let registration = finish(
                Solved {
                    params: reg,
                    campaign: id,
                    index: c,
                    replaced,
                    active,
                    solver,
                    subspace: sub,
                    residual,
                    n_poses: sums.pose_runs,
                    n_residuals: sums.m,
                },
                model_rms_m,
                options,
            );
            return Ok(StreamedRegistration {
                registration,
                rows: scanned.rows,
                sample_rows: scanned.sample.len(),
                passes,
            });
        }
        let mut full = vec![0.0; layout.len()];
        for (i, &k) in active.iter().enumerate() {
            full[k] = step[i] * scales[i];
        }
        reg.retract(&layout, &full);
    }
}

/// `M^{1/2}` of a symmetric positive semidefinite `m` (for the rank decision when Cholesky fails:
/// a parameter the rows do not determine).
fn symmetric_root(m: &DMatrix<f64>) -> DMatrix<f64> {
    let eig = m.clone().symmetric_eigen();
    let sqrt = eig.eigenvalues.map(|v| v.max(0.0).sqrt());
    &eig.eigenvectors * DMatrix::from_diagonal(&sqrt) * eig.eigenvectors.transpose()
}

impl PassSums {
    fn stats(&self) -> ResidualStats {
        let n = self.n.max(1) as f64;
        ResidualStats {
            n: self.n,
            rms_m: (self.sum2 / n).sqrt(),
            mean_m: self.sum / n,
            max_m: self.max,
            max_row: self.max_row,
            mean_vector_m: (self.sum_vector / n).into(),
            rms_rad: None,
            max_rad: None,
        }
    }
}

/// One pass over every row at the registration `reg` (see the module docs).
#[allow(clippy::too_many_arguments)]
fn pass(
    model: &Model,
    params: &KinematicParams,
    reg: &KinematicParams,
    extensions: Option<&ExtensionSettings>,
    learned: Option<&LearnedResidual>,
    base_model: &Prediction<'_>,
    source: &dyn ChunkSource,
    active: &[usize],
    scales: &[f64],
    options: &RegisterOptions,
    id: i64,
) -> Result<PassSums> {
    let a = active.len();
    let mut sums = PassSums {
        gram: DMatrix::zeros(a + 1, a + 1),
        m: 0,
        n: 0,
        sum: 0.0,
        sum2: 0.0,
        sum_vector: Vector3::zeros(),
        max: 0.0,
        max_row: 0,
        pose_runs: 0,
    };
    let c = reg.campaign_index(id).expect("registered campaign");
    let frame = reg.t_tracker_base_of(c).rotation.matrix()
        * params.t_tracker_base.rotation.matrix().transpose();
    let registered = Prediction::new(model, reg).with_learned(learned);
    let mut last_pose = None;
    let mut s = base_model.scratch();
    for chunk in source.pass()? {
        cancel::checkpoint()?;
        let chunk = chunk?;
        let t = &chunk.table;
        let rows: Vec<usize> = (0..t.len()).collect();
        let mut obs = Observations::from_table(t, &rows, &options.noise, source.name())?;
        if obs.orientation.is_some() {
            return Err(CalibError::BadValue {
                context: source.name().to_string(),
                field: "qw, qx, qy, qz".into(),
                value: "present".into(),
                problem: "a streamed registration fits positions only: register in memory".into(),
            });
        }
        if let Some(s) = extensions {
            obs.ext = Regressors::build(model, s, t, &rows, source.name(), Some(params))?;
        }
        for r in 0..obs.len() {
            obs.source_row[r] = chunk.first_row + r;
        }
        obs.campaign = Some(vec![id; obs.len()]);
        // Statistics at `reg`, on the measured positions.
        let errors = registered.errors(&obs);
        for (r, e) in errors.iter().enumerate() {
            let norm = e.norm();
            sums.sum += norm;
            sums.sum2 += norm * norm;
            sums.sum_vector += e;
            if norm > sums.max {
                sums.max = norm;
                sums.max_row = chunk.first_row + r + 1;
            }
            let key = t.pose_key(r);
            if last_pose != Some(key) {
                sums.pose_runs += 1;
                last_pose = Some(key);
            }
        }
        sums.n += obs.len();
        // The learned correction turned into the campaign's frame, subtracted from the measurements.
        if learned.is_some() {
            for r in 0..obs.len() {
                let physical = base_model
                    .physical_in(&obs.ext, r, obs.q_row(r), 0, &mut s)
                    .p_tracker;
                let full = base_model.row_in(&obs.ext, r, obs.q_row(r), 0, &mut s);
                obs.position[r] -= frame * (full - physical);
            }
        }
        let mut prob = KinematicProblem::new(model, &obs, reg.clone(), active.to_vec());
        let m = prob.n_residuals();
        let mut res = vec![0.0; m];
        prob.set_params(&vec![0.0; a]);
        prob.residuals(&mut res);
        let mut jac = DMatrix::zeros(m, a);
        prob.jacobian(&mut jac);
        // [J D, r]ᵀ [J D, r], the residual column last.
        let mut aug = DMatrix::zeros(m, a + 1);
        for (col, scale) in scales.iter().enumerate() {
            aug.column_mut(col).copy_from(&(jac.column(col) * *scale));
        }
        aug.column_mut(a).copy_from_slice(&res);
        sums.gram.gemm_tr(1.0, &aug, &aug, 1.0);
        sums.m += m;
    }
    Ok(sums)
}
