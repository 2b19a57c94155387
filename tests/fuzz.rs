//! Seeded mutation fuzzing of every input format under `cargo test`: probe CSV, linear run CSV, temperature log and sensor table, G-code in each dialect, CSV toolpaths, job TOML and controller tables. No input may panic or take more than [`MAX_CASE_CPU`] of CPU.
//!
//! Each target starts from its seed corpus in `tests/fuzz-corpus/<corpus>/` and applies a
//! seeded series of byte mutations (bit flips, inserts, deletes, duplicated ranges, spliced
//! seeds, tokens the formats care about: separators, NaN, 1e308, G-code words …). A normal
//! `cargo test` runs 2,000 cases per target; a long run sets the count and the seed:
//!
//! ```text
//! ERRMAP_FUZZ_ITERS=10000000 ERRMAP_FUZZ_SEED=7 cargo test --release --test fuzz -- --exact job_toml --nocapture
//! ```
//!
//! Each case costs what its input exercises: fixtures (fields, settings, the fixed half of a
//! two-file format) are built once outside the loop, inputs are parsed from memory, and the
//! loop runs on a one-thread rayon pool so the library's parallel loops run inline rather than
//! handing every case to other threads. A case is timed in that thread's CPU time, so a busy
//! machine cannot make a quick case look like a hang. A panicking or slow input is written to
//! `target/tmp/fuzz-findings/<target>-<n>.bin` and fails the test.

use cpu_time::ThreadTime;
use errmap::geom::{Axis, ErrorField};
use errmap::interp::{resample, Grid, Method, Surface};
use errmap::io::CsvTable;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::cell::RefCell;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Tokens the formats give meaning to; inserting them reaches deeper than random bytes.
const TOKENS: &[&[u8]] = &[
    b"X=AC(",
    b"X=IC(",
    b"CR=",
    b"TRANS",
    b"ATRANS",
    b"ROT",
    b"G70",
    b"G71",
    b"G52",
    b"G68",
    b"G51",
    b"M98",
    b"M99",
    b"#100=",
    b"O1000",
    b"WHILE[",
    b"GOTO",
    b"N10",
    b" *",
    b"%P1 G71 *",
    b"X+",
    b"L X+",
    b"CC",
    b"BEGIN PGM",
    b",",
    b"\n",
    b"\r\n",
    b"\r",
    b"#",
    b"\"",
    b" ",
    b"\t",
    b"NaN",
    b"inf",
    b"-inf",
    b"1e308",
    b"-1e308",
    b"1e-308",
    b"0",
    b"-0",
    b"5",
    b"1e9",
    b"999999999999999999999",
    b"0.000001",
    b"-",
    b"+",
    b".",
    b"e",
    b"[",
    b"]",
    b"=",
    b"(",
    b")",
    b";",
    b"G0",
    b"G1",
    b"G2",
    b"G3",
    b"G17",
    b"G18",
    b"G19",
    b"G20",
    b"G21",
    b"G90",
    b"G91",
    b"G53",
    b"G92",
    b"X",
    b"Y",
    b"Z",
    b"R",
    b"I",
    b"J",
    b"K",
    b"F",
    b"#1",
    b"#<v>",
    b"o100",
    b"while",
    b"endwhile",
    b"if",
    b"endif",
    b"sub",
    b"call",
    b"%",
    b"x_mm",
    b"y_mm",
    b"z_mm",
    b"nx_mm",
    b"id",
    b"time_s",
    b"run",
    b"target_mm",
    b"direction",
    b"+",
    b"-",
    b"[model]",
    b"[clean]",
    b"epochs",
    b"k_sigma",
    b"\xff",
    b"\xef\xbb\xbf",
    b"\x00",
];

/// Largest fuzzed input, bytes.
const MAX_LEN: usize = 1 << 16;

