//! A CSV stream source: a file a data logger appends to, standard input, or a replay of a log.
//! The format is the machine log of `errmap thermal compensate` (a header line, then one row
//! per reading: `time_s,position_mm,direction,<sensor>…,ambient_c,coolant`, any columns, plain
//! comma-separated values, `#` comment lines); every column is a channel of the source.
//!
//! - On the wall clock each poll takes every complete line that has arrived, stamped with the
//!   loop time it was read at (the newest row wins).
//! - In a replay the `time_s` column is the loop clock: a row is taken once the loop time
//!   reaches its `time_s`, and stamped with it, so a log replays exactly, time-accelerated.

use super::{Snapshot, Source, Value};
use errmap_core::error::{Error, Result};
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::sync::mpsc;

enum Input {
    File(BufReader<std::fs::File>),
    /// Lines read by a thread from standard input.
    Lines(mpsc::Receiver<String>),
}

/// A parsed data row.
struct Row {
    time_s: Option<f64>,
    fields: Vec<String>,
}

/// A CSV source: a machine log in the format of `errmap thermal compensate`, read from a file
/// or standard input, every column a channel; replayed by its `time_s` column or taken as
/// lines arrive on the wall clock.
pub struct CsvSource {
    name: String,
    path: PathBuf,
    headers: Vec<String>,
    time_col: Option<usize>,
    input: Input,
    partial: String,
    line_no: u64,
    replay: bool,
    follow: bool,
    eof: bool,
    next_row: Option<Row>,
    last_time_s: Option<f64>,
    first_time_s: Option<f64>,
    snap: Snapshot,
}

impl CsvSource {
    /// Open the stream and read its header. `path` `-` is standard input. A missing file or
    /// header is a source that cannot be reached (exit 3).
    pub fn open(
        name: &str,
        path: &Path,
        follow: bool,
        replay: bool,
        header_wait_ms: u64,
    ) -> Result<CsvSource> {
        let unreachable = |why: String| {
            Error::io(
                "open the CSV source",
                path,
                std::io::Error::new(std::io::ErrorKind::NotFound, why),
            )
        };
        let input = if path == Path::new("-") {
            let (tx, rx) = mpsc::sync_channel::<String>(4096);
            std::thread::Builder::new()
                .name(format!("csv-stdin-{name}"))
                .spawn(move || {
                    let stdin = std::io::stdin();
                    let mut lock = stdin.lock();
                    let mut line = String::new();
                    loop {
                        line.clear();
                        match lock.read_line(&mut line) {
                            Ok(0) | Err(_) => break,
                            Ok(_) => {
                                if tx.send(std::mem::take(&mut line)).is_err() {
                                    break;
                                }
                            }
                        }
                    }
                })
                .map_err(|e| Error::io("start a reader of", path, e))?;
            Input::Lines(rx)
        } else {
            errmap_core::io::safety::protect(path);
            let file =
                std::fs::File::open(path).map_err(|e| Error::io("open the CSV source", path, e))?;
            Input::File(BufReader::new(file))
        };
        let mut source = CsvSource {
            name: name.to_string(),
            path: path.to_path_buf(),
            headers: Vec::new(),
            time_col: None,
            input,
            partial: String::new(),
            line_no: 0,
            replay,
            follow,
            eof: false,
            next_row: None,
            last_time_s: None,
            first_time_s: None,
            snap: Snapshot::default(),
        };
        let deadline = std::time::Instant::now() + std::time::Duration::from_millis(header_wait_ms);
        let header = loop {
            match source.next_line(true) {
                Some(l) => break l,
                None if source.eof && !source.follow => {
                    return Err(unreachable(
                        "the stream ended before its header line".into(),
                    ))
                }
                None if std::time::Instant::now() >= deadline => {
                    return Err(unreachable(format!(
                        "no header line within {header_wait_ms} ms"
                    )))
                }
                None => std::thread::sleep(std::time::Duration::from_millis(10)),
            }
        };
        source.headers = header.split(',').map(|h| h.trim().to_string()).collect();
        source.time_col = source.headers.iter().position(|h| h == "time_s");
        if replay && source.time_col.is_none() {
            return Err(Error::input(
                errmap_core::error::Location::line(path, source.line_no),
                "a replay needs a time_s column",
                "log time_s in seconds, as `errmap thermal compensate` reads it",
            ));
        }
        if replay {
            source.fetch_row(true);
            source.first_time_s = source.next_row.as_ref().and_then(|r| r.time_s);
        }
        Ok(source)
    }

