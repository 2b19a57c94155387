//! Probe files of machined parts: reading and validating measured points, averaging repeats, and rejecting gross errors.
//!
//! A probe file is a CSV with a header: measured `x_mm,y_mm,z_mm`, the nominal point either as
//! `nx_mm,ny_mm,nz_mm` per row or as one nominal plane along the normal axis
//! ([`ProbeSpec::nominal_plane_mm`]), and an optional `id`. The error of a point is
//! `E = measured − nominal` along the normal axis, in µm; the map coordinates `(u, v)` are the
//! nominal coordinates along the two plane axes ([`Axis::plane_axes`]). See `docs/probe-files.md`.

mod clean;

pub use clean::{
    reject_gross_errors, Cleaned, Rejected, DEFAULT_K_SIGMA, MIN_POINTS_TO_JUDGE, SIGMA_FLOOR_UM,
};

use crate::error::{Error, Location, Result};
use crate::geom::{Axis, Domain};
use crate::io::{write_atomic, CsvTable};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// How to read a probe file: the error direction, the nominal plane (when the file has no
/// nominal columns) and, optionally, the domain every point must lie in.
#[derive(Debug, Clone, PartialEq)]
pub struct ProbeSpec {
    pub normal: Axis,
    /// Nominal coordinate along the normal axis for every point, used when the file has no
    /// `nx_mm,ny_mm,nz_mm` columns (the columns win when both are given).
    pub nominal_plane_mm: Option<f64>,
    /// Map domain in the plane axes; a point outside it is an error naming its line.
    pub domain: Option<Domain>,
    /// Plausibility bound: a deviation |measured − nominal| along the normal above this is an
    /// error that names the likely unit slip (default [`DEFAULT_MAX_DEVIATION_MM`]).
    pub max_deviation_mm: f64,
}

impl Default for ProbeSpec {
    fn default() -> Self {
        ProbeSpec {
            normal: Axis::Z,
            nominal_plane_mm: None,
            domain: None,
            max_deviation_mm: DEFAULT_MAX_DEVIATION_MM,
        }
    }
}

/// Largest believable deviation of a machined surface from its nominal, mm. A finished part
/// is off by microns to tenths of a millimetre; a millimetre or more is almost always a unit
/// slip (µm or inches written as mm), a wrong nominal plane or a wrong normal axis.
pub const DEFAULT_MAX_DEVIATION_MM: f64 = 1.0;

/// Check a plausibility bound given on the command line or in a job file.
pub fn validate_max_deviation(max_mm: f64, flag: &str) -> Result<()> {
    if max_mm.is_finite() && max_mm > 0.0 {
        Ok(())
    } else {
        Err(Error::usage(
            format!("{flag} {max_mm} must be a positive number of mm"),
            format!("the default is {DEFAULT_MAX_DEVIATION_MM} mm; raise it only for parts that really are that far off"),
        ))
    }
}

/// What a deviation of `deviation_mm` between `measured_mm` and `nominal_mm` most likely means.
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
    /// Error along the normal, measured − nominal, in µm (mean over repeats).
    pub e_um: f64,
    /// Number of rows averaged into this point.
    pub repeats: u32,
    /// Sample standard deviation of `e_um` over the repeats (0 for a single row).
    pub spread_um: f64,
}

