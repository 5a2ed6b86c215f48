//! The noise floor: the RMS position error (m) that measurement noise alone leaves, the level below which
//! no model can predict held-out poses.

use crate::fit::problem::NoiseModel;
use sim::measurement_table::MeasurementTable;

/// Fewest degrees of freedom (repeats beyond the first, summed over poses) for the repeated-pose estimate.
pub const MIN_REPEAT_DOF: usize = 10;

/// The noise floor (m) and where it comes from: the pooled scatter of repeated measurements of a pose
/// when the table has at least [`MIN_REPEAT_DOF`] repeats, else the RMS of `√3 σ` over the `test_rows`
/// with `σ` from the `sigma` column or the isotropic tracker model `noise` (per axis, `a + b · distance`).
pub fn estimate(
    table: &MeasurementTable,
    test_rows: &[usize],
    noise: &NoiseModel,
) -> (f64, String) {
    let all: Vec<usize> = (0..table.len()).collect();
    if let Some(r) = crate::fit::repeats::of_rows(table, &all)
        && r.repeats >= MIN_REPEAT_DOF
    {
        return (r.rms_m, format!("repeated poses ({} repeats)", r.repeats));
    }
    let sigma = |r: usize| match &table.sigma {
        Some(s) => s[r],
        None => {
            let p = table.position[r];
            noise.position_sigma_m
                + noise.position_sigma_per_m * (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt()
        }
    };
    let n = test_rows.len().max(1) as f64;
    let ms = test_rows
        .iter()
        .map(|&r| 3.0 * sigma(r).powi(2))
        .sum::<f64>()
        / n;
    let source = if table.sigma.is_some() {
        "sigma column".to_string()
    } else {
        format!(
            "tracker noise model ({:.1} µm + {:.1} µm/m per axis)",
            noise.position_sigma_m * 1e6,
            noise.position_sigma_per_m * 1e6
        )
    };
    (ms.sqrt(), source)
}

#[cfg(test)]
mod tests {
    use super::*;
    use sim::measurement_table::{OptionalColumns, Row};

    #[test]
    fn repeated_poses_give_their_pooled_scatter() {
        // 12 poses measured twice, the second 3 µm further along x: each pair scatters by
        // Σ|x − x̄|² = 2 (1.5 µm)², one degree of freedom, so the floor is √(4.5e-12) m.
        let mut t = MeasurementTable::new(1, OptionalColumns::NONE);
        for k in 0..12 {
            for rep in 0..2 {
                let x = 1.0 + k as f64 + 3e-6 * rep as f64;
                t.push_row(&Row {
                    pose: k,
                    q: &[0.1],
                    position: [x, 0.0, 0.0],
                    ..Row::default()
                })
                .unwrap();
            }
        }
        let (floor, source) = estimate(&t, &[0, 2], &NoiseModel::default());
        assert!((floor - 4.5e-12f64.sqrt()).abs() < 1e-15, "{floor}");
        assert!(source.contains("12 repeats"));
    }

    #[test]
    fn without_repeats_the_tracker_model_sets_it() {
        let mut t = MeasurementTable::new(1, OptionalColumns::NONE);
        t.push_row(&Row {
            pose: 0,
            q: &[0.1],
            position: [2.0, 0.0, 0.0],
            ..Row::default()
        })
        .unwrap();
        let noise = NoiseModel::default();
        let (floor, _) = estimate(&t, &[0], &noise);
        // σ = 7.5 µm + 3 µm/m · 2 m = 13.5 µm per axis.
        assert!((floor - 3f64.sqrt() * 13.5e-6).abs() < 1e-15);
    }
}
