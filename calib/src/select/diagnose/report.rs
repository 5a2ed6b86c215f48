//! What `diagnose --report DIR` draws: the numbers of the plots, filled by the diagnosis and not part of
//! its JSON. The rendering (SVG, HTML, Markdown) lives with the command line (`robocal`'s `report`
//! module), on the general plotting crate `plot`.

/// One "residual against regressor" scatter: the held-out residual expressed as the joint-angle error
/// (or growth) that would explain it, against that parameter's regressor.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RegressorPlot {
    /// File stem, e.g. `joint_compliance_joint2`.
    pub file: String,
    /// Title.
    pub title: String,
    /// Horizontal axis label (regressor and unit).
    pub x_label: String,
    /// Vertical axis label (unit).
    pub y_label: String,
    /// Regressor per test row.
    pub x: Vec<f64>,
    /// Partial residual (vertical units) per test row: the residual with the term left out.
    pub before: Vec<f64>,
    /// Residual with the term.
    pub after: Vec<f64>,
    /// Identified slope (vertical units per regressor unit): the fitted line.
    pub slope: f64,
    /// The identified curve instead of a line, when the term is not linear in `x` (a transmission
    /// error against its joint's angle): points `(x, vertical)` in ascending `x`; empty for a line.
    pub curve: Vec<(f64, f64)>,
}

/// What the report draws; filled by the diagnosis, not part of its JSON.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PlotData {
    /// One per finding and named joint (or growth).
    pub regressors: Vec<RegressorPlot>,
    /// Residual of the final model against the joint angle it correlates with, if structure is left.
    pub unexplained: Option<RegressorPlot>,
    /// Test error norms of the kinematic model (m).
    pub test_errors_kinematic_m: Vec<f64>,
    /// Test error norms of the final model (m).
    pub test_errors_final_m: Vec<f64>,
}
