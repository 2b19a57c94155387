//! The wgpu path: adapter choice, device limits, buffers and pipelines for training and evaluating networks in WGSL compute shaders.
//!
//! One host file per shader family: [`train`] (`shaders/train.wgsl`), [`evaluate`]
//! (`shaders/evaluate.wgsl`); [`layout`] mirrors the WGSL structs; [`context`] picks the
//! adapter and turns device failures into [`Error::device`].

pub mod context;
pub mod evaluate;
pub mod fixed;
pub mod layout;
pub mod train;

pub use context::{list_adapters, AdapterSummary, GpuContext, LimitsSummary};

use crate::nn::{check_batch, check_nets, Mlp, ModelConfig, Trainer, TrainingSet, MAX_WIDTH};
use crate::{Error, Result};

/// Trains and evaluates networks in WGSL compute shaders on one device.
pub struct GpuTrainer {
    ctx: GpuContext,
    /// Largest buffer a training group may use (the device limit unless lowered).
    buffer_limit_bytes: u64,
    train: train::TrainPipelines,
    eval: evaluate::EvalPipeline,
}

impl GpuTrainer {
    /// Opens the best adapter (hardware, else software Vulkan) and compiles the shaders.
    pub fn new() -> Result<GpuTrainer> {
        GpuTrainer::open(true)
    }

    /// Like [`GpuTrainer::new`]; `allow_software = false` refuses software adapters.
    pub fn open(allow_software: bool) -> Result<GpuTrainer> {
        let ctx = GpuContext::open(allow_software)?;
        let train = train::TrainPipelines::new(&ctx)?;
        let eval = evaluate::EvalPipeline::new(&ctx)?;
        let buffer_limit_bytes = ctx
            .limits
            .max_storage_buffer_binding_size
            .min(ctx.limits.max_buffer_size);
        Ok(GpuTrainer {
            ctx,
            buffer_limit_bytes,
            train,
            eval,
        })
    }

    /// Lowers the buffer size a training group may use, so a batch splits into more
    /// groups (for tests of the splitting; results do not depend on it).
    pub fn with_buffer_limit(mut self, bytes: u64) -> GpuTrainer {
        self.buffer_limit_bytes = self.buffer_limit_bytes.min(bytes);
        self
    }

    pub fn context(&self) -> &GpuContext {
        &self.ctx
    }
}

/// The shaders hold one layer in private memory and the layer table in a uniform.
fn check_gpu_shape(nets: &[Mlp]) -> Result<()> {
    for (k, net) in nets.iter().enumerate() {
        if net.layer_sizes.len() > layout::MAX_LAYERS + 1
            || net.layer_sizes.iter().any(|&w| w > MAX_WIDTH)
        {
            return Err(Error::usage(
                format!(
                    "network {k} has layers {:?}; the GPU path takes at most {} hidden layers of width {MAX_WIDTH}",
                    net.layer_sizes,
                    layout::MAX_LAYERS - 1
                ),
                "use a smaller network or --backend cpu",
            ));
        }
    }
    Ok(())
}

impl Trainer for GpuTrainer {
    fn name(&self) -> String {
        format!("gpu: {}", self.ctx.describe())
    }

    fn train_from(
        &self,
        initial: Vec<Mlp>,
        sets: &[TrainingSet],
        config: &ModelConfig,
    ) -> Result<Vec<Mlp>> {
        check_batch(&initial, sets, config)?;
        check_gpu_shape(&initial)?;
        if config.optimizer != crate::nn::Optimizer::Adam {
            return Err(Error::usage(
                "model.optimizer = \"lbfgs\" runs on the CPU trainers, not the GPU",
                "use backend = \"cpu\" or \"auto\" with lbfgs, or optimizer = \"adam\" on the GPU",
            ));
        }
        let Some(first) = initial.first() else {
            return Ok(Vec::new());
        };
        let dims = layout::dims_for(first, 1, 0);
        let groups = train::plan_groups(
            self.buffer_limit_bytes,
            self.ctx.limits.max_compute_workgroups_per_dimension as usize,
            sets,
            dims.unit_count as u64,
            dims.param_count as u64,
        )?;
        let mut out = Vec::with_capacity(initial.len());
        for range in groups {
            out.extend(train::train_group(
                &self.ctx,
                &self.train,
                &initial[range.clone()],
                &sets[range.clone()],
                config,
                range.start,
            )?);
        }
        Ok(out)
    }

    fn evaluate_batch(&self, nets: &[Mlp], inputs: &[[f32; 2]]) -> Result<Vec<Vec<f32>>> {
        check_nets(nets)?;
        check_gpu_shape(nets)?;
        evaluate::evaluate(&self.ctx, &self.eval, nets, inputs)
    }
}

/// Mesa's Vulkan drivers print "XDG_RUNTIME_DIR is invalid or not set" on headless machines
/// (batch nodes, CI) where no login session sets it. When it is unset, point it at a private
/// 0700 folder of ours, as the XDG spec requires. Call it before any thread starts or opens
/// Vulkan (the binary does so first thing in `main`; in-process tests from their one shared
/// set-up): changing the environment while other threads read it is a race.
pub fn quiet_headless_vulkan() {
    #[cfg(unix)]
    {
        use std::os::unix::fs::{DirBuilderExt, MetadataExt, PermissionsExt};
        if std::env::var_os("XDG_RUNTIME_DIR").is_some() {
            return;
        }
        let Ok(uid) = std::fs::metadata("/proc/self").map(|m| m.uid()) else {
            return;
        };
        let dir = std::env::temp_dir().join(format!("errmap-runtime-{uid}"));
        let _ = std::fs::DirBuilder::new().mode(0o700).create(&dir);
        // Use it only if it is ours and private.
        match std::fs::symlink_metadata(&dir) {
            Ok(m) if m.is_dir() && m.uid() == uid && m.permissions().mode() & 0o777 == 0o700 => {
                std::env::set_var("XDG_RUNTIME_DIR", &dir);
            }
            _ => {}
        }
    }
}
