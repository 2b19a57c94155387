//! Leave-one-out prediction of one probe point from the others as coefficients on their values: Sibson's C1 interpolant inside their hull, the neighbours' linear extrapolations outside it, and the studentised residual.

use super::ProbePoint;
use crate::interp::{gradient_coefficients, Site, Tri};
use spade::handles::FixedVertexHandle;
use spade::{Point2, Triangulation};

/// Point i's residual `e_i − ê_i` and the residual divided by `sqrt(1 + Σ c_k²)`: with
/// independent noise of standard deviation s on every value, the residual has standard
/// deviation `s·sqrt(1 + Σ c_k²)`, so the scaled residuals of good points share one σ whether
/// they are predicted from close neighbours or extrapolated at the hull. `None` when not finite.
pub(super) fn residual(
    points: &[ProbePoint],
    i: usize,
    prediction: Prediction,
) -> Option<(f64, f64)> {
    let predicted: f64 = prediction.iter().map(|&(k, c)| c * points[k].e_um).sum();
    let gain2: f64 = prediction.iter().map(|&(_, c)| c * c).sum();
    let residual = points[i].e_um - predicted;
    residual
        .is_finite()
        .then_some((residual, residual / (1.0 + gain2).sqrt()))
}

pub(super) fn site(points: &[ProbePoint], i: usize) -> Site {
    Site {
        position: Point2::new(points[i].u_mm, points[i].v_mm),
        e: points[i].e_um,
        grad: [0.0, 0.0],
        index: i,
    }
}

/// A leave-one-out prediction as a linear combination of the other points' values:
/// `ê = Σ c_k·e_k` over `(point index, c_k)`.
pub(super) type Prediction = Vec<(usize, f64)>;

fn add_coefficient(prediction: &mut Prediction, index: usize, c: f64) {
    match prediction.iter_mut().find(|(k, _)| *k == index) {
        Some((_, sum)) => *sum += c,
        None => prediction.push((index, c)),
    }
}

/// Add `weight · (e_j + ∇e_j·d)` (the linear extrapolation of site `h` by `d`) to a prediction.
fn add_extrapolation(
    prediction: &mut Prediction,
    tri: &Tri,
    h: FixedVertexHandle,
    d: [f64; 2],
    weight: f64,
) {
    add_coefficient(prediction, tri.vertex(h).data().index, weight);
    for (k, c) in gradient_coefficients(tri, h) {
        add_coefficient(
            prediction,
            tri.vertex(k).data().index,
            weight * (d[0] * c[0] + d[1] * c[1]),
        );
    }
}

/// Sibson's C1 interpolant at `p` (flatness 0.5: Sibson 1981, the formula of spade's
/// `interpolate_gradient` and [`crate::interp`]'s `sibson_c1`), as coefficients on the site
/// values. `None` outside the convex hull.
pub(super) fn predict_sibson_c1(tri: &Tri, p: Point2<f64>) -> Option<Prediction> {
    let mut weights = Vec::new();
    tri.natural_neighbor().get_weights(p, &mut weights);
    if weights.is_empty() {
        return None;
    }
    // value = (α·Σ w_j e_j + β·Σ (c_j/S) ζ_j) / (α + β), with c_j = w_j / r_j, S = Σ c_j,
    // α = Σ c_j r_j² / S, β = Σ w_j r_j², ζ_j = e_j + ∇e_j·(p − p_j).
    let (mut alpha, mut beta, mut s) = (0.0, 0.0, 0.0);
    let mut geometry = Vec::with_capacity(weights.len());
    for &(h, w) in &weights {
        let q = tri.vertex(h).position();
        let d = [p.x - q.x, p.y - q.y];
        let r2 = d[0] * d[0] + d[1] * d[1];
        if r2 == 0.0 {
            return Some(vec![(tri.vertex(h).data().index, 1.0)]);
        }
        let c = w / r2.sqrt();
        alpha += c * r2;
        beta += w * r2;
        s += c;
        geometry.push((h, w, c, d));
    }
    alpha /= s;
    let mut prediction = Prediction::new();
    for (h, w, c, d) in geometry {
        add_coefficient(
            &mut prediction,
            tri.vertex(h).data().index,
            alpha * w / (alpha + beta),
        );
        add_extrapolation(&mut prediction, tri, h, d, beta * c / s / (alpha + beta));
    }
    Some(prediction)
}

/// Prediction at a point outside the hull of the others: the mean of its Delaunay neighbours'
/// linear extrapolations `e_j + ∇e_j·(p − p_j)`, weighted by 1/|p − p_j|².
pub(super) fn predict_outside(
    tri: &Tri,
    neighbours: &[usize],
    p: Point2<f64>,
) -> Option<Prediction> {
    let mut handle_of: Vec<(usize, FixedVertexHandle)> =
        tri.vertices().map(|v| (v.data().index, v.fix())).collect();
    handle_of.sort_unstable_by_key(|&(k, _)| k);
    let mut geometry = Vec::new();
    let mut sum_weights = 0.0;
    for &k in neighbours {
        let Ok(at) = handle_of.binary_search_by_key(&k, |&(i, _)| i) else {
            continue;
        };
        let h = handle_of[at].1;
        let q = tri.vertex(h).position();
        let d = [p.x - q.x, p.y - q.y];
        let r2 = d[0] * d[0] + d[1] * d[1];
        if r2 == 0.0 {
            return Some(vec![(k, 1.0)]);
        }
        sum_weights += 1.0 / r2;
        geometry.push((h, d, 1.0 / r2));
    }
    if sum_weights <= 0.0 {
        return None;
    }
    let mut prediction = Prediction::new();
    for (h, d, w) in geometry {
        add_extrapolation(&mut prediction, tri, h, d, w / sum_weights);
    }
    Some(prediction)
}
