//! (being written)

/// (being written)
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ThermalDrift {}
