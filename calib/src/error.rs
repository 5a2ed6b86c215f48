//! The one error type of the `calib` crate: bad input and misuse. Outcomes of a solve (converged or
//! not, rank deficiency) are data in the reports, never errors.

/// Everything that makes a calibration, prediction or pose plan impossible to start.
///
/// Each variant carries what a user needs to fix the input (file, row, field, value, counts).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CalibError {
    /// Loading the robot or reading a measurement table failed (the message names file, row, column).
    #[error(transparent)]
    Sim(Box<sim::SimError>),
    /// A value of the input is unusable; `context` names the file and row, `field` the column or key.
    #[error("{context}: {field} = {value}: {problem}")]
    BadValue {
        /// File (and row) the value comes from.
        context: String,
        /// Column or key.
        field: String,
        /// The offending value, as text.
        value: String,
        /// What is wrong with it.
        problem: String,
    },
    /// The data cannot determine the model: too few distinct poses for its identifiable parameters.
    #[error(
        "{context}: {poses} distinct poses give {equations} equations, but the kinematic model of robot \
         '{robot}' has {identifiable} identifiable parameter combinations (the joint axes and zero offsets \
         of {joints} joints, the tracker-to-base transform and the target offset cannot all be \
         determined): at least {needed} distinct poses are needed, and 3 to 10 times that many for a \
         calibration worth having"
    )]
    TooFewPoses {
        /// File (and subset, e.g. `training set`) the poses come from.
        context: String,
        /// Which part of the file's rows: a validation fit's (a fold, a split's training part) or
        /// the fit of every pose.
        part: crate::part::Part,
        /// Robot name.
        robot: String,
        /// Joints of the robot.
        joints: usize,
        /// Distinct pose ids available.
        poses: usize,
        /// Scalar equations they give (3 per pose, 6 with orientation).
        equations: usize,
        /// Identifiable parameter combinations for a generic pose set.
        identifiable: usize,
        /// Distinct poses needed at least (one more equation than parameters, for the noise estimate).
        needed: usize,
    },
    /// A calibrated-model file (MODEL.json) is unreadable or inconsistent.
    #[error("{file}: {message}")]
    ModelFile {
        /// The file.
        file: String,
        /// What is wrong, naming the key.
        message: String,
    },
    /// An input file (a model file, a URDF) could not be opened or read: bad input.
    #[error("{path}: cannot read: {message}")]
    Read {
        /// The file.
        path: String,
        /// What the operating system said.
        message: String,
    },
    /// A file could not be written: a runtime failure, the input was fine.
    #[error("{path}: {message}")]
    Io {
        /// The file.
        path: String,
        /// What the operating system said.
        message: String,
    },
    /// The API was called with arguments that do not fit together (a programming error of the caller).
    #[error("invalid argument: {0}")]
    Misuse(String),
    /// The caller asked the work to stop ([`crate::cancel`]: Ctrl-C in Python); nothing is returned.
    #[error("cancelled")]
    Cancelled,
}

impl From<sim::SimError> for CalibError {
    fn from(e: sim::SimError) -> Self {
        CalibError::Sim(Box::new(e))
    }
}

/// Result alias for the `calib` crate.
pub type Result<T> = std::result::Result<T, CalibError>;
