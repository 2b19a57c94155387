//! The 62 real public programs of ../shared/corpus/programs through the real binary, with a flat +20 µm map and `--zone all`: each is followed (exit 0, its output checked by an executor that is not errmap's code) or refused (exit 2 at a line, for a reason in docs/toolpath.md's "Refusal reasons" table); never exit 0 with a wrong line, a panic, exit 3 or an error without a line.
//!
//! Judges: LinuxCNC's rs274 (tests/common/rs274_canon.rs), a Fanuc reference tracer
//! (tests/common/fanuc_trace.rs), a Klartext reference tracer (tests/common/klartext_trace.rs)
//! and nc-gcode-interpreter from PyPI for Sinumerik (tests/common/sinumerik_nci.rs); each hands
//! its moves to tests/common/path_judge.rs. The tally is printed on every run.

mod common;
#[path = "common/fanuc_trace.rs"]
mod fanuc_trace;
#[path = "common/klartext_trace.rs"]
mod klartext_trace;
#[path = "common/path_judge.rs"]
mod path_judge;
#[path = "common/rs274_canon.rs"]
mod rs274_canon;
#[path = "common/sinumerik_nci.rs"]
mod sinumerik_nci;

use path_judge::Seg;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// E of the flat map, mm (e_mean_um = 20 with a network that outputs zero).
const E_MM: f64 = 0.020;

/// A flat +20 µm map measured over ±5000 mm: every program of the corpus lies inside.
const FLAT_MODEL_WIDE: &str = r#"{
  "format": "errmap-map-model/1",
  "name": "flat-wide",
  "normal": "z",
  "domain": {"u_min_mm": -5000.0, "v_min_mm": -5000.0, "u_max_mm": 5000.0, "v_max_mm": 5000.0},
  "normalisation": {"u_min_mm": -5000.0, "u_max_mm": 5000.0, "v_min_mm": -5000.0, "v_max_mm": 5000.0,
                    "e_mean_um": 20.0, "e_std_um": 1.0},
  "network": {"layer_sizes": [2, 1], "activation": "tanh", "params": [0.0, 0.0, 0.0]},
  "hull_mm": [[-5000.0, -5000.0], [5000.0, -5000.0], [5000.0, 5000.0], [-5000.0, 5000.0]],
  "surface_mm": [-1.0, -1.0]
}"#;

