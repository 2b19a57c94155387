//! Circular and helical arcs of G2/G3 (centre I/J/K or radius R form) and their linearisation within a chord tolerance.
//!
//! An arc lies in the selected plane with axes (first, second) and moves linearly along the
//! plane's third axis (helix). LinuxCNC's convention (RS274/NGC v3, §3.5.3): G17 = (X, Y) about
//! Z, G18 = (Z, X) about Y, G19 = (Y, Z) about X; G3 turns counter-clockwise in (first, second)
//! seen from the positive third axis, G2 clockwise.

use std::f64::consts::PI;

/// The selected plane.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Plane {
    /// G17: the XY plane, arcs about Z.
    G17,
    /// G18: the ZX plane (first axis Z, second X), arcs about Y.
    G18,
    /// G19: the YZ plane, arcs about X.
    G19,
}

impl Plane {
    /// Indices (first, second, axis) into an `[x, y, z]` triple.
    pub fn axes(self) -> (usize, usize, usize) {
        match self {
            Plane::G17 => (0, 1, 2),
            Plane::G18 => (2, 0, 1),
            Plane::G19 => (1, 2, 0),
        }
    }
}

/// A parametrised arc: radius interpolated linearly from start to end radius (so both ends are
/// exact even when I/J/K give slightly different radii), axis coordinate linear in angle.
#[derive(Debug, Clone)]
pub struct Arc {
    /// The plane the arc turns in.
    pub plane: Plane,
    /// Start point `[x, y, z]`, program units (mm or inch).
    pub start: [f64; 3],
    /// End point `[x, y, z]`, program units.
    pub end: [f64; 3],
    /// Centre in the plane's (first, second) coordinates ([`Plane::axes`]), program units.
    pub centre: (f64, f64),
    /// Distance from the centre to the start in the plane, program units.
    pub r_start: f64,
    /// Distance from the centre to the end in the plane, program units.
    pub r_end: f64,
    /// Angle of the start about the centre, radians, counter-clockwise from the plane's first
    /// axis.
    pub theta_start: f64,
    /// Signed sweep in radians: positive counter-clockwise (G3), negative clockwise (G2).
    pub sweep: f64,
}

impl Arc {
    /// Build from a centre in plane coordinates. `clockwise` for G2; `turns` ≥ 1 (the P word).
    /// Start and end equal in the plane make a full circle.
    pub fn from_centre(
        plane: Plane,
        start: [f64; 3],
        end: [f64; 3],
        centre: (f64, f64),
        clockwise: bool,
        turns: u32,
    ) -> Result<Arc, String> {
        let (a1, a2, _) = plane.axes();
        let r_start = (start[a1] - centre.0).hypot(start[a2] - centre.1);
        let r_end = (end[a1] - centre.0).hypot(end[a2] - centre.1);
        if r_start < 1e-12 || r_end < 1e-12 {
            return Err("arc centre coincides with its start or end point".into());
        }
        // RS274/NGC rejects arcs whose start and end radii differ by more than a small amount
        // (LinuxCNC: 0.0002 in / 0.002 mm absolute, 0.1 % relative); accept 0.1 % + 0.002.
        if (r_start - r_end).abs() > 0.002 + 0.001 * r_start.max(r_end) {
            return Err(format!(
                "arc radius differs between start ({r_start:.5}) and end ({r_end:.5})"
            ));
        }
        let theta_start = (start[a2] - centre.1).atan2(start[a1] - centre.0);
        let theta_end = (end[a2] - centre.1).atan2(end[a1] - centre.0);
        let same = (start[a1] - end[a1]).abs() < 1e-12 && (start[a2] - end[a2]).abs() < 1e-12;
        let mut sweep = if clockwise {
            -(theta_start - theta_end).rem_euclid(2.0 * PI)
        } else {
            (theta_end - theta_start).rem_euclid(2.0 * PI)
        };
        if same || sweep.abs() < 1e-12 {
            sweep = if clockwise { -2.0 * PI } else { 2.0 * PI };
        }
        let extra = f64::from(turns.max(1) - 1) * 2.0 * PI;
        sweep += if clockwise { -extra } else { extra };
        Ok(Arc {
            plane,
            start,
            end,
            centre,
            r_start,
            r_end,
            theta_start,
            sweep,
        })
    }

