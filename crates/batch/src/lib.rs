//! Batch jobs over a part family: the job manifest, scheduling over parts, sharding and the summary.
#![forbid(unsafe_code)]
#![warn(missing_docs)]
#![deny(rustdoc::broken_intra_doc_links)]

pub(crate) mod commit;
pub(crate) mod driver;
mod error;
pub(crate) mod family_sums;
pub mod folder_report;
pub(crate) mod job;
pub mod journal;
pub(crate) mod json_out;
pub mod k8s;
pub mod manifest;
pub mod nested;
mod part_record;
pub(crate) mod plan;
pub(crate) mod reduce;
pub(crate) mod resolve;
pub(crate) mod run;
pub mod run_page;
mod setting;
pub(crate) mod single;
pub mod slurm;
pub(crate) mod stages;
pub(crate) mod summary;
pub(crate) mod timing;
pub(crate) mod train_step;

pub use driver::{merge_job, run_job, JobRun, MergeRequest};
pub use error::{ClusterError, FolderError, JobError, MergeError, RunError, ShardError};
pub use job::{Job, JobFile, MapChoice};
pub use plan::{PartInput, Plan, Settings, ToolpathPlan, PART_OUTPUTS};
pub use resolve::{plan_job, with_backend, ResolvedJob, SelectTrainer};
pub use run::{execute, execute_with, parts_per_chunk, PartDone};
pub use setting::Setting;
pub use single::{map_part, MapRequest};
pub use summary::{merge, BatchSummary, PartSummary};

use errmap_core::error::{Diagnostic, Result};
use std::path::PathBuf;

/// Which share of the parts this process maps: shard `index` of `count` (0-based) takes the
/// parts whose position in the sorted file list is `index` modulo `count`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    /// This shard's number, 0-based, below `count`.
    pub index: usize,
    /// How many shards the job is split into (at least 1).
    pub count: usize,
}

impl Shard {
    /// Parse `i/n` (0-based i < n).
    pub fn parse(text: &str) -> Result<Shard, ShardError> {
        let shard = errmap_core::setting::words(crate::Setting::Shard);
        let hint = &format!("write {shard} INDEX/COUNT with 0 ≤ INDEX < COUNT, e.g. {shard} 0/4");
        let (a, b) = text.split_once('/').ok_or_else(|| {
            ShardError::Spec(Diagnostic::usage(
                format!("{shard} '{text}' is not INDEX/COUNT"),
                hint,
            ))
        })?;
        let index: usize = a.trim().parse().map_err(|_| {
            ShardError::Spec(Diagnostic::usage(
                format!("{shard} index '{a}' is not a number"),
                hint,
            ))
        })?;
        let count: usize = b.trim().parse().map_err(|_| {
            ShardError::Spec(Diagnostic::usage(
                format!("{shard} count '{b}' is not a number"),
                hint,
            ))
        })?;
        Shard::new(index, count).ok_or_else(|| {
            ShardError::Spec(Diagnostic::usage(
                format!("{shard} {index}/{count} is out of range"),
                hint,
            ))
        })
    }

    /// Shard `index` of `count`; `None` unless 0 ≤ `index` < `count`.
    pub fn new(index: usize, count: usize) -> Option<Shard> {
        (count > 0 && index < count).then_some(Shard { index, count })
    }

    /// The shard from a scheduler's environment: `SLURM_ARRAY_TASK_ID` (with
    /// `SLURM_ARRAY_TASK_COUNT`, or `count`) or `JOB_COMPLETION_INDEX` of a Kubernetes
    /// Indexed Job (with `count`). `None` when neither variable is set.
    pub fn from_env(
        count: Option<usize>,
        env: impl Fn(&str) -> Option<String>,
    ) -> Result<Option<Shard>, ShardError> {
        let hint = &format!(
            "pass {} COUNT (the number of array tasks / completions)",
            errmap_core::setting::words(crate::Setting::Shards)
        );
        for (var, count_var) in [
            ("SLURM_ARRAY_TASK_ID", Some("SLURM_ARRAY_TASK_COUNT")),
            ("JOB_COMPLETION_INDEX", None),
        ] {
            let Some(value) = env(var) else { continue };
            let index: usize = value.trim().parse().map_err(|_| {
                ShardError::Env(Diagnostic::usage(
                    format!("{var}='{value}' is not an index"),
                    hint,
                ))
            })?;
            let count = match count {
                Some(c) => c,
                None => count_var
                    .and_then(&env)
                    .and_then(|v| v.trim().parse().ok())
                    .ok_or_else(|| {
                        ShardError::Env(Diagnostic::usage(
                            format!("{var} is set but the number of shards is not known"),
                            hint,
                        ))
                    })?,
            };
            // Slurm arrays often start at 1 (--array=1-N); accept index == count as the last shard.
            let index = if var == "SLURM_ARRAY_TASK_ID" && index == count {
                0
            } else {
                index
            };
            return Shard::new(index, count).map(Some).ok_or_else(|| {
                ShardError::Env(Diagnostic::usage(
                    format!("{var}={index} is not below the shard count {count}"),
                    hint,
                ))
            });
        }
        Ok(None)
    }

    /// Whether this shard maps the part at 0-based `position` of the sorted probe files.
    pub fn takes(&self, position: usize) -> bool {
        position % self.count == self.index
    }
}