/// The points of one probe file.
#[derive(Debug, Clone, PartialEq)]
pub struct ProbeSet {
    pub path: PathBuf,
    pub normal: Axis,
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

/// Columns a probe file may have.
pub const PROBE_COLUMNS: [&str; 7] = ["id", "x_mm", "y_mm", "z_mm", "nx_mm", "ny_mm", "nz_mm"];

/// Two rows are repeats of one nominal point when their nominal coordinates agree within this.
pub const REPEAT_TOLERANCE_MM: f64 = 1e-6;

/// Points are "on one line" when the widest spread across the line through the two points
/// furthest apart is below this fraction of their distance.
pub const COLLINEAR_RELATIVE_TOLERANCE: f64 = 1e-6;

/// A point may sit this far outside the domain (rounding in the file) and still count as inside.
const DOMAIN_TOLERANCE_MM: f64 = 1e-9;

/// One row as read, before repeats are merged.
struct Row {
    id: Option<String>,
    line: u64,
    measured_mm: [f64; 3],
    nominal_mm: [f64; 3],
}

/// Read and validate a probe file: columns, numbers, nominal, domain; repeats of one nominal
/// point (same nominal within [`REPEAT_TOLERANCE_MM`], or same `id`) are averaged. Points keep
/// the order of their first row.
pub fn read_probes(path: &Path, spec: &ProbeSpec) -> Result<ProbeSet> {
    let table = CsvTable::read(path)?;
    read_table(&table, spec)
}

/// [`read_probes`] on a table already read.
pub fn read_table(table: &CsvTable, spec: &ProbeSpec) -> Result<ProbeSet> {
    let path = &table.path;
    table.reject_unknown(&PROBE_COLUMNS)?;
    let measured_cols = [
        table.require("x_mm")?,
        table.require("y_mm")?,
        table.require("z_mm")?,
    ];
    let nominal_names = ["nx_mm", "ny_mm", "nz_mm"];
    let present: Vec<&str> = nominal_names
        .iter()
        .copied()
        .filter(|n| table.column(n).is_some())
        .collect();
    let nominal_cols = match present.len() {
        3 => Some([
            table.require("nx_mm")?,
            table.require("ny_mm")?,
            table.require("nz_mm")?,
        ]),
        0 => None,
        _ => {
            let missing: Vec<&str> = nominal_names
                .iter()
                .copied()
                .filter(|n| !present.contains(n))
                .collect();
            return Err(Error::input(
                Location::line(path, 1),
                format!(
                    "nominal columns are incomplete: {} present, {} missing",
                    present.join(","),
                    missing.join(",")
                ),
                "give all three of nx_mm,ny_mm,nz_mm, or none of them and a nominal plane",
            ));
        }
    };
    if nominal_cols.is_none() {
        match spec.nominal_plane_mm {
            None => {
                return Err(Error::input(
                    Location::line(path, 1),
                    "no nominal: the file has no nx_mm,ny_mm,nz_mm columns and no nominal plane was given",
                    format!(
                        "add nominal columns, or give the nominal {} of the surface (--nominal-plane MM, or `nominal_plane_mm` in the job)",
                        spec.normal.name()
                    ),
                ))
            }
            Some(plane) if !plane.is_finite() => {
                return Err(Error::usage(
                    format!("nominal plane {plane} mm is not a finite number"),
                    "give the nominal coordinate of the surface in mm, e.g. 30",
                ))
            }
            Some(_) => {}
        }
    }
    let id_col = table.column("id");
    let n = spec.normal.index();
    let (ua, va) = spec.normal.plane_axes();

    let mut rows = Vec::with_capacity(table.rows.len());
    for row in &table.rows {
        let mut measured_mm = [0.0; 3];
        for (k, &c) in measured_cols.iter().enumerate() {
            measured_mm[k] = table.f64(row, c)?;
        }
        let nominal_mm = match nominal_cols {
            Some(cols) => {
                let mut nominal = [0.0; 3];
                for (k, &c) in cols.iter().enumerate() {
                    nominal[k] = table.f64(row, c)?;
                }
                nominal
            }
            None => {
                let mut nominal = measured_mm;
                nominal[n] = spec.nominal_plane_mm.unwrap_or(0.0);
                nominal
            }
        };
        // Two finite coordinates near ±f64::MAX can still differ by more than f64 holds.
        if !((measured_mm[n] - nominal_mm[n]) * 1000.0).is_finite() {
            return Err(table.error_at(
                row,
                Some(measured_cols[n]),
                format!(
                    "the deviation {} − {} mm along {} is too large to represent in µm",
                    measured_mm[n],
                    nominal_mm[n],
                    spec.normal.name()
                ),
                "check the units: probe coordinates are in mm",
            ));
        }
        let deviation_mm = measured_mm[n] - nominal_mm[n];
        if deviation_mm.abs() > spec.max_deviation_mm {
            return Err(table.error_at(
                row,
                Some(measured_cols[n]),
                format!(
                    "the deviation {deviation_mm} mm along {} (measured {} − nominal {}) is beyond the plausibility bound of {} mm",
                    spec.normal.name(),
                    measured_mm[n],
                    nominal_mm[n],
                    spec.max_deviation_mm
                ),
                unit_slip_hint(
                    measured_mm[n],
                    nominal_mm[n],
                    spec.max_deviation_mm,
                    "--max-deviation-mm, or max_deviation_mm in the job",
                ),
            ));
        }
        if let Some(domain) = &spec.domain {
            let (u, v) = (nominal_mm[ua.index()], nominal_mm[va.index()]);
            let grown = Domain {
                u_min_mm: domain.u_min_mm - DOMAIN_TOLERANCE_MM,
                v_min_mm: domain.v_min_mm - DOMAIN_TOLERANCE_MM,
                u_max_mm: domain.u_max_mm + DOMAIN_TOLERANCE_MM,
                v_max_mm: domain.v_max_mm + DOMAIN_TOLERANCE_MM,
            };
            if !grown.contains(u, v) {
                let (un, vn) = (ua.name(), va.name());
                return Err(table.error_at(
                    row,
                    None,
                    format!(
                        "point ({un} {u}, {vn} {v}) mm is outside the domain {un} {}..{}, {vn} {}..{} mm",
                        domain.u_min_mm, domain.u_max_mm, domain.v_min_mm, domain.v_max_mm
                    ),
                    "widen the domain or remove the point (is it from another part or set-up?)",
                ));
            }
        }
        let id = id_col
            .map(|c| table.text(row, c).to_string())
            .filter(|s| !s.is_empty());
        rows.push(Row {
            id,
            line: row.line,
            measured_mm,
            nominal_mm,
        });
    }

    let points = merge_repeats(&rows, spec.normal);
    if points.len() < 3 {
        return Err(Error::input(
            Location::file(path),
            format!(
                "{} usable point(s) after averaging repeats ({} data rows); a map needs at least 3",
                points.len(),
                rows.len()
            ),
            "probe at least 3 distinct points spread over the surface",
        ));
    }
    check_not_collinear(path, &points, ua, va)?;
    Ok(ProbeSet {
        path: path.clone(),
        normal: spec.normal,
        points,
    })
}

/// Group rows into points (same id, or same nominal within the tolerance) and average each group.
fn merge_repeats(rows: &[Row], normal: Axis) -> Vec<ProbePoint> {
    // Union-find over rows, joined by id and by nominal position (spatial hash on a grid of the
    // tolerance, checking the neighbouring cells so points across a cell border still meet).
    let mut parent: Vec<usize> = (0..rows.len()).collect();
    fn find(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    fn union(parent: &mut [usize], a: usize, b: usize) {
        let (ra, rb) = (find(parent, a), find(parent, b));
        if ra != rb {
            // Keep the earliest row as the root: points keep the order of their first row.
            let (lo, hi) = if ra < rb { (ra, rb) } else { (rb, ra) };
            parent[hi] = lo;
        }
    }
    let mut by_id: HashMap<&str, usize> = HashMap::new();
    let mut by_cell: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
    let cell_of = |p: &[f64; 3]| p.map(|x| (x / REPEAT_TOLERANCE_MM).floor() as i64);
    for (i, row) in rows.iter().enumerate() {
        if let Some(id) = &row.id {
            match by_id.get(id.as_str()) {
                Some(&j) => union(&mut parent, i, j),
                None => {
                    by_id.insert(id, i);
                }
            }
        }
        let c = cell_of(&row.nominal_mm);
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let key = [
                        c[0].saturating_add(dx),
                        c[1].saturating_add(dy),
                        c[2].saturating_add(dz),
                    ];
                    if let Some(members) = by_cell.get(&key) {
                        for &j in members {
                            let close = (0..3).all(|k| {
                                (rows[j].nominal_mm[k] - row.nominal_mm[k]).abs()
                                    <= REPEAT_TOLERANCE_MM
                            });
                            if close {
                                union(&mut parent, i, j);
                            }
                        }
                    }
                }
            }
        }
        by_cell.entry(c).or_default().push(i);
    }
    let mut groups: Vec<Vec<usize>> = Vec::new();
    let mut group_of_root: HashMap<usize, usize> = HashMap::new();
    for i in 0..rows.len() {
        let root = find(&mut parent, i);
        let g = *group_of_root.entry(root).or_insert_with(|| {
            groups.push(Vec::new());
            groups.len() - 1
        });
        groups[g].push(i);
    }
    let n = normal.index();
    let (ua, va) = normal.plane_axes();
    groups
        .iter()
        .map(|members| {
            let count = members.len() as f64;
            let mut measured_mm = [0.0; 3];
            let mut nominal_mm = [0.0; 3];
            for &i in members {
                for k in 0..3 {
                    measured_mm[k] += rows[i].measured_mm[k] / count;
                    nominal_mm[k] += rows[i].nominal_mm[k] / count;
                }
            }
            let errors_um: Vec<f64> = members
                .iter()
                .map(|&i| (rows[i].measured_mm[n] - rows[i].nominal_mm[n]) * 1000.0)
                .collect();
            let e_um = errors_um.iter().sum::<f64>() / count;
            let spread_um = if members.len() > 1 {
                (errors_um.iter().map(|e| (e - e_um).powi(2)).sum::<f64>() / (count - 1.0)).sqrt()
            } else {
                0.0
            };
            let first = &rows[members[0]];
            ProbePoint {
                id: first.id.clone(),
                line: first.line,
                measured_mm,
                nominal_mm,
                u_mm: nominal_mm[ua.index()],
                v_mm: nominal_mm[va.index()],
                e_um,
                repeats: members.len() as u32,
                spread_um,
            }
        })
        .collect()
}

