//! Probe files of machined parts: reading and validating measured points, averaging repeats, and rejecting gross errors.
//!
//! A probe file is a CSV with a header: measured `x_mm,y_mm,z_mm`, the nominal point either as
//! `nx_mm,ny_mm,nz_mm` per row or as one nominal plane along the normal axis
//! ([`ProbeSpec::nominal_plane_mm`]), and an optional `id`; or an instrument's CSV export read
//! through a column mapping, DMIS output, or an XYZ / PLY point cloud ([`ProbeFormat`]). The
//! error of a point is `E = measured − nominal` along the normal axis, or along the point's
//! vector where the file gives one, in µm; the map coordinates `(u, v)` are the nominal
//! coordinates along the two plane axes ([`Axis::plane_axes`]). See `docs/probe-files.md`.

pub mod budget;
mod clean;
mod cloud;
mod columns;
mod dmis;
mod loo;
mod order_stat;
mod point;
mod predict;
mod read;

pub use clean::{
    reject_gross_errors, Cleaned, Rejected, DEFAULT_K_SIGMA, FROM_SCRATCH_MAX_POINTS,
    MIN_POINTS_TO_JUDGE, SIGMA_FLOOR_UM,
};
pub use columns::ProbeColumns;
pub use read::{
    detect_format, read_probe_file, read_probes, read_table, ProbeFormat, ProbeRead,
    COLLINEAR_RELATIVE_TOLERANCE, MAX_VECTOR_ANGLE_DEG, PROBE_COLUMNS, REPEAT_TOLERANCE_MM,
    VECTOR_NORM_TOLERANCE,
};

pub use crate::error::ProbeError;
use errmap_core::error::{Error, Result};
use errmap_core::geom::{Axis, Domain};
use errmap_core::io::write_atomic;
use std::path::{Path, PathBuf};

/// How to read a probe file: the error direction, the nominal plane (when the file has no
/// nominal columns) and, optionally, the domain every point must lie in.
#[derive(Debug, Clone, PartialEq)]
pub struct ProbeSpec {
    /// Machine axis normal to the probed surface: E is measured along it (positive towards its
    /// + direction), and the other two axes are the map plane `(u, v)`.
    pub normal: Axis,
    /// Nominal coordinate along the normal axis for every point, used when the file has no
    /// `nx_mm,ny_mm,nz_mm` columns (the columns win when both are given).
    pub nominal_plane_mm: Option<f64>,
    /// Map domain in the plane axes; a point outside it is an error naming its line.
    pub domain: Option<Domain>,
    /// Plausibility bound: a deviation |measured − nominal| along the normal above this is an
    /// error that names the likely unit slip (default [`DEFAULT_MAX_DEVIATION_MM`]).
    pub max_deviation_mm: f64,
    /// A column mapping for an instrument's CSV export (`x=X,y=Y,z=Z[um],…`, see
    /// [`ProbeColumns`]); `None`: errmap's own columns.
    pub columns: Option<String>,
    /// 1-based line of a CSV file's header; `None`: the first line, or with a mapping the
    /// first line naming every mapped column.
    pub header_line: Option<u64>,
}

impl Default for ProbeSpec {
    fn default() -> Self {
        ProbeSpec {
            normal: Axis::Z,
            nominal_plane_mm: None,
            domain: None,
            max_deviation_mm: DEFAULT_MAX_DEVIATION_MM,
            columns: None,
            header_line: None,
        }
    }
}

/// Largest believable deviation of a machined surface from its nominal, mm. A finished part
/// is off by microns to tenths of a millimetre; a millimetre or more is almost always a unit
/// slip (µm or inches written as mm), a wrong nominal plane or a wrong normal axis.
pub const DEFAULT_MAX_DEVIATION_MM: f64 = 1.0;

/// Check a plausibility bound given on the command line or in a job file.
pub fn validate_max_deviation(max_mm: f64, flag: &str) -> Result<(), ProbeError> {
    if max_mm.is_finite() && max_mm > 0.0 {
        Ok(())
    } else {
        Err(Error::usage(
            format!("{flag} {max_mm} must be a positive number of mm"),
            format!("the default is {DEFAULT_MAX_DEVIATION_MM} mm; raise it only for parts that really are that far off"),
        ).into())
    }
}

