//! Points of a path in program units: the distance between two and the point a fraction along a segment.

/// Euclidean distance between two points.
pub(crate) fn dist(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// The point a fraction `t` of the way from `a` to `b`.
pub(crate) fn lerp(a: &[f64; 3], b: &[f64; 3], t: f64) -> [f64; 3] {
    [
        a[0] + t * (b[0] - a[0]),
        a[1] + t * (b[1] - a[1]),
        a[2] + t * (b[2] - a[2]),
    ]
}

/// The point when every coordinate of it is known.
pub(crate) fn known(p: [Option<f64>; 3]) -> Option<[f64; 3]> {
    Some([p[0]?, p[1]?, p[2]?])
}
