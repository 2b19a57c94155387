//! `--expand`: Fanuc subprograms, macro calls, loops and variables run into plain blocks, each compensated point checked against P − E computed by hand; refusals name the original line.

mod common;
#[path = "common/path_judge.rs"]
mod path_judge;
#[path = "common/sinumerik_nci.rs"]
mod sinumerik_nci;

use errmap::geom::{Axis, ErrorField};
use errmap::toolpath::{compensate_gcode, CompensationSettings, Dialect, FanucNumbers};
use std::path::Path;

/// E = 0.01 + 0.001·x mm along Z, everywhere measured.
struct F;

impl ErrorField for F {
    fn normal(&self) -> Axis {
        Axis::Z
    }
    fn error_mm(&self, u: f64, v: f64) -> Option<f64> {
        (u.abs() <= 1000.0 && v.abs() <= 1000.0).then(|| e(u))
    }
    fn measured(&self, _u: f64, _v: f64, _margin: f64) -> Option<bool> {
        Some(true)
    }
}

fn e(x_mm: f64) -> f64 {
    0.01 + 0.001 * x_mm
}

fn settings(expand: bool) -> CompensationSettings {
    CompensationSettings {
        everywhere: true,
        dialect: Some(Dialect::Fanuc),
        max_segment: 1000.0,
        expand,
        ..CompensationSettings::default()
    }
}

fn run(text: &str, s: &CompensationSettings) -> String {
    compensate_gcode(text, Path::new("t.nc"), &F, s)
        .unwrap_or_else(|e| panic!("refused: {e}\n--- input ---\n{text}"))
        .0
}

fn refuse(text: &str, s: &CompensationSettings) -> String {
    match compensate_gcode(text, Path::new("t.nc"), &F, s) {
        Ok((out, _)) => panic!("expected a refusal, got:\n{out}"),
        Err(e) => e.to_string(),
    }
}

fn word(line: &str, letter: char) -> Option<f64> {
    line.split_whitespace()
        .find_map(|w| w.strip_prefix(letter))
        .and_then(|v| v.trim_end_matches(';').parse().ok())
}

/// (x, y, z) of every output block that writes all three, in order.
fn points(out: &str) -> Vec<[f64; 3]> {
    out.lines()
        .filter_map(|l| Some([word(l, 'X')?, word(l, 'Y')?, word(l, 'Z')?]))
        .collect()
}

/// The cut end points `(x, y, z)` compensated by hand: z − E(x). The first cut starts in the
/// zone, so its start point gets a step to z − E first (listed as a cut).
fn expect(out: &str, first: [f64; 3], cuts: &[[f64; 3]]) {
    let got = points(out);
    let mut want = vec![first];
    want.extend(cuts.iter().map(|p| [p[0], p[1], p[2] - e(p[0])]));
    assert_eq!(got.len(), want.len(), "{out}");
    for (g, w) in got.iter().zip(&want) {
        for k in 0..3 {
            assert!((g[k] - w[k]).abs() < 1e-6, "got {g:?}, want {w:?}\n{out}");
        }
    }
}

fn assert_msg(msg: &str, parts: &[&str]) {
    for p in parts {
        assert!(msg.contains(p), "`{p}` not in: {msg}");
    }
}

