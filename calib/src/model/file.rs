//! The calibrated model file (`MODEL.json`): everything `predict` needs, with the robot embedded; the
//! predictor that evaluates it. The calibrated URDF is written by [`crate::model::urdf_export`].
//!
//! # MODEL.json
//! ```json
//! {
//!   "format": "robocal-calibrated-model", "format_version": 2, "software": "robocal-calib 0.1.0",
//!   "model": "kinematic",
//!   "robot": {"name": "iiwa7", "source": "built-in robot 'iiwa7'", "base_link": "…", "tip_link": "…",
//!             "urdf": "<?xml …"},
//!   "parameters": {
//!     "joint_error_twists": [[ωx, ωy, ωz, vx, vy, vz], …],   // ξᵢ, base frame (rad, m)
//!     "zero_offsets": [δq₁, …],                              // rad (m for prismatic joints)
//!     "t_tracker_base": {"translation_m": [x, y, z], "rotation": [[…], […], […]]},
//!     "p_flange_target_m": [x, y, z],
//!     "r_flange_target": [[…], […], […]] or null,
//!     "campaign": 0,                                          // id of the campaign registered above
//!     "campaigns": [{"id": 1, "t_tracker_base": {…},          // further campaigns (absent: none)
//!                    "p_flange_target_m": [x, y, z] or null, "r_flange_target": … or null}],
//!     "default_campaign": 0                                   // campaign of rows without a `campaign`
//!   },
//!   "covariance": {"parameters": ["joint 1 twist ω_x", …], "matrix": [[…], …], "variance_factor": 1.02},
//!   "fit": {"train_rms_m": 1.1e-5, "held_out_rms_m": 1.2e-5, "n_train_poses": 200,
//!           "new_region_rms_m": 1.4e-5,          // held-out regions (absent: not validated by region)
//!           "calibration_sigma_m": 3.1e-6}        // 95th percentile of sigma_m on the calibration rows
//! }
//! ```
//! Format version 1 (before campaigns) is still read: one campaign, id 0.
//! The real screw of joint `i` is `Ad(exp[ξᵢ]) Sᵢ` with `Sᵢ` the embedded URDF's screw; the covariance is
//! that of a step at the solution in [`crate::model::params::ParamLayout`] order (physical units). Floats are written by
//! `serde_json` as the shortest decimal that reads back to the same `f64`.

use crate::error::{CalibError, Result};
use crate::model::extensions::{Cause, ExtensionSettings};
use crate::model::learned::LearnedResidual;
use crate::model::params::{KinematicParams, ParamKind, ParamLayout};
use crate::model::spec::ModelSpec;
use crate::units::Unit;
use nalgebra::{Matrix3, Vector3, Vector6};
use sim::lie::{Pose, pose_from};
use sim::{ChainSpec, Model};

/// The `format` value of a calibrated model file.
pub const FORMAT: &str = "robocal-calibrated-model";
/// The current `format_version` (2: campaigns and the fit summary).
pub const FORMAT_VERSION: u32 = 2;
/// Format versions this version reads.
pub const READABLE_VERSIONS: [u32; 2] = [1, 2];

/// The robot, embedded.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EmbeddedRobot {
    /// Robot name from the URDF.
    pub name: String,
    /// Where the URDF came from when the model was calibrated.
    pub source: String,
    /// Root link of the chain.
    pub base_link: String,
    /// Tip link of the chain (the flange).
    pub tip_link: String,
    /// The URDF text.
    pub urdf: String,
    /// FNV-1a 64-bit hash of `urdf` (16 hex digits), written with the file and checked on load: a
    /// model whose URDF text was replaced or edited is refused. Absent in older files (not checked).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub urdf_fnv1a64: Option<String>,
    /// Couplings declared beside the URDF when the model was calibrated (`--couplings FILE`,
    /// [`sim::coupled_joints`]); absent when there were none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub couplings: Vec<sim::coupled_joints::CouplingDecl>,
}

/// FNV-1a 64-bit hash of `text`, as 16 hex digits ([`EmbeddedRobot::urdf_fnv1a64`]).
pub fn urdf_checksum(text: &str) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in text.bytes() {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    format!("{h:016x}")
}

