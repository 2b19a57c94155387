//! Reading a circular-test run: the radial (ballbar) and two-axis (grid encoder) CSV forms, checked row by row and sorted by angle.

use super::circle::fit_circle;
use crate::Setting;
use errmap_core::error::{Error, Location, Result};
use errmap_core::io::{CsvRow, CsvTable};
use errmap_core::setting::words;
use serde::Serialize;
use std::f64::consts::{PI, TAU};
use std::path::{Path, PathBuf};

/// Largest allowed angle between neighbouring readings of one direction.
pub const MAX_GAP_DEG: f64 = 10.0;
/// Fewest readings a direction may have (one every 10°).
pub const MIN_READINGS: usize = 36;
/// A reading farther than this fraction of the radius from the nominal radius means the
/// radius (or the centre, or the unit) does not match the data.
pub const RADIUS_TOLERANCE: f64 = 0.10;
/// A reading farther than this fraction of the radius from the circle fitted through the
/// run is not near a circle.
pub const OFF_CIRCLE_FRACTION: f64 = 0.01;
/// Two angles of one direction closer than this (degrees) are the same angle.
const SAME_ANGLE_DEG: f64 = 1e-9;

/// Sense of rotation of the contouring, seen with the plane's first axis to the right and the second up
/// (G3 is counter-clockwise, G2 clockwise, in G17, G18 and G19 alike).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Rotation {
    /// Counter-clockwise: the angle grows from +first toward +second axis (G3).
    Ccw,
    /// Clockwise: the angle shrinks (G2).
    Cw,
}

impl Rotation {
    /// +1 when the angle grows with time (ccw), −1 when it shrinks (cw).
    pub fn sense(self) -> f64 {
        match self {
            Rotation::Ccw => 1.0,
            Rotation::Cw => -1.0,
        }
    }
    /// The direction word of the run file (`ccw`, `cw`), also used in messages and the chart
    /// legend.
    pub fn name(self) -> &'static str {
        match self {
            Rotation::Ccw => "ccw",
            Rotation::Cw => "cw",
        }
    }
}

/// The plane of the circle: its first and second axis (angles run from +first toward +second).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Plane {
    /// First axis X, second Y (the G17 plane).
    #[default]
    Xy,
    /// First axis Y, second Z (the G19 plane).
    Yz,
    /// First axis Z, second X (the G18 plane).
    Zx,
}

impl Plane {
    /// Names of the first and second axis.
    pub fn axes(self) -> [&'static str; 2] {
        match self {
            Plane::Xy => ["X", "Y"],
            Plane::Yz => ["Y", "Z"],
            Plane::Zx => ["Z", "X"],
        }
    }
}

/// Which of the two CSV forms a file has.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Form {
    /// `direction,angle_deg,deviation_um`: measured radius minus nominal, as a ballbar gives it.
    Radial,
    /// `direction,x_mm,y_mm`: positions read on the plane's first and second axis.
    TwoAxis,
}

/// How to read a run file.
#[derive(Debug, Clone, Copy)]
pub struct ReadOptions {
    /// Nominal radius of the programmed circle.
    pub radius_mm: f64,
    /// Nominal centre in the coordinates of a two-axis file (first, second axis).
    pub centre_mm: [f64; 2],
}

/// One reading of a direction, as a point relative to the nominal centre.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reading {
    /// 1-based line in the file.
    pub line: u64,
    /// The sense of the contouring when the reading was taken.
    pub direction: Rotation,
    /// Angle about the nominal centre in [0, 2π): as read (radial form) or of the point (two-axis).
    pub angle_rad: f64,
    /// Position relative to the nominal centre (first, second axis).
    pub point_mm: [f64; 2],
}

/// A checked run: readings of each direction sorted by angle; overshoot rows counted, not used.
#[derive(Debug, Clone)]
pub struct CircularRun {
    /// The file read, as messages name it.
    pub path: PathBuf,
    /// The CSV form of the file.
    pub form: Form,
    /// Programmed (nominal) radius of the circle, mm.
    pub radius_mm: f64,
    /// ccw readings first, then cw, each sorted by angle.
    pub readings: Vec<Reading>,
    /// Rows not evaluated: marked `overshoot`, or past one turn of their direction.
    pub overshoot_rows: usize,
    /// Of those, the readings past one turn (taken as overshoot by errmap, not marked).
    pub overrun_rows: usize,
}

