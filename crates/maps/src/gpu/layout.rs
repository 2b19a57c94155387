//! Host mirrors of the WGSL structs in `shaders/*.wgsl` (same names, same field order, explicit padding) and the builders that fill them.

use bytemuck::{Pod, Zeroable};

use crate::nn::{layer_spans, AdamScalars, Mlp, ModelConfig, TrainingSet, MAX_HIDDEN_LAYERS};

/// Weight layers the shaders' `Dims.layers` table holds (`MAX_LAYERS` in common.wgsl).
pub const MAX_LAYERS: usize = MAX_HIDDEN_LAYERS + 1;

/// Mirrors `LayerInfo` in shaders/common.wgsl.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Pod, Zeroable)]
pub struct LayerInfo {
    pub inputs: u32,
    pub outputs: u32,
    pub weight_offset: u32,
    pub unit_offset: u32,
}

/// Mirrors `Dims` in shaders/common.wgsl.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Pod, Zeroable)]
pub struct Dims {
    pub net_count: u32,
    pub param_count: u32,
    pub layer_count: u32,
    pub unit_count: u32,
    pub sample_count: u32,
    pub activation: u32,
    pub _pad0: u32,
    pub _pad1: u32,
    pub layers: [LayerInfo; MAX_LAYERS],
}

/// Mirrors `NetInfo` in shaders/train.wgsl.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct NetInfo {
    pub sample_offset: u32,
    pub sample_count: u32,
    pub act_offset: u32,
    pub grad_scale: f32,
}

/// Mirrors `Sample` in shaders/train.wgsl.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct Sample {
    pub x: f32,
    pub y: f32,
    pub target_value: f32,
    pub net: u32,
}

/// Mirrors `Step` in shaders/train.wgsl.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct Step {
    pub learning_rate: f32,
    pub correction1: f32,
    pub correction2: f32,
    pub _pad: u32,
}

impl Step {
    pub fn at(config: &ModelConfig, epoch: u32) -> Step {
        let s = AdamScalars::at(config, epoch);
        Step {
            learning_rate: s.learning_rate,
            correction1: s.correction1,
            correction2: s.correction2,
            _pad: 0,
        }
    }
}

/// `Dims` for networks with these layer sizes; `sample_count` as given.
/// The caller has validated the sizes (at most [`MAX_LAYERS`] weight layers).
pub fn dims_for(net: &Mlp, net_count: usize, sample_count: usize) -> Dims {
    let mut layers = [LayerInfo::zeroed(); MAX_LAYERS];
    let mut units = 0u32;
    let spans = layer_spans(&net.layer_sizes);
    for (slot, span) in layers.iter_mut().zip(&spans) {
        *slot = LayerInfo {
            inputs: span.inputs as u32,
            outputs: span.outputs as u32,
            weight_offset: span.weight_offset as u32,
            unit_offset: units,
        };
        units += span.outputs as u32;
    }
    Dims {
        net_count: net_count as u32,
        param_count: net.params.len() as u32,
        layer_count: spans.len() as u32,
        unit_count: units,
        sample_count: sample_count as u32,
        activation: net.activation.shader_code(),
        _pad0: 0,
        _pad1: 0,
        layers,
    }
}

/// Per-network table and the flattened samples of a batch, in network order.
pub fn pack_samples(sets: &[TrainingSet], unit_count: u32) -> (Vec<NetInfo>, Vec<Sample>) {
    let total: usize = sets.iter().map(|s| s.len()).sum();
    let mut nets = Vec::with_capacity(sets.len());
    let mut samples = Vec::with_capacity(total);
    for (k, set) in sets.iter().enumerate() {
        let offset = samples.len() as u32;
        nets.push(NetInfo {
            sample_offset: offset,
            sample_count: set.len() as u32,
            act_offset: offset * unit_count,
            grad_scale: 2.0f32 / set.len() as f32,
        });
        samples.extend(set.inputs.iter().zip(&set.targets).map(|(x, &t)| Sample {
            x: x[0],
            y: x[1],
            target_value: t,
            net: k as u32,
        }));
    }
    (nets, samples)
}
