//! Fast natural-neighbour weights along grid rows: circumcircle sweep and Watson's per-triangle area formula.
//!
//! Inserting a query point x into a Delaunay triangulation destroys exactly the triangles whose
//! circumcircle contains x (the conflict triangles). Along one grid row those are the
//! triangles whose circumcircle crosses the row at x, so a sweep over precomputed circle–row
//! intervals finds them without walking the triangulation.
//!
//! The Sibson weight of a vertex a is the area x's new Voronoi cell takes from a's cell. That
//! area is the polygon (g₀, C₁, …, C_k, g_k): the circumcentres C_T of a's conflict triangles
//! and, at the ends, the circumcentres g of (x, a, b) for the cavity's boundary edges. Splitting
//! it per conflict triangle T = (a, b, c) gives the signed area of (C_T, g_ab, g_ca), where
//! g_ab = circumcentre(x, a, b): the extra points g of edges inside the cavity lie both on the
//! line C_T C_T' and on the bisector of x and a, so they add nothing (Watson 1992, "Contouring",
//! §3; Sambridge, Braun & McQueen 1995). Weights are normalised by their sum, the area of the
//! new cell.
//!
//! Anything doubtful goes back to spade's exact-predicate path: nodes within a hair of the hull,
//! rows through the hull's extreme vertices, nodes nearly on the line of an edge inside the
//! cavity (where g runs off to infinity and two large areas would cancel).

use super::{Site, Tri};
use spade::Triangulation;

/// One Delaunay triangle: vertex indices (counter-clockwise) and circumcircle.
struct Triangle {
    v: [usize; 3],
    center: [f64; 2],
    radius2: f64,
}

/// Everything the sweep needs, copied out of the triangulation once.
pub(super) struct Sweep {
    sites: Vec<Site>,
    triangles: Vec<Triangle>,
    hull: Vec<([f64; 2], [f64; 2])>,
    /// Distances below this (1e-9 of the sites' extent) count as "on" a hull edge.
    eps: f64,
    v_min: f64,
    v_max: f64,
}

/// A circumcircle's span along one row.
#[derive(Clone, Copy)]
pub(super) struct Span {
    start: f64,
    end: f64,
    triangle: u32,
}

/// Reusable per-thread buffers for one row.
#[derive(Default)]
pub(super) struct RowBuffers {
    spans: Vec<Span>,
    active: Vec<Span>,
    /// (vertex index, weight) of the current node.
    pub(super) weights: Vec<(usize, f64)>,
}

/// What the sweep says about one node.
pub(super) enum Node {
    Outside,
    /// Weights are in [`RowBuffers::weights`], normalised.
    Weights,
    /// Too close to a degenerate case: ask spade.
    Fallback,
}

/// Circumcentre of (0, a, b), relative to the origin; `None` when the three are (nearly) on one line.
#[inline]
fn circumcentre0(a: [f64; 2], b: [f64; 2]) -> Option<[f64; 2]> {
    let d = 2.0 * (a[0] * b[1] - a[1] * b[0]);
    let la = a[0] * a[0] + a[1] * a[1];
    let lb = b[0] * b[0] + b[1] * b[1];
    // |d| / (2·|a|·|b|) is the sine of the angle at the origin.
    if d.abs() <= 2e-5 * (la * lb).sqrt() {
        return None;
    }
    Some([(b[1] * la - a[1] * lb) / d, (a[0] * lb - b[0] * la) / d])
}

#[inline]
fn cross(p: [f64; 2], q: [f64; 2]) -> f64 {
    p[0] * q[1] - p[1] * q[0]
}

impl Sweep {
    pub(super) fn new(tri: &Tri) -> Sweep {
        let sites: Vec<Site> = tri.vertices().map(|v| *v.data()).collect();
        let triangles = tri
            .inner_faces()
            .map(|f| {
                let v = f.vertices().map(|v| v.fix().index());
                let (center, radius2) = f.circumcircle();
                Triangle {
                    v,
                    center: [center.x, center.y],
                    radius2,
                }
            })
            .collect();
        let hull: Vec<([f64; 2], [f64; 2])> = tri
            .convex_hull()
            .map(|e| {
                let [a, b] = e.positions();
                ([a.x, a.y], [b.x, b.y])
            })
            .collect();
        let (mut u_min, mut u_max, mut v_min, mut v_max) = (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        );
        for s in &sites {
            u_min = u_min.min(s.position.x);
            u_max = u_max.max(s.position.x);
            v_min = v_min.min(s.position.y);
            v_max = v_max.max(s.position.y);
        }
        let extent = (u_max - u_min).max(v_max - v_min);
        Sweep {
            sites,
            triangles,
            hull,
            eps: 1e-9 * extent,
            v_min,
            v_max,
        }
    }

    pub(super) fn site(&self, vertex: usize) -> &Site {
        &self.sites[vertex]
    }

