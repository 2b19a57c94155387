//! Compensation tables over the full turn of a modulo rotary axis, written for every controller (LinuxCNC, Sinumerik, Fanuc, Heidenhain, CSV) through [`crate::controller`].

use super::analysis::{modulo_deg, Analysis, TableRow};
use super::input::Direction;
use crate::controller::{AxisKind, ControllerTable};
use crate::Setting;
use errmap_core::error::{Error, Result};
use errmap_core::setting::words;
use std::path::{Path, PathBuf};

pub use crate::controller::{fixed, TableFormat, TableOptions};
/// Most entries per turn a table may have (0.01° steps).
pub const MAX_ENTRIES: usize = 36_000;
/// Largest gap between measured angles the table will interpolate across.
pub const MAX_GAP_DEG: f64 = 90.0;

/// How every entry's value comes from the measured errors; stated in the outputs.
pub const INTERPOLATION: &str =
    "linear between adjacent measured angles, periodic over 360 deg (a measured angle gets its own mean error)";

/// Errors on a uniform grid over the whole turn, 0° … 360° inclusive; the last entry
/// repeats the first, so a modulo axis sees no jump at 360° → 0°.
#[derive(Debug, Clone, PartialEq)]
pub struct CompTable {
    /// Axis letter (`A`, `B`, `C`), written into the table.
    pub axis: String,
    /// Spacing of the entries, degrees (a divisor of 360).
    pub step_deg: f64,
    /// Entry angles 0 … 360 inclusive, degrees.
    pub angles_deg: Vec<f64>,
    /// err = α − β with the axis approaching in the + direction.
    pub forward_arcsec: Vec<f64>,
    /// … in the − direction (equal to forward when only + was measured).
    pub reverse_arcsec: Vec<f64>,
    /// Whether the reverse direction was measured.
    pub bidirectional: bool,
    /// How the grid was chosen (for the output).
    pub grid_note: String,
}

/// Build the table from an analysis; see [`table_from_rows`].
pub fn build_table(
    analysis: &Analysis,
    step_deg: Option<f64>,
    start_deg: Option<f64>,
) -> Result<CompTable> {
    table_from_rows(
        &analysis.axis.to_string(),
        &analysis.table,
        step_deg,
        start_deg,
    )
}

/// Build the table from the mean error per angle and direction.
///
/// The grid goes through the measured angles when they are equally spaced over the turn
/// (`start + step·k`); otherwise, or when given, it is `start_deg + step_deg·k` (step dividing
/// 360; start 0 by default; step by default the smallest measured spacing rounded down to a
/// divisor of 360). Controllers' tables run 0° … 360°, so a grid that does not pass through 0°
/// is refined to the largest step dividing both its step and its start: the extra entries lie
/// on the straight lines between the grid's, and the controller's own linear interpolation
/// draws the same curve.
pub fn table_from_rows(
    axis: &str,
    rows: &[TableRow],
    step_deg: Option<f64>,
    start_deg: Option<f64>,
) -> Result<CompTable> {
    let curves = Curves::from_rows(rows)?;
    if let Some(a) = start_deg.filter(|a| !a.is_finite()) {
        return Err(Error::usage(
            format!("start {a}° is not an angle"),
            format!(
                "give {} as a number of degrees, e.g. 0 or 15",
                words(Setting::StartDeg)
            ),
        ));
    }
    let grid = choose_grid(&curves, step_deg, start_deg)?;
    let fine = step_through_zero(grid.step_deg, grid.start_deg);
    let n = (360.0 / fine).round() as usize;
    if n > MAX_ENTRIES {
        return Err(Error::usage(
            format!(
                "a grid through {}° every {}° needs a {fine}° step from 0° ({n} entries per turn, at most {MAX_ENTRIES})",
                grid.start_deg, grid.step_deg
            ),
            format!(
                "give a {} that is a multiple of a coarser step (e.g. 0 or 15), or a coarser {}",
                words(Setting::StartDeg),
                words(Setting::StepDeg)
            ),
        ));
    }
    let angles_deg: Vec<f64> = (0..=n).map(|i| i as f64 * fine).collect();
    let sample = |c: &[(f64, f64)]| -> Vec<f64> {
        let mut v: Vec<f64> = angles_deg[..n]
            .iter()
            .map(|&g| periodic_interp(c, g))
            .collect();
        v.push(v[0]);
        v
    };
    Ok(CompTable {
        axis: axis.to_string(),
        step_deg: fine,
        forward_arcsec: sample(&curves.forward),
        reverse_arcsec: sample(&curves.reverse),
        angles_deg,
        bidirectional: curves.bidirectional,
        grid_note: grid.note,
    })
}

