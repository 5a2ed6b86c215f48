//! Joint compliance, as the estimator models it: `θᵢ = qᵢ − cᵢ τᵢ(q)`.
//!
//! `cᵢ` is joint `i`'s compliance (rad/(N m); m/N for a prismatic joint) and `τᵢ(q)` the torque (N m)
//! the joint applies to hold the nominal arm and the payload still at the commanded `q` against gravity
//! ([`sim::statics::gravity_torques`]). This is the first-order solution of the spring balance
//! `K (q − θ) = τ(θ)`; the exact one differs by `C H C τ` (`H = ∂τ/∂θ`), second order in the compliance:
//! below 0.1 µrad for the iiwa 7's 1e-4 rad/(N m) and 50 N m.
//! A joint whose torque does not change over the data (joint 1 of an upright arm) cannot be identified;
//! the solver says so and leaves its compliance at zero.
//!
//! # Plausibility bounds
//! `0 ≤ cᵢ ≤` [`MAX_RAD_PER_NM`] (1e-2 rad/(N m), a stiffness of at least 100 N m/rad; prismatic
//! joints [`MAX_M_PER_N`], 1e-4 m/N). A negative compliance is impossible: no spring turns a joint
//! along its load. Harmonic-drive joints of lightweight arms are 5e3–2e4 N m/rad, industrial arms
//! stiffer still, and the series-elastic springs of compliant humanoid joints a few hundred N m/rad;
//! below 100 N m/rad a 50 N m holding torque would sag the joint by half a radian, which no
//! position-controlled arm does. A fitted compliance beyond the bound stands in for another error.

use super::per_joint_params;
use super::{Cause, CauseModel, ExtensionParam, ExtensionSettings, PlotAxis, RowInputs, Term};
use crate::units::Unit;
use sim::Model;
use sim::measurement_table::MeasurementTable;

/// Expected compliance (rad/(N m)): harmonic-drive joints of lightweight arms are 5e3–2e4 N m/rad.
pub const SCALE_RAD_PER_NM: f64 = 1e-4;

/// Largest plausible compliance of a rotational joint (rad/(N m)): stiffness 100 N m/rad (module
/// docs).
pub const MAX_RAD_PER_NM: f64 = 1e-2;

/// Largest plausible compliance of a prismatic joint (m/N): stiffness 1e4 N/m, 1 mm under 10 N.
pub const MAX_M_PER_N: f64 = 1e-4;

/// Joint compliance: one compliance per joint, regressor `−τᵢ`.
pub struct JointCompliance;

impl CauseModel for JointCompliance {
    fn cause(&self) -> Cause {
        Cause::JointCompliance
    }

    fn usable(&self, model: &Model, _table: &MeasurementTable) -> std::result::Result<(), String> {
        model
            .require_inertials()
            .map_err(|e| format!("the gravity torques it needs cannot be computed: {e}"))
    }

    fn needs_gravity_torque(&self, _settings: &ExtensionSettings) -> bool {
        true
    }

    fn needs_equilibrium(&self) -> bool {
        true
    }

    fn params(&self, model: &Model, _settings: &ExtensionSettings) -> Vec<ExtensionParam> {
        per_joint_params(
            model,
            Cause::JointCompliance,
            "compliance",
            Unit::RadianPerNewtonMetre,
            Unit::MetrePerNewton,
            SCALE_RAD_PER_NM,
        )
    }

    /// Regressors `−τᵢ` (N m) from the row's gravity torques.
    fn regressors(&self, _settings: &ExtensionSettings, row: &RowInputs<'_>, out: &mut [f64]) {
        for (o, t) in out.iter_mut().zip(row.tau) {
            *o = -t;
        }
    }

    /// `Δθᵢ = −cᵢ τᵢ(θ)`: `∂Δθᵢ/∂θⱼ = −cᵢ ∂τᵢ/∂θⱼ` (exact; [`torque_jacobian`]).
    fn angle_jacobian(
        &self,
        _settings: &ExtensionSettings,
        row: &RowInputs<'_>,
        torque_jacobian: &[f64],
        x: &[f64],
        _d_dq: &mut [f64],
        d_dtheta: &mut [f64],
    ) {
        let n = row.q.len();
        for (i, c) in x.iter().enumerate() {
            for j in 0..n {
                d_dtheta[i * n + j] -= c * torque_jacobian[i * n + j];
            }
        }
    }

    fn evidence_subject(&self, joints: &str) -> String {
        format!("the gravity torque of {joints}")
    }

    fn remark(&self, value: f64) -> String {
        if value > 0.0 {
            format!(" (stiffness {:.0} N m/rad)", 1.0 / value)
        } else {
            " (negative: no spring; it stands in for another error)".to_string()
        }
    }

    fn implausible(&self, param: &ExtensionParam, value: f64) -> Option<String> {
        let (max, words) = if param.unit == Unit::MetrePerNewton {
            (MAX_M_PER_N, "1e-4 m/N (stiffness below 1e4 N/m)")
        } else {
            (
                MAX_RAD_PER_NM,
                "1e-2 rad/(N m) (stiffness below 100 N m/rad)",
            )
        };
        super::outside_zero_to(
            value,
            max,
            "negative compliance: no spring turns a joint along its load",
            || format!("a compliance above {words}: no position-controlled joint is that soft"),
        )
    }

