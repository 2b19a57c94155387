//! Heidenhain Klartext in `compensate`: programs written from the TNC manual's examples checked point by point against P' = P − E (computed here), every refusal of the docs table triggered with its message, renumbering, units from BEGIN PGM, and byte-for-byte copies outside the zone.

mod common;

use errmap::error::Diagnose;
use errmap::geom::{Axis, ErrorField};
use errmap::toolpath::{
    compensate_gcode, trace_gcode, CompensationReport, CompensationSettings, Dialect, Units,
};
use std::path::Path;

/// E = e0 + g·x mm along Z, defined for |x|, |y| ≤ 1000 mm, measured for x ≤ `x_meas`.
struct F {
    e0: f64,
    g: f64,
    x_meas: f64,
}

impl F {
    fn e(&self, x_mm: f64) -> f64 {
        self.e0 + self.g * x_mm
    }
}

impl ErrorField for F {
    fn normal(&self) -> Axis {
        Axis::Z
    }
    fn error_mm(&self, u: f64, v: f64) -> Option<f64> {
        (u.abs() <= 1000.0 && v.abs() <= 1000.0).then(|| self.e(u))
    }
    fn measured(&self, u: f64, _v: f64, margin: f64) -> Option<bool> {
        Some(u <= self.x_meas + margin)
    }
}

const F1: F = F {
    e0: 0.01,
    g: 0.001,
    x_meas: 1e9,
};

fn settings() -> CompensationSettings {
    CompensationSettings {
        zone: Some((-10.0, 0.0)),
        dialect: None,
        max_segment: 5.0,
        ..CompensationSettings::default()
    }
}

fn run(text: &str, s: &CompensationSettings) -> (String, CompensationReport) {
    compensate_gcode(text, Path::new("k.h"), &F1, s)
        .unwrap_or_else(|e| panic!("refused: {e}\n--- input ---\n{text}"))
}

fn refuse(text: &str) -> String {
    refuse_with(text, &settings())
}

fn refuse_with(text: &str, s: &CompensationSettings) -> String {
    match compensate_gcode(text, Path::new("k.h"), &F1, s) {
        Ok((out, _)) => panic!("expected a refusal, got:\n{out}"),
        Err(e) => format!("{e} {}", e.diagnostic().report().hint.unwrap_or_default()),
    }
}

fn assert_msg(msg: &str, parts: &[&str]) {
    for p in parts {
        assert!(msg.contains(p), "`{p}` not in: {msg}");
    }
}

/// The number after `addr` (`X`, `Z` …) in a block, if any.
fn word(line: &str, addr: &str) -> Option<f64> {
    line.split_whitespace()
        .find_map(|w| w.strip_prefix(addr))
        .and_then(|v| v.parse().ok())
}

/// (x, y, z) of every `L` block with all three coordinates, in order.
fn points(out: &str) -> Vec<[f64; 3]> {
    out.lines()
        .filter(|l| l.split_whitespace().nth(1) == Some("L"))
        .filter_map(|l| Some([word(l, "X")?, word(l, "Y")?, word(l, "Z")?]))
        .collect()
}

/// The block numbers are 0, 1, 2 … on every line.
fn assert_sequential(out: &str) {
    for (i, l) in out.lines().enumerate() {
        let n: usize = l.split_whitespace().next().unwrap().parse().unwrap();
        assert_eq!(n, i, "block numbers not sequential at `{l}`\n{out}");
    }
}

/// Written after the TNC 640 manual's example "Circular movements" (Programming contours,
/// path contours — Cartesian coordinates), posted as the tool-centre path (R0): lines, a CR
/// arc, a CC + C arc and an incremental line at Z −5.
const CIRCULAR: &str = "0 BEGIN PGM CIRCULAR MM
1 BLK FORM 0.1 Z X+0 Y+0 Z-20
2 BLK FORM 0.2 X+100 Y+100 Z+0
3 TOOL CALL 1 Z S4000
4 L Z+250 R0 FMAX
5 L X-10 Y-10 R0 FMAX
6 L Z-5 R0 F1000 M3
7 L X+5 Y+5 R0 F300
8 L X+5 Y+85
9 L X+30 Y+85
10 CR X+70 Y+95 R+30 DR-
11 L X+95
12 CC X+95 Y+70
13 C X+95 Y+45 DR-
14 L IX-90
15 L Z+250 R0 FMAX M2
16 END PGM CIRCULAR MM
";

