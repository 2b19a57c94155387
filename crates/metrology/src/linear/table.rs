//! Linear pitch-error compensation tables: the mean error of each direction resampled on equally spaced points, written through the controller writers of [`crate::controller`], and read back from any controller's file.
//!
//! Internally a table holds the axis error e(x) = actual - nominal (µm) of each direction at
//! equally spaced positions; each controller writer converts to its own sign and unit (see
//! [`crate::controller`] and docs/linear.md).

use super::eval::Evaluation;
use super::runs::Direction;
use crate::controller::{self, AxisKind, ControllerTable};
pub use crate::controller::{sinumerik_cec_path, TableFormat, TableOptions, LINUXCNC_MAX_LINES};
use crate::Setting;
use errmap_core::error::{Error, Location, Result};
use errmap_core::setting::words;
use std::path::{Path, PathBuf};

/// Most Fanuc compensation points any supported series reads back (30i-B: 0 ... 1535).
pub const FANUC_MAX_POINTS: usize = 1536;

/// Axis error of each direction at equally spaced positions.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct CompTable {
    /// Table points, mm: first target + k·spacing, ascending.
    pub positions_mm: Vec<f64>,
    /// e↑ = actual − nominal, forward approach (µm).
    pub forward_um: Vec<f64>,
    /// e↓, reverse approach (µm).
    pub reverse_um: Vec<f64>,
    /// Whether both directions were measured (a unidirectional table repeats one direction).
    pub bidirectional: bool,
    /// How the table was made where a user should know (ASCII): e.g. a travel extended to the
    /// next whole spacing.
    pub notes: Vec<String>,
}

fn interp(xs: &[f64], ys: &[f64], x: f64) -> f64 {
    match xs.len() {
        0 => 0.0,
        1 => ys[0],
        _ => {
            if x <= xs[0] {
                return ys[0];
            }
            let last = xs.len() - 1;
            if x >= xs[last] {
                return ys[last];
            }
            let i = xs.partition_point(|&p| p <= x).clamp(1, last);
            let (x0, x1) = (xs[i - 1], xs[i]);
            let t = (x - x0) / (x1 - x0);
            ys[i - 1] + t * (ys[i] - ys[i - 1])
        }
    }
}

impl CompTable {
    /// Resample the mean deviation of each direction to positions first target + k·spacing,
    /// linearly between targets. The table always covers the whole measured travel: when the
    /// spacing does not divide it, one more point past the last target holds the last target's
    /// error (as a controller holds its last entry), and a note says so.
    pub fn from_evaluation(ev: &Evaluation, spacing_mm: f64) -> Result<CompTable> {
        if !(spacing_mm.is_finite() && spacing_mm > 0.0) {
            return Err(Error::usage(
                format!("spacing {spacing_mm} mm is not a positive length"),
                format!(
                    "give the table spacing in mm, e.g. {} 20",
                    words(Setting::Spacing)
                ),
            ));
        }
        let xs: Vec<f64> = ev.targets.iter().map(|t| t.target).collect();
        // A unidirectional test gives one direction's means: the table then carries the same
        // values in both columns (the controller compensates both directions alike).
        let side = |t: &super::eval::TargetFigures, x: Option<f64>| x.unwrap_or(t.mean_any());
        let up: Vec<f64> = ev.targets.iter().map(|t| side(t, t.mean_up)).collect();
        let down: Vec<f64> = ev.targets.iter().map(|t| side(t, t.mean_down)).collect();
        let (first, last) = match (xs.first(), xs.last()) {
            (Some(&f), Some(&l)) => (f, l),
            _ => return Err(Error::numeric("no targets", "measure at least two targets")),
        };
        // Count in f64 first: a tiny spacing must not wrap a usize.
        let intervals = ((last - first) / spacing_mm - 1e-9).ceil().max(0.0);
        if intervals.is_nan() || intervals + 1.0 > 100_000.0 {
            return Err(Error::usage(
                format!(
                    "spacing {spacing_mm:?} mm over {} mm gives {:.3e} table points, more than 100000",
                    last - first,
                    intervals + 1.0
                ),
                "choose a coarser spacing",
            ));
        }
        let count = intervals as usize + 1;
        let positions_mm: Vec<f64> = (0..count).map(|k| first + k as f64 * spacing_mm).collect();
        let mut notes = Vec::new();
        let end = positions_mm[count - 1];
        if end > last + 1e-6 {
            notes.push(format!(
                "spacing {spacing_mm} mm does not divide the travel {first} ... {last} mm: the table runs to {} mm, its last point holding the error measured at {last} mm",
                controller::fixed(end, 4)
            ));
        }
        Ok(CompTable {
            forward_um: positions_mm.iter().map(|&x| interp(&xs, &up, x)).collect(),
            reverse_um: positions_mm
                .iter()
                .map(|&x| interp(&xs, &down, x))
                .collect(),
            positions_mm,
            bidirectional: ev.unidirectional.is_none(),
            notes,
        })
    }

