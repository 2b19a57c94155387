//! The one error type of errmap: every input error names its file, line and column and says what would fix it.

use std::fmt;
use std::path::{Path, PathBuf};

/// Where in an input file a problem sits. Lines are 1-based as an editor shows them;
/// `column` is the CSV column name (or 1-based field number) or a G-code word.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Location {
    pub file: PathBuf,
    pub line: Option<u64>,
    pub column: Option<String>,
}

impl Location {
    pub fn file(file: impl AsRef<Path>) -> Self {
        Location {
            file: file.as_ref().to_path_buf(),
            line: None,
            column: None,
        }
    }
    pub fn line(file: impl AsRef<Path>, line: u64) -> Self {
        Location {
            file: file.as_ref().to_path_buf(),
            line: Some(line),
            column: None,
        }
    }
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

/// Everything that can go wrong in errmap. The CLI maps each kind to an exit code
/// (see [`Error::exit_code`]).
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Bad content in an input file (CSV, TOML, G-code …).
    #[error("{location}: {message}{}", hint_suffix(.hint))]
    Input {
        location: Location,
        message: String,
        hint: String,
    },

    /// A bad option or combination of options, not tied to a file.
    #[error("{message}{}", hint_suffix(.hint))]
    Usage { message: String, hint: String },

    /// A file could not be read or written.
    #[error("cannot {action} {}: {source}", .path.display())]
    Io {
        action: &'static str,
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },

    /// The GPU could not be used (no adapter, device lost, out of memory, limits too small).
    #[error("GPU: {message}{}", hint_suffix(.hint))]
    Device { message: String, hint: String },

    /// A numerical method could not produce a result from otherwise valid input
    /// (singular system, no convergence).
    #[error("{message}{}", hint_suffix(.hint))]
    Numeric { message: String, hint: String },

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
    pub fn usage(message: impl Into<String>, hint: impl Into<String>) -> Self {
        Error::Usage {
            message: message.into(),
            hint: hint.into(),
        }
    }
    pub fn device(message: impl Into<String>, hint: impl Into<String>) -> Self {
        Error::Device {
            message: message.into(),
            hint: hint.into(),
        }
    }
    pub fn numeric(message: impl Into<String>, hint: impl Into<String>) -> Self {
        Error::Numeric {
            message: message.into(),
            hint: hint.into(),
        }
    }
    pub fn read(path: impl AsRef<Path>, source: std::io::Error) -> Self {
        Error::Io {
            action: "read",
            path: path.as_ref().to_path_buf(),
            source,
        }
    }
    pub fn write(path: impl AsRef<Path>, source: std::io::Error) -> Self {
        Error::Io {
            action: "write",
            path: path.as_ref().to_path_buf(),
            source,
        }
    }

    /// CLI exit code: 2 bad input or usage, 3 internal or device failure.
    /// (Exit code 1, "a batch finished but some parts failed", is decided by the batch.)
    pub fn exit_code(&self) -> i32 {
        match self {
            Error::Input { .. } | Error::Usage { .. } | Error::Numeric { .. } => 2,
            Error::Io { action, .. } if *action == "read" => 2,
            Error::Io { .. } | Error::Device { .. } | Error::Internal(_) => 3,
        }
    }
}
