//! Controller limits at and just beyond each edge (accepted, then refused with exit 2 and a message naming the entry, the limit and what to do), tables that cover the whole travel, and the `--columns` import of instrument exports, on the real binary.

mod common;

use common::{errmap, json, ok};
use std::path::{Path, PathBuf};

fn golden(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/golden")
        .join(name)
}

fn runs_small() -> String {
    golden("linear/runs_small.csv")
        .to_str()
        .unwrap()
        .to_string()
}

/// `linear table` of `runs` with `flags`; returns (exit code, stderr).
fn linear_table(dir: &Path, runs: &str, flags: &[&str]) -> (i32, String) {
    let mut args = vec!["linear", "table", runs];
    args.extend_from_slice(flags);
    let run = errmap(dir, &args);
    (run.code, run.stderr.clone())
}

fn lines(dir: &Path, name: &str) -> Vec<String> {
    std::fs::read_to_string(dir.join(name))
        .unwrap()
        .lines()
        .map(str::to_string)
        .collect()
}

#[track_caller]
fn refused(result: (i32, String), needles: &[&str]) {
    assert_eq!(result.0, 2, "expected exit 2: {}", result.1);
    for n in needles {
        assert!(result.1.contains(n), "missing '{n}' in: {}", result.1);
    }
}

// The travel of runs_small.csv is 0 ... 200 mm: a spacing s gives ceil(200 / s) + 1 points.

#[test]
fn linuxcnc_takes_256_lines_and_refuses_257() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let runs = runs_small();
    // 200 / 0.785 = 254.8 → 255 intervals → 256 lines.
    let r = linear_table(
        d,
        &runs,
        &["--format", "linuxcnc", "--spacing", "0.785", "-o", "a.comp"],
    );
    assert_eq!(r.0, 0, "{}", r.1);
    assert_eq!(lines(d, "a.comp").len(), 256);
    // 200 / 0.782 = 255.8 → 257 lines.
    refused(
        linear_table(
            d,
            &runs,
            &["--format", "linuxcnc", "--spacing", "0.782", "-o", "b.comp"],
        ),
        // The hint is a spacing that fits (0.782 · 256 / 255 rounded up): 200 / 0.7851 → 256 lines.
        &["257 points", "at most 256", "spacing of at least 0.7851 mm"],
    );
    assert!(!d.join("b.comp").exists());
}

#[test]
fn heidenhain_takes_256_entries_refuses_257_and_an_unrepresentable_spacing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let runs = runs_small();
    let r = linear_table(
        d,
        &runs,
        &[
            "--format",
            "heidenhain",
            "--spacing",
            "0.785",
            "-o",
            "a.com",
        ],
    );
    assert_eq!(r.0, 0, "{}", r.1);
    // BEGIN, header, 256 rows, [END]; and the .CMA that assigns A.COM to the X axis.
    assert_eq!(lines(d, "a.com").len(), 259);
    assert_eq!(
        lines(d, "a.cma")[2].split_whitespace().collect::<Vec<_>>(),
        ["0", "A.COM", "*"]
    );
    refused(
        linear_table(
            d,
            &runs,
            &[
                "--format",
                "heidenhain",
                "--spacing",
                "0.782",
                "-o",
                "b.com",
            ],
        ),
        &["257 entries", "at most 256", "(.COM)"],
    );
    // AXISPOS has 4 decimals: 1.00005 mm would not be equally spaced in the file.
    refused(
        linear_table(
            d,
            &runs,
            &[
                "--format",
                "heidenhain",
                "--spacing",
                "1.00005",
                "-o",
                "c.com",
            ],
        ),
        &["spacing 1.00005 mm is not a multiple of 0.0001 mm"],
    );
}

