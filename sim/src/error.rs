//! The one error type of the `sim` crate.

use std::path::PathBuf;

/// Everything that can go wrong when loading a robot or evaluating it with bad input.
///
/// Each variant carries what a user needs to fix the input: the file, the element and the value.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SimError {
    /// The file could not be read.
    #[error("{path}: cannot read: {source}")]
    Io {
        /// File that was asked for.
        path: PathBuf,
        /// Underlying I/O error.
        source: std::io::Error,
    },
    /// The file is a xacro macro file, not a URDF.
    #[error(
        "{source_name}: this is a xacro file, not a URDF; expand it first (`xacro {source_name} > robot.urdf`)"
    )]
    Xacro {
        /// File or source name.
        source_name: String,
    },
    /// The XML could not be parsed as a URDF.
    #[error("{source_name}: not a valid URDF: {message}")]
    Parse {
        /// File or source name.
        source_name: String,
        /// What the parser said.
        message: String,
    },
    /// The URDF parsed, but its structure cannot give a serial chain.
    #[error("{source_name}: {message}")]
    Structure {
        /// File or source name.
        source_name: String,
        /// What is wrong, naming links and joints.
        message: String,
    },
    /// A numeric value in the URDF is NaN, infinite or out of its domain.
    #[error("{source_name}: {element} '{name}': {field} = {value} is {problem}")]
    BadValue {
        /// File or source name.
        source_name: String,
        /// `joint` or `link`.
        element: &'static str,
        /// Name of the joint or link.
        name: String,
        /// Attribute, e.g. `origin xyz`, `mass`, `inertia ixx`.
        field: &'static str,
        /// The offending value.
        value: f64,
        /// What is wrong with it, e.g. `not finite`.
        problem: &'static str,
    },
    /// Gravity torques or compliance were asked for but some moving bodies have no inertial data.
    #[error(
        "robot '{robot}': statics need masses, but these moving links have no <inertial> (or zero mass): {links}"
    )]
    MissingInertial {
        /// Robot name.
        robot: String,
        /// Comma-separated link names.
        links: String,
    },
    /// A joint vector has the wrong length.
    #[error("expected {expected} joint values, got {got}")]
    JointCount {
        /// Joints in the chain.
        expected: usize,
        /// Values given.
        got: usize,
    },
    /// A joint value is NaN or infinite.
    #[error("joint {joint} (1-based) value {value} is not finite")]
    NonFiniteJoint {
        /// 1-based joint number.
        joint: usize,
        /// The value.
        value: f64,
    },
    /// A name given for a built-in robot is unknown.
    #[error("unknown robot '{name}': not a file, and not one of the built-in robots ({known})")]
    UnknownRobot {
        /// What was asked for.
        name: String,
        /// Built-in names.
        known: String,
    },
}

/// Result alias for the `sim` crate.
pub type Result<T> = std::result::Result<T, SimError>;
