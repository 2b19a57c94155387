//! Toolpath compensation per dialect (Fanuc, Sinumerik, Heidenhain ISO, LinuxCNC), checked point by point against P' = P − E, each refusal with its message, and one test per failure measured in the field.

use errmap_core::geom::{Axis, ErrorField};
use errmap_toolpath::{
    compensate_gcode, CompensationReport, CompensationSettings, Dialect, FanucNumbers, Units,
};
use std::path::Path;

/// E = e0 + g·x mm along Z, defined for |x|, |y| ≤ 1000 mm; measured (probed) for x ≤ `x_meas`
/// (when the map knows its measured domain); probed surface at `surface`.
struct F {
    e0: f64,
    g: f64,
    x_meas: Option<f64>,
    surface: Option<(f64, f64)>,
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
        self.x_meas.map(|x| u <= x + margin)
    }
    fn surface_mm(&self) -> Option<(f64, f64)> {
        self.surface
    }
}

/// E = 0.01 + 0.001·x mm everywhere, all measured.
fn field() -> F {
    F {
        e0: 0.01,
        g: 0.001,
        x_meas: Some(1e9),
        surface: None,
    }
}

fn settings(dialect: Dialect) -> CompensationSettings {
    CompensationSettings {
        everywhere: true,
        dialect: Some(dialect),
        max_segment: 1000.0,
        ..CompensationSettings::default()
    }
}

fn run(text: &str, f: &dyn ErrorField, s: &CompensationSettings) -> (String, CompensationReport) {
    compensate_gcode(text, Path::new("t.nc"), f, s)
        .unwrap_or_else(|e| panic!("refused: {e}\n--- input ---\n{text}"))
}

fn refuse(text: &str, f: &dyn ErrorField, s: &CompensationSettings) -> String {
    match compensate_gcode(text, Path::new("t.nc"), f, s) {
        Ok((out, _)) => panic!("expected a refusal, got:\n{out}"),
        Err(e) => e.to_string(),
    }
}

/// The number after `letter` (`X`, `CR=` …) in an output block, if any.
fn word(line: &str, letter: &str) -> Option<f64> {
    line.split_whitespace()
        .find_map(|w| w.strip_prefix(letter))
        .and_then(|v| v.trim_end_matches('*').parse().ok())
}

/// (x, y, z) of every output block with all three, in order.
fn points(out: &str) -> Vec<[f64; 3]> {
    out.lines()
        .filter_map(|l| Some([word(l, "X")?, word(l, "Y")?, word(l, "Z")?]))
        .collect()
}

fn assert_msg(msg: &str, parts: &[&str]) {
    for p in parts {
        assert!(msg.contains(p), "`{p}` not in: {msg}");
    }
}

// ---- Fanuc ---------------------------------------------------------------------------------

#[test]
fn fanuc_decimal_less_numbers_are_increments_or_refused() {
    // Fanuc 0i-MF manual, "Decimal point programming": with DPI = 0 and IS-B, `Y80000` is
    // 80.000 mm. Measured failure: errmap wrote `Y80000.0000` (an 80 m move).
    let text = "O1000\nG21 G90 G17\nG00 X0 Y0 Z0\nG01 Y80000 F500\nM30\n";
    let f = field();
    let msg = refuse(text, &f, &settings(Dialect::Fanuc));
    assert_msg(
        &msg,
        &["t.nc:4, column 5 (Y80000)", "`fanuc_numbers`", "0.001"],
    );
    let s = CompensationSettings {
        fanuc_numbers: Some(FanucNumbers::IsB),
        ..settings(Dialect::Fanuc)
    };
    let (out, _) = run(text, &f, &s);
    let p = points(&out);
    // E at x = 0 is 0.01 mm: the cut from (0, 0, 0) to (0, 80, 0) becomes z = −0.01.
    assert_eq!(p.last().unwrap(), &[0.0, 80.0, -0.01], "{out}");
    assert!(p.iter().all(|q| q[1] <= 80.0), "{out}");
    // Calculator-type input: `Y80000` is 80000 mm (and then needs more than a million segments).
    let s = CompensationSettings {
        fanuc_numbers: Some(FanucNumbers::Calculator),
        max_segment: 0.01,
        ..settings(Dialect::Fanuc)
    };
    assert_msg(&refuse(text, &f, &s), &["more than a million segments"]);
    // Detected as Fanuc from the O number; M98 marks it too.
    let msg = refuse(
        text,
        &f,
        &CompensationSettings {
            dialect: None,
            ..settings(Dialect::Fanuc)
        },
    );
    assert_msg(&msg, &["Y80000", "`fanuc_numbers`"]);
}

