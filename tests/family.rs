//! End-to-end tests of the family pipeline: the real `errmap` binary on web-plate families generated with known truth.
//!
//! Accuracy is judged against the generator's analytic truth (`truth.json`), never against an
//! earlier output of the pipeline: planted outliers must be rejected, the map must match the
//! truth inside the probed area, and re-machining with the compensated program must remove most
//! of the error.

mod common;

use common::Run;
use errmap::synth::web_plate::Truth;
use std::path::{Path, PathBuf};

/// Run errmap in `cwd`; a scheduler's shard index in the test's own environment is removed so
/// it cannot split these batches.
fn errmap(args: &[&str], cwd: &Path) -> Run {
    common::errmap_with(cwd, args, |cmd| {
        for var in [
            "SLURM_ARRAY_TASK_ID",
            "SLURM_ARRAY_TASK_COUNT",
            "JOB_COMPLETION_INDEX",
        ] {
            cmd.env_remove(var);
        }
    })
}

/// Run errmap and require an exit code.
#[track_caller]
fn run_expect(args: &[&str], cwd: &Path, code: i32) -> Run {
    let run = errmap(args, cwd);
    run.expect_code(code);
    run
}

/// `errmap synth web-plate --parts <parts> --out-dir data <extra…>`, which must succeed.
#[track_caller]
fn synth_family(cwd: &Path, parts: &str, extra: &[&str]) {
    let mut args = vec!["synth", "web-plate", "--parts", parts, "--out-dir", "data"];
    args.extend_from_slice(extra);
    run_expect(&args, cwd, 0);
}

/// `errmap batch data/job.toml --backend <backend> --out-dir <out> --quiet <extra…>`.
fn batch_args<'a>(backend: &'a str, out: &'a str, extra: &[&'a str]) -> Vec<&'a str> {
    let mut args = vec![
        "batch",
        "data/job.toml",
        "--backend",
        backend,
        "--out-dir",
        out,
        "--quiet",
    ];
    args.extend_from_slice(extra);
    args
}

/// Run the batch of `batch_args` and require an exit code.
#[track_caller]
fn batch(cwd: &Path, backend: &str, out: &str, code: i32) -> Run {
    run_expect(&batch_args(backend, out, &[]), cwd, code)
}

fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<f64>>) {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut lines = text.lines();
    let header: Vec<String> = lines
        .next()
        .unwrap()
        .split(',')
        .map(str::to_string)
        .collect();
    let rows = lines
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            l.split(',')
                .map(|v| v.trim().parse::<f64>().unwrap())
                .collect()
        })
        .collect();
    (header, rows)
}

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
}

fn pv(v: &[f64]) -> f64 {
    let max = v.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    let min = v.iter().cloned().fold(f64::INFINITY, f64::min);
    max - min
}

/// Points (x, y, z) where the tool cuts inside the zone, from a G-code program in G21 G90
/// (what `synth web-plate` writes): every programmed end point, and after compensation every
/// emitted point of the split/linearised moves.
fn cutting_points(ngc: &Path, zone: (f64, f64)) -> Vec<(f64, f64, f64)> {
    let text = std::fs::read_to_string(ngc).unwrap_or_else(|e| panic!("{}: {e}", ngc.display()));
    let mut pos = [0.0f64; 3];
    let mut motion = 0;
    let mut points = Vec::new();
    for line in text.lines() {
        // Drop comments.
        let mut code = String::new();
        let mut depth = 0;
        for c in line.chars() {
            match c {
                '(' => depth += 1,
                ')' => depth -= 1,
                ';' if depth == 0 => break,
                _ if depth == 0 => code.push(c),
                _ => {}
            }
        }
        let code = code.to_ascii_uppercase();
        let words: Vec<(char, f64)> = {
            let mut w = Vec::new();
            let chars: Vec<char> = code.chars().filter(|c| !c.is_whitespace()).collect();
            let mut i = 0;
            while i < chars.len() {
                let letter = chars[i];
                let mut j = i + 1;
                while j < chars.len()
                    && (chars[j].is_ascii_digit()
                        || chars[j] == '.'
                        || chars[j] == '-'
                        || chars[j] == '+')
                {
                    j += 1;
                }
                if letter.is_ascii_alphabetic() {
                    let num: String = chars[i + 1..j].iter().collect();
                    if let Ok(v) = num.parse::<f64>() {
                        w.push((letter, v));
                    }
                }
                i = j.max(i + 1);
            }
            w
        };
        let mut moved = false;
        for &(l, v) in &words {
            match l {
                'G' if [0.0, 1.0, 2.0, 3.0].contains(&v) => motion = v as i32,
                'X' => {
                    pos[0] = v;
                    moved = true
                }
                'Y' => {
                    pos[1] = v;
                    moved = true
                }
                'Z' => {
                    pos[2] = v;
                    moved = true
                }
                _ => {}
            }
        }
        if moved && motion != 0 && pos[2] >= zone.0 && pos[2] <= zone.1 {
            points.push((pos[0], pos[1], pos[2]));
        }
    }
    points
}

