//! The one error type of errmap: every input error names its file, line and column and says what would fix it.

use std::fmt;
use std::path::{Path, PathBuf};

/// Where in an input file a problem sits. Lines are 1-based as an editor shows them;
/// `column` is the CSV column name (or 1-based field number) or a G-code word.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Location {
    /// The input file, as the user named it.
    pub file: PathBuf,
    /// 1-based line number; `None` when the problem is the file as a whole.
    pub line: Option<u64>,
    /// CSV column name (or 1-based field number) or G-code word; `None` for the whole line.
    pub column: Option<String>,
}

impl Location {
    /// The whole file, no line.
    pub fn file(file: impl AsRef<Path>) -> Self {
        Location {
            file: file.as_ref().to_path_buf(),
            line: None,
            column: None,
        }
    }
    /// One line (1-based) of a file.
    pub fn line(file: impl AsRef<Path>, line: u64) -> Self {
        Location {
            file: file.as_ref().to_path_buf(),
            line: Some(line),
            column: None,
        }
    }
    /// One cell: a line (1-based) and a column name, field number or G-code word.
    pub fn cell(file: impl AsRef<Path>, line: u64, column: impl Into<String>) -> Self {
        Location {
            file: file.as_ref().to_path_buf(),
            line: Some(line),
            column: Some(column.into()),
        }
    }
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file.display())?;
        if let Some(line) = self.line {
            write!(f, ":{line}")?;
        }
        if let Some(column) = &self.column {
            write!(f, ", column {column}")?;
        }
        Ok(())
    }
}

/// An [`Error`] as a record for files and scripts (`summary.json`).
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct ErrorReport {
    /// `input`, `io`, `device` or `internal` (see [`Error::kind`]).
    pub kind: String,
    /// What went wrong, without the location or hint.
    pub message: String,
    /// The file at fault; `None` for errors not tied to a file (options, GPU, internal).
    pub file: Option<PathBuf>,
    /// 1-based line in `file`; `None` when the whole file is at fault or there is no file.
    pub line: Option<u64>,
    /// CSV column name (or field number) or G-code word; `None` when not known.
    pub column: Option<String>,
    /// What would fix it; `None` when the error has no hint.
    pub hint: Option<String>,
}

impl fmt::Display for ErrorReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if let Some(file) = &self.file {
            let location = Location {
                file: file.clone(),
                line: self.line,
                column: self.column.clone(),
            };
            write!(f, "{location}: ")?;
        }
        write!(f, "{}", self.message)?;
        if let Some(hint) = &self.hint {
            write!(f, " (hint: {hint})")?;
        }
        Ok(())
    }
}

impl ErrorReport {
    /// The error again, for a command that reports one part's failure as its own: the kind
    /// (and so the exit code), place, message and hint are kept.
    pub fn into_error(self) -> Error {
        let hint = self.hint.unwrap_or_default();
        match (self.kind.as_str(), self.file) {
            ("input", Some(file)) => Error::Input {
                location: Location {
                    file,
                    line: self.line,
                    column: self.column,
                },
                message: self.message,
                hint,
            },
            ("input", None) => Error::Usage {
                message: self.message,
                hint,
            },
            ("io", file) => Error::Io {
                action: if self.message.starts_with("cannot read") {
                    "read"
                } else {
                    "write"
                },
                path: file.unwrap_or_default(),
                source: std::io::Error::other(
                    self.message
                        .split_once(": ")
                        .map_or(self.message.clone(), |(_, cause)| cause.to_string()),
                ),
            },
            ("device", _) => Error::Device {
                message: self.message,
                hint,
            },
            _ => Error::Internal(self.message),
        }
    }
}

/// Everything that can go wrong in errmap. The CLI maps each kind to an exit code
/// (see [`Error::exit_code`]).
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Bad content in an input file (CSV, TOML, G-code …).
    #[error("{location}: {message}{}", hint_suffix(.hint))]
    Input {
        /// File, line and column of the bad content.
        location: Location,
        /// What is wrong there.
        message: String,
        /// What would fix it (empty for none).
        hint: String,
    },

    /// A bad option or combination of options, not tied to a file.
    #[error("{message}{}", hint_suffix(.hint))]
    Usage {
        /// What is wrong with the options.
        message: String,
        /// What would fix it (empty for none).
        hint: String,
    },

    /// A file could not be read or written.
    #[error("cannot {action} {}: {source}", .path.display())]
    Io {
        /// What was attempted, as a verb phrase after "cannot": `read`, `write`, `create folder` …
        action: &'static str,
        /// The file or folder it was attempted on.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },

    /// The GPU could not be used (no adapter, device lost, out of memory, limits too small).
    #[error("GPU: {message}{}", hint_suffix(.hint))]
    Device {
        /// What failed on the GPU.
        message: String,
        /// What would fix it (empty for none).
        hint: String,
    },

    /// A numerical method could not produce a result from otherwise valid input
    /// (singular system, no convergence).
    #[error("{message}{}", hint_suffix(.hint))]
    Numeric {
        /// Which method failed on which data.
        message: String,
        /// What would fix it (empty for none).
        hint: String,
    },

    /// A bug in errmap: an invariant that should have held did not.
    #[error("internal error: {0}")]
    Internal(String),
}