#[test]
fn fanuc_g51_scaling_is_no_cut_and_refused_in_the_zone() {
    // Measured failure: `G51 X0 Y0 Z0 P2000` was compensated as a cut of its own.
    let text = "O1\nG21 G90\nG0 X1. Y1. Z0.\nG51 X0. Y0. Z0. P2000\nG1 X5. F100\nG50\nM30\n";
    let msg = refuse(text, &field(), &settings(Dialect::Fanuc));
    assert_msg(&msg, &["t.nc:5", "G51", "line 4", "Scaling"]);
    // After G50, cuts are compensated again; G51 itself is copied.
    let text = "O1\nG21 G90\nG0 X1. Y1. Z0.\nG51 X0. Y0. Z0. P2000\nG50\nG1 X5. F100\nM30\n";
    let (out, rep) = run(text, &field(), &settings(Dialect::Fanuc));
    assert!(out.contains("\nG51 X0. Y0. Z0. P2000\nG50\n"), "{out}");
    assert_eq!(rep.moves_changed, 1);
}

#[test]
fn fanuc_g68_rotation_is_refused_until_g69() {
    // Measured failure: G68 was ignored and the unrotated points were compensated.
    let text =
        "O1\nG21 G90 G17\nG0 X0. Y0. Z0.\nG68 X0. Y0. R30.\nG1 X10. F100\nG69\nG1 X20.\nM30\n";
    let msg = refuse(text, &field(), &settings(Dialect::Fanuc));
    assert_msg(&msg, &["t.nc:5", "G68", "Rotation", "G69"]);
    // A rotation about Z keeps Z: a zone above the rotated cuts lets them through unchanged.
    let s = CompensationSettings {
        zone: Some((5.0, 6.0)),
        everywhere: false,
        ..settings(Dialect::Fanuc)
    };
    let (out, rep) = run(text, &field(), &s);
    assert_eq!((out.as_str(), rep.moves_changed), (text, 0));
}

#[test]
fn fanuc_g52_local_offset_and_g92_are_followed() {
    // G52 X10.: program x = 0 is map x = 10, so E = 0.01 + 0.001·10 = 0.02 mm there.
    let text = "O1\nG21 G90\nG0 X0. Y0. Z0.\nG52 X10.\nG0 X0. Y0.\nG1 X5. F100\nG52 X0.\nM30\n";
    let (out, _) = run(text, &field(), &settings(Dialect::Fanuc));
    let p = points(&out);
    let f = field();
    let first = p.iter().find(|q| q[0] == 0.0 && q[2] != 0.0).unwrap();
    assert!((first[2] + f.e(10.0)).abs() < 1e-9, "{out}");
    assert!((p.last().unwrap()[2] + f.e(15.0)).abs() < 1e-9, "{out}");
    // G92 X100. at x = 0 shifts by −100: program x = 105 is map x = 5.
    let text = "O1\nG21 G90\nG0 X0. Y0. Z0.\nG92 X100.\nG1 X105. F100\nM30\n";
    let (out, _) = run(text, &field(), &settings(Dialect::Fanuc));
    let p = points(&out);
    assert!((p.last().unwrap()[2] + f.e(5.0)).abs() < 1e-9, "{out}");
    assert_eq!(p.last().unwrap()[0], 105.0);
}

#[test]
fn fanuc_subprograms_macros_and_loops_are_refused() {
    let f = field();
    let s = settings(Dialect::Fanuc);
    // Measured failure: M98 and a WHILE loop with G91 moves were compensated once per text.
    let msg = refuse(
        "O1\nG21 G90\nG0 X0. Y0. Z0.\nM98 P2000 L4\nM30\nO2000\nG91 G1 X1. F100\nM99\n",
        &f,
        &s,
    );
    assert_msg(&msg, &["t.nc:4", "M98", "subprogram", "expand"]);
    let msg = refuse(
        "O1\nG21 G90\nG0 X0. Y0. Z0.\n#1=0\nWHILE[#1LT4]DO1\nG91 G1 X1. F100\n#1=#1+1\nEND1\nM30\n",
        &f,
        &s,
    );
    assert_msg(&msg, &["t.nc:6", "WHILE … DO"]);
    let msg = refuse(
        "O1\nG21 G90\nG0 X0. Y0. Z0.\nN10 G1 X1. F100\nIF[#1LT4]GOTO10\nM30\n",
        &f,
        &s,
    );
    assert_msg(&msg, &["t.nc:4", "jumps", "line 5"]);
    let msg = refuse("O1\nG21 G90\nG0 X0. Y0. Z0.\nG65 P9000 A1.\nM30\n", &f, &s);
    assert_msg(&msg, &["t.nc:4", "G65", "macro"]);
    // A subprogram file (ends in M99) runs in its caller's frame.
    let msg = refuse("O2000\nG21 G90\nG0 X0. Y0. Z0.\nG1 X1. F100\nM99\n", &f, &s);
    assert_msg(&msg, &["t.nc:5", "M99", "subprogram"]);
}