/// Most CPU one case may take. A program whose control flow runs until `--expand`'s iteration
/// bound (an endless loop the mutation made) costs about a second in the test profile, 1.0–1.2 s
/// on a busy 2-core machine; a blow-up worse than the bounds allow takes far longer.
const MAX_CASE_CPU: Duration = Duration::from_secs(3);
fn mutate(rng: &mut ChaCha8Rng, seeds: &[Vec<u8>]) -> Vec<u8> {
    let mut data = seeds[rng.random_range(0..seeds.len())].clone();
    let rounds = 1 + rng.random_range(0..8);
    for _ in 0..rounds {
        let len = data.len();
        let at = if len == 0 {
            0
        } else {
            rng.random_range(0..=len)
        };
        match rng.random_range(0..10) {
            0 if len > 0 => {
                let i = rng.random_range(0..len);
                data[i] ^= 1 << rng.random_range(0..8);
            }
            1 if len > 0 => {
                let i = rng.random_range(0..len);
                data[i] = rng.random();
            }
            2 => data.insert(at, rng.random()),
            3 if len > 0 => {
                let end = (at + rng.random_range(1..64)).min(len);
                data.drain(at.min(end)..end);
            }
            4 if len > 0 => {
                let start = rng.random_range(0..len);
                let end = (start + rng.random_range(1..256)).min(len);
                let chunk = data[start..end].to_vec();
                let times = 1 + rng.random_range(0..4);
                for _ in 0..times {
                    data.splice(at..at, chunk.iter().copied());
                }
            }
            5 => {
                let other = &seeds[rng.random_range(0..seeds.len())];
                if !other.is_empty() {
                    let from = rng.random_range(0..other.len());
                    data.truncate(at);
                    data.extend_from_slice(&other[from..]);
                }
            }
            6 => data.truncate(at),
            _ => {
                let token = TOKENS[rng.random_range(0..TOKENS.len())];
                data.splice(at..at, token.iter().copied());
            }
        }
        data.truncate(MAX_LEN);
    }
    data
}

fn corpus(target: &str) -> Vec<(String, Vec<u8>)> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fuzz-corpus")
        .join(target);
    let mut seeds: Vec<(String, Vec<u8>)> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| {
            let p = e.unwrap().path();
            (
                p.file_name().unwrap().to_string_lossy().to_string(),
                std::fs::read(&p).unwrap(),
            )
        })
        .collect();
    seeds.sort();
    assert!(!seeds.is_empty(), "no seeds in {}", dir.display());
    seeds
}

fn iterations() -> u64 {
    std::env::var("ERRMAP_FUZZ_ITERS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(2_000)
}

/// Optional wall-clock budget of a long run (`ERRMAP_FUZZ_SECONDS`): the run stops there and
/// reports the executions it made.
fn time_budget() -> Option<Duration> {
    std::env::var("ERRMAP_FUZZ_SECONDS")
        .ok()
        .and_then(|v| v.parse().ok())
        .map(Duration::from_secs_f64)
}

fn base_seed() -> u64 {
    std::env::var("ERRMAP_FUZZ_SEED")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1)
}

thread_local! {
    static PANIC_MESSAGE: RefCell<Option<String>> = const { RefCell::new(None) };
    static IN_CASE: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Keep panics of fuzzed inputs quiet (their message is reported with the input) but print
/// every other panic, the test's own verdict included, as usual.
fn quiet_panics() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let default = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if IN_CASE.with(|c| c.get()) {
                let message = format!("{info}");
                PANIC_MESSAGE.with(|m| *m.borrow_mut() = Some(message));
            } else {
                default(info);
            }
        }));
    });
}

