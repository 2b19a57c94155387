//! Reading and validating probe files: the format, columns (errmap's or mapped), numbers, nominal, vectors, plausibility, domain; repeats of one nominal point merged; points that span no surface refused.

use std::collections::HashMap;
use std::path::Path;

use super::columns::ProbeColumns;
use super::point::{check_plane, plane_nominal, point_row, Place, RawPoint, Row};
pub use super::point::{MAX_VECTOR_ANGLE_DEG, VECTOR_NORM_TOLERANCE};
use super::{ProbePoint, ProbeSet, ProbeSpec};
use crate::ProbeError;
use crate::Setting;
use errmap_core::error::{Error, Location, Result};
use errmap_core::geom::Axis;
use errmap_core::io::columns::{self as shared_columns, Conversion};
use errmap_core::io::{CsvRow, CsvTable, HeaderAt};
use errmap_core::setting::words;

/// Columns a probe file may have.
pub const PROBE_COLUMNS: [&str; 7] = ["id", "x_mm", "y_mm", "z_mm", "nx_mm", "ny_mm", "nz_mm"];

/// Two rows are repeats of one nominal point when their nominal coordinates agree within this.
pub const REPEAT_TOLERANCE_MM: f64 = 1e-6;

/// Points are "on one line" when the widest spread across the line through the two points
/// furthest apart is below this fraction of their distance.
pub const COLLINEAR_RELATIVE_TOLERANCE: f64 = 1e-6;

/// Read and validate a probe file: columns, numbers, nominal, domain; repeats of one nominal
/// point (same nominal within [`REPEAT_TOLERANCE_MM`], or same `id`) are averaged. Points keep
/// the order of their first row. The format follows from the file ([`detect_format`]).
///
/// Four points of a plate whose nominal is the plane Z 0, the third probed twice:
///
/// ```
/// use errmap_maps::probe::{read_probes, ProbeSpec};
///
/// let dir = tempfile::tempdir().unwrap();
/// let path = dir.path().join("p01.csv");
/// std::fs::write(
///     &path,
///     "id,x_mm,y_mm,z_mm\na,0,0,0.010\nb,10,0,0.020\nc,0,10,-0.005\nc,0,10,-0.015\nd,10,10,0\n",
/// )
/// .unwrap();
/// let spec = ProbeSpec { nominal_plane_mm: Some(0.0), ..ProbeSpec::default() };
/// let set = read_probes(&path, &spec).unwrap();
/// let e_um: Vec<f64> = set.points.iter().map(|p| p.e_um).collect();
/// // E = measured − nominal along Z, in µm; the repeat of `c` is averaged: (−5 − 15) / 2.
/// let expected = [10.0, 20.0, -10.0, 0.0];
/// assert!(e_um.iter().zip(expected).all(|(a, b)| (a - b).abs() < 1e-9), "{e_um:?}");
/// assert_eq!(set.points[2].repeats, 2);
/// ```
pub fn read_probes(path: &Path, spec: &ProbeSpec) -> Result<ProbeSet, ProbeError> {
    read_probe_file(path, spec).map(|r| r.set)
}

/// What [`read_probe_file`] read besides the points.
#[derive(Debug, Clone, PartialEq)]
pub struct ProbeRead {
    /// The points read.
    pub set: ProbeSet,
    /// The format the file was read as ([`detect_format`]).
    pub format: ProbeFormat,
    /// Lines with text before a CSV export's header, skipped.
    pub preamble_lines: usize,
    /// DMIS features other than points (planes, circles …), skipped.
    pub skipped_features: usize,
}

/// [`read_probes`] with what was skipped on the way.
pub fn read_probe_file(path: &Path, spec: &ProbeSpec) -> Result<ProbeRead, ProbeError> {
    let format = detect_format(path)?;
    if format != ProbeFormat::Csv {
        let given = match (&spec.columns, spec.header_line) {
            (Some(_), _) => Some(format!("a column mapping ({})", words(Setting::Columns))),
            (None, Some(_)) => Some(format!("a header line ({})", words(Setting::HeaderLine))),
            (None, None) => None,
        };
        if let Some(given) = given {
            return Err(Error::usage(
                format!(
                    "{} is a {} file: {given} applies to CSV probe files only",
                    path.display(),
                    format.name()
                ),
                "leave the column mapping and header line out for DMIS, XYZ and PLY files",
            )
            .into());
        }
    }
    let (rows, preamble_lines, skipped_features) = match format {
        ProbeFormat::Csv => {
            let table = read_csv(path, spec)?;
            (csv_rows(&table, spec)?, table.preamble_lines, 0)
        }
        ProbeFormat::Dmis => {
            let (rows, skipped) = super::dmis::read(path, spec)?;
            (rows, 0, skipped)
        }
        ProbeFormat::Xyz => (super::cloud::read_xyz(path, spec)?, 0, 0),
        ProbeFormat::Ply => (super::cloud::read_ply(path, spec)?, 0, 0),
    };
    Ok(ProbeRead {
        set: finish(path, &rows, spec)?,
        format,
        preamble_lines,
        skipped_features,
    })
}

