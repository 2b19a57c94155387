//! The wgpu path: adapter choice, device limits, buffers and pipelines for training and evaluating networks in WGSL compute shaders.
//!
//! One host file per shader family: [`train`] (`shaders/train.wgsl`) and `fixed` for
//! hardware GPUs, [`lavapipe`] (generated WGSL) for CPU adapters, [`evaluate`]
//! (`shaders/evaluate.wgsl`); [`layout`] mirrors the WGSL structs; `context` picks the
//! adapter ([`GpuContext`]) and turns device failures into [`Error::device`].

pub(crate) mod context;
pub(crate) mod epochs;
pub mod evaluate;
pub(crate) mod fixed;
pub mod lavapipe;
pub mod layout;
pub mod pipeline_cache;
pub mod train;

pub use context::{list_adapters, AdapterSummary, GpuContext, LimitsSummary};

use crate::nn::{check_batch, check_nets, Mlp, ModelConfig, Trainer, TrainingSet, MAX_WIDTH};
use errmap_core::{Error, Result};

/// Which training kernels a [`GpuTrainer`] runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum KernelFamily {
    /// By adapter: [`KernelFamily::CpuAdapter`] on a CPU adapter (lavapipe), else
    /// [`KernelFamily::Hardware`].
    #[default]
    Auto,
    /// `shaders/train.wgsl` and `gpu::fixed`: a workgroup per tile of samples, 64 gradient
    /// lanes (the order of `CpuTrainer::with_lanes(GRAD_LANES)`).
    Hardware,
    /// [`lavapipe`]: one 8-invocation workgroup per network and epoch, the reference order
    /// (`CpuTrainer::reference()`, bit for bit). Architectures it does not take (see
    /// [`lavapipe::epoch_source`]) train with the hardware kernels.
    CpuAdapter,
}

