//! Probe files: the error sign and axes, repeats, and one test per rejected input, each asserting its message.

use errmap_core::geom::{Axis, Domain};
use errmap_maps::probe::{read_probes, write_points_csv, write_rejected_csv, ProbeSpec, Rejected};
use std::path::PathBuf;

/// Write `text` to a file named `name` in a fresh temp dir; keep the dir alive with the path.
fn file(name: &str, text: &str) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(name);
    std::fs::write(&path, text).unwrap();
    (dir, path)
}

/// A nominal plane, with the plausibility bound out of the way: these tests use round numbers
/// millimetres off the plane (the bound has its own test).
fn plane_spec(z_mm: f64) -> ProbeSpec {
    ProbeSpec {
        normal: Axis::Z,
        nominal_plane_mm: Some(z_mm),
        domain: None,
        max_deviation_mm: 1e6,
        ..ProbeSpec::default()
    }
}

#[test]
fn deviations_beyond_the_bound_name_the_row_and_the_likely_slip() {
    let spec = ProbeSpec {
        nominal_plane_mm: Some(5.0),
        ..ProbeSpec::default()
    };
    // µm written as mm on line 3.
    let err = err_of("x_mm,y_mm,z_mm\n0,0,5.001\n1,0,5002\n0,1,5\n", &spec);
    assert!(
        err.contains("p.csv:3, column z_mm") && err.contains("µm written as mm"),
        "{err}"
    );
    // Inches written as mm: 0.19685 in = 5.0 mm.
    let err = err_of("x_mm,y_mm,z_mm\n0,0,0.19685\n1,0,5\n0,1,5\n", &spec);
    assert!(err.contains("inches written as mm"), "{err}");
    // 15 mm off: no unit explains it.
    let err = err_of("x_mm,y_mm,z_mm\n0,0,5\n1,0,-10\n0,1,5\n", &spec);
    assert!(
        err.contains("p.csv:3") && err.contains("bound of 1 mm") && err.contains("nominal plane"),
        "{err}"
    );
    // Just inside the bound is fine; the bound is a setting.
    let ok = "x_mm,y_mm,z_mm\n0,0,5.999\n1,0,4.001\n0,1,5\n";
    assert!(read_probes(&file("p.csv", ok).1, &spec).is_ok());
    let far = ProbeSpec {
        max_deviation_mm: 20.0,
        ..spec.clone()
    };
    assert!(read_probes(
        &file("p.csv", "x_mm,y_mm,z_mm\n0,0,5\n1,0,-10\n0,1,5\n").1,
        &far
    )
    .is_ok());
}

fn err_of(text: &str, spec: &ProbeSpec) -> String {
    let (_dir, path) = file("p.csv", text);
    read_probes(&path, spec).unwrap_err().to_string()
}

#[test]
fn error_is_measured_minus_nominal_in_micrometres() {
    let (_d, path) = file(
        "p.csv",
        "x_mm,y_mm,z_mm\n10,20,30.012\n110,20,29.995\n10,120,30\n",
    );
    let set = read_probes(&path, &plane_spec(30.0)).unwrap();
    assert_eq!(set.normal, Axis::Z);
    assert_eq!(set.points.len(), 3);
    let p = &set.points[0];
    assert!((p.e_um - 12.0).abs() < 1e-9, "{p:?}");
    assert_eq!((p.u_mm, p.v_mm, p.line), (10.0, 20.0, 2));
    assert_eq!(p.nominal_mm, [10.0, 20.0, 30.0]);
    assert_eq!(p.measured_mm, [10.0, 20.0, 30.012]);
    assert!((set.points[1].e_um + 5.0).abs() < 1e-9);
    assert_eq!(set.points[2].e_um, 0.0);
    assert_eq!((p.repeats, p.spread_um, p.id.clone()), (1, 0.0, None));
}

#[test]
fn nominal_columns_and_a_wall_normal() {
    // Normal x: E along x, map over (y, z) (Axis::plane_axes).
    let (_d, path) = file(
        "wall.csv",
        "id,x_mm,y_mm,z_mm,nx_mm,ny_mm,nz_mm\n\
         a,5.003,10,1,5,10,1\n\
         b,4.998,60,1,5,60,1\n\
         c,5,10,21,5,10,21\n",
    );
    let spec = ProbeSpec {
        normal: Axis::X,
        nominal_plane_mm: Some(99.0), // ignored: the columns win
        domain: None,
        ..ProbeSpec::default()
    };
    let set = read_probes(&path, &spec).unwrap();
    let p: Vec<_> = set.points.iter().map(|p| (p.u_mm, p.v_mm)).collect();
    assert_eq!(p, vec![(10.0, 1.0), (60.0, 1.0), (10.0, 21.0)]);
    assert!((set.points[0].e_um - 3.0).abs() < 1e-9);
    assert!((set.points[1].e_um + 2.0).abs() < 1e-9);
    assert_eq!(set.points[0].id.as_deref(), Some("a"));
    // Normal y: E along y, the plane axes are (z, x).
    let (_d, path) = file(
        "side.csv",
        "x_mm,y_mm,z_mm,nx_mm,ny_mm,nz_mm
0,7.001,0,0,7,0
40,7,0,40,7,0
0,7,25,0,7,25
",
    );
    let spec = ProbeSpec {
        normal: Axis::Y,
        ..spec
    };
    let set = read_probes(&path, &spec).unwrap();
    let p: Vec<_> = set.points.iter().map(|p| (p.u_mm, p.v_mm)).collect();
    assert_eq!(p, vec![(0.0, 0.0), (0.0, 40.0), (25.0, 0.0)]);
    assert!((set.points[0].e_um - 1.0).abs() < 1e-9);
}

