//! Deterministic Parquet: the writer settings that fix the bytes ([`deterministic_writer_properties`])
//! and [`ParquetStream`], which hands record batches to the writer in fixed pieces, so that the same
//! rows give the same bytes however they were batched (see [`super`]).

use arrow_array::RecordBatch;
use parquet::arrow::ArrowWriter;
use parquet::basic::Compression;
use parquet::errors::ParquetError;
use parquet::file::properties::{
    DEFAULT_CREATED_BY, EnabledStatistics, WriterProperties, WriterPropertiesBuilder, WriterVersion,
};
use std::io::Write;

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

/// Rows [`ParquetStream`] hands to the parquet writer at a time: a multiple of the write batch size
/// of [`deterministic_writer_properties`] (1024), so that the writer's mini-batches, and with them its
/// pages, fall on the same rows as when a whole row group is written in one call.
pub const PARQUET_FEED_ROWS: usize = 8192;

/// A Parquet file written as a stream of record batches: rows are buffered and handed to the parquet
/// writer in pieces of [`PARQUET_FEED_ROWS`] rows (fewer only where a row group ends), row groups of at
/// most `max_row_group_rows` rows. The bytes therefore depend on the rows and the properties only,
/// never on how the rows were split into the batches given to [`ParquetStream::write`]. Memory: the
/// row group being written (encoded) plus at most one feed and one batch.
///
/// ```
/// use arrow_array::{ArrayRef, Float64Array, RecordBatch};
/// use arrow_schema::{DataType, Field, Schema};
/// use std::sync::Arc;
/// let schema = Arc::new(Schema::new(vec![Field::new("x", DataType::Float64, false)]));
/// let batch = |v: std::ops::Range<u32>| {
///     let col: ArrayRef = Arc::new(Float64Array::from_iter_values(v.map(f64::from)));
///     RecordBatch::try_new(schema.clone(), vec![col]).unwrap()
/// };
/// let props = || sim::io::deterministic_writer_properties(4096).build();
/// let mut one = sim::io::ParquetStream::new(Vec::new(), schema.clone(), props(), 4096).unwrap();
/// one.write(&batch(0..10_000)).unwrap();
/// let mut parts = sim::io::ParquetStream::new(Vec::new(), schema.clone(), props(), 4096).unwrap();
/// for r in [0..3, 3..5000, 5000..10_000] {
///     parts.write(&batch(r)).unwrap();
/// }
/// assert_eq!(one.finish().unwrap(), parts.finish().unwrap());
/// ```
pub struct ParquetStream<W: Write + Send> {
    writer: ArrowWriter<W>,
    schema: arrow_schema::SchemaRef,
    /// Batches not yet handed to the writer, in order, and their rows.
    pending: std::collections::VecDeque<RecordBatch>,
    pending_rows: usize,
    /// Rows per row group, and rows handed to the writer in the current one.
    group_rows: usize,
    in_group: usize,
}

impl<W: Write + Send> ParquetStream<W> {
    /// A stream into `sink` with `schema` and `props` (which should set the row group size to
    /// `max_row_group_rows`, as [`deterministic_writer_properties`] does).
    ///
    /// # Errors
    /// What the parquet writer reports (a schema it cannot encode).
    pub fn new(
        sink: W,
        schema: arrow_schema::SchemaRef,
        props: WriterProperties,
        max_row_group_rows: usize,
    ) -> std::result::Result<Self, ParquetError> {
        Ok(ParquetStream {
            writer: ArrowWriter::try_new(sink, schema.clone(), Some(props))?,
            schema,
            pending: std::collections::VecDeque::new(),
            pending_rows: 0,
            group_rows: max_row_group_rows.max(1),
            in_group: 0,
        })
    }

    /// Appends the rows of `batch` (of the stream's schema).
    ///
    /// # Errors
    /// What the parquet writer or the sink reports.
    pub fn write(&mut self, batch: &RecordBatch) -> std::result::Result<(), ParquetError> {
        if batch.num_rows() > 0 {
            self.pending_rows += batch.num_rows();
            self.pending.push_back(batch.clone());
        }
        while self.pending_rows >= self.next_feed() {
            self.feed(self.next_feed())?;
        }
        Ok(())
    }

    /// Writes what is buffered and the file footer; returns the sink.
    ///
    /// # Errors
    /// What the parquet writer or the sink reports.
    pub fn finish(mut self) -> std::result::Result<W, ParquetError> {
        while self.pending_rows > 0 {
            self.feed(self.next_feed().min(self.pending_rows))?;
        }
        self.writer.into_inner()
    }

