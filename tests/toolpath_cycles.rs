//! Drilling canned cycles: the position after G98/G99 holes is followed, and with `--compensate-holes` each hole whose bottom lies in the zone gets Z and R moved by −E at its own position (every later hole block of the series written with its own levels); LinuxCNC's rs274 checks the drilled depths.

#[path = "common/klartext_trace.rs"]
mod klartext_trace;
#[path = "common/path_judge.rs"]
mod path_judge;
#[path = "common/sinumerik_holes.rs"]
mod sinumerik_holes;

use errmap::geom::{Axis, ErrorField};
use errmap::toolpath::{compensate_gcode, CompensationSettings, Dialect};
use std::path::Path;
use std::process::Command;

/// E = 0.02 + 0.001·x + 0.0005·y mm along Z, measured for |x|, |y| ≤ 100 mm.
struct Tilted;

fn e(x: f64, y: f64) -> f64 {
    0.02 + 0.001 * x + 0.0005 * y
}

impl ErrorField for Tilted {
    fn normal(&self) -> Axis {
        Axis::Z
    }
    fn error_mm(&self, u: f64, v: f64) -> Option<f64> {
        (u.abs() <= 1000.0 && v.abs() <= 1000.0).then(|| e(u, v))
    }
    fn measured(&self, u: f64, v: f64, _margin: f64) -> Option<bool> {
        Some(u.abs() <= 100.0 && v.abs() <= 100.0)
    }
}

fn settings(holes: bool) -> CompensationSettings {
    CompensationSettings {
        zone: Some((-2.0, 0.0)),
        dialect: Some(Dialect::Linuxcnc),
        compensate_holes: holes,
        ..CompensationSettings::default()
    }
}

fn run(text: &str, holes: bool) -> Result<String, String> {
    compensate_gcode(text, Path::new("h.ngc"), &Tilted, &settings(holes))
        .map(|(o, _)| o)
        .map_err(|e| e.to_string())
}

/// Three holes of one G99 series at Z−1 (in the zone), R2; the third is outside the domain.
const HOLES: &str = "G21 G90 G17
G0 X0 Y0 Z10
G99 G81 X10 Y5 Z-1 R2 F100
X20 Y5
X150 Y5
X30 Y-5 (last)
G80
G0 Z10
M2
";

#[test]
fn each_hole_in_the_zone_gets_z_and_r_minus_e_at_its_position() {
    let out = run(HOLES, true).unwrap();
    println!("{out}");
    // By hand: E(10, 5) = 0.0325, E(20, 5) = 0.0425, E(30, −5) = 0.0475; X150 is outside the
    // measured domain: nominal, written out because the series was rewritten.
    let want = "G21 G90 G17
G0 X0 Y0 Z10
G99 G81 X10 Y5 Z-1.0325 R1.9675 F100
X20 Y5 Z-1.0425 R1.9575
X150 Y5 Z-1.0000 R2.0000
X30 Y-5 Z-1.0475 R1.9525 (last)
G80
G0 Z10
M2
";
    assert_eq!(out, want);
}

#[test]
fn holes_in_the_zone_are_refused_without_the_flag_and_with_g91() {
    let err = run(HOLES, false).unwrap_err();
    assert!(err.contains("h.ngc:3"), "{err}");
    assert!(
        err.contains("canned cycle G81: the hole at X10 Y5 ends at Z-1 in the compensation zone"),
        "{err}"
    );
    assert!(err.contains("`compensate_holes`"), "{err}");
    // Given the flag, a G91 series in the zone is refused without suggesting it again.
    let g91 = "G21 G90 G17\nG0 X0 Y0 Z10\nG91 G99 G81 X10 Y5 Z-11 R-8 F100\n";
    let err = run(g91, true).unwrap_err();
    assert!(
        err.contains("h.ngc:3") && err.contains("under G91"),
        "{err}"
    );
    assert!(!err.contains("`compensate_holes`"), "{err}");
    // A through hole: from R2 to Z−5 through the zone [−2, 0], its bottom below it.
    let through = "G21 G90 G17\nG0 X0 Y0 Z10\nG98 G81 X10 Y5 Z-5 R2 F100\n";
    let err = run(through, true).unwrap_err();
    assert!(
        err.contains("passes through the compensation zone"),
        "{err}"
    );
}

