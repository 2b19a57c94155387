//! Laser-interferometer run files: reading, validating and flattening `run,direction,target_mm,…` CSV into samples.

use super::columns::ColumnMap;
use errmap_core::error::{Error, Location, Result};
use errmap_core::io::{CsvRow, CsvTable};
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

pub use errmap_core::direction::Direction;

/// One measured deviation: the `run`-th approach from `direction` to `target`.
///
/// Unit-agnostic: linear axes use mm targets and µm deviations, rotary axes deg and arcsec;
/// [`crate::linear::evaluate`] never converts.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Sample {
    /// Run (repeat) number j of the approach.
    pub run: u32,
    /// Approach direction: forward (`+`, increasing) or reverse (`-`).
    pub direction: Direction,
    /// Target position: mm on a linear axis, degrees on a rotary one.
    pub target: f64,
    /// Deviation actual − target: µm on a linear axis, arcsec on a rotary one.
    pub deviation: f64,
}

/// Optional environment of a row, as the laser's weather station and material sensors logged it.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct Env {
    /// Air temperature at the beam, °C; `None`: not logged.
    pub air_temp_c: Option<f64>,
    /// Absolute air pressure, kPa; `None`: not logged.
    pub pressure_kpa: Option<f64>,
    /// Relative humidity, %; `None`: not logged.
    pub humidity_pct: Option<f64>,
    /// Temperature of the axis' material (scale or screw), °C; `None`: not logged.
    pub material_temp_c: Option<f64>,
}

/// One row of a run file.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct RunRow {
    /// Run number from the `run` column (non-negative integer).
    pub run: u32,
    /// Approach direction from the `direction` column (`+` forward, `-` reverse).
    pub direction: Direction,
    /// Commanded target position, mm.
    pub target_mm: f64,
    /// Positional deviation, actual − target (ISO 230-2 sign), in µm.
    pub deviation_um: f64,
    /// The environment logged with the reading (all `None` when the file has no such columns).
    pub env: Env,
    /// Optional time stamp of the reading (seconds from any origin), for thermal campaigns.
    pub time_s: Option<f64>,
    /// 1-based line of the row in its file.
    pub line: u64,
}

impl RunRow {
    /// The position the laser read, mm: target + deviation.
    pub fn actual_mm(&self) -> f64 {
        self.target_mm + self.deviation_um * 1e-3
    }
}

/// A validated run file: every (run, direction) pass visits the same set of targets once.
#[derive(Debug, Clone, serde::Serialize)]
pub struct RunFile {
    /// The file read, as messages name it.
    pub path: PathBuf,
    /// Rows in file order.
    pub rows: Vec<RunRow>,
    /// Whether the file gave `actual_mm` (true) or `deviation_um` (false).
    pub had_actual: bool,
}

/// Columns a run file may have.
pub const RUN_COLUMNS: &[&str] = &[
    "run",
    "direction",
    "target_mm",
    "actual_mm",
    "deviation_um",
    "air_temp_c",
    "pressure_kpa",
    "humidity_pct",
    "material_temp_c",
    "time_s",
];

/// Targets closer than this (mm) are the same target; a pass must hit each one exactly once.
pub const TARGET_TOLERANCE_MM: f64 = 1e-6;

/// Read and validate a run file (CSV with a header).
///
/// Required: `run` (non-negative integer), `direction` (`+`/`-`), `target_mm`, and exactly one of
/// `actual_mm` (the laser's reading, mm) or `deviation_um` (actual − target, µm). Optional per row:
/// `air_temp_c`, `pressure_kpa`, `humidity_pct`, `material_temp_c`, `time_s` (empty cell = not logged).
/// Every error names file:line and column. A target visited by some passes but not by others,
/// or twice in one pass, is an error that names the target and the pass.
pub fn read_runs(path: &Path) -> Result<RunFile> {
    let table = CsvTable::read(path)?;
    parse_table(&table)
}

