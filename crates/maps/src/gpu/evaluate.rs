//! Host side of `shaders/evaluate.wgsl`: every network of a batch on the same points, chunked under the device limits.

use wgpu::util::DeviceExt;

use super::context::GpuContext;
use super::layout::dims_for;
use crate::nn::Mlp;
use errmap_core::{Error, Result};

/// WGSL source: the shared declarations, then the evaluation kernel.
pub const EVALUATE_WGSL: &str = concat!(
    include_str!("../../../../shaders/common.wgsl"),
    include_str!("../../../../shaders/evaluate.wgsl")
);

const WORKGROUP: u32 = 64;

/// The compiled evaluation kernel (one thread per point and network) and its bind group
/// layout.
pub struct EvalPipeline {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
}

impl EvalPipeline {
    /// Compiles `evaluate.wgsl` on the device; a device error while compiling is an error.
    pub fn new(ctx: &GpuContext) -> Result<EvalPipeline> {
        let device = &ctx.device;
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("evaluate.wgsl"),
            source: wgpu::ShaderSource::Wgsl(EVALUATE_WGSL.into()),
        });
        let buffer = |binding, ty| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty,
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("evaluate"),
            entries: &[
                buffer(0, wgpu::BufferBindingType::Uniform),
                buffer(1, wgpu::BufferBindingType::Storage { read_only: true }),
                buffer(2, wgpu::BufferBindingType::Storage { read_only: true }),
                buffer(3, wgpu::BufferBindingType::Storage { read_only: false }),
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("evaluate"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("evaluate"),
            layout: Some(&pipeline_layout),
            module: &module,
            entry_point: Some("evaluate"),
            compilation_options: Default::default(),
            cache: None,
        });
        ctx.wait("compiling the evaluation shader")?;
        Ok(EvalPipeline { layout, pipeline })
    }
}

/// `out[k][i]` = `nets[k]` at `points[i]`. Consecutive networks of the same architecture share
/// dispatches; points are chunked so every buffer fits the device.
pub fn evaluate(
    ctx: &GpuContext,
    pipeline: &EvalPipeline,
    nets: &[Mlp],
    points: &[[f32; 2]],
) -> Result<Vec<Vec<f32>>> {
    let mut out: Vec<Vec<f32>> = Vec::with_capacity(nets.len());
    let limit = ctx
        .limits
        .max_storage_buffer_binding_size
        .min(ctx.limits.max_buffer_size);
    let max_groups = ctx.limits.max_compute_workgroups_per_dimension.max(1) as usize;
    let mut start = 0;
    while start < nets.len() {
        let arch = (&nets[start].layer_sizes, nets[start].activation);
        let mut end = start + 1;
        while end < nets.len()
            && end - start < max_groups
            && (&nets[end].layer_sizes, nets[end].activation) == arch
        {
            end += 1;
        }
        let group = &nets[start..end];
        let mut results = vec![Vec::with_capacity(points.len()); group.len()];
        let per_point = 4 * group.len() as u64;
        let chunk = ((limit / per_point).min(limit / 8).min(u32::MAX as u64 / 2) as usize).max(1);
        if points.is_empty() {
            out.extend(results);
            start = end;
            continue;
        }
        for slice in points.chunks(chunk) {
            let values = evaluate_chunk(ctx, pipeline, group, slice)?;
            for (k, result) in results.iter_mut().enumerate() {
                result.extend_from_slice(&values[k * slice.len()..(k + 1) * slice.len()]);
            }
        }
        out.extend(results);
        start = end;
    }
    Ok(out)
}

fn evaluate_chunk(
    ctx: &GpuContext,
    pipeline: &EvalPipeline,
    nets: &[Mlp],
    points: &[[f32; 2]],
) -> Result<Vec<f32>> {
    let device = &ctx.device;
    let Some(first) = nets.first() else {
        return Ok(Vec::new());
    };
    let dims = dims_for(first, nets.len(), points.len());
    let params: Vec<f32> = nets.iter().flat_map(|n| n.params.iter().copied()).collect();
    let output_len = (nets.len() * points.len()) as u64;
    let dims_buf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("dims"),
        contents: bytemuck::bytes_of(&dims),
        usage: wgpu::BufferUsages::UNIFORM,
    });
    let params_buf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("params"),
        contents: bytemuck::cast_slice(&params),
        usage: wgpu::BufferUsages::STORAGE,
    });
    let points_buf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("points"),
        contents: bytemuck::cast_slice(points),
        usage: wgpu::BufferUsages::STORAGE,
    });
    let outputs_buf = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("outputs"),
        size: output_len.max(1) * 4,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    ctx.check("allocating evaluation buffers")?;
    let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("evaluate"),
        layout: &pipeline.layout,
        entries: &[
            (0, &dims_buf),
            (1, &params_buf),
            (2, &points_buf),
            (3, &outputs_buf),
        ]
        .map(|(binding, buffer)| wgpu::BindGroupEntry {
            binding,
            resource: buffer.as_entire_binding(),
        }),
    });
    let max_groups = ctx.limits.max_compute_workgroups_per_dimension.max(1);
    let groups_x = (points.len() as u32)
        .div_ceil(WORKGROUP)
        .clamp(1, max_groups);
    let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
        label: Some("evaluate"),
    });
    {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("evaluate"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&pipeline.pipeline);
        pass.set_bind_group(0, &group, &[]);
        pass.dispatch_workgroups(groups_x, nets.len() as u32, 1);
    }
    ctx.queue.submit([encoder.finish()]);
    let bytes = ctx.read_buffer(&outputs_buf, output_len * 4, "evaluating networks")?;
    Ok(bytemuck::try_cast_slice::<u8, f32>(&bytes)
        .map_err(|e| Error::Internal(format!("evaluation read-back: {e}")))?
        .to_vec())
}
