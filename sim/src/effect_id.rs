//! The typed identity of every injected effect ([`EffectId`]) and the registry that lists them: one
//! line per effect, in stage order.
//!
//! A leaf: it imports nothing, so that [`crate::error::SimError`] can name the effect of an error by
//! its id, below everything that can fail. [`crate::effects`] expands the same list into the effect
//! containers and the stage loop (see [`crate::effects`], "One effect, one file").

/// The registry: calls `$callback!` with one line per effect, in stage order, each
/// `key: module::Type => Id = "name"`:
///
/// * `key` names the scenario section `[effects.<key>]`, the `truth.json` entry `effects.<key>`, the
///   `truth.parquet` columns `<key>_{x,y,z}` and the fields of the effect containers;
/// * `module::Type` is the effect's parameter type in `sim/src/effects/<module>.rs`;
/// * `Id` is its [`EffectId`] variant and `"name"` its name in summaries and errors.
///
/// Adding an effect is one module in `sim/src/effects/` and one line here.
macro_rules! for_each_effect {
    ($callback:ident) => {
        $callback! {
            /// Thermal drift.
            thermal: thermal_drift::ThermalDrift => ThermalDrift = "thermal_drift",
            /// Kinematic offsets (geometric errors).
            kinematic: kinematic_offsets::KinematicOffsets => KinematicOffsets = "kinematic_offsets",
            /// Transmission error (periodic in the joint's own angle).
            transmission: transmission_error::TransmissionError => TransmissionError
                = "transmission_error",
            /// Joint coupling (link angle error proportional to a joint angle).
            coupling: joint_coupling::JointCoupling => JointCoupling = "joint_coupling",
            /// Coupled transmission error (link angle error periodic in another joint's angle).
            coupled_transmission: coupled_transmission::CoupledTransmission => CoupledTransmission
                = "coupled_transmission_error",
            /// Gear backlash.
            backlash: gear_backlash::GearBacklash => GearBacklash = "gear_backlash",
            /// Joint compliance.
            compliance: joint_compliance::JointCompliance => JointCompliance = "joint_compliance",
            /// Link deflection (compliance across the joint axes), settled with the joint springs;
            /// the last stage.
            deflection: link_deflection::LinkDeflection => LinkDeflection = "link_deflection",
        }
    };
}
pub(crate) use for_each_effect;

/// Generates [`EffectId`] from the registry lines.
macro_rules! effect_ids {
    ($( $(#[$doc:meta])* $key:ident : $ty:ty => $id:ident = $name:literal ),+ $(,)?) => {
        /// Typed identity of an injected effect; [`EffectId::ALL`] lists them in stage order.
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize)]
        #[serde(rename_all = "snake_case")]
        pub enum EffectId {
            $( $(#[$doc])* $id, )+
        }

        impl EffectId {
            /// Every effect, in stage order.
            pub const ALL: &'static [EffectId] = &[$(EffectId::$id),+];

            /// Name in summaries and errors (`gear_backlash`).
            pub const fn name(self) -> &'static str {
                match self {
                    $( EffectId::$id => $name, )+
                }
            }

            /// Key of the scenario section, `truth.json` entry and `truth.parquet` columns
            /// (`backlash`).
            pub const fn key(self) -> &'static str {
                match self {
                    $( EffectId::$id => stringify!($key), )+
                }
            }
        }
    };
}

for_each_effect!(effect_ids);

impl std::fmt::Display for EffectId {
    /// The name ([`EffectId::name`]).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::EffectId;

    #[test]
    fn names_and_keys_are_unique_and_display_is_the_name() {
        let mut names: Vec<&str> = EffectId::ALL.iter().map(|id| id.name()).collect();
        let mut keys: Vec<&str> = EffectId::ALL.iter().map(|id| id.key()).collect();
        names.sort_unstable();
        names.dedup();
        keys.sort_unstable();
        keys.dedup();
        assert_eq!(names.len(), EffectId::ALL.len());
        assert_eq!(keys.len(), EffectId::ALL.len());
        assert_eq!(EffectId::GearBacklash.to_string(), "gear_backlash");
        assert_eq!(EffectId::GearBacklash.key(), "backlash");
        assert_eq!(
            EffectId::CoupledTransmission.to_string(),
            "coupled_transmission_error"
        );
    }
}
