//! Synthetic training work for throughput measurements: a family of web-plate-like deflection fields on a grid, the workload of `errmap bench training` and `benches/peers/peers.py`.

use super::{Normalisation, TrainingSet};
use errmap_core::geom::Domain;

/// The plate: 600 × 300 mm from the origin.
pub fn plate_domain() -> Domain {
    Domain {
        u_min_mm: 0.0,
        v_min_mm: 0.0,
        u_max_mm: 600.0,
        v_max_mm: 300.0,
    }
}

/// e(u, v) of part k in µm: a ±40 µm sag, a 6 µm tilt along u, a part-dependent tilt along v.
pub fn plate_field_um(u_mm: f64, v_mm: f64, k: usize) -> f64 {
    use std::f64::consts::PI;
    -40.0 * (PI * u_mm / 600.0).sin() * (PI * v_mm / 300.0).sin()
        + 6.0 * (u_mm / 600.0 - 0.5)
        + 0.5 * k as f64 * (v_mm / 300.0)
}

/// Grid columns and rows for `samples` points, 3 columns to 2 rows (the plate itself is 2:1,
/// so the nodes lie closer along v than along u)
/// (1536 samples → 48 × 32, the benchmark's grid).
pub fn plate_grid(samples: usize) -> (usize, usize) {
    let nu = ((1.5 * samples as f64).sqrt().ceil() as usize).max(2);
    let nv = samples.div_ceil(nu).max(2);
    (nu, nv)
}

/// `parts` training sets of `samples` points each (the first `samples` nodes of
/// [`plate_grid`], u fastest), standardised like a part's training set.
pub fn plate_family(parts: usize, samples: usize) -> Vec<TrainingSet> {
    let (nu, nv) = plate_grid(samples);
    (0..parts)
        .map(|k| {
            let points: Vec<(f64, f64, f64)> = (0..nv)
                .flat_map(|j| (0..nu).map(move |i| (i, j)))
                .take(samples)
                .map(|(i, j)| {
                    let u = 600.0 * i as f64 / (nu - 1) as f64;
                    let v = 300.0 * j as f64 / (nv - 1) as f64;
                    (u, v, plate_field_um(u, v, k))
                })
                .collect();
            let e: Vec<f64> = points.iter().map(|p| p.2).collect();
            let norm = Normalisation::new(&plate_domain(), &e);
            TrainingSet {
                inputs: points.iter().map(|p| norm.scale_input(p.0, p.1)).collect(),
                targets: points.iter().map(|p| norm.scale_target(p.2)).collect(),
            }
        })
        .collect()
}
