//! Scenarios from code: a [`ScenarioBuilder`] fills the same sections a scenario file has
//! ([`crate::scenario::schema`]) and [`ScenarioBuilder::build`] checks the result exactly as a file is
//! checked (it renders the sections as TOML, parses that text back and resolves it), so a scenario
//! built in code and the same scenario written as a file give the same robot, the same draws and the
//! same bytes.
//!
//! ```
//! use sim::effects::gear_backlash::BacklashMode;
//! use sim::scenario::{Magnitude, Overrides, ScenarioBuilder};
//!
//! let scenario = ScenarioBuilder::builtin("iiwa7")
//!     .name("backlash_demo")
//!     .seed(3)
//!     .poses(20)
//!     .backlash(Magnitude::Number(2.9e-4), BacklashMode::Direction)
//!     .build()
//!     .unwrap();
//! let res = scenario.resolve(&Overrides::default()).unwrap();
//! assert!(res.effects.backlash.is_some());
//! // The same checks as a file: a dead band in degrees is refused, naming the key.
//! let e = ScenarioBuilder::builtin("iiwa7")
//!     .backlash(Magnitude::Number(1.0), BacklashMode::Direction)
//!     .build()
//!     .unwrap_err()
//!     .to_string();
//! assert!(e.contains("effects.backlash.dead_band_rad[0]"), "{e}");
//! ```

use crate::campaign::{BranchRule, DirectionRule};
use crate::effects::Registered;
use crate::effects::coupled_transmission::CoupledTransmissionSection;
use crate::effects::gear_backlash::{BacklashMode, BacklashSection};
use crate::effects::joint_compliance::ComplianceSection;
use crate::effects::joint_coupling::CouplingSection;
use crate::effects::kinematic_offsets::KinematicSection;
use crate::effects::link_deflection::DeflectionSection;
use crate::effects::thermal_drift::{TemperatureProfile, ThermalSection};
use crate::effects::transmission_error::TransmissionSection;
use crate::error::{Result, scenario_err};
use crate::magnitude::Magnitude;
use crate::scenario::build::{Overrides, Resolved, Scenario};
use crate::scenario::schema::{
    CampaignSection, FileSection, GridSection, IsoSection, PayloadSection, RobotSection,
    SamplingKind, ScenarioFile, TrackerSection, TruthModel, TruthSection,
};
use std::path::{Path, PathBuf};

/// Builds a [`Scenario`] from code (see the module docs). Every setter takes and returns the builder;
/// nothing is checked until [`ScenarioBuilder::build`], which checks everything a scenario file is
/// checked for.
#[must_use = "a builder does nothing until `build` or `resolve` is called"]
#[derive(Clone, Debug, PartialEq)]
pub struct ScenarioBuilder {
    file: ScenarioFile,
    label: String,
    base_dir: PathBuf,
}

impl ScenarioBuilder {
    fn with_robot(robot: RobotSection) -> ScenarioBuilder {
        ScenarioBuilder {
            file: ScenarioFile {
                name: None,
                description: None,
                seed: None,
                robot,
                campaign: CampaignSection::default(),
                tracker: TrackerSection::default(),
                effects: Default::default(),
                truth: TruthSection::default(),
            },
            label: "built scenario".into(),
            base_dir: PathBuf::from("."),
        }
    }

    /// A scenario of built-in robot `name` (`iiwa7`, `ur5`, `ur10`, `wam`) with every default.
    pub fn builtin(name: &str) -> ScenarioBuilder {
        ScenarioBuilder::with_robot(RobotSection {
            name: Some(name.into()),
            ..RobotSection::default()
        })
    }

    /// A scenario of the robot in URDF file `path` (relative to [`ScenarioBuilder::base_dir`]).
    pub fn urdf(path: &str) -> ScenarioBuilder {
        ScenarioBuilder::with_robot(RobotSection {
            urdf: Some(path.into()),
            ..RobotSection::default()
        })
    }

