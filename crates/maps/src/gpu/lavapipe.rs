//! The CPU-adapter kernel family (Mesa lavapipe and other `DeviceType::Cpu` adapters): one WGSL kernel generated per architecture that runs a whole Adam epoch of a network in one 8-invocation workgroup, and its host side.
//!
//! Why this shape (Mesa 22.3 llvmpipe, measured; docs/gpu.md, Kernels):
//! - llvmpipe compiles a workgroup of 8 invocations into one 8-wide SIMD function. It has no
//!   divergence analysis: a storage or workgroup-memory load whose address it cannot prove
//!   uniform becomes a serial loop over the lanes (~55 ns), while a uniform-buffer load at a
//!   constant offset from the binding costs a few ns. So each network's parameters are read
//!   through a uniform binding, at offsets that are constants of the generated text; the
//!   parameters ping-pong between two buffers so that the Adam step writes the one that is
//!   not bound as uniform in this epoch. Each parameter is loaded once per epoch, before the
//!   sample loop (LLVM does not hoist those loads out of the loop by itself).
//! - Lane t handles samples t, t + 8, t + 16, … in ascending order and accumulates every
//!   gradient in registers; at the end the 8 lanes are added in the fixed tree (lane l +=
//!   lane l + 4, + 2, + 1) with subgroup shuffles (where the device has 8-wide subgroups) or
//!   through workgroup memory, then Adam updates each parameter.
//!   That is exactly the order of the CPU reference ([`crate::nn::REFERENCE_LANES`] = 8), and
//!   the arithmetic is the reference's operation for operation (no FMA, the rational
//!   `tanh_f32`, Adam constants read from a uniform so the compiler cannot fold them), so the
//!   kernel reproduces `CpuTrainer::reference()` bit for bit.
//! - One dispatch per epoch does forward, backward, reduction and Adam for every network of
//!   a binding (one workgroup each); a batch larger than one uniform binding holds takes one
//!   dispatch per binding.
//! - Where the device has 8-wide subgroups (lavapipe on AVX2) training uses the many-epoch
//!   kernel of [`many_epochs`] instead, which shares this module's sample loop;
//!   this kernel trains where there are none (its subgroup variant stays for comparison).

use std::collections::HashMap;
use std::fmt::Write;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use super::context::GpuContext;
use super::epochs::{init_buffer, sized, slot_offset, step_buffer, uniform_align, EpochLoop};
use super::layout::{pack_samples, Step};
use super::pipeline_cache::{self, CacheUse};
use crate::nn::{
    layer_spans, Activation, LayerSpan, Mlp, ModelConfig, TrainingSet, ADAM_BETA1, ADAM_BETA2,
    ADAM_EPSILON, ADAM_ONE_MINUS_BETA1, ADAM_ONE_MINUS_BETA2,
};
use bytemuck::{Pod, Zeroable};
use errmap_core::progress::Notes;
use errmap_core::{Error, Result};

pub mod many_epochs;

/// Declarations shared with the other kernels (`tanh_f32`).
pub(super) const COMMON_WGSL: &str = include_str!("../../../../shaders/common.wgsl");

/// Invocations per workgroup = gradient lanes = llvmpipe's SIMD width on AVX2.
pub const LANES: usize = 8;

/// Samples of a lane that go forward and backward before their gradient terms are added
/// together (measured on lavapipe: docs/gpu.md, Kernels).
pub const SAMPLES_PER_PASS: usize = 4;

/// Largest parameter count the generated kernel takes: its size (and llvmpipe's compile
/// time) grows with the parameters; larger networks use the hardware kernels.
pub const MAX_CPU_PARAMS: usize = 4096;

/// Parameters reduced per round of the workgroup-memory tree (8 lanes × 4 bytes each:
/// 16 KiB, under the 32 KiB lavapipe grants).
const REDUCE_CHUNK: usize = 512;