/// Largest magnitude a joint error twist component may have on load (rad, or m): no calibrated joint
/// is off by a radian or a metre.
pub const MAX_JOINT_ERROR: f64 = 1.0;
/// Largest zero offset on load (rad, or m for prismatic joints).
pub const MAX_ZERO_OFFSET: f64 = std::f64::consts::TAU;
/// Largest tracker-to-base distance on load (m), as for measured positions.
pub const MAX_TRACKER_DISTANCE_M: f64 = 1000.0;
/// Largest target offset from the flange on load (m).
pub const MAX_TARGET_OFFSET_M: f64 = 10.0;
/// Largest magnitude of an extension value on load (in its own unit: rad/(N m), rad, 1/K, …): far
/// beyond any physical value, it catches garbage such as 1e308.
pub const MAX_EXTENSION_VALUE: f64 = 1e6;

/// A pose as translation (m) and rotation matrix rows.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoseJson {
    /// Translation (m).
    pub translation_m: [f64; 3],
    /// Rotation matrix, row by row.
    pub rotation: [[f64; 3]; 3],
}

fn rows(m: &Matrix3<f64>) -> [[f64; 3]; 3] {
    [0, 1, 2].map(|i| [m[(i, 0)], m[(i, 1)], m[(i, 2)]])
}

fn matrix(r: &[[f64; 3]; 3]) -> Matrix3<f64> {
    Matrix3::from_fn(|i, j| r[i][j])
}

/// The kinematic parameters in file form.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelParameters {
    /// Error twist `ξᵢ = [ω; v]` per joint (base frame; rad, m).
    pub joint_error_twists: Vec<[f64; 6]>,
    /// Zero offset per joint (rad; m for prismatic joints).
    pub zero_offsets: Vec<f64>,
    /// `T_tracker_base`.
    pub t_tracker_base: PoseJson,
    /// Target position in the flange frame (m).
    pub p_flange_target_m: [f64; 3],
    /// Target orientation in the flange frame (rotation matrix rows), or `null` for position-only models.
    pub r_flange_target: Option<[[f64; 3]; 3]>,
    /// Id of the measurement campaign registered by `t_tracker_base` (0 for data without a
    /// `campaign` column; absent in version 1 files).
    #[serde(default)]
    pub campaign: i64,
    /// The registrations of further campaigns.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub campaigns: Vec<CampaignJson>,
    /// The campaign of rows that name none (a table without a `campaign` column); absent: `campaign`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub default_campaign: Option<i64>,
}

/// The tracker registration of a campaign after the first.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CampaignJson {
    /// Campaign id (the `campaign` column's value).
    pub id: i64,
    /// Its `T_tracker_base`.
    pub t_tracker_base: PoseJson,
    /// Its own target position in the flange frame (m), or `null` when it shares the first's.
    pub p_flange_target_m: Option<[f64; 3]>,
    /// Its own target orientation (rotation matrix rows), or `null`.
    pub r_flange_target: Option<[[f64; 3]; 3]>,
}

/// How well the model fits: what `robocal register` compares a new campaign's residual with.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FitSummary {
    /// RMS position error on the calibration rows (m).
    pub train_rms_m: f64,
    /// RMS position error on held-out poses (cross-validated or a test set; m), when validated.
    pub held_out_rms_m: Option<f64>,
    /// Distinct poses of the calibration.
    pub n_train_poses: usize,
    /// RMS position error on held-out regions of the configuration space (m), when validated by
    /// region: the promise for poses unlike the calibration's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub new_region_rms_m: Option<f64>,
    /// The 95th percentile of the predicted standard deviation `sigma_m` over the calibration's rows
    /// (m): the uncertainty of the predictions its validation tested. `predict` marks a row whose
    /// `sigma_m` exceeds [`crate::model::predict::SIGMA_BEYOND_CALIBRATION`] times it (and
    /// [`crate::model::predict::SIGMA_MATTERS`] times `held_out_rms_m`) `outside_support`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub calibration_sigma_m: Option<f64>,
}

/// Covariance of the parameters.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CovarianceJson {
    /// Parameter names in [`crate::model::params::ParamLayout`] order.
    pub parameters: Vec<String>,
    /// The covariance matrix, row by row (physical units).
    pub matrix: Vec<Vec<f64>>,
    /// The variance factor `σ̂²` it includes.
    pub variance_factor: f64,
}

