//! A dense scan end to end: 50,000 points of a known surface with chips, mapped by `errmap batch`; the chips go, the map matches the truth, every figure exists; and a scan beyond the memory bound is refused before it is read.

mod common;

use common::errmap;
use errmap::synth::scan::{truth_um, write_scan, ScanSpec, SCAN_RECT_MM};
use std::path::Path;

fn read_json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn a_dense_scan_is_binned_cleaned_and_mapped_close_to_its_truth() {
    let dir = tempfile::tempdir().unwrap();
    let files = write_scan(
        &ScanSpec {
            points: 50_000,
            chips_per_million: 400,
            ..ScanSpec::default()
        },
        dir.path(),
    )
    .unwrap();
    let job = files.job.to_string_lossy().to_string();
    errmap(dir.path(), &["batch", &job, "--out-dir", "out", "--quiet"]).expect_code(0);
    let part = dir.path().join("out/scan");
    let summary = read_json(&dir.path().join("out/summary.json"));
    let p = &summary["parts"][0];
    assert_eq!(p["points"].as_u64(), Some(50_000));

    // Every chip (+40 µm against 1 µm noise) rejected, and at most 0.3 % of the good points
    // (3σ rejects 0.27 % of normal noise).
    let coords = |text: &str| -> Vec<[f64; 2]> {
        text.lines()
            .skip(1)
            .map(|l| {
                let v: Vec<f64> = l.split(',').map(|x| x.parse().unwrap()).collect();
                [v[0], v[1]]
            })
            .collect()
    };
    let probes = coords(&std::fs::read_to_string(&files.probes).unwrap());
    let rejected = coords(&std::fs::read_to_string(part.join("rejected.csv")).unwrap());
    for &k in &files.chips {
        assert!(
            rejected
                .iter()
                .any(|r| (r[0] - probes[k][0]).abs() < 1e-9 && (r[1] - probes[k][1]).abs() < 1e-9),
            "chip {k} at {:?} kept",
            probes[k]
        );
    }
    let good_rejected = rejected.len() - files.chips.len();
    assert!(good_rejected <= 150, "{good_rejected} good points rejected");

    // The map against the truth, at the nodes inside the scanned floor: the noise averages
    // out in the bins, so the map is closer to the truth than one point's noise (1 µm).
    let map = std::fs::read_to_string(part.join("map.csv")).unwrap();
    let [x0, y0, x1, y1] = SCAN_RECT_MM;
    let (mut sum, mut n) = (0.0, 0usize);
    for line in map.lines().skip(1) {
        let v: Vec<f64> = line.split(',').map(|x| x.parse().unwrap()).collect();
        if (x0..=x1).contains(&v[0]) && (y0..=y1).contains(&v[1]) {
            sum += (v[2] - truth_um(v[0], v[1])).powi(2);
            n += 1;
        }
    }
    let rms = (sum / n as f64).sqrt();
    assert!(
        n > 6000 && rms < 0.8,
        "map − truth RMS {rms} µm over {n} nodes"
    );

    // The hold-out, the kriging baseline (local at this size), the benefit and u(E) exist.
    for key in [
        "holdout_rmse_um",
        "kriging_holdout_rmse_um",
        "delivered_holdout_rmse_um",
        "benefit_share",
        "u_median_um",
    ] {
        assert!(p[key].as_f64().is_some(), "{key} missing: {p}");
    }
    // Held-out misses are noise (1 µm) plus the map's error: near 1 µm.
    let holdout = p["delivered_holdout_rmse_um"].as_f64().unwrap();
    assert!((0.9..1.3).contains(&holdout), "hold-out RMS {holdout} µm");
}

#[test]
fn a_scan_beyond_the_memory_bound_is_refused_naming_the_bound() {
    let dir = tempfile::tempdir().unwrap();
    let files = write_scan(
        &ScanSpec {
            points: 20_000,
            ..ScanSpec::default()
        },
        dir.path(),
    )
    .unwrap();
    let job = files.job.to_string_lossy().to_string();
    // 20,001 lines need 100 MB + 20,001 · 1500 B ≈ 131 MB: 120 MB is too little.
    let run = errmap(
        dir.path(),
        &["batch", &job, "--out-dir", "out", "--max-memory-mb", "120"],
    );
    run.expect_code(1);
    let summary = read_json(&dir.path().join("out/summary.json"));
    let error = summary["parts"][0]["error"].to_string();
    assert!(
        error.contains("120 MB")
            && error.contains("--max-memory-mb")
            && error.contains("max_memory_mb"),
        "{error}"
    );
    // `errmap map` of the one scan: exit 2 with the same words; the job key works too.
    let probes = files.probes.to_string_lossy().to_string();
    let run = errmap(
        dir.path(),
        &[
            "map",
            &probes,
            "--out-dir",
            "one",
            "--nominal-plane",
            "5",
            "--max-memory-mb",
            "120",
        ],
    );
    run.expect_code(2);
    assert!(run.stderr.contains("--max-memory-mb"), "{}", run.stderr);
    let text = std::fs::read_to_string(&files.job).unwrap();
    std::fs::write(
        &files.job,
        text.replace(
            "family = \"scan\"",
            "family = \"scan\"\nmax_memory_mb = 120",
        ),
    )
    .unwrap();
    errmap(dir.path(), &["batch", &job, "--out-dir", "out2"]).expect_code(1);
    let error = read_json(&dir.path().join("out2/summary.json"))["parts"][0]["error"].to_string();
    assert!(error.contains("120 MB"), "{error}");
}