/// The WGSL of the epoch kernel `train_epoch` for one architecture, or `None` when the
/// architecture is outside this family (too many parameters, not 2 → … → 1).
///
/// `stride_floats`: floats between consecutive networks in the parameter buffers (a multiple
/// of 4, at least the parameter count); `nets_per_binding`: networks one uniform binding of
/// the parameters holds (the workgroups of one dispatch).
pub fn epoch_source(
    layer_sizes: &[usize],
    activation: Activation,
    stride_floats: usize,
    nets_per_binding: usize,
    subgroups: bool,
) -> Option<String> {
    let spans = layer_spans(layer_sizes);
    let params = spans.last().map(|s| s.bias_offset + s.outputs)?;
    if params > MAX_CPU_PARAMS
        || layer_sizes.first() != Some(&2)
        || layer_sizes.last() != Some(&1)
        || stride_floats < params
        || !stride_floats.is_multiple_of(4)
        || nets_per_binding == 0
    {
        return None;
    }
    let mut w = String::new();
    let mut line = |text: &str| {
        // `writeln!` into a String cannot fail.
        let _ = writeln!(w, "{text}");
    };
    for text in COMMON_WGSL.lines() {
        line(text);
    }
    declarations(&mut line, stride_floats, nets_per_binding, params);
    if subgroups {
        line("// One level of the lane tree: x + (x of the lane `half` above).");
        line("fn tree_step(x: f32, half: u32) -> f32 {");
        line("    return x + subgroupShuffleDown(x, half);");
        line("}");
    }
    line("@compute @workgroup_size(8)");
    line("fn train_epoch(@builtin(local_invocation_id) lid: vec3<u32>, @builtin(workgroup_id) wid: vec3<u32>) {");
    line("    let t = lid.x;");
    line("    let local_net = wid.x;");
    line("    let k = batch.first_net + local_net;");
    line("    let net = nets[k];");
    line("    let n = net.sample_count;");
    if nets_per_binding == 1 {
        line("    let wb = 0u;");
    } else {
        line(&format!("    let wb = local_net * {}u;", stride_floats / 4));
    }
    // g0 … g{P-1}: this lane's gradient sums; g{P}: its squared errors.
    for c in 0..=params {
        line(&format!("    var g{c} = 0.0;"));
    }
    // Every parameter read once, before the sample loop, into a value of its own: llvmpipe
    // does not hoist the uniform loads out of the loop itself, and reloading ~2400 of them
    // per iteration took half the loop's time (docs/gpu.md, Kernels).
    for c in 0..params {
        line(&format!("    let {} = {};", param(c), uniform_param(c)));
    }
    sample_loop(&mut line, &spans, activation, params);
    if subgroups {
        subgroup_reduce_and_adam(&mut line, params, stride_floats);
    } else {
        reduce_and_adam(&mut line, params, stride_floats);
    }
    line("}");
    Some(w)
}

/// The sample loop of lane t: every sample of the set goes forward and backward and adds
/// its gradient terms to the lane's sums `g0 …` (declared before it, with the parameters
/// `p0 …`); the squared errors go to `g{params}`.
pub(super) fn sample_loop(
    line: &mut dyn FnMut(&str),
    spans: &[LayerSpan],
    activation: Activation,
    params: usize,
) {
    // SAMPLES_PER_PASS samples of this lane per iteration, s0, s0 + 8, …: all go forward and
    // backward, then their gradient terms are added in one pass,
    // g = ((g + term(s0)) + term(s0 + 8)) + …, so each accumulator (they live on the stack)
    // is read and written once per SAMPLES_PER_PASS samples. A sample past the set is
    // replaced by sample s0 with a zero error: its terms are ±0, and g + ±0 = g because g, a
    // sum that starts at +0, is never −0. The order is the reference's, and so are the bits.
    line(&format!(
        "    for (var s0 = t; s0 < n; s0 += {}u) {{",
        LANES * SAMPLES_PER_PASS
    ));
    let suffixes: Vec<String> = (0..SAMPLES_PER_PASS)
        .map(|k| ((b'a' + k as u8) as char).to_string())
        .collect();
    for (k, suffix) in suffixes.iter().enumerate() {
        if k == 0 {
            sample_pass(line, spans, activation, params, suffix, "s0", None);
            continue;
        }
        let offset = k * LANES;
        line(&format!("        let has_{suffix} = s0 + {offset}u < n;"));
        sample_pass(
            line,
            spans,
            activation,
            params,
            suffix,
            &format!("select(s0, s0 + {offset}u, has_{suffix})"),
            Some(&format!("has_{suffix}")),
        );
    }
    let names: Vec<&str> = suffixes.iter().map(|s| s.as_str()).collect();
    gradient_terms(line, spans, params, &names);
    line("    }");
}

/// Forward and backward pass of the sample at index `index`, its values named with
/// `suffix`; with `present`, the error is zero where that condition is false. Adds its squared
/// error to this lane's sum; the gradient terms are added by [`gradient_terms`].
fn sample_pass(
    line: &mut dyn FnMut(&str),
    spans: &[LayerSpan],
    activation: Activation,
    params: usize,
    suffix: &str,
    index: &str,
    present: Option<&str>,
) {
    line(&format!(
        "        let sample{suffix} = samples[net.sample_offset + {index}];"
    ));
    line(&format!("        let a0_0{suffix} = sample{suffix}.x;"));
    line(&format!("        let a0_1{suffix} = sample{suffix}.y;"));
    forward(line, spans, activation, suffix);
    let err = format!("y{suffix} - sample{suffix}.target_value");
    match present {
        None => line(&format!("        let err{suffix} = {err};")),
        Some(cond) => line(&format!(
            "        let err{suffix} = select(0.0, {err}, {cond});"
        )),
    }
    let sq = acc(params);
    line(&format!("        {sq} = {sq} + err{suffix} * err{suffix};"));
    line(&format!(
        "        let d{}_0{suffix} = err{suffix} * net.grad_scale;",
        spans.len() - 1
    ));
    backward(line, spans, activation, suffix);
}

