//! End-to-end tests of `errmap linear …` and `errmap synth linear` on the real binary: JSON shape and values, errors, golden controller tables, table round trips, corrections, synthetic data.

mod common;

use common::{errmap, json, ok};
use std::path::{Path, PathBuf};

fn golden(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/golden/linear")
        .join(name)
}

fn close(v: &serde_json::Value, expected: f64, what: &str) {
    let got = v
        .as_f64()
        .unwrap_or_else(|| panic!("{what}: {v} is not a number"));
    assert!(
        (got - expected).abs() < 1e-9,
        "{what}: got {got}, expected {expected}"
    );
}

/// The 3 × 2 × 3 hand data set of crates/metrology/tests/linear_eval.rs (figures worked out there).
const HAND: &str = "run,direction,target_mm,deviation_um\n\
1,+,0,1\n1,+,100,4\n1,+,200,-1\n1,-,200,-7\n1,-,100,2\n1,-,0,-1\n\
2,+,0,2\n2,+,100,6\n2,+,200,-1\n2,-,200,-5\n2,-,100,3\n2,-,0,0\n\
3,+,0,3\n3,+,100,8\n3,+,200,-1\n3,-,200,-3\n3,-,100,4\n3,-,0,1\n";

#[test]
fn analyze_json_has_the_issue_shape_and_hand_values() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("hand.csv"), HAND).unwrap();
    let out = ok(
        dir.path(),
        &[
            "linear",
            "analyze",
            "hand.csv",
            "--standard",
            "iso230-2:2014",
            "--json",
        ],
    );
    let doc = json(&out);
    // Keys in the issue's order.
    let at = |k: &str| out.stdout.find(&format!("\"{k}\"")).unwrap();
    assert!(
        at("standard") < at("unit") && at("unit") < at("targets") && at("targets") < at("axis")
    );
    assert!(at("target_mm") < at("mean_up") && at("s_down") < at("reversal"));
    assert_eq!(doc["standard"], "iso230-2:2014");
    assert_eq!(doc["unit"], "um");
    let keys: Vec<&str> = doc
        .as_object()
        .unwrap()
        .keys()
        .map(String::as_str)
        .collect();
    // The four keys of the shape, plus `figures` (the axis figures in the standard's symbols)
    // and `target_symbols` (the per-target headings in them).
    assert_eq!(keys.len(), 6, "{keys:?}");
    assert_eq!(doc["figures"][0]["symbol"], "A");
    assert_eq!(doc["target_symbols"][4], "B_i");
    let t = &doc["targets"][1];
    for key in [
        "target_mm",
        "mean_up",
        "mean_down",
        "s_up",
        "s_down",
        "reversal",
        "repeatability_up",
        "repeatability_down",
        "repeatability",
    ] {
        assert!(t.get(key).is_some(), "target lacks {key}");
    }
    assert_eq!(t.as_object().unwrap().len(), 9);
    close(&t["target_mm"], 100.0, "target");
    close(&t["mean_up"], 6.0, "x̄↑ = (4+6+8)/3");
    close(&t["s_up"], 2.0, "s↑");
    close(&t["reversal"], 3.0, "B_i = 6 − 3");
    close(&t["repeatability"], 9.0, "R_i = max(4+2+3, 8, 4)");
    let a = &doc["axis"];
    assert_eq!(a.as_object().unwrap().len(), 12);
    for (key, v) in [
        ("B", 4.0),
        ("B_mean", 3.0),
        ("R_up", 8.0),
        ("R_down", 8.0),
        ("R", 9.0),
        ("E_up", 7.0),
        ("E_down", 8.0),
        ("E", 11.0),
        ("M", 7.5),
        ("A_up", 11.0),
        ("A_down", 14.0),
        ("A", 19.0),
    ] {
        close(&a[key], v, key);
    }
    // GB 10931: A = 23 (±3S), VDI 3441: P = 18.5.
    let gb = json(&ok(
        dir.path(),
        &[
            "linear",
            "analyze",
            "hand.csv",
            "--standard",
            "gb10931-1989",
            "--json",
        ],
    ));
    close(&gb["axis"]["A"], 23.0, "GB A");
    let vdi = json(&ok(
        dir.path(),
        &[
            "linear",
            "analyze",
            "hand.csv",
            "--standard",
            "vdi3441",
            "--json",
        ],
    ));
    close(&vdi["axis"]["A"], 18.5, "VDI P");
    // Human output names the figures.
    let text = ok(
        dir.path(),
        &[
            "linear",
            "analyze",
            "hand.csv",
            "--standard",
            "iso230-2:1997",
        ],
    )
    .stdout;
    assert!(
        text_figure(&text, "A") == "19.000" && text_figure(&text, "B") == "4.000",
        "{text}"
    );
}