    /// The hull's span `[lo, hi]` along row `v`, or `None` if the row misses the hull.
    /// `Some(None)` marks a row that must go to spade (through an extreme vertex).
    fn hull_span(&self, v: f64) -> Option<Option<(f64, f64)>> {
        if v < self.v_min - self.eps || v > self.v_max + self.eps {
            return None;
        }
        if v <= self.v_min + self.eps || v >= self.v_max - self.eps {
            return Some(None);
        }
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for &(a, b) in &self.hull {
            let (v0, v1) = (a[1].min(b[1]), a[1].max(b[1]));
            if v < v0 || v > v1 || a[1] == b[1] {
                continue;
            }
            let u = a[0] + (v - a[1]) * (b[0] - a[0]) / (b[1] - a[1]);
            lo = lo.min(u);
            hi = hi.max(u);
        }
        Some((lo <= hi).then_some((lo, hi)))
    }

    /// Prepare the spans of the circumcircles crossing row `v`; returns the hull span as
    /// [`Sweep::hull_span`] does.
    pub(super) fn start_row(&self, v: f64, buf: &mut RowBuffers) -> Option<Option<(f64, f64)>> {
        buf.spans.clear();
        buf.active.clear();
        let span = self.hull_span(v)?;
        for (k, t) in self.triangles.iter().enumerate() {
            let dv = v - t.center[1];
            let h2 = t.radius2 - dv * dv;
            if h2 > 0.0 {
                let h = h2.sqrt();
                buf.spans.push(Span {
                    start: t.center[0] - h,
                    end: t.center[0] + h,
                    triangle: k as u32,
                });
            }
        }
        // Latest start first, so the next circle to open is at the back.
        buf.spans.sort_by(|a, b| {
            b.start
                .total_cmp(&a.start)
                .then(b.triangle.cmp(&a.triangle))
        });
        Some(span)
    }

    /// Natural-neighbour weights at `(u, v)` on the current row. Nodes must come in increasing
    /// `u` after [`Sweep::start_row`].
    pub(super) fn node(&self, u: f64, v: f64, hull: (f64, f64), buf: &mut RowBuffers) -> Node {
        // Open the circles that start at or before u, close those that ended before it.
        while let Some(&s) = buf.spans.last() {
            if s.start > u {
                break;
            }
            buf.active.push(s);
            buf.spans.pop();
        }
        buf.active.retain(|s| s.end >= u);
        let (lo, hi) = hull;
        if u < lo - self.eps || u > hi + self.eps {
            return Node::Outside;
        }
        if u <= lo + self.eps || u >= hi - self.eps {
            return Node::Fallback;
        }
        buf.weights.clear();
        let mut total = 0.0;
        for span in &buf.active {
            let t = &self.triangles[span.triangle as usize];
            let du = u - t.center[0];
            let dv = v - t.center[1];
            // A node on the circle (four cocircular sites of a lattice put it there, give or
            // take a rounding) is no conflict: the triangle would add two huge areas that
            // cancel. Exactly on the circle its share is zero.
            if du * du + dv * dv >= t.radius2 * (1.0 - 1e-10) {
                continue;
            }
            let rel = |i: usize| {
                let p = self.sites[t.v[i]].position;
                [p.x - u, p.y - v]
            };
            let (a, b, c) = (rel(0), rel(1), rel(2));
            let (Some(g_ab), Some(g_bc), Some(g_ca)) = (
                circumcentre0(a, b),
                circumcentre0(b, c),
                circumcentre0(c, a),
            ) else {
                return Node::Fallback;
            };
            let center = [t.center[0] - u, t.center[1] - v];
            let d = |g: [f64; 2]| [g[0] - center[0], g[1] - center[1]];
            let (g_ab, g_bc, g_ca) = (d(g_ab), d(g_bc), d(g_ca));
            // Signed areas (doubled) of (C_T, g_ab, g_ca) for a, and rotations for b and c.
            let terms = [cross(g_ab, g_ca), cross(g_bc, g_ab), cross(g_ca, g_bc)];
            for (i, term) in terms.into_iter().enumerate() {
                let vertex = t.v[i];
                match buf.weights.iter_mut().find(|(w, _)| *w == vertex) {
                    Some((_, w)) => *w += term,
                    None => buf.weights.push((vertex, term)),
                }
                total += term;
            }
        }
        if buf.weights.is_empty() || !(total.is_finite() && total != 0.0) {
            return Node::Fallback;
        }
        for (_, w) in buf.weights.iter_mut() {
            *w /= total;
        }
        // Sibson weights are never negative: a negative one is cancellation, not geometry.
        if buf.weights.iter().any(|&(_, w)| w.is_nan() || w < -1e-9) {
            return Node::Fallback;
        }
        Node::Weights
    }
}