/// Structs and bindings. Host mirrors: `NetInfo`, `Sample`, `Step` in `super::layout`,
/// `AdamConstants` and `BatchInfo` below.
fn declarations(line: &mut dyn FnMut(&str), stride: usize, per_binding: usize, params: usize) {
    let text = format!(
        "struct NetInfo {{ sample_offset: u32, sample_count: u32, act_offset: u32, grad_scale: f32, }}
struct Sample {{ x: f32, y: f32, target_value: f32, net: u32, }}
struct Step {{ learning_rate: f32, correction1: f32, correction2: f32, _pad: u32, }}
struct AdamConstants {{ beta1: f32, one_minus_beta1: f32, beta2: f32, one_minus_beta2: f32, epsilon: f32, _pad0: u32, _pad1: u32, _pad2: u32, }}
struct BatchInfo {{ first_net: u32, _pad0: u32, _pad1: u32, _pad2: u32, }}
// This epoch's parameters of the networks of this dispatch (dynamic offset), and the same
// buffer whole; the Adam step writes the other buffer.
@group(0) @binding(0) var<uniform> w: array<vec4<f32>, {}>;
@group(0) @binding(1) var<storage, read> p_in: array<f32>;
@group(0) @binding(2) var<storage, read_write> p_out: array<f32>;
// Network k: first moments at 2k·stride, second moments at (2k + 1)·stride.
@group(0) @binding(3) var<storage, read_write> moments: array<f32>;
@group(0) @binding(4) var<storage, read> nets: array<NetInfo>;
@group(0) @binding(5) var<storage, read> samples: array<Sample>;
@group(0) @binding(6) var<storage, read_write> losses: array<f32>;
@group(1) @binding(0) var<uniform> step: Step;
@group(1) @binding(1) var<uniform> batch: BatchInfo;
@group(1) @binding(2) var<uniform> adam: AdamConstants;
// Lane partial sums of up to {REDUCE_CHUNK} parameters: parameter c of the chunk, lane l at 8c + l.
var<workgroup> red: array<f32, {}>;
// {params} parameters, {stride} floats per network.",
        per_binding * stride / 4,
        LANES * (REDUCE_CHUNK + 1)
    );
    for l in text.lines() {
        line(l);
    }
}

/// The accumulator of parameter `c` (`c` = parameter count: the squared error).
pub(super) fn acc(c: usize) -> String {
    format!("g{c}")
}

/// `w[…]` of parameter `c` of this network (a constant offset from `wb`).
fn uniform_param(c: usize) -> String {
    let comp = ["x", "y", "z", "w"][c % 4];
    format!("w[wb + {}u].{comp}", c / 4)
}

/// The value parameter `c` was loaded into before the sample loop.
pub(super) fn param(c: usize) -> String {
    format!("p{c}")
}

fn apply(activation: Activation, z: &str) -> String {
    match activation {
        Activation::Tanh => format!("tanh_f32({z})"),
        Activation::Relu => format!("max({z}, 0.0)"),
    }
}

fn derivative(activation: Activation, a: &str) -> String {
    match activation {
        Activation::Tanh => format!("(1.0 - {a} * {a})"),
        Activation::Relu => format!("select(0.0, 1.0, {a} > 0.0)"),
    }
}

/// a{l+1}_i = f(b[i] + Σ_j W[i][j]·a{l}_j), j ascending; the output layer is linear (`y`);
/// every name ends with `suffix`.
fn forward(line: &mut dyn FnMut(&str), spans: &[LayerSpan], activation: Activation, suffix: &str) {
    let last = spans.len() - 1;
    for (l, span) in spans.iter().enumerate() {
        for i in 0..span.outputs {
            let mut z = param(span.bias_offset + i);
            for j in 0..span.inputs {
                let _ = write!(
                    z,
                    " + {} * a{l}_{j}{suffix}",
                    param(span.weight_offset + i * span.inputs + j)
                );
            }
            if l == last {
                line(&format!("        let y{suffix} = {z};"));
            } else {
                line(&format!(
                    "        let a{}_{i}{suffix} = {};",
                    l + 1,
                    apply(activation, &z)
                ));
            }
        }
    }
}

/// δ_prev[j] = (0 + Σ_i W[i][j]·δ_i, i ascending)·f'(a_j) of every layer below the output,
/// names ending with `suffix`.
fn backward(line: &mut dyn FnMut(&str), spans: &[LayerSpan], activation: Activation, suffix: &str) {
    for (l, span) in spans.iter().enumerate().rev() {
        if l == 0 {
            continue;
        }
        for j in 0..span.inputs {
            let mut b = "0.0".to_string();
            for i in 0..span.outputs {
                let _ = write!(
                    b,
                    " + {} * d{l}_{i}{suffix}",
                    param(span.weight_offset + i * span.inputs + j)
                );
            }
            let a = format!("a{l}_{j}{suffix}");
            line(&format!(
                "        let d{}_{j}{suffix} = ({b}) * {};",
                l - 1,
                derivative(activation, &a)
            ));
        }
    }
}

/// The gradient terms of the samples named by `suffixes`, in that order, added to this
/// lane's sums: bias += δ_i, W[i][j] += δ_i·a_j.
fn gradient_terms(
    line: &mut dyn FnMut(&str),
    spans: &[LayerSpan],
    params: usize,
    suffixes: &[&str],
) {
    debug_assert!(params >= spans.last().map_or(0, |s| s.bias_offset + s.outputs));
    for (l, span) in spans.iter().enumerate().rev() {
        for i in 0..span.outputs {
            let b = acc(span.bias_offset + i);
            let mut sum = b.clone();
            for x in suffixes {
                let _ = write!(sum, " + d{l}_{i}{x}");
            }
            line(&format!("        {b} = {sum};"));
            for j in 0..span.inputs {
                let c = acc(span.weight_offset + i * span.inputs + j);
                let mut sum = c.clone();
                for x in suffixes {
                    let _ = write!(sum, " + d{l}_{i}{x} * a{l}_{j}{x}");
                }
                line(&format!("        {c} = {sum};"));
            }
        }
    }
}

