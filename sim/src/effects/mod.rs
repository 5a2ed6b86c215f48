//! Injected errors: what makes the real robot miss its commanded pose. One module per physical effect.
//!
//! The analytic truth of one measurement, [`true_target`], applies the effects in this fixed order and
//! records the displacement each one adds to the target position (base frame, m):
//! 1. thermal drift (link growth and joint-zero drift at the pose's temperature),
//! 2. kinematic offsets (adjoint error twists, joint zero offsets, base and tool errors),
//! 3. gear backlash (link-side angle shifted by half the dead band),
//! 4. joint compliance (link-side angle settles where the joint springs balance gravity and payload).
//! The contributions are successive increments, so they add up to the total deviation from nominal.
//!
//! (Interface fixed by the lead; the effect modules and `true_target` are being written.)

use crate::lie::Pose;
use crate::model::Model;
use crate::statics::Payload;
use nalgebra::Vector3;

pub mod gear_backlash;
pub mod joint_compliance;
pub mod kinematic_offsets;
pub mod thermal_drift;

/// Every effect injected into one simulated robot; `None` = effect absent.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Effects {
    /// Geometric errors.
    pub kinematic: Option<kinematic_offsets::KinematicOffsets>,
    /// Joint stiffness.
    pub compliance: Option<joint_compliance::JointCompliance>,
    /// Gear lost motion.
    pub backlash: Option<gear_backlash::GearBacklash>,
    /// Temperature-driven growth and drift.
    pub thermal: Option<thermal_drift::ThermalDrift>,
}

/// What the controller reports and the environment imposes at one measurement.
#[derive(Clone, Copy, Debug)]
pub struct Conditions<'a> {
    /// Motor-side joint positions the controller reports (rad or m), length `model.nq()`.
    pub q: &'a [f64],
    /// Sign of each joint's last motion (−1, 0, +1), or `None` when unknown.
    pub dir: Option<&'a [i8]>,
    /// Robot temperature (°C).
    pub temp_c: f64,
    /// Mass at the flange, if any.
    pub payload: Option<Payload>,
}

/// The noise-free truth of one measurement.
#[derive(Clone, Debug, PartialEq)]
pub struct TrueTarget {
    /// `T_base_flange` of the real robot (m).
    pub flange: Pose,
    /// Target position in the base frame (m).
    pub p_base: Vector3<f64>,
    /// Displacement added by each effect, in the order of the module docs (base frame, m).
    pub contribution: Contributions,
    /// Link-side joint positions after backlash and compliance (rad or m).
    pub q_link: Vec<f64>,
    /// Link-side positions from the first-order compliance solution, for comparison (rad or m).
    pub q_link_first_order: Vec<f64>,
    /// Fixed-point iterations the compliance equilibrium took (0 without compliance).
    pub compliance_iterations: usize,
}

/// Displacements of the target point by each effect (base frame, m).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Contributions {
    /// Thermal drift.
    pub thermal: [f64; 3],
    /// Kinematic offsets.
    pub kinematic: [f64; 3],
    /// Gear backlash.
    pub backlash: [f64; 3],
    /// Joint compliance.
    pub compliance: [f64; 3],
}

/// Noise-free target position of the real robot for one measurement.
///
/// `p_flange` is the target (reflector) position in the flange frame (m); `gravity` the gravity vector in
/// the base frame (m/s²). Fails for bad input (wrong joint count, compliance without inertials, an
/// equilibrium that does not converge).
pub fn true_target(
    model: &Model,
    effects: &Effects,
    cond: &Conditions<'_>,
    p_flange: &Vector3<f64>,
    gravity: &Vector3<f64>,
) -> crate::Result<TrueTarget> {
    let _ = (model, effects, cond, p_flange, gravity);
    todo!("being written")
}
