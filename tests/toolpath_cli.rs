//! `errmap compensate` run as a real binary: report line, --json, exit codes, refusals naming the line.

mod common;

use common::errmap;

#[test]
fn compensate_writes_the_program_and_reports() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    std::fs::write(dir.join("model.json"), common::FLAT_MODEL_20UM).unwrap();
    let program = "%\nG21 G90\nG0 X10 Y10 Z5\nG1 Z-1 F100 (plunge)\nG1 X20\nG0 Z5\nM2\n%\n";
    std::fs::write(dir.join("in.ngc"), program).unwrap();
    let out = errmap(
        dir,
        &[
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
        ],
    );
    out.expect_code(0);
    // Zone z ∈ [-2, 0]: the plunge is split at z 0; E = 0.02 mm; X10 → X20 in 5 mm segments.
    let expected = "%\nG21 G90\nG0 X10 Y10 Z5\n\
        G1 X10.0000 Y10.0000 Z0.0000 F100 (plunge)\n\
        G1 X10.0000 Y10.0000 Z-0.0200\n\
        G1 X10.0000 Y10.0000 Z-1.0200\n\
        G1 X15.0000 Y10.0000 Z-1.0200\n\
        G1 X20.0000 Y10.0000 Z-1.0200\n\
        G0 Z5\nM2\n%\n";
    assert_eq!(
        std::fs::read_to_string(dir.join("out.ngc")).unwrap(),
        expected
    );
    let stdout = out.stdout.as_str();
    assert!(
        stdout.contains("2 moves changed, 2 split, max |E| applied 0.0200 mm"),
        "{stdout}"
    );

    // --json: one document with the report.
    let out = errmap(
        dir,
        &[
            "compensate",
            "--model",
            "model.json",
            "--dialect",
            "linuxcnc",
            "in.ngc",
            "-o",
            "out2.ngc",
            "--json",
        ],
    );
    out.expect_code(0);
    let doc = common::json(&out);
    assert_eq!(doc["report"]["moves_changed"], 2);
    assert!((doc["report"]["max_abs_error_mm"].as_f64().unwrap() - 0.02).abs() < 1e-9);
    assert!(doc["input"].as_str().unwrap().ends_with("in.ngc"), "{doc}");
    // Keys in alphabetical order at every level, as scripts have read them.
    let text = out.stdout.trim();
    let at = |key: &str| text.find(&format!("\"{key}\"")).unwrap_or(usize::MAX);
    let keys = [
        "dialect",
        "lines_in",
        "max_abs_error_mm",
        "moves_changed",
        "zone_mm",
    ];
    assert!(keys.windows(2).all(|w| at(w[0]) < at(w[1])), "{text}");
    assert!(
        at("input") < at("output") && at("output") < at("report"),
        "{text}"
    );

    // A refusal names file:line and exits 2; nothing is written (G41 offsets in ZX under G18,
    // which a Z map would change).
    std::fs::write(
        dir.join("comp.ngc"),
        "G21 G18 G0 X10 Y10 Z-1\nG41 D1\nG1 X20 F100\n",
    )
    .unwrap();
    let out = errmap(
        dir,
        &[
            "compensate",
            "--model",
            "model.json",
            "--dialect",
            "linuxcnc",
            "comp.ngc",
            "-o",
            "bad.ngc",
        ],
    );
    out.expect_code(2);
    let stderr = out.stderr.as_str();
    assert!(
        stderr.contains("comp.ngc:3") && stderr.contains("G41"),
        "{stderr}"
    );
    assert!(!dir.join("bad.ngc").exists());
}

#[test]
fn bad_options_exit_2_with_a_hint() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    std::fs::write(dir.join("model.json"), common::FLAT_MODEL_20UM).unwrap();
    std::fs::write(dir.join("in.ngc"), "G0 X0 Y0 Z0\nM2\n").unwrap();
    for (args, what) in [
        (vec!["--zone", "1"], "is not MIN,MAX"),
        (vec!["--zone", "0,-1"], "MIN ≤ MAX"),
        (vec!["--max-segment", "0"], "maximum segment length"),
        (vec!["--chord-tol", "-1"], "chord tolerance"),
    ] {
        let mut all = vec![
            "compensate",
            "--model",
            "model.json",
            "--dialect",
            "linuxcnc",
        ];
        all.extend(args);
        all.extend(["in.ngc", "-o", "out.ngc"]);
        let out = errmap(dir, &all);
        out.expect_code(2);
        let stderr = out.stderr.as_str();
        assert!(stderr.contains(what) && stderr.contains("hint"), "{stderr}");
    }
}
