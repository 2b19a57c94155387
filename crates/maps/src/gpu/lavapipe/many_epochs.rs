//! The CPU-adapter kernel that runs many Adam epochs of a network per dispatch (where the device has 8-wide subgroups): each lane keeps an eighth of the network's parameters and moments between epochs, and its host side.
//!
//! Why this shape (Mesa 22.3 llvmpipe, measured; docs/gpu.md, Kernels):
//! - llvmpipe runs the workgroups of a dispatch on its worker threads, each taking an equal
//!   share in one piece, and the dispatch ends when the last one is done. With one epoch per
//!   dispatch the cores met every epoch and (most likely) a worker that another process held
//!   up left the other core idle: about 1.4–1.6 of 2 cores were busy, 1.8–1.9 now. Here
//!   they meet once every [`EPOCHS_PER_DISPATCH`] epochs (once per
//!   submission), and all the networks of a group share one dispatch.
//! - Between epochs the state stays in the kernel's variables. Lane t holds parameters
//!   t, t + 8, t + 16, … and their moments (one value per lane of a SIMD variable, so a
//!   2-32-32-1 network is 149 variables of each kind); every epoch broadcasts each parameter
//!   to all lanes (`subgroupBroadcast` at a constant lane: an extract and a splat) before the
//!   sample loop. Workgroup or storage memory inside a loop would cost a loop over the lanes
//!   per access in llvmpipe, and holding every parameter in every lane (vec4s) took minutes
//!   to compile.
//! - After the sample loop the lanes' gradient sums are added in the reference tree (lane l
//!   += lane l + 4, + 2, + 1) by a reduce-scatter: for 8 parameters at once, level d keeps
//!   in each lane half of the pairs (by lane bit d) and adds the partner's with
//!   `subgroupShuffleXor`, so lane t ends with parameter t's sum, the tree's terms in the
//!   tree's order (an addition's operands swapped at most, which IEEE addition does not
//!   see): 7 shuffles per 8 parameters. Each lane then applies Adam to its own parameters.
//!   The bits are those of `CpuTrainer::reference()`.

use std::fmt::Write;

use super::super::context::GpuContext;
use super::super::epochs::{
    init_buffer, sized, slot_offset, step_buffer, EpochLoop, EPOCHS_PER_SUBMISSION,
};
use super::super::layout::{pack_samples, Step};
use super::{acc, param, sample_loop, AdamConstants, Layouts, COMMON_WGSL, LANES, MAX_CPU_PARAMS};
use crate::nn::{layer_spans, Activation, Mlp, ModelConfig, TrainingSet};
use bytemuck::{Pod, Zeroable};
use errmap_core::Result;

/// Most epochs one dispatch runs: a whole submission (32 per dispatch kept the cores a
/// little less busy on lavapipe: docs/gpu.md, Kernels).
pub const EPOCHS_PER_DISPATCH: u32 = EPOCHS_PER_SUBMISSION;

/// Floats between consecutive networks in the parameter and moment buffers: the parameter
/// count rounded up to a multiple of the lanes, so every lane's last value has a place.
pub fn stride_floats(params: usize) -> usize {
    params.div_ceil(LANES) * LANES
}

