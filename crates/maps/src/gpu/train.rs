//! Host side of `shaders/train.wgsl`: buffers, pipelines and the epoch loop that trains every network of a batch in the same dispatches.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use super::context::GpuContext;
use super::epochs::{init_buffer, sized, slot_offset, step_buffer, uniform_align, EpochLoop};
use super::layout::{dims_for, pack_samples, Dims, NetInfo, Sample, Step};
use crate::nn::{Mlp, ModelConfig, TrainingSet, GRAD_LANES};
use errmap_core::{Error, Result};

/// WGSL source: the shared declarations, then the training kernels.
pub const TRAIN_WGSL: &str = concat!(
    include_str!("../../../../shaders/common.wgsl"),
    include_str!("../../../../shaders/train.wgsl")
);

const FORWARD_WORKGROUP: u32 = 64;

/// The compiled training kernels of `train.wgsl` (forward-backward, gradient-and-Adam, loss
/// reduction) and their layouts; the row kernels of `gpu::fixed` are added per
/// architecture.
pub struct TrainPipelines {
    data_layout: wgpu::BindGroupLayout,
    step_layout: wgpu::BindGroupLayout,
    layout: wgpu::PipelineLayout,
    forward_backward: wgpu::ComputePipeline,
    gradient_adam: wgpu::ComputePipeline,
    loss_reduce: wgpu::ComputePipeline,
    /// The row gradient kernel of one architecture (src/gpu/fixed.rs), compiled on first
    /// use; `None` where a layer is too wide for it.
    fixed: Mutex<HashMap<ArchitectureKey, Option<Arc<FixedPipelines>>>>,
}

/// Layer sizes and activation shader code of an architecture.
type ArchitectureKey = (Vec<usize>, u32);

/// `gradient_adam_rows` of one architecture and its workgroups per network.
pub struct FixedPipelines {
    gradient_adam: wgpu::ComputePipeline,
    rows: u32,
    /// `forward_backward_rows`, where the layers are narrow enough.
    forward_backward: Option<wgpu::ComputePipeline>,
}

fn entry(binding: u32, ty: wgpu::BufferBindingType, dynamic: bool) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty,
            has_dynamic_offset: dynamic,
            min_binding_size: None,
        },
        count: None,
    }
}

fn storage(binding: u32, read_only: bool) -> wgpu::BindGroupLayoutEntry {
    entry(
        binding,
        wgpu::BufferBindingType::Storage { read_only },
        false,
    )
}

impl TrainPipelines {
    /// Compiles `train.wgsl` on the device; a device error while compiling is an error.
    pub fn new(ctx: &GpuContext) -> Result<TrainPipelines> {
        let device = &ctx.device;
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("train.wgsl"),
            source: wgpu::ShaderSource::Wgsl(TRAIN_WGSL.into()),
        });
        // Group 0: dims, nets, samples, params, moments, acts, deltas, sq_err, losses.
        let data_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("train data"),
            entries: &[
                entry(0, wgpu::BufferBindingType::Uniform, false),
                storage(1, true),
                storage(2, true),
                storage(3, false),
                storage(4, false),
                storage(5, false),
                storage(6, false),
                storage(7, false),
                storage(8, false),
            ],
        });
        // Group 1: this epoch's Step, picked by dynamic offset.
        let step_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("train step"),
            entries: &[entry(0, wgpu::BufferBindingType::Uniform, true)],
        });
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("train"),
            bind_group_layouts: &[Some(&data_layout), Some(&step_layout)],
            immediate_size: 0,
        });
        let pipeline = |entry_point: &str| {
            device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(entry_point),
                layout: Some(&layout),
                module: &module,
                entry_point: Some(entry_point),
                compilation_options: Default::default(),
                cache: None,
            })
        };
        let pipelines = TrainPipelines {
            forward_backward: pipeline("forward_backward"),
            gradient_adam: pipeline("gradient_adam"),
            loss_reduce: pipeline("loss_reduce"),
            data_layout,
            step_layout,
            layout,
            fixed: Mutex::new(HashMap::new()),
        };
        ctx.wait("compiling the training shaders")?;
        Ok(pipelines)
    }
}

impl TrainPipelines {
    /// The row gradient kernel for `net`'s architecture, compiled once per architecture.
    fn fixed_for(&self, ctx: &GpuContext, net: &Mlp) -> Result<Option<Arc<FixedPipelines>>> {
        let key = (net.layer_sizes.clone(), net.activation.shader_code());
        let mut cache = self
            .fixed
            .lock()
            .map_err(|_| Error::Internal("training pipeline cache poisoned".into()))?;
        if let Some(found) = cache.get(&key) {
            return Ok(found.clone());
        }
        let built = match super::fixed::gradient_rows_source(&net.layer_sizes) {
            None => None,
            Some((gradient, rows)) => {
                let forward = super::fixed::forward_rows_source(&net.layer_sizes, net.activation);
                let source = format!(
                    "{TRAIN_WGSL}\n{gradient}\n{}",
                    forward.as_deref().unwrap_or("")
                );
                let device = &ctx.device;
                let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                    label: Some("train.wgsl + gradient_adam_rows"),
                    source: wgpu::ShaderSource::Wgsl(source.into()),
                });
                let pipeline = |entry_point: &str| {
                    device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                        label: Some(entry_point),
                        layout: Some(&self.layout),
                        module: &module,
                        entry_point: Some(entry_point),
                        compilation_options: Default::default(),
                        cache: None,
                    })
                };
                let fixed = FixedPipelines {
                    gradient_adam: pipeline("gradient_adam_rows"),
                    rows,
                    forward_backward: forward.map(|_| pipeline("forward_backward_rows")),
                };
                ctx.wait("compiling the unrolled training shaders")?;
                Some(Arc::new(fixed))
            }
        };
        cache.insert(key, built.clone());
        Ok(built)
    }
}

