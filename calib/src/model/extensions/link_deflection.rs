//! Link deflection, as the estimator models it: the arm bends at each joint about the two axes
//! orthogonal to the joint's own, in proportion to the gravity moment the joint transmits.
//!
//! For joint `i` (0-based) with origin `oᵢ` and joint frame `Rᵢ` (the child link's frame, which turns
//! with the joint: `R_base_joint` at the link angle), the moment of gravity on everything beyond the
//! joint (its child link and all later links, and the payload) about the joint's origin is
//!
//! ```text
//! Mᵢ = Σₖ≥ᵢ (cₖ − oᵢ) × mₖ g  (+ the payload's term)          (N m, base frame)
//! mᵢ = Rᵢᵀ Mᵢ                                                 (the same in the joint frame)
//! ```
//!
//! (`cₖ` the centres of mass, `g` gravity). Its component along the joint axis is what the joint's
//! motor holds (`τᵢ = −aᵢ · mᵢ`, the holding torque of [`super::joint_compliance`]); the components
//! about the two orthogonal axes `u`, `v` of the joint frame load its bearing and the link beyond it,
//! whose bending stiffness turns with the joint. With bending compliances `c_u`, `c_v` (rad/(N m)),
//! everything beyond the joint turns about the joint's origin by the rotation vector (joint frame)
//!
//! ```text
//! φᵢ = c_u (u · mᵢ) u + c_v (v · mᵢ) v
//! ```
//!
//! i.e. along the load, as a joint spring turns along its torque. The regressors are `u · mᵢ`, `v · mᵢ`
//! (N m) and the term is [`Term::Bend`]: the chain applies `exp([φᵢ])` after the joint's own rotation
//! ([`crate::model::chain::Chain::forward_bent`]). `u`, `v` are the joint frame's coordinate axes other than
//! the joint axis, in x, y, z order (x and y for a joint about z, x and z for one about y); a joint
//! whose axis is not along a coordinate axis of its frame gets no bending parameters. (Two hinges in
//! series, `Rot(u, α) Rot(v, β)`, differ from `exp([α u + β v])` by `αβ/2`, 10⁻⁸ rad for bends of
//! 10⁻⁴ rad: ten nanometres at a metre.)
//!
//! # Bending that is the next joint's compliance
//! When a bending axis of joint `i` lies on the axis line of joint `i + 1` (fixed in the same link),
//! bending about it turns everything beyond about that very line, by an angle in proportion to the
//! moment about it: the moment of everything beyond joint `i`, which differs from the moment joint
//! `i + 1` holds only by link `i`'s own weight about a line through it. That is joint `i + 1`'s
//! compliance to any measurement ([`aliased_with_next_joint`]), and so is bending of a vertical first
//! joint about an axis parallel to the second's. The estimator leaves those directions to the
//! compliance and gives joint `i` no bending parameter about them: one error, one name. On the iiwa 7
//! the bending of joints 2 and 4 about z (the upper arm and forearm axes) is joints 3 and 5's
//! compliance and joint 1's bending about y is joint 2's, so joints 1, 2 and 4 bend about x only
//! (joint 6 keeps z: joint 7's axis runs 6 cm beside its origin).
//!
//! The moments are those of the nominal robot at the link angles of the current estimate (with joint
//! compliance, the sagged angles, as for the holding torques); the bending itself moves the centres of
//! mass by `φ` (about 10⁻⁴ rad) and so changes the moments by that fraction, a second-order effect
//! (10⁻⁸ rad) left out. A joint whose bending moment does not vary over the data (the last joint
//! without payload) cannot be identified; the solver says so and leaves its compliances at zero.
//!
//! # A robot without masses
//! Without inertials the moments are unknown, but linear in the unknown mass moments, as the
//! holding torques are ([`super::lumped_gravity`]): about axis `a` of joint `i` the bend is
//! `Σₖ βₐₖ Gₐₖ(q)` with known dimensionless patterns `Gₐₖ` ([`LumpedGravity::bend_patterns`]) and the
//! lumped products `βₐₖ = c_a bₐₖ` (rad) of the bending compliance with the combinations `bₐₖ` (N m)
//! of the moments that the bending moment depends on: the parameters
//! `joint i bending compliance × mass moment k about a`. Payload masses that change over the data
//! add the bending compliance itself, multiplying the known moment of the payload's mass at the
//! flange origin, and its products `c_a |g| r` (rad/kg) with the payload's unknown centre of mass
//! `r` (flange frame), as for joint compliance. The same axes are modelled as with masses.
//!
//! # Plausibility bounds
//! `0 ≤ c ≤` [`MAX_RAD_PER_NM`] (1e-3 rad/(N m), a bending stiffness of at least 1e3 N m/rad). A
//! negative compliance is impossible: no link bends against its load. Cross-roller output bearings of
//! harmonic drives have moment stiffnesses of 1e4–1e6 N m/rad (Harmonic Drive CSF/CSG catalogue) and
//! aluminium link tubes more; bending a hundred times softer than the softest of them (and softer than
//! most joints about their own axes) is no link's: it stands in for another error.
//!
//! Without masses a product has no sign of its own; its bound is the bend: `|βₐₖ| ≤`
//! [`MAX_SAG_RAD`] (0.01 rad, a centimetre at a metre: the softest plausible bending compliance
//! under a 10 N m moment, more than any link shows), and `|c_a |g| r| ≤`
//! [`MAX_PAYLOAD_RAD_PER_KG`] (the largest compliance with a centre of mass a metre away).

