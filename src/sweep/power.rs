//! Detection power of `robocal sweep --score diagnose`: per cell the rate at which diagnose named
//! exactly the hidden causes and the rate of false alarms, each with its Wilson score interval; per
//! power curve (one noise level and pose count, magnitude on the x axis) the smallest magnitude
//! detected in at least 90 % of the runs; and the false-alarm rate at magnitude 0, which is the real
//! size of diagnose's tests.
//!
//! Written beside the sweep file as `FILE.power.csv` (one row per cell, [`CSV_HEADER`]), summarised on
//! stderr and in `--json`, and drawn as the sweep's plot (`FILE.svg`).

use super::CellSummary;
use serde::Serialize;

/// The standard normal quantile of the two-sided 95 % interval (Φ⁻¹(0.975)).
pub const Z_95: f64 = 1.959_963_984_540_054;

/// The detection rate a power curve must reach for [`PowerCurve::magnitude_90`].
pub const TARGET_RATE: f64 = 0.9;

/// The Wilson score interval of a binomial proportion: `k` successes in `n` trials, two-sided at the
/// normal quantile `z` (`Z_95` for 95 %). `(lower, upper)` in [0, 1]; exactly 0 below at `k = 0` and
/// exactly 1 above at `k = n`. `(0, 1)` without trials.
pub fn wilson(k: usize, n: usize, z: f64) -> (f64, f64) {
    if n == 0 {
        return (0.0, 1.0);
    }
    let nf = n as f64;
    let p = k as f64 / nf;
    let z2n = z * z / nf;
    let centre = (p + z2n / 2.0) / (1.0 + z2n);
    let half = z / (1.0 + z2n) * (p * (1.0 - p) / nf + z2n / (4.0 * nf)).sqrt();
    let lower = if k == 0 {
        0.0
    } else {
        (centre - half).max(0.0)
    };
    let upper = if k == n {
        1.0
    } else {
        (centre + half).min(1.0)
    };
    (lower, upper)
}

/// One cell's detection and false-alarm rates.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PowerCell {
    /// Factor on the injected effects (0 = absent).
    pub magnitude: f64,
    /// Tracker noise multiplier.
    pub noise_scale: f64,
    /// Poses per run.
    pub poses: usize,
    /// The payload set's masses, `/`-separated (kg), empty for the scenario's payloads.
    pub payloads: String,
    /// Runs of the cell.
    pub runs: usize,
    /// Runs where diagnose named exactly the hidden causes (`detected`).
    pub detected: usize,
    /// `detected / runs`.
    pub detection_rate: f64,
    /// Its 95 % Wilson interval, lower end.
    pub detection_lower: f64,
    /// Its 95 % Wilson interval, upper end.
    pub detection_upper: f64,
    /// Runs with a false alarm (`false_alarm`).
    pub false_alarms: usize,
    /// `false_alarms / runs`.
    pub false_alarm_rate: f64,
    /// Its 95 % Wilson interval, lower end.
    pub false_alarm_lower: f64,
    /// Its 95 % Wilson interval, upper end.
    pub false_alarm_upper: f64,
}

/// One power curve: a noise level, a pose count and a payload set, its cells in magnitude order.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PowerCurve {
    /// Tracker noise multiplier.
    pub noise_scale: f64,
    /// Poses per run.
    pub poses: usize,
    /// The payload set's masses, `/`-separated (kg), empty for the scenario's payloads.
    pub payloads: String,
    /// The smallest magnitude above 0 whose detection rate is at least [`TARGET_RATE`] and stays so
    /// at every larger magnitude of the sweep; `None` when the largest does not reach it.
    pub magnitude_90: Option<f64>,
    /// False alarms at magnitude 0, of runs there (`None` without a magnitude 0).
    pub false_alarms_at_0: Option<(usize, usize)>,
}

impl PowerCurve {
    /// Whether `cell` lies on this curve (its noise level, pose count and payload set).
    pub fn holds(&self, cell: &PowerCell) -> bool {
        cell.noise_scale == self.noise_scale
            && cell.poses == self.poses
            && cell.payloads == self.payloads
    }