/// Read an instrument's CSV export through a column mapping (see [`ColumnMap`]): the mapped
/// columns become a run file's, in its units, and are validated like one.
pub fn read_runs_mapped(path: &Path, map: &ColumnMap) -> Result<RunFile> {
    let table = CsvTable::read(path)?;
    parse_table(&super::columns::map_table(&table, map)?)
}

/// [`read_runs`] on CSV text already in memory (`path` is only used in messages).
pub fn parse_runs(path: &Path, text: &str) -> Result<RunFile> {
    let table = CsvTable::parse(path, text)?;
    parse_table(&table)
}

fn parse_table(table: &CsvTable) -> Result<RunFile> {
    let path = &table.path;
    let cols = RunColumns::find(table)?;
    if table.rows.is_empty() {
        return Err(Error::input(
            Location::file(path),
            "the file has a header but no rows",
            "add one row per reading",
        ));
    }
    let rows = table
        .rows
        .iter()
        .map(|row| parse_row(table, &cols, row))
        .collect::<Result<Vec<RunRow>>>()?;
    // Directions first: a target never measured in one direction is a mixed file, named at
    // that target's first line, rather than a pass "missing" it.
    check_directions(path, &rows)?;
    check_passes(path, &rows)?;
    Ok(RunFile {
        path: path.to_path_buf(),
        rows,
        had_actual: matches!(cols.reading, Reading::ActualMm(_)),
    })
}

/// The column of the reading: the laser's position (mm) or the deviation (µm).
enum Reading {
    ActualMm(usize),
    DeviationUm(usize),
}

/// Where each field of a run file is.
struct RunColumns {
    run: usize,
    direction: usize,
    target_mm: usize,
    reading: Reading,
    air_temp_c: Option<usize>,
    pressure_kpa: Option<usize>,
    humidity_pct: Option<usize>,
    material_temp_c: Option<usize>,
    time_s: Option<usize>,
}

impl RunColumns {
    /// Find the columns by name; unknown columns and a missing or doubled reading are errors.
    fn find(table: &CsvTable) -> Result<RunColumns> {
        let path = &table.path;
        table.reject_unknown(RUN_COLUMNS)?;
        let run = table.require("run")?;
        let direction = table.require("direction")?;
        let target_mm = table.require("target_mm")?;
        let reading =
            match (table.column("actual_mm"), table.column("deviation_um")) {
                (Some(c), None) => Reading::ActualMm(c),
                (None, Some(c)) => Reading::DeviationUm(c),
                (Some(_), Some(_)) => return Err(Error::input(
                    Location::cell(path, 1, "deviation_um"),
                    "the header has both actual_mm and deviation_um",
                    "keep one: actual_mm (laser reading, mm) or deviation_um (actual − target, µm)",
                )),
                (None, None) => {
                    return Err(Error::input(
                        Location::line(path, 1),
                        format!(
                            "missing column 'actual_mm' or 'deviation_um' (header has: {})",
                            table.headers.join(",")
                        ),
                        "add actual_mm (laser reading, mm) or deviation_um (actual − target, µm)",
                    ))
                }
            };
        Ok(RunColumns {
            run,
            direction,
            target_mm,
            reading,
            air_temp_c: table.column("air_temp_c"),
            pressure_kpa: table.column("pressure_kpa"),
            humidity_pct: table.column("humidity_pct"),
            material_temp_c: table.column("material_temp_c"),
            time_s: table.column("time_s"),
        })
    }
}

