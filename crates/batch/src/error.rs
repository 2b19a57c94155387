//! The typed errors of the batch's operations: reading a job file, a run, shards and their
//! merge, the Slurm and Kubernetes files, a run folder's report. Each variant carries the
//! located diagnostic errmap prints; the binary maps them to exit codes.

use errmap_core::error::{Diagnose, Diagnostic};
use errmap_report::ReportError;

/// Why a job file was refused ([`crate::Job::read`], [`crate::Job::parse`],
/// [`crate::JobFile::probe_files`]).
#[derive(Debug)]
#[non_exhaustive]
pub enum JobError {
    /// Not a job in TOML: a syntax error, an unknown key or a value of the wrong type (the
    /// diagnostic names its line and column).
    Toml(Diagnostic),
    /// A key's value means nothing (out of range, an unknown name, keys that contradict each
    /// other), at its line.
    Value(Diagnostic),
    /// The `probes` glob is bad or matches no file.
    Probes(Diagnostic),
    /// The job file, or a probe file its glob matches, cannot be read.
    Read(Diagnostic),
    /// A bug in errmap.
    Internal(Diagnostic),
}
errmap_core::typed_error!(JobError {
    Toml,
    Value,
    Probes,
    Read,
    Internal
});

impl From<Diagnostic> for JobError {
    /// A diagnostic of the job's checks, by its kind.
    fn from(d: Diagnostic) -> Self {
        match d {
            Diagnostic::Input { .. } | Diagnostic::Usage { .. } | Diagnostic::Numeric { .. } => {
                JobError::Value(d)
            }
            Diagnostic::Io { .. } if d.is_read() => JobError::Read(d),
            Diagnostic::Io { .. } | Diagnostic::Device { .. } | Diagnostic::Internal(_) => {
                JobError::Internal(d)
            }
        }
    }
}

/// Why a shard could not be named ([`crate::Shard::parse`], [`crate::Shard::from_env`],
/// [`crate::check_shard_count`], [`crate::require_shard_domain`]).
#[derive(Debug)]
#[non_exhaustive]
pub enum ShardError {
    /// The shard or shard count given is not `INDEX/COUNT` with 0 ≤ INDEX < COUNT, or out of
    /// range.
    Spec(Diagnostic),
    /// The scheduler's environment (`SLURM_ARRAY_TASK_ID`, `JOB_COMPLETION_INDEX`) names no
    /// usable shard.
    Env(Diagnostic),
    /// The job has no fixed map domain, which shards share.
    Domain(Diagnostic),
}
errmap_core::typed_error!(ShardError { Spec, Env, Domain });

/// Why a run ([`crate::run_job`], [`crate::execute`], [`crate::map_part`]) or its plan
/// ([`crate::ResolvedJob::new`], [`crate::plan_job`], [`crate::MapRequest::plan`]) failed.
#[derive(Debug)]
#[non_exhaustive]
pub enum RunError {
    /// The job file was refused.
    Job(JobError),
    /// The options mean nothing together with this job (a setting out of range, a shard or
    /// `--resume` without a fixed domain).
    Options(Diagnostic),
    /// An input the run needs is bad: a probe file, a toolpath, a file of the previous run
    /// that `--resume` would keep.
    Input(Diagnostic),
    /// The output folder is refused: a file, a folder of other files, or one that holds an
    /// input.
    Output(Diagnostic),
    /// An input cannot be read.
    Read(Diagnostic),
    /// An output cannot be written.
    Write(Diagnostic),
    /// The trainer's device (the GPU) failed.
    Device(Diagnostic),
    /// A bug in errmap.
    Internal(Diagnostic),
}
errmap_core::typed_error!(RunError {
    Job,
    Options,
    Input,
    Output,
    Read,
    Write,
    Device,
    Internal
});

impl From<JobError> for RunError {
    fn from(e: JobError) -> Self {
        RunError::Job(e)
    }
}

impl From<Diagnostic> for RunError {
    /// A diagnostic of the run's stages, by its kind.
    fn from(d: Diagnostic) -> Self {
        match d {
            Diagnostic::Usage { .. } => RunError::Options(d),
            Diagnostic::Input { .. } | Diagnostic::Numeric { .. } => RunError::Input(d),
            Diagnostic::Io { .. } if d.is_read() => RunError::Read(d),
            Diagnostic::Io { .. } => RunError::Write(d),
            Diagnostic::Device { .. } => RunError::Device(d),
            Diagnostic::Internal(_) => RunError::Internal(d),
        }
    }
}

impl RunError {
    /// A refusal of the output folder, or the I/O failure met while checking it.
    pub(crate) fn output(d: Diagnostic) -> Self {
        match d {
            Diagnostic::Usage { .. } | Diagnostic::Input { .. } => RunError::Output(d),
            other => RunError::from(other),
        }
    }
}

/// Why the shards of a job could not be merged ([`crate::merge_job`], [`crate::merge`],
/// [`crate::BatchSummary::read`]).
#[derive(Debug)]
#[non_exhaustive]
pub enum MergeError {
    /// Shards are missing: no shard folder, or shards without a committed run (the hint says
    /// how to rerun them).
    Missing(Diagnostic),
    /// The folders are not one split of one output folder: several shard counts, a folder
    /// merged already, a shard folder elsewhere.
    Split(Diagnostic),
    /// A shard is not what it claims: another shard's or another job's run, a file that
    /// differs from its manifest, summaries that do not fit together, a job that is not the
    /// shards'.
    Mismatch(Diagnostic),
    /// The job file was refused.
    Job(JobError),
    /// The family run of the merge failed.
    Run(RunError),
    /// A shard's file cannot be read.
    Read(Diagnostic),
    /// A bug in errmap.
    Internal(Diagnostic),
}
errmap_core::typed_error!(MergeError {
    Missing,
    Split,
    Mismatch,
    Job,
    Run,
    Read,
    Internal
});

