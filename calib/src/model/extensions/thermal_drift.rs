//! Thermal drift, as the estimator models it: joint zeros drift and the arm grows with temperature.
//!
//! With `ΔT = T − T_ref` (K; `T_ref` the training mean, where the kinematic parameters hold):
//!
//! - joint-zero drift: `θᵢ = qᵢ + βᵢ ΔT` (`βᵢ` in rad/K, m/K for a prismatic joint);
//! - link growth: every link grows by the same fraction `α ΔT` (`α` in 1/K), which scales the target's
//!   position about the base origin, `p_base ← (1 + α ΔT) p_base`. Per-link coefficients are not
//!   separable from one common one with the data a calibration campaign gives (they would need the
//!   temperature to vary independently per link), so the model has one.
//!
//! Without a `temp` column, `ΔT` is replaced by the first-order warm-up `w(t) = 1 − exp(−t/τ)` (minus its
//! training mean) from the `t` column, and the parameters are per unit of warm-up (rad, 1); the time
//! constant τ (s) is found by the calibration's search over candidates ([`WARM_UP_TAUS_S`]).
//!
//! # Plausibility bounds
//! - Link growth: `−5e-6 ≤ α ≤ 5e-5` 1/K ([`MIN_GROWTH_PER_K`], [`MAX_GROWTH_PER_K`]). Structural
//!   steel expands by about 1.2e-5/K and aluminium alloys by 2.3e-5/K; carbon-fibre tubes by −1e-6 to
//!   +3e-6/K. The bounds give the metals a factor of two and the composites a factor of five; a
//!   growth beyond them is no arm's (it stands in for a drift of the tracker or another error).
//! - Joint-zero drift: `|βᵢ| ≤ 1e-3` rad/K ([`MAX_ZERO_DRIFT_PER_K`]; m/K for a prismatic joint):
//!   0.06°/K, 0.6° over a 10 K warm-up, a hundred times the drift of an encoder on a growing
//!   housing.
//! - Without temperatures the parameters are per unit of warm-up: the bounds are those per kelvin
//!   times a warm-up of at most [`MAX_WARM_UP_RISE_K`] (40 K).

use super::settings::missing_column;
use super::{Cause, CauseModel, ExtensionParam, ExtensionSettings, PlotAxis, RowInputs, Term};
use super::{ThermalInput, per_joint_params};
use crate::error::{CalibError, Result};
use crate::units::Unit;
use sim::Model;
use sim::measurement_table::MeasurementTable;

/// Expected joint-zero drift (rad/K).
pub const BETA_SCALE_RAD_PER_K: f64 = 1e-5;
/// Expected linear expansion (1/K): aluminium is 23e-6.
pub const ALPHA_SCALE_PER_K: f64 = 2e-5;
/// Smallest plausible link growth (1/K): five times the contraction of carbon-fibre tubes.
pub const MIN_GROWTH_PER_K: f64 = -5e-6;
/// Largest plausible link growth (1/K): twice aluminium's 2.3e-5.
pub const MAX_GROWTH_PER_K: f64 = 5e-5;
/// Largest plausible joint-zero drift (rad/K; m/K for a prismatic joint).
pub const MAX_ZERO_DRIFT_PER_K: f64 = 1e-3;
/// Largest warm-up temperature rise (K) assumed when the bounds are per unit of warm-up.
pub const MAX_WARM_UP_RISE_K: f64 = 40.0;

/// Warm-up time constants tried without a temperature column (s): 5 min to 4 h.
pub const WARM_UP_TAUS_S: [f64; 10] = [
    300.0, 450.0, 600.0, 900.0, 1200.0, 1800.0, 2700.0, 3600.0, 7200.0, 14400.0,
];

/// The `ΔT` source for training rows `rows` of `table`: the temperature column (reference = its mean
/// over `rows`), else a warm-up with time constant `tau_s` (default 1800 s) from the time column.
pub fn input_for(
    table: &MeasurementTable,
    rows: &[usize],
    tau_s: Option<f64>,
    source: &str,
) -> Result<ThermalInput> {
    let mean = |v: &[f64], f: &dyn Fn(f64) -> f64| {
        rows.iter().map(|&r| f(v[r])).sum::<f64>() / rows.len().max(1) as f64
    };
    if let Some(temp) = &table.temp {
        return Ok(ThermalInput::Temperature {
            t_ref_c: mean(temp, &|x| x),
        });
    }
    if let Some(t) = &table.t {
        let tau = tau_s.unwrap_or(1800.0);
        return Ok(ThermalInput::WarmUp {
            tau_s: tau,
            w_ref: mean(t, &|x| warm_up(x, tau)),
        });
    }
    Err(CalibError::BadValue {
        context: source.to_string(),
        field: "temp, t".into(),
        value: "absent".into(),
        problem: "thermal_drift needs a temperature (temp) or time (t) column".into(),
    })
}

/// `1 − exp(−t/τ)` (dimensionless; `t`, `τ` in s).
#[inline]
pub fn warm_up(t_s: f64, tau_s: f64) -> f64 {
    1.0 - (-t_s.max(0.0) / tau_s).exp()
}

/// Thermal drift: joint-zero drift per joint, then the common link growth, all with regressor `ΔT`.
pub struct ThermalDrift;

