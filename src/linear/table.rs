//! Bidirectional pitch-error compensation tables for real controllers (LinuxCNC, Sinumerik, Fanuc, Heidenhain, CSV): writing them from the mean error of each direction, and reading them back.
//!
//! Internally a table holds the axis error e(x) = actual − nominal (µm) of each direction at
//! equally spaced positions; each format converts to its controller's own sign and unit:
//!
//! | format | file | value written | sign |
//! |---|---|---|---|
//! | `linuxcnc` type 0 | `nominal forward reverse` (mm) | x + e↑, x + e↓: the actual positions | LinuxCNC converts to trims nominal − actual (usrmotLoadComp) |
//! | `linuxcnc` type 1 | `nominal forward_trim reverse_trim` (mm) | −e↑, −e↓ | trim = nominal − actual, added to the command |
//! | `sinumerik` LEC | `$AA_ENC_COMP[0,i,AXIS]` (mm), `_N_AX_EEC_INI` | ē = (e↑ + e↓)/2 | +e: "a positive compensation value moves the axis in the negative direction" (Siemens LEC) |
//! | `sinumerik` CEC | `$AN_CEC[t,i]` (mm), `_N_NC_CEC_INI`, second file | −(e↑ − ē), −(e↓ − ē) with `$AN_CEC_DIRECTION` 1 / −1 | CEC is added to the setpoint: −e |
//! | `fanuc` | `N1xxxx P…` per point (detection units), parameters 3620–3624, 3626, 3627 | incremental −Δe per interval | compensation pulses: −e |
//! | `heidenhain` | `.COM` table, columns NR, AXISPOS, axis, BACKLASH (mm) | e↑ in the axis column, e↓ in BACKLASH | the measured error, positive when the travel is too long (TNC 407 manual, MP720), which the control compensates |
//! | `csv` | `position_mm,forward_um,reverse_um` | e↑, e↓ (µm) | the error itself |

use super::eval::Evaluation;
use super::runs::Direction;
use crate::error::{Error, Location, Result};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Controller file format.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum TableFormat {
    Linuxcnc,
    Sinumerik,
    Fanuc,
    Heidenhain,
    Csv,
}

impl TableFormat {
    pub fn name(self) -> &'static str {
        match self {
            TableFormat::Linuxcnc => "linuxcnc",
            TableFormat::Sinumerik => "sinumerik",
            TableFormat::Fanuc => "fanuc",
            TableFormat::Heidenhain => "heidenhain",
            TableFormat::Csv => "csv",
        }
    }
}

/// Axis error of each direction at equally spaced positions.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct CompTable {
    pub positions_mm: Vec<f64>,
    /// e↑ = actual − nominal, forward approach (µm).
    pub forward_um: Vec<f64>,
    /// e↓, reverse approach (µm).
    pub reverse_um: Vec<f64>,
}

/// Options of the controller formats.
#[derive(Debug, Clone, PartialEq)]
pub struct TableOptions {
    /// LinuxCNC COMP_FILE_TYPE: 0 positions, 1 trims.
    pub linuxcnc_type: u8,
    /// Axis name: Sinumerik machine axis (AX1, X1), Heidenhain column (X), Fanuc axis number (1).
    pub axis: Option<String>,
    /// Fanuc detection unit (µm per count); also the unit of parameter 3624.
    pub fanuc_unit_um: f64,
    /// Machine position of the reference point (Fanuc 3620); defaults to the first position.
    pub reference_mm: Option<f64>,
    /// First Sinumerik CEC table index for the direction-dependent part (uses t and t + 1).
    pub cec_table: u32,
}

impl Default for TableOptions {
    fn default() -> Self {
        TableOptions {
            linuxcnc_type: 0,
            axis: None,
            fanuc_unit_um: 1.0,
            reference_mm: None,
            cec_table: 0,
        }
    }
}