#[test]
fn a_spacing_that_does_not_divide_the_travel_still_covers_it_and_says_so() {
    // 200 mm at 33 mm: points 0, 33, …, 198 would stop short of the last target; the table
    // runs to 231 mm with the errors at 200 mm (e↑ = 10 µm, e↓ = 6 µm) held, as a note says.
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let r = linear_table(
        d,
        &runs_small(),
        &["--format", "heidenhain", "--spacing", "33", "-o", "x.com"],
    );
    assert_eq!(r.0, 0, "{}", r.1);
    assert!(r.1.contains("the table runs to 231.0000 mm"), "{}", r.1);
    let rows = lines(d, "x.com");
    let last: Vec<&str> = rows[rows.len() - 2].split_whitespace().collect();
    assert_eq!(last, ["7", "+231", "+0.01", "+0.006"]);
    // 198 mm lies between 100 (6, 3 µm) and 200 mm (10, 6 µm): 6 + 0.98·4 = 9.92, 3 + 0.98·3 = 5.94.
    let at_198: Vec<&str> = rows[rows.len() - 3].split_whitespace().collect();
    assert_eq!(at_198, ["6", "+198", "+0.00992", "+0.00594"]);
}

#[test]
fn sinumerik_takes_its_configured_points_and_refuses_one_more() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let runs = runs_small();
    // 200 / 1.006 = 198.8 → 200 points: the default limit of 200.
    let r = linear_table(
        d,
        &runs,
        &["--format", "sinumerik", "--spacing", "1.006", "-o", "a.ini"],
    );
    assert_eq!(r.0, 0, "{}", r.1);
    let a = std::fs::read_to_string(d.join("a.ini")).unwrap();
    assert!(a.contains("$AA_ENC_COMP[0,199,AX1]=") && !a.contains("$AA_ENC_COMP[0,200,"));
    // 200 / 1.002 = 199.6 → 201 points.
    refused(
        linear_table(
            d,
            &runs,
            &["--format", "sinumerik", "--spacing", "1.002", "-o", "b.ini"],
        ),
        &[
            "201 interpolation points",
            "holds 200",
            "MD38000",
            "--sinumerik-max-points",
        ],
    );
    let r = linear_table(
        d,
        &runs,
        &[
            "--format",
            "sinumerik",
            "--spacing",
            "1.002",
            "--sinumerik-max-points",
            "201",
            "-o",
            "c.ini",
        ],
    );
    assert_eq!(r.0, 0, "{}", r.1);
    // The CEC tables name their axes in the (AXn) form, and the LEC is zero at the reference.
    let cec = std::fs::read_to_string(d.join("c_cec.ini")).unwrap();
    assert!(
        cec.contains("$AN_CEC_INPUT_AXIS[0]=(AX1)") && cec.contains("$AN_CEC_OUTPUT_AXIS[1]=(AX1)")
    );
    let r = linear_table(
        d,
        &runs,
        &[
            "--format",
            "sinumerik",
            "--spacing",
            "50",
            "--reference-mm",
            "100",
            "-o",
            "r.ini",
        ],
    );
    assert_eq!(r.0, 0, "{}", r.1);
    // Mean 0.5, 2.5, 4.5, 6.25, 8 µm less 4.5 µm at 100 mm.
    let r = std::fs::read_to_string(d.join("r.ini")).unwrap();
    for (i, v) in ["-0.004000", "-0.002000", "0.000000", "0.001750", "0.003500"]
        .iter()
        .enumerate()
    {
        assert!(
            r.contains(&format!("$AA_ENC_COMP[0,{i},AX1]={v}\n")),
            "{i}: {r}"
        );
    }
}

#[test]
fn fanuc_point_numbers_follow_the_series() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let runs = runs_small();
    // 0.392 mm: 200 / 0.392 = 510.2 → 512 points per direction, numbers 0 … 1023 (0i-F's last).
    let r = linear_table(
        d,
        &runs,
        &["--format", "fanuc", "--spacing", "0.392", "-o", "a.txt"],
    );
    assert_eq!(r.0, 0, "{}", r.1);
    let a = std::fs::read_to_string(d.join("a.txt")).unwrap();
    assert!(a.contains("\nN11023P") && !a.contains("\nN11024P"));
    // 0.391 mm: 513 points per direction, numbers up to 1025.
    refused(
        linear_table(
            d,
            &runs,
            &["--format", "fanuc", "--spacing", "0.391", "-o", "b.txt"],
        ),
        &[
            "1026 compensation points",
            "0 ... 1025",
            "series 0i-F's 0 ... 1023",
        ],
    );
    // The 30i-B numbers points 0 … 1535.
    let r = linear_table(
        d,
        &runs,
        &[
            "--format",
            "fanuc",
            "--spacing",
            "0.391",
            "--fanuc-series",
            "30i-B",
            "-o",
            "c.txt",
        ],
    );
    assert_eq!(r.0, 0, "{}", r.1);
}

