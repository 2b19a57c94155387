//! Compensation tables over the full turn of a modulo rotary axis: errmap CSV, LinuxCNC COMP_FILE and Sinumerik LEC.

use super::analysis::{modulo_deg, Analysis};
use super::input::Direction;
use crate::error::{Error, Result};
use std::fmt::Write;

/// Output format of `rotary table`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum TableFormat {
    /// `angle_deg,error_forward_arcsec,error_reverse_arcsec` (err = α − β).
    Csv,
    /// LinuxCNC `[JOINT_n]COMP_FILE` with `COMP_FILE_TYPE = 0`: nominal, actual forward, actual reverse (degrees).
    Linuxcnc,
    /// Sinumerik 840D measuring-system error compensation (`%_N_AX_EEC_INI`, `$AA_ENC_COMP`).
    Sinumerik,
}

/// LinuxCNC reads at most 256 triplets per joint (ini-config, `COMP_FILE`).
pub const LINUXCNC_MAX_ENTRIES: usize = 256;
/// Most entries per turn a table may have (0.01° steps).
pub const MAX_ENTRIES: usize = 36_000;
/// Largest gap between measured angles the table will interpolate across.
pub const MAX_GAP_DEG: f64 = 90.0;

/// Errors on a uniform grid over the whole turn, 0° … 360° inclusive; the last entry
/// repeats the first, so a modulo axis sees no jump at 360° → 0°.
#[derive(Debug, Clone, PartialEq)]
pub struct CompTable {
    pub axis: String,
    pub step_deg: f64,
    pub angles_deg: Vec<f64>,
    /// err = α − β with the axis approaching in the + direction.
    pub forward_arcsec: Vec<f64>,
    /// … in the − direction (equal to forward when only + was measured).
    pub reverse_arcsec: Vec<f64>,
    /// Whether the reverse direction was measured.
    pub bidirectional: bool,
}

/// Build the table from an analysis. `step_deg` must divide 360; by default it is the
/// smallest spacing of the measured angles, rounded down to a divisor of 360.
pub fn build_table(analysis: &Analysis, step_deg: Option<f64>) -> Result<CompTable> {
    let forward = curve(analysis, Direction::Forward);
    let reverse = curve(analysis, Direction::Reverse);
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
    let min_gap = forward
        .windows(2)
        .chain(reverse.windows(2))
        .map(|w| w[1].0 - w[0].0)
        .fold(f64::INFINITY, f64::min);
    let step = match step_deg {
        Some(s) => {
            let n = 360.0 / s;
            if !(s.is_finite() && s > 0.0) || n.round() < 1.0 || (n - n.round()).abs() > 1e-9 {
                return Err(Error::usage(
                    format!("step {s}° does not divide the turn"),
                    "choose a step that divides 360, e.g. 1, 5, 7.5, 10, 15, 30",
                ));
            }
            s
        }
        None => 360.0 / (360.0 / min_gap - 1e-9).ceil(),
    };
    let n = (360.0 / step).round() as usize;
    if n > MAX_ENTRIES {
        return Err(Error::usage(
            format!("a {step}° step makes {n} entries per turn (at most {MAX_ENTRIES})"),
            "give a coarser --step-deg, e.g. 1 or 5",
        ));
    }
    let angles_deg: Vec<f64> = (0..=n).map(|i| i as f64 * step).collect();
    let sample = |c: &[(f64, f64)]| -> Vec<f64> {
        let mut v: Vec<f64> = angles_deg[..n]
            .iter()
            .map(|&g| periodic_interp(c, g))
            .collect();
        v.push(v[0]);
        v
    };
    Ok(CompTable {
        axis: analysis.axis.to_string(),
        step_deg: step,
        forward_arcsec: sample(&forward),
        reverse_arcsec: sample(&reverse),
        angles_deg,
        bidirectional,
    })
}