    /// Starts from a parsed scenario (its sections, label and folder), e.g. a shipped file to which
    /// code adds effects.
    pub fn from_scenario(scenario: &Scenario) -> ScenarioBuilder {
        ScenarioBuilder {
            file: scenario.file.clone(),
            label: scenario.label.clone(),
            base_dir: scenario.base_dir.clone(),
        }
    }

    /// The sections as set so far.
    pub fn file(&self) -> &ScenarioFile {
        &self.file
    }

    /// The name errors give for this scenario (default `built scenario`).
    pub fn label(mut self, label: &str) -> ScenarioBuilder {
        self.label = label.into();
        self
    }

    /// The folder relative paths (URDF, pose file) refer to (default `.`).
    pub fn base_dir(mut self, dir: &Path) -> ScenarioBuilder {
        self.base_dir = dir.to_path_buf();
        self
    }

    /// `name`.
    pub fn name(mut self, name: &str) -> ScenarioBuilder {
        self.file.name = Some(name.into());
        self
    }

    /// `description`.
    pub fn description(mut self, text: &str) -> ScenarioBuilder {
        self.file.description = Some(text.into());
        self
    }

    /// `seed` of every random draw.
    pub fn seed(mut self, seed: u64) -> ScenarioBuilder {
        self.file.seed = Some(seed);
        self
    }

    /// `[robot] base_link` and `tip_link`: the chain to take from the URDF.
    pub fn chain(mut self, base_link: &str, tip_link: &str) -> ScenarioBuilder {
        self.file.robot.base_link = Some(base_link.into());
        self.file.robot.tip_link = Some(tip_link.into());
        self
    }

    /// `[robot] gravity_m_per_s2`: gravity in the base frame (m/s²).
    pub fn gravity_m_per_s2(mut self, g: [f64; 3]) -> ScenarioBuilder {
        self.file.robot.gravity_m_per_s2 = Some(g);
        self
    }

    /// Replaces the whole `[campaign]` section.
    pub fn campaign(mut self, c: CampaignSection) -> ScenarioBuilder {
        self.file.campaign = c;
        self
    }

    /// `[campaign] poses`.
    pub fn poses(mut self, n: usize) -> ScenarioBuilder {
        self.file.campaign.poses = Some(n);
        self
    }

    /// `[campaign] repeats`: measurements per pose.
    pub fn repeats(mut self, n: usize) -> ScenarioBuilder {
        self.file.campaign.repeats = Some(n);
        self
    }

    /// `[campaign] sampling`.
    pub fn sampling(mut self, kind: SamplingKind) -> ScenarioBuilder {
        self.file.campaign.sampling = Some(kind);
        self
    }

    /// `[campaign] seconds_per_pose` (s).
    pub fn seconds_per_pose(mut self, s: f64) -> ScenarioBuilder {
        self.file.campaign.seconds_per_pose = Some(s);
        self
    }

    /// `[campaign] seconds_per_repeat` (s).
    pub fn seconds_per_repeat(mut self, s: f64) -> ScenarioBuilder {
        self.file.campaign.seconds_per_repeat = Some(s);
        self
    }

    /// `[campaign] branches`.
    pub fn branches(mut self, rule: BranchRule) -> ScenarioBuilder {
        self.file.campaign.branches = Some(rule);
        self
    }

    /// `[campaign] directions`.
    pub fn directions(mut self, rule: DirectionRule) -> ScenarioBuilder {
        self.file.campaign.directions = Some(rule);
        self
    }

    /// `[campaign] start_q` (rad or m).
    pub fn start_q(mut self, q: Vec<f64>) -> ScenarioBuilder {
        self.file.campaign.start_q = Some(q);
        self
    }

    /// `[campaign] joint_margin_rad` (rad or m).
    pub fn joint_margin_rad(mut self, margin: f64) -> ScenarioBuilder {
        self.file.campaign.joint_margin_rad = Some(margin);
        self
    }

