//! What a diagnosis says: the steps, findings, rivals, rejections, trials and the whole [`Diagnosis`].

#[allow(unused_imports)]
use super::*;

/// One model of the sequence: its fit and held-out errors.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Step {
    /// The model (serialised as its name: `kinematic`, `kinematic+joint_compliance`, …).
    pub model: ModelSpec,
    /// RMS position error on the training poses (m).
    pub train_rms_m: f64,
    /// RMS position error on the test poses (m).
    pub test_rms_m: f64,
    /// Largest position error on the test poses (m).
    pub test_max_m: f64,
}

/// An identified extension parameter, for the report.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FoundParameter {
    /// Its name (e.g. `joint 2 compliance`).
    pub name: String,
    /// Its unit.
    pub unit: Unit,
    /// The estimate.
    pub value: f64,
    /// Its standard deviation (NaN when not determined on its own).
    pub sigma: f64,
    /// How it enters the chain (which joint), for the code; not part of the JSON.
    #[serde(skip)]
    pub term: Option<Term>,
}

/// A cause the data show.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Finding {
    /// The cause (`joint_compliance`, `gear_backlash`, `thermal_drift`, …).
    pub cause: Cause,
    /// 1-based joints it acts on (empty where it is not tied to joints).
    pub joints: Vec<usize>,
    /// One sentence of evidence.
    pub evidence: String,
    /// Test RMS before adopting it (m).
    pub test_rms_m_before: f64,
    /// Test RMS after (m).
    pub test_rms_m_after: f64,
    /// `1 − after/before`.
    pub gain: f64,
    /// Correlation of the residual with what the cause predicts (test poses).
    pub r: f64,
    /// Paired test `z` on the test poses.
    pub test_z: f64,
    /// Training `χ²` drop as a normal `z`.
    pub train_z: f64,
    /// The cause's identified parameters.
    pub parameters: Vec<FoundParameter>,
    /// 1-based joints the cause is fitted at in the adopted model when diagnose limited it to some of
    /// its joints ([`JointSelection`]; the model name reads `cause@2,4`); absent when it acts at all.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fitted_joints: Option<Vec<usize>>,
    /// The nearest rival when it was adopted: the other candidate cause, or the probe for structure no
    /// cause explains, that gained most on the held-out poses in that round.
    #[serde(default)]
    pub rival: Option<Rival>,
}

/// The nearest rival of a finding.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Rival {
    /// A cause's word (`link_deflection`) or a probe's name (`harmonics 1-3 of joint 3`).
    pub name: String,
    /// Its relative test-RMS reduction in that round.
    pub gain: f64,
    /// Why it lost, in words.
    pub why_not: String,
}

/// A cause that would have gained on the held-out poses but whose identified physics is impossible or
/// implausible (outside the cause's plausibility bounds) at every joint it names: not adopted, and
/// reported as evidence of an error no known cause explains.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Rejected {
    /// The cause.
    pub cause: Cause,
    /// 1-based joints whose identified parameter is impossible.
    pub joints: Vec<usize>,
    /// What is impossible.
    pub reason: String,
    /// Relative test-RMS reduction it would have brought.
    pub gain: f64,
    /// Paired test `z` on the test poses.
    pub test_z: f64,
    /// The impossible parameters (value at least [`DiagnoseOptions::joint_z`] standard deviations on the
    /// impossible side).
    pub parameters: Vec<FoundParameter>,
    /// One sentence for people.
    pub evidence: String,
}

/// Joints diagnose dropped from a cause: a parameter the final joint fit named at some joints was
/// impossible or implausible, so the cause was refitted at its other named joints (`cause@kept`)
/// instead of being rejected as a whole.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct JointSelection {
    /// The cause.
    pub cause: Cause,
    /// 1-based joints it was refitted at.
    pub kept: Vec<usize>,
    /// 1-based joints dropped: the implausible ones and those whose parameters were insignificant.
    pub dropped: Vec<usize>,
    /// 1-based joints dropped for an impossible or implausible parameter.
    pub implausible: Vec<usize>,
    /// What was implausible (of the first such parameter).
    pub reason: String,
    /// The implausible parameters, as fitted before the drop.
    pub parameters: Vec<FoundParameter>,
    /// One sentence for people.
    pub evidence: String,
}

