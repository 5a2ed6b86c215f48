//! What a validation reports: held-out statistics per model, per fold or region, and the text.

#[allow(unused_imports)]
use super::*;

/// Held-out position errors of one model.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct HeldOutStats {
    /// Held-out rows.
    pub n_rows: usize,
    /// Held-out poses.
    pub n_poses: usize,
    /// RMS of the position error norms (m).
    pub rms_m: f64,
    /// Mean position error norm (m).
    pub mean_m: f64,
    /// Largest position error norm (m).
    pub max_m: f64,
    /// ISO 9283-style mean (m): the mean over poses of the norm of the pose's mean error vector.
    pub iso_mean_m: f64,
}

impl HeldOutStats {
    /// One line of a validation table: `name` (padded to `w`), poses, RMS, mean, max and ISO mean
    /// (mm).
    fn row(&self, name: &str, w: usize) -> String {
        let mm = |v: f64| format!("{:.4} mm", v * 1e3);
        format!(
            "  {name:<w$} {:>6} {:>12} {:>12} {:>12} {:>12}\n",
            self.n_poses,
            mm(self.rms_m),
            mm(self.mean_m),
            mm(self.max_m),
            mm(self.iso_mean_m)
        )
    }

    /// The statistics of `errors` (m, `predicted − measured`), one per row, the rows of pose
    /// `pose_key[r]` (campaign, pose) averaged for the ISO mean.
    pub fn of(errors: &[Vector3<f64>], pose_key: &[(i64, i64)]) -> Self {
        assert_eq!(errors.len(), pose_key.len(), "one pose per error");
        let n = errors.len();
        if n == 0 {
            return HeldOutStats::default();
        }
        let (mut sum2, mut sum, mut max) = (0.0, 0.0, 0.0f64);
        let mut per_pose: BTreeMap<(i64, i64), (Vector3<f64>, usize)> = BTreeMap::new();
        for (e, key) in errors.iter().zip(pose_key) {
            let v = e.norm();
            sum2 += v * v;
            sum += v;
            max = max.max(v);
            let entry = per_pose.entry(*key).or_insert((Vector3::zeros(), 0));
            entry.0 += e;
            entry.1 += 1;
        }
        let iso = per_pose
            .values()
            .map(|(s, k)| (s / *k as f64).norm())
            .sum::<f64>()
            / per_pose.len() as f64;
        HeldOutStats {
            n_rows: n,
            n_poses: per_pose.len(),
            rms_m: (sum2 / n as f64).sqrt(),
            mean_m: sum / n as f64,
            max_m: max,
            iso_mean_m: iso,
        }
    }
}

/// [`HeldOutStats`] summed row by row, poses as runs of consecutive rows with one key.
#[derive(Clone, Debug, Default)]
pub struct HeldOutSum {
    n: usize,
    sum2: f64,
    sum: f64,
    max: f64,
    run: Option<((i64, i64), Vector3<f64>, usize)>,
    iso_sum: f64,
    poses: usize,
}

impl HeldOutSum {
    /// Adds a row of pose `key` with error `e` (m).
    pub fn add(&mut self, key: (i64, i64), e: &Vector3<f64>) {
        let v = e.norm();
        self.n += 1;
        self.sum2 += v * v;
        self.sum += v;
        self.max = self.max.max(v);
        match &mut self.run {
            Some((k, s, m)) if *k == key => {
                *s += e;
                *m += 1;
            }
            _ => {
                self.close_run();
                self.run = Some((key, *e, 1));
            }
        }
    }

    fn close_run(&mut self) {
        if let Some((_, s, m)) = self.run.take() {
            self.iso_sum += (s / m as f64).norm();
            self.poses += 1;
        }
    }

    /// The statistics of the rows added.
    pub fn finish(mut self) -> HeldOutStats {
        self.close_run();
        if self.n == 0 {
            return HeldOutStats::default();
        }
        let n = self.n as f64;
        HeldOutStats {
            n_rows: self.n,
            n_poses: self.poses,
            rms_m: (self.sum2 / n).sqrt(),
            mean_m: self.sum / n,
            max_m: self.max,
            iso_mean_m: self.iso_sum / self.poses as f64,
        }
    }
}

/// One fold of a cross-validation.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FoldStats {
    /// Fold (0-based).
    pub fold: usize,
    /// Poses fitted.
    pub n_train_poses: usize,
    /// The calibrated model (learned correction included, when there is one) on the fold's poses.
    pub held_out: HeldOutStats,
}