    /// Build from the R form: |R| is the radius; R > 0 takes the arc of at most 180°, R < 0 the
    /// longer one (RS274/NGC §3.5.3.1).
    pub fn from_radius(
        plane: Plane,
        start: [f64; 3],
        end: [f64; 3],
        r: f64,
        clockwise: bool,
        turns: u32,
    ) -> Result<Arc, String> {
        let (a1, a2, _) = plane.axes();
        let dx = end[a1] - start[a1];
        let dy = end[a2] - start[a2];
        let d = dx.hypot(dy);
        if d < 1e-12 {
            return Err(
                "R-form arc with the same start and end point (use I/J/K for a full circle)".into(),
            );
        }
        let radius = r.abs();
        let half = d / 2.0;
        if radius < half - 1e-9 * radius.max(1.0) {
            return Err(format!(
                "arc radius {radius} is smaller than half the distance between its ends ({half:.5})"
            ));
        }
        let h = (radius * radius - half * half).max(0.0).sqrt();
        // Left of the chord for a short counter-clockwise arc; right for clockwise; R < 0 swaps.
        let (lx, ly) = (-dy / d, dx / d);
        let mut side = if clockwise { -1.0 } else { 1.0 };
        if r < 0.0 {
            side = -side;
        }
        let centre = (
            start[a1] + dx / 2.0 + side * h * lx,
            start[a2] + dy / 2.0 + side * h * ly,
        );
        Arc::from_centre(plane, start, end, centre, clockwise, turns)
    }

    /// Point at fraction `s` ∈ [0, 1] of the sweep; `s = 1` returns `end` exactly.
    pub fn point(&self, s: f64) -> [f64; 3] {
        if s >= 1.0 {
            return self.end;
        }
        if s <= 0.0 {
            return self.start;
        }
        let (a1, a2, ax) = self.plane.axes();
        let th = self.theta_start + s * self.sweep;
        let r = self.r_start + s * (self.r_end - self.r_start);
        let mut p = [0.0; 3];
        p[a1] = self.centre.0 + r * th.cos();
        p[a2] = self.centre.1 + r * th.sin();
        p[ax] = self.start[ax] + s * (self.end[ax] - self.start[ax]);
        p
    }

    /// Number of chords so that the sagitta r·(1 − cos(δ/2)) ≤ `chord_tol`, every chord is at
    /// most `max_segment` long (helix included) and spans at most 90°.
    pub fn chords(&self, chord_tol: f64, max_segment: f64) -> usize {
        let r = self.r_start.max(self.r_end);
        let dmax_tol = if chord_tol >= r {
            PI
        } else {
            2.0 * (1.0 - chord_tol / r).acos()
        };
        let sweep = self.sweep.abs();
        let n_tol = (sweep / dmax_tol.max(1e-9)).ceil();
        let (_, _, ax) = self.plane.axes();
        let length = (sweep * r).hypot(self.end[ax] - self.start[ax]);
        let n_len = (length / max_segment.max(1e-9)).ceil();
        let n_quarter = (sweep / (PI / 2.0)).ceil();
        n_tol.max(n_len).max(n_quarter).clamp(1.0, 1e7) as usize
    }

    /// The point at fraction `f` of the piece of this arc from `a` to `b` (both on it, less
    /// than a full turn apart in its direction): angle and radius interpolated, the third axis
    /// linear.
    pub(crate) fn point_between(&self, a: &[f64; 3], b: &[f64; 3], f: f64) -> [f64; 3] {
        let (a1, a2, ax) = self.plane.axes();
        let (c1, c2) = self.centre;
        let (ta, tb) = (
            (a[a2] - c2).atan2(a[a1] - c1),
            (b[a2] - c2).atan2(b[a1] - c1),
        );
        let tau = std::f64::consts::TAU;
        let sweep = if self.sweep >= 0.0 {
            (tb - ta).rem_euclid(tau)
        } else {
            -(ta - tb).rem_euclid(tau)
        };
        let (ra, rb) = (
            (a[a1] - c1).hypot(a[a2] - c2),
            (b[a1] - c1).hypot(b[a2] - c2),
        );
        let (t, r) = (ta + f * sweep, ra + f * (rb - ra));
        let mut p = [0.0; 3];
        p[a1] = c1 + r * t.cos();
        p[a2] = c2 + r * t.sin();
        p[ax] = a[ax] + f * (b[ax] - a[ax]);
        p
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: [f64; 3], b: [f64; 3]) -> bool {
        (0..3).all(|i| (a[i] - b[i]).abs() < 1e-9)
    }