/// Runs with e = 0, k, 2k µm at 0, 100, 200 mm in both directions.
fn ramp(dir: &Path, k_um: i32) -> String {
    let path = dir.join(format!("ramp{k_um}.csv"));
    let mut text = String::from("run,direction,target_mm,deviation_um\n");
    for (dir_sym, order) in [("+", [0, 1, 2]), ("-", [2, 1, 0])] {
        for i in order {
            text.push_str(&format!("1,{dir_sym},{},{}\n", 100 * i, k_um * i));
        }
    }
    std::fs::write(&path, text).unwrap();
    path.to_str().unwrap().to_string()
}

#[test]
fn fanuc_values_outside_the_series_range_are_refused_with_the_entry_and_the_cure() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let fanuc = |runs: &str, extra: &[&str], out: &str| {
        let mut flags = vec!["--format", "fanuc", "--spacing", "100", "-o", out];
        flags.extend_from_slice(extra);
        linear_table(d, runs, &flags)
    };
    // Increments −e per 100 mm interval: −128 is the lowest value a point takes.
    let r = fanuc(&ramp(d, 128), &[], "a.txt");
    assert_eq!(r.0, 0, "{}", r.1);
    let a = std::fs::read_to_string(d.join("a.txt")).unwrap();
    assert!(a.contains("N10001P-128\nN10002P-128\n"), "{a}");
    refused(
        fanuc(&ramp(d, 129), &[], "b.txt"),
        &[
            "N10001 (forward, 100.0000 mm): increment -129",
            "outside -128 ... 127 of series 0i-F",
            "--fanuc-magnification 2",
        ],
    );
    // Upper edge: +127 taken, +128 refused.
    assert_eq!(fanuc(&ramp(d, -127), &[], "c.txt").0, 0);
    refused(
        fanuc(&ramp(d, -128), &[], "d.txt"),
        &["increment 128", "outside -128 ... 127"],
    );
    // Magnification 2 (parameter 3623): round(−129/2) = −65, round(−258/2) = −129 → −65, −64.
    let r = fanuc(&ramp(d, 129), &["--fanuc-magnification", "2"], "e.txt");
    assert_eq!(r.0, 0, "{}", r.1);
    let e = std::fs::read_to_string(d.join("e.txt")).unwrap();
    assert!(
        e.contains("N3623A1P2\n") && e.contains("N10001P-65\nN10002P-64\n"),
        "{e}"
    );
    // The magnification itself: 1 … 100.
    assert_eq!(
        fanuc(&ramp(d, 10), &["--fanuc-magnification", "100"], "f.txt").0,
        0
    );
    refused(
        fanuc(&ramp(d, 10), &["--fanuc-magnification", "101"], "g.txt"),
        &["magnification 101 (parameter 3623) is outside 1 ... 100"],
    );
}

#[test]
fn rotary_tables_keep_the_limits_too() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let meas = golden("rotary/meas.csv");
    let meas = meas.to_str().unwrap();
    let table = |format: &str, step: &str, out: &str| {
        let run = errmap(
            d,
            &[
                "rotary",
                "table",
                meas,
                "--format",
                format,
                "--step-deg",
                step,
                "-o",
                out,
            ],
        );
        (run.code, run.stderr.clone())
    };
    // 360 / 1.44 = 250 steps → 251 entries; 360 / 1.40625 = 256 steps → 257 entries.
    for (format, out) in [("linuxcnc", "a.comp"), ("heidenhain", "a.com")] {
        assert_eq!(table(format, "1.44", out).0, 0);
    }
    refused(
        table("linuxcnc", "1.40625", "b.comp"),
        &["257 points", "at most 256"],
    );
    refused(
        table("heidenhain", "1.40625", "b.com"),
        &["257 entries", "at most 256"],
    );
    refused(
        table("sinumerik", "1.44", "b.ini"),
        &["251 interpolation points", "holds 200"],
    );
    // Every controller file is ASCII, byte by byte.
    for name in ["a.comp", "a.com", "a.cma"] {
        let bytes = std::fs::read(d.join(name)).unwrap();
        assert!(bytes.iter().all(|b| b.is_ascii()), "{name}");
    }
}