#[test]
fn single_run_reports_null_not_zero() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("one.csv"),
        "run,direction,target_mm,deviation_um\n1,+,0,3\n1,+,500,1\n1,-,500,-4\n1,-,0,-1\n",
    )
    .unwrap();
    let doc = json(&ok(
        dir.path(),
        &[
            "linear",
            "analyze",
            "one.csv",
            "--standard",
            "iso230-2:2014",
            "--json",
            "--chart",
            "one.png",
        ],
    ));
    // Both directions are drawn: the forward (blue) and reverse (red) means and bands.
    let img = image::open(dir.path().join("one.png")).unwrap().to_rgb8();
    let (blue, red) = (pixels(&img, FORWARD_RGB), pixels(&img, REVERSE_RGB));
    println!("one.png: {blue} forward, {red} reverse pixels");
    assert!(
        blue > 100 && red > 100,
        "{blue} forward, {red} reverse pixels"
    );
    for key in ["R_up", "R_down", "R", "A_up", "A_down", "A"] {
        assert!(doc["axis"][key].is_null(), "{key} = {}", doc["axis"][key]);
    }
    assert!(doc["targets"][0]["s_up"].is_null());
    close(&doc["axis"]["B"], 5.0, "B");
}

#[test]
fn bad_input_exits_2_naming_file_line_and_target() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("gap.csv"),
        "run,direction,target_mm,deviation_um\n1,+,0,1\n1,+,100,2\n1,-,100,1\n1,-,0,0\n2,+,0,1\n2,-,100,1\n2,-,0,0\n",
    )
    .unwrap();
    let out = errmap(
        dir.path(),
        &["linear", "analyze", "gap.csv", "--standard", "vdi3441"],
    );
    out.expect_code(2);
    assert!(
        out.stderr.contains("gap.csv:6")
            && out
                .stderr
                .contains("target 100 mm missing from run 2 direction +"),
        "{}",
        out.stderr
    );
    std::fs::write(
        dir.path().join("bad.csv"),
        "run,direction,target_mm,deviation_um\n1,+,0,1\n1,up?,100,x\n",
    )
    .unwrap();
    let out = errmap(
        dir.path(),
        &["linear", "analyze", "bad.csv", "--standard", "vdi3441"],
    );
    out.expect_code(2);
    assert!(
        out.stderr.contains("bad.csv:3, column direction"),
        "{}",
        out.stderr
    );
    let out = errmap(
        dir.path(),
        &["linear", "analyze", "bad.csv", "--standard", "iso9000"],
    );
    out.expect_code(2);
    assert!(
        out.stderr.contains("invalid value 'iso9000'"),
        "{}",
        out.stderr
    );
}

#[test]
fn air_index_command_prints_nist_values() {
    let dir = tempfile::tempdir().unwrap();
    let args = [
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
        "--json",
    ];
    let doc = json(&ok(dir.path(), &args));
    assert!(
        (doc["n"].as_f64().unwrap() - 1.000_271_373).abs() < 1e-9,
        "{doc}"
    );
    // `errmap linear air-index` in dry air at `temp_c`, with `extra` flags.
    let dry_air = |temp_c: &str, extra: &[&str]| {
        let mut args = vec![
            "linear",
            "air-index",
            "--temp-c",
            temp_c,
            "--pressure-kpa",
            "101.325",
            "--humidity-pct",
            "0",
            "--wavelength-nm",
            "633",
        ];
        args.extend_from_slice(extra);
        errmap(dir.path(), &args)
    };
    let out = dry_air("20", &["--formula", "edlen"]);
    out.expect_code(0);
    let text = out.stdout;
    assert!(text.contains("n = 1.000271799"), "{text}");
    // The Edlén equation with another CO2 content is refused, and the hint names the flag
    // that `air-index` and `analyze` both take for the equation.
    let out = dry_air("20", &["--air-formula", "edlen", "--co2-ppm", "600"]);
    out.expect_code(2);
    assert!(
        out.stderr
            .contains("use --air-formula ciddor for another CO2 content"),
        "{}",
        out.stderr
    );
    let out = dry_air("-60", &[]);
    out.expect_code(2);
    assert!(
        out.stderr.contains("air temperature -60 °C is outside"),
        "{}",
        out.stderr
    );
}