/// Checks what any covariance matrix is: one row and column per named parameter, finite entries,
/// variances ≥ 0, symmetric and within the Cauchy–Schwarz bound `|Cᵢⱼ| ≤ √(Cᵢᵢ Cⱼⱼ)` (both to a
/// relative 1e-6, far above the rounding of the matrix as written); a finite variance factor ≥ 0.
/// (The fuzzing suite found covariances of 1e308 or negative variances loaded without a word.)
fn check_covariance(c: &CovarianceJson) -> std::result::Result<(), String> {
    let n = c.parameters.len();
    let at = |i: usize, j: usize| format!("key 'covariance.matrix'[{i}][{j}]");
    if c.matrix.len() != n || c.matrix.iter().any(|r| r.len() != n) {
        return Err(format!(
            "key 'covariance.matrix' is not {n} × {n} (one row and column per name in 'covariance.parameters')"
        ));
    }
    if !(c.variance_factor.is_finite() && c.variance_factor >= 0.0) {
        return Err(format!(
            "key 'covariance.variance_factor' is {:e}: a variance factor is finite and ≥ 0",
            c.variance_factor
        ));
    }
    for (i, row) in c.matrix.iter().enumerate() {
        for (j, v) in row.iter().enumerate() {
            if !v.is_finite() {
                return Err(format!("{} is {v}: not finite", at(i, j)));
            }
        }
        if row[i] < 0.0 {
            return Err(format!("{} is {:e}: a variance is ≥ 0", at(i, i), row[i]));
        }
    }
    for i in 0..n {
        for j in 0..i {
            let (a, b) = (c.matrix[i][j], c.matrix[j][i]);
            let scale = (c.matrix[i][i] * c.matrix[j][j]).sqrt();
            if (a - b).abs() > 1e-6 * scale.max(a.abs()) {
                return Err(format!(
                    "{} is {a:e} but {} is {b:e}: a covariance matrix is symmetric",
                    at(i, j),
                    at(j, i)
                ));
            }
            if a.abs() > scale * (1.0 + 1e-6) {
                return Err(format!(
                    "{} is {a:e}, beyond √(C{i}{i} C{j}{j}) = {scale:e}: not a covariance",
                    at(i, j)
                ));
            }
        }
    }
    Ok(())
}

/// A calibrated model file.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CalibratedModel {
    /// Always [`FORMAT`].
    pub format: String,
    /// [`FORMAT_VERSION`].
    pub format_version: u32,
    /// Software that wrote it.
    pub software: String,
    /// Model name: `kinematic`, or a `+`-joined extension such as `kinematic+joint_compliance`.
    pub model: ModelSpec,
    /// The robot.
    pub robot: EmbeddedRobot,
    /// The identified parameters.
    pub parameters: ModelParameters,
    /// Their covariance, when known.
    pub covariance: Option<CovarianceJson>,
    /// The model extensions: settings and identified values.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub extensions: Option<ExtensionsJson>,
    /// The learned residual correction.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub learned: Option<LearnedResidual>,
    /// How well it fits (absent in version 1 files).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fit: Option<FitSummary>,
}

/// The model extensions of a calibrated model.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExtensionsJson {
    /// What the regressors are made from.
    pub settings: ExtensionSettings,
    /// Parameter names, in order (for people; checked against the settings on load).
    pub names: Vec<String>,
    /// Parameter units, in order.
    pub units: Vec<Unit>,
    /// Identified values, in order (units as `units`).
    pub values: Vec<f64>,
}

