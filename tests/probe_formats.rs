//! Probe files as instruments write them: CSV exports through a column mapping (header after a preamble, units, column numbers, point vectors), DMIS output, XYZ and PLY point clouds; every E value computed by hand in the comments, every refusal's place asserted.

mod common;

use common::errmap;
use errmap::geom::Axis;
use errmap::probe::{read_probe_file, read_probes, ProbeRead, ProbeSpec};
use std::path::{Path, PathBuf};

/// Write `bytes` to `name` in a fresh temp dir; keep the dir alive with the path.
fn file(name: &str, bytes: &[u8]) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(name);
    std::fs::write(&path, bytes).unwrap();
    (dir, path)
}

fn spec(columns: Option<&str>, plane: Option<f64>) -> ProbeSpec {
    ProbeSpec {
        columns: columns.map(str::to_string),
        nominal_plane_mm: plane,
        ..ProbeSpec::default()
    }
}

fn read(name: &str, text: &[u8], spec: &ProbeSpec) -> ProbeRead {
    let (_d, path) = file(name, text);
    read_probe_file(&path, spec).unwrap_or_else(|e| panic!("{name}: {e}"))
}

fn err(name: &str, text: &[u8], spec: &ProbeSpec) -> String {
    let (_d, path) = file(name, text);
    match read_probes(&path, spec) {
        Ok(_) => panic!("{name} was read"),
        Err(e) => e.to_string(),
    }
}

/// (line, id, e_um) of every point.
fn points(r: &ProbeRead) -> Vec<(u64, Option<String>, f64)> {
    r.set
        .points
        .iter()
        .map(|p| (p.line, p.id.clone(), p.e_um))
        .collect()
}

#[track_caller]
fn assert_e(got: &[(u64, Option<String>, f64)], want: &[(u64, &str, f64)]) {
    assert_eq!(got.len(), want.len(), "{got:?}");
    for (g, w) in got.iter().zip(want) {
        assert_eq!(g.0, w.0, "line of {got:?}");
        if !w.1.is_empty() {
            assert_eq!(g.1.as_deref(), Some(w.1), "{got:?}");
        }
        assert!(
            (g.2 - w.2).abs() < 1e-6,
            "E {} µm, want {} ({got:?})",
            g.2,
            w.2
        );
    }
}

/// A Vision-CMM-like flatness export: a date line, then `POINT,X,Y,Z,I,J,K`.
const VISION: &str = "03/14/2025 10:42:07\n\
POINT,X,Y,Z,I,J,K\n\
1,0,0,10.002,0,0,1\n\
2,50,0,9.997,0,0,1\n\
3,0,50,10.0005,0,0,1\n\
4,50,50,10.001,0,0,1\n";

const VISION_MAP: &str = "x=X,y=Y,z=Z,i=I,j=J,k=K,id=POINT";

#[test]
fn a_cmm_export_with_a_date_line_reads_with_one_mapping() {
    // Nominal plane z = 10, vectors (0,0,1): E = (z − 10)·1000 µm.
    let r = read(
        "flat.csv",
        VISION.as_bytes(),
        &spec(Some(VISION_MAP), Some(10.0)),
    );
    assert_eq!(r.preamble_lines, 1);
    assert_e(
        &points(&r),
        &[(3, "1", 2.0), (4, "2", -3.0), (5, "3", 0.5), (6, "4", 1.0)],
    );
    // Without the mapping the date line is the header, as before: refused at the next line.
    let e = err("flat.csv", VISION.as_bytes(), &spec(None, Some(10.0)));
    assert!(
        e.contains("flat.csv:2: 7 fields, but the header names 1 columns"),
        "{e}"
    );
    // … and the hint points to the mapping (its key: the library is called without the binary's
    // wording of flags).
    assert!(e.contains("`columns` x=…,y=…,z=…"), "{e}");
}