/// The formats a probe file may have.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ProbeFormat {
    /// errmap's columns, or an export read through a column mapping.
    Csv,
    /// DMIS (ISO 22093) output: `F(label)=FEAT/POINT,…` nominals and `FA(label)=…` actuals.
    Dmis,
    /// ASCII point cloud: `x y z` per line.
    Xyz,
    /// PLY point cloud (ASCII or binary).
    Ply,
}

impl ProbeFormat {
    /// The format's name as messages write it: `CSV`, `DMIS`, `XYZ`, `PLY`.
    pub fn name(self) -> &'static str {
        match self {
            ProbeFormat::Csv => "CSV",
            ProbeFormat::Dmis => "DMIS",
            ProbeFormat::Xyz => "XYZ",
            ProbeFormat::Ply => "PLY",
        }
    }
}

/// The format of a probe file: by extension (`.dmi`, `.dms`, `.dmis`; `.ply`; `.xyz`), else by
/// content (a PLY file starts with the line `ply`; a DMIS file's first line that is not blank
/// or a `$$` comment starts with `DMISMN/`, `F(` or `FA(`), else CSV.
pub fn detect_format(path: &Path) -> Result<ProbeFormat, ProbeError> {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    match ext.as_deref() {
        Some("dmi" | "dms" | "dmis") => return Ok(ProbeFormat::Dmis),
        Some("ply") => return Ok(ProbeFormat::Ply),
        Some("xyz") => return Ok(ProbeFormat::Xyz),
        _ => {}
    }
    let mut head = Vec::with_capacity(4096);
    {
        use std::io::Read;
        let file = errmap_core::io::open(path)?;
        file.take(4096)
            .read_to_end(&mut head)
            .map_err(|e| Error::read(path, e))?;
    }
    if head.starts_with(b"ply\n") || head.starts_with(b"ply\r\n") {
        return Ok(ProbeFormat::Ply);
    }
    let text = String::from_utf8_lossy(&head);
    let first = text
        .lines()
        .map(|l| l.trim_start_matches('\u{feff}').trim())
        .find(|l| !l.is_empty() && !l.starts_with("$$"));
    if let Some(line) = first {
        let upper = line.to_ascii_uppercase();
        if upper.starts_with("DMISMN/") || upper.starts_with("F(") || upper.starts_with("FA(") {
            return Ok(ProbeFormat::Dmis);
        }
    }
    Ok(ProbeFormat::Csv)
}

/// A CSV probe file: from its first line, or from the header the mapping or
/// `--header-line` finds.
fn read_csv(path: &Path, spec: &ProbeSpec) -> Result<CsvTable> {
    let columns = spec
        .columns
        .as_deref()
        .map(ProbeColumns::parse)
        .transpose()?;
    match (spec.header_line, &columns) {
        (Some(0), _) => Err(Error::usage(
            format!(
                "{} 0: lines are numbered from 1",
                words(Setting::HeaderLine)
            ),
            "give the 1-based line of the header, as an editor shows it",
        )),
        (Some(n), _) => CsvTable::read_with_header(
            path,
            HeaderAt::Line(n),
            &format!(
                "give the 1-based line of the header ({}, or header_line in the job)",
                words(Setting::HeaderLine)
            ),
        ),
        (None, Some(map)) => CsvTable::read_with_header(
            path,
            HeaderAt::First(&|cells: &[String]| map.is_header(cells)),
            &format!(
                "no line names all of the mapped columns ({}): check each name against the export's header as written, or give the header's line with {} N (header_line in the job) to see which is missing",
                map.columns_named(),
                words(Setting::HeaderLine)
            ),
        ),
        (None, None) => CsvTable::read(path).map_err(|e| match e {
            // A row wider than the header: most often an instrument export whose first lines
            // (a date, a title) come before its real header.
            Error::Input {
                location,
                message,
                hint,
            } if message.contains("but the header names") => Error::Input {
                location,
                message,
                hint: format!(
                    "{hint}; if the file is an instrument export with lines before its header, name its columns with {} x=…,y=…,z=… (the header is then found), or give its line with {} N",
                    words(Setting::Columns),
                    words(Setting::HeaderLine)
                ),
            },
            e => e,
        }),
    }
}

/// [`read_probes`] on a table already read (CSV, errmap's columns or `spec.columns`).
pub fn read_table(table: &CsvTable, spec: &ProbeSpec) -> Result<ProbeSet, ProbeError> {
    let rows = csv_rows(table, spec)?;
    finish(&table.path, &rows, spec).map_err(Into::into)
}

/// The checked rows of a CSV table.
fn csv_rows(table: &CsvTable, spec: &ProbeSpec) -> Result<Vec<Row>> {
    let columns = match spec.columns.as_deref() {
        Some(text) => mapped_columns(table, &ProbeColumns::parse(text)?, spec)?,
        None => {
            table.reject_unknown(&PROBE_COLUMNS)?;
            let plain = |c| (c, Conversion::IDENTITY);
            Columns {
                measured: [
                    plain(table.require("x_mm")?),
                    plain(table.require("y_mm")?),
                    plain(table.require("z_mm")?),
                ],
                nominal: nominal_columns(table, spec)?.map(|cols| cols.map(plain)),
                vector: None,
                id: table.column("id"),
            }
        }
    };
    table
        .rows
        .iter()
        .map(|row| read_row(table, row, &columns, spec))
        .collect()
}

