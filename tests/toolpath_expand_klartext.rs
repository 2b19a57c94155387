//! `--expand` for Heidenhain Klartext: labels, subprogram calls, program-section repeats, FN 0–12 and Q parameters run into a flattened program, judged against the reference Klartext tracer (tests/common/klartext_trace.rs, written from the TNC manual) run on the original, and against values computed here by hand; refusals name the original line, block and call.

#[path = "common/klartext_trace.rs"]
mod klartext_trace;
#[path = "common/path_judge.rs"]
mod path_judge;

use errmap::geom::{Axis, ErrorField};
use errmap::toolpath::{compensate_gcode, CompensationSettings, Dialect};
use std::path::Path;

/// E of the flat map, mm along Z.
const E_MM: f64 = 0.02;

/// E = 0.02 mm along Z everywhere, measured everywhere.
struct Flat;

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

fn settings(expand: bool) -> CompensationSettings {
    CompensationSettings {
        zone: Some((-50.0, 0.0)),
        dialect: Some(Dialect::Heidenhain),
        max_segment: 1000.0,
        expand,
        ..CompensationSettings::default()
    }
}

fn run_with(text: &str, s: &CompensationSettings) -> String {
    compensate_gcode(text, Path::new("t.h"), &Flat, s)
        .unwrap_or_else(|e| panic!("refused: {e}\n--- input ---\n{text}"))
        .0
}

fn run(text: &str) -> String {
    run_with(text, &settings(true))
}

fn refuse_with(text: &str, s: &CompensationSettings) -> String {
    match compensate_gcode(text, Path::new("t.h"), &Flat, s) {
        Ok((out, _)) => panic!("expected a refusal, got:\n{out}"),
        Err(e) => e.to_string(),
    }
}

fn refuse(text: &str) -> String {
    refuse_with(text, &settings(true))
}

fn assert_msg(msg: &str, parts: &[&str]) {
    for p in parts {
        assert!(msg.contains(p), "`{p}` not in: {msg}");
    }
}

/// The output, judged: the reference tracer runs the original (with its labels and Q
/// parameters) and the output; every cut of the output, raised by E, lies on the original's
/// path, and the rapids agree. Returns the output.
fn judged(text: &str, s: &CompensationSettings) -> String {
    let out = run_with(text, s);
    let orig = klartext_trace::trace(text).unwrap_or_else(|e| panic!("tracer: {e}\n{text}"));
    let new =
        klartext_trace::trace(&out).unwrap_or_else(|e| panic!("tracer on output: {e}\n{out}"));
    path_judge::judge(&orig, &new, E_MM).unwrap_or_else(|e| panic!("{e}\n--- output ---\n{out}"));
    out
}

/// The flattened program is plain Klartext: no label, call, jump or Q word in a block that
/// moves; block numbers 0, 1, 2 … in order; BEGIN PGM first and END PGM last.
fn assert_plain(out: &str) {
    let numbers: Vec<u64> = out
        .lines()
        .filter_map(|l| l.split_whitespace().next()?.parse().ok())
        .collect();
    let want: Vec<u64> = (0..numbers.len() as u64).collect();
    assert_eq!(numbers, want, "{out}");
    assert!(
        out.lines().next().unwrap_or("").contains("BEGIN PGM"),
        "{out}"
    );
    assert!(
        out.lines().last().unwrap_or("").contains("END PGM"),
        "{out}"
    );
    for l in out.lines() {
        let code = l.split(';').next().unwrap_or("");
        assert!(
            !code.contains("LBL") && !code.contains("FN 9"),
            "{l}\n{out}"
        );
        if code.contains(" L ") || code.contains(" CC ") || code.contains(" C ") {
            assert!(!code.contains('Q'), "{l}\n{out}");
        }
    }
}

/// (x, y, z) of every `L` block of the output that writes all three, in order.
fn points(out: &str) -> Vec<[f64; 3]> {
    let word = |l: &str, a: char| {
        l.split_whitespace()
            .find_map(|w| w.strip_prefix(a))
            .and_then(|v| v.parse::<f64>().ok())
    };
    out.lines()
        .filter(|l| l.split_whitespace().nth(1) == Some("L"))
        .filter_map(|l| Some([word(l, 'X')?, word(l, 'Y')?, word(l, 'Z')?]))
        .collect()
}