#[test]
fn fanuc_arcs_with_ijk_and_r_end_on_the_circle() {
    // Quarter circle r = 10 about the origin (I/J incremental, then R): every emitted point
    // lies on the circle within the chord tolerance, with z = −E(x).
    let text =
        "O1\nG21 G90 G17\nG0 X10. Y0. Z0.\nG3 X0. Y10. I-10. J0. F100\nG3 X-10. Y0. R10.\nM30\n";
    let f = field();
    let (out, _) = run(text, &f, &settings(Dialect::Fanuc));
    let p = points(&out);
    assert!(p.len() > 40, "{out}");
    for q in &p[1..] {
        let r = q[0].hypot(q[1]);
        assert!((r - 10.0).abs() < 1e-3, "{q:?} off the circle");
        assert!((q[2] + f.e(q[0])).abs() < 1e-4, "{q:?}: z is not −E");
    }
    assert!(out.contains(" R10.0000"), "{out}");
}

// ---- Units -----------------------------------------------------------------------------------

#[test]
fn a_program_without_unit_codes_is_refused_unless_units_are_given() {
    // Measured failure: an inch program without G20 got a millimetre offset (25.4× too large).
    let text = "G90\nG0 X0 Y0 Z0\nG1 X1 F10\n";
    let f = field();
    let msg = refuse(text, &f, &settings(Dialect::Linuxcnc));
    assert_msg(
        &msg,
        &["t.nc:3, column 1 (G1)", "G20/G21", "`units` mm|inch"],
    );
    let s = CompensationSettings {
        units: Some(Units::Inch),
        ..settings(Dialect::Linuxcnc)
    };
    let (out, _) = run(text, &f, &s);
    // x = 1 in = 25.4 mm: E = 0.01 + 0.0254 = 0.0354 mm = 0.00139370 in.
    let z = points(&out).last().unwrap()[2];
    assert!((z + 0.0354 / 25.4).abs() < 6e-6, "{out}");
    // Sinumerik and Heidenhain name their own codes.
    let msg = refuse(
        "G90\nG0 X0 Y0 Z0\nG1 X=1 F10\n",
        &f,
        &settings(Dialect::Sinumerik),
    );
    assert_msg(&msg, &["G70/G71"]);
}

#[test]
fn the_zone_follows_unit_switches() {
    // Zone −20…−10 in the program's first units (mm). After G20, z = −0.5 in = −12.7 mm is in
    // it. Measured failure: the zone was compared with inch coordinates after the switch.
    let text = "G21 G90\nG0 X0 Y0 Z0\nG20\nG0 Z-0.5\nG1 X1 F10\n";
    let s = CompensationSettings {
        zone: Some((-20.0, -10.0)),
        everywhere: false,
        ..settings(Dialect::Linuxcnc)
    };
    let (_, rep) = run(text, &field(), &s);
    assert_eq!(rep.moves_changed, 1);
    assert_eq!(rep.zone_mm, Some((-20.0, -10.0)));
}

// ---- Strict blocks --------------------------------------------------------------------------

