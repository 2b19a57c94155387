//! The typed error of reports: reading analysis results back and printing a report to PDF.
//! Each variant carries the located diagnostic errmap prints.

use errmap_core::error::Diagnostic;

/// Why a report could not be built or printed ([`crate::pdf::print_pdf`],
/// [`crate::result::read_result`], [`crate::result::results_in`],
/// [`crate::result::render_results`]).
#[derive(Debug)]
#[non_exhaustive]
pub enum ReportError {
    /// No headless Chromium to print with (none on the PATH, or `ERRMAP_CHROMIUM` names no
    /// file).
    NoBrowser(Diagnostic),
    /// The browser started but did not print (it failed, timed out, or could not be run).
    Print(Diagnostic),
    /// The output is refused by the safety rules (over an input, outside the folder a
    /// command writes into) or would replace a chart.
    Output(Diagnostic),
    /// A file beside a chart is not an errmap analysis result.
    Result(Diagnostic),
    /// An input (a result, a chart) cannot be read.
    Read(Diagnostic),
    /// An output cannot be written.
    Write(Diagnostic),
    /// A bug in errmap.
    Internal(Diagnostic),
}
errmap_core::typed_error!(ReportError {
    NoBrowser,
    Print,
    Output,
    Result,
    Read,
    Write,
    Internal
});

impl From<Diagnostic> for ReportError {
    /// A diagnostic by its kind.
    fn from(d: Diagnostic) -> Self {
        match d {
            Diagnostic::Usage { .. } | Diagnostic::Input { .. } | Diagnostic::Numeric { .. } => {
                ReportError::Result(d)
            }
            Diagnostic::Io { .. } if d.is_read() => ReportError::Read(d),
            Diagnostic::Io { .. } => ReportError::Write(d),
            Diagnostic::Device { .. } => ReportError::Print(d),
            Diagnostic::Internal(_) => ReportError::Internal(d),
        }
    }
}
