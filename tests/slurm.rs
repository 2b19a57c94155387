//! The sample job under a real single-node Slurm (tests/slurm/run.sh): a 4-task array and its merge through `errmap slurm --submit`, compared byte for byte with an unsharded run.
//!
//! Skipped (with a note) where Slurm or root is missing; `ERRMAP_REQUIRE_SLURM=1` (CI) makes
//! that a failure.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

fn have(cmd: &str) -> bool {
    Command::new("sh")
        .args(["-c", &format!("command -v {cmd}")])
        .output()
        .is_ok_and(|o| o.status.success())
}

fn is_root() -> bool {
    Command::new("id")
        .arg("-u")
        .output()
        .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).trim() == "0")
}

fn files(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            if e.path().is_dir() {
                stack.push(e.path());
            } else {
                let rel = e
                    .path()
                    .strip_prefix(dir)
                    .unwrap()
                    .to_string_lossy()
                    .to_string();
                out.insert(rel, std::fs::read(e.path()).unwrap());
            }
        }
    }
    out
}

#[test]
fn sample_job_as_a_4_task_slurm_array_and_merge_matches_one_machine() {
    let missing: Vec<&str> = ["sbatch", "slurmctld", "slurmd", "munged"]
        .into_iter()
        .filter(|c| !have(c))
        .collect();
    let why = if !missing.is_empty() {
        Some(format!(
            "{missing:?} not installed (apt-get install slurm-wlm munge)"
        ))
    } else if !is_root() {
        Some("the test cluster's daemons need root".to_string())
    } else {
        None
    };
    if let Some(why) = why {
        if std::env::var("ERRMAP_REQUIRE_SLURM").is_ok_and(|v| v == "1") {
            panic!("ERRMAP_REQUIRE_SLURM=1 but {why}");
        }
        eprintln!("SKIPPED: real Slurm test: {why}");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/slurm/run.sh");
    let out = Command::new(&script)
        .arg(env!("CARGO_BIN_EXE_errmap"))
        .arg(dir.path())
        .env_remove("SLURM_ARRAY_TASK_ID")
        .env_remove("JOB_COMPLETION_INDEX")
        .output()
        .unwrap();
    let log = format!(
        "{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.status.success(), "tests/slurm/run.sh failed:\n{log}");
    let single = files(&dir.path().join("single"));
    let sharded = files(&dir.path().join("sharded"));
    // The merge committed every shard and left the folder as one machine writes it: the
    // parts at <part>/, no shard folder.
    let manifest: serde_json::Value = serde_json::from_slice(&sharded["run.json"]).unwrap();
    assert_eq!(manifest["kind"], "reduce", "{log}");
    let shards: Vec<&String> = manifest["shards"].as_object().unwrap().keys().collect();
    assert_eq!(
        shards,
        [
            "shard-0-of-4",
            "shard-1-of-4",
            "shard-2-of-4",
            "shard-3-of-4"
        ],
        "{log}"
    );
    let left: Vec<&String> = sharded.keys().filter(|k| k.starts_with("shard-")).collect();
    assert!(
        left.is_empty(),
        "shard folders left after the merge: {left:?}"
    );
    let mut compared = 0;
    for (rel, bytes) in &single {
        if !rel.contains('/') || rel.ends_with("summary.json") || rel.starts_with("slurm/") {
            continue;
        }
        // Every part file and every family file at the same path: seeds come from names, not
        // positions.
        assert_eq!(
            sharded.get(rel),
            Some(bytes),
            "{rel} differs from the unsharded run"
        );
        compared += 1;
    }
    assert!(compared >= 8 * 5, "nothing compared: {:?}", single.keys());
    let merged: serde_json::Value = serde_json::from_slice(&sharded["summary.json"]).unwrap();
    assert_eq!(merged["parts"].as_array().unwrap().len(), 8);
    assert_eq!(merged["failed_parts"], 0);
    assert_eq!(merged["family_map"]["parts"], 8);
}