/// The tree of the 8 lanes of parameter `c` (lane l += lane l + 4, + 2, + 1) with subgroup
/// shuffles; lane 0's sum, broadcast to every lane. (Eight broadcasts and seven adds give
/// the same bits but took 18 s to compile instead of 16 s for 2-32-32-1.)
fn lane_tree(c: usize) -> String {
    let g = acc(c);
    format!("subgroupBroadcast(tree_step(tree_step(tree_step({g}, 4u), 2u), 1u), 0u)")
}

/// With one 8-lane subgroup per workgroup: every lane gets each parameter's tree sum and
/// writes it at a constant address (the same value from every lane, so
/// llvmpipe stores it once: no per-lane loop); then lane t applies Adam to parameters
/// t, t + 8, …
fn subgroup_reduce_and_adam(line: &mut dyn FnMut(&str), params: usize, stride: usize) {
    line(&format!("    let pb = k * {stride}u;"));
    line(&format!("    let mb = 2u * k * {stride}u;"));
    for c in 0..=params {
        line(&format!("    red[{c}u] = {};", lane_tree(c)));
    }
    line("    workgroupBarrier();");
    line(&format!("    for (var c = t; c < {params}u; c += 8u) {{"));
    line("        let g = red[c];");
    adam(line, stride);
    line("    }");
    line("    if t == 0u {");
    line(&format!("        losses[k] = red[{params}u];"));
    line("    }");
}

/// Adam on parameter `c` of network k with gradient `g` (as `crate::nn::adam_update`).
fn adam(line: &mut dyn FnMut(&str), stride: usize) {
    line("        let m = adam.beta1 * moments[mb + c] + adam.one_minus_beta1 * g;");
    line(&format!(
        "        let v = adam.beta2 * moments[mb + {stride}u + c] + adam.one_minus_beta2 * (g * g);"
    ));
    line("        moments[mb + c] = m;");
    line(&format!("        moments[mb + {stride}u + c] = v;"));
    line("        let m_hat = m * step.correction1;");
    line("        let v_hat = v * step.correction2;");
    line("        p_out[pb + c] = p_in[pb + c] - step.learning_rate * m_hat / (sqrt(v_hat) + adam.epsilon);");
}

/// The lanes meet in workgroup memory chunk by chunk; lane t then sums parameters
/// t, t + 8, … of the chunk in the tree order and applies Adam to them.
fn reduce_and_adam(line: &mut dyn FnMut(&str), params: usize, stride: usize) {
    line(&format!("    let pb = k * {stride}u;"));
    line(&format!("    let mb = 2u * k * {stride}u;"));
    let mut start = 0;
    while start < params {
        let end = (start + REDUCE_CHUNK).min(params);
        if start > 0 {
            line("    workgroupBarrier();");
        }
        let stored = if end == params { end + 1 } else { end };
        for c in start..stored {
            line(&format!(
                "    red[{}u + t] = {};",
                (c - start) * LANES,
                acc(c)
            ));
        }
        line("    workgroupBarrier();");
        line(&format!(
            "    for (var c = {start}u + t; c < {end}u; c += 8u) {{"
        ));
        line(&format!("        let r = (c - {start}u) * 8u;"));
        line("        let g = ((red[r] + red[r + 4u]) + (red[r + 2u] + red[r + 6u])) + ((red[r + 1u] + red[r + 5u]) + (red[r + 3u] + red[r + 7u]));");
        adam(line, stride);
        line("    }");
        start = end;
    }
    let r = (params - (params - 1) / REDUCE_CHUNK * REDUCE_CHUNK) * LANES;
    line("    if t == 0u {");
    line(&format!("        let r = {r}u;"));
    line("        losses[k] = ((red[r] + red[r + 4u]) + (red[r + 2u] + red[r + 6u])) + ((red[r + 1u] + red[r + 5u]) + (red[r + 3u] + red[r + 7u]));");
    line("    }");
}

// ---------------------------------------------------------------------------------------
// Host side.

/// Mirrors `AdamConstants` in the generated WGSL: Adam's constants as a uniform, so the
/// shader compiler sees variables (it can neither fold nor reassociate them).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct AdamConstants {
    /// β₁ ([`crate::nn::ADAM_BETA1`]).
    pub beta1: f32,
    /// 1 − β₁ ([`crate::nn::ADAM_ONE_MINUS_BETA1`]).
    pub one_minus_beta1: f32,
    /// β₂ ([`crate::nn::ADAM_BETA2`]).
    pub beta2: f32,
    /// 1 − β₂ ([`crate::nn::ADAM_ONE_MINUS_BETA2`]).
    pub one_minus_beta2: f32,
    /// ε ([`crate::nn::ADAM_EPSILON`]).
    pub epsilon: f32,
    /// Padding of the struct to 32 bytes; 0.
    pub _pad0: u32,
    /// Padding, as `_pad0`; 0.
    pub _pad1: u32,
    /// Padding, as `_pad0`; 0.
    pub _pad2: u32,
}