/// LinuxCNC's limit on triplets per joint.
pub const LINUXCNC_MAX_LINES: usize = 256;
/// Fanuc pitch-error compensation points (data numbers 0…1023).
pub const FANUC_MAX_POINTS: usize = 1024;

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
    /// Resample the mean deviation of each direction to positions first target + k·spacing
    /// (≤ last target), linearly between targets.
    pub fn from_evaluation(ev: &Evaluation, spacing_mm: f64) -> Result<CompTable> {
        if !(spacing_mm.is_finite() && spacing_mm > 0.0) {
            return Err(Error::usage(
                format!("spacing {spacing_mm} mm is not a positive length"),
                "give the table spacing in mm, e.g. --spacing 20",
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
        let count_f = ((last - first) / spacing_mm + 1e-9).floor() + 1.0;
        if count_f.is_nan() || count_f > 100_000.0 {
            return Err(Error::usage(
                format!(
                    "spacing {spacing_mm:?} mm over {} mm gives {count_f:.3e} table points, more than 100000",
                    last - first
                ),
                "choose a coarser spacing",
            ));
        }
        let count = count_f as usize;
        let positions_mm: Vec<f64> = (0..count).map(|k| first + k as f64 * spacing_mm).collect();
        Ok(CompTable {
            forward_um: positions_mm.iter().map(|&x| interp(&xs, &up, x)).collect(),
            reverse_um: positions_mm
                .iter()
                .map(|&x| interp(&xs, &down, x))
                .collect(),
            positions_mm,
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

/// Path of the second Sinumerik file (direction-dependent CEC tables) beside `path`.
pub fn sinumerik_cec_path(path: &Path) -> PathBuf {
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let name = match path.extension() {
        Some(ext) => format!("{stem}_cec.{}", ext.to_string_lossy()),
        None => format!("{stem}_cec"),
    };
    path.with_file_name(name)
}

/// The rendered file(s) of a table: `(path, text)` pairs (Sinumerik writes two).
pub fn render_table(
    table: &CompTable,
    format: TableFormat,
    opts: &TableOptions,
    path: &Path,
) -> Result<Vec<(PathBuf, String)>> {
    if table.positions_mm.len() < 2 {
        return Err(Error::usage(
            "a compensation table needs at least two points",
            "use a smaller --spacing or measure a longer travel",
        ));
    }
    Ok(match format {
        TableFormat::Linuxcnc => vec![(path.to_path_buf(), linuxcnc(table, opts)?)],
        TableFormat::Sinumerik => {
            let (lec, cec) = sinumerik(table, opts);
            vec![(path.to_path_buf(), lec), (sinumerik_cec_path(path), cec)]
        }
        TableFormat::Fanuc => vec![(path.to_path_buf(), fanuc(table, opts)?)],
        TableFormat::Heidenhain => vec![(path.to_path_buf(), heidenhain(table, opts, path))],
        TableFormat::Csv => vec![(path.to_path_buf(), csv(table))],
    })
}

fn linuxcnc(t: &CompTable, opts: &TableOptions) -> Result<String> {
    if t.positions_mm.len() > LINUXCNC_MAX_LINES {
        return Err(Error::usage(
            format!(
                "{} points, but LinuxCNC reads at most {LINUXCNC_MAX_LINES} per joint",
                t.positions_mm.len()
            ),
            "choose a larger --spacing",
        ));
    }
    let mut out = String::new();
    for ((x, f), r) in t.positions_mm.iter().zip(&t.forward_um).zip(&t.reverse_um) {
        // Machine units (mm); nothing but the triplets: LinuxCNC stops at the first other line.
        let (a, b) = match opts.linuxcnc_type {
            0 => (x + f * 1e-3, x + r * 1e-3),
            1 => (-f * 1e-3, -r * 1e-3),
            other => {
                return Err(Error::usage(
                    format!("LinuxCNC COMP_FILE_TYPE {other} does not exist"),
                    "use --linuxcnc-type 0 (positions) or 1 (trims)",
                ))
            }
        };
        let _ = writeln!(out, "{x:.6} {a:.6} {b:.6}");
    }
    Ok(out)
}

fn fmt_mm(v_um: f64) -> String {
    let v = v_um * 1e-3;
    // Avoid "-0.000000".
    let v = if v.abs() < 5e-7 { 0.0 } else { v };
    format!("{v:.6}")
}

fn sinumerik(t: &CompTable, opts: &TableOptions) -> (String, String) {
    let axis = opts.axis.clone().unwrap_or_else(|| "AX1".to_string());
    let n = t.positions_mm.len();
    let step = t.spacing_mm();
    let min = t.positions_mm[0];
    let max = t.positions_mm[n - 1];
    let mean: Vec<f64> = t
        .forward_um
        .iter()
        .zip(&t.reverse_um)
        .map(|(f, r)| (f + r) / 2.0)
        .collect();
    let mut lec = String::new();
    let _ = writeln!(lec, "%_N_AX_EEC_INI");
    let _ = writeln!(lec, "CHANDATA(1)");
    let _ = writeln!(
        lec,
        "; errmap LEC, axis {axis}: mean of both directions, +error in mm (positive moves the axis negative)"
    );
    for (i, v) in mean.iter().enumerate() {
        let _ = writeln!(lec, "$AA_ENC_COMP[0,{i},{axis}]={}", fmt_mm(*v));
    }
    let _ = writeln!(lec, "$AA_ENC_COMP_STEP[0,{axis}]={step:.6}");
    let _ = writeln!(lec, "$AA_ENC_COMP_MIN[0,{axis}]={min:.6}");
    let _ = writeln!(lec, "$AA_ENC_COMP_MAX[0,{axis}]={max:.6}");
    let _ = writeln!(lec, "$AA_ENC_COMP_IS_MODULO[0,{axis}]=0");
    let _ = writeln!(lec, "M17");

    let mut cec = String::new();
    let _ = writeln!(cec, "%_N_NC_CEC_INI");
    let _ = writeln!(cec, "CHANDATA(1)");
    let _ = writeln!(
        cec,
        "; errmap direction-dependent LEC, axis {axis}: −(e − mean) in mm, added to the setpoint"
    );
    for (k, (dir, ys)) in [(1, &t.forward_um), (-1, &t.reverse_um)]
        .into_iter()
        .enumerate()
    {
        let tab = opts.cec_table + k as u32;
        for (i, (v, m)) in ys.iter().zip(&mean).enumerate() {
            let _ = writeln!(cec, "$AN_CEC[{tab},{i}]={}", fmt_mm(-(v - m)));
        }
        let _ = writeln!(cec, "$AN_CEC_INPUT_AXIS[{tab}]={axis}");
        let _ = writeln!(cec, "$AN_CEC_OUTPUT_AXIS[{tab}]={axis}");
        let _ = writeln!(cec, "$AN_CEC_STEP[{tab}]={step:.6}");
        let _ = writeln!(cec, "$AN_CEC_MIN[{tab}]={min:.6}");
        let _ = writeln!(cec, "$AN_CEC_MAX[{tab}]={max:.6}");
        let _ = writeln!(cec, "$AN_CEC_DIRECTION[{tab}]={dir}");
        let _ = writeln!(cec, "$AN_CEC_MULT_BY_TABLE[{tab}]=0");
        let _ = writeln!(cec, "$AN_CEC_IS_MODULO[{tab}]=0");
    }
    let _ = writeln!(cec, "M17");
    (lec, cec)
}

/// Fanuc layout: forward points 0…n−1, reverse points n…2n−1, reference = nearest position.
struct FanucLayout {
    axis: u32,
    unit_um: f64,
    reference_index: usize,
    interval_counts: i64,
}

fn fanuc_layout(t: &CompTable, opts: &TableOptions) -> Result<FanucLayout> {
    let axis: u32 = match &opts.axis {
        None => 1,
        Some(a) => a.parse().ok().filter(|&n| n >= 1).ok_or_else(|| {
            Error::usage(
                format!("Fanuc axis '{a}' is not an axis number"),
                "give the controlled-axis number, e.g. --axis 1 for X",
            )
        })?,
    };
    let unit_um = opts.fanuc_unit_um;
    if !(unit_um.is_finite() && unit_um > 0.0) {
        return Err(Error::usage(
            format!("Fanuc detection unit {unit_um} µm is not positive"),
            "use --fanuc-unit-um 1 for IS-B (0.001 mm), 0.1 for IS-C",
        ));
    }
    let n = t.positions_mm.len();
    if 2 * n > FANUC_MAX_POINTS {
        return Err(Error::usage(
            format!(
                "{} compensation points exceed Fanuc's {FANUC_MAX_POINTS}",
                2 * n
            ),
            "choose a larger --spacing",
        ));
    }
    let spacing_counts = t.spacing_mm() * 1e3 / unit_um;
    let interval_counts = spacing_counts.round() as i64;
    if (spacing_counts - interval_counts as f64).abs() > 1e-6 || interval_counts <= 0 {
        return Err(Error::usage(
            format!(
                "spacing {} mm is not a whole number of detection units of {unit_um} µm",
                t.spacing_mm()
            ),
            "choose a spacing that is a multiple of the detection unit",
        ));
    }
    let reference_mm = opts.reference_mm.unwrap_or(t.positions_mm[0]);
    let reference_index = t
        .positions_mm
        .iter()
        .position(|&x| (x - reference_mm).abs() < 1e-6)
        .ok_or_else(|| {
            Error::usage(
                format!("reference position {reference_mm} mm is not a table point"),
                "give --reference-mm equal to the first target plus a multiple of --spacing",
            )
        })?;
    Ok(FanucLayout {
        axis,
        unit_um,
        reference_index,
        interval_counts,
    })
}

fn fanuc(t: &CompTable, opts: &TableOptions) -> Result<String> {
    let l = fanuc_layout(t, opts)?;
    let n = t.positions_mm.len();
    // Absolute compensation in counts, C = round(−e / unit); increments C_k − C_{k−1} so that
    // rounding never accumulates. Point 0 of each block covers the section below the table: 0.
    let counts =
        |ys: &[f64]| -> Vec<i64> { ys.iter().map(|e| (-e / l.unit_um).round() as i64).collect() };
    let up = counts(&t.forward_um);
    let down = counts(&t.reverse_um);
    let a = l.axis;
    let mut out = String::from("%\n");
    let _ = writeln!(out, "N3620A{a}P{}", l.reference_index);
    let _ = writeln!(out, "N3621A{a}P0");
    let _ = writeln!(out, "N3622A{a}P{}", n - 1);
    let _ = writeln!(out, "N3623A{a}P1");
    let _ = writeln!(out, "N3624A{a}P{}", l.interval_counts);
    let _ = writeln!(out, "N3626A{a}P{n}");
    let _ = writeln!(
        out,
        "N3627A{a}P{}",
        down[l.reference_index] - up[l.reference_index]
    );
    for (block, c) in [(0, &up), (n, &down)] {
        for k in 0..n {
            let v = if k == 0 { 0 } else { c[k] - c[k - 1] };
            let _ = writeln!(out, "N{}P{v}", 10000 + block + k);
        }
    }
    out.push_str("%\n");
    Ok(out)
}

fn heidenhain(t: &CompTable, opts: &TableOptions, path: &Path) -> String {
    let axis = opts.axis.clone().unwrap_or_else(|| "X".to_string());
    let name = path
        .file_name()
        .map(|s| s.to_string_lossy().to_uppercase())
        .unwrap_or_else(|| format!("{axis}.COM"));
    let mut out = String::new();
    let _ = writeln!(out, "BEGIN {name} MM");
    let _ = writeln!(
        out,
        "{:<6}{:<16}{:<16}{:<16}",
        "NR", "AXISPOS", axis, "BACKLASH"
    );
    for (i, ((x, f), r)) in t
        .positions_mm
        .iter()
        .zip(&t.forward_um)
        .zip(&t.reverse_um)
        .enumerate()
    {
        let sign = |v: f64| format!("{}{}", if v < 0.0 { "" } else { "+" }, v);
        let _ = writeln!(
            out,
            "{:<6}{:<16}{:<16}{:<16}",
            i,
            sign((x * 1e4).round() / 1e4),
            sign(fmt_mm(*f).parse().unwrap_or(0.0)),
            sign(fmt_mm(*r).parse().unwrap_or(0.0))
        );
    }
    let _ = writeln!(out, "[END]");
    out
}

fn csv(t: &CompTable) -> String {
    let mut out = String::from(
        "# errmap compensation table: axis error e = actual - nominal per direction (um); a controller applies -e\nposition_mm,forward_um,reverse_um\n",
    );
    for ((x, f), r) in t.positions_mm.iter().zip(&t.forward_um).zip(&t.reverse_um) {
        let _ = writeln!(out, "{x:.6},{f:.4},{r:.4}");
    }
    out
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
) -> Result<CompTable> {
    let text = crate::io::read_text(path)?;
    let format = match format.or_else(|| detect_format(&text)) {
        Some(f) => f,
        None => {
            return Err(Error::input(
                Location::file(path),
                "cannot tell which controller format this table is",
                "errmap reads the files `errmap linear table` writes (linuxcnc, sinumerik, fanuc, heidenhain, csv)",
            ))
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
        ));
    }
    Ok(table)
}

fn read_linuxcnc(path: &Path, text: &str, kind: u8) -> Result<CompTable> {
    let mut t = CompTable {
        positions_mm: vec![],
        forward_um: vec![],
        reverse_um: vec![],
    };
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
    let (mut fwd, mut rev) = (mean.clone(), mean.clone());
    let cec_path = sinumerik_cec_path(path);
    if cec_path.exists() {
        let cec = crate::io::read_text(&cec_path)?;
        let mut tables: std::collections::BTreeMap<u32, (Vec<(usize, f64)>, i32)> =
            Default::default();
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
                            &cec_path,
                            i + 1,
                            "bad $AN_CEC index",
                            "write $AN_CEC[t,i]=value",
                        )
                    })?;
                    entry.0.push((k, num(&cec_path, i + 1, rhs)? * 1e3));
                }
                "$AN_CEC_DIRECTION" => entry.1 = num(&cec_path, i + 1, rhs)? as i32,
                _ => {}
            }
        }
        for (_, (mut pts, dir)) in tables {
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
    })
}

fn read_fanuc(path: &Path, text: &str, opts: &TableOptions) -> Result<CompTable> {
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
    let cumulative = |base: i64| -> Result<Vec<f64>> {
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
            .map(|v| -(v as f64) * unit)
            .collect())
    };
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
    })
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
    let mut t = CompTable {
        positions_mm: vec![],
        forward_um: vec![],
        reverse_um: vec![],
    };
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
    let table = crate::io::CsvTable::parse(path, text)?;
    table.reject_unknown(&["position_mm", "forward_um", "reverse_um"])?;
    let (cx, cf, cr) = (
        table.require("position_mm")?,
        table.require("forward_um")?,
        table.require("reverse_um")?,
    );
    let mut t = CompTable {
        positions_mm: vec![],
        forward_um: vec![],
        reverse_um: vec![],
    };
    for row in &table.rows {
        t.positions_mm.push(table.f64(row, cx)?);
        t.forward_um.push(table.f64(row, cf)?);
        t.reverse_um.push(table.f64(row, cr)?);
    }
    Ok(t)
}