/// Run `run` on `iterations()` mutated inputs of the corpus `corpus`; `run` gets the input
/// and the name of the seed it came from (which picks the reader where a format has several).
fn fuzz(target: &str, corpus_name: &str, salt: u64, run: impl Fn(&[u8], &str) + Sync) {
    quiet_panics();
    let seeds = corpus(corpus_name);
    let names: Vec<String> = seeds.iter().map(|(n, _)| n.clone()).collect();
    let bytes: Vec<Vec<u8>> = seeds.into_iter().map(|(_, b)| b).collect();
    // One worker, and the loop on it: rayon's parallel loops inside the library then run inline.
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let (iters, budget) = (iterations(), time_budget());
    let started = Instant::now();
    let (done, slowest, findings) = pool.install(|| {
        let mut rng = ChaCha8Rng::seed_from_u64(base_seed() ^ salt);
        let (mut slowest, mut findings) = (Duration::ZERO, Vec::new());
        let mut done = 0;
        for n in 0..iters {
            // Long runs say how far they are, so that a run cut short still has its figures.
            if n > 0 && n % 1_000_000 == 0 {
                println!(
                    "fuzz {target}: {n} execs in {:.1?}, slowest {slowest:.1?} CPU, {} findings so far",
                    started.elapsed(),
                    findings.len()
                );
            }
            if n % 1_000 == 0 && budget.is_some_and(|b| started.elapsed() > b) {
                break;
            }
            // The seeds themselves first, then mutants; the seed name picks the reader.
            let k = (n as usize) % bytes.len();
            let data = if (n as usize) < bytes.len() {
                bytes[k].clone()
            } else {
                mutate(&mut rng, &bytes)
            };
            // CPU time of this thread (the only one the case runs on): what the case costs,
            // whatever else the machine is doing.
            let t0 = ThreadTime::now();
            IN_CASE.with(|c| c.set(true));
            let result =
                std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| run(&data, &names[k])));
            IN_CASE.with(|c| c.set(false));
            let took = t0.elapsed();
            slowest = slowest.max(took);
            let problem = match result {
                Err(_) => Some(
                    PANIC_MESSAGE
                        .with(|m| m.borrow_mut().take())
                        .unwrap_or_else(|| "panic".into()),
                ),
                Ok(()) if took > MAX_CASE_CPU => Some(format!("took {took:?} of CPU")),
                Ok(()) => None,
            };
            if let Some(problem) = problem {
                let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("fuzz-findings");
                std::fs::create_dir_all(&dir).unwrap();
                let file = dir.join(format!("{target}-{n}.bin"));
                std::fs::write(&file, &data).unwrap();
                findings.push(format!("{}: {problem}", file.display()));
            }
            done = n + 1;
        }
        (done, slowest, findings)
    });
    println!(
        "fuzz {target}: {done} execs in {:.1?}, slowest {slowest:.1?} CPU, {} findings, seed {}",
        started.elapsed(),
        findings.len(),
        base_seed()
    );
    assert!(findings.is_empty(), "{}", findings.join("\n"));
}

fn text(data: &[u8]) -> String {
    String::from_utf8_lossy(data).into_owned()
}

/// The bytes of one seed of a corpus.
fn seed_bytes(corpus_name: &str, name: &str) -> Vec<u8> {
    corpus(corpus_name)
        .into_iter()
        .find(|(n, _)| n == name)
        .unwrap_or_else(|| panic!("no seed {name} in {corpus_name}"))
        .1
}

#[test]
fn probe_csv() {
    let specs = [
        errmap::probe::ProbeSpec {
            nominal_plane_mm: Some(5.0),
            ..Default::default()
        },
        errmap::probe::ProbeSpec {
            normal: Axis::X,
            nominal_plane_mm: Some(0.0),
            max_deviation_mm: 1e9,
            ..Default::default()
        },
    ];
    fuzz("probe_csv", "probe", 1, |data, _| {
        let Ok(table) = CsvTable::from_reader(Path::new("p.csv"), data) else {
            return;
        };
        for spec in &specs {
            let Ok(set) = errmap::probe::read_table(&table, spec) else {
                continue;
            };
            let _ = errmap::probe::reject_gross_errors(&set, 3.0);
            let Ok(surface) = Surface::new(&set.uve()) else {
                continue;
            };
            let b = surface.bounding_box();
            let step = b.width_mm().max(b.height_mm()) / 12.0;
            if let Ok(grid) = Grid::covering(&b, step) {
                for method in [Method::NaturalNeighbour, Method::SibsonC1, Method::Linear] {
                    for e in resample(&surface, method, &grid).into_iter().flatten() {
                        assert!(e.is_finite(), "{method} gave {e}");
                    }
                }
            }
        }
    });
}

#[test]
fn linear_run_csv() {
    let standards = &errmap::linear::Standard::ALL;
    fuzz("linear_run_csv", "runs", 2, |data, _| {
        let Ok(file) = errmap::linear::parse_runs(Path::new("runs.csv"), &text(data)) else {
            return;
        };
        let samples = file.samples();
        for standard in standards {
            let _ = errmap::linear::evaluate(&samples, *standard);
        }
    });
}