use super::axis_name;
use super::lumped_gravity::{self, LumpedGravity};
use super::{Cause, CauseModel, ExtensionParam, ExtensionSettings, PlotAxis, RowInputs, Term};
use crate::error::Result;
use crate::units::Unit;
use nalgebra::{Point3, Vector3};
use sim::Model;
use sim::measurement_table::MeasurementTable;
use sim::statics::Payload;

/// Expected bending compliance (rad/(N m)): a bearing and link of a lightweight arm are stiffer than
/// its joint (1e-4), about 1e-6 to 1e-5.
pub const SCALE_RAD_PER_NM: f64 = 3e-6;

/// Largest plausible bending compliance (rad/(N m)): stiffness 1e3 N m/rad (module docs).
pub const MAX_RAD_PER_NM: f64 = 1e-3;

/// Largest plausible lumped product of a robot without masses (rad): a bend of 0.01 rad under
/// gravity (module docs).
pub const MAX_SAG_RAD: f64 = 1e-2;

/// Expected lumped product (rad): a bending compliance of 3e-6 rad/(N m) times 30 N m.
pub const SCALE_PRODUCT_RAD: f64 = 1e-4;

/// Largest plausible product of a bending compliance with gravity and a payload's centre of mass
/// (rad/kg): [`MAX_RAD_PER_NM`] × 9.81 m/s² × 1 m, rounded up.
pub const MAX_PAYLOAD_RAD_PER_KG: f64 = 1e-2;

/// Expected product of a bending compliance with gravity and a payload's centre of mass (rad/kg):
/// 3e-6 rad/(N m) × 9.81 m/s² × 0.1 m.
pub const SCALE_PAYLOAD_RAD_PER_KG: f64 = 3e-6;

/// What a lumped product is called: `joint 2 bending compliance × mass moment 1 about x`.
pub const PRODUCT_QUANTITY: &str = "bending compliance × mass moment";

/// What the products of a bending compliance with gravity and the payload's centre of mass (flange
/// frame) are called, axis by axis (rad/kg; module docs).
pub const PAYLOAD_COM_QUANTITIES: [&str; 3] = [
    "bending compliance × payload centre of mass x",
    "bending compliance × payload centre of mass y",
    "bending compliance × payload centre of mass z",
];

/// Link deflection: two bending compliances per joint whose axis lies along a coordinate axis of its
/// frame.
pub struct LinkDeflection;

/// The two bending axes (0 = x, 1 = y, 2 = z of the joint frame) of a joint with unit axis `axis`
/// (joint frame): the other two coordinate axes in x, y, z order (z → x, y; y → x, z; x → y, z);
/// `None` when the axis is not along a coordinate axis.
pub fn bending_axes(axis: &Vector3<f64>) -> Option<[usize; 2]> {
    (0..3)
        .find(|&k| (axis[k].abs() - 1.0).abs() < 1e-9)
        .map(|k| match k {
            0 => [1, 2],
            1 => [0, 2],
            _ => [0, 1],
        })
}

