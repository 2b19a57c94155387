//! Interpolation checked against closed forms: plane reproduction, exactness at the sites, Sibson C1 on a quadratic, hull limits, grids.

use errmap_core::geom::Domain;
use errmap_maps::interp::{resample, Grid, Method, Surface};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const METHODS: [Method; 3] = [Method::NaturalNeighbour, Method::SibsonC1, Method::Linear];

/// Seeded scattered sites in a 600 × 300 mm plate, plus its four corners so the hull is the plate.
fn scattered_sites(n: usize, seed: u64) -> Vec<(f64, f64)> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut sites = vec![(0.0, 0.0), (600.0, 0.0), (600.0, 300.0), (0.0, 300.0)];
    for _ in 0..n {
        sites.push((rng.random_range(0.0..600.0), rng.random_range(0.0..300.0)));
    }
    sites
}

fn plane(u: f64, v: f64) -> f64 {
    12.5 + 0.031 * u - 0.047 * v
}

/// A quadratic with all three second-order terms (µm over mm).
fn quadratic(u: f64, v: f64) -> f64 {
    let (x, y) = (u - 300.0, v - 150.0);
    5.0 + 0.01 * x - 0.02 * y + 4e-4 * x * x - 3e-4 * x * y + 6e-4 * y * y
}

fn surface_of(sites: &[(f64, f64)], f: fn(f64, f64) -> f64) -> Surface {
    let uve: Vec<[f64; 3]> = sites.iter().map(|&(u, v)| [u, v, f(u, v)]).collect();
    Surface::new(&uve).unwrap()
}

#[test]
fn every_method_reproduces_a_plane_inside_the_hull() {
    let sites = scattered_sites(140, 1);
    let surface = surface_of(&sites, plane);
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    for _ in 0..2000 {
        let (u, v) = (rng.random_range(0.0..600.0), rng.random_range(0.0..300.0));
        for method in METHODS {
            let e = surface
                .sample(method, u, v)
                .unwrap_or_else(|| panic!("{method} gave None at ({u}, {v}) inside the hull"));
            assert!(
                (e - plane(u, v)).abs() < 1e-9,
                "{method} at ({u}, {v}): {e} vs {}",
                plane(u, v)
            );
        }
    }
    // On a hull edge too (two-point interpolation along the edge).
    for method in METHODS {
        let e = surface.sample(method, 250.0, 0.0).unwrap();
        assert!((e - plane(250.0, 0.0)).abs() < 1e-9, "{method}: {e}");
    }
}

#[test]
fn resampled_grid_of_a_plane_matches_the_plane_at_every_node() {
    let sites = scattered_sites(60, 3);
    let surface = surface_of(&sites, plane);
    let domain = Domain {
        u_min_mm: 0.0,
        v_min_mm: 0.0,
        u_max_mm: 600.0,
        v_max_mm: 300.0,
    };
    let grid = Grid::covering(&domain, 10.0).unwrap();
    assert_eq!((grid.nu, grid.nv), (61, 31));
    for method in METHODS {
        let values = resample(&surface, method, &grid);
        assert_eq!(values.len(), 61 * 31);
        for j in 0..grid.nv {
            for i in 0..grid.nu {
                let (u, v) = grid.node(i, j);
                let e = values[j * grid.nu + i]
                    .unwrap_or_else(|| panic!("{method}: node ({u}, {v}) is inside the plate"));
                assert!(
                    (e - plane(u, v)).abs() < 1e-9,
                    "{method} at ({u}, {v}): {e}"
                );
            }
        }
    }
}

#[test]
fn a_quadratic_is_reproduced_exactly_at_the_sites() {
    let sites = scattered_sites(80, 4);
    let surface = surface_of(&sites, quadratic);
    for &(u, v) in &sites {
        for method in METHODS {
            let e = surface.sample(method, u, v).unwrap();
            assert!(
                (e - quadratic(u, v)).abs() < 1e-9,
                "{method} at ({u}, {v}): {e}"
            );
        }
    }
}

