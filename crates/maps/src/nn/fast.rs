//! The fast CPU trainer: the reference's arithmetic blocked 8 samples wide with fused multiply-adds (AVX2 + FMA where the processor has them), networks and sample chunks spread over all cores.
//!
//! Same model, loss and Adam step as [`super::CpuTrainer`], and the same gradient lanes
//! (sample s to lane s mod 8, lanes summed in ascending sample order, then the tree
//! +4, +2, +1), but every multiply-add is fused, so results differ from the reference in the
//! last bits; `crates/maps/tests/nn.rs` bounds the difference. The order of every sum depends only on the
//! training set's size (chunks of [`CHUNK_BLOCKS`] blocks, added in chunk order), never on
//! the number of cores, so a run gives the same bytes on any machine with the same SIMD path.

use rayon::prelude::*;

use super::config::{Activation, ModelConfig};
use super::mlp::{layer_spans, unit_offsets, LayerSpan, Mlp};
use super::train::{adam_steps, continue_each, fit_one, train_each, AdamRun, REFERENCE_LANES};
use super::{CpuTrainer, Trainer, TrainingSet};
use errmap_core::Result;

/// SIMD width = gradient lanes: one f32 lane per sample of a block.
const W: usize = REFERENCE_LANES;
type V = [f32; W];
/// Blocks of 8 samples per chunk: a chunk is the unit of parallel work within a network
/// (512 samples; a 1536-sample set makes 3 chunks).
pub const CHUNK_BLOCKS: usize = 64;
/// Blocks whose gradients are accumulated together (one load and store of a lane
/// accumulator per 2 fused multiply-adds), in ascending sample order per lane.
const PAIR: usize = 2;

/// Trains on the CPU as fast as this processor allows; see the module documentation.
#[derive(Debug, Clone, Copy, Default)]
pub struct FastCpuTrainer;

impl FastCpuTrainer {
    /// The SIMD path this processor runs: "avx2+fma" or "portable".
    pub fn simd_path() -> &'static str {
        #[cfg(target_arch = "x86_64")]
        if pulp::x86::V3::is_available() {
            return "avx2+fma";
        }
        "portable"
    }
}

impl Trainer for FastCpuTrainer {
    fn name(&self) -> String {
        format!(
            "cpu ({}, {} threads)",
            Self::simd_path(),
            rayon::current_num_threads()
        )
    }

    fn train_from(
        &self,
        initial: Vec<Mlp>,
        sets: &[TrainingSet],
        config: &ModelConfig,
    ) -> Result<Vec<Mlp>> {
        train_each(initial, sets, config, |net, set, k| {
            let mut fast = FastGradient::new(net, set);
            fit_one(net, config, k, |params, grad| {
                fast.loss_and_gradient(params, set, grad)
            })
        })
    }

    fn train_segment(
        &self,
        runs: &mut [AdamRun],
        sets: &[TrainingSet],
        config: &ModelConfig,
        to_epoch: u32,
    ) -> Result<()> {
        continue_each(runs, sets, config, to_epoch, |run, set, k| {
            let mut fast = FastGradient::new(&run.net, set);
            adam_steps(run, config, to_epoch, k, |params, grad| {
                fast.loss_and_gradient(params, set, grad)
            })
        })
    }

    fn evaluate_batch(&self, nets: &[Mlp], inputs: &[[f32; 2]]) -> Result<Vec<Vec<f32>>> {
        // The reference's blocked evaluator (it checks the networks).
        CpuTrainer::reference().evaluate_batch(nets, inputs)
    }
}

/// The network's shape as the blocked pass needs it.
struct Shape {
    spans: Vec<LayerSpan>,
    /// First unit of each layer's outputs in the activation and delta arrays.
    unit_offset: Vec<usize>,
    activation: Activation,
}