    fn signature(&self) -> &'static str {
        "turns a joint about its own axis in proportion to its gravity torque"
    }

    fn plot_axis(&self, term: Term) -> PlotAxis {
        PlotAxis {
            sign: -1.0,
            label: format!(
                "holding torque of joint {} (N m)",
                term.joint().map_or(0, |j| j + 1)
            ),
        }
    }
}

/// `∂τᵢ/∂θⱼ` (N m per rad; N per rad, N m per m, N per m for prismatic joints), row-major `nq × nq`
/// into `out`, of the holding torques `τ` that [`sim::statics::gravity_torques`] left in `data` (its
/// joint frames at `θ`), for `gravity` (base frame, m/s²) and `payload`.
///
/// With `wᵢ`, `oᵢ` joint `i`'s axis and origin (base frame), `mᵢ` and `Sᵢ = Σ m c` the mass and first
/// moment of everything beyond joint `i` (its link, the links after it, the payload), and
/// `dᵢ = Sᵢ − mᵢ oᵢ`, a rotational joint holds `τᵢ = −wᵢ · (dᵢ × g)`, a prismatic one `τᵢ = −wᵢ · g mᵢ`.
/// A turn of a rotational joint `j ≥ i` moves only what is beyond `j`: `δSᵢ = wⱼ × dⱼ`; a turn of
/// `j < i` turns `wᵢ`, `oᵢ` and `dᵢ` together, which is gravity turned the other way:
/// `δτᵢ = −wᵢ · (dᵢ × (−wⱼ × g))` (`−(wⱼ × wᵢ) · g mᵢ` for a prismatic `i`). A slide of a prismatic
/// joint `j > i` shifts the first moment by `mⱼ wⱼ`; one of `j < i` shifts `oᵢ` with it (no change).
pub fn torque_jacobian(
    model: &Model,
    data: &sim::Data,
    gravity: &nalgebra::Vector3<f64>,
    payload: Option<&sim::statics::Payload>,
    out: &mut [f64],
) {
    use nalgebra::{Point3, Vector3};
    let n = model.nq();
    assert_eq!(out.len(), n * n, "nq × nq");
    let mut mass = vec![0.0; n];
    let mut lever = vec![Vector3::zeros(); n];
    let mut axis = vec![Vector3::zeros(); n];
    let (mut m, mut first) = (0.0, Vector3::zeros());
    if let Some(pl) = payload {
        let c = data.flange * Point3::from(Vector3::from(pl.com));
        m += pl.mass;
        first += c.coords * pl.mass;
    }
    for i in (0..n).rev() {
        let t = &data.joint_poses[i];
        let body = &model.bodies()[i];
        let c = t * Point3::from(body.com);
        m += body.mass;
        first += c.coords * body.mass;
        mass[i] = m;
        lever[i] = first - t.translation.vector * m;
        axis[i] = t.rotation * model.joints()[i].axis;
    }
    let joints = model.joints();
    for i in 0..n {
        let wi = axis[i];
        for j in 0..n {
            let wj = axis[j];
            let rot_i = joints[i].kind.is_rotational();
            let rot_j = joints[j].kind.is_rotational();
            out[i * n + j] = match (rot_i, rot_j, j >= i) {
                (true, true, true) => -wi.dot(&wj.cross(&lever[j]).cross(gravity)),
                (true, true, false) => -wi.dot(&lever[i].cross(&(-wj.cross(gravity)))),
                (false, true, true) => 0.0,
                (false, true, false) => -(wj.cross(&wi)).dot(gravity) * mass[i],
                (true, false, true) if j > i => -wi.dot(&(wj * mass[j]).cross(gravity)),
                _ => 0.0,
            };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The analytic `∂τ/∂θ` against central differences of the simulator's gravity torques.
    #[test]
    fn torque_jacobian_matches_central_differences() {
        let model = sim::robots::load_builtin("iiwa7").unwrap();
        let n = model.nq();
        let g = nalgebra::Vector3::from(sim::statics::DEFAULT_GRAVITY);
        let payload = sim::statics::Payload {
            mass: 3.0,
            com: [0.01, -0.02, 0.08],
        };
        let mut data = sim::Data::new(&model);
        let q = [0.3, 0.7, -0.4, -1.1, 0.5, 0.9, -0.2];
        sim::statics::gravity_torques(&model, &mut data, &q, &g, Some(&payload)).unwrap();
        let mut jac = vec![0.0; n * n];
        torque_jacobian(&model, &data, &g, Some(&payload), &mut jac);
        let h = 1e-6;
        for j in 0..n {
            let mut qp = q;
            qp[j] += h;
            sim::statics::gravity_torques(&model, &mut data, &qp, &g, Some(&payload)).unwrap();
            let tp = data.gravity_torque.clone();
            qp[j] -= 2.0 * h;
            sim::statics::gravity_torques(&model, &mut data, &qp, &g, Some(&payload)).unwrap();
            let tm = data.gravity_torque.clone();
            for i in 0..n {
                let fd = (tp[i] - tm[i]) / (2.0 * h);
                assert!(
                    (fd - jac[i * n + j]).abs() < 1e-6 * (1.0 + fd.abs()),
                    "dtau{i}/dq{j}: analytic {} against {fd}",
                    jac[i * n + j]
                );
            }
        }
    }
}
