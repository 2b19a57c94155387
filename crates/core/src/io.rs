//! File plumbing shared by every module: atomic writes that obey the output safety rules, and a streaming CSV table reader that keeps line numbers for error messages.

pub mod columns;
pub(crate) mod lines;
pub mod safety;
pub mod stamp;

use crate::error::{Error, Location, Result};
use std::collections::HashMap;
use std::io::Write;
use std::path::{Path, PathBuf};

/// 1-based (line, column) of a byte offset in a text, the column in characters, as an editor
/// shows them (the TOML files' error locations: job files and live configs).
pub fn line_col(text: &str, byte: usize) -> (u64, u64) {
    let end = byte.min(text.len());
    let before = &text.as_bytes()[..end];
    let line = 1 + before.iter().filter(|&&b| b == b'\n').count() as u64;
    let line_start = before
        .iter()
        .rposition(|&b| b == b'\n')
        .map_or(0, |p| p + 1);
    let col = 1 + text.get(line_start..end).map_or(0, |s| s.chars().count()) as u64;
    (line, col)
}

/// Write a file atomically: the content goes to a temporary file beside `path`, which is
/// flushed and then renamed over the target, so an interrupted run never leaves a
/// half-written file that looks complete. The file is created with mode 0666 less the umask,
/// like every Unix tool's output, and [`safety::check_output`] refuses a path that is one of
/// the command's inputs or lies outside its output folder.
pub fn write_atomic(
    path: &Path,
    fill: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> Result<()> {
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    std::fs::create_dir_all(&dir).map_err(|e| Error::io("create folder", &dir, e))?;
    safety::check_output(path)?;
    let mut builder = tempfile::Builder::new();
    builder.prefix(".errmap-").suffix(".tmp");
    // tempfile's default is 0600; the kernel applies the umask to the mode asked for here.
    #[cfg(unix)]
    builder.permissions(std::os::unix::fs::PermissionsExt::from_mode(0o666));
    let mut tmp = builder
        .tempfile_in(&dir)
        .map_err(|e| Error::io("create a temporary file in", &dir, e))?;
    {
        let limit = safety::max_output_bytes();
        let mut limited = Limited {
            inner: std::io::BufWriter::new(tmp.as_file_mut()),
            left: limit,
            tripped: false,
        };
        let filled = fill(&mut limited).and_then(|()| limited.inner.flush());
        if limited.tripped {
            return Err(Error::usage(
                format!(
                    "{} would exceed the output limit of {} MB",
                    path.display(),
                    limit / 1_000_000
                ),
                format!(
                    "choose coarser steps or spacings, or raise {}",
                    crate::setting::words(crate::core_setting::Setting::MaxOutputMb)
                ),
            ));
        }
        filled.map_err(|e| Error::write(path, e))?;
    }
    tmp.as_file()
        .sync_all()
        .map_err(|e| Error::write(path, e))?;
    tmp.persist(path)
        .map_err(|e| Error::io("rename the finished file to", path, e.error))?;
    Ok(())
}

/// A writer that refuses to grow a file past a limit (outputs whose size follows from user
/// numbers: grid steps, segment lengths, table spacings).
struct Limited<W: Write> {
    inner: W,
    left: u64,
    tripped: bool,
}

impl<W: Write> Write for Limited<W> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        if buf.len() as u64 > self.left {
            self.tripped = true;
            return Err(std::io::Error::other("output size limit reached"));
        }
        let n = self.inner.write(buf)?;
        self.left -= n as u64;
        Ok(n)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}

/// [`write_atomic`] for content already in memory.
///
/// ```
/// let dir = tempfile::tempdir().unwrap();
/// let path = dir.path().join("table.txt");
/// errmap_core::io::write_atomic_bytes(&path, b"0 0.000 0.000\n").unwrap();
/// assert_eq!(std::fs::read(&path).unwrap(), b"0 0.000 0.000\n");
/// // Nothing else is left in the folder: the temporary file was renamed into place.
/// assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
/// ```
pub fn write_atomic_bytes(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic(path, |w| w.write_all(bytes))
}

