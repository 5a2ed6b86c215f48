//! What kind of joint a joint is, and its limits: shared by the chain's joints ([`crate::model`])
//! and the joints of branches off it ([`crate::branches`]).

/// Kind of a movable joint.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum JointKind {
    /// Rotation about the axis within limits; `q` in rad.
    Revolute,
    /// Rotation about the axis without limits; `q` in rad.
    Continuous,
    /// Translation along the axis; `q` in m.
    Prismatic,
}

impl JointKind {
    /// True for revolute and continuous joints.
    pub fn is_rotational(self) -> bool {
        !matches!(self, JointKind::Prismatic)
    }
    /// Unit of `q` for this joint: `rad` or `m`.
    pub fn unit(self) -> &'static str {
        if self.is_rotational() { "rad" } else { "m" }
    }
}

/// Position and effort limits of one joint from the URDF.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct JointLimits {
    /// Lower position limit (rad or m).
    pub lower: f64,
    /// Upper position limit (rad or m).
    pub upper: f64,
    /// Velocity limit (rad/s or m/s); 0 when the URDF gives none.
    pub velocity: f64,
    /// Effort limit (N m or N); 0 when the URDF gives none.
    pub effort: f64,
}