impl AdamConstants {
    /// The constants of [`crate::nn::adam_update`].
    pub fn reference() -> AdamConstants {
        AdamConstants {
            beta1: ADAM_BETA1,
            one_minus_beta1: ADAM_ONE_MINUS_BETA1,
            beta2: ADAM_BETA2,
            one_minus_beta2: ADAM_ONE_MINUS_BETA2,
            epsilon: ADAM_EPSILON,
            _pad0: 0,
            _pad1: 0,
            _pad2: 0,
        }
    }
}

/// Mirrors `BatchInfo` in the generated WGSL: the first network of one dispatch.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Pod, Zeroable)]
pub struct BatchInfo {
    /// Index in the batch of the dispatch's first network.
    pub first_net: u32,
    /// Padding of the struct to 16 bytes; 0.
    pub _pad0: u32,
    /// Padding, as `_pad0`; 0.
    pub _pad1: u32,
    /// Padding, as `_pad0`; 0.
    pub _pad2: u32,
}

/// Where networks sit in the parameter buffers on this device.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ParamPlan {
    /// Floats from one network to the next: the parameter count rounded up to the uniform
    /// offset alignment, so every network can start a binding.
    pub stride_floats: usize,
    /// Networks one uniform binding (one dispatch) holds.
    pub nets_per_binding: usize,
}

/// The parameter plan for `params` parameters under these limits, or `None` when one
/// network does not fit a uniform binding.
pub fn param_plan(limits: &wgpu::Limits, params: usize) -> Option<ParamPlan> {
    let align_floats = (limits.min_uniform_buffer_offset_alignment.max(16) / 4) as usize;
    let stride_floats = params.div_ceil(align_floats) * align_floats;
    let binding_bytes = limits.max_uniform_buffer_binding_size;
    let nets_per_binding = (binding_bytes / (stride_floats as u64 * 4))
        .min(limits.max_compute_workgroups_per_dimension as u64)
        as usize;
    (nets_per_binding > 0).then_some(ParamPlan {
        stride_floats,
        nets_per_binding,
    })
}

/// Layer sizes and activation shader code of an architecture.
type ArchitectureKey = (Vec<usize>, u32);

/// The compiled epoch kernel of one architecture.
pub struct EpochPipeline {
    pipeline: wgpu::ComputePipeline,
    plan: ParamPlan,
    /// `Some(most epochs per dispatch)` for the many-epoch kernel of
    /// [`many_epochs`], `None` for the one-epoch kernel of this module.
    per_dispatch: Option<u32>,
    /// Seconds spent creating the pipeline and running its first (tiny) dispatch, which is
    /// when llvmpipe compiles it.
    pub build_s: f64,
    /// What the on-disk pipeline cache did for this build.
    pub cache: CacheUse,
}

impl EpochPipeline {
    /// Where this kernel expects the networks in the parameter buffers.
    pub fn plan(&self) -> ParamPlan {
        self.plan
    }
}

/// Bind group layouts of the family and its kernels, compiled per architecture on first use.
pub struct CpuKernels {
    epochs_layouts: Layouts,
    epoch_layouts: Layouts,
    built: Mutex<HashMap<ArchitectureKey, Option<Arc<EpochPipeline>>>>,
    /// errmap's cache folder, where pipeline caches are kept (`None`: none kept).
    pub cache_dir: Option<std::path::PathBuf>,
    /// Where a pipeline cache that could not be used or written is reported.
    pub notes: Notes,
}

/// A kernel's two bind group layouts (0: data, 1: step) and its pipeline layout.
pub struct Layouts {
    data: wgpu::BindGroupLayout,
    step: wgpu::BindGroupLayout,
    /// The pipeline layout the kernel is built with.
    pub pipeline: wgpu::PipelineLayout,
}

/// One buffer binding of a layout: its type and whether it takes a dynamic offset.
type Binding = (wgpu::BufferBindingType, bool);

impl Layouts {
    /// Group 0 from `data`, group 1 from `step`, bindings numbered in order; `name` labels them.
    fn new(device: &wgpu::Device, name: &str, data: &[Binding], step: &[Binding]) -> Layouts {
        let group = |part: &str, bindings: &[Binding]| {
            let entries: Vec<wgpu::BindGroupLayoutEntry> = bindings
                .iter()
                .enumerate()
                .map(|(k, &(ty, dynamic))| wgpu::BindGroupLayoutEntry {
                    binding: k as u32,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Buffer {
                        ty,
                        has_dynamic_offset: dynamic,
                        min_binding_size: None,
                    },
                    count: None,
                })
                .collect();
            device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some(&format!("{name} {part}")),
                entries: &entries,
            })
        };
        let (data, step) = (group("data", data), group("step", step));
        let pipeline = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some(name),
            bind_group_layouts: &[Some(&data), Some(&step)],
            immediate_size: 0,
        });
        Layouts {
            data,
            step,
            pipeline,
        }
    }
}