/// Whether bending of joint `i` about axis `about` (0, 1, 2: x, y, z of its frame) is joint `i + 1`'s
/// rotation: the line through joint `i`'s origin along that axis is the axis line of joint `i + 1`
/// (rotational, directions within 1e-9, the origin within 1 µm of the line).
///
/// Also the first joint when it turns about the vertical (`gravity`, base frame) and the next axis
/// is parallel to the bending axis on the vertical line above or below it: the moments about the two
/// parallel lines are then equal (their offset is parallel to the weight), and the rotations differ by
/// a shift the rest of the model takes up (fitted to each other's data, they leave the same residual).
pub fn aliased_with_next_joint(
    joints: &[sim::Joint],
    i: usize,
    about: usize,
    gravity: &Vector3<f64>,
) -> bool {
    let Some(next) = joints.get(i + 1) else {
        return false;
    };
    if !next.kind.is_rotational() {
        return false;
    }
    let e = Vector3::ith(about, 1.0);
    let axis = next.origin.rotation * next.axis;
    let point = next.origin.translation.vector;
    if axis.cross(&e).norm() >= 1e-9 {
        return false;
    }
    let offset = point - e * point.dot(&e);
    if offset.norm() < 1e-6 {
        return true;
    }
    let own = joints[i].origin.rotation * joints[i].axis;
    i == 0
        && own.cross(&gravity.normalize()).norm() < 1e-9
        && offset.cross(&joints[i].axis).norm() < 1e-6
}

/// The bending axes of joint `i` that get parameters: [`bending_axes`], less those
/// [`aliased_with_next_joint`] (gravity `gravity` in the base frame).
pub fn modelled_axes(joints: &[sim::Joint], i: usize, gravity: &Vector3<f64>) -> Vec<usize> {
    bending_axes(&joints[i].axis)
        .map(|axes| {
            axes.into_iter()
                .filter(|&about| !aliased_with_next_joint(joints, i, about, gravity))
                .collect()
        })
        .unwrap_or_default()
}

impl CauseModel for LinkDeflection {
    fn cause(&self) -> Cause {
        Cause::LinkDeflection
    }

    /// With the robot's masses it identifies the bending compliances, without them the lumped
    /// products; a robot none of whose joints turns about a coordinate axis of its frame has no
    /// bending axes.
    fn usable(&self, model: &Model, _table: &MeasurementTable) -> std::result::Result<(), String> {
        if model
            .joints()
            .iter()
            .all(|j| bending_axes(&j.axis).is_none())
        {
            return Err("no joint turns about a coordinate axis of its frame".into());
        }
        Ok(())
    }

    /// Without the robot's masses: the combinations of mass moments each bending moment depends on
    /// ([`LumpedGravity::with_bending`]), beside joint compliance's if it is in the model.
    fn configure(
        &self,
        settings: &mut ExtensionSettings,
        model: &Model,
        table: &MeasurementTable,
        rows: &[usize],
        _source: &str,
    ) -> Result<()> {
        if model.require_inertials().is_ok() {
            return Ok(());
        }
        let g = Vector3::from(settings.gravity_base);
        let axes: Vec<(usize, usize)> = (0..model.nq())
            .flat_map(|i| {
                modelled_axes(model.joints(), i, &g)
                    .into_iter()
                    .map(move |a| (i, a))
            })
            .collect();
        let base = settings.lumped_gravity.take().unwrap_or_else(|| {
            LumpedGravity::for_model(model, &g, lumped_gravity::payload_varies(table, rows))
        });
        settings.lumped_gravity = Some(base.with_bending(model, &g, &axes));
        Ok(())
    }

    fn needs_gravity_torque(&self, _settings: &ExtensionSettings) -> bool {
        false
    }

    fn needs_frames(&self, settings: &ExtensionSettings) -> bool {
        settings.lumped_gravity.is_some()
    }