impl CalibratedModel {
    /// JSON text (pretty-printed).
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("a calibrated model serialises")
    }

    /// Reads and checks a model file; errors name the file and the key.
    pub fn load(path: &std::path::Path) -> Result<Self> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| CalibError::Read {
            path: file.clone(),
            message: e.to_string(),
        })?;
        Self::from_json(&text, &file)
    }

    /// Parses and checks model-file text; `file` names it in errors.
    pub fn from_json(text: &str, file: &str) -> Result<Self> {
        let bad = |message: String| CalibError::ModelFile {
            file: file.to_string(),
            message,
        };
        let v: serde_json::Value =
            serde_json::from_str(text).map_err(|e| bad(format!("not JSON: {e}")))?;
        match v.get("format").and_then(|f| f.as_str()) {
            Some(FORMAT) => {}
            other => {
                return Err(bad(format!(
                    "key 'format' is {other:?}, not \"{FORMAT}\": not a robocal calibrated model"
                )));
            }
        }
        if let Some(text) = v.get("model").and_then(|m| m.as_str()) {
            ModelSpec::parse(text).map_err(|e| bad(format!("key 'model': {e}")))?;
        }
        let m: CalibratedModel = serde_json::from_value(v).map_err(|e| bad(format!("{e}")))?;
        if !READABLE_VERSIONS.contains(&m.format_version) {
            return Err(bad(format!(
                "key 'format_version' is {}, this version reads {} (a newer robocal wrote it?)",
                m.format_version,
                READABLE_VERSIONS
                    .iter()
                    .map(|v| v.to_string())
                    .collect::<Vec<_>>()
                    .join(" and ")
            )));
        }
        let p = &m.parameters;
        let finite = |key: &str, vals: &[f64]| -> Result<()> {
            match vals.iter().position(|v| !v.is_finite()) {
                Some(i) => Err(bad(format!("key '{key}'[{i}] is not finite"))),
                None => Ok(()),
            }
        };
        let spec = &m.model;
        let stored: Vec<Cause> = m
            .extensions
            .as_ref()
            .map_or(Vec::new(), |e| e.settings.causes.clone());
        if spec.causes != stored {
            return Err(bad(format!(
                "key 'model' is '{}' but key 'extensions' holds [{}]",
                m.model,
                stored
                    .iter()
                    .map(|c| c.name())
                    .collect::<Vec<_>>()
                    .join(", ")
            )));
        }
        let stored_joints = m
            .extensions
            .as_ref()
            .map(|e| e.settings.joints.clone())
            .unwrap_or_default();
        if spec.joints != stored_joints {
            let stored = ModelSpec {
                causes: spec.causes.clone(),
                joints: stored_joints,
                learned: spec.learned,
            };
            return Err(bad(format!(
                "key 'model' is '{}' but key 'extensions.settings.joints' makes it '{}'",
                m.model, stored
            )));
        }
        spec.check_joints(p.joint_error_twists.len())
            .map_err(|e| bad(format!("key 'model': {e}")))?;
        if spec.learned.is_some() != m.learned.is_some() {
            return Err(bad(format!(
                "key 'model' is '{}' but key 'learned' is {}",
                m.model,
                if m.learned.is_some() {
                    "present"
                } else {
                    "absent"
                }
            )));
        }
        if let Some(support) = m.learned.as_ref().and_then(|l| l.support()) {
            support.check().map_err(&bad)?;
            if support.n_joints != m.learned.as_ref().map_or(0, |l| l.n_joints()) {
                return Err(bad(format!(
                    "key 'learned.support.n_joints' is {}, but the correction takes {} joints",
                    support.n_joints,
                    m.learned.as_ref().map_or(0, |l| l.n_joints())
                )));
            }
        }
        if let Some(e) = &m.extensions {
            finite("extensions.values", &e.values)?;
            if e.values.len() != e.names.len() || e.units.len() != e.names.len() {
                return Err(bad(format!(
                    "key 'extensions': {} names, {} units and {} values",
                    e.names.len(),
                    e.units.len(),
                    e.values.len()
                )));
            }
        }
        for (i, t) in p.joint_error_twists.iter().enumerate() {
            finite(&format!("parameters.joint_error_twists[{i}]"), t)?;
        }
        finite("parameters.zero_offsets", &p.zero_offsets)?;
        finite(
            "parameters.t_tracker_base.translation_m",
            &p.t_tracker_base.translation_m,
        )?;
        finite(
            "parameters.t_tracker_base.rotation",
            p.t_tracker_base.rotation.as_flattened(),
        )?;
        finite("parameters.p_flange_target_m", &p.p_flange_target_m)?;
        let orthonormal = |key: &str, r: &[[f64; 3]; 3]| -> Result<()> {
            let m = matrix(r);
            let e = (m.transpose() * m - Matrix3::identity()).amax();
            if e > 1e-9 || m.determinant() < 0.0 {
                return Err(bad(format!(
                    "key '{key}' is not a rotation matrix (|RᵀR − I| = {e:.1e})"
                )));
            }
            Ok(())
        };
        orthonormal(
            "parameters.t_tracker_base.rotation",
            &p.t_tracker_base.rotation,
        )?;
        if let Some(r) = &p.r_flange_target {
            finite("parameters.r_flange_target", r.as_flattened())?;
            orthonormal("parameters.r_flange_target", r)?;
        }
        let plausible = |key: &str, vals: &[f64], limit: f64, unit: &str| -> Result<()> {
            match vals.iter().position(|v| v.abs() > limit) {
                Some(i) => Err(bad(format!(
                    "key '{key}'[{i}] is {:e} {unit}, beyond the plausible {limit:e} {unit}",
                    vals[i]
                ))),
                None => Ok(()),
            }
        };
        for (i, t) in p.joint_error_twists.iter().enumerate() {
            plausible(
                &format!("parameters.joint_error_twists[{i}]"),
                t,
                MAX_JOINT_ERROR,
                "(rad or m)",
            )?;
        }
        plausible(
            "parameters.zero_offsets",
            &p.zero_offsets,
            MAX_ZERO_OFFSET,
            "(rad or m)",
        )?;
        let distance = |v: &[f64; 3]| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        plausible(
            "parameters.t_tracker_base.translation_m",
            &[distance(&p.t_tracker_base.translation_m)],
            MAX_TRACKER_DISTANCE_M,
            "m",
        )?;
        plausible(
            "parameters.p_flange_target_m",
            &[distance(&p.p_flange_target_m)],
            MAX_TARGET_OFFSET_M,
            "m",
        )?;
        if let Some(e) = &m.extensions {
            plausible(
                "extensions.values",
                &e.values,
                MAX_EXTENSION_VALUE,
                "(own unit)",
            )?;
        }
        if let Some(c) = &m.covariance {
            check_covariance(c).map_err(bad)?;
        }
        if let Some(stored) = &m.robot.urdf_fnv1a64 {
            let actual = urdf_checksum(&m.robot.urdf);
            if *stored != actual {
                return Err(bad(format!(
                    "key 'robot.urdf' does not match 'robot.urdf_fnv1a64' ({actual} against {stored}): \
                     the embedded robot was changed after calibration"
                )));
            }
        }
        check_campaigns(p, &bad)?;
        let n = p.joint_error_twists.len();
        if p.zero_offsets.len() != n {
            return Err(bad(format!(
                "key 'parameters.zero_offsets' has {} values for {n} joint error twists",
                p.zero_offsets.len()
            )));
        }
        Ok(m)
    }

    /// The embedded robot model (the URDF rebuilt with the stored chain).
    pub fn robot_model(&self) -> Result<Model> {
        let spec = ChainSpec {
            base_link: Some(self.robot.base_link.clone()),
            tip_link: Some(self.robot.tip_link.clone()),
        };
        let model = sim::urdf::load_str(
            &self.robot.urdf,
            &format!("embedded robot '{}'", self.robot.name),
            &spec,
        )?;
        let model = if self.robot.couplings.is_empty() {
            model
        } else {
            model.with_couplings(&self.robot.couplings)?
        };
        if model.nq() != self.parameters.joint_error_twists.len() {
            return Err(CalibError::ModelFile {
                file: "embedded robot".into(),
                message: format!(
                    "the URDF chain has {} joints but the parameters are for {}",
                    model.nq(),
                    self.parameters.joint_error_twists.len()
                ),
            });
        }
        Ok(model)
    }

    /// The parameters as a [`KinematicParams`] (extension values included).
    pub fn params(&self) -> KinematicParams {
        let p = &self.parameters;
        let twists: Vec<Vector6<f64>> = p
            .joint_error_twists
            .iter()
            .map(|t| Vector6::from_row_slice(t))
            .collect();
        let params = KinematicParams::from_twists(
            &twists,
            p.zero_offsets.clone(),
            pose_from(
                matrix(&p.t_tracker_base.rotation),
                Vector3::from(p.t_tracker_base.translation_m),
            ),
            Vector3::from(p.p_flange_target_m),
            p.r_flange_target.as_ref().map(matrix),
        )
        .with_extension(
            self.extensions
                .as_ref()
                .map_or(Vec::new(), |e| e.values.clone()),
        );
        let mut ids = vec![p.campaign];
        ids.extend(p.campaigns.iter().map(|c| c.id));
        let starts: Vec<Pose> = p
            .campaigns
            .iter()
            .map(|c| pose(&c.t_tracker_base))
            .collect();
        let own = p
            .campaigns
            .first()
            .is_some_and(|c| c.p_flange_target_m.is_some());
        let mut params = params.with_campaigns(&ids, &starts, own);
        for (reg, c) in params.campaigns.iter_mut().zip(&p.campaigns) {
            reg.p_flange_target = c.p_flange_target_m.map(Vector3::from);
            reg.r_flange_target = c.r_flange_target.as_ref().map(matrix);
        }
        params.default_campaign = p
            .default_campaign
            .and_then(|d| ids.iter().position(|&i| i == d))
            .unwrap_or(0);
        params
    }
}

