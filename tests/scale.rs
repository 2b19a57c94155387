//! Scale-out and crash consistency of family batches, through the real binary: shards + merge against one unsharded run, a killed shard, shards of another job, `kill -9` at random points, and `--resume`.

mod common;

use common::Run;
use rand::{Rng, SeedableRng};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

/// Run errmap in `cwd` with no scheduler variables from the test's own environment.
fn errmap(cwd: &Path, args: &[&str]) -> Run {
    common::errmap_with(cwd, args, scrub)
}

fn scrub(cmd: &mut Command) {
    // Runs are compared byte for byte: fix the run's date (run.json, report.html).
    cmd.env("SOURCE_DATE_EPOCH", "1795450265");
    for var in [
        "SLURM_ARRAY_TASK_ID",
        "SLURM_ARRAY_TASK_COUNT",
        "JOB_COMPLETION_INDEX",
    ] {
        cmd.env_remove(var);
    }
}

#[track_caller]
fn run_ok(cwd: &Path, args: &[&str]) -> Run {
    let r = errmap(cwd, args);
    r.expect_code(0);
    r
}

/// A synthetic family of `parts` web plates in `cwd/data` (job with a fixed domain and a
/// family-compensated finishing program), trained for few epochs.
fn family(cwd: &Path, parts: usize) {
    let parts = parts.to_string();
    run_ok(
        cwd,
        &[
            "synth",
            "web-plate",
            "--parts",
            &parts,
            "--epochs",
            "20",
            "--out-dir",
            "data",
        ],
    );
}

fn batch(cwd: &Path, out: &str, extra: &[&str]) -> Run {
    let mut args = vec![
        "batch",
        "data/job.toml",
        "--backend",
        "cpu",
        "--out-dir",
        out,
        "--quiet",
    ];
    args.extend_from_slice(extra);
    errmap(cwd, &args)
}

/// Every file below `dir` by relative path, with its bytes.
fn snapshot(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    common::files(dir)
        .into_iter()
        .map(|f| {
            let rel = f.strip_prefix(dir).unwrap().to_string_lossy().to_string();
            (rel, std::fs::read(&f).unwrap())
        })
        .collect()
}

/// A part's `summary.json` without its folder (which differs between shard and batch).
fn part_summary_without_folder(bytes: &[u8]) -> serde_json::Value {
    let mut v: serde_json::Value = serde_json::from_slice(bytes).unwrap();
    v.as_object_mut().unwrap().remove("output_dir");
    v
}

/// Compare the merge of a sharded run in `sharded` with the unsharded run in `single`, file by
/// file at the same paths (a merged run's folder looks like one machine's: parts at `<part>/`,
/// no shard folder): the family folder always; with `parts`, the same files and every part's
/// files too.
fn compare_runs(single: &Path, sharded: &Path, parts: bool) -> Vec<String> {
    let mut diffs = Vec::new();
    let one = snapshot(single);
    let many = snapshot(sharded);
    let shard_files: Vec<&String> = many.keys().filter(|k| k.starts_with("shard-")).collect();
    assert!(
        shard_files.is_empty(),
        "left after the merge: {shard_files:?}"
    );
    if parts {
        assert_eq!(
            one.keys().collect::<Vec<_>>(),
            many.keys().collect::<Vec<_>>(),
            "the merged folder holds other files than the unsharded run's"
        );
    }
    let mut family_files = 0;
    for (rel, bytes) in &one {
        if rel.starts_with("family/") {
            family_files += 1;
            if many.get(rel) != Some(bytes) {
                diffs.push(rel.clone());
            }
            continue;
        }
        if !parts || !rel.contains('/') {
            continue;
        }
        let same = match many.get(rel) {
            Some(b) if rel.ends_with("summary.json") => {
                part_summary_without_folder(b) == part_summary_without_folder(bytes)
            }
            Some(b) => b == bytes,
            None => false,
        };
        if !same {
            diffs.push(rel.clone());
        }
    }
    assert!(
        family_files >= 6,
        "the unsharded run has a family folder: {one:?}",
        one = one.keys()
    );
    diffs
}