    fn needs_gravity_moment(&self, settings: &ExtensionSettings) -> bool {
        settings.lumped_gravity.is_none()
    }

    /// The moments are evaluated where the links are (with joint compliance in the model) and the
    /// payload's centre of mass is estimated in the refits.
    fn needs_equilibrium(&self) -> bool {
        true
    }

    /// With masses, one compliance per modelled axis; without, per stored bending basis (the
    /// modelled axes, in their order, [`LinkDeflection::configure`]) its products, after the
    /// compliance and its payload products when the payload separates them.
    fn params(&self, model: &Model, settings: &ExtensionSettings) -> Vec<ExtensionParam> {
        let compliance = |term| ExtensionParam {
            cause: Cause::LinkDeflection,
            term,
            quantity: "bending compliance",
            unit: Unit::RadianPerNewtonMetre,
            scale: SCALE_RAD_PER_NM,
            pattern: None,
        };
        let Some(lumped) = &settings.lumped_gravity else {
            let g = Vector3::from(settings.gravity_base);
            return (0..model.nq())
                .flat_map(|i| {
                    modelled_axes(model.joints(), i, &g)
                        .into_iter()
                        .map(move |about| compliance(Term::Bend { joint: i, about }))
                })
                .collect();
        };
        let mut out = Vec::new();
        for basis in lumped.bending.iter().filter(|b| !b.combinations.is_empty()) {
            let term = Term::Bend {
                joint: basis.joint,
                about: basis.about,
            };
            if lumped.payload_compliance {
                out.push(compliance(term));
                out.extend(
                    PAYLOAD_COM_QUANTITIES
                        .iter()
                        .map(|&quantity| ExtensionParam {
                            cause: Cause::LinkDeflection,
                            term,
                            quantity,
                            unit: Unit::RadianPerKilogram,
                            scale: SCALE_PAYLOAD_RAD_PER_KG,
                            pattern: None,
                        }),
                );
            }
            out.extend((1..=basis.combinations.len()).map(|k| ExtensionParam {
                cause: Cause::LinkDeflection,
                term,
                quantity: PRODUCT_QUANTITY,
                unit: Unit::Radian,
                scale: SCALE_PRODUCT_RAD,
                pattern: Some(k),
            }));
        }
        out
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
        let counts: Vec<String> = lumped
            .bending
            .iter()
            .filter(|b| {
                !b.combinations.is_empty()
                    && settings.acts_at(
                        Cause::LinkDeflection,
                        Term::Bend {
                            joint: b.joint,
                            about: b.about,
                        },
                    )
            })
            .map(|b| {
                format!(
                    "joint {} about {}: {}",
                    b.joint + 1,
                    axis_name(b.about),
                    b.combinations.len()
                )
            })
            .collect();
        let payload = if lumped.payload_compliance {
            "; the payload masses, known and changing over the data, add each bending compliance \
             itself (rad/(N m)) where they separate it from the moments"
        } else {
            ""
        };
        vec![format!(
            "robot without masses (no inertial data for {}): link deflection identifies the products \
             of each bending compliance with the combinations of mass moments its bending moment \
             depends on (`joint i {PRODUCT_QUANTITY} k about a`, rad; {}), not the compliances{payload}",
            model.massless_links().join(", "),
            counts.join(", ")
        )]
    }

    /// The components `u · mᵢ`, `v · mᵢ` (N m) of each bending joint's moment, joint frame; without
    /// masses the patterns `Gₐₖ` (and the payload's moment regressors) from the row's joint frames.
    fn regressors(&self, settings: &ExtensionSettings, row: &RowInputs<'_>, out: &mut [f64]) {
        let g = Vector3::from(settings.gravity_base);
        let Some(lumped) = &settings.lumped_gravity else {
            let mut k = 0;
            for (i, m) in row.moment.iter().enumerate() {
                for about in modelled_axes(row.joints, i, &g) {
                    out[k] = m[about];
                    k += 1;
                }
            }
            return;
        };
        let Some(frames) = row.frames else {
            out.fill(0.0);
            return;
        };
        let mut col = 0;
        for basis in lumped.bending.iter().filter(|b| !b.combinations.is_empty()) {
            let count = basis.combinations.len();
            if lumped.payload_compliance {
                let i = basis.joint;
                let w = frames.joint_poses[i].rotation * Vector3::ith(basis.about, 1.0);
                out[col..col + 4].copy_from_slice(&LumpedGravity::payload_moment_regressors(
                    frames,
                    &g,
                    row.payload_kg,
                    &w,
                    i,
                ));
                col += 4;
            }
            lumped.bend_patterns(frames, &g, basis, &mut out[col..col + count]);
            col += count;
        }
    }