    /// `noise ×N, P poses` (and `, payloads 0/7 kg` with a payload set).
    pub fn label(&self) -> String {
        let mut s = format!("noise ×{}, {} poses", self.noise_scale, self.poses);
        if !self.payloads.is_empty() {
            s.push_str(&format!(", payloads {} kg", self.payloads));
        }
        s
    }
}

/// The power study of a `--score diagnose` sweep: every cell and every curve.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Power {
    /// One row per cell, in cell order.
    pub cells: Vec<PowerCell>,
    /// One curve per noise level, pose count and payload set.
    pub curves: Vec<PowerCurve>,
    /// Pooled over the curves: false alarms at magnitude 0 and runs there (`None` without a
    /// magnitude 0).
    pub false_alarms_at_0: Option<(usize, usize)>,
}

/// The power study of the cells of a `--score diagnose` sweep (`None` for another score).
pub fn power(cells: &[CellSummary]) -> Option<Power> {
    let rows: Vec<PowerCell> = cells
        .iter()
        .map(|c| {
            let (d, f) = (c.detected?, c.false_alarms?);
            let (dl, du) = wilson(d, c.runs, Z_95);
            let (fl, fu) = wilson(f, c.runs, Z_95);
            let rate = |k: usize| {
                if c.runs == 0 {
                    0.0
                } else {
                    k as f64 / c.runs as f64
                }
            };
            Some(PowerCell {
                magnitude: c.magnitude,
                noise_scale: c.noise_scale,
                poses: c.poses,
                payloads: c.payloads.clone(),
                runs: c.runs,
                detected: d,
                detection_rate: rate(d),
                detection_lower: dl,
                detection_upper: du,
                false_alarms: f,
                false_alarm_rate: rate(f),
                false_alarm_lower: fl,
                false_alarm_upper: fu,
            })
        })
        .collect::<Option<_>>()?;
    let mut keys: Vec<(f64, usize, &str)> = Vec::new();
    for c in &rows {
        let key = (c.noise_scale, c.poses, c.payloads.as_str());
        if !keys.contains(&key) {
            keys.push(key);
        }
    }
    let curves: Vec<PowerCurve> = keys
        .iter()
        .map(|&(noise, poses, payloads)| {
            let mut mine: Vec<&PowerCell> = rows
                .iter()
                .filter(|c| c.noise_scale == noise && c.poses == poses && c.payloads == payloads)
                .collect();
            mine.sort_by(|a, b| a.magnitude.total_cmp(&b.magnitude));
            // From the largest magnitude down, as long as the rate holds.
            let mut magnitude_90 = None;
            for c in mine.iter().rev().filter(|c| c.magnitude > 0.0) {
                if c.detection_rate >= TARGET_RATE {
                    magnitude_90 = Some(c.magnitude);
                } else {
                    break;
                }
            }
            let zero: Vec<&&PowerCell> = mine.iter().filter(|c| c.magnitude == 0.0).collect();
            let false_alarms_at_0 = (!zero.is_empty()).then(|| {
                (
                    zero.iter().map(|c| c.false_alarms).sum(),
                    zero.iter().map(|c| c.runs).sum(),
                )
            });
            PowerCurve {
                noise_scale: noise,
                poses,
                payloads: payloads.to_string(),
                magnitude_90,
                false_alarms_at_0,
            }
        })
        .collect();
    let at_0: Vec<(usize, usize)> = curves.iter().filter_map(|c| c.false_alarms_at_0).collect();
    let false_alarms_at_0 = (!at_0.is_empty()).then(|| {
        (
            at_0.iter().map(|p| p.0).sum(),
            at_0.iter().map(|p| p.1).sum(),
        )
    });
    Some(Power {
        cells: rows,
        curves,
        false_alarms_at_0,
    })
}

/// The header of `FILE.power.csv`.
pub const CSV_HEADER: &str = "magnitude,noise_scale,poses,payloads,runs,detected,detection_rate,detection_lower_95,detection_upper_95,false_alarms,false_alarm_rate,false_alarm_lower_95,false_alarm_upper_95";

