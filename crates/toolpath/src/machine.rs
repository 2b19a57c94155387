//! The machine state every program reader drives (G-code dialects and Klartext): where the tool is, in which units and work coordinates, where the compensation zone lies and how much the map moves a point, so each of these rules is written once.
//!
//! A reader keeps its own syntax and modes (plane, motion, cycles, frames it does not follow)
//! and calls into this core for the map: [`Machine::error_at`] (E at a point, in program units,
//! inside the zone and the measured domain), [`Machine::may_touch`] (could a path through
//! partly known points reach them) and [`Machine::lose_position`].

use super::arc::Arc;
use super::reach::{self, MaybePoint};
use super::CompensationSettings;
use errmap_core::geom::ErrorField;

/// Millimetres per inch.
const MM_PER_INCH: f64 = 25.4;

/// A point of a rewritten path (program units) and E there (`None`: left nominal).
pub(crate) type Emitted = ([f64; 3], Option<f64>);

/// Most times one arc piece under cutter radius compensation is halved before errmap refuses
/// (2¹² pieces: a map that bends that sharply along an arc is not one errmap follows).
const MAX_HALVINGS: u32 = 12;

/// Fractions of a piece where its tool-axis coordinate is checked against P − E.
const CHECKS: [f64; 3] = [0.25, 0.5, 0.75];

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
    /// Set by [`Self::error_at`] when a point in the zone lies outside the measured domain or
    /// where u(E) exceeds the bound; counted per move into the report.
    pub kept_nominal: reach::KeptNominal,
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
            kept_nominal: reach::KeptNominal::default(),
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
        reach::domain_error_mm(self.field, self.settings, u, v, &self.kept_nominal)
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

    /// The pieces of an arc under cutter radius compensation, where the arc must stay arcs:
    /// each helical piece (end point and E, from `start`) is halved until E along it stays
    /// within the chord tolerance of the linear change of E between its ends. `None` when a
    /// piece needs more than [`MAX_HALVINGS`] halvings (the caller refuses in its dialect).
    pub fn helical_pieces(
        &self,
        arc: &Arc,
        start: [f64; 3],
        pieces: &[Emitted],
    ) -> Option<Vec<Emitted>> {
        let mut out = Vec::with_capacity(pieces.len());
        // The output stands at P − E at the start only after a compensated cut that ended
        // there; otherwise the first piece carries the step and is not checked.
        let e_start = self
            .error_at(&start)
            .filter(|e| (e + self.offset).abs() <= 1e-12 * (1.0 + e.abs()));
        let mut prev = (start, e_start);
        for &piece in pieces {
            self.halve(arc, prev, piece, 0, &mut out)?;
            prev = piece;
        }
        Some(out)
    }

    /// Push the points of the arc piece from `a` to `z` (z included), halving it as needed.
    fn halve(
        &self,
        arc: &Arc,
        a: Emitted,
        z: Emitted,
        depth: u32,
        out: &mut Vec<Emitted>,
    ) -> Option<()> {
        let (Some(ea), Some(ez)) = (a.1, z.1) else {
            out.push(z);
            return Some(());
        };
        let tol = self.chord_tol();
        let on = |f: f64| arc.point_between(&a.0, &z.0, f);
        let fits = CHECKS.iter().all(|&f| {
            self.error_at(&on(f))
                .is_some_and(|e| ((ea + f * (ez - ea)) - e).abs() <= tol)
        });
        if fits {
            out.push(z);
            return Some(());
        }
        if depth >= MAX_HALVINGS {
            return None;
        }
        let m = on(0.5);
        let mid = (m, self.error_at(&m));
        self.halve(arc, a, mid, depth + 1, out)?;
        self.halve(arc, mid, z, depth + 1, out)
    }
}
