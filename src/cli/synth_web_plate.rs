//! CLI of `errmap synth web-plate`.

use super::Globals;
use errmap::Result;

#[derive(Debug, clap::Args)]
pub struct SynthWebPlateArgs {
    /// Output folder.
    #[arg(long)]
    pub out: std::path::PathBuf,
}

pub fn run(_args: SynthWebPlateArgs, _globals: Globals) -> Result<i32> {
    super::not_built("synth web-plate")
}
