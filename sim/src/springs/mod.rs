//! The joint springs and deflection hinges as parameters: the checks of stiffness and compliance
//! lists, the deflection axes, and the settings that settle them in the physics engine.
//!
//! Shared by the injected effects ([`crate::effects::joint_compliance`],
//! [`crate::effects::link_deflection`], [`crate::effects::rapier_compliance`]) and the rapier truth
//! ([`crate::rapier_truth`]); it sits below both, so that neither imports the other for them.

pub(crate) mod deflection;
pub mod settle;
pub(crate) mod stiffness;

pub use deflection::MAX_COMPLIANCE_RAD_PER_NM;
pub use settle::SettleOptions;
