//! Cutter radius compensation (G41/G42, Klartext RL/RR) with a Z map under G17 / tool axis Z: the compensated contour keeps every plane coordinate and arc centre, only Z gets −E, no block without X/Y motion is written while compensation is on, and what errmap cannot keep exact is refused; LinuxCNC's rs274 checks the offset path, the Klartext reference tracer the programmed one.

#[path = "common/klartext_trace.rs"]
mod klartext_trace;
#[path = "common/path_judge.rs"]
mod path_judge;

use errmap::geom::{Axis, ErrorField};
use errmap::toolpath::{compensate_gcode, CompensationSettings, Dialect};
use std::path::{Path, PathBuf};
use std::process::Command;

/// E = e0 + gx·x + gy·y mm along Z, everywhere measured.
struct Plane {
    e0: f64,
    gx: f64,
    gy: f64,
}

impl Plane {
    fn e(&self, x: f64, y: f64) -> f64 {
        self.e0 + self.gx * x + self.gy * y
    }
}

impl ErrorField for Plane {
    fn normal(&self) -> Axis {
        Axis::Z
    }
    fn error_mm(&self, u: f64, v: f64) -> Option<f64> {
        (u.abs() <= 1000.0 && v.abs() <= 1000.0).then(|| self.e(u, v))
    }
    fn measured(&self, _u: f64, _v: f64, _margin: f64) -> Option<bool> {
        Some(true)
    }
}

const FIELD: Plane = Plane {
    e0: 0.02,
    gx: 0.001,
    gy: 0.0005,
};

fn settings(zone: (f64, f64), chord_tol: f64) -> CompensationSettings {
    CompensationSettings {
        zone: Some(zone),
        dialect: Some(Dialect::Linuxcnc),
        chord_tol,
        ..CompensationSettings::default()
    }
}

/// A pocket wall at Z−1 under G41: entry line, two lines, a half circle about (20, 10), exit.
const CONTOUR: &str = "G21 G90 G17
G0 X-10 Y-5 Z5
G1 Z-1 F100
G41 D1
G1 X0 Y0 (entry)
G1 X20 Y0
G3 X20 Y20 I0 J10
G1 X0 Y20
G0 Z5
G40
G0 X-10 Y30
M2
";

/// A move of a program as written, read independently of errmap: absolute G90 mm only.
#[derive(Debug, Clone)]
struct Mv {
    line: String,
    code: u32,
    end: [f64; 3],
    centre: Option<(f64, f64)>,
    start: [f64; 3],
}

fn moves(text: &str) -> Vec<Mv> {
    let mut pos = [0.0; 3];
    let mut code = 0;
    let mut out = Vec::new();
    for line in text.lines() {
        let body = line.split('(').next().unwrap_or("");
        let mut end = pos;
        let (mut i, mut j) = (None, None);
        let mut moved = false;
        for w in body.split_whitespace() {
            let (l, v) = w.split_at(1);
            let Ok(v) = v.parse::<f64>() else { continue };
            match l {
                "G" if [0.0, 1.0, 2.0, 3.0].contains(&v) => code = v as u32,
                "X" => (end[0], moved) = (v, true),
                "Y" => (end[1], moved) = (v, true),
                "Z" => (end[2], moved) = (v, true),
                "I" => i = Some(v),
                "J" => j = Some(v),
                _ => {}
            }
        }
        if moved {
            let centre = (code >= 2).then(|| (pos[0] + i.unwrap(), pos[1] + j.unwrap()));
            out.push(Mv {
                line: line.to_string(),
                code,
                end,
                centre,
                start: pos,
            });
            pos = end;
        }
    }
    out
}