/// A run's `summary.json` with its output folder's name replaced by `single`.
fn summary_in(dir: &Path, name: &str) -> serde_json::Value {
    let text = std::fs::read_to_string(dir.join(name).join("summary.json")).unwrap();
    serde_json::from_str(&text.replace(&format!("\"{name}/"), "\"single/")).unwrap()
}

/// Run a job as `n` shards plus the merge into `out`.
fn sharded(cwd: &Path, out: &str, n: usize) {
    for i in 0..n {
        let shard = format!("{i}/{n}");
        batch(cwd, out, &["--shard", &shard]).expect_code(0);
    }
    run_ok(cwd, &["merge", out, "--backend", "cpu", "--quiet"]);
}

#[test]
fn family_network_and_toolpaths_of_1_2_3_7_shards_equal_the_unsharded_run() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    family(d, 7);
    batch(d, "single", &[]).expect_code(0);
    for n in [1, 2, 3, 7] {
        let out = format!("sharded-{n}");
        sharded(d, &out, n);
        let diffs = compare_runs(&d.join("single"), &d.join(&out), n == 1);
        // Until each part's seed derives from its name, only the family network (fitted to the
        // mean of the parts' training sets) and its toolpaths are independent of the split;
        // the family's mean and std maps come from the parts' networks.
        let expected: Vec<String> = if n == 1 {
            Vec::new()
        } else {
            diffs
                .iter()
                .filter(|f| {
                    !["family/model.json", "family/finish-compensated.ngc"].contains(&f.as_str())
                })
                .cloned()
                .collect()
        };
        assert_eq!(diffs, expected, "{n} shards differ from the unsharded run");
        let merged: serde_json::Value =
            serde_json::from_slice(&std::fs::read(d.join(&out).join("summary.json")).unwrap())
                .unwrap();
        assert_eq!(merged["parts"].as_array().unwrap().len(), 7);
        assert_eq!(merged["family_map"]["parts"], 7);
        assert_eq!(merged["toolpaths"][0]["map"], "family");
    }
}

#[test]
fn every_file_of_2_3_7_shards_equals_the_unsharded_run() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    family(d, 7);
    batch(d, "single", &[]).expect_code(0);
    for n in [2, 3, 7] {
        let out = format!("sharded-{n}");
        sharded(d, &out, n);
        let diffs = compare_runs(&d.join("single"), &d.join(&out), true);
        assert!(diffs.is_empty(), "{n} shards: {diffs:?} differ");
        // The merged summary is the unsharded run's, part folders included.
        assert_eq!(summary_in(d, &out), summary_in(d, "single"), "{n} shards");
    }
}

#[test]
fn shards_that_warm_start_from_the_family_network_equal_the_unsharded_run() {
    // Each shard rebuilds the family network from every part, as the whole run does, so its
    // parts start from the same network and every file matches.
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    run_ok(
        d,
        &[
            "synth",
            "web-plate",
            "--parts",
            "5",
            "--epochs",
            "20",
            "--warm-epochs",
            "10",
            "--out-dir",
            "data",
        ],
    );
    batch(d, "single", &[]).expect_code(0);
    for n in [2, 3] {
        let out = format!("sharded-{n}");
        sharded(d, &out, n);
        let diffs = compare_runs(&d.join("single"), &d.join(&out), true);
        assert!(diffs.is_empty(), "{n} shards: {diffs:?} differ");
    }
    // And the warm start made a difference: a run from scratch gives other part networks.
    let job = std::fs::read_to_string(d.join("data/job.toml")).unwrap();
    std::fs::write(
        d.join("data/job.toml"),
        job.replace("warm_start = \"family\"", "warm_start = \"none\""),
    )
    .unwrap();
    batch(d, "cold", &[]).expect_code(0);
    assert!(
        std::fs::read(d.join("single/p01/model.json")).unwrap()
            != std::fs::read(d.join("cold/p01/model.json")).unwrap(),
        "p01's network is the same with and without the warm start"
    );
}