/// Truth of a part (or the family mean with `part = None`) at (x, y), µm.
fn truth_at(truth: &Truth, part: Option<usize>, x: f64, y: f64) -> f64 {
    match part {
        Some(k) => truth.e_um(k, x, y).unwrap(),
        None => truth.family_e_um(x, y),
    }
}

/// The checks of the issue on one generated family mapped into `out`.
fn check_family(data: &Path, out: &Path, truth: &Truth) {
    let [x0, y0, x1, y1] = truth.probed_mm;
    // Rows minus the header and the two repeated measurements.
    let points_per_part = std::fs::read_to_string(data.join("probes/p01.csv"))
        .unwrap()
        .lines()
        .count()
        - 3;
    for (k, part) in truth.parts.iter().enumerate() {
        let dir = out.join(&part.part);
        // Every planted outlier rejected; at most 2 % of the good points.
        let (_, rejected) = read_csv(&dir.join("rejected.csv"));
        let planted: Vec<_> = truth
            .outliers
            .iter()
            .filter(|o| o.part == part.part)
            .collect();
        for o in &planted {
            assert!(
                rejected
                    .iter()
                    .any(|r| (r[0] - o.x_mm).abs() < 1e-3 && (r[1] - o.y_mm).abs() < 1e-3),
                "{}: planted outlier {} at ({}, {}) not rejected: {rejected:?}",
                part.part,
                o.id,
                o.x_mm,
                o.y_mm
            );
        }
        let good_rejected = rejected.len() - planted.len();
        let good = points_per_part - planted.len();
        assert!(
            good_rejected as f64 <= 0.02 * good as f64,
            "{}: {good_rejected} of {good} good points rejected",
            part.part
        );
        // Map vs truth inside the probed area.
        let (header, map) = read_csv(&dir.join("map.csv"));
        assert_eq!(header, ["x_mm", "y_mm", "e_um", "u_um"]);
        let errors: Vec<f64> = map
            .iter()
            .filter(|r| r[0] >= x0 && r[0] <= x1 && r[1] >= y0 && r[1] <= y1)
            .map(|r| r[2] - truth_at(truth, Some(k), r[0], r[1]))
            .collect();
        assert!(
            errors.len() > 100,
            "{} map nodes inside the probed area",
            errors.len()
        );
        let map_rms = rms(&errors);
        eprintln!("{}: map RMS error vs truth {map_rms:.3} µm, {} planted + {good_rejected} good rejected", part.part, planted.len());
        assert!(
            map_rms <= 1.5,
            "{}: map RMS error vs truth {map_rms:.3} µm",
            part.part
        );
        for f in ["map.png", "model.json", "clean.csv", "summary.json"] {
            assert!(dir.join(f).is_file(), "{} missing", dir.join(f).display());
        }
    }
    // Re-machining with the compensated program: residual = truth − E applied.
    let comp = out.join("family/finish-compensated.ngc");
    let floor = truth.spec.floor_z_mm;
    // The floor: E is tens of µm, so ±0.2 mm keeps the cut and leaves out the plunge through the zone.
    let points = cutting_points(&comp, (floor - 0.2, floor + 0.2));
    let original = cutting_points(&data.join("finish.ngc"), (floor - 0.2, floor + 0.2));
    assert!(
        points.len() > 4 * original.len(),
        "long moves and arcs are split: {} points from {}",
        points.len(),
        original.len()
    );
    let before: Vec<f64> = points
        .iter()
        .map(|&(x, y, _)| truth_at(truth, None, x, y))
        .collect();
    let after: Vec<f64> = points
        .iter()
        .map(|&(x, y, z)| truth_at(truth, None, x, y) - (floor - z) * 1000.0)
        .collect();
    let rms_cut = 1.0 - rms(&after) / rms(&before);
    let pv_cut = 1.0 - pv(&after) / pv(&before);
    eprintln!(
        "re-machining at {} points: RMS {:.2} → {:.2} µm ({:.1} % cut), PV {:.2} → {:.2} µm ({:.1} % cut)",
        points.len(),
        rms(&before),
        rms(&after),
        100.0 * rms_cut,
        pv(&before),
        pv(&after),
        100.0 * pv_cut
    );
    assert!(
        rms_cut >= 0.85 && pv_cut >= 0.75,
        "RMS {:.2} → {:.2} µm ({:.0} %), PV {:.2} → {:.2} µm ({:.0} %)",
        rms(&before),
        rms(&after),
        100.0 * rms_cut,
        pv(&before),
        pv(&after),
        100.0 * pv_cut
    );
}

