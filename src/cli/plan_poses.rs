//! `robocal plan-poses`: choose the measurement poses (and payloads) that determine a model's
//! parameters best, within what the cell allows.

use super::paths::Inputs;
use super::robot_arg::RobotArgs;
use super::shared::{CliError, CliResult, print_json};
use calib::fit::plan::{Candidates, CellConstraints, Criterion, PlanOptions, PosePlan, plan};
use calib::model::spec::{ModelChoice, ModelSpec};
use nalgebra::Vector3;
use serde_json::json;
use std::path::PathBuf;

/// Arguments of `robocal plan-poses`.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(flatten)]
    robot: RobotArgs,
    /// The robot's reachable poses to choose from: CSV or Parquet `pose, q1..qN` (x, y, z and the
    /// context columns payload, temp, t, dir1..dirN optional; a pose's first row counts).
    #[arg(long, value_name = "FILE")]
    candidates_file: Option<PathBuf>,
    /// Where to write the poses as CSV `pose,q1..qN` (and `payload`): a pose file for generate's
    /// `[campaign.file]` and for predict.
    #[arg(long, value_name = "FILE.csv")]
    out: Option<PathBuf>,
    /// Also write every candidate's information block as CSV (`candidate, q1..qN, payload,
    /// coordinate, a1..ar`: its weighted, scaled Jacobian rows on the identifiable combinations), to
    /// compare other designs on the same candidates.
    #[arg(long, value_name = "FILE.csv")]
    information_out: Option<PathBuf>,
    /// Print one JSON document on stdout instead of text on stderr.
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    options: Options,
}

/// The value flags of `robocal plan-poses`: one definition for the command line and the Python
/// package (`robocal.plan_poses(**options)`, parsed by [`super::flags::parse`]).
#[derive(clap::Args, Debug, Clone)]
pub struct Options {
    /// The model whose parameters the poses should determine: `kinematic` or a `+`-joined extension
    /// such as `kinematic+joint_compliance` (each cause at only some joints with `@`). Learned
    /// corrections and `auto` have no parameters to plan for.
    #[arg(long, value_name = "MODEL", default_value = "kinematic")]
    pub model: String,
    /// Design criterion: `d` (largest log det of the information, the default), `a` (smallest sum of
    /// the scaled parameter variances) or `e` (largest smallest eigenvalue).
    #[arg(long, value_name = "d|a|e", default_value = "d")]
    pub criterion: String,
    /// Random candidate configurations to choose from (uniform within the joint limits less
    /// --joint-margin). Ignored with --candidates-file.
    #[arg(long, value_name = "N", default_value_t = 2000)]
    pub candidates: usize,
    /// Poses to select.
    #[arg(long, value_name = "K")]
    pub select: usize,
    /// Payload masses each pose may carry (kg, comma-separated, e.g. `0,3.5,7`): the plan chooses one
    /// per pose and writes a `payload` column. Pays with causes that load the joints (compliance,
    /// deflection).
    #[arg(long, value_name = "M1,M2,..")]
    pub payloads: Option<String>,
    /// The payload's centre of mass in the flange frame (m).
    #[arg(
        long,
        value_name = "X,Y,Z",
        allow_hyphen_values = true,
        default_value = "0,0,0"
    )]
    pub payload_com: String,
    /// Seed of the candidate draw and of the random comparison sets.
    #[arg(long, value_name = "S", default_value_t = 0)]
    pub seed: u64,
    /// Target position in the flange frame assumed for planning (m).
    #[arg(
        long,
        value_name = "X,Y,Z",
        allow_hyphen_values = true,
        default_value = "0.05,0.03,0.08"
    )]
    pub target_offset: String,
    /// Tracker noise per coordinate (m), for the predicted standard deviations.
    #[arg(long, value_name = "M", default_value_t = 1e-5)]
    pub noise: f64,
    /// Tracker noise growing with the distance from the tracker (m per m; needs --tracker to mean
    /// the real distance).
    #[arg(long, value_name = "M_PER_M", default_value_t = 0.0)]
    pub noise_per_m: f64,
    /// The tracker's position in the robot base frame (m).
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true)]
    pub tracker: Option<String>,
    /// The tracker's range (m): the target must lie between MIN and MAX from it. Needs --tracker.
    #[arg(long, value_name = "MIN,MAX")]
    pub tracker_range: Option<String>,
    /// Keep the laser beam clear of every link by this much (m; links as segments between joint
    /// origins, the reflector's own link excepted). Needs --tracker.
    #[arg(long, value_name = "M")]
    pub line_of_sight: Option<f64>,
    /// Floor height in the base frame (m): every joint origin after the first, the flange and the
    /// target stay above it.
    #[arg(long, value_name = "Z", allow_hyphen_values = true)]
    pub floor: Option<f64>,
    /// Distance to keep from every joint limit (rad, or m for prismatic joints).
    #[arg(long, value_name = "RAD", default_value_t = 0.0)]
    pub joint_margin: f64,
}

