//! Work offsets G54–G59 (G54.1 P…): a second offset refused in the zone by default, followed with `--same-part-per-offset` (the map applied in each offset's coordinates), and the position unknown after any change of offset.

use errmap_core::geom::{Axis, ErrorField};
use errmap_toolpath::{compensate_gcode, CompensationSettings, Dialect};
use std::path::Path;

/// E = 0.02 + 0.001·x mm along Z, everywhere measured.
struct Sloped;

impl ErrorField for Sloped {
    fn normal(&self) -> Axis {
        Axis::Z
    }
    fn error_mm(&self, u: f64, _v: f64) -> Option<f64> {
        Some(0.02 + 0.001 * u)
    }
    fn measured(&self, _u: f64, _v: f64, _margin: f64) -> Option<bool> {
        Some(true)
    }
}

fn run(text: &str, dialect: Dialect, same_part: bool) -> Result<String, String> {
    let s = CompensationSettings {
        zone: Some((-2.0, 0.0)),
        dialect: Some(dialect),
        max_segment: 1000.0,
        same_part_per_offset: same_part,
        ..CompensationSettings::default()
    };
    compensate_gcode(text, Path::new("o.nc"), &Sloped, &s)
        .map(|(o, _)| o)
        .map_err(|e| e.to_string())
}

/// The same slot cut under G54 and under G55 (identical parts on a fixture plate).
const PLATE: &str = "G21 G90 G17
G54
G0 X10 Y5 Z5
G1 Z-1 F100
G1 X20
G55
G0 X10 Y5 Z5
G1 Z-1
G1 X20
G0 Z5
M30
";

#[test]
fn each_offset_gets_the_map_in_its_own_coordinates_with_same_part_per_offset() {
    let out = run(PLATE, Dialect::Linuxcnc, true).unwrap();
    println!("{out}");
    // By hand: E(10) = 0.03, E(20) = 0.04 in both offsets' coordinates. The G54 cut ends
    // compensated, so a return (in G54) precedes the G55 line.
    let want = "G21 G90 G17
G54
G0 X10 Y5 Z5
G1 X10.0000 Y5.0000 Z0.0000 F100
G1 X10.0000 Y5.0000 Z-0.0300
G1 X10.0000 Y5.0000 Z-1.0300
G1 X20.0000 Y5.0000 Z-1.0400
G1 Z-1.0000
G55
G0 X10 Y5 Z5
G1 X10.0000 Y5.0000 Z0.0000
G1 X10.0000 Y5.0000 Z-0.0300
G1 X10.0000 Y5.0000 Z-1.0300
G1 X20.0000 Y5.0000 Z-1.0400
G0 Z5
M30
";
    assert_eq!(out, want);
}

#[test]
fn a_second_offset_is_refused_in_the_zone_without_the_flag() {
    let err = run(PLATE, Dialect::Linuxcnc, false).unwrap_err();
    assert!(err.contains("o.nc:8"), "{err}");
    assert!(
        err.contains("`G55` (line 6) selects a work offset other than the program's first (G54)"),
        "{err}"
    );
    assert!(err.contains("`same_part_per_offset`"), "{err}");
    // Fanuc G54.1 P1 and P2 are two offsets, not one.
    let fanuc = "O1\nG21 G90 G17\nG54.1 P1\nG0 X10. Y5. Z5.\nG54.1 P2\nG0 X10. Y5. Z5.\nG1 Z-1. F100.\nM30\n";
    let err = run(fanuc, Dialect::Fanuc, false).unwrap_err();
    assert!(
        err.contains("o.nc:7") && err.contains("`G54.1 P2` (line 5)"),
        "{err}"
    );
}

#[test]
fn the_position_is_unknown_after_an_offset_change() {
    // After G55 the tool is where it was on the machine, at coordinates the program does not
    // show: a cut with no absolute X Y Z first is refused, naming the G55 line; returning to
    // G54 does not bring the G54 coordinates back either.
    for text in [
        "G21 G90 G17\nG54\nG0 X10 Y5 Z-1\nG55\nG1 X20 F100\n",
        "G21 G90 G17\nG54\nG0 X10 Y5 Z-1\nG55\nG54\nG1 X20 F100\n",
    ] {
        let err = run(text, Dialect::Linuxcnc, true).unwrap_err();
        assert!(
            err.contains("the start point of this move is unknown since line"),
            "{err}"
        );
    }
}

#[test]
fn fadal_e_words_are_fixture_offsets_and_g187_is_not_one() {
    // Fadal: E1 selects fixture offset 1 (the map's), E2 another one.
    let text = "O1\nG21 G90 G17\nG0 X10. Y5. Z5. E1\nG1 Z-1. F100.\nG0 Z5.\nG0 X10. Y5. E2\nG1 Z-1.\nM30\n";
    let err = run(text, Dialect::Fanuc, false).unwrap_err();
    assert!(
        err.contains("o.nc:7")
            && err.contains(
                "`E2` (line 6) selects a work offset other than the program's first (E1)"
            ),
        "{err}"
    );
    // Haas G187 E.635: a tolerance, not an offset; the cut is followed (E(10) = 0.03).
    let text = "O1\nG21 G90 G17\nG187 P2 E.635\nG0 X10. Y5. Z5.\nG1 Z-1. F100.\nM30\n";
    let out = run(text, Dialect::Fanuc, false).unwrap();
    assert!(
        out.contains("G187 P2 E.635\n") && out.contains("Z-1.0300"),
        "{out}"
    );
}

#[test]
fn labels_variables_and_hints_read_as_a_machinist_names_them() {
    // A Sinumerik label on its own block is a label (copied), not an unknown instruction.
    let text = "G71 G90 G17\nG0 X10 Y5 Z5\nMETKA1:\nG1 Z-1 F100\nM30\n";
    let out = run(text, Dialect::Sinumerik, false).unwrap();
    assert!(
        out.contains("\nMETKA1:\nG1 X10.0000 Y5.0000 Z0.0000 F100\n"),
        "{out}"
    );
    // A variable on a move in the zone is named.
    let text = "G21 G90 G17\n#<z>=-1\nG0 X10 Y5 Z5\nG1 Z#<z> F100\n";
    let err = run(text, Dialect::Linuxcnc, false).unwrap_err();
    assert!(
        err.contains("`Z#<z>` reads the variable #<z>") && err.contains("`expand`"),
        "{err}"
    );
    let text = "G71 G90 G17\nR1=-1\nG0 X10 Y5 Z5\nG1 Z=R1+0 F100\n";
    let err = run(text, Dialect::Sinumerik, false).unwrap_err();
    assert!(err.contains("reads the variable R1"), "{err}");
    // The dialect was given: the hint does not ask for it again.
    let err = run("G21 G90\nG0 X0 Y0 Z5 E1\n", Dialect::Linuxcnc, false).unwrap_err();
    assert!(
        err.contains("E is not a LinuxCNC word") && !err.contains("`dialect`"),
        "{err}"
    );
}

#[test]
fn selecting_the_active_offset_again_changes_nothing() {
    // `G54` again (posts repeat it with every tool) keeps the position: the cut is followed.
    let text = "G21 G90 G17\nG54\nG0 X10 Y5 Z-1\nG54 G1 X20 F100\nM30\n";
    let out = run(text, Dialect::Linuxcnc, false).unwrap();
    // E(20) = 0.04 at the end of the cut (a step to −E(10) first).
    assert!(out.contains("X20.0000 Y5.0000 Z-1.0400"), "{out}");
}