/// The committed sample family, `data/web-plate/` (the quick start's data).
fn sample_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("data/web-plate")
}

#[test]
fn committed_sample_is_what_its_readme_command_makes() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let readme = std::fs::read_to_string(sample_dir().join("README.md")).unwrap();
    let command = "errmap synth web-plate --parts 8 --warm-epochs 60 --out-dir data/web-plate";
    assert!(readme.contains(command), "{readme}");
    let args: Vec<&str> = command.split(' ').skip(1).collect();
    run_expect(&args, d, 0);
    let made = common::files(&d.join("data/web-plate"));
    let committed = common::files(&sample_dir());
    assert_eq!(made.len(), committed.len(), "{made:?} vs {committed:?}");
    for (m, c) in made.iter().zip(&committed) {
        assert!(
            std::fs::read(m).unwrap() == std::fs::read(c).unwrap(),
            "{} differs from the generator's",
            c.display()
        );
    }
}

#[test]
fn sample_family_rejects_outliers_matches_truth_and_compensation_removes_the_error() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let job = sample_dir().join("job.toml");
    let job = job.to_str().unwrap();
    let out = run_expect(
        &[
            "batch",
            job,
            "--backend",
            "cpu",
            "--out-dir",
            "out",
            "--quiet",
        ],
        d,
        0,
    );
    let stdout = out.stdout.as_str();
    assert!(
        stdout.contains("hold-out RMS µm") && stdout.contains("p08"),
        "{stdout}"
    );
    let truth = Truth::read(&sample_dir().join("truth.json")).unwrap();
    check_family(&sample_dir(), &d.join("out"), &truth);
    // The batch summary lists every part with its figures.
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("out/summary.json")).unwrap())
            .unwrap();
    let parts = summary["parts"].as_array().unwrap();
    assert_eq!(parts.len(), 8);
    for p in parts {
        assert_eq!(p["ok"], true);
        assert_eq!(p["points"], 144);
        let h = p["holdout_rmse_um"].as_f64().unwrap();
        // Held-out probe points carry 1 µm noise: the honest error cannot be far below it.
        assert!((0.5..2.5).contains(&h), "hold-out RMS {h}");
    }
    assert!(d.join("out/family/mean.png").is_file() && d.join("out/family/std.csv").is_file());
}