const SECTION_REPEAT: &str = "0 BEGIN PGM REP MM
1 BLK FORM 0.1 Z X-25 Y-25 Z-50
2 BLK FORM 0.2 X+25 Y+25 Z+1
3 TOOL CALL 4 Z S3000 F200
4 L Z+25 R0 FMAX M3
5 L X-20 Y-13 R0 FMAX
6 L Z+0 R0 F200
7 LBL 1
8 L IZ-0.5
9 L X+20
10 L IZ-0.5
11 L X-20
12 LBL 0
13 CALL LBL 1 REP2
14 L Z+25 R0 FMAX
15 M30
16 END PGM REP MM
";

#[test]
fn a_section_repeat_runs_the_section_once_more_than_rep() {
    let out = judged(SECTION_REPEAT, &settings(true));
    assert_plain(&out);
    // REP2: the section runs 3 times, each 1 mm deeper: the last cut is at Z−3, compensated.
    let z: Vec<f64> = points(&out).iter().map(|p| p[2]).collect();
    let lowest = z.iter().copied().fold(f64::INFINITY, f64::min);
    assert!((lowest - (-3.0 - E_MM)).abs() < 1e-9, "{out}");
    // The reference tracer itself: 4 cuts a pass, 3 passes.
    let cuts = klartext_trace::trace(SECTION_REPEAT)
        .unwrap()
        .iter()
        .filter(|s| s.cut && s.start != s.end)
        .count();
    assert_eq!(cuts, 1 + 12);
}

#[test]
fn without_expand_the_refusal_offers_the_flag_and_names_the_label() {
    let msg = refuse_with(SECTION_REPEAT, &settings(false));
    assert_msg(&msg, &["t.h:9", "LBL 1", "`expand`"]);
}

const SUBPROGRAM: &str = "0 BEGIN PGM SUB MM
1 TOOL CALL 1 Z S5000
2 L X+0 Y+0 Z+5 R0 FMAX
3 CALL LBL 5
4 L X+40 Y+0 Z+5 R0 FMAX
5 CALL LBL 5
6 L Z+50 R0 FMAX M30
7 ; the subprograms
8 LBL 5
9 L IZ-7 R0 F100
10 L IX+10 IY+5
11 CALL LBL \"SIDE\"
12 L IZ+7 FMAX
13 LBL 0
14 LBL \"SIDE\"
15 L IY-5
16 LBL 0
17 END PGM SUB MM
";

#[test]
fn subprograms_after_the_main_program_run_at_each_call_and_nest() {
    let out = judged(SUBPROGRAM, &settings(true));
    assert_plain(&out);
    let p = points(&out);
    // Both calls: down to Z−2 (compensated), 10 along X and 5 along Y, 5 back along Y.
    for (x0, at) in [(0.0, 0), (40.0, 1)] {
        let cuts: Vec<&[f64; 3]> = p
            .iter()
            .filter(|q| {
                (q[2] - (-2.0 - E_MM)).abs() < 1e-9 && q[0] >= x0 - 1e-9 && q[0] <= x0 + 10.0 + 1e-9
            })
            .collect();
        assert!(cuts.len() >= 3, "call {at}: {out}");
    }
    assert_eq!(out.matches("END PGM").count(), 1, "{out}");
}