    /// The next complete, non-comment line (without its end), or None when none has arrived.
    /// `block`: wait for standard input (a replay); a file at its end returns None at once.
    fn next_line(&mut self, block: bool) -> Option<String> {
        loop {
            let got = match &mut self.input {
                Input::File(r) => {
                    let mut chunk = String::new();
                    match r.read_line(&mut chunk) {
                        Ok(0) => None,
                        Ok(_) => Some(chunk),
                        Err(e) => {
                            self.snap.problem = Some(format!("read failed: {e}"));
                            None
                        }
                    }
                }
                Input::Lines(rx) => {
                    let r = if block {
                        rx.recv().map_err(|_| mpsc::TryRecvError::Disconnected)
                    } else {
                        rx.try_recv()
                    };
                    match r {
                        Ok(l) => Some(l),
                        Err(mpsc::TryRecvError::Empty) => return None,
                        Err(mpsc::TryRecvError::Disconnected) => {
                            self.eof = true;
                            return None;
                        }
                    }
                }
            };
            let Some(chunk) = got else {
                if matches!(self.input, Input::File(_)) {
                    self.eof = true;
                }
                return None;
            };
            self.partial.push_str(&chunk);
            if !self.partial.ends_with('\n') {
                // A line still being written: keep it until its end arrives.
                if matches!(self.input, Input::File(_)) {
                    self.eof = true;
                    return None;
                }
                continue;
            }
            self.eof = false;
            self.line_no += 1;
            let line = std::mem::take(&mut self.partial);
            let line = line.trim_end_matches(['\n', '\r']);
            if line.trim().is_empty() || line.trim_start().starts_with('#') {
                continue;
            }
            return Some(line.to_string());
        }
    }

    /// Parse a data line; a bad one is recorded as the source's problem and skipped.
    fn parse(&mut self, line: &str) -> Option<Row> {
        let fields: Vec<String> = line.split(',').map(|f| f.trim().to_string()).collect();
        if fields.len() != self.headers.len() {
            self.snap.problem = Some(format!(
                "{}:{}: {} fields, but the header names {}",
                self.path.display(),
                self.line_no,
                fields.len(),
                self.headers.len()
            ));
            return None;
        }
        let time_s = match self.time_col {
            Some(c) => match fields[c].parse::<f64>().ok().filter(|t| t.is_finite()) {
                Some(t) => Some(t),
                None => {
                    self.snap.problem = Some(format!(
                        "{}:{}: time_s '{}' is not a number",
                        self.path.display(),
                        self.line_no,
                        fields[c]
                    ));
                    return None;
                }
            },
            None => None,
        };
        if let (Some(t), Some(last)) = (time_s, self.last_time_s) {
            if self.replay && t <= last {
                self.snap.problem = Some(format!(
                    "{}:{}: time_s {t} does not increase (previous {last})",
                    self.path.display(),
                    self.line_no
                ));
                return None;
            }
        }
        if time_s.is_some() {
            self.last_time_s = time_s;
        }
        Some(Row { time_s, fields })
    }

    /// Read ahead to the next good row (a replay).
    fn fetch_row(&mut self, block: bool) {
        while self.next_row.is_none() {
            let Some(line) = self.next_line(block) else {
                return;
            };
            self.next_row = self.parse(&line);
        }
    }

    fn apply(&mut self, row: Row, at_s: f64) {
        for (h, f) in self.headers.iter().zip(row.fields) {
            let value = match f.parse::<f64>() {
                Ok(v) => Value::Number(v),
                Err(_) => Value::Text(f),
            };
            self.snap.set(h, value, at_s);
        }
        self.snap.last_ok_s = Some(at_s);
        self.snap.problem = None;
    }
}

impl Source for CsvSource {
    fn name(&self) -> &str {
        &self.name
    }

    fn kind(&self) -> &'static str {
        "csv"
    }

    fn channel_names(&self) -> Vec<String> {
        self.headers.clone()
    }

    fn poll(&mut self, now_s: f64) {
        if self.replay {
            loop {
                self.fetch_row(!self.follow);
                let due = matches!(&self.next_row, Some(r) if r.time_s.unwrap_or(f64::INFINITY) <= now_s + 1e-9);
                if !due {
                    return;
                }
                let row = self.next_row.take().expect("a due row");
                let at = row.time_s.unwrap_or(now_s);
                self.apply(row, at);
            }
        }
        while let Some(line) = self.next_line(false) {
            if let Some(row) = self.parse(&line) {
                self.apply(row, now_s);
            }
        }
    }

    fn snapshot(&self) -> &Snapshot {
        &self.snap
    }

    fn finished(&self) -> bool {
        self.replay && !self.follow && self.eof && self.next_row.is_none()
    }

    fn replay_start_s(&self) -> Option<f64> {
        self.first_time_s
    }
}