/// The nearest point of the programmed contour (entry, lines and the half circle about
/// (20, 10)) to (x, y) in the plane, and its distance.
fn nearest_on_contour(x: f64, y: f64) -> ((f64, f64), f64) {
    let seg = |a: (f64, f64), b: (f64, f64)| {
        let (dx, dy) = (b.0 - a.0, b.1 - a.1);
        let t = (((x - a.0) * dx + (y - a.1) * dy) / (dx * dx + dy * dy)).clamp(0.0, 1.0);
        (a.0 + t * dx, a.1 + t * dy)
    };
    let mut cands = vec![
        seg((-10.0, -5.0), (0.0, 0.0)),
        seg((0.0, 0.0), (20.0, 0.0)),
        seg((20.0, 20.0), (0.0, 20.0)),
    ];
    let d = (x - 20.0).hypot(y - 10.0);
    if x >= 20.0 && d > 0.0 {
        cands.push((20.0 + (x - 20.0) * 10.0 / d, 10.0 + (y - 10.0) * 10.0 / d));
    }
    cands
        .into_iter()
        .map(|q| (q, (x - q.0).hypot(y - q.1)))
        .fold(
            ((0.0, 0.0), f64::INFINITY),
            |a, b| if b.1 < a.1 { b } else { a },
        )
}

fn off_contour(x: f64, y: f64) -> f64 {
    nearest_on_contour(x, y).1
}

#[test]
fn a_contour_under_g41_keeps_its_plane_path_and_arcs_and_gets_z_minus_e() {
    let tol = 0.0002;
    let (out, report) = compensate_gcode(
        CONTOUR,
        Path::new("pocket.ngc"),
        &FIELD,
        &settings((-2.0, 0.0), tol),
    )
    .unwrap_or_else(|e| panic!("{e}"));
    println!("{out}");
    assert!(report.moves_changed >= 4, "{}", report.summary_line());
    let mv = moves(&out);
    let comp_on = out.lines().position(|l| l.starts_with("G41")).unwrap();
    let comp_off = out.lines().position(|l| l.starts_with("G40")).unwrap();
    // The D word and the entry comment stay where they were.
    assert!(out.contains("G41 D1\n"));
    assert!(out.contains("(entry)"));
    let mut arcs = 0;
    for m in &mv {
        let at = out.lines().position(|l| l == m.line).unwrap();
        let active = at > comp_on && at < comp_off;
        let in_plane = (m.end[0] - m.start[0]).hypot(m.end[1] - m.start[1]) > 1e-9;
        // While compensation is on, only the program's own retract moves Z alone.
        if active && !in_plane {
            assert_eq!(m.line, "G0 Z5", "a block without X/Y motion under G41");
        }
        if !(active && m.end[2] < 0.0) {
            continue;
        }
        // Every point at depth: on the programmed contour, Z = −1 − E(x, y).
        assert!(off_contour(m.end[0], m.end[1]) < 1e-4, "{}", m.line);
        let want = -1.0 - FIELD.e(m.end[0], m.end[1]);
        assert!(
            (m.end[2] - want).abs() < 1e-4,
            "{}: want Z{want:.4}",
            m.line
        );
        if let Some((cx, cy)) = m.centre {
            arcs += 1;
            // Arc pieces turn counter-clockwise about the programmed centre, and the helix
            // stays within the tolerance of P − E between its ends.
            assert_eq!(m.code, 3, "{}", m.line);
            assert!(
                (cx - 20.0).abs() < 2e-4 && (cy - 10.0).abs() < 2e-4,
                "{}",
                m.line
            );
            let t0 = (m.start[1] - 10.0).atan2(m.start[0] - 20.0);
            let t1 = (m.end[1] - 10.0).atan2(m.end[0] - 20.0);
            let sweep = (t1 - t0).rem_euclid(std::f64::consts::TAU);
            for k in 1..20 {
                let f = f64::from(k) / 20.0;
                let t = t0 + f * sweep;
                let (x, y) = (20.0 + 10.0 * t.cos(), 10.0 + 10.0 * t.sin());
                let z = m.start[2] + f * (m.end[2] - m.start[2]);
                let dev = (z - (-1.0 - FIELD.e(x, y))).abs();
                assert!(dev <= tol + 2e-4, "{}: {dev} at {f}", m.line);
            }
        } else {
            assert_eq!(m.code, 1, "{}", m.line);
        }
    }
    // 180° about r = 10 mm: at least two quarter pieces, more to follow the tilted plane
    // within 0.2 µm; the chords of a 0.2 µm tolerance would be over 200.
    assert!((2..100).contains(&arcs), "{arcs} arc pieces");
    // The entry move is one block straight to its compensated end.
    let entry: Vec<_> = mv.iter().filter(|m| m.line.contains("(entry)")).collect();
    assert_eq!(entry.len(), 1);
    assert!((entry[0].end[2] - (-1.0 - FIELD.e(0.0, 0.0))).abs() < 1e-4);
    // Lines outside compensation and the zone are copied byte for byte.
    assert!(out.contains("\nG0 Z5\nG40\nG0 X-10 Y30\nM2\n"));
}