/// The measured curves of both directions, each covering the turn.
struct Curves {
    /// Mean error per angle in [0, 360) of the + direction (of − when + was not measured).
    forward: Vec<(f64, f64)>,
    /// … of the − direction (of + when − was not measured).
    reverse: Vec<(f64, f64)>,
    /// Whether both directions were measured.
    bidirectional: bool,
}

impl Curves {
    /// Curves of the table rows; a direction measured alone stands for both, and a gap wider
    /// than [`MAX_GAP_DEG`] in either is an error.
    fn from_rows(rows: &[TableRow]) -> Result<Curves> {
        let forward = curve(rows, Direction::Forward);
        let reverse = curve(rows, Direction::Reverse);
        let bidirectional = !reverse.is_empty() && !forward.is_empty();
        let (forward, reverse) = match (forward.is_empty(), reverse.is_empty()) {
            (false, false) => (forward, reverse),
            (false, true) => (forward.clone(), forward),
            (true, false) => (reverse.clone(), reverse),
            (true, true) => {
                return Err(Error::Internal("analysis without a table".into()));
            }
        };
        for c in [&forward, &reverse] {
            check_coverage(c)?;
        }
        Ok(Curves {
            forward,
            reverse,
            bidirectional,
        })
    }
}

/// A grid start + step·k before it is refined to pass through 0°, and how it was chosen.
struct Grid {
    step_deg: f64,
    start_deg: f64,
    note: String,
}

/// The grid: through the measured angles when they are equally spaced (unless a start off them
/// is given), else as given, else the smallest measured spacing rounded down to a divisor of 360.
fn choose_grid(curves: &Curves, step_deg: Option<f64>, start_deg: Option<f64>) -> Result<Grid> {
    let grid = |step_deg, start_deg, note| Grid {
        step_deg,
        start_deg,
        note,
    };
    Ok(
        match (step_deg, equal_spacing(&curves.forward, &curves.reverse)) {
            (None, Some((s, a))) => {
                let off = start_deg.map_or(0.0, |g| (g - a).rem_euclid(s));
                match start_deg {
                    Some(given) if off.min(s - off) > 1e-6 => {
                        let note = format!(
                            "grid {given} + {s}*k deg as given: the entries between the measured angles are interpolated"
                        );
                        grid(s, given, note)
                    }
                    _ => grid(
                        s,
                        a,
                        format!("grid {a} + {s}*k deg through the equally spaced measured angles"),
                    ),
                }
            }
            (Some(s), _) => {
                let a = start_deg.unwrap_or(0.0);
                grid(check_step(s)?, a, format!("grid {a} + {s}*k deg as given"))
            }
            (None, None) => {
                let min_gap = curves
                    .forward
                    .windows(2)
                    .chain(curves.reverse.windows(2))
                    .map(|w| w[1].0 - w[0].0)
                    .fold(f64::INFINITY, f64::min);
                let s = 360.0 / (360.0 / min_gap - 1e-9).ceil();
                let a = start_deg.unwrap_or(0.0);
                let note = format!(
                    "grid {a} + {s}*k deg: the measured angles are not equally spaced, so the entries \
                     are interpolated (choose the grid with --step-deg and --start-deg)"
                );
                grid(s, a, note)
            }
        },
    )
}

fn check_step(s: f64) -> Result<f64> {
    let n = 360.0 / s;
    if !(s.is_finite() && s > 0.0) || n.round() < 1.0 || (n - n.round()).abs() > 1e-9 {
        return Err(Error::usage(
            format!("step {s}° does not divide the turn"),
            "choose a step that divides 360, e.g. 1, 5, 7.5, 10, 15, 30",
        ));
    }
    Ok(s)
}

/// (step, start in [0, step)) when the measured angles of both directions together are
/// equally spaced all round the turn.
fn equal_spacing(forward: &[(f64, f64)], reverse: &[(f64, f64)]) -> Option<(f64, f64)> {
    let mut angles: Vec<f64> = forward.iter().chain(reverse).map(|p| p.0).collect();
    angles.sort_by(f64::total_cmp);
    angles.dedup_by(|a, b| (*a - *b).abs() < 1e-6);
    if angles.len() < 2 {
        return None;
    }
    let step = angles[1] - angles[0];
    let wrap = 360.0 - angles[angles.len() - 1] + angles[0];
    let even =
        angles.windows(2).all(|w| (w[1] - w[0] - step).abs() < 1e-6) && (wrap - step).abs() < 1e-6;
    even.then(|| (step, angles[0] % step))
}