/// The original contour at Z −5: which piece (x, y) lies on, if any.
fn on_circular(p: [f64; 2]) -> bool {
    let on_line = |a: [f64; 2], b: [f64; 2]| {
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let t = ((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / (dx * dx + dy * dy);
        let (qx, qy) = (a[0] + t * dx, a[1] + t * dy);
        (-1e-9..=1.0 + 1e-9).contains(&t) && (qx - p[0]).hypot(qy - p[1]) < 2e-4
    };
    // CR from (30, 85) to (70, 95), R 30, clockwise, ≤ 180°: the centre lies right of the
    // chord, at h = √(R² − (c/2)²) from its midpoint.
    let (ax, ay, bx, by) = (30.0f64, 85.0f64, 70.0f64, 95.0f64);
    let c = (bx - ax).hypot(by - ay);
    let h = (900.0 - c * c / 4.0).sqrt();
    let (ux, uy) = ((bx - ax) / c, (by - ay) / c);
    let centre = ((ax + bx) / 2.0 + h * uy, (ay + by) / 2.0 - h * ux);
    let on_cr =
        ((p[0] - centre.0).hypot(p[1] - centre.1) - 30.0).abs() < 2e-4 && (p[1] - ay) >= -1e-6;
    // C around (95, 70) from (95, 95) to (95, 45) clockwise: the right half, x ≥ 95.
    let on_c = ((p[0] - 95.0).hypot(p[1] - 70.0) - 25.0).abs() < 2e-4 && p[0] >= 95.0 - 1e-4;
    on_line([-10.0, -10.0], [5.0, 5.0])
        || on_line([5.0, 5.0], [5.0, 85.0])
        || on_line([5.0, 85.0], [30.0, 85.0])
        || on_cr
        || on_line([70.0, 95.0], [95.0, 95.0])
        || on_c
        || on_line([95.0, 45.0], [5.0, 45.0])
}

#[test]
fn the_manual_circular_example_is_compensated_point_by_point() {
    let s = settings();
    let (out, rep) = run(CIRCULAR, &s);
    assert_eq!(rep.dialect, Some(Dialect::Heidenhain));
    assert_sequential(&out);
    let pts: Vec<[f64; 3]> = points(&out).into_iter().filter(|p| p[2] < 0.0).collect();
    assert!(pts.len() > 60, "{out}");
    for p in &pts {
        // Every cutting point lies on the original contour, with z = −5 − E(x).
        assert!(on_circular([p[0], p[1]]), "{p:?} is off the contour\n{out}");
        let want = -5.0 - F1.e(p[0]);
        assert!(
            (p[2] - want).abs() < 1.5e-4,
            "{p:?}: z should be {want}\n{out}"
        );
    }
    // The chords of the arcs stay within the chord tolerance: their midpoints are within
    // 0.005 mm of the circle (plus rounding).
    for w in pts.windows(2) {
        let mid = [(w[0][0] + w[1][0]) / 2.0, (w[0][1] + w[1][1]) / 2.0];
        let r = (mid[0] - 95.0).hypot(mid[1] - 70.0);
        if w[0][0] > 95.0 && w[1][0] > 95.0 {
            assert!(r > 25.0 - 0.005 - 2e-4, "chord {w:?} sags {}", 25.0 - r);
        }
        // No piece is longer than --max-segment.
        let len = (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]);
        assert!(len <= 5.0 + 1e-3, "{w:?}");
    }
    // The arc end points are those of the program; the plunge is a cut too.
    assert!(pts
        .iter()
        .any(|p| (p[0] - 70.0).abs() < 1e-9 && (p[1] - 95.0).abs() < 1e-9));
    assert!(pts
        .iter()
        .any(|p| (p[0] - 95.0).abs() < 1e-9 && (p[1] - 45.0).abs() < 1e-9));
    assert!(pts
        .iter()
        .any(|p| (p[0] - 5.0).abs() < 1e-9 && (p[1] - 45.0).abs() < 1e-9));
    // F and M3 stay on the first piece of their block; M2 stays on the rapid; no C/CR/CC
    // block is left in the rewritten contour (arcs are L chords on the arc).
    assert!(out.contains("R0 F1000 M3"), "{out}");
    assert!(out.contains("R0 FMAX M2"), "{out}");
    assert!(
        !out.lines()
            .any(|l| l.contains(" CR ") || l.contains(" C X")),
        "{out}"
    );
    assert!(out.lines().last().unwrap().ends_with("END PGM CIRCULAR MM"));
    // The return to Z −5 is not needed: the block after the contour gives Z+250.
    assert_eq!(rep.returns_inserted, 0);
    assert_eq!(rep.moves_changed, 8, "{out}");
}

#[test]
fn outside_the_zone_the_program_is_copied_byte_for_byte() {
    let s = CompensationSettings {
        zone: Some((-50.0, -40.0)),
        ..settings()
    };
    let text = CIRCULAR.replace("7 L X+5 Y+5 R0 F300", "7  L  X+5 Y+5 R0 F300 ; start\r")
        + "17 ; trailing";
    let (out, rep) = run(&text, &s);
    assert_eq!(out, text);
    assert_eq!(rep.moves_changed, 0);
}

#[test]
fn inserted_blocks_renumber_the_program_and_labels_keep_their_numbers() {
    // A cut split in three, then a rapid without Z: a return to Z −1 comes before it.
    let text = "0 BEGIN PGM R MM
1 L X+0 Y+0 Z-1 R0 FMAX
2 L X+12 F200
3 L X+20 Y+0 FMAX
4 M30
5 LBL 1
6 L Z+100 R0 FMAX
7 LBL 0
8 END PGM R MM
";
    let (out, rep) = run(text, &settings());
    assert_sequential(&out);
    assert_eq!(rep.returns_inserted, 1);
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(lines.len(), 13, "{out}");
    // The start point gets its E too (a step of E along Z), then every 4 mm.
    assert_eq!(lines[2], "2 L X+0.0000 Y+0.0000 Z-1.0100 F200", "{out}");
    assert_eq!(lines[3], "3 L X+4.0000 Y+0.0000 Z-1.0140");
    assert_eq!(lines[4], "4 L X+8.0000 Y+0.0000 Z-1.0180");
    assert_eq!(lines[5], "5 L X+12.0000 Y+0.0000 Z-1.0220");
    assert_eq!(lines[6], "6 L Z-1.0000 FMAX");
    assert_eq!(lines[7], "7 L X+20 Y+0 FMAX");
    assert_eq!(lines[9], "9 LBL 1");
    assert_eq!(lines[11], "11 LBL 0");
}

#[test]
fn begin_pgm_inch_gives_inches() {
    let text = "0 BEGIN PGM P INCH
1 L X+0 Y+0 Z-0.1 R0 FMAX
2 L X+1 F10
3 END PGM P INCH
";
    let s = CompensationSettings {
        zone: Some((-1.0, 0.0)),
        max_segment: 1000.0,
        ..settings()
    };
    let (out, _) = run(text, &s);
    let pts = points(&out);
    // E at x = 1 in = 25.4 mm is 0.01 + 0.0254 mm = 0.0354 mm = 0.0013937 in.
    let last = pts.last().unwrap();
    let want = -0.1 - (0.01 + 0.001 * 25.4) / 25.4;
    assert!((last[2] - want).abs() < 1e-5, "{out}");
    assert!(
        (last[2] - (-0.1 - 0.0354)).abs() > 0.01,
        "millimetres applied as inches"
    );
    // --units agreeing is fine; disagreeing is refused.
    let s_mm = CompensationSettings {
        units: Some(Units::Mm),
        ..s
    };
    let msg = refuse_with(text, &s_mm);
    assert_msg(&msg, &["k.h:1", "INCH", "`units`"]);
}

#[test]
fn cycle_7_datum_shift_is_followed() {
    // After CYCL DEF 7.1 X+10, program X 0…5 is work X 10…15: E is looked up there.
    let text = "0 BEGIN PGM D MM
1 CYCL DEF 7.0 DATUM SHIFT
2 CYCL DEF 7.1 X+10
3 L X+0 Y+0 Z-1 R0 FMAX
4 L X+5 F100
5 CYCL DEF 7.0 DATUM SHIFT
6 CYCL DEF 7.1 IX+5
7 L X+0 Y+0 Z-1 R0 FMAX
8 L X+5 F100
9 END PGM D MM
";
    let s = CompensationSettings {
        max_segment: 1000.0,
        ..settings()
    };
    let (out, _) = run(text, &s);
    let ends: Vec<f64> = points(&out)
        .iter()
        .filter(|p| p[0] == 5.0)
        .map(|p| p[2])
        .collect();
    assert_eq!(ends.len(), 2, "{out}");
    assert!((ends[0] - (-1.0 - F1.e(15.0))).abs() < 1e-9, "{out}");
    assert!((ends[1] - (-1.0 - F1.e(20.0))).abs() < 1e-9, "{out}");
    // The tool returns to Z −1 before the datum moves.
    assert!(out.contains("L Z-1.0000\n7 CYCL DEF 7.0"), "{out}");
}

#[test]
fn rounding_chamfers_and_labels_far_from_the_zone_are_copied() {
    let text = "0 BEGIN PGM F MM
1 L X+0 Y+0 Z+20 R0 FMAX
2 L X+10 F100
3 RND R2
4 L Y+10
5 CHF 1
6 L X+0
7 CALL LBL 1 REP 2
8 L X+0 Y+0 Z-1 R0 FMAX
9 L X+5 F100
10 M30
11 LBL 1
12 L X+0 Y+0 Z+30 R0 FMAX
13 L IX+10 F100
14 LBL 0
15 END PGM F MM
";
    let (out, rep) = run(text, &settings());
    assert_eq!(rep.moves_changed, 1, "{out}");
    assert!(
        out.contains("3 RND R2\n5 CHF 1\n") || out.contains("RND R2"),
        "{out}"
    );
}

#[test]
fn trace_reads_klartext_moves_in_mm() {
    let moves = trace_gcode(CIRCULAR, Path::new("k.h"), &settings()).unwrap();
    let arcs: Vec<_> = moves.iter().filter(|m| m.arc_mm.is_some()).collect();
    assert_eq!(arcs.len(), 2);
    let c = arcs[1].arc_mm.as_ref().unwrap();
    assert!((c.centre.0 - 95.0).abs() < 1e-12 && (c.centre.1 - 70.0).abs() < 1e-12);
    assert!(
        (c.sweep + std::f64::consts::PI).abs() < 1e-9,
        "DR- is clockwise"
    );
}

const HEAD: &str = "0 BEGIN PGM T MM\n1 L X+0 Y+0 Z-1 R0 FMAX\n";

#[test]
fn every_refusal_in_the_table_is_triggered_with_its_message() {
    let cases: &[(&str, &[&str])] = &[
        ("2 L X+10 RL F100\n3 L IZ+1 FMAX\n", &["k.h:4", "RL", "radius compensation", "cannot carry the return"]),
        ("2 L X+1 RR F100\n3 CR X+10 Y+0 R+5 DR+\n", &["k.h:4", "RR", "CP about the pole CC"]),
        ("2 CYCL DEF 10.0 ROTATION\n3 CYCL DEF 10.1 ROT+45\n4 L X+10 F100\n", &["k.h:5", "CYCL DEF 10 ROTATION", "ROT+0"]),
        ("2 CYCL DEF 8.0 MIRROR IMAGE\n3 CYCL DEF 8.1 X\n4 L X+10 F100\n", &["k.h:5", "MIRROR"]),
        ("2 CYCL DEF 11.0 SCALING\n3 CYCL DEF 11.1 SCL 0.5\n4 L X+10 F100\n", &["k.h:5", "SCALING"]),
        ("2 CYCL DEF 26.0 AXIS-SPECIFIC SCALING\n3 CYCL DEF 26.1 X+2 Y+1\n4 L X+10 F100\n", &["k.h:5", "CYCL DEF 26"]),
        ("2 CYCL DEF 7.0 DATUM SHIFT\n3 CYCL DEF 7.1 #5\n4 L X+0 Y+0 Z-1 R0 FMAX\n5 L X+10 F100\n", &["k.h:6", "#5"]),
        ("2 L X+10 F100\n3 RND R2\n4 L Y+10\n", &["k.h:4", "RND R2", "CR/C"]),
        ("2 L X+0 Y+0 Z+20 FMAX\n3 L X+10 F100\n4 CHF 2\n5 L Y+10 Z-1\n", &["k.h:5", "CHF 2", "line 6"]),
        ("2 L X+10 F100\n3 CT X+20 Y+10\n", &["k.h:4", "CT", "CC + C"]),
        ("2 L X+0 Y+0 Z+20 FMAX\n3 CT X+20 Y+10 Z-1\n", &["k.h:4", "CT"]),
        ("2 LBL 1\n3 L X+0 Y+0 Z-1 R0 FMAX\n4 L X+10 F100\n5 LBL 0\n", &["k.h:5", "LBL 1", "`expand`"]),
        ("2 CALL LBL 1 REP 2\n3 L X+10 F100\n4 M30\n5 LBL 1\n6 L IX+1 F100\n7 LBL 0\n", &["k.h:4", "block 3:", "unknown since block 2, line 3"]),
        ("2 L X+Q1 F100\n", &["k.h:3", "X+Q1", "Q parameter Q1"]),
        ("2 CYCL DEF 7.0 DATUM SHIFT\n3 CYCL DEF 7.1 Z+Q12\n4 L X+0 Y+0 Z-1 R0 FMAX\n5 L X+10 F100\n", &["k.h:6", "Z+Q12", "Q parameter", "FN18"]),
        ("2 CC X+0 Y+10\n3 LP IPR+10 PA+0 F100\n", &["k.h:4", "IPR+10", "absolute radius PR"]),
        ("2 CC X+0 Y+10\n3 CP IPA+90 DR- F100\n", &["k.h:4", "IPA+90", "same sign"]),
        ("2 CP IPA+90 DR+ F100\n", &["k.h:3", "unknown pole CC"]),
        ("2 CC X+0 Y+10\n3 CP IPA+90 X+5 DR+ F100\n", &["k.h:4", "X+5", "polar coordinates"]),
        ("2 CC X+0 Y+10\n3 CP IPA+90 F100\n", &["k.h:4", "DR+"]),
        ("2 / L X+10 F100\n", &["k.h:3", "block 2:", "block skip", "switch"]),
        ("/ 2 L X+10 F100\n", &["k.h:3", "block 2:", "block skip"]),
        ("2 / L Z+5 FMAX\n3 L X+10 F100\n", &["k.h:4", "unknown since block 2, line 3"]),
        ("2 L M140 MB MAX\n3 L X+10 F100\n", &["k.h:4", "unknown since block 2, line 3"]),
        ("2 M140 MB MAX\n3 L X+10 F100\n", &["k.h:4", "unknown since block 2, line 3"]),
        ("2 L X+10 Y+0 FMAX M91\n3 L X+20 F100\n", &["k.h:4", "unknown since block 2, line 3"]),
        ("2 L X+10 F Q5 Y+Q2\n", &["k.h:3", "Y+Q2", "Q parameter"]),
        ("2 FL X+10 Y+0 F100\n", &["k.h:3", "FK free contour"]),
        ("2 APPR LT X+10 Y+0 LEN5 RL F100\n", &["k.h:3", "APPR"]),
        ("2 PLANE SPATIAL SPA+0 SPB+10 SPC+0\n3 L X+0 Y+0 Z-1 R0 FMAX\n4 L X+10 F100\n", &["k.h:5", "PLANE SPATIAL", "5-axis", "untilted"]),
        ("2 M128\n3 L X+0 Y+0 Z-1 R0 FMAX\n4 L X+10 F100\n", &["k.h:5", "M128", "5-axis"]),
        ("2 PLANE SPATIAL SPA+0 SPB+10 SPC+0\n3 PLANE RESET STAY\n4 L X+0 Y+0 Z-1 R0 FMAX\n5 L X+10 F100\n", &["k.h:6", "PLANE RESET STAY", "5-axis"]),
        ("2 PLANE RESET TURN FMAX\n3 L X+0 Y+0 Z-1 R0 FMAX\n4 L X+10 F100\n", &["k.h:5", "PLANE RESET TURN", "5-axis"]),
        ("2 L X+0 Y+0 Z-1 R0 FMAX M128\n3 M129\n4 FUNCTION TCPM F TCP AXIS POS PATHCTRL AXIS\n5 L X+0 Y+0 Z-1 R0 FMAX\n6 L X+10 F100\n", &["k.h:7", "FUNCTION TCPM", "5-axis"]),
        ("2 CALL PGM TNC:\\REF\n3 L X+0 Y+0 Z-1 R0 FMAX\n4 L X+10 F100\n", &["k.h:5", "CALL PGM", "another program", "paste"]),
        ("2 TCH PROBE 412 DATUM INSIDE CIRCLE\n3 L X+0 Y+0 Z-1 R0 FMAX\n4 L X+10 F100\n", &["k.h:5", "TCH PROBE", "probes"]),
        ("2 CYCL DEF 200 DRILLING Q200=+2 Q201=-5 Q203=+Q7\n3 M99\n", &["k.h:4", "Q203 is `Q203=+Q7`"]),
        ("2 TOOL CALL 2 Z S3000\n3 L X+10 F100\n", &["k.h:4", "unknown since block 2, line 3"]),
        ("2 CYCL DEF 200 DRILLING\n3 CYCL CALL\n", &["k.h:4", "CYCL CALL", "cycle"]),
        ("2 L X+10 F100 M99\n", &["k.h:3", "M99"]),
        ("2 L X+10 F100 M126\n", &["k.h:3", "M126", "block of its own"]),
        ("2 L X+10 B+10 F100\n", &["k.h:3", "B+10", "axis B"]),
        ("2 CC X+0 Y+10\n3 C X+10 Y+10 DR+ Z-2\n", &["k.h:4", "helix"]),
        ("2 C X+10 Y+0 DR+\n", &["k.h:3", "circle centre CC"]),
        ("2 CC X+0 Y+10\n3 C X+10 Y+10\n", &["k.h:4", "DR+"]),
        ("2 CR X+10 Y+0 DR+\n", &["k.h:3", "radius"]),
        ("2 CC X+0 Y+10\n3 C X+20 Y+10 DR+\n", &["k.h:4", "not on the circle", "radius 10.0000 at the start", "20.0000 at the end", "0.016 mm"]),
        ("2 TOOL CALL 1 Y\n3 L X+0 Y+0 Z-1 R0 FMAX\n4 CC X+0 Z+5\n5 C X+0 Z-11 DR+\n", &["k.h:6", "tool axis Y"]),
        ("2 L X+1.2.3 F100\n", &["k.h:3", "X+1.2.3", "malformed"]),
        ("2 L X+1 X+2 F100\n", &["k.h:3", "twice"]),
        ("2 L X+1 G01 F100\n", &["k.h:3", "G01"]),
        ("2 L Z 25.000 FMAX\n", &["k.h:3", "block 2:", "without a value", "Z+25"]),
        ("2 L X+10 ~\n  Y+5 F100\n", &["k.h:3", "continued with `~`", "one line"]),
        // A rotary axis turned away from 0 by a positioning block: the part is turned.
        ("2 L B+30 FMAX\n3 L X+10 F100\n", &["k.h:4", "rotary axis B+30", "block 2", "stands away from 0"]),
        ("2 L IC+90 FMAX\n3 L X+10 F100\n", &["k.h:4", "rotary axis C+90", "stands away from 0"]),
        ("2 L B+0 FMAX\n3 L B+15 FMAX\n4 L X+10 F100\n", &["k.h:5", "rotary axis B+15"]),
    ];
    for (body, parts) in cases {
        let text = format!("{HEAD}{body}");
        let msg = refuse(&text);
        assert_msg(&msg, parts);
    }
    // Back at 0 the map applies again.
    run(
        &format!("{HEAD}2 L B+30 FMAX\n3 L B+0 C+0 FMAX\n4 L X+10 F100\n"),
        &settings(),
    );
    // No BEGIN PGM and no --units: the first cut is refused, at any height.
    let msg = refuse("1 L X+0 Y+0 Z+50 R0 FMAX\n2 L X+10 F100\n");
    assert_msg(&msg, &["k.h:2", "BEGIN PGM", "`units`"]);
    let s = CompensationSettings {
        units: Some(Units::Mm),
        dialect: Some(Dialect::Heidenhain),
        ..settings()
    };
    run("1 L X+0 Y+0 Z+50 R0 FMAX\n2 L X+10 F100\n", &s);
    // BEGIN PGM without a unit.
    let msg = refuse("0 BEGIN PGM X\n1 L X+0 Y+0 Z+50 R0 FMAX\n");
    assert_msg(&msg, &["k.h:1", "MM or INCH"]);
}

#[test]
fn refused_constructs_far_from_the_zone_are_copied() {
    // The same constructs at Z+20, with the zone at −10…0: nothing to compensate, no refusal.
    let text = "0 BEGIN PGM T MM
1 L X+0 Y+0 Z+20 R0 FMAX
2 L X+10 RL F100
3 L Y+10 R0
4 CYCL DEF 10.0 ROTATION
5 CYCL DEF 10.1 ROT+45
6 L X+0 F100
7 CYCL DEF 10.1 ROT+0
8 CC X+0 Y+0
9 LP PR+10 PA+0 F100
10 L X+0 Y+0 Z+20 R0 F100
11 CT X+20 Y+10
12 L X+0 Y+0 Z-1 R0 FMAX
13 L X+5 F100
14 TOOL CALL 2 Z S2000
15 L R0 F300 M3
16 END PGM T MM
";
    let (out, rep) = run(text, &settings());
    assert_eq!(rep.moves_changed, 1, "{out}");
}

#[test]
fn the_cli_compensates_klartext_without_flags_and_refuses_with_exit_2() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    std::fs::write(dir.join("model.json"), common::FLAT_MODEL_20UM).unwrap();
    // Detected from BEGIN PGM, units from it, zone = the probed surface ± 0.5 mm.
    let program = "0 BEGIN PGM P1 MM\n1 TOOL CALL 1 Z S4000\n2 L X+10 Y+10 Z+5 R0 FMAX\n3 L Z-1 F100\n4 L X+20\n5 L Z+5 R0 FMAX M2\n6 END PGM P1 MM\n";
    std::fs::write(dir.join("in.h"), program).unwrap();
    let out = common::errmap(
        dir,
        &["compensate", "--model", "model.json", "in.h", "-o", "out.h"],
    );
    out.expect_code(0);
    let expected = "0 BEGIN PGM P1 MM\n1 TOOL CALL 1 Z S4000\n2 L X+10 Y+10 Z+5 R0 FMAX\n\
        3 L X+10.0000 Y+10.0000 Z-0.5000 F100\n\
        4 L X+10.0000 Y+10.0000 Z-0.5200\n\
        5 L X+10.0000 Y+10.0000 Z-1.0200\n\
        6 L X+15.0000 Y+10.0000 Z-1.0200\n\
        7 L X+20.0000 Y+10.0000 Z-1.0200\n\
        8 L Z+5 R0 FMAX M2\n9 END PGM P1 MM\n";
    assert_eq!(
        std::fs::read_to_string(dir.join("out.h")).unwrap(),
        expected
    );
    // An arc CR under radius compensation in the zone: exit 2, file:line:column, nothing written.
    std::fs::write(
        dir.join("rl.h"),
        program.replace("4 L X+20", "4 CR X+20 Y+10 R+5 DR+ RL"),
    )
    .unwrap();
    let out = common::errmap(
        dir,
        &["compensate", "--model", "model.json", "rl.h", "-o", "bad.h"],
    );
    out.expect_code(2);
    assert!(
        out.stderr.contains("rl.h:5") && out.stderr.contains("RL"),
        "{}",
        out.stderr
    );
    assert!(!dir.join("bad.h").exists());
}

