//! Measurement rows prepared for the solver: joint values, measured target poses, their standard
//! deviations ([`NoiseModel`]) and robust weights, and the extensions' regressors.

use crate::error::{CalibError, Result};
use crate::lie3::rotation_from_quaternion;
use crate::model::extensions::Regressors;
use crate::model::params::KinematicParams;
use nalgebra::{Matrix3, Vector3};
use sim::measurement_table::MeasurementTable;

/// Standard deviations of the measurements when the table has no `sigma` column (a laser-tracker model).
///
/// Position: `σ = position_sigma_m + position_sigma_per_m · d`, `d` the distance of the measured point from
/// the tracker frame's origin (the tracker head). The defaults, 7.5 µm + 3 µm/m, are half the maximum
/// permissible error of common laser trackers (e.g. 15 µm + 6 µm/m for the GTS3800 of the real data
/// sets), which manufacturers state at about 2σ. Only ratios of weights change the estimate; the
/// reported covariance uses the variance factor estimated from the residuals, so a wrong absolute level
/// shows up as `χ²/dof ≠ 1`, not as wrong standard deviations.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct NoiseModel {
    /// Constant part of the position standard deviation (m). Default 7.5e-6.
    pub position_sigma_m: f64,
    /// Distance-proportional part (m per m of distance from the tracker). Default 3e-6.
    pub position_sigma_per_m: f64,
    /// Standard deviation of each orientation component (rad), for 6-DoF probes. Default 1e-4
    /// (about 0.006°, half the 0.01° typical of 6-DoF laser-tracker probes).
    pub orientation_sigma_rad: f64,
}

impl Default for NoiseModel {
    fn default() -> Self {
        NoiseModel {
            position_sigma_m: 7.5e-6,
            position_sigma_per_m: 3e-6,
            orientation_sigma_rad: 1e-4,
        }
    }
}

/// Measurement rows prepared for the solver (a subset of a [`MeasurementTable`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Observations {
    /// Joints per row.
    pub n_joints: usize,
    /// Joint positions, row-major (rad or m).
    pub q: Vec<f64>,
    /// Measured target positions, tracker frame (m).
    pub position: Vec<Vector3<f64>>,
    /// Measured target orientations, tracker frame, when the table has them.
    pub orientation: Option<Vec<Matrix3<f64>>>,
    /// Position standard deviation per row (m).
    pub sigma: Vec<f64>,
    /// Orientation standard deviation (rad).
    pub sigma_rotation: f64,
    /// Robust weight per row in (0, 1]; 1 without a robust loss.
    pub weight: Vec<f64>,
    /// Pose id per row.
    pub pose: Vec<i64>,
    /// 0-based index of each row in the source table.
    pub source_row: Vec<usize>,
    /// Regressors of the model extensions per row ([`Regressors::none`] for the kinematic model).
    pub ext: Regressors,
    /// Campaign id per row, from the table's `campaign` column (`None` without it: every row is in
    /// the parameters' default campaign, [`KinematicParams::default_campaign`]).
    pub campaign: Option<Vec<i64>>,
}

impl Observations {
    /// Takes `rows` (0-based) of `table`; `source` names the table in errors. Sigma comes from the
    /// `sigma` column when present (it must be > 0), otherwise from `noise`.
    pub fn from_table(
        table: &MeasurementTable,
        rows: &[usize],
        noise: &NoiseModel,
        source: &str,
    ) -> Result<Self> {
        let n = table.n_joints;
        let mut q = Vec::with_capacity(rows.len() * n);
        let mut position = Vec::with_capacity(rows.len());
        let mut sigma = Vec::with_capacity(rows.len());
        let mut orientation = table
            .orientation
            .as_ref()
            .map(|_| Vec::with_capacity(rows.len()));
        for &r in rows {
            q.extend_from_slice(table.q_row(r));
            let p = Vector3::from(table.position[r]);
            position.push(p);
            let s = match &table.sigma {
                Some(col) => {
                    let s = col[r];
                    if !(s > 0.0 && s.is_finite()) {
                        return Err(CalibError::BadValue {
                            context: format!("{source}: row {}", r + 1),
                            field: "sigma".into(),
                            value: format!("{s:?}"),
                            problem: "a measurement cannot be exact: give its 1-sigma uncertainty in m (> 0)"
                                .into(),
                        });
                    }
                    s
                }
                None => noise.position_sigma_m + noise.position_sigma_per_m * p.norm(),
            };
            sigma.push(s);
            if let (Some(o), Some(qu)) = (orientation.as_mut(), table.unit_orientation(r)) {
                o.push(rotation_from_quaternion(&qu));
            }
        }
        Ok(Observations {
            n_joints: n,
            q,
            position,
            orientation,
            sigma,
            sigma_rotation: noise.orientation_sigma_rad,
            weight: vec![1.0; rows.len()],
            pose: rows.iter().map(|&r| table.pose[r]).collect(),
            source_row: rows.to_vec(),
            ext: Regressors::none(),
            campaign: table
                .campaign
                .as_ref()
                .map(|c| rows.iter().map(|&r| c[r]).collect()),
        })
    }