/// How a calibration was validated, and what it gave.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Validation {
    /// `cross_validation`, `test_fraction` (one split of the data) or `test_data` (another file).
    pub kind: String,
    /// Folds of a cross-validation.
    pub folds: Option<usize>,
    /// Seed of the folds or the split.
    pub seed: Option<u64>,
    /// Held-out errors of the nominal robot (only base and target fitted).
    pub before: HeldOutStats,
    /// Held-out errors of the calibrated physical model.
    pub after: HeldOutStats,
    /// Held-out errors with the learned correction, for a model that has one.
    pub learned: Option<HeldOutStats>,
    /// Per fold, for a cross-validation.
    pub per_fold: Vec<FoldStats>,
    /// Standard deviation of the per-fold RMS (m): how much one fold's estimate varies.
    pub fold_rms_spread_m: Option<f64>,
    /// Regions of the leave-one-region-out validation (`--regions`; [`regions`]), when it ran.
    #[serde(default)]
    pub regions: Option<usize>,
    /// The saved model (its learned correction included, within its support) on held-out regions:
    /// what it promises for poses unlike the ones it saw ([`ByRegion::final_stats`]).
    #[serde(default)]
    pub new_region: Option<HeldOutStats>,
    /// The leave-one-region-out validation in detail.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub by_region: Option<ByRegion>,
    /// The saved model on campaigns it did not see, each registered on
    /// [`campaigns::REGISTER_POSES`] of its poses ([`campaigns`]), with several campaigns.
    #[serde(default)]
    pub new_campaign: Option<HeldOutStats>,
    /// The leave-one-campaign-out validation in detail.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub by_campaign: Option<ByCampaign>,
}

/// Leave-one-region-out validation: each region of the configuration space ([`regions`]) predicted
/// by the model fitted on the others.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ByRegion {
    /// Regions.
    pub regions: usize,
    /// Seed of the clustering.
    pub seed: u64,
    /// The nominal robot (base and target fitted).
    pub before: HeldOutStats,
    /// The calibrated physical model.
    pub after: HeldOutStats,
    /// With the learned correction, for a model that has one.
    pub learned: Option<HeldOutStats>,
    /// Per region: its poses, the poses fitted without it, the final model's errors on it.
    pub per_region: Vec<FoldStats>,
    /// Held-out rows not predicted: their campaign had no pose outside the region, so no fit
    /// registered it (the leave-one-campaign-out validation covers them).
    pub n_rows_not_predicted: usize,
}

impl ByRegion {
    /// The final model's errors: with the learned correction when there is one.
    pub fn final_stats(&self) -> &HeldOutStats {
        self.learned.as_ref().unwrap_or(&self.after)
    }
}

/// Leave-one-campaign-out validation ([`campaigns`]).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ByCampaign {
    /// Campaigns predicted.
    pub n_campaigns: usize,
    /// Poses of each that registered it.
    pub register_poses: usize,
    /// The calibrated physical model on the predicted poses.
    pub after: HeldOutStats,
    /// With the learned correction, for a model that has one.
    pub learned: Option<HeldOutStats>,
}

