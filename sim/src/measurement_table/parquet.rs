//! Parquet reading and writing of the measurement table (see the parent module for the format).

use super::{
    IN_MEMORY, MeasurementTable, OptionalColumns, Positions, Role, resolve_columns, table_err,
};
use crate::error::{Result, SimError};
use arrow_array::cast::AsArray;
use arrow_array::types::{
    Float32Type, Float64Type, Int8Type, Int16Type, Int32Type, Int64Type, UInt8Type, UInt16Type,
    UInt32Type, UInt64Type,
};
use arrow_array::{Array, ArrayRef, Float64Array, Int8Array, Int64Array, RecordBatch};
use arrow_schema::{DataType, Field, Schema};
use parquet::arrow::ProjectionMask;
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use parquet::file::properties::WriterProperties;
use parquet::schema::types::ColumnPath;
use std::collections::HashMap;
use std::path::Path;
use std::sync::Arc;

/// Most rows in one Parquet row group (about 16 MB of a 16-column table); smaller tables are one group.
pub const PARQUET_MAX_ROW_GROUP_ROWS: usize = 131_072;

/// Largest integer magnitude up to which every integer is exactly an `f64` (2⁵³).
const EXACT_INT: i128 = 1 << 53;

/// The Parquet bytes of `table` (deterministic: the same table always gives the same bytes). Fails if
/// the table is invalid ([`MeasurementTable::validate`]), naming it [`IN_MEMORY`].
pub fn write_parquet_bytes(table: &MeasurementTable) -> Result<Vec<u8>> {
    table.validate_named(IN_MEMORY)?;
    write_parquet_unchecked(table, IN_MEMORY)
}

/// Writer properties of a measurement table with `n_joints` joints and the optional `columns`, all set
/// explicitly so that the bytes depend on the rows only.
fn writer_properties(n_joints: usize, columns: OptionalColumns) -> WriterProperties {
    let mut b = crate::io::deterministic_writer_properties(PARQUET_MAX_ROW_GROUP_ROWS)
        .set_column_dictionary_enabled(ColumnPath::from("pose"), true);
    if columns.dir {
        for j in 1..=n_joints {
            b = b.set_column_dictionary_enabled(ColumnPath::from(format!("dir{j}")), true);
        }
    }
    b.build()
}

/// The Arrow schema of a table's file: `pose` Int64, `dir*` Int8, every other column Float64.
fn schema(n_joints: usize, columns: OptionalColumns) -> Arc<Schema> {
    let fields: Vec<Field> = MeasurementTable::new(n_joints, columns)
        .column_names()
        .into_iter()
        .map(|name| {
            let dt = if name == "pose" {
                DataType::Int64
            } else if name.starts_with("dir") {
                DataType::Int8
            } else {
                DataType::Float64
            };
            Field::new(name, dt, false)
        })
        .collect();
    Arc::new(Schema::new(fields))
}

/// The columns of rows `rows` as Arrow arrays, in [`MeasurementTable::column_names`] order.
fn arrays(table: &MeasurementTable, rows: std::ops::Range<usize>) -> Vec<ArrayRef> {
    let nq = table.n_joints;
    let f = |v: Vec<f64>| Arc::new(Float64Array::from(v)) as ArrayRef;
    let mut out: Vec<ArrayRef> = vec![Arc::new(Int64Array::from(
        table.pose[rows.clone()].to_vec(),
    ))];
    for j in 0..nq {
        out.push(f(rows.clone().map(|r| table.q[r * nq + j]).collect()));
    }
    for k in 0..3 {
        out.push(f(rows.clone().map(|r| table.position[r][k]).collect()));
    }
    if let Some(o) = &table.orientation {
        out.extend((0..4).map(|k| f(rows.clone().map(|r| o[r][k]).collect())));
    }
    for c in [&table.t, &table.temp].into_iter().flatten() {
        out.push(f(c[rows.clone()].to_vec()));
    }
    if let Some(d) = &table.dir {
        for j in 0..nq {
            let v: Vec<i8> = rows.clone().map(|r| d[r * nq + j]).collect();
            out.push(Arc::new(Int8Array::from(v)));
        }
    }
    for c in [&table.payload, &table.sigma].into_iter().flatten() {
        out.push(f(c[rows.clone()].to_vec()));
    }
    out
}

