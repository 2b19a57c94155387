//! Seed 000: thermal positioning error by difference, Et_i(t) = E_i(t) − Es_i, with the
//! least-squares thermal error line of every measurement time, per direction.
//!
//! E_i(t) is the mean of the repeats at target i of the measurement at time t; Es_i the same in
//! the first (cold) measurement of the campaign. The line of each time is
//! `Et(x) = offset_um + slope_um_per_m·x_mm/1000` (least squares over the targets).

use super::campaign::{direction_name, Campaign, Direction, DIRECTIONS};
use errmap_core::error::{Error, Location, Result};
use serde::Serialize;
use std::collections::BTreeMap;

/// Et at one target and time.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DifferenceRow {
    pub time_s: f64,
    pub direction: Direction,
    pub target_mm: f64,
    /// Mean error of the measurement at this time (µm).
    pub e_um: f64,
    /// Mean error of the cold measurement (µm).
    pub es_um: f64,
    /// Thermal error Et = E − Es (µm).
    pub et_um: f64,
}

/// The thermal error line of one time and direction.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ThermalLine {
    pub time_s: f64,
    pub direction: Direction,
    pub slope_um_per_m: f64,
    /// Et of the line at x = 0 mm (µm).
    pub offset_um: f64,
    /// RMS of Et about the line (µm).
    pub rms_um: f64,
    /// Mean temperatures over the measurement (°C).
    pub temperatures_c: BTreeMap<String, f64>,
}

/// The difference result of a campaign.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Difference {
    pub campaign: String,
    pub cold_time_s: f64,
    pub rows: Vec<DifferenceRow>,
    pub lines: Vec<ThermalLine>,
}

/// Mean deviation per target of one direction of a measurement: (target_mm, mean_um, line).
fn means(points: &[super::campaign::LaserPoint], d: Direction) -> Vec<(f64, f64, u64)> {
    let mut by_target: BTreeMap<i64, (f64, f64, usize, u64)> = BTreeMap::new();
    for p in points.iter().filter(|p| p.direction == d) {
        let e = by_target
            .entry((p.target_mm * 1e6).round() as i64)
            .or_insert((p.target_mm, 0.0, 0, p.line));
        e.1 += p.deviation_um;
        e.2 += 1;
    }
    by_target
        .into_values()
        .map(|(x, sum, n, line)| (x, sum / n as f64, line))
        .collect()
}

/// Least-squares line y = a + b·x; returns (a, b, rms).
pub fn fit_line(xs: &[f64], ys: &[f64]) -> Option<(f64, f64, f64)> {
    errmap_core::numeric::lsq::fit_line(xs, ys).map(|l| (l.intercept, l.slope, l.rms))
}

/// Et = E − Es for every time, target and direction of a campaign, and the line of each time.
pub fn difference(campaign: &Campaign) -> Result<Difference> {
    let runs_path = &campaign.runs_path;
    let cold = campaign.measurements.first().ok_or_else(|| {
        Error::usage(
            format!("campaign '{}' has no measurements", campaign.name),
            "add laser runs",
        )
    })?;
    let mut rows = Vec::new();
    let mut lines = Vec::new();
    for d in DIRECTIONS {
        let es = means(&cold.points, d);
        if es.len() < 2 {
            return Err(Error::usage(
                format!(
                    "the cold measurement of '{}' has {} {} target(s)",
                    campaign.name,
                    es.len(),
                    direction_name(d)
                ),
                "measure at least two targets in each direction",
            ));
        }
        for m in &campaign.measurements {
            let e = means(&m.points, d);
            let (mut xs, mut ets) = (Vec::new(), Vec::new());
            for &(x, e_um, line) in &e {
                let Some(&(_, es_um, _)) = es.iter().find(|c| (c.0 - x).abs() < 1e-6) else {
                    return Err(Error::input(
                        Location::cell(runs_path, line, "target_mm"),
                        format!(
                            "target {x} mm at {} s is not in the cold measurement ({} s)",
                            m.time_s, cold.time_s
                        ),
                        "measure the same targets at every time (seed 000: same conditions)",
                    ));
                };
                rows.push(DifferenceRow {
                    time_s: m.time_s,
                    direction: d,
                    target_mm: x,
                    e_um,
                    es_um,
                    et_um: e_um - es_um,
                });
                xs.push(x);
                ets.push(e_um - es_um);
            }
            if let Some((a, b_um_per_mm, rms)) = fit_line(&xs, &ets) {
                lines.push(ThermalLine {
                    time_s: m.time_s,
                    direction: d,
                    slope_um_per_m: b_um_per_mm * 1000.0,
                    offset_um: a,
                    rms_um: rms,
                    temperatures_c: m.temperatures_c.clone(),
                });
            }
        }
    }
    Ok(Difference {
        campaign: campaign.name.clone(),
        cold_time_s: cold.time_s,
        rows,
        lines,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn line_fit_of_exact_points() {
        let (a, b, rms) = fit_line(&[0.0, 100.0, 200.0], &[1.0, 3.0, 5.0]).unwrap();
        assert!((a - 1.0).abs() < 1e-12 && (b - 0.02).abs() < 1e-12 && rms < 1e-12);
        assert!(fit_line(&[1.0, 1.0], &[0.0, 1.0]).is_none());
    }
}