/// The largest step (µdeg resolution) dividing both `step` and `start` (mod `step`).
fn step_through_zero(step: f64, start: f64) -> f64 {
    let micro = |v: f64| (v * 1e6).round() as i64;
    let s = micro(step).max(1);
    let a = micro(start).rem_euclid(s);
    let (mut x, mut y) = (s, a);
    while y != 0 {
        (x, y) = (y, x % y);
    }
    x as f64 / 1e6
}

/// Mean error per angle modulo 360 for one direction, sorted by angle (0° and 360° merge).
fn curve(rows: &[TableRow], direction: Direction) -> Vec<(f64, f64)> {
    let mut points: Vec<(i64, f64, f64, usize)> = Vec::new();
    for row in rows.iter().filter(|r| r.direction == direction) {
        let a = modulo_deg(row.angle_deg);
        let k = (a * 1e6).round() as i64 % 360_000_000;
        match points.iter_mut().find(|p| p.0 == k) {
            Some(p) => {
                p.2 += row.error_arcsec * row.n as f64;
                p.3 += row.n;
            }
            None => points.push((k, a, row.error_arcsec * row.n as f64, row.n)),
        }
    }
    points.sort_by_key(|p| p.0);
    points
        .into_iter()
        .map(|(_, a, sum, n)| (a, sum / n as f64))
        .collect()
}

fn check_coverage(c: &[(f64, f64)]) -> Result<()> {
    let gap = match c {
        [] | [_] => 360.0,
        _ => c
            .windows(2)
            .map(|w| w[1].0 - w[0].0)
            .fold(360.0 - c[c.len() - 1].0 + c[0].0, f64::max),
    };
    if gap > MAX_GAP_DEG {
        return Err(Error::usage(
            format!("the measured angles leave a gap of {gap:.1}° in the turn"),
            format!("a table over the full turn needs measurements at most {MAX_GAP_DEG}° apart all round"),
        ));
    }
    Ok(())
}

/// Linear interpolation on a periodic (360°) curve sorted by angle.
fn periodic_interp(c: &[(f64, f64)], g: f64) -> f64 {
    let n = c.len();
    // Index of the first point at or after g.
    let i = c.partition_point(|p| p.0 < g - 1e-9);
    let (lo, hi) = if i == 0 || i == n {
        let lo = (c[n - 1].0 - 360.0, c[n - 1].1);
        let hi = (c[0].0 + 360.0, c[0].1);
        if i == 0 {
            (lo, c[0])
        } else {
            (c[n - 1], hi)
        }
    } else {
        (c[i - 1], c[i])
    };
    if (hi.0 - g).abs() < 1e-9 {
        return hi.1;
    }
    let t = (g - lo.0) / (hi.0 - lo.0);
    lo.1 + t * (hi.1 - lo.1)
}

impl CompTable {
    /// The table in the controller writers' model: e = actual - nominal = -err, reference 0 deg.
    pub fn to_controller(&self) -> ControllerTable {
        ControllerTable {
            kind: AxisKind::Rotary,
            axis: self.axis.clone(),
            start: 0.0,
            step: self.step_deg,
            forward: self.forward_arcsec.iter().map(|e| -e).collect(),
            reverse: self.reverse_arcsec.iter().map(|e| -e).collect(),
            bidirectional: self.bidirectional,
            reference: 0.0,
            notes: vec![format!("values: {INTERPOLATION}; {}", self.grid_note)],
        }
    }
}