#[test]
fn steps_at_the_zone_edge_ride_on_the_next_piece_under_g41() {
    // The wall climbs out of the zone (Z > 0 is outside) along a ramp: the cut leaves the zone
    // mid-move, and its step back to the program's Z is merged into the next piece.
    let text = "G21 G90 G17\nG0 X-5 Y0 Z5\nG1 Z-1 F100\nG41 D1\nG1 X0 Y0\nG1 X10 Y0 Z1\nG1 X20 Y0\nG0 Z5\nG40\nM2\n";
    let (out, _) = compensate_gcode(
        text,
        Path::new("ramp.ngc"),
        &FIELD,
        &settings((-2.0, 0.0), 0.005),
    )
    .unwrap_or_else(|e| panic!("{e}"));
    println!("{out}");
    let mv = moves(&out);
    for m in &mv {
        let in_plane = (m.end[0] - m.start[0]).hypot(m.end[1] - m.start[1]) > 1e-9;
        if m.start[0] >= 0.0 && m.end[0] <= 20.0 && m.line != "G0 Z5" && m.start[2] < 5.0 {
            assert!(in_plane, "Z-only block under G41: {}", m.line);
        }
    }
    // Along the ramp z = −1 + 0.2·x: compensated while z ≤ 0 (x ≤ 5), nominal after the piece
    // that carries the step; the end of the ramp and the flat run after it are nominal.
    for m in &mv {
        let (x, z) = (m.end[0], m.end[2]);
        if m.start[2] < 5.0 && (0.0..=20.0).contains(&x) && m.line.starts_with("G1") {
            let nominal = if x <= 10.0 { -1.0 + 0.2 * x } else { 1.0 };
            if nominal <= 0.0 {
                assert!((z - (nominal - FIELD.e(x, 0.0))).abs() < 1e-4, "{}", m.line);
            } else {
                assert!((z - nominal).abs() < 1e-4, "{}", m.line);
            }
        }
    }
    assert!(out.ends_with("G1 X20 Y0\nG0 Z5\nG40\nM2\n"), "{out}");
}

#[test]
fn the_return_after_a_compensated_cut_rides_on_the_next_move_under_g41() {
    // The contour dips into the zone and its next line, outside it, has no Z: errmap appends
    // the return (Z of the program) to that line instead of a Z-only block.
    let text = "G21 G90 G17\nG0 X-5 Y0 Z5\nG1 Z-1 F100\nG41 D1\nG1 X0 Y0\nG1 X5 Y0\nG1 Z1\nG1 X10 Y0 (next)\nG0 Z5\nG40\nM2\n";
    // Zone [−2, 0]: `G1 Z1` is a Z-only move of the program itself; it leaves the zone and
    // ends nominal, so `(next)` needs no return.
    let (out, _) = compensate_gcode(
        text,
        Path::new("r.ngc"),
        &FIELD,
        &settings((-2.0, 0.0), 0.005),
    )
    .unwrap();
    assert!(out.contains("G1 X10 Y0 (next)\n"), "{out}");
    // Without the Z-only line the cut ends compensated and the next line carries the return.
    let text = "G21 G90 G17\nG0 X-5 Y0 Z5\nG1 Z-1 F100\nG41 D1\nG1 X0 Y0\nG1 X5 Y0\nG0 X10 Y0 (next)\nG0 Z5\nG40\nM2\n";
    let (out, report) = compensate_gcode(
        text,
        Path::new("r.ngc"),
        &FIELD,
        &settings((-2.0, 0.0), 0.005),
    )
    .unwrap();
    println!("{out}");
    assert!(out.contains("G0 X10 Y0 Z-1.0000 (next)\n"), "{out}");
    assert_eq!(report.returns_inserted, 1);
    // A line that cannot carry it (a G91 Z-only move) is refused, naming it.
    let text = "G21 G90 G17\nG0 X-5 Y0 Z5\nG1 Z-1 F100\nG41 D1\nG1 X0 Y0\nG1 X5 Y0\nG28\nM2\n";
    let err = compensate_gcode(
        text,
        Path::new("r.ngc"),
        &FIELD,
        &settings((-2.0, 0.0), 0.005),
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("r.ngc:7"), "{err}");
    assert!(
        err.contains("block without motion in the compensation plane"),
        "{err}"
    );
    assert!(err.contains("G41 (line 4)"), "{err}");
}

