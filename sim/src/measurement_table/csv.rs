//! CSV reading and writing of the measurement table (see the parent module for the format).

use super::{IN_MEMORY, Layout, MeasurementTable, Positions, Role, resolve_columns};
use crate::error::{Result, SimError, fragment, fragment_n};
use std::io::Write;

/// Parses a CSV measurement table from text; `file` is the name shown in errors.
pub fn read_csv_str(text: &str, file: &str) -> Result<MeasurementTable> {
    read_csv_bytes(text.as_bytes(), file, Positions::Required)
}

/// The CSV text of `table` (see the parent module for the format). Fails if the table is invalid
/// ([`MeasurementTable::validate`]), naming it [`IN_MEMORY`].
pub fn write_csv_string(table: &MeasurementTable) -> Result<String> {
    table.validate_named(IN_MEMORY)?;
    let bytes = write_csv_bytes(table);
    Ok(String::from_utf8(bytes).expect("the CSV writer writes ASCII only"))
}

/// A cell of a record: byte range in the buffer, and whether it was quoted.
#[derive(Clone, Copy, Debug)]
struct Cell {
    start: usize,
    end: usize,
    quoted: bool,
}

/// Splits a buffer into CSV records (RFC 4180 quotes, `\n` or `\r\n` line ends, blanks around unquoted
/// cells trimmed), counting lines.
struct Records<'a> {
    buf: &'a [u8],
    pos: usize,
    /// 1-based line at `pos`.
    line: usize,
}

impl<'a> Records<'a> {
    fn new(buf: &'a [u8]) -> Self {
        Records {
            buf,
            pos: 0,
            line: 1,
        }
    }

    /// Reads the next record into `cells`; returns the 1-based line it starts on, `None` at the end, or
    /// `Err((line, message))`.
    fn next_record(
        &mut self,
        cells: &mut Vec<Cell>,
    ) -> std::result::Result<Option<usize>, (usize, String)> {
        cells.clear();
        let buf = self.buf;
        let n = buf.len();
        if self.pos >= n {
            return Ok(None);
        }
        let start_line = self.line;
        let mut i = self.pos;
        loop {
            while i < n && (buf[i] == b' ' || buf[i] == b'\t') {
                i += 1;
            }
            if i < n && buf[i] == b'"' {
                let s = i + 1;
                let mut j = s;
                loop {
                    if j >= n {
                        return Err((start_line, "a quoted cell is not closed".into()));
                    }
                    match buf[j] {
                        b'"' if j + 1 < n && buf[j + 1] == b'"' => j += 2,
                        b'"' => break,
                        b'\n' => {
                            self.line += 1;
                            j += 1;
                        }
                        _ => j += 1,
                    }
                }
                cells.push(Cell {
                    start: s,
                    end: j,
                    quoted: true,
                });
                i = j + 1;
                while i < n && matches!(buf[i], b' ' | b'\t' | b'\r') {
                    i += 1;
                }
                if i < n && buf[i] != b',' && buf[i] != b'\n' {
                    return Err((self.line, "unexpected text after a closing quote".into()));
                }
            } else {
                let s = i;
                i = find_separator(buf, i);
                let mut e = i;
                while e > s && matches!(buf[e - 1], b' ' | b'\t' | b'\r') {
                    e -= 1;
                }
                cells.push(Cell {
                    start: s,
                    end: e,
                    quoted: false,
                });
            }
            if i >= n {
                self.pos = n;
                return Ok(Some(start_line));
            }
            if buf[i] == b',' {
                i += 1;
                continue;
            }
            // A line end.
            self.pos = i + 1;
            self.line += 1;
            return Ok(Some(start_line));
        }
    }
}