#[test]
fn budget_command_reports_terms_and_errors_with_lines() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("setup.toml"),
        "length_mm = 500.0\n[abbe]\noffset_mm = 20.0\nangle_arcsec = 1.0\n[thermal]\nexpansion_ppm_per_k = 10.0\ntemp_uncertainty_c = 0.1\n",
    )
    .unwrap();
    let doc = json(&ok(
        dir.path(),
        &["linear", "budget", "setup.toml", "--json"],
    ));
    // δ1 = 0.1 ppm × 500 mm = 0.05 µm; δ3 = 20 000 µm × tan(1″) = 0.0969627 µm;
    // δ5 = 10e-6 × 0.1 × 500 000 µm = 0.5 µm; total = √(0.0025 + 0.0094018 + 0.25) = √0.2619018 = 0.511763 µm.
    let terms = doc["terms"].as_array().unwrap();
    assert_eq!(terms.len(), 3);
    close(&terms[0]["value_um"], 0.05, "δ1");
    assert!((terms[1]["value_um"].as_f64().unwrap() - 0.096_962_7).abs() < 1e-7);
    close(&terms[2]["value_um"], 0.5, "δ5");
    assert!(
        (doc["total_um"].as_f64().unwrap() - 0.511_763).abs() < 1e-6,
        "{doc}"
    );
    std::fs::write(
        dir.path().join("typo.toml"),
        "length_mm = 500.0\n\n[abbe]\noffset = 2\n",
    )
    .unwrap();
    let out = errmap(dir.path(), &["linear", "budget", "typo.toml"]);
    out.expect_code(2);
    assert!(out.stderr.contains("typo.toml:4"), "{}", out.stderr);
}