/// The WGSL of the kernel `train_epochs` for one architecture, or `None` when the
/// architecture is outside this family (too many parameters, not 2 → … → 1). Network k's
/// parameters start at float k·stride of the parameter buffer, its first moments at
/// 2k·stride of the moment buffer and its second moments at (2k + 1)·stride, with
/// stride = [`stride_floats`].
pub fn epochs_source(layer_sizes: &[usize], activation: Activation) -> Option<String> {
    let spans = layer_spans(layer_sizes);
    let params = spans.last().map(|s| s.bias_offset + s.outputs)?;
    if params > MAX_CPU_PARAMS || layer_sizes.first() != Some(&2) || layer_sizes.last() != Some(&1)
    {
        return None;
    }
    let stride = stride_floats(params);
    let groups = stride / LANES;
    let mut w = String::new();
    let mut line = |text: &str| {
        // `writeln!` into a String cannot fail.
        let _ = writeln!(w, "{text}");
    };
    for text in COMMON_WGSL.lines() {
        line(text);
    }
    declarations(&mut line);
    line("@compute @workgroup_size(8)");
    line("fn train_epochs(@builtin(local_invocation_id) lid: vec3<u32>, @builtin(workgroup_id) wid: vec3<u32>) {");
    line("    let t = lid.x;");
    line("    let k = run.first_net + wid.x;");
    line("    let net = nets[k];");
    line("    let n = net.sample_count;");
    line(&format!("    let pb = k * {stride}u + t;"));
    line(&format!("    let mb = 2u * k * {stride}u + t;"));
    line("    let hi4 = (t & 4u) != 0u;");
    line("    let hi2 = (t & 2u) != 0u;");
    line("    let hi1 = (t & 1u) != 0u;");
    // Lane t's parameters t + 8q and their moments, for all the epochs of the dispatch.
    for q in 0..groups {
        let at = q * LANES;
        line(&format!("    var pv{q} = params[pb + {at}u];"));
        line(&format!("    var mv{q} = moments[mb + {at}u];"));
        line(&format!("    var vv{q} = moments[mb + {}u];", stride + at));
    }
    line("    var loss = 0.0;");
    line("    for (var e = 0u; e < run.epochs; e += 1u) {");
    line("    let step = steps[run.first_step + e];");
    // g0 … g{P-1}: this lane's gradient sums; g{P}: its squared errors.
    for c in 0..=params {
        line(&format!("    var {} = 0.0;", acc(c)));
    }
    for c in 0..params {
        line(&format!(
            "    let {} = subgroupBroadcast(pv{}, {}u);",
            param(c),
            c / LANES,
            c % LANES
        ));
    }
    sample_loop(&mut line, &spans, activation, params);
    for q in 0..groups {
        reduce_scatter(&mut line, params, q);
        adam(&mut line, q);
    }
    line(&format!("    loss = {};", butterfly(&acc(params))));
    line("    }");
    for q in 0..groups {
        let at = q * LANES;
        line(&format!("    params[pb + {at}u] = pv{q};"));
        line(&format!("    moments[mb + {at}u] = mv{q};"));
        line(&format!("    moments[mb + {}u] = vv{q};", stride + at));
    }
    line("    if t == 0u {");
    line("        losses[k] = loss;");
    line("    }");
    line("}");
    Some(w)
}

/// Structs and bindings. Host mirrors: `NetInfo`, `Sample`, `Step` in `gpu::layout`,
/// `AdamConstants` in `super`, `RunInfo` below.
fn declarations(line: &mut dyn FnMut(&str)) {
    let text = format!(
        "struct NetInfo {{ sample_offset: u32, sample_count: u32, act_offset: u32, grad_scale: f32, }}
struct Sample {{ x: f32, y: f32, target_value: f32, net: u32, }}
struct Step {{ learning_rate: f32, correction1: f32, correction2: f32, _pad: u32, }}
struct AdamConstants {{ beta1: f32, one_minus_beta1: f32, beta2: f32, one_minus_beta2: f32, epsilon: f32, _pad0: u32, _pad1: u32, _pad2: u32, }}
struct RunInfo {{ first_step: u32, epochs: u32, first_net: u32, _pad0: u32, }}
// Network k's parameters from k·stride, read at the start of a dispatch and written at its end.
@group(0) @binding(0) var<storage, read_write> params: array<f32>;
// Network k: first moments at 2k·stride, second moments at (2k + 1)·stride.
@group(0) @binding(1) var<storage, read_write> moments: array<f32>;
@group(0) @binding(2) var<storage, read> nets: array<NetInfo>;
@group(0) @binding(3) var<storage, read> samples: array<Sample>;
@group(0) @binding(4) var<storage, read_write> losses: array<f32>;
// The Step of every epoch of the submission; this dispatch runs epochs first_step, … of it.
@group(1) @binding(0) var<uniform> steps: array<Step, {EPOCHS_PER_SUBMISSION}>;
@group(1) @binding(1) var<uniform> run: RunInfo;
@group(1) @binding(2) var<uniform> adam: AdamConstants;"
    );
    for l in text.lines() {
        line(l);
    }
}

/// The tree sums of parameters 8q … 8q + 7 into `gq{q}`, lane t getting parameter 8q + t's
/// (0 for lanes past the parameters).
fn reduce_scatter(line: &mut dyn FnMut(&str), params: usize, q: usize) {
    let a = |i: usize| {
        let c = q * LANES + i;
        if c < params {
            acc(c)
        } else {
            "0.0".to_string()
        }
    };
    // Level 4: lanes 0–3 keep parameter i's pairs (l, l + 4), lanes 4–7 parameter i + 4's.
    for i in 0..4 {
        let (lo, hi) = (a(i), a(i + 4));
        line(&format!(
            "    let h{q}_{i} = select({lo}, {hi}, hi4) + subgroupShuffleXor(select({hi}, {lo}, hi4), 4u);"
        ));
    }
    // Level 2: of those, lanes with bit 1 clear keep parameter i's, the others i + 2's.
    for i in 0..2 {
        line(&format!(
            "    let f{q}_{i} = select(h{q}_{i}, h{q}_{j}, hi2) + subgroupShuffleXor(select(h{q}_{j}, h{q}_{i}, hi2), 2u);",
            j = i + 2
        ));
    }
    // Level 1: lane t ends with parameter t's sum.
    line(&format!(
        "    let gq{q} = select(f{q}_0, f{q}_1, hi1) + subgroupShuffleXor(select(f{q}_1, f{q}_0, hi1), 1u);"
    ));
}