/// Index of the first `,` or `\n` at or after `i` (or `buf.len()`), eight bytes at a time.
#[inline]
fn find_separator(buf: &[u8], mut i: usize) -> usize {
    const LO: u64 = 0x0101_0101_0101_0101;
    const HI: u64 = 0x8080_8080_8080_8080;
    const COMMA: u64 = LO * b',' as u64;
    const NEWLINE: u64 = LO * b'\n' as u64;
    while let Some(chunk) = buf.get(i..i + 8) {
        let w = u64::from_le_bytes(chunk.try_into().expect("8 bytes"));
        let (a, b) = (w ^ COMMA, w ^ NEWLINE);
        // High bit set in the bytes of `a` or `b` that are zero; the lowest such bit is exact.
        let z = (a.wrapping_sub(LO) & !a & HI) | (b.wrapping_sub(LO) & !b & HI);
        if z != 0 {
            return i + (z.trailing_zeros() / 8) as usize;
        }
        i += 8;
    }
    while i < buf.len() && buf[i] != b',' && buf[i] != b'\n' {
        i += 1;
    }
    i
}

fn is_blank(cells: &[Cell]) -> bool {
    cells.len() == 1 && !cells[0].quoted && cells[0].start == cells[0].end
}

/// The text of a cell for an error message (quoted, shortened).
fn show(bytes: &[u8]) -> String {
    format!("'{}'", fragment_n(&String::from_utf8_lossy(bytes), 40))
}

/// The cell `start..end` as text: sliced from `text` (the whole buffer, when it is valid UTF-8), else
/// checked on its own.
#[inline]
fn cell_str<'a>(
    bytes: &'a [u8],
    text: Option<&'a str>,
    c: &Cell,
) -> std::result::Result<&'a str, String> {
    match text {
        // Cell bounds sit next to ASCII bytes (',', '\n', '"', blanks) or the ends: char boundaries.
        Some(t) => Ok(&t[c.start..c.end]),
        None => std::str::from_utf8(&bytes[c.start..c.end])
            .map_err(|_| format!("{} is not a number", show(&bytes[c.start..c.end]))),
    }
}

fn parse_f64(s: &str) -> std::result::Result<f64, String> {
    if s.is_empty() {
        return Err("empty cell: a number is required".into());
    }
    let v = s
        .parse::<f64>()
        .map_err(|_| format!("{} is not a number", show(s.as_bytes())))?;
    if v.is_finite() {
        Ok(v)
    } else {
        Err(format!("{} is not finite", show(s.as_bytes())))
    }
}

/// An integer cell; integral floats such as `3.0` are accepted when exact.
fn parse_i64(s: &str) -> std::result::Result<i64, String> {
    if s.is_empty() {
        return Err("empty cell: an integer is required".into());
    }
    if let Ok(v) = s.parse::<i64>() {
        return Ok(v);
    }
    match s.parse::<f64>() {
        Ok(v) if v.fract() == 0.0 && v.abs() <= 9_007_199_254_740_992.0 => Ok(v as i64),
        _ => Err(format!("{} is not an integer", show(s.as_bytes()))),
    }
}

fn parse_dir(s: &str) -> std::result::Result<i8, String> {
    let v = parse_i64(s)?;
    if (-1..=1).contains(&v) {
        Ok(v as i8)
    } else {
        Err(format!(
            "{} is not a direction (-1, 0 or +1)",
            show(s.as_bytes())
        ))
    }
}

/// The 1-based line holding data row `row` (1-based), found by scanning again (error path only).
fn line_of_row(bytes: &[u8], row: usize) -> Option<usize> {
    let mut rec = Records::new(bytes);
    let mut cells = Vec::new();
    let mut seen = 0usize; // records that are not blank, header included
    while let Ok(Some(line)) = rec.next_record(&mut cells) {
        if is_blank(&cells) {
            continue;
        }
        if seen == row {
            return Some(line);
        }
        seen += 1;
    }
    None
}

/// Parses a CSV measurement table from bytes (UTF-8, optional BOM); `file` is the name shown in errors.
pub(super) fn read_csv_bytes(
    bytes: &[u8],
    file: &str,
    positions: Positions,
) -> Result<MeasurementTable> {
    let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    let table = parse(bytes, file, positions)?;
    table
        .validate_named(file)
        .map_err(|e| super::at_file_row(e, 0, |r| line_of_row(bytes, r)))?;
    Ok(table)
}

