//! Settings of a diagnosis: levels, split, screening.

#[allow(unused_imports)]
use super::*;

/// Settings of [`diagnose`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DiagnoseOptions {
    /// Fraction of the poses held out (default 1/3).
    pub test_fraction: f64,
    /// Seed of the split and of the learned models' folds.
    pub seed: u64,
    /// Calibration settings.
    pub calibration: CalibrationOptions,
    /// Family-wise false-alarm level of each round's training test (default 1e-3).
    pub alpha: f64,
    /// Family-wise level of each round's held-out test (default 0.05). It guards against a model that
    /// fits the training poses without predicting others; false alarms are held down by `alpha`, the
    /// two tests together by their product.
    pub held_out_alpha: f64,
    /// Smallest relative test-RMS reduction a finding must bring (default 0.02).
    pub min_gain: f64,
    /// A joint is named when its parameter differs from zero by this many standard deviations (default 4).
    pub joint_z: f64,
    /// Causes to try (default: all).
    pub candidates: Vec<Cause>,
    /// Learned models tried on what is left (default `kernel`, `poly`).
    pub learned_kinds: Vec<LearnedKind>,
    /// The noise floor (RMS position error norm, m) when the user knows it better than the data tell,
    /// e.g. a robot's repeatability; `None` estimates it ([`noise_floor::estimate`]).
    pub noise_floor_m: Option<f64>,
    /// Poses (training and test) above which the candidates are tried on a seeded subsample of this
    /// many and the adopted models refitted on every pose (default
    /// [`screening::DEFAULT_SCREEN_POSES`]; 0: every pose throughout).
    #[serde(default = "default_screen_poses")]
    pub screen_poses: usize,
    /// Regions of the configuration space an adopted cause must transfer to ([`transfer`]; default
    /// [`crate::validate::regions::DEFAULT_REGIONS`]; 0: no transfer test).
    #[serde(default = "default_regions")]
    pub regions: usize,
}

pub(super) fn default_regions() -> usize {
    crate::validate::regions::DEFAULT_REGIONS
}

pub(super) fn default_screen_poses() -> usize {
    screening::DEFAULT_SCREEN_POSES
}

impl Default for DiagnoseOptions {
    fn default() -> Self {
        DiagnoseOptions {
            test_fraction: 1.0 / 3.0,
            seed: 0,
            calibration: CalibrationOptions::default(),
            alpha: 1e-3,
            held_out_alpha: 0.05,
            min_gain: 0.02,
            joint_z: 5.0,
            candidates: Cause::ALL.to_vec(),
            learned_kinds: vec![LearnedKind::Kernel, LearnedKind::Poly],
            noise_floor_m: None,
            screen_poses: screening::DEFAULT_SCREEN_POSES,
            regions: default_regions(),
        }
    }
}