/// Serialise a value as pretty JSON (with a final newline) and write it atomically.
pub fn write_json<T: serde::Serialize>(path: &Path, value: &T) -> Result<()> {
    let mut text = serde_json::to_string_pretty(value)
        .map_err(|e| Error::Internal(format!("JSON for {}: {e}", path.display())))?;
    text.push('\n');
    write_atomic_bytes(path, text.as_bytes())
}

/// Read a whole file as UTF-8 text, with the error naming the file. The file becomes a
/// protected input ([`safety::protect`]).
pub fn read_text(path: &Path) -> Result<String> {
    safety::protect(path);
    std::fs::read_to_string(path).map_err(|e| Error::read(path, e))
}

/// Open a file for reading, with the error naming the file; it becomes a protected input.
pub fn open(path: &Path) -> Result<std::fs::File> {
    safety::protect(path);
    std::fs::File::open(path).map_err(|e| Error::read(path, e))
}

/// A CSV file read whole: its header and its records, each with its 1-based line number.
/// Columns are looked up by name; every error names file, line and column.
#[derive(Debug, Clone)]
pub struct CsvTable {
    /// The file read; every error about the table names it.
    pub path: PathBuf,
    /// Column names as written in the header, trimmed (a leading byte-order mark removed).
    pub headers: Vec<String>,
    /// The records in file order, without blank and `#` lines.
    pub rows: Vec<CsvRow>,
    /// 1-based line of the header (1 unless lines before it were skipped).
    pub header_line: u64,
    /// Lines with text before the header that were skipped (an instrument's date, title or
    /// program name); blank and `#` lines are not counted.
    pub preamble_lines: usize,
    index: HashMap<String, usize>,
}

/// Where the header of a CSV export is.
pub enum HeaderAt<'a> {
    /// This 1-based line.
    Line(u64),
    /// The first line (not blank, not `#`) whose cells satisfy the test.
    First(&'a dyn Fn(&[String]) -> bool),
}

/// One record of a [`CsvTable`].
#[derive(Debug, Clone)]
pub struct CsvRow {
    /// 1-based line of the file where the record starts, for messages.
    pub line: u64,
    /// The record's cells, trimmed, one per header column.
    pub fields: csv::StringRecord,
}

/// Comment character of errmap's CSV files.
const CSV_COMMENT: u8 = b'#';

impl CsvTable {
    /// Read a CSV file with a header line. Blank lines and lines starting with `#` are skipped;
    /// headers and fields are trimmed. A record with a different number of fields from the
    /// header is an error naming its line. The file is streamed: line numbers are tracked as
    /// it is read (linear in its size), and memory holds the records, not the file twice.
    pub fn read(path: &Path) -> Result<CsvTable> {
        let file = open(path)?;
        Self::from_reader(path, std::io::BufReader::with_capacity(1 << 16, file))
    }

    /// Parse CSV text; `path` is only used in messages.
    pub fn parse(path: &Path, text: &str) -> Result<CsvTable> {
        Self::from_reader(path, text.as_bytes())
    }

    /// Read a CSV export whose header is not on its first line: the lines before the header
    /// are skipped and counted ([`CsvTable::preamble_lines`]); from the header on the file is
    /// read as [`CsvTable::read`] reads it, line numbers counting from the file's start. The
    /// file is streamed once.
    pub fn read_with_header(path: &Path, at: HeaderAt, missing_hint: &str) -> Result<CsvTable> {
        use std::io::BufRead;
        let file = open(path)?;
        let mut reader = std::io::BufReader::with_capacity(1 << 16, file);
        let mut line = Vec::new();
        let mut number = 0u64;
        let mut preamble = 0usize;
        loop {
            line.clear();
            let n = reader
                .read_until(b'\n', &mut line)
                .map_err(|e| Error::read(path, e))?;
            if n == 0 {
                let message = match at {
                    HeaderAt::Line(want) => {
                        format!("the file has {number} lines, so line {want} cannot be its header")
                    }
                    HeaderAt::First(_) => {
                        "no line of the file names every mapped column".to_string()
                    }
                };
                return Err(Error::input(Location::file(path), message, missing_hint));
            }
            number += 1;
            let cells = header_cells(&line);
            let has_text = !(cells.iter().all(|c| c.is_empty())
                || line.trim_ascii_start().first() == Some(&CSV_COMMENT));
            let found = match at {
                HeaderAt::Line(want) => number == want,
                HeaderAt::First(test) => has_text && test(&cells),
            };
            if found {
                break;
            }
            if has_text {
                preamble += 1;
            }
        }
        let rest = std::io::Read::chain(std::io::Cursor::new(line), reader);
        let mut table = Self::from_reader_at(path, rest, number - 1)?;
        table.preamble_lines = preamble;
        Ok(table)
    }