#[test]
fn repeats_are_averaged_with_their_spread() {
    // Three readings of (0,0), two of (50,0) with the same id but a hair apart in x.
    let (_d, path) = file(
        "rep.csv",
        "id,x_mm,y_mm,z_mm\n\
         p1,0,0,30.010\n\
         p2,50,0,30.000\n\
         p1,0,0,30.012\n\
         p3,0,50,29.990\n\
         p2,50.0000001,0,30.004\n\
         ,0,0,30.014\n",
    );
    let set = read_probes(&path, &plane_spec(30.0)).unwrap();
    assert_eq!(set.points.len(), 3, "{:?}", set.points);
    let p = &set.points[0];
    assert_eq!((p.repeats, p.line, p.id.as_deref()), (3, 2, Some("p1")));
    // mean of 10, 12, 14 = 12; sample std = sqrt(((−2)² + 0 + 2²)/2) = 2.
    assert!((p.e_um - 12.0).abs() < 1e-9, "{p:?}");
    assert!((p.spread_um - 2.0).abs() < 1e-9, "{p:?}");
    let q = &set.points[1];
    assert_eq!(q.repeats, 2);
    assert!(
        (q.e_um - 2.0).abs() < 1e-9 && (q.spread_um - 8f64.sqrt()).abs() < 1e-9,
        "{q:?}"
    );
    assert_eq!(set.points[2].repeats, 1);
}

#[test]
fn missing_column_is_named() {
    let err = err_of("x_mm,y_mm\n1,2\n", &plane_spec(0.0));
    assert!(
        err.contains("p.csv:1") && err.contains("missing column 'z_mm'"),
        "{err}"
    );
}

#[test]
fn unknown_column_is_named() {
    let err = err_of("x_mm,y_mm,z_mm,z_um\n1,2,3,4\n", &plane_spec(0.0));
    assert!(
        err.contains("p.csv:1, column z_um")
            && err.contains("unknown column 'z_um'")
            && err.contains("hint"),
        "{err}"
    );
}

#[test]
fn incomplete_nominal_columns_are_named() {
    let err = err_of("x_mm,y_mm,z_mm,nx_mm,ny_mm\n1,2,3,1,2\n", &plane_spec(0.0));
    assert!(
        err.contains("p.csv:1") && err.contains("nz_mm missing"),
        "{err}"
    );
}

#[test]
fn non_number_names_line_and_column() {
    let err = err_of("x_mm,y_mm,z_mm\n1,2,3\n4,five,6\n", &plane_spec(0.0));
    assert!(
        err.contains("p.csv:3, column y_mm") && err.contains("'five' is not a number"),
        "{err}"
    );
}

#[test]
fn nan_and_infinity_are_refused() {
    for bad in ["NaN", "inf", "-inf"] {
        let err = err_of(
            &format!("x_mm,y_mm,z_mm\n1,2,3\n\n4,5,{bad}\n"),
            &plane_spec(0.0),
        );
        assert!(
            err.contains("p.csv:4, column z_mm") && err.contains("not a finite number"),
            "{bad}: {err}"
        );
    }
    // Finite coordinates whose deviation overflows: 1e308 mm − (−1e308 mm) is beyond f64.
    let err = err_of(
        "x_mm,y_mm,z_mm,nx_mm,ny_mm,nz_mm
0,0,0,0,0,0
1,0,1e308,1,0,-1e308
0,1,0,0,1,0
",
        &ProbeSpec::default(),
    );
    assert!(
        err.contains("p.csv:3, column z_mm") && err.contains("too large"),
        "{err}"
    );
}

#[test]
fn no_nominal_at_all_is_refused() {
    let spec = ProbeSpec::default();
    let err = err_of("x_mm,y_mm,z_mm\n1,2,3\n", &spec);
    assert!(
        err.contains("p.csv:1")
            && err.contains("no nominal")
            && err.contains("`nominal_plane_mm` MM"),
        "{err}"
    );
}

