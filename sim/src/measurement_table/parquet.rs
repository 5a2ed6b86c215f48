//! Parquet reading and writing of the measurement table (see the parent module for the format).

use super::columns::{ColumnValues, ColumnsBuilder};
use super::{IN_MEMORY, MeasurementTable, Positions, Role, resolve_columns, table_err};
use crate::error::{Result, SimError};
use arrow_array::cast::AsArray;
use arrow_array::types::{
    Float32Type, Float64Type, Int8Type, Int16Type, Int32Type, Int64Type, UInt8Type, UInt16Type,
    UInt32Type, UInt64Type,
};
use arrow_array::{Array, ArrayRef, Float64Array, Int8Array, Int64Array, RecordBatch};
use arrow_schema::{DataType, Field, Schema};
use parquet::arrow::ArrowWriter;
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

/// Writer properties of a measurement table, all set explicitly so that the bytes depend on the table
/// only.
fn writer_properties(table: &MeasurementTable) -> WriterProperties {
    let mut b = crate::io::deterministic_writer_properties(PARQUET_MAX_ROW_GROUP_ROWS)
        .set_column_dictionary_enabled(ColumnPath::from("pose"), true);
    if table.dir.is_some() {
        for j in 1..=table.n_joints {
            b = b.set_column_dictionary_enabled(ColumnPath::from(format!("dir{j}")), true);
        }
    }
    b.build()
}

/// The Arrow schema of a table's file: `pose` Int64, `dir*` Int8, every other column Float64.
fn schema(table: &MeasurementTable) -> Arc<Schema> {
    let fields: Vec<Field> = table
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
    let fail = |e: &dyn std::fmt::Display| {
        table_err(file, None, None, format!("cannot write Parquet: {e}"))
    };
    let schema = schema(table);
    let mut writer =
        ArrowWriter::try_new(Vec::new(), schema.clone(), Some(writer_properties(table)))
            .map_err(|e| fail(&e))?;
    let n = table.len();
    let mut start = 0;
    while start < n {
        let end = (start + PARQUET_MAX_ROW_GROUP_ROWS).min(n);
        let batch = RecordBatch::try_new(schema.clone(), arrays(table, start..end))
            .map_err(|e| fail(&e))?;
        writer.write(&batch).map_err(|e| fail(&e))?;
        start = end;
    }
    writer.into_inner().map_err(|e| fail(&e))
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

    let mut columns = ColumnsBuilder::new(&layout, n_rows);
    for batch in reader {
        let batch = batch.map_err(|e| bad_file(&e))?;
        let schema = batch.schema();
        let row0 = columns.rows();
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
    }
    let table = columns.finish();
    table.validate_named(file)?;
    Ok(table)
}