/// One chunk's scratch: activations and deltas of [`PAIR`] blocks, 8 lane accumulators
/// per parameter, and the chunk's squared error.
struct Chunk {
    first_block: usize,
    blocks: usize,
    acts: Vec<Vec<V>>,
    deltas: Vec<Vec<V>>,
    lanes: Vec<V>,
    sq_err: f64,
}

/// Loss gradient of one network on one training set, reused across optimiser steps.
pub struct FastGradient {
    shape: Shape,
    chunks: Vec<Chunk>,
    /// Lanes of all chunks added, before the tree.
    total: Vec<V>,
    /// The gradient after [`FastGradient::compute`].
    pub sum: Vec<f32>,
}

impl FastGradient {
    /// Scratch for `net`'s architecture and `set`'s size, in chunks of [`CHUNK_BLOCKS`]
    /// blocks of samples; the parameters themselves are given to each
    /// [`FastGradient::compute`].
    pub fn new(net: &Mlp, set: &TrainingSet) -> FastGradient {
        let spans = layer_spans(&net.layer_sizes);
        let unit_offset = unit_offsets(&spans);
        let units: usize = spans.iter().map(|s| s.outputs).sum();
        let params = net.params.len();
        let blocks = set.len().div_ceil(W);
        let chunks = (0..blocks.div_ceil(CHUNK_BLOCKS))
            .map(|c| Chunk {
                first_block: c * CHUNK_BLOCKS,
                blocks: CHUNK_BLOCKS.min(blocks - c * CHUNK_BLOCKS),
                acts: vec![vec![[0.0; W]; units]; PAIR],
                deltas: vec![vec![[0.0; W]; units]; PAIR],
                lanes: vec![[0.0; W]; params],
                sq_err: 0.0,
            })
            .collect();
        FastGradient {
            shape: Shape {
                spans,
                unit_offset,
                activation: net.activation,
            },
            chunks,
            total: vec![[0.0; W]; params],
            sum: vec![0.0; params],
        }
    }

    /// [`FastGradient::compute`], the gradient copied into `grad`; returns the loss.
    pub fn loss_and_gradient(
        &mut self,
        params: &[f32],
        set: &TrainingSet,
        grad: &mut [f32],
    ) -> f64 {
        let loss = self.compute(params, set);
        grad.copy_from_slice(&self.sum);
        loss
    }

    /// Gradient of the mean squared error at `params` into [`FastGradient::sum`]; returns
    /// the mean squared error.
    pub fn compute(&mut self, params: &[f32], set: &TrainingSet) -> f64 {
        let shape = &self.shape;
        let grad_scale = 2.0f32 / set.len() as f32;
        self.chunks.par_iter_mut().for_each(|chunk| {
            let pass = ChunkPass {
                shape,
                params,
                set,
                grad_scale,
                chunk,
            };
            #[cfg(target_arch = "x86_64")]
            if let Some(simd) = pulp::x86::V3::try_new() {
                return simd.vectorize(pass);
            }
            pass.run();
        });
        // Chunks in order, then the 8-lane tree: the order depends on the set's size only.
        let mut sq_err = 0.0;
        let total = &mut self.total;
        total.copy_from_slice(&self.chunks[0].lanes);
        sq_err += self.chunks[0].sq_err;
        for chunk in &self.chunks[1..] {
            sq_err += chunk.sq_err;
            for (t, l) in total.iter_mut().zip(&chunk.lanes) {
                for b in 0..W {
                    t[b] += l[b];
                }
            }
        }
        for (g, l) in self.sum.iter_mut().zip(total.iter()) {
            let q = [l[0] + l[4], l[1] + l[5], l[2] + l[6], l[3] + l[7]];
            let h = [q[0] + q[2], q[1] + q[3]];
            *g = h[0] + h[1];
        }
        sq_err / set.len().max(1) as f64
    }
}

/// The work of one chunk, run inside the SIMD dispatch (so everything it calls is inlined
/// with the processor's vector features).
struct ChunkPass<'a> {
    shape: &'a Shape,
    params: &'a [f32],
    set: &'a TrainingSet,
    grad_scale: f32,
    chunk: &'a mut Chunk,
}

