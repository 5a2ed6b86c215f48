//! `robocal calibrate` on a table read in pieces ([`calib::fit::stream`]): when the streamed fit
//! applies (`--stream`), and the file the model checks see on the first pass.

use super::shared::CliError;
use calib::fit::stream::{ChunkSource, FileSource};
use sim::measurement_table::{Chunk, ModelCheck, read_chunks};
use std::cell::RefCell;
use std::path::Path;

/// Tables of more rows than this are streamed under `--stream auto` when the options allow it:
/// four pieces of the default 65,536 rows.
pub const STREAM_MIN_ROWS: usize = 1 << 18;

/// `--stream`: whether `calibrate` reads the table in pieces.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum StreamMode {
    /// Tables of more than 262,144 rows, when the options allow it.
    Auto,
    /// Any table; options that need the table in memory are refused.
    Always,
    /// Never: the table is held in memory.
    Never,
}

/// Why the options need the table in memory, if they do: the streamed fit takes the kinematic
/// model without a robust loss, and validates by folds and regions (or not at all), not by a split
/// or another file.
pub fn needs_memory(
    model: &str,
    robust: bool,
    test_fraction: f64,
    test_data: bool,
) -> Option<String> {
    if model != "kinematic" {
        Some(format!(
            "--model {model} (the streamed fit takes the kinematic model)"
        ))
    } else if robust {
        Some("--robust (the streamed fit excludes gross errors instead)".into())
    } else if test_data {
        Some("--test-data".into())
    } else if test_fraction > 0.0 {
        Some("--test-fraction".into())
    } else {
        None
    }
}

/// Whether a command reads `path` in pieces under `mode`, given why the options need the table in
/// memory (`memory_reason`), and whether the file has more than [`STREAM_MIN_ROWS`] rows (known
/// under `auto` only). `--stream always` with such options is an input error naming them.
pub fn decide_stream(
    mode: StreamMode,
    path: &Path,
    memory_reason: Option<&str>,
    robot: &sim::Model,
) -> Result<(bool, bool), CliError> {
    let memory_reason = match memory_reason {
        Some(r) => Some(r),
        None if !robot.couplings().is_empty() => Some("a robot with coupled joints"),
        None => None,
    };
    match mode {
        StreamMode::Never => Ok((false, false)),
        StreamMode::Always => match memory_reason {
            Some(r) => Err(CliError::Input(format!(
                "--stream always: {r} needs the table in memory"
            ))),
            None => Ok((true, false)),
        },
        StreamMode::Auto => {
            let large = has_more_rows_than(path, STREAM_MIN_ROWS);
            Ok((large && memory_reason.is_none(), large))
        }
    }
}

/// Whether the file has more than `n` rows, reading at most about that many. A file that cannot be
/// read counts as small: the in-memory read reports its error.
pub fn has_more_rows_than(path: &Path, n: usize) -> bool {
    let Ok(chunks) = read_chunks(path, sim::measurement_table::DEFAULT_CHUNK_ROWS) else {
        return false;
    };
    let mut rows = 0;
    for c in chunks {
        match c {
            Ok(c) => rows += c.table.len(),
            Err(_) => return false,
        }
        if rows > n {
            return true;
        }
    }
    false
}

/// A measurement file read in pieces whose first pass is also checked against the robot (joint
/// limits, units: [`ModelCheck`], the checks of an in-memory read).
pub struct CheckedFile<'a> {
    file: FileSource,
    check: RefCell<ModelCheck<'a>>,
    checked: RefCell<bool>,
}

impl<'a> CheckedFile<'a> {
    /// `path`, in pieces of `rows_per_chunk` rows, checked against `model`.
    pub fn new(path: &Path, rows_per_chunk: usize, model: &'a sim::Model) -> Self {
        CheckedFile {
            file: FileSource::new(path, rows_per_chunk),
            check: RefCell::new(ModelCheck::new(model, path)),
            checked: RefCell::new(false),
        }
    }

    /// The check's warnings, one line each.
    pub fn warnings(&self) -> Vec<String> {
        self.check.borrow().warnings()
    }
}

impl ChunkSource for CheckedFile<'_> {
    fn name(&self) -> &str {
        self.file.name()
    }

    fn pass(&self) -> calib::Result<Box<dyn Iterator<Item = calib::Result<Chunk>> + '_>> {
        let first = !self.checked.replace(true);
        let inner = self.file.pass()?;
        Ok(Box::new(inner.map(move |c| {
            let c = c?;
            if first {
                self.check.borrow_mut().add(&c.table, c.first_row)?;
            }
            Ok(c)
        })))
    }
}

/// The one-line account of a streamed fit (and its validation's passes, when it ran) for the
/// terminal and the JSON `stream` object.
pub fn describe(
    s: &calib::fit::stream::StreamedCalibration,
    validation_passes: Option<usize>,
    chunk_rows: usize,
) -> (String, serde_json::Value) {
    let validation = match validation_passes {
        Some(n) => format!(
            "; validated in {n} more passes (folds by a seeded hash of the pose, regions placed on \
             the sample's poses)"
        ),
        None => String::new(),
    };
    (
        format!(
            "streamed: {} rows in {} passes of pieces of up to {chunk_rows} rows, starting from the fit \
             of a seeded sample of {} rows (memory does not grow with the rows but for 8 bytes a \
             row){validation}",
            s.rows, s.passes, s.sample_rows
        ),
        serde_json::json!({
            "rows": s.rows,
            "passes": s.passes,
            "chunk_rows": chunk_rows,
            "sample_rows": s.sample_rows,
            "validation_passes": validation_passes,
        }),
    )
}

/// `--chunk-rows` must hold a row.
pub fn check_chunk_rows(n: usize) -> Result<(), CliError> {
    if n == 0 {
        Err(CliError::Input(
            "--chunk-rows 0: a piece holds at least 1 row".into(),
        ))
    } else {
        Ok(())
    }
}