    /// `[campaign] floor_z_m` (base frame, m).
    pub fn floor_z_m(mut self, z: f64) -> ScenarioBuilder {
        self.file.campaign.floor_z_m = Some(z);
        self
    }

    /// `[campaign] min_axis_distance_m` (m).
    pub fn min_axis_distance_m(mut self, d: f64) -> ScenarioBuilder {
        self.file.campaign.min_axis_distance_m = Some(d);
        self
    }

    /// `[campaign] max_tries_per_pose`.
    pub fn max_tries_per_pose(mut self, n: usize) -> ScenarioBuilder {
        self.file.campaign.max_tries_per_pose = Some(n);
        self
    }

    /// `[campaign.iso9283]`.
    pub fn iso9283(mut self, iso: IsoSection) -> ScenarioBuilder {
        self.file.campaign.iso9283 = Some(iso);
        self
    }

    /// `[campaign.grid]`.
    pub fn grid(mut self, grid: GridSection) -> ScenarioBuilder {
        self.file.campaign.grid = Some(grid);
        self
    }

    /// `[campaign.file] path`: poses from a measurement table (relative to the base folder).
    pub fn pose_file(mut self, path: &str) -> ScenarioBuilder {
        self.file.campaign.file = Some(FileSection { path: path.into() });
        self
    }

    /// `[campaign.payload]`.
    pub fn payload(mut self, payload: PayloadSection) -> ScenarioBuilder {
        self.file.campaign.payload = Some(payload);
        self
    }

    /// `[campaign.temperature]`: the robot temperature over time (°C).
    pub fn temperature(mut self, profile: TemperatureProfile) -> ScenarioBuilder {
        self.file.campaign.temperature = Some(profile);
        self
    }

    /// Replaces the whole `[tracker]` section.
    pub fn tracker(mut self, t: TrackerSection) -> ScenarioBuilder {
        self.file.tracker = t;
        self
    }

    /// `[tracker] xyz_m` and `rpy_rad`: the robot base in the tracker frame (m, rad).
    pub fn tracker_placement(mut self, xyz_m: Magnitude, rpy_rad: Magnitude) -> ScenarioBuilder {
        self.file.tracker.xyz_m = Some(xyz_m);
        self.file.tracker.rpy_rad = Some(rpy_rad);
        self
    }

    /// `[tracker] reflector_m`: the target in the flange frame (m).
    pub fn reflector_m(mut self, p: [f64; 3]) -> ScenarioBuilder {
        self.file.tracker.reflector_m = Some(p);
        self
    }

    /// `[tracker] radial_sigma_a_m`, `radial_sigma_b_m_per_m`: radial σ = a + b d (m, m/m).
    pub fn radial_sigma(mut self, a_m: f64, b_m_per_m: f64) -> ScenarioBuilder {
        self.file.tracker.radial_sigma_a_m = Some(a_m);
        self.file.tracker.radial_sigma_b_m_per_m = Some(b_m_per_m);
        self
    }

    /// `[tracker] transverse_sigma_a_m`, `transverse_sigma_b_m_per_m`: transverse σ = a + b d (m, m/m).
    pub fn transverse_sigma(mut self, a_m: f64, b_m_per_m: f64) -> ScenarioBuilder {
        self.file.tracker.transverse_sigma_a_m = Some(a_m);
        self.file.tracker.transverse_sigma_b_m_per_m = Some(b_m_per_m);
        self
    }

    /// `[tracker] outlier_rate` (fraction of rows).
    pub fn outlier_rate(mut self, rate: f64) -> ScenarioBuilder {
        self.file.tracker.outlier_rate = Some(rate);
        self
    }

    /// `[tracker] noise_scale`: multiplier on every tracker error.
    pub fn noise_scale(mut self, scale: f64) -> ScenarioBuilder {
        self.file.tracker.noise_scale = Some(scale);
        self
    }

