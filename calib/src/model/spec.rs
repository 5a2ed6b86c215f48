//! The model specification: which causes extend the kinematic model (at which of their joints), and
//! which learned residual model (if any) corrects what is left. Parsed from and printed as the
//! `--model` name.
//!
//! A cause tied to joints may be limited to some of them: `joint_compliance@2,4` (1-based joint
//! numbers, as the `q1..qN` columns). The parameters of the joints left out are absent from the model
//! (not fixed at zero in the solver); a cause without `@` acts at every joint it has parameters for.

use crate::error::{CalibError, Result};
use crate::model::extensions::Cause;
use crate::model::learned::LearnedKind;
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use std::collections::BTreeMap;

/// Parsed `--model` value: `kinematic`, optionally `+cause` words (each optionally `@` a list of
/// joints) and one `+learned:KIND`. Serialised as its canonical name ([`ModelSpec::name`]).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ModelSpec {
    /// Physical extensions, sorted, without repeats.
    pub causes: Vec<Cause>,
    /// The 0-based joints of each cause limited to some of its joints (`cause@2,4` holds `[1, 3]`),
    /// ascending, without repeats, never empty; a cause absent from the map acts at all its joints.
    /// Use [`ModelSpec::with_joints`] and [`ModelSpec::without`] to keep it in step with `causes`.
    pub joints: BTreeMap<Cause, Vec<usize>>,
    /// Learned residual model kind, if any.
    pub learned: Option<LearnedKind>,
}

impl ModelSpec {
    /// The kinematic model alone.
    pub fn kinematic() -> Self {
        ModelSpec::default()
    }

    /// Whether this is the kinematic model alone: no cause, no learned correction.
    pub fn is_kinematic(&self) -> bool {
        self.causes.is_empty() && self.learned.is_none()
    }

    /// Parses a `+`-joined model name such as `kinematic+joint_compliance+learned:poly`. The word
    /// `kinematic` may be left out; `auto` is not a model (diagnose decides it) and is refused here.
    pub fn parse(text: &str) -> Result<Self> {
        let mut spec = ModelSpec::default();
        let bad = |problem: String| CalibError::BadValue {
            context: "--model".into(),
            field: "model".into(),
            value: text.to_string(),
            problem,
        };
        let learned_words = || {
            LearnedKind::ALL
                .iter()
                .map(|k| k.name())
                .collect::<Vec<_>>()
        };
        if text.trim().is_empty() {
            return Err(bad("empty model name".into()));
        }
        for word in text.split('+').map(str::trim) {
            if word == "kinematic" {
                continue;
            }
            if let Some(kind) = word.strip_prefix("learned:") {
                let Some(kind) = LearnedKind::from_name(kind) else {
                    return Err(bad(format!(
                        "unknown learned model '{kind}' (known: {})",
                        learned_words().join(", ")
                    )));
                };
                if spec.learned.replace(kind).is_some() {
                    return Err(bad("at most one learned:KIND part".into()));
                }
                continue;
            }
            let (cause_word, subset) = match word.split_once('@') {
                Some((c, list)) => (c.trim(), Some(parse_joints(c.trim(), list).map_err(&bad)?)),
                None => (word, None),
            };
            match Cause::from_name(cause_word) {
                Some(c) => {
                    if spec.causes.contains(&c) && spec.joints.get(&c) != subset.as_ref() {
                        return Err(bad(format!(
                            "'{c}' is named twice with different joints; name it once"
                        )));
                    }
                    spec.causes.push(c);
                    if let Some(joints) = subset {
                        spec.joints.insert(c, joints);
                    }
                }
                None if subset.is_some()
                    && (cause_word == "kinematic" || cause_word.starts_with("learned:")) =>
                {
                    return Err(bad(format!(
                        "'{word}': only a cause takes @joints, not '{cause_word}'"
                    )));
                }
                None => {
                    let causes: Vec<&str> = Cause::ALL.iter().map(|c| c.name()).collect();
                    return Err(bad(format!(
                        "unknown model part '{word}' (known: kinematic, {}, learned:{})",
                        causes.join(", "),
                        learned_words().join("|learned:")
                    )));
                }
            }
        }
        spec.causes.sort();
        spec.causes.dedup();
        Ok(spec)
    }

    /// The canonical name: `kinematic`, then the causes (`@` their joints, 1-based, when limited to
    /// some), then `learned:KIND`.
    pub fn name(&self) -> String {
        let mut s = String::from("kinematic");
        for c in &self.causes {
            s.push('+');
            s.push_str(c.name());
            if let Some(joints) = self.joints.get(c) {
                let list: Vec<String> = joints.iter().map(|j| (j + 1).to_string()).collect();
                s.push('@');
                s.push_str(&list.join(","));
            }
        }
        if let Some(k) = self.learned {
            s.push_str("+learned:");
            s.push_str(k.name());
        }
        s
    }

    /// The same model with `cause` added at all its joints (a limit on its joints is lifted).
    pub fn with(&self, cause: Cause) -> Self {
        self.with_joints(cause, None)
    }

    /// The same model with `cause` added at the 0-based `joints` (all its joints with `None`),
    /// replacing its joints if it was there. `joints` are sorted and deduplicated.
    pub fn with_joints(&self, cause: Cause, joints: Option<&[usize]>) -> Self {
        let mut s = self.clone();
        s.causes.push(cause);
        s.causes.sort();
        s.causes.dedup();
        match joints {
            Some(j) => {
                let mut j = j.to_vec();
                j.sort_unstable();
                j.dedup();
                s.joints.insert(cause, j);
            }
            None => {
                s.joints.remove(&cause);
            }
        }
        s
    }