fn hint_suffix(hint: &str) -> String {
    if hint.is_empty() {
        String::new()
    } else {
        format!(" (hint: {hint})")
    }
}

/// errmap's result: [`Error`] unless another error type is named.
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// Bad input at a location, with what would fix it.
    pub fn input(location: Location, message: impl Into<String>, hint: impl Into<String>) -> Self {
        Error::Input {
            location,
            message: message.into(),
            hint: hint.into(),
        }
    }
    /// A bad option or combination of options, with what would fix it.
    pub fn usage(message: impl Into<String>, hint: impl Into<String>) -> Self {
        Error::Usage {
            message: message.into(),
            hint: hint.into(),
        }
    }
    /// The GPU could not be used, with what would fix it.
    pub fn device(message: impl Into<String>, hint: impl Into<String>) -> Self {
        Error::Device {
            message: message.into(),
            hint: hint.into(),
        }
    }
    /// A numerical method failed on valid input (singular system, no convergence), with what
    /// would fix it.
    pub fn numeric(message: impl Into<String>, hint: impl Into<String>) -> Self {
        Error::Numeric {
            message: message.into(),
            hint: hint.into(),
        }
    }
    /// A file could not be read.
    pub fn read(path: impl AsRef<Path>, source: std::io::Error) -> Self {
        Error::Io {
            action: "read",
            path: path.as_ref().to_path_buf(),
            source,
        }
    }
    /// A file could not be written.
    pub fn write(path: impl AsRef<Path>, source: std::io::Error) -> Self {
        Error::Io {
            action: "write",
            path: path.as_ref().to_path_buf(),
            source,
        }
    }
    /// An operation other than a plain read or write ("create folder", "rename …").
    pub fn io(action: &'static str, path: impl AsRef<Path>, source: std::io::Error) -> Self {
        Error::Io {
            action,
            path: path.as_ref().to_path_buf(),
            source,
        }
    }

    /// The kind a script can act on: `input` (bad file content, options or data a method cannot
    /// use: fix the input), `io` (a file could not be read or written), `device` (the GPU) or
    /// `internal` (a bug in errmap).
    pub fn kind(&self) -> &'static str {
        match self {
            Error::Input { .. } | Error::Usage { .. } | Error::Numeric { .. } => "input",
            Error::Io { .. } => "io",
            Error::Device { .. } => "device",
            Error::Internal(_) => "internal",
        }
    }

    /// The error as data: kind, message, location and hint (what `summary.json` records for a
    /// failed part).
    pub fn report(&self) -> ErrorReport {
        let (message, location, hint) = match self {
            Error::Input {
                location,
                message,
                hint,
            } => (message.clone(), Some(location.clone()), hint.clone()),
            Error::Usage { message, hint }
            | Error::Device { message, hint }
            | Error::Numeric { message, hint } => (message.clone(), None, hint.clone()),
            Error::Io {
                action,
                path,
                source,
            } => (
                format!("cannot {action}: {source}"),
                Some(Location::file(path)),
                match *action {
                    "read" => "check that the file exists and is readable".to_string(),
                    _ => format!(
                        "check that {} is writable and the disk has room",
                        path.display()
                    ),
                },
            ),
            Error::Internal(m) => (
                m.clone(),
                None,
                "this is a bug in errmap: please report it with the input".to_string(),
            ),
        };
        ErrorReport {
            kind: self.kind().to_string(),
            message,
            file: location.as_ref().map(|l| l.file.clone()),
            line: location.as_ref().and_then(|l| l.line),
            column: location.and_then(|l| l.column),
            hint: (!hint.is_empty()).then_some(hint),
        }
    }

    /// CLI exit code: 2 bad input, usage, a numeric failure or a file that cannot be read;
    /// 3 any other I/O failure, the device or an internal error.
    /// (Exit code 1, "a batch finished but some parts failed", is decided by the batch.)
    pub fn exit_code(&self) -> i32 {
        match self {
            Error::Input { .. } | Error::Usage { .. } | Error::Numeric { .. } => 2,
            Error::Io { action, .. } if *action == "read" => 2,
            Error::Io { .. } | Error::Device { .. } | Error::Internal(_) => 3,
        }
    }
}