impl CircularRun {
    /// The readings of one direction (sorted by angle); empty when the run lacks it.
    pub fn direction(&self, d: Rotation) -> Vec<&Reading> {
        self.readings.iter().filter(|r| r.direction == d).collect()
    }
    /// Directions present, ccw first.
    pub fn directions(&self) -> Vec<Rotation> {
        [Rotation::Ccw, Rotation::Cw]
            .into_iter()
            .filter(|d| self.readings.iter().any(|r| r.direction == *d))
            .collect()
    }
}

/// Read and check a run file.
pub fn read_run(path: &Path, opts: &ReadOptions) -> Result<CircularRun> {
    let table = CsvTable::read(path)?;
    from_table(&table, opts)
}

/// [`read_run`] on text in memory; `path` is only used in messages.
pub fn parse_run(path: &Path, text: &str, opts: &ReadOptions) -> Result<CircularRun> {
    let table = CsvTable::parse(path, text)?;
    from_table(&table, opts)
}

fn from_table(t: &CsvTable, opts: &ReadOptions) -> Result<CircularRun> {
    let r_mm = opts.radius_mm;
    let radius_ok = r_mm.is_finite() && r_mm > 0.0;
    if !radius_ok || opts.centre_mm.iter().any(|c| !c.is_finite()) {
        return Err(Error::usage(
            format!(
                "radius {r_mm} mm or centre {:?} mm is not usable",
                opts.centre_mm
            ),
            format!(
                "give the programmed radius with {r} (e.g. {r} 100) and a finite {}",
                words(Setting::Centre),
                r = words(Setting::Radius)
            ),
        ));
    }
    let form = detect_form(t)?;
    let dir_col = t.require("direction")?;
    let mut readings = Vec::new();
    let mut overshoot_rows = 0;
    for row in &t.rows {
        let Some(direction) = parse_direction(t, row, dir_col)? else {
            overshoot_rows += 1;
            // Overshoot rows are checked as numbers but not evaluated.
            read_point(t, row, form, opts)?;
            continue;
        };
        let (angle_rad, point_mm) = read_point(t, row, form, opts)?;
        readings.push(Reading {
            line: row.line,
            direction,
            angle_rad,
            point_mm,
        });
    }
    let overrun = split_overrun(&mut readings);
    overshoot_rows += overrun;
    if readings.is_empty() {
        return Err(Error::input(
            Location::file(&t.path),
            "no cw or ccw readings (only overshoot rows or none at all)",
            "a run needs at least one full turn in one direction",
        ));
    }
    readings.sort_by(|a, b| {
        a.direction
            .cmp(&b.direction)
            .then(a.angle_rad.total_cmp(&b.angle_rad))
    });
    for d in [Rotation::Ccw, Rotation::Cw] {
        let of_dir: Vec<&Reading> = readings.iter().filter(|r| r.direction == d).collect();
        if !of_dir.is_empty() {
            check_direction(&t.path, d, &of_dir)?;
        }
    }
    check_near_circle(&t.path, &readings, r_mm)?;
    Ok(CircularRun {
        path: t.path.clone(),
        form,
        radius_mm: r_mm,
        readings,
        overshoot_rows,
        overrun_rows: overrun,
    })
}

/// Readings past one turn: an instrument records on while the machine runs out of the circle
/// (a ballbar's or grid encoder's overrun). For each direction whose rows come in time order
/// (or sorted by angle: every step between neighbouring rows turns the same way), the angle is
/// followed from the first reading; from the reading that completes 360° on, the rest are
/// overshoot. Rows in no order are left as they are (a repeat is then refused as before).
/// Removes the overrun from `readings` and returns how many readings it held. A reading at
/// 360° after rows sorted from 0° is the overrun's first.
fn split_overrun(readings: &mut Vec<Reading>) -> usize {
    let full_turn_rad = TAU - SAME_ANGLE_DEG.to_radians();
    let mut past = vec![false; readings.len()];
    for d in [Rotation::Ccw, Rotation::Cw] {
        let of_dir: Vec<usize> = (0..readings.len())
            .filter(|&i| readings[i].direction == d)
            .collect();
        // The step between neighbours, the short way round.
        let steps: Vec<f64> = of_dir
            .windows(2)
            .map(|w| {
                (readings[w[1]].angle_rad - readings[w[0]].angle_rad + PI).rem_euclid(TAU) - PI
            })
            .collect();
        let one_way = steps.iter().all(|s| *s > 0.0) || steps.iter().all(|s| *s < 0.0);
        if !one_way {
            continue;
        }
        let mut travelled_rad = 0.0_f64;
        for (k, &i) in of_dir.iter().enumerate() {
            if k > 0 {
                travelled_rad += steps[k - 1];
            }
            past[i] = travelled_rad.abs() >= full_turn_rad;
        }
    }
    let n = past.iter().filter(|p| **p).count();
    let mut flags = past.into_iter();
    readings.retain(|_| !flags.next().unwrap_or(false));
    n
}