/// One reading of a run file, its fields checked.
fn parse_row(table: &CsvTable, cols: &RunColumns, row: &CsvRow) -> Result<RunRow> {
    let opt = |c: Option<usize>| -> Result<Option<f64>> {
        match c {
            Some(c) => table.f64_opt(row, c),
            None => Ok(None),
        }
    };
    let run_text = table.text(row, cols.run);
    let run: u32 = run_text.parse().map_err(|_| {
        table.error_at(
            row,
            Some(cols.run),
            format!("'{run_text}' is not a run number"),
            "number runs 1, 2, 3 … (a non-negative integer)",
        )
    })?;
    let dir_text = table.text(row, cols.direction);
    let direction = Direction::parse(dir_text).ok_or_else(|| {
        table.error_at(
            row,
            Some(cols.direction),
            format!("'{dir_text}' is not a direction"),
            "write + for the forward (increasing) approach or - for the reverse",
        )
    })?;
    let target_mm = table.f64(row, cols.target_mm)?;
    let deviation_um = match cols.reading {
        Reading::ActualMm(c) => (table.f64(row, c)? - target_mm) * 1e3,
        Reading::DeviationUm(c) => table.f64(row, c)?,
    };
    let env = Env {
        air_temp_c: opt(cols.air_temp_c)?,
        pressure_kpa: opt(cols.pressure_kpa)?,
        humidity_pct: opt(cols.humidity_pct)?,
        material_temp_c: opt(cols.material_temp_c)?,
    };
    check_env(table, cols, row, &env)?;
    Ok(RunRow {
        run,
        direction,
        target_mm,
        deviation_um,
        env,
        time_s: opt(cols.time_s)?,
        line: row.line,
    })
}

/// A row's air pressure must be positive and its humidity within 0…100 %.
fn check_env(table: &CsvTable, cols: &RunColumns, row: &CsvRow, env: &Env) -> Result<()> {
    if let (Some(p), Some(c)) = (env.pressure_kpa, cols.pressure_kpa) {
        if p <= 0.0 {
            return Err(table.error_at(
                row,
                Some(c),
                format!("pressure {p} kPa is not positive"),
                "write the absolute air pressure in kPa, e.g. 101.325",
            ));
        }
    }
    if let (Some(h), Some(c)) = (env.humidity_pct, cols.humidity_pct) {
        if !(0.0..=100.0).contains(&h) {
            return Err(table.error_at(
                row,
                Some(c),
                format!("relative humidity {h} % is outside 0…100"),
                "write the relative humidity in percent",
            ));
        }
    }
    Ok(())
}

/// Every pass (run, direction) must visit every target of the file exactly once.
fn check_passes(path: &Path, rows: &[RunRow]) -> Result<()> {
    let targets = distinct_targets(rows.iter().map(|r| r.target_mm));
    let mut passes: BTreeMap<(u32, Direction), Vec<Option<u64>>> = BTreeMap::new();
    for r in rows {
        let slots = passes
            .entry((r.run, r.direction))
            .or_insert_with(|| vec![None; targets.len()]);
        let i = target_index(&targets, r.target_mm)
            .ok_or_else(|| Error::Internal("target not in its own list".into()))?;
        if let Some(first) = slots[i] {
            return Err(Error::input(
                Location::line(path, r.line),
                format!(
                    "run {} direction {} visits target {} mm twice (first at line {first})",
                    r.run,
                    r.direction.symbol(),
                    r.target_mm
                ),
                "keep one reading per run, direction and target (or give the repeat its own run number)",
            ));
        }
        slots[i] = Some(r.line);
    }
    for ((run, dir), slots) in &passes {
        let missing: Vec<String> = slots
            .iter()
            .zip(&targets)
            .filter(|(s, _)| s.is_none())
            .map(|(_, t)| format!("{t}"))
            .collect();
        if !missing.is_empty() {
            let where_seen = rows
                .iter()
                .find(|r| r.run == *run && r.direction == *dir)
                .map(|r| r.line)
                .unwrap_or(1);
            return Err(Error::input(
                Location::line(path, where_seen),
                format!(
                    "target {} mm missing from run {run} direction {} (other runs visit it)",
                    missing.join(", "),
                    dir.symbol()
                ),
                "every run must measure every target in each direction it runs; add the readings or drop the target from all runs",
            ));
        }
    }
    Ok(())
}

