//! The model floor: what a calibrated robot *is*, and how it predicts.
//!
//! The kinematic parameters ([`params`]) and their product of exponentials ([`chain`]), the causes
//! that extend it ([`extensions`], one file each), the learned corrections ([`learned`]), the model
//! specification that names them ([`spec::ModelSpec`]), the one prediction path ([`predict`], with
//! [`physical_row`]) and the rows it reads ([`observations`]), residual statistics ([`stats`]), each
//! prediction's Jacobian ([`jacobian`]) and standard deviation ([`uncertainty`]), its inverse
//! ([`compensate`]), the model file ([`file`]), its URDF export ([`urdf_export`]) and UR's kinematics
//! file ([`ur_kinematics`]), and the robot a model belongs to
//! ([`robot`]).
//!
//! Nothing here fits, validates or chooses: this floor imports only the ground floor (`lm`, `linalg`,
//! `lie3`, `units`, `error`, …) and itself.

pub mod chain;
pub mod compensate;
pub mod extensions;
pub mod file;
pub mod jacobian;
pub mod learned;
pub mod observations;
pub mod params;
pub mod physical_row;
pub mod predict;
pub mod robot;
pub mod spec;
pub mod stats;
pub mod uncertainty;
pub mod ur_kinematics;
pub mod urdf_export;

pub use spec::{ModelChoice, ModelSpec};