#[test]
fn fewer_than_three_usable_points() {
    // Four rows, but two are repeats of the other two.
    let err = err_of(
        "x_mm,y_mm,z_mm\n0,0,1\n10,0,1\n0,0,1.001\n10,0,1.002\n",
        &plane_spec(1.0),
    );
    assert!(
        err.contains("p.csv") && err.contains("2 usable point(s)") && err.contains("4 data rows"),
        "{err}"
    );
    let err = err_of("x_mm,y_mm,z_mm\n", &plane_spec(1.0));
    assert!(err.contains("0 usable point(s)"), "{err}");
}

#[test]
fn collinear_points_are_refused() {
    let err = err_of(
        "x_mm,y_mm,z_mm\n0,0,1\n10,5,1\n20,10,1.001\n30,15,1\n",
        &plane_spec(1.0),
    );
    assert!(
        err.contains("p.csv") && err.contains("lie on one line") && err.contains("lines 2 to 5"),
        "{err}"
    );
    // Off the line by 1e-7 of the length is still a line; by 1e-3 it spans an area.
    let ok = "x_mm,y_mm,z_mm\n0,0,1\n1000,0,1\n500,0.5,1\n";
    let (_d, path) = file("ok.csv", ok);
    assert!(read_probes(&path, &plane_spec(1.0)).is_ok());
    let err = err_of(
        "x_mm,y_mm,z_mm\n0,0,1\n1000,0,1\n500,0.0001,1\n",
        &plane_spec(1.0),
    );
    assert!(err.contains("lie on one line"), "{err}");
}

#[test]
fn points_outside_the_domain_name_their_line() {
    let spec = ProbeSpec {
        domain: Some(Domain {
            u_min_mm: 0.0,
            v_min_mm: 0.0,
            u_max_mm: 100.0,
            v_max_mm: 50.0,
        }),
        ..plane_spec(0.0)
    };
    let err = err_of("x_mm,y_mm,z_mm\n0,0,0\n100,50,0\n100,50.5,0\n", &spec);
    assert!(
        err.contains("p.csv:4") && err.contains("outside the domain") && err.contains("y 50.5"),
        "{err}"
    );
}

#[test]
fn missing_file_is_a_read_error() {
    let dir = tempfile::tempdir().unwrap();
    let err = read_probes(&dir.path().join("none.csv"), &plane_spec(0.0)).unwrap_err();
    assert!(matches!(err, errmap_maps::ProbeError::Read(_)), "{err}");
    assert!(err.to_string().contains("none.csv"), "{err}");
}

#[test]
fn points_and_rejected_files_have_their_columns() {
    let (dir, path) = file("p.csv", "x_mm,y_mm,z_mm\n1,2,30.5\n3,4,30\n5,1,30\n");
    let set = read_probes(&path, &plane_spec(30.0)).unwrap();
    let out = dir.path().join("clean.csv");
    write_points_csv(&out, Axis::Z, &set.points).unwrap();
    assert_eq!(
        std::fs::read_to_string(&out).unwrap(),
        "x_mm,y_mm,z_mm,e_um\n1,2,30.5,500\n3,4,30,0\n5,1,30,0\n"
    );
    let out = dir.path().join("rejected.csv");
    let rejected = vec![Rejected {
        point: set.points[0].clone(),
        residual_um: 41.5,
    }];
    write_rejected_csv(&out, &rejected).unwrap();
    assert_eq!(
        std::fs::read_to_string(&out).unwrap(),
        "x_mm,y_mm,z_mm,residual_um\n1,2,30.5,41.5\n"
    );
}

#[test]
fn absurd_but_finite_coordinates_do_not_panic() {
    // 1e300 mm saturates the repeat lookup's cells; 1e-300 is below what the triangulation takes.
    let (_d, path) = file(
        "huge.csv",
        "x_mm,y_mm,z_mm\n1e300,1e300,1\n-1e300,1e300,1\n1e300,-1e300,1\n1e300,1e300,2\n",
    );
    let set = read_probes(&path, &plane_spec(1.0)).unwrap();
    assert_eq!(set.points.len(), 3);
    assert_eq!(set.points[0].repeats, 2);
    // Two sites 1e-300 apart are one site (positions are snapped to 1e-12 of the extent), so
    // two distinct sites remain and the surface is refused.
    let err =
        errmap_maps::interp::Surface::new(&[[0.0, 0.0, 1.0], [1e-300, 0.0, 1.0], [0.0, 1.0, 1.0]])
            .unwrap_err()
            .to_string();
    assert!(err.contains("2 distinct site(s)"), "{err}");
    let err = errmap_maps::interp::Surface::new(&[
        [0.0, 0.0, 1.0],
        [1e-300, 0.0, 1.0],
        [0.0, 1e-300, 1.0],
    ])
    .unwrap_err()
    .to_string();
    assert!(err.contains("cannot triangulate"), "{err}");
}
