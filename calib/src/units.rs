//! Units of the estimator's parameters, as a typed identity instead of a string.
//!
//! Every parameter the estimator reports carries one of these. They print (and serialise) as the short
//! text the reports and the model file have always used (`rad`, `m`, `rad/(N m)`, `1/K`, …), so the
//! JSON stays as it is.

use serde::{Deserialize, Deserializer, Serialize, Serializer};
use std::fmt;

/// The unit of a parameter value.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Unit {
    /// Radian (angles, rotation components of twists).
    Radian,
    /// Metre (lengths, translation components, prismatic joint offsets).
    Metre,
    /// Radian per newton metre: the compliance of a revolute joint.
    RadianPerNewtonMetre,
    /// Metre per newton: the compliance of a prismatic joint.
    MetrePerNewton,
    /// Radian per kelvin: joint-zero drift with temperature.
    RadianPerKelvin,
    /// Metre per kelvin: prismatic joint-zero drift with temperature.
    MetrePerKelvin,
    /// Per kelvin: linear thermal expansion.
    PerKelvin,
    /// Radian per unit of warm-up `1 − exp(−t/τ)` (thermal drift from time stamps alone).
    RadianPerWarmUp,
    /// Metre per unit of warm-up.
    MetrePerWarmUp,
    /// Dimensionless per unit of warm-up (link growth from time stamps alone).
    PerWarmUp,
    /// Radian per kilogram: a joint's compliance times gravity times the payload's centre of mass
    /// (robot without masses, payload of known mass and unknown centre of mass).
    RadianPerKilogram,
}

impl Unit {
    /// Every unit.
    pub const ALL: [Unit; 11] = [
        Unit::Radian,
        Unit::Metre,
        Unit::RadianPerNewtonMetre,
        Unit::MetrePerNewton,
        Unit::RadianPerKelvin,
        Unit::MetrePerKelvin,
        Unit::PerKelvin,
        Unit::RadianPerWarmUp,
        Unit::MetrePerWarmUp,
        Unit::PerWarmUp,
        Unit::RadianPerKilogram,
    ];

    /// The unit's text, as reports and model files write it.
    pub fn symbol(self) -> &'static str {
        match self {
            Unit::Radian => "rad",
            Unit::Metre => "m",
            Unit::RadianPerNewtonMetre => "rad/(N m)",
            Unit::MetrePerNewton => "m/N",
            Unit::RadianPerKelvin => "rad/K",
            Unit::MetrePerKelvin => "m/K",
            Unit::PerKelvin => "1/K",
            Unit::RadianPerWarmUp => "rad per warm-up",
            Unit::MetrePerWarmUp => "m per warm-up",
            Unit::PerWarmUp => "1 per warm-up",
            Unit::RadianPerKilogram => "rad/kg",
        }
    }

    /// The unit written `text`, if any.
    pub fn from_symbol(text: &str) -> Option<Unit> {
        Unit::ALL.into_iter().find(|u| u.symbol() == text)
    }

    /// `rad` for a rotational quantity, `m` for a translational one.
    pub fn angle_or_length(rotational: bool) -> Unit {
        if rotational {
            Unit::Radian
        } else {
            Unit::Metre
        }
    }
}

impl fmt::Display for Unit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.pad(self.symbol())
    }
}

impl Serialize for Unit {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.symbol())
    }
}

impl<'de> Deserialize<'de> for Unit {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let text = String::deserialize(d)?;
        Unit::from_symbol(&text).ok_or_else(|| {
            serde::de::Error::custom(format!(
                "unknown unit '{text}' (known: {})",
                Unit::ALL.map(Unit::symbol).join(", ")
            ))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn symbols_are_distinct_and_round_trip() {
        for u in Unit::ALL {
            assert_eq!(Unit::from_symbol(u.symbol()), Some(u));
            let json = serde_json::to_string(&u).unwrap();
            assert_eq!(json, format!("\"{}\"", u.symbol()));
            assert_eq!(serde_json::from_str::<Unit>(&json).unwrap(), u);
        }
        assert!(serde_json::from_str::<Unit>("\"furlong\"").is_err());
    }
}