/// The flags a user of each program would give besides `--dialect` (from its folder): units
/// where the program states none (read from its source and numbers), how the machine reads
/// decimal-less numbers, the power-on motion mode where axis words come before any motion
/// word, and `--expand` / `--compensate-holes` where it uses subprograms, loops or cycles.
const FLAGS: &[(&str, &[&str])] = &[
    // Fanuc, Haas, Fadal.
    (
        "donpayne-advanced_arcs_o2001.cnc",
        &["--fanuc-numbers", "is-b", "--expand"],
    ),
    (
        "donpayne-advanced_arcs_o9001.cnc",
        &["--units", "inch", "--fanuc-numbers", "is-b", "--expand"],
    ),
    (
        "donpayne-gauge_tool_o1011.cnc",
        &["--fanuc-numbers", "is-b", "--expand"],
    ),
    (
        "donpayne-gauge_tool_o1012.cnc",
        &["--units", "inch", "--fanuc-numbers", "is-b", "--expand"],
    ),
    (
        "donpayne-lathe_jaws_o4001.cnc",
        &["--fanuc-numbers", "is-b", "--power-on-motion", "g0"],
    ),
    (
        "donpayne-turners_cube_o3001.cnc",
        &["--fanuc-numbers", "is-b", "--power-on-motion", "g0"],
    ),
    ("enier-1003-inspection-plate.nc", &["--compensate-holes"]),
    (
        "enier-1006-motor-spacer-bracket.nc",
        &["--compensate-holes"],
    ),
    ("enier-mill_hp_4.nc", &["--compensate-holes"]),
    ("enier-slot_assembly_11.nc", &["--compensate-holes"]),
    ("haas-lathe-L8-Ex1.nc", &["--fanuc-numbers", "is-b"]),
    ("janforys-fadal-frezowanie.nc", &["--units", "mm"]),
    (
        "janforys-fadal-plytka.nc",
        &[
            "--units",
            "mm",
            "--fanuc-numbers",
            "is-b",
            "--power-on-motion",
            "g0",
            "--expand",
            "--compensate-holes",
        ],
    ),
    (
        "janforys-fadal-wiercenie.nc",
        &[
            "--units",
            "mm",
            "--fanuc-numbers",
            "is-b",
            "--power-on-motion",
            "g0",
            "--expand",
            "--compensate-holes",
        ],
    ),
    ("janforys-fadal-zamn020.nc", &["--fanuc-numbers", "is-b"]),
    ("stcline-Cline_Maze.nc", &["--units", "inch"]),
    ("vendetta-haas-mastercam-face-mill-O0006.NC", &[]),
    (
        "vendetta-sscnc-Phase2_Code60_Work_Version_Update.txt",
        &["--fanuc-numbers", "calculator"],
    ),
    (
        "vendetta-sscnc-Sub_Programs_Test.txt",
        &["--fanuc-numbers", "calculator", "--expand"],
    ),
    // Heidenhain Klartext.
    ("aptpp-Interface-glue-11.h", &["--compensate-holes"]),
    ("aptpp-basemach-11.h", &["--compensate-holes"]),
    ("aptpp-boss-0TREF.h", &[]),
    ("aptpp-boss-12.h", &[]),
    ("digiliner-YL-01.h", &[]),
    ("digiliner-YL-05.h", &[]),
    ("digiliner-xiaojiubei-11.H", &["--expand"]),
    (
        "janforys-AD-N031-STR-2.H",
        &["--expand", "--compensate-holes"],
    ),
    ("janforys-CHWYT-125.h", &["--expand"]),
    (
        "janforys-DP-N060-GAB.H",
        &["--expand", "--compensate-holes"],
    ),
    ("janforys-KR-N091-KR-KOL-MOC-WCIECIE.H", &["--expand"]),
    ("janforys-KR-N091-n091.h", &[]),
    ("janforys-PLYTA-SP-n160-GAB.h", &["--expand"]),
    (
        "janforys-PLYTA-SP-n160-OTW.h",
        &["--expand", "--compensate-holes"],
    ),
    (
        "janforys-PLYTA-SP-n160-PLAN-OS-Y-ROT.h",
        &["--expand", "--compensate-holes"],
    ),
    ("janforys-PODZIALY-PODZIAL-ODP.H", &[]),
    (
        "polymech-800_Feed-512_Brackets-opening.h",
        &["--compensate-holes"],
    ),
    (
        "polymech-asterix-sm-10m-slot-30d.h",
        &["--compensate-holes"],
    ),
    (
        "polymech-asterix-sm-cabinet-contours.h",
        &["--compensate-holes"],
    ),
    (
        "polymech-cas-edc-max-beams-upn80-878.h",
        &["--compensate-holes"],
    ),
    (
        "polymech-cas-mini-pockets-finish-993.h",
        &["--compensate-holes"],
    ),
    ("polymech-e-cab-omron-pockets.h", &["--compensate-holes"]),
    (
        "polymech-motorflange-register-67.h",
        &["--compensate-holes"],
    ),
    ("polymech-tb-mount-m7s.h", &["--compensate-holes"]),
    // LinuxCNC.
    ("lagun-HEMA-P016-M.250.ngc", &[]),
    ("lagun-HEMA-P030.ngc", &[]),
    ("lagun-HEMA-P040-D.ngc", &["--compensate-holes"]),
    ("lagun-HEMA-TMP-M6mm.ngc", &["--compensate-holes"]),
    ("lagun-HEMS-0003.ngc", &["--expand"]),
    ("lagun-HEQJ-P008.ngc", &[]),
    ("lagun-camarm.ngc", &["--units", "inch", "--expand"]),
    ("lagun-mmh_rest.ngc", &[]),
    ("lagun-pocket_rect.ngc", &["--units", "inch", "--expand"]),
    ("linuxcnc-tests-cam-nisley.ngc", &["--expand"]),
    // Sinumerik.
    ("dubovikov-123.mpf", &["--units", "mm", "--expand"]),
    ("dubovikov-CHAMFER.spf", &["--units", "mm", "--expand"]),
    (
        "dubovikov-KANAVKA_SFERA.spf",
        &["--units", "mm", "--expand"],
    ),
    (
        "dubovikov-kanavka_vint_sector.mpf",
        &["--units", "mm", "--expand"],
    ),
    ("dubovikov-slot.mpf", &["--units", "mm", "--expand"]),
    ("fb422-PRIPREMA-KONTURA.MPF", &["--units", "mm", "--expand"]),
    (
        "fb422-PRIPREMA-PROBA_NAVOJA_KONTURNO.MPF",
        &["--units", "mm", "--expand"],
    ),
    ("philip-CAM_TEST.MPF", &["--expand"]),
    ("takashinord-test_1.mpf", &["--units", "mm", "--expand"]),
];

/// A refusal reason: a row of docs/toolpath.md's "Refusal reasons" table, recognised by any of
/// its phrases in errmap's message. `cannot_vouch`: no rewrite can be exact from the file
/// alone (the documented cannot-vouch list). Checked in order; the first match names it.
struct Reason {
    name: &'static str,
    phrases: &'static [&'static str],
    cannot_vouch: bool,
}