#[test]
fn unseen_plate_irregular_layout_nominal_columns_other_size_and_origin() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    synth_family(
        d,
        "1",
        &[
            "--size",
            "450x250",
            "--origin",
            "-120,35",
            "--irregular",
            "110",
            "--nominal-columns",
            "--seed",
            "7",
            "--epochs",
            "400",
        ],
    );
    let job = std::fs::read_to_string(d.join("data/job.toml")).unwrap();
    assert!(!job.contains("nominal_plane_mm"), "{job}");
    batch(d, "cpu", "out", 0);
    let truth = Truth::read(&d.join("data/truth.json")).unwrap();
    check_family(&d.join("data"), &d.join("out"), &truth);
}

#[test]
fn a_corrupt_part_is_reported_and_the_others_finish() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    synth_family(d, "2", &["--epochs", "30"]);
    std::fs::write(
        d.join("data/probes/p00.csv"),
        "id,x_mm,y_mm,z_mm\nA,30,30,5.001\nB,60,30,5.002\nC,30,60,abc\n",
    )
    .unwrap();
    // Each part's own map compensates its own copy of the program.
    let job = std::fs::read_to_string(d.join("data/job.toml")).unwrap();
    assert!(job.contains("map = \"family\""));
    let job = job.replace("map = \"family\"", "map = \"part\"");
    std::fs::write(d.join("data/job.toml"), job).unwrap();
    let out = batch(d, "cpu", "out", 1);
    let stdout = out.stdout.as_str();
    assert!(
        stdout.contains("p00") && stdout.contains("FAILED"),
        "{stdout}"
    );
    for part in ["p01", "p02"] {
        let comp = d.join("out").join(part).join("finish-compensated.ngc");
        assert!(comp.is_file(), "{}", comp.display());
    }
    assert!(!d.join("out/family/finish-compensated.ngc").exists());
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("out/summary.json")).unwrap())
            .unwrap();
    assert_eq!(summary["failed_parts"], 1);
    let parts = summary["parts"].as_array().unwrap();
    assert_eq!(parts.len(), 3);
    let bad = &parts[0];
    assert_eq!(bad["part"], "p00");
    assert_eq!(bad["ok"], false);
    // The error is data a script can act on: kind, place, message and fix.
    let err = &bad["error"];
    assert_eq!(err["kind"], "input", "{err}");
    assert!(err["file"].as_str().unwrap().ends_with("p00.csv"), "{err}");
    assert_eq!(err["line"], 4, "{err}");
    assert_eq!(err["column"], "z_mm", "{err}");
    assert!(
        err["message"]
            .as_str()
            .unwrap()
            .contains("'abc' is not a number"),
        "{err}"
    );
    assert!(err["hint"].is_string(), "{err}");
    for p in &parts[1..] {
        assert_eq!(p["ok"], true, "{p}");
        let dir = d.join("out").join(p["part"].as_str().unwrap());
        assert!(dir.join("map.csv").is_file() && dir.join("map.png").is_file());
    }
    assert!(!d.join("out/p00").exists());
    // No temporary file is left behind.
    assert!(common::files(d)
        .iter()
        .all(|p| !p.to_string_lossy().contains(".errmap-")));
}

#[test]
fn the_same_job_gives_the_same_bytes_on_the_cpu() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    synth_family(d, "2", &["--epochs", "40"]);
    // The run's date (run.json, report.html) is the one thing that differs between runs:
    // fixed here as reproducible builds fix it.
    let fixed_date = |c: &mut std::process::Command| {
        c.env("SOURCE_DATE_EPOCH", "1795450265");
    };
    common::errmap_with(d, &batch_args("cpu", "out", &[]), fixed_date).expect_code(0);
    let first: Vec<(PathBuf, Vec<u8>)> = common::files(&d.join("out"))
        .into_iter()
        .map(|p| (p.clone(), std::fs::read(&p).unwrap()))
        .collect();
    assert!(first.len() > 10);
    let run: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("out/run.json")).unwrap()).unwrap();
    assert_eq!(run["created_utc"], "2026-11-23T16:11:05Z");
    common::errmap_with(d, &batch_args("cpu", "out", &[]), fixed_date).expect_code(0);
    for (path, bytes) in &first {
        assert!(
            std::fs::read(path).unwrap() == *bytes,
            "{} changed between runs",
            path.display()
        );
    }
    assert_eq!(common::files(&d.join("out")).len(), first.len());
}

