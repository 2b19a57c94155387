//! Lines errmap inserts run under the modes in force where they stand, and blocks with axis words before any motion word are refused or read in the controller's power-on mode: regression tests for two wrong programs, judged by LinuxCNC's rs274 where it runs.
//!
//! The rs274 checks need `../shared/corpus/gcode/rs274-check.sh` (or `$ERRMAP_GCODE_CORPUS`)
//! and rs274; they skip with a printed reason otherwise, and fail under
//! `ERRMAP_REQUIRE_RS274=1`.

use errmap::geom::{Axis, ErrorField};
use errmap::toolpath::{
    compensate_gcode, trace_gcode, CompensationSettings, Dialect, PowerOnMotion,
};
use std::path::{Path, PathBuf};
use std::process::Command;

/// E = +20 µm along Z everywhere, all measured.
struct Flat;

const E_MM: f64 = 0.02;

impl ErrorField for Flat {
    fn normal(&self) -> Axis {
        Axis::Z
    }
    fn error_mm(&self, _u: f64, _v: f64) -> Option<f64> {
        Some(E_MM)
    }
    fn measured(&self, _u: f64, _v: f64, _margin: f64) -> Option<bool> {
        Some(true)
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

fn corpus() -> Option<PathBuf> {
    let dir = std::env::var_os("ERRMAP_GCODE_CORPUS")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/corpus/gcode"));
    dir.join("rs274-check.sh").is_file().then_some(dir)
}

/// rs274's motions of a program, mm: (feed, end point). `None` when rs274 is missing (a
/// skip, which fails under `ERRMAP_REQUIRE_RS274=1`).
fn rs274_motions(program: &str) -> Option<Vec<(bool, [f64; 3])>> {
    let require = std::env::var("ERRMAP_REQUIRE_RS274").is_ok_and(|v| v == "1");
    let Some(dir) = corpus() else {
        assert!(
            !require,
            "ERRMAP_REQUIRE_RS274=1 but rs274-check.sh is missing"
        );
        println!("SKIPPED the rs274 check: ../shared/corpus/gcode/rs274-check.sh not found");
        return None;
    };
    let tmp = tempfile::tempdir().unwrap();
    let (ngc, canon) = (tmp.path().join("p.ngc"), tmp.path().join("p.canon"));
    std::fs::write(&ngc, program).unwrap();
    let out = Command::new(dir.join("rs274-check.sh"))
        .arg(&ngc)
        .arg(&canon)
        .output()
        .expect("cannot run rs274-check.sh");
    match out.status.code() {
        Some(127) => {
            assert!(
                !require,
                "ERRMAP_REQUIRE_RS274=1 but rs274 is not installed"
            );
            println!("SKIPPED the rs274 check: rs274 not installed (see docs/toolpath.md)");
            return None;
        }
        Some(0) => {}
        code => panic!(
            "rs274 stopped ({code:?}): {}\n{program}",
            String::from_utf8_lossy(&out.stderr)
        ),
    }
    let canon = std::fs::read_to_string(&canon).unwrap();
    let mut k = 1.0;
    let mut motions = Vec::new();
    for line in canon.lines() {
        let Some(open) = line.find('(') else { continue };
        let name = line[..open].split_whitespace().last().unwrap_or("");
        let args: Vec<f64> = line[open + 1..]
            .trim_end_matches(')')
            .split(',')
            .map(|a| a.trim().parse().unwrap_or(f64::NAN))
            .collect();
        match name {
            "USE_LENGTH_UNITS" => k = if line.contains("INCHES") { 25.4 } else { 1.0 },
            "STRAIGHT_TRAVERSE" | "STRAIGHT_FEED" => motions.push((
                name == "STRAIGHT_FEED",
                [args[0] * k, args[1] * k, args[2] * k],
            )),
            _ => {}
        }
    }
    Some(motions)
}

/// Equal within what rs274 prints (4 decimals: 0.00005 in = 1.3 µm in inch mode).
fn close(a: [f64; 3], b: [f64; 3]) -> bool {
    (0..3).all(|i| (a[i] - b[i]).abs() < 2e-3)
}

/// The program of the field report: a cut, then an incremental rapid on a `G91` line, then
/// `G90` again. The return step must run in G90 (where it stands), not in the line's G91.
const FIELD_REPORT: &str = "G21 G90\nG0 X0 Y0 Z20\nG1 Z10 F100\nG1 X10\nG91 G0 Z5\nG90 X0\nM2\n";

#[test]
fn a_return_before_a_g91_line_is_written_in_the_mode_in_force_before_it() {
    let (out, report) = compensate_gcode(
        FIELD_REPORT,
        Path::new("t.ngc"),
        &Flat,
        &settings(Dialect::Linuxcnc),
    )
    .unwrap();
    assert_eq!(report.returns_inserted, 1, "{out}");
    // The return stands before `G91 G0 Z5`, in G90: an absolute Z of the original.
    assert!(out.contains("G1 Z10.0000\nG91 G0 Z5\n"), "{out}");
    // errmap's reading and LinuxCNC's: the tool goes back to Z10 and up 5 mm, never down.
    let ends: Vec<[f64; 3]> = trace_gcode(&out, Path::new("o.ngc"), &settings(Dialect::Linuxcnc))
        .unwrap()
        .iter()
        .map(|m| m.end_mm)
        .collect();
    // With the zone everywhere the plunge is compensated too: a step of −E at Z20 first.
    let expected = [
        [0.0, 0.0, 20.0 - E_MM],
        [0.0, 0.0, 10.0 - E_MM],
        [10.0, 0.0, 10.0 - E_MM],
        [10.0, 0.0, 10.0],
        [10.0, 0.0, 15.0],
        [0.0, 0.0, 15.0],
    ];
    assert_eq!(ends.len(), expected.len(), "{ends:?}");
    for (a, b) in ends.iter().zip(&expected) {
        assert!(close(*a, *b), "errmap trace {ends:?}\n{out}");
    }
    if let Some(m) = rs274_motions(&out) {
        let ends: Vec<[f64; 3]> = m.iter().map(|(_, p)| *p).collect();
        // rs274 also reports the first rapid to X0 Y0 Z20.
        assert_eq!(ends.len(), expected.len() + 1, "{m:?}");
        for (a, b) in ends[1..].iter().zip(&expected) {
            assert!(close(*a, *b), "rs274 {m:?}\n{out}");
        }
        // No feed ends below the compensated cut.
        assert!(m.iter().all(|(_, p)| p[2] >= 10.0 - E_MM - 1e-6), "{m:?}");
    }
}

#[test]
fn a_return_before_g91_g28_is_written_in_g90_in_every_dialect() {
    for (dialect, text, ret) in [
        (
            Dialect::Fanuc,
            "O1000\nG21 G90 G17\nG0 X0. Y0. Z20.\nG1 Z10. F100.\nX10.\nG91 G28 Z0.\nM30\n",
            "G1 Z10.0000\nG91 G28 Z0.\n",
        ),
        (
            Dialect::Linuxcnc,
            "G21 G90 G17\nG0 X0 Y0 Z20\nG1 Z10 F100\nX10\nG91 G28 Z0\nG90\nM2\n",
            "G1 Z10.0000\nG91 G28 Z0\n",
        ),
        (
            Dialect::Sinumerik,
            "G71 G90 G17\nG0 X0 Y0 Z20\nG1 Z10 F100\nX10\nG91 G0 Z5\nG90 X0\nM30\n",
            "G1 Z10.0000\nG91 G0 Z5\n",
        ),
    ] {
        let (out, report) =
            compensate_gcode(text, Path::new("t.nc"), &Flat, &settings(dialect)).unwrap();
        assert_eq!(report.returns_inserted, 1, "{dialect:?}\n{out}");
        assert!(out.contains(ret), "{dialect:?}\n{out}");
        if dialect == Dialect::Linuxcnc {
            if let Some(m) = rs274_motions(&out) {
                // The return feed goes up to Z10, not down to Z0.02.
                let feeds: Vec<_> = m.iter().filter(|(f, _)| *f).map(|(_, p)| *p).collect();
                assert!(
                    feeds.iter().any(|p| close(*p, [10.0, 0.0, 10.0])),
                    "{m:?}\n{out}"
                );
                assert!(feeds.iter().all(|p| p[2] > 9.0), "{m:?}\n{out}");
            }
        }
    }
}

#[test]
fn a_return_before_a_unit_switch_is_written_in_the_units_in_force_before_it() {
    // The cut ends at Z10 mm compensated; the next line switches to inches and moves up.
    let text = "G21 G90\nG0 X0 Y0 Z20\nG1 Z10 F100\nG1 X10\nG20 G91 G0 Z0.2\nG21 G90 X0\nM2\n";
    let (out, _) = compensate_gcode(
        text,
        Path::new("t.ngc"),
        &Flat,
        &settings(Dialect::Linuxcnc),
    )
    .unwrap();
    assert!(out.contains("G1 Z10.0000\nG20 G91 G0 Z0.2\n"), "{out}");
    if let Some(m) = rs274_motions(&out) {
        let ends: Vec<[f64; 3]> = m.iter().map(|(_, p)| *p).collect();
        assert!(close(ends[4], [10.0, 0.0, 10.0]), "{m:?}\n{out}");
        assert!(
            close(ends[5], [10.0, 0.0, 10.0 + 0.2 * 25.4]),
            "{m:?}\n{out}"
        );
    }
}

#[test]
fn a_return_comes_before_a_loop_not_inside_it() {
    // After the compensated cut, the loop body's incremental rapids run many times: the
    // return must stand before the loop, once.
    let text = "G21 G90\nG0 X0 Y0 Z20\nG1 Z10 F100\nG1 X10\no100 repeat [3]\nG91 G0 Z1\nG90\no100 endrepeat\nM2\n";
    let (out, report) = compensate_gcode(
        text,
        Path::new("t.ngc"),
        &Flat,
        &settings(Dialect::Linuxcnc),
    )
    .unwrap();
    assert_eq!(report.returns_inserted, 1, "{out}");
    assert!(out.contains("G1 Z10.0000\no100 repeat [3]\n"), "{out}");
    if let Some(m) = rs274_motions(&out) {
        let last = m.last().unwrap().1;
        assert!(close(last, [10.0, 0.0, 13.0]), "{m:?}\n{out}");
    }
}

#[test]
fn axis_words_before_any_motion_word_are_refused_or_read_in_the_power_on_mode() {
    // LinuxCNC refuses the block itself, whatever the flags.
    let lx = "G21 G90\nX0 Y0 Z5\nG1 X10 F100\nM2\n";
    for power_on in [None, Some(PowerOnMotion::Linear)] {
        let s = CompensationSettings {
            power_on_motion: power_on,
            ..settings(Dialect::Linuxcnc)
        };
        let err = compensate_gcode(lx, Path::new("t.ngc"), &Flat, &s).unwrap_err();
        let msg = err.to_string();
        assert_eq!(err.exit_code(), 2);
        assert!(msg.contains("t.ngc:2, column 1 (X0)"), "{msg}");
        assert!(
            msg.contains("Cannot use axis values without a g code that uses them"),
            "{msg}"
        );
    }
    // Fanuc and Sinumerik: refused without the flag, naming it; followed with it.
    for (dialect, text, param) in [
        (
            Dialect::Fanuc,
            "O1\nG21 G90\nX0. Y0. Z5.\nG1 X10. F100.\nM30\n",
            "parameter 3402#0",
        ),
        (
            Dialect::Sinumerik,
            "G71 G90\nX0 Y0 Z5\nG1 X10 F100\nM30\n",
            "MD20150",
        ),
    ] {
        let err = compensate_gcode(text, Path::new("t.nc"), &Flat, &settings(dialect))
            .unwrap_err()
            .to_string();
        assert!(err.contains(param), "{dialect:?}: {err}");
        assert!(
            err.contains("--power-on-motion g0|g1"),
            "{dialect:?}: {err}"
        );
        // As G0 the block positions the tool, and X10 is then a compensated cut.
        let s = CompensationSettings {
            power_on_motion: Some(PowerOnMotion::Rapid),
            ..settings(dialect)
        };
        let (out, report) = compensate_gcode(text, Path::new("t.nc"), &Flat, &s).unwrap();
        assert_eq!(report.moves_changed, 1, "{out}");
        let moves = trace_gcode(text, Path::new("t.nc"), &s).unwrap();
        assert!(
            moves.iter().any(|m| m.end_mm == [10.0, 0.0, 5.0]),
            "{moves:?}"
        );
        // As G1 it is a cut from an unknown position: refused for that, not for the mode.
        let s = CompensationSettings {
            power_on_motion: Some(PowerOnMotion::Linear),
            ..settings(dialect)
        };
        let err = compensate_gcode(text, Path::new("t.nc"), &Flat, &s)
            .unwrap_err()
            .to_string();
        assert!(err.contains("start point of this move is unknown"), "{err}");
        assert!(!err.contains("--power-on-motion"), "{err}");
    }
}
