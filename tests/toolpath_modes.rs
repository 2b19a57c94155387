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

#[path = "common/path_judge.rs"]
mod path_judge;
#[path = "common/rs274_canon.rs"]
mod rs274_canon;
#[path = "common/sloped_field.rs"]
mod sloped_field;

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

/// Equal within what rs274 prints (4 decimals: two values a hair apart can print one unit,
/// 0.0001 in = 2.54 µm, apart in inch mode).
fn close(a: [f64; 3], b: [f64; 3]) -> bool {
    (0..3).all(|i| (a[i] - b[i]).abs() < RS274_TOL_MM)
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
        assert!(
            matches!(err, errmap::toolpath::CompensateError::Program(_)),
            "{msg}"
        );
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
            err.contains("`power_on_motion` g0|g1"),
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
        assert!(!err.contains("`power_on_motion`"), "{err}");
    }
}

// ---------------------------------------------------------------------------------------------
// Property: random LinuxCNC programs that switch G90/G91, G20/G21 and G17/G18/G19 between and
// on compensated moves, return with G28/G30/G53 after cuts, and move with axis-only blocks,
// compensated and then run by rs274 beside their original. rs274 is the judge of both: the
// output's rapids are the original's, and every cutting point of the output lies on the
// original's path, lowered by E inside the zone and measured domain and unchanged outside.

use sloped_field::{sloped_e_mm, Sloped, CHORD_TOL_MM, X_MEASURED_MM, ZONE_MM};

/// A random program and the modes it leaves at each line, as the controller reads it.
struct Generator {
    text: String,
    /// Position reached, mm.
    pos: [f64; 3],
    inch: bool,
    absolute: bool,
    plane: u8,
    /// The modal motion: 0 rapid, 1 feed, 2/3 arcs.
    motion: u8,
}

impl Generator {
    fn new() -> Generator {
        Generator {
            text: "G21 G90 G17 G40 G49 G80 F100\nG0 X0 Y0 Z2\n".into(),
            pos: [0.0, 0.0, 2.0],
            inch: false,
            absolute: true,
            plane: 17,
            motion: 0,
        }
    }

    fn scale(&self) -> f64 {
        if self.inch {
            25.4
        } else {
            1.0
        }
    }

    fn decimals(&self) -> i32 {
        if self.inch {
            5
        } else {
            4
        }
    }

    /// The words that move to `target` (mm) in the current modes, and the point the controller
    /// reaches from them.
    fn axis_words(&self, target: [f64; 3]) -> (String, [f64; 3]) {
        let (k, d) = (self.scale(), self.decimals());
        let mut words = String::new();
        let mut reached = self.pos;
        for (i, l) in ["X", "Y", "Z"].iter().enumerate() {
            let t = if self.absolute {
                target[i]
            } else {
                target[i] - self.pos[i]
            };
            let v = (t / k * 10f64.powi(d)).round() / 10f64.powi(d) + 0.0;
            words.push_str(&format!(" {l}{v:.p$}", p = d as usize));
            reached[i] = if self.absolute {
                v * k
            } else {
                self.pos[i] + v * k
            };
        }
        (words, reached)
    }

    /// Mode switches for the next line (perhaps none), applied to the state.
    fn switches(&mut self, rng: &mut impl rand::Rng) -> String {
        let mut s = String::new();
        if rng.random_bool(0.15) {
            self.inch = !self.inch;
            s.push_str(if self.inch { "G20 " } else { "G21 " });
        }
        if rng.random_bool(0.2) {
            self.absolute = !self.absolute;
            s.push_str(if self.absolute { "G90 " } else { "G91 " });
        }
        if rng.random_bool(0.15) {
            self.plane = [17, 18, 19][rng.random_range(0..3)];
            s.push_str(&format!("G{} ", self.plane));
        }
        s
    }

    fn random_point(rng: &mut impl rand::Rng) -> [f64; 3] {
        [
            rng.random_range(-20..=20) as f64 * 0.25,
            rng.random_range(-20..=20) as f64 * 0.25,
            -3.0 + 0.3 * rng.random_range(0..=13) as f64,
        ]
    }