    /// Rows of the next piece: a full feed, or what is left of the row group.
    fn next_feed(&self) -> usize {
        PARQUET_FEED_ROWS.min(self.group_rows - self.in_group)
    }

    /// Hands the first `rows` buffered rows to the writer as one batch.
    fn feed(&mut self, rows: usize) -> std::result::Result<(), ParquetError> {
        let mut parts = Vec::new();
        let mut need = rows;
        while need > 0 {
            let Some(front) = self.pending.pop_front() else {
                break;
            };
            let n = front.num_rows();
            if n <= need {
                need -= n;
                parts.push(front);
            } else {
                parts.push(front.slice(0, need));
                self.pending.push_front(front.slice(need, n - need));
                need = 0;
            }
        }
        let batch = if parts.len() == 1 {
            parts.swap_remove(0)
        } else {
            arrow_select::concat::concat_batches(&self.schema, &parts)?
        };
        self.writer.write(&batch)?;
        self.pending_rows -= rows;
        self.in_group = (self.in_group + rows) % self.group_rows;
        Ok(())
    }
}

/// The Parquet file bytes of `batch` written with `props`, in row groups of at most
/// `max_row_group_rows` rows ([`ParquetStream`] with one batch).
///
/// # Errors
/// What the parquet writer reports (a schema it cannot encode).
pub fn parquet_bytes(
    batch: &RecordBatch,
    props: WriterProperties,
    max_row_group_rows: usize,
) -> std::result::Result<Vec<u8>, ParquetError> {
    let mut w = ParquetStream::new(Vec::new(), batch.schema(), props, max_row_group_rows)?;
    w.write(batch)?;
    w.finish()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::write_atomic;
    use std::path::PathBuf;

    fn temp_dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("sim-io-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    /// A stream gives the bytes of the parquet writer fed one whole row group at a time (how the
    /// project wrote Parquet before it streamed), however the rows come: in one batch, in batches of
    /// one row, or of sizes that straddle feeds and row groups; with a row group that is not a
    /// multiple of the feed, a dictionary column and a boolean.
    #[test]
    fn streams_give_the_bytes_of_whole_row_groups_however_the_rows_are_split() {
        use arrow_array::{ArrayRef, BooleanArray, Float64Array, Int64Array};
        use arrow_schema::{DataType, Field, Schema};
        use parquet::schema::types::ColumnPath;
        use std::sync::Arc;
        let schema = Arc::new(Schema::new(vec![
            Field::new("pose", DataType::Int64, false),
            Field::new("x", DataType::Float64, false),
            Field::new("flag", DataType::Boolean, false),
        ]));
        let n = 3 * PARQUET_FEED_ROWS + 20_000 + 17;
        let batch = |r: std::ops::Range<usize>| {
            let cols: Vec<ArrayRef> = vec![
                Arc::new(Int64Array::from_iter_values(
                    r.clone().map(|i| (i / 3) as i64),
                )),
                Arc::new(Float64Array::from_iter_values(
                    r.clone().map(|i| (i as f64 * 0.7).sin() * 1e3),
                )),
                Arc::new(BooleanArray::from_iter(r.map(|i| Some(i % 7 == 0)))),
            ];
            RecordBatch::try_new(schema.clone(), cols).unwrap()
        };
        let group = 20_000;
        let props = || {
            deterministic_writer_properties(group)
                .set_column_dictionary_enabled(ColumnPath::from("pose"), true)
                .build()
        };
        let old = {
            let mut w = ArrowWriter::try_new(Vec::new(), schema.clone(), Some(props())).unwrap();
            let mut start = 0;
            while start < n {
                let end = (start + group).min(n);
                w.write(&batch(start..end)).unwrap();
                start = end;
            }
            w.into_inner().unwrap()
        };
        let streamed = |cuts: &[usize]| {
            let mut w = ParquetStream::new(Vec::new(), schema.clone(), props(), group).unwrap();
            let mut start = 0;
            for &c in cuts.iter().chain([n].iter()) {
                w.write(&batch(start..c)).unwrap();
                start = c;
            }
            w.finish().unwrap()
        };
        assert!(streamed(&[]) == old, "one batch");
        assert!(streamed(&[1, 2, 8191, 8193, 19_999, 20_001, 40_000]) == old);
        let ones: Vec<usize> = (1..3000).collect();
        assert!(streamed(&ones) == old, "single rows");
        let odd: Vec<usize> = (1..n / 997).map(|k| k * 997).collect();
        assert!(streamed(&odd) == old, "997-row batches");
        assert!(parquet_bytes(&batch(0..n), props(), group).unwrap() == old);
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