#[test]
fn a_killed_shard_is_reported_by_merge_and_its_rerun_completes_the_job() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    family(d, 5);
    batch(d, "single", &[]).expect_code(0);
    batch(d, "out", &["--shard", "0/3"]).expect_code(0);
    batch(d, "out", &["--shard", "2/3"]).expect_code(0);
    // Shard 1 dies by SIGKILL while it runs.
    let mut child = common::command();
    scrub(&mut child);
    let mut child = child
        .args([
            "batch",
            "data/job.toml",
            "--backend",
            "cpu",
            "--out-dir",
            "out",
            "--quiet",
            "--shard",
            "1/3",
        ])
        .current_dir(d)
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(150));
    child.kill().unwrap();
    child.wait().unwrap();
    let merge = errmap(d, &["merge", "out", "--backend", "cpu"]);
    merge.expect_code(2);
    assert!(
        merge
            .stderr
            .contains("shards [1] of 3 have no complete run")
            && merge.stderr.contains("Slurm array task ids 1"),
        "{}",
        merge.report()
    );
    assert!(!d.join("out/family").exists() && !d.join("out/summary.json").exists());
    batch(d, "out", &["--shard", "1/3"]).expect_code(0);
    run_ok(d, &["merge", "out", "--backend", "cpu", "--quiet"]);
    for f in ["family/model.json", "family/finish-compensated.ngc"] {
        assert_eq!(
            std::fs::read(d.join("single").join(f)).unwrap(),
            std::fs::read(d.join("out").join(f)).unwrap(),
            "{f}"
        );
    }
    let m: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("out/run.json")).unwrap()).unwrap();
    assert_eq!(m["kind"], "reduce");
    assert_eq!(m["shards"].as_object().unwrap().len(), 3);
}

#[test]
fn merge_refuses_a_shard_of_another_job_and_a_shard_without_its_folder() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    family(d, 3);
    batch(d, "out", &["--shard", "0/2"]).expect_code(0);
    // Shard 1 of the same family with other settings (more epochs), moved in beside shard 0.
    let other = std::fs::read_to_string(d.join("data/job.toml"))
        .unwrap()
        .replace("epochs = 20", "epochs = 21");
    std::fs::write(d.join("data/other.toml"), other).unwrap();
    let r = errmap(
        d,
        &[
            "batch",
            "data/other.toml",
            "--backend",
            "cpu",
            "--out-dir",
            "elsewhere",
            "--quiet",
            "--shard",
            "1/2",
        ],
    );
    r.expect_code(0);
    std::fs::rename(d.join("elsewhere/shard-1-of-2"), d.join("out/shard-1-of-2")).unwrap();
    let merge = errmap(d, &["merge", "out", "--backend", "cpu"]);
    merge.expect_code(2);
    assert!(
        merge.stderr.contains("belongs to another job"),
        "{}",
        merge.report()
    );
    assert!(!d.join("out/family").exists());
    // A shard's summary edited after its run no longer matches its manifest.
    batch(d, "out", &["--shard", "1/2"]).expect_code(0);
    let s = d.join("out/shard-1-of-2/summary.json");
    let text = std::fs::read_to_string(&s)
        .unwrap()
        .replace("\"p02\"", "\"p02 \"");
    std::fs::write(&s, text).unwrap();
    let merge = errmap(d, &["merge", "out", "--backend", "cpu"]);
    merge.expect_code(2);
    assert!(
        merge
            .stderr
            .contains("differs from the one the shard's run.json lists"),
        "{}",
        merge.report()
    );
}