#[test]
fn the_header_rule_skips_titles_and_counts_them_and_header_line_overrides() {
    // Two title lines with commas, a blank line and a comment (not counted), then the header.
    let text = "Part,Web plate 7\nProgram,FLAT-01,rev B\n\n# exported\n\
                Pt,Xm,Ym,Zm,Extra\n\
                a,0,0,5.004,x\nb,40,0,4.999,y\nc,0,30,5,z\n";
    let map = "x=Xm,y=Ym,z=Zm,id=Pt";
    let r = read("t.csv", text.as_bytes(), &spec(Some(map), Some(5.0)));
    assert_eq!(r.preamble_lines, 2);
    // Unmapped column Extra is ignored; E = (z − 5)·1000.
    assert_e(&points(&r), &[(6, "a", 4.0), (7, "b", -1.0), (8, "c", 0.0)]);
    // --header-line 5 gives the same points; lines 1, 2 counted.
    let s = ProbeSpec {
        header_line: Some(5),
        ..spec(Some(map), Some(5.0))
    };
    let r = read("t.csv", text.as_bytes(), &s);
    assert_eq!(r.preamble_lines, 2);
    assert_e(&points(&r), &[(6, "a", 4.0), (7, "b", -1.0), (8, "c", 0.0)]);
    // --header-line also works for errmap's own columns after a title.
    let own = "Flatness of plate 7\nx_mm,y_mm,z_mm\n0,0,5.004\n40,0,4.999\n0,30,5\n";
    let s = ProbeSpec {
        header_line: Some(2),
        ..spec(None, Some(5.0))
    };
    let r = read("own.csv", own.as_bytes(), &s);
    assert_eq!(r.preamble_lines, 1);
    assert_e(&points(&r), &[(3, "", 4.0), (4, "", -1.0), (5, "", 0.0)]);
    // A bad value after a preamble names the file's own line and the export's column.
    let bad = "Part,7\nPt,Xm,Ym,Zm\na,0,0,5\nb,40,zero,5\nc,0,30,5\n";
    let e = err("b.csv", bad.as_bytes(), &spec(Some(map), Some(5.0)));
    assert!(
        e.contains("b.csv:4, column Ym") && e.contains("'zero' is not a number"),
        "{e}"
    );
    // A header line past the end of the file.
    let s = ProbeSpec {
        header_line: Some(40),
        ..spec(Some(map), Some(5.0))
    };
    let e = err("t.csv", text.as_bytes(), &s);
    assert!(e.contains("line 40 cannot be its header"), "{e}");
}

#[test]
fn units_and_column_numbers_convert_to_mm() {
    // z in µm, nominal z in µm: E = (5002 − 5000) µm = 2; (4996.5 − 5000) = −3.5; x, y in mm.
    let text = "X,Y,Z,NX,NY,NZ\n0,0,5002,0,0,5000\n10,0,4996.5,10,0,5000\n0,10,5000,0,10,5000\n";
    let map = "x=X,y=Y,z=Z[um],nx=NX,ny=NY,nz=NZ[um]";
    let r = read("u.csv", text.as_bytes(), &spec(Some(map), None));
    assert_e(&points(&r), &[(2, "", 2.0), (3, "", -3.5), (4, "", 0.0)]);
    assert_eq!(r.set.points[1].nominal_mm, [10.0, 0.0, 5.0]);
    // Inches: 0.19693 in = 5.002022 mm → E = 2.022 µm against the plane 5 mm.
    let text = "A,B,C\n0,0,0.19693\n0.5,0,0.19685\n0,0.5,0.19685\n";
    let r = read(
        "in.csv",
        text.as_bytes(),
        &spec(Some("x=A[in],y=B[in],z=C[in]"), Some(5.0)),
    );
    assert_e(
        &points(&r),
        &[
            (2, "", (0.19693 * 25.4 - 5.0) * 1000.0),
            (3, "", (0.19685 * 25.4 - 5.0) * 1000.0),
            (4, "", (0.19685 * 25.4 - 5.0) * 1000.0),
        ],
    );
    assert!((r.set.points[1].u_mm - 12.7).abs() < 1e-12);
    // 1-based numbers instead of names (column 1 is the label).
    let r = read(
        "n.csv",
        VISION.as_bytes(),
        &spec(Some("x=2,y=3,z=4,id=1"), Some(10.0)),
    );
    assert_eq!(r.preamble_lines, 1);
    assert_e(
        &points(&r),
        &[(3, "1", 2.0), (4, "2", -3.0), (5, "3", 0.5), (6, "4", 1.0)],
    );
}

