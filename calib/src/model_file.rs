//! The calibrated model file (`MODEL.json`): everything `predict` needs, with the robot embedded; the
//! predictor that evaluates it. The calibrated URDF is written by [`crate::urdf_export`].
//!
//! # MODEL.json
//! ```json
//! {
//!   "format": "robocal-calibrated-model", "format_version": 1, "software": "robocal-calib 0.1.0",
//!   "model": "kinematic",
//!   "robot": {"name": "iiwa7", "source": "built-in robot 'iiwa7'", "base_link": "…", "tip_link": "…",
//!             "urdf": "<?xml …"},
//!   "parameters": {
//!     "joint_error_twists": [[ωx, ωy, ωz, vx, vy, vz], …],   // ξᵢ, base frame (rad, m)
//!     "zero_offsets": [δq₁, …],                              // rad (m for prismatic joints)
//!     "t_tracker_base": {"translation_m": [x, y, z], "rotation": [[…], […], […]]},
//!     "p_flange_target_m": [x, y, z],
//!     "r_flange_target": [[…], […], […]] or null
//!   },
//!   "covariance": {"parameters": ["joint 1 twist ω_x", …], "matrix": [[…], …], "variance_factor": 1.02}
//! }
//! ```
//! The real screw of joint `i` is `Ad(exp[ξᵢ]) Sᵢ` with `Sᵢ` the embedded URDF's screw; the covariance is
//! that of a step at the solution in [`crate::params::ParamLayout`] order (physical units). Floats are written by
//! `serde_json` as the shortest decimal that reads back to the same `f64`.

use crate::calibrate::Calibration;
use crate::chain::{Chain, ChainScratch};
use crate::error::{CalibError, Result};
use crate::extensions::{Cause, ExtensionSettings, ModelSpec, Regressors};
use crate::learned::LearnedResidual;
use crate::lie3::quaternion_from_rotation;
use crate::params::KinematicParams;
use crate::predict::Prediction;
use crate::robot::Robot;
use crate::units::Unit;
use nalgebra::{Matrix3, Vector3, Vector6};
use sim::lie::pose_from;
use sim::measurement_table::MeasurementTable;
use sim::{ChainSpec, Model};

/// The `format` value of a calibrated model file.
pub const FORMAT: &str = "robocal-calibrated-model";
/// The current `format_version`.
pub const FORMAT_VERSION: u32 = 1;

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
}

/// Covariance of the parameters.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CovarianceJson {
    /// Parameter names in [`crate::params::ParamLayout`] order.
    pub parameters: Vec<String>,
    /// The covariance matrix, row by row (physical units).
    pub matrix: Vec<Vec<f64>>,
    /// The variance factor `σ̂²` it includes.
    pub variance_factor: f64,
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
    pub model: String,
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
    /// The file form of a calibration of `robot`.
    pub fn new(robot: &Robot, cal: &Calibration) -> Self {
        let p = &cal.params;
        let n = robot.model.nq();
        let vf = if cal.report.chi2_per_dof.is_finite() {
            cal.report.chi2_per_dof
        } else {
            1.0
        };
        CalibratedModel {
            format: FORMAT.into(),
            format_version: FORMAT_VERSION,
            software: format!("robocal-calib {}", env!("CARGO_PKG_VERSION")),
            model: cal.report.model.clone(),
            robot: EmbeddedRobot {
                name: robot.model.name.clone(),
                source: robot.source.clone(),
                base_link: robot.model.base_link.clone(),
                tip_link: robot.model.tip_link.clone(),
                urdf: robot.urdf.clone(),
                urdf_fnv1a64: Some(urdf_checksum(&robot.urdf)),
            },
            parameters: ModelParameters {
                joint_error_twists: (0..n)
                    .map(|i| {
                        let x = p.joint_twist(i);
                        [x[0], x[1], x[2], x[3], x[4], x[5]]
                    })
                    .collect(),
                zero_offsets: p.zero_offset.clone(),
                t_tracker_base: PoseJson {
                    translation_m: p.t_tracker_base.translation.vector.into(),
                    rotation: rows(p.t_tracker_base.rotation.matrix()),
                },
                p_flange_target_m: p.p_flange_target.into(),
                r_flange_target: p.r_flange_target.as_ref().map(rows),
            },
            covariance: Some(CovarianceJson {
                parameters: (0..cal.layout.len()).map(|k| cal.layout.name(k)).collect(),
                matrix: (0..cal.covariance.nrows())
                    .map(|i| cal.covariance.row(i).iter().copied().collect())
                    .collect(),
                variance_factor: vf,
            }),
            extensions: cal.extensions.as_ref().map(|settings| ExtensionsJson {
                settings: settings.clone(),
                names: cal.layout.extensions.iter().map(|e| e.name()).collect(),
                units: cal.layout.extensions.iter().map(|e| e.unit).collect(),
                values: p.extension.clone(),
            }),
            learned: cal.learned.clone(),
        }
    }

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
        let m: CalibratedModel = serde_json::from_value(v).map_err(|e| bad(format!("{e}")))?;
        if m.format_version != FORMAT_VERSION {
            return Err(bad(format!(
                "key 'format_version' is {}, this version reads {FORMAT_VERSION}",
                m.format_version
            )));
        }
        let p = &m.parameters;
        let finite = |key: &str, vals: &[f64]| -> Result<()> {
            match vals.iter().position(|v| !v.is_finite()) {
                Some(i) => Err(bad(format!("key '{key}'[{i}] is not finite"))),
                None => Ok(()),
            }
        };
        let spec = ModelSpec::parse(&m.model).map_err(|e| bad(format!("key 'model': {e}")))?;
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
        if let Some(stored) = &m.robot.urdf_fnv1a64 {
            let actual = urdf_checksum(&m.robot.urdf);
            if *stored != actual {
                return Err(bad(format!(
                    "key 'robot.urdf' does not match 'robot.urdf_fnv1a64' ({actual} against {stored}): \
                     the embedded robot was changed after calibration"
                )));
            }
        }
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
        KinematicParams::from_twists(
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
        )
    }
}

