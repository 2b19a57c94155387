//! One measured point, whatever file it came from (CSV row, DMIS feature, cloud vertex): its vector, deviation and domain checks and its error E, with the place a problem is reported at.

use std::path::Path;

use super::{unit_slip_hint, ProbeSpec};
use crate::Setting;
use errmap_core::error::{Error, Location, Result};
use errmap_core::geom::{Axis, Domain};
use errmap_core::setting::words;

/// A point may sit this far outside the domain (rounding in the file) and still count as inside.
const DOMAIN_TOLERANCE_MM: f64 = 1e-9;

/// One row as read, before repeats are merged.
pub(super) struct Row {
    pub(super) id: Option<String>,
    pub(super) line: u64,
    pub(super) measured_mm: [f64; 3],
    pub(super) nominal_mm: [f64; 3],
    /// Error of the row, µm: along the normal axis, or along the row's vector.
    pub(super) e_um: f64,
}

/// A row's numbers as a reader found them, before the checks.
pub(super) struct RawPoint {
    pub(super) id: Option<String>,
    pub(super) line: u64,
    pub(super) measured_mm: [f64; 3],
    pub(super) nominal_mm: [f64; 3],
    /// The nominal surface normal (i, j, k) as written, if the file gives one.
    pub(super) vector: Option<[f64; 3]>,
}

/// Where a row's problems are reported: the row, the measured coordinate along the normal,
/// the vector, and a prefix for the message (a binary file's byte offset).
pub(super) struct Place {
    pub(super) row: Location,
    pub(super) normal: Location,
    pub(super) vector: Location,
    pub(super) prefix: String,
}

impl Place {
    /// Every problem at one line.
    pub(super) fn line(path: &Path, line: u64) -> Place {
        Place {
            row: Location::line(path, line),
            normal: Location::line(path, line),
            vector: Location::line(path, line),
            prefix: String::new(),
        }
    }
}

/// The point vectors (i, j, k) are unit vectors within this (|n| − 1); a CMM writes direction
/// cosines to 4–6 decimals, angles or a zero vector are far off.
pub const VECTOR_NORM_TOLERANCE: f64 = 0.01;

/// Largest angle, degrees, between a point's vector and the map's normal axis (either sense).
pub const MAX_VECTOR_ANGLE_DEG: f64 = 5.0;

/// A file without nominal points needs a finite nominal plane; `what` says what is missing.
pub(super) fn check_plane(path: &Path, line: u64, spec: &ProbeSpec, what: &str) -> Result<f64> {
    match spec.nominal_plane_mm {
        None => Err(Error::input(
            Location::line(path, line),
            format!("no nominal: {what} and no nominal plane was given"),
            format!(
                "give the nominal {} of the surface ({} MM, or `nominal_plane_mm` in the job)",
                spec.normal.name(),
                words(Setting::NominalPlane)
            ),
        )),
        Some(plane) if !plane.is_finite() => Err(Error::usage(
            format!("nominal plane {plane} mm is not a finite number"),
            "give the nominal coordinate of the surface in mm, e.g. 30",
        )),
        Some(plane) => Ok(plane),
    }
}

/// The nominal of a point of a file without nominal points: the measured point with its
/// coordinate along the normal set to the nominal plane.
pub(super) fn plane_nominal(measured_mm: [f64; 3], spec: &ProbeSpec) -> [f64; 3] {
    let mut nominal = measured_mm;
    nominal[spec.normal.index()] = spec.nominal_plane_mm.unwrap_or(0.0);
    nominal
}

/// A point checked: its vector (a unit vector within [`VECTOR_NORM_TOLERANCE`], within
/// [`MAX_VECTOR_ANGLE_DEG`] of the normal axis), its error against the plausibility bound, its
/// nominal against the domain.
pub(super) fn point_row(raw: RawPoint, place: &Place, spec: &ProbeSpec) -> Result<Row> {
    let e_mm = match raw.vector {
        None => check_deviation(place, raw.measured_mm, raw.nominal_mm, spec)?,
        Some(v) => {
            let unit = check_vector(place, v, spec.normal)?;
            check_deviation_along(place, raw.measured_mm, raw.nominal_mm, unit, spec)?
        }
    };
    if let Some(domain) = &spec.domain {
        check_in_domain(place, raw.nominal_mm, domain, spec.normal)?;
    }
    Ok(Row {
        id: raw.id,
        line: raw.line,
        measured_mm: raw.measured_mm,
        nominal_mm: raw.nominal_mm,
        e_um: e_mm * 1000.0,
    })
}