/// `FILE.power.csv`: [`CSV_HEADER`] and one row per cell (rates as fractions, shortest round-trip
/// decimal).
pub fn csv(power: &Power) -> String {
    let mut s = String::from(CSV_HEADER);
    s.push('\n');
    for c in &power.cells {
        s.push_str(&format!(
            "{},{},{},{},{},{},{},{},{},{},{},{},{}\n",
            c.magnitude,
            c.noise_scale,
            c.poses,
            c.payloads,
            c.runs,
            c.detected,
            c.detection_rate,
            c.detection_lower,
            c.detection_upper,
            c.false_alarms,
            c.false_alarm_rate,
            c.false_alarm_lower,
            c.false_alarm_upper
        ));
    }
    s
}

/// The power summary for stderr: per curve the smallest magnitude detected in 90 % of runs and the
/// false alarms at magnitude 0, then the pooled false-alarm rate with its interval.
pub fn summary_text(power: &Power) -> String {
    let mut s = String::from("detection power (95 % Wilson intervals in FILE.power.csv):\n");
    for c in &power.curves {
        let swept = power
            .cells
            .iter()
            .any(|cell| c.holds(cell) && cell.magnitude > 0.0);
        let m90 = match c.magnitude_90 {
            Some(m) => format!("detected in ≥ 90 % of runs from magnitude {m}"),
            None if swept => {
                "detected in ≥ 90 % of runs: not reached at the largest magnitude".to_string()
            }
            None => "no magnitude above 0 swept".to_string(),
        };
        s.push_str(&format!("  {}: {m90}", c.label()));
        if let Some((f, n)) = c.false_alarms_at_0 {
            s.push_str(&format!("; false alarms at magnitude 0: {f} of {n}"));
        }
        s.push('\n');
    }
    if let Some((f, n)) = power.false_alarms_at_0 {
        let (lo, hi) = wilson(f, n, Z_95);
        s.push_str(&format!(
            "  false-alarm rate at magnitude 0 (the real size of diagnose's tests): {f} of {n} = {:.2} %, 95 % interval [{:.2} %, {:.2} %]\n",
            100.0 * f as f64 / n.max(1) as f64,
            100.0 * lo,
            100.0 * hi
        ));
    }
    s
}

