//! Choosing measurement poses: D-optimal selection from random candidates.
//!
//! `N` candidate configurations are drawn uniformly within the joint limits (±π for joints without
//! limits) from `StdRng::seed_from_u64(seed)`. Each candidate's position Jacobian of the kinematic model at
//! the nominal robot (target at `target_offset` in the flange frame), weighted by the noise and scaled by
//! the expected parameter magnitudes, is projected onto the identifiable subspace of the whole candidate
//! set (`Aₖ = Jₖ B`, 3 × r). The criterion is the D-optimal `log det Σₖ∈S Aₖᵀ Aₖ` (Sun and Hollerbach's
//! O1 up to monotone transformations). Selection is greedy, each step adding the candidate with the
//! largest gain `log det(I₃ + Aₖ P Aₖᵀ)` (`P` the inverse information, kept by Woodbury updates, started
//! from a tiny ridge), followed by exchange passes (swap a selected pose for a candidate while the
//! criterion rises). Collisions and cable routing are not considered.

use crate::error::{CalibError, Result};
use crate::fit::CalibrationOptions;
use crate::fit::identifiability::Observability;
use crate::lm::Subspace;
use crate::model::chain::{Chain, ChainScratch};
use crate::model::params::{KinematicParams, ParamLayout};
use nalgebra::{DMatrix, Matrix3, Vector3};
use rand::{RngExt, SeedableRng};
use sim::Model;

/// Settings of [`plan_poses`].
#[derive(Clone, Debug, PartialEq)]
pub struct PlanOptions {
    /// Number of random candidate configurations `N`.
    pub candidates: usize,
    /// Number of poses to select `K`.
    pub select: usize,
    /// Seed of the candidate draw (and of the random comparison sets).
    pub seed: u64,
    /// Target position in the flange frame (m) assumed for planning. Default (0.05, 0.03, 0.08): a
    /// reflector off the flange axes (one on the last joint's axis hides that axis's position).
    pub target_offset: Vector3<f64>,
    /// Position noise σ (m) of each coordinate. Default 1e-5.
    pub sigma_m: f64,
    /// Calibration settings (parameter scales, rank threshold).
    pub calibration: CalibrationOptions,
    /// Random K-subsets drawn for the comparison. Default 50.
    pub random_sets: usize,
    /// Maximum exchange passes after the greedy selection. Default 4.
    pub exchange_passes: usize,
}

impl PlanOptions {
    /// Defaults for `candidates` and `select`.
    pub fn new(candidates: usize, select: usize, seed: u64) -> Self {
        PlanOptions {
            candidates,
            select,
            seed,
            target_offset: Vector3::new(0.05, 0.03, 0.08),
            sigma_m: 1e-5,
            calibration: CalibrationOptions::default(),
            random_sets: 50,
            exchange_passes: 4,
        }
    }
}

/// The selected poses and how much better they are than random ones.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PosePlan {
    /// Joint values of the selected poses (rad or m), in selection order.
    pub selected: Vec<Vec<f64>>,
    /// Their indices among the candidates.
    pub candidate_indices: Vec<usize>,
    /// Identifiable combinations of the candidate set.
    pub rank: usize,
    /// Parameters of the model.
    pub n_params: usize,
    /// `log det` of the scaled information of the selection (identifiable subspace).
    pub log_det: f64,
    /// Mean `log det` of random K-subsets of the candidates (non-singular ones).
    pub random_log_det_mean: f64,
    /// Standard deviation of that over the random subsets.
    pub random_log_det_std: f64,
    /// Random subsets whose information was singular (left out of the mean).
    pub random_singular: usize,
    /// `exp((log det_random − log det_selected) / (2 r))`: how many times larger the geometric-mean
    /// parameter standard deviation of random poses is.
    pub parameter_sigma_ratio: f64,
    /// Predicted RMS position standard deviation (m) over all candidates after calibrating on the
    /// selection (noise `sigma_m`).
    pub position_sigma_m: f64,
    /// The same for the median random subset.
    pub random_position_sigma_m: f64,
    /// Observability indices of the selection.
    pub observability: Observability,
}