/// A flat 20 µm error along Z, measured everywhere.
struct Flat20;

impl ErrorField for Flat20 {
    fn normal(&self) -> Axis {
        Axis::Z
    }
    fn error_mm(&self, _u: f64, _v: f64) -> Option<f64> {
        Some(0.02)
    }
    fn measured(&self, _u: f64, _v: f64, _margin: f64) -> Option<bool> {
        Some(true)
    }
}

#[test]
fn every_heidenhain_program_of_the_corpus_is_followed_or_refused_at_a_line() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/corpus/programs/heidenhain");
    let Ok(entries) = std::fs::read_dir(&dir) else {
        eprintln!("no corpus at {}: skipped", dir.display());
        return;
    };
    let mut files: Vec<_> = entries.filter_map(|e| Some(e.ok()?.path())).collect();
    files.sort();
    let s = CompensationSettings {
        zone: None,
        everywhere: true,
        dialect: Some(Dialect::Heidenhain),
        ..CompensationSettings::default()
    };
    let (mut followed, mut refused) = (0, 0);
    for path in &files {
        let bytes = std::fs::read(path).unwrap();
        let text = String::from_utf8_lossy(&bytes);
        let name = path.file_name().unwrap().to_string_lossy().to_string();
        match compensate_gcode(&text, Path::new(&name), &Flat20, &s) {
            Ok((_, rep)) => {
                followed += 1;
                eprintln!("followed  {name}: {} moves changed", rep.moves_changed);
            }
            Err(e) => {
                refused += 1;
                let msg = e.to_string();
                eprintln!("refused   {msg}");
                assert!(
                    msg.starts_with(&format!("{name}:"))
                        && msg[name.len() + 1..].starts_with(|c: char| c.is_ascii_digit()),
                    "an error without a line number: {msg}"
                );
            }
        }
    }
    eprintln!("{followed} followed, {refused} refused of {}", files.len());
}