/// The plot of a `--score diagnose` sweep: detection rate against magnitude, one curve per noise
/// level and pose count (line and markers), its 95 % Wilson interval as a band.
pub fn plot_svg(scenario: &str, power: &Power) -> String {
    use plot::{Plot, Series, Style};
    let mut series = Vec::new();
    for curve in &power.curves {
        let mut mine: Vec<&PowerCell> = power.cells.iter().filter(|c| curve.holds(c)).collect();
        mine.sort_by(|a, b| a.magnitude.total_cmp(&b.magnitude));
        let label = curve.label();
        series.push(Series {
            label: label.clone(),
            points: mine
                .iter()
                .map(|c| (c.magnitude, c.detection_lower))
                .collect(),
            style: Style::Band {
                upper: mine.iter().map(|c| c.detection_upper).collect(),
            },
        });
        series.push(Series {
            label,
            points: mine
                .iter()
                .map(|c| (c.magnitude, c.detection_rate))
                .collect(),
            style: Style::LineMarkers,
        });
    }
    Plot {
        title: format!(
            "{scenario}: diagnose's detection rate — measured (line), 95 % Wilson interval (band)"
        ),
        x_label: "magnitude (factor on the injected effect; 0 = absent)".into(),
        y_label: "runs detected (fraction)".into(),
        log_x: false,
        log_y: false,
        series,
    }
    .to_svg(800, 520)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Hand-computed Wilson intervals: 5 of 10 at z = 1.96 gives centre 1/2 and half-width
    /// 1.96/1.38416 · √(0.025 + 3.8416/400) = 0.2634104 (Newcombe 1998, table I: 0.2366–0.7634);
    /// 0 of 200 gives [0, (z²/200)/(1 + z²/200)], 200 of 200 its mirror.
    #[test]
    fn wilson_matches_hand_values() {
        let (lo, hi) = wilson(5, 10, 1.96);
        assert!(
            (lo - 0.236_589_6).abs() < 1e-7 && (hi - 0.763_410_4).abs() < 1e-7,
            "{lo} {hi}"
        );
        let z2 = Z_95 * Z_95;
        let (lo, hi) = wilson(0, 200, Z_95);
        assert_eq!(lo, 0.0);
        assert!(
            (hi - (z2 / 200.0) / (1.0 + z2 / 200.0)).abs() < 1e-15,
            "{hi}"
        );
        let (lo, hi) = wilson(200, 200, Z_95);
        assert_eq!(hi, 1.0);
        assert!((lo - 1.0 / (1.0 + z2 / 200.0)).abs() < 1e-15, "{lo}");
        assert_eq!(wilson(0, 0, Z_95), (0.0, 1.0));
    }

    fn cell(magnitude: f64, poses: usize, runs: usize, detected: usize, fa: usize) -> CellSummary {
        CellSummary {
            cell: 0,
            magnitude,
            payloads: String::new(),
            noise_scale: 1.0,
            poses,
            runs,
            not_converged: 0,
            sigma_median_m: 0.0,
            test_error_median_m: 0.0,
            test_error_p10_m: 0.0,
            test_error_p90_m: 0.0,
            predicted_median_m: 0.0,
            param_z2_mean_median: 0.0,
            condition_number_median: 0.0,
            detected: Some(detected),
            false_alarms: Some(fa),
            causes: Vec::new(),
        }
    }

    /// The 90 % magnitude is where the rate reaches 90 % and stays there: a lucky dip above it at a
    /// small magnitude does not count. False alarms at 0 pool over the curves.
    #[test]
    fn magnitude_90_needs_the_rate_to_hold_above_it() {
        let cells = [
            cell(0.0, 100, 20, 19, 1),
            cell(0.1, 100, 20, 18, 0),
            cell(0.2, 100, 20, 15, 0),
            cell(0.4, 100, 20, 19, 0),
            cell(1.0, 100, 20, 20, 0),
            cell(0.0, 200, 20, 20, 0),
            cell(0.1, 200, 20, 10, 2),
            cell(1.0, 200, 20, 17, 0),
        ];
        let p = power(&cells).unwrap();
        assert_eq!(p.curves.len(), 2);
        assert_eq!(p.curves[0].magnitude_90, Some(0.4));
        assert_eq!(p.curves[0].false_alarms_at_0, Some((1, 20)));
        assert_eq!(p.curves[1].magnitude_90, None);
        assert_eq!(p.false_alarms_at_0, Some((1, 40)));
        assert_eq!(p.cells[6].false_alarm_rate, 0.1);
        let csv = csv(&p);
        assert_eq!(csv.lines().count(), 1 + cells.len());
        assert!(
            csv.lines()
                .nth(2)
                .unwrap()
                .starts_with("0.1,1,100,,20,18,0.9,")
        );
        let mut plain = cells[0].clone();
        plain.detected = None;
        assert!(power(&[plain]).is_none());
        let text = summary_text(&p);
        assert!(
            text.contains("100 poses: detected in ≥ 90 % of runs from magnitude 0.4"),
            "{text}"
        );
        assert!(
            text.contains("200 poses: detected in ≥ 90 % of runs: not reached"),
            "{text}"
        );
    }

    #[test]
    fn a_sweep_of_clean_runs_alone_says_so() {
        let p = power(&[cell(0.0, 200, 4000, 4000, 0)]).unwrap();
        let text = summary_text(&p);
        assert!(
            text.contains(
                "200 poses: no magnitude above 0 swept; false alarms at magnitude 0: 0 of 4000"
            ),
            "{text}"
        );
        assert!(
            text.contains("0 of 4000 = 0.00 %, 95 % interval [0.00 %, 0.10 %]"),
            "{text}"
        );
    }
}
