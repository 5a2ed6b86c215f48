//! Streaming reads of the measurement table: a file read in pieces of rows, so that a tool can work
//! through 10⁷ rows holding only a bounded number ([`read_chunks`], [`read_configuration_chunks`]).
//!
//! Parquet is read record batch by record batch (at most `rows_per_chunk` rows, decoding only the
//! contract's columns); CSV in pieces of whole lines of about 256 bytes a row of text, at most
//! [`CSV_BLOCK_BYTES`]. Each piece
//! is checked as [`MeasurementTable::validate`] checks a whole table, and its errors name the
//! file-wide row (and CSV line), exactly as a whole-file read names them. One check differs: rows that
//! share a pose id must agree in their joint values ([`super::POSE_REPEAT_TOLERANCE`]) only within a
//! piece, since a file-wide check would hold every pose in memory. The concatenated pieces are the
//! table [`super::read`] returns (tested for both formats and several piece sizes), branch joint
//! columns (`q_<name>`) included: each piece carries its rows' values.

use super::{MeasurementTable, OptionalColumns, Positions, csv::CsvChunks, table_err};
use crate::error::{Result, SimError};
use std::path::{Path, PathBuf};

/// Text read from a CSV file per piece (bytes): about 80,000 rows of a 7-joint table.
pub const CSV_BLOCK_BYTES: usize = 8 << 20;

/// Rows per piece that the command-line tools stream with.
pub const DEFAULT_CHUNK_ROWS: usize = 65_536;

/// Rows of a measurement file read together.
#[derive(Clone, Debug, PartialEq)]
pub struct Chunk {
    /// 0-based row of the file (among data rows) of the piece's first row.
    pub first_row: usize,
    /// The rows.
    pub table: MeasurementTable,
}

/// Iterator over the pieces of a measurement file; ends after the first error.
pub struct TableChunks {
    path: PathBuf,
    name: String,
    source: Source,
    rows_per_chunk: usize,
    /// Data rows handed out so far.
    rows: usize,
    done: bool,
}

enum Source {
    Csv(CsvChunks),
    Parquet(super::parquet::OpenParquet),
}

/// Opens the measurement file `path` (CSV or Parquet by extension) for reading in pieces of at most
/// `rows_per_chunk` rows (Parquet; CSV pieces are about 256 bytes of text a row, at most
/// [`CSV_BLOCK_BYTES`]). The header (or
/// schema) is read and resolved here; its errors are returned at once.
pub fn read_chunks(path: &Path, rows_per_chunk: usize) -> Result<TableChunks> {
    open(path, rows_per_chunk, Positions::Required)
}

/// [`read_chunks`] for a table of joint configurations (`x, y, z` optional, as
/// [`super::read_configurations`]).
pub fn read_configuration_chunks(path: &Path, rows_per_chunk: usize) -> Result<TableChunks> {
    open(path, rows_per_chunk, Positions::Optional)
}

fn open(path: &Path, rows_per_chunk: usize, positions: Positions) -> Result<TableChunks> {
    let format = super::Format::from_path(path)?;
    let name = path.display().to_string();
    let f = std::fs::File::open(path).map_err(|e| SimError::Read {
        path: path.to_path_buf(),
        source: e,
    })?;
    let rows_per_chunk = rows_per_chunk.max(1);
    let source = match format {
        super::Format::Csv => Source::Csv(CsvChunks::new(
            f,
            path,
            &name,
            positions,
            csv_block(rows_per_chunk),
        )?),
        super::Format::Parquet => Source::Parquet(guarded(&name, || {
            super::parquet::OpenParquet::new(f, &name, positions, rows_per_chunk)
        })?),
    };
    Ok(TableChunks {
        path: path.to_path_buf(),
        name,
        source,
        rows_per_chunk,
        rows: 0,
        done: false,
    })
}

/// Text per CSV piece for pieces of `rows_per_chunk` rows: 256 bytes a row (more than a row of 7
/// joints with every optional column takes), at least 4 KiB, at most [`CSV_BLOCK_BYTES`].
fn csv_block(rows_per_chunk: usize) -> usize {
    rows_per_chunk
        .saturating_mul(256)
        .clamp(4096, CSV_BLOCK_BYTES)
}

/// `read` with the Parquet decoder's panics turned into an error naming the file.
fn guarded<T>(name: &str, read: impl FnOnce() -> Result<T>) -> Result<T> {
    crate::decoder_guard::contain(read).unwrap_or_else(|message| {
        Err(table_err(
            name,
            None,
            None,
            format!(
                "not a readable Parquet file: the decoder failed ({}): is the file corrupt?",
                crate::error::fragment_n(&message, 120)
            ),
        ))
    })
}

impl TableChunks {
    /// Joint columns of the file.
    pub fn n_joints(&self) -> usize {
        self.layout().n_joints
    }

    /// The optional columns the file has.
    pub fn columns(&self) -> OptionalColumns {
        self.layout().columns
    }

    /// Names of the file's branch joints (its `q_<name>` columns without the prefix, in column
    /// order; empty without): every piece's [`MeasurementTable::branch_names`].
    pub fn branch_names(&self) -> &[String] {
        &self.layout().branch
    }

    /// The file name as shown in errors.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Data rows read so far.
    pub fn rows_read(&self) -> usize {
        self.rows
    }

    fn layout(&self) -> &super::Layout {
        match &self.source {
            Source::Csv(c) => &c.layout,
            Source::Parquet(p) => &p.layout,
        }
    }

    fn next_table(&mut self) -> Result<Option<(usize, MeasurementTable)>> {
        match &mut self.source {
            Source::Csv(c) => c.next_table(&self.path, &self.name),
            Source::Parquet(p) => {
                let (name, rows, want) = (&self.name, self.rows, self.rows_per_chunk);
                guarded(name, || {
                    let mut columns = super::columns::ColumnsBuilder::new(&p.layout, want);
                    while columns.rows() < want && p.next_batch_at(&mut columns, name, rows)? {}
                    if columns.rows() == 0 {
                        return Ok(None);
                    }
                    let table = columns.finish();
                    table
                        .validate_named(name)
                        .map_err(|e| super::at_file_row(e, rows, |_| None))?;
                    Ok(Some((rows, table)))
                })
            }
        }
    }
}

impl Iterator for TableChunks {
    type Item = Result<Chunk>;

    fn next(&mut self) -> Option<Result<Chunk>> {
        if self.done {
            return None;
        }
        match self.next_table() {
            Ok(Some((first_row, table))) => {
                self.rows += table.len();
                Some(Ok(Chunk { first_row, table }))
            }
            Ok(None) => {
                self.done = true;
                (self.rows == 0)
                    .then(|| Err(table_err(&self.name, None, None, "no data rows".into())))
            }
            Err(e) => {
                self.done = true;
                Some(Err(e))
            }
        }
    }
}