    /// The table in the controller writers' model; the reference position is
    /// `opts.reference_mm` or the first point.
    pub fn to_controller(&self, opts: &TableOptions) -> Result<ControllerTable> {
        let start = self.positions_mm.first().copied().unwrap_or(0.0);
        Ok(ControllerTable {
            kind: AxisKind::Linear,
            axis: opts.axis.clone().unwrap_or_else(|| "X".into()),
            start,
            step: self.spacing_mm(),
            forward: self.forward_um.clone(),
            reverse: self.reverse_um.clone(),
            bidirectional: self.bidirectional,
            reference: opts.reference_mm.unwrap_or(start),
            notes: self.notes.clone(),
        })
    }

    /// The tabled error of `direction` at `x_mm` (µm), linear between points, end values held.
    pub fn error_at(&self, direction: Direction, x_mm: f64) -> f64 {
        let ys = match direction {
            Direction::Forward => &self.forward_um,
            Direction::Reverse => &self.reverse_um,
        };
        interp(&self.positions_mm, ys, x_mm)
    }

    fn spacing_mm(&self) -> f64 {
        match self.positions_mm.as_slice() {
            [a, b, ..] => b - a,
            _ => 0.0,
        }
    }
}

/// The rendered file(s) of a table: `(path, text)` pairs (Sinumerik and Heidenhain write two).
pub fn render_table(
    table: &CompTable,
    format: TableFormat,
    opts: &TableOptions,
    path: &Path,
) -> Result<Vec<(PathBuf, String)>, crate::error::TableError> {
    controller::render(&table.to_controller(opts)?, format, opts, path).map_err(Into::into)
}

/// Guess a table file's format from its content.
pub fn detect_format(text: &str) -> Option<TableFormat> {
    let first = text.lines().map(str::trim).find(|l| !l.is_empty())?;
    if text.contains("$AA_ENC_COMP") || text.contains("$AN_CEC") {
        Some(TableFormat::Sinumerik)
    } else if first.starts_with("BEGIN") {
        Some(TableFormat::Heidenhain)
    } else if first == "%" && text.contains("N10000P") {
        Some(TableFormat::Fanuc)
    } else if text.lines().any(|l| l.trim().starts_with("position_mm")) {
        Some(TableFormat::Csv)
    } else if first
        .split_whitespace()
        .filter(|w| w.parse::<f64>().is_ok())
        .count()
        == 3
    {
        Some(TableFormat::Linuxcnc)
    } else {
        None
    }
}

fn bad(path: &Path, line: usize, msg: impl Into<String>, hint: impl Into<String>) -> Error {
    Error::input(Location::line(path, line as u64), msg, hint)
}

fn num(path: &Path, line: usize, text: &str) -> Result<f64> {
    text.trim()
        .parse::<f64>()
        .ok()
        .filter(|v| v.is_finite())
        .ok_or_else(|| {
            bad(
                path,
                line,
                format!("'{}' is not a number", text.trim()),
                "fix the value",
            )
        })
}

/// Read a table file back into axis errors (µm) per direction. Sinumerik also reads the
/// `_cec` file beside it when present; Fanuc needs the same `reference_mm` and unit as when
/// written (positions are not in the file).
pub fn read_table(
    path: &Path,
    format: Option<TableFormat>,
    opts: &TableOptions,
) -> Result<CompTable, crate::error::TableError> {
    let text = errmap_core::io::read_text(path)?;
    let format = match format.or_else(|| detect_format(&text)) {
        Some(f) => f,
        None => {
            return Err(Error::input(
                Location::file(path),
                "cannot tell which controller format this table is",
                "errmap reads the files `errmap linear table` writes (linuxcnc, sinumerik, fanuc, heidenhain, csv)",
            ).into())
        }
    };
    let table = match format {
        TableFormat::Linuxcnc => read_linuxcnc(path, &text, opts.linuxcnc_type)?,
        TableFormat::Sinumerik => read_sinumerik(path, &text)?,
        TableFormat::Fanuc => read_fanuc(path, &text, opts)?,
        TableFormat::Heidenhain => read_heidenhain(path, &text)?,
        TableFormat::Csv => read_csv(path, &text)?,
    };
    if table.positions_mm.len() < 2 || table.positions_mm.windows(2).any(|w| w[1] <= w[0]) {
        return Err(Error::input(
            Location::file(path),
            "the table needs at least two strictly ascending positions",
            "check the file",
        )
        .into());
    }
    Ok(table)
}

