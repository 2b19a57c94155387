//! ISO 230-4 figures of a run: least-squares centre (set-up offset), circular deviation G by the exact minimum zone, radial deviation F, circular hysteresis H.

use super::circle::fit_circle;
use super::input::{CircularRun, Form, Rotation};
use super::zone::min_zone;
use errmap_core::error::{Error, Result};
use serde::Serialize;

/// A value per direction and for both together; `None` where a direction is missing.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PerDirection {
    /// The value of the clockwise readings alone; `None` when the run has none.
    pub cw: Option<f64>,
    /// The value of the counter-clockwise readings alone; `None` when the run has none.
    pub ccw: Option<f64>,
    /// The value of both directions together; `None` unless the run has both.
    pub bidirectional: Option<f64>,
}

/// The minimum zone of one set of readings, with its centre.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ZoneReport {
    /// Zone centre minus the least-squares centre of the run, µm.
    pub centre_from_lsc_um: [f64; 2],
    /// Radius of the inner circle minus the nominal radius, µm.
    pub inner_um: f64,
    /// Radius of the outer circle minus the nominal radius, µm.
    pub outer_um: f64,
    /// Lines of the readings that touch the outer circle.
    pub outer_lines: Vec<u64>,
    /// Lines of the readings that touch the inner circle.
    pub inner_lines: Vec<u64>,
}

/// The ISO 230-4 figures.
#[derive(Debug, Clone, Serialize)]
pub struct Figures {
    /// Programmed (nominal) radius R, mm.
    pub radius_mm: f64,
    /// The CSV form the run was read from.
    pub form: Form,
    /// Readings evaluated per direction, and the rows left out.
    pub readings: ReadingCounts,
    /// Circular deviation G (minimum zone).
    pub g_um: PerDirection,
    /// Circular hysteresis H: the largest radial difference between the ccw and cw paths
    /// about their common least-squares centre; `None` with one direction.
    pub h_um: Option<f64>,
    /// Largest radial deviation F: distance from the least-squares centre minus the nominal
    /// radius, µm.
    pub f_max_um: PerDirection,
    /// Smallest radial deviation F about the least-squares centre, µm (negative inside the nominal
    /// circle).
    pub f_min_um: PerDirection,
    /// Least-squares centre minus nominal centre (first, second axis), removed as set-up error.
    pub centre_offset_um: [f64; 2],
    /// Least-squares radius minus nominal radius.
    pub mean_radius_deviation_um: f64,
    /// The minimum zone of all readings evaluated together (both directions when present).
    pub zone: ZoneReport,
}

/// Readings evaluated per direction and rows left out, as the report counts them.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct ReadingCounts {
    /// Counter-clockwise readings evaluated.
    pub ccw: usize,
    /// Clockwise readings evaluated.
    pub cw: usize,
    /// Rows not evaluated: marked `overshoot`, or past one turn.
    pub overshoot: usize,
    /// Of `overshoot`, the readings past one turn of their direction (an instrument's overrun).
    pub overrun: usize,
}

impl Figures {
    /// The G the diagnosis shares refer to: bidirectional when both directions exist.
    pub fn reference_g_um(&self) -> f64 {
        self.g_um
            .bidirectional
            .or(self.g_um.ccw)
            .or(self.g_um.cw)
            .unwrap_or(0.0)
    }
}

/// Readings about the run's least-squares centre: the input of the diagnosis and the chart.
#[derive(Debug, Clone)]
pub struct Centred {
    /// The direction of each reading.
    pub direction: Vec<Rotation>,
    /// Angle about the least-squares centre, [0, 2π).
    pub angle_rad: Vec<f64>,
    /// Angle about the nominal centre, [0, 2π): the machine's (commanded) angle, at which
    /// the axes reverse whatever the set-up offset; the diagnosis model uses it.
    pub nominal_angle_rad: Vec<f64>,
    /// Distance from the least-squares centre minus nominal radius, µm.
    pub dev_um: Vec<f64>,
    /// 1-based line of each reading in the run file.
    pub line: Vec<u64>,
}