#[test]
fn temperature_log_and_sensor_table() {
    use errmap::thermal::sensors::{SensorTable, TemperatureLog};
    // The fixed half of each pair, read once: a fuzzed sensor table reads the seed log, a
    // fuzzed log is read with the seed sensor table.
    let (sensors_path, log_path) = (Path::new("sensors.csv"), Path::new("log.csv"));
    let seed_table =
        CsvTable::from_reader(sensors_path, &seed_bytes("templog", "sensors.csv")[..]).unwrap();
    let seed_sensors = SensorTable::from_csv(&seed_table).unwrap();
    let seed_log = CsvTable::from_reader(log_path, &seed_bytes("templog", "log.csv")[..]).unwrap();
    fuzz(
        "temperature_log_and_sensor_table",
        "templog",
        3,
        |data, seed| {
            if seed == "sensors.csv" {
                let Ok(table) = CsvTable::from_reader(sensors_path, data) else {
                    return;
                };
                let Ok(sensors) = SensorTable::from_csv(&table) else {
                    return;
                };
                if let Ok(log) = TemperatureLog::from_csv(&seed_log, &sensors) {
                    let _ = log.process(&sensors);
                }
            } else {
                let Ok(table) = CsvTable::from_reader(log_path, data) else {
                    return;
                };
                if let Ok(log) = TemperatureLog::from_csv(&table, &seed_sensors) {
                    let _ = log.process(&seed_sensors);
                }
            }
        },
    );
}

/// A small smooth map over ±1000 mm for compensating fuzzed programs: measured within ±500 mm
/// (so the domain edge splits moves), with its probed surface at z 0 … 5 mm when `surface`.
struct Tilt {
    surface: bool,
}

impl ErrorField for Tilt {
    fn normal(&self) -> Axis {
        Axis::Z
    }
    fn error_mm(&self, u_mm: f64, v_mm: f64) -> Option<f64> {
        (u_mm.abs() <= 1000.0 && v_mm.abs() <= 1000.0).then_some(0.01 + 1e-5 * u_mm - 2e-5 * v_mm)
    }
    fn measured(&self, u_mm: f64, v_mm: f64, margin_mm: f64) -> Option<bool> {
        Some(u_mm.abs() <= 500.0 + margin_mm && v_mm.abs() <= 500.0 + margin_mm)
    }
    fn surface_mm(&self) -> Option<(f64, f64)> {
        self.surface.then_some((0.0, 5.0))
    }
}

/// Three ways to compensate each program: (1) the dialect given, mm, everywhere, Fanuc
/// decimal-less numbers as IS-B increments; (2) the dialect detected, units and Fanuc numbers
/// unknown (refused where they matter), the zone around the map's probed surface; (3) as (1)
/// with every opt-in of real programs: `--expand`, `--compensate-holes`,
/// `--same-part-per-offset`, `--power-on-motion g1`. Segments up to 25 mm keep the output
/// short; arcs still split at the chord tolerance.
fn toolpath_cases(
    dialect: Option<errmap::toolpath::Dialect>,
) -> [(Tilt, errmap::toolpath::CompensationSettings); 3] {
    use errmap::toolpath::{CompensationSettings, FanucNumbers, PowerOnMotion, Units};
    let base = CompensationSettings {
        max_segment: 25.0,
        ..CompensationSettings::default()
    };
    [
        (
            Tilt { surface: false },
            CompensationSettings {
                everywhere: true,
                dialect,
                units: Some(Units::Mm),
                fanuc_numbers: Some(FanucNumbers::IsB),
                ..base
            },
        ),
        (Tilt { surface: true }, base),
        (
            Tilt { surface: false },
            CompensationSettings {
                everywhere: true,
                dialect,
                units: Some(Units::Mm),
                fanuc_numbers: Some(FanucNumbers::IsB),
                expand: true,
                compensate_holes: true,
                same_part_per_offset: true,
                power_on_motion: Some(PowerOnMotion::Linear),
                ..base
            },
        ),
    ]
}

/// Compensated programs stop at 8 MB (`--max-output-mb 8`; inputs are at most 64 KB), so that a
/// fuzzed program of many long arcs is refused at the line where it outgrows that, as a user's
/// would be at the default 1000 MB. (No other target writes output.)
fn limit_toolpath_output() {
    errmap::io::safety::set_max_output_mb(8);
}

/// G-code of one dialect: the lexer, then compensation both ways of [`toolpath_cases`].
fn fuzz_gcode(target: &str, corpus_name: &str, salt: u64, dialect: errmap::toolpath::Dialect) {
    let cases = toolpath_cases(Some(dialect));
    limit_toolpath_output();
    fuzz(target, corpus_name, salt, |data, _| {
        let program = text(data);
        let _ = errmap::toolpath::lexer::lex(&program);
        for (field, settings) in &cases {
            let _ =
                errmap::toolpath::compensate_gcode(&program, Path::new("p.nc"), field, settings);
        }
    });
}