#[test]
fn malformed_blocks_are_refused_with_line_and_column() {
    let f = field();
    let s = settings(Dialect::Linuxcnc);
    let msg = refuse("G21 G90\nG0 X0 Y0 Z0\nG1 X1 X2 F10\n", &f, &s);
    assert_msg(&msg, &["t.nc:3, column 7 (X2)", "given twice"]);
    let msg = refuse("G21 G90\nG0 X0 Y0 Z0\nG1 X20,5 F10\n", &f, &s);
    assert_msg(&msg, &["t.nc:3", "decimal comma", "X20.5"]);
    let msg = refuse("G21 G90\nG0 X0 Y0 Z0\nG1 X2 E5 F10\n", &f, &s);
    assert_msg(&msg, &["t.nc:3, column 7 (E5)", "not a LinuxCNC word"]);
    let msg = refuse("G21 G90\nG0 X0 Y0 Z0\nG1 X2 $ F10\n", &f, &s);
    assert_msg(&msg, &["t.nc:3, column 7 ($)"]);
    let msg = refuse("G21 G90\nG0 X0 Y0 Z0\nG12.3 X1\n", &f, &s);
    assert_msg(&msg, &["t.nc:3", "G12.3", "not a G code errmap follows"]);
}

#[test]
fn a_long_line_is_read_in_one_pass() {
    // 160 kB on one line (a run of letters, then words): read, and refused at its first
    // stray letters, without rescanning (the old lexer took 17.5 s on such a line).
    let mut text = String::from("G21 G90\nG0 X0 Y0 Z0\n");
    text.push_str(&"ABCDEFGHIJKLMNOP".repeat(10_000));
    text.push('\n');
    let msg = refuse(&text, &field(), &settings(Dialect::Linuxcnc));
    assert_msg(&msg, &["t.nc:3, column 1"]);
    let mut text = String::from("G21 G90\nG0 X0 Y0 Z0\nG1 F100");
    text.push_str(&" (c)".repeat(40_000));
    text.push_str(" X1\n");
    let (out, rep) = run(&text, &field(), &settings(Dialect::Linuxcnc));
    assert_eq!(rep.moves_changed, 1);
    assert!(out.len() > 160_000);
}

// ---- Sinumerik -------------------------------------------------------------------------------

#[test]
fn sinumerik_assignments_ac_ic_and_cr_arcs_are_followed() {
    // Sinumerik 840D programming manual (fundamentals): `X=AC(…)` absolute and `X=IC(…)`
    // incremental in any G90/G91 mode; `CR=` is the radius (+ ≤ 180°). Measured failure:
    // `X=` and `CR=` lost their positions.
    let text = "N10 G71 G90 G17\nN20 G0 X=10 Y0 Z0\nN30 G1 X=IC(10) F100\nN40 Y=AC(5)\nN50 G3 X10 Y5 CR=5\nM30\n";
    let f = field();
    let (out, _) = run(text, &f, &settings(Dialect::Sinumerik));
    let p = points(&out);
    let close = |q: &[f64; 3], x: f64, y: f64| (q[0] - x).abs() < 1e-9 && (q[1] - y).abs() < 1e-9;
    assert!(
        p.iter()
            .any(|q| close(q, 20.0, 0.0) && (q[2] + f.e(20.0)).abs() < 1e-9),
        "{out}"
    );
    assert!(p.iter().any(|q| close(q, 20.0, 5.0)), "{out}");
    let last = p.last().unwrap();
    assert!(
        close(last, 10.0, 5.0) && (last[2] + f.e(10.0)).abs() < 1e-9,
        "{out}"
    );
    // Half circle about (15, 5): points on it; the arc piece errmap writes uses CR=, never R.
    for q in p.iter().filter(|q| q[1] > 5.0) {
        assert!(
            ((q[0] - 15.0).hypot(q[1] - 5.0) - 5.0).abs() < 1e-3,
            "{q:?}"
        );
    }
    assert!(out.contains(" CR=5.0000"), "{out}");
    assert!(
        !out.lines()
            .any(|l| l.split_whitespace().any(|w| w.starts_with('R'))),
        "{out}"
    );
}