/// Adam on lane t's parameter 8q + t (as `crate::nn::adam_update`).
fn adam(line: &mut dyn FnMut(&str), q: usize) {
    let (p, m, v, g) = (
        format!("pv{q}"),
        format!("mv{q}"),
        format!("vv{q}"),
        format!("gq{q}"),
    );
    line(&format!(
        "    {m} = adam.beta1 * {m} + adam.one_minus_beta1 * {g};"
    ));
    line(&format!(
        "    {v} = adam.beta2 * {v} + adam.one_minus_beta2 * ({g} * {g});"
    ));
    line(&format!(
        "    {p} = {p} - step.learning_rate * ({m} * step.correction1) / (sqrt({v} * step.correction2) + adam.epsilon);"
    ));
}

/// The tree sum of `x`'s 8 lanes in every lane (a butterfly: the tree's additions, operands
/// swapped in some lanes).
fn butterfly(x: &str) -> String {
    let x4 = format!("({x} + subgroupShuffleXor({x}, 4u))");
    let x2 = format!("({x4} + subgroupShuffleXor({x4}, 2u))");
    format!("{x2} + subgroupShuffleXor({x2}, 1u)")
}

// ---------------------------------------------------------------------------------------
// Host side.

/// Mirrors `RunInfo` in the generated WGSL: the epochs and networks of one dispatch.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Pod, Zeroable)]
pub struct RunInfo {
    /// Slot of the dispatch's first epoch in the submission's Steps.
    pub first_step: u32,
    /// Epochs the dispatch runs (1 to [`EPOCHS_PER_DISPATCH`]).
    pub epochs: u32,
    /// Index in the group of the dispatch's first network.
    pub first_net: u32,
    /// Padding of the struct to 16 bytes; 0.
    pub _pad0: u32,
}

/// The bind group and pipeline layouts of this kernel.
pub fn layouts(device: &wgpu::Device) -> Layouts {
    let uniform = wgpu::BufferBindingType::Uniform;
    let storage = |read_only| wgpu::BufferBindingType::Storage { read_only };
    Layouts::new(
        device,
        "cpu-adapter epochs",
        // Group 0: parameters, moments, networks, samples, losses.
        &[
            (storage(false), false),
            (storage(false), false),
            (storage(true), false),
            (storage(true), false),
            (storage(false), false),
        ],
        // Group 1: the submission's Steps, this dispatch's RunInfo (dynamic), Adam constants.
        &[(uniform, false), (uniform, true), (uniform, false)],
    )
}

