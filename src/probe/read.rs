//! Reading and validating probe files: columns, numbers, nominal, plausibility, domain; repeats of one nominal point merged; points that span no surface refused.

use std::collections::HashMap;
use std::path::Path;

use super::{unit_slip_hint, ProbePoint, ProbeSet, ProbeSpec};
use crate::error::{Error, Location, Result};
use crate::geom::{Axis, Domain};
use crate::io::{CsvRow, CsvTable};

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
    let columns = Columns {
        measured: [
            table.require("x_mm")?,
            table.require("y_mm")?,
            table.require("z_mm")?,
        ],
        nominal: nominal_columns(table, spec)?,
        id: table.column("id"),
    };
    let rows = table
        .rows
        .iter()
        .map(|row| read_row(table, row, &columns, spec))
        .collect::<Result<Vec<Row>>>()?;
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
    let (ua, va) = spec.normal.plane_axes();
    check_not_collinear(path, &points, ua, va)?;
    Ok(ProbeSet {
        path: path.clone(),
        normal: spec.normal,
        points,
    })
}

/// Where a probe file's fields are: measured and nominal `[x, y, z]`, and `id`.
struct Columns {
    measured: [usize; 3],
    /// `None`: the nominal is the spec's nominal plane.
    nominal: Option<[usize; 3]>,
    id: Option<usize>,
}

/// The nominal columns (all three or none); with none, the spec must give a finite nominal
/// plane.
fn nominal_columns(table: &CsvTable, spec: &ProbeSpec) -> Result<Option<[usize; 3]>> {
    let path = &table.path;
    let nominal_names = ["nx_mm", "ny_mm", "nz_mm"];
    let present: Vec<&str> = nominal_names
        .iter()
        .copied()
        .filter(|n| table.column(n).is_some())
        .collect();
    match present.len() {
        3 => {
            return Ok(Some([
                table.require("nx_mm")?,
                table.require("ny_mm")?,
                table.require("nz_mm")?,
            ]))
        }
        0 => {}
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
    }
    match spec.nominal_plane_mm {
        None => Err(Error::input(
            Location::line(path, 1),
            "no nominal: the file has no nx_mm,ny_mm,nz_mm columns and no nominal plane was given",
            format!(
                "add nominal columns, or give the nominal {} of the surface (--nominal-plane MM, or `nominal_plane_mm` in the job)",
                spec.normal.name()
            ),
        )),
        Some(plane) if !plane.is_finite() => Err(Error::usage(
            format!("nominal plane {plane} mm is not a finite number"),
            "give the nominal coordinate of the surface in mm, e.g. 30",
        )),
        Some(_) => Ok(None),
    }
}

/// One data row: its numbers, checked against the plausibility bound and the domain.
fn read_row(table: &CsvTable, row: &CsvRow, columns: &Columns, spec: &ProbeSpec) -> Result<Row> {
    let mut measured_mm = [0.0; 3];
    for (k, &c) in columns.measured.iter().enumerate() {
        measured_mm[k] = table.f64(row, c)?;
    }
    let nominal_mm = match columns.nominal {
        Some(cols) => {
            let mut nominal = [0.0; 3];
            for (k, &c) in cols.iter().enumerate() {
                nominal[k] = table.f64(row, c)?;
            }
            nominal
        }
        None => {
            let mut nominal = measured_mm;
            nominal[spec.normal.index()] = spec.nominal_plane_mm.unwrap_or(0.0);
            nominal
        }
    };
    let normal_col = columns.measured[spec.normal.index()];
    check_deviation(table, row, normal_col, measured_mm, nominal_mm, spec)?;
    if let Some(domain) = &spec.domain {
        check_in_domain(table, row, nominal_mm, domain, spec.normal)?;
    }
    let id = columns
        .id
        .map(|c| table.text(row, c).to_string())
        .filter(|s| !s.is_empty());
    Ok(Row {
        id,
        line: row.line,
        measured_mm,
        nominal_mm,
    })
}

