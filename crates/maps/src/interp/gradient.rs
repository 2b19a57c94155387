//! Gradient estimation at the sites of a triangulation: weighted least-squares quadratic fit over the two rings of Delaunay neighbours.

use super::Tri;
use nalgebra::DMatrix;
use spade::handles::FixedVertexHandle;
use spade::Triangulation;

/// Singular values below this fraction of the largest mark a fit as ill-posed.
const RCOND_MIN: f64 = 1e-8;

/// Gradient `[∂e/∂u, ∂e/∂v]` at vertex `h`: see [`gradient_coefficients`].
pub(crate) fn quadratic_gradient(tri: &Tri, h: FixedVertexHandle) -> [f64; 2] {
    let mut g = [0.0, 0.0];
    for (k, c) in gradient_coefficients(tri, h) {
        let e = tri.vertex(k).data().e;
        g[0] += c[0] * e;
        g[1] += c[1] * e;
    }
    g
}

/// The gradient at vertex `h` as a linear combination of site values: `∇e_h = Σ c_k·e_k`
/// over the returned `(vertex, c_k)` (which include `h` itself). The gradient comes from a
/// least-squares fit of `e − e_h = g·d + ½·dᵀHd` (5 unknowns) over the vertex's first and
/// second rings of Delaunay neighbours, each row weighted by 1/|d| (squared residuals by
/// 1/|d|²). The fit passes through the site itself, so it is exact for quadratic data (this is
/// what lets Sibson's C1 interpolant reproduce a quadratic better than the C0 one). Where the
/// rings are too few or too degenerate for a quadratic, a plane is fitted instead, and failing
/// that the gradient is zero (no coefficients). The coefficients, not just the value, let the
/// gross-error check know how much a prediction amplifies the noise of the data.
pub(crate) fn gradient_coefficients(
    tri: &Tri,
    h: FixedVertexHandle,
) -> Vec<(FixedVertexHandle, [f64; 2])> {
    let vertex = tri.vertex(h);
    let p0 = vertex.position();
    let mut ring: Vec<FixedVertexHandle> = vertex.out_edges().map(|e| e.to().fix()).collect();
    let first_ring = ring.len();
    for k in 0..first_ring {
        for edge in tri.vertex(ring[k]).out_edges() {
            let w = edge.to().fix();
            if w != h && !ring.contains(&w) {
                ring.push(w);
            }
        }
    }
    if ring.len() < 2 {
        return Vec::new();
    }
    // Work in units of the mean neighbour distance so the normal matrix is well scaled.
    let scale = ring
        .iter()
        .map(|&w| {
            let p = tri.vertex(w).position();
            ((p.x - p0.x).powi(2) + (p.y - p0.y).powi(2)).sqrt()
        })
        .sum::<f64>()
        / ring.len() as f64;
    if !(scale > 0.0 && scale.is_finite()) {
        return Vec::new();
    }
    let rows: Vec<(f64, f64, f64)> = ring
        .iter()
        .map(|&w| {
            let p = tri.vertex(w).position();
            let du = (p.x - p0.x) / scale;
            let dv = (p.y - p0.y) / scale;
            (du, dv, 1.0 / (du * du + dv * dv).sqrt())
        })
        .collect();
    let solve = if rows.len() >= 6 {
        fit(&rows, 5).or_else(|| fit(&rows, 2))
    } else {
        fit(&rows, 2)
    };
    let Some(pinv) = solve else {
        return Vec::new();
    };
    // g = Σ_k P[0..2, k]·w_k·(e_k − e_h) / scale.
    let mut out = Vec::with_capacity(ring.len() + 1);
    let mut centre = [0.0, 0.0];
    for (k, (&w, &(_, _, weight))) in ring.iter().zip(&rows).enumerate() {
        let c = [pinv[(0, k)] * weight / scale, pinv[(1, k)] * weight / scale];
        centre[0] -= c[0];
        centre[1] -= c[1];
        out.push((w, c));
    }
    out.push((h, centre));
    out
}

/// Pseudo-inverse of the weighted design matrix with the first `unknowns` columns of
/// `[du, dv, du²/2, du·dv, dv²/2]` (row weight `weight`); `None` if ill-conditioned.
fn fit(rows: &[(f64, f64, f64)], unknowns: usize) -> Option<DMatrix<f64>> {
    let n = rows.len();
    let mut a = DMatrix::<f64>::zeros(n, unknowns);
    for (r, &(du, dv, w)) in rows.iter().enumerate() {
        let columns = [du, dv, 0.5 * du * du, du * dv, 0.5 * dv * dv];
        for c in 0..unknowns {
            a[(r, c)] = w * columns[c];
        }
    }
    let svd = a.svd(true, true);
    let max = svd.singular_values.max();
    let min = svd.singular_values.min();
    // `max` is NaN or zero for a fit with no information.
    if max.is_nan() || max <= 0.0 || min < RCOND_MIN * max {
        return None;
    }
    let pinv = svd.pseudo_inverse(0.0).ok()?;
    pinv.iter().all(|v| v.is_finite()).then_some(pinv)
}