/// (x, y, z) of every `L` block with all three coordinates that is not a rapid (FMAX).
fn cut_points(out: &str) -> Vec<[f64; 3]> {
    let cuts: String = out
        .lines()
        .filter(|l| !l.contains("FMAX"))
        .map(|l| format!("{l}\n"))
        .collect();
    points(&cuts)
}

/// The lines of an output that are `L` blocks (with or without a block number).
fn l_blocks(out: &str) -> Vec<&str> {
    out.lines()
        .filter(|l| l.starts_with("L ") || l.split_whitespace().nth(1) == Some("L"))
        .collect()
}

#[test]
fn a_program_without_block_numbers_is_followed_and_stays_unnumbered() {
    // As CAM posts write it (the APT post, NX): no block numbers, TOOL DEF, M140 MB MAX, STOP,
    // comments, a skipped STOP, trailing-dot numbers, feeds F AUTO / F Q5 / FQ5, and a
    // continued cycle definition.
    let text = "BEGIN PGM U MM
BLK FORM 0.1 Z X+0 Y+0 Z-20
BLK FORM 0.2 X+100 Y+100 Z+0
TOOL DEF 1 L+0 R+3
TOOL CALL 1 Z S3000 F AUTO
L M140 MB MAX
; setup
STOP
/ STOP
CYCL DEF 200 DRILLING ~
  Q200=+2 ;SET-UP CLEARANCE ~
  Q201=-5 ;DEPTH
L X-450. Y-10. R0 FMAX M91
L X+0 Y+0. R0 FMAX
L Z-1. R0 FMAX
L X+12. R0 F Q5
L Y+6 FQ5
L X+20 F AUTO
M140 MB MAX
END PGM U MM
";
    let (out, rep) = run(text, &settings());
    assert_eq!(rep.dialect, Some(Dialect::Heidenhain));
    let lines: Vec<&str> = out.lines().collect();
    // Everything up to the first cut is copied byte for byte, the continued cycle included.
    let head: Vec<&str> = text.lines().take(15).collect();
    assert_eq!(&lines[..15], &head[..], "{out}");
    // Cut X 0 → 12 at Z −1 in three pieces of 4 mm, Y 0 → 6 in two of 3, X 12 → 20 in two of 4;
    // each point at Z = −1 − E(x), E = 0.01 + 0.001·x; no block numbers.
    let want: Vec<[f64; 3]> = [
        [0.0, 0.0],
        [4.0, 0.0],
        [8.0, 0.0],
        [12.0, 0.0],
        [12.0, 3.0],
        [12.0, 6.0],
        [16.0, 6.0],
        [20.0, 6.0],
    ]
    .iter()
    .map(|p| [p[0], p[1], -1.0 - (0.01 + 0.001 * p[0])])
    .collect();
    let cut: Vec<&str> = lines[15..].iter().copied().take(want.len()).collect();
    for (l, w) in cut.iter().zip(&want) {
        assert!(
            l.starts_with("L X"),
            "numbered or not an L block: {l}\n{out}"
        );
        let p = [
            word(l, "X").unwrap(),
            word(l, "Y").unwrap(),
            word(l, "Z").unwrap(),
        ];
        for k in 0..3 {
            assert!((p[k] - w[k]).abs() < 1e-9, "{l}: want {w:?}\n{out}");
        }
    }
    // The feed words stay on the first piece of their block, as written.
    assert!(cut[0].ends_with(" R0 F Q5"), "{out}");
    assert!(cut[4].ends_with(" FQ5"), "{out}");
    assert!(cut[6].ends_with(" F AUTO"), "{out}");
    // Before M140 the tool returns to the programmed Z −1 (an unnumbered L block).
    assert_eq!(lines[15 + want.len()], "L Z-1.0000", "{out}");
    assert_eq!(&lines[16 + want.len()..], &["M140 MB MAX", "END PGM U MM"]);
}

