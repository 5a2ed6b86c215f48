//! The sweep's long table of extension parameters, `FILE.params.parquet` beside `FILE.parquet`: one
//! row per run and identified extension parameter ([`ParamRow`]), in run order and, within a run, in
//! the model file's parameter order. Runs of a kinematic model have no rows here.
//!
//! Written with the same deterministic writer as the wide table (see [`super::table`]): shards merge
//! to the same bytes as a single run.

use arrow_array::{
    Array, ArrayRef, BooleanArray, Float64Array, Int64Array, RecordBatch, StringArray,
};
use arrow_schema::{DataType, Field, Schema};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Rows per row group (a constant, so that the bytes do not depend on how rows arrived).
const ROW_GROUP_ROWS: usize = 65_536;

/// Column names and their meaning, in file order.
pub const COLUMNS: &[(&str, &str)] = &[
    ("run", "run index, as the `run` column of the wide table"),
    (
        "cause",
        "the cause the parameter belongs to (`joint_compliance`, …)",
    ),
    (
        "param",
        "the parameter's id, as in the model file's `extensions.names` (`joint 2 compliance`)",
    ),
    (
        "unit",
        "the parameter's unit (`rad/(N m)`, `rad`, …), as in the model file's `extensions.units`",
    ),
    ("estimate", "identified value (unit)"),
    (
        "truth",
        "the simulator's value in this parameter (unit; 0 when the run did not inject the cause; NaN when it cannot be mapped, see docs/sweep.md)",
    ),
    (
        "sigma",
        "predicted standard deviation of the estimate (unit): √ of the calibration covariance's diagonal, χ²/dof included",
    ),
    (
        "z",
        "(estimate − truth) / sigma; NaN when the truth is not mapped or the parameter is not identifiable on its own",
    ),
    (
        "identifiable",
        "the parameter is determined on its own: less than 0.1 of its scaled direction lies in the Jacobian's null space",
    ),
];

/// One identified extension parameter of one run.
#[derive(Clone, Debug, PartialEq)]
pub struct ParamRow {
    /// Run index.
    pub run: i64,
    /// Cause name.
    pub cause: String,
    /// Parameter id (model file name).
    pub param: String,
    /// Unit symbol.
    pub unit: String,
    /// Identified value (unit).
    pub estimate: f64,
    /// True value (unit), NaN when not mapped.
    pub truth: f64,
    /// Predicted standard deviation (unit).
    pub sigma: f64,
    /// `(estimate − truth) / sigma`, NaN when not scored.
    pub z: f64,
    /// Determined on its own.
    pub identifiable: bool,
}

/// The long table's path beside the sweep file `out`: `FILE.params.parquet`.
pub fn path_beside(out: &Path) -> PathBuf {
    out.with_extension("params.parquet")
}

fn schema() -> Schema {
    let f = |n: &str, t: DataType| Field::new(n, t, false);
    Schema::new(vec![
        f("run", DataType::Int64),
        f("cause", DataType::Utf8),
        f("param", DataType::Utf8),
        f("unit", DataType::Utf8),
        f("estimate", DataType::Float64),
        f("truth", DataType::Float64),
        f("sigma", DataType::Float64),
        f("z", DataType::Float64),
        f("identifiable", DataType::Boolean),
    ])
}

/// Deterministic Parquet bytes of `rows` (in the order given) with the key-value `metadata`.
pub fn parquet_bytes(rows: &[ParamRow], metadata: &[(String, String)]) -> Result<Vec<u8>, String> {
    use parquet::file::metadata::KeyValue;
    let kv: Vec<KeyValue> = metadata
        .iter()
        .map(|(k, v)| KeyValue::new(k.clone(), v.clone()))
        .collect();
    let props = sim::io::deterministic_writer_properties(ROW_GROUP_ROWS)
        .set_key_value_metadata(Some(kv))
        .build();
    let f64s = |g: fn(&ParamRow) -> f64| -> ArrayRef {
        Arc::new(Float64Array::from(rows.iter().map(g).collect::<Vec<_>>()))
    };
    let strs = |g: fn(&ParamRow) -> &str| -> ArrayRef {
        Arc::new(StringArray::from(rows.iter().map(g).collect::<Vec<_>>()))
    };
    let arrays: Vec<ArrayRef> = vec![
        Arc::new(Int64Array::from(
            rows.iter().map(|r| r.run).collect::<Vec<_>>(),
        )),
        strs(|r| &r.cause),
        strs(|r| &r.param),
        strs(|r| &r.unit),
        f64s(|r| r.estimate),
        f64s(|r| r.truth),
        f64s(|r| r.sigma),
        f64s(|r| r.z),
        Arc::new(BooleanArray::from(
            rows.iter().map(|r| r.identifiable).collect::<Vec<_>>(),
        )),
    ];
    let batch = RecordBatch::try_new(Arc::new(schema()), arrays)
        .map_err(|e| format!("cannot build the parameter table: {e}"))?;
    sim::io::parquet_bytes(&batch, props, ROW_GROUP_ROWS)
        .map_err(|e| format!("cannot write Parquet: {e}"))
}