#[test]
fn gcode_linuxcnc() {
    fuzz_gcode(
        "gcode_linuxcnc",
        "gcode-linuxcnc",
        4,
        errmap::toolpath::Dialect::Linuxcnc,
    );
}

#[test]
fn gcode_fanuc() {
    fuzz_gcode(
        "gcode_fanuc",
        "gcode-fanuc",
        7,
        errmap::toolpath::Dialect::Fanuc,
    );
}

#[test]
fn gcode_sinumerik() {
    fuzz_gcode(
        "gcode_sinumerik",
        "gcode-sinumerik",
        8,
        errmap::toolpath::Dialect::Sinumerik,
    );
}

#[test]
fn gcode_heidenhain() {
    fuzz_gcode(
        "gcode_heidenhain",
        "gcode-heidenhain",
        9,
        errmap::toolpath::Dialect::Heidenhain,
    );
}

#[test]
fn toolpath_csv() {
    let cases = toolpath_cases(None);
    limit_toolpath_output();
    fuzz("toolpath_csv", "toolpath-csv", 10, |data, _| {
        let path = text(data);
        for (field, settings) in &cases {
            let _ = errmap::toolpath::compensate_csv(&path, Path::new("p.csv"), field, settings);
        }
    });
}

#[test]
fn job_toml() {
    fuzz("job_toml", "job", 5, |data, _| {
        let _ = errmap::batch::Job::parse(Path::new("job.toml"), &text(data));
    });
}

#[test]
fn controller_tables() {
    // The tables are read from files (a Sinumerik table is two), so each case writes one small
    // file, in memory where the system has /dev/shm. Two folders hold the fixed Sinumerik
    // half: a fuzzed LEC file reads the seed CEC file beside it, and a fuzzed CEC file is read
    // through the seed LEC file.
    let scratch = match tempfile::tempdir_in("/dev/shm") {
        Ok(dir) => dir,
        Err(_) => tempfile::tempdir().unwrap(),
    };
    let (main_dir, cec_dir) = (scratch.path().join("main"), scratch.path().join("cec"));
    for dir in [&main_dir, &cec_dir] {
        std::fs::create_dir(dir).unwrap();
    }
    std::fs::write(
        main_dir.join("x_lec_cec.ini"),
        seed_bytes("tables", "x_lec_cec.ini"),
    )
    .unwrap();
    std::fs::write(cec_dir.join("x_lec.ini"), seed_bytes("tables", "x_lec.ini")).unwrap();
    let names: Vec<String> = corpus("tables").into_iter().map(|(n, _)| n).collect();
    let paths: std::collections::HashMap<String, (PathBuf, PathBuf)> = names
        .into_iter()
        .map(|name| {
            let paths = if name == "x_lec_cec.ini" {
                (cec_dir.join(&name), cec_dir.join("x_lec.ini"))
            } else {
                (main_dir.join(&name), main_dir.join(&name))
            };
            (name, paths)
        })
        .collect();
    let opts = errmap::linear::TableOptions::default();
    fuzz("controller_tables", "tables", 6, |data, seed| {
        let (write_to, read_from) = &paths[seed];
        std::fs::write(write_to, data).unwrap();
        let _ = errmap::linear::read_table(read_from, None, &opts);
    });
}

// ---- Findings, kept as regressions (their inputs are in the seed corpus too) ----------------

#[test]
fn sinumerik_frame_word_starting_with_a_non_ascii_letter_is_refused_not_a_panic() {
    // Found by `gcode_sinumerik`: `TRANS éX10` split the word inside its first character.
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/fuzz-corpus/gcode-sinumerik/trans-non-ascii.mpf"),
    )
    .unwrap();
    for (field, settings) in &toolpath_cases(Some(errmap::toolpath::Dialect::Sinumerik)) {
        let err = errmap::toolpath::compensate_gcode(&text, Path::new("t.mpf"), field, settings)
            .expect_err("a frame with a non-axis word must be refused");
        let msg = err.to_string();
        assert!(
            msg.contains("t.mpf:3") && msg.contains("X, Y and Z"),
            "{msg}"
        );
    }
}
