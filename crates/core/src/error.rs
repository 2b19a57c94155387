//! The located diagnostic every errmap error carries (kind, file, line, column, message, hint)
//! and the glue of the typed errors each operation returns ([`Diagnose`], [`typed_error!`](crate::typed_error)).
//!
//! A library operation returns its own error enum (as `errmap_toolpath::CompensateError`), whose
//! variants say what a caller can act on; each variant carries a [`Diagnostic`], which words
//! the message exactly as errmap prints it. Exit codes are the binary's (`src/cli/exit.rs`).

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

/// A [`Diagnostic`] as a record for files and scripts (`summary.json`).
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct ErrorReport {
    /// `input`, `io`, `device` or `internal` (see [`Diagnostic::kind`]).
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
    /// The diagnostic again, for a command that reports one part's failure as its own: the
    /// kind (and so the exit code), place, message and hint are kept.
    pub fn into_error(self) -> Diagnostic {
        let hint = self.hint.unwrap_or_default();
        match (self.kind.as_str(), self.file) {
            ("input", Some(file)) => Diagnostic::Input {
                location: Location {
                    file,
                    line: self.line,
                    column: self.column,
                },
                message: self.message,
                hint,
            },
            ("input", None) => Diagnostic::Usage {
                message: self.message,
                hint,
            },
            ("io", file) => Diagnostic::Io {
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
            ("device", _) => Diagnostic::Device {
                message: self.message,
                hint,
            },
            _ => Diagnostic::Internal(self.message),
        }
    }
}

/// What went wrong, where and what would fix it: the message errmap prints, word for word.
/// Its kind (input, usage, io, device, numeric, internal) is what `summary.json` records; the
/// binary maps it (and each operation's typed error) to an exit code.
#[derive(Debug, thiserror::Error)]
pub enum Diagnostic {
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

/// The name [`Diagnostic`] had while it was errmap's one error type; the crate that still
/// returns it whole (the batch), its callers and the crates' internals use this name.
pub type Error = Diagnostic;

/// A result whose error is a [`Diagnostic`] unless another error type is named.
pub type Result<T, E = Diagnostic> = std::result::Result<T, E>;

impl Diagnostic {
    /// Bad input at a location, with what would fix it.
    pub fn input(location: Location, message: impl Into<String>, hint: impl Into<String>) -> Self {
        Diagnostic::Input {
            location,
            message: message.into(),
            hint: hint.into(),
        }
    }
    /// A bad option or combination of options, with what would fix it.
    pub fn usage(message: impl Into<String>, hint: impl Into<String>) -> Self {
        Diagnostic::Usage {
            message: message.into(),
            hint: hint.into(),
        }
    }
    /// The GPU could not be used, with what would fix it.
    pub fn device(message: impl Into<String>, hint: impl Into<String>) -> Self {
        Diagnostic::Device {
            message: message.into(),
            hint: hint.into(),
        }
    }
    /// A numerical method failed on valid input (singular system, no convergence), with what
    /// would fix it.
    pub fn numeric(message: impl Into<String>, hint: impl Into<String>) -> Self {
        Diagnostic::Numeric {
            message: message.into(),
            hint: hint.into(),
        }
    }
    /// A file could not be read.
    pub fn read(path: impl AsRef<Path>, source: std::io::Error) -> Self {
        Diagnostic::Io {
            action: "read",
            path: path.as_ref().to_path_buf(),
            source,
        }
    }
    /// A file could not be written.
    pub fn write(path: impl AsRef<Path>, source: std::io::Error) -> Self {
        Diagnostic::Io {
            action: "write",
            path: path.as_ref().to_path_buf(),
            source,
        }
    }
    /// An operation other than a plain read or write ("create folder", "rename …").
    pub fn io(action: &'static str, path: impl AsRef<Path>, source: std::io::Error) -> Self {
        Diagnostic::Io {
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
            Diagnostic::Input { .. } | Diagnostic::Usage { .. } | Diagnostic::Numeric { .. } => {
                "input"
            }
            Diagnostic::Io { .. } => "io",
            Diagnostic::Device { .. } => "device",
            Diagnostic::Internal(_) => "internal",
        }
    }

    /// A file that could not be read (as opposed to written, renamed or created): the input's
    /// fault more often than the machine's, which the binary's exit codes tell apart.
    pub fn is_read(&self) -> bool {
        matches!(self, Diagnostic::Io { action, .. } if *action == "read")
    }

    /// Whether the diagnostic names a line of its file (a bad value, point or block there),
    /// as opposed to the file as a whole or no file at all.
    pub fn at_line(&self) -> bool {
        matches!(self, Diagnostic::Input { location, .. } if location.line.is_some())
    }

    /// The error as data: kind, message, location and hint (what `summary.json` records for a
    /// failed part).
    pub fn report(&self) -> ErrorReport {
        let (message, location, hint) = match self {
            Diagnostic::Input {
                location,
                message,
                hint,
            } => (message.clone(), Some(location.clone()), hint.clone()),
            Diagnostic::Usage { message, hint }
            | Diagnostic::Device { message, hint }
            | Diagnostic::Numeric { message, hint } => (message.clone(), None, hint.clone()),
            Diagnostic::Io {
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
            Diagnostic::Internal(m) => (
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
}

/// An error that carries a [`Diagnostic`]: every typed error of errmap's library crates, so a
/// caller that only prints (or records a part's failure in `summary.json`) treats them alike.
pub trait Diagnose: std::error::Error {
    /// The located diagnostic: kind, file, line, column, message and hint.
    fn diagnostic(&self) -> &Diagnostic;
    /// The diagnostic, for a caller that keeps only it.
    fn into_diagnostic(self) -> Diagnostic;
}

impl Diagnose for Diagnostic {
    fn diagnostic(&self) -> &Diagnostic {
        self
    }
    fn into_diagnostic(self) -> Diagnostic {
        self
    }
}

/// A boxed typed error (a caller that keeps a large error off its `Result`'s stack) carries
/// the same diagnostic.
impl<T: Diagnose> Diagnose for Box<T> {
    fn diagnostic(&self) -> &Diagnostic {
        (**self).diagnostic()
    }
    fn into_diagnostic(self) -> Diagnostic {
        (*self).into_diagnostic()
    }
}

/// Gives a typed error enum whose every variant carries one [`Diagnose`] value (a
/// [`Diagnostic`] or another typed error) what every errmap error has: [`Diagnose`], `Display`
/// and `source` exactly as the carried diagnostic's (so every message stays word for word), and
/// `From<enum> for Diagnostic` (so a caller still on [`Diagnostic`] takes it with `?`).
///
/// ```
/// use errmap_core::error::{Diagnose, Diagnostic};
///
/// /// Why a calibration could not be read.
/// #[derive(Debug)]
/// pub enum CalibrationError {
///     /// A bad value at a line.
///     Value(Diagnostic),
///     /// The file cannot be read.
///     Read(Diagnostic),
/// }
/// errmap_core::typed_error!(CalibrationError { Value, Read });
///
/// let e = CalibrationError::Value(Diagnostic::usage("offset is not a number", "give mm"));
/// assert_eq!(e.to_string(), "offset is not a number (hint: give mm)");
/// assert_eq!(Diagnostic::from(e).kind(), "input");
/// ```
#[macro_export]
macro_rules! typed_error {
    ($ty:ident { $($variant:ident),+ $(,)? }) => {
        impl $crate::error::Diagnose for $ty {
            fn diagnostic(&self) -> &$crate::error::Diagnostic {
                match self {
                    $( $ty::$variant(inner) => $crate::error::Diagnose::diagnostic(inner), )+
                }
            }
            fn into_diagnostic(self) -> $crate::error::Diagnostic {
                match self {
                    $( $ty::$variant(inner) => $crate::error::Diagnose::into_diagnostic(inner), )+
                }
            }
        }
        impl ::std::fmt::Display for $ty {
            fn fmt(&self, f: &mut ::std::fmt::Formatter<'_>) -> ::std::fmt::Result {
                ::std::fmt::Display::fmt($crate::error::Diagnose::diagnostic(self), f)
            }
        }
        impl ::std::error::Error for $ty {
            fn source(&self) -> ::std::option::Option<&(dyn ::std::error::Error + 'static)> {
                ::std::error::Error::source($crate::error::Diagnose::diagnostic(self))
            }
        }
        impl ::std::convert::From<$ty> for $crate::error::Diagnostic {
            fn from(e: $ty) -> Self {
                $crate::error::Diagnose::into_diagnostic(e)
            }
        }
    };
}