#[test]
fn tables_match_hand_written_golden_files() {
    // Golden files were written by hand from runs_small.csv: mean e↑ = 2, 6, 10 µm and
    // e↓ = −1, 3, 6 µm at 0, 100, 200 mm; at 50 mm spacing e↑ = 2, 4, 6, 8, 10 and
    // e↓ = −1, 1, 3, 4.5, 6 (linear between targets).
    //  linuxcnc type 0: actual positions x + e (mm), e.g. "50.000000 50.004000 50.001000";
    //  type 1: trims nominal − actual = −e, e.g. "50.000000 -0.004000 -0.001000";
    //  sinumerik LEC: mean (e↑ + e↓)/2 = 0.5, 2.5, 4.5, 6.25, 8 µm less its value at the
    //  reference point 0 mm: 0, 2, 4, 5.75, 7.5 µm; CEC ↑: −(e↑ − mean) = −1.5 …
    //  −2 µm with DIRECTION 1, CEC ↓: +1.5 … +2 µm with DIRECTION −1;
    //  fanuc (1 µm units): C↑ = round(−e↑) = −2, −4, −6, −8, −10 → increments 0, −2, −2, −2, −2;
    //  C↓ = 1, −1, −3, −5 (−4.5 rounds away from zero), −6 → 0, −2, −2, −2, −1;
    //  3627 = C↓(ref) − C↑(ref) = 1 − (−2) = 3; 3624 = 50 mm / 1 µm = 50000;
    //  heidenhain: X = e↑, BACKLASH = e↓ in mm; csv: e↑, e↓ in µm.
    let dir = tempfile::tempdir().unwrap();
    let runs = golden("runs_small.csv");
    let runs = runs.to_str().unwrap();
    let cases: [(&str, &[&str], &[&str]); 6] = [
        ("x_type0.comp", &["--format", "linuxcnc"], &["x_type0.comp"]),
        (
            "x_type1.comp",
            &["--format", "linuxcnc", "--linuxcnc-type", "1"],
            &["x_type1.comp"],
        ),
        (
            "x_lec.ini",
            &["--format", "sinumerik"],
            &["x_lec.ini", "x_lec_cec.ini"],
        ),
        ("x_fanuc.txt", &["--format", "fanuc"], &["x_fanuc.txt"]),
        ("x.com", &["--format", "heidenhain"], &["x.com", "x.cma"]),
        ("x.csv", &["--format", "csv"], &["x.csv"]),
    ];
    for (output, flags, files) in cases {
        let mut args = vec![
            "linear",
            "table",
            runs,
            "--spacing",
            "50",
            "-o",
            output,
            "-q",
        ];
        args.extend_from_slice(flags);
        ok(dir.path(), &args);
        for f in files {
            let got = std::fs::read_to_string(dir.path().join(f)).unwrap();
            let want = std::fs::read_to_string(golden(f)).unwrap();
            assert_eq!(got, want, "{f} differs from tests/golden/linear/{f}");
            assert!(got.is_ascii(), "{f} is not ASCII");
        }
    }
    // LinuxCNC reads at most 256 triplets: 200 mm at 0.5 mm spacing is 401 lines.
    let out = errmap(
        dir.path(),
        &[
            "linear",
            "table",
            runs,
            "--format",
            "linuxcnc",
            "--spacing",
            "0.5",
            "-o",
            "big.comp",
        ],
    );
    out.expect_code(2);
    assert!(out.stderr.contains("at most 256"), "{}", out.stderr);
}

#[test]
fn applying_each_table_removes_the_errors_it_encodes() {
    let dir = tempfile::tempdir().unwrap();
    let runs = golden("runs_small.csv");
    let runs = runs.to_str().unwrap();
    // Before: E = max(2,6,10,−1,3,6) − min = 10 − (−1) = 11 µm, B = max(3, 3, 4) = 4 µm.
    for (file, extra, residual) in [
        ("x_type0.comp", vec![], 0.0),
        ("x_type1.comp", vec!["--linuxcnc-type", "1"], 0.0),
        // The LEC is zero at the reference point (0 mm, mean 0.5 µm): 0.5 µm remain everywhere.
        ("x_lec.ini", vec![], 0.5),
        ("x.com", vec![], 0.0),
        ("x.csv", vec![], 0.0),
        // Fanuc compensates relative to the reference point (0 mm, e↑ = 2 µm): 2 µm remain everywhere.
        ("x_fanuc.txt", vec![], 2.0),
    ] {
        let table = golden(file);
        let mut args = vec![
            "linear",
            "analyze",
            runs,
            "--standard",
            "iso230-2:2014",
            "--json",
            "--apply-table",
            table.to_str().unwrap(),
        ];
        args.extend(extra);
        let doc = json(&ok(dir.path(), &args));
        close(&doc["axis"]["E"], 11.0, "E before");
        close(&doc["axis"]["B"], 4.0, "B before");
        for t in doc["after"]["targets"].as_array().unwrap() {
            assert!(
                (t["mean_up"].as_f64().unwrap() - residual).abs() < 1e-9,
                "{file}: {t}"
            );
            assert!(
                (t["mean_down"].as_f64().unwrap() - residual).abs() < 1e-9,
                "{file}: {t}"
            );
        }
        assert!(
            doc["after"]["axis"]["B"].as_f64().unwrap().abs() < 1e-9,
            "{file}"
        );
    }
}