#[test]
fn fn_9_to_12_loops_and_q_words_become_numbers() {
    let text = "0 BEGIN PGM LOOP MM
1 FN 0: Q1 = +0
2 L X+0 Y+0 Z+5 R0 FMAX
3 L Z-1 F100
4 LBL 1
5 L X+Q1 Y-Q1 F200
6 FN 1: Q1 = +Q1 + +10
7 FN 12: IF +Q1 LT +40 GOTO LBL 1
8 FN 0: Q2 = +3
9 LBL 2
10 FN 2: Q2 = +Q2 - +1
11 L X+50 Y+Q2
12 FN 10: IF +Q2 NE +0 GOTO LBL 2
13 FN 11: IF +Q2 GT -1 GOTO LBL 3
14 L X+999 Y+999
15 LBL 3
16 FN 9: IF +Q2 EQU +0 GOTO LBL 4
17 L X+888
18 LBL 4
19 L Z+5 FMAX
20 END PGM LOOP MM
";
    let out = judged(text, &settings(true));
    assert_plain(&out);
    let xy: Vec<(f64, f64)> = points(&out).iter().map(|p| (p[0], p[1])).collect();
    let want = [
        (0.0, 0.0),
        (0.0, 0.0),
        (10.0, -10.0),
        (20.0, -20.0),
        (30.0, -30.0),
        (50.0, 2.0),
        (50.0, 1.0),
        (50.0, 0.0),
    ];
    let got: Vec<(f64, f64)> = xy.iter().copied().skip(xy.len() - want.len()).collect();
    for (g, w) in got.iter().zip(&want) {
        assert!(
            (g.0 - w.0).abs() < 1e-9 && (g.1 - w.1).abs() < 1e-9,
            "{got:?}\n{out}"
        );
    }
    assert!(!out.contains("999") && !out.contains("888"), "{out}");
}

#[test]
fn q_arithmetic_fn_4_to_8_and_formulas_in_degrees() {
    let text = "0 BEGIN PGM MATH MM
1 FN 0: Q1 = +16
2 FN 5: Q2 = SQRT +Q1
3 FN 6: Q3 = SIN +30
4 FN 7: Q4 = COS +60
5 FN 8: Q5 = +3 LEN +4
6 FN 4: Q6 = +Q1 DIV +Q2
7 FN 3: Q7 = +Q3 * +Q5
8 Q8 = Q2 + 2 * SIN ( Q9 + 90 ) - (Q4 - 0.5)
9 QL1 = -(Q2 ^ 2) / 8
10 L X+0 Y+0 Z+5 R0 FMAX
11 L Z-1 F100
12 L X+Q2 Y+Q5
13 L X+Q6 Y+Q7
14 L X+Q8 Y-QL1
15 L Z+5 FMAX
16 END PGM MATH MM
";
    // Q9 is read before it is set: refused, naming it (line 8 computes Q8 from it).
    let msg = refuse(text);
    assert_msg(
        &msg,
        &[
            "t.h:15",
            "block 14",
            "Q9",
            "read before the program sets it",
        ],
    );
    let text = text.replace("Q9 + 90", "90");
    let out = judged(&text.replace("X+Q8 Y-QL1", "X+Q8 Y+2"), &settings(true));
    let p = points(&out);
    // Hand values: SQRT 16 = 4, SIN 30° = 0.5, COS 60° = 0.5, 3 LEN 4 = 5, 16 DIV 4 = 4,
    // 0.5 · 5 = 2.5, 4 + 2·SIN 90° − (0.5 − 0.5) = 6.
    let want = [[4.0, 5.0], [4.0, 2.5], [6.0, 2.0]];
    let got: Vec<[f64; 2]> = p.iter().rev().take(3).rev().map(|q| [q[0], q[1]]).collect();
    for (g, w) in got.iter().zip(&want) {
        assert!(
            (g[0] - w[0]).abs() < 1e-9 && (g[1] - w[1]).abs() < 1e-9,
            "{got:?}\n{out}"
        );
    }
    // QL1 = −(4²)/8 = −2: `Y-QL1` is Y+2.
    let out = run(&text);
    let last = points(&out).last().copied().unwrap_or_default();
    assert!(
        (last[0] - 6.0).abs() < 1e-9 && (last[1] - 2.0).abs() < 1e-9,
        "{out}"
    );
}

