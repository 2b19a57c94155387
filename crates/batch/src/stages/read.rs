//! Stage 1, read and clean: a part's probe file ([`PartInput`]) read, repeats merged, gross errors rejected and the hold-out points chosen ([`Prepared`]), or the part's failure.

use crate::plan::{PartInput, Settings};
use crate::summary::PartSummary;
use errmap_core::error::Diagnostic;
use errmap_core::geom::Domain;
use errmap_maps::probe::{self, ProbePoint, ProbeSpec, Rejected};
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

/// A part after reading and cleaning.
pub(crate) struct Prepared {
    pub(crate) input: PartInput,
    pub(crate) points: usize,
    pub(crate) repeats_averaged: usize,
    pub(crate) preamble_lines: usize,
    pub(crate) skipped_features: usize,
    pub(crate) clean: Vec<ProbePoint>,
    pub(crate) rejected: Vec<Rejected>,
    pub(crate) sigma_um: f64,
    pub(crate) holdout: Vec<usize>,
}

/// A part read and cleaned, or why not.
pub(crate) type Prep = std::result::Result<Prepared, Box<(PartInput, Diagnostic)>>;

/// Read and clean the parts of one chunk (rayon).
pub(crate) fn prepare_chunk(chunk: &[PartInput], s: &Settings) -> Vec<Prep> {
    chunk.par_iter().map(|p| prepare(p.clone(), s)).collect()
}

pub(crate) fn prepare(
    input: PartInput,
    s: &Settings,
) -> std::result::Result<Prepared, Box<(PartInput, Diagnostic)>> {
    let spec = ProbeSpec {
        normal: s.normal,
        nominal_plane_mm: s.nominal_plane_mm,
        domain: s.domain,
        max_deviation_mm: s.max_deviation_mm,
        columns: s.columns.clone(),
        header_line: s.header_line,
    };
    let bound_mb = probe::budget::max_memory_mb(s.max_memory_mb);
    if let Err(e) = probe::budget::check(&input.probe_file, bound_mb) {
        return Err(Box::new((input, e)));
    }
    let (set, preamble_lines, skipped_features) =
        match probe::read_probe_file(&input.probe_file, &spec) {
            Ok(read) => (read.set, read.preamble_lines, read.skipped_features),
            Err(e) => return Err(Box::new((input, e.into()))),
        };
    let cleaned = match probe::reject_gross_errors(&set, s.k_sigma) {
        Ok(c) => c,
        Err(e) => return Err(Box::new((input, e.into()))),
    };
    let rows: u32 = set.points.iter().map(|p| p.repeats).sum();
    let holdout = choose_holdout(
        &cleaned.clean,
        s.model.holdout_fraction,
        s.model.seed,
        &input.name,
    );
    Ok(Prepared {
        points: set.points.len(),
        repeats_averaged: (rows as usize).saturating_sub(set.points.len()),
        preamble_lines,
        skipped_features,
        clean: cleaned.clean,
        rejected: cleaned.rejected,
        sigma_um: cleaned.sigma_um,
        holdout,
        input,
    })
}

/// Most held-out points of a part: 10,000 misses give its hold-out RMS to better than 1 %, and
/// more would only slow the hold-out checks of a dense scan's training.
pub const MAX_HOLDOUT_POINTS: usize = 10_000;

/// Seeded choice of the held-out points: interior points only (the hull stays the same, so the
/// hold-out fit is judged where it interpolates), `round(fraction · n)` of them, at least one
/// and at most [`MAX_HOLDOUT_POINTS`].
pub(crate) fn choose_holdout(
    clean: &[ProbePoint],
    fraction: f64,
    seed: u64,
    name: &str,
) -> Vec<usize> {
    if fraction <= 0.0 || clean.len() < 8 {
        return Vec::new();
    }
    let boundary = hull_boundary(clean);
    let mut candidates: Vec<usize> = (0..clean.len()).filter(|&i| !boundary[i]).collect();
    let want = ((fraction * clean.len() as f64).round() as usize).clamp(1, MAX_HOLDOUT_POINTS);
    let want = want
        .min(candidates.len())
        .min(clean.len().saturating_sub(5));
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ crate::train_step::fnv1a(name));
    candidates.shuffle(&mut rng);
    let mut chosen: Vec<usize> = candidates.into_iter().take(want).collect();
    chosen.sort_unstable();
    chosen
}