    /// Distinct campaign ids of the rows, ascending; `[0]` without a campaign column.
    pub fn campaign_ids(&self) -> Vec<i64> {
        match &self.campaign {
            Some(c) => {
                let mut ids = c.clone();
                ids.sort_unstable();
                ids.dedup();
                ids
            }
            None => vec![0],
        }
    }

    /// The campaign index (in `params`' order) of every row: the default campaign for all rows
    /// without a campaign column. Errors with the first row (index into these rows) whose campaign
    /// `params` does not register, and its id.
    pub fn campaign_indices(
        &self,
        params: &KinematicParams,
    ) -> std::result::Result<Vec<usize>, (usize, i64)> {
        match &self.campaign {
            None => Ok(vec![params.default_campaign; self.len()]),
            Some(ids) => ids
                .iter()
                .enumerate()
                .map(|(r, &id)| params.campaign_index(id).ok_or((r, id)))
                .collect(),
        }
    }

    /// [`Observations::campaign_indices`], with an unknown campaign as a one-line error naming the
    /// table `source`, its row and the campaigns `params` knows.
    pub fn campaign_indices_or_error(
        &self,
        params: &KinematicParams,
        source: &str,
    ) -> Result<Vec<usize>> {
        self.campaign_indices(params)
            .map_err(|(r, id)| CalibError::BadValue {
                context: format!("{source}: row {}", self.source_row[r] + 1),
                field: "campaign".into(),
                value: id.to_string(),
                problem: format!(
                    "the model knows campaigns {}: this campaign's tracker registration is unknown \
                     (register it with `robocal register`)",
                    params
                        .campaign_ids
                        .iter()
                        .map(|c| c.to_string())
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            })
    }

    /// Number of measurement rows.
    #[inline]
    pub fn len(&self) -> usize {
        self.position.len()
    }

    /// True without rows.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.position.is_empty()
    }

    /// Residuals per row: 3, or 6 with orientation.
    #[inline]
    pub fn dim(&self) -> usize {
        if self.orientation.is_some() { 6 } else { 3 }
    }

    /// Joint positions of row `r` (rad or m).
    #[inline]
    pub fn q_row(&self, r: usize) -> &[f64] {
        &self.q[r * self.n_joints..(r + 1) * self.n_joints]
    }

    /// Number of distinct poses (pose ids, per campaign).
    pub fn n_poses(&self) -> usize {
        let mut ids: Vec<(i64, i64)> = match &self.campaign {
            Some(c) => c.iter().copied().zip(self.pose.iter().copied()).collect(),
            None => self.pose.iter().map(|&p| (0, p)).collect(),
        };
        ids.sort_unstable();
        ids.dedup();
        ids.len()
    }

    /// Number of distinct joint configurations (rows with bit-identical joint values count once,
    /// whatever their pose ids): what determines the parameters.
    pub fn n_configurations(&self) -> usize {
        let bits = |r: usize| self.q_row(r).iter().map(|v| v.to_bits());
        let mut rows: Vec<usize> = (0..self.len()).collect();
        rows.sort_unstable_by(|&a, &b| bits(a).cmp(bits(b)));
        rows.dedup_by(|a, b| bits(*a).eq(bits(*b)));
        rows.len()
    }
}