/// `N` comma-separated finite numbers for `flag`.
fn numbers(flag: &str, text: &str, n: Option<usize>, what: &str) -> Result<Vec<f64>, CliError> {
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
                        "{flag}: value {} ('{}') is not a number",
                        i + 1,
                        s.trim()
                    ))
                })
        })
        .collect::<Result<_, _>>()?;
    if let Some(n) = n
        && v.len() != n
    {
        return Err(CliError::Input(format!(
            "{flag}: {} values, expected {what}",
            v.len()
        )));
    }
    Ok(v)
}

fn vector3(flag: &str, text: &str) -> Result<Vector3<f64>, CliError> {
    let v = numbers(flag, text, Some(3), "X,Y,Z in m")?;
    Ok(Vector3::new(v[0], v[1], v[2]))
}

/// The planner's settings the value flags give.
pub fn plan_options(args: &Options) -> Result<PlanOptions, CliError> {
    let mut o = PlanOptions::new(args.candidates, args.select, args.seed);
    o.model = match args.model.parse::<ModelChoice>()? {
        ModelChoice::Auto => {
            return Err(CliError::Input(
                "--model auto: plan-poses plans for a model with parameters; name its causes \
                 (e.g. kinematic+joint_compliance)"
                    .into(),
            ));
        }
        ModelChoice::Model(m) => m,
    };
    o.criterion = Criterion::parse(&args.criterion).ok_or_else(|| {
        CliError::Input(format!(
            "--criterion {}: not one of d, a, e",
            args.criterion
        ))
    })?;
    if let Some(text) = &args.payloads {
        let masses = numbers("--payloads", text, None, "masses in kg")?;
        let max = sim::measurement_table::MAX_PAYLOAD_KG;
        if let Some(m) = masses.iter().find(|m| !(0.0..=max).contains(*m)) {
            return Err(CliError::Input(format!(
                "--payloads {text}: {m} is not a mass in kg between 0 and {max}"
            )));
        }
        let mut sorted = masses.clone();
        sorted.sort_by(f64::total_cmp);
        if sorted.windows(2).any(|w| w[0] == w[1]) {
            return Err(CliError::Input(format!(
                "--payloads {text}: a mass appears twice"
            )));
        }
        o.payloads_kg = masses;
    }
    o.payload_com_m = vector3("--payload-com", &args.payload_com)?;
    o.target_offset = vector3("--target-offset", &args.target_offset)?;
    for (flag, v) in [("--noise", args.noise), ("--noise-per-m", args.noise_per_m)] {
        if !(v >= 0.0 && v.is_finite()) {
            return Err(CliError::Input(format!(
                "{flag} {v}: must be a number of metres ≥ 0"
            )));
        }
    }
    if args.noise == 0.0 && args.noise_per_m == 0.0 {
        return Err(CliError::Input(
            "--noise 0: the tracker noise must be > 0 m (it sets the predicted standard deviations)"
                .into(),
        ));
    }
    o.noise.position_sigma_m = args.noise;
    o.noise.position_sigma_per_m = args.noise_per_m;
    let range = match &args.tracker_range {
        Some(t) => {
            let v = numbers("--tracker-range", t, Some(2), "MIN,MAX in m")?;
            Some((v[0], v[1]))
        }
        None => None,
    };
    o.constraints = CellConstraints {
        tracker_base_m: args
            .tracker
            .as_deref()
            .map(|t| vector3("--tracker", t))
            .transpose()?,
        tracker_range_m: range,
        line_of_sight_clearance_m: args.line_of_sight,
        floor_z_m: args.floor,
        joint_margin: args.joint_margin,
    };
    Ok(o)
}

fn sigma_text(unit: calib::units::Unit, v: f64) -> String {
    match unit.symbol() {
        "m" => format!("{:.3} µm", v * 1e6),
        "rad" => format!("{:.3} µrad", v * 1e6),
        u => format!("{v:.3e} {u}"),
    }
}