#[test]
fn shards_map_their_parts_and_merge_joins_the_summaries() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    synth_family(d, "3", &["--epochs", "20"]);
    for shard in ["0/2", "1/2"] {
        run_expect(&batch_args("cpu", "out", &["--shard", shard]), d, 0);
    }
    // Each shard maps its parts into its own folder, committed by its run.json.
    for p in ["shard-0-of-2/p01", "shard-1-of-2/p02", "shard-0-of-2/p03"] {
        assert!(d.join("out").join(p).join("map.csv").is_file(), "{p}");
    }
    assert!(d.join("out/shard-1-of-2/run.json").is_file());
    // Shard 0 of 2 took parts 1 and 3.
    let s0: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(d.join("out/shard-0-of-2/summary.json")).unwrap(),
    )
    .unwrap();
    let names: Vec<&str> = s0["parts"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["part"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["p01", "p03"]);
    let out = run_expect(
        &[
            "merge",
            "out/shard-1-of-2/summary.json",
            "out/shard-0-of-2",
            "--backend",
            "cpu",
            "--json",
        ],
        d,
        0,
    );
    let merged: serde_json::Value = serde_json::from_str(&out.stdout).unwrap();
    let names: Vec<&str> = merged["parts"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["part"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["p01", "p02", "p03"]);
    assert!(d.join("out/summary.json").is_file());
    // The merged folder is laid out as one machine's: the parts at out/<part>, no shard folder.
    let left: Vec<String> = common::listing(&d.join("out"))
        .into_iter()
        .filter(|f| !f.contains('/') || f.ends_with('/'))
        .collect();
    assert_eq!(
        left,
        [
            "family/",
            "p01/",
            "p02/",
            "p03/",
            "report.html",
            "run.json",
            "summary.json"
        ]
    );
    for p in ["p01", "p02", "p03"] {
        let s: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(d.join("out").join(p).join("summary.json")).unwrap(),
        )
        .unwrap();
        assert_eq!(
            s["output_dir"],
            format!("out/{p}"),
            "{p}'s summary names its folder"
        );
    }
    // The family maps are the node-wise mean and std of the three parts' maps.
    let maps: Vec<Vec<Vec<f64>>> = ["p01", "p02", "p03"]
        .iter()
        .map(|p| read_csv(&d.join("out").join(p).join("map.csv")).1)
        .collect();
    let (_, mean) = read_csv(&d.join("out/family/mean.csv"));
    let (_, std) = read_csv(&d.join("out/family/std.csv"));
    assert_eq!(mean.len(), maps[0].len());
    for k in [0, mean.len() / 2, mean.len() - 1] {
        let v: Vec<f64> = maps.iter().map(|m| m[k][2]).collect();
        let mu = v.iter().sum::<f64>() / 3.0;
        let sd = (v.iter().map(|x| (x - mu).powi(2)).sum::<f64>() / 3.0).sqrt();
        assert!(
            (mean[k][2] - mu).abs() < 2e-4 && (std[k][2] - sd).abs() < 2e-4,
            "node {k}: {v:?}"
        );
        assert_eq!((mean[k][0], mean[k][1]), (maps[0][k][0], maps[0][k][1]));
    }
    assert!(d.join("out/family/mean.png").is_file() && d.join("out/family/std.png").is_file());
    // The reduce also fits the family network and compensates the family toolpath.
    assert!(d.join("out/family/model.json").is_file());
    assert!(d.join("out/family/finish-compensated.ngc").is_file());
    assert_eq!(merged["family_map"]["parts"], 3);
    // Merged once, the shards are in the run: a second merge says so.
    let out = run_expect(&["merge", "out", "--backend", "cpu"], d, 2);
    assert!(
        out.stderr.contains("is a merged run already"),
        "{}",
        out.report()
    );
    // A missing shard is an error naming it.
    run_expect(&batch_args("cpu", "out", &["--shard", "1/2"]), d, 0);
    let out = run_expect(&["merge", "out", "--backend", "cpu"], d, 2);
    assert!(
        out.stderr
            .as_str()
            .contains("shards [0] of 2 have no complete run"),
        "{}",
        out.report()
    );
}