fn column<'a, T: 'static>(batch: &'a RecordBatch, name: &str, file: &str) -> Result<&'a T, String> {
    let col = batch.column_by_name(name).ok_or_else(|| {
        format!("{file}: column '{name}' is missing: not a sweep parameter table")
    })?;
    if col.null_count() > 0 {
        return Err(format!("{file}: column '{name}' has nulls"));
    }
    col.as_any()
        .downcast_ref::<T>()
        .ok_or_else(|| format!("{file}: column '{name}' has type {}", col.data_type()))
}

/// Reads a parameter table; errors are one line naming the file.
pub fn read(path: &Path) -> Result<Vec<ParamRow>, String> {
    use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
    let file = path.display().to_string();
    let f = std::fs::File::open(path).map_err(|e| format!("{file}: cannot open: {e}"))?;
    let reader = ParquetRecordBatchReaderBuilder::try_new(f)
        .and_then(|b| b.build())
        .map_err(|e| format!("{file}: not a Parquet file: {e}"))?;
    let mut rows = Vec::new();
    for batch in reader {
        let b = batch.map_err(|e| format!("{file}: cannot read: {e}"))?;
        let run = column::<Int64Array>(&b, "run", &file)?;
        let cause = column::<StringArray>(&b, "cause", &file)?;
        let param = column::<StringArray>(&b, "param", &file)?;
        let unit = column::<StringArray>(&b, "unit", &file)?;
        let estimate = column::<Float64Array>(&b, "estimate", &file)?;
        let truth = column::<Float64Array>(&b, "truth", &file)?;
        let sigma = column::<Float64Array>(&b, "sigma", &file)?;
        let z = column::<Float64Array>(&b, "z", &file)?;
        let identifiable = column::<BooleanArray>(&b, "identifiable", &file)?;
        for i in 0..b.num_rows() {
            rows.push(ParamRow {
                run: run.value(i),
                cause: cause.value(i).to_string(),
                param: param.value(i).to_string(),
                unit: unit.value(i).to_string(),
                estimate: estimate.value(i),
                truth: truth.value(i),
                sigma: sigma.value(i),
                z: z.value(i),
                identifiable: identifiable.value(i),
            });
        }
    }
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_round_trip_and_bytes_are_reproducible() {
        let rows: Vec<ParamRow> = (0..5)
            .map(|r| ParamRow {
                run: r / 2,
                cause: "joint_compliance".into(),
                param: format!("joint {} compliance", r + 1),
                unit: "rad/(N m)".into(),
                estimate: 1e-4 + r as f64 * 1e-6,
                truth: if r == 3 { f64::NAN } else { 1e-4 },
                sigma: 2e-6,
                z: if r == 3 { f64::NAN } else { r as f64 * 0.5 },
                identifiable: r != 0,
            })
            .collect();
        let meta = vec![("k".to_string(), "v".to_string())];
        let bytes = parquet_bytes(&rows, &meta).unwrap();
        assert_eq!(bytes, parquet_bytes(&rows, &meta).unwrap());
        let dir = std::env::temp_dir().join(format!("robocal_params_table_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("t.params.parquet");
        std::fs::write(&p, &bytes).unwrap();
        let back = read(&p).unwrap();
        assert_eq!(back.len(), rows.len());
        for (a, b) in back.iter().zip(&rows) {
            assert_eq!(
                (a.run, &a.param, a.identifiable),
                (b.run, &b.param, b.identifiable)
            );
            assert_eq!(a.z.to_bits(), b.z.to_bits());
            assert_eq!(a.truth.to_bits(), b.truth.to_bits());
        }
        assert_eq!(
            path_beside(Path::new("a/s.parquet")),
            Path::new("a/s.params.parquet")
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn every_column_is_documented_in_docs_sweep_md() {
        let doc = include_str!("../../docs/sweep.md");
        for (name, _) in COLUMNS {
            assert!(
                doc.contains(&format!("| `{name}` |")),
                "docs/sweep.md misses column {name}"
            );
        }
    }
}