fn print_text(model: &sim::Model, select: usize, plan: &PosePlan, spec: &ModelSpec) {
    eprintln!(
        "selected {} of {} candidate poses for '{}', model {} ({} of {} parameter combinations \
         identifiable, {}-optimal)",
        select,
        plan.candidates,
        model.name(),
        spec.name(),
        plan.rank,
        plan.n_params,
        plan.criterion.letter().to_uppercase()
    );
    for r in &plan.rejected {
        eprintln!(
            "  {} candidates left out by {} (first: poses {})",
            r.count,
            r.constraint.name(),
            r.first_poses
                .iter()
                .map(i64::to_string)
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    if let Some(p) = &plan.payload_kg {
        let mut masses: Vec<f64> = p.clone();
        masses.sort_by(f64::total_cmp);
        masses.dedup();
        let counts: Vec<String> = masses
            .iter()
            .map(|m| format!("{} × {m} kg", p.iter().filter(|x| *x == m).count()))
            .collect();
        eprintln!("payloads: {}", counts.join(", "));
    }
    eprintln!(
        "D-optimal criterion log det: selected {:.2}, random sets {:.2} ± {:.2} ({} random sets \
         singular)",
        plan.log_det, plan.random_log_det_mean, plan.random_log_det_std, plan.random_singular
    );
    eprintln!(
        "parameter σ (geometric mean): random poses {:.2}× the selected ones",
        plan.parameter_sigma_ratio
    );
    eprintln!(
        "predicted held-out error against the truth (RMS over the candidates): selected {:.2} µm, \
         random (median) {:.2} µm; against measurements {:.2} µm",
        plan.position_sigma_m * 1e6,
        plan.random_position_sigma_m * 1e6,
        plan.predicted_heldout_rms_m * 1e6
    );
    let undetermined = plan.parameters.iter().filter(|p| p.sigma.is_none()).count();
    if undetermined < plan.parameters.len() {
        eprintln!(
            "predicted σ of the {} parameters determined alone (selected; random median; ratio):",
            plan.parameters.len() - undetermined
        );
    }
    for p in plan.parameters.iter().filter(|p| p.sigma.is_some()) {
        match (p.sigma, p.random_sigma) {
            (Some(s), Some(r)) => eprintln!(
                "  {:<52} {:>16}  {:>16}  ({:.2}×)",
                p.name,
                sigma_text(p.unit, s),
                sigma_text(p.unit, r),
                r / s
            ),
            (Some(s), _) => eprintln!("  {:<52} {:>16}", p.name, sigma_text(p.unit, s)),
            _ => {}
        }
    }
    if undetermined > 0 {
        eprintln!(
            "  {} parameters are determined only in combinations (the {} identifiable ones; \
             --json lists every parameter)",
            if undetermined < plan.parameters.len() {
                format!("{undetermined} more")
            } else {
                format!("all {undetermined}")
            },
            plan.rank
        );
    }
}

/// Plans as `robocal plan-poses` with the value flags `options`: among `candidates` (a table of
/// configurations and the name its messages give it) or, without, `options.candidates` drawn ones.
/// With `keep_information` the plan keeps every candidate's information block
/// ([`PosePlan::information_csv`]).
pub fn plan_poses(
    model: &sim::Model,
    candidates: Option<(&sim::measurement_table::MeasurementTable, &str)>,
    options: &Options,
    keep_information: bool,
) -> Result<PosePlan, CliError> {
    let mut o = plan_options(options)?;
    o.keep_information = keep_information;
    let candidates = match candidates {
        Some((table, name)) => Candidates::from_table(model, table, name)?,
        None => Candidates::drawn(model, options.candidates, options.seed, &o.constraints)?,
    };
    if candidates.len() < options.select {
        return Err(CliError::Input(format!(
            "--select {}: more than the {} candidates of {}",
            options.select,
            candidates.len(),
            candidates.source
        )));
    }
    Ok(plan(model, &candidates, &o)?)
}

/// The `plan-poses --json` document.
pub fn json(
    model: &sim::Model,
    options: &Options,
    candidates_file: Option<&str>,
    out: Option<&str>,
    plan: &PosePlan,
) -> serde_json::Value {
    json!({
        "robot": model.name(),
        "model": plan.model,
        "candidates": plan.candidates + plan.rejected.iter().map(|r| r.count).sum::<usize>(),
        "candidates_file": candidates_file,
        "select": options.select,
        "seed": options.seed,
        "out": out,
        "plan": plan,
    })
}

/// Runs `robocal plan-poses`.
pub fn run(args: Args) -> CliResult {
    let mut inputs = Inputs::new();
    inputs.add_robot(&args.robot.robot);
    if let Some(c) = &args.candidates_file {
        inputs.add("--candidates-file", c);
    }
    if let Some(out) = &args.out {
        inputs.check("--out", out)?;
    }
    if let Some(info) = &args.information_out {
        inputs.check("--information-out", info)?;
        if let Some(out) = &args.out {
            super::paths::check_distinct(("--out", out), ("--information-out", info))?;
        }
    }
    let model = args.robot.load()?;
    let spec = plan_options(&args.options)?.model;
    let file = args
        .candidates_file
        .as_ref()
        .map(|p| p.display().to_string());
    let table = args
        .candidates_file
        .as_ref()
        .map(|p| sim::measurement_table::read_configurations(p))
        .transpose()?;
    let plan = plan_poses(
        &model,
        table.as_ref().zip(file.as_deref()),
        &args.options,
        args.information_out.is_some(),
    )?;
    if let Some(path) = &args.out {
        sim::io::write_atomic(path, plan.to_csv().as_bytes())?;
    }
    if let (Some(path), Some(text)) = (&args.information_out, plan.information_csv()) {
        sim::io::write_atomic(path, text.as_bytes())?;
    }
    if args.json {
        let out = args.out.as_ref().map(|p| p.display().to_string());
        return print_json(&json(
            &model,
            &args.options,
            file.as_deref(),
            out.as_deref(),
            &plan,
        ));
    }
    print_text(&model, args.options.select, &plan, &spec);
    if let Some(p) = &args.out {
        eprintln!("wrote {}", p.display());
    }
    Ok(())
}
