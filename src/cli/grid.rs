//! CLI of `errmap grid`: interpolate probe points onto a grid without a network.

use super::Globals;
use errmap::Result;

#[derive(Debug, clap::Args)]
pub struct GridArgs {
    /// The probe file (CSV).
    pub probes: std::path::PathBuf,
}

pub fn run(_args: GridArgs, _globals: Globals) -> Result<i32> {
    super::not_built("grid")
}
