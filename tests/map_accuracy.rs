//! The delivered map against a kriging baseline on a planted plate unlike the sample: the map's RMSE against the generator's truth must be no worse than the Gaussian-process baseline's.

mod common;

use errmap::interp::kriging::Kriging;
use errmap::synth::web_plate::Truth;
use serde_json::Value;
use std::path::Path;

fn rows(path: &Path) -> Vec<Vec<f64>> {
    let text = std::fs::read_to_string(path).unwrap();
    text.lines()
        .skip(1)
        .filter(|l| !l.trim().is_empty())
        .map(|l| l.split(',').map(|v| v.trim().parse().unwrap()).collect())
        .collect()
}

#[test]
fn the_default_map_is_no_worse_than_kriging_on_an_unseen_plate() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // Unlike the sample (600 × 300 mm at the origin, a regular 8-part grid): one 450 × 250 mm
    // plate at (−120, 35), 110 irregularly placed points, another seed of the truth.
    common::ok(
        d,
        &[
            "synth",
            "web-plate",
            "--parts",
            "1",
            "--out-dir",
            "data",
            "--size",
            "450x250",
            "--origin",
            "-120,35",
            "--irregular",
            "110",
            "--seed",
            "7",
        ],
    );
    common::errmap_with(
        d,
        &[
            "batch",
            "data/job.toml",
            "--backend",
            "cpu",
            "--out-dir",
            "out",
            "--quiet",
        ],
        |cmd| {
            cmd.env_remove("SLURM_ARRAY_TASK_ID")
                .env_remove("JOB_COMPLETION_INDEX");
        },
    )
    .expect_code(0);
    let truth = Truth::read(&d.join("data/truth.json")).unwrap();
    let [x0, y0, x1, y1] = truth.probed_mm;
    // The baseline: kriging of the same clean points (what the pipeline kept).
    let clean: Vec<[f64; 3]> = rows(&d.join("out/p01/clean.csv"))
        .iter()
        .map(|r| [r[0], r[1], r[3]])
        .collect();
    let gp = Kriging::fit(&clean).unwrap();
    let (mut map_sq, mut gp_sq, mut n) = (0.0, 0.0, 0usize);
    for r in rows(&d.join("out/p01/map.csv")) {
        let (x, y, e) = (r[0], r[1], r[2]);
        if x < x0 || x > x1 || y < y0 || y > y1 {
            continue;
        }
        let t = truth.e_um(0, x, y).unwrap();
        map_sq += (e - t).powi(2);
        gp_sq += (gp.predict(x, y) - t).powi(2);
        n += 1;
    }
    assert!(n > 1000, "{n} map nodes in the probed area");
    let (map_rmse, gp_rmse) = ((map_sq / n as f64).sqrt(), (gp_sq / n as f64).sqrt());
    eprintln!("map RMSE {map_rmse:.3} µm against the truth, kriging baseline {gp_rmse:.3} µm");
    assert!(
        map_rmse <= gp_rmse,
        "map RMSE {map_rmse:.3} µm against the truth, kriging baseline {gp_rmse:.3} µm"
    );
    // The summary shows both hold-out figures and which fits better.
    let s: Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("out/p01/summary.json")).unwrap())
            .unwrap();
    let network = s["holdout_rmse_um"].as_f64().unwrap();
    let kriging = s["kriging_holdout_rmse_um"].as_f64().unwrap();
    let better = if kriging < network {
        "kriging"
    } else {
        "network"
    };
    assert_eq!(s["better_fit"], better);
}