#[test]
fn the_position_after_a_cycle_is_its_retract_level() {
    // Holes above the zone; then a cut with no Z word: under G98 it runs at the initial level
    // Z10, under G99 at R8 — both known, both above the zone: copied. Then a plunge and a cut
    // in the zone, compensated: it starts from a known point.
    for retract in ["G98", "G99"] {
        let text = format!(
            "G21 G90 G17\nG0 X0 Y0 Z10\n{retract} G81 X10 Y5 Z5 R8 F100\nG80\nG1 X20 Y5 F100\nG1 Z-1\nG1 X30\nM2\n"
        );
        let out = run(&text, false).unwrap_or_else(|e| panic!("{retract}: {e}"));
        assert!(out.contains("\nG80\nG1 X20 Y5 F100\n"), "{out}");
        // The last cut ends at (30, 5, −1 − E(30, 5) = −1.0525).
        assert!(out.contains("X30.0000 Y5.0000 Z-1.0525\n"), "{out}");
    }
    // Before G98/G99 is given the retract level is the machine's default: unknown.
    let text =
        "G21 G90 G17\nG0 X0 Y0 Z10\nG81 X10 Y5 Z5 R8 F100\nG80\nG1 X20 Y5 F100\nG1 X30 Z-1\n";
    let err = run(text, false).unwrap_err();
    assert!(
        err.contains("h.ngc:5") && err.contains("unknown since line 3"),
        "{err}"
    );
}

#[test]
fn rs274_drills_each_compensated_hole_to_its_depth_minus_e() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/corpus/gcode");
    let script = dir.join("rs274-check.sh");
    if !script.is_file() {
        assert!(std::env::var("ERRMAP_REQUIRE_RS274").as_deref() != Ok("1"));
        println!("skipped: no rs274-check.sh");
        return;
    }
    let work = std::env::temp_dir().join(format!("errmap-holes-{}", std::process::id()));
    std::fs::create_dir_all(&work).unwrap();
    let out = run(HOLES, true).unwrap();
    let canon = |name: &str, text: &str| -> Option<Vec<(String, [f64; 3])>> {
        let p = work.join(name);
        std::fs::write(&p, text).unwrap();
        let c = work.join(format!("{name}.canon"));
        let o = Command::new(&script).arg(&p).arg(&c).output().unwrap();
        match o.status.code() {
            Some(127) => return None,
            Some(0) => {}
            code => panic!("rs274 {code:?}: {}", String::from_utf8_lossy(&o.stderr)),
        }
        let text = std::fs::read_to_string(&c).unwrap();
        Some(
            text.lines()
                .filter_map(|l| {
                    let open = l.find('(')?;
                    let name = l[..open].split_whitespace().last()?.to_string();
                    if !name.starts_with("STRAIGHT_") {
                        return None;
                    }
                    let a: Vec<f64> = l[open + 1..]
                        .trim_end_matches(')')
                        .split(',')
                        .map(|v| v.trim().parse().unwrap())
                        .collect();
                    Some((name, [a[0], a[1], a[2]]))
                })
                .collect(),
        )
    };
    let Some(orig) = canon("orig.ngc", HOLES) else {
        assert!(std::env::var("ERRMAP_REQUIRE_RS274").as_deref() != Ok("1"));
        println!("skipped: rs274 not installed");
        return;
    };
    let new = canon("new.ngc", &out).unwrap();
    // The drilling feeds one for one: X and Y equal, Z moved by −E at holes in the domain.
    // (Rapids differ: between holes of different E the control adds a µm traverse to the new
    // R level.) Every rapid stays over a point the original visits.
    let feeds = |m: &[(String, [f64; 3])]| -> Vec<[f64; 3]> {
        m.iter()
            .filter(|(k, _)| k == "STRAIGHT_FEED")
            .map(|(_, p)| *p)
            .collect()
    };
    let (of, nf) = (feeds(&orig), feeds(&new));
    assert_eq!(of.len(), nf.len());
    let mut bottoms = 0;
    for (o, n) in of.iter().zip(&nf) {
        assert_eq!((o[0], o[1]), (n[0], n[1]));
        let inside = o[0].abs() <= 100.0 && o[1].abs() <= 100.0;
        let want = if inside { o[2] - e(o[0], o[1]) } else { o[2] };
        assert!((n[2] - want).abs() < 1e-4, "{o:?} → {n:?}, want Z {want}");
        bottoms += usize::from(inside);
    }
    assert_eq!(bottoms, 3, "three holes drilled in the domain");
    for (_, n) in &new {
        let known = orig.iter().any(|(_, o)| (o[0], o[1]) == (n[0], n[1]));
        assert!(known, "{n:?} over no point of the original");
    }
    std::fs::remove_dir_all(&work).ok();
}