/// An error inside one chunk of data lines: chunk-local 1-based row (if any) and line.
struct ChunkError {
    row: Option<usize>,
    line: usize,
    column: Option<usize>,
    message: String,
}

/// Rows parsed from one chunk of data lines, and the number of lines the chunk spans.
struct Chunk {
    table: MeasurementTable,
    rows: usize,
    lines: usize,
}

/// Chunks bigger than this are worth parsing in parallel (bytes).
const PARALLEL_CHUNK: usize = 1 << 20;

/// The header of a CSV measurement file: its resolved columns, its names, the byte offset where the
/// data lines start and the 1-based line they start on. `bytes` must hold at least the header line
/// (the first line that is not blank) and its line end, unless it is the whole file.
fn header(bytes: &[u8], file: &str, positions: Positions) -> Result<Header> {
    // Control bytes other than tab and line ends in the first line: not text (a binary file); said so
    // before its bytes are taken for cells. Bytes that are not UTF-8 (a Latin-1 name of an ignored
    // column) are read as before.
    let first = &bytes[..bytes.len().min(4096)];
    let first = &first[..first
        .iter()
        .position(|&b| b == b'\n')
        .unwrap_or(first.len())];
    if first
        .iter()
        .any(|&b| (b < 0x20 && !matches!(b, b'\t' | b'\r')) || b == 0x7f)
    {
        return Err(super::table_err(
            file,
            None,
            None,
            format!(
                "not a CSV text file: its first line holds binary bytes ({})",
                show(first)
            ),
        ));
    }
    let mut rec = Records::new(bytes);
    let mut cells: Vec<Cell> = Vec::with_capacity(32);
    // Header: the first line that is not blank.
    loop {
        match rec.next_record(&mut cells) {
            Err((line, message)) => {
                return Err(SimError::Table {
                    file: file.to_string(),
                    row: None,
                    line: Some(line),
                    column: None,
                    message,
                });
            }
            Ok(None) => {
                return Err(super::table_err(
                    file,
                    None,
                    None,
                    "the file is empty: a header row is required".into(),
                ));
            }
            Ok(Some(_)) if is_blank(&cells) => continue,
            Ok(Some(_)) => break,
        }
    }
    let names: Vec<String> = cells
        .iter()
        .map(|c| {
            let s = String::from_utf8_lossy(&bytes[c.start..c.end]);
            if c.quoted {
                s.replace("\"\"", "\"")
            } else {
                s.into_owned()
            }
        })
        .collect();
    let layout = resolve_columns(&names, file, positions)?;
    Ok(Header {
        layout,
        names,
        data_start: rec.pos,
        first_line: rec.line,
    })
}

/// What [`header`] finds.
struct Header {
    layout: Layout,
    names: Vec<String>,
    data_start: usize,
    first_line: usize,
}