#[test]
fn map_one_part_and_bad_inputs_name_file_line_and_column() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    synth_family(d, "1", &["--grid", "9x7"]);
    run_expect(
        &[
            "map",
            "data/probes/p01.csv",
            "--out-dir",
            "one",
            "--nominal-plane",
            "5",
            "--epochs",
            "30",
            "--backend",
            "cpu",
            "--quiet",
        ],
        d,
        0,
    );
    for f in [
        "map.csv",
        "map.png",
        "model.json",
        "clean.csv",
        "rejected.csv",
        "summary.json",
    ] {
        assert!(d.join("one").join(f).is_file(), "{f} missing");
    }
    // The domain defaults to the probes' bounding box: the map's first node is the first probe.
    let (_, map) = read_csv(&d.join("one/map.csv"));
    let truth = Truth::read(&d.join("data/truth.json")).unwrap();
    assert_eq!(
        (map[0][0], map[0][1]),
        (truth.probed_mm[0], truth.probed_mm[1])
    );
    // A wall: E along x over the y,z plane, nominal plane x = 100 mm, E = 10 µm + 20 µm·z/40.
    let mut wall = String::from("x_mm,y_mm,z_mm\n");
    for j in 0..6 {
        for i in 0..8 {
            let (y, z) = (i as f64 * 20.0, j as f64 * 8.0);
            wall.push_str(&format!(
                "{:.4},{y},{z}\n",
                100.0 + (10.0 + 20.0 * z / 40.0) / 1000.0
            ));
        }
    }
    std::fs::write(d.join("wall.csv"), wall).unwrap();
    run_expect(
        &[
            "map",
            "wall.csv",
            "--normal",
            "x",
            "--nominal-plane",
            "100",
            "--out-dir",
            "wall",
            "--grid-step",
            "4",
            "--epochs",
            "300",
            "--backend",
            "cpu",
            "--quiet",
        ],
        d,
        0,
    );
    let (header, map) = read_csv(&d.join("wall/map.csv"));
    assert_eq!(header, ["y_mm", "z_mm", "e_um", "u_um"]);
    // Nodes run u (y) fastest over the bounding box y 0…140, z 0…40.
    assert_eq!((map[1][0], map[1][1]), (4.0, 0.0));
    assert_eq!(map.last().unwrap()[1], 40.0);
    let worst = map
        .iter()
        .map(|r| (r[2] - (10.0 + 20.0 * r[1] / 40.0)).abs())
        .fold(0.0, f64::max);
    assert!(worst < 2.0, "wall map off the plane by {worst} µm");
    // A probe file without z_mm.
    std::fs::write(d.join("bad.csv"), "x_mm,y_mm\n1,2\n").unwrap();
    let out = run_expect(
        &[
            "map",
            "bad.csv",
            "--out-dir",
            "bad",
            "--nominal-plane",
            "5",
            "--backend",
            "cpu",
        ],
        d,
        2,
    );
    let err = out.stderr.as_str();
    assert!(
        err.contains("bad.csv:1") && err.contains("missing column 'z_mm'"),
        "{err}"
    );
    // A job with a misspelt key.
    std::fs::write(
        d.join("data/typo.toml"),
        "family = \"f\"\n[clean]\nk_sigm = 2\n",
    )
    .unwrap();
    let out = run_expect(&["batch", "data/typo.toml"], d, 2);
    let err = out.stderr.as_str();
    assert!(
        err.contains("typo.toml:3, column 1") && err.contains("k_sigm"),
        "{err}"
    );
}

