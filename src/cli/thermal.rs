//! CLI of `errmap thermal …`.

use super::Globals;
use errmap::Result;

#[derive(Debug, clap::Subcommand)]
pub enum ThermalCommand {
    /// Analyse measurements.
    Analyze { file: std::path::PathBuf },
}

#[derive(Debug, clap::Args)]
pub struct SynthThermalArgs {
    /// Output folder.
    #[arg(long)]
    pub out: std::path::PathBuf,
}

pub fn run(_cmd: ThermalCommand, _globals: Globals) -> Result<i32> {
    super::not_built("thermal")
}

pub fn run_synth(_args: SynthThermalArgs, _globals: Globals) -> Result<i32> {
    super::not_built("synth thermal")
}