/// The point's vector as a unit vector pointing to the + side of the normal axis; refused when
/// it is not a unit vector or is more than [`MAX_VECTOR_ANGLE_DEG`] off the axis.
fn check_vector(place: &Place, v: [f64; 3], normal: Axis) -> Result<[f64; 3]> {
    let norm = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    let [i, j, k] = v;
    if !(norm.is_finite() && (norm - 1.0).abs() <= VECTOR_NORM_TOLERANCE) {
        return Err(Error::input(
            place.vector.clone(),
            format!(
                "{}the vector ({i}, {j}, {k}) has length {norm}, not 1 (within {VECTOR_NORM_TOLERANCE})",
                place.prefix
            ),
            "i, j, k are the direction cosines of the nominal surface normal (e.g. 0,0,1 on a floor); export cosines, not angles, and no zero vector",
        ));
    }
    let unit = [i / norm, j / norm, k / norm];
    let along = unit[normal.index()];
    let angle_deg = along.abs().clamp(0.0, 1.0).acos().to_degrees();
    if angle_deg > MAX_VECTOR_ANGLE_DEG {
        let nearest = [Axis::X, Axis::Y, Axis::Z]
            .into_iter()
            .max_by(|a, b| unit[a.index()].abs().total_cmp(&unit[b.index()].abs()))
            .unwrap_or(normal);
        return Err(Error::input(
            place.vector.clone(),
            format!(
                "{}the vector ({i}, {j}, {k}) is {angle_deg:.1}° from the normal axis {} (at most {MAX_VECTOR_ANGLE_DEG}°)",
                place.prefix,
                normal.name()
            ),
            format!(
                "the map's normal axis must be the surface normal: the vector is nearest to {} ({} {}), or the point is not on this surface",
                nearest.name(),
                words(Setting::Normal),
                nearest.name()
            ),
        ));
    }
    Ok(if along < 0.0 { unit.map(|c| -c) } else { unit })
}

/// Refuses a deviation along the normal that µm cannot represent or that is beyond the
/// spec's plausibility bound (naming the likely unit slip); the deviation in mm.
fn check_deviation(
    place: &Place,
    measured_mm: [f64; 3],
    nominal_mm: [f64; 3],
    spec: &ProbeSpec,
) -> Result<f64> {
    let n = spec.normal.index();
    // Two finite coordinates near ±f64::MAX can still differ by more than f64 holds.
    if !((measured_mm[n] - nominal_mm[n]) * 1000.0).is_finite() {
        return Err(Error::input(
            place.normal.clone(),
            format!(
                "{}the deviation {} − {} mm along {} is too large to represent in µm",
                place.prefix,
                measured_mm[n],
                nominal_mm[n],
                spec.normal.name()
            ),
            "check the units: probe coordinates are in mm",
        ));
    }
    let deviation_mm = measured_mm[n] - nominal_mm[n];
    if deviation_mm.abs() > spec.max_deviation_mm {
        return Err(Error::input(
            place.normal.clone(),
            format!(
                "{}the deviation {deviation_mm} mm along {} (measured {} − nominal {}) is beyond the plausibility bound of {} mm",
                place.prefix,
                spec.normal.name(),
                measured_mm[n],
                nominal_mm[n],
                spec.max_deviation_mm
            ),
            unit_slip_hint(
                measured_mm[n],
                nominal_mm[n],
                spec.max_deviation_mm,
                &format!(
                    "{}, or max_deviation_mm in the job",
                    words(Setting::MaxDeviation)
                ),
            ),
        ));
    }
    Ok(deviation_mm)
}

/// [`check_deviation`] for the deviation along a point's unit vector: (measured − nominal) · n̂.
fn check_deviation_along(
    place: &Place,
    measured_mm: [f64; 3],
    nominal_mm: [f64; 3],
    unit: [f64; 3],
    spec: &ProbeSpec,
) -> Result<f64> {
    let d: Vec<f64> = (0..3).map(|k| measured_mm[k] - nominal_mm[k]).collect();
    let deviation_mm = d[0] * unit[0] + d[1] * unit[1] + d[2] * unit[2];
    if !(deviation_mm * 1000.0).is_finite() {
        return Err(Error::input(
            place.normal.clone(),
            format!(
                "{}the deviation along the point's vector is too large to represent in µm",
                place.prefix
            ),
            "check the units: probe coordinates are in mm",
        ));
    }
    if deviation_mm.abs() > spec.max_deviation_mm {
        let n = spec.normal.index();
        return Err(Error::input(
            place.normal.clone(),
            format!(
                "{}the deviation {deviation_mm} mm along the point's vector (measured − nominal = ({}, {}, {}) mm) is beyond the plausibility bound of {} mm",
                place.prefix, d[0], d[1], d[2], spec.max_deviation_mm
            ),
            unit_slip_hint(
                measured_mm[n],
                nominal_mm[n],
                spec.max_deviation_mm,
                &format!(
                    "{}, or max_deviation_mm in the job",
                    words(Setting::MaxDeviation)
                ),
            ),
        ));
    }
    Ok(deviation_mm)
}

/// Refuses a point whose nominal lies outside `domain` (grown by [`DOMAIN_TOLERANCE_MM`]).
fn check_in_domain(
    place: &Place,
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
    Err(Error::input(
        place.row.clone(),
        format!(
            "{}point ({un} {u}, {vn} {v}) mm is outside the domain {un} {}..{}, {vn} {}..{} mm",
            place.prefix, domain.u_min_mm, domain.u_max_mm, domain.v_min_mm, domain.v_max_mm
        ),
        "widen the domain or remove the point (is it from another part or set-up?)",
    ))
}
