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
//! 2. Residual `r_i = e_i − ê_i`; σ = max(1.4826·MAD(r), [`SIGMA_FLOOR_UM`]) — 1.4826·MAD
//!    estimates the standard deviation of normal data (Rousseeuw & Croux 1993) and ignores a
//!    minority of outliers.
//! 3. If the largest |r_i| exceeds k·σ, reject that one point only and start again from 1:
//!    an outlier drags its neighbours' residuals too, so removing the worst first and
//!    recomputing keeps a good neighbour from being rejected with it (and unmasks a second
//!    outlier next to the first).

use super::{ProbePoint, ProbeSet};
use crate::error::{Error, Result};
use crate::interp::{quadratic_gradient, Site, Tri};
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
    pub point: ProbePoint,
    pub residual_um: f64,
}

/// The outcome of [`reject_gross_errors`].
#[derive(Debug, Clone, PartialEq)]
pub struct Cleaned {
    /// Points kept, in file order.
    pub clean: Vec<ProbePoint>,
    /// Points rejected, in file order.
    pub rejected: Vec<Rejected>,
    /// Robust σ of the leave-one-out residuals of the clean points, µm (at least the floor).
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
        let known: Vec<f64> = residuals.iter().flatten().copied().collect();
        sigma_um = robust_sigma(&known).max(SIGMA_FLOOR_UM);
        let worst = residuals
            .iter()
            .enumerate()
            .filter_map(|(k, r)| r.map(|r| (k, r)))
            .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()).then(b.0.cmp(&a.0)));
        match worst {
            Some((k, r)) if r.abs() > k_sigma * sigma_um && active.len() > MIN_POINTS_TO_JUDGE => {
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

/// Leave-one-out residual of each active point (same order as `active`); `None` where the
/// others cannot predict it (they lie on one line).
fn loo_residuals(points: &[ProbePoint], active: &[usize]) -> Vec<Option<f64>> {
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
            let predicted = predict_sibson_c1(&tri, p).or_else(|| {
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
            Some(points[i].e_um - predicted)
        })
        .collect()
}

/// Sibson's C1 interpolant at `p` (flatness 0.5: Sibson 1981, as in spade's
/// `interpolate_gradient`), estimating gradients only at the natural neighbours of `p`.
/// `None` outside the convex hull.
fn predict_sibson_c1(tri: &Tri, p: Point2<f64>) -> Option<f64> {
    let mut weights = Vec::new();
    tri.natural_neighbor().get_weights(p, &mut weights);
    if weights.is_empty() {
        return None;
    }
    let (mut sum_c0, mut sum_c1, mut sum_c1_weights, mut alpha, mut beta) =
        (0.0, 0.0, 0.0, 0.0, 0.0);
    for &(h, w) in &weights {
        let v = tri.vertex(h);
        let q = v.position();
        let (du, dv) = (p.x - q.x, p.y - q.y);
        let r2 = du * du + dv * dv;
        if r2 == 0.0 {
            return Some(v.data().e);
        }
        let g = quadratic_gradient(tri, h);
        let c1_weight = w / r2.sqrt();
        let zeta = v.data().e + du * g[0] + dv * g[1];
        alpha += c1_weight * r2;
        beta += w * r2;
        sum_c1_weights += c1_weight;
        sum_c1 += zeta * c1_weight;
        sum_c0 += v.data().e * w;
    }
    alpha /= sum_c1_weights;
    sum_c1 /= sum_c1_weights;
    let value = (alpha * sum_c0 + beta * sum_c1) / (alpha + beta);
    value.is_finite().then_some(value)
}

/// Prediction at a point outside the hull of the others: the mean of its Delaunay neighbours'
/// linear extrapolations `e_j + ∇e_j·(p − p_j)`, weighted by 1/|p − p_j|².
fn predict_outside(
    tri: &Tri,
    n_points: usize,
    neighbours: &[usize],
    p: Point2<f64>,
) -> Option<f64> {
    let mut handle_of: Vec<Option<FixedVertexHandle>> = vec![None; n_points];
    for v in tri.vertices() {
        handle_of[v.data().index] = Some(v.fix());
    }
    let (mut sum, mut sum_weights) = (0.0, 0.0);
    for &k in neighbours {
        let Some(h) = handle_of.get(k).copied().flatten() else {
            continue;
        };
        let v = tri.vertex(h);
        let q = v.position();
        let (du, dv) = (p.x - q.x, p.y - q.y);
        let r2 = du * du + dv * dv;
        if r2 == 0.0 {
            return Some(v.data().e);
        }
        let g = quadratic_gradient(tri, h);
        sum += (v.data().e + du * g[0] + dv * g[1]) / r2;
        sum_weights += 1.0 / r2;
    }
    (sum_weights > 0.0).then(|| sum / sum_weights)
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
}