/// Bytes a batch of these sets needs in its largest buffer (activations or deltas).
fn largest_buffer_bytes(total_samples: u64, unit_count: u64, nets: u64, params: u64) -> u64 {
    (total_samples * unit_count * 4).max(2 * nets * params * 4)
}

/// Splits `0..sets.len()` into consecutive groups that fit the device's buffer and
/// dispatch limits; a single network that does not fit is an error.
/// `limit_bytes`: the largest buffer the device binds; `max_nets`: its largest dispatch dimension.
pub fn plan_groups(
    limit_bytes: u64,
    max_nets: usize,
    sets: &[TrainingSet],
    unit_count: u64,
    param_count: u64,
) -> Result<Vec<std::ops::Range<usize>>> {
    let limit = limit_bytes;
    let max_nets = max_nets.max(1);
    let mut groups = Vec::new();
    let mut start = 0;
    let mut samples = 0u64;
    for (k, set) in sets.iter().enumerate() {
        let n = set.len() as u64;
        let alone = largest_buffer_bytes(n, unit_count, 1, param_count);
        if alone > limit {
            return Err(Error::device(
                format!(
                    "training set {k} ({n} samples) needs a {} MB buffer, the device allows {} MB",
                    alone >> 20,
                    limit >> 20
                ),
                format!(
                    "use a coarser training-set spacing, a smaller network, or {} cpu",
                    errmap_core::setting::words(crate::Setting::Backend)
                ),
            ));
        }
        let count = (k - start + 1) as u64;
        if largest_buffer_bytes(samples + n, unit_count, count, param_count) > limit
            || k - start >= max_nets
        {
            groups.push(start..k);
            start = k;
            samples = 0;
        }
        samples += n;
    }
    if start < sets.len() {
        groups.push(start..sets.len());
    }
    Ok(groups)
}

/// Trains one group (all networks fit the device at once). `initial` and `sets` are checked.
pub fn train_group(
    ctx: &GpuContext,
    pipelines: &TrainPipelines,
    initial: &[Mlp],
    sets: &[TrainingSet],
    config: &ModelConfig,
    first_index: usize,
) -> Result<Vec<Mlp>> {
    let Some(first) = initial.first() else {
        return Ok(Vec::new());
    };
    let buffers = GroupBuffers::new(ctx, initial, sets)?;
    let (data_group, step_group) = buffers.bind(ctx, pipelines)?;
    let fixed = pipelines.fixed_for(ctx, first)?;
    let dispatch = Dispatch::plan(
        ctx,
        pipelines,
        fixed.as_deref(),
        sets,
        initial.len(),
        first.params.len(),
    );
    let align = buffers.align;
    let epochs = EpochLoop {
        ctx,
        config,
        steps: &buffers.steps,
        align,
        losses: &buffers.losses,
        net_count: initial.len(),
        first_index,
    };
    epochs.run(|pass, epochs, read_loss| {
        pass.set_bind_group(0, &data_group, &[]);
        for e in epochs.clone() {
            let step_offset = slot_offset(e - epochs.start, align);
            dispatch.record_epoch(pass, &step_group, step_offset);
        }
        if read_loss {
            dispatch.record_loss(pass, pipelines);
        }
    })?;
    epochs.read_trained(&buffers.params, initial, first.params.len())
}

/// The buffers of one group's training: group 0's bindings in order, then the Step slots.
struct GroupBuffers {
    dims: wgpu::Buffer,
    nets: wgpu::Buffer,
    samples: wgpu::Buffer,
    params: wgpu::Buffer,
    moments: wgpu::Buffer,
    acts: wgpu::Buffer,
    deltas: wgpu::Buffer,
    sq_err: wgpu::Buffer,
    losses: wgpu::Buffer,
    steps: wgpu::Buffer,
    /// Bytes between Step slots.
    align: u64,
}