#[test]
fn material_expansion_flag_normalises_to_20_c() {
    // α = 10 µm/(m·K): at 25 °C a reading of 500.025 mm is 500.000 mm at 20 °C (hand: 500.025 / 1.00005).
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("m.csv"),
        "run,direction,target_mm,actual_mm,material_temp_c\n1,+,0,0,25\n1,+,500,500.025,25\n1,-,500,500.025,25\n1,-,0,0,25\n",
    )
    .unwrap();
    let raw = json(&ok(
        dir.path(),
        &[
            "linear",
            "analyze",
            "m.csv",
            "--standard",
            "iso230-2:2014",
            "--json",
        ],
    ));
    assert!((raw["targets"][1]["mean_up"].as_f64().unwrap() - 25.0).abs() < 1e-6);
    let doc = json(&ok(
        dir.path(),
        &[
            "linear",
            "analyze",
            "m.csv",
            "--standard",
            "iso230-2:2014",
            "--json",
            "--material-expansion",
            "10",
        ],
    ));
    assert!(
        doc["targets"][1]["mean_up"].as_f64().unwrap().abs() < 1e-6,
        "{doc}"
    );
    assert!(doc["corrections"][0].as_str().unwrap().contains("20 °C"));
}

#[test]
fn synthetic_runs_recover_their_ground_truth() {
    let dir = tempfile::tempdir().unwrap();
    ok(
        dir.path(),
        &["synth", "linear", "--out-dir", "s", "--seed", "7", "-q"],
    );
    ok(
        dir.path(),
        &["synth", "linear", "--out-dir", "s2", "--seed", "7", "-q"],
    );
    let runs = std::fs::read(dir.path().join("s/runs.csv")).unwrap();
    assert_eq!(
        runs,
        std::fs::read(dir.path().join("s2/runs.csv")).unwrap(),
        "same seed, same bytes"
    );
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("s/truth.json")).unwrap())
            .unwrap();
    let doc = json(&ok(
        dir.path(),
        &[
            "linear",
            "analyze",
            "s/runs.csv",
            "--standard",
            "iso230-2:2014",
            "--json",
            "--fit-pitch",
            "10",
            "--chart",
            "c.png",
            "--material-expansion",
            "11.5",
        ],
    ));
    let fit = &doc["pitch_fit"];
    // Noise 0.4 µm per reading, 10 readings per target mean: σ ≈ 0.13 µm per point.
    for (key, truth_key, tol) in [
        ("a_um", "a_um", 0.3),
        ("k_um_per_m", "k_um_per_m", 0.6),
        ("d_um", "d_um", 0.2),
        ("phi_rad", "phi_rad", 0.15),
    ] {
        let got = fit[key].as_f64().unwrap();
        let want = truth[truth_key].as_f64().unwrap();
        assert!(
            (got - want).abs() < tol,
            "{key}: fitted {got}, planted {want}"
        );
    }
    // Without the normalisation the slope carries the expansion: α·(T − 20) ≈ 11.5 × 0.5…0.8
    // ≈ 6…9 µm/m on top of the planted 12 µm/m.
    let warm = json(&ok(
        dir.path(),
        &[
            "linear",
            "analyze",
            "s/runs.csv",
            "--standard",
            "iso230-2:2014",
            "--json",
            "--fit-pitch",
            "10",
        ],
    ));
    let k_warm = warm["pitch_fit"]["k_um_per_m"].as_f64().unwrap();
    assert!((k_warm - 12.0 - 11.5 * 0.65).abs() < 1.5, "{k_warm}");
    // Mean reversal ≈ planted 4 µm.
    assert!(
        (doc["axis"]["B_mean"].as_f64().unwrap() - truth["reversal_um"].as_f64().unwrap()).abs()
            < 0.3
    );
    let img = image::open(dir.path().join("c.png")).unwrap();
    assert_eq!((img.width(), img.height()), (1280, 720));
    // The raw (vacuum-scale) readings, air-corrected, give back the compensated file's figures.
    let doc = json(&ok(
        dir.path(),
        &[
            "linear",
            "analyze",
            "s/runs.csv",
            "--standard",
            "iso230-2:2014",
            "--json",
        ],
    ));
    let raw = json(&ok(
        dir.path(),
        &[
            "linear",
            "analyze",
            "s/runs_raw.csv",
            "--standard",
            "iso230-2:2014",
            "--json",
            "--correct-air",
        ],
    ));
    let uncorrected = json(&ok(
        dir.path(),
        &[
            "linear",
            "analyze",
            "s/runs_raw.csv",
            "--standard",
            "iso230-2:2014",
            "--json",
        ],
    ));
    for (a, b) in raw["targets"]
        .as_array()
        .unwrap()
        .iter()
        .zip(doc["targets"].as_array().unwrap())
    {
        assert!(
            (a["mean_up"].as_f64().unwrap() - b["mean_up"].as_f64().unwrap()).abs() < 1e-3,
            "{a} vs {b}"
        );
    }
    // Without the correction, 1000 mm reads ≈ 271 µm long (n − 1 ≈ 2.71e-4).
    let last = uncorrected["targets"].as_array().unwrap().last().unwrap()["mean_up"]
        .as_f64()
        .unwrap();
    let last_c = raw["targets"].as_array().unwrap().last().unwrap()["mean_up"]
        .as_f64()
        .unwrap();
    assert!((last - last_c - 271.0).abs() < 3.0, "{last} vs {last_c}");
}