#[test]
fn sinumerik_trans_is_followed_and_frames_calls_parameters_are_refused() {
    let f = field();
    let s = settings(Dialect::Sinumerik);
    // TRANS X10: program x = 0 is map x = 10.
    let (out, _) = run(
        "G71 G90\nG0 X0 Y0 Z0\nTRANS X10\nG1 X0 F100\nG1 X5\nTRANS\nM30\n",
        &f,
        &s,
    );
    let last = *points(&out).last().unwrap();
    assert!((last[2] + f.e(15.0)).abs() < 1e-9, "{out}");
    let msg = refuse("G71 G90\nG0 X0 Y0 Z0\nROT Z30\nG1 X10 F100\n", &f, &s);
    assert_msg(&msg, &["t.nc:4", "ROT", "Rotation"]);
    let msg = refuse("G71 G90\nG0 X0 Y0 Z0\nAMIRROR X0\nG1 X10 F100\n", &f, &s);
    assert_msg(&msg, &["AMIRROR", "Mirror"]);
    let msg = refuse("G71 G90\nG0 X0 Y0 Z0\nL10\n", &f, &s);
    assert_msg(&msg, &["t.nc:3", "L10", "subprogram"]);
    let msg = refuse("G71 G90\nG0 X0 Y0 Z0\nCALL \"POCKET\"\n", &f, &s);
    assert_msg(&msg, &["t.nc:3", "CALL"]);
    let msg = refuse("G71 G90\nR1=5\nG0 X0 Y0 Z0\nG1 X=R1 F100\n", &f, &s);
    assert_msg(&msg, &["t.nc:4", "parameters or [expressions]"]);
    let msg = refuse("G71 G90\nG0 X0 Y0 Z0\nREPEAT LABEL1 P=3\n", &f, &s);
    assert_msg(&msg, &["t.nc:", "REPEAT"]);
}

// ---- Heidenhain ------------------------------------------------------------------------------

#[test]
fn heidenhain_klartext_is_followed_and_iso_lines_are_followed() {
    // Measured failure: Klartext went through with "0 moves changed", exit 0. It is now read
    // as Klartext (tests/toolpath_klartext.rs has the details): the cut gets P − E.
    let f = field();
    let klartext = "0 BEGIN PGM P1 MM\n1 BLK FORM 0.1 Z X+0 Y+0 Z-20\n2 L X+0 Y+0 Z+0 R0 FMAX\n3 L X+10 F100\n4 END PGM P1 MM\n";
    let (out, rep) = run(
        klartext,
        &f,
        &CompensationSettings {
            dialect: None,
            ..settings(Dialect::Heidenhain)
        },
    );
    assert_eq!(rep.moves_changed, 1, "{out}");
    let end = out.lines().find(|l| l.contains("X+10.0000")).unwrap();
    assert!((word(end, "Z").unwrap() + f.e(10.0)).abs() < 1e-9, "{out}");
    // TNC ISO: units in the % header, blocks end in `*`; errmap-inserted blocks too.
    let iso =
        "%P1 G71 *\nN10 G90 *\nN20 G00 X+0 Y+0 Z+0 *\nN30 G01 X+10 F100 *\nN99999 %P1 G71 *\n";
    let s = CompensationSettings {
        dialect: None,
        max_segment: 5.0,
        ..settings(Dialect::Heidenhain)
    };
    let (out, rep) = run(iso, &f, &s);
    assert_eq!(rep.dialect, Some(Dialect::Heidenhain));
    let cut: Vec<&str> = out.lines().filter(|l| l.contains("Z-")).collect();
    assert_eq!(cut.len(), 3, "{out}");
    assert!(cut.iter().all(|l| l.ends_with('*')), "{out}");
    assert!(
        (word(cut[2], "Z").unwrap() + f.e(10.0)).abs() < 1e-9,
        "{out}"
    );
    // Circles are refused in the zone.
    let msg = refuse(
        "%P1 G71 *\nN10 G90 *\nN20 G00 X+0 Y+0 Z+0 *\nN30 G02 X+10 Y+0 I+5 J+0 *\n",
        &f,
        &s,
    );
    assert_msg(&msg, &["t.nc:4", "G2", "heidenhain"]);
}

// ---- Domain and zone -------------------------------------------------------------------------

#[test]
fn points_outside_the_measured_domain_keep_their_nominal_values() {
    // Measured failure: compensation applied the map's extrapolation beyond the probes' hull.
    let f = F {
        x_meas: Some(5.0),
        ..field()
    };
    let text = "G21 G90\nG0 X0 Y0 Z0\nG1 X10 F100\n";
    let (out, rep) = run(text, &f, &settings(Dialect::Linuxcnc));
    assert_eq!(rep.moves_outside_domain, 1);
    for q in points(&out) {
        if q[0] <= 5.0 && q[2] != 0.0 {
            assert!((q[2] + f.e(q[0])).abs() < 1e-9, "{q:?}");
        }
        if q[0] > 5.0 + 1e-6 {
            assert_eq!(q[2], 0.0, "{q:?} was extrapolated");
        }
    }
    let (out, rep) = run(
        text,
        &f,
        &CompensationSettings {
            extrapolate: true,
            ..settings(Dialect::Linuxcnc)
        },
    );
    assert_eq!(rep.moves_outside_domain, 0);
    assert!(
        (points(&out).last().unwrap()[2] + f.e(10.0)).abs() < 1e-9,
        "{out}"
    );
    // A margin of 5 mm counts x ≤ 10 as measured.
    let (_, rep) = run(
        text,
        &f,
        &CompensationSettings {
            domain_margin_mm: 5.0,
            ..settings(Dialect::Linuxcnc)
        },
    );
    assert_eq!(rep.moves_outside_domain, 0);
    // A map that does not know its measured domain is refused unless --extrapolate.
    let old = F {
        x_meas: None,
        ..field()
    };
    let msg = refuse(text, &old, &settings(Dialect::Linuxcnc));
    assert_msg(&msg, &["measured domain", "`extrapolate`"]);
}