/// All points on one line (within [`COLLINEAR_RELATIVE_TOLERANCE`]) span no surface.
fn check_not_collinear(path: &Path, points: &[ProbePoint], ua: Axis, va: Axis) -> Result<()> {
    // The two points furthest apart, approximately: the first point's furthest, then that
    // one's furthest (within a factor 2 of the diameter, enough for a tolerance test).
    // Coordinates are taken relative to the first point and scaled by the largest offset so
    // squares cannot overflow.
    let Some(p0) = points.first() else {
        return Ok(());
    };
    let scale = points
        .iter()
        .map(|p| (p.u_mm - p0.u_mm).abs().max((p.v_mm - p0.v_mm).abs()))
        .fold(0.0, f64::max);
    if !(scale > 0.0 && scale.is_finite()) {
        return Ok(()); // one distinct position: caught by the point count
    }
    let uv: Vec<(f64, f64)> = points
        .iter()
        .map(|p| ((p.u_mm - p0.u_mm) / scale, (p.v_mm - p0.v_mm) / scale))
        .collect();
    let dist2 = |a: (f64, f64), b: (f64, f64)| (a.0 - b.0).powi(2) + (a.1 - b.1).powi(2);
    let far = |from: usize| {
        (0..uv.len())
            .max_by(|&a, &b| dist2(uv[from], uv[a]).total_cmp(&dist2(uv[from], uv[b])))
            .unwrap_or(from)
    };
    let ia = far(0);
    let ib = far(ia);
    let (a, b) = (uv[ia], uv[ib]);
    let length = dist2(a, b).sqrt();
    let spread = uv
        .iter()
        .map(|p| ((b.0 - a.0) * (p.1 - a.1) - (b.1 - a.1) * (p.0 - a.0)).abs() / length)
        .fold(0.0, f64::max);
    if spread <= COLLINEAR_RELATIVE_TOLERANCE * length {
        return Err(Error::input(
            Location::file(path),
            format!(
                "all {} points lie on one line in the {}{} plane (lines {} to {}): they span no surface",
                points.len(),
                ua.name(),
                va.name(),
                points[ia].line.min(points[ib].line),
                points[ia].line.max(points[ib].line)
            ),
            "probe points off that line, or check that --normal names the error direction",
        ));
    }
    Ok(())
}

