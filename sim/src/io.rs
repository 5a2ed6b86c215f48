//! The project's one way of writing files: atomically, and (for Parquet) deterministically.
//!
//! * [`write_atomic`] writes bytes to a temporary file with a unique name in the destination's own
//!   folder, syncs it and renames it over the destination, so that a reader sees the old file or the
//!   new one, never a half-written one; on every failure the temporary file is removed.
//! * [`deterministic_writer_properties`] fixes every Parquet writer setting that shapes the bytes, and
//!   [`parquet_bytes`] writes one record batch with them in row groups of a bounded size: the same data
//!   always gives the same bytes, whatever the parquet crate's defaults become.
//!
//! Every file that `sim`, `calib` and the `robocal` command line write goes through here (measurement
//! tables, `truth.parquet`, `truth.json`, calibrated models, predictions, sweep tables, reports).
//!
//! ```
//! let dir = std::env::temp_dir().join(format!("sim-io-doctest-{}", std::process::id()));
//! std::fs::create_dir_all(&dir).unwrap();
//! let path = dir.join("hello.txt");
//! sim::io::write_atomic(&path, b"hello").unwrap();
//! assert_eq!(std::fs::read(&path).unwrap(), b"hello");
//! // Only the file itself is left in the folder: the temporary file was renamed over it.
//! assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
//! std::fs::remove_dir_all(&dir).unwrap();
//! ```

use crate::error::{Result, SimError};
use arrow_array::RecordBatch;
use parquet::arrow::ArrowWriter;
use parquet::basic::Compression;
use parquet::errors::ParquetError;
use parquet::file::properties::{
    DEFAULT_CREATED_BY, EnabledStatistics, WriterProperties, WriterPropertiesBuilder, WriterVersion,
};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// Temporary files written by this process so far: with the process id, a name no other writer uses.
static TEMP_COUNTER: AtomicU64 = AtomicU64::new(0);

/// Writes `bytes` to `path` atomically: to a temporary file `.NAME.tmp-PID-N` in `path`'s folder
/// (unique within and across processes), synced to disk, then renamed over `path`. On any failure the
/// temporary file is removed and `path` is left as it was.
///
/// # Errors
/// [`SimError::Io`] naming `path` when `path` has no file name, or the folder does not exist or is not
/// writable, or the write, sync or rename fails.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let io_err = |source: std::io::Error| SimError::Io {
        path: path.to_path_buf(),
        source,
    };
    let name = path.file_name().ok_or_else(|| {
        io_err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            "not a file name",
        ))
    })?;
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let tmp = dir.join(format!(
        ".{}.tmp-{}-{}",
        name.to_string_lossy(),
        std::process::id(),
        TEMP_COUNTER.fetch_add(1, Ordering::Relaxed)
    ));
    let result = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        drop(f);
        std::fs::rename(&tmp, path)
    })();
    result.map_err(|source| {
        // The temporary file may not exist (creation failed); nothing else can be done about it.
        let _ = std::fs::remove_file(&tmp);
        io_err(source)
    })
}

/// Parquet writer properties with every setting that shapes the bytes fixed explicitly (writer version
/// 1.0, the parquet crate's creator string, Snappy, row groups of at most `max_row_group_rows` rows
/// and no byte limit, write batches of 1024 values, data pages of at most 1 MiB and 20,000 rows,
/// chunk statistics, no bloom filters, no key-value metadata, no sorting columns, no dictionaries), so
/// that the bytes depend on the data only. Every deterministic Parquet file of the project starts here;
/// callers may add to it (dictionaries for chosen columns, key-value metadata).
pub fn deterministic_writer_properties(max_row_group_rows: usize) -> WriterPropertiesBuilder {
    WriterProperties::builder()
        .set_writer_version(WriterVersion::PARQUET_1_0)
        .set_created_by(DEFAULT_CREATED_BY.to_string())
        .set_compression(Compression::SNAPPY)
        .set_max_row_group_row_count(Some(max_row_group_rows))
        .set_max_row_group_bytes(None)
        .set_write_batch_size(1024)
        .set_data_page_size_limit(1024 * 1024)
        .set_data_page_row_count_limit(20_000)
        .set_statistics_enabled(EnabledStatistics::Chunk)
        .set_bloom_filter_enabled(false)
        .set_key_value_metadata(None)
        .set_sorting_columns(None)
        .set_dictionary_enabled(false)
}