/// Copy a folder tree.
fn copy_tree(from: &Path, to: &Path) {
    for f in common::files(from) {
        let dest = to.join(f.strip_prefix(from).unwrap());
        std::fs::create_dir_all(dest.parent().unwrap()).unwrap();
        std::fs::copy(&f, &dest).unwrap();
    }
}

fn temporaries(dir: &Path) -> Vec<PathBuf> {
    let mut found = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let name = e.file_name().to_string_lossy().to_string();
            if name.starts_with(".errmap-") {
                found.push(e.path());
            } else if e.path().is_dir() {
                stack.push(e.path());
            }
        }
    }
    found
}

#[test]
fn kill_9_at_20_random_points_leaves_the_old_run_or_the_new_one() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    family(d, 3);
    let new_job = std::fs::read_to_string(d.join("data/job.toml"))
        .unwrap()
        .replace("seed = 1", "seed = 2");
    std::fs::write(d.join("data/new.toml"), new_job).unwrap();
    let new_args = [
        "batch",
        "data/new.toml",
        "--backend",
        "cpu",
        "--out-dir",
        "out",
        "--quiet",
    ];
    // The old complete run and, in the same folder name, the new one.
    batch(d, "out", &[]).expect_code(0);
    let old = snapshot(&d.join("out"));
    copy_tree(&d.join("out"), &d.join("old"));
    let started = std::time::Instant::now();
    run_ok(d, &new_args);
    let full_ms = started.elapsed().as_millis() as u64;
    let new = snapshot(&d.join("out"));
    assert_ne!(old, new);
    let mut outcomes = BTreeMap::new();
    for seed in 0..20u64 {
        std::fs::remove_dir_all(d.join("out")).unwrap();
        copy_tree(&d.join("old"), &d.join("out"));
        let delay_ms =
            rand_chacha::ChaCha8Rng::seed_from_u64(seed).random_range(0..=full_ms * 3 / 2);
        let mut cmd = common::command();
        scrub(&mut cmd);
        let mut child = cmd.args(new_args).current_dir(d).spawn().unwrap();
        std::thread::sleep(std::time::Duration::from_millis(delay_ms));
        let _ = child.kill();
        child.wait().unwrap();
        let now = snapshot(&d.join("out"));
        let outcome = if now == old {
            "old"
        } else if now == new {
            "new"
        } else {
            let mixed: Vec<&String> = now.keys().filter(|k| old.get(*k) != now.get(*k)).collect();
            panic!("seed {seed}, killed after {delay_ms} ms: a mix of runs, changed {mixed:?}");
        };
        *outcomes.entry(outcome).or_insert(0) += 1;
        let tmp = temporaries(&d.join("out"));
        assert!(
            tmp.is_empty(),
            "seed {seed}: temporaries inside the run folder {tmp:?}"
        );
    }
    // The next run removes what the killed ones left beside the folder.
    run_ok(d, &new_args);
    assert_eq!(snapshot(&d.join("out")), new);
    assert!(temporaries(d).is_empty(), "{:?}", temporaries(d));
    eprintln!("kill -9 outcomes over 20 seeds (full run {full_ms} ms): {outcomes:?}");
}