/// The Parquet bytes of a table assumed valid; `file` names it in errors.
pub(super) fn write_parquet_unchecked(table: &MeasurementTable, file: &str) -> Result<Vec<u8>> {
    let mut w = ParquetTableWriter::new(Vec::new(), table.n_joints, table.columns(), file)?;
    w.append_unchecked(table)?;
    w.finish()
}

/// A measurement table written to Parquet part by part, rows appended in order: the file is the one
/// [`super::write`] gives for the whole table, byte for byte, however the rows are split into parts
/// ([`crate::io::ParquetStream`]). Memory is one row group, whatever the number of rows. Used by
/// `robocal generate`, which streams campaigns of any size.
pub struct ParquetTableWriter<W: std::io::Write + Send> {
    stream: crate::io::ParquetStream<W>,
    schema: Arc<Schema>,
    n_joints: usize,
    columns: OptionalColumns,
    /// Rows written so far (to number the rows of a part in errors).
    rows: usize,
    /// The file, for errors.
    file: String,
}

impl<W: std::io::Write + Send> ParquetTableWriter<W> {
    /// A writer into `sink` of a table with `n_joints` joint columns and the optional `columns`;
    /// `file` names it in errors.
    ///
    /// # Errors
    /// [`SimError::Io`] naming `file` when the parquet writer cannot be made.
    pub fn new(sink: W, n_joints: usize, columns: OptionalColumns, file: &str) -> Result<Self> {
        let schema = schema(n_joints, columns);
        let stream = crate::io::ParquetStream::new(
            sink,
            schema.clone(),
            writer_properties(n_joints, columns),
            PARQUET_MAX_ROW_GROUP_ROWS,
        )
        .map_err(|e| write_err(file, &e))?;
        Ok(ParquetTableWriter {
            stream,
            schema,
            n_joints,
            columns,
            rows: 0,
            file: file.to_string(),
        })
    }

    /// Appends the rows of `part`, which must have the writer's columns and be valid
    /// ([`MeasurementTable::validate`]; errors name the file and the row in the whole table; pose
    /// ids are checked for reuse within the part).
    ///
    /// # Errors
    /// [`SimError::Table`] for an invalid part, [`SimError::Io`] for a failed write.
    pub fn append(&mut self, part: &MeasurementTable) -> Result<()> {
        if part.n_joints != self.n_joints || part.columns() != self.columns {
            return Err(table_err(
                &self.file,
                None,
                None,
                "a part with other columns than the table's".into(),
            ));
        }
        let offset = self.rows;
        part.validate_named(&self.file).map_err(|mut e| {
            if let SimError::Table { row: Some(r), .. } = &mut e {
                *r += offset;
            }
            e
        })?;
        self.append_unchecked(part)
    }

    fn append_unchecked(&mut self, part: &MeasurementTable) -> Result<()> {
        let n = part.len();
        let batch = RecordBatch::try_new(self.schema.clone(), arrays(part, 0..n))
            .map_err(|e| write_err(&self.file, &e))?;
        self.stream
            .write(&batch)
            .map_err(|e| write_err(&self.file, &e))?;
        self.rows += n;
        Ok(())
    }

    /// Rows written so far.
    pub fn rows(&self) -> usize {
        self.rows
    }

    /// Writes the rest and the footer; returns the sink.
    ///
    /// # Errors
    /// [`SimError::Io`] for a failed write.
    pub fn finish(self) -> Result<W> {
        let file = self.file;
        self.stream.finish().map_err(|e| write_err(&file, &e))
    }
}

/// A write failure of the table `file` (the sink failed, or the encoder): [`SimError::Io`], a runtime
/// failure, not a bad table.
fn write_err(file: &str, e: &dyn std::fmt::Display) -> SimError {
    SimError::Io {
        path: std::path::PathBuf::from(file),
        source: std::io::Error::other(format!("Parquet: {e}")),
    }
}

/// A problem in one column: the 0-based index within the array (if one value is at fault) and what.
type ColumnProblem = (Option<usize>, String);

fn first_null(arr: &dyn Array) -> std::result::Result<(), ColumnProblem> {
    if arr.null_count() == 0 {
        return Ok(());
    }
    let i = (0..arr.len()).find(|&i| arr.is_null(i));
    Err((i, "missing value (null): a number is required".into()))
}

fn unsupported(dt: &DataType) -> ColumnProblem {
    (
        None,
        format!("has Arrow type {dt}; an integer or floating-point type is required"),
    )
}

