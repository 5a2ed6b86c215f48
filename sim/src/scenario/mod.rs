//! Scenarios: one TOML file (or a [`ScenarioBuilder`] in code) says which robot, which injected errors, which tracker and which
//! campaign. [`Scenario::parse`] reads it (refusing unknown keys and wrong types, naming the line and
//! key); [`Scenario::resolve`] draws every random magnitude from the seed and checks the result against
//! the robot, giving a [`Resolved`] scenario ready for [`crate::generate`].
//!
//! The modules, by job: [`schema`] (the file as written, one struct per table), [`magnitude`] (the
//! random draws; defined in [`crate::magnitude`], below the effects whose sections hold them), [`build`] (parsing, loading and resolving), [`builder`] (the same scenario from code,
//! validated as a file is). The `[effects.*]` sections are defined by their effects
//! ([`crate::effects::Effect::Section`]).
//!
//! # Layout
//!
//! ```toml
//! name = "iiwa7_all"          # optional
//! description = "..."         # optional
//! seed = 42                   # optional (default 0); `robocal generate --seed` overrides it
//!
//! [robot]
//! name = "iiwa7"              # a built-in robot, or:
//! # urdf = "robots/my.urdf"   # a URDF file, relative to this scenario file
//! # base_link = "..."; tip_link = "..."
//! # gravity_m_per_s2 = [0.0, 0.0, -9.81]
//!
//! [campaign]                  # see crate::campaign for the meaning
//! poses = 200                 # default: 100 random, 150 for iso9283, the whole list for grid/file
//! repeats = 1
//! sampling = "random"         # "random" | "iso9283" | "grid" | "file" (default: random, or the one
//!                             #  sub-table given)
//! seconds_per_pose = 10.0
//! seconds_per_repeat = 1.0
//! directions = "move"         # "move" | "random" | "unknown"
//! branches = "zero"           # "zero" | "random": the joints of branches off the chain (a second
//!                             #  arm, a head), written as q_<joint> columns when random
//! start_q = [0, 0, 0, 0, 0, 0, 0]
//! joint_margin_rad = 0.05     # random and grid
//! floor_z_m = 0.05            # reachability filter, base frame
//! min_axis_distance_m = 0.10
//! max_tries_per_pose = 10000
//! [campaign.iso9283]          # cube_side_m = 0.3, center_m = [x, y, z] (optional), seed_q = [...]
//! [campaign.grid]             # points_per_joint = [3, 3, 3, 3, 3, 3, 1] (or one number for all)
//! [campaign.file]             # path = "poses.csv"
//! [campaign.payload]          # mass_kg = 2.0, or choice_kg = [0.0, 1.5, 3.0]; com_m = [0, 0, 0.05]
//! [campaign.temperature]      # constant = 20.0 | warm_up = { t0_c, delta_c, tau_s } |
//!                             # schedule = [[t_s, temp_c], ...]
//!
//! [tracker]
//! xyz_m = [2.5, 1.0, -0.2]    # robot base origin in the tracker frame (m)
//! rpy_rad = [0.0, 0.0, 2.5]   # robot base orientation in the tracker frame (rad)
//! reflector_m = [0.0, 0.0, 0.05]   # target in the flange frame (m)
//! six_dof = false; probe_rpy_rad = [0, 0, 0]
//! radial_sigma_a_m = 5e-6; radial_sigma_b_m_per_m = 0.15e-6
//! transverse_sigma_a_m = 7.5e-6; transverse_sigma_b_m_per_m = 3e-6
//! orientation_sigma_rad = 8.7e-5
//! outlier_rate = 0.0; outlier_magnitude_m = 1e-3
//! noise_scale = 1.0           # `robocal generate --noise` overrides it
//!
//! [effects.kinematic]         # any subset; each: shape below
//! joint_rotation_rad = { normal = [0.0, 3e-4] }     # [n][3]: ω of each joint's error twist
//! joint_translation_m = { normal = [0.0, 2e-4] }    # [n][3]: v of each joint's error twist
//! zero_offset_rad = { normal = [0.0, 5e-4] }        # [n]
//! base_rotation_rad = ...; base_translation_m = ... # [3] each
//! tool_rotation_rad = ...; tool_translation_m = ... # [3] each
//! [effects.compliance]
//! stiffness_nm_per_rad = { uniform = [5e3, 2e4] }   # [n]; inf = rigid
//! [effects.backlash]
//! dead_band_rad = 2.9e-4      # [n]
//! mode = "direction"          # or "gravity" (then threshold_nm, [n])
//! [effects.thermal]
//! t_ref_c = 20.0
//! alpha_per_k = 23e-6         # [n + 1], links 0 … n
//! beta_rad_per_k = 0.0        # [n]
//! [effects.transmission]      # link angle q + Σ A sin(h q + φ) of the reported angle q
//! harmonics = [1, 2, 3]       # orders h (cycles per revolution; default 1, 2, 3; up to 1000)
//! amplitude_rad = { normal = [0.0, 5e-5] }          # [n][len(harmonics)]
//! phase_rad = { uniform = [-3.14159, 3.14159] }     # [n][len(harmonics)], default 0
//! [effects.coupling]          # link angle of `joint` gains ratio · q_source
//! pairs = [[6, 4]]            # [joint, source], numbered from 1 (joint = source: scale error)
//! ratio_rad_per_rad = 2e-4    # [len(pairs)]
//! [effects.coupled_transmission]  # link angle of `joint` gains A sin(h q_source + φ), source ≠ joint
//! pairs = [[6, 5]]            # [joint, source], numbered from 1
//! order = [1]                 # h per pair (cycles per revolution of the source), default 1
//! amplitude_rad = 5e-5        # [len(pairs)]
//! phase_rad = 0.0             # [len(pairs)], default 0
//! [effects.deflection]        # compliance across each joint axis, about u and v
//! compliance_rad_per_nm = [[0, 0], [2e-6, 2e-6], [0, 0], [3e-6, 3e-6], [0, 0], [0, 0], [0, 0]]  # [n][2]
//!
//! [truth]
//! model = "analytic"          # or "rapier": joint compliance settled by the rapier physics engine
//! ```
//!
//! Every effect table may carry `enabled = false` to switch it off without deleting it.
//!
//! # Magnitudes
//!
//! Every effect magnitude (and the tracker placement) is a [`Magnitude`]: a number (the same value
//! for every entry), a random draw `{ uniform = [low, high] }` or `{ normal = [mean, sd] }` (drawn
//! independently for every entry), or a list with one item per joint (each item again a magnitude,
//! so `[1e4, { uniform = [5e3, 2e4] }, ...]` and, for `[n][3]` shapes, `[[0, 0, 1e-4], ...]` work).
//! Draws come from a generator seeded by the scenario seed and the key's name (see
//! [`crate::campaign::derive_seed`]), drawn in list order, so the same seed always gives the same
//! robot and adding a key does not change the others' draws.

pub mod build;
pub mod builder;
pub mod schema;

pub use crate::effects::EffectsSection;
pub use crate::effects::coupled_transmission::CoupledTransmissionSection;
pub use crate::effects::gear_backlash::BacklashSection;
pub use crate::effects::joint_compliance::ComplianceSection;
pub use crate::effects::joint_coupling::CouplingSection;
pub use crate::effects::kinematic_offsets::KinematicSection;
pub use crate::effects::link_deflection::DeflectionSection;
pub use crate::effects::thermal_drift::ThermalSection;
pub use crate::effects::transmission_error::TransmissionSection;
/// The random draws, kept at their old path (they live in [`crate::magnitude`], below the effects).
pub use crate::magnitude;
pub use crate::magnitude::{Draw, Magnitude, fnv1a64};
pub use build::{Overrides, Resolved, RobotSource, Scenario};
pub use builder::ScenarioBuilder;
pub use schema::{
    CampaignSection, FileSection, GridSection, IsoSection, PayloadSection, PointsPerJoint,
    RobotSection, SamplingKind, ScenarioFile, TrackerSection, TruthModel, TruthSection,
};
