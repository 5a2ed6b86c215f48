//! Where a streamed fit reads its rows from: a measurement file read piece by piece, or a table in
//! memory cut into the same pieces.

use crate::error::Result;
use sim::measurement_table::{Chunk, MeasurementTable, read_chunks};
use std::path::{Path, PathBuf};

/// Rows of a measurement table, handed out in pieces, the same pieces on every pass.
pub trait ChunkSource {
    /// The table's name in messages (its file name).
    fn name(&self) -> &str;
    /// One pass over every row from the first, in pieces of consecutive rows ([`Chunk::first_row`]
    /// is the 0-based row of the table). Each call starts a new pass.
    fn pass(&self) -> Result<Box<dyn Iterator<Item = Result<Chunk>> + '_>>;
}

/// A measurement file (CSV or Parquet) read in pieces of at most `rows_per_chunk` rows
/// ([`sim::measurement_table::read_chunks`]), opened anew for each pass.
#[derive(Clone, Debug)]
pub struct FileSource {
    path: PathBuf,
    name: String,
    rows_per_chunk: usize,
}

impl FileSource {
    /// The file `path`, read in pieces of at most `rows_per_chunk` rows.
    pub fn new(path: &Path, rows_per_chunk: usize) -> Self {
        FileSource {
            path: path.to_path_buf(),
            name: path.display().to_string(),
            rows_per_chunk: rows_per_chunk.max(1),
        }
    }
}

impl ChunkSource for FileSource {
    fn name(&self) -> &str {
        &self.name
    }

    /// The pieces are decoded one ahead, on a thread of their own, while the caller works on the
    /// previous one (decoding is serial; the solver's work on a piece is parallel).
    fn pass(&self) -> Result<Box<dyn Iterator<Item = Result<Chunk>> + '_>> {
        let chunks = read_chunks(&self.path, self.rows_per_chunk)?;
        Ok(Box::new(Prefetched::new(chunks, &self.name)))
    }
}

/// The pieces of a file decoded on a thread of their own, one piece ahead of the consumer.
struct Prefetched {
    pieces: std::sync::mpsc::Receiver<Result<Chunk>>,
    reader: Option<std::thread::JoinHandle<()>>,
    name: String,
}

impl Prefetched {
    fn new(chunks: sim::measurement_table::TableChunks, name: &str) -> Self {
        let (send, pieces) = std::sync::mpsc::sync_channel(1);
        let reader = std::thread::spawn(move || {
            for piece in chunks {
                // A consumer that stopped (an error, a cancel) ends the reading.
                if send.send(piece.map_err(Into::into)).is_err() {
                    break;
                }
            }
        });
        Prefetched {
            pieces,
            reader: Some(reader),
            name: name.to_string(),
        }
    }
}

impl Iterator for Prefetched {
    type Item = Result<Chunk>;

    fn next(&mut self) -> Option<Result<Chunk>> {
        match self.pieces.recv() {
            Ok(piece) => Some(piece),
            Err(_) => {
                // The reader is done: a panic there must not pass for the end of the file.
                let reader = self.reader.take()?;
                match reader.join() {
                    Ok(()) => None,
                    Err(_) => Some(Err(crate::error::CalibError::BadValue {
                        context: self.name.clone(),
                        field: "file".into(),
                        value: self.name.clone(),
                        problem: "reading the file failed part way (its reader stopped)".into(),
                    })),
                }
            }
        }
    }
}

/// A table in memory handed out in pieces of `rows_per_chunk` rows: the streamed fit of a table
/// that fits in memory (tests compare it with the in-memory fit).
#[derive(Clone, Debug)]
pub struct TableSource<'a> {
    table: &'a MeasurementTable,
    name: String,
    rows_per_chunk: usize,
}

impl<'a> TableSource<'a> {
    /// `table`, named `name` in messages, in pieces of `rows_per_chunk` rows.
    pub fn new(table: &'a MeasurementTable, name: &str, rows_per_chunk: usize) -> Self {
        TableSource {
            table,
            name: name.to_string(),
            rows_per_chunk: rows_per_chunk.max(1),
        }
    }
}

impl ChunkSource for TableSource<'_> {
    fn name(&self) -> &str {
        &self.name
    }

    fn pass(&self) -> Result<Box<dyn Iterator<Item = Result<Chunk>> + '_>> {
        let n = self.table.len();
        let step = self.rows_per_chunk;
        Ok(Box::new((0..n.div_ceil(step)).map(move |c| {
            let rows: Vec<usize> = (c * step..((c + 1) * step).min(n)).collect();
            Ok(Chunk {
                first_row: c * step,
                table: self.table.select_rows(&rows),
            })
        })))
    }
}
