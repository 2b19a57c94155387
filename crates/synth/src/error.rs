//! The typed error of the sample-data generators. Each variant carries the located
//! diagnostic errmap prints.

use errmap_core::error::Diagnostic;

/// Why sample data could not be generated ([`crate::linear::generate`],
/// [`crate::circular::write_set`], [`crate::rotary::write_set`], [`crate::scan::write_scan`],
/// [`crate::web_plate::generate`] …).
#[derive(Debug)]
#[non_exhaustive]
pub enum SynthError {
    /// The generator's parameters mean nothing (a size, a count, a noise level, a layout).
    Options(Diagnostic),
    /// A file read back (a plate's `truth.json`) is not what errmap wrote.
    Input(Diagnostic),
    /// A file read back cannot be read.
    Read(Diagnostic),
    /// An output cannot be written.
    Write(Diagnostic),
    /// A bug in errmap.
    Internal(Diagnostic),
}
errmap_core::typed_error!(SynthError {
    Options,
    Input,
    Read,
    Write,
    Internal
});

impl From<Diagnostic> for SynthError {
    /// A diagnostic by its kind.
    fn from(d: Diagnostic) -> Self {
        match d {
            Diagnostic::Usage { .. } => SynthError::Options(d),
            Diagnostic::Input { .. } | Diagnostic::Numeric { .. } => SynthError::Input(d),
            Diagnostic::Io { .. } if d.is_read() => SynthError::Read(d),
            Diagnostic::Io { .. } => SynthError::Write(d),
            Diagnostic::Device { .. } | Diagnostic::Internal(_) => SynthError::Internal(d),
        }
    }
}