/// Mean error per angle modulo 360 for one direction, sorted by angle (0° and 360° merge).
fn curve(analysis: &Analysis, direction: Direction) -> Vec<(f64, f64)> {
    let mut points: Vec<(i64, f64, f64, usize)> = Vec::new();
    for row in analysis.table.iter().filter(|r| r.direction == direction) {
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

fn deg(arcsec: f64) -> f64 {
    arcsec / 3600.0
}

/// Fixed-point text with `digits` decimals and no "-0.000".
pub fn fixed(v: f64, digits: usize) -> String {
    let text = format!("{v:.digits$}");
    if text
        .trim_start_matches('-')
        .chars()
        .all(|c| c == '0' || c == '.')
    {
        text.trim_start_matches('-').to_string()
    } else {
        text
    }
}

/// Render the table in `format`. `machine_axis` names the Sinumerik machine axis (e.g. `C1`).
pub fn render(table: &CompTable, format: TableFormat, machine_axis: &str) -> Result<String> {
    let mut s = String::new();
    match format {
        TableFormat::Csv => {
            let _ = writeln!(
                s,
                "# errmap rotary table, axis {}: err = alpha - beta (commanded - measured), arcsec; add err to the command to correct",
                table.axis
            );
            s.push_str("angle_deg,error_forward_arcsec,error_reverse_arcsec\n");
            for i in 0..table.angles_deg.len() {
                let _ = writeln!(
                    s,
                    "{},{},{}",
                    table.angles_deg[i],
                    fixed(table.forward_arcsec[i], 3),
                    fixed(table.reverse_arcsec[i], 3)
                );
            }
        }
        TableFormat::Linuxcnc => {
            if table.angles_deg.len() > LINUXCNC_MAX_ENTRIES {
                return Err(Error::usage(
                    format!(
                        "{} entries, LinuxCNC reads at most {LINUXCNC_MAX_ENTRIES} per joint",
                        table.angles_deg.len()
                    ),
                    "use a coarser --step-deg (e.g. 5)",
                ));
            }
            // COMP_FILE_TYPE = 0: nominal, actual position moving +, actual moving − (degrees).
            // actual β = α − err. No comment lines: the loader expects numbers only.
            for i in 0..table.angles_deg.len() {
                let a = table.angles_deg[i];
                let _ = writeln!(
                    s,
                    "{} {} {}",
                    fixed(a, 6),
                    fixed(a - deg(table.forward_arcsec[i]), 7),
                    fixed(a - deg(table.reverse_arcsec[i]), 7)
                );
            }
        }
        TableFormat::Sinumerik => {
            let ax = machine_axis;
            if ax.is_empty() || !ax.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
                return Err(Error::usage(
                    format!("'{ax}' is not a machine axis name"),
                    "give the machine axis name as configured, e.g. C1 or AX4",
                ));
            }
            s.push_str("%_N_AX_EEC_INI\nCHANDATA(1)\n");
            let _ = writeln!(
                s,
                "; errmap rotary table, axis {}: value = -(err) = beta - alpha in degrees (a positive value moves the axis negative)",
                table.axis
            );
            if table.bidirectional {
                // Over one turn: the 360° entry repeats 0° and is left out.
                let turn = table.angles_deg.len().saturating_sub(1).max(1);
                let reversal: f64 = table
                    .forward_arcsec
                    .iter()
                    .zip(&table.reverse_arcsec)
                    .take(turn)
                    .map(|(f, r)| r - f)
                    .sum::<f64>()
                    / turn as f64;
                let _ = writeln!(
                    s,
                    "; LEC acts in both directions: values are the mean of + and -; mean reversal (err- minus err+) {reversal:.2} arcsec belongs in the backlash compensation"
                );
            }
            for i in 0..table.angles_deg.len() {
                let mean = 0.5 * (table.forward_arcsec[i] + table.reverse_arcsec[i]);
                let _ = writeln!(s, "$AA_ENC_COMP[0,{i},{ax}]={}", fixed(-deg(mean), 7));
            }
            let _ = writeln!(s, "$AA_ENC_COMP_STEP[0,{ax}]={}", table.step_deg);
            let _ = writeln!(s, "$AA_ENC_COMP_MIN[0,{ax}]=0.0");
            let _ = writeln!(s, "$AA_ENC_COMP_MAX[0,{ax}]=360.0");
            let _ = writeln!(s, "$AA_ENC_COMP_IS_MODULO[0,{ax}]=1");
            s.push_str("M17\n");
        }
    }
    Ok(s)
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

    #[test]
    fn fixed_point_has_no_negative_zero() {
        assert_eq!(fixed(-0.0000001, 3), "0.000");
        assert_eq!(fixed(-0.0004, 3), "0.000");
        assert_eq!(fixed(-0.0006, 3), "-0.001");
        assert_eq!(fixed(12.5, 1), "12.5");
    }
}
