//! Resolving a parsed scenario into a runnable one: the robot loaded, every magnitude drawn, the
//! effects, the tracker and the campaign built and checked against each other ([`Scenario::resolve`]).

use crate::campaign::{CampaignSpec, DirectionRule, Iso9283, PayloadRule, Reachability, Sampling};
use crate::effects::Effects;
use crate::error::{Result, SimError, scenario_err};
use crate::magnitude::fnv1a64;
use crate::model::Model;
use crate::scenario::schema::{PointsPerJoint, SamplingKind, ScenarioFile, TruthModel};
use crate::tracker::{self, NoiseModel, Tracker};
use crate::urdf::ChainSpec;
use nalgebra::Vector3;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// A parsed scenario with where it came from.
#[derive(Clone, Debug, PartialEq)]
pub struct Scenario {
    /// File name used in messages (as given).
    pub label: String,
    /// Folder relative paths in the file refer to.
    pub base_dir: PathBuf,
    /// The file's text.
    pub text: String,
    /// The parsed file.
    pub file: ScenarioFile,
}

/// Command-line overrides of the scenario.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Overrides {
    /// Replaces `seed`.
    pub seed: Option<u64>,
    /// Replaces `[campaign] poses`.
    pub poses: Option<usize>,
    /// Replaces `[tracker] noise_scale`.
    pub noise: Option<f64>,
}

/// Where the robot came from, for the record.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RobotSource {
    /// `built-in iiwa7` or the URDF file name.
    pub source: String,
    /// FNV-1a 64 hash of the URDF text, hex.
    pub urdf_fnv1a64: String,
}

/// A scenario with every draw made and every value checked: what the generator runs.
#[derive(Clone, Debug)]
pub struct Resolved {
    /// The parsed scenario.
    pub scenario: Scenario,
    /// The overrides applied.
    pub overrides: Overrides,
    /// The seed in force.
    pub seed: u64,
    /// The nominal robot.
    pub model: Model,
    /// Where the robot came from.
    pub robot_source: RobotSource,
    /// Gravity in the base frame (m/s²).
    pub gravity: Vector3<f64>,
    /// The injected effects, every number resolved.
    pub effects: Effects,
    /// The tracker, placement resolved.
    pub tracker: Tracker,
    /// Tracker placement as drawn: base origin in the tracker frame (m).
    pub tracker_xyz_m: [f64; 3],
    /// Tracker placement as drawn: base roll-pitch-yaw in the tracker frame (rad).
    pub tracker_rpy_rad: [f64; 3],
    /// The campaign.
    pub campaign: CampaignSpec,
    /// Truth model.
    pub truth_model: TruthModel,
}

/// Line, section and key at byte `pos` of `text`: `line 12, [effects.compliance] stiffness`.
fn locate(text: &str, pos: usize) -> String {
    let pos = pos.min(text.len());
    let before = &text[..pos];
    let line_no = before.matches('\n').count() + 1;
    let is_header = |l: &str| {
        let t = l.trim();
        t.starts_with('[')
            && t.chars()
                .nth(1)
                .is_some_and(|c| c.is_ascii_alphabetic() || c == '[' || c == '_')
            && !t.contains('=')
    };
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    let section = text[..line_start]
        .lines()
        .rev()
        .find(|l| is_header(l))
        .map(|l| {
            let t = l.trim();
            t[..t.find(']').map_or(t.len(), |i| i + 1)].to_string()
        })
        .filter(|_| !text.lines().nth(line_no - 1).is_some_and(is_header));
    let line = text.lines().nth(line_no - 1).unwrap_or("");
    let key = line.split_once('=').map(|(k, _)| k.trim().to_string());
    let mut s = format!("line {line_no}");
    if let Some(sec) = section {
        s.push_str(&format!(", {sec}"));
    }
    if let Some(k) = key.filter(|k| !k.is_empty()) {
        s.push_str(&format!(" {k}"));
    }
    s
}

