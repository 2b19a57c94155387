//! Gross-error rejection: leave-one-out natural-neighbour residuals, a robust σ from the MAD, and iterated k·σ rejection, worst first.
//!
//! Seed 001 rejects points whose deviation exceeds the standard deviation of all
//! measurements; taken literally that discards real extremes of the error field. errmap instead
//! judges each point against what its neighbours predict (see `docs/probe-files.md`):
//!
//! 1. For every point i, predict `ê_i` from the other points with Sibson's C1 natural-neighbour
//!    interpolant (gradients at the neighbours from local quadratic fits, the point itself left
//!    out). A point outside the convex hull of the others (a hull corner, an irregular edge) is
//!    predicted by the mean of its Delaunay neighbours' linear extrapolations
//!    `e_j + ∇e_j·(p_i − p_j)`, weighted by 1/|p_i − p_j|².
//! 2. Residual `r_i = e_i − ê_i`, studentised: the prediction is linear in the data,
//!    `ê_i = Σ c_k·e_k`, so `z_i = r_i / √(1 + Σ c_k²)` has the noise's standard deviation for
//!    every good point, interior or extrapolated. σ = max(1.4826·MAD(z), [`SIGMA_FLOOR_UM`]) —
//!    1.4826·MAD estimates the standard deviation of normal data (Rousseeuw & Croux 1993) and
//!    ignores a minority of outliers.
//! 3. If the largest |z_i| exceeds k·σ, reject that one point only and start again from 1:
//!    an outlier drags its neighbours' residuals too, so removing the worst first and
//!    recomputing keeps a good neighbour from being rejected with it (and unmasks a second
//!    outlier next to the first).

use super::{ProbePoint, ProbeSet};
use crate::interp::{gradient_coefficients, Site, Tri};
use errmap_core::error::{Error, Result};
use rayon::prelude::*;
use spade::handles::FixedVertexHandle;
use spade::{Point2, Triangulation};

/// Default rejection threshold in robust standard deviations.
pub const DEFAULT_K_SIGMA: f64 = 3.0;

/// Lower bound of σ in µm, so data that is almost noise-free (residuals of 1e-12 µm) does not
/// turn rounding into "gross errors". 0.1 µm is below any touch probe's repeatability.
pub const SIGMA_FLOOR_UM: f64 = 0.1;

/// 1.4826 · MAD is a consistent estimator of σ for normally distributed residuals.
const MAD_TO_SIGMA: f64 = 1.4826;

/// Fewer points than this are not judged: nothing is rejected from them, and rejection stops
/// before the set would shrink below it.
pub const MIN_POINTS_TO_JUDGE: usize = 5;

/// A point removed as a gross error, with its leave-one-out residual when it was removed.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Rejected {
    /// The point as read.
    pub point: ProbePoint,
    /// Its error minus the value its neighbours predict for it, `e − ê`, µm (not studentised).
    pub residual_um: f64,
}

/// The outcome of [`reject_gross_errors`].
#[derive(Debug, Clone, PartialEq)]
pub struct Cleaned {
    /// Points kept, in file order.
    pub clean: Vec<ProbePoint>,
    /// Points rejected, in file order.
    pub rejected: Vec<Rejected>,
    /// Robust σ of the studentised leave-one-out residuals of the clean points, µm (at least
    /// the floor): an estimate of the probe noise.
    pub sigma_um: f64,
}