#[test]
fn what_compensation_cannot_keep_exact_is_refused() {
    let s = settings((-2.0, 0.0), 0.005);
    let cases: [(&str, u64, &[&str]); 4] = [
        // G18 under a Z map: the control offsets in ZX, which Z − E would change.
        (
            "G21 G90 G18\nG0 X0 Y0 Z-1\nG41 D1\nG1 X10 Z-1 F100\n",
            4,
            &[
                "offsets the contour in the G18 plane",
                "normal axis Z",
                "G17",
            ],
        ),
        // An arc start-up block cannot stay one block exactly with a sloped map.
        (
            "G21 G90 G17\nG0 X0 Y0 Z-1\nG41 D1\nG3 X10 Y10 I10 J0 F100\n",
            4,
            &[
                "starts up cutter radius compensation (G41, line 3)",
                "it is an arc",
            ],
        ),
        // A start-up move that crosses the zone edge.
        (
            "G21 G90 G17\nG0 X0 Y0 Z1\nG41 G1 X10 Y0 Z-1 D1 F100\n",
            3,
            &[
                "starts up cutter radius compensation",
                "crosses the edge of the zone",
            ],
        ),
        // A D word on a move errmap splits: the new offset would be reached too early.
        (
            "G21 G90 G17\nG0 X-5 Y0 Z-1\nG41 D1\nG1 X0 Y0 F100\nG1 X20 Y0 D2\n",
            5,
            &["`D2` changes the cutter offset", "4 blocks"],
        ),
    ];
    for (text, line, wants) in cases {
        let err = compensate_gcode(text, Path::new("c.ngc"), &FIELD, &s)
            .map(|(o, _)| o)
            .expect_err(text)
            .to_string();
        assert!(err.contains(&format!("c.ngc:{line}")), "{err}");
        for w in wants {
            assert!(err.contains(w), "want `{w}`: {err}");
        }
    }
}

// ---- LinuxCNC's rs274 executes G41 with the tool table beside its script --------------------

fn corpus() -> Option<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/corpus/gcode");
    dir.join("rs274-check.sh").is_file().then_some(dir)
}

/// A canonical motion's end (x, y, z) and, for an arc, its centre.
type CanonMove = ([f64; 3], Option<(f64, f64)>);

/// STRAIGHT_FEED / ARC_FEED ends (x, y, z) and arc centres of a canonical output.
fn canon(text: &str) -> Vec<CanonMove> {
    let mut out = Vec::new();
    for l in text.lines() {
        let Some(open) = l.find('(') else { continue };
        let name = l[..open].split_whitespace().last().unwrap_or("");
        let a: Vec<f64> = l[open + 1..]
            .trim_end_matches(')')
            .split(',')
            .map(|v| v.trim().parse().unwrap_or(f64::NAN))
            .collect();
        match name {
            "STRAIGHT_FEED" | "STRAIGHT_TRAVERSE" => out.push(([a[0], a[1], a[2]], None)),
            "ARC_FEED" => out.push(([a[0], a[1], a[5]], Some((a[2], a[3])))),
            _ => {}
        }
    }
    out
}