    fn evidence_subject(&self, joints: &str) -> String {
        format!("the bending moment across {joints}")
    }

    fn remark(&self, unit: Unit, value: f64) -> String {
        if unit != Unit::RadianPerNewtonMetre {
            String::new() // a lumped product: no stiffness of its own
        } else if value > 0.0 {
            format!(" (stiffness {:.3e} N m/rad)", 1.0 / value)
        } else {
            " (negative: no elastic link bends against its load)".to_string()
        }
    }

    fn implausible(&self, param: &ExtensionParam, value: f64) -> Option<String> {
        if param.unit == Unit::RadianPerKilogram {
            return (value.abs() > MAX_PAYLOAD_RAD_PER_KG).then(|| {
                "a bending compliance times gravity times the payload's centre of mass above \
                 0.01 rad/kg: the softest link with a centre of mass a metre from the flange"
                    .to_string()
            });
        }
        if param.pattern.is_some() {
            return (value.abs() > MAX_SAG_RAD).then(|| {
                "a bend above 0.01 rad under gravity: no link and bearing bend that much"
                    .to_string()
            });
        }
        super::outside_zero_to(
            value,
            MAX_RAD_PER_NM,
            "negative bending compliance: no link bends against its load",
            || {
                "a bending compliance above 1e-3 rad/(N m) (stiffness below 1e3 N m/rad): softer \
                 than a link and its bearing can be"
                    .into()
            },
        )
    }

    fn signature(&self) -> &'static str {
        "turns the arm about axes across a joint in proportion to the bending moment it carries"
    }

    fn plot_axis(&self, term: Term) -> PlotAxis {
        let (joint, about) = match term {
            Term::Bend { joint, about } => (joint + 1, axis_name(about)),
            _ => (0, "?"),
        };
        PlotAxis {
            sign: 1.0,
            label: format!("bending moment of joint {joint} about {about} (N m)"),
        }
    }
}