fn parse(bytes: &[u8], file: &str, positions: Positions) -> Result<MeasurementTable> {
    let Header {
        layout,
        names,
        data_start,
        first_line,
    } = header(bytes, file, positions)?;
    let data = &bytes[data_start..];
    let text = std::str::from_utf8(data).ok();

    // Split into chunks at line ends, unless quotes could hide a line end inside a cell.
    let n_chunks = if data.len() >= 2 * PARALLEL_CHUNK && !data.contains(&b'"') {
        (data.len() / PARALLEL_CHUNK).min(4 * rayon::current_num_threads().max(1))
    } else {
        1
    };
    let mut bounds = vec![0usize];
    for k in 1..n_chunks {
        let target = (data.len() * k / n_chunks).max(*bounds.last().unwrap_or(&0));
        if let Some(nl) = data[target..].iter().position(|&b| b == b'\n') {
            let b = target + nl + 1;
            if b > *bounds.last().unwrap_or(&0) && b < data.len() {
                bounds.push(b);
            }
        }
    }
    bounds.push(data.len());
    let ranges: Vec<(usize, usize)> = bounds.windows(2).map(|w| (w[0], w[1])).collect();
    use rayon::prelude::*;
    let parts: Vec<std::result::Result<Chunk, ChunkError>> = ranges
        .par_iter()
        .map(|&(s, e)| parse_chunk(&data[s..e], text.map(|t| &t[s..e]), &layout))
        .collect();

    let rows: usize = parts.iter().map(|p| p.as_ref().map_or(0, |c| c.rows)).sum();
    let mut table = layout.empty_table(rows);
    let (mut rows_before, mut line_before) = (0usize, first_line - 1);
    for part in parts {
        match part {
            Err(e) => {
                return Err(SimError::Table {
                    file: file.to_string(),
                    row: e.row.map(|r| rows_before + r),
                    line: Some(line_before + e.line),
                    column: e.column.map(|c| fragment(&names[c])),
                    message: e.message,
                });
            }
            Ok(c) => {
                append(&mut table, c.table);
                rows_before += c.rows;
                line_before += c.lines;
            }
        }
    }
    Ok(table)
}

/// Moves the rows of `part` to the end of `table` (same columns).
fn append(table: &mut MeasurementTable, part: MeasurementTable) {
    fn ext<T>(a: &mut Option<Vec<T>>, b: Option<Vec<T>>) {
        if let (Some(a), Some(b)) = (a.as_mut(), b) {
            a.extend(b);
        }
    }
    table.pose.extend(part.pose);
    table.q.extend(part.q);
    table.position.extend(part.position);
    ext(&mut table.orientation, part.orientation);
    ext(&mut table.t, part.t);
    ext(&mut table.temp, part.temp);
    ext(&mut table.dir, part.dir);
    ext(&mut table.payload, part.payload);
    ext(&mut table.sigma, part.sigma);
    ext(&mut table.campaign, part.campaign);
    if let (Some(a), Some(b)) = (table.branch.as_mut(), part.branch) {
        a.values.extend(b.values);
    }
}