/// The Parquet file bytes of `batch` written with `props`, in row groups of at most
/// `max_row_group_rows` rows (the batch is sliced, never copied).
///
/// # Errors
/// What the parquet writer reports (a schema it cannot encode).
pub fn parquet_bytes(
    batch: &RecordBatch,
    props: WriterProperties,
    max_row_group_rows: usize,
) -> std::result::Result<Vec<u8>, ParquetError> {
    let mut w = ArrowWriter::try_new(Vec::new(), batch.schema(), Some(props))?;
    let n = batch.num_rows();
    let step = max_row_group_rows.max(1);
    let mut start = 0;
    while start < n {
        let len = (n - start).min(step);
        w.write(&batch.slice(start, len))?;
        start += len;
    }
    w.into_inner()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp_dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("sim-io-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn names(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn replaces_the_file_and_leaves_no_temporary_file() {
        let dir = temp_dir("replace");
        let p = dir.join("a.txt");
        std::fs::write(&p, "old").unwrap();
        write_atomic(&p, b"new").unwrap();
        write_atomic(&p, b"newer").unwrap();
        assert_eq!(std::fs::read_to_string(&p).unwrap(), "newer");
        assert_eq!(names(&dir), vec!["a.txt".to_string()]);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn failures_name_the_file_and_leave_nothing_behind() {
        let dir = temp_dir("fail");
        // The folder does not exist: the temporary file cannot even be created.
        let e = write_atomic(&dir.join("no/such/dir/a.txt"), b"x").unwrap_err();
        assert!(matches!(e, SimError::Io { .. }), "{e}");
        assert!(e.to_string().contains("no/such/dir/a.txt"), "{e}");
        // The destination is a non-empty folder: the rename fails after the write, and the temporary
        // file is removed again.
        let blocker = dir.join("b");
        std::fs::create_dir_all(blocker.join("inside")).unwrap();
        let e = write_atomic(&blocker, b"x").unwrap_err();
        assert!(matches!(e, SimError::Io { .. }), "{e}");
        assert_eq!(names(&dir), vec!["b".to_string()]);
        // No file name at all.
        assert!(matches!(
            write_atomic(Path::new("/"), b"x"),
            Err(SimError::Io { .. })
        ));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn temporary_names_are_unique() {
        let dir = temp_dir("unique");
        std::thread::scope(|s| {
            for k in 0..8 {
                let p = dir.join("same.txt");
                s.spawn(move || write_atomic(&p, format!("{k}").as_bytes()).unwrap());
            }
        });
        assert_eq!(names(&dir), vec!["same.txt".to_string()]);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn parquet_bytes_are_reproducible_and_split_into_row_groups() {
        use arrow_array::{ArrayRef, Float64Array};
        use arrow_schema::{DataType, Field, Schema};
        use std::sync::Arc;
        let schema = Arc::new(Schema::new(vec![Field::new("x", DataType::Float64, false)]));
        let col: ArrayRef = Arc::new(Float64Array::from_iter_values((0..10).map(f64::from)));
        let batch = RecordBatch::try_new(schema, vec![col]).unwrap();
        let bytes = |rows| {
            parquet_bytes(&batch, deterministic_writer_properties(rows).build(), rows).unwrap()
        };
        assert_eq!(bytes(4), bytes(4));
        assert_ne!(bytes(4), bytes(5));
        use parquet::file::reader::{FileReader, SerializedFileReader};
        let dir = temp_dir("parquet");
        let p = dir.join("x.parquet");
        write_atomic(&p, &bytes(4)).unwrap();
        let r = SerializedFileReader::new(std::fs::File::open(&p).unwrap()).unwrap();
        let groups: Vec<i64> = (0..r.num_row_groups())
            .map(|g| r.metadata().row_group(g).num_rows())
            .collect();
        assert_eq!(groups, vec![4, 4, 2]);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
