//! Drilling canned cycles: the position after G98/G99 holes is followed, and with `--compensate-holes` each hole whose bottom lies in the zone gets Z and R moved by −E at its own position (every later hole block of the series written with its own levels); LinuxCNC's rs274 checks the drilled depths.

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
    assert!(err.contains("--compensate-holes"), "{err}");
    // Given the flag, a G91 series in the zone is refused without suggesting it again.
    let g91 = "G21 G90 G17\nG0 X0 Y0 Z10\nG91 G99 G81 X10 Y5 Z-11 R-8 F100\n";
    let err = run(g91, true).unwrap_err();
    assert!(
        err.contains("h.ngc:3") && err.contains("under G91"),
        "{err}"
    );
    assert!(!err.contains("--compensate-holes"), "{err}");
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
