//! Tables from typed columns: the one conversion from column values to a [`MeasurementTable`], used by
//! the Parquet reader (one Arrow array at a time) and by tables handed over from memory
//! ([`from_columns`]: numpy arrays of the Python package, a pandas or polars DataFrame's columns).
//! Both follow the contract's column rules ([`resolve_columns`]), convert values the same way (any
//! integer or float type whose values convert exactly) and check the result the same way
//! ([`MeasurementTable::validate`]), so a table in memory gets exactly the errors its file would get.

use super::{MeasurementTable, Positions, Role, resolve_columns, table_err};
use crate::error::{Result, fragment};

/// Largest integer magnitude up to which every integer is exactly an `f64` (2⁵³).
const EXACT_INT: i128 = 1 << 53;

/// The values of one column, borrowed in the type they come in (no copy until they enter the table).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ColumnValues<'a> {
    /// 64-bit floats.
    F64(&'a [f64]),
    /// 32-bit floats (widened exactly).
    F32(&'a [f32]),
    /// 8-bit integers.
    I8(&'a [i8]),
    /// 16-bit integers.
    I16(&'a [i16]),
    /// 32-bit integers.
    I32(&'a [i32]),
    /// 64-bit integers.
    I64(&'a [i64]),
    /// 8-bit unsigned integers.
    U8(&'a [u8]),
    /// 16-bit unsigned integers.
    U16(&'a [u16]),
    /// 32-bit unsigned integers.
    U32(&'a [u32]),
    /// 64-bit unsigned integers.
    U64(&'a [u64]),
    /// Values of another type (text, dates, objects), named as the source names it (e.g. `object`):
    /// an error unless the column is one the contract ignores.
    Other(&'a str),
}

impl ColumnValues<'_> {
    /// Number of values (0 for [`ColumnValues::Other`]).
    pub fn len(&self) -> usize {
        match self {
            ColumnValues::F64(v) => v.len(),
            ColumnValues::F32(v) => v.len(),
            ColumnValues::I8(v) => v.len(),
            ColumnValues::I16(v) => v.len(),
            ColumnValues::I32(v) => v.len(),
            ColumnValues::I64(v) => v.len(),
            ColumnValues::U8(v) => v.len(),
            ColumnValues::U16(v) => v.len(),
            ColumnValues::U32(v) => v.len(),
            ColumnValues::U64(v) => v.len(),
            ColumnValues::Other(_) => 0,
        }
    }

    /// True when there are no values.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// One named column of a table in memory.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Column<'a> {
    /// Column name (the contract's: `pose`, `q1`, `x`, …; others are ignored).
    pub name: &'a str,
    /// Its values.
    pub values: ColumnValues<'a>,
    /// 0-based index of the first missing value (a null, `NA`), when the source has any: an error
    /// naming that row, as for a null in a Parquet file.
    pub first_null: Option<usize>,
}

/// A measurement table from columns in memory; `source` names the table in errors (like a file
/// name). The columns follow the contract as a file's do (names, required columns, gaps, types), and
/// the table is checked as [`super::read`] checks a file: the same errors, naming `source`, the row
/// (1-based) and the column.
pub fn from_columns(columns: &[Column<'_>], source: &str) -> Result<MeasurementTable> {
    table_from(columns, source, Positions::Required)
}

/// [`from_columns`] with `x, y, z` optional (zero when absent), as [`super::read_configurations`]:
/// joint configurations for a prediction.
pub fn configurations_from_columns(
    columns: &[Column<'_>],
    source: &str,
) -> Result<MeasurementTable> {
    table_from(columns, source, Positions::Optional)
}

fn table_from(
    columns: &[Column<'_>],
    source: &str,
    positions: Positions,
) -> Result<MeasurementTable> {
    let names: Vec<String> = columns.iter().map(|c| c.name.trim().to_string()).collect();
    let layout = resolve_columns(&names, source, positions)?;
    let used: Vec<(usize, Role)> = (0..columns.len())
        .filter(|&i| layout.roles[i] != Role::Ignore)
        .map(|i| (i, layout.roles[i]))
        .collect();
    let fail = |i: usize, row: Option<usize>, message: String| {
        table_err(source, row, Some(&fragment(&names[i])), message)
    };
    let rows = used
        .iter()
        .find(|(i, _)| !matches!(columns[*i].values, ColumnValues::Other(_)))
        .map(|(i, _)| (*i, columns[*i].values.len()));
    let mut builder = ColumnsBuilder::new(&layout, rows.map_or(0, |(_, n)| n));
    for &(i, role) in &used {
        let c = &columns[i];
        if let Some(k) = c.first_null {
            return Err(fail(
                i,
                Some(k + 1),
                "missing value (null): a number is required".into(),
            ));
        }
        if let (Some((first, n)), false) = (rows, matches!(c.values, ColumnValues::Other(_)))
            && c.values.len() != n
        {
            return Err(fail(
                i,
                None,
                format!(
                    "{} values, but column {} has {n}: every column needs one value per row",
                    c.values.len(),
                    fragment(&names[first])
                ),
            ));
        }
        builder
            .add(role, c.values)
            .map_err(|(row, message)| fail(i, row.map(|r| r + 1), message))?;
    }
    let table = builder.finish();
    table.validate_named(source)?;
    Ok(table)
}

/// A problem in one column: the 0-based index within the values (if one value is at fault) and what.
pub(super) type ColumnProblem = (Option<usize>, String);

/// The values as `f64`, accepting any integer or float type whose values convert exactly.
fn floats(values: ColumnValues<'_>) -> std::result::Result<Vec<f64>, ColumnProblem> {
    fn exact<I: Copy + Into<i128> + std::fmt::Display>(
        v: &[I],
    ) -> std::result::Result<Vec<f64>, ColumnProblem> {
        v.iter()
            .enumerate()
            .map(|(i, &x)| {
                let w: i128 = x.into();
                if w.abs() <= EXACT_INT {
                    Ok(w as f64)
                } else {
                    Err((
                        Some(i),
                        format!("{x} cannot be represented exactly as a 64-bit float"),
                    ))
                }
            })
            .collect()
    }
    Ok(match values {
        ColumnValues::F64(v) => v.to_vec(),
        ColumnValues::F32(v) => v.iter().map(|&x| x as f64).collect(),
        ColumnValues::I8(v) => exact(v)?,
        ColumnValues::I16(v) => exact(v)?,
        ColumnValues::I32(v) => exact(v)?,
        ColumnValues::I64(v) => exact(v)?,
        ColumnValues::U8(v) => exact(v)?,
        ColumnValues::U16(v) => exact(v)?,
        ColumnValues::U32(v) => exact(v)?,
        ColumnValues::U64(v) => exact(v)?,
        ColumnValues::Other(t) => return Err(unsupported(t)),
    })
}

/// The values as `i64`, accepting any integer type in range and floats that are exact integers.
fn integers(values: ColumnValues<'_>) -> std::result::Result<Vec<i64>, ColumnProblem> {
    fn small<I: Copy + Into<i64>>(v: &[I]) -> Vec<i64> {
        v.iter().map(|&x| x.into()).collect()
    }
    fn from_float(v: impl Iterator<Item = f64>) -> std::result::Result<Vec<i64>, ColumnProblem> {
        v.enumerate()
            .map(|(i, x)| {
                if x.fract() == 0.0 && x.abs() < (1u64 << 63) as f64 {
                    Ok(x as i64)
                } else {
                    Err((Some(i), format!("{x:?} is not an integer")))
                }
            })
            .collect()
    }
    Ok(match values {
        ColumnValues::I8(v) => small(v),
        ColumnValues::I16(v) => small(v),
        ColumnValues::I32(v) => small(v),
        ColumnValues::I64(v) => v.to_vec(),
        ColumnValues::U8(v) => small(v),
        ColumnValues::U16(v) => small(v),
        ColumnValues::U32(v) => small(v),
        ColumnValues::U64(v) => v
            .iter()
            .enumerate()
            .map(|(i, &x)| {
                i64::try_from(x)
                    .map_err(|_| (Some(i), format!("{x} is too large for a 64-bit integer")))
            })
            .collect::<std::result::Result<_, _>>()?,
        ColumnValues::F64(v) => from_float(v.iter().copied())?,
        ColumnValues::F32(v) => from_float(v.iter().map(|&x| x as f64))?,
        ColumnValues::Other(t) => return Err(unsupported(t)),
    })
}

fn directions(values: ColumnValues<'_>) -> std::result::Result<Vec<i8>, ColumnProblem> {
    integers(values)?
        .into_iter()
        .enumerate()
        .map(|(i, v)| {
            if (-1..=1).contains(&v) {
                Ok(v as i8)
            } else {
                Err((Some(i), format!("{v} is not a direction (-1, 0 or +1)")))
            }
        })
        .collect()
}

fn unsupported(type_name: &str) -> ColumnProblem {
    (
        None,
        format!(
            "has type {}; an integer or floating-point type is required",
            fragment(type_name)
        ),
    )
}

/// The contract's columns gathered one array at a time (a whole column, or one Parquet batch of it),
/// then laid out as a [`MeasurementTable`] (row-major `q` and `dir`).
pub(super) struct ColumnsBuilder {
    columns: super::OptionalColumns,
    pose: Vec<i64>,
    campaign: Vec<i64>,
    q: Vec<Vec<f64>>,
    /// One column per branch joint (`q_<name>`), in header order.
    branch_names: Vec<String>,
    branch: Vec<Vec<f64>>,
    dir: Vec<Vec<i8>>,
    position: [Vec<f64>; 3],
    quaternion: [Vec<f64>; 4],
    t: Vec<f64>,
    temp: Vec<f64>,
    payload: Vec<f64>,
    sigma: Vec<f64>,
}

impl ColumnsBuilder {
    /// An empty builder for `layout`, with room for `rows` rows of the joint columns.
    pub(super) fn new(layout: &super::Layout, rows: usize) -> Self {
        let nq = layout.n_joints;
        ColumnsBuilder {
            columns: layout.columns,
            pose: Vec::with_capacity(rows),
            campaign: Vec::new(),
            q: vec![Vec::with_capacity(rows); nq],
            branch_names: layout.branch.clone(),
            branch: vec![Vec::with_capacity(rows); layout.branch.len()],
            dir: vec![Vec::new(); if layout.columns.dir { nq } else { 0 }],
            position: Default::default(),
            quaternion: Default::default(),
            t: Vec::new(),
            temp: Vec::new(),
            payload: Vec::new(),
            sigma: Vec::new(),
        }
    }

    /// Rows gathered so far (of the `pose` column).
    pub(super) fn rows(&self) -> usize {
        self.pose.len()
    }

    /// Appends `values` to the column of `role`, converted; the problem names the value's index.
    pub(super) fn add(
        &mut self,
        role: Role,
        values: ColumnValues<'_>,
    ) -> std::result::Result<(), ColumnProblem> {
        match role {
            Role::Ignore => {}
            Role::Pose => self.pose.extend(integers(values)?),
            Role::Campaign => self.campaign.extend(integers(values)?),
            Role::Dir(j) => self.dir[j].extend(directions(values)?),
            _ => {
                let v = floats(values)?;
                match role {
                    Role::Q(j) => self.q[j].extend(v),
                    Role::Branch(k) => self.branch[k].extend(v),
                    Role::Position(i) => self.position[i].extend(v),
                    Role::Quaternion(i) => self.quaternion[i].extend(v),
                    Role::T => self.t.extend(v),
                    Role::Temp => self.temp.extend(v),
                    Role::Payload => self.payload.extend(v),
                    Role::Sigma => self.sigma.extend(v),
                    Role::Ignore | Role::Pose | Role::Campaign | Role::Dir(_) => {}
                }
            }
        }
        Ok(())
    }

    /// The table (not yet validated; the caller runs [`MeasurementTable::validate_named`]). Without
    /// `x, y, z` (joint configurations only, `Positions::Optional`) the positions are zero.
    pub(super) fn finish(self) -> MeasurementTable {
        let nq = self.q.len();
        let n = self.pose.len();
        let mut table = MeasurementTable::with_capacity(nq, self.columns, n);
        table.pose = self.pose;
        for r in 0..n {
            for col in &self.q {
                table.q.push(col[r]);
            }
            let p = |k: usize| self.position[k].get(r).copied().unwrap_or(0.0);
            table.position.push([p(0), p(1), p(2)]);
        }
        let quat = &self.quaternion;
        if let Some(o) = table.orientation.as_mut() {
            o.extend((0..n).map(|r| [quat[0][r], quat[1][r], quat[2][r], quat[3][r]]));
        }
        if let Some(d) = table.dir.as_mut() {
            for r in 0..n {
                d.extend(self.dir.iter().map(|c| c[r]));
            }
        }
        if !self.branch_names.is_empty() {
            let mut values = Vec::with_capacity(n * self.branch.len());
            for r in 0..n {
                values.extend(self.branch.iter().map(|c| c[r]));
            }
            table.branch = Some(super::BranchColumns {
                names: self.branch_names,
                values,
            });
        }
        let c = self.columns;
        table.t = c.t.then_some(self.t);
        table.temp = c.temp.then_some(self.temp);
        table.payload = c.payload.then_some(self.payload);
        table.sigma = c.sigma.then_some(self.sigma);
        table.campaign = c.campaign.then_some(self.campaign);
        table
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn col<'a>(name: &'a str, values: ColumnValues<'a>) -> Column<'a> {
        Column {
            name,
            values,
            first_null: None,
        }
    }

    #[test]
    fn columns_give_the_table_their_csv_gives() {
        let csv = "pose,q1,q2,x,y,z,note\n0,0.5,-1.0,0.1,0.2,0.3,7\n1,0.25,2.0,1.5,-0.5,0.75,8\n";
        let expected = super::super::read_csv_str(csv, "m.csv").unwrap();
        let pose = [0i32, 1];
        let q1 = [0.5f32, 0.25];
        let q2 = [-1.0, 2.0];
        let (x, y, z) = ([0.1, 1.5], [0.2, -0.5], [0.3, 0.75]);
        let cols = [
            col("pose", ColumnValues::I32(&pose)),
            col("q1", ColumnValues::F32(&q1)),
            col("q2", ColumnValues::F64(&q2)),
            col("x", ColumnValues::F64(&x)),
            col("y", ColumnValues::F64(&y)),
            col("z", ColumnValues::F64(&z)),
            col("note", ColumnValues::Other("object")),
        ];
        assert_eq!(from_columns(&cols, "df").unwrap(), expected);
    }

    #[test]
    fn errors_name_the_source_row_and_column_as_for_a_file() {
        let base = |q1: ColumnValues<'static>| {
            vec![
                col("pose", ColumnValues::I64(&[0, 1])),
                col("q1", q1),
                col("x", ColumnValues::F64(&[0.0, 0.0])),
                col("y", ColumnValues::F64(&[0.0, 0.0])),
                col("z", ColumnValues::F64(&[0.0, 0.0])),
            ]
        };
        let e = from_columns(&base(ColumnValues::F64(&[0.5, f64::NAN])), "df").unwrap_err();
        assert_eq!(e.to_string(), "df: row 2, column q1: NaN is not finite");
        let e = from_columns(&base(ColumnValues::Other("object")), "df").unwrap_err();
        assert_eq!(
            e.to_string(),
            "df: column q1: has type object; an integer or floating-point type is required"
        );
        let e = from_columns(&base(ColumnValues::F64(&[0.5])), "df").unwrap_err();
        assert_eq!(
            e.to_string(),
            "df: column q1: 1 values, but column pose has 2: every column needs one value per row"
        );
        let mut cols = base(ColumnValues::F64(&[0.5, 0.25]));
        cols[0].first_null = Some(1);
        let e = from_columns(&cols, "df").unwrap_err();
        assert_eq!(
            e.to_string(),
            "df: row 2, column pose: missing value (null): a number is required"
        );
        cols[0].first_null = None;
        cols.remove(3);
        let e = from_columns(&cols, "df").unwrap_err();
        assert!(
            e.to_string()
                .starts_with("df: column y: missing required column 'y'"),
            "{e}"
        );
        assert!(from_columns(&base(ColumnValues::F32(&[0.5, 1.0])), "df").is_ok());
        let e = from_columns(
            &[
                col("pose", ColumnValues::F64(&[0.5])),
                col("q1", ColumnValues::F64(&[0.0])),
                col("x", ColumnValues::F64(&[0.0])),
                col("y", ColumnValues::F64(&[0.0])),
                col("z", ColumnValues::F64(&[0.0])),
            ],
            "df",
        )
        .unwrap_err();
        assert_eq!(
            e.to_string(),
            "df: row 1, column pose: 0.5 is not an integer"
        );
    }

    #[test]
    fn configurations_need_no_positions() {
        let cols = [
            col("pose", ColumnValues::U8(&[3])),
            col("q1", ColumnValues::I64(&[1])),
        ];
        assert!(from_columns(&cols, "df").is_err());
        let t = configurations_from_columns(&cols, "df").unwrap();
        assert_eq!(
            (t.pose.clone(), t.q.clone(), t.position.clone()),
            (vec![3], vec![1.0], vec![[0.0; 3]])
        );
    }
}