static REASONS: &[Reason] = &[
    Reason {
        name: "lathe program",
        phrases: &["`G96`", "`G97`", "`G71` is not", "`G75` is not", "lathe"],
        cannot_vouch: true,
    },
    Reason {
        name: "5-axis, rotary axes or tilted plane",
        phrases: &[
            "PLANE",
            "M128",
            "TRAORI",
            "CYCLE800",
            "CYCL DEF 19",
            " A+",
            " B+",
            " C+",
            "rotary",
            "tilt",
        ],
        cannot_vouch: true,
    },
    Reason {
        name: "runtime values (read from the machine)",
        phrases: &[
            "SYSREAD",
            "system variable",
            "at run time",
            "runtime",
            "sets a variable errmap does not follow",
        ],
        cannot_vouch: true,
    },
    Reason {
        name: "missing file (a called program or the caller)",
        phrases: &[
            "not defined in this file",
            "not in this file",
            "a main program errmap cannot see",
            "CALL PGM",
            "it is a subprogram",
            "file is not",
        ],
        cannot_vouch: true,
    },
    Reason {
        name: "units not stated",
        phrases: &["cannot tell millimetres from inches"],
        cannot_vouch: false,
    },
    Reason {
        name: "decimal-less number",
        phrases: &["has no decimal point"],
        cannot_vouch: false,
    },
    Reason {
        name: "axis words before any motion word",
        phrases: &["axis words before any motion word"],
        cannot_vouch: false,
    },
    Reason {
        name: "dialect not known",
        phrases: &["cannot tell the controller dialect"],
        cannot_vouch: false,
    },
    Reason {
        name: "cutter radius compensation",
        phrases: &["cutter radius compensation", "radius compensation"],
        cannot_vouch: false,
    },
    Reason {
        name: "canned or machining cycle",
        phrases: &["canned cycle", "cycle call", "machining cycle"],
        cannot_vouch: false,
    },
    Reason {
        name: "subprogram, label, loop or jump",
        phrases: &[
            "subprogram",
            "subroutine",
            "O-word",
            "label",
            "jumps",
            "loop",
            "REP",
        ],
        cannot_vouch: false,
    },
    Reason {
        name: "parameters or expressions",
        phrases: &["parameters or [expressions]", "parameter", "expression"],
        cannot_vouch: false,
    },
    Reason {
        name: "unknown start point",
        phrases: &["start point of this move is unknown"],
        cannot_vouch: false,
    },
    Reason {
        name: "function or frame not followed",
        phrases: &[
            "is a function errmap does not follow",
            "may move or transform",
            "does not follow the",
        ],
        cannot_vouch: false,
    },
    Reason {
        name: "Klartext program without block numbers",
        phrases: &["errmap follows Heidenhain ISO programs only"],
        cannot_vouch: false,
    },
    Reason {
        name: "word or code errmap does not read",
        phrases: &[
            "is not a word",
            "is not a G code",
            "not a word of a Klartext",
            "without a value right after it",
            "outside a comment",
        ],
        cannot_vouch: false,
    },
];

/// What became of one program.
enum Outcome {
    /// Exit 0, output checked by the judge: cutting points checked.
    Followed { judge: &'static str, points: usize },
    /// Exit 0 with nothing compensated (no cutting move): the output equals the input.
    Unchanged,
    /// Exit 2 at a line, for a documented reason.
    Refused {
        reason: &'static Reason,
        message: String,
        /// Flags the hint suggests although they were given.
        suggests_given: String,
    },
    /// Exit 0, but the dialect's judge is not installed here and not required: reported, not
    /// counted as followed.
    Unjudged(String),
    /// Anything else: the test fails.
    Wrong(String),
}

fn corpus() -> Option<PathBuf> {
    let dir = std::env::var_os("ERRMAP_CORPUS_PROGRAMS")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/corpus/programs"));
    dir.is_dir().then_some(dir)
}

/// The program's units as its users would state them, for the tracers: `--units` or none.
fn flag<'a>(flags: &[&'a str], name: &str) -> Option<&'a str> {
    flags
        .iter()
        .position(|f| *f == name)
        .and_then(|i| flags.get(i + 1).copied())
}

/// How the Fanuc tracer reads what a program leaves open, from the flags errmap was given.
fn fanuc_setup(flags: &[&str]) -> fanuc_trace::FanucSetup {
    fanuc_trace::FanucSetup {
        inch: flag(flags, "--units").map(|u| u == "inch"),
        increment_mm: match flag(flags, "--fanuc-numbers") {
            Some("is-a") => Some(0.01),
            Some("is-b") => Some(0.001),
            Some("is-c") => Some(0.0001),
            _ => None,
        },
        power_on_g1: flag(flags, "--power-on-motion").map(|m| m == "g1"),
    }
}

/// Moves of `bytes` by the dialect's judge; `None` when its executor is not installed.
fn execute(
    dialect: &str,
    flags: &[&str],
    work: &Path,
    name: &str,
    bytes: &[u8],
) -> Option<Result<Vec<Seg>, String>> {
    let text = String::from_utf8_lossy(bytes);
    match dialect {
        "linuxcnc" => {
            // A program that states no units runs in the machine's (`--units`): say them to
            // rs274 too, in front of both programs alike.
            let mut with_units = match flag(flags, "--units") {
                Some("inch") => b"G20\n".to_vec(),
                Some("mm") => b"G21\n".to_vec(),
                _ => Vec::new(),
            };
            with_units.extend_from_slice(bytes);
            rs274_canon::run(work, name, &with_units)
        }
        "fanuc" => Some(fanuc_trace::trace(&text, fanuc_setup(flags))),
        "heidenhain" => Some(klartext_trace::trace(&text)),
        "sinumerik" => {
            if !sinumerik_nci::available() {
                return None;
            }
            let path = work.join(format!("{name}.mpf"));
            std::fs::write(&path, bytes).ok()?;
            Some(sinumerik_nci::trace(&path, &text))
        }
        _ => Some(Err(format!("no judge for {dialect}"))),
    }
}

fn judge_name(dialect: &str) -> &'static str {
    match dialect {
        "linuxcnc" => "rs274",
        "fanuc" => "fanuc tracer",
        "heidenhain" => "klartext tracer",
        _ => "nc-gcode-interpreter",
    }
}