#[test]
fn rs274_offsets_the_compensated_contour_as_the_original_and_moves_only_z() {
    let Some(dir) = corpus() else {
        assert!(std::env::var("ERRMAP_REQUIRE_RS274").as_deref() != Ok("1"));
        println!("skipped: ../shared/corpus/gcode not found");
        return;
    };
    let work = std::env::temp_dir().join(format!("errmap-comp-{}", std::process::id()));
    std::fs::create_dir_all(&work).unwrap();
    // rs274 needs a tool with a diameter: T1 (1/8 in) from the corpus tool table.
    let program = CONTOUR.replace("G21 G90 G17\n", "G21 G90 G17\nT1 M6\n");
    let (out, _) = compensate_gcode(
        &program,
        Path::new("pocket.ngc"),
        &FIELD,
        &settings((-2.0, 0.0), 0.0002),
    )
    .unwrap();
    let run = |name: &str, text: &str| -> Option<String> {
        let p = work.join(name);
        std::fs::write(&p, text).unwrap();
        let c = work.join(format!("{name}.canon"));
        let o = Command::new(dir.join("rs274-check.sh"))
            .arg(&p)
            .arg(&c)
            .output()
            .unwrap();
        match o.status.code() {
            Some(127) => None,
            Some(0) => Some(std::fs::read_to_string(&c).unwrap()),
            code => panic!("rs274 {code:?}: {}", String::from_utf8_lossy(&o.stderr)),
        }
    };
    let Some(orig) = run("orig.ngc", &program) else {
        assert!(std::env::var("ERRMAP_REQUIRE_RS274").as_deref() != Ok("1"));
        println!("skipped: rs274 not installed");
        return;
    };
    let new = run("comp.ngc", &out).unwrap();
    let (orig, new) = (canon(&orig), canon(&new));
    // The original's tool-centre path at depth, in the plane: segments and arcs.
    let r_tool = 0.0625 * 25.4;
    let on_orig = |p: [f64; 3]| {
        let mut best = f64::INFINITY;
        for w in orig.windows(2) {
            let (a, (b, c)) = (w[0].0, w[1]);
            let d = match c {
                None => {
                    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
                    let len2 = dx * dx + dy * dy;
                    let t = if len2 > 0.0 {
                        (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / len2).clamp(0.0, 1.0)
                    } else {
                        0.0
                    };
                    (p[0] - a[0] - t * dx).hypot(p[1] - a[1] - t * dy)
                }
                Some((cx, cy)) => {
                    let r = (b[0] - cx).hypot(b[1] - cy);
                    ((p[0] - cx).hypot(p[1] - cy) - r).abs()
                }
            };
            best = best.min(d);
        }
        best
    };
    let (mut checked, mut arcs) = (0, 0);
    for (p, centre) in &new {
        // Every new tool-centre point lies on the original's offset path.
        assert!(on_orig(*p) < 1e-3, "{p:?} off the original offset path");
        // Arcs turn about the original's centres: the programmed one, and the corner arc the
        // control inserts at the entry.
        if let Some((cx, cy)) = centre {
            let known = orig
                .iter()
                .filter_map(|(_, c)| *c)
                .any(|(ox, oy)| (cx - ox).abs() < 1e-3 && (cy - oy).abs() < 1e-3);
            assert!(known, "centre {cx} {cy} is not one of the original's");
            arcs += 1;
        }
        // At depth, past the plunge (made before G41 at X−10 Y−5).
        if p[2] < -0.5 && p[2] > -2.0 && (p[0] + 10.0).hypot(p[1] + 5.0) > 1e-6 {
            // The contour point the tool centre is offset from is the nearest programmed one,
            // one tool radius away: the offset is the original's. Z = −1 − E there.
            let (q, dist) = nearest_on_contour(p[0], p[1]);
            assert!(
                (dist - r_tool).abs() < 1e-3,
                "{p:?}: {dist} from the contour"
            );
            let want = -1.0 - FIELD.e(q.0, q.1);
            assert!((p[2] - want).abs() < 2e-4, "{p:?}: want Z {want}");
            checked += 1;
        }
    }
    assert!(checked >= 6, "{checked} points at depth");
    // The half circle stays arcs: more than the original's two (corner and half circle).
    assert!(arcs > 4, "{arcs} arcs");
    // Both end where the program ends.
    assert_eq!(orig.last().unwrap().0, new.last().unwrap().0);
    std::fs::remove_dir_all(&work).ok();
}