    fn line(&mut self, text: &str) {
        self.text.push_str(text.trim());
        self.text.push('\n');
    }

    /// One random block (or a few, for a return and the move that positions again).
    fn step(&mut self, rng: &mut impl rand::Rng) {
        let r: f64 = rng.random();
        if r < 0.12 {
            // A switch on a line of its own.
            let s = self.switches(rng);
            self.line(&s);
        } else if r < 0.2 {
            self.ret(rng);
        } else if r < 0.3 && self.motion <= 1 {
            // An axis-only block in the modal G0 or G1.
            let (words, reached) = self.axis_words(Self::random_point(rng));
            self.line(&words);
            self.pos = reached;
        } else if r < 0.4 {
            let s = self.switches(rng);
            let (words, reached) = self.axis_words(Self::random_point(rng));
            self.line(&format!("{s}G0{words}"));
            self.motion = 0;
            self.pos = reached;
        } else if r < 0.75 {
            let s = self.switches(rng);
            let (words, reached) = self.axis_words(Self::random_point(rng));
            self.line(&format!("{s}G1{words}"));
            self.motion = 1;
            self.pos = reached;
        } else {
            self.arc(rng);
        }
    }

    /// A return to a machine position after the cuts, then an absolute rapid that positions
    /// the tool again (errmap follows cuts once X, Y and Z are known).
    fn ret(&mut self, rng: &mut impl rand::Rng) {
        let (text, keeps_g91) = match rng.random_range(0..4) {
            0 => ("G91 G28 Z0", true),
            1 => ("G28", false),
            2 => ("G91 G30 Z0", true),
            _ => ("G53 G0 Z5", false),
        };
        if text.starts_with("G53") && !self.absolute {
            // LinuxCNC takes G53 under G90 only.
            self.line("G90");
        }
        self.line(text);
        if keeps_g91 {
            self.absolute = false;
        }
        if text.starts_with("G53") {
            self.motion = 0;
        }
        // The next block comes in whatever mode the return left (often G91): the rapid that
        // positions again says G90.
        self.absolute = true;
        let target = Self::random_point(rng);
        let (words, reached) = self.axis_words([target[0], target[1], 1.0]);
        self.line(&format!("G90 G0{words}"));
        self.motion = 0;
        self.pos = reached;
    }

    /// An arc in the XY plane (G17 said on the line when another plane is selected), I J form,
    /// about a centre 1–4 mm away, helical or flat.
    fn arc(&mut self, rng: &mut impl rand::Rng) {
        // The plane word of the switches is dropped: the arc says G17 where it must.
        let plane_before = self.plane;
        let mut s = self.switches(rng);
        for g in ["G17 ", "G18 ", "G19 "] {
            s = s.replace(g, "");
        }
        self.plane = plane_before;
        if self.plane != 17 {
            s.push_str("G17 ");
            self.plane = 17;
        }
        let (k, d) = (self.scale(), self.decimals());
        let rad = rng.random_range(1.0..4.0);
        let phi0: f64 = rng.random_range(0.0..std::f64::consts::TAU);
        let centre = [
            self.pos[0] - rad * phi0.cos(),
            self.pos[1] - rad * phi0.sin(),
        ];
        let mut sweep = rng.random_range(20.0..160.0_f64).to_radians();
        if rng.random_bool(0.5) {
            sweep = -sweep;
        }
        let z_end = if rng.random_bool(0.5) {
            self.pos[2]
        } else {
            Self::random_point(rng)[2]
        };
        let target = [
            centre[0] + rad * (phi0 + sweep).cos(),
            centre[1] + rad * (phi0 + sweep).sin(),
            z_end,
        ];
        let (words, reached) = self.axis_words(target);
        let q = |v: f64| (v / k * 10f64.powi(d)).round() / 10f64.powi(d) + 0.0;
        let (i, j) = (q(centre[0] - self.pos[0]), q(centre[1] - self.pos[1]));
        // rs274 refuses an end point off the circle by more than its tolerance: keep arcs whose
        // rounded end lies on the rounded circle.
        let c = [self.pos[0] + i * k, self.pos[1] + j * k];
        let r_start = (self.pos[0] - c[0]).hypot(self.pos[1] - c[1]);
        let r_end = (reached[0] - c[0]).hypot(reached[1] - c[1]);
        if (r_end - r_start).abs() > 5e-4 {
            self.line(&s);
            return;
        }
        let g = if sweep < 0.0 { "G2" } else { "G3" };
        self.line(&format!("{s}{g}{words} I{i:.p$} J{j:.p$}", p = d as usize));
        self.motion = if sweep < 0.0 { 2 } else { 3 };
        self.pos = reached;
    }
}

