//! Slurm batch scripts for a sharded job: an array job with one task per shard and a merge job that runs after it (`--dependency=afterok`).

use crate::ClusterError;
use errmap_core::error::{Diagnostic, Result};
use std::path::{Path, PathBuf};

/// One word of the command line an array task runs.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Word {
    /// A word as it is (quoted for the shell where it needs to be).
    Text(String),
    /// The task's shard, `"${SLURM_ARRAY_TASK_ID}/N"` with N the plan's shards: the shell
    /// gives each array task its own.
    TaskShard,
}

/// What the scripts run and where. The errmap command lines are the caller's: the batch
/// knows Slurm, the front end knows its own command line.
#[derive(Debug, Clone)]
pub struct SlurmPlan {
    /// The errmap binary the nodes run (absolute, or a name on the nodes' PATH).
    pub errmap: PathBuf,
    /// The arguments of each array task's errmap, [`Word::TaskShard`] where its shard goes.
    pub shard_args: Vec<Word>,
    /// The arguments of the merge job's errmap.
    pub merge_args: Vec<String>,
    /// The batch's output folder (absolute): shard folders, family, summary, logs.
    pub out: PathBuf,
    /// The job's family; names the Slurm jobs (`errmap-<family>`, `errmap-<family>-merge`).
    pub family: String,
    /// Number of shards: the array's tasks (`--array=0-(shards−1)`).
    pub shards: usize,
    /// `#SBATCH --partition` of both jobs; `None` = the cluster's default.
    pub partition: Option<String>,
    /// `#SBATCH --time` limit of each task and of the merge, in Slurm's format (`02:00:00`);
    /// `None` = the partition's default.
    pub time: Option<String>,
}

/// Quote for a POSIX shell: one word whatever it holds.
pub fn shell_quote(text: &str) -> String {
    let plain = !text.is_empty()
        && text
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "/._-+=:,@%".contains(c));
    if plain {
        text.to_string()
    } else {
        format!("'{}'", text.replace('\'', r"'\''"))
    }
}

fn q(p: &Path) -> String {
    shell_quote(&p.to_string_lossy())
}

impl SlurmPlan {
    /// Folder of the scripts and the tasks' logs.
    pub fn slurm_dir(&self) -> PathBuf {
        self.out.join("slurm")
    }

    fn header(&self, name: &str, log: &str) -> String {
        let mut s = String::from("#!/bin/bash\n");
        s.push_str(&format!("#SBATCH --job-name={}\n", shell_quote(name)));
        s.push_str(&format!(
            "#SBATCH --output={}\n",
            q(&self.slurm_dir().join(log))
        ));
        if let Some(p) = &self.partition {
            s.push_str(&format!("#SBATCH --partition={}\n", shell_quote(p)));
        }
        if let Some(t) = &self.time {
            s.push_str(&format!("#SBATCH --time={}\n", shell_quote(t)));
        }
        s
    }