#[test]
fn a_piece_that_rounds_to_no_plane_motion_is_merged_into_the_next() {
    // The ramp X0 Z1 → X8 Z−1 (8.25 mm) is split at its middle, X4 Z0, and enters the zone
    // (Z ≤ 0.000005) at X3.99998, 0.02 µm before it: as written (4 decimals) both are X4.0000,
    // and the step to −E between them would be a block without X/Y motion.
    let text = "G21 G90 G17\nG0 X-5 Y0 Z1\nG41 D1\nG1 X0 Y0 F100\nG1 X8 Y0 Z-1\nG1 X15 Y0\nG0 Z5\nG40\nM2\n";
    let mut s = settings((-2.0, 0.000005), 0.005);
    s.max_segment = 5.0;
    let (out, _) = compensate_gcode(text, Path::new("ramp.ngc"), &FIELD, &s).unwrap();
    println!("{out}");
    let mv = moves(&out);
    let on = mv.iter().position(|m| m.line == "G1 X0 Y0 F100").unwrap();
    for m in &mv[on + 1..] {
        if m.line.starts_with("G0") {
            break;
        }
        let d = (m.end[0] - m.start[0]).hypot(m.end[1] - m.start[1]);
        assert!(d > 1e-9, "a block without X/Y motion under G41: {}", m.line);
    }
    // By hand: the ramp ends at Z−1 − E(8, 0) = −1.028, the run after it at −1 − E(15, 0).
    assert!(out.contains("G1 X8.0000 Y0.0000 Z-1.0280\n"), "{out}");
    assert!(out.contains("G1 X15.0000 Y0.0000 Z-1.0350\n"), "{out}");
}

// ---------------------------------------------------------------------------------------
// Klartext RL/RR: judged by the reference tracer (tests/common/klartext_trace.rs).

/// E = 0.02 + 0.001·x + 0.0005·y mm along Z (or along `normal`), measured for x ≤ `x_max`.
struct KtField {
    normal: Axis,
    flat: bool,
    x_max: f64,
}

impl KtField {
    fn e(&self, x: f64, y: f64) -> f64 {
        if self.flat {
            0.02
        } else {
            0.02 + 0.001 * x + 0.0005 * y
        }
    }
}

impl ErrorField for KtField {
    fn normal(&self) -> Axis {
        self.normal
    }
    fn error_mm(&self, u: f64, v: f64) -> Option<f64> {
        (u.abs() <= 1000.0 && v.abs() <= 1000.0).then(|| self.e(u, v))
    }
    fn measured(&self, u: f64, _v: f64, _margin: f64) -> Option<bool> {
        Some(u <= self.x_max)
    }
}

const KT_TILTED: KtField = KtField {
    normal: Axis::Z,
    flat: false,
    x_max: 1000.0,
};

fn kt(text: &str, field: &KtField) -> Result<String, String> {
    let settings = CompensationSettings {
        zone: Some((-2.0, 0.0)),
        dialect: Some(Dialect::Heidenhain),
        chord_tol: 0.001,
        ..CompensationSettings::default()
    };
    compensate_gcode(text, Path::new("wall.h"), field, &settings)
        .map(|(o, _)| o)
        .map_err(|e| e.to_string())
}