/// A motion of rs274's canonical output, mm.
#[derive(Debug, Clone)]
struct CanonMove {
    cut: bool,
    start: [f64; 3],
    end: [f64; 3],
    /// XY arcs: centre, start angle, signed sweep, start and end radius.
    arc: Option<([f64; 2], f64, f64, f64, f64)>,
}

/// rs274's motions of a program (read by tests/common/rs274_canon.rs), with each XY arc's
/// start angle and radii; `None` when rs274 is missing.
fn rs274_moves(program: &str) -> Option<Vec<CanonMove>> {
    corpus()?;
    let tmp = tempfile::tempdir().unwrap();
    let segs = match rs274_canon::run(tmp.path(), "p", program.as_bytes())? {
        Ok(segs) => segs,
        Err(e) => panic!("{e}\n{program}"),
    };
    let moves = segs
        .iter()
        .map(|s| {
            let arc = s.arc.as_ref().map(|a| {
                assert_eq!(a.axes, (0, 1, 2), "an arc outside the XY plane\n{program}");
                let c = [a.centre.0, a.centre.1];
                let a0 = (s.start[1] - c[1]).atan2(s.start[0] - c[0]);
                let r0 = (s.start[0] - c[0]).hypot(s.start[1] - c[1]);
                let r1 = (s.end[0] - c[0]).hypot(s.end[1] - c[1]);
                (c, a0, a.sweep_rad, r0, r1)
            });
            CanonMove {
                cut: s.cut,
                start: s.start,
                end: s.end,
                arc,
            }
        })
        .collect();
    Some(moves)
}

/// Where `q` lies on original move `m`: the original z there and how far off it a printed
/// point may be (the printing tolerance, plus the slope times the tolerance in the plane)
/// (`Some(None)` on a vertical move), or `None` when `q` is off the move by more than `tol_xy`
/// in the plane.
fn on_canon_move(m: &CanonMove, q: &[f64; 3], tol_xy: f64) -> Option<Option<(f64, f64)>> {
    let (a, b) = (m.start, m.end);
    if let Some((c, a0, sweep, r0, r1)) = m.arc {
        let (dx, dy) = (q[0] - c[0], q[1] - c[1]);
        let tau = std::f64::consts::TAU;
        let turned = ((dy.atan2(dx) - a0) * sweep.signum()).rem_euclid(tau);
        // Rounding puts a point at the start a hair before it: within the tolerance along the
        // arc, it is the start (or the end).
        let along = tol_xy / r0.max(1e-9);
        let turned = if turned > tau - along { 0.0 } else { turned };
        let s = turned / sweep.abs();
        if s > 1.0 + along / sweep.abs() {
            return None;
        }
        let r = r0 + s.min(1.0) * (r1 - r0);
        let z = a[2] + s.min(1.0) * (b[2] - a[2]);
        let slope = (b[2] - a[2]).abs() / (sweep.abs() * r0.max(1e-9));
        let z_tol = RS274_TOL_MM * (1.0 + slope);
        return ((dx.hypot(dy) - r).abs() < tol_xy).then_some(Some((z, z_tol)));
    }
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len2 = dx * dx + dy * dy;
    if len2 < 1e-12 {
        let near = (a[0] - q[0]).hypot(a[1] - q[1]) < tol_xy;
        let (lo, hi) = (a[2].min(b[2]), a[2].max(b[2]));
        return (near && q[2] >= lo - 0.1 && q[2] <= hi + 0.1).then_some(None);
    }
    let t = ((q[0] - a[0]) * dx + (q[1] - a[1]) * dy) / len2;
    let (px, py) = (a[0] + t * dx, a[1] + t * dy);
    let t_tol = tol_xy / len2.sqrt();
    let ok = (-t_tol..=1.0 + t_tol).contains(&t) && (px - q[0]).hypot(py - q[1]) < tol_xy;
    let slope = (b[2] - a[2]).abs() / len2.sqrt();
    let z_tol = RS274_TOL_MM * (1.0 + slope);
    ok.then_some(Some((a[2] + t.clamp(0.0, 1.0) * (b[2] - a[2]), z_tol)))
}

