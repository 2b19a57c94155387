//! The multilayer perceptron: its flat parameter layout (shared with the WGSL shaders), Glorot initialisation and forward pass.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::config::Activation;

/// A fully connected network 2 → hidden… → 1.
///
/// Parameter layout (the same in `shaders/*.wgsl`): for each layer l in order, its weight
/// matrix W row-major `[out][in]` (element `(i, j)` at `i * in + j`), then its bias `b[out]`.
/// Hidden layers apply the activation; the output layer is linear.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Mlp {
    /// Units per layer, the 2 inputs first and the 1 output last.
    pub layer_sizes: Vec<usize>,
    /// Activation of the hidden layers.
    pub activation: Activation,
    /// Every weight and bias, in the layout above ([`layer_spans`] says where each layer's sit).
    pub params: Vec<f32>,
}

/// Where one layer's parameters sit in [`Mlp::params`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LayerSpan {
    /// Units feeding the layer (the previous layer's width, 2 for the first).
    pub inputs: usize,
    /// Units of the layer (its bias count, 1 for the output layer).
    pub outputs: usize,
    /// Offset of `W[0][0]`.
    pub weight_offset: usize,
    /// Offset of `b[0]` (= weight_offset + outputs·inputs).
    pub bias_offset: usize,
}

/// Layer spans of a network with these sizes, in order.
pub fn layer_spans(layer_sizes: &[usize]) -> Vec<LayerSpan> {
    let mut offset = 0;
    layer_sizes
        .windows(2)
        .map(|w| {
            let span = LayerSpan {
                inputs: w[0],
                outputs: w[1],
                weight_offset: offset,
                bias_offset: offset + w[0] * w[1],
            };
            offset += w[0] * w[1] + w[1];
            span
        })
        .collect()
}

/// First unit of each layer's outputs when a network's units are numbered layer after layer
/// (the activation and delta layout of the trainers and the shaders).
pub fn unit_offsets(spans: &[LayerSpan]) -> Vec<usize> {
    spans
        .iter()
        .scan(0usize, |units, span| {
            let first = *units;
            *units += span.outputs;
            Some(first)
        })
        .collect()
}

/// Number of parameters (weights and biases) of a network with these layer sizes.
pub fn param_count(layer_sizes: &[usize]) -> usize {
    layer_sizes.windows(2).map(|w| w[0] * w[1] + w[1]).sum()
}

impl Mlp {
    /// Glorot-uniform weights (Glorot & Bengio 2010: U(±√(6/(fan_in+fan_out)))), zero biases,
    /// drawn from ChaCha8 seeded with `seed` in layout order.
    pub fn init(layer_sizes: &[usize], activation: Activation, seed: u64) -> Mlp {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut params = vec![0.0f32; param_count(layer_sizes)];
        for span in layer_spans(layer_sizes) {
            let limit = (6.0 / (span.inputs + span.outputs) as f64).sqrt() as f32;
            for w in &mut params[span.weight_offset..span.bias_offset] {
                *w = rng.random_range(-limit..limit);
            }
        }
        Mlp {
            layer_sizes: layer_sizes.to_vec(),
            activation,
            params,
        }
    }

    /// Whether sizes and parameter count agree (2 inputs, 1 output, no empty layer).
    pub fn is_consistent(&self) -> bool {
        self.layer_sizes.len() >= 2
            && self.layer_sizes.first() == Some(&2)
            && self.layer_sizes.last() == Some(&1)
            && self.layer_sizes.iter().all(|&s| s > 0)
            && self.params.len() == param_count(&self.layer_sizes)
    }

    /// Network output for one scaled input. Sums run over inputs in ascending order,
    /// starting from the bias, exactly as the shaders do. An inconsistent network (see
    /// [`Mlp::is_consistent`], e.g. a hand-edited model file) gives NaN instead of panicking;
    /// loaders should reject it up front with [`crate::nn::check_nets`].
    pub fn forward(&self, x: [f32; 2]) -> f32 {
        if !self.is_consistent() {
            return f32::NAN;
        }
        let mut prev: Vec<f32> = x.to_vec();
        let mut next = Vec::new();
        let spans = layer_spans(&self.layer_sizes);
        let last = spans.len().saturating_sub(1);
        for (l, span) in spans.iter().enumerate() {
            next.clear();
            for i in 0..span.outputs {
                let row = &self.params[span.weight_offset + i * span.inputs..][..span.inputs];
                let mut z = self.params[span.bias_offset + i];
                for (w, a) in row.iter().zip(&prev) {
                    z += w * a;
                }
                next.push(if l == last {
                    z
                } else {
                    self.activation.apply(z)
                });
            }
            std::mem::swap(&mut prev, &mut next);
        }
        prev.first().copied().unwrap_or(0.0)
    }
}