#[test]
fn a_mapping_naming_a_missing_column_is_refused() {
    let s = spec(Some("x=X,y=Y,z=W"), Some(10.0));
    let e = err("m.csv", VISION.as_bytes(), &s);
    assert!(
        e.contains("m.csv: no line of the file names every mapped column")
            && e.contains("(X, Y, W)"),
        "{e}"
    );
    // With the header's line given, the missing column itself is named.
    let s = ProbeSpec {
        header_line: Some(2),
        ..s
    };
    let e = err("m.csv", VISION.as_bytes(), &s);
    assert!(
        e.contains("m.csv:2, column W")
            && e.contains("the mapped column 'W' for 'z' is not in the file (header has 7 columns: POINT,X,Y,Z,I,J,K)"),
        "{e}"
    );
    // A column number beyond the header.
    let s = ProbeSpec {
        header_line: Some(2),
        ..spec(Some("x=2,y=3,z=9"), Some(10.0))
    };
    let e = err("m.csv", VISION.as_bytes(), &s);
    assert!(e.contains("m.csv:2, column #9"), "{e}");
    // Mapping errors are usage errors before any file is read.
    let e = err(
        "m.csv",
        VISION.as_bytes(),
        &spec(Some("x=X,y=Y,z=Z,i=I"), Some(10.0)),
    );
    assert!(e.contains("map all three of i,j,k or none of them"), "{e}");
}

#[test]
fn a_tilted_vector_gives_the_deviation_along_it() {
    // n = (0.03, 0.04, 0.99874922), 2.87° from z; |n| = 1 within 1e-8.
    // Row 2: m − n = (0.010, −0.020, 0.004) mm:
    //   E = 0.03·0.010 + 0.04·(−0.020) + 0.99874922·0.004 = 0.0003 − 0.0008 + 0.00399499688
    //     = 0.00349499688 mm = 3.49499688 µm.
    // Row 3: the same vector pointing down (a face looking −z) is turned to +z: m − n =
    //   (0, 0, −0.005) → E = 0.99874922·(−0.005) mm = −4.9937461 µm.
    // Row 4: (0,0,1) and m − n = (0.3, 0, 0.001): E = 1 µm (the in-plane offset does not count).
    let text = "id,X,Y,Z,NX,NY,NZ,I,J,K\n\
                a,10.010,-0.020,5.004,10,0,5,0.03,0.04,0.99874922\n\
                b,0,30,4.995,0,30,5,-0.03,-0.04,-0.99874922\n\
                c,40.3,0,5.001,40,0,5,0,0,1\n";
    let map = "x=X,y=Y,z=Z,nx=NX,ny=NY,nz=NZ,i=I,j=J,k=K,id=id";
    let r = read("v.csv", text.as_bytes(), &spec(Some(map), None));
    assert_e(
        &points(&r),
        &[(2, "a", 3.49499688), (3, "b", -4.9937461), (4, "c", 1.0)],
    );
    // Map coordinates are the nominal ones.
    assert_eq!((r.set.points[0].u_mm, r.set.points[0].v_mm), (10.0, 0.0));
    // Without nominal columns: the nominal-plane point is the measured point with z = 5, and E
    // is (measured − that point) · n = (z − 5)·k: 0.004 · 0.99874922 = 3.99499688 µm.
    let text = "X,Y,Z,I,J,K\n0,0,5.004,0.03,0.04,0.99874922\n30,0,5,0,0,1\n0,30,4.998,0,0,1\n";
    let r = read(
        "p.csv",
        text.as_bytes(),
        &spec(Some("x=X,y=Y,z=Z,i=I,j=J,k=K"), Some(5.0)),
    );
    assert_e(
        &points(&r),
        &[(2, "", 3.99499688), (3, "", 0.0), (4, "", -2.0)],
    );
}