fn detect_form(t: &CsvTable) -> Result<Form> {
    let radial = t.column("angle_deg").is_some() || t.column("deviation_um").is_some();
    let two_axis = t.column("x_mm").is_some() || t.column("y_mm").is_some();
    let form =
        match (radial, two_axis) {
            (true, false) => Form::Radial,
            (false, true) => Form::TwoAxis,
            _ => return Err(Error::input(
                Location::line(&t.path, 1),
                format!(
                    "the header ({}) is neither the radial nor the two-axis form",
                    t.headers.join(",")
                ),
                "use direction,angle_deg,deviation_um (ballbar) or direction,x_mm,y_mm (two axes)",
            )),
        };
    match form {
        Form::Radial => {
            t.reject_unknown(&["direction", "angle_deg", "deviation_um"])?;
            t.require("angle_deg")?;
            t.require("deviation_um")?;
        }
        Form::TwoAxis => {
            t.reject_unknown(&["direction", "x_mm", "y_mm"])?;
            t.require("x_mm")?;
            t.require("y_mm")?;
        }
    }
    Ok(form)
}

/// `Some(direction)`, or `None` for an overshoot row.
fn parse_direction(t: &CsvTable, row: &CsvRow, col: usize) -> Result<Option<Rotation>> {
    match t.text(row, col).to_ascii_lowercase().as_str() {
        "ccw" => Ok(Some(Rotation::Ccw)),
        "cw" => Ok(Some(Rotation::Cw)),
        "overshoot" => Ok(None),
        other => Err(t.error_at(
            row,
            Some(col),
            format!("direction '{other}' is not cw, ccw or overshoot"),
            "write cw or ccw for readings of the turn, overshoot for the arcs before and after it",
        )),
    }
}

/// Angle in [0, 2π) and point relative to the nominal centre; a reading whose distance from
/// the centre is more than 10 % off the radius is an error at its line.
fn read_point(
    t: &CsvTable,
    row: &CsvRow,
    form: Form,
    opts: &ReadOptions,
) -> Result<(f64, [f64; 2])> {
    let r_mm = opts.radius_mm;
    match form {
        Form::Radial => {
            let a_col = t.require("angle_deg")?;
            let d_col = t.require("deviation_um")?;
            let angle_deg = t.f64(row, a_col)?;
            let dev_um = t.f64(row, d_col)?;
            if dev_um.abs() * 1e-3 > RADIUS_TOLERANCE * r_mm {
                return Err(t.error_at(
                    row,
                    Some(d_col),
                    format!(
                        "deviation {dev_um} µm is more than 10 % of the radius {r_mm} mm: the radius does not match the data"
                    ),
                    format!(
                        "give the programmed radius with {}, and deviations in µm (measured minus nominal radius)",
                        words(Setting::Radius)
                    ),
                ));
            }
            let a = angle_deg.to_radians().rem_euclid(TAU);
            let rho = r_mm + dev_um * 1e-3;
            Ok((a, [rho * a.cos(), rho * a.sin()]))
        }
        Form::TwoAxis => {
            let x_col = t.require("x_mm")?;
            let y_col = t.require("y_mm")?;
            let p = [
                t.f64(row, x_col)? - opts.centre_mm[0],
                t.f64(row, y_col)? - opts.centre_mm[1],
            ];
            let rho = p[0].hypot(p[1]);
            if (rho - r_mm).abs() > RADIUS_TOLERANCE * r_mm {
                return Err(t.error_at(
                    row,
                    None,
                    format!(
                        "the point is {rho:.4} mm from the nominal centre ({}, {}) but the radius is {r_mm} mm (more than 10 % apart): the radius does not match the data",
                        opts.centre_mm[0], opts.centre_mm[1]
                    ),
                    format!(
                        "give the programmed radius with {} and the circle's centre with {} (x_mm, y_mm are positions on the plane's first and second axis)",
                        words(Setting::Radius),
                        words(Setting::Centre)
                    ),
                ));
            }
            Ok((p[1].atan2(p[0]).rem_euclid(TAU), p))
        }
    }
}

