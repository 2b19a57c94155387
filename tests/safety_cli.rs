//! Lose nothing and overwrite nothing, through the real binary: inputs given as outputs survive byte for byte, outputs follow the umask, part names cannot escape or collide, a closed pipe exits quietly, sizes from user numbers are bounded, unit slips are refused.

mod common;

use common::{errmap, errmap_with, ok};
use std::path::Path;
use std::process::{Command, Stdio};

fn read(path: &Path) -> Vec<u8> {
    std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// A probe file on a 5 mm plane: a 6 × 5 lattice with a gentle error (µm range).
fn probe_text() -> String {
    let mut text = String::from("x_mm,y_mm,z_mm\n");
    for j in 0..5 {
        for i in 0..6 {
            let (x, y) = (i as f64 * 20.0, j as f64 * 15.0);
            let z = 5.0 + 0.001 * (x / 100.0) - 0.002 * (y / 60.0);
            text.push_str(&format!("{x},{y},{z}\n"));
        }
    }
    text
}

/// Run `args` in `dir`, require exit 2 and `file` unchanged, and return stderr.
#[track_caller]
fn refused(dir: &Path, args: &[&str], file: &str) -> String {
    let before = read(&dir.join(file));
    let run = errmap(dir, args);
    run.expect_code(2);
    assert_eq!(
        read(&dir.join(file)),
        before,
        "{file} changed\n{}",
        run.report()
    );
    assert!(
        run.stderr.contains("refusing to write") || run.stderr.contains("overwrite the input"),
        "{}",
        run.report()
    );
    run.stderr
}

#[test]
fn every_command_refuses_an_output_that_is_one_of_its_inputs() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("p.csv"), probe_text()).unwrap();
    let grid = ["grid", "p.csv", "--step", "10", "--nominal-plane", "5"];
    // The same file by another spelling, through a symlink and through a hard link.
    std::fs::create_dir(d.join("sub")).unwrap();
    std::os::unix::fs::symlink(d.join("p.csv"), d.join("link.csv")).unwrap();
    std::fs::hard_link(d.join("p.csv"), d.join("hard.csv")).unwrap();
    for out in ["p.csv", "./sub/../p.csv", "link.csv", "hard.csv"] {
        let mut args = grid.to_vec();
        args.extend(["-o", out]);
        refused(d, &args, "p.csv");
    }
    // map --out-dir . beside a probe file named like one of its outputs: nothing is written.
    std::fs::create_dir(d.join("m")).unwrap();
    std::fs::write(d.join("m/clean.csv"), probe_text()).unwrap();
    let md = d.join("m");
    refused(
        &md,
        &[
            "map",
            "clean.csv",
            "--out-dir",
            ".",
            "--epochs",
            "5",
            "--backend",
            "cpu",
        ],
        "clean.csv",
    );
    assert_eq!(
        common::listing(&md),
        vec!["clean.csv"],
        "a refused map wrote files"
    );

    // Linear: analyze --chart and table -o over the runs file.
    ok(d, &["synth", "linear", "--out-dir", "lin", "-q"]);
    let runs = "lin/runs.csv";
    let analyze = ["linear", "analyze", runs, "--standard", "vdi3441"];
    refused(d, &[&analyze[..], &["--chart", runs]].concat(), runs);
    refused(
        d,
        &[
            "linear",
            "table",
            runs,
            "--format",
            "csv",
            "--spacing",
            "20",
            "-o",
            runs,
        ],
        runs,
    );
    // Rotary: analyze --chart and table -o over the measurement.
    ok(d, &["synth", "rotary", "--out-dir", "rot", "-q"]);
    let meas = "rot/centres.csv";
    refused(d, &["rotary", "analyze", meas, "--chart", meas], meas);
    refused(
        d,
        &["rotary", "table", meas, "--format", "csv", "-o", meas],
        meas,
    );
    // Thermal: calibrate -o over the log, fit -o over a campaign file, compensate -o over the log.
    ok(d, &["synth", "thermal", "--out-dir", "th", "-q"]);
    let cal = "th/calibration.csv";
    refused(
        d,
        &[
            "thermal",
            "calibrate",
            "--sensors",
            "th/sensors.csv",
            cal,
            "-o",
            cal,
        ],
        cal,
    );
    let c1 = "th/campaign-1-coolant-off";
    let c1_runs = "th/campaign-1-coolant-off/runs.csv";
    let campaigns = [c1, "th/campaign-2-coolant-on", "th/campaign-3-coolant-off"];
    refused(
        d,
        &[&["thermal", "fit", "-o", c1_runs][..], &campaigns].concat(),
        c1_runs,
    );
    ok(
        d,
        &[
            &["thermal", "fit", "-o", "model.json", "-q"][..],
            &campaigns,
        ]
        .concat(),
    );
    let log = "th/campaign-1-coolant-off/temperatures.csv";
    refused(
        d,
        &[
            "thermal",
            "compensate",
            "--model",
            "model.json",
            log,
            "-o",
            log,
        ],
        log,
    );
    refused(
        d,
        &[
            "thermal",
            "compensate",
            "--model",
            "model.json",
            log,
            "-o",
            "model.json",
        ],
        "model.json",
    );
}