/// Either every target is approached from both directions (bidirectional test) or every target
/// from the same single direction (unidirectional test, ISO 230-2 allows n ≥ 1 runs per
/// direction); a mix is an error naming the first line of the first target that lacks a direction.
fn check_directions(path: &Path, rows: &[RunRow]) -> Result<()> {
    let targets = distinct_targets(rows.iter().map(|r| r.target_mm));
    // Per target: first line seen in each direction [forward, reverse].
    let mut seen: Vec<[Option<u64>; 2]> = vec![[None, None]; targets.len()];
    for r in rows {
        let i = target_index(&targets, r.target_mm)
            .ok_or_else(|| Error::Internal("target not in its own list".into()))?;
        let slot = &mut seen[i][usize::from(r.direction == Direction::Reverse)];
        if slot.is_none() {
            *slot = Some(r.line);
        }
    }
    let both = seen.iter().any(|s| s[0].is_some() && s[1].is_some());
    let only = |d: usize| seen.iter().all(|s| s[d].is_some() && s[1 - d].is_none());
    if !both && (only(0) || only(1)) {
        return Ok(());
    }
    if seen.iter().all(|s| s[0].is_some() && s[1].is_some()) {
        return Ok(());
    }
    // Mixed: report the single-direction target whose first reading comes first in the file.
    let offending = seen
        .iter()
        .zip(&targets)
        .filter_map(|(s, t)| match s {
            [Some(l), None] => Some((*l, *t, Direction::Forward)),
            [None, Some(l)] => Some((*l, *t, Direction::Reverse)),
            _ => None,
        })
        .min_by_key(|(l, _, _)| *l);
    let Some((line, target, dir)) = offending else {
        return Ok(());
    };
    let other = match dir {
        Direction::Forward => Direction::Reverse,
        Direction::Reverse => Direction::Forward,
    };
    let why = if both {
        "other targets are approached from both directions".to_string()
    } else {
        format!(
            "other targets are approached in direction {} only",
            other.symbol()
        )
    };
    Err(Error::input(
        Location::line(path, line),
        format!(
            "target {target} mm is approached in direction {} only but {why} (mixed uni/bidirectional file)",
            dir.symbol()
        ),
        "measure every target from both directions, or every target from the same one direction (unidirectional test)",
    ))
}

/// Sorted distinct targets, merging values closer than [`TARGET_TOLERANCE_MM`].
pub(crate) fn distinct_targets(values: impl Iterator<Item = f64>) -> Vec<f64> {
    let mut all: Vec<f64> = values.collect();
    all.sort_by(f64::total_cmp);
    let mut out: Vec<f64> = Vec::new();
    for v in all {
        match out.last() {
            Some(&last) if (v - last).abs() <= TARGET_TOLERANCE_MM => {}
            _ => out.push(v),
        }
    }
    out
}

pub(crate) fn target_index(targets: &[f64], value: f64) -> Option<usize> {
    targets
        .iter()
        .position(|t| (t - value).abs() <= TARGET_TOLERANCE_MM)
}

impl RunFile {
    /// The rows as unit-agnostic samples (target in mm, deviation in µm), in file order.
    pub fn samples(&self) -> Vec<Sample> {
        self.rows
            .iter()
            .map(|r| Sample {
                run: r.run,
                direction: r.direction,
                target: r.target_mm,
                deviation: r.deviation_um,
            })
            .collect()
    }

    /// Distinct targets, ascending (mm).
    pub fn targets_mm(&self) -> Vec<f64> {
        distinct_targets(self.rows.iter().map(|r| r.target_mm))
    }

    /// Distinct run numbers, ascending.
    pub fn runs(&self) -> Vec<u32> {
        self.rows
            .iter()
            .map(|r| r.run)
            .collect::<BTreeSet<_>>()
            .into_iter()
            .collect()
    }
}