#[test]
fn division_by_zero_and_a_negative_root_are_refused_with_the_block() {
    let base = "0 BEGIN PGM DIV MM\n1 FN 0: Q1 = +0\n2 L X+0 Y+0 Z+5 R0 FMAX\n3 LBL 1\n4 L Z-1 F100\n5 LBL 0\n6 CALL LBL 1\n";
    let msg = refuse(&format!(
        "{base}7 FN 4: Q2 = +5 DIV +Q1\n8 END PGM DIV MM\n"
    ));
    assert_msg(&msg, &["t.h:8", "block 7", "division by zero"]);
    let msg = refuse(&format!("{base}7 Q2 = SQRT (Q1 - 4)\n8 END PGM DIV MM\n"));
    assert_msg(
        &msg,
        &["t.h:8", "block 7", "square root of a negative number"],
    );
}

#[test]
fn fn_18_sysread_is_refused_on_a_cut_naming_the_parameter() {
    let text = "0 BEGIN PGM SYS MM
1 FN 18: SYSREAD Q5 = ID240 NR1 IDX3
2 L X+0 Y+0 Z+5 R0 FMAX
3 LBL 1
4 L Z+Q5 F100
5 LBL 0
6 CALL LBL 1
7 END PGM SYS MM
";
    let msg = refuse(text);
    assert_msg(
        &msg,
        &["t.h:5", "block 4", "Z+Q5", "Q5", "SYSREAD", "run time"],
    );
    // A jump on it: the run cannot go on, refused at the jump.
    let text = "0 BEGIN PGM SYS MM
1 FN 18: SYSREAD Q5 = ID240 NR1 IDX3
2 FN 9: IF +Q5 EQU +0 GOTO LBL 1
3 L X+0 Y+0 Z+5 R0 FMAX
4 LBL 1
5 L Z-1 F100
6 LBL 0
7 END PGM SYS MM
";
    let msg = refuse(text);
    assert_msg(&msg, &["t.h:3", "block 2", "Q5", "SYSREAD"]);
}

#[test]
fn fn_17_and_preassigned_parameters_are_runtime_values() {
    let text = "0 BEGIN PGM SYS MM
1 L X+0 Y+0 Z+5 R0 FMAX
2 LBL 1
3 L Z-1 F100
4 L X+Q108
5 LBL 0
6 CALL LBL 1
7 END PGM SYS MM
";
    let msg = refuse(text);
    assert_msg(&msg, &["t.h:5", "Q108", "preset by the TNC", "runtime"]);
    let text = "0 BEGIN PGM SYS MM
1 L X+0 Y+0 Z+5 R0 FMAX
2 LBL 1
3 L Z-1 F100
4 LBL 0
5 CALL LBL 1
6 FN 17: SYSWRITE ID 990 NR1 = +1
7 END PGM SYS MM
";
    let msg = refuse(text);
    assert_msg(&msg, &["t.h:7", "block 6", "SYSWRITE", "run time"]);
}

#[test]
fn an_endless_jump_loop_is_refused_by_the_budget() {
    let text = "0 BEGIN PGM LOOP MM
1 L X+0 Y+0 Z+5 R0 FMAX
2 LBL 1
3 L Z-1 F100
4 LBL 7
5 FN 9: IF +0 EQU +0 GOTO LBL 7
6 LBL 0
7 CALL LBL 1
8 END PGM LOOP MM
";
    let msg = refuse(text);
    assert_msg(
        &msg,
        &[
            "t.h:5",
            "block 4",
            "block 5, line 6",
            "more than 1000000 times",
            "endless loop",
        ],
    );
}

#[test]
fn flow_that_compensates_nothing_is_copied_byte_for_byte() {
    // The plain reading refuses the label's cut (its start is unknown there); run, it stays
    // above the zone, so nothing is compensated and the file is copied as it is (CRLF kept).
    let text = "0 BEGIN PGM COPY MM\r\n1 L X+0 Y+0 Z+5 R0 FMAX\r\n2 Q1 = 10\r\n3 CALL LBL 1\r\n4 M30\r\n5 LBL 1\r\n6 L X+Q1 Y+0 Z+5 F100\r\n7 LBL 0\r\n8 END PGM COPY MM\r\n";
    assert!(compensate_gcode(text, Path::new("t.h"), &Flat, &settings(false)).is_err());
    assert_eq!(run(text), text);
}