#[test]
fn resume_redoes_exactly_the_parts_that_did_not_finish_or_changed() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    family(d, 4);
    let p03 = d.join("data/probes/p03.csv");
    let good = std::fs::read_to_string(&p03).unwrap();
    std::fs::write(&p03, "x_mm,y_mm,z_mm\n1,2,not-a-number\n").unwrap();
    // First run: p03 fails, the rest finish.
    batch(d, "out", &[]).expect_code(1);
    // The summary says which part failed, and why.
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("out/summary.json")).unwrap())
            .unwrap();
    let failed: Vec<&serde_json::Value> = summary["parts"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|p| p["ok"] == false)
        .collect();
    assert_eq!(failed.len(), 1, "{summary}");
    assert_eq!(failed[0]["part"], "p03", "{summary}");
    assert_eq!(failed[0]["error"]["kind"], "input", "{summary}");
    assert!(
        failed[0]["error"]["message"]
            .as_str()
            .unwrap()
            .contains("'not-a-number' is not a number"),
        "{summary}"
    );
    std::fs::write(&p03, good).unwrap();
    // p02's map edited since; p04's probe file changed (one point 1 µm higher).
    let map02 = d.join("out/p02/map.csv");
    let mut text = std::fs::read_to_string(&map02).unwrap();
    text.push('\n');
    std::fs::write(&map02, text).unwrap();
    let p04 = d.join("data/probes/p04.csv");
    let lines: Vec<String> = std::fs::read_to_string(&p04)
        .unwrap()
        .lines()
        .map(str::to_string)
        .collect();
    let mut fields: Vec<String> = lines[1].split(',').map(str::to_string).collect();
    let z: f64 = fields[2].parse().unwrap();
    fields[2] = format!("{:.4}", z + 0.001);
    let mut changed = lines.clone();
    changed[1] = fields.join(",");
    std::fs::write(&p04, changed.join("\n") + "\n").unwrap();
    use std::os::unix::fs::MetadataExt;
    let inode = |p: &str| std::fs::metadata(d.join(p)).unwrap().ino();
    let kept_before = (
        inode("out/p01/map.csv"),
        std::fs::read(d.join("out/p01/model.json")).unwrap(),
    );

    batch(d, "out", &["--resume"]).expect_code(0);
    let m: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("out/run.json")).unwrap()).unwrap();
    let reused: BTreeMap<String, bool> = m["parts"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| {
            (
                p["part"].as_str().unwrap().to_string(),
                p["reused"].as_bool().unwrap(),
            )
        })
        .collect();
    let expect: BTreeMap<String, bool> = [
        ("p01", true),
        ("p02", false),
        ("p03", false),
        ("p04", false),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect();
    assert_eq!(reused, expect);
    // The kept part is the same file (hard-linked, not recomputed).
    assert_eq!(inode("out/p01/map.csv"), kept_before.0);
    assert_eq!(
        std::fs::read(d.join("out/p01/model.json")).unwrap(),
        kept_before.1
    );
    let s: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("out/summary.json")).unwrap()).unwrap();
    assert_eq!(s["failed_parts"], 0);
    assert_eq!(s["family_map"]["parts"], 4);
    assert!(
        d.join("out/family/model.json").is_file()
            && d.join("out/family/finish-compensated.ngc").is_file()
    );
    // Nothing left to redo: a second resume keeps all four.
    batch(d, "out", &["--resume"]).expect_code(0);
    let m: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("out/run.json")).unwrap()).unwrap();
    assert!(m["parts"]
        .as_array()
        .unwrap()
        .iter()
        .all(|p| p["reused"] == true));
}

#[test]
fn a_folder_of_other_files_is_not_replaced_and_sharding_needs_a_domain() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    family(d, 2);
    std::fs::create_dir(d.join("mine")).unwrap();
    std::fs::write(d.join("mine/notes.txt"), "keep").unwrap();
    let r = batch(d, "mine", &[]);
    r.expect_code(2);
    assert!(r.stderr.contains("holds no errmap run"), "{}", r.report());
    assert_eq!(
        std::fs::read_to_string(d.join("mine/notes.txt")).unwrap(),
        "keep"
    );
    let r = errmap(
        d,
        &[
            "batch",
            "data/job.toml",
            "--backend",
            "cpu",
            "--out-dir",
            "data",
            "--quiet",
        ],
    );
    r.expect_code(2);
    assert!(r.stderr.contains("holds no input"), "{}", r.report());
    let job = std::fs::read_to_string(d.join("data/job.toml")).unwrap();
    let no_domain: String = job
        .lines()
        .filter(|l| !l.starts_with("domain"))
        .map(|l| format!("{l}\n"))
        .collect();
    std::fs::write(d.join("data/job.toml"), no_domain).unwrap();
    let r = batch(d, "out", &["--shard", "0/2"]);
    r.expect_code(2);
    assert!(
        r.stderr.contains("needs a fixed map domain"),
        "{}",
        r.report()
    );
}

