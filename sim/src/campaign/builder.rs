//! [`CampaignBuilder`]: a [`CampaignSpec`] made value by value, checked when built.

use super::err;
use super::spec::{
    BranchRule, CampaignSpec, DirectionRule, PayloadRule, Sampling, check_model_free,
};
use crate::effects::thermal_drift::TemperatureProfile;
use crate::error::Result;
use crate::kinematics::ik::Reachability;

/// Builds a [`CampaignSpec`]; [`CampaignBuilder::build`] checks every value that does not need the
/// robot (the rest is checked by [`super::plan`]). Errors are [`crate::error::SimError::Scenario`] under the builder's
/// label and the scenario key (`campaign.repeats`, …).
#[must_use = "a builder does nothing until `build` is called"]
#[derive(Clone, Debug, PartialEq)]
pub struct CampaignBuilder {
    spec: CampaignSpec,
    label: String,
}

impl CampaignSpec {
    /// A builder starting from the defaults of [`CampaignSpec::random`]`(100)`.
    pub fn builder() -> CampaignBuilder {
        CampaignSpec::random(100).to_builder()
    }

    /// A builder starting from this campaign.
    pub fn to_builder(&self) -> CampaignBuilder {
        CampaignBuilder {
            spec: self.clone(),
            label: "campaign".into(),
        }
    }
}

impl CampaignBuilder {
    /// The name errors give (the scenario file; default `campaign`).
    pub fn label(mut self, label: &str) -> CampaignBuilder {
        self.label = label.into();
        self
    }
    /// Number of poses, ≥ 1; `None` = 100 for random sampling, 150 (30 cycles) for ISO 9283, the whole
    /// list for grid and file.
    pub fn poses(mut self, poses: Option<usize>) -> CampaignBuilder {
        self.spec.poses = poses;
        self
    }
    /// Measurements per pose (≥ 1).
    pub fn repeats(mut self, repeats: usize) -> CampaignBuilder {
        self.spec.repeats = repeats;
        self
    }
    /// Pose source.
    pub fn sampling(mut self, sampling: Sampling) -> CampaignBuilder {
        self.spec.sampling = sampling;
        self
    }
    /// Cell constraints (lengths in m, |value| ≤ 10 m).
    pub fn reachability(mut self, reachability: Reachability) -> CampaignBuilder {
        self.spec.reachability = reachability;
        self
    }
    /// Time between successive poses (s, finite, ≥ 0).
    pub fn seconds_per_pose(mut self, s: f64) -> CampaignBuilder {
        self.spec.seconds_per_pose = s;
        self
    }
    /// Time between repeated measurements of one pose (s, finite, ≥ 0).
    pub fn seconds_per_repeat(mut self, s: f64) -> CampaignBuilder {
        self.spec.seconds_per_repeat = s;
        self
    }
    /// Approach-direction rule.
    pub fn directions(mut self, rule: DirectionRule) -> CampaignBuilder {
        self.spec.directions = rule;
        self
    }
    /// Where the branches off the chain are (checked against the robot by [`super::plan`]).
    pub fn branches(mut self, rule: BranchRule) -> CampaignBuilder {
        self.spec.branches = rule;
        self
    }
    /// Joint positions before the first pose (rad or m; checked against the robot by [`super::plan`]).
    pub fn start_q(mut self, q: Option<Vec<f64>>) -> CampaignBuilder {
        self.spec.start_q = q;
        self
    }
    /// Payload rule (masses finite, ≥ 0 kg) and centre of mass (flange frame, m, |value| ≤ 2 m).
    pub fn payload(mut self, rule: PayloadRule, com_m: [f64; 3]) -> CampaignBuilder {
        self.spec.payload = rule;
        self.spec.payload_com_m = com_m;
        self
    }
    /// Robot temperature over time (°C).
    pub fn temperature(mut self, profile: TemperatureProfile) -> CampaignBuilder {
        self.spec.temperature = profile;
        self
    }
    /// Target (reflector) position in the flange frame (m).
    pub fn p_flange_m(mut self, p: [f64; 3]) -> CampaignBuilder {
        self.spec.p_flange_m = p;
        self
    }

    /// The campaign, every value checked (see the setters).
    pub fn build(self) -> Result<CampaignSpec> {
        let f = self.label.as_str();
        let spec = self.spec;
        let r = &spec.reachability;
        for (key, v) in [
            ("campaign.floor_z_m", r.floor_z_m),
            ("campaign.min_axis_distance_m", r.min_axis_distance_m),
        ] {
            if !v.is_finite() || v.abs() > 10.0 {
                return Err(err(f, key, format!("{v} is not a plausible length in m")));
            }
        }
        let margin = match &spec.sampling {
            Sampling::Random {
                joint_margin_rad, ..
            }
            | Sampling::Grid {
                joint_margin_rad, ..
            } => Some(*joint_margin_rad),
            _ => None,
        };
        if let Some(m) = margin.filter(|m| !(m.is_finite() && *m >= 0.0)) {
            return Err(err(
                f,
                "campaign.joint_margin_rad",
                format!("{m} must be finite and ≥ 0"),
            ));
        }
        if spec
            .payload_com_m
            .iter()
            .any(|v| !v.is_finite() || v.abs() > 2.0)
        {
            return Err(err(
                f,
                "campaign.payload.com_m",
                format!("{:?} is not a plausible offset in m", spec.payload_com_m),
            ));
        }
        check_model_free(&spec, f)?;
        Ok(spec)
    }
}