/// Write points as `x_mm,y_mm,z_mm,e_um` (measured coordinates), atomically.
pub fn write_points_csv(path: &Path, normal: Axis, points: &[ProbePoint]) -> Result<()> {
    let _ = normal; // The columns are the same for every normal; E is along it.
    write_atomic(path, |w| {
        writeln!(w, "x_mm,y_mm,z_mm,e_um")?;
        for p in points {
            let [x, y, z] = p.measured_mm;
            writeln!(w, "{x},{y},{z},{}", p.e_um)?;
        }
        Ok(())
    })
}

/// Write rejected points as `x_mm,y_mm,z_mm,residual_um` (measured coordinates), atomically.
pub fn write_rejected_csv(path: &Path, rejected: &[Rejected]) -> Result<()> {
    write_atomic(path, |w| {
        writeln!(w, "x_mm,y_mm,z_mm,residual_um")?;
        for r in rejected {
            let [x, y, z] = r.point.measured_mm;
            writeln!(w, "{x},{y},{z},{}", r.residual_um)?;
        }
        Ok(())
    })
}

/// Parse a domain written `UMIN,VMIN,UMAX,VMAX` in mm (the two plane axes of the normal, e.g.
/// `XMIN,YMIN,XMAX,YMAX` for normal z), as given on the command line.
pub fn parse_domain(text: &str) -> Result<Domain> {
    let hint =
        "write the domain as UMIN,VMIN,UMAX,VMAX in mm along the two plane axes, e.g. 0,0,600,300";
    let values: Vec<f64> = text
        .split(',')
        .map(|s| s.trim().parse::<f64>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| Error::usage(format!("domain '{text}' is not four numbers"), hint))?;
    let [u_min_mm, v_min_mm, u_max_mm, v_max_mm] = values[..] else {
        return Err(Error::usage(
            format!("domain '{text}' has {} values, not 4", values.len()),
            hint,
        ));
    };
    if !values.iter().all(|v| v.is_finite()) || u_max_mm <= u_min_mm || v_max_mm <= v_min_mm {
        return Err(Error::usage(
            format!("domain '{text}' is not a rectangle: each minimum must be below its maximum"),
            hint,
        ));
    }
    Ok(Domain {
        u_min_mm,
        v_min_mm,
        u_max_mm,
        v_max_mm,
    })
}
