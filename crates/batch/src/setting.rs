//! The batch settings that hints name; the front end words them (the binary as its flags).

/// A setting of a batch, a one-part map, a merge or a scale-out that a hint can tell the user
/// to give.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Setting {
    /// This process's shard of the parts, `INDEX/COUNT`.
    Shard,
    /// The number of shards of a split.
    Shards,
    /// Keep the finished parts of the folder's last run.
    Resume,
    /// The output folder of a run, instead of the job's `output`.
    OutDir,
    /// The job file a merge reduces with.
    Job,
    /// The Slurm array task ids to submit.
    Array,
    /// Print the scripts instead of writing or submitting them.
    DryRun,
    /// Submit the scripts to Slurm.
    Submit,
    /// The step of the output grid of one part, mm.
    GridStep,
    /// The spacing of the training set of one part, mm.
    Spacing,
    /// The gross-error threshold k of one part.
    KSigma,
    /// An analysis's chart (linear and rotary `analyze`), whose folder holds its result.
    Chart,
}

impl errmap_core::Setting for Setting {
    fn key(self) -> &'static str {
        match self {
            Setting::Shard => "shard",
            Setting::Shards => "shards",
            Setting::Resume => "resume",
            Setting::OutDir => "output",
            Setting::Job => "job",
            Setting::Array => "array",
            Setting::DryRun => "dry_run",
            Setting::Submit => "submit",
            Setting::GridStep => "grid_step_mm",
            Setting::Spacing => "spacing_mm",
            Setting::KSigma => "k_sigma",
            Setting::Chart => "chart",
        }
    }
}