#[test]
fn bad_vectors_are_refused_at_their_line() {
    let map = "x=X,y=Y,z=Z,i=I,j=J,k=K";
    let head = "X,Y,Z,I,J,K\n0,0,5,0,0,1\n";
    // A zero vector.
    let e = err(
        "z.csv",
        format!("{head}10,0,5,0,0,0\n0,10,5,0,0,1\n").as_bytes(),
        &spec(Some(map), Some(5.0)),
    );
    assert!(
        e.contains("z.csv:3: the vector (0, 0, 0) has length 0, not 1"),
        "{e}"
    );
    // Angles instead of cosines.
    let e = err(
        "a.csv",
        format!("{head}10,0,5,90,90,0\n0,10,5,0,0,1\n").as_bytes(),
        &spec(Some(map), Some(5.0)),
    );
    assert!(
        e.contains("a.csv:3: the vector (90, 90, 0) has length 127.27"),
        "{e}"
    );
    // A unit vector 11.54° from z (sin 11.54° = 0.2): refused, the nearest axis named.
    let e = err(
        "t.csv",
        format!("{head}10,0,5,0.2,0,0.9797959\n0,10,5,0,0,1\n").as_bytes(),
        &spec(Some(map), Some(5.0)),
    );
    assert!(
        e.contains(
            "t.csv:3: the vector (0.2, 0, 0.9797959) is 11.5° from the normal axis z (at most 5°)"
        ) && e.contains("nearest to z"),
        "{e}"
    );
    // A wall's vectors with --normal z: nearest axis x.
    let e = err(
        "w.csv",
        "X,Y,Z,I,J,K\n0,0,5,1,0,0\n".as_bytes(),
        &spec(Some(map), Some(5.0)),
    );
    assert!(
        e.contains("w.csv:2")
            && e.contains("90.0° from the normal axis z")
            && e.contains("`normal` x"),
        "{e}"
    );
    // Read with --normal x, the wall's vectors agree.
    let s = ProbeSpec {
        normal: Axis::X,
        ..spec(Some(map), Some(0.0))
    };
    let r = read(
        "w.csv",
        "X,Y,Z,I,J,K\n0.002,0,0,1,0,0\n0,10,0,1,0,0\n0,0,10,1,0,0\n".as_bytes(),
        &s,
    );
    assert_e(&points(&r), &[(2, "", 2.0), (3, "", 0.0), (4, "", 0.0)]);
}

/// A DMIS output as a CMM writes it: header, units, a plane feature, points with `$`
/// continuation, comments, measurement blocks.
const DMIS: &str = "DMISMN/'flatness check $$ not a comment',05.2\n\
FILNAM/'PLATE7',05.2\n\
UNITS/MM,ANGDEC\n\
$$ nominals\n\
F(PL1)=FEAT/PLANE,CART,0,0,10,0,0,1\n\
F(P1)=FEAT/POINT,CART,0,0,10,0,0,1\n\
F(P2)=FEAT/POINT,CART,$\n\
50,0,10,$   $$ x, y, z\n\
0,0,1\n\
F(P3)=FEAT/POINT,CART,0,50,10,0.03,0.04,0.99874922\n\
MEAS/POINT,F(P1),1\n\
PTMEAS/CART,0,0,10.002,0,0,1\n\
ENDMES\n\
FA(P1)=FEAT/POINT,CART,0,0,10.002,0,0,1\n\
FA(P2)=FEAT/POINT,CART,50,0,9.997,0,0,1\n\
FA(P3)=FEAT/POINT,CART,0.01,49.98,10.004,0.03,0.04,0.99874922\n\
FA(PL1)=FEAT/PLANE,CART,0,0,10.001,0,0,1\n\
ENDFIL\n";

#[test]
fn dmis_points_pair_nominal_and_actual_by_label() {
    let r = read("plate.dmi", DMIS.as_bytes(), &spec(None, None));
    assert_eq!(r.format, errmap::probe::ProbeFormat::Dmis);
    // P1: (0,0,0.002)·(0,0,1) = 2 µm. P2 (continued over lines 7–9): −3 µm.
    // P3: (0.01, −0.02, 0.004)·(0.03, 0.04, 0.99874922) = 3.49499688 µm (as the CSV case).
    assert_e(
        &points(&r),
        &[(14, "P1", 2.0), (15, "P2", -3.0), (16, "P3", 3.49499688)],
    );
    // The nominal is the map position: P2 at (50, 0) from its continued lines.
    assert_eq!(r.set.points[1].nominal_mm, [50.0, 0.0, 10.0]);
    // The plane, nominal and actual, is skipped and counted.
    assert_eq!(r.skipped_features, 2);
    // Recognised by content under another name.
    let r = read("plate.txt", DMIS.as_bytes(), &spec(None, None));
    assert_eq!(r.format, errmap::probe::ProbeFormat::Dmis);
}