#[test]
fn m140_and_m91_leave_the_tool_axis_unknown_until_an_absolute_coordinate() {
    let text = "0 BEGIN PGM M MM
1 L X+0 Y+0 Z-1 R0 FMAX
2 L M140 MB MAX
3 L Z-1 FMAX
4 L X+5 F100
5 L X+10 Y+0 Z-2 F100 M91
6 L X+0 Y+0 Z-1 FMAX
7 L X+5 F100
8 END PGM M MM
";
    let s = CompensationSettings {
        max_segment: 1000.0,
        ..settings()
    };
    let (out, _) = run(text, &s);
    // The M91 move is copied as it is (machine coordinates, never compensated).
    assert!(
        out.contains("\nL X+10 Y+0 Z-2 F100 M91\n") || out.contains(" L X+10 Y+0 Z-2 F100 M91\n"),
        "{out}"
    );
    let ends: Vec<[f64; 3]> = points(&out).into_iter().filter(|p| p[0] == 5.0).collect();
    assert_eq!(ends.len(), 2, "{out}");
    for p in ends {
        assert!((p[2] - (-1.0 - 0.015)).abs() < 1e-9, "{out}");
    }
}

/// The angle of (x, y) about the origin, continued from `prev` (no jump of 2π).
fn unwrap(prev: f64, x: f64, y: f64) -> f64 {
    let a = y.atan2(x);
    let k = ((prev - a) / (2.0 * std::f64::consts::PI)).round();
    a + k * 2.0 * std::f64::consts::PI
}