impl Validation {
    /// A `k`-fold cross-validation (seed `seed`): the pooled held-out statistics of the nominal,
    /// physical and learned models and the folds' own, with the spread of the folds' RMS (`None`
    /// with fewer than two folds predicted). Regions and campaigns are added after.
    pub fn cross_validation(
        k: usize,
        seed: u64,
        (before, after, learned): (HeldOutStats, HeldOutStats, Option<HeldOutStats>),
        per_fold: Vec<FoldStats>,
    ) -> Self {
        let rms: Vec<f64> = per_fold.iter().map(|f| f.held_out.rms_m).collect();
        let n = rms.len() as f64;
        let spread = (rms.len() >= 2).then(|| {
            let mean = rms.iter().sum::<f64>() / n;
            (rms.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
        });
        Validation {
            kind: "cross_validation".into(),
            folds: Some(k),
            seed: Some(seed),
            before,
            after,
            learned,
            per_fold,
            fold_rms_spread_m: spread,
            regions: None,
            new_region: None,
            by_region: None,
            new_campaign: None,
            by_campaign: None,
        }
    }

    /// Adds the leave-one-region-out validation `r`, and its final model's figures as the promise
    /// for a new region.
    pub fn set_regions(&mut self, r: ByRegion) {
        self.regions = Some(r.regions);
        self.new_region = Some(r.final_stats().clone());
        self.by_region = Some(r);
    }

    /// The final model's held-out errors: with the learned correction when there is one.
    pub fn final_stats(&self) -> &HeldOutStats {
        self.learned.as_ref().unwrap_or(&self.after)
    }

    /// The validation as text for a terminal.
    pub fn text(&self, model: &str) -> String {
        let how = match (self.kind.as_str(), self.folds) {
            ("cross_validation", Some(k)) => format!(
                "{k}-fold cross-validation by pose (seed {}): every pose held out once, predicted by a model \
                 fitted on the other folds",
                self.seed.unwrap_or(0)
            ),
            ("test_fraction", _) => format!(
                "one split by pose (seed {}): the held-out poses predicted by a model fitted on the others",
                self.seed.unwrap_or(0)
            ),
            _ => "the test data, predicted by the saved model".to_string(),
        };
        let w = model.chars().count().max(20);
        let mut s = format!(
            "validation on held-out poses: {how}\n  {:<w$} {:>6} {:>12} {:>12} {:>12} {:>12}\n",
            "model", "poses", "RMS", "mean", "max", "ISO mean"
        );
        let mut row = |name: &str, st: &HeldOutStats| s.push_str(&st.row(name, w));
        row("nominal+base+target", &self.before);
        let physical = model.split("+learned:").next().unwrap_or(model);
        row(physical, &self.after);
        if let Some(l) = &self.learned {
            row(model, l);
        }
        if let Some(sd) = self.fold_rms_spread_m {
            s.push_str(&format!(
                "  per-fold RMS: {} (spread {:.4} mm)\n",
                self.per_fold
                    .iter()
                    .map(|f| format!("{:.4}", f.held_out.rms_m * 1e3))
                    .collect::<Vec<_>>()
                    .join(", "),
                sd * 1e3
            ));
        }
        if let Some(r) = &self.by_region {
            s.push_str(&format!(
                "validation on held-out regions: {} regions of the configuration space (k-means on \
                 sin q, cos q; seed {}), each predicted by a model fitted on the others\n",
                r.regions, r.seed
            ));
            let mut row = |name: &str, st: &HeldOutStats| s.push_str(&st.row(name, w));
            row("nominal+base+target", &r.before);
            row(physical, &r.after);
            if let Some(l) = &r.learned {
                row(model, l);
            }
            if r.n_rows_not_predicted > 0 {
                s.push_str(&format!(
                    "  {} held-out rows not predicted: their campaign lies inside one region\n",
                    r.n_rows_not_predicted
                ));
            }
        }
        if let Some(c) = &self.by_campaign {
            s.push_str(&format!(
                "validation on unseen campaigns: each of {} campaigns predicted by a model fitted on \
                 the others, registered on {} of its poses\n",
                c.n_campaigns, c.register_poses
            ));
            let mut row = |name: &str, st: &HeldOutStats| s.push_str(&st.row(name, w));
            row(physical, &c.after);
            if let Some(l) = &c.learned {
                row(model, l);
            }
        }
        if let Some(promise) = self.promise_text() {
            s.push_str(&promise);
        }
        s
    }

    /// How far to trust the figures: the promise for poses unlike the calibration's, against the
    /// held-out poses' figure.
    pub fn promise_text(&self) -> Option<String> {
        let region = self.new_region.as_ref()?;
        let poses = self.final_stats();
        let mm = |v: f64| format!("{:.4} mm", v * 1e3);
        let ratio = if poses.mean_m > 0.0 {
            region.mean_m / poses.mean_m
        } else {
            1.0
        };
        let mut s = format!(
            "promise: {} mean on poses like the calibration's (held-out poses), {} on poses unlike them \
             (held-out regions)",
            mm(poses.mean_m),
            mm(region.mean_m)
        );
        if let Some(c) = &self.new_campaign {
            s.push_str(&format!(", {} on a new campaign", mm(c.mean_m)));
        }
        s.push_str(if ratio > 1.25 {
            ". The model is worth less away from its poses: expect the held-out-region figure where \
             you did not measure, and measure there to do better.\n"
        } else {
            ". The two agree: the figure holds across the workspace the regions span.\n"
        });
        Some(s)
    }
}