/// rs274 prints 4 decimals: in inch mode each coordinate is rounded by up to 1.3 µm, and two
/// values a hair apart can print 2.54 µm apart.
const RS274_TOL_MM: f64 = 3e-3;
/// How far a printed point may lie off the path through other printed points (an arc's
/// start, centre and end, each rounded so).
const RS274_PATH_TOL_MM: f64 = 6e-3;

/// rs274's run of the output against its run of the original: the same rapids in the same
/// order, and every cutting point on the original's cutting path (in order), at z − E inside
/// the zone and measured domain and at z outside. Returns (compensated, unchanged) counts.
fn judge(orig: &[CanonMove], out: &[CanonMove], what: &str) -> (usize, usize) {
    let rapids =
        |m: &[CanonMove]| -> Vec<[f64; 3]> { m.iter().filter(|m| !m.cut).map(|m| m.end).collect() };
    let (ro, rc) = (rapids(orig), rapids(out));
    assert_eq!(ro.len(), rc.len(), "{what}: rapid count");
    for (a, b) in ro.iter().zip(&rc) {
        assert!(
            close(*a, *b),
            "{what}: rapid to {b:?}, the original's to {a:?}"
        );
    }
    let cuts: Vec<&CanonMove> = orig.iter().filter(|m| m.cut).collect();
    let (mut k, mut compensated, mut unchanged) = (0, 0, 0);
    // The cuts after a rapid of the output follow the cuts after the same rapid of the
    // original: the search moves on to there at each rapid.
    let mut orig_rapid_index = 0;
    for m in out {
        if !m.cut {
            // Advance the original's cut cursor past the matching rapid.
            let idx = orig
                .iter()
                .enumerate()
                .filter(|(_, m)| !m.cut)
                .nth(orig_rapid_index)
                .map(|(i, _)| i)
                .unwrap();
            orig_rapid_index += 1;
            k = k.max(orig[..idx].iter().filter(|m| m.cut).count());
            continue;
        }
        let q = m.end;
        let e = sloped_e_mm(q[0]);
        let z_ok = |k: usize| match on_canon_move(cuts[k], &q, RS274_PATH_TOL_MM) {
            Some(Some((z, tol))) => (q[2] - z).abs() < tol || (q[2] - (z - e)).abs() < tol,
            Some(None) => true,
            None => false,
        };
        while k < cuts.len() && !z_ok(k) {
            k += 1;
        }
        assert!(
            k < cuts.len(),
            "{what}: cut to {q:?} lies on no original cut"
        );
        if m.arc.is_none() {
            let mid = [0, 1, 2].map(|i| 0.5 * (m.start[i] + m.end[i]));
            let near = (k.saturating_sub(1)..=k)
                .any(|j| on_canon_move(cuts[j], &mid, CHORD_TOL_MM + RS274_PATH_TOL_MM).is_some());
            assert!(near, "{what}: the chord to {q:?} leaves the original path");
        }
        let Some(Some((z, z_tol))) = on_canon_move(cuts[k], &q, RS274_PATH_TOL_MM) else {
            continue;
        };
        // On a steep move the printed point's z is known only roughly: too roughly to tell
        // z from z − E there.
        if z_tol > e / 3.0 {
            continue;
        }
        // A step along Z (a return to the original, or the step at a zone or domain edge)
        // ends at z or z − E: checked above; which one is the move's business, not the point's.
        if (m.start[0] - q[0]).hypot(m.start[1] - q[1]) < RS274_PATH_TOL_MM {
            continue;
        }
        let slack = z_tol.max(RS274_TOL_MM);
        let inside =
            (ZONE_MM.0 + slack..=ZONE_MM.1 - slack).contains(&z) && q[0] < X_MEASURED_MM - slack;
        let outside =
            !(ZONE_MM.0 - slack..=ZONE_MM.1 + slack).contains(&z) || q[0] > X_MEASURED_MM + slack;
        if inside {
            assert!(
                (q[2] - (z - e)).abs() < z_tol,
                "{what}: {q:?} not compensated (original z {z})"
            );
            compensated += 1;
        }
        if outside {
            assert!(
                (q[2] - z).abs() < z_tol,
                "{what}: {q:?} changed outside (original z {z})"
            );
            unchanged += 1;
        }
    }
    (compensated, unchanged)
}