/// Run one program and judge it.
fn one(dir: &Path, dialect: &str, path: &Path, flags: &[&str]) -> Outcome {
    let name = path.file_name().unwrap().to_string_lossy().into_owned();
    let out = dir.join(format!("out-{name}"));
    let mut args = vec![
        "compensate",
        "--model",
        "model.json",
        "--zone",
        "all",
        "--dialect",
        dialect,
    ];
    args.extend_from_slice(flags);
    let input = path.to_string_lossy().into_owned();
    let output = out.to_string_lossy().into_owned();
    args.extend_from_slice(&[&input, "-o", &output, "--json"]);
    let run = common::errmap(dir, &args);
    match run.code {
        0 => {}
        2 => {
            let message = run.stderr.trim().to_string();
            // file:LINE, the line a machinist looks for.
            let at_line = message
                .split_once(&format!("{input}:"))
                .is_some_and(|(_, rest)| rest.starts_with(|c: char| c.is_ascii_digit()));
            if !at_line {
                return Outcome::Wrong(format!("refused without a line number: {message}"));
            }
            if message.contains("panicked") {
                return Outcome::Wrong(format!("panic: {message}"));
            }
            // The reason is read after the location (the file name may hold any word).
            let reason_text = message
                .split_once(&format!("{input}:"))
                .map_or(message.as_str(), |(_, rest)| rest);
            return match REASONS
                .iter()
                .find(|r| r.phrases.iter().any(|p| reason_text.contains(p)))
            {
                Some(reason) => {
                    // A hint must not suggest a flag the user already gave (reported, not
                    // asserted: the messages belong to the readers being worked on).
                    let hint = reason_text.split_once("(hint:").map_or("", |(_, h)| h);
                    let again: Vec<&str> = args
                        .iter()
                        .filter(|a| a.starts_with("--") && hint.contains(*a))
                        .copied()
                        .collect();
                    Outcome::Refused {
                        reason,
                        message: message.replace(&input, &format!("{dialect}/{name}")),
                        suggests_given: again.join(" "),
                    }
                }
                None => Outcome::Wrong(format!(
                    "refused for a reason not in the Refusal reasons table: {message}"
                )),
            };
        }
        code => return Outcome::Wrong(format!("exit {code}: {}", run.stderr.trim())),
    }
    let doc: serde_json::Value = match serde_json::from_str(&run.stdout) {
        Ok(d) => d,
        Err(e) => return Outcome::Wrong(format!("exit 0 without a JSON report ({e})")),
    };
    let changed = doc["report"]["moves_changed"].as_u64().unwrap_or(0);
    let original = std::fs::read(path).unwrap();
    let Ok(written) = std::fs::read(&out) else {
        return Outcome::Wrong("exit 0 but no output file".into());
    };
    if changed == 0 {
        return if written == original {
            Outcome::Unchanged
        } else {
            Outcome::Wrong("nothing compensated, yet the output differs from the input".into())
        };
    }
    let work = dir.join(format!("judge-{name}"));
    std::fs::create_dir_all(&work).unwrap();
    let judge = judge_name(dialect);
    let orig = execute(dialect, flags, &work, "orig", &original);
    let new = execute(dialect, flags, &work, "out", &written);
    match (orig, new) {
        (None, _) | (_, None) => Outcome::Wrong(format!("{judge} is not installed: cannot verify")),
        (Some(Err(e)), _) => Outcome::Wrong(format!(
            "followed, but {judge} does not follow the original: {e}"
        )),
        (_, Some(Err(e))) => Outcome::Wrong(format!("{judge} rejects the output: {e}")),
        (Some(Ok(o)), Some(Ok(n))) => match path_judge::judge(&o, &n, E_MM) {
            // Under cutter compensation the output may not add moves without motion in the
            // plane (the control looks past only a few).
            Ok(_) if dialect == "fanuc"
                && fanuc_trace::plane_less_moves_under_comp(
                    &String::from_utf8_lossy(&written),
                    fanuc_setup(flags),
                ) > fanuc_trace::plane_less_moves_under_comp(
                    &String::from_utf8_lossy(&original),
                    fanuc_setup(flags),
                ) =>
            {
                Outcome::Wrong(format!(
                    "WRONG OUTPUT ({judge}): moves without motion in the plane added under cutter compensation"
                ))
            }
            Ok(v) => Outcome::Followed {
                judge,
                points: v.points_checked,
            },
            Err(e) => Outcome::Wrong(format!("WRONG OUTPUT ({judge}): {e}")),
        },
    }
}

