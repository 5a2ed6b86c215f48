//! The `--robot`, `--base-link`, `--tip-link` and `--couplings` flags shared by every subcommand that
//! needs a robot.

use sim::coupled_joints::Couplings;
use sim::{ChainSpec, Model, robots};

/// Which robot to load.
#[derive(clap::Args, Debug, Clone)]
pub struct RobotArgs {
    /// URDF file, or a built-in robot name (iiwa7, ur5, ur10, wam). Default: the embedded iiwa 7.
    #[arg(long, value_name = "FILE|NAME", default_value = robots::DEFAULT_ROBOT)]
    pub robot: String,
    /// Root link of the chain (default: the URDF's root link).
    #[arg(long, value_name = "LINK")]
    pub base_link: Option<String>,
    /// Tip link of the chain (default: the single leaf link).
    #[arg(long, value_name = "LINK")]
    pub tip_link: Option<String>,
    /// Coupled joints declared beside the URDF: a TOML file of `[[coupling]]` tables (`joint`,
    /// `sources`, `multipliers`, `offset`), added to the URDF's own `<mimic>` and
    /// `<robocal:coupling>` couplings. A coupled joint has no column in the measurement table.
    #[arg(long, value_name = "FILE")]
    pub couplings: Option<std::path::PathBuf>,
}

impl RobotArgs {
    /// Loads the model, or a one-line input error. What the loader tolerated but a user should
    /// know (a branch off the chain loading it with its joints at zero, say) goes to stderr as
    /// warnings.
    pub fn load(&self) -> Result<Model, crate::error::CliError> {
        let model = self.load_quietly()?;
        for note in model.notes() {
            eprintln!("warning: robot '{}': {note}", model.name());
        }
        Ok(model)
    }

    /// [`RobotArgs::load`] without the warnings, for a command that shows the notes itself (`info`).
    pub fn load_quietly(&self) -> Result<Model, crate::error::CliError> {
        let spec = ChainSpec {
            base_link: self.base_link.clone(),
            tip_link: self.tip_link.clone(),
        };
        let model = robots::load_robot(&self.robot, &spec)?;
        match &self.couplings {
            None => Ok(model),
            Some(path) => Ok(model.with_couplings(&Couplings::read_file(path)?)?),
        }
    }

    /// The robot with its URDF text ([`calib::model::robot::Robot`]), as calibrate and diagnose
    /// embed it, with the `--couplings` file applied.
    pub fn load_robot(&self) -> Result<calib::model::robot::Robot, crate::error::CliError> {
        let spec = ChainSpec {
            base_link: self.base_link.clone(),
            tip_link: self.tip_link.clone(),
        };
        let robot = calib::model::robot::Robot::load(&self.robot, &spec)?;
        match &self.couplings {
            None => Ok(robot),
            Some(path) => Ok(robot.with_couplings(Couplings::read_file(path)?)?),
        }
    }
}