#[test]
fn random_mode_switches_returns_and_axis_only_blocks_run_in_rs274_as_the_original_minus_e() {
    use rand::SeedableRng;
    let require = std::env::var("ERRMAP_REQUIRE_RS274").is_ok_and(|v| v == "1");
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(22);
    let s = CompensationSettings {
        zone: Some(ZONE_MM),
        dialect: Some(Dialect::Linuxcnc),
        max_segment: 2.0,
        chord_tol: CHORD_TOL_MM,
        ..CompensationSettings::default()
    };
    let (mut totals, mut runs, mut returns) = ((0, 0), 0, 0);
    for case in 0..40 {
        let mut g = Generator::new();
        for _ in 0..30 {
            g.step(&mut rng);
        }
        g.line("M2");
        let text = g.text;
        let what = format!("case {case}");
        let (out, report) = compensate_gcode(&text, Path::new("p.ngc"), &Sloped, &s)
            .unwrap_or_else(|e| panic!("{what}: refused: {e}\n{text}"));
        returns += report.returns_inserted;
        let (Some(orig), Some(comp)) = (rs274_moves(&text), rs274_moves(&out)) else {
            assert!(!require, "ERRMAP_REQUIRE_RS274=1 but rs274 is missing");
            println!("SKIPPED: rs274 or ../shared/corpus/gcode/rs274-check.sh not found");
            return;
        };
        let (c, u) = judge(
            &orig,
            &comp,
            &format!("{what}\n{text}\n--- output ---\n{out}"),
        );
        totals.0 += c;
        totals.1 += u;
        runs += 1;
    }
    println!("rs274 judged {runs} programs: {totals:?} points (compensated, unchanged), {returns} returns inserted");
    // The programs reach both sides of the zone and domain edges, and return after cuts.
    assert!(totals.0 > 200 && totals.1 > 200, "{totals:?}");
    assert!(returns > 20, "{returns}");
}

// ---------------------------------------------------------------------------------------------
// States errmap does not follow across blocks: modes a called subroutine changes, rotary axes
// away from 0, Fadal subprograms. Each was a program written wrong with exit 0.

