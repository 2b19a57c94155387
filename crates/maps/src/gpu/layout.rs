//! Host mirrors of the WGSL structs in `shaders/*.wgsl` (same names, same field order, explicit padding) and the builders that fill them.

use bytemuck::{Pod, Zeroable};

use crate::nn::{layer_spans, AdamScalars, Mlp, ModelConfig, TrainingSet, MAX_HIDDEN_LAYERS};

/// Weight layers the shaders' `Dims.layers` table holds (`MAX_LAYERS` in common.wgsl).
pub const MAX_LAYERS: usize = MAX_HIDDEN_LAYERS + 1;

/// Mirrors `LayerInfo` in shaders/common.wgsl.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Pod, Zeroable)]
pub struct LayerInfo {
    /// Units feeding the layer.
    pub inputs: u32,
    /// Units of the layer.
    pub outputs: u32,
    /// Offset of the layer's `W[0][0]` within one network's parameters (its biases follow
    /// the `outputs × inputs` weights).
    pub weight_offset: u32,
    /// First of this layer's outputs among a sample's stored units (activations, deltas).
    pub unit_offset: u32,
}

/// Mirrors `Dims` in shaders/common.wgsl.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Pod, Zeroable)]
pub struct Dims {
    /// Networks in the batch (or in this evaluation dispatch); all share one architecture.
    pub net_count: u32,
    /// Parameters of one network; network k's start at `k × param_count`.
    pub param_count: u32,
    /// Weight layers used in `layers` (hidden layers + output layer).
    pub layer_count: u32,
    /// Units stored per sample: the outputs of every layer, hidden and output.
    pub unit_count: u32,
    /// Training: samples of the whole batch. Evaluation: points of this dispatch.
    pub sample_count: u32,
    /// Hidden-layer activation code ([`crate::nn::Activation::shader_code`]: 0 tanh, 1 relu).
    pub activation: u32,
    /// Padding so `layers` starts at byte 32, 16-byte aligned as a struct array in WGSL's
    /// uniform address space must be; 0.
    pub _pad0: u32,
    /// Padding, as `_pad0`; 0.
    pub _pad1: u32,
    /// The weight layers in order; slots past `layer_count` are zero.
    pub layers: [LayerInfo; MAX_LAYERS],
}

/// Mirrors `NetInfo` in shaders/train.wgsl.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct NetInfo {
    /// Index of the network's first sample in the batch's flattened sample array.
    pub sample_offset: u32,
    /// Samples of the network's training set.
    pub sample_count: u32,
    /// First float of the network's activations and deltas in the unit storage
    /// (`sample_offset × unit_count`; unit u of sample s at `act_offset + u·sample_count + s`).
    pub act_offset: u32,
    /// `2 / sample_count`, the factor of the mean-squared-error gradient, computed on the host.
    pub grad_scale: f32,
}

/// Mirrors `Sample` in shaders/train.wgsl.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct Sample {
    /// Scaled u of the sample, in [-1, 1].
    pub x: f32,
    /// Scaled v of the sample, in [-1, 1].
    pub y: f32,
    /// Standardised target error of the sample.
    pub target_value: f32,
    /// Index of the network (training set) the sample belongs to.
    pub net: u32,
}

/// Mirrors `Step` in shaders/train.wgsl.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct Step {
    /// Adam step size of the epoch.
    pub learning_rate: f32,
    /// 1/(1 − β₁ᵗ), the first moment's bias correction.
    pub correction1: f32,
    /// 1/(1 − β₂ᵗ), the second moment's bias correction.
    pub correction2: f32,
    /// Padding of the struct to 16 bytes; 0.
    pub _pad: u32,
}

impl Step {
    /// The step of epoch `epoch` (0-based) of `config`'s schedule ([`AdamScalars::at`]).
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
