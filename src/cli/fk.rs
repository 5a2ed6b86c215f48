//! `robocal fk`: the flange pose at a joint configuration.

use super::robot_arg::RobotArgs;
use super::shared::{CliError, CliResult, print_json};
use serde_json::json;

/// Arguments of `robocal fk`.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(flatten)]
    robot: RobotArgs,
    /// Joint positions q1,q2,... (rad for revolute joints, m for prismatic ones).
    #[arg(long, value_name = "Q1,Q2,...", allow_hyphen_values = true)]
    q: String,
    /// Print one JSON document on stdout instead of text on stderr.
    #[arg(long)]
    json: bool,
}

/// Parses a comma-separated joint vector.
fn parse_q(text: &str) -> Result<Vec<f64>, CliError> {
    text.split(',')
        .enumerate()
        .map(|(i, s)| {
            s.trim().parse::<f64>().map_err(|_| {
                CliError::Input(format!(
                    "--q: value {} ('{}') is not a number",
                    i + 1,
                    s.trim()
                ))
            })
        })
        .collect()
}

/// Runs `robocal fk`.
pub fn run(args: Args) -> CliResult {
    let model = args.robot.load()?;
    let q = parse_q(&args.q)?;
    model.check_q(&q).map_err(|e| {
        CliError::Input(format!(
            "--q: {e} (robot '{}' of --robot {})",
            model.name(),
            args.robot.robot
        ))
    })?;
    for (i, (j, v)) in model.joints().iter().zip(&q).enumerate() {
        if let Some(l) = j.limits
            && (*v < l.lower || *v > l.upper)
        {
            eprintln!(
                "warning: q{} = {v} is outside the limits [{}, {}] of joint '{}'",
                i + 1,
                l.lower,
                l.upper,
                j.name
            );
        }
    }
    let mut data = sim::Data::new(&model);
    let t = sim::flange_pose(&model, &mut data, &q);
    let p = t.translation.vector;
    let r = t.rotation.matrix();
    if args.json {
        let rows: Vec<Vec<f64>> = (0..3)
            .map(|i| (0..3).map(|j| r[(i, j)]).collect())
            .collect();
        return print_json(&json!({
            "robot": model.name(), "base_link": model.base_link(), "tip_link": model.tip_link(),
            "q": q, "position_m": [p.x, p.y, p.z], "rotation": rows,
        }));
    }
    eprintln!(
        "T_base_flange ({} in {}):",
        model.tip_link(),
        model.base_link()
    );
    eprintln!("  position (m): {:.9} {:.9} {:.9}", p.x, p.y, p.z);
    eprintln!("  rotation:");
    for i in 0..3 {
        eprintln!(
            "    {:+.12} {:+.12} {:+.12}",
            r[(i, 0)],
            r[(i, 1)],
            r[(i, 2)]
        );
    }
    Ok(())
}