/// Evaluates a calibrated model.
#[derive(Clone, Debug)]
pub struct Predictor {
    /// The robot.
    pub model: Model,
    /// The parameters.
    pub params: KinematicParams,
    /// Settings of the model extensions, if any.
    pub extensions: Option<ExtensionSettings>,
    /// Learned residual correction, if any.
    pub learned: Option<LearnedResidual>,
    chain: Chain,
    scratch: ChainScratch,
}

/// Predictions for the rows of a table.
#[derive(Clone, Debug, PartialEq)]
pub struct Predictions {
    /// Pose id per row.
    pub pose: Vec<i64>,
    /// Predicted target position per row (tracker frame, m).
    pub position: Vec<[f64; 3]>,
    /// Predicted target orientation per row (unit quaternion `[qw, qx, qy, qz]`, tracker frame), when the
    /// model has orientation.
    pub orientation: Option<Vec<[f64; 4]>>,
}

impl Predictions {
    /// CSV text `pose,x,y,z[,qw,qx,qy,qz]`.
    pub fn to_csv(&self) -> String {
        let mut header: Vec<String> = ["pose", "x", "y", "z"].map(String::from).to_vec();
        if self.orientation.is_some() {
            header.extend(["qw", "qx", "qy", "qz"].map(String::from));
        }
        let rows: Vec<(i64, Vec<f64>)> = (0..self.pose.len())
            .map(|r| {
                let mut v = self.position[r].to_vec();
                if let Some(o) = &self.orientation {
                    v.extend_from_slice(&o[r]);
                }
                (self.pose[r], v)
            })
            .collect();
        crate::io::csv_text(&header, &rows)
    }
}

impl Predictor {
    /// A predictor for `model` with `params`.
    pub fn new(model: Model, params: KinematicParams) -> Self {
        let chain = Chain::new(&model, &params);
        let scratch = ChainScratch::new(model.nq());
        Predictor {
            model,
            params,
            extensions: None,
            learned: None,
            chain,
            scratch,
        }
    }

    /// A predictor for a model file.
    pub fn from_file(m: &CalibratedModel) -> Result<Self> {
        let mut p = Predictor::new(m.robot_model()?, m.params());
        p.extensions = m.extensions.as_ref().map(|e| e.settings.clone());
        p.learned = m.learned.clone();
        if let Some(s) = &p.extensions
            && s.params(&p.model).len() != p.params.extension.len()
        {
            return Err(CalibError::ModelFile {
                file: "model".into(),
                message: format!(
                    "key 'extensions' has {} values; its causes need {}",
                    p.params.extension.len(),
                    s.params(&p.model).len()
                ),
            });
        }
        Ok(p)
    }

    /// Target position (tracker frame, m) and orientation (tracker frame) at the controller's `q`, for the
    /// kinematic part of the model only (extensions need a row's payload, directions and temperature:
    /// use [`Predictor::predict_table`]), learned correction included.
    ///
    /// # Panics
    /// If `q` has the wrong length (check tables with [`Predictor::predict_table`]).
    pub fn predict(&mut self, q: &[f64]) -> (Vector3<f64>, Matrix3<f64>) {
        self.chain.forward(&mut self.scratch, q);
        let p = self.scratch.p_tracker
            + self
                .learned
                .as_ref()
                .map_or(Vector3::zeros(), |l| l.predict(q));
        (p, self.scratch.r_tracker_target)
    }

    /// Predictions for every row of `table` (its x, y, z are ignored); `file` names it in errors.
    pub fn predict_table(&mut self, table: &MeasurementTable, file: &str) -> Result<Predictions> {
        if table.n_joints != self.model.nq() {
            return Err(CalibError::BadValue {
                context: file.to_string(),
                field: "q1..qN".into(),
                value: format!("{} joint columns", table.n_joints),
                problem: format!(
                    "the model's robot '{}' has {} joints",
                    self.model.name,
                    self.model.nq()
                ),
            });
        }
        let orientation = self.params.r_flange_target.is_some();
        let mut out = Predictions {
            pose: table.pose.clone(),
            position: Vec::with_capacity(table.len()),
            orientation: orientation.then(|| Vec::with_capacity(table.len())),
        };
        let rows: Vec<usize> = (0..table.len()).collect();
        let regs = match &self.extensions {
            Some(s) => {
                s.check_table(table, file)?;
                Regressors::build(&self.model, s, table, &rows, file, &self.params.extension)?
            }
            None => Regressors::none(),
        };
        let mut position = vec![Vector3::zeros(); table.len()];
        let mut rotation = orientation.then(|| vec![Matrix3::identity(); table.len()]);
        Prediction::new(&self.model, &self.params)
            .with_learned(self.learned.as_ref())
            .positions(&table.q, &regs, &mut position, rotation.as_deref_mut());
        out.position = position.iter().map(|p| (*p).into()).collect();
        out.orientation = rotation.map(|r| r.iter().map(quaternion_from_rotation).collect());
        Ok(out)
    }
}