    /// `[tracker] six_dof = true` with `probe_rpy_rad` (rad, flange frame).
    pub fn six_dof(mut self, probe_rpy_rad: [f64; 3]) -> ScenarioBuilder {
        self.file.tracker.six_dof = Some(true);
        self.file.tracker.probe_rpy_rad = Some(probe_rpy_rad);
        self
    }

    /// `[effects.<KEY>]` of any registered effect `E`, as written.
    pub fn effect<E: Registered>(mut self, section: E::Section) -> ScenarioBuilder {
        *E::section_slot(&mut self.file.effects) = Some(section);
        self
    }

    /// `[effects.kinematic]`.
    pub fn kinematic(self, section: KinematicSection) -> ScenarioBuilder {
        self.effect::<crate::effects::kinematic_offsets::KinematicOffsets>(section)
    }

    /// `[effects.compliance] stiffness_nm_per_rad` (N m/rad, shape `[n]`; `inf` = rigid).
    pub fn compliance(self, stiffness_nm_per_rad: Magnitude) -> ScenarioBuilder {
        self.effect::<crate::effects::joint_compliance::JointCompliance>(ComplianceSection {
            enabled: None,
            stiffness_nm_per_rad,
        })
    }

    /// `[effects.backlash]` with `dead_band_rad` (rad, shape `[n]`) and `mode`; for gravity mode add
    /// the threshold with [`ScenarioBuilder::effect`] and a full [`BacklashSection`].
    pub fn backlash(self, dead_band_rad: Magnitude, mode: BacklashMode) -> ScenarioBuilder {
        self.effect::<crate::effects::gear_backlash::GearBacklash>(BacklashSection {
            enabled: None,
            dead_band_rad,
            mode: Some(mode),
            threshold_nm: None,
        })
    }

    /// `[effects.thermal]`: reference temperature (°C), link expansion `alpha_per_k` (1/K, shape
    /// `[n + 1]`) and joint-zero drift `beta_rad_per_k` (rad/K, shape `[n]`).
    pub fn thermal(
        self,
        t_ref_c: f64,
        alpha_per_k: Magnitude,
        beta_rad_per_k: Option<Magnitude>,
    ) -> ScenarioBuilder {
        self.effect::<crate::effects::thermal_drift::ThermalDrift>(ThermalSection {
            enabled: None,
            t_ref_c: Some(t_ref_c),
            alpha_per_k,
            beta_rad_per_k,
        })
    }

    /// `[effects.transmission]` with harmonic orders 1, 2, 3: `amplitude_rad` and `phase_rad` (rad,
    /// shape `[n][3]`, row `i` for joint `i + 1`). For other orders use [`ScenarioBuilder::effect`]
    /// with a full [`TransmissionSection`].
    pub fn transmission_error(
        self,
        amplitude_rad: Magnitude,
        phase_rad: Magnitude,
    ) -> ScenarioBuilder {
        self.effect::<crate::effects::transmission_error::TransmissionError>(TransmissionSection {
            enabled: None,
            harmonics: None,
            amplitude_rad,
            phase_rad: Some(phase_rad),
        })
    }

    /// `[effects.coupling]`: each `[joint, source]` pair (joints numbered from 1) gives joint `joint`
    /// a link angle error `ratio · q_source`; `ratio_rad_per_rad` (rad/rad) has shape
    /// `[pairs.len()]`.
    pub fn joint_coupling(
        self,
        pairs: Vec<[usize; 2]>,
        ratio_rad_per_rad: Magnitude,
    ) -> ScenarioBuilder {
        self.effect::<crate::effects::joint_coupling::JointCoupling>(CouplingSection {
            enabled: None,
            pairs,
            ratio_rad_per_rad,
        })
    }