/// Trains and evaluates networks in WGSL compute shaders on one device.
pub struct GpuTrainer {
    ctx: GpuContext,
    /// Largest buffer a training group may use (the device limit unless lowered).
    buffer_limit_bytes: u64,
    family: KernelFamily,
    train: train::TrainPipelines,
    cpu_adapter: lavapipe::CpuKernels,
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
        let cpu_adapter = lavapipe::CpuKernels::new(&ctx, errmap_core::io::cache_dir());
        let eval = evaluate::EvalPipeline::new(&ctx)?;
        let buffer_limit_bytes = ctx
            .limits
            .max_storage_buffer_binding_size
            .min(ctx.limits.max_buffer_size);
        Ok(GpuTrainer {
            ctx,
            buffer_limit_bytes,
            family: KernelFamily::Auto,
            train,
            cpu_adapter,
            eval,
        })
    }

    /// Lowers the buffer size a training group may use, so a batch splits into more
    /// groups (for tests of the splitting; results do not depend on it).
    pub fn with_buffer_limit(mut self, bytes: u64) -> GpuTrainer {
        self.buffer_limit_bytes = self.buffer_limit_bytes.min(bytes);
        self
    }

    /// Chooses the training kernels (both families run on any adapter; tests use this to
    /// check each against its CPU reference order on lavapipe).
    pub fn with_kernels(mut self, family: KernelFamily) -> GpuTrainer {
        self.family = family;
        self
    }

    /// Keeps the CPU-adapter kernels' pipeline caches in `dir` instead of errmap's cache
    /// folder (`None`: keep none). Takes effect for kernels not built yet.
    pub fn with_pipeline_cache_dir(mut self, dir: Option<std::path::PathBuf>) -> GpuTrainer {
        self.cpu_adapter.cache_dir = dir;
        self
    }

    /// Sends notes (a pipeline cache that could not be used or written) to `notes`.
    pub fn with_notes(mut self, notes: errmap_core::progress::Notes) -> GpuTrainer {
        self.cpu_adapter.notes = notes;
        self
    }

    /// What the pipeline cache did when this architecture's CPU-adapter kernel was built
    /// (`None` when it is not built, or this trainer uses the hardware kernels for it).
    pub fn pipeline_cache_use(&self, config: &ModelConfig) -> Option<pipeline_cache::CacheUse> {
        let net = Mlp::init(&config.layer_sizes(), config.activation, 0);
        self.cpu_adapter
            .built(&net)
            .map(|kernel| kernel.cache.clone())
    }

    /// Makes the CPU-adapter kernels reduce their lanes through workgroup memory, as on a
    /// device without 8-wide subgroups (for tests of that path; the bits do not change).
    pub fn without_subgroups(mut self) -> GpuTrainer {
        self.ctx.subgroup_size = None;
        self
    }

    /// The open device this trainer trains on.
    pub fn context(&self) -> &GpuContext {
        &self.ctx
    }

    /// Builds the training kernel of this architecture now instead of at the first training
    /// call, and returns the seconds its build took (pipeline creation and llvmpipe's compile
    /// at the first dispatch; 0 when it was built before), or `None` when this trainer uses
    /// the hardware kernels for it (compiled in [`GpuTrainer::open`]).
    pub fn prepare(&self, config: &ModelConfig) -> Result<Option<f64>> {
        config.validate()?;
        let net = Mlp::init(&config.layer_sizes(), config.activation, 0);
        let started = std::time::Instant::now();
        let kernel = self.cpu_adapter_kernel(&net)?;
        Ok(kernel.map(|_| started.elapsed().as_secs_f64()))
    }

    /// The CPU-adapter kernel of `net`'s architecture when this trainer uses that family
    /// for it (built on first use).
    fn cpu_adapter_kernel(
        &self,
        net: &Mlp,
    ) -> Result<Option<std::sync::Arc<lavapipe::EpochPipeline>>> {
        let wanted = match self.family {
            KernelFamily::Auto => self.ctx.adapter.software,
            KernelFamily::Hardware => false,
            KernelFamily::CpuAdapter => true,
        };
        if !wanted {
            return Ok(None);
        }
        self.cpu_adapter.pipeline_for(&self.ctx, net)
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
                format!("use a smaller network or {} cpu", errmap_core::setting::words(crate::Setting::Backend)),
            ));
        }
    }
    Ok(())
}

/// The networks of every group in order, each group trained by `train_group`.
fn train_in_groups(
    groups: Vec<std::ops::Range<usize>>,
    net_count: usize,
    mut train_group: impl FnMut(std::ops::Range<usize>) -> Result<Vec<Mlp>>,
) -> Result<Vec<Mlp>> {
    let mut out = Vec::with_capacity(net_count);
    for range in groups {
        out.extend(train_group(range)?);
    }
    Ok(out)
}

impl Trainer for GpuTrainer {
    fn name(&self) -> String {
        format!("gpu: {}", self.ctx.describe())
    }

    fn networks_per_call(&self) -> usize {
        64
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
        if let Some(kernel) = self.cpu_adapter_kernel(first)? {
            // Samples (16 bytes each, as 4 "units") and the parameter buffers per group.
            let plan = kernel.plan();
            let groups = train::plan_groups(
                self.buffer_limit_bytes,
                usize::MAX,
                sets,
                4,
                plan.stride_floats as u64,
            )?;
            return train_in_groups(groups, initial.len(), |range| {
                lavapipe::train_group(
                    &self.ctx,
                    &self.cpu_adapter,
                    &kernel,
                    &initial[range.clone()],
                    &sets[range.clone()],
                    config,
                    range.start,
                )
            });
        }
        let dims = layout::dims_for(first, 1, 0);
        let groups = train::plan_groups(
            self.buffer_limit_bytes,
            self.ctx.limits.max_compute_workgroups_per_dimension as usize,
            sets,
            dims.unit_count as u64,
            dims.param_count as u64,
        )?;
        train_in_groups(groups, initial.len(), |range| {
            train::train_group(
                &self.ctx,
                &self.train,
                &initial[range.clone()],
                &sets[range.clone()],
                config,
                range.start,
            )
        })
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
