//! Injected file faults through the real binary: for every command that reads or writes, a missing input, a folder given as a file, a file that cannot be opened and an output that cannot be created each end with the documented exit code and a message that names the path.
//!
//! Exit codes (README): 2 when an input cannot be read, 3 when an output cannot be written.
//! Tests may run as root, where permissions block nothing, so the faults are ones root meets
//! too: a symbolic link that points at itself (ELOOP on open), a folder where a file is
//! expected, an output below a regular file (ENOTDIR), an output that is an existing folder,
//! and an output cut short by `--max-output-mb`. Where the tests do not run as root, a file
//! with no read permission is added.

mod common;

use common::{errmap, ok};
use std::path::Path;

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

const C1: &str = "th/campaign-1-coolant-off";

/// Every command that reads a file, with `IN` where the faulty input goes (the other inputs are
/// good). Inputs a command reads through a folder (campaigns, shard runs) are given as such.
const READS: &[&str] = &[
    "grid IN --step 10 --nominal-plane 5 -o g.csv",
    "map IN --out mo --epochs 2 --backend cpu --nominal-plane 5",
    "compensate --model m/model.json IN -o c.ngc --zone all",
    "compensate --model IN prog.ngc -o c.ngc --zone all",
    "batch IN --backend cpu",
    "merge IN",
    "slurm IN --shards 2 --dry-run",
    "k8s IN --shards 2 --image img --pvc pvc --dry-run",
    "linear analyze IN --standard vdi3441",
    "linear table IN --format csv --spacing 20 -o t.csv",
    "linear budget IN",
    "rotary analyze IN",
    "rotary table IN --format csv -o rt.csv",
    "circular IN --radius 150",
    "thermal difference IN",
    "thermal fit -o fm.json IN",
    "thermal ingest IN --db st.sqlite",
    "thermal models --db IN",
    "thermal compensate --model model.json IN -o tc.csv",
    "thermal compensate --model IN clog.csv -o tc.csv",
    "thermal evaluate --model model.json IN",
    "thermal evaluate --model IN th/campaign-1-coolant-off",
    "thermal calibrate --sensors sens.csv IN -o cal.csv",
    "thermal calibrate --sensors IN th/calibration.csv -o cal.csv",
];

/// Every command that writes, with `OUT` where the output (file or folder) goes.
const WRITES: &[&str] = &[
    "grid p.csv --step 10 --nominal-plane 5 -o OUT",
    "map p.csv --out-dir OUT --epochs 2 --backend cpu --nominal-plane 5",
    "batch wp/job.toml --backend cpu --out-dir OUT",
    "compensate --model m/model.json prog.ngc -o OUT --zone all",
    "k8s wp/job.toml --shards 2 --image img --pvc pvc --manifest-dir OUT",
    "slurm wp/job.toml --shards 2 --out-dir OUT",
    "linear analyze lin/runs.csv --standard vdi3441 --chart OUT",
    "linear table lin/runs.csv --format csv --spacing 20 -o OUT",
    "rotary analyze rot/centres.csv --chart OUT",
    "rotary table rot/centres.csv --format csv -o OUT",
    "circular circ/run.csv --radius 150 -o OUT",
    "thermal difference th/campaign-1-coolant-off --out-dir OUT",
    "thermal fit -o OUT th/campaign-1-coolant-off th/campaign-2-coolant-on",
    "thermal ingest th/campaign-1-coolant-off --db OUT",
    "thermal compensate --model model.json clog.csv -o OUT",
    "thermal evaluate --model model.json th/campaign-1-coolant-off --out-dir OUT",
    "thermal calibrate --sensors sens.csv th/calibration.csv -o OUT",
    "synth web-plate --out-dir OUT --parts 1 --epochs 2",
    "synth linear --out-dir OUT",
    "synth thermal --out-dir OUT",
    "synth rotary --out-dir OUT",
    "synth circular --out-dir OUT",
];