#[test]
fn batch_merge_and_compensate_refuse_their_inputs_too() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(
        d,
        &[
            "synth",
            "web-plate",
            "--out-dir",
            "wp",
            "--parts",
            "2",
            "--epochs",
            "10",
            "-q",
        ],
    );
    let wp = d.join("wp");
    // compensate -o over its program or its model. (merge writes only into its run folder and
    // reads only shard folders under it: tests/scale.rs checks what it refuses.)
    ok(
        &wp,
        &[
            "batch",
            "job.toml",
            "--backend",
            "cpu",
            "--out-dir",
            "out",
            "-q",
        ],
    );
    refused(
        &wp,
        &[
            "compensate",
            "--model",
            "out/p01/model.json",
            "finish.ngc",
            "-o",
            "finish.ngc",
        ],
        "finish.ngc",
    );
    refused(
        &wp,
        &[
            "compensate",
            "--model",
            "out/p01/model.json",
            "finish.ngc",
            "-o",
            "out/p01/model.json",
        ],
        "out/p01/model.json",
    );
}

#[test]
fn outputs_are_created_0666_less_the_umask() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("p.csv"), probe_text()).unwrap();
    let bin = env!("CARGO_BIN_EXE_errmap");
    for (umask, mode) in [
        ("022", 0o644),
        ("027", 0o640),
        ("077", 0o600),
        ("002", 0o664),
    ] {
        let out = format!("g{umask}.csv");
        let status = Command::new("sh")
            .arg("-c")
            .arg(format!(
                "umask {umask}; exec '{bin}' grid p.csv --step 10 --nominal-plane 5 -q -o {out}"
            ))
            .current_dir(d)
            .status()
            .unwrap();
        assert!(status.success(), "umask {umask}");
        let got = std::fs::metadata(d.join(&out))
            .unwrap()
            .permissions()
            .mode()
            & 0o777;
        assert_eq!(got, mode, "umask {umask}: mode {got:o}");
    }
}

#[test]
fn part_names_stay_in_the_output_folder_and_never_collide() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(
        d,
        &[
            "synth",
            "web-plate",
            "--out-dir",
            "wp",
            "--parts",
            "3",
            "--epochs",
            "10",
            "-q",
        ],
    );
    let wp = d.join("wp");
    let p = |n: &str| std::fs::read(wp.join("probes").join(n)).unwrap();
    let (a, b, c) = (p("p01.csv"), p("p02.csv"), p("p03.csv"));
    for sub in ["a", "b", "c"] {
        std::fs::create_dir_all(wp.join("in").join(sub)).unwrap();
    }
    std::fs::write(wp.join("in/a/p1.csv"), &a).unwrap();
    std::fs::write(wp.join("in/b/p1.csv"), &b).unwrap();
    std::fs::write(wp.join("in/c/p1-1.csv"), &c).unwrap();
    std::fs::write(wp.join("in/c/...csv"), &a).unwrap();
    std::fs::write(wp.join("in/c/family.csv"), &b).unwrap();
    let job = std::fs::read_to_string(wp.join("job.toml"))
        .unwrap()
        .replace("probes = \"probes/*.csv\"", "probes = \"in/*/*.csv\"");
    std::fs::write(wp.join("job.toml"), job).unwrap();
    let run = errmap(
        &wp,
        &[
            "batch",
            "job.toml",
            "--backend",
            "cpu",
            "--out-dir",
            "out/x",
        ],
    );
    run.expect_code(0);
    for note in [
        "'p1' is written as 'p1-2'",
        "'..' is written as 'part'",
        "'family' is written as 'family-part'",
    ] {
        assert!(run.stderr.contains(note), "{note}\n{}", run.report());
    }
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(wp.join("out/x/summary.json")).unwrap())
            .unwrap();
    let mut dirs: Vec<String> = summary["parts"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["part"].as_str().unwrap().to_string())
        .collect();
    dirs.sort();
    assert_eq!(dirs, ["family-part", "p1-1", "p1-2", "p1-3", "part"]);
    for name in &dirs {
        assert!(
            wp.join("out/x").join(name).join("map.csv").is_file(),
            "{name}"
        );
    }
    // The family folder holds the family network, not a part's.
    let model: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(wp.join("out/x/family/model.json")).unwrap())
            .unwrap();
    assert_eq!(model["name"], "family");
    // Nothing was written beside out/x.
    assert_eq!(common::listing(&wp.join("out")), {
        let mut l: Vec<String> = common::listing(&wp.join("out/x"))
            .into_iter()
            .map(|p| format!("x/{p}"))
            .collect();
        l.push("x/".into());
        l.sort();
        l
    });
}