#[test]
fn a_cp_helix_around_cc_is_compensated_on_the_helix() {
    // TNC manual, helical interpolation: the total angle as IPA, the height as Z, DR with the
    // sign of IPA. Radius 10 about (0, 0) from Z −1 down to Z −3 in one and a half turns.
    let text = "0 BEGIN PGM H MM
1 L X+10 Y+0 Z-1 R0 FMAX
2 CC X+0 Y+0
3 CP IPA+540 Z-3 DR+ F200
4 L Z+50 FMAX
5 END PGM H MM
";
    let (out, rep) = run(text, &settings());
    assert_sequential(&out);
    let pts = cut_points(&out);
    assert!(pts.len() > 100, "{out}");
    let total = 3.0 * std::f64::consts::PI;
    let mut angle = 0.0;
    for (i, p) in pts.iter().enumerate() {
        angle = unwrap(angle, p[0], p[1]);
        // On the cylinder r = 10, at the height of its angle, minus E.
        let r = p[0].hypot(p[1]);
        assert!((r - 10.0).abs() < 2e-4, "{p:?}");
        let z = -1.0 - 2.0 * angle / total;
        assert!(
            (p[2] - (z - F1.e(p[0]))).abs() < 2e-4,
            "point {i} {p:?} angle {angle}\n{out}"
        );
        // Counter-clockwise: the angle never decreases.
        assert!(angle >= -1e-9 && angle <= total + 1e-6, "{p:?}");
    }
    assert!((angle - total).abs() < 1e-6, "ends after 540°: {angle}");
    let last = pts.last().unwrap();
    assert!(
        (last[0] + 10.0).abs() < 1e-9 && last[1].abs() < 1e-9,
        "{last:?}"
    );
    // Chords within the chord tolerance: the midpoint of each lies within 5 µm of the circle.
    for w in pts.windows(2) {
        let mid = ((w[0][0] + w[1][0]) / 2.0).hypot((w[0][1] + w[1][1]) / 2.0);
        assert!(mid > 10.0 - 0.005 - 2e-4, "{w:?}");
    }
    // No CP or CC is left in the rewritten cut.
    assert!(!out.contains(" CP "), "{out}");
    assert_eq!(rep.moves_changed, 1);

    // A full circle CP IPA-360 DR- ends where it started, clockwise.
    let text = "0 BEGIN PGM H MM\n1 L X+10 Y+0 Z-1 R0 FMAX\n2 CC X+0 Y+0\n3 CP IPA-360 DR- F200\n4 END PGM H MM\n";
    let (out, _) = run(text, &settings());
    let pts = points(&out);
    let last = pts.last().unwrap();
    assert!(
        (last[0] - 10.0).abs() < 1e-9 && last[1].abs() < 1e-9,
        "{out}"
    );
    // The first point after the start is below the X axis (clockwise).
    assert!(pts[2][1] < 0.0, "{out}");
}

#[test]
fn cc_in_the_zx_plane_gives_arcs_in_that_plane_with_its_rotation_sense() {
    // TNC angle reference: in the Z/X plane 0° lies along +Z and positive angles turn towards
    // +X. From (x 50, z 0) about CC X+50 Z-5, IPA-90 DR- ends at (x 45, z −5) through x < 50.
    let text = "0 BEGIN PGM Z MM
1 L X+50 Y+0 Z+0 R0 FMAX
2 CC X+50 Z-5
3 CP IPA-90 DR- F100
4 L Z+50 FMAX
5 END PGM Z MM
";
    let (out, _) = run(text, &settings());
    let pts = cut_points(&out);
    assert!(pts.len() > 10, "{out}");
    for p in &pts {
        // Nominal z = written z + E(x).
        let z = p[2] + F1.e(p[0]);
        let r = (z + 5.0).hypot(p[0] - 50.0);
        assert!((r - 5.0).abs() < 2e-4, "{p:?} off the circle\n{out}");
        assert!(
            p[0] <= 50.0 + 1e-9 && z >= -5.0 - 1e-9,
            "{p:?} in the wrong quadrant\n{out}"
        );
        assert!(p[1] == 0.0);
    }
    let last = pts.last().unwrap();
    assert!(
        (last[0] - 45.0).abs() < 1e-9 && (last[2] - (-5.0 - F1.e(45.0))).abs() < 1e-9,
        "{out}"
    );
    // A C block after it turns in the same plane: back to (x 50, z 0) counter-clockwise (DR+).
    let text = text.replace(
        "3 CP IPA-90 DR- F100",
        "3 C X+45 Z-5 DR- F100\n4 C X+50 Z+0 DR+",
    );
    let text = text
        .replace("4 L Z+50", "5 L Z+50")
        .replace("5 END", "6 END");
    let (out, _) = run(&text, &settings());
    let pts = cut_points(&out);
    for p in &pts {
        let z = p[2] + F1.e(p[0]);
        assert!(
            ((z + 5.0).hypot(p[0] - 50.0) - 5.0).abs() < 2e-4,
            "{p:?}\n{out}"
        );
        assert!(p[0] <= 50.0 + 1e-9 && z >= -5.0 - 1e-9, "{p:?}\n{out}");
    }
}

