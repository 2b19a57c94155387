//! Gradient estimation at the sites of a triangulation: weighted least-squares quadratic fit over the two rings of Delaunay neighbours.

use super::Tri;
use nalgebra::{DMatrix, DVector};
use spade::handles::FixedVertexHandle;
use spade::Triangulation;

/// Singular values below this fraction of the largest mark a fit as ill-posed.
const RCOND_MIN: f64 = 1e-8;

/// Gradient `[∂e/∂u, ∂e/∂v]` at vertex `h`, from a least-squares fit of
/// `e − e_h = g·d + ½·dᵀHd` (5 unknowns) over the vertex's first and second rings of
/// Delaunay neighbours, weighted by 1/|d|². The fit passes through the site itself, so it is
/// exact for quadratic data (this is what lets Sibson's C1 interpolant reproduce a quadratic
/// better than the C0 one). Where the rings are too few or too degenerate for a quadratic,
/// a plane is fitted instead, and failing that the gradient is zero.
pub(crate) fn quadratic_gradient(tri: &Tri, h: FixedVertexHandle) -> [f64; 2] {
    let vertex = tri.vertex(h);
    let p0 = vertex.position();
    let e0 = vertex.data().e;
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
        return [0.0, 0.0];
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
        return [0.0, 0.0];
    }
    let rows: Vec<(f64, f64, f64, f64)> = ring
        .iter()
        .map(|&w| {
            let v = tri.vertex(w);
            let p = v.position();
            let du = (p.x - p0.x) / scale;
            let dv = (p.y - p0.y) / scale;
            let weight = 1.0 / (du * du + dv * dv).sqrt();
            (du, dv, v.data().e - e0, weight)
        })
        .collect();
    if rows.len() >= 6 {
        if let Some(g) = fit(&rows, 5) {
            return [g[0] / scale, g[1] / scale];
        }
    }
    match fit(&rows, 2) {
        Some(g) => [g[0] / scale, g[1] / scale],
        None => [0.0, 0.0],
    }
}

/// Weighted least squares with the first `unknowns` columns of `[du, dv, du²/2, du·dv, dv²/2]`
/// (row weight `weight`, i.e. squared residuals weighted by `weight²` = 1/|d|²).
fn fit(rows: &[(f64, f64, f64, f64)], unknowns: usize) -> Option<Vec<f64>> {
    let n = rows.len();
    let mut a = DMatrix::<f64>::zeros(n, unknowns);
    let mut b = DVector::<f64>::zeros(n);
    for (r, &(du, dv, de, w)) in rows.iter().enumerate() {
        let columns = [du, dv, 0.5 * du * du, du * dv, 0.5 * dv * dv];
        for c in 0..unknowns {
            a[(r, c)] = w * columns[c];
        }
        b[r] = w * de;
    }
    let svd = a.svd(true, true);
    let max = svd.singular_values.max();
    let min = svd.singular_values.min();
    if !(max > 0.0) || min < RCOND_MIN * max {
        return None;
    }
    let x = svd.solve(&b, 0.0).ok()?;
    let x: Vec<f64> = x.iter().copied().collect();
    x.iter().all(|v| v.is_finite()).then_some(x)
}
