//! `grid` never leaves a node inside or on the probes' hull without a finite value: many convex layouts on fine lattices, every method, nodes that rounding puts on or next to the hull's edges.

use errmap_core::geom::Domain;
use errmap_maps::interp::{resample, Grid, Method, Surface};

const METHODS: [Method; 3] = [Method::NaturalNeighbour, Method::SibsonC1, Method::Linear];

/// Lattice points of pitch `pitch_mm` inside (or on) a convex polygon given counter-clockwise.
fn lattice_in(polygon: &[(f64, f64)], pitch_mm: f64) -> Vec<(f64, f64)> {
    let (mut u0, mut v0, mut u1, mut v1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
    for &(u, v) in polygon {
        u0 = u0.min(u);
        v0 = v0.min(v);
        u1 = u1.max(u);
        v1 = v1.max(v);
    }
    let mut pts: Vec<(f64, f64)> = polygon.to_vec();
    let (ni, nj) = (
        ((u1 - u0) / pitch_mm).round() as i64,
        ((v1 - v0) / pitch_mm).round() as i64,
    );
    for j in 0..=nj {
        for i in 0..=ni {
            let (u, v) = (u0 + i as f64 * pitch_mm, v0 + j as f64 * pitch_mm);
            if inside_or_on(polygon, u, v, 1e-12) && !pts.contains(&(u, v)) {
                pts.push((u, v));
            }
        }
    }
    pts
}

/// True when (u, v) is inside the convex counter-clockwise polygon or within `tol` of an edge.
fn inside_or_on(polygon: &[(f64, f64)], u: f64, v: f64, tol: f64) -> bool {
    (0..polygon.len()).all(|k| {
        let (a, b) = (polygon[k], polygon[(k + 1) % polygon.len()]);
        let len = (b.0 - a.0).hypot(b.1 - a.1);
        let cross = (b.0 - a.0) * (v - a.1) - (b.1 - a.1) * (u - a.0);
        cross / len >= -tol
    })
}

fn plane(u: f64, v: f64) -> f64 {
    3.0 + 2.0 * u - 1.5 * v
}

fn layouts() -> Vec<(&'static str, Vec<(f64, f64)>)> {
    vec![
        (
            "diamond",
            vec![(1.0, 0.0), (2.0, 1.0), (1.0, 2.0), (0.0, 1.0)],
        ),
        (
            "square",
            vec![(0.0, 0.0), (2.0, 0.0), (2.0, 2.0), (0.0, 2.0)],
        ),
        ("triangle", vec![(0.0, 0.0), (3.0, 0.0), (0.0, 1.5)]),
        (
            "hexagon",
            vec![
                (1.0, 0.0),
                (2.0, 0.0),
                (3.0, 1.0),
                (2.0, 2.0),
                (1.0, 2.0),
                (0.0, 1.0),
            ],
        ),
        (
            "slanted",
            vec![(0.0, 0.0), (3.0, 0.9), (2.1, 2.7), (-0.9, 1.8)],
        ),
        (
            "offset diamond",
            vec![(101.0, 50.0), (102.0, 51.0), (101.0, 52.0), (100.0, 51.0)],
        ),
    ]
}

#[test]
fn the_node_on_the_diamond_edge_has_the_planes_value() {
    // Node (1.35, 0.35) lies on the edge (1, 0)–(2, 1) of a diamond probed on a 0.3 mm lattice;
    // rounding put it on the hull, and natural-neighbour and Sibson gave no value or NaN there.
    let polygon = [(1.0, 0.0), (2.0, 1.0), (1.0, 2.0), (0.0, 1.0)];
    let uve: Vec<[f64; 3]> = lattice_in(&polygon, 0.3)
        .iter()
        .map(|&(u, v)| [u, v, plane(u, v)])
        .collect();
    let surface = Surface::new(&uve).unwrap();
    for method in METHODS {
        for (u, v) in [
            (1.35, 0.35),
            (0.45, 0.55),
            (1.0 + 0.35, 0.35000000000000003),
        ] {
            let e = surface.sample(method, u, v);
            assert!(
                e.is_some_and(|e| (e - plane(u, v)).abs() < 1e-9),
                "{method} at ({u}, {v}): {e:?}"
            );
        }
    }
}

#[test]
fn no_node_inside_or_on_the_hull_is_left_without_a_finite_value() {
    let mut failures = Vec::new();
    let mut checked = 0usize;
    for (name, polygon) in layouts() {
        for pitch in [0.1, 0.3, 0.25, 0.5] {
            let sites = lattice_in(&polygon, pitch);
            let uve: Vec<[f64; 3]> = sites.iter().map(|&(u, v)| [u, v, plane(u, v)]).collect();
            let surface = Surface::new(&uve).unwrap();
            let b = surface.bounding_box();
            for step in [0.05, 0.1, 0.15, 0.3, 0.35] {
                let domain = Domain {
                    u_min_mm: b.u_min_mm,
                    v_min_mm: b.v_min_mm,
                    u_max_mm: b.u_max_mm,
                    v_max_mm: b.v_max_mm,
                };
                let grid = Grid::covering(&domain, step).unwrap();
                for method in METHODS {
                    let values = resample(&surface, method, &grid);
                    for j in 0..grid.nv {
                        for i in 0..grid.nu {
                            let (u, v) = grid.node(i, j);
                            if !inside_or_on(&polygon, u, v, 1e-9) {
                                continue;
                            }
                            checked += 1;
                            let e = values[j * grid.nu + i];
                            let single = surface.sample(method, u, v);
                            // Every method reproduces a plane, on the hull too.
                            let exact =
                                |x: Option<f64>| x.is_some_and(|x| (x - plane(u, v)).abs() < 1e-9);
                            if !exact(e) || !exact(single) {
                                failures.push(format!(
                                    "{name} pitch {pitch} step {step} {method}: node ({u}, {v}) gave {e:?} (sample {single:?})"
                                ));
                            }
                        }
                    }
                }
            }
        }
    }
    assert!(checked > 10_000, "{checked}");
    assert!(
        failures.is_empty(),
        "{} of {checked} nodes:\n{}",
        failures.len(),
        failures[..failures.len().min(30)].join("\n")
    );
}
