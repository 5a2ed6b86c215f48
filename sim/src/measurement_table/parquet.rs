//! Parquet reading and writing of the measurement table (see the parent module for the format).

use super::columns::{ColumnValues, ColumnsBuilder};
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
    if columns.campaign {
        b = b.set_column_dictionary_enabled(ColumnPath::from("campaign"), true);
    }
    if columns.dir {
        for j in 1..=n_joints {
            b = b.set_column_dictionary_enabled(ColumnPath::from(format!("dir{j}")), true);
        }
    }
    b.build()
}

/// The Arrow schema of a table's file: `pose` and `campaign` Int64, `dir*` Int8, every other column
/// (the branch joints' `q_<name>` included) Float64.
fn schema(n_joints: usize, columns: OptionalColumns, branch_names: &[String]) -> Arc<Schema> {
    let mut empty = MeasurementTable::new(n_joints, columns);
    if !branch_names.is_empty() {
        empty.branch = Some(super::BranchColumns {
            names: branch_names.to_vec(),
            values: Vec::new(),
        });
    }
    let fields: Vec<Field> = empty
        .column_names()
        .into_iter()
        .map(|name| {
            let dt = if name == "pose" || name == "campaign" {
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
    if let Some(b) = &table.branch {
        let nb = b.names.len();
        for k in 0..nb {
            out.push(f(rows.clone().map(|r| b.values[r * nb + k]).collect()));
        }
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
    if let Some(c) = &table.campaign {
        out.push(Arc::new(Int64Array::from(c[rows.clone()].to_vec())));
    }
    out
}

/// The Parquet bytes of a table assumed valid; `file` names it in errors.
pub(super) fn write_parquet_unchecked(table: &MeasurementTable, file: &str) -> Result<Vec<u8>> {
    let mut w = ParquetTableWriter::with_branch_names(
        Vec::new(),
        table.n_joints,
        table.columns(),
        table.branch_names(),
        file,
    )?;
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
    /// Names of the branch joints (`q_<name>` columns), in column order.
    branch_names: Vec<String>,
    /// Rows written so far (to number the rows of a part in errors).
    rows: usize,
    /// The file, for errors.
    file: String,
}

impl<W: std::io::Write + Send> ParquetTableWriter<W> {
    /// A writer into `sink` of a table with `n_joints` joint columns and the optional `columns`, and
    /// no branch joint columns; `file` names it in errors.
    ///
    /// # Errors
    /// [`SimError::Io`] naming `file` when the parquet writer cannot be made.
    pub fn new(sink: W, n_joints: usize, columns: OptionalColumns, file: &str) -> Result<Self> {
        Self::with_branch_names(sink, n_joints, columns, &[], file)
    }

    /// [`ParquetTableWriter::new`] for a table with the branch joint columns `q_<name>` of
    /// `branch_names` ([`MeasurementTable::branch_names`]; none when empty), written after `q1..qN`.
    ///
    /// # Errors
    /// [`SimError::Table`] naming `file` for a branch joint name that is empty, has blanks at either
    /// end or is given twice; [`SimError::Io`] when the parquet writer cannot be made.
    pub fn with_branch_names(
        sink: W,
        n_joints: usize,
        columns: OptionalColumns,
        branch_names: &[String],
        file: &str,
    ) -> Result<Self> {
        if !branch_names.is_empty() {
            let mut check = MeasurementTable::new(n_joints, columns);
            check.branch = Some(super::BranchColumns {
                names: branch_names.to_vec(),
                values: Vec::new(),
            });
            check.shape_check(file)?;
        }
        let schema = schema(n_joints, columns, branch_names);
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
            branch_names: branch_names.to_vec(),
            rows: 0,
            file: file.to_string(),
        })
    }

    /// Appends the rows of `part`, which must have the writer's columns (branch joint names included,
    /// in the same order) and be valid
    /// ([`MeasurementTable::validate`]; errors name the file and the row in the whole table; pose
    /// ids are checked for reuse within the part).
    ///
    /// # Errors
    /// [`SimError::Table`] for an invalid part, [`SimError::Io`] for a failed write.
    pub fn append(&mut self, part: &MeasurementTable) -> Result<()> {
        if part.n_joints != self.n_joints
            || part.columns() != self.columns
            || part.branch_names() != self.branch_names.as_slice()
        {
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

/// The values of an Arrow array as borrowed typed values ([`ColumnValues`]); nulls are a problem.
fn values(arr: &dyn Array) -> std::result::Result<ColumnValues<'_>, ColumnProblem> {
    if arr.null_count() > 0 {
        let i = (0..arr.len()).find(|&i| arr.is_null(i));
        return Err((i, "missing value (null): a number is required".into()));
    }
    Ok(match arr.data_type() {
        DataType::Float64 => ColumnValues::F64(arr.as_primitive::<Float64Type>().values()),
        DataType::Float32 => ColumnValues::F32(arr.as_primitive::<Float32Type>().values()),
        DataType::Int8 => ColumnValues::I8(arr.as_primitive::<Int8Type>().values()),
        DataType::Int16 => ColumnValues::I16(arr.as_primitive::<Int16Type>().values()),
        DataType::Int32 => ColumnValues::I32(arr.as_primitive::<Int32Type>().values()),
        DataType::Int64 => ColumnValues::I64(arr.as_primitive::<Int64Type>().values()),
        DataType::UInt8 => ColumnValues::U8(arr.as_primitive::<UInt8Type>().values()),
        DataType::UInt16 => ColumnValues::U16(arr.as_primitive::<UInt16Type>().values()),
        DataType::UInt32 => ColumnValues::U32(arr.as_primitive::<UInt32Type>().values()),
        DataType::UInt64 => ColumnValues::U64(arr.as_primitive::<UInt64Type>().values()),
        dt => {
            return Err((
                None,
                format!("has Arrow type {dt}; an integer or floating-point type is required"),
            ));
        }
    })
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
    let mut open = OpenParquet::new(f, file, positions, 65_536)?;
    let mut columns = ColumnsBuilder::new(&open.layout, open.n_rows.min(MAX_RESERVED_ROWS));
    while open.next_batch_into(&mut columns, file)? {}
    let table = columns.finish();
    table.validate_named(file)?;
    Ok(table)
}

/// A Parquet measurement file opened for reading: its resolved columns and a reader of record
/// batches of the contract's columns (the others are not decoded).
pub(super) struct OpenParquet {
    reader: parquet::arrow::arrow_reader::ParquetRecordBatchReader,
    /// The file's columns resolved against the contract.
    pub(super) layout: super::Layout,
    role_of: HashMap<String, Role>,
    /// Rows the file's metadata announces.
    pub(super) n_rows: usize,
}

impl OpenParquet {
    /// Opens `f` (`file` names it in errors), reading batches of at most `batch_rows` rows.
    pub(super) fn new(
        f: std::fs::File,
        file: &str,
        positions: Positions,
        batch_rows: usize,
    ) -> Result<Self> {
        let builder =
            ParquetRecordBatchReaderBuilder::try_new(f).map_err(|e| bad_file(file, &e))?;
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
        let role_of: HashMap<String, Role> = used
            .iter()
            .map(|&i| (names[i].clone(), layout.roles[i]))
            .collect();
        let mask = ProjectionMask::roots(builder.parquet_schema(), used.iter().copied());
        let n_rows = usize::try_from(builder.metadata().file_metadata().num_rows()).unwrap_or(0);
        let reader = builder
            .with_projection(mask)
            .with_batch_size(batch_rows.max(1))
            .build()
            .map_err(|e| bad_file(file, &e))?;
        Ok(OpenParquet {
            reader,
            layout,
            role_of,
            n_rows,
        })
    }

    /// Decodes the next record batch into `columns`; `false` at the end of the file. Errors name
    /// `file` and the file-wide 1-based row (counted by `columns`' rows before the batch).
    pub(super) fn next_batch_into(
        &mut self,
        columns: &mut ColumnsBuilder,
        file: &str,
    ) -> Result<bool> {
        self.next_batch_at(columns, file, 0)
    }

    /// [`OpenParquet::next_batch_into`] for a builder that starts at file row `rows_before` (0-based).
    pub(super) fn next_batch_at(
        &mut self,
        columns: &mut ColumnsBuilder,
        file: &str,
        rows_before: usize,
    ) -> Result<bool> {
        let Some(batch) = self.reader.next() else {
            return Ok(false);
        };
        let batch = batch.map_err(|e| bad_file(file, &e))?;
        let schema = batch.schema();
        let row0 = rows_before + columns.rows();
        for (k, arr) in batch.columns().iter().enumerate() {
            let name = schema.field(k).name().trim();
            let Some(&role) = self.role_of.get(name) else {
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
            let res = values(arr).and_then(|v| columns.add(role, v));
            if let Err((i, message)) = res {
                return Err(table_err(
                    file,
                    i.map(|i| row0 + i + 1),
                    Some(&crate::error::fragment(name)),
                    message,
                ));
            }
        }
        Ok(true)
    }
}

/// "not a readable Parquet file" naming `file`.
fn bad_file(file: &str, e: &dyn std::fmt::Display) -> SimError {
    table_err(
        file,
        None,
        None,
        format!("not a readable Parquet file: {e}"),
    )
}