    /// Parse CSV from a reader; `path` is only used in messages.
    pub fn from_reader(path: &Path, source: impl std::io::Read) -> Result<CsvTable> {
        Self::from_reader_at(path, source, 0)
    }

    /// [`CsvTable::from_reader`] for a stream that starts after `skipped` lines of its file:
    /// every line number is counted from the file's start.
    fn from_reader_at(path: &Path, source: impl std::io::Read, skipped: u64) -> Result<CsvTable> {
        let csv_error = |path: &Path, e: csv::Error| -> Error {
            let mut err = csv_error(path, e);
            if let Error::Input { location, .. } = &mut err {
                location.line = location.line.map(|l| l + skipped);
            }
            err
        };
        let header_line = skipped + 1;
        let (tracked, lines) = lines::track(source);
        let mut reader = csv::ReaderBuilder::new()
            .has_headers(true)
            .comment(Some(CSV_COMMENT))
            .trim(csv::Trim::All)
            .flexible(true)
            .from_reader(tracked);
        let headers: Vec<String> = reader
            .headers()
            .map_err(|e| csv_error(path, e))?
            .iter()
            .map(|h| h.trim_start_matches('\u{feff}').to_string())
            .collect();
        if headers.iter().all(|h| h.is_empty()) {
            return Err(Error::input(
                Location::line(path, header_line),
                "the file has no header line",
                "the first line must name the columns (see the file format in the docs)",
            ));
        }
        let mut index = HashMap::new();
        for (i, h) in headers.iter().enumerate() {
            if index.insert(h.clone(), i).is_some() {
                return Err(Error::input(
                    Location::cell(path, header_line, h.clone()),
                    format!("column '{h}' appears twice in the header"),
                    "keep one column of each name",
                ));
            }
        }
        let mut rows = Vec::new();
        let mut record = csv::StringRecord::new();
        loop {
            match reader.read_record(&mut record) {
                Ok(true) => {}
                Ok(false) => break,
                Err(e) => return Err(csv_error(path, e)),
            }
            // The csv crate's own line count includes the blank and comment lines it skipped
            // before the record: step over them from the record's byte offset.
            let line = record
                .position()
                .map(|p| lines.line_of_record(p.byte(), Some(CSV_COMMENT)) + skipped)
                .unwrap_or(0);
            if record.iter().all(|f| f.is_empty()) {
                continue;
            }
            if record.len() != headers.len() {
                return Err(Error::input(
                    Location::line(path, line),
                    format!(
                        "{} fields, but the header names {} columns",
                        record.len(),
                        headers.len()
                    ),
                    "give every row one value per header column",
                ));
            }
            let mut fields = record.clone();
            fields.set_position(None);
            rows.push(CsvRow { line, fields });
        }
        Ok(CsvTable {
            path: path.to_path_buf(),
            headers,
            rows,
            header_line,
            preamble_lines: 0,
            index,
        })
    }

    /// A table from a header and records already read (an instrument export mapped onto
    /// errmap's columns); a header named twice is an error.
    pub fn from_records(path: &Path, headers: Vec<String>, rows: Vec<CsvRow>) -> Result<CsvTable> {
        let mut index = HashMap::new();
        for (i, h) in headers.iter().enumerate() {
            if index.insert(h.clone(), i).is_some() {
                return Err(Error::input(
                    Location::cell(path, 1, h.clone()),
                    format!("column '{h}' appears twice in the header"),
                    "keep one column of each name",
                ));
            }
        }
        Ok(CsvTable {
            path: path.to_path_buf(),
            headers,
            rows,
            header_line: 1,
            preamble_lines: 0,
            index,
        })
    }