impl GroupBuffers {
    /// Packs the networks and their samples and allocates the group's buffers.
    fn new(ctx: &GpuContext, initial: &[Mlp], sets: &[TrainingSet]) -> Result<GroupBuffers> {
        let device = &ctx.device;
        let net_count = initial.len();
        let total: usize = sets.iter().map(|s| s.len()).sum();
        let dims: Dims = dims_for(&initial[0], net_count, total);
        let (net_infos, samples): (Vec<NetInfo>, Vec<Sample>) = pack_samples(sets, dims.unit_count);
        let params: Vec<f32> = initial
            .iter()
            .flat_map(|n| n.params.iter().copied())
            .collect();
        let units = total as u64 * dims.unit_count as u64;
        let zeroed = |label: &str, floats: u64| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: floats.max(1) * 4,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            })
        };
        let storage = wgpu::BufferUsages::STORAGE;
        let align = uniform_align(ctx);
        let buffers = GroupBuffers {
            dims: init_buffer(
                device,
                "dims",
                bytemuck::bytes_of(&dims),
                wgpu::BufferUsages::UNIFORM,
            ),
            nets: init_buffer(device, "nets", bytemuck::cast_slice(&net_infos), storage),
            samples: init_buffer(device, "samples", bytemuck::cast_slice(&samples), storage),
            params: init_buffer(
                device,
                "params",
                bytemuck::cast_slice(&params),
                storage | wgpu::BufferUsages::COPY_SRC,
            ),
            // Moments start at zero (wgpu zero-initialises buffers).
            moments: zeroed("moments", 2 * params.len() as u64),
            acts: zeroed("acts", units),
            deltas: zeroed("deltas", units),
            sq_err: zeroed("sq_err", total as u64),
            losses: zeroed("losses", net_count as u64),
            steps: step_buffer(device, align),
            align,
        };
        ctx.check("allocating training buffers")?;
        Ok(buffers)
    }

    /// Group 0 (the data) and group 1 (one Step slot, dynamically offset).
    fn bind(
        &self,
        ctx: &GpuContext,
        pipelines: &TrainPipelines,
    ) -> Result<(wgpu::BindGroup, wgpu::BindGroup)> {
        let device = &ctx.device;
        let data_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("train data"),
            layout: &pipelines.data_layout,
            entries: &[
                (0, &self.dims),
                (1, &self.nets),
                (2, &self.samples),
                (3, &self.params),
                (4, &self.moments),
                (5, &self.acts),
                (6, &self.deltas),
                (7, &self.sq_err),
                (8, &self.losses),
            ]
            .map(|(binding, buffer)| wgpu::BindGroupEntry {
                binding,
                resource: buffer.as_entire_binding(),
            }),
        });
        let step_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("train step"),
            layout: &pipelines.step_layout,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: sized(&self.steps, std::mem::size_of::<Step>() as u64),
            }],
        });
        ctx.check("binding training buffers")?;
        Ok((data_group, step_group))
    }
}

/// The pipelines one group's epochs run and their workgroup counts.
struct Dispatch<'a> {
    forward: &'a wgpu::ComputePipeline,
    forward_groups: u32,
    gradient: &'a wgpu::ComputePipeline,
    gradient_groups: u32,
    loss_groups: u32,
    net_count: u32,
}

impl<'a> Dispatch<'a> {
    /// The row kernels of `fixed` where the architecture has them, else the generic ones.
    fn plan(
        ctx: &GpuContext,
        pipelines: &'a TrainPipelines,
        fixed: Option<&'a FixedPipelines>,
        sets: &[TrainingSet],
        net_count: usize,
        param_count: usize,
    ) -> Dispatch<'a> {
        let forward = fixed
            .and_then(|f| f.forward_backward.as_ref())
            .unwrap_or(&pipelines.forward_backward);
        let max_groups = ctx.limits.max_compute_workgroups_per_dimension.max(1);
        // x: samples of the largest network, y: networks.
        let largest = sets.iter().map(|s| s.len()).max().unwrap_or(1) as u32;
        let forward_groups = largest.div_ceil(FORWARD_WORKGROUP).clamp(1, max_groups);
        // Gradient: the row kernel (one workgroup per weight row) where the architecture has
        // one, else one thread per parameter.
        let (gradient, gradient_groups) = match fixed {
            Some(f) if f.rows <= max_groups => (&f.gradient_adam, f.rows),
            _ => (
                &pipelines.gradient_adam,
                (param_count as u32).div_ceil(64).clamp(1, max_groups),
            ),
        };
        debug_assert_eq!(GRAD_LANES, 64);
        Dispatch {
            forward,
            forward_groups,
            gradient,
            gradient_groups,
            loss_groups: (net_count as u32).clamp(1, max_groups),
            net_count: net_count as u32,
        }
    }

    /// One epoch: forward and backward, then gradient and Adam, with the Step at `step_offset`.
    fn record_epoch(
        &self,
        pass: &mut wgpu::ComputePass<'_>,
        step_group: &wgpu::BindGroup,
        step_offset: u32,
    ) {
        pass.set_pipeline(self.forward);
        pass.set_bind_group(1, step_group, &[step_offset]);
        pass.dispatch_workgroups(self.forward_groups, self.net_count, 1);
        pass.set_pipeline(self.gradient);
        pass.dispatch_workgroups(self.gradient_groups, self.net_count, 1);
    }

    /// The reduction of each network's squared errors into its loss.
    fn record_loss(&self, pass: &mut wgpu::ComputePass<'_>, pipelines: &TrainPipelines) {
        pass.set_pipeline(&pipelines.loss_reduce);
        pass.dispatch_workgroups(self.loss_groups, 1, 1);
    }
}