#[test]
fn a_subroutine_that_changes_the_distance_mode_refuses_the_cuts_after_its_call() {
    let text =
        "G21 G90\no100 sub\nG91\no100 endsub\nG0 X5 Y0 Z1\no100 call\nG1 X10 Z-1 F100\nG90\nM2\n";
    let err = compensate_gcode(
        text,
        Path::new("t.ngc"),
        &Flat,
        &settings(Dialect::Linuxcnc),
    )
    .unwrap_err()
    .to_string();
    assert!(
        err.contains("t.ngc:7")
            && err.contains("distance (G90/G91)")
            && err.contains("line 3 in o100"),
        "{err}"
    );
    // Saying the mode again after the call ends it: the cut is read in G90.
    let said = text.replace("o100 call\n", "o100 call\nG90\n");
    let (out, _) = compensate_gcode(
        &said,
        Path::new("t.ngc"),
        &Flat,
        &settings(Dialect::Linuxcnc),
    )
    .unwrap();
    assert!(out.contains("G1 X10.0000 Y0.0000 Z-1.0200"), "{out}");
    // With --expand the subroutine runs: rs274 ends the cut at the original's end minus E.
    let s = CompensationSettings {
        expand: true,
        ..settings(Dialect::Linuxcnc)
    };
    let (out, _) = compensate_gcode(text, Path::new("t.ngc"), &Flat, &s).unwrap();
    if let (Some(o), Some(c)) = (rs274_motions(text), rs274_motions(&out)) {
        let (o, c) = (o.last().unwrap().1, c.last().unwrap().1);
        assert!(close(o, [15.0, 0.0, 0.0]), "{o:?}");
        assert!(close(c, [15.0, 0.0, -E_MM]), "{c:?}\n{out}");
    }
}

#[test]
fn a_rotary_axis_away_from_0_refuses_the_cuts_until_it_is_back() {
    for (dialect, at, text) in [
        (
            Dialect::Linuxcnc,
            "t.nc:4,",
            "G21 G90\nG0 X0 Y0 Z10\nG0 B30\nG1 Z-1 F100\nG1 X10\nM2\n",
        ),
        (
            Dialect::Sinumerik,
            "t.nc:4,",
            "G71 G90\nG0 X0 Y0 Z10\nG0 B30\nG1 Z-1 F100\nG1 X10\nM30\n",
        ),
        (
            Dialect::Fanuc,
            "t.nc:5,",
            "O1\nG21 G90\nG0 X0. Y0. Z10.\nG0 A90.\nG1 Z-1. F100.\nG1 X10.\nM30\n",
        ),
    ] {
        let err = compensate_gcode(text, Path::new("t.nc"), &Flat, &settings(dialect))
            .unwrap_err()
            .to_string();
        // Refused at the first cut after the turn.
        assert!(err.contains(at), "{dialect:?}: {err}");
        assert!(err.contains("stands away from 0"), "{dialect:?}: {err}");
        // Back at 0 before the cuts, the map applies.
        let back = text
            .replace("G0 B30\n", "G0 B30\nG0 B0\n")
            .replace("G0 A90.\n", "G0 A90.\nG0 A0.\n");
        let (_, report) =
            compensate_gcode(&back, Path::new("t.nc"), &Flat, &settings(dialect)).unwrap();
        assert_eq!(report.moves_changed, 2, "{dialect:?}");
    }
}

#[test]
fn fadal_subprograms_and_repeat_counts_are_refused() {
    let s = CompensationSettings {
        units: Some(errmap::toolpath::Units::Mm),
        ..settings(Dialect::Fanuc)
    };
    for (text, word) in [
        (
            "O1\nG0 G90 X0. Y0. Z5.\nL100\nX1. Y1.\nM17\nG1 Z-1. F100.\nM30\n",
            "L100",
        ),
        (
            "O1\nG0 G90 X0. Y0. Z5.\nG1 Z-1. F100.\nG91 G3 I-2. Z-0.2 L19\nG90\nM30\n",
            "L19",
        ),
    ] {
        let err = compensate_gcode(text, Path::new("t.nc"), &Flat, &s)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains(&format!("({word})")) && err.contains("Fadal"),
            "{err}"
        );
    }
    // L as M98's repeat count stays a repeat count (the call itself is refused, naming M98).
    let err = compensate_gcode(
        "O1\nG0 G90 X0. Y0. Z5.\nM98 P2 L3\nM30\n",
        Path::new("t.nc"),
        &Flat,
        &s,
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("M98") && !err.contains("Fadal"), "{err}");
}
