//! CLI of `errmap rotary …`.

use super::Globals;
use errmap::Result;

#[derive(Debug, clap::Subcommand)]
pub enum RotaryCommand {
    /// Analyse measurements.
    Analyze { file: std::path::PathBuf },
}

#[derive(Debug, clap::Args)]
pub struct SynthRotaryArgs {
    /// Output folder.
    #[arg(long)]
    pub out: std::path::PathBuf,
}

pub fn run(_cmd: RotaryCommand, _globals: Globals) -> Result<i32> {
    super::not_built("rotary")
}

pub fn run_synth(_args: SynthRotaryArgs, _globals: Globals) -> Result<i32> {
    super::not_built("synth rotary")
}