#[test]
fn fanuc_reference_point_elsewhere_than_the_first_target() {
    // Reference at 100 mm = point 2: 3620 = 2; 3627 = C↓(100) − C↑(100) = round(−3) − round(−6) = 3.
    // The table compensates relative to the reference, so e↑(100) = 6 µm remains everywhere.
    let dir = tempfile::tempdir().unwrap();
    let runs = golden("runs_small.csv");
    let runs = runs.to_str().unwrap();
    ok(
        dir.path(),
        &[
            "linear",
            "table",
            runs,
            "--format",
            "fanuc",
            "--spacing",
            "50",
            "--reference-mm",
            "100",
            "-o",
            "f.txt",
            "-q",
        ],
    );
    let text = std::fs::read_to_string(dir.path().join("f.txt")).unwrap();
    assert!(
        text.contains("N3620A1P2\n") && text.contains("N3627A1P3\n"),
        "{text}"
    );
    let doc = json(&ok(
        dir.path(),
        &[
            "linear",
            "analyze",
            runs,
            "--standard",
            "iso230-2:2014",
            "--json",
            "--apply-table",
            "f.txt",
            "--reference-mm",
            "100",
        ],
    ));
    for t in doc["after"]["targets"].as_array().unwrap() {
        close(&t["mean_up"], 6.0, "after ↑");
        close(&t["mean_down"], 6.0, "after ↓");
    }
    // A reference that is not a table point is refused.
    let out = errmap(
        dir.path(),
        &[
            "linear",
            "table",
            runs,
            "--format",
            "fanuc",
            "--spacing",
            "50",
            "--reference-mm",
            "75",
            "-o",
            "g.txt",
        ],
    );
    out.expect_code(2);
    assert!(
        out.stderr
            .contains("reference position 75 mm is not a table point"),
        "{}",
        out.stderr
    );
}

/// Forward-only hand data (figures worked out in crates/metrology/tests/linear_eval.rs):
/// target 0: 1, 2, 3 → x̄ = 2, s = 1; target 10: 4, 6, 8 → x̄ = 6, s = 2; target 20: −1, 0, 1 → x̄ = 0, s = 1.
const FORWARD_ONLY: &str = "run,direction,target_mm,deviation_um\n\
1,+,0,1\n1,+,10,4\n1,+,20,-1\n\
2,+,0,2\n2,+,10,6\n2,+,20,0\n\
3,+,0,3\n3,+,10,8\n3,+,20,1\n";

