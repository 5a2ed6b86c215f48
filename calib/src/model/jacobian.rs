//! The Jacobian of one row's predicted target position with respect to every parameter of a
//! [`ParamLayout`]: the chain's kinematic columns ([`Chain::position_jacobian_of`]), turned into
//! those of the grown prediction ([`grow_columns`]), and the extension columns
//! ([`extension_columns`]). The solver ([`crate::fit::problem`]) and the prediction uncertainty
//! ([`crate::model::uncertainty`]) share it.

use crate::model::chain::Chain;
use crate::model::extensions::Term;
use crate::model::params::ParamLayout;
use crate::model::physical_row::{PredictScratch, RowPrediction};
use nalgebra::Vector3;

/// Turns the kinematic position Jacobian of `p_kin` into that of the grown prediction
/// `p = t + (1 + γ)(p_kin − t)` (`t` the base origin, tracker frame): every column that moves `p_kin`
/// only is multiplied by `1 + γ`; the base twist moves `p` rigidly, `[−[p], I]` at the final `p` (m).
pub fn grow_columns(
    layout: &ParamLayout,
    campaign: usize,
    growth: f64,
    p: &Vector3<f64>,
    block: &mut [f64],
) {
    let np = layout.len();
    let kb = layout.campaign_base(campaign);
    let ec_cross_p = [
        Vector3::new(0.0, -p.z, p.y),
        Vector3::new(p.z, 0.0, -p.x),
        Vector3::new(-p.y, p.x, 0.0),
    ];
    for row in 0..3 {
        let cols = &mut block[row * np..row * np + layout.kinematic_len()];
        for (k, v) in cols.iter_mut().enumerate() {
            if !(kb..kb + 6).contains(&k) {
                *v *= 1.0 + growth;
            }
        }
        for c in 0..3 {
            cols[kb + c] = ec_cross_p[c][row];
            cols[kb + 3 + c] = if row == c { 1.0 } else { 0.0 };
        }
    }
}

/// How a bending term moves the target of one row: the chain and its evaluation, the row's bends.
pub struct BendColumns<'c> {
    /// The chain.
    pub chain: &'c Chain,
    /// Its evaluation at the row.
    pub scratch: &'c PredictScratch,
    /// `1 + γ`: the growth multiplies every displacement of `p_kin`.
    pub grown: f64,
    /// `true` for the position rows (`ω × (p_kin − oᵢ)`), `false` for the orientation rows (`ω`).
    pub position: bool,
}

impl BendColumns<'_> {
    /// The column of a unit bend of joint `joint` about axis `about` of its frame (3 rows).
    fn column(&self, joint: usize, about: usize) -> Vector3<f64> {
        let local = Vector3::ith(about, 1.0);
        let s = self.scratch;
        let (w, o) = self
            .chain
            .bend_axis(&s.chain, joint, &local, &s.bend[joint]);
        if self.position {
            w.cross(&(s.chain.p_tracker - o)) * self.grown
        } else {
            w
        }
    }
}

/// Fills the extension columns of a 3-row Jacobian block (row-major, `layout.len()` columns) whose
/// kinematic columns are set: a joint-angle term is the joint's zero-offset column (plus `a` times
/// that of each joint coupled to it with multiplier `a`) times its regressor,
/// the growth term `lever` times its regressor, a bending term the bend's own column
/// ([`Chain::bend_axis`]) times its regressor.
pub fn extension_columns(
    layout: &ParamLayout,
    coef: &[f64],
    lever: &Vector3<f64>,
    bend: &BendColumns<'_>,
    block: &mut [f64],
) {
    let np = layout.len();
    for (e, (p, &g)) in layout.extensions.iter().zip(coef).enumerate() {
        let ke = layout.extension(e);
        match p.term {
            Term::JointAngle { joint } => {
                // A driven joint's angle moves the joints coupled to it through the linkage.
                for row in 0..3 {
                    let mut c = block[row * np + layout.zero_offset(joint)];
                    for &(k, a) in layout.couplings.followers(joint) {
                        c += a * block[row * np + layout.zero_offset(k)];
                    }
                    block[row * np + ke] = c * g;
                }
            }
            Term::Growth => {
                for row in 0..3 {
                    block[row * np + ke] = lever[row] * g;
                }
            }
            Term::Bend { joint, about } => {
                let c = bend.column(joint, about);
                for row in 0..3 {
                    block[row * np + ke] = c[row] * g;
                }
            }
        }
    }
}

/// The whole position Jacobian (3 × [`ParamLayout::len`], row-major, m per unit) of the row last
/// evaluated into `s` by [`crate::model::physical_row::physical_row`] (its result `pred`, campaign
/// index `campaign`, regressors `coef` of the row).
pub fn position_jacobian_row(
    chain: &Chain,
    layout: &ParamLayout,
    s: &PredictScratch,
    pred: &RowPrediction,
    campaign: usize,
    coef: &[f64],
    out: &mut [f64],
) {
    let np = layout.len();
    chain.position_jacobian_of(&s.chain, layout, true, &mut out[..3 * np]);
    if pred.growth != 0.0 {
        grow_columns(
            layout,
            campaign,
            pred.growth,
            &pred.p_tracker,
            &mut out[..3 * np],
        );
    }
    let bend = BendColumns {
        chain,
        scratch: s,
        grown: 1.0 + pred.growth,
        position: true,
    };
    extension_columns(layout, coef, &pred.lever, &bend, &mut out[..3 * np]);
}