fn random_q(model: &Model, rng: &mut rand::rngs::StdRng) -> Vec<f64> {
    model
        .joints()
        .iter()
        .map(|j| {
            let (lo, hi) = j
                .limits
                .map_or((-std::f64::consts::PI, std::f64::consts::PI), |l| {
                    (l.lower, l.upper)
                });
            lo + (hi - lo) * rng.random::<f64>()
        })
        .collect()
}

/// `log det` of `Σ Aₖᵀ Aₖ` over `set`, or `None` when singular.
fn log_det(a: &[DMatrix<f64>], set: &[usize], r: usize) -> Option<f64> {
    let mut info = DMatrix::zeros(r, r);
    for &k in set {
        info.gemm_tr(1.0, &a[k], &a[k], 1.0);
    }
    let ch = info.cholesky()?;
    let l = ch.l_dirty();
    let mut s = 0.0;
    for i in 0..r {
        let d = l[(i, i)];
        if d <= 0.0 || !d.is_finite() {
            return None;
        }
        s += 2.0 * d.ln();
    }
    Some(s)
}

/// Inverse information of `set`, or `None` when singular.
fn inverse_info(a: &[DMatrix<f64>], set: &[usize], r: usize) -> Option<DMatrix<f64>> {
    let mut info = DMatrix::zeros(r, r);
    for &k in set {
        info.gemm_tr(1.0, &a[k], &a[k], 1.0);
    }
    info.cholesky().map(|c| c.inverse())
}

/// `log det(I₃ + A P Aᵀ)` and `A P` for one candidate.
fn gain(a: &DMatrix<f64>, p: &DMatrix<f64>) -> (f64, DMatrix<f64>) {
    let ap = a * p;
    let m = Matrix3::identity() + Matrix3::from_fn(|i, j| ap.row(i).dot(&a.row(j)));
    (m.determinant().max(f64::MIN_POSITIVE).ln(), ap)
}

/// Woodbury update `P ← P − (AP)ᵀ (I + A P Aᵀ)⁻¹ (AP)` for adding (`sign = 1`) or removing (`−1`) `A`.
fn update(p: &mut DMatrix<f64>, a: &DMatrix<f64>, sign: f64) {
    let ap = a * &*p;
    let m = Matrix3::identity() * sign + Matrix3::from_fn(|i, j| ap.row(i).dot(&a.row(j)));
    if let Some(mi) = m.try_inverse() {
        let mi = DMatrix::from_fn(3, 3, |i, j| mi[(i, j)]);
        let t = mi * &ap;
        *p -= ap.transpose() * t;
    }
}

fn rms_position_sigma(a: &[DMatrix<f64>], pinv: &DMatrix<f64>, sigma: f64) -> f64 {
    let n = a.len() as f64;
    let s: f64 = a
        .iter()
        .map(|ak| (ak * pinv * ak.transpose()).trace())
        .sum();
    (s / n).sqrt() * sigma
}

/// The D-optimal selection of `options.select` of `candidates` (see the module docs), with what the
/// comparisons need.
struct Selection {
    a: Vec<DMatrix<f64>>,
    r: usize,
    set: Vec<usize>,
    current: f64,
    jall: DMatrix<f64>,
    np: usize,
    scales: nalgebra::DVector<f64>,
}