impl From<JobError> for MergeError {
    fn from(e: JobError) -> Self {
        MergeError::Job(e)
    }
}

impl From<RunError> for MergeError {
    fn from(e: RunError) -> Self {
        MergeError::Run(e)
    }
}

impl From<Diagnostic> for MergeError {
    /// A diagnostic of reading the shards, by its kind; the rest is the family run's.
    fn from(d: Diagnostic) -> Self {
        match d {
            Diagnostic::Input { .. } => MergeError::Mismatch(d),
            Diagnostic::Io { .. } if d.is_read() => MergeError::Read(d),
            Diagnostic::Internal(_) => MergeError::Internal(d),
            other => MergeError::Run(RunError::from(other)),
        }
    }
}

/// Why Slurm scripts or Kubernetes manifests were not written or submitted
/// ([`crate::slurm::write_scripts`], [`crate::slurm::submit`], [`crate::k8s::write_manifests`] …).
#[derive(Debug)]
#[non_exhaustive]
pub enum ClusterError {
    /// The array task ids given are not a list of shard indexes.
    Array(Diagnostic),
    /// `sbatch` cannot be run here (no Slurm on this machine).
    NoScheduler(Diagnostic),
    /// `sbatch` refused or failed the submission.
    Submit(Diagnostic),
    /// A script or manifest cannot be written.
    Write(Diagnostic),
    /// A bug in errmap.
    Internal(Diagnostic),
}
errmap_core::typed_error!(ClusterError {
    Array,
    NoScheduler,
    Submit,
    Write,
    Internal
});

impl From<Diagnostic> for ClusterError {
    /// A diagnostic of writing the files: an I/O failure or a bug.
    fn from(d: Diagnostic) -> Self {
        match d {
            Diagnostic::Io { .. } => ClusterError::Write(d),
            _ => ClusterError::Internal(d),
        }
    }
}

/// Why a run folder's `report.html` could not be made or checked
/// ([`crate::folder_report::render_path`], [`crate::manifest::RunManifest::read`]).
#[derive(Debug)]
#[non_exhaustive]
pub enum FolderError {
    /// The folder holds no errmap run and no analysis result, or does not exist.
    NotARun(Diagnostic),
    /// An analysis result was refused, or its report could not be made.
    Result(ReportError),
    /// A file of the run (`run.json`, `summary.json`, a result) is bad.
    File(Diagnostic),
    /// A file of the run cannot be read.
    Read(Diagnostic),
    /// The report cannot be written.
    Write(Diagnostic),
    /// A bug in errmap (or the report's renderer).
    Internal(Diagnostic),
}
errmap_core::typed_error!(FolderError {
    NotARun,
    Result,
    File,
    Read,
    Write,
    Internal
});

impl From<ReportError> for FolderError {
    fn from(e: ReportError) -> Self {
        FolderError::Result(e)
    }
}

impl From<FolderError> for RunError {
    /// A file of the previous run (`--resume`) as any diagnostic of the run.
    fn from(e: FolderError) -> Self {
        RunError::from(e.into_diagnostic())
    }
}

impl From<FolderError> for MergeError {
    /// A shard's `run.json` or `summary.json` as any diagnostic of the merge.
    fn from(e: FolderError) -> Self {
        MergeError::from(e.into_diagnostic())
    }
}

impl From<Diagnostic> for FolderError {
    /// A diagnostic of reading the folder, by its kind.
    fn from(d: Diagnostic) -> Self {
        match d {
            Diagnostic::Usage { .. } => FolderError::NotARun(d),
            Diagnostic::Input { .. } | Diagnostic::Numeric { .. } => FolderError::File(d),
            Diagnostic::Io { .. } if d.is_read() => FolderError::Read(d),
            Diagnostic::Io { .. } => FolderError::Write(d),
            Diagnostic::Device { .. } | Diagnostic::Internal(_) => FolderError::Internal(d),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use errmap_core::error::Location;

    #[test]
    fn a_diagnostic_is_filed_by_its_kind() {
        let input = || Diagnostic::input(Location::line("j.toml", 3), "bad", "");
        let read = || Diagnostic::read("p.csv", std::io::Error::other("gone"));
        let write = || Diagnostic::write("o.csv", std::io::Error::other("full"));
        assert!(matches!(JobError::from(input()), JobError::Value(_)));
        assert!(matches!(JobError::from(read()), JobError::Read(_)));
        assert!(matches!(RunError::from(input()), RunError::Input(_)));
        assert!(matches!(
            RunError::output(Diagnostic::usage("taken", "")),
            RunError::Output(_)
        ));
        assert!(matches!(RunError::output(write()), RunError::Write(_)));
        assert!(matches!(
            RunError::from(Diagnostic::device("lost", "")),
            RunError::Device(_)
        ));
        assert!(matches!(MergeError::from(input()), MergeError::Mismatch(_)));
        assert!(matches!(
            MergeError::from(write()),
            MergeError::Run(RunError::Write(_))
        ));
        assert!(matches!(
            ClusterError::from(write()),
            ClusterError::Write(_)
        ));
        assert!(matches!(
            FolderError::from(Diagnostic::usage("no run", "")),
            FolderError::NotARun(_)
        ));
        // The message is the diagnostic's, word for word.
        assert_eq!(RunError::from(read()).to_string(), read().to_string());
        assert_eq!(RunError::from(read()).diagnostic().kind(), "io");
    }
}