#[test]
fn on_the_gpu_the_reduce_fits_the_same_family_network_as_the_unsharded_run() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    family(d, 3);
    let gpu = |out: &str, extra: &[&str]| {
        let mut args = vec![
            "batch",
            "data/job.toml",
            "--backend",
            "gpu",
            "--out-dir",
            out,
            "--quiet",
        ];
        args.extend_from_slice(extra);
        errmap(d, &args)
    };
    let single = gpu("single", &[]);
    if single.code == 3 && std::env::var("ERRMAP_REQUIRE_GPU").as_deref() != Ok("1") {
        eprintln!(
            "SKIPPED: GPU reduce test: no usable adapter ({})",
            single.stderr.trim()
        );
        return;
    }
    single.expect_code(0);
    gpu("out", &["--shard", "0/2"]).expect_code(0);
    gpu("out", &["--shard", "1/2"]).expect_code(0);
    run_ok(d, &["merge", "out", "--backend", "gpu", "--quiet"]);
    for f in ["family/model.json", "family/finish-compensated.ngc"] {
        assert_eq!(
            std::fs::read(d.join("single").join(f)).unwrap(),
            std::fs::read(d.join("out").join(f)).unwrap(),
            "{f}: the family network trained alone differs from the one trained in the batch"
        );
    }
}

#[test]
fn a_sharded_rerun_into_an_unsharded_runs_folder_leaves_no_part_of_the_old_run() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    family(d, 2);
    batch(d, "out", &[]).expect_code(0);
    assert!(d.join("out/p01/map.csv").is_file());
    sharded(d, "out", 2);
    // Every file is the merge's: listed in its run.json with its hash (no file of the old
    // run, no shard folder).
    let m: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("out/run.json")).unwrap()).unwrap();
    let mut listed: BTreeMap<String, String> = BTreeMap::new();
    for p in m["parts"].as_array().unwrap() {
        for (k, v) in p["outputs"].as_object().unwrap() {
            listed.insert(k.clone(), v.as_str().unwrap().to_string());
        }
    }
    for (k, v) in m["files"].as_object().unwrap() {
        listed.insert(k.clone(), v.as_str().unwrap().to_string());
    }
    let mut present = common::listing(&d.join("out"));
    present.retain(|f| f != "run.json" && !f.ends_with('/'));
    assert_eq!(
        present,
        listed.keys().cloned().collect::<Vec<_>>(),
        "files not of the merge"
    );
    // Hashed by coreutils' sha256sum, not errmap's own code.
    for (rel, hash) in &listed {
        let out = Command::new("sha256sum")
            .arg(d.join("out").join(rel))
            .output()
            .unwrap();
        let text = String::from_utf8_lossy(&out.stdout);
        assert_eq!(text.split_whitespace().next(), Some(hash.as_str()), "{rel}");
    }
    let m: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("out/run.json")).unwrap()).unwrap();
    assert_eq!(m["kind"], "reduce");
}

/// The journal of the run now writing into `dir/out` (in its staging folder beside it).
fn journal_lines(dir: &Path) -> Vec<serde_json::Value> {
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let name = e.file_name().to_string_lossy().to_string();
        if name.starts_with(".errmap-out-") && name.ends_with(".tmp") {
            let text =
                std::fs::read_to_string(e.path().join(".errmap-journal.jsonl")).unwrap_or_default();
            // Only whole lines: the last may be being written.
            return text
                .lines()
                .skip(1)
                .filter_map(|l| serde_json::from_str(l).ok())
                .collect();
        }
    }
    Vec::new()
}