#[test]
fn every_real_program_is_followed_exactly_or_refused_for_a_documented_reason() {
    let Some(root) = corpus() else {
        let why = "../shared/corpus/programs is missing";
        if std::env::var("ERRMAP_REQUIRE_CORPUS").is_ok_and(|v| v == "1") {
            panic!("{why} and ERRMAP_REQUIRE_CORPUS=1");
        }
        println!("SKIPPED: {why}");
        return;
    };
    let rs274_missing = !rs274_canon::gcode_dir().join("rs274-check.sh").is_file()
        || (!Path::new("/opt/linuxcnc-rs274/usr/bin/rs274").is_file()
            && std::env::var_os("RS274").is_none()
            && !std::process::Command::new("sh")
                .args(["-c", "command -v rs274"])
                .status()
                .is_ok_and(|s| s.success()));
    if rs274_missing && rs274_canon::required() {
        panic!("rs274 is missing and ERRMAP_REQUIRE_RS274=1");
    }
    if !sinumerik_nci::available() && sinumerik_nci::required() {
        panic!(
            "nc-gcode-interpreter is missing from {} and ERRMAP_REQUIRE_NCI=1",
            sinumerik_nci::venv().display()
        );
    }
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("model.json"), FLAT_MODEL_WIDE).unwrap();

    let mut rows: Vec<(String, Outcome)> = Vec::new();
    for dialect in ["fanuc", "heidenhain", "linuxcnc", "sinumerik"] {
        let mut files: Vec<PathBuf> = std::fs::read_dir(root.join(dialect))
            .map(|d| d.flatten().map(|e| e.path()).collect())
            .unwrap_or_default();
        files.sort();
        for path in files {
            let name = path.file_name().unwrap().to_string_lossy().into_owned();
            let flags = FLAGS
                .iter()
                .find(|(f, _)| *f == name)
                .map_or(&[][..], |(_, fl)| *fl);
            let skip = match dialect {
                "linuxcnc" => rs274_missing,
                "sinumerik" => !sinumerik_nci::available(),
                _ => false,
            };
            let mut outcome = one(dir.path(), dialect, &path, flags);
            if let Outcome::Wrong(m) = &outcome {
                if skip && m.contains("not installed") {
                    outcome = Outcome::Unjudged(m.clone());
                }
            }
            rows.push((format!("{dialect}/{name}"), outcome));
        }
    }

    // The tally, printed always.
    let mut tally = String::new();
    let mut again = String::new();
    let (mut followed, mut unchanged, mut refused, mut vouchless, mut wrong, mut unjudged) =
        (0, 0, 0, 0, 0, 0);
    for (file, outcome) in &rows {
        let line = match outcome {
            Outcome::Followed { judge, points } => {
                followed += 1;
                format!("followed+verified ({judge}, {points} cut points on the path)")
            }
            Outcome::Unchanged => {
                unchanged += 1;
                "followed, nothing to compensate (output = input)".to_string()
            }
            Outcome::Refused {
                reason,
                message,
                suggests_given,
            } => {
                refused += 1;
                if !suggests_given.is_empty() {
                    writeln!(again, "  {file}: suggests {suggests_given}, already given").unwrap();
                }
                if reason.cannot_vouch {
                    vouchless += 1;
                }
                let mark = if reason.cannot_vouch {
                    " [cannot vouch]"
                } else {
                    ""
                };
                let short: String = message.chars().take(220).collect();
                format!("refused: {}{mark}: {short}", reason.name)
            }
            Outcome::Unjudged(m) => {
                unjudged += 1;
                format!("SKIPPED (exit 0, not verified): {m}")
            }
            Outcome::Wrong(m) => {
                wrong += 1;
                format!("FAIL: {m}")
            }
        };
        writeln!(tally, "{file:<62} {line}").unwrap();
    }
    if !again.is_empty() {
        writeln!(
            tally,
            "\nrefusals whose hint suggests a flag the test already gave:\n{again}"
        )
        .unwrap();
    }
    writeln!(tally, "\nby refusal reason:").unwrap();
    for reason in REASONS {
        let n = rows
            .iter()
            .filter(|(_, o)| matches!(o, Outcome::Refused { reason: r, .. } if std::ptr::eq(*r, reason)))
            .count();
        if n > 0 {
            let mark = if reason.cannot_vouch {
                " [cannot vouch]"
            } else {
                ""
            };
            writeln!(tally, "  {n:>3}  {}{mark}", reason.name).unwrap();
        }
    }
    let judged = rows.len() - vouchless;
    writeln!(
        tally,
        "\n{} programs: {followed} followed+verified, {unchanged} followed with nothing to compensate, {refused} refused ({vouchless} cannot-vouch), {unjudged} not verified (judge not installed), {wrong} FAILED\ngoal figure: followed+verified {followed} of {judged} programs not refused for a cannot-vouch reason = {:.0} % (goal ≥ 80 %)",
        rows.len(),
        100.0 * followed as f64 / judged.max(1) as f64
    )
    .unwrap();
    println!("{tally}");
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("target"));
    let _ = std::fs::write(target.join("toolpath_corpus_tally.txt"), &tally);
    assert_eq!(
        wrong, 0,
        "programs that are neither followed exactly nor refused for a documented reason:\n{tally}"
    );
    assert_eq!(
        rows.len(),
        FLAGS.len(),
        "the flag table lists every corpus program:\n{tally}"
    );
}

/// The judges themselves, on programs whose moves are known by hand: a judge that passed a
/// wrong output would make the corpus test worthless.
mod judges {
    use super::{fanuc_trace, klartext_trace, path_judge, E_MM};
    use std::f64::consts::PI;

    fn fanuc(text: &str) -> Vec<path_judge::Seg> {
        fanuc_in(text, None)
    }

    fn fanuc_in(text: &str, increment_mm: Option<f64>) -> Vec<path_judge::Seg> {
        let setup = fanuc_trace::FanucSetup {
            inch: None,
            increment_mm,
            power_on_g1: None,
        };
        fanuc_trace::trace(text, setup).unwrap()
    }