impl CpuKernels {
    /// The layouts; no shader is compiled here. Pipeline caches are kept in `cache_dir`.
    pub fn new(ctx: &GpuContext, cache_dir: Option<std::path::PathBuf>) -> CpuKernels {
        let device = &ctx.device;
        let uniform = wgpu::BufferBindingType::Uniform;
        let storage = |read_only| wgpu::BufferBindingType::Storage { read_only };
        let epoch_layouts = Layouts::new(
            device,
            "cpu-adapter train",
            // Group 0: w (this epoch's parameters, uniform), p_in, p_out, moments, nets,
            // samples, losses.
            &[
                (uniform, true),
                (storage(true), false),
                (storage(false), false),
                (storage(false), false),
                (storage(true), false),
                (storage(true), false),
                (storage(false), false),
            ],
            // Group 1: this epoch's Step and this dispatch's BatchInfo (dynamic), Adam constants.
            &[(uniform, true), (uniform, true), (uniform, false)],
        );
        CpuKernels {
            epochs_layouts: many_epochs::layouts(device),
            epoch_layouts,
            built: Mutex::new(HashMap::new()),
            cache_dir,
            notes: errmap_core::progress::silent(),
        }
    }

    /// The epoch kernel of `net`'s architecture, built once; `None` when the architecture is
    /// outside this family on this device.
    pub fn pipeline_for(&self, ctx: &GpuContext, net: &Mlp) -> Result<Option<Arc<EpochPipeline>>> {
        let key = (net.layer_sizes.clone(), net.activation.shader_code());
        let mut built = self
            .built
            .lock()
            .map_err(|_| Error::Internal("cpu-adapter pipeline cache poisoned".into()))?;
        if let Some(found) = built.get(&key) {
            return Ok(found.clone());
        }
        let subgroups = ctx.subgroup_size == Some(LANES as u32);
        // With 8-wide subgroups the many-epoch kernel; without them the one-epoch kernel.
        let per_dispatch = many_epochs::EPOCHS_PER_DISPATCH;
        let many = if subgroups {
            many_epochs::epochs_source(&net.layer_sizes, net.activation)
        } else {
            None
        };
        let pipeline = if let Some(source) = many {
            let plan = ParamPlan {
                stride_floats: many_epochs::stride_floats(net.params.len()),
                nets_per_binding: ctx.limits.max_compute_workgroups_per_dimension.max(1) as usize,
            };
            Some(Arc::new(self.build(
                ctx,
                net,
                &source,
                plan,
                Some(per_dispatch),
            )?))
        } else {
            match param_plan(&ctx.limits, net.params.len()) {
                None => None,
                Some(plan) => {
                    match epoch_source(
                        &net.layer_sizes,
                        net.activation,
                        plan.stride_floats,
                        plan.nets_per_binding,
                        subgroups,
                    ) {
                        None => None,
                        Some(source) => Some(Arc::new(self.build(ctx, net, &source, plan, None)?)),
                    }
                }
            }
        };
        built.insert(key, pipeline.clone());
        Ok(pipeline)
    }

    /// The kernel of `net`'s architecture if it was built already.
    pub fn built(&self, net: &Mlp) -> Option<Arc<EpochPipeline>> {
        let key = (net.layer_sizes.clone(), net.activation.shader_code());
        self.built.lock().ok()?.get(&key).cloned().flatten()
    }

    fn build(
        &self,
        ctx: &GpuContext,
        net: &Mlp,
        source: &str,
        plan: ParamPlan,
        per_dispatch: Option<u32>,
    ) -> Result<EpochPipeline> {
        let started = Instant::now();
        let device = &ctx.device;
        // The cache key holds the kernel's text (by digest), so any change to it is a miss.
        let architecture = format!(
            "{:?} {} wgsl {}",
            net.layer_sizes,
            net.activation.name(),
            source_digest(source)
        );
        let (cache, mut cache_use) =
            pipeline_cache::open(ctx, self.cache_dir.as_deref(), &architecture);
        let (layout, entry_point) = match per_dispatch {
            Some(_) => (&self.epochs_layouts.pipeline, "train_epochs"),
            None => (&self.epoch_layouts.pipeline, "train_epoch"),
        };
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some(entry_point),
            source: wgpu::ShaderSource::Wgsl(source.to_string().into()),
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(entry_point),
            layout: Some(layout),
            module: &module,
            entry_point: Some(entry_point),
            compilation_options: Default::default(),
            cache: cache.as_ref(),
        });
        ctx.wait("compiling the cpu-adapter training kernel")?;
        let mut built = EpochPipeline {
            pipeline,
            plan,
            per_dispatch,
            build_s: 0.0,
            cache: CacheUse::default(),
        };
        // llvmpipe compiles at the first dispatch: one epoch on one sample, results dropped.
        let probe = TrainingSet {
            inputs: vec![[0.0, 0.0]],
            targets: vec![0.0],
        };
        let config = ModelConfig {
            hidden: net.layer_sizes[1..net.layer_sizes.len() - 1].to_vec(),
            activation: net.activation,
            epochs: 1,
            loss_every: 1,
            ..Default::default()
        };
        train_group(
            ctx,
            self,
            &built,
            std::slice::from_ref(net),
            &[probe],
            &config,
            0,
        )?;
        if let Some(cache) = &cache {
            pipeline_cache::save(ctx, cache, &architecture, &mut cache_use);
        }
        if let Some(note) = &cache_use.note {
            (self.notes)(&format!("note: {note}"));
        }
        built.cache = cache_use;
        built.build_s = started.elapsed().as_secs_f64();
        Ok(built)
    }
}

