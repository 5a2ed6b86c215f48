//! Step 2 of the pipeline: the truth and the tracker reading of every row of a plan, in parallel, and
//! the measurement table they make.

use crate::campaign::{Plan, STREAM_TRACKER, derive_seed, rng_for};
use crate::effects::{ComplianceSolver, Conditions, Contributions, Truth};
use crate::error::{Result, SimError};
use crate::scenario::{Resolved, TruthModel};
use crate::statics::Payload;
use crate::tracker::{Reading, Tracker};
use nalgebra::Vector3;
use rayon::prelude::*;
use std::sync::Mutex;

/// The simulated truth and reading of one row.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RowTruth {
    /// Noise-free target position in the base frame (m).
    pub p_base: [f64; 3],
    /// Displacement by each effect (base frame, m).
    pub contribution: Contributions,
    /// Newton iterations of the compliance equilibrium.
    pub compliance_iterations: usize,
    /// The tracker reading (true and measured target, noise, σ, orientation).
    pub reading: Reading,
}

/// The output of [`simulate`]: one [`RowTruth`] per plan row, and the per-joint vectors.
#[derive(Clone, Debug, PartialEq)]
pub struct Simulation {
    /// Joints.
    pub nq: usize,
    /// Per row.
    pub rows: Vec<RowTruth>,
    /// Link-side joint positions, row-major (rad or m).
    pub q_link: Vec<f64>,
    /// First-order link-side joint positions, row-major (rad or m).
    pub q_link_first_order: Vec<f64>,
}

/// Per-row progress callback: called with the number of rows just finished.
pub type Progress<'a> = &'a (dyn Fn(u64) + Sync);

/// Rows between progress callbacks and the least rows per parallel task: analytic truth (≈ 4 µs a
/// row) and rapier truth (≈ 200 µs a row, so a progress bar moves and two cores share 200 poses).
pub(super) const fn batching(solver: ComplianceSolver) -> (usize, usize) {
    match solver {
        ComplianceSolver::Analytic => (4096, 64),
        ComplianceSolver::Rapier(_) => (16, 4),
    }
}

/// The truth of a resolved scenario: [`Truth::with_solver`] with the solver its `[truth] model`
/// names (rapier with the default [`crate::springs::SettleOptions`]). Errors name the scenario
/// file and `effects` or `truth.model`.
pub fn truth_of(res: &Resolved) -> Result<Truth> {
    let (solver, key) = match res.truth_model {
        TruthModel::Analytic => (ComplianceSolver::Analytic, "effects"),
        TruthModel::Rapier => (
            ComplianceSolver::Rapier(crate::springs::SettleOptions::default()),
            "truth.model",
        ),
    };
    Truth::with_solver(&res.model, &res.effects, solver).map_err(|e| SimError::Scenario {
        file: res.scenario.label.clone(),
        key: key.into(),
        message: e.to_string(),
    })
}

/// Simulates every row of `plan`: truth with `truth` under `gravity` (base frame, m/s²), reading with
/// `tracker`, noise drawn from `seed` (see the module docs). Runs on the current rayon pool. Fails with
/// the lowest failing row's error (e.g. a compliance equilibrium that is not found), naming the pose.
pub fn simulate(
    truth: &Truth,
    tracker: &Tracker,
    gravity: &Vector3<f64>,
    plan: &Plan,
    seed: u64,
    progress: Option<Progress<'_>>,
) -> Result<Simulation> {
    let n = plan.len();
    let nq = plan.nq;
    let mut rows = vec![RowTruth::default(); n];
    let mut q_link = vec![0.0; n * nq];
    let mut q_first = vec![0.0; n * nq];
    let failure: Mutex<Option<(usize, SimError)>> = Mutex::new(None);
    let com = plan.payload_com_m;
    let (every, min_len) = batching(truth.solver());
    rows.par_iter_mut()
        .zip(q_link.par_chunks_mut(nq))
        .zip(q_first.par_chunks_mut(nq))
        .enumerate()
        .with_min_len(min_len)
        .for_each_init(
            || truth.scratch(),
            |scratch, (r, ((row, ql), qf))| {
                let mass = plan.payload_kg[r];
                let cond = Conditions {
                    q: plan.q_row(r),
                    dir: plan.dir_row(r),
                    temp_c: plan.temp_c[r],
                    payload: (mass > 0.0).then_some(Payload { mass, com }),
                    branch: plan.branch_row(r),
                };
                match truth.target(&cond, tracker.p_flange(), gravity, scratch) {
                    Ok(tp) => {
                        let pose = plan.pose[r] as u64;
                        let repeat = plan.repeat_of(r) as u64;
                        let mut rng = rng_for(
                            derive_seed(seed, STREAM_TRACKER, pose),
                            STREAM_TRACKER,
                            repeat,
                        );
                        *row = RowTruth {
                            p_base: [tp.p_base.x, tp.p_base.y, tp.p_base.z],
                            contribution: tp.contribution,
                            compliance_iterations: tp.compliance_iterations,
                            reading: tracker.measure(&tp.flange, &mut rng),
                        };
                        ql.copy_from_slice(scratch.q_link());
                        qf.copy_from_slice(scratch.q_link_first_order());
                    }
                    Err(e) => {
                        let mut f = failure.lock().unwrap_or_else(|p| p.into_inner());
                        if f.as_ref().is_none_or(|(fr, _)| r < *fr) {
                            *f = Some((r, e));
                        }
                    }
                }
                if let Some(p) = progress
                    && (r + 1) % every == 0
                {
                    p(every as u64);
                }
            },
        );
    if let Some((r, e)) = failure.into_inner().unwrap_or_else(|p| p.into_inner()) {
        return Err(SimError::Scenario {
            file: "simulation".into(),
            key: format!("pose {} (row {})", plan.pose[r], plan.first_row + r + 1),
            message: e.to_string(),
        });
    }
    if let Some(p) = progress {
        p((n % every) as u64);
    }
    Ok(Simulation {
        nq,
        rows,
        q_link,
        q_link_first_order: q_first,
    })
}