/// Refuses a deviation along the normal that µm cannot represent or that is beyond the
/// spec's plausibility bound (naming the likely unit slip).
fn check_deviation(
    table: &CsvTable,
    row: &CsvRow,
    normal_col: usize,
    measured_mm: [f64; 3],
    nominal_mm: [f64; 3],
    spec: &ProbeSpec,
) -> Result<()> {
    let n = spec.normal.index();
    // Two finite coordinates near ±f64::MAX can still differ by more than f64 holds.
    if !((measured_mm[n] - nominal_mm[n]) * 1000.0).is_finite() {
        return Err(table.error_at(
            row,
            Some(normal_col),
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
            Some(normal_col),
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
    Ok(())
}

/// Refuses a point whose nominal lies outside `domain` (grown by [`DOMAIN_TOLERANCE_MM`]).
fn check_in_domain(
    table: &CsvTable,
    row: &CsvRow,
    nominal_mm: [f64; 3],
    domain: &Domain,
    normal: Axis,
) -> Result<()> {
    let (ua, va) = normal.plane_axes();
    let (u, v) = (nominal_mm[ua.index()], nominal_mm[va.index()]);
    let grown = Domain {
        u_min_mm: domain.u_min_mm - DOMAIN_TOLERANCE_MM,
        v_min_mm: domain.v_min_mm - DOMAIN_TOLERANCE_MM,
        u_max_mm: domain.u_max_mm + DOMAIN_TOLERANCE_MM,
        v_max_mm: domain.v_max_mm + DOMAIN_TOLERANCE_MM,
    };
    if grown.contains(u, v) {
        return Ok(());
    }
    let (un, vn) = (ua.name(), va.name());
    Err(table.error_at(
        row,
        None,
        format!(
            "point ({un} {u}, {vn} {v}) mm is outside the domain {un} {}..{}, {vn} {}..{} mm",
            domain.u_min_mm, domain.u_max_mm, domain.v_min_mm, domain.v_max_mm
        ),
        "widen the domain or remove the point (is it from another part or set-up?)",
    ))
}

/// Group rows into points (same id, or same nominal within the tolerance) and average each group.
fn merge_repeats(rows: &[Row], normal: Axis) -> Vec<ProbePoint> {
    repeat_groups(rows)
        .iter()
        .map(|members| average_point(rows, members, normal))
        .collect()
}

/// Union-find over rows: the earliest row of a set is its root.
struct Repeats {
    parent: Vec<usize>,
}

impl Repeats {
    fn find(&mut self, mut i: usize) -> usize {
        while self.parent[i] != i {
            self.parent[i] = self.parent[self.parent[i]];
            i = self.parent[i];
        }
        i
    }

    fn union(&mut self, a: usize, b: usize) {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra != rb {
            // Keep the earliest row as the root: points keep the order of their first row.
            let (lo, hi) = if ra < rb { (ra, rb) } else { (rb, ra) };
            self.parent[hi] = lo;
        }
    }
}

/// The rows of each point, points in the order of their first row: rows are joined by id
/// and by nominal position (a spatial hash on a grid of the tolerance, checking the
/// neighbouring cells so points across a cell border still meet).
fn repeat_groups(rows: &[Row]) -> Vec<Vec<usize>> {
    let mut sets = Repeats {
        parent: (0..rows.len()).collect(),
    };
    let mut by_id: HashMap<&str, usize> = HashMap::new();
    let mut by_cell: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
    let cell_of = |p: &[f64; 3]| p.map(|x| (x / REPEAT_TOLERANCE_MM).floor() as i64);
    for (i, row) in rows.iter().enumerate() {
        if let Some(id) = &row.id {
            match by_id.get(id.as_str()) {
                Some(&j) => sets.union(i, j),
                None => {
                    by_id.insert(id, i);
                }
            }
        }
        let c = cell_of(&row.nominal_mm);
        for j in neighbours(&by_cell, c) {
            let close = (0..3)
                .all(|k| (rows[j].nominal_mm[k] - row.nominal_mm[k]).abs() <= REPEAT_TOLERANCE_MM);
            if close {
                sets.union(i, j);
            }
        }
        by_cell.entry(c).or_default().push(i);
    }
    let mut groups: Vec<Vec<usize>> = Vec::new();
    let mut group_of_root: HashMap<usize, usize> = HashMap::new();
    for i in 0..rows.len() {
        let root = sets.find(i);
        let g = *group_of_root.entry(root).or_insert_with(|| {
            groups.push(Vec::new());
            groups.len() - 1
        });
        groups[g].push(i);
    }
    groups
}

/// The rows in cell `c` and its 26 neighbours, cell by cell (x, then y, then z ascending).
fn neighbours(by_cell: &HashMap<[i64; 3], Vec<usize>>, c: [i64; 3]) -> Vec<usize> {
    let mut found = Vec::new();
    for dx in -1..=1 {
        for dy in -1..=1 {
            for dz in -1..=1 {
                let key = [
                    c[0].saturating_add(dx),
                    c[1].saturating_add(dy),
                    c[2].saturating_add(dz),
                ];
                if let Some(members) = by_cell.get(&key) {
                    found.extend_from_slice(members);
                }
            }
        }
    }
    found
}

/// The point of one group of rows: coordinates and error averaged, the spread of the error.
fn average_point(rows: &[Row], members: &[usize], normal: Axis) -> ProbePoint {
    let n = normal.index();
    let (ua, va) = normal.plane_axes();
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
