//! "Benefit before use": a map records the share of E it removes at its held-out points, and
//! `errmap compensate` (and a batch's toolpaths) refuse a map removing under 10 % of it.

mod common;

use common::errmap;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use std::path::Path;

/// Noise σ of the flat plate, µm.
const NOISE_UM: f64 = 3.0;

/// A flat plate at z = 5 mm probed on a 14 × 12 grid (10 mm pitch), each point off by seeded
/// Gaussian noise alone: nothing a map could learn.
fn write_noise_plate(path: &Path) {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let noise = Normal::new(0.0, NOISE_UM / 1000.0).unwrap();
    let mut csv = String::from("x_mm,y_mm,z_mm\n");
    for j in 0..12 {
        for i in 0..14 {
            let z = 5.0 + noise.sample(&mut rng);
            csv.push_str(&format!("{},{},{z:.6}\n", i * 10, j * 10));
        }
    }
    std::fs::write(path, csv).unwrap();
}

fn map_part(dir: &Path, probes: &str, out: &str) {
    errmap(
        dir,
        &[
            "map",
            probes,
            "--out-dir",
            out,
            "--nominal-plane",
            "5",
            "--epochs",
            "60",
            "--backend",
            "cpu",
            "--quiet",
        ],
    )
    .expect_code(0);
}

fn read_json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// A short program cutting across the middle of the plate at the probed surface.
const PROGRAM: &str = "%\nG21 G90\nG0 X40 Y40 Z10\nG1 Z5 F100\nG1 X80 Y60\nG0 Z10\nM2\n%\n";

fn compensate(dir: &Path, model: &str, out: &str, extra: &[&str]) -> common::Run {
    let mut args = vec![
        "compensate",
        "--model",
        model,
        "--dialect",
        "linuxcnc",
        "in.ngc",
        "-o",
        out,
    ];
    args.extend_from_slice(extra);
    errmap(dir, &args)
}

#[test]
fn a_map_of_noise_is_refused_unless_allowed() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    write_noise_plate(&d.join("noise.csv"));
    std::fs::write(d.join("in.ngc"), PROGRAM).unwrap();
    map_part(d, "noise.csv", "noise");
    let summary = read_json(&d.join("noise/summary.json"));
    let part = &summary;
    // The held-out E is the noise itself: its RMS is about σ (17 points: within ±50 %).
    let e_rms = part["holdout_e_rms_um"].as_f64().unwrap();
    assert!(
        (0.5 * NOISE_UM..1.5 * NOISE_UM).contains(&e_rms),
        "{summary}"
    );
    // Noise cannot be predicted at points the fit never saw: the share is about zero or below.
    let share = part["benefit_share"].as_f64().unwrap();
    assert!(share < 0.10, "{summary}");
    let model = read_json(&d.join("noise/model.json"));
    assert_eq!(model["benefit"]["share"].as_f64(), Some(share));

    let out = compensate(d, "noise/model.json", "out.ngc", &[]);
    out.expect_code(2);
    let err = out.stderr.as_str();
    assert!(
        err.contains("noise/model.json")
            && err.contains(&format!("{e_rms:.3} µm"))
            && err.contains(&format!("{:.1} %", share * 100.0))
            && err.contains("--allow-weak-map"),
        "{}",
        out.report()
    );
    assert!(!d.join("out.ngc").exists());
    let out = compensate(d, "noise/model.json", "out.ngc", &["--allow-weak-map"]);
    out.expect_code(0);
    assert!(d.join("out.ngc").is_file());
    assert!(!out.stderr.contains("benefit"), "{}", out.report());

    // The batch: that toolpath failed (exit 1) unless [toolpaths] allow_weak_map.
    std::fs::create_dir(d.join("probes")).unwrap();
    std::fs::copy(d.join("noise.csv"), d.join("probes/p01.csv")).unwrap();
    let job = |allow: bool| {
        format!(
            "family = \"flat\"\nnominal_plane_mm = 5\n[model]\nepochs = 60\nbackend = \"cpu\"\n\
             [toolpaths]\nfiles = [\"in.ngc\"]\ndialect = \"linuxcnc\"\nmap = \"part\"\nallow_weak_map = {allow}\n"
        )
    };
    std::fs::write(d.join("job.toml"), job(false)).unwrap();
    let out = errmap(d, &["batch", "job.toml", "--out-dir", "b1", "--quiet"]);
    out.expect_code(1);
    let summary = read_json(&d.join("b1/summary.json"));
    let error = summary["toolpaths"][0]["error"].to_string();
    assert!(error.contains("allow_weak_map"), "{summary}");
    assert!(!error.contains("--allow-weak-map"), "{summary}");
    std::fs::write(d.join("job.toml"), job(true)).unwrap();
    let out = errmap(d, &["batch", "job.toml", "--out-dir", "b2", "--quiet"]);
    out.expect_code(0);
    let summary = read_json(&d.join("b2/summary.json"));
    assert!(summary["toolpaths"][0]["error"].is_null(), "{summary}");
}