const WHILE_LOOP: &str = "O0001
G21 G90 G17
G0 X0. Y0. Z5.
#1=0
WHILE [#1 LT 3] DO1
#2=10.*[#1+1]
G1 X#2 Y[#1*2.] Z-1. F100.
#1=#1+1
END1
G0 Z5.
M30
";

#[test]
fn while_loop_with_variables_is_run_and_compensated() {
    let out = run(WHILE_LOOP, &settings(true));
    expect(
        &out,
        [0.0, 0.0, 5.0],
        &[
            [0.0, 0.0, 5.0],
            [10.0, 0.0, -1.0],
            [20.0, 2.0, -1.0],
            [30.0, 4.0, -1.0],
        ],
    );
    assert!(!out.contains('#') && !out.contains("WHILE"), "{out}");
}

#[test]
fn without_expand_the_refusal_names_the_flag_and_the_original_line() {
    let msg = refuse(WHILE_LOOP, &settings(false));
    assert_msg(&msg, &["t.nc:7", "`expand`"]);
}

#[test]
fn m98_subprogram_repeated_with_l_and_a_common_variable() {
    let text = "%
O0001
G21 G90 G17
G0 X0. Y0. Z5.
#100=0
M98 P1000 L3
G0 Z5.
M30
O1000
#100=#100+1
G1 X[#100*10.] Y5. Z-2. F100.
M99
%
";
    let out = run(text, &settings(true));
    expect(
        &out,
        [0.0, 0.0, 5.0],
        &[
            [0.0, 0.0, 5.0],
            [10.0, 5.0, -2.0],
            [20.0, 5.0, -2.0],
            [30.0, 5.0, -2.0],
        ],
    );
    assert!(
        out.starts_with("%\nO0001\n") && out.ends_with("%\n"),
        "{out}"
    );
    assert!(!out.contains("M98") && !out.contains("M99"), "{out}");
}

#[test]
fn old_form_p_count_and_number_is_a_repeat() {
    // `M98 P30100`: O0100 three times (Fanuc's P<count><number> form; no O30100 in the file).
    let text = "O0001
G21 G90 G17
G0 X0. Y0. Z5.
#100=0
M98 P30100
M30
O0100
#100=#100+5.
G1 X#100 Y0. Z-1. F100.
M99
";
    let out = run(text, &settings(true));
    expect(
        &out,
        [0.0, 0.0, 5.0],
        &[
            [0.0, 0.0, 5.0],
            [5.0, 0.0, -1.0],
            [10.0, 0.0, -1.0],
            [15.0, 0.0, -1.0],
        ],
    );
}

#[test]
fn g65_macro_arguments_if_goto_and_trig() {
    // A = #1 (count), B = #2 (radius), C = #3 (start angle): argument specification I.
    let text = "O0001
G21 G90 G17
G0 X0. Y0. Z5.
G65 P9001 A2. B10. C60.
G0 Z5.
M30
O9001
#4=0
N10 IF [#4 GE #1] GOTO 20
G1 X[#2*COS[#3+#4*30.]] Y[#2*SIN[#3+#4*30.]] Z-1. F100.
#4=#4+1
GOTO 10
N20 M99
";
    let out = run(text, &settings(true));
    let (c60, s60) = (60f64.to_radians().cos(), 60f64.to_radians().sin());
    expect(
        &out,
        [0.0, 0.0, 5.0],
        &[
            [0.0, 0.0, 5.0],
            [10.0 * c60, 10.0 * s60, -1.0],
            [0.0, 10.0, -1.0],
        ],
    );
}

#[test]
fn a_system_variable_is_refused_naming_it_and_its_line() {
    let text = "O0001
G21 G90 G17
G0 X0. Y0. Z5.
#1=#5021
G1 X#1 Y0. Z-1. F100.
M30
";
    let msg = refuse(text, &settings(true));
    assert_msg(&msg, &["t.nc:4", "#5021 is a system variable", "positions"]);
    assert!(!msg.contains("`expand`"), "{msg}");
}

#[test]
fn a_vacant_variable_is_refused() {
    let text = "O0001
G21 G90 G17
G0 X0. Y0. Z5.
#1=0
WHILE [#1 LT 2] DO1
G1 X#7 Y0. Z-1. F100.
#1=#1+1
END1
M30
";
    let msg = refuse(text, &settings(true));
    assert_msg(&msg, &["t.nc:6", "X#7", "vacant"]);
}

#[test]
fn a_subprogram_in_another_file_is_refused_naming_it() {
    let text = "O0001
G21 G90 G17
G0 X0. Y0. Z5.
G1 Z-1. F100.
M98 P1012 L4
M30
";
    let msg = refuse(text, &settings(true));
    assert_msg(&msg, &["t.nc:5", "O1012", "not in this file"]);
}

#[test]
fn an_endless_loop_is_refused_naming_its_line() {
    let text = "O0001
G21 G90 G17
G0 X0. Y0. Z5.
#1=0
WHILE [#1 GE 0] DO1
IF [#1 GT 0] GOTO 10
G1 X1. Y0. Z-1. F100.
N10 #1=#1+1
END1
M30
";
    let msg = refuse(text, &settings(true));
    assert_msg(&msg, &["t.nc:5", "line 9", "more than 1000000 times"]);
}

#[test]
fn the_flattened_program_stops_at_the_output_limit() {
    // 200 000 cuts of about 20 bytes: 4 MB, over a 1 MB limit (every other test here writes
    // a few hundred bytes, so the process-wide limit does not touch them).
    errmap::io::safety::set_max_output_mb(1);
    let text = "O0001
G21 G90 G17
G0 X0. Y0. Z5.
#1=0
WHILE [#1 LT 200000] DO1
G1 X[#1*0.001] Y0. Z-1. F100.
#1=#1+1
END1
M30
";
    let msg = refuse(text, &settings(true));
    assert_msg(&msg, &["t.nc:6", "output limit of 1 MB", "`max_output_mb`"]);
}

#[test]
fn a_refusal_inside_a_subprogram_names_the_original_line_and_call() {
    // A rotation in the zone is refused by the rewrite of the flattened program; the message
    // names the subprogram's own lines and the call.
    let text = "O0001
G21 G90 G17
G0 X0. Y0. Z5.
M98 P2000
M30
O2000
G68 X0. Y0. R30.
G1 X10. Y0. Z-1. F100.
G69
M99
";
    let msg = refuse(text, &settings(true));
    assert_msg(&msg, &["t.nc:8", "G68", "line 7", "O2000 called on line 4"]);
}

#[test]
fn flow_that_never_reaches_the_zone_is_copied_byte_for_byte() {
    let text = "O0001\r\nG21 G90 G17\r\nG0 X0. Y0. Z5.\r\n#1=0\r\nWHILE [#1 LT 3] DO1\r\nG1 X[#1*10.] Y0. Z5. F100.\r\n#1=#1+1\r\nEND1\r\nM30\r\n";
    let s = CompensationSettings {
        everywhere: false,
        zone: Some((-10.0, 0.0)),
        ..settings(true)
    };
    assert_eq!(run(text, &s), text);
}

/// A public Haas program whose subprogram sits before the main program in the same file:
/// refused without --expand (the hint names it), compensated with it.
#[test]
fn corpus_sub_before_main_is_run() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/corpus/programs/fanuc/vendetta-sscnc-Sub_Programs_Test.txt");
    let Ok(text) = std::fs::read_to_string(&path) else {
        return;
    };
    // Whole numbers without a decimal point read as mm (calculator-type input).
    let s = |expand| CompensationSettings {
        fanuc_numbers: Some(FanucNumbers::Calculator),
        ..settings(expand)
    };
    let msg = refuse(&text, &s(false));
    assert_msg(&msg, &["`expand`"]);
    let out = run(&text, &s(true));
    assert!(!out.contains("M98") && !out.contains("M99"), "{out}");
    // The plunge to Z-10 at X-50: −10 − E(−50) = −10 + 0.04 = −9.96.
    assert!(
        out.lines().any(|l| l.contains("Z-9.96")),
        "no compensated plunge:\n{out}"
    );
}

// ---- LinuxCNC: LinuxCNC's own interpreter (rs274) is the judge -----------------------------

/// A subroutine with arguments and a `while` loop, `if/else` on the returned `#<_value>`,
/// `do/while`, `while` left by `break`, `repeat`, named local and global parameters.
const NGC: &str = "G21 G90 G17
G0 X0 Y0 Z5
o<row> sub
  #<n> = 0
  o101 while [#<n> LT #1]
    G1 X[#2 + #<n> * 5] Y#3 Z-1 F100
    #<n> = [#<n> + 1]
  o101 endwhile
o<row> endsub [#<n> * 2]
o<row> call [3] [10] [2]
o102 if [#<_value> EQ 6]
  G1 X[#<_value>] Y0 Z-2
o102 else
  G1 X1 Y1 Z-2
o102 endif
#<k> = 0
o103 do
  G1 X[#<k>] Y[#<k> * 2 + 1] Z-3
  #<k> = [#<k> + 1]
o103 while [#<k> LT 2]
#<_r> = 0
o104 while [1]
  #<_r> = [#<_r> + 1]
  o105 if [#<_r> GT 2]
    o104 break
  o105 endif
  G1 X[7 + #<_r>] Y7 Z-4
o104 endwhile
o106 repeat [2]
  #<_r> = [#<_r> + 1]
  G1 X[10 + #<_r>] Y8 Z-4
o106 endrepeat
G0 Z5
M2
";

/// E = 0.01 + 0.001·x, or nothing at all (then the output is the flattened program).
struct Lin(bool);

impl ErrorField for Lin {
    fn normal(&self) -> Axis {
        Axis::Z
    }
    fn error_mm(&self, u: f64, _v: f64) -> Option<f64> {
        Some(if self.0 { e(u) } else { 0.0 })
    }
    fn measured(&self, _u: f64, _v: f64, _margin: f64) -> Option<bool> {
        Some(true)
    }
}

/// The motion calls of rs274's canonical output: (kind, [x, y, z]); `None` without rs274.
fn rs274_motions(name: &str, program: &str) -> Option<Vec<(String, [f64; 3])>> {
    let script =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/corpus/gcode/rs274-check.sh");
    if !script.exists() {
        return None;
    }
    let dir = std::env::temp_dir().join(format!("errmap-expand-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let ngc = dir.join(format!("{name}.ngc"));
    let canon = dir.join(format!("{name}.canon"));
    std::fs::write(&ngc, program).unwrap();
    let out = std::process::Command::new(&script)
        .arg(&ngc)
        .arg(&canon)
        .output()
        .unwrap();
    match out.status.code() {
        Some(127) => return None,
        Some(0) => {}
        c => panic!(
            "rs274 refused {name} ({c:?}): {}\n{program}",
            String::from_utf8_lossy(&out.stderr)
        ),
    }
    let text = std::fs::read_to_string(&canon).unwrap();
    Some(
        text.lines()
            .filter_map(|l| {
                let kind = ["STRAIGHT_TRAVERSE", "STRAIGHT_FEED"]
                    .into_iter()
                    .find(|k| l.contains(&format!("{k}(")))?;
                let args = l.split_once('(')?.1.trim_end_matches(')');
                let v: Vec<f64> = args
                    .split(',')
                    .filter_map(|a| a.trim().parse().ok())
                    .collect();
                Some((kind.to_string(), [v[0], v[1], v[2]]))
            })
            .collect(),
    )
}

fn lin_settings() -> CompensationSettings {
    CompensationSettings {
        dialect: Some(Dialect::Linuxcnc),
        ..settings(true)
    }
}

#[test]
fn linuxcnc_flattened_program_moves_as_the_original_under_rs274() {
    let Some(original) = rs274_motions("original", NGC) else {
        println!("skipping: rs274 is not installed");
        return;
    };
    // Hand check of what rs274 reads: the subroutine's three cuts, the `if` on #<_value> = 6,
    // the do/while twice, the while left by break after two cuts, the repeat twice.
    let feeds: Vec<[f64; 3]> = original
        .iter()
        .filter(|m| m.0 == "STRAIGHT_FEED")
        .map(|m| m.1)
        .collect();
    assert_eq!(
        feeds,
        vec![
            [10.0, 2.0, -1.0],
            [15.0, 2.0, -1.0],
            [20.0, 2.0, -1.0],
            [6.0, 0.0, -2.0],
            [0.0, 1.0, -3.0],
            [1.0, 3.0, -3.0],
            [8.0, 7.0, -4.0],
            [9.0, 7.0, -4.0],
            [14.0, 8.0, -4.0],
            [15.0, 8.0, -4.0],
        ]
    );
    let (flat, _) = compensate_gcode(NGC, Path::new("t.ngc"), &Lin(false), &lin_settings())
        .unwrap_or_else(|e| panic!("refused: {e}"));
    assert!(
        !flat.contains('#') && !flat.to_ascii_lowercase().contains("o10"),
        "{flat}"
    );
    assert_eq!(rs274_motions("flat", &flat).unwrap(), original, "{flat}");
    // Compensated: every feed is the original's minus E, after one entry step at the start.
    let (out, _) = compensate_gcode(NGC, Path::new("t.ngc"), &Lin(true), &lin_settings())
        .unwrap_or_else(|e| panic!("refused: {e}"));
    let got: Vec<[f64; 3]> = rs274_motions("compensated", &out)
        .unwrap()
        .iter()
        .filter(|m| m.0 == "STRAIGHT_FEED")
        .map(|m| m.1)
        .collect();
    let mut want = vec![[0.0, 0.0, 5.0 - e(0.0)]];
    want.extend(feeds.iter().map(|p| [p[0], p[1], p[2] - e(p[0])]));
    assert_eq!(got.len(), want.len(), "{out}");
    for (g, w) in got.iter().zip(&want) {
        for k in 0..3 {
            assert!((g[k] - w[k]).abs() < 1e-4, "got {g:?}, want {w:?}\n{out}");
        }
    }
}

#[test]
fn linuxcnc_refusals_name_the_parameter_or_subroutine_and_the_line() {
    let s = lin_settings();
    let probe = "G21 G90\nG0 X0 Y0 Z5\no1 repeat [2]\nG1 X[#5061] Y0 Z-1 F100\no1 endrepeat\nM2\n";
    assert_msg(
        &refuse_ngc(probe, &s),
        &["t.ngc:4", "#5061 is a system parameter"],
    );
    let other = "G21 G90\nG0 X0 Y0 Z5\nG1 Z-1 F100\no<pocket> call [1]\nM2\n";
    assert_msg(
        &refuse_ngc(other, &s),
        &["t.ngc:4", "o<pocket>", "not in this file"],
    );
    // The cut runs on the first turn only, so the loop count, not the output limit, stops it.
    let endless = "G21 G90\nG0 X0 Y0 Z5\n#<a> = 0\no1 while [1]\no2 if [#<a> EQ 0]\nG1 X1 Y0 Z-1 F100\no2 endif\n#<a> = [#<a> + 1]\no1 endwhile\nM2\n";
    assert_msg(
        &refuse_ngc(endless, &s),
        &["t.ngc:4", "more than 1000000 times"],
    );
    let unset = "G21 G90\nG0 X0 Y0 Z5\no1 repeat [2]\nG1 X#<_x> Y0 Z-1 F100\no1 endrepeat\nM2\n";
    assert_msg(&refuse_ngc(unset, &s), &["t.ngc:4", "#<_x> is read before"]);
    // Without --expand the same loop is refused with the flag in the hint.
    let fine = "G21 G90\nG0 X0 Y0 Z5\no1 repeat [2]\nG1 X1 Y0 Z-1 F100\no1 endrepeat\nM2\n";
    let msg = refuse_ngc(fine, &CompensationSettings { expand: false, ..s });
    assert_msg(&msg, &["t.ngc:4", "`expand`"]);
}

fn refuse_ngc(text: &str, s: &CompensationSettings) -> String {
    match compensate_gcode(text, Path::new("t.ngc"), &F, s) {
        Ok((out, _)) => panic!("expected a refusal, got:\n{out}"),
        Err(e) => e.to_string(),
    }
}

/// The CLI: `--expand` turns a refusal (exit 2, the hint naming the flag) into a compensated
/// program (exit 0) with the loop written out; the flat 20 µm map lowers every cut by 0.02 mm.
#[test]
fn cli_expand_flag_runs_the_loop() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    std::fs::write(dir.join("model.json"), common::FLAT_MODEL_20UM).unwrap();
    let program = "G21 G90\nG0 X10 Y10 Z5\nG1 Z-1 F100\n#<x> = 10\no1 repeat [2]\n#<x> = [#<x> + 5]\nG1 X#<x> Y10 Z-1\no1 endrepeat\nG0 Z5\nM2\n";
    std::fs::write(dir.join("in.ngc"), program).unwrap();
    let args = [
        "compensate",
        "--model",
        "model.json",
        "--zone",
        "-2,0",
        "--dialect",
        "linuxcnc",
        "in.ngc",
        "-o",
        "out.ngc",
    ];
    let refused = common::errmap(dir, &args);
    refused.expect_code(2);
    assert!(
        refused.stderr.contains("in.ngc:7") && refused.stderr.contains("--expand"),
        "{}",
        refused.report()
    );
    let done = common::errmap(dir, &[&args[..], &["--expand"]].concat());
    done.expect_code(0);
    let out = std::fs::read_to_string(dir.join("out.ngc")).unwrap();
    for cut in ["X15.0000 Y10.0000 Z-1.0200", "X20.0000 Y10.0000 Z-1.0200"] {
        assert!(out.contains(cut), "no `{cut}` in:\n{out}");
    }
    assert!(!out.contains("o1") && !out.contains('#'), "{out}");
}

/// A public Haas program whose subprogram is another file (`M98 P1012 L4`, O1012 in
/// donpayne-gauge_tool_o1012.cnc): refused with --expand, naming the subprogram and the line.
#[test]
fn corpus_sub_in_another_file_is_refused_naming_it() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/corpus/programs/fanuc/donpayne-gauge_tool_o1011.cnc");
    let Ok(text) = std::fs::read_to_string(&path) else {
        return;
    };
    let s = CompensationSettings {
        fanuc_numbers: Some(FanucNumbers::IsB),
        units: None,
        ..settings(true)
    };
    let msg = refuse(&text, &s);
    assert_msg(&msg, &["t.nc:24", "O1012", "not in this file"]);
}

/// Without --expand errmap only tries the run on a small budget (100 000 loop turns) to decide
/// the hint: a longer loop is left to the run with the flag, and the hint still names it.
#[test]
fn without_expand_a_long_loop_still_names_the_flag() {
    let text = "O0001
G21 G90 G17
G0 X0. Y0. Z5.
#1=0
WHILE [#1 LT 300000] DO1
IF [#1 GT 0] GOTO 10
G1 X1. Y0. Z-1. F100.
N10 #1=#1+1
END1
M30
";
    let started = std::time::Instant::now();
    let msg = refuse(text, &settings(false));
    assert_msg(&msg, &["t.nc:7", "`expand`"]);
    assert!(
        started.elapsed().as_secs_f64() < 1.0,
        "{:?}",
        started.elapsed()
    );
    // With the flag the whole loop runs: one cut, compensated.
    let out = run(text, &settings(true));
    expect(&out, [0.0, 0.0, 5.0], &[[0.0, 0.0, 5.0], [1.0, 0.0, -1.0]]);
}

/// Recursion, huge repeat counts, deep indirection and broken blocks are refused with a
/// message, never a panic or an endless run.
#[test]
fn hostile_programs_are_refused_not_a_panic() {
    let fanuc = settings(true);
    let ngc = lin_settings();
    let deep = format!("#1={}1{}", "#[".repeat(200), "]".repeat(200));
    let cases: Vec<(&CompensationSettings, String, &str)> = vec![
        (&fanuc, "O0001\nG21 G90\nG0 X0. Y0. Z5.\nM98 P1000\nM30\nO1000\nG1 X1. Y0. Z-1. F100.\nM98 P1000\nM99\n".into(), "nested deeper"),
        (&fanuc, "O0001\nG21 G90\nG0 X0. Y0. Z5.\nM98 P1000 L0\nM30\nO1000\nG1 X1. Y0. Z-1. F100.\nM99\n".into(), "repeat count"),
        (&fanuc, format!("O0001\nG21 G90\nG0 X0. Y0. Z5.\n{deep}\nWHILE [#1 LT 2] DO1\nG1 X1. Y0. Z-1. F100.\nEND1\nM30\n"), "t.nc:4"),
        (&fanuc, "O0001\nG21 G90\nG0 X0. Y0. Z5.\n#1=0\nWHILE [#1 LT 2] DO1\nG1 X1. Y0. Z-1. F100.\nEND2\nM30\n".into(), "t.nc:5, column 1 (WHILE): a DO without its END"),
        (&fanuc, "O0001\nG21 G90\nG0 X0. Y0. Z5.\n#1=0\nN10 G1 X1. Y0. Z-1. F100.\nGOTO 99\nM30\n".into(), "no block N99"),
        (&ngc, "G21 G90\nG0 X0 Y0 Z5\no<r> sub\nG1 X1 Y0 Z-1 F100\no<r> call\no<r> endsub\no<r> call\nM2\n".into(), "nested deeper"),
        (&ngc, "G21 G90\nG0 X0 Y0 Z5\no1 if [0]\nG1 X1 Y0 Z-1 F100\nM2\n".into(), "t.ngc:3"),
        (&ngc, "G21 G90\nG0 X0 Y0 Z5\no1 repeat [1e300]\nG1 X1 Y0 Z-1 F100\no1 endrepeat\nM2\n".into(), "t.ngc:3"),
    ];
    for (s, text, want) in cases {
        let path = if s.dialect == Some(Dialect::Linuxcnc) {
            "t.ngc"
        } else {
            "t.nc"
        };
        match compensate_gcode(&text, Path::new(path), &F, s) {
            Ok((out, _)) => panic!("expected a refusal of\n{text}\ngot\n{out}"),
            Err(e) => assert!(e.to_string().contains(want), "`{want}` not in: {e}\n{text}"),
        }
    }
}

/// The public Haas pair O2001 (main) + O9001 (a G65 macro solving Pythagoras into the variable
/// whose number is passed as V) run together: errmap refuses #10100 (a Fanuc tool offset, a Haas
/// NGC variable); written with #100 and in one file, the arc's start Y = 1.625 + .625 − √(.625² −
/// .125²) is computed by the macro, and the cut is lowered by E (inch program: E/25.4).
#[test]
fn corpus_g65_macro_pair_in_one_file() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/corpus/programs/fanuc");
    let (Ok(main), Ok(mac)) = (
        std::fs::read_to_string(dir.join("donpayne-advanced_arcs_o2001.cnc")),
        std::fs::read_to_string(dir.join("donpayne-advanced_arcs_o9001.cnc")),
    ) else {
        return;
    };
    let s = CompensationSettings {
        fanuc_numbers: Some(FanucNumbers::IsB),
        ..settings(true)
    };
    let msg = refuse(&main, &s);
    assert_msg(&msg, &["t.nc:24", "#10100", "write it as #100"]);
    let main = main
        .replace("#10100", "#100")
        .replace("V10100.", "V100.")
        .replace(":(", "(");
    let msg = refuse(&main, &s);
    assert_msg(&msg, &["t.nc:25", "G65 P9001", "O9001", "not in this file"]);
    let out = run(&format!("{main}{mac}"), &s);
    let y = 1.625 + 0.625 - (0.625f64 * 0.625 - 0.125 * 0.125).sqrt();
    let z = -e(3.125 * 25.4) / 25.4;
    let hit = out.lines().any(|l| {
        matches!(
            (word(l, 'X'), word(l, 'Y'), word(l, 'Z')),
            (Some(x), Some(yy), Some(zz)) if x == 3.125 && (yy - y).abs() < 1e-6 && (zz - z).abs() < 1e-6
        )
    });
    assert!(hit, "no cut to X3.125 Y{y:.6} Z{z:.6} in:\n{out}");
}

// Sinumerik: R parameters, DEF variables, labels and jumps, loops and section repetition run
// into plain blocks. Each flattened-and-compensated program is judged against its original by
// an executor outside errmap (nc-gcode-interpreter where it parses the construct, else the
// tests' reference tracer written from the SINUMERIK manuals), with E = 0.02 mm everywhere.

/// E = 0.02 mm along Z everywhere.
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

fn sin_settings(expand: bool) -> CompensationSettings {
    CompensationSettings {
        dialect: Some(Dialect::Sinumerik),
        ..settings(expand)
    }
}

fn sin_refuse(text: &str, s: &CompensationSettings) -> String {
    match compensate_gcode(text, Path::new("t.mpf"), &Flat20, s) {
        Ok((out, _)) => panic!("expected a refusal, got:\n{out}"),
        Err(e) => e.to_string(),
    }
}

/// The moves of a Sinumerik program by the outside executor: nc-gcode-interpreter where it is
/// installed (it hands what it cannot parse to the reference tracer), else the reference tracer.
fn sin_trace(dir: &Path, name: &str, text: &str) -> Vec<path_judge::Seg> {
    if !sinumerik_nci::available() {
        assert!(
            !sinumerik_nci::required(),
            "nc-gcode-interpreter is missing"
        );
        return sinumerik_nci::reference::trace(text).unwrap_or_else(|e| panic!("{e}\n{text}"));
    }
    let path = dir.join(format!("{name}.mpf"));
    std::fs::write(&path, text).unwrap();
    sinumerik_nci::trace(&path, text).unwrap_or_else(|e| panic!("{e}\n{text}"))
}

/// Compensate `text` with --expand and judge the output against the original; returns the
/// original's cut ends (as the executor read them) and the output.
fn sin_judged(text: &str) -> (Vec<[f64; 3]>, String) {
    let (out, report) = compensate_gcode(text, Path::new("t.mpf"), &Flat20, &sin_settings(true))
        .unwrap_or_else(|e| panic!("refused: {e}\n{text}"));
    assert!(report.moves_changed > 0, "{out}");
    let dir = tempfile::tempdir().unwrap();
    let orig = sin_trace(dir.path(), "orig", text);
    let new = sin_trace(dir.path(), "out", &out);
    let v = path_judge::judge(&orig, &new, 0.02).unwrap_or_else(|e| panic!("{e}\n{out}"));
    let cuts: Vec<[f64; 3]> = orig.iter().filter(|s| s.cut).map(|s| s.end).collect();
    assert!(v.points_checked >= cuts.len(), "{v:?}");
    (cuts, out)
}

fn close(got: &[[f64; 3]], want: &[[f64; 3]]) {
    assert_eq!(got.len(), want.len(), "{got:?}");
    for (g, w) in got.iter().zip(want) {
        for k in 0..3 {
            assert!((g[k] - w[k]).abs() < 1e-9, "got {g:?}, want {w:?}");
        }
    }
}

#[test]
fn sinumerik_labels_gotob_loop_and_functions() {
    let text = "N10 G71 G90 G17
N20 R1=0 ; counter
N30 R2=TRUNC(7.9)/7
N40 G0 X0 Y0 Z5
N50 G1 Z-1 F100
N60 LOOP_A:
N70 R1=R1+10
N80 G1 X=R1 Y=R1*SIN(30)*R2
N90 IF R1<30 GOTOB LOOP_A
N100 GOTOF ENDE
N110 G1 X99 Y99
N120 ENDE: G0 Z5
N130 M30
";
    let (cuts, out) = sin_judged(text);
    // By hand: the loop runs for R1 = 10, 20, 30; Y = R1·sin 30° = R1/2; N110 is jumped over.
    close(
        &cuts,
        &[
            [0.0, 0.0, -1.0],
            [10.0, 5.0, -1.0],
            [20.0, 10.0, -1.0],
            [30.0, 15.0, -1.0],
        ],
    );
    let upper = out.to_ascii_uppercase();
    assert!(
        !upper.contains("GOTO") && !upper.contains("R1") && !upper.contains("X99"),
        "{out}"
    );
}

#[test]
fn sinumerik_if_else_and_while_as_nc_gcode_interpreter_runs_them() {
    let text = "G71 G90 G17
R1=5
G0 X0 Y0 Z5
G1 Z-1 F100
IF R1==5
G1 Y10
ELSE
G1 Y20
ENDIF
WHILE R1<8
R1=R1+1
G1 X=R1*2
ENDWHILE
G0 Z5
M30
";
    let (cuts, _) = sin_judged(text);
    close(
        &cuts,
        &[
            [0.0, 0.0, -1.0],
            [0.0, 10.0, -1.0],
            [12.0, 10.0, -1.0],
            [14.0, 10.0, -1.0],
            [16.0, 10.0, -1.0],
        ],
    );
}

#[test]
fn sinumerik_for_loop_and_def_variables() {
    let text = "DEF INT I
DEF REAL DEPTH=-1.5, STEP
G71 G90 G17
STEP=2.5
G0 X0 Y0 Z5
G1 Z=DEPTH F100
FOR I=1 TO 3
G1 X=I*STEP Y=I
ENDFOR
G0 Z5
M30
";
    let (cuts, _) = sin_judged(text);
    close(
        &cuts,
        &[
            [0.0, 0.0, -1.5],
            [2.5, 1.0, -1.5],
            [5.0, 2.0, -1.5],
            [7.5, 3.0, -1.5],
        ],
    );
}

#[test]
fn sinumerik_repeat_sections_and_repeat_until() {
    let text = "G71 G90 G17
R1=0
G0 X0 Y0 Z5
G1 Z-1 F100
STEP_A: R1=R1+1
G1 X=R1
REPEAT STEP_A P=2
REPEATB STEP_B P=2
G1 Y=R1
STEP_B: G1 Y=R1*2
REPEAT
R1=R1+1
G1 X=R1
UNTIL R1>=6
G0 Z5
M30
";
    // By hand: STEP_A runs once and twice more (X1, X2, X3); REPEATB runs STEP_B's block
    // twice (Y6, Y6), then Y3, then STEP_B once more on the way (Y6); REPEAT…UNTIL X4…X6.
    let (cuts, out) = sin_judged(text);
    close(
        &cuts,
        &[
            [0.0, 0.0, -1.0],
            [1.0, 0.0, -1.0],
            [2.0, 0.0, -1.0],
            [3.0, 0.0, -1.0],
            [3.0, 6.0, -1.0],
            [3.0, 3.0, -1.0],
            [3.0, 6.0, -1.0],
            [4.0, 6.0, -1.0],
            [5.0, 6.0, -1.0],
            [6.0, 6.0, -1.0],
        ],
    );
    assert!(!out.to_ascii_uppercase().contains("REPEAT"), "{out}");
}

#[test]
fn sinumerik_without_expand_the_refusal_names_the_flag() {
    let text = "G71 G90 G17\nR1=0\nG0 X0 Y0 Z5\nLAB1:\nR1=R1+1\nG1 X=R1 Z-1 F100\nIF R1<3 GOTOB LAB1\nM30\n";
    let msg = sin_refuse(text, &sin_settings(false));
    assert_msg(&msg, &["t.mpf:", "`expand`"]);
}

#[test]
fn sinumerik_runtime_values_are_refused_naming_them() {
    let system = "G71 G90 G17\nG0 X0 Y0 Z5\nR1=$AA_IM[X]+1\nG1 X=R1 Z-1 F100\nM30\n";
    let msg = sin_refuse(system, &sin_settings(true));
    assert_msg(&msg, &["t.mpf:3", "$AA_IM", "system variable", "run time"]);
    // An R parameter read before the program sets it holds what the controller left in it.
    let unset = "G71 G90 G17\nG0 X0 Y0 Z5\nG1 X=R7 Z-1 F100\nM30\n";
    let msg = sin_refuse(unset, &sin_settings(true));
    assert_msg(
        &msg,
        &["t.mpf:3", "(R7)", "R7 is read before the program sets it"],
    );
    // A name the program does not define: a global user variable of the controller.
    let gud = "G71 G90 G17\nG0 X0 Y0 Z5\nIF (ThHa<>0)\nG1 X1 Z-1 F100\nENDIF\nM30\n";
    let msg = sin_refuse(gud, &sin_settings(true));
    assert_msg(
        &msg,
        &["t.mpf:3", "THHA is not defined in this program", "run time"],
    );
    // A value used only in a message is harmless: MSG is copied.
    let text = "G71 G90 G17\nMSG(\"PASS \"<<$AA_IM[X])\nR1=2\nG0 X0 Y0 Z5\nG1 X=R1 Z-1 F100\nM30\n";
    let (cuts, _) = compensate_gcode(text, Path::new("t.mpf"), &Flat20, &sin_settings(true))
        .map(|(o, _)| (o.contains("MSG(\"PASS \"<<$AA_IM[X])"), ()))
        .unwrap();
    assert!(cuts);
}

#[test]
fn sinumerik_calls_of_other_programs_are_refused_as_not_in_this_file() {
    for (call, name) in [
        ("L140(2)", "L140"),
        ("L106", "L106"),
        ("SPEC_UGV", "SPEC_UGV"),
        ("_THREAD_SETUP(1,2)", "_THREAD_SETUP"),
        ("println(\"METKA1\")", "PRINTLN"),
        ("CALL \"SUB1\"", "CALL"),
    ] {
        let text = format!("G71 G90 G17\nR1=1\nG0 X0 Y0 Z5\n{call}\nG1 X=R1 Z-1 F100\nM30\n");
        let msg = sin_refuse(&text, &sin_settings(true));
        assert_msg(&msg, &["t.mpf:4", name, "which is not in this file"]);
    }
    // A file that is a subprogram with parameters: only its caller gives them.
    let text = "PROC CHAMFER(REAL RSTART, REAL ANG)\nG1 X=RSTART Z-1 F100\nM17\n";
    let msg = sin_refuse(text, &sin_settings(true));
    assert_msg(
        &msg,
        &["t.mpf:1", "PROC", "caller", "which is not in this file"],
    );
}

#[test]
fn sinumerik_an_endless_loop_is_refused_by_the_budget() {
    let text = "G71 G90 G17\nG0 X0 Y0 Z5\nR1=0\nLOOP\nR1=R1+1\nENDLOOP\nG1 X1 Z-1 F100\nM30\n";
    let msg = sin_refuse(text, &sin_settings(true));
    assert_msg(&msg, &["t.mpf:5", "line 6", "more than 1000000 times"]);
}

#[test]
fn sinumerik_flow_that_never_reaches_the_zone_is_copied_byte_for_byte() {
    let text = "G71 G90 G17\r\nDEF INT I\r\nG0 X0 Y0 Z5\r\nFOR I=0 TO 2\r\nG1 X=I*10 Y0 Z5 F100\r\nENDFOR\r\nM30\r\n";
    let s = CompensationSettings {
        everywhere: false,
        zone: Some((-10.0, 0.0)),
        ..sin_settings(true)
    };
    let out = compensate_gcode(text, Path::new("t.mpf"), &Flat20, &s)
        .unwrap_or_else(|e| panic!("{e}"))
        .0;
    assert_eq!(out, text);
}

#[test]
fn sinumerik_the_flattened_program_stops_at_the_output_limit() {
    // 200 000 cuts of about 20 bytes: 4 MB, over the 1 MB limit (as the Fanuc test above).
    errmap::io::safety::set_max_output_mb(1);
    let text = "G71 G90 G17\nG0 X0 Y0 Z5\nR1=0\nWHILE R1<200000\nG1 X=R1*0.001 Y0 Z-1 F100\nR1=R1+1\nENDWHILE\nM30\n";
    let msg = sin_refuse(text, &sin_settings(true));
    assert_msg(
        &msg,
        &["t.mpf:5", "output limit of 1 MB", "`max_output_mb`"],
    );
}

#[test]
fn sinumerik_hostile_lines_are_refused_not_a_panic() {
    for text in [
        "R1=(((((((\nM30\n",
        "IF\nM30\n",
        "ENDIF\nM30\n",
        "GOTOB\nM30\n",
        "R1=1\nREPEAT XX P=3\nM30\n",
        "DEF REAL A[3]\nM30\n",
        "R1=1/0\nG1 X=R1\nM30\n",
        "FOR R1=1 TO\nENDFOR\nM30\n",
        "R1=1 G1 X=R1 ; é\nM30\n",
    ] {
        let _ = compensate_gcode(text, Path::new("t.mpf"), &Flat20, &sin_settings(true));
    }
    let deep = format!(
        "R1={}1{}\nG1 X=R1\nM30\n",
        "(".repeat(5000),
        ")".repeat(5000)
    );
    assert!(compensate_gcode(&deep, Path::new("t.mpf"), &Flat20, &sin_settings(true)).is_err());
}

// Sinumerik subprograms of the same file: `PROC NAME(REAL A, …)` after the main program's M30,
// called `NAME(a, b)`; judged as above (the reference tracer runs the PROC calls from the Job
// Planning manual's "Subprogram technique"), with the cut ends also worked out by hand.

#[test]
fn sinumerik_a_local_proc_called_twice_with_real_arguments() {
    let text = "G71 G90 G17
R1=0
G0 X0 Y0 Z5
G1 Z-1 F100
SLOT(10, 2.5)
SLOT(20.5, R1+4)
G1 X=R1
G0 Z5
M30
PROC SLOT(REAL XE, REAL YE)
DEF REAL H
H=YE*2
G1 X=XE Y=YE
G1 Y=H
R1=R1+1
M17
";
    let (cuts, out) = sin_judged(text);
    // By hand: SLOT(10, 2.5) cuts to (10, 2.5) then Y = 2·2.5; R1 is global, so the second
    // call gets YE = 1 + 4 = 5 and after both calls R1 = 2.
    close(
        &cuts,
        &[
            [0.0, 0.0, -1.0],
            [10.0, 2.5, -1.0],
            [10.0, 5.0, -1.0],
            [20.5, 5.0, -1.0],
            [20.5, 10.0, -1.0],
            [2.0, 10.0, -1.0],
        ],
    );
    let upper = out.to_ascii_uppercase();
    assert!(
        !upper.contains("PROC") && !upper.contains("SLOT") && !upper.contains("M17"),
        "{out}"
    );
    assert!(upper.contains("M30"), "{out}");
}

#[test]
fn sinumerik_nested_proc_calls_with_a_left_out_argument() {
    let text = "G71 G90 G17
G0 X0 Y0 Z5
G1 Z-1 F100
OUTER(5)
G0 Z5
M30
PROC OUTER(REAL D)
INNER(D, 1.4)
INNER(D*2, )
RET
PROC INNER(REAL A, INT B)
G1 X=A Y=B
";
    // By hand: INNER(5, 1.4) cuts to (5, 1) (INT rounds); INNER(10, ) to (10, 0) (a left-out
    // parameter is 0); INNER returns at the next PROC or the end of the file.
    let (cuts, _) = sin_judged(text);
    close(
        &cuts,
        &[[0.0, 0.0, -1.0], [5.0, 1.0, -1.0], [10.0, 0.0, -1.0]],
    );
}

#[test]
fn sinumerik_a_refusal_inside_a_proc_names_its_line_and_the_call() {
    // A value the run does not know, refused by the run itself.
    let text = "G71 G90 G17\nG0 X0 Y0 Z5\nG1 Z-1 F100\nCUTS(2)\nM30\nPROC CUTS(REAL A)\nG1 X=A\nG1 Y=R9\nM17\n";
    let msg = sin_refuse(text, &sin_settings(true));
    assert_msg(
        &msg,
        &[
            "t.mpf:8",
            "(R9)",
            "R9 is read before the program sets it",
            "(in CUTS called on line 4)",
        ],
    );
    // An instruction the rewriter refuses in the flattened program, mapped back through the
    // calls: the innermost first.
    let text = "G71 G90 G17\nG0 X0 Y0 Z5\nG1 Z-1 F100\nOUTER\nM30\nPROC OUTER\nG1 X1\nCUTS(2)\nM17\nPROC CUTS(REAL A)\nG1 X=A\nTRAORI\nG1 Y1\nM17\n";
    let msg = sin_refuse(text, &sin_settings(true));
    assert_msg(
        &msg,
        &[
            "t.mpf:12",
            "TRAORI",
            "(in CUTS called on line 8, in OUTER called on line 4)",
        ],
    );
}

#[test]
fn sinumerik_a_recursive_proc_call_is_refused() {
    let text = "G71 G90 G17\nG0 X0 Y0 Z5\nG1 Z-1 F100\nR1=0\nAGAIN\nM30\nPROC AGAIN\nR1=R1+1\nG1 X=R1\nIF R1<3\nAGAIN\nENDIF\nM17\n";
    let msg = sin_refuse(text, &sin_settings(true));
    assert_msg(
        &msg,
        &[
            "t.mpf:11",
            "(AGAIN)",
            "recursive",
            "(in AGAIN called on line 5)",
        ],
    );
}

#[test]
fn sinumerik_a_var_parameter_is_refused_at_the_call() {
    let text = "G71 G90 G17\nDEF REAL W\nG0 X0 Y0 Z5\nG1 Z-1 F100\nSETW(W)\nG1 X=W\nM30\nPROC SETW(VAR REAL C)\nC=5\nM17\n";
    let msg = sin_refuse(text, &sin_settings(true));
    assert_msg(
        &msg,
        &["t.mpf:5", "(SETW)", "VAR", "call-by-reference", "line 8"],
    );
}

#[test]
fn sinumerik_a_call_of_a_proc_not_in_the_file_is_still_refused_as_missing() {
    let text = "G71 G90 G17\nG0 X0 Y0 Z5\nG1 Z-1 F100\nSLOT(1)\nOTHER(2)\nM30\nPROC SLOT(REAL A)\nG1 X=A\nM17\n";
    let msg = sin_refuse(text, &sin_settings(true));
    assert_msg(&msg, &["t.mpf:5", "OTHER", "which is not in this file"]);
}