fn read_linuxcnc(path: &Path, text: &str, kind: u8) -> Result<CompTable> {
    let mut t = CompTable::default();
    for (i, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let words: Vec<&str> = line.split_whitespace().collect();
        if words.len() != 3 {
            return Err(bad(
                path,
                i + 1,
                "expected 'nominal forward reverse'",
                "three numbers per line",
            ));
        }
        let x = num(path, i + 1, words[0])?;
        let f = num(path, i + 1, words[1])?;
        let r = num(path, i + 1, words[2])?;
        let (ef, er) = match kind {
            0 => ((f - x) * 1e3, (r - x) * 1e3),
            _ => (-f * 1e3, -r * 1e3),
        };
        t.positions_mm.push(x);
        t.forward_um.push(ef);
        t.reverse_um.push(er);
    }
    Ok(t)
}

/// `NAME[i,j,…]=value` → (NAME, indices, value).
fn sinumerik_assign(line: &str) -> Option<(&str, Vec<&str>, &str)> {
    let (lhs, rhs) = line.split_once('=')?;
    let open = lhs.find('[')?;
    let close = lhs.rfind(']')?;
    let idx = lhs
        .get(open + 1..close)?
        .split(',')
        .map(str::trim)
        .collect();
    Some((lhs[..open].trim(), idx, rhs.trim()))
}

fn read_sinumerik(path: &Path, text: &str) -> Result<CompTable> {
    let (positions_mm, mean) = read_lec(path, text)?;
    let (mut fwd, mut rev) = (mean.clone(), mean);
    let cec_path = sinumerik_cec_path(path);
    if cec_path.exists() {
        let cec = errmap_core::io::read_text(&cec_path)?;
        for (_, (mut pts, dir)) in read_cec_tables(&cec_path, &cec)? {
            pts.sort_by_key(|p| p.0);
            let target = match dir {
                1 => &mut fwd,
                -1 => &mut rev,
                _ => continue,
            };
            for (k, v) in pts {
                if let Some(slot) = target.get_mut(k) {
                    // CEC = −(e − mean)  ⇒  e = mean − CEC.
                    *slot -= v;
                }
            }
        }
    }
    Ok(CompTable {
        positions_mm,
        forward_um: fwd,
        reverse_um: rev,
        ..CompTable::default()
    })
}

/// The LEC file: the table's positions (mm) and its values, the mean of both directions (µm).
fn read_lec(path: &Path, text: &str) -> Result<(Vec<f64>, Vec<f64>)> {
    let mut values: Vec<(usize, f64)> = Vec::new();
    let (mut step, mut min) = (None, None);
    for (i, raw) in text.lines().enumerate() {
        let line = raw.split(';').next().unwrap_or("").trim();
        let Some((name, idx, rhs)) = sinumerik_assign(line) else {
            continue;
        };
        match name {
            "$AA_ENC_COMP" => {
                let k: usize = idx.get(1).and_then(|s| s.parse().ok()).ok_or_else(|| {
                    bad(
                        path,
                        i + 1,
                        "bad $AA_ENC_COMP index",
                        "write $AA_ENC_COMP[0,i,AXIS]=value",
                    )
                })?;
                values.push((k, num(path, i + 1, rhs)? * 1e3));
            }
            "$AA_ENC_COMP_STEP" => step = Some(num(path, i + 1, rhs)?),
            "$AA_ENC_COMP_MIN" => min = Some(num(path, i + 1, rhs)?),
            _ => {}
        }
    }
    let (Some(step), Some(min)) = (step, min) else {
        return Err(Error::input(
            Location::file(path),
            "no $AA_ENC_COMP_STEP / $AA_ENC_COMP_MIN in the LEC file",
            "the LEC file must give the table's start and step",
        ));
    };
    values.sort_by_key(|v| v.0);
    let n = values.len();
    if values.iter().enumerate().any(|(i, v)| v.0 != i) {
        return Err(Error::input(
            Location::file(path),
            "LEC points are not numbered 0…n−1",
            "check the indices",
        ));
    }
    let mean: Vec<f64> = values.iter().map(|v| v.1).collect();
    let positions_mm: Vec<f64> = (0..n).map(|k| min + k as f64 * step).collect();
    Ok((positions_mm, mean))
}