fn three(v: Vec<f64>) -> [f64; 3] {
    [v[0], v[1], v[2]]
}

impl Scenario {
    /// Parses scenario `text`; `label` names it in errors and `base_dir` anchors its relative paths.
    /// Unknown keys, wrong types and malformed TOML are refused with the line, section and key.
    pub fn parse(text: &str, label: &str, base_dir: &Path) -> Result<Scenario> {
        let file: ScenarioFile = toml::from_str(text).map_err(|e| {
            let key = e
                .span()
                .map_or_else(|| "toml".to_string(), |s| locate(text, s.start));
            let message = e.message().trim().replace('\n', " ");
            scenario_err(label, &key, message)
        })?;
        Ok(Scenario {
            label: label.to_string(),
            base_dir: base_dir.to_path_buf(),
            text: text.to_string(),
            file,
        })
    }

    /// Reads and parses the scenario file at `path`.
    pub fn load(path: &Path) -> Result<Scenario> {
        let text = std::fs::read_to_string(path).map_err(|source| SimError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        let base = path
            .parent()
            .map_or_else(|| PathBuf::from("."), Path::to_path_buf);
        Scenario::parse(&text, &path.display().to_string(), &base)
    }

    fn load_robot(&self) -> Result<(Model, RobotSource)> {
        let f = &self.label;
        let r = &self.file.robot;
        let spec = ChainSpec {
            base_link: r.base_link.clone(),
            tip_link: r.tip_link.clone(),
        };
        let (text, source) = match (&r.name, &r.urdf) {
            (Some(_), Some(_)) => {
                return Err(scenario_err(
                    f,
                    "robot",
                    "give either name or urdf, not both".into(),
                ));
            }
            (None, None) => {
                return Err(scenario_err(
                    f,
                    "robot",
                    "needs name (a built-in robot) or urdf (a file)".into(),
                ));
            }
            (Some(name), None) => {
                let t = crate::robots::builtin_urdf(name).ok_or_else(|| {
                    scenario_err(
                        f,
                        "robot.name",
                        format!(
                            "unknown built-in robot '{name}' (known: {}); for a file use urdf = \"...\"",
                            crate::robots::BUILTIN
                                .iter()
                                .map(|(n, _)| *n)
                                .collect::<Vec<_>>()
                                .join(", ")
                        ),
                    )
                })?;
                (t.to_string(), format!("built-in {name}"))
            }
            (None, Some(u)) => {
                let path = self.base_dir.join(u);
                let t = std::fs::read_to_string(&path).map_err(|e| {
                    scenario_err(
                        f,
                        "robot.urdf",
                        format!("cannot read {}: {e}", path.display()),
                    )
                })?;
                let name = Path::new(u)
                    .file_name()
                    .map_or_else(|| u.clone(), |n| n.to_string_lossy().into_owned());
                (t, name)
            }
        };
        let model = crate::urdf::load_str(&text, &source, &spec)
            .map_err(|e| scenario_err(f, "robot", e.to_string()))?;
        let model = match &r.couplings {
            None => model,
            Some(c) => {
                let path = self.base_dir.join(c);
                let decls = crate::coupled_joints::Couplings::read_file(&path)
                    .map_err(|e| scenario_err(f, "robot.couplings", e.to_string()))?;
                model
                    .with_couplings(&decls)
                    .map_err(|e| scenario_err(f, "robot.couplings", e.to_string()))?
            }
        };
        Ok((
            model,
            RobotSource {
                source,
                urdf_fnv1a64: format!("{:016x}", fnv1a64(text.as_bytes())),
            },
        ))
    }

    fn effects(&self, model: &Model, seed: u64) -> Result<Effects> {
        Effects::from_sections(&self.file.effects, model, seed, &self.label)
    }

    fn tracker(&self, seed: u64, noise: Option<f64>) -> Result<(Tracker, [f64; 3], [f64; 3])> {
        let f = self.label.as_str();
        let t = &self.file.tracker;
        let xyz = match &t.xyz_m {
            Some(m) => three(m.resolve(seed, f, "tracker.xyz_m", &[3])?),
            None => tracker::DEFAULT_BASE_XYZ_M,
        };
        let rpy = match &t.rpy_rad {
            Some(m) => three(m.resolve(seed, f, "tracker.rpy_rad", &[3])?),
            None => tracker::DEFAULT_BASE_RPY_RAD,
        };
        let d = Vector3::from(xyz).norm();
        if d > 100.0 {
            return Err(scenario_err(
                f,
                "tracker.xyz_m",
                format!("the robot is {d} m from the tracker: give metres, not millimetres"),
            ));
        }
        if let Some((k, v)) = rpy
            .iter()
            .enumerate()
            .find(|(_, v)| v.abs() > 2.0 * std::f64::consts::PI)
        {
            return Err(scenario_err(
                f,
                &format!("tracker.rpy_rad[{k}]"),
                format!("{v} is more than 2π: give radians, not degrees"),
            ));
        }
        let reflector = t.reflector_m.unwrap_or(tracker::DEFAULT_P_FLANGE_M);
        let r = Vector3::from(reflector).norm();
        if r > 2.0 {
            return Err(scenario_err(
                f,
                "tracker.reflector_m",
                format!("{r} m from the flange: give metres, not millimetres"),
            ));
        }
        let dflt = NoiseModel::default();
        let noise_model = NoiseModel {
            radial_a_m: t.radial_sigma_a_m.unwrap_or(dflt.radial_a_m),
            radial_b_m_per_m: t.radial_sigma_b_m_per_m.unwrap_or(dflt.radial_b_m_per_m),
            transverse_a_m: t.transverse_sigma_a_m.unwrap_or(dflt.transverse_a_m),
            transverse_b_m_per_m: t
                .transverse_sigma_b_m_per_m
                .unwrap_or(dflt.transverse_b_m_per_m),
            orientation_sigma_rad: t
                .orientation_sigma_rad
                .unwrap_or(dflt.orientation_sigma_rad),
            outlier_rate: t.outlier_rate.unwrap_or(dflt.outlier_rate),
            outlier_magnitude_m: t.outlier_magnitude_m.unwrap_or(dflt.outlier_magnitude_m),
        };
        let scale = noise.or(t.noise_scale).unwrap_or(1.0);
        let map = |e: SimError| match e {
            SimError::BadCondition {
                field,
                value,
                problem,
            } => {
                let key = match field.as_str() {
                    "tracker.radial_a_m" => "tracker.radial_sigma_a_m".to_string(),
                    "tracker.radial_b_m_per_m" => "tracker.radial_sigma_b_m_per_m".to_string(),
                    "tracker.transverse_a_m" => "tracker.transverse_sigma_a_m".to_string(),
                    "tracker.transverse_b_m_per_m" => {
                        "tracker.transverse_sigma_b_m_per_m".to_string()
                    }
                    "tracker.noise_scale" if noise.is_some() => "--noise".to_string(),
                    other => other.to_string(),
                };
                scenario_err(f, &key, format!("value {value}: {problem}"))
            }
            other => scenario_err(f, "tracker", other.to_string()),
        };
        let mut tr = Tracker::new(xyz, rpy, reflector, noise_model, scale).map_err(map)?;
        if t.six_dof.unwrap_or(false) {
            tr = tr.with_six_dof(t.probe_rpy_rad.unwrap_or([0.0; 3]));
        } else if t.probe_rpy_rad.is_some() {
            return Err(scenario_err(
                f,
                "tracker.probe_rpy_rad",
                "only used with six_dof = true".into(),
            ));
        }
        Ok((tr, xyz, rpy))
    }

    fn campaign(
        &self,
        model: &Model,
        poses: Option<usize>,
        p_flange: [f64; 3],
    ) -> Result<CampaignSpec> {
        let f = self.label.as_str();
        let c = &self.file.campaign;
        let dflt = CampaignSpec::random(100);
        let reachability = Reachability {
            floor_z_m: c.floor_z_m.unwrap_or(dflt.reachability().floor_z_m),
            min_axis_distance_m: c
                .min_axis_distance_m
                .unwrap_or(dflt.reachability().min_axis_distance_m),
        };
        for (key, v) in [
            ("campaign.floor_z_m", reachability.floor_z_m),
            (
                "campaign.min_axis_distance_m",
                reachability.min_axis_distance_m,
            ),
        ] {
            if !v.is_finite() || v.abs() > 10.0 {
                return Err(scenario_err(
                    f,
                    key,
                    format!("{v} is not a plausible length in m"),
                ));
            }
        }
        let margin = c.joint_margin_rad.unwrap_or(0.05);
        if !(margin.is_finite() && margin >= 0.0) {
            return Err(scenario_err(
                f,
                "campaign.joint_margin_rad",
                format!("{margin} must be finite and ≥ 0"),
            ));
        }
        let given: Vec<SamplingKind> = [
            (c.iso9283.is_some(), SamplingKind::Iso9283),
            (c.grid.is_some(), SamplingKind::Grid),
            (c.file.is_some(), SamplingKind::File),
        ]
        .into_iter()
        .filter_map(|(g, k)| g.then_some(k))
        .collect();
        let kind = match (c.sampling, given.as_slice()) {
            (Some(k), []) => k,
            (Some(k), [g]) if *g == k => k,
            (None, []) => SamplingKind::Random,
            (None, [g]) => *g,
            (_, gs) => {
                return Err(scenario_err(
                    f,
                    "campaign.sampling",
                    format!(
                        "sampling = {:?} but the tables {:?} are given; keep only the one that is used",
                        c.sampling.unwrap_or(SamplingKind::Random),
                        gs
                    ),
                ));
            }
        };
        let sampling = match kind {
            SamplingKind::Random => Sampling::Random {
                joint_margin_rad: margin,
                max_tries_per_pose: c.max_tries_per_pose.unwrap_or(10_000),
            },
            SamplingKind::Iso9283 => {
                let iso = c.iso9283.as_ref().ok_or_else(|| {
                    scenario_err(
                        f,
                        "campaign.iso9283",
                        "sampling = \"iso9283\" needs [campaign.iso9283] with seed_q".into(),
                    )
                })?;
                Sampling::Iso9283(Iso9283 {
                    cube_side_m: iso.cube_side_m.unwrap_or(0.3),
                    center_base_m: iso.center_m,
                    seed_q: iso.seed_q.clone(),
                })
            }
            SamplingKind::Grid => {
                let g = c.grid.as_ref().ok_or_else(|| {
                    scenario_err(
                        f,
                        "campaign.grid",
                        "sampling = \"grid\" needs [campaign.grid] points_per_joint".into(),
                    )
                })?;
                Sampling::Grid {
                    points_per_joint: match &g.points_per_joint {
                        PointsPerJoint::All(k) => vec![*k; model.nq()],
                        PointsPerJoint::PerJoint(v) => v.clone(),
                    },
                    joint_margin_rad: margin,
                }
            }
            SamplingKind::File => {
                let p = c.file.as_ref().ok_or_else(|| {
                    scenario_err(
                        f,
                        "campaign.file",
                        "sampling = \"file\" needs [campaign.file] path".into(),
                    )
                })?;
                Sampling::File {
                    path: self.base_dir.join(&p.path),
                    as_written: p.path.clone(),
                }
            }
        };
        let (payload, payload_com_m) = match &c.payload {
            Some(p) => {
                let rule = match (p.mass_kg, &p.choice_kg) {
                    (Some(_), Some(_)) => {
                        return Err(scenario_err(
                            f,
                            "campaign.payload",
                            "give mass_kg or choice_kg, not both".into(),
                        ));
                    }
                    (Some(m), None) => PayloadRule::Fixed(m),
                    (None, Some(v)) => PayloadRule::Choice(v.clone()),
                    (None, None) => PayloadRule::Fixed(0.0),
                };
                let com = p.com_m.unwrap_or([0.0; 3]);
                if com.iter().any(|v| !v.is_finite() || v.abs() > 2.0) {
                    return Err(scenario_err(
                        f,
                        "campaign.payload.com_m",
                        format!("{com:?} is not a plausible offset in m"),
                    ));
                }
                (rule, com)
            }
            None => (dflt.payload().clone(), dflt.payload_com_m()),
        };
        dflt.to_builder()
            .label(f)
            .poses(poses.or(c.poses))
            .repeats(c.repeats.unwrap_or(1))
            .seconds_per_pose(c.seconds_per_pose.unwrap_or(dflt.seconds_per_pose()))
            .seconds_per_repeat(c.seconds_per_repeat.unwrap_or(dflt.seconds_per_repeat()))
            .directions(c.directions.unwrap_or(DirectionRule::Move))
            .branches(c.branches.unwrap_or_default())
            .start_q(c.start_q.clone())
            .p_flange_m(p_flange)
            .reachability(reachability)
            .sampling(sampling)
            .payload(payload, payload_com_m)
            .temperature(
                c.temperature
                    .clone()
                    .unwrap_or_else(|| dflt.temperature().clone()),
            )
            .build()
    }

    /// Draws every random magnitude from the seed (the override's, else the file's, else 0), loads
    /// the robot, builds the effects, the tracker and the campaign, and checks them against each
    /// other. Errors name the file and the key.
    pub fn resolve(&self, overrides: &Overrides) -> Result<Resolved> {
        let f = self.label.as_str();
        let truth_model = self.file.truth.model.unwrap_or_default();
        let seed = overrides.seed.or(self.file.seed).unwrap_or(0);
        let (model, robot_source) = self.load_robot()?;
        let gravity = self
            .file
            .robot
            .gravity_m_per_s2
            .unwrap_or(crate::statics::DEFAULT_GRAVITY);
        if let Some((k, v)) = gravity
            .iter()
            .enumerate()
            .find(|(_, v)| !v.is_finite() || v.abs() > 100.0)
        {
            return Err(scenario_err(
                f,
                &format!("robot.gravity_m_per_s2[{k}]"),
                format!("{v} is not a plausible gravity in m/s²"),
            ));
        }
        let effects = self.effects(&model, seed)?;
        if truth_model == TruthModel::Rapier && effects.compliance.is_none() {
            return Err(scenario_err(
                f,
                "truth.model",
                "\"rapier\" settles the compliant joints in the physics engine: it needs an enabled \
                 [effects.compliance] (without one the truth is purely kinematic; use \"analytic\")"
                    .into(),
            ));
        }
        let (tracker, xyz, rpy) = self.tracker(seed, overrides.noise)?;
        let p_flange = [
            tracker.p_flange().x,
            tracker.p_flange().y,
            tracker.p_flange().z,
        ];
        let campaign = self.campaign(&model, overrides.poses, p_flange)?;
        Ok(Resolved {
            scenario: self.clone(),
            overrides: *overrides,
            seed,
            model,
            robot_source,
            gravity: Vector3::from(gravity),
            effects,
            tracker,
            tracker_xyz_m: xyz,
            tracker_rpy_rad: rpy,
            campaign,
            truth_model,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn locate_names_line_section_and_key() {
        let text = "seed = 1\n[robot]\nname = \"iiwa7\"\n\n[effects.compliance]\nstifness = 3\n";
        let pos = text.find("stifness").unwrap();
        assert_eq!(locate(text, pos), "line 6, [effects.compliance] stifness");
    }
}