impl Centred {
    /// Number of readings.
    pub fn len(&self) -> usize {
        self.dev_um.len()
    }
    /// Whether there are no readings.
    pub fn is_empty(&self) -> bool {
        self.dev_um.is_empty()
    }
    /// Indices of one direction's readings.
    pub fn of(&self, d: Rotation) -> Vec<usize> {
        (0..self.len())
            .filter(|&i| self.direction[i] == d)
            .collect()
    }
}

/// Radial deviation (µm) and angle of each point about `centre_mm`.
fn about(points: &[[f64; 2]], centre_mm: [f64; 2], radius_mm: f64) -> (Vec<f64>, Vec<f64>) {
    points
        .iter()
        .map(|p| {
            let (dx, dy) = (p[0] - centre_mm[0], p[1] - centre_mm[1]);
            (
                (dx.hypot(dy) - radius_mm) * 1e3,
                dy.atan2(dx).rem_euclid(std::f64::consts::TAU),
            )
        })
        .unzip()
}

/// The exact minimum zone of points: the limaçon LP, re-linearised about each new centre
/// until the centre moves less than 1e-7 µm. Returns (centre, deviations about it).
fn exact_zone(
    points: &[[f64; 2]],
    start_mm: [f64; 2],
    radius_mm: f64,
) -> ([f64; 2], Vec<f64>, super::Zone) {
    let mut c = start_mm;
    let (mut dev, mut ang) = about(points, c, radius_mm);
    let mut zone = min_zone(&dev, &ang);
    for _ in 0..20 {
        let shift = zone.shift_um;
        c = [c[0] + shift[0] * 1e-3, c[1] + shift[1] * 1e-3];
        (dev, ang) = about(points, c, radius_mm);
        zone = min_zone(&dev, &ang);
        if shift[0].hypot(shift[1]) < 1e-7 {
            break;
        }
    }
    (c, dev, zone)
}

/// G of a set of points (exact radii about the converged zone centre).
fn g_of(points: &[[f64; 2]], start_mm: [f64; 2], radius_mm: f64) -> f64 {
    let (_, dev, _) = exact_zone(points, start_mm, radius_mm);
    let max = dev.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    let min = dev.iter().cloned().fold(f64::INFINITY, f64::min);
    max - min
}

/// The least-squares circle through points (nominal radius `radius_mm`).
fn lsq_circle(points: &[[f64; 2]], radius_mm: f64) -> Result<super::CircleFit> {
    fit_circle(points, radius_mm).ok_or_else(|| {
        Error::numeric(
            "no least-squares circle through the readings",
            "readings must lie around a full circle",
        )
    })
}

/// F max and min about the least-squares centre of the points.
fn f_of(points: &[[f64; 2]], radius_mm: f64) -> Result<(f64, f64, [f64; 2])> {
    let fit = lsq_circle(points, radius_mm)?;
    let (dev, _) = about(points, fit.centre_mm, radius_mm);
    let max = dev.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    let min = dev.iter().cloned().fold(f64::INFINITY, f64::min);
    Ok((max, min, fit.centre_mm))
}

/// Evaluate the figures of a run and the readings about its least-squares centre.
pub fn evaluate(run: &CircularRun) -> Result<(Figures, Centred)> {
    let r_mm = run.radius_mm;
    let all: Vec<[f64; 2]> = run.readings.iter().map(|r| r.point_mm).collect();
    let fit = lsq_circle(&all, r_mm)?;
    let [mut g, mut fmax, mut fmin] = per_direction(run)?;
    let (dev, angle) = about(&all, fit.centre_mm, r_mm);
    let zone = zone_report(run, &all, fit.centre_mm);
    let both = run.directions().len() == 2;
    if both {
        g.bidirectional = Some(zone.outer_um - zone.inner_um);
        fmax.bidirectional = dev.iter().cloned().reduce(f64::max);
        fmin.bidirectional = dev.iter().cloned().reduce(f64::min);
    }
    let centred = Centred {
        direction: run.readings.iter().map(|r| r.direction).collect(),
        angle_rad: angle,
        nominal_angle_rad: run.readings.iter().map(|r| r.angle_rad).collect(),
        dev_um: dev,
        line: run.readings.iter().map(|r| r.line).collect(),
    };
    let h_um = if both {
        Some(hysteresis_um(&centred))
    } else {
        None
    };
    let figures = Figures {
        radius_mm: r_mm,
        form: run.form,
        readings: ReadingCounts {
            ccw: run.direction(Rotation::Ccw).len(),
            cw: run.direction(Rotation::Cw).len(),
            overshoot: run.overshoot_rows,
            overrun: run.overrun_rows,
        },
        g_um: g,
        h_um,
        f_max_um: fmax,
        f_min_um: fmin,
        centre_offset_um: [fit.centre_mm[0] * 1e3, fit.centre_mm[1] * 1e3],
        mean_radius_deviation_um: (fit.radius_mm - r_mm) * 1e3,
        zone,
    };
    Ok((figures, centred))
}

