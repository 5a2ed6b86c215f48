//! Reading the written files back: the target distances of `truth.parquet` (the median's radix
//! selection) and the column names of a Parquet file.

use super::summary;
use crate::error::{Result, SimError};
use std::path::Path;

/// Calls `visit` with the length of every row's noise-free target `p_tracker` (m), read back from
/// the `truth.parquet` at `path` (the median's radix selection; the values are those simulated, bit
/// for bit, as Parquet stores doubles exactly).
pub(super) fn replay_distances(path: &Path, visit: &mut dyn FnMut(f64)) -> Result<()> {
    use arrow_array::cast::AsArray;
    use arrow_array::types::Float64Type;
    let io = |e: &dyn std::fmt::Display| SimError::Io {
        path: path.to_path_buf(),
        source: std::io::Error::other(format!("reading back: {e}")),
    };
    let f = std::fs::File::open(path).map_err(|e| io(&e))?;
    let b = parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(f)
        .map_err(|e| io(&e))?;
    let mask = parquet::arrow::ProjectionMask::columns(
        b.parquet_schema(),
        ["p_tracker_x", "p_tracker_y", "p_tracker_z"],
    );
    let reader = b
        .with_projection(mask)
        .with_batch_size(1 << 16)
        .build()
        .map_err(|e| io(&e))?;
    for batch in reader {
        let batch = batch.map_err(|e| io(&e))?;
        let col = |name: &str| {
            batch
                .column_by_name(name)
                .and_then(|c| c.as_primitive_opt::<Float64Type>())
                .ok_or_else(|| io(&format!("no Float64 column {name}")))
        };
        let (x, y, z) = (
            col("p_tracker_x")?,
            col("p_tracker_y")?,
            col("p_tracker_z")?,
        );
        for i in 0..batch.num_rows() {
            visit(summary::distance([x.value(i), y.value(i), z.value(i)]));
        }
    }
    Ok(())
}

/// Column names of a Parquet file, in file order (to check what a file holds without interpreting it).
pub fn parquet_column_names(path: &Path) -> Result<Vec<String>> {
    let io = |e: &dyn std::fmt::Display| SimError::Read {
        path: path.to_path_buf(),
        source: std::io::Error::other(e.to_string()),
    };
    let f = std::fs::File::open(path).map_err(|source| SimError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    let b = parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(f)
        .map_err(|e| io(&e))?;
    Ok(b.schema()
        .fields()
        .iter()
        .map(|f| f.name().clone())
        .collect())
}