/// Gravity moment each joint transmits, in its joint frame (the child link's; N m; see the module
/// docs): `out[i] = mᵢ`,
/// for the joint poses in `data` (from [`sim::kinematics::forward_kinematics`] at the link angles),
/// gravity `gravity` (base frame, m/s²) and an optional payload at the flange.
///
/// # Panics
/// If `out.len()` differs from the joint count.
pub fn gravity_moments(
    model: &Model,
    data: &sim::Data,
    gravity: &Vector3<f64>,
    payload: Option<&Payload>,
    out: &mut [Vector3<f64>],
) {
    assert_eq!(out.len(), model.nq(), "one moment per joint");
    // From the tip: mass and first moment Σ m c (base frame) of everything beyond joint i.
    let mut mass = 0.0;
    let mut first = Vector3::zeros();
    if let Some(pl) = payload {
        let c = data.flange * Point3::from(Vector3::from(pl.com));
        mass += pl.mass;
        first += c.coords * pl.mass;
    }
    for i in (0..model.nq()).rev() {
        let frame = &data.joint_poses[i];
        let body = &model.bodies()[i];
        // The centre as the statics saw it: with the branches off the chain posed.
        let c = frame * Point3::from(data.body_com[i]);
        mass += body.mass;
        first += c.coords * body.mass;
        let o = frame.translation.vector;
        let m_base = (first - o * mass).cross(gravity);
        out[i] = frame.rotation.inverse_transform_vector(&m_base);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use sim::kinematics::forward_kinematics;

    #[test]
    fn the_iiwa_bends_only_about_axes_that_are_no_next_joint_axis() {
        let model = sim::robots::load_builtin("iiwa7").unwrap();
        let g = Vector3::from(sim::statics::DEFAULT_GRAVITY);
        let axes: Vec<Vec<usize>> = (0..7)
            .map(|i| modelled_axes(model.joints(), i, &g))
            .collect();
        // Joint 2's and 4's z axes run along the upper arm and forearm, the axes of joints 3 and 5;
        // joint 1's y axis is parallel to joint 2's, 0.19 m below it on the vertical.
        assert_eq!(
            axes,
            vec![
                vec![0],
                vec![0],
                vec![0, 1],
                vec![0],
                vec![0, 1],
                vec![0, 2],
                vec![0, 1]
            ]
        );
        // Hung from a wall (gravity along the base x), joint 1's y bending is its own again.
        let wall = Vector3::new(-9.81, 0.0, 0.0);
        assert_eq!(modelled_axes(model.joints(), 0, &wall), vec![0, 1]);
    }

    #[test]
    fn bending_axes_follow_the_joint_axis() {
        assert_eq!(bending_axes(&Vector3::z()), Some([0, 1]));
        assert_eq!(bending_axes(&-Vector3::x()), Some([1, 2]));
        assert_eq!(bending_axes(&Vector3::y()), Some([0, 2]));
        assert_eq!(bending_axes(&Vector3::new(0.6, 0.8, 0.0)), None);
    }

    /// The moment about any axis through a joint's origin is minus the derivative of the potential
    /// energy when everything beyond the joint turns about that axis: an independent check of every
    /// component (the axial one is also minus the holding torque of `sim::statics`).
    #[test]
    fn moments_are_minus_the_potential_energy_gradient() {
        let model = sim::robots::load_builtin("iiwa7").unwrap();
        let g = Vector3::from(sim::statics::DEFAULT_GRAVITY);
        let pl = Payload {
            mass: 2.3,
            com: [0.02, -0.01, 0.07],
        };
        let q = [0.4, -0.9, 1.2, 1.3, -0.6, 0.8, 0.3];
        let mut data = sim::Data::new(&model);
        sim::statics::gravity_torques(&model, &mut data, &q, &g, Some(&pl)).unwrap();
        let tau = data.gravity_torque.clone();
        let mut m = vec![Vector3::zeros(); 7];
        gravity_moments(&model, &data, &g, Some(&pl), &mut m);
        forward_kinematics(&model, &mut data, &q);
        // Potential energy with everything beyond joint i turned by angle h about the base-frame unit
        // axis w through the point o.
        let energy = |i: usize, w: &Vector3<f64>, o: &Vector3<f64>, h: f64| -> f64 {
            let rot = nalgebra::Rotation3::from_scaled_axis(w * h);
            let moved = |p: Vector3<f64>| o + rot * (p - o);
            let mut v = 0.0;
            for k in i..7 {
                let c = (data.joint_poses[k] * Point3::from(model.bodies()[k].com)).coords;
                v -= model.bodies()[k].mass * g.dot(&moved(c));
            }
            let c = (data.flange * Point3::from(Vector3::from(pl.com))).coords;
            v - pl.mass * g.dot(&moved(c))
        };
        for (i, mi) in m.iter().enumerate() {
            let frame = data.joint_poses[i];
            let o = frame.translation.vector;
            for (about, &component) in mi.iter().enumerate() {
                let w = frame.rotation * Vector3::ith(about, 1.0);
                let h = 1e-6;
                let fd = -(energy(i, &w, &o, h) - energy(i, &w, &o, -h)) / (2.0 * h);
                assert!(
                    (fd - component).abs() < 1e-7 * (1.0 + fd.abs()),
                    "joint {} about {about}: {fd} vs {component}",
                    i + 1
                );
            }
            let a = model.joints()[i].axis;
            assert!(
                (a.dot(&m[i]) + tau[i]).abs() < 1e-10 * (1.0 + tau[i].abs()),
                "joint {}: axial moment {} vs holding torque {}",
                i + 1,
                a.dot(&m[i]),
                tau[i]
            );
        }
    }
}