/// A pocket wall at Z−1 under RL: RL entry line, a line, a half circle about CC (20, 10), a
/// line, the R0 exit, all in the zone.
const KT_WALL: &str = "0 BEGIN PGM WALL MM
1 TOOL CALL 1 Z S3000
2 L X-10 Y-5 Z+5 R0 FMAX
3 L Z-1 F100
4 L X+0 Y+0 RL F200
5 L X+20 Y+0
6 CC X+20 Y+10
7 C X+20 Y+20 DR+
8 L X+0 Y+20
9 L X-10 Y+30 R0
10 L Z+5 FMAX
11 END PGM WALL MM
";

/// The programmed contour of KT_WALL in the plane, for the tilted-map check: the nearest point
/// of the traced original cuts that move in XY, and that cut's Z there.
fn on_original(orig: &[path_judge::Seg], p: [f64; 3]) -> (f64, f64) {
    orig.iter()
        .filter(|s| {
            s.cut
                && (s.arc.is_some() || (s.end[0] - s.start[0]).hypot(s.end[1] - s.start[1]) > 1e-9)
        })
        .map(|s| {
            // Distance in the plane: the point lifted to the cut's Z.
            let mut q = p;
            q[2] = s.start[2];
            (s.distance(&q), s.start[2])
        })
        .fold((f64::INFINITY, 0.0), |a, b| if b.0 < a.0 { b } else { a })
}

#[test]
fn klartext_rl_contour_keeps_its_plane_path_and_arcs_and_gets_z_minus_e() {
    let out = kt(KT_WALL, &KT_TILTED).unwrap();
    println!("{out}");
    let orig = klartext_trace::trace(KT_WALL).unwrap();
    let new = klartext_trace::trace(&out).unwrap();
    // Every output cut that moves in the plane: its points (ends and quarters) lie on the
    // programmed contour in XY, at Z = −1 − E(x, y) within --chord-tol (+ the last written
    // digit). The plunge (no plane motion) is judged apart.
    let mut checked = 0;
    for s in new.iter().filter(|s| s.cut) {
        let plane_len = (s.end[0] - s.start[0]).hypot(s.end[1] - s.start[1]);
        if s.arc.is_none() && plane_len < 1e-9 {
            continue;
        }
        for t in [0.25, 0.5, 0.75, 1.0] {
            let p = s.at(t);
            let (d, z) = on_original(&orig, p);
            assert!(
                d < 2e-4,
                "output line {} at {p:?} is {d} mm off the contour",
                s.line
            );
            let want = z - KT_TILTED.e(p[0], p[1]);
            assert!(
                (p[2] - want).abs() <= 0.001 + 1e-4,
                "output line {} at {p:?}: Z {} but −1 − E = {want}",
                s.line,
                p[2]
            );
            checked += 1;
        }
        if let Some(a) = &s.arc {
            // Arc pieces turn about the programmed centre.
            assert!((a.centre.0 - 20.0).abs() < 1e-9 && (a.centre.1 - 10.0).abs() < 1e-9);
        }
    }
    assert!(checked > 20, "{checked}");
    // The half circle is written as helical CP pieces about CC, never as chords.
    assert!(out.contains(" CP IPA+"), "{out}");
    assert!(new.iter().filter(|s| s.arc.is_some()).count() >= 2);
    // The RL and R0 blocks stay one block each, with their words; no block without XY motion
    // runs under RL that the original does not have.
    assert!(
        out.contains(" L X+0.0000 Y+0.0000 Z-1.0200 RL F200\n"),
        "{out}"
    );
    assert!(
        out.contains(" L X-10.0000 Y+30.0000 Z-1.0250 R0\n"),
        "{out}"
    );
    assert_eq!(klartext_trace::plane_less_blocks_under_comp(&out), 0);
    // Blocks renumbered in order.
    for (i, l) in out.lines().enumerate() {
        assert!(l.starts_with(&format!("{i} ")), "{l}");
    }
}

#[test]
fn klartext_rl_contour_with_a_flat_map_passes_the_judge() {
    let flat = KtField {
        normal: Axis::Z,
        flat: true,
        x_max: 1000.0,
    };
    let out = kt(KT_WALL, &flat).unwrap();
    let orig = klartext_trace::trace(KT_WALL).unwrap();
    let new = klartext_trace::trace(&out).unwrap();
    let v = path_judge::judge(&orig, &new, 0.02).unwrap();
    assert!(v.points_checked > 5, "{v:?}");
}

