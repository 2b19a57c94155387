//! The points a compensated move is emitted at: split at most `max_segment` apart in the zone and exactly at zone and domain edges, on the move's own curve.

/// Walk the polyline; split every piece so segments in the zone are at most max_segment
/// long, and split exactly where the path enters or leaves the zone/domain. Returns each
/// point with E (program units) when it is compensated. At a boundary the point is emitted
/// twice, uncompensated and compensated, so the outside part of the move stays unchanged.
pub(crate) fn emit_points(
    path: &[[f64; 3]],
    step: f64,
    zone: Option<(f64, f64)>,
    normal: usize,
    error_at: &dyn Fn(&[f64; 3]) -> Option<f64>,
) -> Vec<([f64; 3], Option<f64>)> {
    let curve = |s: f64| {
        let i = (s.floor() as usize).min(path.len().saturating_sub(2));
        match (path.get(i), path.get(i + 1)) {
            (Some(a), Some(b)) => lerp(a, b, s - i as f64),
            (Some(a), None) => *a,
            _ => [0.0; 3],
        }
    };
    let mut out = Vec::new();
    if !path.is_empty() {
        let breaks = Breaks::Indices(path.len() - 1);
        // A CSV path's points are bounded by its rows and `max_segment`, checked by the caller.
        emit_curve(
            breaks,
            &curve,
            step,
            zone,
            normal,
            &error_at,
            usize::MAX,
            &mut out,
        );
    }
    out
}

/// The parameters of a polyline's corners along its curve.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Breaks {
    /// `0, 1, …, n` (a polyline of n pieces parametrised by its corner index).
    Indices(usize),
    /// `0, 1/n, …, 1` (a curve over [0, 1] cut into n chords).
    Fractions(usize),
}

impl Breaks {
    fn pieces(self) -> usize {
        match self {
            Breaks::Indices(n) | Breaks::Fractions(n) => n,
        }
    }

    fn at(self, i: usize) -> f64 {
        match self {
            Breaks::Indices(_) => i as f64,
            Breaks::Fractions(n) => i as f64 / n as f64,
        }
    }
}

/// [`emit_points`] along a curve given by its parameter: `breaks` are the parameters of the
/// polyline's corners; intermediate and boundary points are taken on the curve. The points
/// are appended to `out`. Returns false, with `out` cut short, as soon as it holds more than
/// `max_points` (the output budget of the caller): a many-turn arc stops there, not after
/// millions of points.
#[allow(clippy::too_many_arguments)]
pub(crate) fn emit_curve(
    breaks: Breaks,
    curve: &impl Fn(f64) -> [f64; 3],
    step: f64,
    zone: Option<(f64, f64)>,
    normal: usize,
    error_at: &impl Fn(&[f64; 3]) -> Option<f64>,
    max_points: usize,
    out: &mut Vec<([f64; 3], Option<f64>)>,
) -> bool {
    let first = curve(breaks.at(0));
    out.push((first, error_at(&first)));
    for i in 0..breaks.pieces() {
        let (sa, sb) = (breaks.at(i), breaks.at(i + 1));
        let piece = Piece {
            a: curve(sa),
            b: curve(sb),
            sa,
            sb,
        };
        if !emit_piece(&piece, curve, step, zone, normal, error_at, max_points, out) {
            return false;
        }
    }
    true
}

/// One piece of the polyline: its end points and their parameters on the curve.
struct Piece {
    a: [f64; 3],
    b: [f64; 3],
    sa: f64,
    sb: f64,
}

impl Piece {
    /// The curve's point at fraction `t` of the piece (its ends exactly at 0 and 1).
    fn at(&self, curve: &impl Fn(f64) -> [f64; 3], t: f64) -> [f64; 3] {
        if t <= 0.0 {
            self.a
        } else if t >= 1.0 {
            self.b
        } else {
            curve(self.sa + t * (self.sb - self.sa))
        }
    }

