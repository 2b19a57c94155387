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
    let breaks: Vec<f64> = (0..path.len()).map(|i| i as f64).collect();
    let curve = |s: f64| {
        let i = (s.floor() as usize).min(path.len().saturating_sub(2));
        match (path.get(i), path.get(i + 1)) {
            (Some(a), Some(b)) => lerp(a, b, s - i as f64),
            (Some(a), None) => *a,
            _ => [0.0; 3],
        }
    };
    emit_curve(&breaks, &curve, step, zone, normal, error_at)
}

/// [`emit_points`] along a curve given by its parameter: `breaks` are the parameters of the
/// polyline's corners; intermediate and boundary points are taken on the curve.
pub(crate) fn emit_curve(
    breaks: &[f64],
    curve: &dyn Fn(f64) -> [f64; 3],
    step: f64,
    zone: Option<(f64, f64)>,
    normal: usize,
    error_at: &dyn Fn(&[f64; 3]) -> Option<f64>,
) -> Vec<([f64; 3], Option<f64>)> {
    let mut out: Vec<([f64; 3], Option<f64>)> = Vec::new();
    let Some(&s0) = breaks.first() else {
        return out;
    };
    let first = curve(s0);
    out.push((first, error_at(&first)));
    for w in breaks.windows(2) {
        let (sa, sb) = (w[0], w[1]);
        let (a, b) = (curve(sa), curve(sb));
        let at = |t: f64| {
            if t <= 0.0 {
                a
            } else if t >= 1.0 {
                b
            } else {
                curve(sa + t * (sb - sa))
            }
        };
        let len = dist(&a, &b);
        let k = (len / step).ceil().clamp(1.0, 1e7) as usize;
        let mut ts: Vec<f64> = (1..=k).map(|i| i as f64 / k as f64).collect();
        // Exact zone crossings along the normal.
        if let Some((lo, hi)) = zone {
            let (na, nb) = (a[normal], b[normal]);
            if (nb - na).abs() > 0.0 {
                for z in [lo, hi] {
                    let t = (z - na) / (nb - na);
                    if t > 0.0 && t < 1.0 {
                        ts.push(t);
                    }
                }
            }
        }
        ts.sort_by(|x, y| x.total_cmp(y));
        let mut t_prev = 0.0;
        let mut e_prev = error_at(&a);
        for t in ts {
            // The last point is the piece end exactly (lerp can round past a domain edge).
            let p = at(t);
            let e_here = error_at(&p);
            if e_prev.is_some() != e_here.is_some() {
                // Bisect for the boundary: keep `lo_t` on the side of e_prev.
                let (mut lo_t, mut hi_t) = (t_prev, t);
                for _ in 0..60 {
                    let mid = 0.5 * (lo_t + hi_t);
                    if error_at(&at(mid)).is_some() == e_prev.is_some() {
                        lo_t = mid;
                    } else {
                        hi_t = mid;
                    }
                }
                let (t_in, t_out) = if e_prev.is_some() {
                    (lo_t, hi_t)
                } else {
                    (hi_t, lo_t)
                };
                let p_in = at(t_in);
                let p_out = at(t_out);
                let e_in = error_at(&p_in);
                if e_prev.is_some() {
                    out.push((p_in, e_in));
                    out.push((p_out, None));
                } else {
                    out.push((p_out, None));
                    out.push((p_in, e_in));
                }
            }
            // Outside stretches of a straight piece need no intermediate points.
            let last = (t - 1.0).abs() < 1e-15;
            if e_here.is_some() || last {
                out.push((if last { b } else { p }, e_here));
            }
            t_prev = t;
            e_prev = e_here;
        }
    }
    out
}

pub(crate) fn dist(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

pub(crate) fn lerp(a: &[f64; 3], b: &[f64; 3], t: f64) -> [f64; 3] {
    [
        a[0] + t * (b[0] - a[0]),
        a[1] + t * (b[1] - a[1]),
        a[2] + t * (b[2] - a[2]),
    ]
}