    /// The exec line of a task: the binary and `args`, each one word for the shell.
    fn exec_line<'a>(&self, args: impl Iterator<Item = std::borrow::Cow<'a, str>>) -> String {
        let mut line = format!("exec {}", q(&self.errmap));
        for word in args {
            line.push(' ');
            line.push_str(&word);
        }
        line.push('\n');
        line
    }

    /// The array job: task I maps shard I of N into `OUT/shard-I-of-N/`.
    pub fn shards_script(&self) -> String {
        let mut s = self.header(&format!("errmap-{}", self.family), "shard-%a.log");
        s.push_str(&format!("#SBATCH --array=0-{}\n", self.shards - 1));
        s.push_str("# One shard of the batch per array task; the task id is the shard index.\n");
        s.push_str("set -euo pipefail\n");
        let words = self.shard_args.iter().map(|w| match w {
            Word::Text(t) => shell_quote(t).into(),
            Word::TaskShard => format!("\"${{SLURM_ARRAY_TASK_ID}}/{}\"", self.shards).into(),
        });
        s.push_str(&self.exec_line(words));
        s
    }

    /// The merge job: the reduce of every shard into `OUT/` (family network, maps, toolpaths).
    pub fn merge_script(&self) -> String {
        let mut s = self.header(&format!("errmap-{}-merge", self.family), "merge.log");
        s.push_str("# Submitted with --dependency=afterok:<array job id>: runs once every shard succeeded.\n");
        s.push_str("set -euo pipefail\n");
        let words = self.merge_args.iter().map(|w| shell_quote(w).into());
        s.push_str(&self.exec_line(words));
        s
    }

    /// `sbatch` arguments of the array job; `array` resubmits only those task ids.
    pub fn sbatch_shards_args(&self, array: Option<&str>) -> Vec<String> {
        let mut a = vec!["--parsable".to_string()];
        if let Some(ids) = array {
            a.push(sbatch_option("array", ids));
        }
        a.push(
            self.slurm_dir()
                .join("shards.sbatch")
                .to_string_lossy()
                .into(),
        );
        a
    }

    /// `sbatch` arguments of the merge job after array job `array_job_id`.
    pub fn sbatch_merge_args(&self, array_job_id: &str) -> Vec<String> {
        vec![
            "--parsable".to_string(),
            sbatch_option("dependency", &format!("afterok:{array_job_id}")),
            "--kill-on-invalid-dep=yes".to_string(),
            self.slurm_dir()
                .join("merge.sbatch")
                .to_string_lossy()
                .into(),
        ]
    }
}

/// An option of `sbatch` (not of errmap): `--NAME=VALUE`.
fn sbatch_option(name: &str, value: &str) -> String {
    format!("--{name}={value}")
}

/// The job id in `sbatch --parsable` output (`ID` or `ID;CLUSTER`).
pub fn parse_job_id(stdout: &str) -> Option<String> {
    let id = stdout.trim().split(';').next()?.trim();
    (!id.is_empty() && id.chars().all(|c| c.is_ascii_digit())).then(|| id.to_string())
}

/// Whether `ids` is a Slurm array spec of shard indexes below `count` (`1,3`, `0-2`, `2`).
pub fn valid_array_ids(ids: &str, count: usize) -> bool {
    !ids.is_empty()
        && ids.split(',').all(|part| {
            let mut ends = part.splitn(2, '-').map(|x| x.trim().parse::<usize>());
            match (ends.next(), ends.next()) {
                (Some(Ok(a)), None) => a < count,
                (Some(Ok(a)), Some(Ok(b))) => a <= b && b < count,
                _ => false,
            }
        })
}

/// `--array IDS` checked against the shard count.
pub fn check_array_ids(ids: &str, count: usize) -> Result<(), ClusterError> {
    if valid_array_ids(ids, count) {
        return Ok(());
    }
    Err(ClusterError::Array(Diagnostic::usage(
        format!(
            "{} '{ids}' is not a list of task ids below {count}",
            errmap_core::setting::words(crate::Setting::Array)
        ),
        format!(
            "e.g. {array} 1,3 or {array} 0-2",
            array = errmap_core::setting::words(crate::Setting::Array)
        ),
    )))
}

/// The scripts of `plan` written into its Slurm folder: `[shards.sbatch, merge.sbatch]`.
pub fn write_scripts(plan: &SlurmPlan) -> Result<[PathBuf; 2], ClusterError> {
    let dir = plan.slurm_dir();
    let paths = [dir.join("shards.sbatch"), dir.join("merge.sbatch")];
    errmap_core::io::write_atomic_bytes(&paths[0], plan.shards_script().as_bytes())?;
    errmap_core::io::write_atomic_bytes(&paths[1], plan.merge_script().as_bytes())?;
    Ok(paths)
}