#[test]
fn a_refusal_inside_a_called_label_names_its_line_block_and_the_call() {
    let text = "0 BEGIN PGM RL MM
1 L X+0 Y+0 Z+5 R0 FMAX
2 CALL LBL 2
3 L Z+50 R0 FMAX M30
4 LBL 2
5 L Z-1 F100
6 CT X+10 Y+10
7 LBL 0
8 END PGM RL MM
";
    let msg = refuse(text);
    assert_msg(&msg, &["t.h:7", "block 6:", "CT", "LBL 2 called on line 3"]);
}

#[test]
fn cycles_inside_labels_compensate_holes_as_outside() {
    let text = "0 BEGIN PGM HOLES MM
1 TOOL CALL 27 Z S6000
2 L X+0 Y+0 Z+50 R0 FMAX
3 CYCL DEF 200 DRILLING ~
    Q200=+2 ;SET-UP CLEARANCE ~
    Q201=-8 ;DEPTH ~
    Q206=+150 ;FEED RATE FOR PLUNGING ~
    Q202=+8 ;PLUNGING DEPTH ~
    Q210=+0 ;DWELL TIME AT TOP ~
    Q203=+0 ;SURFACE COORDINATE ~
    Q204=+50 ;2ND SET-UP CLEARANCE ~
    Q211=+0 ;DWELL TIME AT DEPTH
4 CALL LBL 1
5 L Z+50 R0 FMAX M30
6 LBL 1
7 L X+21 Y-15 R0 FMAX M99
8 L X+31 Y-15 R0 FMAX M99
9 LBL 0
10 END PGM HOLES MM
";
    let holes = CompensationSettings {
        compensate_holes: true,
        ..settings(true)
    };
    let out = judged(text, &holes);
    assert!(out.contains("Q203=-0.02"), "{out}");
    let msg = refuse_with(text, &settings(true));
    assert_msg(&msg, &["t.h:16", "`compensate_holes`"]);
}

#[test]
fn call_pgm_leaves_the_parameters_unknown_as_a_missing_file() {
    let text = "0 BEGIN PGM CALLER MM
1 Q1 = 5
2 CALL PGM TNC:\\SUB
3 L X+0 Y+0 Z+5 R0 FMAX
4 LBL 1
5 L Z-1 X+Q1 F100
6 LBL 0
7 CALL LBL 1
8 END PGM CALLER MM
";
    let msg = refuse(text);
    assert_msg(&msg, &["t.h:6", "CALL PGM"]);
}

#[test]
fn control_flow_behind_a_block_skip_is_refused_after_earlier_cuts() {
    let text = "0 BEGIN PGM SKIP MM
1 L X+0 Y+0 Z+5 R0 FMAX
2 LBL 1
3 L Z-1 F100
4 LBL 0
5 CALL LBL 1
6 L Z+5 FMAX
/ 7 L M30
8 CALL LBL 1
9 END PGM SKIP MM
";
    let msg = refuse(text);
    assert_msg(&msg, &["t.h:8", "block 7", "block skip"]);
    // An earlier refusal comes first.
    let msg = refuse(&text.replace("3 L Z-1 F100", "3 L Z-1 F100 RL"));
    assert_msg(&msg, &["t.h:4", "RL"]);
}

#[test]
fn the_flattened_program_stops_at_the_output_limit() {
    // 120 000 blocks of about 25 bytes: 3 MB, over a 1 MB limit (every other test here writes a
    // few hundred bytes, so the process-wide limit does not touch them).
    errmap::io::safety::set_max_output_mb(1);
    let text = "0 BEGIN PGM BIG MM
1 L X+0 Y+0 Z+5 R0 FMAX
2 Q1 = 0
3 LBL 1
4 L X+Q1 Y+0 Z-1 F100
5 Q1 = Q1 + 0.001
6 FN 12: IF +Q1 LT +120 GOTO LBL 1
7 END PGM BIG MM
";
    let msg = refuse(text);
    assert_msg(&msg, &["t.h:", "output limit of 1 MB", "`max_output_mb`"]);
}