#[test]
fn klartext_steps_at_the_domain_edge_ride_on_the_next_piece_under_rl() {
    // The line X0 → X80 leaves the measured domain at X50: the step back to nominal Z rides
    // on the piece after it; then the return after the compensated arc rides on the R0 line.
    let field = KtField {
        normal: Axis::Z,
        flat: false,
        x_max: 50.0,
    };
    let text = "0 BEGIN PGM EDGE MM
1 TOOL CALL 1 Z S3000
2 L X-10 Y-5 Z-1 R0 FMAX
3 L X+0 Y+0 RL F200
4 L X+80 Y+0
5 L X+80 Y+20 R0
6 L Z+5 FMAX
7 END PGM EDGE MM
";
    let out = kt(text, &field).unwrap();
    println!("{out}");
    assert_eq!(
        klartext_trace::plane_less_blocks_under_comp(&out),
        0,
        "{out}"
    );
    let new = klartext_trace::trace(&out).unwrap();
    // Along the line every written end is at −1 − E inside the domain and −1 outside.
    let cuts: Vec<_> = new.iter().filter(|s| s.cut && s.end[1] == 0.0).collect();
    assert!(cuts.len() >= 2);
    for s in &cuts {
        let (x, z) = (s.end[0], s.end[2]);
        let want = if x <= 50.0 {
            -1.0 - field.e(x, 0.0)
        } else {
            -1.0
        };
        assert!((z - want).abs() < 1e-4, "{s:?}");
        assert!(
            (s.end[0] - s.start[0]).abs() > 1e-6,
            "a step without X/Y motion: {s:?}"
        );
    }
    assert!(cuts.iter().any(|s| s.end[0] == 80.0));
}

#[test]
fn klartext_what_rl_compensation_cannot_keep_exact_is_refused() {
    // After a compensated cut under RL, an incremental Z move cannot carry the return.
    let text = "0 BEGIN PGM R MM
1 TOOL CALL 1 Z S3000
2 L X-10 Y-5 Z-1 R0 FMAX
3 L X+0 Y+0 RL F200
4 L X+20 Y+0
5 L IZ+5 FMAX
6 L X+30 Y+0
7 L X+40 Y+10 R0
8 END PGM R MM
";
    let err = kt(text, &KT_TILTED).unwrap_err();
    assert!(err.contains("wall.h:6"), "{err}");
    assert!(
        err.contains(
            "block 5: a compensated cut under tool radius compensation RL (from block 3, line 4)"
        ),
        "{err}"
    );
    assert!(err.contains("cannot carry the return along Z"), "{err}");
    // The map's normal is not the tool axis: X map, tool axis Z.
    let x_map = KtField {
        normal: Axis::X,
        flat: true,
        x_max: 1000.0,
    };
    let err = kt(KT_WALL, &x_map).unwrap_err();
    assert!(
        err.contains("offsets the contour in the working plane of tool axis Z, which holds the map's normal axis X"),
        "{err}"
    );
    // A CR arc under RL in the zone: its centre is not the pole CC.
    let cr = KT_WALL
        .replace("6 CC X+20 Y+10\n", "6 L X+20 Y+0\n")
        .replace("7 C X+20 Y+20 DR+", "7 CR X+20 Y+20 R+10 DR+");
    let err = kt(&cr, &KT_TILTED).unwrap_err();
    assert!(
        err.contains("wall.h:8") && err.contains("arc CR under tool radius compensation RL"),
        "{err}"
    );
    // RL switched on in the zone on a block crossing the domain edge cannot stay one block.
    let edge = KtField {
        normal: Axis::Z,
        flat: false,
        x_max: -5.0,
    };
    let err = kt(KT_WALL, &edge).unwrap_err();
    assert!(err.contains("wall.h:5") && err.contains("this block starts tool radius compensation, so errmap must keep it one block, but it crosses the edge"), "{err}");
}
