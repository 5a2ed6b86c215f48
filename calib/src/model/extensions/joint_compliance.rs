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
//!
//! # A robot without masses
//! Without inertials (a DH table, a URDF without `<inertial>`) the torques are unknown, but linear
//! in the unknown mass moments ([`super::lumped_gravity`]): the sag of joint `i` is
//! `Σₖ βᵢₖ Gᵢₖ(q)` with known dimensionless patterns `Gᵢₖ` and the lumped products
//! `βᵢₖ = cᵢ bᵢₖ` (rad) of the compliance with the combinations `bᵢₖ` (N m) of the moments that the
//! torque depends on: the parameters `joint i compliance × mass moment k`. A table with payload
//! masses that change over the data adds each joint's compliance `cᵢ` itself, multiplying the
//! torque of the payload's mass at the flange origin, and the products `πᵢ = cᵢ |g| r` (rad/kg) of
//! the compliance with the payload's unknown centre of mass `r` (flange frame): linear, where the
//! model with masses searches the centre of mass by refits. A product has no sign of its own (a combination of moments may be
//! negative); its bound is the sag: `|βᵢₖ| ≤` [`MAX_SAG_RAD`] (0.05 rad, 2.9°; [`MAX_SAG_M`], 5 mm,
//! for a prismatic joint).

use super::lumped_gravity::{self, LumpedGravity};
use super::per_joint_params;
use super::{Cause, CauseModel, ExtensionParam, ExtensionSettings, PlotAxis, RowInputs, Term};
use crate::error::Result;
use crate::units::Unit;
use nalgebra::Vector3;
use sim::Model;
use sim::measurement_table::MeasurementTable;

/// Expected compliance (rad/(N m)): harmonic-drive joints of lightweight arms are 5e3–2e4 N m/rad.
pub const SCALE_RAD_PER_NM: f64 = 1e-4;

/// Largest plausible compliance of a rotational joint (rad/(N m)): stiffness 100 N m/rad (module
/// docs).
pub const MAX_RAD_PER_NM: f64 = 1e-2;

/// Largest plausible compliance of a prismatic joint (m/N): stiffness 1e4 N/m, 1 mm under 10 N.
pub const MAX_M_PER_N: f64 = 1e-4;

/// Largest plausible lumped product of a rotational joint (rad): a sag of 0.05 rad (2.9°) under
/// gravity, beyond any position-controlled arm (module docs).
pub const MAX_SAG_RAD: f64 = 5e-2;

/// Largest plausible lumped product of a prismatic joint (m): a sag of 5 mm under gravity.
pub const MAX_SAG_M: f64 = 5e-3;

/// Expected lumped product (rad): a compliance of 1e-4 rad/(N m) times 10 N m.
pub const SCALE_PRODUCT_RAD: f64 = 1e-3;

/// Expected lumped product of a prismatic joint (m).
pub const SCALE_PRODUCT_M: f64 = 1e-4;

/// What the products of a joint's compliance with gravity and the payload's centre of mass (flange
/// frame) are called, axis by axis: `πᵢ = cᵢ |g| r` (rad/kg; module docs).
pub const PAYLOAD_COM_QUANTITIES: [&str; 3] = [
    "compliance × payload centre of mass x",
    "compliance × payload centre of mass y",
    "compliance × payload centre of mass z",
];

/// Largest plausible product of a compliance with gravity and a payload's centre of mass (rad/kg):
/// [`MAX_RAD_PER_NM`] × 9.81 m/s² × 1 m, rounded up.
pub const MAX_PAYLOAD_RAD_PER_KG: f64 = 0.1;

/// Expected product of a compliance with gravity and a payload's centre of mass (rad/kg): 1e-4
/// rad/(N m) × 9.81 m/s² × 0.1 m.
pub const SCALE_PAYLOAD_RAD_PER_KG: f64 = 1e-4;

/// What a lumped product is called: `joint 2 compliance × mass moment 1`.
pub const PRODUCT_QUANTITY: &str = "compliance × mass moment";

/// Joint compliance: one compliance per joint, regressor `−τᵢ`; on a robot without masses, the
/// lumped products (module docs).
pub struct JointCompliance;

impl CauseModel for JointCompliance {
    fn cause(&self) -> Cause {
        Cause::JointCompliance
    }

    /// With the robot's masses it identifies the compliances, without them the lumped products; not
    /// a robot with coupled joints and no masses.
    fn usable(&self, model: &Model, _table: &MeasurementTable) -> std::result::Result<(), String> {
        if !model.couplings().is_empty() && model.require_inertials().is_err() {
            return Err(
                "the robot has coupled joints and no masses: lumped products through a coupling \
                 are not modelled"
                    .into(),
            );
        }
        Ok(())
    }

