//! A calibration in the model file's form ([`CalibratedModel`]): the file written by `calibrate`,
//! and the file after `register` refitted a campaign.

use crate::fit::Calibration;
use crate::fit::register::Registration;
use crate::model::file::{
    CalibratedModel, CovarianceJson, EmbeddedRobot, ExtensionsJson, FORMAT, FORMAT_VERSION,
    FitSummary, keep_unrefitted, layout_map, parameters_json, urdf_checksum,
};
use crate::model::params::ParamLayout;
use crate::model::robot::Robot;
use sim::Model;

impl CalibratedModel {
    /// The file form of a calibration of `robot`.
    pub fn new(robot: &Robot, cal: &Calibration) -> Self {
        let p = &cal.params;
        let vf = cal.report.variance_factor();
        CalibratedModel {
            format: FORMAT.into(),
            format_version: FORMAT_VERSION,
            software: format!("robocal-calib {}", env!("CARGO_PKG_VERSION")),
            model: cal.report.model.clone(),
            robot: EmbeddedRobot {
                name: robot.model.name().to_string(),
                source: robot.source.clone(),
                base_link: robot.model.base_link().to_string(),
                tip_link: robot.model.tip_link().to_string(),
                urdf: robot.urdf.clone(),
                urdf_fnv1a64: Some(urdf_checksum(&robot.urdf)),
                couplings: robot.couplings.clone(),
            },
            parameters: parameters_json(p),
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
            fit: Some(FitSummary {
                train_rms_m: cal
                    .report
                    .learned
                    .as_ref()
                    .map_or(cal.report.after.train.rms_m, |l| l.train.rms_m),
                held_out_rms_m: None,
                n_train_poses: cal.report.n_train_poses,
                new_region_rms_m: None,
                calibration_sigma_m: None,
            }),
        }
    }

    /// Records in the fit summary the 95th percentile of the predicted standard deviation over the
    /// calibration rows `rows` of `table` ([`FitSummary::calibration_sigma_m`]; at most
    /// [`SIGMA_SAMPLE_ROWS`] of them, evenly spaced), with the default prior. Nothing without a
    /// covariance or a fit summary; errors as `predict`'s on `table`.
    pub fn record_calibration_sigma(
        &mut self,
        table: &sim::measurement_table::MeasurementTable,
        rows: &[usize],
        name: &str,
    ) -> crate::error::Result<()> {
        if self.covariance.is_none() || self.fit.is_none() || rows.is_empty() {
            return Ok(());
        }
        let stride = rows.len().div_ceil(SIGMA_SAMPLE_ROWS);
        let sample: Vec<usize> = rows.iter().step_by(stride).copied().collect();
        let predictor = crate::model::predict::Predictor::from_file(self)?;
        let Some(mut sigma) = predictor.sigma_table(&table.select_rows(&sample), name)? else {
            return Ok(());
        };
        sigma.retain(|s| s.is_finite());
        if sigma.is_empty() {
            return Ok(());
        }
        sigma.sort_by(f64::total_cmp);
        let p95 = sigma[((sigma.len() - 1) as f64 * 0.95).round() as usize];
        if let Some(f) = self.fit.as_mut() {
            f.calibration_sigma_m = Some(p95);
        }
        Ok(())
    }
}

/// Most calibration rows whose predicted standard deviation [`CalibratedModel::record_calibration_sigma`]
/// computes.
pub const SIGMA_SAMPLE_ROWS: usize = 10_000;

impl CalibratedModel {
    /// The model with a campaign registered by [`crate::fit::register::register`] (`reg`): its
    /// parameters, the default campaign, and the covariance grown by the registration's block (a
    /// registration is conditional on the robot: no cross terms). `model` is the embedded robot.
    pub fn registered(&self, model: &Model, reg: &Registration) -> Self {
        let mut out = self.clone();
        out.format_version = FORMAT_VERSION;
        out.software = format!("robocal-calib {}", env!("CARGO_PKG_VERSION"));
        out.parameters = parameters_json(&reg.params);
        keep_unrefitted(&mut out.parameters, &self.parameters, reg.report.campaign);
        let ext = self
            .extensions
            .as_ref()
            .map_or(Vec::new(), |e| e.settings.params(model));
        let old = ParamLayout::for_params(model, &self.params(), ext.clone());
        let new = ParamLayout::for_params(model, &reg.params, ext);
        if let Some(cov) = &self.covariance
            && cov.matrix.len() == old.len()
        {
            let map = layout_map(&old, &new);
            let mut m = vec![vec![0.0; new.len()]; new.len()];
            for (i, mi) in map.iter().enumerate() {
                for (j, mj) in map.iter().enumerate() {
                    if let (Some(a), Some(b)) = (mi, mj) {
                        m[*a][*b] = cov.matrix[i][j];
                    }
                }
            }
            for (a, &ka) in reg.indices.iter().enumerate() {
                for (b, &kb) in reg.indices.iter().enumerate() {
                    m[ka][kb] = reg.covariance[(a, b)];
                }
                // The registration is refitted: its old cross terms no longer hold.
                for (k, row) in m.iter_mut().enumerate() {
                    if !reg.indices.contains(&k) {
                        row[ka] = 0.0;
                    }
                }
                for (k, v) in m[ka].iter_mut().enumerate() {
                    if !reg.indices.contains(&k) {
                        *v = 0.0;
                    }
                }
            }
            out.covariance = Some(CovarianceJson {
                parameters: (0..new.len()).map(|k| new.name(k)).collect(),
                matrix: m,
                variance_factor: cov.variance_factor,
            });
        }
        out
    }
}