/// Trains one group (its samples fit a storage binding; `initial` and `sets` are checked)
/// with the kernel `pipeline`, at most `per_dispatch` epochs per dispatch.
#[allow(clippy::too_many_arguments)]
pub fn train_group(
    ctx: &GpuContext,
    layouts: &Layouts,
    pipeline: &wgpu::ComputePipeline,
    per_dispatch: u32,
    initial: &[Mlp],
    sets: &[TrainingSet],
    config: &ModelConfig,
    first_index: usize,
) -> Result<Vec<Mlp>> {
    if initial.is_empty() {
        return Ok(Vec::new());
    }
    let device = &ctx.device;
    let net_count = initial.len();
    let params = initial[0].params.len();
    let stride = stride_floats(params);
    let per_dispatch = per_dispatch.clamp(1, EPOCHS_PER_SUBMISSION);
    let max_nets = ctx.limits.max_compute_workgroups_per_dimension.max(1) as usize;
    let chunks = net_count.div_ceil(max_nets);
    let align = super::super::epochs::uniform_align(ctx);
    let mut packed = vec![0.0f32; net_count * stride];
    for (k, net) in initial.iter().enumerate() {
        packed[k * stride..][..net.params.len()].copy_from_slice(&net.params);
    }
    let (net_infos, samples) = pack_samples(sets, 0);
    let storage = wgpu::BufferUsages::STORAGE;
    let params_buffer = init_buffer(
        device,
        "params",
        bytemuck::cast_slice(&packed),
        storage | wgpu::BufferUsages::COPY_SRC,
    );
    // Moments start at zero (wgpu zero-initialises buffers).
    let moments = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("moments"),
        size: (2 * net_count * stride * 4) as u64,
        usage: storage,
        mapped_at_creation: false,
    });
    let nets = init_buffer(device, "nets", bytemuck::cast_slice(&net_infos), storage);
    let samples = init_buffer(device, "samples", bytemuck::cast_slice(&samples), storage);
    let losses = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("losses"),
        size: (net_count * 4) as u64,
        usage: storage | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    // Steps packed (16 bytes apart) as the kernel's array; RunInfo slots `align` apart, one
    // per dispatch of a submission.
    let steps = step_buffer(device, std::mem::size_of::<Step>() as u64);
    let slots = EPOCHS_PER_SUBMISSION.div_ceil(per_dispatch) as usize * chunks;
    let runs = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("runs"),
        size: slots as u64 * align,
        usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let adam = init_buffer(
        device,
        "adam constants",
        bytemuck::bytes_of(&AdamConstants::reference()),
        wgpu::BufferUsages::UNIFORM,
    );
    ctx.check("allocating training buffers")?;
    let data_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("cpu-adapter epochs data"),
        layout: &layouts.data,
        entries: &[
            (0, params_buffer.as_entire_binding()),
            (1, moments.as_entire_binding()),
            (2, nets.as_entire_binding()),
            (3, samples.as_entire_binding()),
            (4, losses.as_entire_binding()),
        ]
        .map(|(binding, resource)| wgpu::BindGroupEntry { binding, resource }),
    });
    let step_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("cpu-adapter epochs step"),
        layout: &layouts.step,
        entries: &[
            (0, steps.as_entire_binding()),
            (1, sized(&runs, std::mem::size_of::<RunInfo>() as u64)),
            (2, adam.as_entire_binding()),
        ]
        .map(|(binding, resource)| wgpu::BindGroupEntry { binding, resource }),
    });
    ctx.check("binding training buffers")?;
    let epochs = EpochLoop {
        ctx,
        config,
        steps: &steps,
        align: std::mem::size_of::<Step>() as u64,
        losses: &losses,
        net_count,
        first_index,
    };
    let mut run_bytes = vec![0u8; slots * align as usize];
    // The kernel writes every network's loss at the end of each dispatch.
    epochs.run(|pass, range, _read_loss| {
        let length = range.len() as u32;
        let mut dispatches = Vec::new();
        let mut first = 0u32;
        while first < length {
            let count = per_dispatch.min(length - first);
            for chunk in 0..chunks {
                let first_net = chunk * max_nets;
                let info = RunInfo {
                    first_step: first,
                    epochs: count,
                    first_net: first_net as u32,
                    _pad0: 0,
                };
                let slot = dispatches.len();
                run_bytes[slot * align as usize..][..std::mem::size_of::<RunInfo>()]
                    .copy_from_slice(bytemuck::bytes_of(&info));
                dispatches.push((slot as u32, (net_count - first_net).min(max_nets) as u32));
            }
            first += count;
        }
        ctx.queue
            .write_buffer(&runs, 0, &run_bytes[..dispatches.len() * align as usize]);
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, &data_group, &[]);
        for (slot, workgroups) in dispatches {
            pass.set_bind_group(1, &step_group, &[slot_offset(slot, align)]);
            pass.dispatch_workgroups(workgroups, 1, 1);
        }
    })?;
    epochs.read_trained(&params_buffer, initial, stride)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_lane_has_a_place_for_its_last_parameter() {
        // 2-32-32-1: 1185 parameters, 149 per-lane values of each kind (1192 floats).
        assert_eq!(stride_floats(1185), 1192);
        assert_eq!(stride_floats(1192), 1192);
        assert_eq!(stride_floats(1), 8);
        let source = epochs_source(&[2, 32, 32, 1], Activation::Tanh).unwrap();
        assert!(source.contains("var pv148 = params[pb + 1184u];"));
        assert!(!source.contains("pv149"));
        // Parameter 1184 (the output bias) is lane 0 of the last variable.
        assert!(source.contains("let p1184 = subgroupBroadcast(pv148, 0u);"));
    }

    #[test]
    fn architectures_outside_the_family_get_no_kernel() {
        let tanh = Activation::Tanh;
        assert!(epochs_source(&[2, 70, 70, 1], tanh).is_none());
        assert!(epochs_source(&[3, 4, 1], tanh).is_none());
        assert!(epochs_source(&[2, 4, 2], tanh).is_none());
    }
}