    /// Without the robot's masses: the combinations of mass moments each joint's torque depends on
    /// ([`LumpedGravity`]), with the compliance itself when the training rows' payload masses
    /// differ.
    fn configure(
        &self,
        settings: &mut ExtensionSettings,
        model: &Model,
        table: &MeasurementTable,
        rows: &[usize],
        source: &str,
    ) -> Result<()> {
        if let Err(why) = self.usable(model, table) {
            return Err(crate::error::CalibError::BadValue {
                context: source.to_string(),
                field: "--model".into(),
                value: "joint_compliance".into(),
                problem: why,
            });
        }
        if model.require_inertials().is_err() && settings.lumped_gravity.is_none() {
            settings.lumped_gravity = Some(LumpedGravity::for_model(
                model,
                &Vector3::from(settings.gravity_base),
                lumped_gravity::payload_varies(table, rows),
            ));
        }
        Ok(())
    }

    fn needs_gravity_torque(&self, settings: &ExtensionSettings) -> bool {
        settings.lumped_gravity.is_none()
    }

    fn needs_frames(&self, settings: &ExtensionSettings) -> bool {
        settings.lumped_gravity.is_some()
    }

    fn needs_equilibrium(&self) -> bool {
        true
    }

    fn params(&self, model: &Model, settings: &ExtensionSettings) -> Vec<ExtensionParam> {
        match &settings.lumped_gravity {
            // A coupled joint has no drive and no spring of its own (module docs).
            None => per_joint_params(
                model,
                Cause::JointCompliance,
                "compliance",
                Unit::RadianPerNewtonMetre,
                Unit::MetrePerNewton,
                SCALE_RAD_PER_NM,
            )
            .into_iter()
            .filter(|p| {
                !p.term
                    .joint()
                    .is_some_and(|j| model.couplings().is_coupled(j))
            })
            .collect(),
            Some(lumped) => lumped_params(model, lumped),
        }
    }

    fn notes(
        &self,
        settings: &ExtensionSettings,
        model: &Model,
        _table: &MeasurementTable,
        _rows: &[usize],
    ) -> Vec<String> {
        let Some(lumped) = &settings.lumped_gravity else {
            return Vec::new();
        };
        let counts: Vec<String> = (0..model.nq())
            .filter(|&i| {
                lumped.count(i) > 0
                    && settings.acts_at(Cause::JointCompliance, Term::JointAngle { joint: i })
            })
            .map(|i| format!("joint {}: {}", i + 1, lumped.count(i)))
            .collect();
        let payload = if lumped.payload_compliance {
            "; the payload masses, known and changing over the data, add each joint's compliance itself \
             (rad/(N m)) where they separate it from the moments"
        } else {
            ""
        };
        vec![format!(
            "robot without masses (no inertial data for {}): joint compliance identifies the products of \
             each joint's compliance with the combinations of mass moments its gravity torque depends on \
             (`joint i {PRODUCT_QUANTITY} k`, rad; {}), not the stiffnesses{payload}",
            model.massless_links().join(", "),
            counts.join(", ")
        )]
    }

    /// Regressors `−τᵢ` (N m) from the row's gravity torques; without masses `−Gᵢₖ` (and `−τᵢ` of
    /// the payload) from the row's joint frames.
    fn regressors(&self, settings: &ExtensionSettings, row: &RowInputs<'_>, out: &mut [f64]) {
        let Some(lumped) = &settings.lumped_gravity else {
            if row.couplings.is_empty() {
                for (o, t) in out.iter_mut().zip(row.tau) {
                    *o = -t;
                }
            } else {
                // Each drive feels its own torque and, by virtual work, those of the joints
                // coupled to it: `(Aᵀ τ)ᵢ`.
                for (o, &i) in out.iter_mut().zip(row.couplings.drives()) {
                    *o = -drive_torque(row.couplings, row.tau, i);
                }
            }
            return;
        };
        let Some(frames) = row.frames else {
            out.fill(0.0);
            return;
        };
        let g = Vector3::from(settings.gravity_base);
        let mut col = 0;
        for i in 0..row.joints.len() {
            let count = lumped.count(i);
            if count == 0 {
                continue;
            }
            if lumped.payload_compliance {
                // The payload's torque with its mass at the flange origin, then the share of its
                // centre of mass: `−cᵢ τ = cᵢ m (p − oᵢ)·uᵢ + Σₐ (cᵢ |g| rₐ) m (R_flangeᵀ uᵢ)ₐ / |g|`,
                // the payload's moment about the joint's axis.
                if row.joints[i].kind.is_rotational() {
                    let w = frames.joint_poses[i].rotation * row.joints[i].axis;
                    out[col..col + 4].copy_from_slice(&LumpedGravity::payload_moment_regressors(
                        frames,
                        &g,
                        row.payload_kg,
                        &w,
                        i,
                    ));
                    col += 4;
                } else {
                    out[col] = -LumpedGravity::payload_torque_at(
                        row.joints,
                        frames,
                        &g,
                        row.payload_kg,
                        &[0.0; 3],
                        i,
                    );
                    col += 1;
                }
            }
            let products = &mut out[col..col + count];
            lumped.patterns(row.joints, frames, &g, i, products);
            products.iter_mut().for_each(|v| *v = -*v);
            col += count;
        }
    }

