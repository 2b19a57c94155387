//! Scaling of one part with its points: generated scans (`errmap_synth::scan`) of 1k, 10k, 100k and 1M points mapped end to end by the errmap binary (`errmap batch`, cpu backend), with wall time, time per point and peak RSS of the child.
//!
//! `cargo bench --bench scale_bench` (all four sizes) or
//! `cargo bench --bench scale_bench -- --sizes 1000,10000 --epochs 400 --out-dir DIR`.
//! `cargo bench --bench scale_bench -- --compare-kriging` instead compares the exact kriging
//! with the local one on the sizes where both run (hold-out RMS and time).
//! Wall and CPU (user + system) seconds and peak RSS come from GNU time (`/usr/bin/time -f
//! '%e %U %S %M'`: RSS is the errmap process's maximum resident set size); without
//! /usr/bin/time the bench says so and stops. The map of every size is also judged against the scan's known truth (RMS of map − truth over the map grid inside
//! the floor), so a faster but worse map shows here.

use errmap::synth::scan::{truth_um, write_scan, ScanSpec};
use std::path::{Path, PathBuf};
use std::process::Command;

fn arg_value(args: &[String], flag: &str) -> Option<String> {
    args.iter()
        .position(|a| a == flag)
        .and_then(|k| args.get(k + 1).cloned())
}

/// RMS of the delivered map (map.csv) against the truth over its nodes, µm.
fn map_error_rms_um(map_csv: &Path) -> Option<f64> {
    let text = std::fs::read_to_string(map_csv).ok()?;
    let mut sum = 0.0;
    let mut n = 0usize;
    for line in text.lines().skip(1) {
        let v: Vec<f64> = line.split(',').filter_map(|x| x.parse().ok()).collect();
        if v.len() >= 3 {
            sum += (v[2] - truth_um(v[0], v[1])).powi(2);
            n += 1;
        }
    }
    (n > 0).then(|| (sum / n as f64).sqrt())
}