/// A numeric column as `f64`, accepting any integer or float type whose values convert exactly.
fn floats(arr: &dyn Array) -> std::result::Result<Vec<f64>, ColumnProblem> {
    first_null(arr)?;
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
    Ok(match arr.data_type() {
        DataType::Float64 => arr.as_primitive::<Float64Type>().values().to_vec(),
        DataType::Float32 => arr
            .as_primitive::<Float32Type>()
            .values()
            .iter()
            .map(|&v| v as f64)
            .collect(),
        DataType::Int8 => exact(arr.as_primitive::<Int8Type>().values())?,
        DataType::Int16 => exact(arr.as_primitive::<Int16Type>().values())?,
        DataType::Int32 => exact(arr.as_primitive::<Int32Type>().values())?,
        DataType::Int64 => exact(arr.as_primitive::<Int64Type>().values())?,
        DataType::UInt8 => exact(arr.as_primitive::<UInt8Type>().values())?,
        DataType::UInt16 => exact(arr.as_primitive::<UInt16Type>().values())?,
        DataType::UInt32 => exact(arr.as_primitive::<UInt32Type>().values())?,
        DataType::UInt64 => exact(arr.as_primitive::<UInt64Type>().values())?,
        dt => return Err(unsupported(dt)),
    })
}

/// An integer column as `i64`, accepting any integer type in range and floats that are exact integers.
fn integers(arr: &dyn Array) -> std::result::Result<Vec<i64>, ColumnProblem> {
    first_null(arr)?;
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
    Ok(match arr.data_type() {
        DataType::Int8 => small(arr.as_primitive::<Int8Type>().values()),
        DataType::Int16 => small(arr.as_primitive::<Int16Type>().values()),
        DataType::Int32 => small(arr.as_primitive::<Int32Type>().values()),
        DataType::Int64 => arr.as_primitive::<Int64Type>().values().to_vec(),
        DataType::UInt8 => small(arr.as_primitive::<UInt8Type>().values()),
        DataType::UInt16 => small(arr.as_primitive::<UInt16Type>().values()),
        DataType::UInt32 => small(arr.as_primitive::<UInt32Type>().values()),
        DataType::UInt64 => arr
            .as_primitive::<UInt64Type>()
            .values()
            .iter()
            .enumerate()
            .map(|(i, &x)| {
                i64::try_from(x)
                    .map_err(|_| (Some(i), format!("{x} is too large for a 64-bit integer")))
            })
            .collect::<std::result::Result<_, _>>()?,
        DataType::Float64 => {
            from_float(arr.as_primitive::<Float64Type>().values().iter().copied())?
        }
        DataType::Float32 => from_float(
            arr.as_primitive::<Float32Type>()
                .values()
                .iter()
                .map(|&v| v as f64),
        )?,
        dt => return Err(unsupported(dt)),
    })
}

