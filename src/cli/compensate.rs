//! CLI of `errmap compensate`: rewrite a G-code or CSV toolpath with P' = P − E.

use super::Globals;
use errmap::Result;

#[derive(Debug, clap::Args)]
pub struct CompensateArgs {
    /// The toolpath to compensate.
    pub input: std::path::PathBuf,
}

pub fn run(_args: CompensateArgs, _globals: Globals) -> Result<i32> {
    super::not_built("compensate")
}