/// First 16 hex digits of the SHA-256 of a kernel's text.
fn source_digest(source: &str) -> String {
    use sha2::Digest;
    sha2::Sha256::digest(source.as_bytes())[..8]
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// Trains one group (its samples fit a storage binding; `initial` and `sets` are checked)
/// with the epoch kernel `pipe`.
pub fn train_group(
    ctx: &GpuContext,
    kernels: &CpuKernels,
    pipe: &EpochPipeline,
    initial: &[Mlp],
    sets: &[TrainingSet],
    config: &ModelConfig,
    first_index: usize,
) -> Result<Vec<Mlp>> {
    if initial.is_empty() {
        return Ok(Vec::new());
    }
    if let Some(per_dispatch) = pipe.per_dispatch {
        return many_epochs::train_group(
            ctx,
            &kernels.epochs_layouts,
            &pipe.pipeline,
            per_dispatch,
            initial,
            sets,
            config,
            first_index,
        );
    }
    let net_count = initial.len();
    let plan = pipe.plan;
    let bindings = net_count.div_ceil(plan.nets_per_binding);
    let buffers = GroupBuffers::new(ctx, initial, sets, plan)?;
    let (data_groups, step_group) = buffers.bind(ctx, kernels, plan)?;
    let align = buffers.align;
    let binding_bytes = (plan.nets_per_binding * plan.stride_floats * 4) as u64;
    let epochs = EpochLoop {
        ctx,
        config,
        steps: &buffers.steps,
        align,
        losses: &buffers.losses,
        net_count,
        first_index,
    };
    // The kernel's loss is written every epoch: nothing more to record for the read-back.
    epochs.run(|pass, epochs, _read_loss| {
        pass.set_pipeline(&pipe.pipeline);
        for e in epochs.clone() {
            let step_offset = slot_offset(e - epochs.start, align);
            for b in 0..bindings {
                let w_offset = (b as u64 * binding_bytes) as u32;
                pass.set_bind_group(0, &data_groups[(e % 2) as usize], &[w_offset]);
                pass.set_bind_group(1, &step_group, &[step_offset, slot_offset(b as u32, align)]);
                let count = (net_count - b * plan.nets_per_binding).min(plan.nets_per_binding);
                pass.dispatch_workgroups(count as u32, 1, 1);
            }
        }
    })?;
    let last = &buffers.ping[(config.epochs % 2) as usize];
    epochs.read_trained(last, initial, plan.stride_floats)
}

/// The buffers of one group's training with the epoch kernel.
struct GroupBuffers {
    /// The parameters; epoch e reads `ping[e % 2]` and writes `ping[(e + 1) % 2]`.
    ping: [wgpu::Buffer; 2],
    moments: wgpu::Buffer,
    nets: wgpu::Buffer,
    samples: wgpu::Buffer,
    losses: wgpu::Buffer,
    /// One [`BatchInfo`] slot per uniform binding of the parameters.
    batches: wgpu::Buffer,
    adam: wgpu::Buffer,
    steps: wgpu::Buffer,
    /// Bytes between Step (and BatchInfo) slots.
    align: u64,
}

impl GroupBuffers {
    /// Lays the networks out by `plan`, packs the samples and allocates the buffers.
    fn new(
        ctx: &GpuContext,
        initial: &[Mlp],
        sets: &[TrainingSet],
        plan: ParamPlan,
    ) -> Result<GroupBuffers> {
        let device = &ctx.device;
        let net_count = initial.len();
        let params = padded_params(initial, plan);
        let (net_infos, samples) = pack_samples(sets, 0);
        let align = uniform_align(ctx);
        let param_usage = wgpu::BufferUsages::UNIFORM
            | wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_SRC;
        let storage = wgpu::BufferUsages::STORAGE;
        let buffers = GroupBuffers {
            ping: [
                init_buffer(
                    device,
                    "params a",
                    bytemuck::cast_slice(&params),
                    param_usage,
                ),
                init_buffer(
                    device,
                    "params b",
                    bytemuck::cast_slice(&params),
                    param_usage,
                ),
            ],
            // Moments start at zero (wgpu zero-initialises buffers).
            moments: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("moments"),
                size: (2 * net_count * plan.stride_floats * 4) as u64,
                usage: storage,
                mapped_at_creation: false,
            }),
            nets: init_buffer(device, "nets", bytemuck::cast_slice(&net_infos), storage),
            samples: init_buffer(device, "samples", bytemuck::cast_slice(&samples), storage),
            losses: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("losses"),
                size: (net_count * 4) as u64,
                usage: storage | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            }),
            batches: init_buffer(
                device,
                "batches",
                &batch_slots(net_count, plan, align),
                wgpu::BufferUsages::UNIFORM,
            ),
            adam: init_buffer(
                device,
                "adam constants",
                bytemuck::bytes_of(&AdamConstants::reference()),
                wgpu::BufferUsages::UNIFORM,
            ),
            steps: step_buffer(device, align),
            align,
        };
        ctx.check("allocating training buffers")?;
        Ok(buffers)
    }

    /// Group 0 for even and odd epochs (the ping-pong of the parameters) and group 1.
    fn bind(
        &self,
        ctx: &GpuContext,
        kernels: &CpuKernels,
        plan: ParamPlan,
    ) -> Result<(Vec<wgpu::BindGroup>, wgpu::BindGroup)> {
        let device = &ctx.device;
        let binding_bytes = (plan.nets_per_binding * plan.stride_floats * 4) as u64;
        let data_groups: Vec<wgpu::BindGroup> = (0..2)
            .map(|i| {
                let (read, write) = (&self.ping[i], &self.ping[1 - i]);
                device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("cpu-adapter train data"),
                    layout: &kernels.epoch_layouts.data,
                    entries: &[
                        (0, sized(read, binding_bytes)),
                        (1, read.as_entire_binding()),
                        (2, write.as_entire_binding()),
                        (3, self.moments.as_entire_binding()),
                        (4, self.nets.as_entire_binding()),
                        (5, self.samples.as_entire_binding()),
                        (6, self.losses.as_entire_binding()),
                    ]
                    .map(|(binding, resource)| wgpu::BindGroupEntry { binding, resource }),
                })
            })
            .collect();
        let step_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("cpu-adapter train step"),
            layout: &kernels.epoch_layouts.step,
            entries: &[
                (0, sized(&self.steps, std::mem::size_of::<Step>() as u64)),
                (
                    1,
                    sized(&self.batches, std::mem::size_of::<BatchInfo>() as u64),
                ),
                (2, self.adam.as_entire_binding()),
            ]
            .map(|(binding, resource)| wgpu::BindGroupEntry { binding, resource }),
        });
        ctx.check("binding training buffers")?;
        Ok((data_groups, step_group))
    }
}

