//! CLI of `errmap linear …`.

use super::Globals;
use errmap::Result;

#[derive(Debug, clap::Subcommand)]
pub enum LinearCommand {
    /// Analyse measurements.
    Analyze { file: std::path::PathBuf },
}

#[derive(Debug, clap::Args)]
pub struct SynthLinearArgs {
    /// Output folder.
    #[arg(long)]
    pub out: std::path::PathBuf,
}

pub fn run(_cmd: LinearCommand, _globals: Globals) -> Result<i32> {
    super::not_built("linear")
}

pub fn run_synth(_args: SynthLinearArgs, _globals: Globals) -> Result<i32> {
    super::not_built("synth linear")
}