    /// The same model without `cause` (and its joints).
    pub fn without(&self, cause: Cause) -> Self {
        let mut s = self.clone();
        s.causes.retain(|c| *c != cause);
        s.joints.remove(&cause);
        s
    }

    /// The 0-based joints `cause` acts at in this model, `None` for all of them.
    pub fn joints_of(&self, cause: Cause) -> Option<&[usize]> {
        self.joints.get(&cause).map(Vec::as_slice)
    }

    /// Checks the joints named with `@` against a robot with `nq` joints: the one-line error names
    /// `--model` and the joint the robot does not have.
    pub fn check_joints(&self, nq: usize) -> Result<()> {
        for (cause, joints) in &self.joints {
            if let Some(&j) = joints.iter().find(|&&j| j >= nq) {
                return Err(CalibError::BadValue {
                    context: "--model".into(),
                    field: "model".into(),
                    value: self.name(),
                    problem: format!(
                        "{cause} names joint {}, but the robot has {nq} joints (numbered 1 to {nq})",
                        j + 1
                    ),
                });
            }
        }
        Ok(())
    }
}

/// The 0-based joints of `list`, the text after `cause@`: 1-based joint numbers joined by commas,
/// each once. Errors say what is wrong, in a few words.
fn parse_joints(cause: &str, list: &str) -> std::result::Result<Vec<usize>, String> {
    if list.trim().is_empty() {
        return Err(format!(
            "'{cause}@' names no joint (write e.g. {cause}@2,4: joints numbered from 1)"
        ));
    }
    let mut joints = Vec::new();
    for item in list.split(',').map(str::trim) {
        let j: usize = item.parse().map_err(|_| {
            format!("'{item}' in '{cause}@{list}' is not a joint number (joints numbered from 1)")
        })?;
        if j == 0 {
            return Err(format!(
                "joint 0 in '{cause}@{list}': joints are numbered from 1"
            ));
        }
        if joints.contains(&(j - 1)) {
            return Err(format!("joint {j} is named twice in '{cause}@{list}'"));
        }
        joints.push(j - 1);
    }
    joints.sort_unstable();
    Ok(joints)
}

impl Serialize for ModelSpec {
    fn serialize<S: Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        s.serialize_str(&self.name())
    }
}

impl<'de> Deserialize<'de> for ModelSpec {
    fn deserialize<D: Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        let text = String::deserialize(d)?;
        ModelSpec::parse(&text).map_err(serde::de::Error::custom)
    }
}

/// A `--model` choice: a model, or `auto` (what diagnose chooses on the data).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ModelChoice {
    /// Diagnose decides.
    Auto,
    /// This model.
    Model(ModelSpec),
}

impl std::str::FromStr for ModelChoice {
    type Err = CalibError;

    fn from_str(s: &str) -> Result<Self> {
        if s.trim() == "auto" {
            Ok(ModelChoice::Auto)
        } else {
            ModelSpec::parse(s).map(ModelChoice::Model)
        }
    }
}

impl std::fmt::Display for ModelChoice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ModelChoice::Auto => f.pad("auto"),
            ModelChoice::Model(m) => m.fmt(f),
        }
    }
}

impl std::str::FromStr for ModelSpec {
    type Err = CalibError;

    fn from_str(s: &str) -> Result<Self> {
        ModelSpec::parse(s)
    }
}

impl std::fmt::Display for ModelSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.pad(&self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cause_at_some_joints_parses_and_prints_canonically() {
        let s = ModelSpec::parse("kinematic + gear_backlash + joint_compliance@4, 2").unwrap();
        assert_eq!(s.causes, [Cause::JointCompliance, Cause::GearBacklash]);
        assert_eq!(s.joints_of(Cause::JointCompliance), Some(&[1, 3][..]));
        assert_eq!(s.joints_of(Cause::GearBacklash), None);
        assert_eq!(s.name(), "kinematic+joint_compliance@2,4+gear_backlash");
        assert_eq!(ModelSpec::parse(&s.name()).unwrap(), s);
        // The same cause twice with the same joints is one; `with` lifts the limit, `without`
        // drops it with the cause.
        let twice = ModelSpec::parse("joint_compliance@2,4+joint_compliance@4,2").unwrap();
        assert_eq!(twice.name(), "kinematic+joint_compliance@2,4");
        assert_eq!(
            twice.with(Cause::JointCompliance).name(),
            "kinematic+joint_compliance"
        );
        assert_eq!(
            twice.without(Cause::JointCompliance),
            ModelSpec::kinematic()
        );
        assert!(s.check_joints(7).is_ok());
        assert!(s.check_joints(3).is_err());
    }

    #[test]
    fn bad_joint_lists_are_one_line_errors_naming_the_flag() {
        for (text, says) in [
            ("joint_compliance@", "names no joint"),
            ("joint_compliance@x", "'x'"),
            ("joint_compliance@0", "numbered from 1"),
            ("joint_compliance@2,2", "joint 2 is named twice"),
            ("joint_compliance@2,", "''"),
            ("joint_compliance@-1", "'-1'"),
            ("joint_compliance@2+joint_compliance@3", "named twice"),
            ("kinematic@2", "only a cause takes @joints"),
            ("learned:poly@2", "unknown learned model"),
            ("no_such_cause@2", "unknown model part"),
        ] {
            let e = ModelSpec::parse(text).unwrap_err().to_string();
            assert!(e.contains("--model") && e.contains(says), "{text}: {e}");
            assert!(!e.contains('\n'), "{text}: {e}");
        }
        let e = ModelSpec::parse("joint_compliance@9")
            .unwrap()
            .check_joints(7)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("--model") && e.contains("joint 9") && e.contains("7 joints"),
            "{e}"
        );
    }
}