/// Parses whole data lines (`text`: the same bytes as text, when valid UTF-8).
fn parse_chunk(
    bytes: &[u8],
    text: Option<&str>,
    layout: &Layout,
) -> std::result::Result<Chunk, ChunkError> {
    let Layout {
        n_joints: nq,
        roles,
        ..
    } = layout;
    let (nq, n_cols) = (*nq, roles.len());
    let mut rec = Records::new(bytes);
    let mut cells: Vec<Cell> = Vec::with_capacity(n_cols + 1);
    // Rows expected, from the length of the first lines (capacity only).
    let sample = &bytes[..bytes.len().min(1 << 16)];
    let sample_lines = sample.iter().filter(|&&b| b == b'\n').count().max(1);
    let estimate = bytes.len() / (sample.len() / sample_lines).max(1) * 21 / 20 + 1;
    let mut table = layout.empty_table(estimate);
    let mut q = vec![0.0; nq];
    let mut branch = vec![0.0; layout.branch.len()];
    let mut dir = vec![0i8; nq];
    let mut pos = [0.0; 3];
    let mut quat = [0.0; 4];
    let (mut pose, mut t, mut temp, mut payload, mut sigma) = (0i64, 0.0, 0.0, 0.0, 0.0);
    let mut campaign = 0i64;
    let mut row = 0usize;
    loop {
        let line = match rec.next_record(&mut cells) {
            Ok(Some(line)) => line,
            Ok(None) => break,
            Err((line, message)) => {
                return Err(ChunkError {
                    row: Some(row + 1),
                    line,
                    column: None,
                    message,
                });
            }
        };
        if is_blank(&cells) {
            continue;
        }
        row += 1;
        if cells.len() != n_cols {
            let hint = if cells.len() > n_cols {
                " (a decimal comma? numbers must use '.')"
            } else {
                ""
            };
            return Err(ChunkError {
                row: Some(row),
                line,
                column: None,
                message: format!("{} cells, but the header has {n_cols}{hint}", cells.len()),
            });
        }
        for (c, (cell, role)) in cells.iter().zip(roles).enumerate() {
            if *role == Role::Ignore {
                continue;
            }
            let res = cell_str(bytes, text, cell).and_then(|s| match *role {
                Role::Ignore => Ok(()),
                Role::Pose => parse_i64(s).map(|v| pose = v),
                Role::Q(j) => parse_f64(s).map(|v| q[j] = v),
                Role::Branch(k) => parse_f64(s).map(|v| branch[k] = v),
                Role::Position(k) => parse_f64(s).map(|v| pos[k] = v),
                Role::Quaternion(k) => parse_f64(s).map(|v| quat[k] = v),
                Role::T => parse_f64(s).map(|v| t = v),
                Role::Temp => parse_f64(s).map(|v| temp = v),
                Role::Dir(j) => parse_dir(s).map(|v| dir[j] = v),
                Role::Payload => parse_f64(s).map(|v| payload = v),
                Role::Sigma => parse_f64(s).map(|v| sigma = v),
                Role::Campaign => parse_i64(s).map(|v| campaign = v),
            });
            if let Err(message) = res {
                return Err(ChunkError {
                    row: Some(row),
                    line,
                    column: Some(c),
                    message,
                });
            }
        }
        table.pose.push(pose);
        table.q.extend_from_slice(&q);
        table.position.push(pos);
        if let Some(v) = table.orientation.as_mut() {
            v.push(quat);
        }
        if let Some(v) = table.t.as_mut() {
            v.push(t);
        }
        if let Some(v) = table.temp.as_mut() {
            v.push(temp);
        }
        if let Some(v) = table.dir.as_mut() {
            v.extend_from_slice(&dir);
        }
        if let Some(v) = table.payload.as_mut() {
            v.push(payload);
        }
        if let Some(v) = table.sigma.as_mut() {
            v.push(sigma);
        }
        if let Some(v) = table.campaign.as_mut() {
            v.push(campaign);
        }
        if let Some(b) = table.branch.as_mut() {
            b.values.extend_from_slice(&branch);
        }
    }
    Ok(Chunk {
        table,
        rows: row,
        lines: rec.line - 1,
    })
}

/// Writes a float as the shortest decimal that reads back to the same `f64`, always with a `.` or an
/// exponent (`1.0`, `-0.0`, `0.25`, `1e300`, `5e-324`).
#[inline]
fn put_f64(out: &mut Vec<u8>, v: f64) {
    write!(out, "{v:?}").expect("writing to a Vec cannot fail");
}

/// A header cell: the column name, quoted (RFC 4180) when it holds what would end or change an
/// unquoted cell (a `,`, a `"`, a line end, blanks at either end). Only a branch joint's name
/// (`q_<name>`) can; the contract's own names are written as they are.
fn put_name(out: &mut Vec<u8>, name: &str) {
    let plain = !name.is_empty()
        && !name
            .bytes()
            .any(|b| matches!(b, b',' | b'"' | b'\n' | b'\r'))
        && name.trim_matches([' ', '\t']) == name;
    if plain {
        out.extend_from_slice(name.as_bytes());
    } else {
        out.push(b'"');
        out.extend_from_slice(name.replace('"', "\"\"").as_bytes());
        out.push(b'"');
    }
}

/// The CSV bytes of a table assumed valid.
pub(super) fn write_csv_bytes(table: &MeasurementTable) -> Vec<u8> {
    use rayon::prelude::*;
    const ROWS_PER_CHUNK: usize = 16_384;
    let n = table.len();
    let names = table.column_names();
    let chunks: Vec<Vec<u8>> = (0..n.div_ceil(ROWS_PER_CHUNK))
        .into_par_iter()
        .map(|k| write_rows(table, k * ROWS_PER_CHUNK..((k + 1) * ROWS_PER_CHUNK).min(n)))
        .collect();
    let mut out = Vec::with_capacity(64 + chunks.iter().map(Vec::len).sum::<usize>());
    for (k, name) in names.iter().enumerate() {
        if k > 0 {
            out.push(b',');
        }
        put_name(&mut out, name);
    }
    out.push(b'\n');
    for c in chunks {
        out.extend_from_slice(&c);
    }
    out
}