#[test]
fn hostile_programs_are_refused_not_a_panic() {
    for text in [
        "0 BEGIN PGM X MM\n1 CALL LBL 9\n2 END PGM X MM\n",
        "0 BEGIN PGM X MM\n1 LBL 1\n2 CALL LBL 1\n3 LBL 0\n4 CALL LBL 1\n5 END PGM X MM\n",
        "0 BEGIN PGM X MM\n1 Q1 = (((\n2 L X+Q1 Y+0 Z-1 F100\n3 END PGM X MM\n",
        "0 BEGIN PGM X MM\n1 FN 9: IF\n2 END PGM X MM\n",
        "0 BEGIN PGM X MM\n1 FN\n2 Q1 = 1 / 0\n3 END PGM X MM\n",
        "0 BEGIN PGM X MM\n1 CALL LBL 1 REP\n2 LBL 1\n3 END PGM X MM\n",
        "0 BEGIN PGM X MM\n1 LBL 1\n2 LBL 1\n3 CALL LBL 1 REP 2\n4 END PGM X MM\n",
        "0 BEGIN PGM X MM\n1 Q1 = SIN\n2 Q2 = ASIN 2\n3 L X+0 Y+0 Z-1 F100\n4 CALL LBL \"\n",
    ] {
        let _ = compensate_gcode(text, Path::new("t.h"), &Flat, &settings(true));
    }
    // A subprogram that calls itself: refused.
    let msg = refuse("0 BEGIN PGM X MM\n1 L X+0 Y+0 Z+5 R0 FMAX\n2 CALL LBL 1\n3 M30\n4 LBL 1\n5 L Z-1 F100\n6 CALL LBL 1\n7 LBL 0\n8 END PGM X MM\n");
    assert_msg(&msg, &["t.h:7", "cannot call itself"]);
}

/// The judge itself, on programs whose moves are known by hand: a tracer that ran labels or Q
/// parameters wrongly would pass a wrong flattening.
#[test]
fn the_reference_tracer_runs_labels_repeats_and_q_as_the_manual_says() {
    let ends = |text: &str| -> Vec<[f64; 3]> {
        klartext_trace::trace(text)
            .unwrap_or_else(|e| panic!("{e}"))
            .iter()
            .map(|s| s.end)
            .collect()
    };
    // A subprogram after M30 runs at its call and returns; REP 1 runs its section twice.
    let got = ends(
        "0 BEGIN PGM T MM\n1 L X+0 Y+0 Z+0 FMAX\n2 CALL LBL 3\n3 LBL 1\n4 L IX+1 F100\n5 CALL LBL 1 REP 1\n6 M30\n7 LBL 3\n8 L Y+7 F100\n9 LBL 0\n10 END PGM T MM\n",
    );
    assert_eq!(
        got,
        vec![
            [0.0, 0.0, 0.0],
            [0.0, 7.0, 0.0],
            [1.0, 7.0, 0.0],
            [2.0, 7.0, 0.0]
        ]
    );
    // FN 12 loop, a formula in degrees, `X-Q1`.
    let got = ends(
        "0 BEGIN PGM T MM\n1 FN 0: Q1 = +1\n2 L X+0 Y+0 Z+0 FMAX\n3 LBL 2\n4 L X-Q1 Y+0 F100\n5 Q1 = Q1 + 2 * COS ( 60 )\n6 FN 12: IF +Q1 LT +3 GOTO LBL 2\n7 END PGM T MM\n",
    );
    assert_eq!(
        got,
        vec![[0.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [-2.0, 0.0, 0.0]]
    );
    // A value read from the machine, or one never set, is not traced.
    assert!(klartext_trace::trace(
        "0 BEGIN PGM T MM\n1 FN 18: SYSREAD Q5 = ID240 NR1 IDX3\n2 L X+Q5 F100\n"
    )
    .is_err());
    assert!(klartext_trace::trace("0 BEGIN PGM T MM\n1 L X+Q5 F100\n").is_err());
}
