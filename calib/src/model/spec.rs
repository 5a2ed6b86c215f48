//! The model specification: which causes extend the kinematic model, and which learned residual model
//! (if any) corrects what is left. Parsed from and printed as the `--model` name.

use crate::error::{CalibError, Result};
use crate::model::extensions::Cause;
use crate::model::learned::LearnedKind;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// Parsed `--model` value: `kinematic`, optionally `+cause` words and one `+learned:KIND`.
/// Serialised as its canonical name ([`ModelSpec::name`]).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ModelSpec {
    /// Physical extensions, sorted, without repeats.
    pub causes: Vec<Cause>,
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
            match Cause::from_name(word) {
                Some(c) => spec.causes.push(c),
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

    /// The canonical name: `kinematic`, then the causes, then `learned:KIND`.
    pub fn name(&self) -> String {
        let mut s = String::from("kinematic");
        for c in &self.causes {
            s.push('+');
            s.push_str(c.name());
        }
        if let Some(k) = self.learned {
            s.push_str("+learned:");
            s.push_str(k.name());
        }
        s
    }

    /// The same model with `cause` added.
    pub fn with(&self, cause: Cause) -> Self {
        let mut s = self.clone();
        s.causes.push(cause);
        s.causes.sort();
        s.causes.dedup();
        s
    }
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
