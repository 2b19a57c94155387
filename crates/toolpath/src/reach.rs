//! Where the map may be applied, for every toolpath reader: E inside the measured domain (or anywhere the map reaches, with `--extrapolate`), and whether a path through partly known points can reach the zone and that domain.

use super::point::{dist, lerp};
use super::{CompensationReport, CompensationSettings};
use errmap_core::geom::ErrorField;
use std::cell::Cell;

/// Whether the map compensates at plane point (u, v), mm: it reaches the point, and the point
/// is in the measured domain (within the job's margin) or `--extrapolate` is given.
pub(crate) fn compensable_mm(
    field: &dyn ErrorField,
    settings: &CompensationSettings,
    u_mm: f64,
    v_mm: f64,
) -> bool {
    field.error_mm(u_mm, v_mm).is_some()
        && (settings.extrapolate
            || field.measured(u_mm, v_mm, settings.domain_margin_mm) == Some(true))
}

/// Which points a move met that stay nominal, and why: set while the move's points are looked
/// up, then [`KeptNominal::count`]ed into the report once per move.
#[derive(Debug, Default)]
pub(crate) struct KeptNominal {
    /// A point in the zone outside the measured domain (the probes' hull and margin).
    outside: Cell<bool>,
    /// A point in the domain where u(E) exceeds `--max-uncertainty-um`.
    uncertain: Cell<bool>,
}

impl KeptNominal {
    /// Count the move just looked up into `report` (`moves_outside_domain`, `moves_uncertain`)
    /// and clear the marks for the next move.
    pub(crate) fn count(&self, report: &mut CompensationReport) {
        report.moves_outside_domain += u64::from(self.outside.replace(false));
        report.moves_uncertain += u64::from(self.uncertain.replace(false));
    }
}

/// E (mm) at plane point (u, v) where the map may be applied, as [`compensable_mm`]; a point the
/// map reaches only by extrapolating gives `None` and marks `kept` outside, and a point in the
/// domain whose E is withheld for its uncertainty ([`ErrorField::withheld`]) gives `None` and
/// marks `kept` uncertain, so the report can count the moves left nominal for each reason.
/// Outside the domain the domain is the reason, whatever u(E) is.
pub(crate) fn domain_error_mm(
    field: &dyn ErrorField,
    settings: &CompensationSettings,
    u_mm: f64,
    v_mm: f64,
    kept: &KeptNominal,
) -> Option<f64> {
    let outside = || {
        !settings.extrapolate && field.measured(u_mm, v_mm, settings.domain_margin_mm) != Some(true)
    };
    let Some(e_mm) = field.error_mm(u_mm, v_mm) else {
        if field.withheld(u_mm, v_mm) {
            if outside() {
                kept.outside.set(true);
            } else {
                kept.uncertain.set(true);
            }
        }
        return None;
    };
    if outside() {
        kept.outside.set(true);
        return None;
    }
    e_mm.is_finite().then_some(e_mm)
}

/// A point with each coordinate known or not (program units).
pub(crate) type MaybePoint = [Option<f64>; 3];

/// Most points [`may_touch`] samples along one path before it answers "may touch".
const MAX_SAMPLES: usize = 2_000_000;

/// Could a path through `points` touch the zone (limits along axis `normal`) and the map's
/// compensable area (`compensable(u, v)` on the plane axes `plane_uv`)? Unknown coordinates may
/// be anywhere, so they answer yes; known ones are checked every `step` along the polyline.
pub(crate) fn may_touch(
    points: &[MaybePoint],
    normal: usize,
    plane_uv: (usize, usize),
    zone: Option<(f64, f64)>,
    step: f64,
    compensable: impl Fn(f64, f64) -> bool,
) -> bool {
    let (mut lo, mut hi, mut normal_known) = (f64::INFINITY, f64::NEG_INFINITY, true);
    for p in points {
        match p[normal] {
            Some(n) => {
                lo = lo.min(n);
                hi = hi.max(n);
            }
            None => normal_known = false,
        }
    }
    if let (Some((zlo, zhi)), true) = (zone, normal_known) {
        if hi < zlo || lo > zhi {
            return false;
        }
    }
    // The domain only needs the two plane coordinates.
    let (ui, vi) = plane_uv;
    let known: Option<Vec<[f64; 3]>> = points.iter().map(|p| Some([p[ui]?, p[vi]?, 0.0])).collect();
    let Some(known) = known.filter(|k| !k.is_empty()) else {
        return true;
    };
    if compensable(known[0][0], known[0][1]) {
        return true;
    }
    // Sampled at most every `step`, and at most MAX_SAMPLES points over the whole path: a path
    // longer than that (a huge arc of many chords, a typo's kilometre move) is taken as one
    // that may touch, which refuses rather than spends minutes proving otherwise.
    let mut left = MAX_SAMPLES;
    for w in known.windows(2) {
        let len = dist(&w[0], &w[1]);
        let k = (len / step).ceil().clamp(1.0, 1e6) as usize;
        if k > left {
            return true;
        }
        left -= k;
        for i in 1..=k {
            let p = lerp(&w[0], &w[1], i as f64 / k as f64);
            if compensable(p[0], p[1]) {
                return true;
            }
        }
    }
    false
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Zone z ∈ [-1, 0]; the compensable area is the unit square at the origin.
    fn touch(points: &[MaybePoint]) -> bool {
        let square = |u: f64, v: f64| (0.0..=1.0).contains(&u) && (0.0..=1.0).contains(&v);
        may_touch(points, 2, (0, 1), Some((-1.0, 0.0)), 0.1, square)
    }

    #[test]
    fn a_path_reaches_only_where_the_zone_and_the_area_meet() {
        // Above the zone: no, wherever it is in the plane.
        assert!(!touch(&[[Some(0.5), Some(0.5), Some(5.0)]]));
        // In the zone and over the square.
        assert!(touch(&[[Some(0.5), Some(0.5), Some(-0.5)]]));
        // In the zone, from (-1, 0.5) to (-0.5, 0.5): never over the square.
        assert!(!touch(&[
            [Some(-1.0), Some(0.5), Some(-0.5)],
            [Some(-0.5), Some(0.5), Some(-0.5)]
        ]));
        // Crossing the square between two outside ends: found by the steps along the way.
        assert!(touch(&[
            [Some(-1.0), Some(0.5), Some(-0.5)],
            [Some(2.0), Some(0.5), Some(-0.5)]
        ]));
        // An unknown plane coordinate may be anywhere; an unknown normal one may be in the zone.
        assert!(touch(&[[None, Some(5.0), Some(-0.5)]]));
        assert!(touch(&[[Some(0.5), Some(0.5), None]]));
    }
}