#[test]
fn after_g28_and_g53_only_the_named_axes_are_unknown() {
    // `G91 G28 Z0` sends Z home (unknown in work coordinates) and leaves X and Y where they
    // are; `G0 Z5` makes Z known again, so the cut at depth is followed.
    let text = "G21 G90 G17\nG0 X10 Y5 Z10\nG91 G28 Z0\nG90 G0 Z5\nG1 Z-1 F100\nG1 X20\nM2\n";
    let out = run(text, false).unwrap();
    // By hand: E(20, 5) = 0.0425 at the end of the cut.
    assert!(out.contains("X20.0000 Y5.0000 Z-1.0425\n"), "{out}");
    // Without the absolute Z the cut is refused, naming the G28 line.
    let text = "G21 G90 G17\nG0 X10 Y5 Z10\nG91 G28 Z0\nG90 G1 X20 F100\n";
    let err = run(text, false).unwrap_err();
    assert!(
        err.contains("h.ngc:4") && err.contains("unknown since line 3"),
        "{err}"
    );
    // G53 moves the named axes in machine coordinates: here Z only.
    let text = "G21 G90 G17\nG0 X10 Y5 Z10\nG53 G0 Z0\nG0 Z5\nG1 Z-1 F100\nG1 X20\nM2\n";
    let out = run(text, false).unwrap();
    assert!(out.contains("X20.0000 Y5.0000 Z-1.0425\n"), "{out}");
    // With no axis word LinuxCNC's G28 sends every axis home: X and Y are unknown after it.
    let text = "G21 G90 G17\nG0 X10 Y5 Z10\nG28\nG0 Z5\nG1 Z-1 F100\n";
    let err = run(text, false).unwrap_err();
    assert!(
        err.contains("h.ngc:5") && err.contains("unknown since line 3"),
        "{err}"
    );
}

// ---------------------------------------------------------------------------------------
// Klartext cycle 1 PECKING: judged by the reference tracer (tests/common/klartext_trace.rs).

/// Holes of cycle 1 (bottom at Z+25 − 25 − 10 = Z−10, in the zone −12…−8) by M99 on
/// positioning blocks; the third is outside the measured domain.
const PECKING: &str = "0 BEGIN PGM PECK MM
1 TOOL CALL 1 Z S3000
2 L X+10 Y+5 Z+25 FMAX
3 CYCL DEF 1.0 PECKING
4 CYCL DEF 1.1 DIST25.000
5 CYCL DEF 1.2 DEPTH-10.000
6 CYCL DEF 1.3 PLNGNG3.0
7 CYCL DEF 1.4 DWELL0
8 CYCL DEF 1.5 F229
9 L FMAX M99
10 L X+20 FMAX M99
11 L X+150 FMAX M99
12 L X+30 Y-5 Z+25 FMAX M99
13 L Z+50 FMAX
14 END PGM PECK MM
";

