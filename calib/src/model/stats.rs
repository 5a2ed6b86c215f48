//! Residual statistics of a parameter point on a set of measurements, and the reproducible
//! train/test split by pose.

use crate::model::observations::Observations;
use crate::model::params::KinematicParams;
use crate::model::predict::Prediction;
use nalgebra::Vector3;
use rand::SeedableRng;
use rand::seq::SliceRandom;
use sim::Model;
use sim::measurement_table::MeasurementTable;

/// Position (and orientation) errors `|predicted − measured|` over a set of rows.
///
/// `mean_m` is the mean of the Euclidean position error per row, the quantity ISO 9283 calls the mean
/// position error (here over measurements instead of repeated visits of one commanded pose).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ResidualStats {
    /// Rows.
    pub n: usize,
    /// Root mean square of the position error norms (m).
    pub rms_m: f64,
    /// Mean position error norm (m).
    pub mean_m: f64,
    /// Largest position error norm (m).
    pub max_m: f64,
    /// 1-based table row of the largest error.
    pub max_row: usize,
    /// Mean signed error per tracker axis (m): a bias that a good fit leaves near zero.
    pub mean_vector_m: [f64; 3],
    /// RMS of the orientation error angle (rad), with orientation measurements.
    pub rms_rad: Option<f64>,
    /// Largest orientation error angle (rad), with orientation measurements.
    pub max_rad: Option<f64>,
}

/// Errors of the model `params` on the rows of `obs`.
pub fn residual_stats(
    model: &Model,
    params: &KinematicParams,
    obs: &Observations,
) -> ResidualStats {
    prediction_stats(&Prediction::new(model, params), obs)
}

/// Errors of `prediction` (learned correction included when it has one) on the rows of `obs`.
pub fn prediction_stats(prediction: &Prediction<'_>, obs: &Observations) -> ResidualStats {
    let mut st = stats_of_errors(&prediction.errors(obs), obs);
    if let Some(angles) = prediction.orientation_errors(obs)
        && !obs.is_empty()
    {
        let sum2r: f64 = angles.iter().map(|a| a * a).sum();
        st.rms_rad = Some((sum2r / obs.len() as f64).sqrt());
        st.max_rad = Some(angles.iter().copied().fold(0.0, f64::max));
    }
    st
}

/// Position statistics of the errors `errors` (tracker frame, m), one per row of `obs` (for the rows'
/// table numbers); orientation fields stay empty.
pub fn stats_of_errors(errors: &[Vector3<f64>], obs: &Observations) -> ResidualStats {
    let mut st = ResidualStats {
        n: errors.len(),
        ..Default::default()
    };
    if errors.is_empty() {
        return st;
    }
    let (mut sum2, mut sum) = (0.0, 0.0);
    let mut mv = [0.0; 3];
    for (r, d) in errors.iter().enumerate() {
        let e = d.norm();
        sum2 += e * e;
        sum += e;
        for k in 0..3 {
            mv[k] += d[k];
        }
        if e > st.max_m {
            st.max_m = e;
            st.max_row = obs.source_row[r] + 1;
        }
    }
    let n = errors.len() as f64;
    st.rms_m = (sum2 / n).sqrt();
    st.mean_m = sum / n;
    st.mean_vector_m = mv.map(|v| v / n);
    st
}

/// Position errors `predicted − measured` (tracker frame, m) of the model `params`, one per row of `obs`.
pub fn position_errors(
    model: &Model,
    params: &KinematicParams,
    obs: &Observations,
) -> Vec<Vector3<f64>> {
    Prediction::new(model, params).errors(obs)
}

/// Splits `table`'s rows into training and test rows by pose id: the distinct ids are shuffled with
/// `StdRng::seed_from_u64(seed)` and the first `round(test_fraction · poses)` (at least one when the
/// fraction is positive and there are two or more poses; never all) go to the test set. Repeated
/// measurements of a pose stay together. Rows come back ascending.
pub fn split_by_pose(
    table: &MeasurementTable,
    test_fraction: f64,
    seed: u64,
) -> (Vec<usize>, Vec<usize>) {
    let groups = table.rows_by_pose();
    let n = groups.len();
    let mut n_test = (test_fraction.clamp(0.0, 1.0) * n as f64).round() as usize;
    if test_fraction > 0.0 && n_test == 0 && n >= 2 {
        n_test = 1;
    }
    n_test = n_test.min(n.saturating_sub(1));
    let mut order: Vec<usize> = (0..n).collect();
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    order.shuffle(&mut rng);
    let mut is_test = vec![false; n];
    for &g in &order[..n_test] {
        is_test[g] = true;
    }
    let (mut train, mut test) = (Vec::new(), Vec::new());
    for (g, (_, rows)) in groups.iter().enumerate() {
        if is_test[g] {
            test.extend_from_slice(rows);
        } else {
            train.extend_from_slice(rows);
        }
    }
    train.sort_unstable();
    test.sort_unstable();
    (train, test)
}