/// The hint for a deviation between `measured_mm` and `nominal_mm` above the bound `max_mm`:
/// which unit slip (µm, m or inches written as mm) would bring the measured value within
/// `max_mm` of the nominal, and the setting `key` that raises the bound.
pub fn unit_slip_hint(measured_mm: f64, nominal_mm: f64, max_mm: f64, key: &str) -> String {
    let near = |x: f64| (x - nominal_mm).abs() <= max_mm;
    let likely = if near(measured_mm / 1000.0) {
        format!(
            "{measured_mm} / 1000 = {} is near the nominal {nominal_mm}: the file looks like µm written as mm",
            measured_mm / 1000.0
        )
    } else if near(measured_mm * 1000.0) {
        format!("{measured_mm} × 1000 is near the nominal {nominal_mm}: the file looks like m written as mm")
    } else if near(measured_mm * 25.4) {
        format!("{measured_mm} × 25.4 is near the nominal {nominal_mm}: the file looks like inches written as mm")
    } else {
        "check the units (mm), the nominal plane and the normal axis".to_string()
    };
    format!("{likely}; if the part really is this far off, raise the bound ({key})")
}

/// One probed point (repeats of the same nominal point already averaged).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ProbePoint {
    /// The `id` cell of the first row of the point, if the file has an `id` column.
    pub id: Option<String>,
    /// 1-based file line of the point's first row.
    pub line: u64,
    /// Measured coordinates `[x, y, z]` (mean over repeats).
    pub measured_mm: [f64; 3],
    /// Nominal coordinates `[x, y, z]`.
    pub nominal_mm: [f64; 3],
    /// Nominal coordinate along the first plane axis.
    pub u_mm: f64,
    /// Nominal coordinate along the second plane axis.
    pub v_mm: f64,
    /// Error E = measured − nominal, µm, along the normal axis, or along the point's vector
    /// where the file gives one (mean over repeats).
    pub e_um: f64,
    /// Number of rows averaged into this point.
    pub repeats: u32,
    /// Sample standard deviation of `e_um` over the repeats (0 for a single row).
    pub spread_um: f64,
}

/// The points of one probe file.
#[derive(Debug, Clone, PartialEq)]
pub struct ProbeSet {
    /// The probe file the points were read from.
    pub path: PathBuf,
    /// Axis the errors are measured along (the [`ProbeSpec::normal`] the file was read with).
    pub normal: Axis,
    /// The points, repeats averaged, in the order of their first row; at least 3, not all on
    /// one line.
    pub points: Vec<ProbePoint>,
}

impl ProbeSet {
    /// `[u_mm, v_mm, e_um]` of every point, the input of [`crate::interp::Surface::new`].
    pub fn uve(&self) -> Vec<[f64; 3]> {
        uve(&self.points)
    }

    /// Bounding box of the points in the plane axes.
    pub fn bounding_box(&self) -> Option<Domain> {
        bounding_box(&self.points)
    }
}

/// `[u_mm, v_mm, e_um]` of each point.
pub fn uve(points: &[ProbePoint]) -> Vec<[f64; 3]> {
    points.iter().map(|p| [p.u_mm, p.v_mm, p.e_um]).collect()
}

/// Bounding box of the points in the plane axes; `None` for no points.
pub fn bounding_box(points: &[ProbePoint]) -> Option<Domain> {
    let first = points.first()?;
    let mut d = Domain {
        u_min_mm: first.u_mm,
        v_min_mm: first.v_mm,
        u_max_mm: first.u_mm,
        v_max_mm: first.v_mm,
    };
    for p in points {
        d.u_min_mm = d.u_min_mm.min(p.u_mm);
        d.u_max_mm = d.u_max_mm.max(p.u_mm);
        d.v_min_mm = d.v_min_mm.min(p.v_mm);
        d.v_max_mm = d.v_max_mm.max(p.v_mm);
    }
    Some(d)
}

/// Write points as `x_mm,y_mm,z_mm,e_um` (measured coordinates), atomically.
pub fn write_points_csv(
    path: &Path,
    normal: Axis,
    points: &[ProbePoint],
) -> Result<(), ProbeError> {
    let _ = normal; // The columns are the same for every normal; E is along it.
    write_atomic(path, |w| {
        writeln!(w, "x_mm,y_mm,z_mm,e_um")?;
        for p in points {
            let [x, y, z] = p.measured_mm;
            writeln!(w, "{x},{y},{z},{}", p.e_um)?;
        }
        Ok(())
    })
    .map_err(Into::into)
}

/// Write rejected points as `x_mm,y_mm,z_mm,residual_um` (measured coordinates), atomically.
pub fn write_rejected_csv(path: &Path, rejected: &[Rejected]) -> Result<(), ProbeError> {
    write_atomic(path, |w| {
        writeln!(w, "x_mm,y_mm,z_mm,residual_um")?;
        for r in rejected {
            let [x, y, z] = r.point.measured_mm;
            writeln!(w, "{x},{y},{z},{}", r.residual_um)?;
        }
        Ok(())
    })
    .map_err(Into::into)
}

pub use errmap_core::geom::parse_domain;