/// The parameters in file form.
pub(crate) fn parameters_json(p: &KinematicParams) -> ModelParameters {
    ModelParameters {
        joint_error_twists: (0..p.joint_error.len())
            .map(|i| {
                let x = p.joint_twist(i);
                [x[0], x[1], x[2], x[3], x[4], x[5]]
            })
            .collect(),
        zero_offsets: p.zero_offset.clone(),
        t_tracker_base: pose_json(&p.t_tracker_base),
        p_flange_target_m: p.p_flange_target.into(),
        r_flange_target: p.r_flange_target.as_ref().map(rows),
        campaign: p.campaign_ids[0],
        campaigns: p
            .campaigns
            .iter()
            .zip(&p.campaign_ids[1..])
            .map(|(c, &id)| CampaignJson {
                id,
                t_tracker_base: pose_json(&c.t_tracker_base),
                p_flange_target_m: c.p_flange_target.map(Into::into),
                r_flange_target: c.r_flange_target.as_ref().map(rows),
            })
            .collect(),
        default_campaign: Some(p.campaign_ids[p.default_campaign]),
    }
}

/// The robot's parameters and every registration that `refitted` (a campaign id) is not, as `old`
/// (the file registered from) has them: the same numbers, not their round trip through a pose
/// (exp and log move the last digit).
pub(crate) fn keep_unrefitted(new: &mut ModelParameters, old: &ModelParameters, refitted: i64) {
    new.joint_error_twists = old.joint_error_twists.clone();
    new.zero_offsets = old.zero_offsets.clone();
    if old.campaign != refitted {
        new.t_tracker_base = old.t_tracker_base.clone();
        new.p_flange_target_m = old.p_flange_target_m;
        new.r_flange_target = old.r_flange_target;
    }
    for c in new.campaigns.iter_mut().filter(|c| c.id != refitted) {
        if let Some(o) = old.campaigns.iter().find(|o| o.id == c.id) {
            c.t_tracker_base = o.t_tracker_base.clone();
            if c.p_flange_target_m.is_some() && o.p_flange_target_m.is_some() {
                c.p_flange_target_m = o.p_flange_target_m;
                c.r_flange_target = o.r_flange_target;
            }
        }
    }
}