#[test]
fn dmis_inch_units_convert() {
    // UNITS/INCH: nominal z 1 in = 25.4 mm, actual 1.0001 in: E = 0.0001·25.4 mm = 2.54 µm.
    let text = "DMISMN/'inch',05.2\nUNITS/INCH,ANGDEC\n\
                F(A)=FEAT/POINT,CART,0,0,1,0,0,1\nF(B)=FEAT/POINT,CART,2,0,1,0,0,1\n\
                F(C)=FEAT/POINT,CART,0,2,1,0,0,1\n\
                FA(A)=FEAT/POINT,CART,0,0,1.0001,0,0,1\nFA(B)=FEAT/POINT,CART,2,0,1,0,0,1\n\
                FA(C)=FEAT/POINT,CART,0,2,0.9999,0,0,1\n";
    let r = read("i.dmis", text.as_bytes(), &spec(None, None));
    assert_e(
        &points(&r),
        &[(6, "A", 2.54), (7, "B", 0.0), (8, "C", -2.54)],
    );
    assert!((r.set.points[1].u_mm - 50.8).abs() < 1e-12);
}

#[test]
fn dmis_refusals_name_label_and_line() {
    let ok = "F(A)=FEAT/POINT,CART,0,0,1,0,0,1\nF(B)=FEAT/POINT,CART,2,0,1,0,0,1\n\
              FA(A)=FEAT/POINT,CART,0,0,1,0,0,1\nFA(B)=FEAT/POINT,CART,2,0,1,0,0,1\n";
    // A nominal that was never measured.
    let text = format!("{ok}F(C)=FEAT/POINT,CART,0,2,1,0,0,1\n");
    let e = err("d.dmi", text.as_bytes(), &spec(None, None));
    assert!(
        e.contains("d.dmi:5: the nominal F(C) has no actual FA(C)"),
        "{e}"
    );
    // An actual without a nominal.
    let text = format!("{ok}FA(D)=FEAT/POINT,CART,0,2,1,0,0,1\n");
    let e = err("d.dmi", text.as_bytes(), &spec(None, None));
    assert!(
        e.contains("d.dmi:5: the actual FA(D) has no nominal F(D)"),
        "{e}"
    );
    // A nominal vector that is not a unit vector names the nominal's line.
    let text = "F(A)=FEAT/POINT,CART,0,0,1,0,0,2\nF(B)=FEAT/POINT,CART,2,0,1,0,0,1\n\
                F(C)=FEAT/POINT,CART,0,2,1,0,0,1\nFA(A)=FEAT/POINT,CART,0,0,1,0,0,1\n\
                FA(B)=FEAT/POINT,CART,2,0,1,0,0,1\nFA(C)=FEAT/POINT,CART,0,2,1,0,0,1\n";
    let e = err("d.dmi", text.as_bytes(), &spec(None, None));
    assert!(
        e.contains("d.dmi:1: F(A): the vector (0, 0, 2) has length 2"),
        "{e}"
    );
    // An actual's vector too, at its own line.
    let text = format!("{ok}F(C)=FEAT/POINT,CART,0,2,1,0,0,1\nFA(C)=FEAT/POINT,CART,0,2,1,0,0,0\n");
    let e = err("d.dmi", text.as_bytes(), &spec(None, None));
    assert!(
        e.contains("d.dmi:6: FA(C): the vector (0, 0, 0) has length 0"),
        "{e}"
    );
    // A bad number on a continuation line names the statement's first line.
    let text = format!("{ok}F(C)=FEAT/POINT,CART,$\n0,two,1,0,0,1\n");
    let e = err("d.dmi", text.as_bytes(), &spec(None, None));
    assert!(
        e.contains("d.dmi:5: F(C): 'two' (y) is not a number"),
        "{e}"
    );
    // Polar points are not read.
    let text = format!("{ok}F(C)=FEAT/POINT,POL,1,0,1,0,0,1\n");
    let e = err("d.dmi", text.as_bytes(), &spec(None, None));
    assert!(
        e.contains("d.dmi:5: F(C): FEAT/POINT,POL is not read"),
        "{e}"
    );
    // A mapping does not apply to DMIS.
    let e = err("d.dmi", ok.as_bytes(), &spec(Some("x=X,y=Y,z=Z"), None));
    assert!(
        e.contains("is a DMIS file: a column mapping (`columns`) applies to CSV probe files only"),
        "{e}"
    );
}

