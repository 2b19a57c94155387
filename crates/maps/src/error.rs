//! The typed errors of reading probe files, fitted maps and map grids: what a caller can act
//! on. Each variant carries the located diagnostic errmap prints.

use errmap_core::error::Diagnostic;

/// Why a probe or scan file was refused ([`crate::probe::read_probes`],
/// [`crate::probe::read_probe_file`], [`crate::probe::reject_gross_errors`] …).
#[derive(Debug)]
#[non_exhaustive]
pub enum ProbeError {
    /// How to read it means nothing: a plausibility bound, a column mapping, a header line.
    Options(Diagnostic),
    /// A line of the file is bad: a cell, a point's vector or deviation, a point outside the
    /// domain (the diagnostic names the line and column).
    Line(Diagnostic),
    /// The file as a whole: its format, header or columns, too few usable points, points that
    /// span no surface, more than the memory bound.
    File(Diagnostic),
    /// The file cannot be read.
    Read(Diagnostic),
    /// An output (the cleaned or rejected points) cannot be written.
    Write(Diagnostic),
    /// A bug in errmap.
    Internal(Diagnostic),
}
errmap_core::typed_error!(ProbeError {
    Options,
    Line,
    File,
    Read,
    Write,
    Internal
});

impl From<Diagnostic> for ProbeError {
    /// A diagnostic by its kind and whether it names a line.
    fn from(d: Diagnostic) -> Self {
        match d {
            Diagnostic::Usage { .. } => ProbeError::Options(d),
            Diagnostic::Input { .. } if d.at_line() => ProbeError::Line(d),
            Diagnostic::Input { .. } | Diagnostic::Numeric { .. } => ProbeError::File(d),
            Diagnostic::Io { .. } if d.is_read() => ProbeError::Read(d),
            Diagnostic::Io { .. } => ProbeError::Write(d),
            Diagnostic::Device { .. } | Diagnostic::Internal(_) => ProbeError::Internal(d),
        }
    }
}

/// Why a fitted map (`model.json`) or a map file (`map.csv`) was refused or not used
/// ([`crate::map::FittedModel::read`], [`crate::map::FittedModel::check_plausible`],
/// [`crate::map::FittedModel::check_benefit`], [`crate::map::ErrorMap::read_csv`] …).
#[derive(Debug)]
#[non_exhaustive]
pub enum MapError {
    /// A bound given with it means nothing (`--max-uncertainty-um`).
    Options(Diagnostic),
    /// A line of the file is bad (not JSON there, a row off the grid, a bad value).
    Line(Diagnostic),
    /// The file as a whole: another format or version, a network that does not fit its
    /// layout, no u(E) recorded where one is asked for.
    File(Diagnostic),
    /// The map would move a point further than the plausibility bound (a unit slip in the
    /// data it was fitted to, or a network that went wild).
    Implausible(Diagnostic),
    /// The map removes too little of E at its held-out points to be used.
    Weak(Diagnostic),
    /// The file cannot be read.
    Read(Diagnostic),
    /// A map file cannot be written.
    Write(Diagnostic),
    /// A bug in errmap.
    Internal(Diagnostic),
}
errmap_core::typed_error!(MapError {
    Options,
    Line,
    File,
    Implausible,
    Weak,
    Read,
    Write,
    Internal
});

impl From<Diagnostic> for MapError {
    /// A diagnostic by its kind and whether it names a line.
    fn from(d: Diagnostic) -> Self {
        match d {
            Diagnostic::Usage { .. } => MapError::Options(d),
            Diagnostic::Input { .. } if d.at_line() => MapError::Line(d),
            Diagnostic::Input { .. } | Diagnostic::Numeric { .. } => MapError::File(d),
            Diagnostic::Io { .. } if d.is_read() => MapError::Read(d),
            Diagnostic::Io { .. } => MapError::Write(d),
            Diagnostic::Device { .. } | Diagnostic::Internal(_) => MapError::Internal(d),
        }
    }
}

/// Why `errmap grid` (probe points interpolated onto a grid,
/// [`crate::map::grid_file::grid_probes`]) failed.
#[derive(Debug)]
#[non_exhaustive]
pub enum GridError {
    /// The probe file was refused.
    Probes(ProbeError),
    /// The request means nothing: a grid step, a domain, an interpolation that cannot run on
    /// these points.
    Options(Diagnostic),
    /// The grid file cannot be written.
    Write(Diagnostic),
    /// A bug in errmap.
    Internal(Diagnostic),
}
errmap_core::typed_error!(GridError {
    Probes,
    Options,
    Write,
    Internal
});

impl From<ProbeError> for GridError {
    fn from(e: ProbeError) -> Self {
        GridError::Probes(e)
    }
}

impl From<Diagnostic> for GridError {
    /// A diagnostic from the grid, the interpolation or the output, by its kind.
    fn from(d: Diagnostic) -> Self {
        match d {
            Diagnostic::Input { .. } | Diagnostic::Usage { .. } | Diagnostic::Numeric { .. } => {
                GridError::Options(d)
            }
            Diagnostic::Io { .. } if d.is_read() => GridError::Probes(ProbeError::Read(d)),
            Diagnostic::Io { .. } => GridError::Write(d),
            Diagnostic::Device { .. } | Diagnostic::Internal(_) => GridError::Internal(d),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use errmap_core::error::Location;

    #[test]
    fn a_diagnostic_is_filed_by_its_kind_and_whether_it_names_a_line() {
        let at_line = Diagnostic::input(Location::cell("p.csv", 4, "x_mm"), "not a number", "");
        let whole = Diagnostic::input(Location::file("p.csv"), "too few points", "");
        let bound = Diagnostic::usage("--max-deviation-mm -1 is not positive", "");
        let unreadable = Diagnostic::read("p.csv", std::io::ErrorKind::NotFound.into());
        assert!(matches!(ProbeError::from(at_line), ProbeError::Line(_)));
        assert!(matches!(ProbeError::from(whole), ProbeError::File(_)));
        assert!(matches!(ProbeError::from(bound), ProbeError::Options(_)));
        assert!(matches!(ProbeError::from(unreadable), ProbeError::Read(_)));
    }
}