impl Finding {
    /// The joints as text, e.g. `2, 4` (empty without joints).
    pub fn joint_list(&self) -> String {
        self.joints
            .iter()
            .map(|j| j.to_string())
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// A candidate tried in one round.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Trial {
    /// Round (1-based).
    pub round: usize,
    /// The cause.
    pub cause: Cause,
    /// 1-based joints it was tried at when limited to some ([`JointSelection`]); absent when at all.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fitted_joints: Option<Vec<usize>>,
    /// Test RMS with it (m).
    pub test_rms_m: f64,
    /// Paired test `z`.
    pub test_z: f64,
    /// Training `z`.
    pub train_z: f64,
    /// Relative test RMS reduction.
    pub gain: f64,
    /// Whether it passed every test.
    pub significant: bool,
    /// The unexplained-structure probe that predicts the test poses at least as well, if any: then the
    /// residual is not this cause's, whatever its significance.
    pub beaten_by: Option<String>,
    /// Why its identified physics is impossible or implausible, if it is (a negative stiffness or
    /// lost motion, a half lost motion above 2 mrad): then it is not adopted as it is, whatever its
    /// significance (in the final joint fit, the joints concerned are dropped from the cause).
    #[serde(default)]
    pub impossible: Option<String>,
    /// True when no parameter of it is determined on its own and differs from zero by
    /// [`DiagnoseOptions::joint_z`] standard deviations: there is no joint (or growth) to name, so it
    /// is not adopted whatever its gain.
    #[serde(default)]
    pub names_nothing: bool,
}

/// A candidate cause diagnose could not try.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NotTried {
    /// The cause.
    pub cause: Cause,
    /// Why not, in one sentence.
    pub reason: String,
}

/// The full result; its JSON form is the `diagnose --json` contract.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Diagnosis {
    /// Robot name.
    pub robot: String,
    /// Training poses.
    pub n_train: usize,
    /// Test poses.
    pub n_test: usize,
    /// RMS position error (m) that noise alone would leave.
    pub noise_floor_m: f64,
    /// Where the noise floor comes from.
    pub noise_floor_source: String,
    /// The models fitted, kinematic first, each adopted extension after.
    pub steps: Vec<Step>,
    /// The causes found, in the order adopted.
    pub findings: Vec<Finding>,
    /// Structure no known cause explains.
    pub unexplained: unexplained::Unexplained,
    /// The chosen model (what `calibrate --model auto` fits; serialised as its name).
    pub model: ModelSpec,
    /// Every candidate tried.
    pub trials: Vec<Trial>,
    /// Significance level used.
    pub alpha: f64,
    /// Split seed.
    pub seed: u64,
    /// Numerical warnings of every fit diagnose made (the kinematic model and every candidate),
    /// counted: empty when all were clean.
    #[serde(default)]
    pub health: Health,
    /// Joints dropped from a cause for an impossible or implausible parameter, in the order dropped
    /// (each time the cause was refitted at the joints kept).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub joint_selection: Vec<JointSelection>,
    /// Candidate causes this robot and table cannot feed (never tried), with the reason: a robot
    /// without inertials cannot be checked for joint compliance, a table without `temp` or `t` for
    /// thermal drift.
    #[serde(default)]
    pub not_tried: Vec<NotTried>,
    /// How the candidates were screened, when on a subsample of the poses (many poses, see
    /// [`screening`]); absent when every pose was used throughout.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub screening: Option<screening::Screening>,
    /// The held-out residual per measurement campaign, with several campaigns.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub campaigns: Option<campaigns::CampaignReport>,
    /// What `--report` draws (not part of the JSON).
    #[serde(skip)]
    pub plots: report::PlotData,
}