impl pulp::NullaryFnOnce for ChunkPass<'_> {
    type Output = ();
    #[inline(always)]
    fn call(self) {
        self.run()
    }
}

impl ChunkPass<'_> {
    #[inline(always)]
    fn run(self) {
        let chunk = self.chunk;
        chunk.lanes.iter_mut().for_each(|l| *l = [0.0; W]);
        let mut sq_err = 0.0f64;
        let n = self.set.len();
        let mut block = 0;
        while block < chunk.blocks {
            // A pair past the chunk's end is padded with an empty block (zero deltas).
            for q in 0..PAIR {
                let s0 = (chunk.first_block + block + q) * W;
                let count = if block + q < chunk.blocks {
                    W.min(n - s0)
                } else {
                    0
                };
                sq_err += forward_backward(
                    self.shape,
                    self.params,
                    self.set,
                    s0,
                    count,
                    self.grad_scale,
                    &mut chunk.acts[q],
                    &mut chunk.deltas[q],
                );
            }
            let (a0, a1) = chunk.acts.split_at(1);
            let (d0, d1) = chunk.deltas.split_at(1);
            accumulate(
                self.shape,
                self.set,
                (chunk.first_block + block) * W,
                [&a0[0], &a1[0]],
                [&d0[0], &d1[0]],
                &mut chunk.lanes,
            );
            block += PAIR;
        }
        chunk.sq_err = sq_err;
    }
}

#[inline(always)]
fn splat(x: f32) -> V {
    [x; W]
}

/// a·b + c in every lane, fused.
#[inline(always)]
fn fma(a: V, b: V, c: V) -> V {
    let mut out = [0.0; W];
    for i in 0..W {
        out[i] = a[i].mul_add(b[i], c[i]);
    }
    out
}

#[inline(always)]
fn mul(a: V, b: V) -> V {
    let mut out = [0.0; W];
    for i in 0..W {
        out[i] = a[i] * b[i];
    }
    out
}

/// The reference's rational tanh ([`super::tanh_f32`]) with fused multiply-adds, lane-wise
/// array operations throughout so that it compiles to vector instructions.
#[inline(always)]
fn tanh_v(x: V) -> V {
    const A: [f32; 7] = [
        f32::from_bits(0x3ba0_59dc),
        f32::from_bits(0x3a27_0ded),
        f32::from_bits(0x3779_434a),
        f32::from_bits(0x335c_0041),
        f32::from_bits(0xaebd_37ff),
        f32::from_bits(0x2a61_337e),
        f32::from_bits(0xa59f_25c0),
    ];
    const B: [f32; 4] = [
        f32::from_bits(0x3ba0_59dd),
        f32::from_bits(0x3b14_aa05),
        f32::from_bits(0x38f8_95d6),
        f32::from_bits(0x35a0_d3d8),
    ];
    const CLAMP: f32 = f32::from_bits(0x40fc_f84f);
    const TINY: f32 = f32::from_bits(0x39d1_b717);
    let x = x.map(|v| v.clamp(-CLAMP, CLAMP));
    let x2 = mul(x, x);
    let mut p = fma(x2, splat(A[6]), splat(A[5]));
    for a in A[..5].iter().rev() {
        p = fma(x2, p, splat(*a));
    }
    p = mul(p, x);
    let mut q = fma(x2, splat(B[3]), splat(B[2]));
    q = fma(x2, q, splat(B[1]));
    q = fma(x2, q, splat(B[0]));
    let mut ratio = [0.0; W];
    for i in 0..W {
        ratio[i] = p[i] / q[i];
    }
    for i in 0..W {
        if x[i].abs() < TINY {
            ratio[i] = x[i];
        }
    }
    ratio
}

/// Rows of a layer computed together, so that their sums are independent chains of
/// fused multiply-adds (each row's own order is unchanged).
const ROWS: usize = 4;

