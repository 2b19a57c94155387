//! The typed errors of toolpath compensation: what a caller can act on when a program, its
//! settings or its map are refused. Each variant carries the located diagnostic errmap prints.

use errmap_core::error::Diagnostic;

/// Why compensation settings were refused ([`crate::zone_spec::SettingsText::settings`],
/// [`crate::CompensationSettings::validate`]).
#[derive(Debug)]
#[non_exhaustive]
pub enum SettingsError {
    /// The zone is not `MIN,MAX` (or `all`).
    Zone(Diagnostic),
    /// A controller choice (dialect, units, Fanuc numbers, power-on motion) names none errmap
    /// knows.
    Choice(Diagnostic),
    /// A length or tolerance out of its range (segment length, chord or surface tolerance,
    /// domain margin) or a zone whose minimum exceeds its maximum.
    Range(Diagnostic),
}
errmap_core::typed_error!(SettingsError {
    Zone,
    Choice,
    Range
});

/// Why the dialect of a program could not be told ([`crate::dialect::resolve`]): it shows no
/// construct of one dialect, or constructs of two, and its meaning depends on which.
#[derive(Debug)]
#[non_exhaustive]
pub enum DialectError {
    /// The program's dialect is not certain; the diagnostic names the line that makes it so.
    Uncertain(Diagnostic),
}
errmap_core::typed_error!(DialectError { Uncertain });

/// Why a toolpath was not compensated (or traced): [`crate::compensate_gcode`],
/// [`crate::compensate_csv`], [`crate::compensate_file`], [`crate::trace_gcode`].
#[derive(Debug)]
#[non_exhaustive]
pub enum CompensateError {
    /// The settings mean nothing or would not end.
    Settings(SettingsError),
    /// The program's dialect is not certain (pass one).
    Dialect(DialectError),
    /// The program cannot be followed as written at a block (file, line, column and word):
    /// malformed, a construct errmap does not follow or vouch for in the zone, or a toolpath
    /// that would outgrow the output limit. The message says which.
    Program(Diagnostic),
    /// The map does not tell where it may compensate: no measured domain recorded (without
    /// extrapolation) or no probed surface for the default zone (without a zone given).
    Uncovered(Diagnostic),
    /// The output would overwrite the input toolpath.
    Overwrite(Diagnostic),
    /// A file could not be read.
    Read(Diagnostic),
    /// The compensated toolpath could not be written.
    Write(Diagnostic),
    /// A bug in errmap.
    Internal(Diagnostic),
}
errmap_core::typed_error!(CompensateError {
    Settings,
    Dialect,
    Program,
    Uncovered,
    Overwrite,
    Read,
    Write,
    Internal
});

impl From<Diagnostic> for CompensateError {
    /// A diagnostic from the block reader, the CSV reader or a file operation, by its kind.
    fn from(d: Diagnostic) -> Self {
        match d {
            Diagnostic::Io { .. } if d.is_read() => CompensateError::Read(d),
            Diagnostic::Io { .. } => CompensateError::Write(d),
            Diagnostic::Internal(_) | Diagnostic::Device { .. } => CompensateError::Internal(d),
            Diagnostic::Input { .. } | Diagnostic::Usage { .. } | Diagnostic::Numeric { .. } => {
                CompensateError::Program(d)
            }
        }
    }
}

impl From<SettingsError> for CompensateError {
    fn from(e: SettingsError) -> Self {
        CompensateError::Settings(e)
    }
}

impl From<DialectError> for CompensateError {
    fn from(e: DialectError) -> Self {
        CompensateError::Dialect(e)
    }
}

impl CompensateError {
    /// The same error with its located diagnostic rewritten by `f` (a hint replaced, mapped
    /// bytes shown), its variant kept.
    pub(crate) fn map_diagnostic(self, f: impl FnOnce(Diagnostic) -> Diagnostic) -> Self {
        use CompensateError as E;
        match self {
            E::Program(d) => E::Program(f(d)),
            E::Uncovered(d) => E::Uncovered(f(d)),
            E::Overwrite(d) => E::Overwrite(f(d)),
            E::Read(d) => E::Read(f(d)),
            E::Write(d) => E::Write(f(d)),
            E::Internal(d) => E::Internal(f(d)),
            E::Dialect(DialectError::Uncertain(d)) => E::Dialect(DialectError::Uncertain(f(d))),
            E::Settings(s) => E::Settings(match s {
                SettingsError::Zone(d) => SettingsError::Zone(f(d)),
                SettingsError::Choice(d) => SettingsError::Choice(f(d)),
                SettingsError::Range(d) => SettingsError::Range(f(d)),
            }),
        }
    }
}