    /// `Δθᵢ = −cᵢ τᵢ(θ)`: `∂Δθᵢ/∂θⱼ = −cᵢ ∂τᵢ/∂θⱼ` (exact; [`torque_jacobian`]). Without masses
    /// `Δθᵢ = −Σₖ βᵢₖ Gᵢₖ(θ) − cᵢ τᵢᵖ(θ)`, minus the torque at joint `i` of virtual bodies whose
    /// moments are `Σₖ βᵢₖ vᵢₖ` (scaled as the patterns) and of a payload of mass `cᵢ m` and first
    /// moment `m πᵢ / |g|`: the same derivative of a torque ([`torque_jacobian_of`]).
    fn angle_jacobian(
        &self,
        settings: &ExtensionSettings,
        row: &RowInputs<'_>,
        torque_jacobian: &[f64],
        x: &[f64],
        _d_dq: &mut [f64],
        d_dtheta: &mut [f64],
    ) {
        let n = row.q.len();
        let Some(lumped) = &settings.lumped_gravity else {
            if row.couplings.is_empty() {
                for (i, c) in x.iter().enumerate() {
                    for j in 0..n {
                        d_dtheta[i * n + j] -= c * torque_jacobian[i * n + j];
                    }
                }
                return;
            }
            // `Δθ = −A C Aᵀ τ(θ)`: drive `i` turns by `−cᵢ (Aᵀ ∂τ/∂θⱼ)ᵢ`, and so, times their
            // multipliers, do the joints coupled to it.
            for (&c, &i) in x.iter().zip(row.couplings.drives()) {
                for j in 0..n {
                    let mut d = torque_jacobian[i * n + j];
                    for &(k, a) in row.couplings.followers(i) {
                        d += a * torque_jacobian[k * n + j];
                    }
                    d_dtheta[i * n + j] -= c * d;
                    for &(k, a) in row.couplings.followers(i) {
                        d_dtheta[k * n + j] -= a * c * d;
                    }
                }
            }
            return;
        };
        let Some(frames) = row.frames else {
            return;
        };
        let g = Vector3::from(settings.gravity_base);
        let mut jac = vec![0.0; n * n];
        let mut col = 0;
        for i in 0..n {
            let count = lumped.count(i);
            if count == 0 {
                continue;
            }
            // The payload's parts: mass `cᵢ m` at the flange origin, first moment `m πᵢ / |g|`
            // (flange frame).
            let (c, pi) = if lumped.payload_compliance {
                let c = x[col];
                col += 1;
                let pi = if row.joints[i].kind.is_rotational() {
                    col += 3;
                    Vector3::new(x[col - 3], x[col - 2], x[col - 1])
                } else {
                    Vector3::zeros()
                };
                (c, pi)
            } else {
                (0.0, Vector3::zeros())
            };
            let payload_mass = c * row.payload_kg;
            let payload_first = pi * (row.payload_kg / g.norm().max(f64::MIN_POSITIVE));
            // The flange in the last joint's frame, where the payload's parts join the last body.
            let last = n - 1;
            let offset = frames.joint_poses[last].inverse() * frames.flange;
            let beta = &x[col..col + count];
            col += count;
            let scale = lumped.pattern_scale(&row.joints[i], &g);
            let body = |j: usize| -> (f64, Vector3<f64>) {
                if j < i {
                    return (0.0, Vector3::zeros());
                }
                let at = lumped_gravity::MOMENTS_PER_BODY * (j - i);
                let mut m = [0.0; lumped_gravity::MOMENTS_PER_BODY];
                for (b, v) in beta.iter().zip(&lumped.combinations[i]) {
                    for (mm, vv) in m
                        .iter_mut()
                        .zip(&v[at..at + lumped_gravity::MOMENTS_PER_BODY])
                    {
                        *mm += b * vv * scale;
                    }
                }
                let mut first = Vector3::new(m[1], m[2], m[3]);
                let mut mass = m[0] / lumped.length_m;
                if j == last {
                    first +=
                        offset.translation.vector * payload_mass + offset.rotation * payload_first;
                    mass += payload_mass;
                }
                (mass, first)
            };
            torque_jacobian_of(row.joints, frames, &g, body, None, &mut jac);
            for j in 0..n {
                d_dtheta[i * n + j] -= jac[i * n + j];
            }
        }
    }