fn select(model: &Model, candidates: &[Vec<f64>], options: &PlanOptions) -> Result<Selection> {
    let bad = |field: &str, value: String, problem: String| CalibError::BadValue {
        context: "plan-poses".into(),
        field: field.into(),
        value,
        problem,
    };
    let (n, k) = (candidates.len(), options.select);
    if k == 0 || n < k {
        return Err(bad(
            "--select",
            k.to_string(),
            format!("select at least one pose and at most the {n} candidates"),
        ));
    }
    let layout = ParamLayout::new(model, false);
    let np = layout.len();
    let mut params = KinematicParams::nominal(model.nq(), false);
    params.p_flange_target = options.target_offset;
    let chain = Chain::new(model, &params);
    let mut s = ChainScratch::new(model.nq());
    let mut buf = vec![0.0; 3 * np];
    let mut jall = DMatrix::zeros(3 * n, np);
    for (c, q) in candidates.iter().enumerate() {
        chain.forward(&mut s, q);
        chain.position_jacobian(&s, &layout, &mut buf);
        for row in 0..3 {
            for col in 0..np {
                jall[(3 * c + row, col)] = buf[row * np + col] / options.sigma_m;
            }
        }
    }
    let scales = options.calibration.scales.vector(&layout);
    let sub = Subspace::analyze(
        &jall,
        scales.as_slice(),
        options.calibration.lm.rank_rtol,
        options.calibration.lm.min_singular_value,
    );
    let r = sub.rank;
    if 3 * k < r + 1 {
        return Err(bad(
            "--select",
            k.to_string(),
            format!(
                "{r} parameter combinations are identifiable: select at least {} poses (3 equations each, \
                 one more than the parameters)",
                (r + 1).div_ceil(3)
            ),
        ));
    }
    let mut b = sub.v.columns(0, r).into_owned();
    for (row, d) in scales.iter().enumerate() {
        // Columns of J are physical; the scaled basis maps through D.
        b.row_mut(row).scale_mut(*d);
    }
    let a: Vec<DMatrix<f64>> = (0..n).map(|c| jall.rows(3 * c, 3) * &b).collect();

    // Greedy with a ridge much smaller than any candidate's information.
    let mean_trace = a.iter().map(|x| x.norm_squared()).sum::<f64>() / n as f64;
    let ridge = 1e-9 * mean_trace / r as f64;
    let mut p = DMatrix::identity(r, r) / ridge;
    let mut chosen = vec![false; n];
    let mut set = Vec::with_capacity(k);
    for _ in 0..k {
        let mut best = (f64::NEG_INFINITY, 0);
        for c in 0..n {
            if chosen[c] {
                continue;
            }
            let (g, _) = gain(&a[c], &p);
            if g > best.0 {
                best = (g, c);
            }
        }
        chosen[best.1] = true;
        set.push(best.1);
        update(&mut p, &a[best.1], 1.0);
    }
    // Exchange passes on the exact criterion.
    let mut current = log_det(&a, &set, r).unwrap_or(f64::NEG_INFINITY);
    for _ in 0..options.exchange_passes {
        let mut improved = false;
        for slot in 0..k {
            let out = set[slot];
            let mut rest = set.clone();
            rest.remove(slot);
            let Some(prest) = inverse_info(&a, &rest, r) else {
                continue;
            };
            let mut best = (f64::NEG_INFINITY, out);
            for c in 0..n {
                if chosen[c] && c != out {
                    continue;
                }
                let (g, _) = gain(&a[c], &prest);
                if g > best.0 {
                    best = (g, c);
                }
            }
            if best.1 != out {
                let mut trial = rest.clone();
                trial.insert(slot, best.1);
                if let Some(v) = log_det(&a, &trial, r)
                    && v > current + 1e-9
                {
                    chosen[out] = false;
                    chosen[best.1] = true;
                    set = trial;
                    current = v;
                    improved = true;
                }
            }
        }
        if !improved {
            break;
        }
    }
    Ok(Selection {
        a,
        r,
        set,
        current,
        jall,
        np,
        scales,
    })
}

/// Selects `options.select` of the given `candidates` (joint positions, rad or m) D-optimally, as
/// [`plan_poses`] does with its random candidates (`options.candidates` and `options.seed` are not
/// used). Returns the chosen candidate indices in selection order.
pub fn select_from(
    model: &Model,
    candidates: &[Vec<f64>],
    options: &PlanOptions,
) -> Result<Vec<usize>> {
    if let Some((i, c)) = candidates
        .iter()
        .enumerate()
        .find(|(_, c)| c.len() != model.nq())
    {
        return Err(CalibError::BadValue {
            context: "pose selection".into(),
            field: format!("candidate {i}"),
            value: format!("{} joint values", c.len()),
            problem: format!("robot '{}' has {} joints", model.name(), model.nq()),
        });
    }
    Ok(select(model, candidates, options)?.set)
}

