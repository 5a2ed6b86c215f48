//! Screening on a subsample: with many poses, the candidate causes are tried on a seeded subsample of
//! the training and test poses, and the models the selection adopts are then refitted on every pose.
//!
//! Why a subsample loses nothing that diagnose would adopt: a cause is adopted only when it lowers the
//! test RMS by at least [`super::DiagnoseOptions::min_gain`] (2 %), i.e. the test mean squared error by
//! about 4 %. With the cause's contribution `c` small against the residual `e` (mean squared norm `M`
//! per pose, three components), the per-pose difference of squared errors `2 e·c + |c|²` has mean
//! `0.04 M` and standard deviation about `√(4 · M/3 · 0.04 M) = 0.23 M`, so the paired test on `n` test
//! poses reaches `z ≈ 0.17 √n`: 5.5 at the 1,000 test poses of the default subsample of 3,000, against
//! a threshold of 2.3 (0.05 over five candidates). Every figure diagnose reports about the adopted
//! models (steps, gains, paired and training `z`, correlations, parameters, named joints, the
//! unexplained analysis) comes from the fits on every pose; only the trials of the rounds (which
//! candidate was tried against which) come from the subsample.

use super::Split;
use crate::fit::{Dataset, Part};
use rand::SeedableRng;
use rand::seq::SliceRandom;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// Default number of poses (training and test together) above which diagnose screens the candidates
/// on a subsample of this many.
pub const DEFAULT_SCREEN_POSES: usize = 3000;

/// Mixed into the seed of the subsample, so that it is not the split's own shuffle.
const SUBSAMPLE_SEED_SALT: u64 = 0x5c7e_e41e_d0a1_1b0e;

/// How the candidates were screened, when on a subsample (part of the diagnose JSON).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Screening {
    /// Training poses of the subsample.
    pub n_train: usize,
    /// Test poses of the subsample.
    pub n_test: usize,
    /// What was done on it and what on every pose, in one sentence.
    pub note: String,
}

/// The rows of `rows` grouped by pose (campaign and pose id), in key order.
fn by_pose(data: &Dataset<'_>) -> Vec<Vec<usize>> {
    let mut groups: BTreeMap<(i64, i64), Vec<usize>> = BTreeMap::new();
    for &r in &data.rows {
        groups.entry(data.table.pose_key(r)).or_default().push(r);
    }
    groups.into_values().collect()
}

/// `k` of `groups`, drawn by `rng`, as ascending rows.
fn draw(mut groups: Vec<Vec<usize>>, k: usize, rng: &mut rand::rngs::StdRng) -> Vec<usize> {
    groups.shuffle(rng);
    let mut rows: Vec<usize> = groups.into_iter().take(k).flatten().collect();
    rows.sort_unstable();
    rows
}

/// The subsample of `full` with `poses` poses in all (its training and test poses in the proportion of
/// `full`'s, at least one of each), drawn with `seed`; `None` when `full` has no more poses than that
/// or `poses` is 0 (no screening).
pub(crate) fn subsample<'a>(full: &Split<'a>, poses: usize, seed: u64) -> Option<Split<'a>> {
    let (train, test) = (by_pose(&full.train), by_pose(&full.test));
    let total = train.len() + test.len();
    if poses == 0 || total <= poses {
        return None;
    }
    let n_test = ((poses as f64 * test.len() as f64 / total as f64).round() as usize)
        .clamp(1, poses.saturating_sub(1).max(1));
    let n_train = poses - n_test;
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed ^ SUBSAMPLE_SEED_SALT);
    let train_rows = draw(train, n_train, &mut rng);
    let test_rows = draw(test, n_test, &mut rng);
    let table = full.train.table;
    Some(Split {
        test_pose: super::campaigns::pose_ids(table, &test_rows),
        train: full.train.part(train_rows, Part::Subsample),
        test: full.test.part(test_rows, Part::Subsample),
    })
}

/// The [`Screening`] record of `sub`.
pub(crate) fn record(sub: &Split<'_>) -> Screening {
    let count = |d: &Dataset<'_>| by_pose(d).len();
    let (n_train, n_test) = (count(&sub.train), count(&sub.test));
    Screening {
        n_train,
        n_test,
        note: format!(
            "the candidate causes were tried on a seeded subsample of {n_train} training and {n_test} \
             test poses; the models adopted there were refitted on every pose, which every figure \
             of the findings, the steps and the unexplained analysis comes from"
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::stats::split_by_pose;
    use sim::measurement_table::{MeasurementTable, OptionalColumns, Row};

    /// 90 poses measured twice each.
    fn table() -> MeasurementTable {
        let mut t = MeasurementTable::new(2, OptionalColumns::NONE);
        for pose in 0..90 {
            for _ in 0..2 {
                t.push_row(&Row {
                    pose,
                    q: &[pose as f64 * 0.01, 0.0],
                    position: [0.0; 3],
                    ..Row::default()
                })
                .unwrap();
            }
        }
        t
    }

    fn split(t: &MeasurementTable) -> Split<'_> {
        let (train, test) = split_by_pose(t, 1.0 / 3.0, 4);
        Split {
            test_pose: crate::select::diagnose::campaigns::pose_ids(t, &test),
            train: Dataset::new(t, train, "t", Part::All),
            test: Dataset::new(t, test, "t", Part::All),
        }
    }

    fn poses(t: &MeasurementTable, rows: &[usize]) -> Vec<i64> {
        let mut p: Vec<i64> = rows.iter().map(|&r| t.pose[r]).collect();
        p.dedup();
        p
    }

    #[test]
    fn the_subsample_keeps_whole_poses_in_the_split_proportion_and_is_seeded() {
        let t = table();
        let full = split(&t);
        let sub = subsample(&full, 30, 7).unwrap();
        let (train, test) = (poses(&t, &sub.train.rows), poses(&t, &sub.test.rows));
        // 30 poses, a third of them test poses (30 of 90 in the full split), both rows of each.
        assert_eq!((train.len(), test.len()), (20, 10));
        assert_eq!(sub.train.rows.len(), 40);
        assert_eq!(sub.test.rows.len(), 20);
        // Drawn from the split's own sides, never across.
        assert!(sub.train.rows.iter().all(|r| full.train.rows.contains(r)));
        assert!(sub.test.rows.iter().all(|r| full.test.rows.contains(r)));
        let record = record(&sub);
        assert_eq!((record.n_train, record.n_test), (20, 10));
        // The same seed draws the same subsample, another seed another one.
        assert_eq!(subsample(&full, 30, 7).unwrap().train.rows, sub.train.rows);
        assert_ne!(subsample(&full, 30, 8).unwrap().train.rows, sub.train.rows);
    }

    #[test]
    fn no_subsample_when_the_table_is_not_larger_or_screening_is_off() {
        let t = table();
        let full = split(&t);
        assert!(subsample(&full, 90, 7).is_none());
        assert!(subsample(&full, 500, 7).is_none());
        assert!(subsample(&full, 0, 7).is_none());
        assert!(subsample(&full, 89, 7).is_some());
    }
}