#[test]
fn sibson_c1_follows_a_quadratic_better_than_natural_neighbour() {
    // 12 × 12 probe grid over the plate, as in seed 001.
    let mut sites = Vec::new();
    for j in 0..12 {
        for i in 0..12 {
            sites.push((600.0 * i as f64 / 11.0, 300.0 * j as f64 / 11.0));
        }
    }
    let surface = surface_of(&sites, quadratic);
    let (mut se_nn, mut se_c1, mut n) = (0.0, 0.0, 0.0);
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    for _ in 0..3000 {
        let (u, v) = (rng.random_range(0.0..600.0), rng.random_range(0.0..300.0));
        let truth = quadratic(u, v);
        se_nn += (surface.sample(Method::NaturalNeighbour, u, v).unwrap() - truth).powi(2);
        se_c1 += (surface.sample(Method::SibsonC1, u, v).unwrap() - truth).powi(2);
        n += 1.0;
    }
    let (rms_nn, rms_c1) = ((se_nn / n).sqrt(), (se_c1 / n).sqrt());
    // Natural neighbour misses the curvature between sites (~h²·f''/8 ≈ 0.1 µm here);
    // Sibson C1 with exact quadratic gradients leaves only its non-spherical part.
    assert!(rms_nn > 0.05, "natural neighbour rms {rms_nn}");
    assert!(
        rms_c1 < 0.25 * rms_nn,
        "C1 rms {rms_c1} vs natural neighbour {rms_nn}"
    );
}

#[test]
fn sibson_c1_reproduces_a_spherical_quadratic() {
    // Sibson's C1 interpolant with exact gradients is exact for a + b·u + c·v + d·(u² + v²).
    let f = |u: f64, v: f64| {
        2.0 + 0.01 * u - 0.03 * v + 1e-4 * ((u - 300.0).powi(2) + (v - 150.0).powi(2))
    };
    let sites = scattered_sites(150, 6);
    let uve: Vec<[f64; 3]> = sites.iter().map(|&(u, v)| [u, v, f(u, v)]).collect();
    let surface = Surface::new(&uve).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    // Inside, away from the hull where the second-ring fits are one-sided but still exact.
    for _ in 0..500 {
        let (u, v) = (rng.random_range(50.0..550.0), rng.random_range(50.0..250.0));
        let e = surface.sample(Method::SibsonC1, u, v).unwrap();
        assert!(
            (e - f(u, v)).abs() < 1e-6,
            "at ({u}, {v}): {e} vs {}",
            f(u, v)
        );
    }
}

#[test]
fn outside_the_hull_is_none() {
    // A triangle: its bounding box holds points outside the hull.
    let surface = Surface::new(&[[0.0, 0.0, 1.0], [100.0, 0.0, 2.0], [0.0, 100.0, 3.0]]).unwrap();
    for method in METHODS {
        assert!(surface.sample(method, 10.0, 10.0).is_some(), "{method}");
        assert_eq!(surface.sample(method, 80.0, 80.0), None, "{method}");
        assert_eq!(surface.sample(method, -1.0, 10.0), None, "{method}");
        assert_eq!(surface.sample(method, 10.0, 100.5), None, "{method}");
        assert_eq!(surface.sample(method, f64::NAN, 10.0), None, "{method}");
    }
    let grid = Grid::covering(
        &Domain {
            u_min_mm: -50.0,
            v_min_mm: 0.0,
            u_max_mm: 100.0,
            v_max_mm: 100.0,
        },
        50.0,
    )
    .unwrap();
    let values = resample(&surface, Method::NaturalNeighbour, &grid);
    let inside: Vec<(usize, usize)> = (0..grid.nv)
        .flat_map(|j| (0..grid.nu).map(move |i| (i, j)))
        .filter(|&(i, j)| values[j * grid.nu + i].is_some())
        .collect();
    // Nodes with u ≥ 0, v ≥ 0 and u + v ≤ 100 (the hull, edges included).
    assert_eq!(
        inside,
        vec![(1, 0), (2, 0), (3, 0), (1, 1), (2, 1), (1, 2)],
        "{values:?}"
    );
}

#[test]
fn surface_rejects_degenerate_sites() {
    let err = Surface::new(&[[0.0, 0.0, 1.0], [1.0, 1.0, 2.0]])
        .unwrap_err()
        .to_string();
    assert!(err.contains("at least 3"), "{err}");
    let err = Surface::new(&[
        [0.0, 0.0, 1.0],
        [1.0, 1.0, 2.0],
        [2.0, 2.0, 3.0],
        [3.0, 3.0, 1.0],
    ])
    .unwrap_err()
    .to_string();
    assert!(err.contains("one line"), "{err}");
    let err = Surface::new(&[[0.0, 0.0, f64::NAN], [1.0, 0.0, 2.0], [0.0, 1.0, 3.0]])
        .unwrap_err()
        .to_string();
    assert!(err.contains("not a finite number"), "{err}");
    // Duplicates are merged by averaging: the site value is the mean.
    let s = Surface::new(&[
        [0.0, 0.0, 1.0],
        [0.0, 0.0, 3.0],
        [1.0, 0.0, 2.0],
        [0.0, 1.0, 2.0],
    ])
    .unwrap();
    assert_eq!(s.num_sites(), 3);
    assert!((s.sample(Method::Linear, 0.0, 0.0).unwrap() - 2.0).abs() < 1e-12);
}