    const ORIGINAL: &str =
        "G21 G90 G17\nG0 X0 Y0 Z5\nG1 Z-1 F100\nG2 X20 Y0 I10 J0\nG1 X30\nG0 Z5\nM30\n";
    /// ORIGINAL lowered by 0.02 mm on its cuts, with the return step a rewriter writes.
    const LOWERED: &str = "G21 G90 G17\nG0 X0 Y0 Z5\nG1 Z-1.02 F100\nG2 X20 Y0 Z-1.02 I10 J0\nG1 X25 Z-1.02\nX30\nG1 Z-1\nG0 Z5\nM30\n";

    #[test]
    fn the_judge_accepts_the_path_lowered_by_e() {
        let v = path_judge::judge(&fanuc(ORIGINAL), &fanuc(LOWERED), E_MM).unwrap();
        // Plunge end, arc end and midpoint, two line ends.
        assert_eq!(v.points_checked, 5);
    }

    #[test]
    fn the_judge_rejects_every_wrong_rewrite() {
        let orig = fanuc(ORIGINAL);
        for (what, wrong) in [
            ("not lowered", LOWERED.replace("Z-1.02", "Z-1.")),
            ("lowered twice", LOWERED.replace("Z-1.02", "Z-1.04")),
            ("raised", LOWERED.replace("Z-1.02", "Z-0.98")),
            ("arc reversed", LOWERED.replace("G2 X20", "G3 X20")),
            (
                "arc dropped",
                LOWERED.replace("G2 X20 Y0 Z-1.02 I10 J0\n", ""),
            ),
            ("cut shortened", LOWERED.replace("X30\n", "X29.99\n")),
            ("rapid moved", LOWERED.replace("G0 Z5\nM30", "G0 Z4.9\nM30")),
            ("no return step", LOWERED.replace("G1 Z-1\nG0 Z5", "G0 X30")),
        ] {
            assert!(
                path_judge::judge(&orig, &fanuc(&wrong), E_MM).is_err(),
                "{what}: accepted\n{wrong}"
            );
        }
    }

    #[test]
    fn the_fanuc_tracer_reads_arcs_units_and_increments_as_the_manual_says() {
        // R arc: from (0,0) to (10,0), R10 clockwise, the shorter arc: centre below the chord
        // at (5, −√75).
        let s = fanuc("G21 G90 G17\nG0 X0 Y0 Z0\nG2 X10. R10.\n");
        let a = s[1].arc.unwrap();
        assert!((a.centre.0 - 5.0).abs() < 1e-9 && (a.centre.1 + 75f64.sqrt()).abs() < 1e-9);
        assert!((a.sweep_rad + 2.0 * (5.0f64 / 10.0).asin()).abs() < 1e-9);
        // R−10: the longer arc, centre above.
        let s = fanuc("G21 G90 G17\nG0 X0 Y0 Z0\nG2 X10. R-10.\n");
        let a = s[1].arc.unwrap();
        assert!((a.centre.1 - 75f64.sqrt()).abs() < 1e-9);
        assert!((a.sweep_rad + 2.0 * PI - 2.0 * (0.5f64).asin()).abs() < 1e-9);
        // G20 inch, G91 incremental, decimal-less is-b (0.0001 in), G18 full circle.
        let s = fanuc_in(
            "G20 G90 G18\nG0 X1. Y0 Z0\nG91 G1 X10000\nG3 I-1. K0\n",
            Some(0.001),
        );
        assert!((s[1].end[0] - 2.0 * 25.4).abs() < 1e-9);
        let a = s[2].arc.unwrap();
        assert_eq!(a.axes, (2, 0, 1));
        assert!((a.centre.1 - 25.4).abs() < 1e-9);
        assert!((a.sweep_rad - 2.0 * PI).abs() < 1e-9);
        // A point a quarter turn on: Z = −R (counter-clockwise seen from +Y takes X to −Z).
        let q = s[2].at(0.25);
        assert!(
            (q[0] - 25.4).abs() < 1e-9 && (q[2] + 25.4).abs() < 1e-9,
            "{q:?}"
        );
        // G92 names the position (10, 0) as 0; G52 shifts X by 5 more: X1. is 16.
        let s = fanuc("G21 G90 G17\nG0 X10. Y0 Z0\nG92 X0 Y0\nG52 X5.\nG1 X1.\n");
        assert!((s[1].end[0] - 16.0).abs() < 1e-9, "{:?}", s[1].end);
        // G99 G81 from Z10: two holes, each rapid to the position and to R2, feed to Z−5, back
        // to R (G99); then G98 with a new Z: the third hole goes back to the start Z, 10.
        let s = fanuc(
            "G21 G90 G17\nG0 X0 Y0 Z10.\nG99 G81 X5. Y0 Z-5. R2. F100.\nX10.\nG98 X15. Z-3.\nG80\n",
        );
        let ends: Vec<(bool, [f64; 3])> = s.iter().map(|g| (g.cut, g.end)).collect();
        let expect = [
            (false, [0.0, 0.0, 10.0]),
            (false, [5.0, 0.0, 10.0]),
            (false, [5.0, 0.0, 2.0]),
            (true, [5.0, 0.0, -5.0]),
            (false, [5.0, 0.0, 2.0]),
            (false, [10.0, 0.0, 2.0]),
            (true, [10.0, 0.0, -5.0]),
            (false, [10.0, 0.0, 2.0]),
            (false, [15.0, 0.0, 2.0]),
            (true, [15.0, 0.0, -3.0]),
            (false, [15.0, 0.0, 10.0]),
        ];
        assert_eq!(ends.len(), expect.len(), "{ends:?}");
        for (a, b) in ends.iter().zip(&expect) {
            assert_eq!(a.0, b.0, "{ends:?}");
            assert!((0..3).all(|k| (a.1[k] - b.1[k]).abs() < 1e-9), "{ends:?}");
        }
    }

