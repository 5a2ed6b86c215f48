//! The `--robot`, `--base-link` and `--tip-link` flags shared by every subcommand that needs a robot.

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
        Ok(robots::load_robot(&self.robot, &spec)?)
    }
}