/// Issue 3's end-to-end check on both backends: the same small job trained with the wgpu
/// trainer (lavapipe where there is no GPU) and with the CPU reference gives the same maps,
/// within the trainers' parity bound (0.05 µm). Skips without a Vulkan adapter unless
/// ERRMAP_REQUIRE_GPU=1.
#[test]
fn the_family_job_gives_the_same_maps_on_the_gpu_and_the_cpu() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    synth_family(d, "2", &["--epochs", "60"]);
    let gpu = errmap(&batch_args("gpu", "gpu", &[]), d);
    if gpu.code == 3 && std::env::var("ERRMAP_REQUIRE_GPU").as_deref() != Ok("1") {
        eprintln!(
            "skipping the GPU end-to-end test: no usable adapter ({})",
            gpu.stderr.trim()
        );
        return;
    }
    gpu.expect_code(0);
    batch(d, "cpu", "cpu", 0);
    let mut compared = 0;
    for part in ["p01", "p02", "family"] {
        let map_name = if part == "family" {
            "mean.csv"
        } else {
            "map.csv"
        };
        let (gpu_header, gpu_rows) = read_csv(&d.join("gpu").join(part).join(map_name));
        let (cpu_header, cpu_rows) = read_csv(&d.join("cpu").join(part).join(map_name));
        assert_eq!(gpu_header, cpu_header);
        assert_eq!(gpu_rows.len(), cpu_rows.len(), "{part}: grid sizes differ");
        assert!(!gpu_rows.is_empty());
        let differences: Vec<f64> = gpu_rows
            .iter()
            .zip(&cpu_rows)
            .map(|(g, c)| {
                assert_eq!(g[..2], c[..2], "{part}: grid nodes differ");
                g[2] - c[2]
            })
            .collect();
        let rms_difference_um = rms(&differences);
        assert!(
            rms_difference_um < 0.05,
            "{part}: GPU and CPU maps differ by {rms_difference_um} µm RMS"
        );
        compared += 1;
    }
    assert_eq!(compared, 3);
}

/// The elements an HTML page may leave unclosed (void elements, and SVG shapes written `/>`).
const VOID_ELEMENTS: [&str; 7] = ["meta", "img", "br", "hr", "link", "input", "col"];

/// Whether `html` is a well-formed document: a doctype, then every element closed in the order
/// it was opened (void elements and `<…/>` excepted). A tag stack, independent of the renderer.
#[track_caller]
fn assert_well_formed(html: &str, what: &str) {
    assert!(html.starts_with("<!DOCTYPE html>\n"), "{what}: no doctype");
    let mut open: Vec<String> = Vec::new();
    let mut rest = &html["<!DOCTYPE html>".len()..];
    while let Some(at) = rest.find('<') {
        rest = &rest[at + 1..];
        let end = rest
            .find('>')
            .unwrap_or_else(|| panic!("{what}: unclosed tag"));
        let tag = &rest[..end];
        rest = &rest[end + 1..];
        if let Some(name) = tag.strip_prefix('/') {
            let top = open.pop();
            assert_eq!(
                top.as_deref(),
                Some(name.trim()),
                "{what}: </{name}> closes {top:?}"
            );
            continue;
        }
        let name: String = tag
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric())
            .collect();
        assert!(!name.is_empty(), "{what}: '<{tag}>' is not a tag");
        if tag.ends_with('/') || VOID_ELEMENTS.contains(&name.as_str()) {
            continue;
        }
        open.push(name);
    }
    assert!(open.is_empty(), "{what}: left open: {open:?}");
}

/// The rows of the table of parts `table` (the HTML from its `<table` on): each row's link
/// and part name.
fn table_rows(table: &str) -> Vec<(String, String)> {
    let table = &table[..table.find("</table>").expect("a closed table")];
    table
        .split("<tr><td><a href=\"")
        .skip(1)
        .map(|row| {
            let (href, rest) = row.split_once("\">").unwrap();
            let name = &rest[..rest.find("</a>").unwrap()];
            (href.to_string(), name.to_string())
        })
        .collect()
}