/// z_i = b_i + Σ_j W[i][j]·a_j for the `ROWS` rows from `i0` (rows past `outputs` unused).
#[inline(always)]
fn layer_rows(params: &[f32], span: &LayerSpan, i0: usize, prev: &[V]) -> [V; ROWS] {
    let mut z = [[0.0f32; W]; ROWS];
    let rows = ROWS.min(span.outputs - i0);
    let mut weights = [&params[0..0]; ROWS];
    for r in 0..rows {
        z[r] = splat(params[span.bias_offset + i0 + r]);
        weights[r] = &params[span.weight_offset + (i0 + r) * span.inputs..][..span.inputs];
    }
    if rows == ROWS {
        for (j, a) in prev.iter().enumerate() {
            for r in 0..ROWS {
                z[r] = fma(splat(weights[r][j]), *a, z[r]);
            }
        }
    } else {
        for r in 0..rows {
            for (w, a) in weights[r].iter().zip(prev) {
                z[r] = fma(splat(*w), *a, z[r]);
            }
        }
    }
    z
}

/// Forward and backward pass of the block of samples s0 … s0 + count − 1 (count ≤ 8; the
/// other lanes carry zero deltas). Leaves each layer's outputs in `acts` and deltas in
/// `deltas`; returns the block's squared error. The stages are `#[inline(always)]`: this is
/// the hot loop, one function once compiled.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn forward_backward(
    shape: &Shape,
    params: &[f32],
    set: &TrainingSet,
    s0: usize,
    count: usize,
    grad_scale: f32,
    acts: &mut [V],
    deltas: &mut [V],
) -> f64 {
    let input = block_inputs(set, s0, count);
    forward(shape, params, &input, acts);
    let out_unit = shape.unit_offset[shape.spans.len() - 1];
    let sq_err = output_deltas(
        &acts[out_unit],
        set,
        s0,
        count,
        grad_scale,
        &mut deltas[out_unit],
    );
    for l in (1..shape.spans.len()).rev() {
        backward_layer(shape, params, l, acts, deltas);
    }
    sq_err
}

/// Forward pass of the block: each layer's outputs (activated except the last) into `acts`.
#[inline(always)]
fn forward(shape: &Shape, params: &[f32], input: &[V; 2], acts: &mut [V]) {
    let last = shape.spans.len() - 1;
    for (l, span) in shape.spans.iter().enumerate() {
        let (done, rest) = acts.split_at_mut(shape.unit_offset[l]);
        let prev: &[V] = if l == 0 {
            input
        } else {
            &done[shape.unit_offset[l - 1]..][..span.inputs]
        };
        let out = &mut rest[..span.outputs];
        for i0 in (0..span.outputs).step_by(ROWS) {
            let z = layer_rows(params, span, i0, prev);
            for (r, o) in out[i0..].iter_mut().take(ROWS).enumerate() {
                *o = if l == last {
                    z[r]
                } else {
                    match shape.activation {
                        Activation::Tanh => tanh_v(z[r]),
                        Activation::Relu => z[r].map(|v| v.max(0.0)),
                    }
                };
            }
        }
    }
}

/// δ_out = (y − t)·grad_scale in the lanes of the block's samples (zero past `count`);
/// returns the block's squared error.
#[inline(always)]
fn output_deltas(
    output: &V,
    set: &TrainingSet,
    s0: usize,
    count: usize,
    grad_scale: f32,
    delta: &mut V,
) -> f64 {
    let mut sq_err = 0.0f64;
    for b in 0..W {
        let err = if b < count {
            output[b] - set.targets[s0 + b]
        } else {
            0.0
        };
        sq_err += err as f64 * err as f64;
        delta[b] = err * grad_scale;
    }
    sq_err
}