/// The exact and the local kriging of the same scan points (every 10th held out), each judged
/// at the held-out points: RMS of the misses against the measured values and against the truth.
fn compare_kriging(sizes: &[usize]) {
    use errmap::interp::kriging::Kriging;
    use errmap::interp::local::LocalKriging;
    println!(
        "{:>7} {:>14} {:>14} {:>14} {:>14} {:>9} {:>9}",
        "points",
        "exact_miss_um",
        "local_miss_um",
        "exact_truth_um",
        "local_truth_um",
        "exact_s",
        "local_s"
    );
    for &n in sizes {
        let dir = tempfile::tempdir().expect("a temporary folder");
        let files = write_scan(
            &ScanSpec {
                points: n,
                chips_per_million: 0,
                ..ScanSpec::default()
            },
            dir.path(),
        )
        .expect("write the scan");
        let text = std::fs::read_to_string(&files.probes).expect("read the scan");
        let pts: Vec<[f64; 3]> = text
            .lines()
            .skip(1)
            .map(|l| {
                let v: Vec<f64> = l
                    .split(',')
                    .map(|x| x.parse().unwrap_or(f64::NAN))
                    .collect();
                [v[0], v[1], (v[2] - 5.0) * 1000.0]
            })
            .collect();
        // The scan's one chip (a gross error) would dominate either figure: left out of both.
        let good = |k: &usize| !files.chips.contains(k);
        let held: Vec<(usize, [f64; 3])> = pts
            .iter()
            .copied()
            .enumerate()
            .filter(|(k, _)| k % 10 == 5 && good(k))
            .collect();
        let kept: Vec<[f64; 3]> = pts
            .iter()
            .enumerate()
            .filter(|(k, _)| k % 10 != 5 && good(k))
            .map(|(_, p)| *p)
            .collect();
        let rms = |f: &dyn Fn(f64, f64) -> f64, truth: bool| {
            let s: f64 = held
                .iter()
                .map(|(_, p)| {
                    let want = if truth { truth_um(p[0], p[1]) } else { p[2] };
                    (want - f(p[0], p[1])).powi(2)
                })
                .sum();
            (s / held.len() as f64).sqrt()
        };
        let t = std::time::Instant::now();
        let exact = Kriging::fit(&kept).expect("exact kriging");
        let exact_s = t.elapsed().as_secs_f64();
        let t = std::time::Instant::now();
        let local = LocalKriging::fit(&kept).expect("local kriging");
        let at: Vec<[f64; 2]> = held.iter().map(|(_, p)| [p[0], p[1]]).collect();
        let local_e: Vec<f64> = local
            .predict_many(&at)
            .into_iter()
            .map(|q| q.map_or(f64::NAN, |q| q.e_um))
            .collect();
        let local_s = t.elapsed().as_secs_f64();
        let local_at = |u: f64, v: f64| {
            let k = at.iter().position(|a| a[0] == u && a[1] == v).unwrap_or(0);
            local_e[k]
        };
        let exact_at = |u: f64, v: f64| exact.predict(u, v);
        println!(
            "{n:>7} {:>14.4} {:>14.4} {:>14.4} {:>14.4} {exact_s:>9.2} {local_s:>9.3}",
            rms(&exact_at, false),
            rms(&local_at, false),
            rms(&exact_at, true),
            rms(&local_at, true),
        );
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.iter().any(|a| a == "--compare-kriging") {
        let sizes: Vec<usize> = arg_value(&args, "--sizes")
            .unwrap_or_else(|| "250,500,1000,2000".into())
            .split(',')
            .filter_map(|s| s.trim().parse().ok())
            .collect();
        compare_kriging(&sizes);
        return;
    }
    let sizes: Vec<usize> = arg_value(&args, "--sizes")
        .unwrap_or_else(|| "1000,10000,100000,1000000".into())
        .split(',')
        .filter_map(|s| s.trim().parse().ok())
        .collect();
    let epochs: u32 = arg_value(&args, "--epochs")
        .and_then(|e| e.parse().ok())
        .unwrap_or(400);
    if !Path::new("/usr/bin/time").exists() {
        eprintln!("scale_bench: /usr/bin/time (GNU time) is missing, so peak RSS cannot be measured; install the `time` package");
        return;
    }
    let keep = arg_value(&args, "--out-dir").map(PathBuf::from);
    let temp = tempfile::tempdir().expect("a temporary folder");
    let root = keep.unwrap_or_else(|| temp.path().to_path_buf());
    let exe = env!("CARGO_BIN_EXE_errmap");
    println!(
        "{:>9} {:>9} {:>9} {:>11} {:>12} {:>9} {:>9} {:>10} {:>10} {:>8}",
        "points",
        "wall_s",
        "cpu_s",
        "us_per_pt",
        "peak_rss_mb",
        "rejected",
        "chips",
        "holdout_um",
        "kriging_um",
        "truth_um"
    );
    let mut per_point = Vec::new();
    for &n in &sizes {
        let dir = root.join(format!("scan-{n}"));
        let files = write_scan(
            &ScanSpec {
                points: n,
                epochs,
                ..ScanSpec::default()
            },
            &dir,
        )
        .expect("write the scan");
        let out = dir.join("out");
        let run = Command::new("/usr/bin/time")
            .args(["-f", "%e %U %S %M", exe, "batch"])
            .arg(&files.job)
            .arg("--out-dir")
            .arg(&out)
            .args(["--backend", "cpu", "--quiet"])
            .output()
            .expect("run errmap");
        let stderr = String::from_utf8_lossy(&run.stderr);
        let last = stderr.lines().last().unwrap_or("");
        let mut fields = last.split_whitespace();
        let mut number = || -> f64 {
            fields
                .next()
                .and_then(|x| x.parse().ok())
                .unwrap_or(f64::NAN)
        };
        let wall_s = number();
        let cpu_s = number() + number();
        let rss_kb = number();
        if !run.status.success() {
            eprintln!("errmap failed on {n} points: {stderr}");
        }
        let summary: serde_json::Value = std::fs::read_to_string(out.join("summary.json"))
            .ok()
            .and_then(|t| serde_json::from_str(&t).ok())
            .unwrap_or_default();
        let part = &summary["parts"][0];
        let figure = |k: &str| part[k].as_f64().map_or("-".into(), |v| format!("{v:.3}"));
        let truth = map_error_rms_um(&out.join("scan").join("map.csv"))
            .map_or("-".into(), |v| format!("{v:.3}"));
        let us = wall_s * 1e6 / n as f64;
        per_point.push(us);
        println!(
            "{n:>9} {wall_s:>9.2} {cpu_s:>9.2} {us:>11.1} {:>12.0} {:>9} {:>9} {:>10} {:>10} {:>8}",
            rss_kb / 1024.0,
            part["rejected"].as_u64().unwrap_or(0),
            files.chips.len(),
            figure("holdout_rmse_um"),
            figure("kriging_holdout_rmse_um"),
            truth
        );
    }
    if let (Some(lo), Some(hi)) = (
        per_point.iter().copied().reduce(f64::min),
        per_point.iter().copied().reduce(f64::max),
    ) {
        println!(
            "time per point: {lo:.1} to {hi:.1} µs (largest / smallest {:.2})",
            hi / lo
        );
    }
}