/// The CEC tables of a Sinumerik CEC file: per table index, its (point, value µm) and its
/// direction (`$AN_CEC_DIRECTION`: 1 forward, −1 reverse).
type CecTables = std::collections::BTreeMap<u32, (Vec<(usize, f64)>, i32)>;

fn read_cec_tables(cec_path: &Path, cec: &str) -> Result<CecTables> {
    let mut tables = CecTables::default();
    for (i, raw) in cec.lines().enumerate() {
        let line = raw.split(';').next().unwrap_or("").trim();
        let Some((name, idx, rhs)) = sinumerik_assign(line) else {
            continue;
        };
        let t: u32 = match idx.first().and_then(|s| s.parse().ok()) {
            Some(t) => t,
            None => continue,
        };
        let entry = tables.entry(t).or_insert((Vec::new(), 0));
        match name {
            "$AN_CEC" => {
                let k: usize = idx.get(1).and_then(|s| s.parse().ok()).ok_or_else(|| {
                    bad(
                        cec_path,
                        i + 1,
                        "bad $AN_CEC index",
                        "write $AN_CEC[t,i]=value",
                    )
                })?;
                entry.0.push((k, num(cec_path, i + 1, rhs)? * 1e3));
            }
            "$AN_CEC_DIRECTION" => entry.1 = num(cec_path, i + 1, rhs)? as i32,
            _ => {}
        }
    }
    Ok(tables)
}

fn read_fanuc(path: &Path, text: &str, opts: &TableOptions) -> Result<CompTable> {
    let (params, points) = read_fanuc_data(path, text)?;
    let get = |p: u32| {
        params.get(&p).copied().ok_or_else(|| {
            Error::input(
                Location::file(path),
                format!("parameter {p} missing"),
                "the file must list 3620–3624, 3626 and 3627",
            )
        })
    };
    let (reference, first, last, mag, interval, first_rev, at_ref) = (
        get(3620)?,
        get(3621)?,
        get(3622)?,
        get(3623)?,
        get(3624)?,
        get(3626)?,
        get(3627)?,
    );
    if last < first || reference < first || reference > last || interval <= 0 {
        return Err(Error::input(
            Location::file(path),
            "inconsistent parameters 3620–3624",
            "check the reference and end points",
        ));
    }
    let n = (last - first + 1) as usize;
    if n > FANUC_MAX_POINTS {
        return Err(Error::input(
            Location::file(path),
            format!("parameters 3621/3622 span {n} points, more than Fanuc's {FANUC_MAX_POINTS}"),
            "check parameters 3621 and 3622",
        ));
    }
    let unit = opts.fanuc_unit_um * mag as f64;
    let r = (reference - first) as usize;
    let cumulative = |base: i64| fanuc_cumulative_um(path, &points, base, n, r, unit);
    let fwd = cumulative(first)?;
    let rev: Vec<f64> = cumulative(first_rev)?
        .into_iter()
        .map(|v| v - at_ref as f64 * unit)
        .collect();
    let step_mm = interval as f64 * opts.fanuc_unit_um * 1e-3;
    let reference_mm = opts.reference_mm.unwrap_or(0.0);
    let positions_mm = (0..n)
        .map(|k| reference_mm + (k as f64 - r as f64) * step_mm)
        .collect();
    Ok(CompTable {
        positions_mm,
        forward_um: fwd,
        reverse_um: rev,
        ..CompTable::default()
    })
}

/// Fanuc data by number: parameters (below 10000) and compensation points (10000 + point).
type FanucData = (
    std::collections::BTreeMap<u32, i64>,
    std::collections::BTreeMap<usize, i64>,
);