#[test]
fn lp_goes_to_the_point_at_pr_and_pa_about_the_pole() {
    let text = "0 BEGIN PGM P MM
1 L X+10 Y+0 Z-1 R0 FMAX
2 CC X+0 Y+0
3 LP PR+10 PA+90 F100
4 END PGM P MM
";
    let s = CompensationSettings {
        max_segment: 1000.0,
        ..settings()
    };
    let (out, _) = run(text, &s);
    let pts = points(&out);
    let last = pts.last().unwrap();
    assert!(
        last[0].abs() < 1e-9 && (last[1] - 10.0).abs() < 1e-9,
        "{out}"
    );
    assert!((last[2] - (-1.0 - F1.e(0.0))).abs() < 1e-9, "{out}");
    assert!(l_blocks(&out).iter().all(|l| !l.contains("PA")), "{out}");
}

#[test]
fn a_c_end_point_off_the_circle_within_the_tnc_tolerance_is_followed() {
    // Start radius 10, end radius 10.012 (within the TNC's 0.016 mm): the radius grows
    // linearly with the angle, both ends exact.
    let text = "0 BEGIN PGM C MM
1 L X+10 Y+0 Z-1 R0 FMAX
2 CC X+0 Y+0
3 C X+0 Y+10.012 DR+ F100
4 END PGM C MM
";
    let (out, _) = run(text, &settings());
    let pts = cut_points(&out);
    assert!(pts.len() > 5, "{out}");
    let mut angle = 0.0;
    for p in &pts {
        angle = unwrap(angle, p[0], p[1]);
        let want = 10.0 + 0.012 * angle / (std::f64::consts::PI / 2.0);
        assert!((p[0].hypot(p[1]) - want).abs() < 2e-4, "{p:?}\n{out}");
        assert!((p[2] - (-1.0 - F1.e(p[0]))).abs() < 2e-4, "{p:?}");
    }
    let last = pts.last().unwrap();
    assert!(
        last[0].abs() < 1e-9 && (last[1] - 10.012).abs() < 1e-9,
        "{out}"
    );
    // 0.02 mm off: the TNC refuses it, errmap too, naming both radii.
    let msg = refuse(&text.replace("Y+10.012", "Y+10.02"));
    assert_msg(
        &msg,
        &[
            "k.h:4",
            "block 3:",
            "10.0000 at the start",
            "10.0200 at the end",
        ],
    );
}

/// E = 0.01 + 0.001·x measured for x ≤ 35 only.
const F35: F = F {
    e0: 0.01,
    g: 0.001,
    x_meas: 35.0,
};

/// Written after the TNC cycle manual's cycle 200 DRILLING: a definition over several lines
/// and calls by M99 on a positioning block and by CYCL CALL.
const HOLES: &str = "0 BEGIN PGM D MM
1 TOOL CALL 1 Z S3000
2 L X+10 Y+10 Z+20 R0 FMAX
3 CYCL DEF 200 DRILLING ~
  Q200=+2 ;SET-UP CLEARANCE ~
  Q201=-5 ;DEPTH ~
  Q206=+150 ;FEED RATE FOR PLNGNG ~
  Q202=+5 ;PLUNGING DEPTH ~
  Q210=+0 ;DWELL TIME AT TOP ~
  Q203=+0 ;SURFACE COORDINATE ~
  Q204=+50 ;2ND SET-UP CLEARANCE ~
  Q211=+0 ;DWELL TIME AT DEPTH
4 L X+10 Y+10 FMAX M99
5 L X+30 Y+10 FMAX M99
6 L X+40 Y+10 FMAX M99
7 L X+20 Y+10 FMAX
8 CYCL CALL
9 L Z+100 FMAX M30
10 END PGM D MM
";

#[test]
fn drilling_cycle_holes_in_the_zone_are_refused_or_drilled_from_a_surface_moved_by_minus_e() {
    let s = settings();
    let msg = match compensate_gcode(HOLES, Path::new("k.h"), &F35, &s) {
        Ok((out, _)) => panic!("expected a refusal:\n{out}"),
        Err(e) => format!("{e} {}", e.diagnostic().report().hint.unwrap_or_default()),
    };
    assert_msg(
        &msg,
        &[
            "k.h:13",
            "block 4:",
            "M99",
            "cycle 200",
            "Z-5.0000",
            "`compensate_holes`",
            "Q203",
        ],
    );
    let s = CompensationSettings {
        compensate_holes: true,
        ..settings()
    };
    let (out, rep) = compensate_gcode(HOLES, Path::new("k.h"), &F35, &s).unwrap();
    // Each call is preceded (nearest definition above it) by Q203 = 0 − E(x) of its hole; the
    // hole at x = 40 lies outside the measured domain and gets the program's own Q203=+0.
    let lines: Vec<&str> = out.lines().collect();
    let mut surface: Option<&str> = None;
    let mut x = None;
    let mut calls = Vec::new();
    for l in &lines {
        if let Some(at) = l.find("Q203=") {
            surface = l[at + 5..].split_whitespace().next();
        }
        if let Some(v) = word(l, "X") {
            x = Some(v);
        }
        if l.contains("M99") || l.contains("CYCL CALL") {
            calls.push((x.unwrap(), surface.unwrap().to_string()));
        }
    }
    assert_eq!(calls.len(), 4, "{out}");
    for (x, q203) in &calls {
        let q: f64 = q203.parse().unwrap();
        if *x > 35.0 {
            assert_eq!(q203, "+0", "{out}");
        } else {
            assert!(
                (q - (0.0 - (0.01 + 0.001 * x))).abs() < 1e-12,
                "x {x}: Q203 {q203}\n{out}"
            );
        }
    }
    assert_eq!(rep.moves_changed, 3);
    assert_eq!(
        rep.moves_outside_domain, 1,
        "the hole at x = 40 is kept nominal"
    );
    // The program's lines are all there, in order; the definitions errmap adds are whole
    // copies (8 lines each) with only Q203 changed; numbered lines are sequential.
    let def: Vec<&str> = HOLES.lines().skip(4).take(7).collect();
    assert_eq!(out.matches("CYCL DEF 200 DRILLING ~").count(), 5, "{out}");
    assert_eq!(out.matches(def[0]).count(), 5);
    let numbered: Vec<u64> = lines
        .iter()
        .filter_map(|l| l.split_whitespace().next()?.parse().ok())
        .collect();
    assert_eq!(
        numbered,
        (0..numbered.len() as u64).collect::<Vec<_>>(),
        "{out}"
    );
    // Far from the zone (surface at Z+50), nothing changes.
    let high = HOLES.replace("Q203=+0 ", "Q203=+50 ");
    let (out, _) = compensate_gcode(&high, Path::new("k.h"), &F35, &s).unwrap();
    assert_eq!(out, high);
}