/// Which points lie on the boundary of their convex hull (vertices and points on its edges).
pub(crate) fn hull_boundary(points: &[ProbePoint]) -> Vec<bool> {
    let uv: Vec<[f64; 2]> = points.iter().map(|p| [p.u_mm, p.v_mm]).collect();
    let hull = errmap_core::geom::convex_hull(&uv);
    if hull.len() < 2 {
        return vec![true; points.len()];
    }
    let scale = uv
        .iter()
        .map(|q| q[0].abs().max(q[1].abs()))
        .fold(1.0, f64::max);
    let on_edge = |a: [f64; 2], b: [f64; 2], q: [f64; 2]| {
        let (du, dv) = (b[0] - a[0], b[1] - a[1]);
        let len = du.hypot(dv);
        let cross = du * (q[1] - a[1]) - dv * (q[0] - a[0]);
        let t = ((q[0] - a[0]) * du + (q[1] - a[1]) * dv) / (len * len);
        len > 0.0 && (cross / len).abs() <= 1e-9 * scale && (-1e-12..=1.0 + 1e-12).contains(&t)
    };
    uv.iter()
        .map(|&q| (0..hull.len()).any(|k| on_edge(hull[k], hull[(k + 1) % hull.len()], q)))
        .collect()
}

/// Bounding box of every clean point of the batch.
pub(crate) fn union_box(parts: &[Prepared]) -> Option<Domain> {
    let mut all: Option<Domain> = None;
    for p in parts {
        if let Some(b) = probe::bounding_box(&p.clean) {
            all = Some(match all {
                None => b,
                Some(a) => Domain {
                    u_min_mm: a.u_min_mm.min(b.u_min_mm),
                    v_min_mm: a.v_min_mm.min(b.v_min_mm),
                    u_max_mm: a.u_max_mm.max(b.u_max_mm),
                    v_max_mm: a.v_max_mm.max(b.v_max_mm),
                },
            });
        }
    }
    all
}

pub(crate) fn union_box_of(a: Domain, b: Domain) -> Option<Domain> {
    Some(Domain {
        u_min_mm: a.u_min_mm.min(b.u_min_mm),
        v_min_mm: a.v_min_mm.min(b.v_min_mm),
        u_max_mm: a.u_max_mm.max(b.u_max_mm),
        v_max_mm: a.v_max_mm.max(b.v_max_mm),
    })
}

/// The summary of a part that failed.
pub(crate) fn failed_part(input: &PartInput, e: &Diagnostic) -> PartSummary {
    PartSummary::failed(&input.name, &input.probe_file, e)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid_points(nx: usize, ny: usize) -> Vec<ProbePoint> {
        let mut pts = Vec::new();
        for j in 0..ny {
            for i in 0..nx {
                pts.push(ProbePoint {
                    id: None,
                    line: (pts.len() + 2) as u64,
                    measured_mm: [i as f64 * 10.0, j as f64 * 5.0, 0.0],
                    nominal_mm: [i as f64 * 10.0, j as f64 * 5.0, 0.0],
                    u_mm: i as f64 * 10.0,
                    v_mm: j as f64 * 5.0,
                    e_um: 0.0,
                    repeats: 1,
                    spread_um: 0.0,
                });
            }
        }
        pts
    }

    #[test]
    fn hull_boundary_is_the_outer_ring_of_a_grid() {
        let pts = grid_points(5, 4);
        let on = hull_boundary(&pts);
        for (k, p) in pts.iter().enumerate() {
            let ring = p.u_mm == 0.0 || p.u_mm == 40.0 || p.v_mm == 0.0 || p.v_mm == 15.0;
            assert_eq!(on[k], ring, "point {k} at ({}, {})", p.u_mm, p.v_mm);
        }
        // 5 × 4 grid: 14 ring points, 6 interior.
        assert_eq!(on.iter().filter(|&&b| b).count(), 14);
    }

    #[test]
    fn holdout_takes_a_tenth_of_interior_points_seeded_by_part_name() {
        let pts = grid_points(12, 12);
        let on = hull_boundary(&pts);
        let a = choose_holdout(&pts, 0.1, 1, "p01");
        // round(0.1 · 144) = 14 points, none on the hull, sorted, distinct.
        assert_eq!(a.len(), 14);
        assert!(a.iter().all(|&i| !on[i]));
        assert!(a.windows(2).all(|w| w[0] < w[1]));
        assert_eq!(a, choose_holdout(&pts, 0.1, 1, "p01"));
        assert_ne!(a, choose_holdout(&pts, 0.1, 1, "p02"));
        assert!(choose_holdout(&pts, 0.0, 1, "p01").is_empty());
        // Too few points to spare any.
        assert!(choose_holdout(&grid_points(2, 3), 0.1, 1, "p01").is_empty());
    }
}