/// The `N…P…` lines of a Fanuc parameter file.
fn read_fanuc_data(path: &Path, text: &str) -> Result<FanucData> {
    let mut params: std::collections::BTreeMap<u32, i64> = Default::default();
    let mut points: std::collections::BTreeMap<usize, i64> = Default::default();
    for (i, raw) in text.lines().enumerate() {
        let line = raw.trim();
        if line.is_empty() || line == "%" {
            continue;
        }
        let body = line.strip_prefix('N').ok_or_else(|| {
            bad(
                path,
                i + 1,
                "expected an N… line",
                "Fanuc data lines start with N",
            )
        })?;
        let (number, rest) = body.split_at(
            body.find(|c: char| !c.is_ascii_digit())
                .unwrap_or(body.len()),
        );
        let number: u32 = number
            .parse()
            .map_err(|_| bad(path, i + 1, "bad data number", "N followed by digits"))?;
        let value_text = rest
            .rsplit_once('P')
            .map(|(_, v)| v)
            .ok_or_else(|| bad(path, i + 1, "no P value", "write NnnnnP<value>"))?;
        let value: i64 = value_text.trim().parse().map_err(|_| {
            bad(
                path,
                i + 1,
                format!("'{value_text}' is not an integer"),
                "Fanuc values are whole counts",
            )
        })?;
        if number >= 10000 {
            points.insert((number - 10000) as usize, value);
        } else {
            params.insert(number, value);
        }
    }
    Ok((params, points))
}

/// The error (µm) at each of the `n` points of a Fanuc table starting at point `base`: the
/// increments summed, zero at the reference point `r`, in detection units of `unit_um`.
fn fanuc_cumulative_um(
    path: &Path,
    points: &std::collections::BTreeMap<usize, i64>,
    base: i64,
    n: usize,
    r: usize,
    unit_um: f64,
) -> Result<Vec<f64>> {
    let mut c = vec![0i64; n];
    for k in 1..n {
        let v = points
            .get(&((base + k as i64) as usize))
            .copied()
            .ok_or_else(|| {
                Error::input(
                    Location::file(path),
                    format!("compensation point {} missing", base + k as i64),
                    "give every point of the table",
                )
            })?;
        c[k] = c[k - 1] + v;
    }
    let at_r = c[r];
    Ok(c.into_iter()
        .map(|v| v - at_r)
        .map(|v| -(v as f64) * unit_um)
        .collect())
}

fn read_heidenhain(path: &Path, text: &str) -> Result<CompTable> {
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty());
    lines.next(); // BEGIN …
    let (_, header) = lines.next().ok_or_else(|| {
        Error::input(
            Location::file(path),
            "no column header",
            "line 2 names the columns",
        )
    })?;
    let cols: Vec<&str> = header.split_whitespace().collect();
    let find = |name: &str| cols.iter().position(|c| c.eq_ignore_ascii_case(name));
    let pos_col = find("AXISPOS").ok_or_else(|| {
        Error::input(
            Location::line(path, 2),
            "no AXISPOS column",
            "the header must name AXISPOS",
        )
    })?;
    let back_col = find("BACKLASH");
    let axis_col = (0..cols.len())
        .find(|&i| i != pos_col && Some(i) != back_col && !cols[i].eq_ignore_ascii_case("NR"))
        .ok_or_else(|| {
            Error::input(
                Location::line(path, 2),
                "no axis column",
                "name the compensated axis, e.g. X",
            )
        })?;
    let mut t = CompTable::default();
    for (i, line) in lines {
        if line.trim().starts_with("[END]") {
            break;
        }
        let words: Vec<&str> = line.split_whitespace().collect();
        let cell = |c: usize| {
            words
                .get(c)
                .copied()
                .ok_or_else(|| bad(path, i + 1, "short row", "one value per column"))
        };
        let x = num(path, i + 1, cell(pos_col)?)?;
        let f = num(path, i + 1, cell(axis_col)?)? * 1e3;
        let r = match back_col {
            Some(c) => num(path, i + 1, cell(c)?)? * 1e3,
            None => f,
        };
        t.positions_mm.push(x);
        t.forward_um.push(f);
        t.reverse_um.push(r);
    }
    Ok(t)
}

fn read_csv(path: &Path, text: &str) -> Result<CompTable> {
    let table = errmap_core::io::CsvTable::parse(path, text)?;
    table.reject_unknown(&["position_mm", "forward_um", "reverse_um"])?;
    let (cx, cf, cr) = (
        table.require("position_mm")?,
        table.require("forward_um")?,
        table.require("reverse_um")?,
    );
    let mut t = CompTable::default();
    for row in &table.rows {
        t.positions_mm.push(table.f64(row, cx)?);
        t.forward_um.push(table.f64(row, cf)?);
        t.reverse_um.push(table.f64(row, cr)?);
    }
    Ok(t)
}
