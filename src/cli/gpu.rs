//! CLI of `errmap gpu-info`: adapters, the one chosen and its limits.

use super::Globals;
use errmap::Result;

#[derive(Debug, clap::Args)]
pub struct GpuInfoArgs {}

pub fn run(_args: GpuInfoArgs, _globals: Globals) -> Result<i32> {
    super::not_built("gpu-info")
}