/// Refuses fewer than 3 points after averaging and points on one line; the set otherwise.
fn finish(path: &Path, rows: &[Row], spec: &ProbeSpec) -> Result<ProbeSet> {
    let points = merge_repeats(rows, spec.normal);
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
        path: path.to_path_buf(),
        normal: spec.normal,
        points,
    })
}

/// Where a probe file's fields are (with the unit conversion of each coordinate): measured and
/// nominal `[x, y, z]`, the vector `[i, j, k]`, and `id`.
struct Columns {
    measured: [(usize, Conversion); 3],
    /// `None`: the nominal is the spec's nominal plane.
    nominal: Option<[(usize, Conversion); 3]>,
    vector: Option<[usize; 3]>,
    id: Option<usize>,
}

/// The columns of a mapped export; with no nominal mapped, the spec must give a nominal plane.
fn mapped_columns(table: &CsvTable, map: &ProbeColumns, spec: &ProbeSpec) -> Result<Columns> {
    use super::columns::Field;
    let at = |f: Field| -> Result<Option<(usize, Conversion)>> {
        map.entry(f)
            .map(|e| shared_columns::resolve(table, e, &super::columns::TABLE))
            .transpose()
    };
    let need = |f: Field| -> Result<(usize, Conversion)> {
        at(f)?.ok_or_else(|| Error::Internal("a parsed probe mapping lacks x, y or z".into()))
    };
    let measured = [need(Field::X)?, need(Field::Y)?, need(Field::Z)?];
    let nominal = match (at(Field::Nx)?, at(Field::Ny)?, at(Field::Nz)?) {
        (Some(a), Some(b), Some(c)) => Some([a, b, c]),
        _ => None,
    };
    let vector = match (at(Field::I)?, at(Field::J)?, at(Field::K)?) {
        (Some(a), Some(b), Some(c)) => Some([a.0, b.0, c.0]),
        _ => None,
    };
    if nominal.is_none() {
        check_plane(
            &table.path,
            table.header_line,
            spec,
            "the mapping has no nx,ny,nz",
        )?;
    }
    Ok(Columns {
        measured,
        nominal,
        vector,
        id: at(Field::Id)?.map(|c| c.0),
    })
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
                Location::line(path, table.header_line),
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
            Location::line(path, table.header_line),
            "no nominal: the file has no nx_mm,ny_mm,nz_mm columns and no nominal plane was given",
            format!(
                "add nominal columns, or give the nominal {} of the surface ({} MM, or `nominal_plane_mm` in the job)",
                spec.normal.name(),
                words(Setting::NominalPlane)
            ),
        )),
        Some(plane) if !plane.is_finite() => Err(Error::usage(
            format!("nominal plane {plane} mm is not a finite number"),
            "give the nominal coordinate of the surface in mm, e.g. 30",
        )),
        Some(_) => Ok(None),
    }
}

/// One data row of a CSV table: its numbers (converted to mm), then [`point_row`].
fn read_row(table: &CsvTable, row: &CsvRow, columns: &Columns, spec: &ProbeSpec) -> Result<Row> {
    let mut measured_mm = [0.0; 3];
    for (k, &(c, conv)) in columns.measured.iter().enumerate() {
        measured_mm[k] = conv.apply(table.f64(row, c)?);
    }
    let nominal_mm = match columns.nominal {
        Some(cols) => {
            let mut nominal = [0.0; 3];
            for (k, &(c, conv)) in cols.iter().enumerate() {
                nominal[k] = conv.apply(table.f64(row, c)?);
            }
            nominal
        }
        None => plane_nominal(measured_mm, spec),
    };
    let vector = match columns.vector {
        Some(cols) => {
            let mut v = [0.0; 3];
            for (k, &c) in cols.iter().enumerate() {
                v[k] = table.f64(row, c)?;
            }
            Some(v)
        }
        None => None,
    };
    let id = columns
        .id
        .map(|c| table.text(row, c).to_string())
        .filter(|s| !s.is_empty());
    let normal_col = columns.measured[spec.normal.index()].0;
    let place = Place {
        row: Location::line(&table.path, row.line),
        normal: Location::cell(&table.path, row.line, table.headers[normal_col].clone()),
        vector: Location::line(&table.path, row.line),
        prefix: String::new(),
    };
    let raw = RawPoint {
        id,
        line: row.line,
        measured_mm,
        nominal_mm,
        vector,
    };
    point_row(raw, &place, spec)
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
    let errors_um: Vec<f64> = members.iter().map(|&i| rows[i].e_um).collect();
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
            format!(
                "probe points off that line, or check that {} names the error direction",
                words(Setting::Normal)
            ),
        ));
    }
    Ok(())
}