impl CauseModel for ThermalDrift {
    fn cause(&self) -> Cause {
        Cause::ThermalDrift
    }

    fn usable(&self, _model: &Model, table: &MeasurementTable) -> std::result::Result<(), String> {
        if table.temp.is_some() || table.t.is_some() {
            Ok(())
        } else {
            Err("the table has neither a temp nor a t column".into())
        }
    }

    /// `ΔT` from the temperature column, else a warm-up with the default time constant from `t`.
    fn configure(
        &self,
        settings: &mut ExtensionSettings,
        _model: &Model,
        table: &MeasurementTable,
        rows: &[usize],
        source: &str,
    ) -> Result<()> {
        settings.thermal = Some(input_for(table, rows, None, source)?);
        Ok(())
    }

    /// Without temperatures, the warm-up time constants [`WARM_UP_TAUS_S`].
    fn alternatives(
        &self,
        settings: &ExtensionSettings,
        table: &MeasurementTable,
        rows: &[usize],
    ) -> Vec<ExtensionSettings> {
        if !matches!(settings.thermal, Some(ThermalInput::WarmUp { .. })) {
            return Vec::new();
        }
        WARM_UP_TAUS_S
            .iter()
            .filter_map(|&tau| {
                let input = input_for(table, rows, Some(tau), "").ok()?;
                Some(ExtensionSettings {
                    thermal: Some(input),
                    ..settings.clone()
                })
            })
            .collect()
    }

    fn needs_gravity_torque(&self, _settings: &ExtensionSettings) -> bool {
        false
    }

    fn params(&self, model: &Model, settings: &ExtensionSettings) -> Vec<ExtensionParam> {
        let per_kelvin = matches!(settings.thermal, Some(ThermalInput::Temperature { .. }));
        let (rad, m, growth, gain) = if per_kelvin {
            (
                Unit::RadianPerKelvin,
                Unit::MetrePerKelvin,
                Unit::PerKelvin,
                1.0,
            )
        } else {
            (
                Unit::RadianPerWarmUp,
                Unit::MetrePerWarmUp,
                Unit::PerWarmUp,
                10.0,
            )
        };
        let mut out = per_joint_params(
            model,
            Cause::ThermalDrift,
            "zero drift",
            rad,
            m,
            BETA_SCALE_RAD_PER_K * gain,
        );
        out.push(ExtensionParam {
            cause: Cause::ThermalDrift,
            term: Term::Growth,
            quantity: "link growth",
            unit: growth,
            scale: ALPHA_SCALE_PER_K * gain,
            pattern: None,
        });
        out
    }

    fn check_table(
        &self,
        settings: &ExtensionSettings,
        table: &MeasurementTable,
        file: &str,
    ) -> Result<()> {
        match settings.thermal {
            Some(ThermalInput::Temperature { .. }) if table.temp.is_none() => {
                Err(missing_column(file, "temp", "thermal_drift"))
            }
            Some(ThermalInput::WarmUp { .. }) if table.t.is_none() => Err(missing_column(
                file,
                "t",
                "thermal_drift (warm-up from time)",
            )),
            _ => Ok(()),
        }
    }

    /// `ΔT` (K, or warm-up units) for every parameter.
    fn regressors(&self, settings: &ExtensionSettings, row: &RowInputs<'_>, out: &mut [f64]) {
        let dt = match settings.thermal {
            Some(ThermalInput::Temperature { t_ref_c }) => row.temp_c.map_or(0.0, |t| t - t_ref_c),
            Some(ThermalInput::WarmUp { tau_s, w_ref }) => {
                row.t_s.map_or(0.0, |t| warm_up(t, tau_s) - w_ref)
            }
            None => 0.0,
        };
        out.fill(dt);
    }

    fn evidence_subject(&self, _joints: &str) -> String {
        "the temperature change".to_string()
    }

    fn implausible(&self, param: &ExtensionParam, value: f64) -> Option<String> {
        let per_kelvin = matches!(
            param.unit,
            Unit::PerKelvin | Unit::RadianPerKelvin | Unit::MetrePerKelvin
        );
        let (scale, per) = if per_kelvin {
            (1.0, "/K")
        } else {
            (MAX_WARM_UP_RISE_K, " per unit of warm-up")
        };
        match param.term {
            Term::Growth => {
                let (lo, hi) = (MIN_GROWTH_PER_K * scale, MAX_GROWTH_PER_K * scale);
                (value < lo || value > hi).then(|| {
                    format!(
                        "a link growth outside {lo:.0e} to {hi:.0e}{per}: no arm's links expand \
                         like that (steel 1.2e-5/K, aluminium 2.3e-5/K)"
                    )
                })
            }
            _ => {
                let max = MAX_ZERO_DRIFT_PER_K * scale;
                (value.abs() > max).then(|| {
                    format!("a joint-zero drift beyond {max:.0e}{per}: no encoder drifts that far")
                })
            }
        }
    }

    fn signature(&self) -> &'static str {
        "follows the temperature or the warm-up, whatever the pose"
    }

    fn plot_axis(&self, _term: Term) -> PlotAxis {
        PlotAxis {
            sign: 1.0,
            label: "temperature change (K or warm-up)".to_string(),
        }
    }
}