/// The CSV lines of rows `rows`.
fn write_rows(table: &MeasurementTable, rows: std::ops::Range<usize>) -> Vec<u8> {
    let nq = table.n_joints;
    let width = table.n_joints + table.branch_names().len() + 4;
    let mut out = Vec::with_capacity(rows.len() * width * 20);
    for r in rows {
        write!(out, "{}", table.pose[r]).expect("writing to a Vec cannot fail");
        for &v in table.q_row(r) {
            out.push(b',');
            put_f64(&mut out, v);
        }
        for &v in table.branch_row(r).unwrap_or(&[]) {
            out.push(b',');
            put_f64(&mut out, v);
        }
        for &v in &table.position[r] {
            out.push(b',');
            put_f64(&mut out, v);
        }
        if let Some(o) = &table.orientation {
            for &v in &o[r] {
                out.push(b',');
                put_f64(&mut out, v);
            }
        }
        for c in [&table.t, &table.temp].into_iter().flatten() {
            out.push(b',');
            put_f64(&mut out, c[r]);
        }
        if let Some(d) = &table.dir {
            for &v in &d[r * nq..(r + 1) * nq] {
                write!(out, ",{v}").expect("writing to a Vec cannot fail");
            }
        }
        for c in [&table.payload, &table.sigma].into_iter().flatten() {
            out.push(b',');
            put_f64(&mut out, c[r]);
        }
        if let Some(c) = &table.campaign {
            write!(out, ",{}", c[r]).expect("writing to a Vec cannot fail");
        }
        out.push(b'\n');
    }
    out
}

/// A CSV measurement file read in pieces of whole lines ([`super::chunks`]): at most about
/// `block` bytes of text are held at a time (more only for a single longer record).
pub(super) struct CsvChunks {
    source: std::fs::File,
    /// Text read and not yet parsed (starts at a line start).
    buf: Vec<u8>,
    eof: bool,
    block: usize,
    /// The file's columns resolved against the contract.
    pub(super) layout: Layout,
    names: Vec<String>,
    /// Data rows and text lines before `buf`.
    rows_before: usize,
    lines_before: usize,
}

impl CsvChunks {
    /// Opens the file `source` (`file` names it in errors) and reads its header.
    pub(super) fn new(
        mut source: std::fs::File,
        path: &std::path::Path,
        file: &str,
        positions: Positions,
        block: usize,
    ) -> Result<Self> {
        let block = block.max(1 << 12);
        let mut buf = Vec::with_capacity(block);
        let mut eof = false;
        fill(&mut source, &mut buf, block, &mut eof, path)?;
        if buf.starts_with(b"\xEF\xBB\xBF") {
            buf.drain(..3);
        }
        while !eof && header_line_end(&buf).is_none() {
            let want = buf.len() + block;
            fill(&mut source, &mut buf, want, &mut eof, path)?;
        }
        let h = header(&buf, file, positions)?;
        buf.drain(..h.data_start);
        Ok(CsvChunks {
            source,
            buf,
            eof,
            block,
            layout: h.layout,
            names: h.names,
            rows_before: 0,
            lines_before: h.first_line - 1,
        })
    }