#[test]
fn without_a_zone_only_the_probed_surface_band_is_compensated() {
    // Measured failure: with no --zone every move was compensated, clearance moves included.
    let f = F {
        surface: Some((-1.0, -1.0)),
        ..field()
    };
    let s = CompensationSettings {
        everywhere: false,
        ..settings(Dialect::Linuxcnc)
    };
    let text = "G21 G90\nG0 X0 Y0 Z5\nG1 X10 F100 (feed in the air)\nG1 Z-1\nG1 X20\n";
    let (out, rep) = run(text, &f, &s);
    assert_eq!(rep.zone_mm, Some((-1.5, -0.5)));
    assert!(out.contains("\nG1 X10 F100 (feed in the air)\n"), "{out}");
    assert_eq!(rep.moves_changed, 2);
    // No surface and no zone: refused, naming the flags.
    let msg = refuse(text, &field(), &s);
    assert_msg(
        &msg,
        &["no compensation zone", "`zone` MIN,MAX", "`zone` all"],
    );
}

#[test]
fn an_arc_split_at_the_domain_edge_splits_on_the_arc() {
    // Measured failure: the split point lay on the chord. Half circle r = 10 about (0, 0),
    // measured for x ≤ 5; chords are coarse (tolerance 0.5 mm) so a chord split would be
    // up to 0.5 mm inside the circle.
    let f = F {
        x_meas: Some(5.0),
        ..field()
    };
    let text = "G21 G90 G17\nG0 X-10 Y0 Z0\nG2 X10 Y0 I10 J0 F100\n";
    let s = CompensationSettings {
        chord_tol: 0.5,
        ..settings(Dialect::Linuxcnc)
    };
    let (out, _) = run(text, &f, &s);
    let p = points(&out);
    let split: Vec<&[f64; 3]> = p.iter().filter(|q| (q[0] - 5.0).abs() < 1e-6).collect();
    assert_eq!(split.len(), 2, "{out}");
    for q in split {
        assert!(
            (q[0].hypot(q[1]) - 10.0).abs() < 1e-4,
            "{q:?} is not on the arc"
        );
    }
}

#[test]
fn no_zero_length_moves_are_emitted() {
    // A split point 20 nm from the move's start rounds onto it (4 decimals): not written.
    let f = F {
        x_meas: Some(0.00002),
        ..field()
    };
    let text = "G21 G90\nG0 X0 Y0 Z0\nG1 X10 F100\n";
    let (out, _) = run(text, &f, &settings(Dialect::Linuxcnc));
    let lines: Vec<&str> = out.lines().collect();
    for w in lines.windows(2) {
        assert_ne!(points(w[0]), points(w[1]), "{out}");
    }
}

// ---- Property: compensated toolpath = original − E inside domain and zone -------------------

/// Straight moves of a random program, in one of three dialect spellings; returns the text
/// and the visited points.
fn random_program(rng: &mut impl rand::Rng, dialect: Dialect) -> (String, Vec<[f64; 3]>) {
    let mut pts = vec![[0.0, 0.0, 0.0]];
    let mut text = match dialect {
        Dialect::Sinumerik => "G71 G90\nG0 X0 Y0 Z0\n".to_string(),
        Dialect::Fanuc => "O10\nG21 G90\nG0 X0. Y0. Z0.\n".to_string(),
        _ => "G21 G90\nG0 X0 Y0 Z0\n".to_string(),
    };
    for _ in 0..30 {
        let p = [
            rng.random_range(-20..=20) as f64 * 0.5,
            rng.random_range(-20..=20) as f64 * 0.5,
            rng.random_range(-6..=2) as f64 * 0.5,
        ];
        match dialect {
            Dialect::Sinumerik => {
                text.push_str(&format!("G1 X={} Y={} Z=AC({}) F100\n", p[0], p[1], p[2]))
            }
            Dialect::Fanuc => text.push_str(&format!(
                "G1 X{:.1} Y{:.1} Z{:.1} F100.\n",
                p[0], p[1], p[2]
            )),
            _ => text.push_str(&format!("G1 X{} Y{} Z{} F100\n", p[0], p[1], p[2])),
        }
        pts.push(p);
    }
    (text, pts)
}