/// The deltas of layer `l`'s inputs from its output deltas:
/// δ_prev[j] = (Σ_i W[i][j]·δ_i, i ascending)·f'(a_prev[j]).
#[inline(always)]
fn backward_layer(shape: &Shape, params: &[f32], l: usize, acts: &[V], deltas: &mut [V]) {
    let span = shape.spans[l];
    let (before, current) = deltas.split_at_mut(shape.unit_offset[l]);
    let delta = &current[..span.outputs];
    let prev_acts = &acts[shape.unit_offset[l - 1]..][..span.inputs];
    let prev_delta = &mut before[shape.unit_offset[l - 1]..][..span.inputs];
    // back_j = Σ_i W[i][j]·δ_i, i ascending: rows of W two at a time, every column j an
    // independent sum.
    let back = &mut prev_delta[..];
    back.iter_mut().for_each(|b| *b = [0.0; W]);
    let mut i = 0;
    while i + 1 < span.outputs {
        let w0 = &params[span.weight_offset + i * span.inputs..][..span.inputs];
        let w1 = &params[span.weight_offset + (i + 1) * span.inputs..][..span.inputs];
        let (d0, d1) = (delta[i], delta[i + 1]);
        for ((b, x0), x1) in back.iter_mut().zip(w0).zip(w1) {
            *b = fma(splat(*x1), d1, fma(splat(*x0), d0, *b));
        }
        i += 2;
    }
    if i < span.outputs {
        let w0 = &params[span.weight_offset + i * span.inputs..][..span.inputs];
        for (b, x0) in back.iter_mut().zip(w0) {
            *b = fma(splat(*x0), delta[i], *b);
        }
    }
    for (b, a) in back.iter_mut().zip(prev_acts) {
        let slope = match shape.activation {
            Activation::Tanh => fma(*a, a.map(|v| -v), splat(1.0)),
            Activation::Relu => a.map(|v| if v > 0.0 { 1.0 } else { 0.0 }),
        };
        *b = mul(*b, slope);
    }
}

/// The two inputs of samples s0 … s0 + count − 1, zero in the lanes past them.
#[inline(always)]
fn block_inputs(set: &TrainingSet, s0: usize, count: usize) -> [V; 2] {
    let mut input = [[0.0f32; W]; 2];
    let s0 = s0.min(set.len());
    for (b, x) in set.inputs[s0..(s0 + count).min(set.len())]
        .iter()
        .enumerate()
    {
        input[0][b] = x[0];
        input[1][b] = x[1];
    }
    input
}

/// Adds δ_i·a_j (and δ_i for the biases) of the [`PAIR`] blocks starting at sample `s0` to
/// the 8 lane accumulators, block after block, so each lane keeps ascending sample order.
#[inline(always)]
fn accumulate(
    shape: &Shape,
    set: &TrainingSet,
    s0: usize,
    acts: [&[V]; PAIR],
    deltas: [&[V]; PAIR],
    lanes: &mut [V],
) {
    let mut inputs = [[[0.0f32; W]; 2]; PAIR];
    for (q, input) in inputs.iter_mut().enumerate() {
        *input = block_inputs(set, s0 + q * W, W);
    }
    for (l, span) in shape.spans.iter().enumerate() {
        let prev: [&[V]; PAIR] = if l == 0 {
            [&inputs[0], &inputs[1]]
        } else {
            let from = shape.unit_offset[l - 1];
            [
                &acts[0][from..][..span.inputs],
                &acts[1][from..][..span.inputs],
            ]
        };
        for i in 0..span.outputs {
            let unit = shape.unit_offset[l] + i;
            let d = [deltas[0][unit], deltas[1][unit]];
            let row = &mut lanes[span.weight_offset + i * span.inputs..][..span.inputs];
            for ((g, a0), a1) in row.iter_mut().zip(prev[0]).zip(prev[1]) {
                *g = fma(d[1], *a1, fma(d[0], *a0, *g));
            }
            let bias = &mut lanes[span.bias_offset + i];
            for b in 0..W {
                bias[b] = bias[b] + d[0][b] + d[1][b];
            }
        }
    }
}