    /// Fractions where the piece crosses the zone's limits along the normal, ascending.
    fn crossings(&self, zone: Option<(f64, f64)>, normal: usize) -> ([f64; 2], usize) {
        let mut ts = [0.0; 2];
        let mut n = 0;
        if let Some((lo, hi)) = zone {
            let (na, nb) = (self.a[normal], self.b[normal]);
            if (nb - na).abs() > 0.0 {
                for z in [lo, hi] {
                    let t = (z - na) / (nb - na);
                    if t > 0.0 && t < 1.0 {
                        ts[n] = t;
                        n += 1;
                    }
                }
            }
        }
        if n == 2 && ts[1] < ts[0] {
            ts.swap(0, 1);
        }
        (ts, n)
    }
}

/// The points of one piece: every `step` in the zone, and both sides of each zone or domain
/// edge it crosses. False when `out` outgrows `max_points`.
#[allow(clippy::too_many_arguments)]
fn emit_piece(
    piece: &Piece,
    curve: &impl Fn(f64) -> [f64; 3],
    step: f64,
    zone: Option<(f64, f64)>,
    normal: usize,
    error_at: &impl Fn(&[f64; 3]) -> Option<f64>,
    max_points: usize,
    out: &mut Vec<([f64; 3], Option<f64>)>,
) -> bool {
    let len = dist(&piece.a, &piece.b);
    let k = (len / step).ceil().clamp(1.0, 1e7) as usize;
    let (cross, ncross) = piece.crossings(zone, normal);
    let mut c = 0;
    let mut i = 1;
    let mut t_prev = 0.0;
    let mut e_prev = error_at(&piece.a);
    // The even steps i/k merged with the zone crossings, in ascending order.
    while i <= k || c < ncross {
        let even = i as f64 / k as f64;
        let t = if c < ncross && (i > k || cross[c] < even) {
            c += 1;
            cross[c - 1]
        } else {
            i += 1;
            even
        };
        let p = piece.at(curve, t);
        let e_here = error_at(&p);
        if e_prev.is_some() != e_here.is_some() {
            boundary(piece, curve, (t_prev, t), e_prev.is_some(), error_at, out);
        }
        // Outside stretches of a straight piece need no intermediate points. The last point
        // is the piece end exactly (lerp can round past a domain edge).
        let last = (t - 1.0).abs() < 1e-15;
        if e_here.is_some() || last {
            out.push((if last { piece.b } else { p }, e_here));
        }
        t_prev = t;
        e_prev = e_here;
        if out.len() > max_points {
            return false;
        }
    }
    true
}

/// Bisect for the zone/domain edge between fractions `span` and emit it twice: uncompensated
/// on the outside, compensated on the inside, in the order the path meets them.
fn boundary(
    piece: &Piece,
    curve: &impl Fn(f64) -> [f64; 3],
    span: (f64, f64),
    was_in: bool,
    error_at: &impl Fn(&[f64; 3]) -> Option<f64>,
    out: &mut Vec<([f64; 3], Option<f64>)>,
) {
    // Keep `lo_t` on the side of the previous point.
    let (mut lo_t, mut hi_t) = span;
    for _ in 0..60 {
        let mid = 0.5 * (lo_t + hi_t);
        if error_at(&piece.at(curve, mid)).is_some() == was_in {
            lo_t = mid;
        } else {
            hi_t = mid;
        }
    }
    let (t_in, t_out) = if was_in { (lo_t, hi_t) } else { (hi_t, lo_t) };
    let p_in = piece.at(curve, t_in);
    let p_out = piece.at(curve, t_out);
    let e_in = error_at(&p_in);
    if was_in {
        out.push((p_in, e_in));
        out.push((p_out, None));
    } else {
        out.push((p_out, None));
        out.push((p_in, e_in));
    }
}

pub(crate) use crate::point::{dist, lerp};