#[test]
fn grid_covering_counts_nodes_and_refuses_bad_steps() {
    let plate = Domain {
        u_min_mm: 0.0,
        v_min_mm: 0.0,
        u_max_mm: 600.0,
        v_max_mm: 300.0,
    };
    let g = Grid::covering(&plate, 0.5).unwrap();
    assert_eq!((g.nu, g.nv, g.len()), (1201, 601, 1201 * 601));
    assert_eq!(g.node(1200, 600), (600.0, 300.0));
    // 0.1 does not divide evenly in binary; 600/0.1 must still give 6001 nodes.
    assert_eq!(Grid::covering(&plate, 0.1).unwrap().nu, 6001);
    // Not a multiple: the last node stays inside.
    let g = Grid::covering(&plate, 7.0).unwrap();
    assert_eq!((g.nu, g.nv), (86, 43));
    for step in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let err = Grid::covering(&plate, step).unwrap_err().to_string();
        assert!(err.contains("not a positive number"), "{step}: {err}");
    }
    let err = Grid::covering(&plate, 0.01).unwrap_err().to_string();
    assert!(
        err.contains("more than the limit") && err.contains("larger step"),
        "{err}"
    );
    let flipped = Domain {
        u_min_mm: 10.0,
        ..plate
    };
    let flipped = Domain {
        u_max_mm: 5.0,
        ..flipped
    };
    let err = Grid::covering(&flipped, 1.0).unwrap_err();
    assert_eq!(err.kind(), "input", "{err}");
    assert!(
        err.to_string()
            .contains("is not a rectangle with min ≤ max"),
        "{err}"
    );
}

#[test]
fn method_names_match_the_command_line_and_files() {
    for (m, name) in [
        (Method::NaturalNeighbour, "natural-neighbour"),
        (Method::SibsonC1, "sibson-c1"),
        (Method::Linear, "linear"),
    ] {
        assert_eq!(m.to_string(), name);
        assert_eq!(serde_json::to_string(&m).unwrap(), format!("\"{name}\""));
    }
}

/// `resample` finds natural neighbours with its own row sweep; `Surface::sample` goes through
/// spade's walk and exact predicates. The two must agree node for node, inside and outside.
#[test]
fn resample_sweep_agrees_with_spade_point_queries() {
    fn wavy(u: f64, v: f64) -> f64 {
        30.0 * (u / 90.0).sin() * (v / 70.0).cos() + 0.01 * u
    }
    // Scattered sites (irregular hull) and the regular 12 × 12 layout (cocircular quadruples,
    // nodes on grid lines through Delaunay edges).
    let mut layouts: Vec<Vec<(f64, f64)>> = vec![scattered_sites(150, 8)[4..].to_vec()];
    let mut regular = Vec::new();
    for j in 0..12 {
        for i in 0..12 {
            regular.push((600.0 * i as f64 / 11.0, 300.0 * j as f64 / 11.0));
        }
    }
    layouts.push(regular);
    let domain = Domain {
        u_min_mm: -10.0,
        v_min_mm: -10.0,
        u_max_mm: 610.0,
        v_max_mm: 310.0,
    };
    let grid = Grid::covering(&domain, 2.5).unwrap();
    for (n, sites) in layouts.iter().enumerate() {
        let surface = surface_of(sites, wavy);
        for method in [Method::NaturalNeighbour, Method::SibsonC1] {
            let values = resample(&surface, method, &grid);
            let mut inside = 0;
            for j in 0..grid.nv {
                for i in 0..grid.nu {
                    let (u, v) = grid.node(i, j);
                    let expected = surface.sample(method, u, v);
                    let got = values[j * grid.nu + i];
                    match (got, expected) {
                        (Some(g), Some(e)) => {
                            inside += 1;
                            assert!(
                                (g - e).abs() < 1e-8,
                                "layout {n} {method} at ({u}, {v}): {g} vs {e}"
                            )
                        }
                        (None, None) => {}
                        _ => panic!("layout {n} {method} at ({u}, {v}): {got:?} vs {expected:?}"),
                    }
                }
            }
            assert!(inside > grid.len() / 2, "layout {n}: {inside} nodes inside");
        }
    }
}