/// The good inputs every case needs, made by the binary itself.
fn fixture(d: &Path) {
    std::fs::write(d.join("p.csv"), probe_text()).unwrap();
    std::fs::write(
        d.join("prog.ngc"),
        "G21 G90\nG0 X0. Y0. Z5.\nG1 Z5. F100\nG1 X80.\nM2\n",
    )
    .unwrap();
    let q = ["-q"];
    let map = "map p.csv --out m --epochs 2 --backend cpu --nominal-plane 5";
    for args in [
        map,
        "synth linear --out lin",
        "synth rotary --out rot",
        "synth thermal --out th",
        "synth circular --out circ",
        "synth web-plate --out wp --parts 1 --epochs 2",
        "thermal fit -o model.json th/campaign-1-coolant-off th/campaign-2-coolant-on",
    ] {
        let args: Vec<&str> = q.iter().copied().chain(args.split(' ')).collect();
        ok(d, &args);
    }
    std::fs::copy(d.join("th/sensors.csv"), d.join("sens.csv")).unwrap();
    std::fs::write(d.join("clog.csv"), compensate_log(20)).unwrap();
    // The faults.
    std::fs::create_dir(d.join("a-folder.csv")).unwrap();
    std::fs::write(d.join("plain.txt"), "a regular file\n").unwrap();
    std::os::unix::fs::symlink("loop.csv", d.join("loop.csv")).unwrap();
}

/// A machine log for `thermal compensate` with the synthetic campaigns' sensors, `rows` long.
fn compensate_log(rows: usize) -> String {
    let mut log = String::from("time_s,position_mm,direction,nut,bearing,room,ambient_c,coolant\n");
    for i in 0..rows {
        let dir = if i % 2 == 0 { '+' } else { '-' };
        log.push_str(&format!(
            "{i},{},{dir},22.5,21.0,20.1,20.1,off\n",
            (i * 7) % 500
        ));
    }
    log
}

/// Whether a file without read permission still opens here (root, or capabilities).
fn permissions_block(d: &Path) -> bool {
    use std::os::unix::fs::PermissionsExt;
    let p = d.join("no-read.csv");
    std::fs::write(&p, "x_mm\n1\n").unwrap();
    std::fs::set_permissions(&p, std::fs::Permissions::from_mode(0o000)).unwrap();
    std::fs::File::open(&p).is_err()
}

/// Run `template` with `slot` replaced by `fault`; require `code` and `named` on stderr.
#[track_caller]
fn check(d: &Path, template: &str, slot: &str, fault: &str, named: &str, code: i32) -> String {
    let line = template.replace(slot, fault);
    let args: Vec<&str> = std::iter::once("-q").chain(line.split(' ')).collect();
    let run = errmap(d, &args);
    run.expect_code(code);
    assert!(
        run.stderr.contains(named),
        "stderr does not name {named}\n{}",
        run.report()
    );
    assert!(
        !run.stderr.contains("panicked") && !run.stderr.contains("internal error"),
        "{}",
        run.report()
    );
    run.stderr
}

#[test]
fn every_command_names_the_path_it_cannot_read_or_write() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    fixture(d);
    let mut faults = vec!["missing.csv", "a-folder.csv", "loop.csv"];
    if permissions_block(d) {
        faults.push("no-read.csv");
    }
    let mut cases = 0;
    for template in READS {
        for fault in &faults {
            check(d, template, "IN", fault, fault, 2);
            cases += 1;
        }
    }
    // An output below a regular file (every command creates the folders it needs, and none
    // can make one there); the message names the folder it could not create.
    for template in WRITES {
        check(d, template, "OUT", "plain.txt/sub/out.csv", "plain.txt", 3);
        cases += 1;
    }
    // A file output that is an existing folder: the finished file cannot take its place.
    for template in WRITES
        .iter()
        .filter(|t| t.contains("-o OUT") || t.contains("--chart OUT"))
    {
        check(d, template, "OUT", "a-folder.csv", "a-folder.csv", 3);
        cases += 1;
    }
    assert!(cases >= 100, "{cases} cases");
    // Nothing left behind by the failed writes.
    let left: Vec<String> = common::listing(d)
        .into_iter()
        .filter(|f| f.contains(".errmap-") || f.starts_with("plain.txt/"))
        .collect();
    assert!(left.is_empty(), "{left:?}");
}

#[test]
fn a_write_cut_short_names_the_output_and_leaves_nothing() {
    // Measured failure: `thermal compensate` reported "internal error: writing row 34681:
    // output size limit reached" (exit 3, no file named) when its output stopped growing.
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(d, &["-q", "synth", "thermal", "--out", "th"]);
    ok(
        d,
        &[
            "-q",
            "thermal",
            "fit",
            "-o",
            "model.json",
            C1,
            "th/campaign-2-coolant-on",
        ],
    );
    // 40 000 rows give about 1.2 MB of compensation values.
    std::fs::write(d.join("long.csv"), compensate_log(40_000)).unwrap();
    let compensate = [
        "thermal",
        "compensate",
        "--model",
        "model.json",
        "long.csv",
        "-o",
        "tc.csv",
    ];
    ok(d, &compensate);
    assert!(std::fs::metadata(d.join("tc.csv")).unwrap().len() > 1_000_000);
    std::fs::remove_file(d.join("tc.csv")).unwrap();
    let run = errmap(d, &[&compensate[..], &["--max-output-mb", "1"]].concat());
    run.expect_code(2);
    assert!(
        run.stderr.contains("tc.csv") && run.stderr.contains("--max-output-mb"),
        "{}",
        run.report()
    );
    assert!(!d.join("tc.csv").exists(), "{}", run.report());
    assert!(
        !common::listing(d).iter().any(|f| f.contains(".errmap-")),
        "{}",
        run.report()
    );
    // The log itself was fine: its path is not blamed.
    assert!(!run.stderr.contains("long.csv"), "{}", run.report());
}