#[test]
fn unidirectional_runs_analyze_to_json_nulls_text_chart_and_table() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("fwd.csv"), FORWARD_ONLY).unwrap();
    let out = ok(
        dir.path(),
        &[
            "linear",
            "analyze",
            "fwd.csv",
            "--standard",
            "iso230-2:2014",
            "--json",
            "--chart",
            "fwd.png",
        ],
    );
    let doc = json(&out);
    assert_eq!(doc["unidirectional"], "forward", "{}", out.report());
    let t = &doc["targets"][1];
    close(&t["mean_up"], 6.0, "x̄↑ = (4+6+8)/3");
    close(&t["s_up"], 2.0, "s↑");
    close(&t["repeatability_up"], 8.0, "R↑_i = 4·2");
    for key in [
        "mean_down",
        "s_down",
        "reversal",
        "repeatability_down",
        "repeatability",
    ] {
        assert!(t[key].is_null(), "{key} must be null: {}", out.stdout);
    }
    let a = &doc["axis"];
    close(&a["E_up"], 6.0, "E↑ = 6 − 0");
    close(&a["R_up"], 8.0, "R↑ = max(4, 8, 4)");
    close(&a["A_up"], 12.0, "A↑ = 10 − (−2)");
    for key in [
        "B", "B_mean", "R", "E", "M", "A", "R_down", "E_down", "A_down",
    ] {
        assert!(
            a.get(key).is_some_and(|v| v.is_null()),
            "axis {key} must be null: {}",
            out.stdout
        );
    }
    // Only the forward direction is drawn: its blue line and bands, nothing in reverse red.
    let img = image::open(dir.path().join("fwd.png")).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (1280, 720));
    let (blue, red) = (pixels(&img, FORWARD_RGB), pixels(&img, REVERSE_RGB));
    println!("fwd.png: {blue} forward, {red} reverse pixels");
    assert!(
        blue > 300 && red == 0,
        "{blue} forward, {red} reverse pixels"
    );

    // Human text: the measured figures and n/a for the rest.
    let text = ok(
        dir.path(),
        &[
            "linear",
            "analyze",
            "fwd.csv",
            "--standard",
            "iso230-2:2014",
        ],
    );
    assert!(
        text.stdout.contains("E  = n/a")
            && text.stdout.contains("E↑ = 6.000")
            && text
                .stdout
                .contains("unidirectional test (direction + only)"),
        "{}",
        text.report()
    );

    // Table: the forward means resampled every 5 mm, the same values in both columns.
    ok(
        dir.path(),
        &[
            "linear",
            "table",
            "fwd.csv",
            "--format",
            "csv",
            "--spacing",
            "5",
            "-o",
            "t.csv",
            "-q",
        ],
    );
    let table = std::fs::read_to_string(dir.path().join("t.csv")).unwrap();
    // 0 → 2, 5 → (2+6)/2 = 4, 10 → 6, 15 → (6+0)/2 = 3, 20 → 0.
    for row in [
        "0.000000,2.0000,2.0000",
        "5.000000,4.0000,4.0000",
        "10.000000,6.0000,6.0000",
        "15.000000,3.0000,3.0000",
        "20.000000,0.0000,0.0000",
    ] {
        assert!(table.contains(row), "missing {row} in\n{table}");
    }
}

#[test]
fn mixed_direction_run_file_names_file_and_line() {
    // Targets 0 and 10 both ways, 20 from − only: its first reading is line 5.
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("mixed.csv"),
        "run,direction,target_mm,deviation_um\n\
1,+,0,1\n1,+,10,2\n1,-,10,2\n1,-,20,0\n1,-,0,1\n",
    )
    .unwrap();
    let out = errmap(
        dir.path(),
        &[
            "linear",
            "analyze",
            "mixed.csv",
            "--standard",
            "iso230-2:2014",
            "--json",
        ],
    );
    out.expect_code(2);
    assert!(
        out.stderr.contains("mixed.csv:5")
            && out.stderr.contains("target 20")
            && out.stderr.contains("direction - only"),
        "{}",
        out.report()
    );
}

/// The value on the text line of axis figure `symbol` (lines `SYMBOL = value  name: definition`).
fn text_figure(stdout: &str, symbol: &str) -> String {
    stdout
        .lines()
        .map(|l| l.trim_start_matches("axis:").trim())
        .find(|l| l.starts_with(symbol) && l[symbol.len()..].trim_start().starts_with('='))
        .and_then(|l| l.split('=').nth(1))
        .map(|v| v.split_whitespace().next().unwrap_or("").to_string())
        .unwrap_or_else(|| panic!("no line for {symbol} in\n{stdout}"))
}