#[test]
fn a_map_of_a_structured_surface_is_used() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    errmap(
        d,
        &[
            "synth",
            "web-plate",
            "--parts",
            "1",
            "--out-dir",
            "data",
            "--grid",
            "9x7",
        ],
    )
    .expect_code(0);
    map_part(d, "data/probes/p01.csv", "web");
    let summary = read_json(&d.join("web/summary.json"));
    let part = &summary;
    // The synthetic web plate's sag is tens of µm against 1 µm-class probe noise: the map
    // removes most of it at points it never saw.
    let share = part["benefit_share"].as_f64().unwrap();
    assert!(share > 0.5, "{summary}");
    // It is the delivered map's nested hold-out RMSE (each held-out point judged by the kind the
    // others chose) against the RMS of E at the same points. Each point's miss is one of the two
    // kinds' misses, so its square is at most their sum: delivered ≤ √(network² + kriging²).
    let delivered = part["delivered_holdout_rmse_um"].as_f64().unwrap();
    let (net, kri) = (
        part["holdout_rmse_um"].as_f64().unwrap(),
        part["kriging_holdout_rmse_um"].as_f64().unwrap(),
    );
    assert!(delivered > 0.0 && delivered <= net.hypot(kri), "{summary}");
    let e_rms = part["holdout_e_rms_um"].as_f64().unwrap();
    assert!(
        (share - (1.0 - delivered / e_rms)).abs() < 1e-12,
        "{summary}"
    );
    let model = read_json(&d.join("web/model.json"));
    let hull = model["hull_mm"].as_array().unwrap();
    let n = hull.len() as f64;
    let c = |k: usize| hull.iter().map(|p| p[k].as_f64().unwrap()).sum::<f64>() / n;
    let program = format!(
        "%\nG21 G90\nG0 X{:.3} Y{:.3} Z10\nG1 Z5 F100\nG0 Z10\nM2\n%\n",
        c(0),
        c(1)
    );
    std::fs::write(d.join("in.ngc"), program).unwrap();
    let out = compensate(d, "web/model.json", "out.ngc", &[]);
    out.expect_code(0);
    assert!(!out.stderr.contains("benefit"), "{}", out.report());
}

#[test]
fn a_model_written_before_the_figures_is_used_with_a_warning() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    std::fs::write(d.join("model.json"), common::FLAT_MODEL_20UM).unwrap();
    assert!(!common::FLAT_MODEL_20UM.contains("benefit"));
    std::fs::write(d.join("in.ngc"), PROGRAM).unwrap();
    let out = compensate(d, "model.json", "out.ngc", &["--zone", "all"]);
    out.expect_code(0);
    assert!(
        out.stderr.contains("warning: benefit unknown") && out.stderr.contains("model.json"),
        "{}",
        out.report()
    );
    assert!(d.join("out.ngc").is_file());
}
