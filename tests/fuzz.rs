//! Seeded mutation fuzzing of every input format under `cargo test`: probe CSV, linear run CSV, temperature log and sensor table, G-code, job TOML and controller tables. No input may panic or take more than a second.
//!
//! Each target starts from its seed corpus in `tests/fuzz-corpus/<target>/` and applies a
//! seeded series of byte mutations (bit flips, inserts, deletes, duplicated ranges, spliced
//! seeds, tokens the formats care about: separators, NaN, 1e308, G-code words …). A normal
//! `cargo test` runs 2,000 cases per target; a long run sets the count and the seed:
//!
//! ```text
//! ERRMAP_FUZZ_ITERS=1000000 ERRMAP_FUZZ_SEED=7 cargo test --release --test fuzz -- --nocapture
//! ```
//!
//! A panicking input is written to `target/fuzz-findings/<target>-<n>.bin` and fails the test.

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

fn base_seed() -> u64 {
    std::env::var("ERRMAP_FUZZ_SEED")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1)
}

thread_local! {
    static PANIC_MESSAGE: RefCell<Option<String>> = const { RefCell::new(None) };
}

/// Keep panics of fuzzed inputs quiet (their message is reported with the input) but still
/// print any other panic.
fn quiet_panics() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        std::panic::set_hook(Box::new(|info| {
            let message = format!("{info}");
            PANIC_MESSAGE.with(|m| *m.borrow_mut() = Some(message));
        }));
    });
}

/// Run `run` on `iterations()` mutated inputs of the target's corpus. `run` gets the input,
/// the name of the seed it came from and a scratch folder.
fn fuzz(target: &str, salt: u64, run: impl Fn(&[u8], &str, &Path)) {
    quiet_panics();
    let seeds = corpus(target);
    let names: Vec<String> = seeds.iter().map(|(n, _)| n.clone()).collect();
    let bytes: Vec<Vec<u8>> = seeds.into_iter().map(|(_, b)| b).collect();
    let scratch = tempfile::tempdir().unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(base_seed() ^ salt);
    let iters = iterations();
    let (mut slowest, mut findings) = (Duration::ZERO, Vec::new());
    let started = Instant::now();
    for n in 0..iters {
        // The seeds themselves first, then mutants; the seed name picks the reader.
        let k = (n as usize) % bytes.len();
        let data = if (n as usize) < bytes.len() {
            bytes[k].clone()
        } else {
            mutate(&mut rng, &bytes)
        };
        let t0 = Instant::now();
        let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            run(&data, &names[k], scratch.path())
        }));
        let took = t0.elapsed();
        slowest = slowest.max(took);
        let problem = match result {
            Err(_) => Some(
                PANIC_MESSAGE
                    .with(|m| m.borrow_mut().take())
                    .unwrap_or_else(|| "panic".into()),
            ),
            Ok(()) if took > Duration::from_secs(1) => Some(format!("took {took:?}")),
            Ok(()) => None,
        };
        if let Some(problem) = problem {
            let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("fuzz-findings");
            std::fs::create_dir_all(&dir).unwrap();
            let file = dir.join(format!("{target}-{n}.bin"));
            std::fs::write(&file, &data).unwrap();
            findings.push(format!("{}: {problem}", file.display()));
        }
    }
    println!(
        "fuzz {target}: {iters} execs in {:.1?}, slowest {slowest:.1?}, {} findings",
        started.elapsed(),
        findings.len()
    );
    assert!(findings.is_empty(), "{}", findings.join("\n"));
}

fn text(data: &[u8]) -> String {
    String::from_utf8_lossy(data).into_owned()
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
    fuzz("probe", 1, |data, _, _| {
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
    use clap::ValueEnum;
    fuzz("runs", 2, |data, _, _| {
        let Ok(file) = errmap::linear::parse_runs(Path::new("runs.csv"), &text(data)) else {
            return;
        };
        let samples = file.samples();
        for standard in errmap::linear::Standard::value_variants() {
            let _ = errmap::linear::evaluate(&samples, *standard);
        }
    });
}

#[test]
fn temperature_log_and_sensor_table() {
    let seeds = corpus("templog");
    let sensors_seed = &seeds.iter().find(|(n, _)| n == "sensors.csv").unwrap().1;
    fuzz("templog", 3, |data, seed, dir| {
        let (sensors, log) = (dir.join("sensors.csv"), dir.join("log.csv"));
        let log_seed = &seeds.iter().find(|(n, _)| n == "log.csv").unwrap().1;
        if seed == "sensors.csv" {
            std::fs::write(&sensors, data).unwrap();
            std::fs::write(&log, log_seed).unwrap();
        } else {
            std::fs::write(&sensors, sensors_seed).unwrap();
            std::fs::write(&log, data).unwrap();
        }
        let Ok(table) = errmap::thermal::sensors::SensorTable::read(&sensors) else {
            return;
        };
        if let Ok(log) = errmap::thermal::sensors::TemperatureLog::read(&log, &table) {
            let _ = log.process(&table);
        }
    });
}

/// A small smooth map over ±1000 mm for compensating fuzzed programs.
struct Tilt;

impl ErrorField for Tilt {
    fn normal(&self) -> Axis {
        Axis::Z
    }
    fn error_mm(&self, u_mm: f64, v_mm: f64) -> Option<f64> {
        (u_mm.abs() <= 1000.0 && v_mm.abs() <= 1000.0).then_some(0.01 + 1e-5 * u_mm - 2e-5 * v_mm)
    }
}

#[test]
fn gcode() {
    let settings = errmap::toolpath::CompensationSettings::default();
    fuzz("gcode", 4, |data, _, _| {
        let program = text(data);
        let _ = errmap::toolpath::lexer::lex(&program);
        let _ = errmap::toolpath::compensate_gcode(&program, Path::new("p.ngc"), &Tilt, &settings);
        let _ = errmap::toolpath::compensate_csv(&program, Path::new("p.csv"), &Tilt, &settings);
    });
}

#[test]
fn job_toml() {
    fuzz("job", 5, |data, _, _| {
        let _ = errmap::batch::Job::parse(Path::new("job.toml"), &text(data));
    });
}

#[test]
fn controller_tables() {
    let seeds = corpus("tables");
    let cec = seeds
        .iter()
        .find(|(n, _)| n == "x_lec_cec.ini")
        .unwrap()
        .1
        .clone();
    fuzz("tables", 6, |data, seed, dir| {
        let path = dir.join(seed);
        std::fs::write(&path, data).unwrap();
        if seed == "x_lec.ini" {
            std::fs::write(dir.join("x_lec_cec.ini"), &cec).unwrap();
        }
        let opts = errmap::linear::TableOptions::default();
        let _ = errmap::linear::read_table(&path, None, &opts);
    });
}
