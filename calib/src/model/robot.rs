//! A robot model together with the URDF text it came from, so that calibrated models can embed it.

use crate::error::{CalibError, Result};
use sim::{ChainSpec, Model, robots, urdf};
use std::path::Path;

/// A robot model and its source.
#[derive(Clone, Debug)]
pub struct Robot {
    /// The chain, built from `urdf`.
    pub model: Model,
    /// The URDF text.
    pub urdf: String,
    /// Where it came from: a file path or `built-in robot 'NAME'`.
    pub source: String,
    /// Couplings declared beside the URDF (`--couplings FILE`), already in `model`; those of the URDF
    /// itself (`<mimic>`, `<robocal:coupling>`) are not repeated here.
    pub couplings: Vec<sim::coupled_joints::CouplingDecl>,
}

impl Robot {
    /// Loads `robot`: a URDF file if such a file exists, otherwise a built-in robot name (as
    /// [`sim::robots::load_robot`] does), keeping the URDF text.
    pub fn load(robot: &str, spec: &ChainSpec) -> Result<Self> {
        let path = Path::new(robot);
        if path.is_file() {
            let text = std::fs::read_to_string(path).map_err(|e| CalibError::Read {
                path: robot.to_string(),
                message: e.to_string(),
            })?;
            let model = urdf::load_file(path, spec)?;
            return Ok(Robot {
                model,
                urdf: text,
                source: robot.to_string(),
                couplings: Vec::new(),
            });
        }
        let model = robots::load_robot(robot, spec)?;
        let text = robots::builtin_urdf(robot)
            .ok_or_else(|| CalibError::Misuse(format!("robot '{robot}' has no URDF text")))?;
        Ok(Robot {
            model,
            urdf: text.to_string(),
            source: format!("built-in robot '{robot}'"),
            couplings: Vec::new(),
        })
    }

    /// Builds the chain from URDF text; `source` names it in errors.
    pub fn from_urdf_str(text: &str, source: &str, spec: &ChainSpec) -> Result<Self> {
        Ok(Robot {
            model: urdf::load_str(text, source, spec)?,
            urdf: text.to_string(),
            source: source.to_string(),
            couplings: Vec::new(),
        })
    }

    /// This robot with the couplings `decls` (a `--couplings` file, [`sim::coupled_joints`]) added
    /// to its chain and kept, so that a calibrated model embeds them.
    ///
    /// # Errors
    /// A name that is not a movable joint of the chain, a joint coupled twice, what
    /// [`sim::coupled_joints::Couplings::new`] refuses.
    pub fn with_couplings(mut self, decls: Vec<sim::coupled_joints::CouplingDecl>) -> Result<Self> {
        self.model = self.model.with_couplings(&decls)?;
        self.couplings.extend(decls);
        Ok(self)
    }
}