    #[test]
    fn the_klartext_tracer_reads_cc_c_cr_and_cp_as_the_manual_says() {
        let s = klartext_trace::trace(
            "0 BEGIN PGM T MM\n1 TOOL CALL 1 Z S1000\n2 L X+10 Y+0 Z+0 R0 FMAX\n3 CC X+0 Y+0\n4 C X+0 Y+10 DR+\n5 CP IPA-450 IZ-2 DR-\n6 L IX+5 F100\n7 CR X+10 Y+0 R+5 DR-\n8 END PGM T MM\n",
        )
        .unwrap();
        assert!(!s[0].cut);
        // C: a quarter turn counter-clockwise.
        assert!((s[1].arc.unwrap().sweep_rad - PI / 2.0).abs() < 1e-9);
        // CP IPA−450 from 90°: ends at −360° ≡ 0° → (10, 0), Z down by 2.
        let cp = &s[2];
        assert!((cp.end[0] - 10.0).abs() < 1e-9 && cp.end[1].abs() < 1e-9);
        assert!((cp.end[2] + 2.0).abs() < 1e-9);
        assert!((cp.arc.unwrap().sweep_rad + 2.5 * PI).abs() < 1e-9);
        // L IX+5 from (10, 0).
        assert!((s[3].end[0] - 15.0).abs() < 1e-9);
        // CR from (15,0) to (10,0), R+5 clockwise: the shorter arc, centre (12.5, +√18.75).
        let a = s[4].arc.unwrap();
        assert!((a.centre.0 - 12.5).abs() < 1e-9 && (a.centre.1 - 18.75f64.sqrt()).abs() < 1e-9);
        assert!(a.sweep_rad < 0.0 && a.sweep_rad > -PI);
        // Cycle 7: X+10 from a datum shifted by 5, then by 2 more (IX), is 17 from the original.
        let s = klartext_trace::trace(
            "0 BEGIN PGM T MM\n1 L X+0 Y+0 Z+0 FMAX\n2 CYCL DEF 7.0 DATUM SHIFT\n3 CYCL DEF 7.1 X+5\n4 CYCL DEF 7.1 IX+2\n5 L X+10 F100\n",
        )
        .unwrap();
        assert!((s[1].end[0] - 17.0).abs() < 1e-9);
        // What the tracer cannot vouch for is refused.
        assert!(klartext_trace::trace("1 CYCL DEF 10.0 ROTATION\n").is_err());
        assert!(klartext_trace::trace("1 M5 M9\n2 M30\n")
            .unwrap()
            .is_empty());
        assert!(klartext_trace::trace("1 M99\n").is_err());
        assert!(klartext_trace::trace("1 L X+Q1 F100\n").is_err());
    }
}