#[test]
fn a_generated_family_of_1000_parts_gets_a_sortable_overview_and_a_page_per_part() {
    // 1000 small parts (36 probe points on a 90 mm plate, 5 training steps): the family is
    // generated and mapped by the real binary; the report is judged on its own structure and
    // against the parts' figures in summary.json.
    let tmp = tempfile::tempdir().unwrap();
    let cwd = tmp.path();
    synth_family(
        cwd,
        "1000",
        &[
            "--grid",
            "6x6",
            "--size",
            "90x90",
            "--outliers",
            "0",
            "--epochs",
            "5",
            "--warm-epochs",
            "1",
        ],
    );
    batch(cwd, "cpu", "out", 0);
    let out = cwd.join("out");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let parts = summary["parts"].as_array().unwrap();
    assert_eq!(parts.len(), 1000);
    let names: Vec<&str> = parts.iter().map(|p| p["part"].as_str().unwrap()).collect();
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert_well_formed(&html, "report.html");
    assert!(!html.contains("<script") && !html.contains("https://"));
    // The overview embeds the family's pictures only (mean, spread, u(E)), no part's.
    let images = html.matches("src=\"data:image/png;base64,").count();
    assert!(
        (2..=3).contains(&images),
        "{images} pictures on the overview"
    );
    assert!(!html.contains("<section id=\"part-"));
    // Eight tables of every part: seven sorted by a column, then the default in file order.
    let tables: Vec<&str> = html
        .match_indices("<table class=\"parts\">")
        .map(|(at, _)| &html[at..])
        .collect();
    assert_eq!(tables.len(), 8);
    for t in &tables {
        assert_eq!(table_rows(t).len(), 1000);
    }
    let default = table_rows(tables[7]);
    let in_order: Vec<&str> = default.iter().map(|(_, n)| n.as_str()).collect();
    assert_eq!(
        in_order, names,
        "the default table is in the order of the probe files"
    );
    // Sorted by map RMS: the order of summary.json's rms_um, largest first, ties by file order.
    let by_rms = &html[html.find("id=\"parts-by-rms\"").unwrap()..];
    let mut want: Vec<(f64, usize)> = parts
        .iter()
        .enumerate()
        .map(|(k, p)| (p["rms_um"].as_f64().unwrap(), k))
        .collect();
    want.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    let got: Vec<String> = table_rows(&by_rms[by_rms.find("<table").unwrap()..])
        .into_iter()
        .map(|(_, n)| n)
        .collect();
    let want: Vec<&str> = want.iter().map(|&(_, k)| names[k]).collect();
    assert_eq!(got, want);
    // Every row links to its part's own page, which exists, names its part, links back and
    // holds that part's pictures only.
    for (href, name) in &default {
        assert_eq!(href, &format!("{name}/report.html"));
        let page =
            std::fs::read_to_string(out.join(href)).unwrap_or_else(|e| panic!("{href}: {e}"));
        assert_well_formed(&page, href);
        assert!(
            page.contains(&format!("<h2>Part {name}</h2>"))
                && page.contains(&format!(
                    "<title>errmap report — web-plate part {name}</title>"
                )),
            "{href} does not name its part"
        );
        assert!(page.contains("href=\"../report.html#parts\""), "{href}");
        let images = page.matches("src=\"data:image/png;base64,").count();
        assert!((1..=2).contains(&images), "{href}: {images} pictures");
    }
    // `errmap report` on the folder gives the same bytes as the batch wrote.
    run_expect(&["report", "out", "-o", "again.html", "--quiet"], cwd, 0);
    assert_eq!(
        std::fs::read(cwd.join("again.html")).unwrap(),
        html.as_bytes(),
        "errmap report differs from the batch's report.html"
    );
}