#[test]
fn names_that_are_not_ascii_identifiers_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    refused(
        linear_table(
            dir.path(),
            &runs_small(),
            &[
                "--format",
                "sinumerik",
                "--spacing",
                "50",
                "--axis",
                "X\u{b5}",
                "-o",
                "a.ini",
            ],
        ),
        &["is not a Sinumerik machine axis name"],
    );
}

/// The hand runs of runs_small.csv as a laser program might export them: its own column names,
/// errors in mm, the direction as Fwd/Bwd, runs not numbered, extra columns.
const EXPORT: &str = "\
Point,Target [mm],Dir,Error [mm],Air Temp [degC],Pressure [hPa]
1,0,Fwd,0.002,20.1,1013.2
2,100,Fwd,0.005,20.1,1013.2
3,200,Fwd,0.010,20.1,1013.2
4,200,Bwd,0.006,20.1,1013.2
5,100,Bwd,0.002,20.1,1013.2
6,0,Bwd,-0.001,20.1,1013.2
7,0,Fwd,0.002,20.1,1013.2
8,100,Fwd,0.007,20.1,1013.2
9,200,Fwd,0.010,20.1,1013.2
10,200,Bwd,0.006,20.1,1013.2
11,100,Bwd,0.004,20.1,1013.2
12,0,Bwd,-0.001,20.1,1013.2
";

#[test]
fn a_column_mapping_reads_an_export_as_the_run_file_it_holds() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("export.csv"), EXPORT).unwrap();
    let runs = runs_small();
    let native = json(&ok(
        d,
        &[
            "linear",
            "analyze",
            &runs,
            "--standard",
            "iso230-2:2014",
            "--json",
        ],
    ));
    for map in [
        "target=Target [mm],deviation=Error [mm],direction=Dir,pressure=Pressure [hPa]",
        "target=2,deviation=4[mm],direction=3",
        "target=Target [mm],deviation=Error [mm],direction=Dir,air_temp=Air Temp [degC]",
    ] {
        let mapped = json(&ok(
            d,
            &[
                "linear",
                "analyze",
                "export.csv",
                "--standard",
                "iso230-2:2014",
                "--json",
                "--columns",
                map,
            ],
        ));
        assert_eq!(mapped["axis"], native["axis"], "{map}");
        assert_eq!(mapped["targets"], native["targets"], "{map}");
    }
    // A table from the export equals the golden table from the run file.
    ok(
        d,
        &[
            "linear",
            "table",
            "export.csv",
            "--format",
            "csv",
            "--spacing",
            "50",
            "-o",
            "x.csv",
            "-q",
            "--columns",
            "target=Target [mm],deviation=Error [mm],direction=Dir",
        ],
    );
    assert_eq!(
        std::fs::read_to_string(d.join("x.csv")).unwrap(),
        std::fs::read_to_string(golden("linear/x.csv")).unwrap()
    );
}

#[test]
fn a_mapping_that_misses_the_file_is_refused_at_the_file_line_and_column() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("export.csv"), EXPORT).unwrap();
    let analyze = |map: &str| {
        let run = errmap(
            d,
            &[
                "linear",
                "analyze",
                "export.csv",
                "--standard",
                "iso230-2:2014",
                "--columns",
                map,
            ],
        );
        (run.code, run.stderr.clone())
    };
    refused(
        analyze("target=Target [mm],deviation=Err,direction=Dir"),
        &[
            "export.csv:1, column Err",
            "the mapped column 'Err' for 'deviation' is not in the file",
        ],
    );
    refused(
        analyze("target=Target [mm],deviation=9,direction=Dir"),
        &["export.csv:1, column #9", "header has 6 columns"],
    );
    refused(
        analyze("target=Target [mm],deviation=Error[furlong],direction=Dir"),
        &["'furlong' in 'Error[furlong]' is not a unit"],
    );
    refused(
        analyze("target=Target [mm],direction=Dir"),
        &["exactly one of 'actual'"],
    );
    // A bad value is named at the export's own line and column.
    std::fs::write(d.join("export.csv"), EXPORT.replace("0.005,", "0.0o5,")).unwrap();
    refused(
        analyze("target=Target [mm],deviation=Error [mm],direction=Dir"),
        &["export.csv:3, column Error [mm]", "'0.0o5' is not a number"],
    );
}