fn klartext(text: &str, field: &dyn ErrorField, holes: bool) -> Result<String, String> {
    let settings = CompensationSettings {
        zone: Some((-12.0, -8.0)),
        dialect: Some(Dialect::Heidenhain),
        compensate_holes: holes,
        ..CompensationSettings::default()
    };
    compensate_gcode(text, Path::new("peck.h"), field, &settings)
        .map(|(o, _)| o)
        .map_err(|e| e.to_string())
}

#[test]
fn klartext_cycle_1_holes_start_from_z_minus_e_at_their_position() {
    let out = klartext(PECKING, &Tilted, true).unwrap();
    println!("{out}");
    // By hand: E(10, 5) = 0.0325, E(20, 5) = 0.0425, E(30, −5) = 0.0475; X150 lies outside the
    // measured domain: drilled from the nominal start after a return to Z+25.
    assert!(out.contains(" L Z+24.9675 FMAX M99\n"), "{out}");
    assert!(out.contains(" L X+20 Z+24.9575 FMAX M99\n"), "{out}");
    assert!(
        out.contains(" L Z+25.0000 FMAX\n") && out.contains(" L X+150 FMAX M99\n"),
        "{out}"
    );
    assert!(out.contains(" L X+30 Y-5 Z+24.9525 FMAX M99\n"), "{out}");
    // The definition is unchanged: DIST and DEPTH are relative to the start.
    assert!(
        out.contains("CYCL DEF 1.1 DIST25.000\n") && out.contains("CYCL DEF 1.2 DEPTH-10.000\n")
    );
    // The tracer (cycle 1 from the manual): every hole of the output is the original's at its
    // X/Y, lowered by E there (or not at all outside the domain).
    let orig = klartext_trace::trace(PECKING).unwrap();
    let new = klartext_trace::trace(&out).unwrap();
    let holes = |s: &[path_judge::Seg]| -> Vec<path_judge::Seg> {
        s.iter().filter(|s| s.cut).cloned().collect()
    };
    let (a, b) = (holes(&orig), holes(&new));
    assert_eq!(a.len(), 4);
    assert_eq!(b.len(), 4);
    for (o, w) in a.iter().zip(&b) {
        let (x, y) = (o.end[0], o.end[1]);
        let lowered = if x.abs() <= 100.0 { e(x, y) } else { 0.0 };
        assert_eq!((w.end[0], w.end[1]), (x, y));
        for (got, want) in [(w.start[2], o.start[2]), (w.end[2], o.end[2])] {
            assert!((got - (want - lowered)).abs() < 1e-9, "{o:?} → {w:?}");
        }
        assert!((o.end[2] + 10.0).abs() < 1e-9, "the bottom is Z−10: {o:?}");
    }
}

/// E = 0.02 mm along Z everywhere.
struct Flat;

