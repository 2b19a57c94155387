//! Host side of `shaders/train.wgsl`: buffers, pipelines and the epoch loop that trains every network of a batch in the same dispatches.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use wgpu::util::DeviceExt;

use super::context::GpuContext;
use super::layout::{dims_for, pack_samples, Dims, NetInfo, Sample, Step};
use crate::nn::{diverged, Mlp, ModelConfig, TrainingSet, GRAD_LANES};
use crate::{Error, Result};

/// WGSL source: the shared declarations, then the training kernels.
pub const TRAIN_WGSL: &str = concat!(
    include_str!("../../shaders/common.wgsl"),
    include_str!("../../shaders/train.wgsl")
);

/// Most epochs recorded into one submission (and Step slots in the step buffer).
const EPOCHS_PER_SUBMISSION: u32 = 256;
const FORWARD_WORKGROUP: u32 = 64;

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
                "use a coarser training-set spacing, a smaller network, or --backend cpu",
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
    let device = &ctx.device;
    let net_count = initial.len();
    let Some(first) = initial.first() else {
        return Ok(Vec::new());
    };
    let total: usize = sets.iter().map(|s| s.len()).sum();
    let dims: Dims = dims_for(first, net_count, total);
    let (net_infos, samples): (Vec<NetInfo>, Vec<Sample>) = pack_samples(sets, dims.unit_count);
    let param_count = dims.param_count as usize;
    let params: Vec<f32> = initial
        .iter()
        .flat_map(|n| n.params.iter().copied())
        .collect();
    let units = total as u64 * dims.unit_count as u64;

    let init = |label: &str, contents: &[u8], usage: wgpu::BufferUsages| {
        device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents,
            usage,
        })
    };
    let zeroed = |label: &str, floats: u64| {
        device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: floats.max(1) * 4,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        })
    };
    let storage = wgpu::BufferUsages::STORAGE;
    let dims_buf = init(
        "dims",
        bytemuck::bytes_of(&dims),
        wgpu::BufferUsages::UNIFORM,
    );
    let nets_buf = init("nets", bytemuck::cast_slice(&net_infos), storage);
    let samples_buf = init("samples", bytemuck::cast_slice(&samples), storage);
    let params_buf = init(
        "params",
        bytemuck::cast_slice(&params),
        storage | wgpu::BufferUsages::COPY_SRC,
    );
    // Moments start at zero (wgpu zero-initialises buffers).
    let moments_buf = zeroed("moments", 2 * params.len() as u64);
    let acts_buf = zeroed("acts", units);
    let deltas_buf = zeroed("deltas", units);
    let sq_err_buf = zeroed("sq_err", total as u64);
    let losses_buf = zeroed("losses", net_count as u64);
    let align = ctx.limits.min_uniform_buffer_offset_alignment.max(16) as u64;
    let step_buf = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("steps"),
        size: EPOCHS_PER_SUBMISSION as u64 * align,
        usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    ctx.check("allocating training buffers")?;

    let data_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("train data"),
        layout: &pipelines.data_layout,
        entries: &[
            (0, &dims_buf),
            (1, &nets_buf),
            (2, &samples_buf),
            (3, &params_buf),
            (4, &moments_buf),
            (5, &acts_buf),
            (6, &deltas_buf),
            (7, &sq_err_buf),
            (8, &losses_buf),
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
            resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                buffer: &step_buf,
                offset: 0,
                size: std::num::NonZeroU64::new(std::mem::size_of::<Step>() as u64),
            }),
        }],
    });
    ctx.check("binding training buffers")?;

    let fixed = pipelines.fixed_for(ctx, first)?;
    let forward_pipeline = fixed
        .as_deref()
        .and_then(|f| f.forward_backward.as_ref())
        .unwrap_or(&pipelines.forward_backward);
    let max_groups = ctx.limits.max_compute_workgroups_per_dimension.max(1);
    // x: samples of the largest network, y: networks.
    let largest = sets.iter().map(|s| s.len()).max().unwrap_or(1) as u32;
    let forward_groups = largest.div_ceil(FORWARD_WORKGROUP).clamp(1, max_groups);
    // Gradient: the row kernel (one workgroup per weight row) where the architecture has
    // one, else one thread per parameter.
    let (gradient_pipeline, gradient_groups) = match fixed.as_deref() {
        Some(f) if f.rows <= max_groups => (&f.gradient_adam, f.rows),
        _ => (
            &pipelines.gradient_adam,
            (param_count as u32).div_ceil(64).clamp(1, max_groups),
        ),
    };
    let loss_groups = (net_count as u32).clamp(1, max_groups);
    debug_assert_eq!(GRAD_LANES, 64);

    let mut epoch = 0u32;
    while epoch < config.epochs {
        // Chunks end at loss read-back epochs so the loss is read only there.
        let next_loss = (epoch / config.loss_every + 1) * config.loss_every;
        let end = config
            .epochs
            .min(epoch + EPOCHS_PER_SUBMISSION)
            .min(next_loss);
        let read_loss = end == next_loss || end == config.epochs;
        let mut slots = vec![0u8; ((end - epoch) as u64 * align) as usize];
        for e in epoch..end {
            let at = ((e - epoch) as u64 * align) as usize;
            slots[at..at + std::mem::size_of::<Step>()]
                .copy_from_slice(bytemuck::bytes_of(&Step::at(config, e)));
        }
        ctx.queue.write_buffer(&step_buf, 0, &slots);
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("epochs"),
        });
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("epochs"),
                timestamp_writes: None,
            });
            pass.set_bind_group(0, &data_group, &[]);
            for e in epoch..end {
                pass.set_pipeline(forward_pipeline);
                pass.set_bind_group(1, &step_group, &[((e - epoch) as u64 * align) as u32]);
                pass.dispatch_workgroups(forward_groups, net_count as u32, 1);
                pass.set_pipeline(gradient_pipeline);
                pass.dispatch_workgroups(gradient_groups, net_count as u32, 1);
            }
            if read_loss {
                pass.set_pipeline(&pipelines.loss_reduce);
                pass.dispatch_workgroups(loss_groups, 1, 1);
            }
        }
        ctx.queue.submit([encoder.finish()]);
        if read_loss {
            let bytes = ctx.read_buffer(&losses_buf, net_count as u64 * 4, "training")?;
            let losses: &[f32] = bytemuck::try_cast_slice(&bytes)
                .map_err(|e| Error::Internal(format!("loss read-back: {e}")))?;
            if let Some(k) = losses.iter().position(|l| !l.is_finite()) {
                return Err(diverged(first_index + k, end - 1));
            }
        }
        ctx.check("training")?;
        epoch = end;
    }

    let bytes = ctx.read_buffer(
        &params_buf,
        params.len() as u64 * 4,
        "reading trained weights",
    )?;
    let trained: Vec<f32> = bytemuck::try_cast_slice::<u8, f32>(&bytes)
        .map_err(|e| Error::Internal(format!("parameter read-back: {e}")))?
        .to_vec();
    let nets: Vec<Mlp> = initial
        .iter()
        .zip(trained.chunks_exact(param_count))
        .map(|(net, p)| Mlp {
            layer_sizes: net.layer_sizes.clone(),
            activation: net.activation,
            params: p.to_vec(),
        })
        .collect();
    if let Some(k) = nets
        .iter()
        .position(|n| n.params.iter().any(|p| !p.is_finite()))
    {
        return Err(diverged(first_index + k, config.epochs));
    }
    Ok(nets)
}
