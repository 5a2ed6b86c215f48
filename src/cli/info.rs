//! `robocal info`: the chain, axes, limits and masses of a robot.

use super::robot_arg::RobotArgs;
use super::shared::{CliResult, print_json};
use serde_json::json;

/// Arguments of `robocal info`.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(flatten)]
    robot: RobotArgs,
    /// Print one JSON document on stdout instead of the table on stderr.
    #[arg(long)]
    json: bool,
}

/// Runs `robocal info`.
pub fn run(args: Args) -> CliResult {
    let model = args.robot.load_quietly()?;
    if args.json {
        let joints: Vec<_> = model
            .joints()
            .iter()
            .zip(model.bodies())
            .map(|(j, b)| {
                json!({
                    "name": j.name, "kind": j.kind,
                    "screw_base": j.screw.as_slice(),
                    "point_on_axis_base_m": j.home.translation.vector.as_slice(),
                    "limits": j.limits,
                    "body_mass_kg": b.mass, "body_com_m": b.com.as_slice(), "body_links": b.links,
                })
            })
            .collect();
        let branch_joints: Vec<_> = model
            .branches()
            .joints()
            .iter()
            .map(|j| {
                json!({
                    "name": j.name, "column": format!("q_{}", j.name), "kind": j.kind,
                    "limits": j.limits, "hangs_from_joint": j.body + 1,
                    "after_branch_joint": j.parent.map(|p| &model.branches().joints()[p].name),
                    "own_links_mass_kg": j.mass,
                })
            })
            .collect();
        let m = model.home_flange().to_homogeneous();
        return print_json(&json!({
            "robot": model.name(), "base_link": model.base_link(), "tip_link": model.tip_link(),
            "joints": joints,
            "branch_joints": branch_joints,
            "home_flange": {"position_m": model.home_flange().translation.vector.as_slice(),
                             "rotation": (0..3).map(|r| (0..3).map(|c| m[(r, c)]).collect::<Vec<_>>()).collect::<Vec<_>>()},
            "moving_mass_kg": model.moving_mass(),
            "massless_links": model.massless_links(), "notes": model.notes(),
        }));
    }
    eprintln!(
        "robot '{}': {} joints, chain {} -> {}",
        model.name(),
        model.nq(),
        model.base_link(),
        model.tip_link()
    );
    eprintln!(
        "{:>3}  {:<16} {:<10} {:>26}  {:>26}  {:>20}  {:>8}",
        "#", "joint", "kind", "axis (base, q=0)", "point on axis (m)", "limits", "mass kg"
    );
    for (i, (j, b)) in model.joints().iter().zip(model.bodies()).enumerate() {
        let w = j.home.rotation * j.axis;
        let p = j.home.translation.vector;
        let lim = match j.limits {
            Some(l) => format!("[{:+.4}, {:+.4}] {}", l.lower, l.upper, j.kind.unit()),
            None => "none".to_string(),
        };
        eprintln!(
            "{:>3}  {:<16} {:<10} ({:+.4}, {:+.4}, {:+.4})  ({:+.4}, {:+.4}, {:+.4})  {:>20}  {:>8.4}",
            i + 1,
            j.name,
            format!("{:?}", j.kind).to_lowercase(),
            w.x,
            w.y,
            w.z,
            p.x,
            p.y,
            p.z,
            lim,
            b.mass
        );
    }
    for j in model.branches().joints() {
        eprintln!(
            "branch joint {} (column q_{}) on the body of joint {}: {:.4} kg of links before the next branch joint",
            j.name,
            j.name,
            j.body + 1,
            j.mass
        );
    }
    let p = model.home_flange().translation.vector;
    eprintln!("flange at q = 0: ({:.6}, {:.6}, {:.6}) m", p.x, p.y, p.z);
    eprintln!("moving mass: {:.4} kg", model.moving_mass());
    if !model.massless_links().is_empty() {
        eprintln!(
            "warning: no inertial data for {}: gravity torques and compliance are unavailable",
            model.massless_links().join(", ")
        );
    }
    for n in model.notes() {
        eprintln!("note: {n}");
    }
    Ok(())
}
