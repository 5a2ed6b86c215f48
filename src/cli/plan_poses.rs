//! `robocal plan-poses`: choose the measurement poses that determine the kinematic parameters best.

use super::paths::Inputs;
use super::robot_arg::RobotArgs;
use super::shared::{CliError, CliResult, print_json};
use calib::fit::plan::{PlanOptions, plan_poses};
use serde_json::json;
use std::path::PathBuf;

/// Arguments of `robocal plan-poses`.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(flatten)]
    robot: RobotArgs,
    /// Random candidate configurations to choose from (uniform within the joint limits).
    #[arg(long, value_name = "N", default_value_t = 2000)]
    candidates: usize,
    /// Poses to select.
    #[arg(long, value_name = "K")]
    select: usize,
    /// Seed of the candidate draw.
    #[arg(long, value_name = "S", default_value_t = 0)]
    seed: u64,
    /// Target position in the flange frame assumed for planning (m).
    #[arg(
        long,
        value_name = "X,Y,Z",
        allow_hyphen_values = true,
        default_value = "0.05,0.03,0.08"
    )]
    target_offset: String,
    /// Tracker noise per coordinate (m), for the predicted standard deviations.
    #[arg(long, value_name = "M", default_value_t = 1e-5)]
    noise: f64,
    /// Where to write the poses as CSV `pose,q1..qN`.
    #[arg(long, value_name = "FILE.csv")]
    out: Option<PathBuf>,
    /// Print one JSON document on stdout instead of text on stderr.
    #[arg(long)]
    json: bool,
}

fn parse3(text: &str) -> Result<nalgebra::Vector3<f64>, CliError> {
    let v: Vec<f64> = text
        .split(',')
        .enumerate()
        .map(|(i, s)| {
            s.trim()
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| {
                    CliError::Input(format!(
                        "--target-offset: value {} ('{}') is not a number",
                        i + 1,
                        s.trim()
                    ))
                })
        })
        .collect::<Result<_, _>>()?;
    if v.len() != 3 {
        return Err(CliError::Input(format!(
            "--target-offset: {} values, expected X,Y,Z in m",
            v.len()
        )));
    }
    Ok(nalgebra::Vector3::new(v[0], v[1], v[2]))
}

/// Runs `robocal plan-poses`.
pub fn run(args: Args) -> CliResult {
    if let Some(out) = &args.out {
        Inputs::new()
            .add_robot(&args.robot.robot)
            .check("--out", out)?;
    }
    let model = args.robot.load()?;
    let mut options = PlanOptions::new(args.candidates, args.select, args.seed);
    options.target_offset = parse3(&args.target_offset)?;
    if !(args.noise > 0.0 && args.noise.is_finite()) {
        return Err(CliError::Input(format!(
            "--noise {}: must be a positive number of metres",
            args.noise
        )));
    }
    options.sigma_m = args.noise;
    let plan = plan_poses(&model, &options)?;
    if let Some(path) = &args.out {
        sim::io::write_atomic(path, plan.to_csv().as_bytes())?;
    }
    if args.json {
        return print_json(&json!({
            "robot": model.name(),
            "candidates": args.candidates,
            "select": args.select,
            "seed": args.seed,
            "out": args.out.as_ref().map(|p| p.display().to_string()),
            "plan": plan,
        }));
    }
    eprintln!(
        "selected {} of {} candidate poses for '{}' ({} of {} parameter combinations identifiable)",
        args.select,
        args.candidates,
        model.name(),
        plan.rank,
        plan.n_params
    );
    eprintln!(
        "D-optimal criterion log det: selected {:.2}, random sets {:.2} ± {:.2} ({} of {} random sets singular)",
        plan.log_det,
        plan.random_log_det_mean,
        plan.random_log_det_std,
        plan.random_singular,
        options.random_sets
    );
    eprintln!(
        "parameter σ (geometric mean): random poses {:.2}× the selected ones",
        plan.parameter_sigma_ratio
    );
    eprintln!(
        "predicted position σ over the workspace at {:.1} µm noise: selected {:.2} µm, random (median) {:.2} µm",
        args.noise * 1e6,
        plan.position_sigma_m * 1e6,
        plan.random_position_sigma_m * 1e6
    );
    if let Some(p) = &args.out {
        eprintln!("wrote {}", p.display());
    }
    Ok(())
}