/// Part names from probe file stems, safe as folder names and distinct
/// ([`errmap_core::io::safety::part_names`]): a repeated stem gets a number, `family` and other
/// reserved names get a suffix, and `..` cannot escape the output folder.
pub fn part_names(files: &[PathBuf]) -> Vec<String> {
    errmap_core::io::safety::part_names(&stems(files)).0
}

/// One line per part whose folder name differs from its probe file's stem.
pub fn renamed_parts(files: &[PathBuf]) -> Vec<String> {
    errmap_core::io::safety::part_names(&stems(files)).1
}

fn stems(files: &[PathBuf]) -> Vec<String> {
    files
        .iter()
        .map(|f| {
            f.file_stem()
                .map_or("part".into(), |s| s.to_string_lossy().to_string())
        })
        .collect()
}

/// Options of `errmap batch` that override or add to the job file.
#[derive(Debug, Clone, Default)]
pub struct BatchOptions {
    /// `--backend`: the trainer backend, replacing the job's `[model] backend`; `None` = the
    /// job's.
    pub backend: Option<errmap_maps::nn::Backend>,
    /// `--shard` (or the scheduler's environment): map only this shard's parts into its own
    /// `shard-I-of-N` folder; `None` = every part.
    pub shard: Option<Shard>,
    /// `--out-dir`: the batch's output folder (a shard writes into its `shard-I-of-N` folder
    /// there); `None` = the job's `output`, else `out/<family>`.
    pub output: Option<PathBuf>,
    /// Keep the parts of the folder's run whose input and outputs still match its `run.json`.
    pub resume: bool,
}

/// The number of shards of a scale-out run (`--shards`): 1 to 10000.
pub fn check_shard_count(shards: usize) -> Result<(), ShardError> {
    if !(1..=10_000).contains(&shards) {
        return Err(ShardError::Spec(Diagnostic::usage(
            format!(
                "{} {shards} is not between 1 and 10000",
                errmap_core::setting::words(crate::Setting::Shards)
            ),
            format!(
                "one shard per array task / completion, e.g. {} 4",
                errmap_core::setting::words(crate::Setting::Shards)
            ),
        )));
    }
    Ok(())
}

/// Shards of a scale-out run share one map domain, which only the job can fix.
pub fn require_shard_domain(file: &JobFile) -> Result<(), ShardError> {
    if file.job.domain.is_none() {
        return Err(ShardError::Domain(Diagnostic::usage(
            format!(
                "{} has no `domain`, and shards need one",
                file.path.display()
            ),
            "add domain = [u_min, v_min, u_max, v_max] (mm) to the job",
        )));
    }
    Ok(())
}

impl Shard {
    /// The shard's own folder inside the batch's output folder: `shard-I-of-N`.
    pub fn folder_name(&self) -> String {
        format!("shard-{}-of-{}", self.index, self.count)
    }

    /// The shard of a folder named `shard-I-of-N`.
    pub fn from_folder_name(name: &str) -> Option<Shard> {
        let rest = name.strip_prefix("shard-")?;
        let (i, n) = rest.split_once("-of-")?;
        Shard::new(i.parse().ok()?, n.parse().ok()?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use errmap_core::error::Diagnose;

    #[test]
    fn shards_split_parts_round_robin_and_read_the_scheduler_env() {
        let s = Shard::parse("1/3").unwrap();
        let taken: Vec<usize> = (0..8).filter(|&i| s.takes(i)).collect();
        assert_eq!(taken, vec![1, 4, 7]);
        for (bad, words) in [
            ("3/3", "`shard` 3/3 is out of range"),
            ("a/3", "`shard` index 'a' is not a number"),
        ] {
            let err = Shard::parse(bad).unwrap_err();
            assert_eq!(err.diagnostic().kind(), "input", "{err}");
            assert!(err.to_string().contains(words), "{err}");
        }
        let env = |k: &str| match k {
            "SLURM_ARRAY_TASK_ID" => Some("2".to_string()),
            "SLURM_ARRAY_TASK_COUNT" => Some("4".to_string()),
            _ => None,
        };
        assert_eq!(Shard::from_env(None, env).unwrap(), Shard::new(2, 4));
        let k8s = |k: &str| (k == "JOB_COMPLETION_INDEX").then(|| "5".to_string());
        assert_eq!(Shard::from_env(Some(6), k8s).unwrap(), Shard::new(5, 6));
        let err = Shard::from_env(None, k8s).unwrap_err();
        assert_eq!(err.diagnostic().kind(), "input", "{err}");
        assert!(
            err.to_string()
                .contains("JOB_COMPLETION_INDEX is set but the number of shards is not known"),
            "{err}"
        );
        assert_eq!(Shard::from_env(None, |_| None).unwrap(), None);
    }

    #[test]
    fn repeated_stems_get_distinct_names() {
        let files = vec![
            PathBuf::from("a/p1.csv"),
            PathBuf::from("b/p1.csv"),
            PathBuf::from("b/p2.csv"),
        ];
        assert_eq!(part_names(&files), vec!["p1-1", "p1-2", "p2"]);
        // `c/p1-1.csv` keeps its name; the repeated stems go round it.
        let files = vec![
            PathBuf::from("a/p1.csv"),
            PathBuf::from("b/p1.csv"),
            PathBuf::from("c/p1-1.csv"),
            PathBuf::from("d/....csv"),
            PathBuf::from("e/family.csv"),
        ];
        let names = part_names(&files);
        assert_eq!(names, vec!["p1-2", "p1-3", "p1-1", "part", "family-part"]);
        assert_eq!(renamed_parts(&files).len(), 4);
    }
}