#[test]
fn xyz_clouds_read_measured_points_against_the_nominal_plane() {
    // E = (z − 10)·1000; extra values (intensity, colour) ignored; commas or blanks.
    let text = "# scanner export\n0 0 10.002\n\n50,0,9.997\n0\t50\t10.0005 12 200 31\n";
    let r = read("s.xyz", text.as_bytes(), &spec(None, Some(10.0)));
    assert_e(&points(&r), &[(2, "", 2.0), (4, "", -3.0), (5, "", 0.5)]);
    let e = err("s.xyz", b"0 0 10\n1 0 abc\n", &spec(None, Some(10.0)));
    assert!(
        e.contains("s.xyz:2, column 3: 'abc' is not a finite number"),
        "{e}"
    );
    let e = err("s.xyz", b"0 0 10\n1 0\n", &spec(None, Some(10.0)));
    assert!(
        e.contains("s.xyz:2: 2 value(s); a point needs x y z"),
        "{e}"
    );
    let e = err("s.xyz", b"0 0 10\n", &spec(None, None));
    assert!(e.contains("s.xyz:1: no nominal: an XYZ point cloud has no nominal points and no nominal plane was given"), "{e}");
}

#[test]
fn ascii_ply_reads_the_vertices() {
    // A face element after the vertices is not read; an extra vertex property is skipped.
    let text = "ply\nformat ascii 1.0\ncomment scan 7\nelement vertex 3\n\
                property float x\nproperty float y\nproperty uchar intensity\nproperty float z\n\
                element face 1\nproperty list uchar int vertex_indices\nend_header\n\
                0 0 200 10.002\n50 0 17 9.997\n0 50 3 10.0005\n3 0 1 2\n";
    let r = read("s.ply", text.as_bytes(), &spec(None, Some(10.0)));
    assert_e(&points(&r), &[(12, "", 2.0), (13, "", -3.0), (14, "", 0.5)]);
    let bad = text.replace("50 0 17 9.997", "50 0 17 nine");
    let e = err("s.ply", bad.as_bytes(), &spec(None, Some(10.0)));
    assert!(
        e.contains("s.ply:13, column z: 'nine' is not a number"),
        "{e}"
    );
}

/// A binary little-endian PLY: header, then per vertex `uchar intensity, double x, y, z`
/// (25 bytes), written byte by byte.
fn binary_ply(vertices: &[[f64; 3]], declared: usize) -> (Vec<u8>, usize) {
    let header = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {declared}\n\
         property uchar intensity\nproperty double x\nproperty double y\nproperty double z\nend_header\n"
    );
    let mut bytes = header.clone().into_bytes();
    for (n, v) in vertices.iter().enumerate() {
        bytes.push(n as u8);
        for c in v {
            bytes.extend_from_slice(&c.to_le_bytes());
        }
    }
    (bytes, header.len())
}

#[test]
fn binary_ply_reads_and_a_truncated_one_names_the_byte() {
    let v = [[0.0, 0.0, 10.002], [50.0, 0.0, 9.997], [0.0, 50.0, 10.0005]];
    let (bytes, header_len) = binary_ply(&v, 3);
    assert_eq!(bytes.len(), header_len + 3 * 25);
    let r = read("b.ply", &bytes, &spec(None, Some(10.0)));
    // Lines of binary vertices are their 1-based vertex numbers.
    assert_e(&points(&r), &[(1, "", 2.0), (2, "", -3.0), (3, "", 0.5)]);
    // Cut 10 bytes into the third vertex: the file ends at byte header + 50 + 10.
    let cut = &bytes[..header_len + 2 * 25 + 10];
    let e = err("b.ply", cut, &spec(None, Some(10.0)));
    let end = header_len + 60;
    let start = header_len + 50;
    assert!(
        e.contains(&format!(
            "b.ply: at byte {end}: the file ends inside vertex 3 of 3 (which starts at byte {start})"
        )),
        "{e}"
    );
    // A header promising more vertices than the file holds.
    let (bytes, header_len) = binary_ply(&v, 4);
    let e = err("b.ply", &bytes, &spec(None, Some(10.0)));
    assert!(
        e.contains(&format!(
            "at byte {}: the file ends inside vertex 4 of 4",
            header_len + 75
        )),
        "{e}"
    );
    // A deviation beyond the bound names the vertex and its byte.
    let (bytes, header_len) =
        binary_ply(&[[0.0, 0.0, 10.0], [1.0, 0.0, 15.0], [0.0, 1.0, 10.0]], 3);
    let e = err("b.ply", &bytes, &spec(None, Some(10.0)));
    assert!(
        e.contains(&format!(
            "b.ply: vertex 2 (byte {}): the deviation 5 mm along z",
            header_len + 25
        )),
        "{e}"
    );
}