/// Run `sbatch --parsable …` and return the job id.
pub fn sbatch(args: &[String]) -> Result<String, ClusterError> {
    let out = std::process::Command::new("sbatch")
        .args(args)
        .output()
        .map_err(|e| {
            ClusterError::NoScheduler(Diagnostic::usage(
                format!("cannot run sbatch: {e}"),
                format!(
                    "run on a Slurm login node, or use {} and submit the scripts yourself",
                    errmap_core::setting::words(crate::Setting::DryRun)
                ),
            ))
        })?;
    let stdout = String::from_utf8_lossy(&out.stdout);
    match (out.status.success(), parse_job_id(&stdout)) {
        (true, Some(id)) => Ok(id),
        _ => Err(ClusterError::Submit(Diagnostic::device(
            format!(
                "sbatch {} failed: {}{}",
                args.join(" "),
                stdout.trim(),
                String::from_utf8_lossy(&out.stderr).trim()
            ),
            "check the partition and time limit with sinfo, or submit the scripts in OUT/slurm/ by hand",
        ))),
    }
}

/// Submit the array job (only task ids `array` when given), then the merge job after it:
/// `(array job id, merge job id)`.
pub fn submit(plan: &SlurmPlan, array: Option<&str>) -> Result<(String, String), ClusterError> {
    let array_id = sbatch(&plan.sbatch_shards_args(array))?;
    let merge_id = sbatch(&plan.sbatch_merge_args(&array_id))?;
    Ok((array_id, merge_id))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plan() -> SlurmPlan {
        let text = |w: &str| Word::Text(w.to_string());
        let job = "/data/web plate/job.toml";
        SlurmPlan {
            errmap: PathBuf::from("/opt/errmap/bin/errmap"),
            shard_args: vec![
                text("batch"),
                text(job),
                text("--shard"),
                Word::TaskShard,
                text("--out-dir"),
                text("/scratch/out"),
                text("--backend"),
                text("cpu"),
                text("--quiet"),
            ],
            merge_args: [
                "merge",
                "/scratch/out",
                "--shards",
                "4",
                "--job",
                job,
                "--quiet",
            ]
            .map(String::from)
            .to_vec(),
            out: PathBuf::from("/scratch/out"),
            family: "web-plate".into(),
            shards: 4,
            partition: Some("cpu".into()),
            time: Some("00:30:00".into()),
        }
    }

    #[test]
    fn array_script_runs_one_shard_per_task_and_merge_depends_on_it() {
        let p = plan();
        let s = p.shards_script();
        assert!(s.starts_with("#!/bin/bash\n"));
        assert!(s.contains("#SBATCH --array=0-3\n"), "{s}");
        assert!(s.contains("#SBATCH --partition=cpu\n#SBATCH --time=00:30:00\n"));
        assert!(s.contains("#SBATCH --output=/scratch/out/slurm/shard-%a.log\n"));
        assert!(s.contains(
            "exec /opt/errmap/bin/errmap batch '/data/web plate/job.toml' --shard \"${SLURM_ARRAY_TASK_ID}/4\" --out-dir /scratch/out --backend cpu --quiet\n"
        ), "{s}");
        let m = p.merge_script();
        assert!(m.contains("merge /scratch/out --shards 4 --job '/data/web plate/job.toml'"));
        assert_eq!(
            p.sbatch_merge_args("1234")[1],
            "--dependency=afterok:1234".to_string()
        );
        assert_eq!(p.sbatch_shards_args(Some("1,3"))[1], "--array=1,3");
    }

    #[test]
    fn job_ids_quotes_and_array_specs() {
        assert_eq!(parse_job_id("42\n").as_deref(), Some("42"));
        assert_eq!(parse_job_id("42;cluster\n").as_deref(), Some("42"));
        assert_eq!(parse_job_id("Submitted batch job 42"), None);
        assert_eq!(shell_quote("it's"), r"'it'\''s'");
        assert_eq!(shell_quote("a/b-c.toml"), "a/b-c.toml");
        assert!(valid_array_ids("1,3", 4) && valid_array_ids("0-3", 4));
        assert!(!valid_array_ids("4", 4) && !valid_array_ids("3-1", 4) && !valid_array_ids("", 4));
    }
}