#[test]
fn random_programs_compensate_to_the_original_minus_e_inside_and_unchanged_outside() {
    use rand::SeedableRng;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let f = F {
        x_meas: Some(3.0),
        ..field()
    };
    let zone = (-2.0, -0.25);
    for dialect in [Dialect::Linuxcnc, Dialect::Fanuc, Dialect::Sinumerik] {
        for _ in 0..20 {
            let (text, orig) = random_program(&mut rng, dialect);
            let s = CompensationSettings {
                zone: Some(zone),
                everywhere: false,
                max_segment: 2.0,
                ..settings(dialect)
            };
            let (out, _) = run(&text, &f, &s);
            // Walk the output: each point lies on the original polyline in the plane (moves
            // are straight, the normal is Z), and its z is the original z there, minus E
            // exactly when that point is in the zone and the measured domain.
            let mut seg = 0;
            for q in points(&out) {
                // `Some(Some(z))`: q lies on move k, whose original z there is z; `Some(None)`:
                // on a vertical move k (z along it not given by x, y).
                let on = |k: usize| -> Option<Option<f64>> {
                    let (a, b) = (orig[k], orig[k + 1]);
                    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
                    let len2 = dx * dx + dy * dy;
                    if len2 == 0.0 {
                        let (lo, hi) = (a[2].min(b[2]), a[2].max(b[2]));
                        let near = (a[0] - q[0]).hypot(a[1] - q[1]) < 2e-4;
                        return (near && q[2] >= lo - 0.1 && q[2] <= hi + 2e-4).then_some(None);
                    }
                    let t = ((q[0] - a[0]) * dx + (q[1] - a[1]) * dy) / len2;
                    let (px, py) = (a[0] + t * dx, a[1] + t * dy);
                    let z = a[2] + t.clamp(0.0, 1.0) * (b[2] - a[2]);
                    // x, y are rounded to 1e-4: z taken from them is good to the slope × 1e-4.
                    let tol = 2e-4 + 2e-4 * (b[2] - a[2]).abs() / len2.sqrt();
                    let z_ok = (q[2] - z).abs() < tol || (q[2] - (z - f.e(q[0]))).abs() < tol;
                    ((-1e-6..=1.0 + 1e-6).contains(&t)
                        && (px - q[0]).hypot(py - q[1]) < 2e-4
                        && z_ok)
                        .then_some(Some(z))
                };
                while seg + 1 < orig.len() && on(seg).is_none() {
                    seg += 1;
                }
                assert!(
                    seg + 1 < orig.len(),
                    "{dialect:?}: {q:?} is on no original move\n{text}\n{out}"
                );
                let Some(Some(z)) = on(seg) else { continue };
                // (z from the rounded x, y is good to ~1e-4: edges get 1e-3 of slack.)
                let inside = (zone.0 + 1e-3..=zone.1 - 1e-3).contains(&z) && q[0] < 3.0 - 1e-3;
                let outside = !(zone.0 - 1e-3..=zone.1 + 1e-3).contains(&z) || q[0] > 3.0 + 1e-3;
                // A point on an edge is written twice (nominal, then compensated): both pass.
                let edge_twin = (q[2] - z).abs() < 2e-4 && !outside && !inside;
                if inside && !edge_twin {
                    assert!(
                        (q[2] - (z - f.e(q[0]))).abs() < 2e-4,
                        "{dialect:?}: {q:?} not compensated (z {z})\n{out}"
                    );
                }
                if outside {
                    assert!(
                        (q[2] - z).abs() < 2e-4,
                        "{dialect:?}: {q:?} changed outside (z {z})\n{out}"
                    );
                }
            }
        }
    }
}

#[test]
fn coordinates_are_fixed_point_without_minus_zero() {
    use errmap_toolpath::format_coord;
    assert_eq!(format_coord(-0.00001, false), "0.0000");
    assert_eq!(format_coord(1.23456, false), "1.2346");
    assert_eq!(format_coord(-2.5, true), "-2.50000");
    assert_eq!(format_coord(80.0, false), "80.0000");
    assert_eq!(format_coord(-1.014, false), "-1.0140");
    assert_eq!(format_coord(1e20, false), "100000000000000000000.0000");
}