/// Run with stdout a pipe whose reading end is already closed: every write fails with EPIPE.
#[track_caller]
fn closed_pipe(dir: &Path, args: &[&str]) {
    closed_pipe_code(dir, args, 0)
}

/// [`closed_pipe`], requiring exit `code`.
#[track_caller]
fn closed_pipe_code(dir: &Path, args: &[&str], code: i32) {
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    let out = common::command()
        .args(args)
        .current_dir(dir)
        .stdout(Stdio::from(writer))
        .stderr(Stdio::piped())
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(
        out.status.code(),
        Some(code),
        "errmap {}: {stderr}",
        args.join(" ")
    );
    assert!(
        !stderr.contains("panicked"),
        "errmap {}: {stderr}",
        args.join(" ")
    );
}

#[test]
fn a_closed_pipe_ends_every_printing_command_quietly() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(
        d.join("setup.toml"),
        "length_mm = 500.0\n[thermal]\nexpansion_ppm_per_k = 10.0\ntemp_uncertainty_c = 0.1\n",
    )
    .unwrap();
    ok(d, &["synth", "linear", "--out-dir", "lin", "-q"]);
    let air = [
        "linear",
        "air-index",
        "--temp-c",
        "20",
        "--pressure-kpa",
        "101.325",
        "--humidity-pct",
        "50",
        "--wavelength-nm",
        "633",
    ];
    closed_pipe(d, &air);
    closed_pipe(d, &["linear", "budget", "setup.toml"]);
    closed_pipe(
        d,
        &[
            "linear",
            "analyze",
            "lin/runs.csv",
            "--standard",
            "vdi3441",
            "--json",
        ],
    );
    closed_pipe(
        d,
        &["linear", "analyze", "lin/runs.csv", "--standard", "vdi3441"],
    );
    closed_pipe(d, &["gpu-info"]);
    std::fs::write(d.join("p.csv"), probe_text()).unwrap();
    let map = [
        "map",
        "p.csv",
        "--out-dir",
        "m",
        "--nominal-plane",
        "5",
        "--epochs",
        "5",
    ];
    closed_pipe(d, &[&map[..], &["--backend", "cpu"]].concat());
    ok(
        d,
        &[
            "synth",
            "web-plate",
            "--out-dir",
            "wp",
            "--parts",
            "2",
            "--epochs",
            "10",
            "-q",
        ],
    );
    closed_pipe(
        &d.join("wp"),
        &["batch", "job.toml", "--backend", "cpu", "-q"],
    );
    closed_pipe(
        &d.join("wp"),
        &[
            "compensate",
            "--model",
            "out/web-plate/p01/model.json",
            "finish.ngc",
            "-o",
            "c.ngc",
            "--json",
        ],
    );
}

#[test]
fn sizes_that_follow_from_user_numbers_are_bounded() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let run = errmap(
        d,
        &["synth", "rotary", "--out-dir", "r", "--step-deg", "1e-300"],
    );
    run.expect_code(2);
    assert!(run.stderr.contains("smallest step"), "{}", run.report());
    assert!(!d.join("r").exists());
    ok(d, &["synth", "linear", "--out-dir", "lin", "-q"]);
    let run = errmap(
        d,
        &[
            "linear",
            "table",
            "lin/runs.csv",
            "--format",
            "csv",
            "--spacing",
            "1e-300",
            "-o",
            "t.csv",
        ],
    );
    run.expect_code(2);
    assert!(
        run.stderr.contains("more than 100000") && run.stderr.contains("coarser"),
        "{}",
        run.report()
    );
    // --max-segment below its documented minimum of 0.01 mm.
    std::fs::write(d.join("p.csv"), probe_text()).unwrap();
    ok(
        d,
        &[
            "map",
            "p.csv",
            "--out-dir",
            "m",
            "--nominal-plane",
            "5",
            "--epochs",
            "5",
            "--backend",
            "cpu",
            "-q",
        ],
    );
    std::fs::write(d.join("a.ngc"), "G21 G90\nG1 X0 Y0 Z5 F100\nG1 X100 Y60\n").unwrap();
    let run = errmap(
        d,
        &[
            "compensate",
            "--model",
            "m/model.json",
            "a.ngc",
            "-o",
            "b.ngc",
            "--max-segment",
            "0.001",
        ],
    );
    run.expect_code(2);
    assert!(run.stderr.contains("at least 0.01"), "{}", run.report());
    assert!(!d.join("b.ngc").exists());
    // An output past --max-output-mb stops with exit 2 and leaves no file, temporary or not.
    let run = errmap(
        d,
        &[
            "grid",
            "p.csv",
            "--step",
            "0.05",
            "--nominal-plane",
            "5",
            "-o",
            "g.csv",
            "--max-output-mb",
            "1",
        ],
    );
    run.expect_code(2);
    assert!(
        run.stderr.contains("output limit of 1 MB"),
        "{}",
        run.report()
    );
    assert!(
        common::files(d).iter().all(|p| {
            let name = p.file_name().unwrap().to_string_lossy();
            name != "g.csv" && !name.starts_with(".errmap-")
        }),
        "{:?}",
        common::listing(d)
    );
    ok(
        d,
        &[
            "grid",
            "p.csv",
            "--step",
            "0.5",
            "--nominal-plane",
            "5",
            "-o",
            "g.csv",
            "-q",
        ],
    );
}