/// The Sinumerik executor on a program whose moves are known by hand.
#[test]
fn the_sinumerik_executor_reads_variables_and_ic() {
    if !sinumerik_nci::available() {
        assert!(
            !sinumerik_nci::required(),
            "nc-gcode-interpreter is missing and ERRMAP_REQUIRE_NCI=1"
        );
        println!(
            "SKIPPED: nc-gcode-interpreter is not installed in {}",
            sinumerik_nci::venv().display()
        );
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    // (nc-gcode-interpreter 0.1.9 reads R parameters as R[1], not R1.)
    let text =
        "G71 G90 G17\nDEF REAL ZS\nZS=5\nG0 X0 Y0 Z=ZS\nG1 Z-1 F100\nG1 X=IC(10)\nG0 Z=ZS*2\nM30\n";
    let path = dir.path().join("p.mpf");
    std::fs::write(&path, text).unwrap();
    let s = sinumerik_nci::trace(&path, text).unwrap();
    let ends: Vec<(bool, [f64; 3])> = s.iter().map(|m| (m.cut, m.end)).collect();
    assert_eq!(
        ends,
        vec![
            (false, [0.0, 0.0, 5.0]),
            (true, [0.0, 0.0, -1.0]),
            (true, [10.0, 0.0, -1.0]),
            (false, [10.0, 0.0, 10.0]),
        ]
    );
    // Arcs and G91 are declined: the interpreter reports no centres and no G91 sums.
    assert!(sinumerik_nci::trace(&path, "G91 G1 X1\n").is_err());
    assert!(sinumerik_nci::trace(&path, "G2 X1 Y1 CR=1\n").is_err());
}

/// The Fanuc tracer and rs274 read the cuts of the corpus's plain LinuxCNC programs (G1–G3,
/// I/J/K arcs in G17 and G18, G20, work offsets) alike: a check of the tracer by an executor
/// that shares no code with it.
#[test]
fn the_fanuc_tracer_agrees_with_rs274_on_plain_programs() {
    let Some(root) = corpus() else {
        println!("SKIPPED: ../shared/corpus/programs is missing");
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    for name in [
        "lagun-HEMA-P016-M.250.ngc",
        "lagun-HEMA-P030.ngc",
        "lagun-HEQJ-P008.ngc",
    ] {
        let bytes = std::fs::read(root.join("linuxcnc").join(name)).unwrap();
        let Some(canon) = rs274_canon::run(dir.path(), name, &bytes) else {
            assert!(
                !rs274_canon::required(),
                "rs274 is missing and ERRMAP_REQUIRE_RS274=1"
            );
            println!("SKIPPED: rs274 is not installed");
            return;
        };
        let canon = canon.unwrap();
        let setup = fanuc_trace::FanucSetup {
            inch: None,
            increment_mm: None,
            power_on_g1: None,
        };
        // M101 runs a script (no motion); G91.1 is LinuxCNC's default incremental I/J/K, the
        // Fanuc's only reading.
        let text = String::from_utf8_lossy(&bytes)
            .replace("M101", "    ")
            .replace("G91.1", "     ");
        let traced = fanuc_trace::trace(&text, setup).unwrap_or_else(|e| panic!("{name}: {e}"));
        // The cuts, in order (rapids differ by G53, whose machine position only rs274 knows).
        let known: Vec<&Seg> = traced.iter().filter(|s| s.cut).collect();
        let canon: Vec<&Seg> = canon.iter().filter(|s| s.cut).collect();
        assert_eq!(known.len(), canon.len(), "{name}: cut counts");
        for (a, b) in known.iter().zip(&canon) {
            assert_eq!(a.cut, b.cut, "{name}: line {}", a.line);
            for k in 0..3 {
                assert!(
                    (a.end[k] - b.end[k]).abs() < 0.002,
                    "{name}: line {}: {:?} vs rs274 {:?}",
                    a.line,
                    a.end,
                    b.end
                );
            }
            match (&a.arc, &b.arc) {
                (None, None) => {}
                (Some(x), Some(y)) => {
                    assert_eq!(x.axes, y.axes, "{name}: line {}", a.line);
                    assert!(
                        (x.centre.0 - y.centre.0).abs() < 0.002
                            && (x.centre.1 - y.centre.1).abs() < 0.002,
                        "{name}: line {}",
                        a.line
                    );
                    assert!(
                        (x.sweep_rad - y.sweep_rad).abs() < 1e-3,
                        "{name}: line {}: sweep {} vs rs274 {}",
                        a.line,
                        x.sweep_rad,
                        y.sweep_rad
                    );
                }
                _ => panic!("{name}: line {}: arc vs line", a.line),
            }
        }
    }
}

/// The LinuxCNC judge (rs274's canonical output in inches, read in mm) rejects a real output
/// with one horizontal cut's vertex left unlowered (Z raised back by E = 0.00079 in).
#[test]
fn the_rs274_judge_rejects_one_unlowered_vertex_in_a_real_program() {
    let Some(root) = corpus() else {
        println!("SKIPPED: ../shared/corpus/programs is missing");
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("model.json"), FLAT_MODEL_WIDE).unwrap();
    let input = root.join("linuxcnc/lagun-HEMA-P030.ngc");
    let output = dir.path().join("out.ngc");
    common::ok(
        dir.path(),
        &[
            "compensate",
            "--model",
            "model.json",
            "--zone",
            "all",
            "--dialect",
            "linuxcnc",
            input.to_str().unwrap(),
            "-o",
            output.to_str().unwrap(),
        ],
    );
    let original = std::fs::read(&input).unwrap();
    let good = std::fs::read_to_string(&output).unwrap();
    let z_of = |l: &str| -> Option<f64> {
        let at = l.find(" Z")?;
        l[at + 2..].split_whitespace().next()?.parse().ok()
    };
    // A G1 line between two G1 lines at the same Z: a vertex of a horizontal cut.
    let lines: Vec<&str> = good.lines().collect();
    let i = (1..lines.len() - 1)
        .find(|&i| {
            (i - 1..=i + 1).all(|j| lines[j].contains("G1 ") && z_of(lines[j]).is_some())
                && z_of(lines[i - 1]) == z_of(lines[i])
                && z_of(lines[i + 1]) == z_of(lines[i])
        })
        .expect("a horizontal cut in the output");
    let z = z_of(lines[i]).unwrap();
    let mut bad_lines: Vec<String> = lines.iter().map(|l| l.to_string()).collect();
    bad_lines[i] = lines[i].replace(&format!("Z{z:.5}"), &format!("Z{:.5}", z + 0.00079));
    assert_ne!(bad_lines[i], lines[i], "the Z word is rewritten");
    let bad = bad_lines.join("\n") + "\n";
    let Some(orig) = rs274_canon::run(dir.path(), "orig", &original) else {
        assert!(
            !rs274_canon::required(),
            "rs274 is missing and ERRMAP_REQUIRE_RS274=1"
        );
        println!("SKIPPED: rs274 is not installed");
        return;
    };
    let orig = orig.unwrap();
    let good = rs274_canon::run(dir.path(), "good", good.as_bytes())
        .unwrap()
        .unwrap();
    let bad = rs274_canon::run(dir.path(), "bad", bad.as_bytes())
        .unwrap()
        .unwrap();
    assert!(path_judge::judge(&orig, &good, E_MM).is_ok());
    let err = path_judge::judge(&orig, &bad, E_MM).unwrap_err();
    assert!(err.contains("from the original path"), "{err}");
}