/// Render the table in `format` as `(path, text)` pairs (Sinumerik and Heidenhain write two
/// files). `opts.axis` names the controller's axis (Sinumerik machine axis, e.g. `C1`;
/// Heidenhain column; Fanuc axis number).
pub fn render(
    table: &CompTable,
    format: TableFormat,
    opts: &TableOptions,
    path: &Path,
) -> Result<Vec<(PathBuf, String)>> {
    crate::controller::render(&table.to_controller(), format, opts, path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn periodic_interpolation_wraps_through_zero() {
        let c = vec![(30.0, 3.0), (150.0, 15.0), (270.0, -9.0)];
        // Between 270 and 30+360 = 390: at 0°, t = 90/120 → −9 + 0.75·12 = 0.
        assert!((periodic_interp(&c, 0.0) - 0.0).abs() < 1e-12);
        assert!((periodic_interp(&c, 90.0) - 9.0).abs() < 1e-12);
        assert!((periodic_interp(&c, 150.0) - 15.0).abs() < 1e-12);
        assert!((periodic_interp(&c, 330.0) - (-3.0)).abs() < 1e-12);
        assert!((periodic_interp(&c, 15.0) - 1.5).abs() < 1e-12);
    }

    fn row(angle_deg: f64, direction: Direction, error_arcsec: f64) -> TableRow {
        TableRow {
            angle_deg,
            direction,
            error_arcsec,
            s_arcsec: None,
            n: 1,
            min_arcsec: error_arcsec,
            max_arcsec: error_arcsec,
        }
    }

    /// The value a controller reads from the table at `g`: linear between its entries.
    fn controller_value(t: &CompTable, values: &[f64], g: f64) -> f64 {
        let i = t.angles_deg.partition_point(|&a| a <= g + 1e-9) - 1;
        if (t.angles_deg[i] - g).abs() < 1e-9 {
            return values[i];
        }
        let f = (g - t.angles_deg[i]) / (t.angles_deg[i + 1] - t.angles_deg[i]);
        values[i] + f * (values[i + 1] - values[i])
    }

    /// A run measured at 15° + 30°·k with errors that are far from linear between the angles
    /// (3″ sin 2α + 2″ cos 3α + 0.7″, reverse 1.5″ higher).
    fn run_15_plus_30k() -> Vec<TableRow> {
        let e =
            |a: f64| 3.0 * (2.0 * a.to_radians()).sin() + 2.0 * (3.0 * a.to_radians()).cos() + 0.7;
        let mut rows = Vec::new();
        for k in 0..12 {
            let a = 15.0 + 30.0 * k as f64;
            rows.push(row(a, Direction::Forward, e(a)));
            rows.push(row(a, Direction::Reverse, e(a) + 1.5));
        }
        rows
    }

    #[test]
    fn a_run_at_15_plus_30k_is_reproduced_at_every_measured_angle() {
        let rows = run_15_plus_30k();
        let t = table_from_rows("C", &rows, None, None).unwrap();
        // The table runs 0 … 360 and its last entry repeats the first.
        assert_eq!(t.angles_deg[0], 0.0);
        assert_eq!(*t.angles_deg.last().unwrap(), 360.0);
        assert_eq!(t.forward_arcsec[0], *t.forward_arcsec.last().unwrap());
        for r in &rows {
            // Every measured angle is an entry of the table …
            assert!(t.angles_deg.iter().any(|&a| (a - r.angle_deg).abs() < 1e-9));
            let values = match r.direction {
                Direction::Forward => &t.forward_arcsec,
                Direction::Reverse => &t.reverse_arcsec,
            };
            // … and the controller's reading there is the measured error within 0.01″.
            let v = controller_value(&t, values, r.angle_deg);
            assert!(
                (v - r.error_arcsec).abs() < 0.01,
                "{}: {v} vs {}",
                r.angle_deg,
                r.error_arcsec
            );
        }
        // Between measured angles the value is the straight line: at 0° the mean of 345° and 15°.
        let e =
            |a: f64| 3.0 * (2.0 * a.to_radians()).sin() + 2.0 * (3.0 * a.to_radians()).cos() + 0.7;
        assert!((t.forward_arcsec[0] - 0.5 * (e(345.0) + e(15.0))).abs() < 1e-9);
    }

    #[test]
    fn a_chosen_grid_is_used_and_the_uneven_default_says_so() {
        let rows = run_15_plus_30k();
        // --step-deg 10 --start-deg 5: entries every 5° from 0 (the grid 5 + 10·k refined).
        let t = table_from_rows("C", &rows, Some(10.0), Some(5.0)).unwrap();
        assert_eq!(t.step_deg, 5.0);
        assert_eq!(t.angles_deg.len(), 73);
        assert!(t.grid_note.contains("as given"));
        // 25° lies a third of the way from 15° to 45°.
        let e15 = rows[0].error_arcsec;
        let e45 = rows[2].error_arcsec;
        assert!((t.forward_arcsec[5] - (e15 + (e45 - e15) / 3.0)).abs() < 1e-9);
        // Uneven angles: the default grid is stated as interpolated.
        let mut uneven = rows.clone();
        uneven.retain(|r| r.angle_deg != 75.0);
        let t = table_from_rows("C", &uneven, None, None).unwrap();
        assert!(
            t.grid_note.contains("not equally spaced"),
            "{}",
            t.grid_note
        );
        let err = table_from_rows("C", &rows, Some(7.0), None).unwrap_err();
        assert_eq!(err.kind(), "input", "{err}");
        assert!(
            err.to_string().contains("step 7° does not divide the turn"),
            "{err}"
        );
        // A start off the measured angles is the user's grid, and the note says so.
        let t = table_from_rows("C", &rows, None, Some(0.0)).unwrap();
        assert!(t.grid_note.contains("as given"), "{}", t.grid_note);
        assert_eq!(t.step_deg, 30.0);
    }
}