    /// Index of a column, if the header has it.
    pub fn column(&self, name: &str) -> Option<usize> {
        self.index.get(name).copied()
    }

    /// Index of a column the file must have.
    pub fn require(&self, name: &str) -> Result<usize> {
        self.column(name).ok_or_else(|| {
            Error::input(
                Location::line(&self.path, self.header_line),
                format!(
                    "missing column '{name}' (header has: {})",
                    self.headers.join(",")
                ),
                format!("add a '{name}' column to the header"),
            )
        })
    }

    /// Reject any header column not in `allowed` (catches typos such as `x_um`).
    pub fn reject_unknown(&self, allowed: &[&str]) -> Result<()> {
        for h in &self.headers {
            if !allowed.contains(&h.as_str()) {
                return Err(Error::input(
                    Location::cell(&self.path, self.header_line, h.clone()),
                    format!("unknown column '{h}'"),
                    format!("allowed columns are: {}", allowed.join(",")),
                ));
            }
        }
        Ok(())
    }

    /// The text of a cell.
    pub fn text<'a>(&'a self, row: &'a CsvRow, col: usize) -> &'a str {
        &row.fields[col]
    }

    /// A finite number from a cell; non-numbers, NaN and infinities are errors naming the cell.
    pub fn f64(&self, row: &CsvRow, col: usize) -> Result<f64> {
        let text = &row.fields[col];
        let at = || Location::cell(&self.path, row.line, self.headers[col].clone());
        let value: f64 = text.parse().map_err(|_| {
            Error::input(
                at(),
                format!("'{text}' is not a number"),
                "write a decimal number such as 12.5",
            )
        })?;
        if !value.is_finite() {
            return Err(Error::input(
                at(),
                format!("'{text}' is not a finite number"),
                "NaN and infinity are not measurements; remove the row or fix the value",
            ));
        }
        Ok(value)
    }

    /// An optional number: an empty cell gives `None`.
    pub fn f64_opt(&self, row: &CsvRow, col: usize) -> Result<Option<f64>> {
        if row.fields[col].is_empty() {
            Ok(None)
        } else {
            self.f64(row, col).map(Some)
        }
    }

    /// An error located at a cell of this table.
    pub fn error_at(
        &self,
        row: &CsvRow,
        col: Option<usize>,
        message: impl Into<String>,
        hint: impl Into<String>,
    ) -> Error {
        let location = match col {
            Some(c) => Location::cell(&self.path, row.line, self.headers[c].clone()),
            None => Location::line(&self.path, row.line),
        };
        Error::input(location, message, hint)
    }
}

/// The trimmed cells of one line as the CSV reader would split it (quotes honoured; a line
/// the reader cannot split has no cells).
fn header_cells(line: &[u8]) -> Vec<String> {
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(false)
        .trim(csv::Trim::All)
        .flexible(true)
        .from_reader(line);
    let mut record = csv::StringRecord::new();
    match reader.read_record(&mut record) {
        Ok(true) => record
            .iter()
            .map(|c| c.trim_start_matches('\u{feff}').to_string())
            .collect(),
        _ => Vec::new(),
    }
}

fn csv_error(path: &Path, e: csv::Error) -> Error {
    csv_error_hinted(path, e, "save the file as plain comma-separated UTF-8 text")
}

/// A CSV reader's error: an io error when the file could not be read, else unreadable content
/// at its line with `hint`.
pub fn csv_error_hinted(path: &Path, e: csv::Error, hint: &str) -> Error {
    let line = e.position().map(|p| p.line());
    let message = format!("unreadable CSV: {e}");
    match e.into_kind() {
        // The file itself could not be read (a folder, a device error): an io error, not content.
        csv::ErrorKind::Io(source) => Error::read(path, source),
        _ => Error::input(
            Location {
                file: path.to_path_buf(),
                line,
                column: None,
            },
            message,
            hint,
        ),
    }
}

/// Environment variable naming errmap's cache folder (default `$XDG_CACHE_HOME/errmap`,
/// else `~/.cache/errmap`).
pub const CACHE_ENV: &str = "ERRMAP_CACHE_DIR";