#[test]
fn a_cycle_32_tolerance_larger_than_e_is_noted_in_the_report() {
    let text = "0 BEGIN PGM T MM
1 CYCL DEF 32.0 TOLERANCE
2 CYCL DEF 32.1 T0.05
3 L X+0 Y+0 Z-1 R0 FMAX
4 L X+10 F100
5 END PGM T MM
";
    // Largest |E| = 0.01 + 0.001·10 = 0.02 mm < 0.05 mm.
    let (out, rep) = run(text, &settings());
    assert_eq!(rep.notes.len(), 1, "{rep:?}");
    assert_msg(
        &rep.notes[0],
        &["CYCL DEF 32", "T0.05", "block 2, line 3", "0.0200 mm"],
    );
    assert!(out.contains("2 CYCL DEF 32.1 T0.05\n"));
    // A tolerance below |E| is not noted, and the note is not in the JSON when there is none.
    let (_, rep) = run(&text.replace("T0.05", "T0.005"), &settings());
    assert!(rep.notes.is_empty());
    let json = errmap::toolpath::CompensationDocument {
        input: Path::new("a"),
        output: Path::new("b"),
        report: &rep,
    }
    .to_json()
    .unwrap();
    assert!(!json.contains("notes"), "{json}");
}

#[test]
fn the_first_preset_of_cycle_247_is_the_map_frame_and_another_is_refused() {
    let text = "0 BEGIN PGM P MM
1 CYCL DEF 247 DATUM SETTING ~
  Q339=+1 ;DATUM NUMBER
2 L X+0 Y+0 Z-1 R0 FMAX
3 L X+10 F100
4 L Z+50 FMAX
5 CYCL DEF 247 DATUM SETTING ~
  Q339=+2 ;DATUM NUMBER
6 L X+0 Y+0 Z+50 R0 FMAX
7 CYCL DEF 247 DATUM SETTING ~
  Q339=+1 ;DATUM NUMBER
8 L X+0 Y+0 Z-1 R0 FMAX
9 L X+10 F100
10 END PGM P MM
";
    let s = CompensationSettings {
        max_segment: 1000.0,
        ..settings()
    };
    let (out, rep) = run(
        &text.replace(
            "0 BEGIN PGM P MM\n",
            "0 BEGIN PGM P MM\n0 PLANE RESET STAY\n",
        ),
        &s,
    );
    assert_eq!(
        rep.moves_changed, 2,
        "PLANE RESET STAY with no tilt is nothing\n{out}"
    );
    let ends: Vec<[f64; 3]> = cut_points(&out)
        .into_iter()
        .filter(|p| p[0] == 10.0)
        .collect();
    assert_eq!(ends.len(), 2, "{out}");
    for p in ends {
        assert!((p[2] - (-1.0 - F1.e(10.0))).abs() < 1e-9, "{out}");
    }
    // A cut under preset 2 is refused, naming both presets.
    let msg = refuse_with(
        &text.replace(
            "6 L X+0 Y+0 Z+50 R0 FMAX",
            "6 L X+0 Y+0 Z-1 R0 FMAX\n6 L X+5 F100",
        ),
        &s,
    );
    assert_msg(
        &msg,
        &[
            "k.h:10",
            "block 6:",
            "Q339=2",
            "another preset",
            "Q339=1",
            "first preset",
        ],
    );
    // A cut before the first CYCL DEF 247: that preset is not the map's frame either.
    let msg = refuse_with(
        &text.replace(
            "0 BEGIN PGM P MM\n",
            "0 BEGIN PGM P MM\n0 L X+0 Y+0 Z-1 R0 FMAX\n0 L X+5 F100\n",
        ),
        &s,
    );
    assert_msg(&msg, &["k.h:7", "after cuts"]);
    // With --same-part-per-offset, preset 2 holds an identical part: its cut is compensated in
    // its own coordinates with the same map.
    let two = text.replace(
        "6 L X+0 Y+0 Z+50 R0 FMAX",
        "6 L X+0 Y+0 Z-1 R0 FMAX\n6 L X+5 F100",
    );
    assert_msg(&refuse_with(&two, &s), &["`same_part_per_offset`"]);
    let same = CompensationSettings {
        same_part_per_offset: true,
        ..s
    };
    let (out, rep) = run(&two, &same);
    assert_eq!(rep.moves_changed, 3, "{out}");
    let p = cut_points(&out).into_iter().find(|p| p[0] == 5.0).unwrap();
    assert!((p[2] - (-1.0 - F1.e(5.0))).abs() < 1e-9, "{out}");
}

#[test]
fn a_huge_arc_far_from_the_map_is_judged_in_bounded_time() {
    // A circle of radius 2·10⁹ mm under RL, nowhere near the map: proving that it misses the
    // map means sampling it every few mm. errmap stops after its sample budget (a fuzz run hung
    // in that sampling) and takes the arc as one that may touch; under RL its arc pieces would
    // number more than a million, so it is refused at once.
    let text = "0 BEGIN PGM T MM\n1 L X+2000000000 Y+0 Z+50 R0 FMAX\n2 L Z-1 RL F100\n3 CC X+0 Y+0\n4 C X-2000000000 Y+0 DR+\n5 END PGM T MM\n";
    let started = std::time::Instant::now();
    let msg = refuse(text);
    assert_msg(&msg, &["k.h:5", "more than a million segments"]);
    // Not a timing assertion of performance: a hang would never get here.
    println!("refused in {:?}", started.elapsed());
}