fn directions(arr: &dyn Array) -> std::result::Result<Vec<i8>, ColumnProblem> {
    integers(arr)?
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

/// Rows reserved up front from the file's own row count; beyond, the columns grow as rows arrive (a
/// corrupt footer can claim any count).
const MAX_RESERVED_ROWS: usize = 1 << 20;

/// Reads a Parquet measurement table; `file` is the name shown in errors. A panic of the Parquet
/// decoder on a corrupt file becomes the same one-line error as a decoding failure
/// ([`crate::decoder_guard`]).
pub(super) fn read_parquet_file(
    path: &Path,
    file: &str,
    positions: Positions,
) -> Result<MeasurementTable> {
    let f = std::fs::File::open(path).map_err(|e| SimError::Read {
        path: path.to_path_buf(),
        source: e,
    })?;
    crate::decoder_guard::contain(|| read_parquet(f, file, positions)).unwrap_or_else(|message| {
        Err(table_err(
            file,
            None,
            None,
            format!(
                "not a readable Parquet file: the decoder failed ({}): is the file corrupt?",
                crate::error::fragment_n(&message, 120)
            ),
        ))
    })
}

fn read_parquet(f: std::fs::File, file: &str, positions: Positions) -> Result<MeasurementTable> {
    let bad_file = |e: &dyn std::fmt::Display| {
        table_err(
            file,
            None,
            None,
            format!("not a readable Parquet file: {e}"),
        )
    };
    let builder = ParquetRecordBatchReaderBuilder::try_new(f).map_err(|e| bad_file(&e))?;
    let names: Vec<String> = builder
        .schema()
        .fields()
        .iter()
        .map(|f| f.name().trim().to_string())
        .collect();
    let layout = resolve_columns(&names, file, positions)?;
    let used: Vec<usize> = (0..names.len())
        .filter(|&i| layout.roles[i] != Role::Ignore)
        .collect();
    let role_of: HashMap<&str, Role> = used
        .iter()
        .map(|&i| (names[i].as_str(), layout.roles[i]))
        .collect();
    let mask = ProjectionMask::roots(builder.parquet_schema(), used.iter().copied());
    let n_rows = usize::try_from(builder.metadata().file_metadata().num_rows())
        .unwrap_or(0)
        .min(MAX_RESERVED_ROWS);
    let reader = builder
        .with_projection(mask)
        .with_batch_size(65_536)
        .build()
        .map_err(|e| bad_file(&e))?;

    let nq = layout.n_joints;
    let mut pose: Vec<i64> = Vec::with_capacity(n_rows);
    let mut q_cols: Vec<Vec<f64>> = vec![Vec::with_capacity(n_rows); nq];
    let mut dir_cols: Vec<Vec<i8>> = vec![Vec::new(); if layout.columns.dir { nq } else { 0 }];
    let mut pos_cols: [Vec<f64>; 3] = Default::default();
    let mut quat_cols: [Vec<f64>; 4] = Default::default();
    let (mut t, mut temp, mut payload, mut sigma) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut row0 = 0usize;
    for batch in reader {
        let batch = batch.map_err(|e| bad_file(&e))?;
        let schema = batch.schema();
        for (k, arr) in batch.columns().iter().enumerate() {
            let name = schema.field(k).name().trim();
            let Some(&role) = role_of.get(name) else {
                continue;
            };
            // A dictionary-typed column (a pandas categorical, say) as its plain values.
            let plain;
            let arr = match arr.as_any_dictionary_opt() {
                Some(dict) => {
                    plain = arrow_select::take::take(dict.values().as_ref(), dict.keys(), None)
                        .map_err(|e| {
                            table_err(file, None, Some(name), format!("dictionary: {e}"))
                        })?;
                    plain.as_ref()
                }
                None => arr.as_ref(),
            };
            let res = match role {
                Role::Ignore => Ok(()),
                Role::Pose => integers(arr).map(|v| pose.extend(v)),
                Role::Dir(j) => directions(arr).map(|v| dir_cols[j].extend(v)),
                _ => floats(arr).map(|v| match role {
                    Role::Q(j) => q_cols[j].extend(v),
                    Role::Position(i) => pos_cols[i].extend(v),
                    Role::Quaternion(i) => quat_cols[i].extend(v),
                    Role::T => t.extend(v),
                    Role::Temp => temp.extend(v),
                    Role::Payload => payload.extend(v),
                    Role::Sigma => sigma.extend(v),
                    Role::Ignore | Role::Pose | Role::Dir(_) => {}
                }),
            };
            if let Err((i, message)) = res {
                return Err(table_err(
                    file,
                    i.map(|i| row0 + i + 1),
                    Some(&crate::error::fragment(name)),
                    message,
                ));
            }
        }
        row0 += batch.num_rows();
    }

    let n = pose.len();
    let mut table = MeasurementTable::with_capacity(nq, layout.columns, n);
    table.pose = pose;
    for r in 0..n {
        for col in &q_cols {
            table.q.push(col[r]);
        }
        // Without x, y, z (joint configurations only, `Positions::Optional`): zero.
        let p = |k: usize| pos_cols[k].get(r).copied().unwrap_or(0.0);
        table.position.push([p(0), p(1), p(2)]);
    }
    if let Some(o) = table.orientation.as_mut() {
        o.extend((0..n).map(|r| {
            [
                quat_cols[0][r],
                quat_cols[1][r],
                quat_cols[2][r],
                quat_cols[3][r],
            ]
        }));
    }
    if let Some(d) = table.dir.as_mut() {
        for r in 0..n {
            d.extend(dir_cols.iter().map(|c| c[r]));
        }
    }
    let c = layout.columns;
    table.t = c.t.then_some(t);
    table.temp = c.temp.then_some(temp);
    table.payload = c.payload.then_some(payload);
    table.sigma = c.sigma.then_some(sigma);
    table.validate_named(file)?;
    Ok(table)
}
