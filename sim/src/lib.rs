//! # robocal `sim`: the simulation side of the testbed
//!
//! A serial robot is a [`Model`] (immutable, from a URDF) plus a [`Data`] workspace for evaluations.
//! Kinematics use the product of exponentials (Lynch and Park, *Modern Robotics*, ch. 4):
//!
//! ```text
//! T_base_flange(q) = exp([S₁] q₁) exp([S₂] q₂) ⋯ exp([Sₙ] qₙ) M
//! ```
//!
//! with `Sᵢ = [ωᵢ; vᵢ]` the screw axis of joint `i` in the base frame at q = 0 (`vᵢ = -ωᵢ × pᵢ` for a
//! point `pᵢ` on a revolute axis) and `M` the flange pose at q = 0. Evaluation uses the equivalent chain
//! of URDF joint frames, which is cheaper; tests check the two agree.
//!
//! Gravity torques `τ_g(q) = -Σₖ Jₖᵀ mₖ g` (see [`statics`]) are what the joints apply to hold the arm.
//!
//! Units are SI (m, rad, kg, N m, s); every pose is named `T_a_b` (frame `b` expressed in `a`).
//!
//! ```
//! use sim::{Data, forward_kinematics, robots};
//! let model = robots::load_builtin("iiwa7").unwrap();
//! let mut data = Data::new(&model);
//! forward_kinematics(&model, &mut data, &[0.0; 7]);
//! assert!((data.flange.translation.z - 1.266).abs() < 1e-12);
//! ```
#![warn(missing_docs)]

pub mod branches;
pub mod campaign;
pub mod coupled_joints;
pub mod decoder_guard;
pub mod effect_id;
pub mod effects;
pub mod error;
pub mod generate;
pub mod io;
pub mod joint_kind;
pub mod kinematics;
pub mod lie;
pub mod magnitude;
pub mod measurement_table;
pub mod model;
pub mod rapier_truth;
pub mod robots;
pub mod scenario;
pub mod seeds;
pub mod springs;
pub mod statics;
pub mod tracker;
pub mod trig;
pub mod urdf;
pub mod urdf_text;

pub use error::{Result, SimError};
pub use kinematics::{Data, Frame, flange_pose, forward_kinematics};
pub use lie::Pose;
pub use model::{Body, Joint, JointKind, JointLimits, Model, ModelParts};
pub use statics::{Payload, gravity_torques};
pub use urdf::ChainSpec;
