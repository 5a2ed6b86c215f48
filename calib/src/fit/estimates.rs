//! Parameter estimates in reporting form, with standard deviations, and strong correlations.

use super::report::{Correlation, ParameterEstimate};
use crate::fit::identifiability::NullSpaceReport;
use crate::lie3::{left_jacobian_inverse, log_rotation};
use crate::lm::Subspace;
use crate::model::params::{KinematicParams, ParamKind, ParamLayout};
use crate::units::Unit;
use nalgebra::{DMatrix, DVector, Matrix3, Matrix3x6};
use sim::lie::skew;

/// True when the linear functional `a` (physical units) of a step does not see the null space.
fn invariant(a: &DVector<f64>, sub: &Subspace) -> bool {
    let p = sub.n_params();
    let da = DVector::from_fn(p, |k, _| a[k] * sub.scales[k]);
    let n = da.norm();
    if n == 0.0 {
        return true;
    }
    let null = sub.v.columns(sub.rank, p - sub.rank);
    (null.tr_mul(&da)).norm() <= 1e-6 * n
}

/// Parameter estimates with standard deviations, in reporting form: joint error twists and zero offsets
/// as they are; `T_tracker_base` as translation (m) and rotation vector (rad); the target position and,
/// with orientation, its rotation vector.
pub(super) fn estimates(
    layout: &ParamLayout,
    params: &KinematicParams,
    cov: &DMatrix<f64>,
    sub: &Subspace,
) -> Vec<ParameterEstimate> {
    let p = layout.len();
    let mut out = Vec::with_capacity(p);
    let mut push = |name: String, unit: Unit, value: f64, a: DVector<f64>| {
        let var = (a.transpose() * cov * &a)[(0, 0)];
        out.push(ParameterEstimate {
            name,
            unit,
            value,
            sigma: var.max(0.0).sqrt(),
            identifiable_alone: invariant(&a, sub),
        });
    };
    let unit_vec = |k: usize| {
        let mut a = DVector::zeros(p);
        a[k] = 1.0;
        a
    };
    for i in 0..layout.n_joints {
        let xi = params.joint_twist(i);
        for c in 0..6 {
            let k = layout.joint_twist(i) + c;
            push(layout.name(k), layout.unit(k), xi[c], unit_vec(k));
        }
        let k = layout.zero_offset(i);
        push(
            layout.name(k),
            layout.unit(k),
            params.zero_offset[i],
            unit_vec(k),
        );
    }
    for c in 0..layout.n_campaigns() {
        // ` (campaign ID)` with several campaigns; the shared target has none.
        let suffix = if layout.n_campaigns() > 1 {
            format!(" (campaign {})", layout.campaign_ids[c])
        } else {
            String::new()
        };
        // Base: t ← exp(β) t moves the origin by ω × t + v; φ = log R moves by J_l⁻¹(φ) ω.
        let kb = layout.campaign_base(c);
        let base = params.t_tracker_base_of(c);
        let t = base.translation.vector;
        let mut lt = Matrix3x6::zeros();
        lt.fixed_view_mut::<3, 3>(0, 0).copy_from(&(-skew(&t)));
        lt.fixed_view_mut::<3, 3>(0, 3)
            .copy_from(&Matrix3::identity());
        for (a, axis) in ["x", "y", "z"].iter().enumerate() {
            let mut f = DVector::zeros(p);
            for c in 0..6 {
                f[kb + c] = lt[(a, c)];
            }
            push(
                format!("T_tracker_base {axis}{suffix}"),
                Unit::Metre,
                t[a],
                f,
            );
        }
        let phi = log_rotation(base.rotation.matrix());
        let jl = left_jacobian_inverse(&phi);
        for (a, axis) in ["x", "y", "z"].iter().enumerate() {
            let mut f = DVector::zeros(p);
            for c in 0..3 {
                f[kb + c] = jl[(a, c)];
            }
            push(
                format!("T_tracker_base rotation φ_{axis}{suffix}"),
                Unit::Radian,
                phi[a],
                f,
            );
        }
        if c > 0 && !layout.campaign_targets {
            continue;
        }
        let kt = layout.campaign_target_position(c);
        let target = params.p_flange_target_of(c);
        for a in 0..3 {
            push(
                layout.name(kt + a),
                Unit::Metre,
                target[a],
                unit_vec(kt + a),
            );
        }
        if let (Some(ko), Some(r)) = (
            layout.campaign_target_orientation(c),
            params.r_flange_target_of(c),
        ) {
            // R ← R exp(ρ): φ moves by J_r⁻¹(φ) ρ = J_l⁻¹(−φ) ρ.
            let phi = log_rotation(r);
            let jr = left_jacobian_inverse(&-phi);
            let tsuffix = if c > 0 { suffix.as_str() } else { "" };
            for (a, axis) in ["x", "y", "z"].iter().enumerate() {
                let mut f = DVector::zeros(p);
                for c in 0..3 {
                    f[ko + c] = jr[(a, c)];
                }
                push(
                    format!("target rotation φ_{axis}{tsuffix}"),
                    Unit::Radian,
                    phi[a],
                    f,
                );
            }
        }
    }
    for (e, x) in params.extension.iter().enumerate() {
        let k = layout.extension(e);
        push(layout.name(k), layout.unit(k), *x, unit_vec(k));
    }
    debug_assert!(matches!(layout.kind(0), ParamKind::JointTwist { .. }));
    out
}

/// Pairs of individually identifiable parameters with |ρ| ≥ 0.95, strongest first, at most 20.
pub(super) fn correlations(
    layout: &ParamLayout,
    cov: &DMatrix<f64>,
    null: &NullSpaceReport,
) -> Vec<Correlation> {
    let alone: Vec<usize> = (0..layout.len())
        .filter(|&k| null.identifiable_alone[k] && cov[(k, k)] > 0.0)
        .collect();
    let mut out = Vec::new();
    for (x, &a) in alone.iter().enumerate() {
        for &b in &alone[x + 1..] {
            let rho = cov[(a, b)] / (cov[(a, a)] * cov[(b, b)]).sqrt();
            if rho.abs() >= 0.95 {
                out.push(Correlation {
                    a: layout.name(a),
                    b: layout.name(b),
                    rho,
                });
            }
        }
    }
    out.sort_by(|x, y| y.rho.abs().total_cmp(&x.rho.abs()));
    out.truncate(20);
    out
}