/// Enough readings, no repeated angle, no gap over 10°, a full turn.
fn check_direction(path: &Path, d: Rotation, rs: &[&Reading]) -> Result<()> {
    let name = d.name();
    if rs.len() < MIN_READINGS {
        return Err(Error::input(
            Location::line(path, rs[rs.len() - 1].line),
            format!(
                "the {name} run has only {} readings; at least {MIN_READINGS} (one every 10° or closer) are needed",
                rs.len()
            ),
            "record the whole turn at a higher sampling rate",
        ));
    }
    for w in rs.windows(2) {
        if (w[1].angle_rad - w[0].angle_rad).to_degrees() < SAME_ANGLE_DEG {
            let (a, b) = if w[0].line < w[1].line {
                (w[0], w[1])
            } else {
                (w[1], w[0])
            };
            return Err(Error::input(
                Location::line(path, b.line),
                format!(
                    "angle {:.6}° of the {name} run is repeated (also at line {}; angles are taken modulo 360°)",
                    a.angle_rad.to_degrees(),
                    a.line
                ),
                "keep one reading per angle: drop the reading that closes the turn (360° repeats 0°) or mark extra readings as overshoot",
            ));
        }
    }
    // Largest circular gap between neighbours (the last wraps to the first).
    let mut worst = (0.0_f64, 0usize);
    for i in 0..rs.len() {
        let next = if i + 1 < rs.len() {
            rs[i + 1].angle_rad
        } else {
            rs[0].angle_rad + TAU
        };
        let gap = (next - rs[i].angle_rad).to_degrees();
        if gap > worst.0 {
            worst = (gap, i);
        }
    }
    let (gap_deg, i) = worst;
    if gap_deg > MAX_GAP_DEG {
        let a = rs[i];
        let b = rs[(i + 1) % rs.len()];
        let (message, hint) = if gap_deg > 90.0 {
            (
                format!(
                    "the {name} run covers only {:.1}° (no reading from {:.2}° at line {} to {:.2}° at line {}); a run needs at least one full turn",
                    360.0 - gap_deg,
                    a.angle_rad.to_degrees(),
                    a.line,
                    b.angle_rad.to_degrees(),
                    b.line
                ),
                "record a full turn of each direction (partial-arc tests are not evaluated)",
            )
        } else {
            (
                format!(
                    "gap of {gap_deg:.2}° in the {name} run between {:.2}° (line {}) and {:.2}° (line {}); at most {MAX_GAP_DEG}° is allowed",
                    a.angle_rad.to_degrees(),
                    a.line,
                    b.angle_rad.to_degrees(),
                    b.line
                ),
                "readings must cover the turn without gaps over 10°; record again or at a higher sampling rate",
            )
        };
        return Err(Error::input(Location::line(path, a.line), message, hint));
    }
    Ok(())
}

/// Every reading within 1 % of the radius from the circle fitted through all readings.
fn check_near_circle(path: &Path, rs: &[Reading], r_mm: f64) -> Result<()> {
    let points: Vec<[f64; 2]> = rs.iter().map(|r| r.point_mm).collect();
    let fit = fit_circle(&points, r_mm).ok_or_else(|| {
        Error::input(
            Location::file(path),
            "no circle can be fitted through the readings",
            "readings must lie around a full circle",
        )
    })?;
    let limit_mm = OFF_CIRCLE_FRACTION * r_mm;
    for r in rs {
        let off = (r.point_mm[0] - fit.centre_mm[0]).hypot(r.point_mm[1] - fit.centre_mm[1])
            - fit.radius_mm;
        if off.abs() > limit_mm {
            return Err(Error::input(
                Location::line(path, r.line),
                format!(
                    "the reading is {:.4} mm off the circle fitted through the run (more than 1 % of the radius): the points are not near a circle",
                    off.abs()
                ),
                "check the row (units, axis order, a reading from another test) or mark it as overshoot if it is off the turn",
            ));
        }
    }
    Ok(())
}
