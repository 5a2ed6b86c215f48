//! Gravity torques of a prepared [`Chain`] and their Hessian: what gravity-mode backlash
//! ([`super::gear_backlash`]) and joint compliance ([`super::joint_compliance`]) read, in the real
//! geometry (see the joint-compliance module docs for why the real one).

use super::chain::Chain;
use crate::lie::Pose;
use crate::statics::Payload;
use nalgebra::{Point3, Vector3};

/// Mass (kg) and centre of mass (joint frame, m) of each moving body, in chain order.
pub(crate) type BodyMasses = [(f64, Vector3<f64>)];

/// Workspace for gravity torques and the equilibrium solve on an `n`-joint chain.
#[derive(Clone, Debug, Default)]
pub(crate) struct GravityWork {
    /// Joint axes in the base frame (unit).
    pub w: Vec<Vector3<f64>>,
    /// First moment of everything beyond joint `i` about joint `i`'s origin, `Σ m (c − pᵢ)` (kg m).
    pub r: Vec<Vector3<f64>>,
    /// Mass beyond joint `i`, joint `i`'s body included (kg).
    pub mass: Vec<f64>,
    /// Holding torques (N m or N).
    pub tau: Vec<f64>,
    /// Hessian `∂τ/∂θ`, row-major n×n (N m/rad).
    pub hess: Vec<f64>,
    /// Newton matrix, row-major n×n.
    pub jac: Vec<f64>,
    /// Newton right-hand side / step.
    pub step: Vec<f64>,
    /// Row permutation of the LU factors in `jac`.
    pub piv: Vec<usize>,
    /// `wⱼ·g` per joint (m/s²).
    pub wg: Vec<f64>,
    /// `rⱼ·g` per joint (kg m²/s²).
    pub rg: Vec<f64>,
    /// The sag `C τ` (or `A C Aᵀ τ` with coupled joints) per joint (rad or m).
    pub sag: Vec<f64>,
}

impl GravityWork {
    /// Workspace for `n` joints.
    pub fn new(n: usize) -> Self {
        GravityWork {
            w: vec![Vector3::zeros(); n],
            r: vec![Vector3::zeros(); n],
            mass: vec![0.0; n],
            tau: vec![0.0; n],
            hess: vec![0.0; n * n],
            jac: vec![0.0; n * n],
            step: vec![0.0; n],
            piv: vec![0; n],
            wg: vec![0.0; n],
            rg: vec![0.0; n],
            sag: vec![0.0; n],
        }
    }
}

/// Holding torques `τ_g` (into `ws.tau`) of the chain whose frames `poses` and `flange` were just
/// evaluated, for `gravity` (base frame, m/s²); also fills `ws.w`, `ws.r`, `ws.mass` for the Hessian.
pub(crate) fn chain_gravity_torques(
    chain: &Chain,
    poses: &[Pose],
    flange: &Pose,
    bodies: &BodyMasses,
    payload: Option<&Payload>,
    gravity: &Vector3<f64>,
    ws: &mut GravityWork,
) {
    // Walk from the tip, as `statics::gravity_torques`: mass and first moment Σ m c beyond joint i.
    let mut mass = 0.0;
    let mut moment = Vector3::zeros();
    if let Some(pl) = payload {
        let c = flange * Point3::from(Vector3::from(pl.com));
        mass += pl.mass;
        moment += c.coords * pl.mass;
    }
    for i in (0..chain.nq()).rev() {
        let t = &poses[i];
        let (m, com) = &bodies[i];
        let c = t * Point3::from(*com);
        mass += m;
        moment += c.coords * *m;
        let joint = &chain.joints[i];
        let w = t.rotation * joint.axis;
        let r = moment - t.translation.vector * mass;
        ws.tau[i] = if joint.rotational {
            -w.dot(&r.cross(gravity))
        } else {
            -w.dot(&(gravity * mass))
        };
        ws.w[i] = w;
        ws.r[i] = r;
        ws.mass[i] = mass;
    }
}

/// Hessian `H = ∂τ_g/∂θ` (into `ws.hess`, row-major) from the quantities of the last
/// [`chain_gravity_torques`] call. For `j ≥ i` (joint `j` moves everything beyond `i`'s part that
/// `τᵢ` depends on), with `rⱼ` the first moment beyond `j` about joint `j` and `mⱼ` the mass beyond `j`:
///
/// ```text
/// i, j rotational:            Hᵢⱼ = −[(wᵢ·rⱼ)(wⱼ·g) − (wᵢ·wⱼ)(rⱼ·g)]
/// i rotational, j prismatic:  Hᵢⱼ = −mⱼ wᵢ·(wⱼ × g)
/// i prismatic:                Hᵢⱼ = 0
/// ```
///
/// and `Hⱼᵢ = Hᵢⱼ` (a Hessian of the potential energy).
pub(crate) fn chain_gravity_hessian(chain: &Chain, gravity: &Vector3<f64>, ws: &mut GravityWork) {
    let n = chain.nq();
    for j in 0..n {
        ws.wg[j] = ws.w[j].dot(gravity);
        ws.rg[j] = ws.r[j].dot(gravity);
    }
    for i in 0..n {
        let wi = ws.w[i];
        let rot_i = chain.joints[i].rotational;
        for j in i..n {
            let h = if !rot_i {
                0.0
            } else if chain.joints[j].rotational {
                -(wi.dot(&ws.r[j]) * ws.wg[j] - wi.dot(&ws.w[j]) * ws.rg[j])
            } else {
                -ws.mass[j] * wi.dot(&ws.w[j].cross(gravity))
            };
            ws.hess[i * n + j] = h;
            ws.hess[j * n + i] = h;
        }
    }
}