/// Where each parameter of `old` (a layout of the same robot and extensions) sits in `new`, which
/// registers the same campaigns (by id) and perhaps more, perhaps with own targets: `None` for a
/// parameter `new` does not have.
pub(crate) fn layout_map(old: &ParamLayout, new: &ParamLayout) -> Vec<Option<usize>> {
    (0..old.len())
        .map(|k| match old.kind(k) {
            ParamKind::JointTwist { joint, component } => Some(new.joint_twist(joint) + component),
            ParamKind::ZeroOffset { joint } => Some(new.zero_offset(joint)),
            ParamKind::BaseTwist {
                campaign,
                component,
            } => new
                .campaign_ids
                .iter()
                .position(|&id| id == old.campaign_ids[campaign])
                .map(|c| new.campaign_base(c) + component),
            ParamKind::TargetPosition { campaign, axis } => {
                let id = old.campaign_ids[campaign];
                let c = new.campaign_ids.iter().position(|&i| i == id)?;
                // A shared target stays the shared one.
                let c = if campaign == 0 || !old.campaign_targets {
                    0
                } else {
                    c
                };
                Some(new.campaign_target_position(c) + axis)
            }
            ParamKind::TargetOrientation { campaign, axis } => {
                let id = old.campaign_ids[campaign];
                let c = new.campaign_ids.iter().position(|&i| i == id)?;
                let c = if campaign == 0 || !old.campaign_targets {
                    0
                } else {
                    c
                };
                new.campaign_target_orientation(c).map(|o| o + axis)
            }
            ParamKind::Extension { index } => Some(new.extension(index)),
        })
        .collect()
}