#[test]
fn unit_slips_are_refused_with_the_likely_cause() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // z in µm written as mm on a 5 mm plane: 5000.x instead of 5.000x.
    let um = probe_text()
        .lines()
        .enumerate()
        .map(|(i, l)| {
            if i == 0 {
                l.to_string()
            } else {
                let f: Vec<f64> = l.split(',').map(|x| x.parse().unwrap()).collect();
                format!("{},{},{}", f[0], f[1], f[2] * 1000.0)
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    std::fs::write(d.join("um.csv"), um).unwrap();
    let run = errmap(
        d,
        &[
            "grid",
            "um.csv",
            "--step",
            "10",
            "--nominal-plane",
            "5",
            "-o",
            "g.csv",
        ],
    );
    run.expect_code(2);
    assert!(
        run.stderr.contains("um.csv:2, column z_mm") && run.stderr.contains("µm written as mm"),
        "{}",
        run.report()
    );
    // ±15 mm deviations: beyond 1 mm, no unit explains them.
    let far = "x_mm,y_mm,z_mm\n0,0,20\n10,0,-10\n0,10,5\n10,10,5\n";
    std::fs::write(d.join("far.csv"), far).unwrap();
    let run = errmap(
        d,
        &[
            "grid",
            "far.csv",
            "--step",
            "1",
            "--nominal-plane",
            "5",
            "-o",
            "g.csv",
        ],
    );
    run.expect_code(2);
    assert!(
        run.stderr.contains("far.csv:2") && run.stderr.contains("plausibility bound of 1 mm"),
        "{}",
        run.report()
    );
    let run = errmap(
        d,
        &[
            "map",
            "far.csv",
            "--out-dir",
            "m",
            "--nominal-plane",
            "5",
            "--epochs",
            "5",
            "--backend",
            "cpu",
        ],
    );
    run.expect_code(2);
    assert!(
        run.stderr.contains("far.csv:2") && run.stderr.contains("plausibility bound of 1 mm"),
        "{}",
        run.report()
    );
    assert!(!d.join("g.csv").exists());
    // The bound is a setting: a part that really is 15 mm off can be mapped on purpose.
    ok(
        d,
        &[
            "grid",
            "far.csv",
            "--step",
            "1",
            "--nominal-plane",
            "5",
            "-o",
            "g.csv",
            "--max-deviation-mm",
            "20",
            "-q",
        ],
    );
    // The job key does the same for a batch: max_deviation_mm = 0 is refused at its line.
    std::fs::write(
        d.join("job.toml"),
        "family = \"f\"\nprobes = \"*.csv\"\nmax_deviation_mm = 0\n",
    )
    .unwrap();
    let run = errmap(d, &["batch", "job.toml"]);
    run.expect_code(2);
    assert!(
        run.stderr.contains("job.toml:3, column 20"),
        "{}",
        run.report()
    );
}

#[test]
fn a_single_part_failure_keeps_its_kind_and_exit_code() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("bad.csv"), "x_mm,y_mm,z_mm\n0,0,5\n1,0,abc\n").unwrap();
    let run = errmap_with(
        d,
        &[
            "map",
            "bad.csv",
            "--out-dir",
            "m",
            "--nominal-plane",
            "5",
            "--backend",
            "cpu",
        ],
        |_| {},
    );
    run.expect_code(2);
    assert!(
        run.stderr.contains("bad.csv:3, column z_mm"),
        "{}",
        run.report()
    );
}