/// Reject gross errors with the k·σ rule on leave-one-out residuals (see the module docs).
pub fn reject_gross_errors(set: &ProbeSet, k_sigma: f64) -> Result<Cleaned> {
    if !(k_sigma.is_finite() && k_sigma > 0.0) {
        return Err(Error::usage(
            format!("k·σ factor {k_sigma} is not a positive number"),
            "use k = 3 (the default) or another positive number",
        ));
    }
    let points = &set.points;
    let mut active: Vec<usize> = (0..points.len()).collect();
    let mut rejected: Vec<(usize, f64)> = Vec::new();
    let mut sigma_um = SIGMA_FLOOR_UM;
    while active.len() >= MIN_POINTS_TO_JUDGE {
        let residuals = loo_residuals(points, &active);
        let scaled: Vec<f64> = residuals.iter().flatten().map(|&(_, z)| z).collect();
        sigma_um = robust_sigma(&scaled).max(SIGMA_FLOOR_UM);
        let worst = residuals
            .iter()
            .enumerate()
            .filter_map(|(k, r)| r.map(|r| (k, r)))
            .max_by(|a, b| a.1 .1.abs().total_cmp(&b.1 .1.abs()).then(b.0.cmp(&a.0)));
        match worst {
            Some((k, (r, z)))
                if z.abs() > k_sigma * sigma_um && active.len() > MIN_POINTS_TO_JUDGE =>
            {
                rejected.push((active[k], r));
                active.remove(k);
            }
            _ => break,
        }
    }
    rejected.sort_by_key(|&(i, _)| i);
    Ok(Cleaned {
        clean: active.iter().map(|&i| points[i].clone()).collect(),
        rejected: rejected
            .into_iter()
            .map(|(i, residual_um)| Rejected {
                point: points[i].clone(),
                residual_um,
            })
            .collect(),
        sigma_um,
    })
}

/// 1.4826 · median(|r − median(r)|); 0 for no residuals.
fn robust_sigma(residuals: &[f64]) -> f64 {
    fn median(values: &mut [f64]) -> f64 {
        if values.is_empty() {
            return 0.0;
        }
        values.sort_by(f64::total_cmp);
        let n = values.len();
        if n % 2 == 1 {
            values[n / 2]
        } else {
            0.5 * (values[n / 2 - 1] + values[n / 2])
        }
    }
    let mut r = residuals.to_vec();
    let m = median(&mut r);
    let mut deviations: Vec<f64> = residuals.iter().map(|x| (x - m).abs()).collect();
    MAD_TO_SIGMA * median(&mut deviations)
}

fn site(points: &[ProbePoint], i: usize) -> Site {
    Site {
        position: Point2::new(points[i].u_mm, points[i].v_mm),
        e: points[i].e_um,
        grad: [0.0, 0.0],
        index: i,
    }
}

/// A leave-one-out prediction as a linear combination of the other points' values:
/// `ê = Σ c_k·e_k` over `(point index, c_k)`.
type Prediction = Vec<(usize, f64)>;

fn add_coefficient(prediction: &mut Prediction, index: usize, c: f64) {
    match prediction.iter_mut().find(|(k, _)| *k == index) {
        Some((_, sum)) => *sum += c,
        None => prediction.push((index, c)),
    }
}

