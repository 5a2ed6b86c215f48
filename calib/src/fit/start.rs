//! The start of the fit: nominal joints, the closed-form tracker-to-base transform (Kabsch), the target
//! at the flange; and the generic rank of the kinematic model.

use super::CalibrationOptions;
use crate::fit::problem::{KinematicProblem, Observations};
use crate::lm::Subspace;
use crate::model::chain::{Chain, ChainScratch};
use crate::model::extensions::Regressors;
use crate::model::params::{KinematicParams, ParamLayout};
use nalgebra::{DMatrix, Matrix3, Vector3};
use sim::Model;
use sim::lie::{Pose, pose_from};

/// Rigid transform `T` with `dst ≈ T src` in the least-squares sense (Kabsch / Horn).
pub(crate) fn kabsch(src: &[Vector3<f64>], dst: &[Vector3<f64>]) -> Pose {
    let n = src.len() as f64;
    let cs = src.iter().sum::<Vector3<f64>>() / n;
    let cd = dst.iter().sum::<Vector3<f64>>() / n;
    let mut h = Matrix3::zeros();
    for (a, b) in src.iter().zip(dst) {
        h += (a - cs) * (b - cd).transpose();
    }
    let svd = h.svd(true, true);
    let (u, vt) = (svd.u.unwrap(), svd.v_t.unwrap());
    let mut d = Matrix3::identity();
    if (vt.transpose() * u.transpose()).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    let r = vt.transpose() * d * u.transpose();
    pose_from(r, cd - r * cs)
}

/// Projection of a 3×3 matrix onto the nearest rotation.
fn nearest_rotation(m: &Matrix3<f64>) -> Matrix3<f64> {
    let svd = m.svd(true, true);
    let (u, vt) = (svd.u.unwrap(), svd.v_t.unwrap());
    let mut d = Matrix3::identity();
    if (u * vt).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    u * d * vt
}

/// The start: nominal joints, closed-form base transform, target at the flange (see module docs).
/// With several campaigns (the rows' `campaign` ids, ascending), each gets its own closed-form
/// `T_tracker_base` from its rows; the target is shared.
pub fn initial_params(model: &Model, obs: &Observations) -> KinematicParams {
    let orientation = obs.orientation.is_some();
    let mut params = KinematicParams::nominal(model.nq(), orientation);
    let chain = Chain::new(model, &params);
    let mut s = ChainScratch::new(model.nq());
    let mut src = Vec::with_capacity(obs.len());
    let mut rots = Vec::with_capacity(obs.len());
    for r in 0..obs.len() {
        chain.forward(&mut s, obs.q_row(r));
        src.push(s.p_tracker);
        rots.push(*s.t_tracker_flange.rotation.matrix());
    }
    let ids = obs.campaign_ids();
    let bases: Vec<Pose> = match &obs.campaign {
        None => vec![kabsch(&src, &obs.position)],
        Some(_) if ids.len() == 1 => vec![kabsch(&src, &obs.position)],
        Some(campaign) => ids
            .iter()
            .map(|&id| {
                let rows: Vec<usize> = (0..obs.len()).filter(|&r| campaign[r] == id).collect();
                let a: Vec<Vector3<f64>> = rows.iter().map(|&r| src[r]).collect();
                let b: Vec<Vector3<f64>> = rows.iter().map(|&r| obs.position[r]).collect();
                kabsch(&a, &b)
            })
            .collect(),
    };
    params.t_tracker_base = bases[0];
    params = params.with_campaigns(&ids, &bases[1..], false);
    if let Some(meas) = &obs.orientation {
        let index = obs
            .campaign_indices(&params)
            .expect("the start registers every campaign of its rows");
        let mut sum = Matrix3::zeros();
        for (r, (rf, rm)) in rots.iter().zip(meas).enumerate() {
            let rb = params.t_tracker_base_of(index[r]).rotation.matrix();
            sum += (rb * rf).transpose() * rm;
        }
        params.r_flange_target = Some(nearest_rotation(&sum));
    }
    params
}

/// Number of identifiable parameter combinations of the kinematic model of `model` for a generic pose
/// set (random configurations within the limits, a target off the flange axes).
pub fn generic_rank(model: &Model, orientation: bool, options: &CalibrationOptions) -> usize {
    use rand::{RngExt, SeedableRng};
    let layout = ParamLayout::new(model, orientation);
    let dim = if orientation { 6 } else { 3 };
    let poses = layout.len() / dim + 12;
    let mut rng = rand::rngs::StdRng::seed_from_u64(0x5eed);
    let n = model.nq();
    let mut q = Vec::with_capacity(poses * n);
    for _ in 0..poses {
        for j in model.joints() {
            let (lo, hi) = j.limits.map_or((-3.0, 3.0), |l| (l.lower, l.upper));
            q.push(lo + (hi - lo) * rng.random::<f64>());
        }
    }
    let mut params = KinematicParams::nominal(n, orientation);
    params.p_flange_target = Vector3::new(0.031, -0.022, 0.083);
    let chain = Chain::new(model, &params);
    let mut s = ChainScratch::new(n);
    let mut position = Vec::with_capacity(poses);
    let mut rot = Vec::with_capacity(poses);
    for k in 0..poses {
        chain.forward(&mut s, &q[k * n..(k + 1) * n]);
        position.push(s.p_tracker);
        rot.push(s.r_tracker_target);
    }
    let obs = Observations {
        n_joints: n,
        q,
        position,
        orientation: orientation.then_some(rot),
        sigma: vec![1e-5; poses],
        sigma_rotation: options.noise.orientation_sigma_rad,
        weight: vec![1.0; poses],
        pose: (0..poses as i64).collect(),
        source_row: (0..poses).collect(),
        ext: Regressors::none(),
        campaign: None,
    };
    let all: Vec<usize> = (0..layout.len()).collect();
    let mut prob = KinematicProblem::new(model, &obs, params, all);
    let mut j = DMatrix::zeros(poses * dim, layout.len());
    crate::lm::LeastSquaresProblem::set_params(&mut prob, &vec![0.0; layout.len()]);
    crate::lm::LeastSquaresProblem::jacobian(&mut prob, &mut j);
    let scales = options.scales.vector(&layout);
    Subspace::analyze(
        &j,
        scales.as_slice(),
        options.lm.rank_rtol,
        options.lm.min_singular_value,
    )
    .rank
}
