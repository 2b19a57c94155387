//! `errmap grid`: probe points interpolated onto a grid without a network, written as CSV
//! (`<u>_mm,<v>_mm,e_um`, nodes outside the probes' convex hull left out).

pub use crate::error::GridError;
use crate::interp::{resample, Grid, Method, Surface};
use crate::probe::{read_probe_file, ProbeSpec};
use errmap_core::error::{Error, Location, Result};
use errmap_core::geom::{Axis, Domain};
use std::path::{Path, PathBuf};

/// What to interpolate and how.
#[derive(Debug, Clone)]
pub struct GridRequest {
    /// The probe file, in any format [`crate::probe::detect_format`] recognises.
    pub probes: PathBuf,
    /// The interpolant evaluated at the nodes.
    pub method: Method,
    /// Node spacing along both plane axes, mm.
    pub step_mm: f64,
    /// The grid's domain; `None`: the probes' bounding box.
    pub domain: Option<Domain>,
    /// Axis E is measured along; the grid spans its plane axes ([`ProbeSpec::normal`]).
    pub normal: Axis,
    /// Nominal coordinate along the normal for a file without nominal columns, mm
    /// ([`ProbeSpec::nominal_plane_mm`]).
    pub nominal_plane_mm: Option<f64>,
    /// Largest believable |measured − nominal| along the normal, mm
    /// ([`ProbeSpec::max_deviation_mm`]).
    pub max_deviation_mm: f64,
    /// Column mapping of a CSV export, see [`ProbeSpec::columns`].
    pub columns: Option<String>,
    /// 1-based header line of a CSV export, see [`ProbeSpec::header_line`].
    pub header_line: Option<u64>,
}

/// What [`grid_probes`] wrote.
#[derive(Debug, Clone)]
pub struct GridOutcome {
    /// Probe points read (repeats averaged).
    pub points: usize,
    /// Lines before a CSV export's header, skipped.
    pub preamble_lines: usize,
    /// DMIS features other than points, skipped.
    pub skipped_features: usize,
    /// Nodes inside the probes' hull (the rows written).
    pub inside: usize,
    /// The grid interpolated on, every node (written or not).
    pub grid: Grid,
}

/// Round to a multiple of 1/`scale` for output, without a negative zero.
fn rounded(x: f64, scale: f64) -> f64 {
    let r = (x * scale).round() / scale;
    if r == 0.0 {
        0.0
    } else {
        r
    }
}

/// Read the probes, interpolate them onto the grid and write the CSV to `output`.
pub fn grid_probes(req: &GridRequest, output: &Path) -> Result<GridOutcome, GridError> {
    crate::probe::validate_max_deviation(
        req.max_deviation_mm,
        &errmap_core::setting::words(crate::Setting::MaxDeviation),
    )?;
    let spec = ProbeSpec {
        normal: req.normal,
        nominal_plane_mm: req.nominal_plane_mm,
        domain: req.domain,
        max_deviation_mm: req.max_deviation_mm,
        columns: req.columns.clone(),
        header_line: req.header_line,
    };
    let read = read_probe_file(&req.probes, &spec)?;
    let set = read.set;
    let domain = req
        .domain
        .or_else(|| set.bounding_box())
        .ok_or_else(|| Error::Internal("a validated probe set has no points".into()))?;
    let grid = Grid::covering(&domain, req.step_mm)?;
    let surface = Surface::new(&set.uve()).map_err(|e| {
        Error::input(
            Location::file(&req.probes),
            e.to_string(),
            "the probes must span an area in the map plane",
        )
    })?;
    let values = resample(&surface, req.method, &grid);
    let inside = write_grid_csv(output, &grid, &values, req.normal.plane_axes())?;
    Ok(GridOutcome {
        points: set.points.len(),
        preamble_lines: read.preamble_lines,
        skipped_features: read.skipped_features,
        inside,
        grid,
    })
}

/// Write the nodes that have a value; the number written.
fn write_grid_csv(
    output: &Path,
    grid: &Grid,
    values: &[Option<f64>],
    (ua, va): (Axis, Axis),
) -> Result<usize> {
    let mut inside = 0usize;
    errmap_core::io::write_atomic(output, |w| {
        writeln!(w, "{}_mm,{}_mm,e_um", ua.name(), va.name())?;
        for j in 0..grid.nv {
            for i in 0..grid.nu {
                if let Some(e) = values[j * grid.nu + i] {
                    let (u, v) = grid.node(i, j);
                    // Nodes to 1 nm (no 0.30000000000000004), E to 1e-6 µm.
                    writeln!(
                        w,
                        "{},{},{}",
                        rounded(u, 1e6),
                        rounded(v, 1e6),
                        rounded(e, 1e6)
                    )?;
                    inside += 1;
                }
            }
        }
        Ok(())
    })?;
    Ok(inside)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rounding_keeps_a_nanometre_and_drops_the_negative_zero() {
        assert_eq!(rounded(0.1 + 0.2, 1e6), 0.3);
        assert_eq!(rounded(-1e-9, 1e6).to_string(), "0");
        assert_eq!(rounded(-2.6e-6, 1e6), -3e-6);
    }
}
