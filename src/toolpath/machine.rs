//! The machine state every program reader drives (G-code dialects and Klartext): where the tool is, in which units and work coordinates, where the compensation zone lies and how much the map moves a point, so each of these rules is written once.
//!
//! A reader keeps its own syntax and modes (plane, motion, cycles, frames it does not follow)
//! and calls into this core for the map: [`Machine::error_at`] (E at a point, in program units,
//! inside the zone and the measured domain), [`Machine::may_touch`] (could a path through
//! partly known points reach them) and [`Machine::lose_position`].

use super::reach::{self, MaybePoint};
use super::CompensationSettings;
use crate::geom::ErrorField;
use std::cell::Cell;

/// Millimetres per inch.
const MM_PER_INCH: f64 = 25.4;

/// Position, units, datum shift and zone of the program being read, and the map it is
/// compensated with.
pub(crate) struct Machine<'a> {
    pub field: &'a dyn ErrorField,
    pub settings: &'a CompensationSettings,
    /// Index (x 0, y 1, z 2) of the map's normal, the coordinate compensation changes.
    pub normal: usize,
    /// Indices of the two map-plane axes (u, v).
    pub plane_uv: (usize, usize),
    /// The original program's position (program coordinates, program units); `None` where
    /// unknown.
    pub pos: MaybePoint,
    pub inches: bool,
    /// Whether the program's units are known (a unit code, the header, or `--units`).
    pub units_known: bool,
    /// Work coordinates = program coordinates + `shift` (G92, G52, TRANS, cycle 7), program
    /// units.
    pub shift: [f64; 3],
    /// The output position differs from `pos` only along the normal, by `offset`.
    pub offset: f64,
    /// Line where the position became unknown, for messages.
    pub unknown_since: Option<u64>,
    /// Set by [`Self::error_at`] when a point in the zone lies outside the measured domain.
    pub extrapolated: Cell<bool>,
    /// `--zone` in the program's first units, until those are known ([`Self::fix_zone`]).
    zone_first_units: Option<(f64, f64)>,
    /// The zone along the normal in mm (work coordinates), once fixed.
    pub zone_mm: Option<(f64, f64)>,
}

impl<'a> Machine<'a> {
    /// The state at a program's start: position unknown, no shift; `default_zone_mm` is the
    /// zone the map gives when `--zone` is not set.
    pub fn new(
        field: &'a dyn ErrorField,
        settings: &'a CompensationSettings,
        inches: bool,
        default_zone_mm: Option<(f64, f64)>,
    ) -> Machine<'a> {
        let normal = field.normal();
        let (u, v) = normal.plane_axes();
        Machine {
            field,
            settings,
            normal: normal.index(),
            plane_uv: (u.index(), v.index()),
            pos: [None; 3],
            inches,
            units_known: false,
            shift: [0.0; 3],
            offset: 0.0,
            unknown_since: None,
            extrapolated: Cell::new(false),
            zone_first_units: settings.zone,
            zone_mm: default_zone_mm,
        }
    }

    /// Program units → mm.
    pub fn scale_mm(&self) -> f64 {
        if self.inches {
            MM_PER_INCH
        } else {
            1.0
        }
    }

    /// Fix the zone given in program units in mm, in the units in effect now: at the program's
    /// first unit code, or its first move if that comes first.
    pub fn fix_zone(&mut self) {
        if let Some((lo, hi)) = self.zone_first_units.take() {
            let s = self.scale_mm();
            self.zone_mm = Some((lo * s, hi * s));
        }
    }

    /// The zone in current program coordinates (units and shift).
    pub fn zone_now(&self) -> Option<(f64, f64)> {
        let s = self.scale_mm();
        let (lo, hi) = match (self.zone_first_units, self.zone_mm) {
            (Some(z), _) => z,
            (None, Some((lo, hi))) => (lo / s, hi / s),
            (None, None) => return None,
        };
        let d = self.shift[self.normal];
        Some((lo - d, hi - d))
    }

    /// Whether the map compensates at plane point (u, v) in program coordinates.
    pub fn compensable(&self, u: f64, v: f64) -> bool {
        let s = self.scale_mm();
        let (iu, iv) = self.plane_uv;
        let (u, v) = ((u + self.shift[iu]) * s, (v + self.shift[iv]) * s);
        reach::compensable_mm(self.field, self.settings, u, v)
    }

    /// E in program units at a point, if the point is in the zone and the measured domain.
    pub fn error_at(&self, p: &[f64; 3]) -> Option<f64> {
        if let Some((lo, hi)) = self.zone_now() {
            let n = p[self.normal];
            if n < lo || n > hi {
                return None;
            }
        }
        let s = self.scale_mm();
        let (iu, iv) = self.plane_uv;
        let (u, v) = ((p[iu] + self.shift[iu]) * s, (p[iv] + self.shift[iv]) * s);
        reach::domain_error_mm(self.field, self.settings, u, v, &self.extrapolated)
            .map(|e_mm| e_mm / s)
    }

    /// Could a path through these points (some coordinates unknown) touch the zone and the
    /// measured domain? Known stretches are sampled every `max_segment` (program units).
    pub fn may_touch(&self, points: &[MaybePoint]) -> bool {
        reach::may_touch(
            points,
            self.normal,
            self.plane_uv,
            self.zone_now(),
            self.step(),
            |u, v| self.compensable(u, v),
        )
    }

    /// Longest segment of a rewritten move, program units.
    pub fn step(&self) -> f64 {
        self.settings.max_segment / self.scale_mm()
    }

    /// Chord tolerance of a rewritten arc, program units.
    pub fn chord_tol(&self) -> f64 {
        self.settings.chord_tol / self.scale_mm()
    }

    /// Forget the whole position from `line` on (a frame, offset or cycle errmap does not
    /// follow moved the tool somewhere).
    pub fn forget_position(&mut self, line: u64) {
        self.pos = [None; 3];
        self.unknown_since = Some(line);
    }

    /// Forget the position along `axes` (a block errmap does not follow moved the tool).
    pub fn lose_position(&mut self, line: u64, axes: &[usize]) {
        for &i in axes {
            if self.pos[i].is_some() {
                self.pos[i] = None;
                self.unknown_since = Some(line);
            }
        }
        if self.unknown_since.is_none() {
            self.unknown_since = Some(line);
        }
    }
}