    /// The next rows (checked as [`MeasurementTable::validate_named`] does, within the piece), with the
    /// 0-based file row of the first; `None` at the end. Errors name file-wide rows and lines.
    pub(super) fn next_table(
        &mut self,
        path: &std::path::Path,
        file: &str,
    ) -> Result<Option<(usize, MeasurementTable)>> {
        loop {
            if !self.eof && self.buf.len() < self.block {
                fill(
                    &mut self.source,
                    &mut self.buf,
                    self.block,
                    &mut self.eof,
                    path,
                )?;
            }
            let split = if self.eof {
                self.buf.len()
            } else {
                match last_line_end(&self.buf) {
                    Some(e) => e,
                    None => {
                        // One record longer than a block: read on.
                        let want = self.buf.len() + self.block;
                        fill(&mut self.source, &mut self.buf, want, &mut self.eof, path)?;
                        continue;
                    }
                }
            };
            if split == 0 {
                return Ok(None);
            }
            let part = &self.buf[..split];
            let chunk =
                parse_chunk(part, std::str::from_utf8(part).ok(), &self.layout).map_err(|e| {
                    SimError::Table {
                        file: file.to_string(),
                        row: e.row.map(|r| self.rows_before + r),
                        line: Some(self.lines_before + e.line),
                        column: e.column.map(|c| fragment(&self.names[c])),
                        message: e.message,
                    }
                })?;
            let first_row = self.rows_before;
            if chunk.rows > 0 {
                let lines_before = self.lines_before;
                chunk.table.validate_named(file).map_err(|e| {
                    super::at_file_row(e, first_row, |r| {
                        line_of_data_row(part, r).map(|l| lines_before + l)
                    })
                })?;
            }
            self.rows_before += chunk.rows;
            self.lines_before += chunk.lines;
            self.buf.drain(..split);
            if chunk.rows > 0 {
                return Ok(Some((first_row, chunk.table)));
            }
        }
    }
}

/// Reads from `source` until `buf` holds `want` bytes or the file ends (`eof` set).
fn fill(
    source: &mut std::fs::File,
    buf: &mut Vec<u8>,
    want: usize,
    eof: &mut bool,
    path: &std::path::Path,
) -> Result<()> {
    use std::io::Read;
    while buf.len() < want && !*eof {
        let start = buf.len();
        buf.resize(want, 0);
        match source.read(&mut buf[start..]) {
            Ok(0) => {
                buf.truncate(start);
                *eof = true;
            }
            Ok(n) => buf.truncate(start + n),
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => buf.truncate(start),
            Err(e) => {
                buf.truncate(start);
                return Err(SimError::Read {
                    path: path.to_path_buf(),
                    source: e,
                });
            }
        }
    }
    Ok(())
}

/// The end (one past the `\n`) of the last complete line of `buf` that is not inside a quoted cell
/// (an even number of `"` before it), if any.
fn last_line_end(buf: &[u8]) -> Option<usize> {
    let mut quotes = 0usize;
    let mut last = None;
    for (i, &b) in buf.iter().enumerate() {
        match b {
            b'"' => quotes += 1,
            b'\n' if quotes.is_multiple_of(2) => last = Some(i + 1),
            _ => {}
        }
    }
    last
}

/// The end of the first line of `buf` that holds more than blanks, outside quotes, if complete.
fn header_line_end(buf: &[u8]) -> Option<usize> {
    let mut quotes = 0usize;
    let mut content = false;
    for (i, &b) in buf.iter().enumerate() {
        match b {
            b'"' => {
                quotes += 1;
                content = true;
            }
            b'\n' if quotes.is_multiple_of(2) && content => return Some(i + 1),
            b' ' | b'\t' | b'\r' | b'\n' => {}
            _ => content = true,
        }
    }
    None
}

/// The 1-based line, within `part` (whole data lines, no header), of its data row `row` (1-based).
fn line_of_data_row(part: &[u8], row: usize) -> Option<usize> {
    let mut rec = Records::new(part);
    let mut cells = Vec::new();
    let mut seen = 0usize;
    while let Ok(Some(line)) = rec.next_record(&mut cells) {
        if is_blank(&cells) {
            continue;
        }
        seen += 1;
        if seen == row {
            return Some(line);
        }
    }
    None
}
