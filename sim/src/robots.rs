//! Robot descriptions shipped with robocal, embedded in the binary.
//!
//! Each URDF under `sim/robots/` was written by this project from published parameters; its header
//! says where every number comes from.

use crate::error::{Result, SimError};
use crate::model::Model;
use crate::urdf::{ChainSpec, load_file, load_str};
use std::path::Path;

/// Name of the default robot: the KUKA LBR iiwa 7 R800.
pub const DEFAULT_ROBOT: &str = "iiwa7";

/// Built-in robots: (name, URDF text).
pub const BUILTIN: &[(&str, &str)] = &[
    ("iiwa7", include_str!("../robots/iiwa7.urdf")),
    ("ur5", include_str!("../robots/ur5.urdf")),
    ("ur10", include_str!("../robots/ur10.urdf")),
    ("wam", include_str!("../robots/wam.urdf")),
];

/// URDF text of a built-in robot.
pub fn builtin_urdf(name: &str) -> Option<&'static str> {
    BUILTIN.iter().find(|(n, _)| *n == name).map(|(_, t)| *t)
}

/// Loads a built-in robot with its default chain.
pub fn load_builtin(name: &str) -> Result<Model> {
    let text = builtin_urdf(name).ok_or_else(|| unknown(name))?;
    load_str(
        text,
        &format!("built-in robot '{name}'"),
        &ChainSpec::default(),
    )
}

/// Loads `robot`: a URDF file path if such a file exists, otherwise a built-in robot's name.
pub fn load_robot(robot: &str, spec: &ChainSpec) -> Result<Model> {
    let path = Path::new(robot);
    // A file wins over a built-in name; a folder that happens to share one (`./ur5/`) does not.
    if path.is_file() {
        return load_file(path, spec);
    }
    match builtin_urdf(robot) {
        Some(text) => load_str(text, &format!("built-in robot '{robot}'"), spec),
        None if robot.ends_with(".urdf") || robot.ends_with(".xacro") || robot.contains('/') => {
            Err(SimError::Read {
                path: path.to_path_buf(),
                source: std::io::Error::new(std::io::ErrorKind::NotFound, "no such file"),
            })
        }
        None => Err(unknown(robot)),
    }
}

fn unknown(name: &str) -> SimError {
    SimError::UnknownRobot {
        name: name.to_string(),
        known: BUILTIN
            .iter()
            .map(|(n, _)| *n)
            .collect::<Vec<_>>()
            .join(", "),
    }
}