#[test]
fn the_cli_reads_an_export_with_columns_and_a_batch_job_with_the_key() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // A 3 × 3 export of the plane E = 1 + 0.1·x + 0.2·y µm on z = 10, after a date line.
    let mut text = String::from("03/14/2025 10:42:07\nPOINT,X,Y,Z,I,J,K\n");
    let mut n = 0;
    for y in [0.0, 10.0, 20.0] {
        for x in [0.0, 10.0, 20.0] {
            n += 1;
            let e_um: f64 = 1.0 + 0.1 * x + 0.2 * y;
            text.push_str(&format!("{n},{x},{y},{},0,0,1\n", 10.0 + e_um / 1000.0));
        }
    }
    std::fs::write(d.join("flat.csv"), &text).unwrap();
    let run = errmap(
        d,
        &[
            "grid",
            "flat.csv",
            "--columns",
            VISION_MAP,
            "--nominal-plane",
            "10",
            "--step",
            "10",
            "-o",
            "grid.csv",
        ],
    );
    run.expect_code(0);
    assert!(
        run.stderr.contains("1 line(s) before the header skipped"),
        "{}",
        run.stderr
    );
    let grid = std::fs::read_to_string(d.join("grid.csv")).unwrap();
    let mut lines = grid.lines();
    assert_eq!(lines.next(), Some("x_mm,y_mm,e_um"));
    let mut count = 0;
    for l in lines {
        let f: Vec<f64> = l.split(',').map(|x| x.parse().unwrap()).collect();
        assert!((f[2] - (1.0 + 0.1 * f[0] + 0.2 * f[1])).abs() < 1e-6, "{l}");
        count += 1;
    }
    assert_eq!(count, 9);
    // Without --columns the export is refused at its second line, exit 2.
    let run = errmap(
        d,
        &[
            "grid",
            "flat.csv",
            "--nominal-plane",
            "10",
            "--step",
            "10",
            "-o",
            "g2.csv",
        ],
    );
    run.expect_code(2);
    assert!(run.stderr.contains("flat.csv:2"), "{}", run.stderr);
    // A batch job with the `columns` key: the part maps and the summary counts the date line.
    std::fs::create_dir(d.join("probes")).unwrap();
    let mut big = String::from("03/14/2025 10:42:07\nPOINT,X,Y,Z,I,J,K\n");
    let mut n = 0;
    for j in 0..6 {
        for i in 0..6 {
            n += 1;
            let (x, y) = (i as f64 * 20.0, j as f64 * 20.0);
            let e_um: f64 = 1.0 + 0.1 * x + 0.2 * y;
            big.push_str(&format!("{n},{x},{y},{},0,0,1\n", 10.0 + e_um / 1000.0));
        }
    }
    std::fs::write(d.join("probes/p1.csv"), &big).unwrap();
    std::fs::write(
        d.join("job.toml"),
        format!(
            "family = \"cmm\"\nnominal_plane_mm = 10.0\nprobes = \"probes/*.csv\"\ngrid_step_mm = 10.0\n\
             columns = \"{VISION_MAP}\"\n[model]\nepochs = 20\nbackend = \"cpu-reference\"\nwarm_start = \"none\"\n"
        ),
    )
    .unwrap();
    let run = errmap(d, &["batch", "job.toml", "--out-dir", "out", "--json"]);
    run.expect_code(0);
    let summary: serde_json::Value = serde_json::from_str(&run.stdout).expect("summary JSON");
    let part = &summary["parts"][0];
    assert_eq!(part["ok"], true, "{part}");
    assert_eq!(part["points"], 36, "{part}");
    assert_eq!(part["preamble_lines"], 1, "{part}");
    assert!(part.get("skipped_features").is_none(), "{part}");
    // A batch of a DMIS file: its plane (nominal and actual) is skipped and counted.
    std::fs::create_dir(d.join("dmis")).unwrap();
    let mut dmis =
        String::from("DMISMN/'plate',05.2\nUNITS/MM\nF(PL1)=FEAT/PLANE,CART,0,0,10,0,0,1\n");
    let mut actual = String::new();
    let mut n = 0;
    for j in 0..6 {
        for i in 0..6 {
            n += 1;
            let (x, y) = (i as f64 * 20.0, j as f64 * 20.0);
            let z = 10.0 + (1.0 + 0.1 * x + 0.2 * y) / 1000.0;
            dmis.push_str(&format!("F(P{n})=FEAT/POINT,CART,{x},{y},10,0,0,1\n"));
            actual.push_str(&format!("FA(P{n})=FEAT/POINT,CART,{x},{y},{z},0,0,1\n"));
        }
    }
    dmis.push_str(&actual);
    dmis.push_str("FA(PL1)=FEAT/PLANE,CART,0,0,10.001,0,0,1\nENDFIL\n");
    std::fs::write(d.join("dmis/p1.dmi"), &dmis).unwrap();
    std::fs::write(
        d.join("dmis.toml"),
        "family = \"dmis\"\nprobes = \"dmis/*.dmi\"\ngrid_step_mm = 10.0\n\
         [model]\nepochs = 20\nbackend = \"cpu-reference\"\nwarm_start = \"none\"\n",
    )
    .unwrap();
    let run = errmap(d, &["batch", "dmis.toml", "--out-dir", "out3", "--json"]);
    run.expect_code(0);
    let summary: serde_json::Value = serde_json::from_str(&run.stdout).expect("summary JSON");
    let part = &summary["parts"][0];
    assert_eq!(part["points"], 36, "{part}");
    assert_eq!(part["skipped_features"], 2, "{part}");
    // A bad key value is refused with the job's key.
    std::fs::write(
        d.join("bad.toml"),
        "probes = \"probes/*.csv\"\nnominal_plane_mm = 10.0\ncolumns = \"x=X,y=Y\"\n",
    )
    .unwrap();
    let run = errmap(d, &["batch", "bad.toml", "--out-dir", "out2"]);
    run.expect_code(2);
    assert!(
        run.stderr.contains("columns") && run.stderr.contains("the mapping has no 'z'"),
        "{}",
        run.stderr
    );
}

