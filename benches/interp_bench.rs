//! Benches of probe reading, gross-error rejection and grid resampling on the seed-001 plate (144 probes, 600 × 300 mm).
//!
//! The probe file is `benches/peers/plate_144.csv`, the same file `benches/peers/griddata_peer.py`
//! gives scipy's `griddata`, so the two timings compare the same work: triangulate 144 points and
//! interpolate all 1201 × 601 nodes of a 0.5 mm grid.

use criterion::{BenchmarkId, Criterion};
use errmap::geom::{Axis, Domain};
use errmap::interp::{resample, Grid, Method, Surface};
use errmap::probe::{read_probes, reject_gross_errors, ProbeSet, ProbeSpec};
use std::hint::black_box;
use std::path::Path;

fn plate() -> ProbeSet {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/peers/plate_144.csv");
    let spec = ProbeSpec {
        normal: Axis::Z,
        nominal_plane_mm: Some(30.0),
        domain: None,
        ..ProbeSpec::default()
    };
    read_probes(&path, &spec).expect("benches/peers/plate_144.csv")
}

pub fn interp_benches(c: &mut Criterion) {
    let set = plate();
    let uve = set.uve();
    let domain = Domain {
        u_min_mm: 0.0,
        v_min_mm: 0.0,
        u_max_mm: 600.0,
        v_max_mm: 300.0,
    };

    let mut group = c.benchmark_group("interp/resample_plate");
    group.sample_size(10);
    for step_mm in [2.0, 0.5] {
        let grid = Grid::covering(&domain, step_mm).expect("grid");
        for method in [Method::NaturalNeighbour, Method::SibsonC1, Method::Linear] {
            group.bench_with_input(
                BenchmarkId::new(method.name(), format!("{step_mm}mm_{}nodes", grid.len())),
                &grid,
                |b, grid| {
                    b.iter(|| {
                        // Triangulation and gradients included, as scipy's griddata does both.
                        let surface = Surface::new(black_box(&uve)).expect("surface");
                        resample(&surface, method, grid)
                    })
                },
            );
        }
    }
    group.finish();

    let mut group = c.benchmark_group("probe");
    group.sample_size(10);
    group.bench_function("reject_gross_errors_144", |b| {
        b.iter(|| reject_gross_errors(black_box(&set), 3.0).expect("clean"))
    });
    group.bench_function("surface_new_144", |b| {
        b.iter(|| Surface::new(black_box(&uve)).expect("surface"))
    });
    group.finish();
}