#[test]
fn sinumerik_trafoof_is_copied_and_supa_is_a_machine_coordinate_block() {
    let s = settings(Dialect::Sinumerik);
    // TRAFOOF switches off a transformation errmap does not follow anyway; SUPA G0 is a rapid
    // in machine coordinates, after which the position is unknown until X, Y and Z are given.
    let text = "G17 G90 G71\nTRAFOOF\nSUPA G0 Z0 D0\nG0 X10 Y0 Z5\nG1 Z-1 F100\nX20\nM30\n";
    let (out, rep) = run(text, &field(), &s);
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(&lines[..4], &text.lines().collect::<Vec<_>>()[..4], "{out}");
    // The plunge ends at Z−1 − E(10) = −1.02; the cut to X20 ends at −1 − E(20) = −1.03.
    let z_at = |x: f64| {
        lines
            .iter()
            .rev()
            .find(|l| l.contains("Z") && word(l, "X").is_none_or(|v| (v - x).abs() < 1e-9))
            .and_then(|l| word(l, "Z"))
    };
    assert!((z_at(20.0).unwrap() + 1.03).abs() < 1e-9, "{out}");
    assert!(rep.moves_changed >= 2, "{out}");
    // A cut right after SUPA starts from an unknown point: refused.
    let text = "G17 G90 G71\nG0 X10 Y0 Z5\nSUPA G0 Z0\nG1 X20 F100\nM30\n";
    let err = refuse(text, &field(), &s);
    assert!(err.contains("start point of this move is unknown"), "{err}");
    // A cut in machine coordinates is refused naming SUPA.
    let text = "G17 G90 G71\nG0 X10 Y0 Z5\nG1 Z-1 F100\nSUPA G1 X20\nM30\n";
    let err = refuse(text, &field(), &s);
    assert!(
        err.contains("t.nc:4") && err.contains("SUPA machine-coordinate cutting move"),
        "{err}"
    );
}

#[test]
fn sinumerik_motion_words_after_an_instruction_on_the_same_block_are_read() {
    // `SOFT G1 Z-1` plunges: the words after SOFT move the tool (errmap once read the block as
    // SOFT alone, kept Z at 5 and wrote the next cut 6 mm too high).
    let s = settings(Dialect::Sinumerik);
    let text = "G17 G90 G71\nG0 X10 Y0 Z5\nSOFT G1 Z-1 F100\nG1 X20\nM30\n";
    let (out, _) = run(text, &field(), &s);
    let last_cut = out
        .lines()
        .rfind(|l| word(l, "X").is_some_and(|x| (x - 20.0).abs() < 1e-9))
        .unwrap_or_else(|| panic!("{out}"));
    // Z −1 − E(20) = −1 − 0.03.
    assert!((word(last_cut, "Z").unwrap() + 1.03).abs() < 1e-9, "{out}");
    assert!(out.lines().nth(2).unwrap().starts_with("SOFT G1 "), "{out}");
    // An instruction that moves or transforms still ends the block's reading: refused.
    let text = "G17 G90 G71\nG0 X10 Y0 Z5\nSOFT TRAORI\nG1 Z-1 F100\nM30\n";
    let err = refuse(text, &field(), &s);
    assert!(err.contains("TRAORI"), "{err}");
    // Words after an instruction with an argument (read to the end of the block) are refused,
    // never dropped.
    for block in ["SPOS=0 G1 Z-1 F100", "MSG(\"plunge\") G1 Z-1 F100"] {
        let text = format!("G17 G90 G71\nG0 X10 Y0 Z5\n{block}\nG1 X20\nM30\n");
        let err = refuse(&text, &field(), &s);
        assert!(
            err.contains("t.nc:3") && err.contains("words after the instruction"),
            "{err}"
        );
    }
    // Alone on its block, or with only its argument and a comment, it is copied.
    let text = "G17 G90 G71\nMSG(\"a (b) c\") ; note\nSPOS=0\nG0 X10 Y0 Z5\nG1 Z-1 F100\nM30\n";
    let (out, _) = run(text, &field(), &s);
    assert!(out.contains("MSG(\"a (b) c\") ; note\nSPOS=0\n"), "{out}");
}