/// The networks' parameters, network k at float `k * stride`; every binding is as large as
/// the kernel declares, the last one included.
fn padded_params(initial: &[Mlp], plan: ParamPlan) -> Vec<f32> {
    let stride = plan.stride_floats;
    let bindings = initial.len().div_ceil(plan.nets_per_binding);
    let mut params = vec![0.0f32; bindings * plan.nets_per_binding * stride];
    for (k, net) in initial.iter().enumerate() {
        params[k * stride..][..net.params.len()].copy_from_slice(&net.params);
    }
    params
}

/// One [`BatchInfo`] per uniform binding of the parameters, `align` bytes apart.
fn batch_slots(net_count: usize, plan: ParamPlan, align: u64) -> Vec<u8> {
    let bindings = net_count.div_ceil(plan.nets_per_binding);
    let mut slots = vec![0u8; (bindings as u64 * align) as usize];
    for b in 0..bindings {
        let info = BatchInfo {
            first_net: (b * plan.nets_per_binding) as u32,
            _pad0: 0,
            _pad1: 0,
            _pad2: 0,
        };
        slots[(b as u64 * align) as usize..][..std::mem::size_of::<BatchInfo>()]
            .copy_from_slice(bytemuck::bytes_of(&info));
    }
    slots
}

#[cfg(test)]
mod tests {
    use super::*;

    fn limits(align: u32, binding: u64) -> wgpu::Limits {
        wgpu::Limits {
            min_uniform_buffer_offset_alignment: align,
            max_uniform_buffer_binding_size: binding,
            ..wgpu::Limits::default()
        }
    }

    #[test]
    fn networks_start_at_aligned_offsets_and_fill_a_binding() {
        // 1185 parameters, 256-byte alignment: 1216 floats (4864 bytes) per network,
        // 13 networks in 64 KiB (13 × 4864 = 63 232 bytes).
        let plan = param_plan(&limits(256, 65_536), 1185).unwrap();
        assert_eq!(plan.stride_floats, 1216);
        assert_eq!(plan.nets_per_binding, 13);
        // 32-byte alignment: 1192 floats.
        assert_eq!(
            param_plan(&limits(32, 65_536), 1185).unwrap().stride_floats,
            1192
        );
        // One network that does not fit a binding: no plan.
        assert_eq!(param_plan(&limits(256, 4096), 1185), None);
    }

    #[test]
    fn architectures_outside_the_family_get_no_kernel() {
        let tanh = Activation::Tanh;
        assert!(epoch_source(&[2, 32, 32, 1], tanh, 1192, 13, true).is_some());
        // 5251 parameters > MAX_CPU_PARAMS.
        assert!(epoch_source(&[2, 70, 70, 1], tanh, 5256, 3, true).is_none());
        // A stride shorter than the parameters, or not a multiple of 4.
        assert!(epoch_source(&[2, 4, 1], tanh, 12, 1, true).is_none());
        assert!(epoch_source(&[2, 4, 1], tanh, 18, 1, true).is_none());
    }
}