/// Leave-one-out residual of each active point (same order as `active`), divided by
/// `sqrt(1 + Σ c_k²)`: with independent noise of standard deviation s on every value, the
/// residual `e_i − Σ c_k·e_k` has standard deviation `s·sqrt(1 + Σ c_k²)`, so the scaled
/// residuals of good points share one σ whether they are predicted from close neighbours or
/// extrapolated at the hull. Returns `(residual_um, scaled)`; `None` where the others cannot
/// predict the point (they lie on one line).
fn loo_residuals(points: &[ProbePoint], active: &[usize]) -> Vec<Option<(f64, f64)>> {
    let full: Option<Tri> = Tri::bulk_load(active.iter().map(|&i| site(points, i)).collect()).ok();
    let Some(full) = full else {
        return vec![None; active.len()];
    };
    // Handle of each point in the full triangulation, for the outside-the-hull fallback.
    let mut full_handle: Vec<Option<FixedVertexHandle>> = vec![None; points.len()];
    for v in full.vertices() {
        full_handle[v.data().index] = Some(v.fix());
    }
    active
        .par_iter()
        .map(|&i| {
            let others: Vec<Site> = active
                .iter()
                .filter(|&&k| k != i)
                .map(|&k| site(points, k))
                .collect();
            let tri = Tri::bulk_load(others).ok()?;
            if tri.all_vertices_on_line() {
                return None;
            }
            let p = Point2::new(points[i].u_mm, points[i].v_mm);
            let prediction = predict_sibson_c1(&tri, p).or_else(|| {
                let neighbours: Vec<usize> = full_handle[i]
                    .map(|h| {
                        full.vertex(h)
                            .out_edges()
                            .map(|e| e.to().data().index)
                            .collect()
                    })
                    .unwrap_or_default();
                predict_outside(&tri, points.len(), &neighbours, p)
            })?;
            let predicted: f64 = prediction.iter().map(|&(k, c)| c * points[k].e_um).sum();
            let gain2: f64 = prediction.iter().map(|&(_, c)| c * c).sum();
            let residual = points[i].e_um - predicted;
            residual
                .is_finite()
                .then_some((residual, residual / (1.0 + gain2).sqrt()))
        })
        .collect()
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
fn predict_sibson_c1(tri: &Tri, p: Point2<f64>) -> Option<Prediction> {
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
fn predict_outside(
    tri: &Tri,
    n_points: usize,
    neighbours: &[usize],
    p: Point2<f64>,
) -> Option<Prediction> {
    let mut handle_of: Vec<Option<FixedVertexHandle>> = vec![None; n_points];
    for v in tri.vertices() {
        handle_of[v.data().index] = Some(v.fix());
    }
    let mut geometry = Vec::new();
    let mut sum_weights = 0.0;
    for &k in neighbours {
        let Some(h) = handle_of.get(k).copied().flatten() else {
            continue;
        };
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn robust_sigma_of_known_values() {
        // median 3, |deviations| = 2,1,0,1,97 → MAD 1 → σ = 1.4826, the outlier ignored.
        let s = robust_sigma(&[1.0, 2.0, 3.0, 4.0, 100.0]);
        assert!((s - 1.4826).abs() < 1e-12, "{s}");
        assert_eq!(robust_sigma(&[]), 0.0);
    }

    fn scattered(n: usize, e: impl Fn(f64, f64) -> f64) -> Vec<ProbePoint> {
        // A deterministic irregular layout (golden-angle spiral, stretched) over 300 × 200 mm.
        (0..n)
            .map(|k| {
                let r = (k as f64 + 0.5).sqrt() / (n as f64).sqrt();
                let t = k as f64 * 2.399_963_229_728_653;
                let (u, v) = (150.0 + 150.0 * r * t.cos(), 100.0 + 100.0 * r * t.sin());
                ProbePoint {
                    id: None,
                    line: k as u64 + 2,
                    measured_mm: [u, v, 0.0],
                    nominal_mm: [u, v, 0.0],
                    u_mm: u,
                    v_mm: v,
                    e_um: e(u, v),
                    repeats: 1,
                    spread_um: 0.0,
                }
            })
            .collect()
    }

    #[test]
    fn leave_one_out_predicts_a_plane_exactly_inside_and_at_the_hull() {
        let plane = |u: f64, v: f64| 7.0 + 0.04 * u - 0.09 * v;
        let points = scattered(60, plane);
        let active: Vec<usize> = (0..points.len()).collect();
        let residuals = loo_residuals(&points, &active);
        for (k, r) in residuals.iter().enumerate() {
            let (r, z) = r.unwrap_or_else(|| panic!("point {k} not predicted"));
            assert!(r.abs() < 1e-9 && z.abs() <= r.abs(), "point {k}: {r} {z}");
        }
    }

    #[test]
    fn prediction_coefficients_sum_to_one() {
        // Constant precision (Σ c = 1) for an interior and for an outside-the-hull prediction.
        let points = scattered(40, |u, v| (u / 40.0).sin() * 10.0 + v * 0.01);
        let sites: Vec<Site> = (1..points.len()).map(|k| site(&points, k)).collect();
        let tri = Tri::bulk_load(sites).unwrap();
        let inside = Point2::new(points[0].u_mm, points[0].v_mm);
        let c = predict_sibson_c1(&tri, inside).expect("point 0 is inside the others' hull");
        let sum: f64 = c.iter().map(|&(_, c)| c).sum();
        assert!((sum - 1.0).abs() < 1e-12, "{sum}");
        let outside = Point2::new(400.0, 100.0);
        assert!(predict_sibson_c1(&tri, outside).is_none());
        let neighbours: Vec<usize> = (1..6).collect();
        let c = predict_outside(&tri, points.len(), &neighbours, outside).unwrap();
        let sum: f64 = c.iter().map(|&(_, c)| c).sum();
        assert!((sum - 1.0).abs() < 1e-12, "{sum}");
    }
}