#[test]
fn vdi_and_gb_text_use_their_own_symbols() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("hand.csv"), HAND).unwrap();
    let vdi = ok(
        dir.path(),
        &["linear", "analyze", "hand.csv", "--standard", "vdi3441"],
    );
    // HAND by hand: U_j = 2, 3, 4 (U max 4, Ū 3); s̄_j = 1, 1.5, 1 → Ps_j = 6, 9, 6 (Ps max 9,
    // P̄s 7); x̄_j = 1, 4.5, −3 (Pa 7.5); (U_j + Ps_j)/2 = 4, 6, 5 → max(x̄ + …) = 10.5,
    // min(x̄ − …) = −8 → P = 18.5.
    for (symbol, want) in [
        ("Ps max", "9.000"),
        ("P̄s", "7.000"),
        ("U max", "4.000"),
        ("Ū", "3.000"),
        ("Pa", "7.500"),
        ("P", "18.500"),
    ] {
        assert_eq!(text_figure(&vdi.stdout, symbol), want, "{symbol}");
    }
    let head = vdi.stdout.lines().nth(1).unwrap();
    assert!(
        head.contains("U_j") && head.contains("Ps_j") && !head.contains("B_i"),
        "{head}"
    );
    let gb = ok(
        dir.path(),
        &[
            "linear",
            "analyze",
            "hand.csv",
            "--standard",
            "gb10931-1989",
        ],
    );
    let head = gb.stdout.lines().nth(1).unwrap();
    assert!(
        head.contains("X̄_j↑") && head.contains("S_j↓") && !head.contains("s_i"),
        "{head}"
    );
    // A = (X̄ + 3S)max − (X̄ − 3S)min = 12 − (−11) = 23 (↑: 5, 12, −1; ↓: 3, 6, 1 | ↑: −1, 0, −1;
    // ↓: −3, 0, −11).
    assert_eq!(text_figure(&gb.stdout, "A"), "23.000");
    assert!(
        gb.stdout.contains("反向差值") && !gb.stdout.contains("B̄"),
        "{}",
        gb.stdout
    );
}

#[test]
fn air_index_json_has_its_keys_in_order_and_the_air_wavelength() {
    let dir = tempfile::tempdir().unwrap();
    let run = ok(
        dir.path(),
        &[
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
            "--json",
        ],
    );
    let out = &run.stdout;
    // The document's keys in their published order: the equation, n, λ_air, then the inputs.
    let keys = [
        "\"formula\"",
        "\"n\"",
        "\"air_wavelength_nm\"",
        "\"temp_c\"",
        "\"pressure_kpa\"",
        "\"humidity_pct\"",
        "\"wavelength_nm\"",
        "\"co2_ppm\"",
    ];
    let at: Vec<usize> = keys
        .iter()
        .map(|k| out.find(k).unwrap_or_else(|| panic!("no {k} in {out}")))
        .collect();
    assert!(at.windows(2).all(|w| w[0] < w[1]), "key order: {out}");
    let doc = json(&run);
    assert_eq!(doc["formula"], "ciddor", "{doc}");
    // NIST's calculator: n = 1.000271373 at 20 °C, 101.325 kPa, 50 %, 633 nm; λ_air = λ₀ / n.
    close(&doc["n"], 1.000_271_373, "n");
    let lambda_air = doc["air_wavelength_nm"].as_f64().unwrap();
    assert!(
        (lambda_air - 633.0 / 1.000_271_373).abs() < 1e-6,
        "{lambda_air}"
    );
    close(&doc["temp_c"], 20.0, "temp_c");
    close(&doc["pressure_kpa"], 101.325, "pressure_kpa");
    close(&doc["humidity_pct"], 50.0, "humidity_pct");
    close(&doc["wavelength_nm"], 633.0, "wavelength_nm");
    close(&doc["co2_ppm"], 450.0, "co2_ppm");
}

/// Colours of the forward and reverse series of the linear chart (src/linear/chart.rs).
const FORWARD_RGB: [u8; 3] = [31, 90, 200];
const REVERSE_RGB: [u8; 3] = [200, 40, 40];

/// How many pixels of `img` are exactly `rgb`.
fn pixels(img: &image::RgbImage, rgb: [u8; 3]) -> usize {
    img.pixels().filter(|p| p.0 == rgb).count()
}