    /// `[effects.coupled_transmission]` with one cycle per revolution of each source joint: each
    /// `[joint, source]` pair (numbered from 1, `source ≠ joint`) gives joint `joint` a link angle error
    /// `A sin(q_source + φ)`; `amplitude_rad` and `phase_rad` (rad) have shape `[pairs.len()]`. Other
    /// orders: [`ScenarioBuilder::effect`] with a full [`CoupledTransmissionSection`].
    pub fn coupled_transmission(
        self,
        pairs: Vec<[usize; 2]>,
        amplitude_rad: Magnitude,
        phase_rad: Magnitude,
    ) -> ScenarioBuilder {
        self.effect::<crate::effects::coupled_transmission::CoupledTransmission>(
            CoupledTransmissionSection {
                enabled: None,
                pairs,
                order: None,
                amplitude_rad,
                phase_rad: Some(phase_rad),
            },
        )
    }

    /// `[effects.deflection] compliance_rad_per_nm` (rad/(N m), shape `[n][2]`: about the `u` and `v`
    /// axes of each joint; 0 = rigid).
    pub fn link_deflection(self, compliance_rad_per_nm: Magnitude) -> ScenarioBuilder {
        self.effect::<crate::effects::link_deflection::LinkDeflection>(DeflectionSection {
            enabled: None,
            compliance_rad_per_nm,
        })
    }

    /// `[truth] model`.
    pub fn truth_model(mut self, model: TruthModel) -> ScenarioBuilder {
        self.file.truth.model = Some(model);
        self
    }

    /// The scenario, checked as a scenario file is: its sections are rendered as TOML (the
    /// [`Scenario::text`], so `truth.json` holds a file that gives the same data), parsed back (which
    /// must give the same sections) and resolved with no overrides. Errors name the label and the key.
    pub fn build(self) -> Result<Scenario> {
        let text = toml::to_string(&self.file).map_err(|e| {
            scenario_err(
                &self.label,
                "toml",
                format!("cannot be written as TOML: {e}"),
            )
        })?;
        let scenario = Scenario::parse(&text, &self.label, &self.base_dir)?;
        if scenario.file != self.file {
            return Err(scenario_err(
                &self.label,
                "toml",
                "the scenario does not survive a TOML round trip (a value TOML cannot hold?)"
                    .into(),
            ));
        }
        scenario.resolve(&Overrides::default())?;
        Ok(scenario)
    }

