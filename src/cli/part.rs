//! CLI of part-family mapping: `batch`, `map` and `merge`.

use super::Globals;
use errmap::Result;

#[derive(Debug, clap::Args)]
pub struct BatchArgs {
    /// The job manifest (TOML).
    pub job: std::path::PathBuf,
}

#[derive(Debug, clap::Args)]
pub struct MapArgs {
    /// The probe file (CSV).
    pub probes: std::path::PathBuf,
}

#[derive(Debug, clap::Args)]
pub struct MergeArgs {
    /// Summaries of the shards.
    pub summaries: Vec<std::path::PathBuf>,
}

pub fn run_batch(_args: BatchArgs, _globals: Globals) -> Result<i32> {
    super::not_built("batch")
}

pub fn run_map(_args: MapArgs, _globals: Globals) -> Result<i32> {
    super::not_built("map")
}

pub fn run_merge(_args: MergeArgs, _globals: Globals) -> Result<i32> {
    super::not_built("merge")
}