/// errmap's cache folder ([`CACHE_ENV`], `$XDG_CACHE_HOME/errmap` or `~/.cache/errmap`).
pub fn cache_dir() -> Option<PathBuf> {
    if let Some(dir) = std::env::var_os(CACHE_ENV).filter(|d| !d.is_empty()) {
        return Some(PathBuf::from(dir));
    }
    if let Some(dir) = std::env::var_os("XDG_CACHE_HOME").filter(|d| !d.is_empty()) {
        return Some(PathBuf::from(dir).join("errmap"));
    }
    std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache").join("errmap"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn line_col_counts_lines_and_characters_from_one() {
        // "ab\n" is bytes 0–2, "cdé\n" 3–7 (é is two bytes), "f" is byte 8.
        let text = "ab\ncdé\nf";
        assert_eq!(line_col(text, 0), (1, 1));
        assert_eq!(line_col(text, 2), (1, 3));
        assert_eq!(line_col(text, 7), (2, 4));
        assert_eq!(line_col(text, 8), (3, 1));
        assert_eq!(line_col(text, 99), (3, 2), "past the end: the end");
    }

    #[test]
    fn numbers_and_errors_name_line_and_column() {
        let t = CsvTable::parse(Path::new("p.csv"), "x_mm,y_mm\n1,2\n\n3,abc\n").unwrap();
        assert_eq!(t.rows.len(), 2);
        assert_eq!(t.rows[1].line, 4);
        let x = t.require("x_mm").unwrap();
        let y = t.require("y_mm").unwrap();
        assert_eq!(t.f64(&t.rows[0], x).unwrap(), 1.0);
        let err = t.f64(&t.rows[1], y).unwrap_err().to_string();
        assert!(
            err.contains("p.csv:4, column y_mm") && err.contains("'abc' is not a number"),
            "{err}"
        );
        let err = t.require("z_mm").unwrap_err().to_string();
        assert!(err.contains("missing column 'z_mm'"), "{err}");
        let err = CsvTable::parse(Path::new("p.csv"), "a,b\n1,2,3\n")
            .unwrap_err()
            .to_string();
        assert!(err.contains("p.csv:2") && err.contains("3 fields"), "{err}");
        let t = CsvTable::parse(Path::new("p.csv"), "a\nNaN\n").unwrap();
        assert!(t
            .f64(&t.rows[0], 0)
            .unwrap_err()
            .to_string()
            .contains("not a finite number"));
    }

    #[test]
    fn line_numbers_count_comments_crlf_and_quoted_newlines() {
        let text = "# head\r\na,b\r\n1,2\r\n\r\n# note\r\n3,\"x\r\ny\"\r\n\r\n5,6";
        let t = CsvTable::parse(Path::new("p.csv"), text).unwrap();
        let lines: Vec<u64> = t.rows.iter().map(|r| r.line).collect();
        assert_eq!(lines, vec![3, 6, 9]);
        assert_eq!(&t.rows[1].fields[1], "x\r\ny");
        // The same from a reader that hands out one byte at a time.
        struct OneByte<'a>(&'a [u8]);
        impl std::io::Read for OneByte<'_> {
            fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
                let n = self.0.len().min(1).min(buf.len());
                buf[..n].copy_from_slice(&self.0[..n]);
                self.0 = &self.0[n..];
                Ok(n)
            }
        }
        let t = CsvTable::from_reader(Path::new("p.csv"), OneByte(text.as_bytes())).unwrap();
        let again: Vec<u64> = t.rows.iter().map(|r| r.line).collect();
        assert_eq!(again, lines);
    }

    #[test]
    fn atomic_write_replaces_whole_file_and_leaves_no_temp() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sub/out.txt");
        write_atomic_bytes(&path, b"first").unwrap();
        write_atomic_bytes(&path, b"second").unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "second");
        let names: Vec<_> = std::fs::read_dir(path.parent().unwrap())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names.len(), 1, "{names:?}");
        // A failing writer leaves the old content in place.
        let failed = write_atomic(&path, |w| {
            w.write_all(b"partial")?;
            Err(std::io::Error::other("interrupted"))
        });
        assert!(failed.is_err());
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "second");
    }
}
