//! Checks of a measurement table against the robot it claims to measure (the contract's bad-input rules
//! that need the robot: joint count, URDF limits, units that look wrong).

use super::{MeasurementTable, QUATERNION_NORM_WARNING, table_err};
use crate::error::Result;
use crate::model::{JointKind, JointLimits, Model};
use std::f64::consts::PI;
use std::path::Path;

/// How far a joint value may lie outside its URDF limits before it is an error (rad for rotational
/// joints, m for prismatic ones); values outside by less are a warning.
pub const LIMIT_TOLERANCE: f64 = 0.1;

/// Positions are taken for millimetres when their median distance from their median point exceeds
/// this many times the robot's reach (plus a tool allowance of 0.5 m) …
const MM_SPREAD_FACTOR: f64 = 10.0;
/// … or when their median distance from the tracker origin exceeds this (m).
const MM_DISTANCE: f64 = 100.0;
/// Allowance for the unknown target offset from the flange when judging reach (m).
const TOOL_ALLOWANCE: f64 = 0.5;
/// A median `sigma` above this (m) is more than any laser tracker's uncertainty: probably millimetres.
const SIGMA_LARGE: f64 = 0.01;
/// Plausible robot temperatures (°C).
const TEMP_RANGE: (f64, f64) = (-50.0, 150.0);

/// An upper bound on the distance from the base origin to the flange over all configurations (m): the
/// sum of the distances between consecutive joint origins at home, the flange offset, and the travel
/// of prismatic joints.
pub fn reach_bound(model: &Model) -> f64 {
    let mut prev = nalgebra::Vector3::zeros();
    let mut sum = 0.0;
    for j in model.joints() {
        let p = j.home.translation.vector;
        sum += (p - prev).norm();
        prev = p;
        if j.kind == JointKind::Prismatic {
            sum += j.limits.map_or(1.0, |l| l.lower.abs().max(l.upper.abs()));
        }
    }
    sum + (model.home_flange().translation.vector - prev).norm()
}

fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_unstable_by(f64::total_cmp);
    let m = v.len() / 2;
    if v.len() % 2 == 1 {
        v[m]
    } else {
        0.5 * (v[m - 1] + v[m])
    }
}