    /// [`ScenarioBuilder::build`], then [`Scenario::resolve`] with `overrides`.
    pub fn resolve(self, overrides: &Overrides) -> Result<Resolved> {
        self.build()?.resolve(overrides)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::effects::thermal_drift::WarmUp;
    use crate::magnitude::Draw;

    /// A scenario built in code resolves exactly as the same scenario written by hand.
    #[test]
    fn built_and_written_scenarios_resolve_alike() {
        let text = "seed = 5\n[robot]\nname = \"iiwa7\"\n[campaign]\nposes = 30\n\
                    [campaign.temperature]\nwarm_up = { t0_c = 20.0, delta_c = 8.5, tau_s = 1800.0 }\n\
                    [effects.kinematic]\nzero_offset_rad = { normal = [0.0, 5e-4] }\n\
                    [effects.compliance]\nstiffness_nm_per_rad = [inf, 1.2e4, inf, 8e3, inf, inf, inf]\n\
                    [effects.thermal]\nt_ref_c = 20.0\nalpha_per_k = 23e-6\n";
        let written = Scenario::parse(text, "t.toml", Path::new("."))
            .unwrap()
            .resolve(&Overrides::default())
            .unwrap();
        let k = [
            f64::INFINITY,
            1.2e4,
            f64::INFINITY,
            8e3,
            f64::INFINITY,
            f64::INFINITY,
            f64::INFINITY,
        ];
        let built = ScenarioBuilder::builtin("iiwa7")
            .seed(5)
            .poses(30)
            .temperature(TemperatureProfile::WarmUp(
                WarmUp::new(20.0, 8.5, 1800.0).unwrap(),
            ))
            .kinematic(KinematicSection {
                zero_offset_rad: Some(Magnitude::Draw(Draw::Normal([0.0, 5e-4]))),
                ..KinematicSection::default()
            })
            .compliance(Magnitude::List(
                k.iter().map(|v| Magnitude::Number(*v)).collect(),
            ))
            .thermal(20.0, Magnitude::Number(23e-6), None)
            .label("t.toml")
            .resolve(&Overrides::default())
            .unwrap();
        assert_eq!(built.scenario.file, written.scenario.file);
        assert_eq!(built.effects, written.effects);
        assert_eq!(built.tracker, written.tracker);
        assert_eq!(built.campaign, written.campaign);
        assert_eq!(built.seed, written.seed);
    }

    /// The three effects of issue 12 from code resolve exactly as the same sections written by hand.
    #[test]
    fn transmission_coupling_and_deflection_from_code_equal_the_written_file() {
        let text = "seed = 9\n[robot]\nname = \"iiwa7\"\n[campaign]\nposes = 10\n\
                    [effects.transmission]\namplitude_rad = { normal = [0.0, 5e-5] }\n\
                    phase_rad = { uniform = [-3.0, 3.0] }\n\
                    [effects.coupling]\npairs = [[6, 4], [2, 2]]\nratio_rad_per_rad = [2e-4, -1e-4]\n\
                    [effects.deflection]\ncompliance_rad_per_nm = [[0, 0], [3e-6, 3e-6], [0, 0], \
                    [4e-6, { uniform = [3e-6, 5e-6] }], [0, 0], [0, 0], [0, 0]]\n\
                    [effects.coupled_transmission]\npairs = [[6, 5]]\n\
                    amplitude_rad = { normal = [0.0, 5e-5] }\nphase_rad = 0.3\n";
        let written = Scenario::parse(text, "t.toml", Path::new("."))
            .unwrap()
            .resolve(&Overrides::default())
            .unwrap();
        let zero = || Magnitude::List(vec![Magnitude::Number(0.0); 2]);
        let built = ScenarioBuilder::builtin("iiwa7")
            .seed(9)
            .poses(10)
            .transmission_error(
                Magnitude::Draw(Draw::Normal([0.0, 5e-5])),
                Magnitude::Draw(Draw::Uniform([-3.0, 3.0])),
            )
            .joint_coupling(
                vec![[6, 4], [2, 2]],
                Magnitude::List(vec![Magnitude::Number(2e-4), Magnitude::Number(-1e-4)]),
            )
            .link_deflection(Magnitude::List(vec![
                zero(),
                Magnitude::Number(3e-6),
                zero(),
                Magnitude::List(vec![
                    Magnitude::Number(4e-6),
                    Magnitude::Draw(Draw::Uniform([3e-6, 5e-6])),
                ]),
                zero(),
                zero(),
                zero(),
            ]))
            .coupled_transmission(
                vec![[6, 5]],
                Magnitude::Draw(Draw::Normal([0.0, 5e-5])),
                Magnitude::Number(0.3),
            )
            .label("t.toml")
            .resolve(&Overrides::default())
            .unwrap();
        assert_eq!(built.effects, written.effects);
        let t = built.effects.transmission.as_ref().unwrap();
        assert_eq!(t.harmonics(), &[1, 2, 3]);
        assert!(
            t.amplitude_rad()
                .iter()
                .flatten()
                .all(|a| *a != 0.0 && a.abs() < 5e-4)
        );
        let c = built.effects.coupling.as_ref().unwrap().terms();
        assert_eq!(
            (c[0].joint, c[0].source, c[0].ratio_rad_per_rad),
            (6, 4, 2e-4)
        );
        let d = built
            .effects
            .deflection
            .as_ref()
            .unwrap()
            .compliance_rad_per_nm();
        assert_eq!(d[1], [3e-6, 3e-6]);
        assert!(d[3][1] >= 3e-6 && d[3][1] <= 5e-6);
        let ct = built.effects.coupled_transmission.as_ref().unwrap().terms();
        assert_eq!(
            (ct[0].joint, ct[0].source, ct[0].order, ct[0].phase_rad),
            (6, 5, 1, 0.3)
        );
        // Refusals name the scenario key.
        let e = ScenarioBuilder::builtin("iiwa7")
            .coupled_transmission(
                vec![[4, 4]],
                Magnitude::Number(1e-5),
                Magnitude::Number(0.0),
            )
            .build()
            .unwrap_err()
            .to_string();
        assert!(e.contains("effects.coupled_transmission.pairs[0]"), "{e}");
        let e = ScenarioBuilder::builtin("iiwa7")
            .joint_coupling(vec![[8, 1]], Magnitude::Number(1e-4))
            .build()
            .unwrap_err()
            .to_string();
        assert!(e.contains("effects.coupling") && e.contains("8"), "{e}");
        let e = ScenarioBuilder::builtin("iiwa7")
            .joint_coupling(vec![[2, 1]], Magnitude::Number(0.2))
            .build()
            .unwrap_err()
            .to_string();
        assert!(e.contains("effects.coupling.ratio_rad_per_rad[0]"), "{e}");
        let e = ScenarioBuilder::builtin("iiwa7")
            .link_deflection(Magnitude::Number(2.5e5))
            .build()
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("effects.deflection.compliance_rad_per_nm[0][0]"),
            "{e}"
        );
        let e = ScenarioBuilder::builtin("iiwa7")
            .transmission_error(Magnitude::Number(1.0), Magnitude::Number(0.0))
            .build()
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("effects.transmission.amplitude_rad[0][0]"),
            "{e}"
        );
        let e = ScenarioBuilder::builtin("iiwa7")
            .effect::<crate::effects::transmission_error::TransmissionError>(TransmissionSection {
                enabled: None,
                harmonics: Some(vec![1, 1]),
                amplitude_rad: Magnitude::Number(1e-5),
                phase_rad: None,
            })
            .build()
            .unwrap_err()
            .to_string();
        assert!(e.contains("effects.transmission.harmonics[1]"), "{e}");
        // The rapier truth settles deflection with the joint springs; without them it is refused.
        let s = ScenarioBuilder::builtin("iiwa7")
            .compliance(Magnitude::Number(1e4))
            .link_deflection(Magnitude::Number(2e-6))
            .truth_model(TruthModel::Rapier)
            .build()
            .unwrap();
        let res = s.resolve(&Overrides::default()).unwrap();
        assert!(crate::generate::truth_of(&res).is_ok());
        let e = ScenarioBuilder::builtin("iiwa7")
            .link_deflection(Magnitude::Number(2e-6))
            .truth_model(TruthModel::Rapier)
            .build()
            .unwrap_err()
            .to_string();
        assert!(e.contains("truth.model") && !e.contains('\n'), "{e}");
    }

    #[test]
    fn build_refuses_what_a_file_would() {
        let e = ScenarioBuilder::builtin("iiwa8")
            .build()
            .unwrap_err()
            .to_string();
        assert!(e.contains("robot.name") && e.contains("iiwa8"), "{e}");
        let e = ScenarioBuilder::builtin("iiwa7")
            .compliance(Magnitude::List(vec![Magnitude::Number(1e4); 3]))
            .build()
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("effects.compliance.stiffness_nm_per_rad") && e.contains("3 entries"),
            "{e}"
        );
        let e = ScenarioBuilder::builtin("iiwa7")
            .floor_z_m(50.0)
            .build()
            .unwrap_err()
            .to_string();
        assert!(e.contains("campaign.floor_z_m"), "{e}");
    }
}
