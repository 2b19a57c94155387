//! Training sets on a web-plate-like deflection field, shared by the GPU parity tests and the training benchmark.
//!
//! The field is a closed form written here, independent of errmap's synth module, and mirrored
//! by `benches/peers/peers.py`. Included by `#[path]` (not a library API: it is a test workload).

use errmap::geom::Domain;
use errmap::nn::{Normalisation, TrainingSet};

/// The plate: 600 × 300 mm from the origin.
pub fn domain() -> Domain {
    Domain {
        u_min_mm: 0.0,
        v_min_mm: 0.0,
        u_max_mm: 600.0,
        v_max_mm: 300.0,
    }
}

/// e(u, v) of part k in µm (±40 µm sag, a 6 µm tilt along u, a part-dependent tilt along v).
pub fn field_um(u_mm: f64, v_mm: f64, k: usize) -> f64 {
    use std::f64::consts::PI;
    -40.0 * (PI * u_mm / 600.0).sin() * (PI * v_mm / 300.0).sin()
        + 6.0 * (u_mm / 600.0 - 0.5)
        + 0.5 * k as f64 * (v_mm / 300.0)
}

/// One training set per `(nu, nv)` grid over the plate (part k = its index, u fastest), with
/// the Normalisation of each.
pub fn sets(sizes: &[(usize, usize)]) -> (Vec<TrainingSet>, Vec<Normalisation>) {
    let mut out = Vec::new();
    let mut norms = Vec::new();
    for (k, &(nu, nv)) in sizes.iter().enumerate() {
        let points: Vec<(f64, f64, f64)> = (0..nv)
            .flat_map(|j| (0..nu).map(move |i| (i, j)))
            .map(|(i, j)| {
                let u = 600.0 * i as f64 / (nu - 1) as f64;
                let v = 300.0 * j as f64 / (nv - 1) as f64;
                (u, v, field_um(u, v, k))
            })
            .collect();
        let e: Vec<f64> = points.iter().map(|p| p.2).collect();
        let norm = Normalisation::new(&domain(), &e);
        out.push(TrainingSet {
            inputs: points.iter().map(|p| norm.scale_input(p.0, p.1)).collect(),
            targets: points.iter().map(|p| norm.scale_target(p.2)).collect(),
        });
        norms.push(norm);
    }
    (out, norms)
}