/// Selects `options.select` poses of `options.candidates` random ones for calibrating `model`.
pub fn plan_poses(model: &Model, options: &PlanOptions) -> Result<PosePlan> {
    let bad = |field: &str, value: String, problem: String| CalibError::BadValue {
        context: "plan-poses".into(),
        field: field.into(),
        value,
        problem,
    };
    let (n, k) = (options.candidates, options.select);
    if k == 0 {
        return Err(bad(
            "--select",
            "0".into(),
            "select at least one pose".into(),
        ));
    }
    if n < k {
        return Err(bad(
            "--candidates",
            n.to_string(),
            format!("fewer candidates than poses to select ({k})"),
        ));
    }
    if options.sigma_m.is_nan() || options.sigma_m <= 0.0 {
        return Err(bad(
            "sigma",
            format!("{:?}", options.sigma_m),
            "must be > 0 m".into(),
        ));
    }
    let mut rng = rand::rngs::StdRng::seed_from_u64(options.seed);
    let candidates: Vec<Vec<f64>> = (0..n).map(|_| random_q(model, &mut rng)).collect();
    let Selection {
        a,
        r,
        set,
        current,
        jall,
        np,
        scales,
    } = select(model, &candidates, options)?;
    let pinv = inverse_info(&a, &set, r).ok_or_else(|| CalibError::BadValue {
        context: "plan-poses".into(),
        field: "--candidates".into(),
        value: n.to_string(),
        problem: "the candidates cannot determine the identifiable parameters; draw more".into(),
    })?;
    let position_sigma_m = rms_position_sigma(&a, &pinv, options.sigma_m);

    // Random subsets of the same size.
    let mut logs = Vec::new();
    let mut sigmas = Vec::new();
    let mut singular = 0;
    for _ in 0..options.random_sets {
        let mut idx: Vec<usize> = (0..n).collect();
        for i in 0..k {
            let j = i + (rng.random::<f64>() * (n - i) as f64) as usize;
            idx.swap(i, j.min(n - 1));
        }
        let subset = &idx[..k];
        match (log_det(&a, subset, r), inverse_info(&a, subset, r)) {
            (Some(v), Some(pi)) => {
                logs.push(v);
                sigmas.push(rms_position_sigma(&a, &pi, options.sigma_m));
            }
            _ => singular += 1,
        }
    }
    let mean = logs.iter().sum::<f64>() / logs.len().max(1) as f64;
    let std = (logs.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>()
        / logs.len().max(1) as f64)
        .sqrt();
    sigmas.sort_by(f64::total_cmp);
    let random_position_sigma_m = sigmas
        .get(sigmas.len() / 2)
        .copied()
        .unwrap_or(f64::INFINITY);

    // Observability of the selection (same scaling as calibrate).
    let mut jsel = DMatrix::zeros(3 * k, np);
    for (i, &c) in set.iter().enumerate() {
        jsel.rows_mut(3 * i, 3).copy_from(&jall.rows(3 * c, 3));
    }
    let obs_sel = Observability::from_subspace(&Subspace::analyze(
        &jsel,
        scales.as_slice(),
        options.calibration.lm.rank_rtol,
        options.calibration.lm.min_singular_value,
    ));
    Ok(PosePlan {
        selected: set.iter().map(|&c| candidates[c].clone()).collect(),
        candidate_indices: set,
        rank: r,
        n_params: np,
        log_det: current,
        random_log_det_mean: mean,
        random_log_det_std: std,
        random_singular: singular,
        parameter_sigma_ratio: if logs.is_empty() {
            f64::INFINITY
        } else {
            ((current - mean) / (2.0 * r as f64)).exp()
        },
        position_sigma_m,
        random_position_sigma_m,
        observability: obs_sel,
    })
}

impl PosePlan {
    /// CSV text `pose,q1..qN` of the selected poses (pose ids 0..K).
    pub fn to_csv(&self) -> String {
        let nq = self.selected.first().map_or(0, Vec::len);
        let mut header = vec!["pose".to_string()];
        header.extend((1..=nq).map(|j| format!("q{j}")));
        let rows: Vec<(i64, Vec<f64>)> = self
            .selected
            .iter()
            .enumerate()
            .map(|(i, q)| (i as i64, q.clone()))
            .collect();
        crate::io::csv_text(&header, &rows)
    }
}