    fn evidence_subject(&self, joints: &str) -> String {
        format!("the gravity torque of {joints}")
    }

    fn remark(&self, unit: Unit, value: f64) -> String {
        if !matches!(unit, Unit::RadianPerNewtonMetre | Unit::MetrePerNewton) {
            String::new() // a lumped product: no stiffness of its own
        } else if value > 0.0 {
            format!(" (stiffness {:.0} N m/rad)", 1.0 / value)
        } else {
            " (negative: no spring; it stands in for another error)".to_string()
        }
    }

    fn implausible(&self, param: &ExtensionParam, value: f64) -> Option<String> {
        if param.unit == Unit::RadianPerKilogram {
            return (value.abs() > MAX_PAYLOAD_RAD_PER_KG).then(|| {
                "a compliance times gravity times the payload's centre of mass above 0.1 rad/kg: \
                 the softest joint with a centre of mass a metre from the flange"
                    .to_string()
            });
        }
        if param.pattern.is_some() {
            let (max, words) = if param.unit == Unit::Metre {
                (MAX_SAG_M, "5 mm")
            } else {
                (MAX_SAG_RAD, "0.05 rad (2.9°)")
            };
            return (value.abs() > max).then(|| {
                format!(
                    "a sag above {words} under gravity: no position-controlled joint sags that much"
                )
            });
        }
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

/// The torque drive `i` feels (N m or N): its own holding torque `τᵢ` and, by virtual work, `a τₖ`
/// of every joint `k` coupled to it with multiplier `a` ([`sim::coupled_joints`]).
#[inline]
fn drive_torque(couplings: &sim::coupled_joints::Couplings, tau: &[f64], i: usize) -> f64 {
    tau[i]
        + couplings
            .followers(i)
            .iter()
            .map(|&(k, a)| a * tau[k])
            .sum::<f64>()
}

/// The parameters of joint compliance without masses: at each joint whose torque changes, its
/// compliance when the payload separates it, then its lumped products.
fn lumped_params(model: &Model, lumped: &LumpedGravity) -> Vec<ExtensionParam> {
    let mut out = Vec::new();
    for (i, joint) in model.joints().iter().enumerate() {
        let count = lumped.count(i);
        if count == 0 {
            continue;
        }
        let rotational = joint.kind.is_rotational();
        let term = Term::JointAngle { joint: i };
        if lumped.payload_compliance {
            out.push(ExtensionParam {
                cause: Cause::JointCompliance,
                term,
                quantity: "compliance",
                unit: if rotational {
                    Unit::RadianPerNewtonMetre
                } else {
                    Unit::MetrePerNewton
                },
                scale: SCALE_RAD_PER_NM,
                pattern: None,
            });
            if rotational {
                out.extend(
                    PAYLOAD_COM_QUANTITIES
                        .iter()
                        .map(|&quantity| ExtensionParam {
                            cause: Cause::JointCompliance,
                            term,
                            quantity,
                            unit: Unit::RadianPerKilogram,
                            scale: SCALE_PAYLOAD_RAD_PER_KG,
                            pattern: None,
                        }),
                );
            }
        }
        out.extend((1..=count).map(|k| ExtensionParam {
            cause: Cause::JointCompliance,
            term,
            quantity: PRODUCT_QUANTITY,
            unit: if rotational {
                Unit::Radian
            } else {
                Unit::Metre
            },
            scale: if rotational {
                SCALE_PRODUCT_RAD
            } else {
                SCALE_PRODUCT_M
            },
            pattern: Some(k),
        }));
    }
    out
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
    // The bodies as the statics saw them: centres with the branches off the chain posed.
    let bodies = model.bodies();
    let body = |j: usize| (bodies[j].mass, data.body_com[j] * bodies[j].mass);
    torque_jacobian_of(model.joints(), data, gravity, body, payload, out);
}

/// [`torque_jacobian`] of the bodies `body(j)` = (mass (kg), first moment `m c` in joint `j`'s frame
/// (kg m)) instead of the model's: of any mass distribution on the chain `joints` with frames
/// `data`.
pub fn torque_jacobian_of(
    joints: &[sim::Joint],
    data: &sim::Data,
    gravity: &nalgebra::Vector3<f64>,
    body: impl Fn(usize) -> (f64, nalgebra::Vector3<f64>),
    payload: Option<&sim::statics::Payload>,
    out: &mut [f64],
) {
    use nalgebra::{Point3, Vector3};
    let n = joints.len();
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
        let (body_mass, body_first) = body(i);
        m += body_mass;
        first += t.rotation * body_first + t.translation.vector * body_mass;
        mass[i] = m;
        lever[i] = first - t.translation.vector * m;
        axis[i] = t.rotation * joints[i].axis;
    }
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

    /// Without masses, the angle Jacobian of the lumped products (and of the payload's compliance)
    /// against central differences of `Σ xₑ gₑ(θ)` over the link angles.
    #[test]
    fn lumped_angle_jacobian_matches_central_differences() {
        let text = sim::urdf_text::without_inertials(sim::robots::builtin_urdf("iiwa7").unwrap());
        let model =
            sim::urdf::load_str(&text, "iiwa7 without masses", &Default::default()).unwrap();
        assert!(model.require_inertials().is_err());
        let n = model.nq();
        let g = Vector3::from(sim::statics::DEFAULT_GRAVITY);
        let settings = ExtensionSettings {
            causes: vec![Cause::JointCompliance],
            gravity_base: sim::statics::DEFAULT_GRAVITY,
            payload_com_m: [0.01, -0.02, 0.08],
            backlash_sign: super::super::BacklashSign::Direction,
            thermal: None,
            transmission_joints: Vec::new(),
            joints: Default::default(),
            lumped_gravity: Some(LumpedGravity::for_model(&model, &g, true)),
        };
        let jc = JointCompliance;
        let params = jc.params(&model, &settings);
        assert!(params.iter().any(|p| p.pattern.is_none()));
        let x: Vec<f64> = (0..params.len())
            .map(|k| 1e-3 * ((k as f64 * 1.7).sin() + 0.3))
            .collect();
        let mut data = sim::Data::new(&model);
        let payload_kg = 2.5;
        // Δθ(θ) = Σ xₑ gₑ(θ) per joint.
        let delta = |theta: &[f64], data: &mut sim::Data| -> Vec<f64> {
            sim::kinematics::forward_kinematics(&model, data, theta);
            let row = RowInputs {
                joints: model.joints(),
                couplings: model.couplings(),
                q: theta,
                tau: &[],
                moment: &[],
                frames: Some(data),
                payload_kg,
                dir: None,
                temp_c: None,
                t_s: None,
            };
            let mut g = vec![0.0; params.len()];
            jc.regressors(&settings, &row, &mut g);
            let mut d = vec![0.0; n];
            for ((p, gv), xv) in params.iter().zip(&g).zip(&x) {
                d[p.term.joint().unwrap()] += gv * xv;
            }
            d
        };
        let theta = [0.3, 0.7, -0.4, -1.1, 0.5, 0.9, -0.2];
        sim::kinematics::forward_kinematics(&model, &mut data, &theta);
        let row = RowInputs {
            joints: model.joints(),
            couplings: model.couplings(),
            q: &theta,
            tau: &[],
            moment: &[],
            frames: Some(&data),
            payload_kg,
            dir: None,
            temp_c: None,
            t_s: None,
        };
        let (mut d_dq, mut d_dtheta) = (vec![0.0; n * n], vec![0.0; n * n]);
        jc.angle_jacobian(&settings, &row, &[], &x, &mut d_dq, &mut d_dtheta);
        assert!(d_dq.iter().all(|v| *v == 0.0));
        let mut scratch = sim::Data::new(&model);
        let h = 1e-6;
        for j in 0..n {
            let mut tp = theta;
            tp[j] += h;
            let dp = delta(&tp, &mut scratch);
            tp[j] -= 2.0 * h;
            let dm = delta(&tp, &mut scratch);
            for i in 0..n {
                let fd = (dp[i] - dm[i]) / (2.0 * h);
                let an = d_dtheta[i * n + j];
                assert!(
                    (fd - an).abs() < 1e-8 * (1.0 + fd.abs()),
                    "dΔθ{i}/dθ{j}: analytic {an} against {fd}"
                );
            }
        }
        assert!(
            d_dtheta.iter().any(|v| v.abs() > 1e-4),
            "the test sees a derivative"
        );
    }
}