    #[test]
    fn r_form_half_circle_and_short_arc_centres() {
        // G2 (0,0) → (10,0) R5: centre (5,0), clockwise through (5,5).
        let a = Arc::from_radius(Plane::G17, [0.0; 3], [10.0, 0.0, 0.0], 5.0, true, 1).unwrap();
        assert!((a.centre.0 - 5.0).abs() < 1e-12 && a.centre.1.abs() < 1e-12);
        assert!(close(a.point(0.5), [5.0, 5.0, 0.0]));
        // G3 (0,0) → (10,0) R 5√2: short CCW arc; centre on the left of the chord: (5, 5).
        let r = 50f64.sqrt();
        let a = Arc::from_radius(Plane::G17, [0.0; 3], [10.0, 0.0, 0.0], r, false, 1).unwrap();
        assert!((a.centre.0 - 5.0).abs() < 1e-12 && (a.centre.1 - 5.0).abs() < 1e-12);
        assert!((a.sweep - PI / 2.0).abs() < 1e-12);
        // Negative R takes the long way: 270°.
        let a = Arc::from_radius(Plane::G17, [0.0; 3], [10.0, 0.0, 0.0], -r, false, 1).unwrap();
        assert!((a.centre.1 + 5.0).abs() < 1e-12);
        assert!((a.sweep - 1.5 * PI).abs() < 1e-12);
    }

    #[test]
    fn full_helical_circle_in_g18() {
        // G18: first = Z, second = X. G2 from (x=1, z=0) about centre (z=0, x=0) with Y rising 2.
        let a = Arc::from_centre(
            Plane::G18,
            [1.0, 0.0, 0.0],
            [1.0, 2.0, 0.0],
            (0.0, 0.0),
            true,
            1,
        )
        .unwrap();
        assert!((a.sweep + 2.0 * PI).abs() < 1e-12);
        // Quarter turn clockwise in (Z, X) from angle 90° goes to angle 0°: Z = 1, X = 0, Y = 0.5.
        assert!(close(a.point(0.25), [0.0, 0.5, 1.0]));
        assert!(close(a.point(1.0), [1.0, 2.0, 0.0]));
    }

    #[test]
    fn chord_count_meets_tolerance_length_and_quarter_limits() {
        let a = Arc::from_centre(
            Plane::G17,
            [10.0, 0.0, 0.0],
            [10.0, 0.0, 0.0],
            (0.0, 0.0),
            false,
            1,
        )
        .unwrap();
        // r = 10, tol 0.005: δ = 2 acos(1 − 0.0005) = 0.063247 rad → ceil(2π / δ) = 100 chords.
        assert_eq!(a.chords(0.005, 1000.0), 100);
        // Length 62.83 mm with max 5 mm → 13 chords; tolerance loose.
        assert_eq!(a.chords(100.0, 5.0), 13);
        // Quarter limit: at least 4 for a full circle.
        assert_eq!(a.chords(100.0, 1000.0), 4);
    }

    #[test]
    fn bad_arcs_are_reported() {
        let err =
            Arc::from_radius(Plane::G17, [0.0; 3], [10.0, 0.0, 0.0], 4.0, true, 1).unwrap_err();
        assert!(
            err.contains("arc radius 4 is smaller than half the distance"),
            "{err}"
        );
        assert!(
            Arc::from_centre(Plane::G17, [0.0; 3], [10.0, 0.0, 0.0], (5.0, 1.0), true, 1).is_ok()
        );
        let err = Arc::from_centre(Plane::G17, [0.0; 3], [10.0, 0.0, 0.0], (4.0, 0.0), true, 1)
            .unwrap_err();
        assert!(err.contains("arc radius differs between start"), "{err}");
    }
}