#[test]
fn a_run_killed_after_its_first_chunk_resumes_without_mapping_those_parts_again() {
    // 36 parts: the first chunk of 32 is written and journaled, then SIGKILL while the rest
    // runs; --resume keeps exactly the journaled parts (the same files, hard-linked) and the
    // folder ends byte for byte as an uninterrupted run's.
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    run_ok(
        d,
        &[
            "synth",
            "web-plate",
            "--parts",
            "36",
            "--grid",
            "9x7",
            "--epochs",
            "20",
            "--out-dir",
            "data",
        ],
    );
    batch(d, "whole", &[]).expect_code(0);
    let mut cmd = common::command();
    scrub(&mut cmd);
    let args = [
        "batch",
        "data/job.toml",
        "--backend",
        "cpu",
        "--out-dir",
        "out",
        "--quiet",
    ];
    let mut child = cmd.args(args).current_dir(d).spawn().unwrap();
    // The first chunk of the cpu backend's parts: killed once it is journaled.
    let chunk = errmap::batch::parts_per_chunk(&errmap::nn::FastCpuTrainer);
    assert!(chunk < 36, "the family outlasts the first chunk");
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(600);
    let journaled = loop {
        let lines = journal_lines(d);
        if lines.len() >= chunk {
            child.kill().unwrap();
            child.wait().unwrap();
            break journal_lines(d);
        }
        assert!(
            child.try_wait().unwrap().is_none(),
            "the run ended before its first chunk was journaled"
        );
        assert!(std::time::Instant::now() < deadline, "no chunk journaled");
        std::thread::sleep(std::time::Duration::from_millis(10));
    };
    assert!(
        !d.join("out/run.json").exists(),
        "killed before it committed"
    );
    let staging = std::fs::read_dir(d)
        .unwrap()
        .flatten()
        .find(|e| e.file_name().to_string_lossy().starts_with(".errmap-out-"))
        .unwrap()
        .path();
    use std::os::unix::fs::MetadataExt;
    let done: BTreeMap<String, u64> = journaled
        .iter()
        .map(|l| {
            let part = l["part"]["part"].as_str().unwrap().to_string();
            let ino = std::fs::metadata(staging.join(&part).join("map.csv"))
                .unwrap()
                .ino();
            (part, ino)
        })
        .collect();
    assert!(done.len() >= chunk && done.len() < 36, "{done:?}");

    batch(d, "out", &["--resume"]).expect_code(0);
    let m: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("out/run.json")).unwrap()).unwrap();
    let reused: Vec<String> = m["parts"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|p| p["reused"] == true)
        .map(|p| p["part"].as_str().unwrap().to_string())
        .collect();
    assert_eq!(reused, done.keys().cloned().collect::<Vec<_>>());
    // Not mapped again: the very files the killed run wrote.
    for (part, ino) in &done {
        let now = std::fs::metadata(d.join("out").join(part).join("map.csv"))
            .unwrap()
            .ino();
        assert_eq!(now, *ino, "{part} was written again");
    }
    // Nothing of the killed run is left beside or inside the folder.
    assert!(temporaries(d).is_empty(), "{:?}", temporaries(d));
    // The same bytes as the uninterrupted run (run.json apart: it says what was reused).
    let whole = snapshot(&d.join("whole"));
    let out = snapshot(&d.join("out"));
    assert_eq!(
        whole.keys().collect::<Vec<_>>(),
        out.keys().collect::<Vec<_>>()
    );
    for (rel, bytes) in &whole {
        if rel == "run.json" {
            continue;
        }
        let theirs = &out[rel];
        let same = if rel.ends_with("summary.json") {
            let norm = |b: &[u8]| String::from_utf8_lossy(b).replace("\"whole/", "\"out/");
            norm(bytes) == norm(theirs)
        } else {
            bytes == theirs
        };
        assert!(same, "{rel} differs from the uninterrupted run");
    }
}