#[test]
fn a_probe_file_the_glob_matches_but_cannot_read_is_named_not_dropped() {
    // Measured failure: a probe file that is a broken link matched `probes/*.csv` and was
    // silently left out of the batch (exit 0 with one part fewer).
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(
        d,
        &[
            "-q",
            "synth",
            "web-plate",
            "--out",
            "wp",
            "--parts",
            "2",
            "--epochs",
            "2",
        ],
    );
    std::os::unix::fs::symlink("gone.csv", d.join("wp/probes/p03.csv")).unwrap();
    // A folder that matches the glob is not a probe file, and is skipped.
    std::fs::create_dir(d.join("wp/probes/old.csv")).unwrap();
    let run = errmap(d, &["-q", "batch", "wp/job.toml", "--backend", "cpu"]);
    run.expect_code(2);
    assert!(
        run.stderr.contains("p03.csv") && run.stderr.contains("cannot read"),
        "{}",
        run.report()
    );
    assert!(!run.stderr.contains("old.csv"), "{}", run.report());
}

#[test]
fn a_toolpath_that_outgrows_the_output_limit_is_refused_at_its_line_while_it_grows() {
    // Found by `gcode_fanuc`: an arc of 2000 turns is 200 000 chords; a program of many such
    // lines was built whole in memory before `--max-output-mb` was looked at, on writing.
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("p.csv"), probe_text()).unwrap();
    ok(
        d,
        &[
            "-q",
            "map",
            "p.csv",
            "--out",
            "m",
            "--epochs",
            "2",
            "--backend",
            "cpu",
            "--nominal-plane",
            "5",
        ],
    );
    // Full circles of radius 10 mm about (50, 30), inside the probed area: 200 turns are about
    // 20 000 chords at the 0.005 mm chord tolerance, some 0.8 MB per line.
    let mut program = String::from("G21 G90 G17\nG0 X60. Y30. Z5.\n");
    for _ in 0..30 {
        program.push_str("G3 X60. Y30. I-10. J0. P200 F100\n");
    }
    program.push_str("M2\n");
    std::fs::write(d.join("arcs.ngc"), program).unwrap();
    let compensate = [
        "compensate",
        "--model",
        "m/model.json",
        "arcs.ngc",
        "-o",
        "out.ngc",
        "--zone",
        "all",
    ];
    let run = errmap(d, &[&["--max-output-mb", "1"][..], &compensate].concat());
    run.expect_code(2);
    assert!(
        run.stderr.contains("arcs.ngc:4") && run.stderr.contains("--max-output-mb"),
        "{}",
        run.report()
    );
    assert!(!d.join("out.ngc").exists(), "{}", run.report());
    // Under the default limit the same program is written.
    ok(d, &compensate);
    assert!(std::fs::metadata(d.join("out.ngc")).unwrap().len() > 10_000_000);

    // One arc of 5000 turns is 500 000 chords, some 20 MB: refused while its points are
    // generated, once they outnumber what 1 MB can hold at 27 bytes a segment, not after.
    std::fs::write(
        d.join("turns.ngc"),
        "G21 G90 G17\nG0 X60. Y30. Z5.\nG3 X60. Y30. I-10. J0. P5000 F100\nM2\n",
    )
    .unwrap();
    let turns = [
        "--max-output-mb",
        "1",
        "compensate",
        "--model",
        "m/model.json",
        "turns.ngc",
        "-o",
        "turns-out.ngc",
        "--zone",
        "all",
    ];
    let run = errmap(d, &turns);
    run.expect_code(2);
    assert!(
        run.stderr.contains("turns.ngc:3")
            && run
                .stderr
                .contains("more segments than the output limit of 1 MB")
            && run.stderr.contains("--max-output-mb"),
        "{}",
        run.report()
    );
    assert!(!d.join("turns-out.ngc").exists(), "{}", run.report());
}