/// A pose in file form.
fn pose_json(t: &Pose) -> PoseJson {
    PoseJson {
        translation_m: t.translation.vector.into(),
        rotation: rows(t.rotation.matrix()),
    }
}

/// A pose from file form (rotation checked on load).
fn pose(t: &PoseJson) -> Pose {
    pose_from(matrix(&t.rotation), Vector3::from(t.translation_m))
}

/// The campaign keys: distinct ids, a known default, finite and plausible registrations, own targets
/// for all campaigns after the first or for none (and orientations exactly when the model has them).
fn check_campaigns(p: &ModelParameters, bad: &dyn Fn(String) -> CalibError) -> Result<()> {
    let mut ids = vec![p.campaign];
    for (k, c) in p.campaigns.iter().enumerate() {
        if ids.contains(&c.id) {
            return Err(bad(format!(
                "key 'parameters.campaigns[{k}].id' is {}, a campaign already registered",
                c.id
            )));
        }
        ids.push(c.id);
        let key = format!("parameters.campaigns[{k}]");
        let t = &c.t_tracker_base;
        let values: Vec<f64> = t
            .translation_m
            .iter()
            .chain(t.rotation.as_flattened())
            .chain(c.p_flange_target_m.iter().flatten())
            .chain(c.r_flange_target.iter().flat_map(|r| r.as_flattened()))
            .copied()
            .collect();
        if values.iter().any(|v| !v.is_finite()) {
            return Err(bad(format!("key '{key}' has a value that is not finite")));
        }
        let norm = |v: &[f64; 3]| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        if norm(&t.translation_m) > MAX_TRACKER_DISTANCE_M {
            return Err(bad(format!(
                "key '{key}.t_tracker_base.translation_m' is {:e} m from the base, beyond the plausible \
                 {MAX_TRACKER_DISTANCE_M:e} m",
                norm(&t.translation_m)
            )));
        }
        for (what, r) in std::iter::once(("t_tracker_base.rotation", &t.rotation))
            .chain(c.r_flange_target.as_ref().map(|r| ("r_flange_target", r)))
        {
            let m = matrix(r);
            let e = (m.transpose() * m - Matrix3::identity()).amax();
            if e > 1e-9 || m.determinant() < 0.0 {
                return Err(bad(format!(
                    "key '{key}.{what}' is not a rotation matrix (|RᵀR − I| = {e:.1e})"
                )));
            }
        }
        if let Some(v) = &c.p_flange_target_m
            && norm(v) > MAX_TARGET_OFFSET_M
        {
            return Err(bad(format!(
                "key '{key}.p_flange_target_m' is {:e} m from the flange, beyond the plausible \
                 {MAX_TARGET_OFFSET_M:e} m",
                norm(v)
            )));
        }
        let own_first = p.campaigns[0].p_flange_target_m.is_some();
        if c.p_flange_target_m.is_some() != own_first {
            return Err(bad(format!(
                "key '{key}.p_flange_target_m': either every further campaign has its own target or none"
            )));
        }
        let orientation = p.r_flange_target.is_some();
        if c.r_flange_target.is_some() != (own_first && orientation) {
            return Err(bad(format!(
                "key '{key}.r_flange_target' must be {} (own target: {own_first}, orientation: {orientation})",
                if own_first && orientation {
                    "given"
                } else {
                    "null"
                }
            )));
        }
    }
    if let Some(d) = p.default_campaign
        && !ids.contains(&d)
    {
        return Err(bad(format!(
            "key 'parameters.default_campaign' is {d}, not one of the campaigns ({})",
            ids.iter()
                .map(|i| i.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        )));
    }
    Ok(())
}
