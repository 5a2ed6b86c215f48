//! One row's physical prediction, the evaluation that the solver ([`crate::fit::problem`]), the
//! prediction path ([`crate::model::predict`]) and the `learned:adjoint` fit ([`crate::model::learned::adjoint`])
//! share, with its per-thread workspaces.
//!
//! ```text
//! θ = q + Σₑ xₑ gₑ(row)                    (joint-angle terms of the extensions)
//! φᵢ = Σₑ xₑ gₑ(row) e_about               (bending terms, turning the chain at joint i)
//! p_kin = T_tracker_base(c) · T_base_flange(θ, φ) · p_flange
//! p = t_base + (1 + γ) (p_kin − t_base),  γ = Σₑ xₑ gₑ(row)   (growth terms)
//! ```
//!
//! The bend is the robot's (the same in every campaign); the campaign `c` only selects the tracker
//! frame and the target.
//!
//! A leaf: it uses the chain, the parameters and the extensions' regressors only, so that the
//! modules above it can use each other's results without importing each other.

use crate::model::chain::{Chain, ChainScratch};
use crate::model::extensions::{Regressors, apply, bends};
use crate::model::params::KinematicParams;
use nalgebra::Vector3;

/// One row's physical prediction (no learned correction).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RowPrediction {
    /// Predicted target position, tracker frame (m), growth applied.
    pub p_tracker: Vector3<f64>,
    /// `p_kin − t_tracker_base` (m): the lever that the growth multiplies.
    pub lever: Vector3<f64>,
    /// The growth factor `γ` (dimensionless; 0 without growth terms).
    pub growth: f64,
}

/// Per-evaluation workspace of a [`crate::model::predict::Prediction`]: made once, reused without
/// allocating.
#[derive(Clone, Debug)]
pub struct PredictScratch {
    /// The chain's frames at the last row (tracker frame), with `r_tracker_target`.
    pub chain: ChainScratch,
    /// Effective joint values `θ` of the last row (rad or m).
    pub theta: Vec<f64>,
    /// Bending rotation vector of each joint at the last row (rad, joint frame; link deflection).
    pub bend: Vec<Vector3<f64>>,
    /// The chain of a `learned:adjoint` model, re-prepared for each row.
    pub adjoint: Option<AdjointScratch>,
}

impl PredictScratch {
    /// Workspace for a robot of `n` joints.
    pub fn new(n: usize) -> Self {
        PredictScratch {
            chain: ChainScratch::new(n),
            theta: vec![0.0; n],
            bend: vec![Vector3::zeros(); n],
            adjoint: None,
        }
    }
}

/// Per-thread workspace of a `learned:adjoint` model's rows: the chain and parameters at the row's
/// configuration-dependent error twists and zero offsets (filled by
/// [`crate::model::learned::adjoint::AdjointModel::prepare`]).
#[derive(Clone, Debug)]
pub struct AdjointScratch {
    /// The chain at the row's parameters.
    pub chain: Chain,
    /// The row's parameters.
    pub params: KinematicParams,
    /// The row's features (the model's polynomial terms of the joint values).
    pub phi: Vec<f64>,
}

impl AdjointScratch {
    /// A workspace from the physical model's `chain` and `params`, for a model of `n_features`
    /// features.
    pub fn new(chain: &Chain, params: &KinematicParams, n_features: usize) -> Self {
        AdjointScratch {
            chain: chain.clone(),
            params: params.clone(),
            phi: vec![0.0; n_features],
        }
    }
}

/// The physical prediction of row `r` (regressors `regs`, joint values `q`) in campaign `campaign`
/// (index) by `chain`, prepared at `params`, into `s`: the one evaluation every path uses.
#[inline]
pub fn physical_row(
    chain: &Chain,
    params: &KinematicParams,
    regs: &Regressors,
    r: usize,
    q: &[f64],
    campaign: usize,
    s: &mut PredictScratch,
) -> RowPrediction {
    let growth = apply(regs, &params.extension, r, q, &mut s.theta);
    if bends(regs, &params.extension, r, &mut s.bend) {
        chain.forward_bent(&mut s.chain, &s.theta, campaign, &s.bend);
    } else {
        chain.forward_in(&mut s.chain, &s.theta, campaign);
    }
    let lever = s.chain.p_tracker - chain.t_tracker_base(campaign).translation.vector;
    RowPrediction {
        p_tracker: s.chain.p_tracker + growth * lever,
        lever,
        growth,
    }
}