impl ErrorField for Flat {
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
fn klartext_cycle_1_with_a_flat_map_passes_the_judge_and_a_call_of_its_own_gets_a_z_block() {
    let text = PECKING.replace("11 L X+150 FMAX M99\n", "11 L X+50 FMAX\n11 CYCL CALL\n");
    let out = klartext(&text, &Flat, true).unwrap();
    println!("{out}");
    assert!(
        out.contains(" L Z+24.9800 FMAX\n") && out.contains(" CYCL CALL\n"),
        "{out}"
    );
    let orig = klartext_trace::trace(&text).unwrap();
    let new = klartext_trace::trace(&out).unwrap();
    let v = path_judge::judge(&orig, &new, 0.02).unwrap();
    assert!(v.points_checked >= 4, "{v:?}");
}

#[test]
fn klartext_cycle_1_holes_in_the_zone_are_refused_without_the_flag() {
    let err = klartext(PECKING, &Tilted, false).unwrap_err();
    assert!(err.contains("peck.h:10"), "{err}");
    assert!(
        err.contains("block 9: `M99` drills a hole of cycle 1 PECKING (block 3, line 4) whose bottom Z-10.0000 lies in the compensation zone, at X+10.0000 Y+5.0000"),
        "{err}"
    );
    assert!(err.contains("`compensate_holes`"), "{err}");
    // DEPTH given by a parameter: the bottom is unknown.
    let q = PECKING.replace("DEPTH-10.000", "DEPTH Q5");
    let err = klartext(&q, &Tilted, true).unwrap_err();
    assert!(
        err.contains("peck.h:10") && err.contains("its 1.2 DEPTH is `Q5`, not a number"),
        "{err}"
    );
    // A block errmap cannot read before the holes (a post's `CYCLE DEF` for `CYCL DEF`) is
    // named as the cause, not the cycle.
    let typo = PECKING.replace(
        "8 CYCL DEF 1.5 F229\n",
        "8 CYCL DEF 1.5 F229\n8 CYCLE DEF 9.0 DWELL TIME\n",
    );
    let err = klartext(&typo, &Tilted, true).unwrap_err();
    assert!(
        err.contains(
            "`CYCLE DEF 9.0 DWELL TIME` (block 8, line 10) is a function errmap does not follow"
        ) && err.contains("the call `M99` of cycle 1"),
        "{err}"
    );
}

// --- Sinumerik standard cycles (CYCLE81–89, CYCLE840, MCALL, CYCLE832) ---

fn sinumerik(
    text: &str,
    holes: bool,
) -> Result<(String, errmap::toolpath::CompensationReport), String> {
    let s = CompensationSettings {
        dialect: Some(Dialect::Sinumerik),
        ..settings(holes)
    };
    compensate_gcode(text, Path::new("h.mpf"), &Tilted, &s).map_err(|e| e.to_string())
}

/// The judge: the output drills the original's holes at the same positions in the same order,
/// each bottom and RFP moved by −E at its X, Y when `in_zone` says so (bottom in [−2, 0] and
/// inside the measured domain), RTP and every other argument as written; the positioning blocks
/// reach the same points.
fn judge_holes(original: &str, output: &str) {
    let a = sinumerik_holes::read(original).expect("original read");
    let b = sinumerik_holes::read(output).expect("output read");
    assert_eq!(a.positions.len(), b.positions.len(), "{output}");
    for (p, q) in a.positions.iter().zip(&b.positions) {
        for i in 0..3 {
            assert!(
                (p[i].is_nan() && q[i].is_nan()) || (p[i] - q[i]).abs() < 1e-9,
                "{p:?} {q:?}\n{output}"
            );
        }
    }
    assert_eq!(a.holes.len(), b.holes.len(), "{output}");
    for (h, k) in a.holes.iter().zip(&b.holes) {
        let in_zone = (-2.0..=0.0).contains(&h.bottom) && h.x.abs() <= 100.0 && h.y.abs() <= 100.0;
        let want = if in_zone { e(h.x, h.y) } else { 0.0 };
        assert_eq!(
            (h.x, h.y, &h.cycle, h.rtp),
            (k.x, k.y, &k.cycle, k.rtp),
            "{output}"
        );
        assert!(
            (k.bottom - (h.bottom - want)).abs() < 1e-4,
            "{h:?} {k:?}\n{output}"
        );
        assert!(
            (k.rfp - (h.rfp - want)).abs() < 1e-4,
            "{h:?} {k:?}\n{output}"
        );
        assert_eq!(h.others, k.others, "{output}");
    }
}

/// Holes at Z−1 (in the zone [−2, 0]) under one modal call; (150, 5) is outside the domain.
const MCALL_HOLES: &str = "G17 G90 G71
G0 X0 Y0 Z10
MCALL CYCLE81(10, 0, 2, -1, 0)
G0 X10 Y5
X20 Y5
X150 Y5
X30 Y-5 ; last
MCALL
G0 Z50
M30
";

#[test]
fn sinumerik_mcall_cycle81_drills_each_hole_with_its_own_e() {
    let (out, rep) = sinumerik(MCALL_HOLES, true).unwrap();
    println!("{out}");
    judge_holes(MCALL_HOLES, &out);
    // E differs per hole (sloped map): each compensated hole has a modal call of its own,
    // and the program's call is in force again after it.
    assert!(out.contains("MCALL CYCLE81(10, -0.0325, 2, -1.0325, 0)\nG0 X10 Y5\nMCALL CYCLE81(10, 0, 2, -1, 0)\n"), "{out}");
    assert!(
        out.contains("MCALL CYCLE81(10, 0, 2, -1, 0)\nX150 Y5\n"),
        "{out}"
    );
    assert_eq!(rep.points_compensated, 3);
    assert!((rep.max_abs_error_mm - e(30.0, -5.0)).abs() < 1e-9);
}

#[test]
fn sinumerik_direct_cycle81_in_and_out_of_the_zone() {
    let text =
        "G17 G90 G71\nG0 X10 Y5 Z10\nCYCLE81(10, 0, 2, -1)\nG0 X40 Y5\nCYCLE81(10, 5, 2, 3)\nM30\n";
    let (out, _) = sinumerik(text, true).unwrap();
    println!("{out}");
    judge_holes(text, &out);
    assert!(
        out.contains("\nCYCLE81(10, -0.0325, 2, -1.0325)\n"),
        "{out}"
    );
    // The second hole ends at Z3, above the zone: as written.
    assert!(out.contains("\nCYCLE81(10, 5, 2, 3)\n"), "{out}");
}

#[test]
fn sinumerik_cycle83_with_dpr_moves_rfp_and_keeps_dpr() {
    // DPR 1 below RFP 0: bottom Z−1; DP empty stays empty, FDPR relative stays.
    let text = "G17 G90 G71\nG0 X20 Y10 Z10\nCYCLE83(10, 0, 2, , 1, , 0.5, 0.2, 0, 0, 1, 0)\nM30\n";
    let (out, _) = sinumerik(text, true).unwrap();
    println!("{out}");
    judge_holes(text, &out);
    let rfp = -e(20.0, 10.0);
    assert!(
        out.contains(&format!(
            "CYCLE83(10, {rfp:.4}, 2, , 1, , 0.5, 0.2, 0, 0, 1, 0)"
        )),
        "{out}"
    );
}

#[test]
fn sinumerik_holes_outside_the_zone_are_copied_byte_for_byte() {
    let text = MCALL_HOLES
        .replace("(10, 0, 2, -1, 0)", "(10, 5, 2, 3, 0)")
        .replace('\n', "\r\n");
    let (out, rep) = sinumerik(&text, false).unwrap();
    assert_eq!(out, text);
    assert_eq!(rep.moves_changed, 0);
}

#[test]
fn sinumerik_cycles_in_the_zone_are_refused_where_errmap_cannot_be_exact() {
    // No flag: the hole, its line and the flag named.
    let err = sinumerik(MCALL_HOLES, false).unwrap_err();
    assert!(err.contains("h.mpf:4"), "{err}");
    assert!(
        err.contains("CYCLE81: the hole at X10 Y5 ends at Z-1 in the compensation zone"),
        "{err}"
    );
    assert!(err.contains("`compensate_holes`"), "{err}");
    let refused = |text: &str, phrase: &str| {
        let err = sinumerik(text, true).unwrap_err();
        assert!(err.contains(phrase), "{phrase}: {err}");
        assert!(!err.contains("pass `compensate_holes`"), "{err}");
    };
    let head = "G17 G90 G71\nG0 X10 Y5 Z10\n";
    // A parameter that is not a number.
    refused(
        &format!("{head}R1=-1\nCYCLE81(10, 0, 2, R1)\n"),
        "`R1` is not a plain number",
    );
    // RTP in the zone.
    refused(
        &format!("{head}CYCLE81(-0.5, -0.8, 0.1, -1)\n"),
        "retraction plane RTP -0.5",
    );
    // G91.
    refused(&format!("{head}G91\nCYCLE81(10, 0, 2, -1)\n"), "under G91");
    // A mode of the 840D sl form errmap does not follow.
    refused(
        &format!("{head}CYCLE81(10, 0, 2, -1, 0, 0, 1)\n"),
        "selects a mode",
    );
    // DP and DPR that disagree.
    refused(
        &format!("{head}CYCLE81(10, 0, 2, -1, 3)\n"),
        "give different depths",
    );
    // A cut in the zone under MCALL would be split into blocks that each drill.
    refused(
        &format!("{head}MCALL CYCLE81(10, 0, 2, -1)\nG1 Z-1 F100\n"),
        "every block with path motion drills",
    );
    // Another cycle is not followed (as before).
    let err = sinumerik(
        &format!("{head}CYCLE800(1, \"TC\", 0, 57, 0, 0, 0, 0, 0, 0, 0, 0, 0, -1)\nG1 Z-1\n"),
        true,
    )
    .unwrap_err();
    assert!(err.contains("CYCLE800"), "{err}");
    let err = sinumerik(&format!("{head}MCALL POCKET3(10, 0, 2, -1)\n"), true).unwrap_err();
    assert!(err.contains("MCALL POCKET3"), "{err}");
}

#[test]
fn sinumerik_cycle832_tolerance_is_noted_when_larger_than_e() {
    let text =
        "G17 G90 G71\nCYCLE832(0.1, 0, 1)\nG0 X10 Y5 Z10\nG1 Z-1 F100\nG1 X20\nCYCLE832()\nM30\n";
    let (out, rep) = sinumerik(text, false).unwrap();
    assert!(
        out.contains("\nCYCLE832(0.1, 0, 1)\n") && out.contains("\nCYCLE832()\n"),
        "{out}"
    );
    assert_eq!(rep.notes.len(), 1, "{rep:?}");
    assert!(
        rep.notes[0].contains("CYCLE832 tolerance 0.1 mm (line 2)"),
        "{}",
        rep.notes[0]
    );
    // Largest |E| applied is 0.0425 mm (at X20 Y5): a tolerance of 0.01 mm is not noted, nor a
    // deselection.
    let (_, rep) = sinumerik(&text.replace("0.1, 0, 1", "0.01, 0, 1"), false).unwrap();
    assert!(rep.notes.is_empty(), "{rep:?}");
    let (_, rep) = sinumerik(&text.replace("0.1, 0, 1", "0, 0, 1"), false).unwrap();
    assert!(rep.notes.is_empty(), "{rep:?}");
}

#[test]
fn sinumerik_mcall_holes_placed_by_a_loop_are_compensated_with_expand() {
    // The hole positions come from an R-parameter loop; --expand runs it and leaves the modal
    // cycle call to the rewriter. Judged against the same holes written out by hand.
    let text = "G17 G90 G71
R1=10
G0 X0 Y0 Z10
MCALL CYCLE81(R1, 0, 2, -1, 0)
R2=10
WHILE R2<=30
G0 X=R2 Y5
R2=R2+10
ENDWHILE
MCALL
G0 Z50
M30
";
    let by_hand = "G17 G90 G71
G0 X0 Y0 Z10
MCALL CYCLE81(10., 0, 2, -1, 0)
G0 X10 Y5
G0 X20 Y5
G0 X30 Y5
MCALL
G0 Z50
M30
";
    let s = CompensationSettings {
        dialect: Some(Dialect::Sinumerik),
        expand: true,
        ..settings(true)
    };
    let (out, rep) =
        compensate_gcode(text, Path::new("h.mpf"), &Tilted, &s).unwrap_or_else(|e| panic!("{e}"));
    println!("{out}");
    judge_holes(by_hand, &out);
    assert_eq!(rep.points_compensated, 3, "{out}");
    // Without --expand the loop is refused, offering the flag.
    let s = CompensationSettings { expand: false, ..s };
    let err = compensate_gcode(text, Path::new("h.mpf"), &Tilted, &s)
        .unwrap_err()
        .to_string();
    assert!(err.contains("`expand`"), "{err}");
}
