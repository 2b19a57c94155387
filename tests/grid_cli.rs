//! `errmap grid` end to end: the real binary on small probe files, values checked against the plane they were sampled from.

mod common;

use common::errmap;
use std::path::Path;

/// E in µm of the plane the probes are sampled from.
fn plane_um(u: f64, v: f64) -> f64 {
    4.0 + 0.05 * u - 0.08 * v
}

/// Parse `u,v,e` rows after checking the header.
fn read_grid(path: &Path, header: &str) -> Vec<(f64, f64, f64)> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some(header));
    lines
        .map(|l| {
            let f: Vec<f64> = l.split(',').map(|x| x.parse().unwrap()).collect();
            (f[0], f[1], f[2])
        })
        .collect()
}

#[test]
fn grid_of_a_sampled_plane_matches_the_plane() {
    let dir = tempfile::tempdir().unwrap();
    // An irregular layout over 100 × 60 mm whose hull is a quadrilateral missing the
    // corner near (100, 60), and a repeat of one point.
    let sites = [
        (0.0, 0.0),
        (100.0, 0.0),
        (0.0, 60.0),
        (60.0, 60.0),
        (100.0, 20.0),
        (33.0, 17.0),
        (71.0, 41.0),
        (18.0, 44.0),
        (52.0, 8.0),
        (33.0, 17.0),
    ];
    let mut text = String::from("x_mm,y_mm,z_mm\n");
    for (u, v) in sites {
        text.push_str(&format!("{u},{v},{}\n", 12.0 + plane_um(u, v) / 1000.0));
    }
    std::fs::write(dir.path().join("probes.csv"), text).unwrap();
    for method in ["natural-neighbour", "sibson-c1", "linear"] {
        let out = errmap(
            dir.path(),
            &[
                "grid",
                "probes.csv",
                "--method",
                method,
                "--step",
                "5",
                "--nominal-plane",
                "12",
                "-o",
                "grid.csv",
            ],
        );
        out.expect_code(0);
        let stderr = out.stderr.as_str();
        assert!(
            stderr.contains("9 probe points") && stderr.contains(method),
            "{stderr}"
        );
        let rows = read_grid(&dir.path().join("grid.csv"), "x_mm,y_mm,e_um");
        // The default domain is the bounding box 0..100 × 0..60: 21 × 13 nodes, of which those
        // beyond the hull edges (60,60)–(100,20), i.e. x + y > 120, are left out.
        let expected = (0..13)
            .flat_map(|j| (0..21).map(move |i| (5.0 * i as f64, 5.0 * j as f64)))
            .filter(|(u, v)| u + v <= 120.0)
            .count();
        assert_eq!(rows.len(), expected, "{method}");
        for (u, v, e) in rows {
            assert!(
                u + v <= 120.0 + 1e-9,
                "{method}: ({u}, {v}) is outside the hull"
            );
            // The file rounds E to 1e-6 µm; the probe z values carry ~1e-12 mm of decimal rounding.
            assert!(
                (e - plane_um(u, v)).abs() < 1e-5,
                "{method} at ({u}, {v}): {e} vs {}",
                plane_um(u, v)
            );
        }
    }
    let names: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    assert_eq!(
        names.len(),
        2,
        "a temporary file was left behind: {names:?}"
    );
}

#[test]
fn wall_grid_uses_the_plane_axes_names_and_the_given_domain() {
    let dir = tempfile::tempdir().unwrap();
    // Normal x: E along x, mapped over (y, z); nominal per point.
    let mut text = String::from("id,x_mm,y_mm,z_mm,nx_mm,ny_mm,nz_mm\n");
    for (k, (y, z)) in [(0.0, 0.0), (40.0, 0.0), (0.0, 20.0), (40.0, 20.0)]
        .iter()
        .enumerate()
    {
        text.push_str(&format!(
            "w{k},{},{y},{z},-5,{y},{z}\n",
            -5.0 + plane_um(*y, *z) / 1000.0
        ));
    }
    std::fs::write(dir.path().join("wall.csv"), text).unwrap();
    let out = errmap(
        dir.path(),
        &[
            "--quiet",
            "grid",
            "wall.csv",
            "--normal",
            "x",
            "--step",
            "10",
            "--domain",
            "-10,0,40,20",
            "-o",
            "out/wall_grid.csv",
        ],
    );
    out.expect_code(0);
    assert!(out.stderr.is_empty(), "--quiet printed on stderr");
    let rows = read_grid(&dir.path().join("out/wall_grid.csv"), "y_mm,z_mm,e_um");
    // Domain −10..40 × 0..20 at 10 mm: 6 × 3 nodes, the y = −10 column outside the hull.
    assert_eq!(rows.len(), 15);
    assert!(rows.iter().all(|&(y, _, _)| y >= 0.0));
    for (y, z, e) in rows {
        assert!((e - plane_um(y, z)).abs() < 1e-5, "({y}, {z}): {e}");
    }
}

#[test]
fn bad_input_exits_2_naming_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("bad.csv"),
        "x_mm,y_mm,z_mm\n0,0,1\n10,0,1\n0,10,oops\n",
    )
    .unwrap();
    let out = errmap(
        dir.path(),
        &[
            "grid",
            "bad.csv",
            "--step",
            "1",
            "--nominal-plane",
            "1",
            "-o",
            "grid.csv",
        ],
    );
    out.expect_code(2);
    let stderr = out.stderr.as_str();
    assert!(
        stderr.contains("bad.csv:4, column z_mm") && stderr.contains("'oops' is not a number"),
        "{stderr}"
    );
    assert!(
        !dir.path().join("grid.csv").exists(),
        "no output on failure"
    );

    // A step that makes too many nodes, and a malformed domain: usage errors, exit 2.
    std::fs::write(
        dir.path().join("ok.csv"),
        "x_mm,y_mm,z_mm\n0,0,1\n1000,0,1\n0,1000,1\n",
    )
    .unwrap();
    let out = errmap(
        dir.path(),
        &[
            "grid",
            "ok.csv",
            "--step",
            "0.0001",
            "--nominal-plane",
            "1",
            "-o",
            "g.csv",
        ],
    );
    out.expect_code(2);
    assert!(
        out.stderr.contains("more than the limit"),
        "{}",
        out.report()
    );
    let out = errmap(
        dir.path(),
        &[
            "grid",
            "ok.csv",
            "--step",
            "1",
            "--domain",
            "0,0,10",
            "--nominal-plane",
            "1",
            "-o",
            "g.csv",
        ],
    );
    out.expect_code(2);
    assert!(
        out.stderr.contains("has 3 values, not 4"),
        "{}",
        out.report()
    );
}