/// G, F max and F min of each direction on its own (the `bidirectional` fields left `None`).
fn per_direction(run: &CircularRun) -> Result<[PerDirection; 3]> {
    let none = PerDirection {
        cw: None,
        ccw: None,
        bidirectional: None,
    };
    let (mut g, mut fmax, mut fmin) = (none, none, none);
    for d in &run.directions() {
        let pts: Vec<[f64; 2]> = run.direction(*d).iter().map(|r| r.point_mm).collect();
        let (hi, lo, centre) = f_of(&pts, run.radius_mm)?;
        let gd = g_of(&pts, centre, run.radius_mm);
        match d {
            Rotation::Ccw => (g.ccw, fmax.ccw, fmin.ccw) = (Some(gd), Some(hi), Some(lo)),
            Rotation::Cw => (g.cw, fmax.cw, fmin.cw) = (Some(gd), Some(hi), Some(lo)),
        }
    }
    Ok([g, fmax, fmin])
}

/// The minimum zone of all readings (`all`), started from the least-squares centre `lsc_mm`.
fn zone_report(run: &CircularRun, all: &[[f64; 2]], lsc_mm: [f64; 2]) -> ZoneReport {
    let (zc, zdev, zone) = exact_zone(all, lsc_mm, run.radius_mm);
    let outer = zdev.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    let inner = zdev.iter().cloned().fold(f64::INFINITY, f64::min);
    let lines = |outer_side: bool| {
        zone.contacts
            .iter()
            .filter(|c| c.1 == outer_side)
            .map(|c| run.readings[c.0].line)
            .collect()
    };
    ZoneReport {
        centre_from_lsc_um: [(zc[0] - lsc_mm[0]) * 1e3, (zc[1] - lsc_mm[1]) * 1e3],
        inner_um: inner,
        outer_um: outer,
        outer_lines: lines(true),
        inner_lines: lines(false),
    }
}

/// Linear interpolation of a periodic curve sorted by angle (angles in [0, 2π)).
pub fn interpolate_periodic(sorted: &[(f64, f64)], angle_rad: f64) -> f64 {
    let n = sorted.len();
    let tau = std::f64::consts::TAU;
    let k = sorted.partition_point(|p| p.0 <= angle_rad);
    let (a, b) = if k == 0 {
        ((sorted[n - 1].0 - tau, sorted[n - 1].1), sorted[0])
    } else if k == n {
        (sorted[n - 1], (sorted[0].0 + tau, sorted[0].1))
    } else {
        (sorted[k - 1], sorted[k])
    };
    if b.0 <= a.0 {
        return a.1;
    }
    a.1 + (b.1 - a.1) * (angle_rad - a.0) / (b.0 - a.0)
}

/// H: the largest |ccw − cw| radial difference, each path interpolated at the other's angles.
fn hysteresis_um(c: &Centred) -> f64 {
    let curve = |d: Rotation| {
        let mut v: Vec<(f64, f64)> = c
            .of(d)
            .iter()
            .map(|&i| (c.angle_rad[i], c.dev_um[i]))
            .collect();
        v.sort_by(|a, b| a.0.total_cmp(&b.0));
        v
    };
    let (ccw, cw) = (curve(Rotation::Ccw), curve(Rotation::Cw));
    let mut h = 0.0_f64;
    for &(a, v) in &ccw {
        h = h.max((v - interpolate_periodic(&cw, a)).abs());
    }
    for &(a, v) in &cw {
        h = h.max((v - interpolate_periodic(&ccw, a)).abs());
    }
    h
}