/// Checks that every joint value of `table` lies within its joint's URDF limits, exactly (no
/// tolerance): what a table whose joint positions are to be commanded, a campaign's pose file
/// (`[campaign.file]`), must hold. The joint count must be the robot's (checked before). The first
/// value outside, in row order, is an error naming `file`, the 1-based data row, the column (`q1`),
/// the value, the limits and the joint.
pub fn check_within_limits(table: &MeasurementTable, model: &Model, file: &Path) -> Result<()> {
    let nq = model.nq();
    for r in 0..table.len() {
        for (j, joint) in model.joints().iter().enumerate() {
            let Some(l) = joint.limits else { continue };
            let v = table.q[r * nq + j];
            if v < l.lower || v > l.upper {
                let unit = joint.kind.unit();
                return Err(table_err(
                    &file.display().to_string(),
                    Some(r + 1),
                    Some(&format!("q{}", j + 1)),
                    format!(
                        "{v:?} {unit} is outside the limits [{}, {}] {unit} of joint '{}': the robot cannot \
                         be commanded there",
                        l.lower, l.upper, joint.name
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// Checks `table` against the robot `model`; `file` names the table in messages. Returns the warnings
/// (one line each), or the first error:
///
/// * everything [`MeasurementTable::validate`] checks (finite values — `t` included —, non-negative
///   `sigma` and `payload`, `dir` values, shapes);
/// * the joint count must equal the robot's (the error says how many each has);
/// * a joint value outside its URDF limits by more than [`LIMIT_TOLERANCE`] is an error naming row,
///   column, value and limits; outside by less, one warning per joint column (rows counted, worst row);
/// * degrees: a rotational joint column is taken for degrees when its largest |q| exceeds 2π + 0.1
///   and every value × π/180 lies within the joint's limits (± tolerance), or, for a joint without
///   limits (continuous), when its largest |q| exceeds 4π. Such a column gets a warning, and the hint
///   is added to a limit error. Prismatic columns likewise for millimetres (× 1/1000);
/// * millimetres in `x, y, z`: warned when the median distance of the points from their
///   coordinate-wise median exceeds 10 × (reach + 0.5 m), [`reach_bound`], or their median distance from
///   the tracker origin exceeds 100 m. Medians make one stray point irrelevant;
/// * quaternion norms off 1 by more than [`QUATERNION_NORM_WARNING`] (use
///   [`MeasurementTable::unit_orientation`]), a median `sigma` above 1 cm
///   (millimetres?), `temp` outside −50…150 °C (kelvin?): warnings.
pub fn check_against_model(
    table: &MeasurementTable,
    model: &Model,
    file: &Path,
) -> Result<Vec<String>> {
    let mut check = ModelCheck::new(model, file);
    check.add(table, 0)?;
    Ok(check.warnings())
}

/// A joint's values outside its limits within [`LIMIT_TOLERANCE`]: how many, the worst excess
/// (rad or m) and its 1-based row.
#[derive(Clone, Copy, Debug, Default)]
struct Outside {
    count: usize,
    worst: f64,
    row: usize,
}

impl Outside {
    fn note(&mut self, excess: f64, row: usize) {
        self.count += 1;
        if excess > self.worst {
            self.worst = excess;
            self.row = row;
        }
    }
}

/// A joint column as limit messages name it: chain joint `j` (0-based; column `q{j+1}`) or a
/// branch joint (column `q_<name>`).
#[derive(Clone, Copy)]
enum LimitColumn<'a> {
    Chain(usize, &'a str),
    Branch(&'a str),
}

/// One joint's column checked against its limits, made once per column (nothing is allocated per
/// value; the names are written only into an error).
struct Limit<'a> {
    file: &'a str,
    column: LimitColumn<'a>,
    limits: JointLimits,
    kind: JointKind,
}

impl Limit<'_> {
    /// How far `v` (at 1-based file row `row`) lies outside the limits when it does (rad or m),
    /// `None` inside; an error naming the file, row and column beyond [`LIMIT_TOLERANCE`] (`hint`
    /// ends its message).
    fn check(&self, v: f64, row: usize, hint: impl FnOnce() -> String) -> Result<Option<f64>> {
        let l = &self.limits;
        let excess = (l.lower - v).max(v - l.upper);
        if excess <= 0.0 {
            return Ok(None);
        }
        if excess > LIMIT_TOLERANCE {
            let unit = self.kind.unit();
            let (column, joint) = match self.column {
                LimitColumn::Chain(j, name) => (format!("q{}", j + 1), format!("joint '{name}'")),
                LimitColumn::Branch(name) => {
                    (format!("q_{name}"), format!("branch joint '{name}'"))
                }
            };
            return Err(table_err(
                self.file,
                Some(row),
                Some(&column),
                format!(
                    "{v:?} {unit} is outside the limits [{}, {}] {unit} of {joint} by {excess:.4} {unit}, \
                     more than the {LIMIT_TOLERANCE} {unit} tolerance{}",
                    l.lower,
                    l.upper,
                    hint()
                ),
            ));
        }
        Ok(Some(excess))
    }
}

/// [`check_against_model`] over a file read in pieces ([`super::read_chunks`]): [`ModelCheck::add`]
/// each piece with its first file row, then [`ModelCheck::warnings`]. Errors and warnings name
/// file-wide rows; counts and worst values run over every piece. The unit heuristics that need
/// medians (positions and `sigma` in millimetres) judge the first piece, and a column's degree or
/// millimetre hint is judged on the rows read so far. Given the whole table as one piece, it is
/// [`check_against_model`].
pub struct ModelCheck<'a> {
    model: &'a Model,
    name: String,
    pieces: usize,
    /// Per joint: largest |q| so far, and whether every value so far fits the limits as degrees
    /// (rotational) or millimetres (prismatic).
    max_abs: Vec<f64>,
    fits_scaled: Vec<bool>,
    /// Per joint: its values outside the limits within the tolerance.
    outside: Vec<Outside>,
    /// Rows whose quaternion norm is off 1 by more than [`QUATERNION_NORM_WARNING`]: count, worst, row.
    quaternion: (usize, f64, usize),
    /// Temperatures seen: lowest, highest.
    temp: Option<(f64, f64)>,
    /// Warnings judged on the first piece (positions and `sigma` in millimetres).
    first_piece: Vec<String>,
    /// The table's branch columns' joint names (`q_<joint>`), from the first piece.
    branch_names: Vec<String>,
    /// Per branch joint of the model: its values outside the limits within the tolerance.
    branch_outside: Vec<Outside>,
}

impl<'a> ModelCheck<'a> {
    /// A check of the file `file` against `model`, before any piece.
    pub fn new(model: &'a Model, file: &Path) -> Self {
        let nq = model.nq();
        ModelCheck {
            model,
            name: file.display().to_string(),
            pieces: 0,
            max_abs: vec![0.0; nq],
            fits_scaled: vec![true; nq],
            outside: vec![Outside::default(); nq],
            quaternion: (0, 0.0, 0),
            temp: None,
            first_piece: Vec::new(),
            branch_names: Vec::new(),
            branch_outside: vec![Outside::default(); model.branches().len()],
        }
    }

    /// The degree (millimetre) hint of joint `j`'s column, from the rows so far.
    fn hint(&self, j: usize) -> Option<String> {
        let joint = &self.model.joints()[j];
        let (max_abs, fits) = (self.max_abs[j], self.fits_scaled[j]);
        match joint.kind {
            JointKind::Revolute | JointKind::Continuous => {
                let deg = if joint.limits.is_some() {
                    max_abs > 2.0 * PI + LIMIT_TOLERANCE && fits
                } else {
                    max_abs > 4.0 * PI
                };
                deg.then(|| {
                    format!("values up to {max_abs} look like degrees, but radians are expected")
                })
            }
            JointKind::Prismatic => {
                let mm = if let Some(l) = joint.limits {
                    max_abs > l.lower.abs().max(l.upper.abs()) + LIMIT_TOLERANCE && fits
                } else {
                    max_abs > 10.0
                };
                mm.then(|| {
                    format!("values up to {max_abs} look like millimetres, but metres are expected")
                })
            }
        }
    }

    /// Checks the rows of `table`, the file's rows from `first_row` (0-based) on: the first error
    /// (naming the file-wide row), or `Ok` with its warnings kept for [`ModelCheck::warnings`].
    pub fn add(&mut self, table: &MeasurementTable, first_row: usize) -> Result<()> {
        let name = self.name.clone();
        table
            .validate_named(&name)
            .map_err(|e| super::at_file_row(e, first_row, |_| None))?;
        let model = self.model;
        let nq = model.nq();
        if table.n_joints != nq {
            let joints: Vec<&str> = model.joints().iter().map(|j| j.name.as_str()).collect();
            return Err(table_err(
                &name,
                None,
                None,
                format!(
                    "the file has {} joint columns (q1..q{}), but robot '{}' has {nq} joints ({})",
                    table.n_joints,
                    table.n_joints,
                    model.name(),
                    joints.join(", ")
                ),
            ));
        }
        let n = table.len();
        let column = |j: usize| (0..n).map(move |r| table.q[r * nq + j]);

        // Units of joint columns.
        for (j, joint) in model.joints().iter().enumerate() {
            self.max_abs[j] = column(j).fold(self.max_abs[j], |m, v| m.max(v.abs()));
            let scale = match joint.kind {
                JointKind::Revolute | JointKind::Continuous => PI / 180.0,
                JointKind::Prismatic => 1e-3,
            };
            self.fits_scaled[j] = self.fits_scaled[j]
                && joint.limits.is_some_and(|l| {
                    column(j).all(|v| {
                        let s = v * scale;
                        s >= l.lower - LIMIT_TOLERANCE && s <= l.upper + LIMIT_TOLERANCE
                    })
                });
        }

        // URDF limits.
        let chain: Vec<Option<Limit<'_>>> = (model.joints().iter().enumerate())
            .map(|(j, joint)| {
                joint.limits.map(|limits| Limit {
                    file: &name,
                    column: LimitColumn::Chain(j, &joint.name),
                    limits,
                    kind: joint.kind,
                })
            })
            .collect();
        for r in 0..n {
            for (j, at) in chain.iter().enumerate() {
                let Some(at) = at else { continue };
                let row = first_row + r + 1;
                let hint = || {
                    self.hint(j)
                        .map(|h| format!(" (the column's {h})"))
                        .unwrap_or_default()
                };
                if let Some(excess) = at.check(table.q[r * nq + j], row, hint)? {
                    self.outside[j].note(excess, row);
                }
            }
        }

        // Branch joints' limits (`q_<joint>` columns of the model's branch joints).
        if let Some(branch) = &table.branch {
            let width = branch.names.len();
            for (k, column) in branch.names.iter().enumerate() {
                let Some(b) = model.branches().index_of(column) else {
                    continue;
                };
                let joint = &model.branches().joints()[b];
                let Some(limits) = joint.limits else { continue };
                let at = Limit {
                    file: &name,
                    column: LimitColumn::Branch(&joint.name),
                    limits,
                    kind: joint.kind,
                };
                for r in 0..n {
                    let row = first_row + r + 1;
                    if let Some(excess) =
                        at.check(branch.values[r * width + k], row, String::new)?
                    {
                        self.branch_outside[b].note(excess, row);
                    }
                }
            }
        }

        if self.pieces == 0 {
            self.first_piece = self.median_warnings(table);
            self.branch_names = table.branch_names().to_vec();
        }
        self.pieces += 1;

        // Quaternion norms.
        if let Some(o) = &table.orientation {
            for (r, q) in o.iter().enumerate() {
                let dev = (q.iter().map(|v| v * v).sum::<f64>().sqrt() - 1.0).abs();
                if dev > QUATERNION_NORM_WARNING {
                    self.quaternion.0 += 1;
                    if dev > self.quaternion.1 {
                        self.quaternion.1 = dev;
                        self.quaternion.2 = first_row + r + 1;
                    }
                }
            }
        }
        if let Some(t) = &table.temp {
            let lo = t.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = t.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            self.temp = Some(self.temp.map_or((lo, hi), |(a, b)| (a.min(lo), b.max(hi))));
        }
        Ok(())
    }

    /// The branch columns' warnings: columns that name no branch joint (not read), branch joints
    /// without a column (at zero), values outside a branch joint's limits within the tolerance.
    fn branch_warnings(&self) -> Vec<String> {
        let name = &self.name;
        let branches = self.model.branches();
        let quoted = |v: &mut dyn Iterator<Item = &str>| {
            v.map(|n| format!("'{n}'")).collect::<Vec<_>>().join(", ")
        };
        let mut warnings = Vec::new();
        let unknown: Vec<&str> = self
            .branch_names
            .iter()
            .map(String::as_str)
            .filter(|n| branches.index_of(n).is_none())
            .collect();
        if !unknown.is_empty() {
            let known = if branches.is_empty() {
                format!("robot '{}' has none", self.model.name())
            } else {
                format!(
                    "robot '{}' has {}",
                    self.model.name(),
                    quoted(&mut branches.joints().iter().map(|j| j.name.as_str()))
                )
            };
            warnings.push(format!(
                "{name}: column(s) {} name no movable joint of a branch off the chain ({known}): not read",
                unknown
                    .iter()
                    .map(|n| format!("q_{n}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ));
        }
        let missing: Vec<&str> = branches
            .joints()
            .iter()
            .map(|j| j.name.as_str())
            .filter(|j| !self.branch_names.iter().any(|n| n == j))
            .collect();
        if !missing.is_empty() {
            warnings.push(format!(
                "{name}: branch joint(s) {} off the chain have no q_<joint> column: their links load \
                 the chain as if at zero",
                quoted(&mut missing.iter().copied())
            ));
        }
        for (j, &Outside { count, worst, row }) in self.branch_outside.iter().enumerate() {
            if count > 0 {
                let joint = &branches.joints()[j];
                let l = joint.limits.expect("only joints with limits count");
                let unit = joint.kind.unit();
                warnings.push(format!(
                    "{name}: column q_{}: {count} row(s) outside the limits [{}, {}] {unit} by up to \
                     {worst:.4} {unit} (row {row}), within the {LIMIT_TOLERANCE} {unit} tolerance",
                    joint.name, l.lower, l.upper
                ));
            }
        }
        warnings
    }

    /// Positions and `sigma` in millimetres, judged on the medians of `table`.
    fn median_warnings(&self, table: &MeasurementTable) -> Vec<String> {
        let name = &self.name;
        let mut warnings = Vec::new();
        let centre: Vec<f64> = (0..3)
            .map(|k| median(table.position.iter().map(|p| p[k]).collect()))
            .collect();
        let spread = median(
            table
                .position
                .iter()
                .map(|p| {
                    ((p[0] - centre[0]).powi(2)
                        + (p[1] - centre[1]).powi(2)
                        + (p[2] - centre[2]).powi(2))
                    .sqrt()
                })
                .collect(),
        );
        let distance = median(
            table
                .position
                .iter()
                .map(|p| (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt())
                .collect(),
        );
        let reach = reach_bound(self.model);
        if spread > MM_SPREAD_FACTOR * (reach + TOOL_ALLOWANCE) || distance > MM_DISTANCE {
            warnings.push(format!(
                "{name}: columns x, y, z: the points lie a median {spread:.4} from their median point and \
                 {distance:.4} from the tracker origin, but robot '{}' reaches about {reach:.3} m: the \
                 positions look like millimetres, but metres are expected",
                self.model.name()
            ));
        }
        if let Some(s) = &table.sigma {
            let med = median(s.clone());
            if med > SIGMA_LARGE {
                warnings.push(format!(
                    "{name}: column sigma: the median sigma is {med} m, more than any laser tracker's \
                     uncertainty: millimetres? metres are expected"
                ));
            }
        }
        warnings
    }

    /// The warnings over every piece added, one line each, in the order of [`check_against_model`].
    pub fn warnings(&self) -> Vec<String> {
        let name = &self.name;
        let mut warnings = Vec::new();
        for (j, &Outside { count, worst, row }) in self.outside.iter().enumerate() {
            if count > 0 {
                let joint = &self.model.joints()[j];
                let l = joint.limits.expect("only joints with limits count");
                let unit = joint.kind.unit();
                warnings.push(format!(
                    "{name}: column q{}: {count} row(s) outside the limits [{}, {}] {unit} of joint '{}' by up \
                     to {worst:.4} {unit} (row {row}), within the {LIMIT_TOLERANCE} {unit} tolerance",
                    j + 1,
                    l.lower,
                    l.upper,
                    joint.name
                ));
            }
        }
        for j in 0..self.model.nq() {
            if let Some(h) = self.hint(j) {
                warnings.push(format!("{name}: column q{}: {h}", j + 1));
            }
        }
        warnings.extend(self.branch_warnings());
        let (sigma, others): (Vec<&String>, Vec<&String>) = self
            .first_piece
            .iter()
            .partition(|w| w.contains(": column sigma:"));
        warnings.extend(others.into_iter().cloned());
        let (count, worst, worst_row) = self.quaternion;
        if count > 0 {
            warnings.push(format!(
                "{name}: columns qw, qx, qy, qz: {count} row(s) are not unit quaternions within \
                 {QUATERNION_NORM_WARNING} (norm off by up to {worst:.2e}, row {worst_row}); they are \
                 normalised before use"
            ));
        }
        warnings.extend(sigma.into_iter().cloned());
        if let Some((lo, hi)) = self.temp
            && (lo < TEMP_RANGE.0 || hi > TEMP_RANGE.1)
        {
            warnings.push(format!(
                "{name}: column temp: values from {lo} to {hi} are implausible robot temperatures in °C \
                 (kelvin or fahrenheit?); degrees Celsius are expected"
            ));
        }
        warnings
    }
}