#[test]
fn the_shared_mapping_keeps_linear_messages() {
    // errmap linear's mapping goes through the same parser; its usage line is its own (the
    // setting in its key form: no binary words it here).
    let e = errmap::linear::ColumnMap::parse("target=P,direction=D").unwrap_err();
    assert!(e.to_string().contains("`columns` target=COLUMN"), "{e}");
    let _ = Path::new("");
}

#[test]
fn the_data_samples_of_every_format_hold_the_same_points() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/probe-formats");
    let cmm = spec(Some(VISION_MAP), Some(5.0));
    let plane = spec(None, Some(5.0));
    let reads = [
        read_probe_file(&dir.join("cmm-export.csv"), &cmm).unwrap(),
        read_probe_file(&dir.join("plate.dmi"), &spec(None, None)).unwrap(),
        read_probe_file(&dir.join("scan.xyz"), &plane).unwrap(),
        read_probe_file(&dir.join("scan.ply"), &plane).unwrap(),
    ];
    assert_eq!(reads[0].preamble_lines, 1);
    // 10 × 10 probes, two measured twice and averaged.
    for r in &reads {
        assert_eq!(r.set.points.len(), 100, "{}", r.set.path.display());
        let rows: u32 = r.set.points.iter().map(|p| p.repeats).sum();
        assert_eq!(rows, 102, "{}", r.set.path.display());
    }
    // The first point of the export, by hand: P001 at (25, 25), z 5.0009 → E = 0.9 µm.
    let text = std::fs::read_to_string(dir.join("cmm-export.csv")).unwrap();
    let row: Vec<f64> = text
        .lines()
        .nth(2)
        .unwrap()
        .split(',')
        .skip(1)
        .map(|v| v.parse().unwrap())
        .collect();
    let e_um = (row[2] - 5.0) * 1000.0;
    for r in &reads {
        let p = &r.set.points[0];
        assert_eq!((p.u_mm, p.v_mm), (row[0], row[1]));
        assert!((p.e_um - e_um).abs() < 1e-9, "{} {}", p.e_um, e_um);
    }
    for k in 0..100 {
        for r in &reads[1..] {
            let (a, b) = (&reads[0].set.points[k], &r.set.points[k]);
            assert_eq!((a.u_mm, a.v_mm), (b.u_mm, b.v_mm));
            assert!(
                (a.e_um - b.e_um).abs() < 1e-9,
                "{} point {k}",
                r.set.path.display()
            );
        }
    }
}
