//! Which part of a file's rows a fit sees: what its errors name.

/// Which part of a file's rows a data set holds (`calib::fit::Dataset`): what errors name, so that a caller can tell a
/// validation fit's failure from the fit of every pose by its variant, never by its text.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Part {
    /// Every row given.
    #[default]
    All,
    /// The training part of one split by pose (`--test-fraction`).
    Training,
    /// The held-out part of one split by pose.
    Test,
    /// The training rows of cross-validation fold `k` (1-based).
    FoldTraining(usize),
    /// The held-out rows of cross-validation fold `k` (1-based).
    FoldHeldOut(usize),
    /// The training rows of validation region `k` (1-based): every pose outside the region.
    RegionTraining(usize),
    /// The held-out rows of validation region `k` (1-based).
    RegionHeldOut(usize),
    /// A seeded subsample of another part (diagnose's screening).
    Subsample,
    /// Every campaign but campaign `id` (leave-one-campaign-out).
    WithoutCampaign(i64),
    /// The poses of campaign `id` predicted after its registration.
    CampaignPredicted(i64),
}

impl Part {
    /// The words after the file name in messages (empty for [`Part::All`]).
    pub fn suffix(self) -> String {
        match self {
            Part::All => String::new(),
            Part::Training => " (training set)".into(),
            Part::Test => " (test set)".into(),
            Part::FoldTraining(k) => format!(" (fold {k} training set)"),
            Part::FoldHeldOut(k) => format!(" (fold {k} held out)"),
            Part::RegionTraining(k) => format!(" (training set without region {k})"),
            Part::RegionHeldOut(k) => format!(" (region {k} held out)"),
            Part::Subsample => " (screening subsample)".into(),
            Part::WithoutCampaign(id) => format!(" (without campaign {id})"),
            Part::CampaignPredicted(id) => format!(" (campaign {id}, predicted poses)"),
        }
    }
}
