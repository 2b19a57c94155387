//! The typed errors of the metrology analyses (linear, thermal, rotary, circular) and of
//! controller tables: what a caller can act on. Each variant carries the located diagnostic
//! errmap prints; a diagnostic from the readers and numerics lands in its variant by its kind
//! and by whether it names a line.

use errmap_core::error::Diagnostic;

/// One analysis' error enum: the same variants, each analysis its own type.
macro_rules! analysis_error {
    ($(#[$doc:meta])* $name:ident) => {
        $(#[$doc])*
        #[derive(Debug)]
        #[non_exhaustive]
        pub enum $name {
            /// The options mean nothing (a bound, a spacing, a standard's parameter, a
            /// combination of inputs).
            Options(Diagnostic),
            /// A line of an input file is bad: a cell, a value out of range, a row out of
            /// order (the diagnostic names the line and column).
            Line(Diagnostic),
            /// An input file as a whole: its format, header or columns, too few targets,
            /// runs or samples, runs that do not match.
            File(Diagnostic),
            /// A fit is not possible on otherwise valid data (a singular design, no
            /// convergence); the message names the data.
            Fit(Diagnostic),
            /// An input file cannot be read.
            Read(Diagnostic),
            /// An output cannot be written.
            Write(Diagnostic),
            /// A bug in errmap.
            Internal(Diagnostic),
        }
        errmap_core::typed_error!($name {
            Options, Line, File, Fit, Read, Write, Internal
        });

        impl From<Diagnostic> for $name {
            /// A diagnostic by its kind and whether it names a line.
            fn from(d: Diagnostic) -> Self {
                match d {
                    Diagnostic::Usage { .. } => $name::Options(d),
                    Diagnostic::Input { .. } if d.at_line() => $name::Line(d),
                    Diagnostic::Input { .. } => $name::File(d),
                    Diagnostic::Numeric { .. } => $name::Fit(d),
                    Diagnostic::Io { .. } if d.is_read() => $name::Read(d),
                    Diagnostic::Io { .. } => $name::Write(d),
                    Diagnostic::Device { .. } | Diagnostic::Internal(_) => $name::Internal(d),
                }
            }
        }
    };
}

analysis_error!(
    /// Why a linear-axis analysis failed: run files, air and material correction, the
    /// evaluation by standard, the pitch-error table plan, the uncertainty budget
    /// ([`crate::linear::analyze`], [`crate::linear::plan_table`] …).
    LinearError
);

analysis_error!(
    /// Why a thermal command failed: campaigns, sensor calibration, the store, the model fit,
    /// compensation of a temperature log, evaluation ([`crate::thermal::commands`]).
    ThermalError
);

analysis_error!(
    /// Why a rotary-axis analysis or table failed ([`crate::rotary::commands`],
    /// [`crate::rotary::analysis::analyze`]).
    RotaryError
);

analysis_error!(
    /// Why a circular test failed ([`crate::circular::run_test`]).
    CircularError
);

analysis_error!(
    /// Why a controller compensation table could not be read or written: a table whose
    /// format, points or limits the controller refuses ([`crate::linear::render_table`],
    /// [`crate::linear::read_table`]).
    TableError
);

impl From<TableError> for LinearError {
    /// A table applied to the runs was refused: the same variant of its diagnostic.
    fn from(e: TableError) -> Self {
        LinearError::from(errmap_core::error::Diagnose::into_diagnostic(e))
    }
}
