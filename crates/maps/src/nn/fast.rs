//! The fast CPU trainer: the reference's arithmetic blocked 8 samples wide with fused multiply-adds (AVX2 + FMA where the processor has them) in register-blocked tiles, networks and sample chunks spread over all cores.
//!
//! Same model, loss and Adam step as [`super::CpuTrainer`], and the same gradient lanes
//! (sample s to lane s mod 8, lanes summed in ascending sample order, then the tree
//! +4, +2, +1), but every multiply-add is fused, so results differ from the reference in the
//! last bits; `crates/maps/tests/nn.rs` bounds the difference. The order of every sum depends
//! only on the training set's size, never on the number of cores or on the tiling below, so
//! a run gives the same bytes on any machine with the same SIMD path:
//! - a layer output z_i = b_i + Σ_j W[i][j]·a_j, j ascending (one fused chain per sample);
//! - a delta δ_prev[j] = (0 + Σ_i W[i][j]·δ_i, i ascending)·(1 − a_j²) for tanh;
//! - a gradient: the set is cut into chunks of [`CHUNK_BLOCKS`] blocks of 8 samples; within
//!   a chunk lane b of each parameter starts at 0 and adds the terms of samples
//!   8·block + b, blocks ascending; the chunks' lanes are added in chunk order, then the
//!   8 lanes in the tree.
//!
//! How the work is laid out does not enter those orders. Blocks go through the network
//! [`TILE`] at a time: a layer's outputs are computed for a few units × the tile's blocks in
//! registers, each weight loaded once for them all; the deltas likewise; and the gradient
//! lanes of a few rows × columns of a weight matrix stay in registers while the tile's blocks
//! are added to them in ascending order, so a lane accumulator is loaded and stored once per
//! tile instead of once per block.

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
/// (512 samples; a 1536-sample set makes 3 chunks), and of the gradient's first sum.
pub const CHUNK_BLOCKS: usize = 64;
/// Blocks that go through the network together (a divisor of [`CHUNK_BLOCKS`]).
pub const TILE: usize = 4;
/// One unit's values over the blocks of a tile.
type T = [V; TILE];

/// Output units computed together in the forward pass (each with the tile's blocks).
const FWD_ROWS: usize = 2;
/// Input units whose deltas are computed together in the backward pass.
const BWD_COLS: usize = 2;
/// Rows × columns of a weight matrix whose gradient lanes stay in registers over a tile.
const GRAD_ROWS: usize = 2;
const GRAD_COLS: usize = 4;

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
        let split = split_chunks(sets.len());
        train_each(initial, sets, config, |net, set, k| {
            let mut fast = FastGradient::new(net, set);
            fast.parallel_chunks = split;
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
        let split = split_chunks(sets.len());
        continue_each(runs, sets, config, to_epoch, |run, set, k| {
            let mut fast = FastGradient::new(&run.net, set);
            fast.parallel_chunks = split;
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

/// Whether a batch of `networks` should also spread each network's chunks over the cores:
/// only when there are fewer networks than threads (otherwise the networks keep every core
/// busy, and splitting an epoch into tasks only adds their cost). Either way the sums are the
/// same.
fn split_chunks(networks: usize) -> bool {
    networks < rayon::current_num_threads()
}

/// The network's shape as the blocked pass needs it.
struct Shape {
    spans: Vec<LayerSpan>,
    /// First unit of each layer's outputs in the activation and delta arrays.
    unit_offset: Vec<usize>,
    activation: Activation,
}

/// One chunk's scratch: activations and deltas of one tile, 8 lane accumulators per
/// parameter, and the chunk's squared error.
struct Chunk {
    first_block: usize,
    blocks: usize,
    acts: Vec<T>,
    deltas: Vec<T>,
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
    /// Whether [`FastGradient::compute`] runs the chunks as parallel tasks (default) or one
    /// after the other on the calling thread; the result is the same bits.
    pub parallel_chunks: bool,
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
                acts: vec![[[0.0; W]; TILE]; units],
                deltas: vec![[[0.0; W]; TILE]; units],
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
            parallel_chunks: true,
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
        let run = |chunk: &mut Chunk| {
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
        };
        if self.parallel_chunks && self.chunks.len() > 1 {
            self.chunks.par_iter_mut().for_each(run);
        } else {
            self.chunks.iter_mut().for_each(run);
        }
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
    /// Every tile of the chunk: forward, output deltas, backward, then the tile's gradient
    /// terms into the lanes. The stages are `#[inline(always)]`: this is the hot loop, one
    /// function once compiled.
    #[inline(always)]
    fn run(self) {
        let Self {
            shape,
            params,
            set,
            grad_scale,
            chunk,
        } = self;
        chunk.lanes.iter_mut().for_each(|l| *l = [0.0; W]);
        let mut sq_err = 0.0f64;
        let n = set.len();
        let last = shape.spans.len() - 1;
        let out_unit = shape.unit_offset[last];
        let mut block = 0;
        while block < chunk.blocks {
            // Blocks of the tile past the chunk's end run with no samples (zero inputs and
            // deltas) and add nothing to the lanes.
            let real = TILE.min(chunk.blocks - block);
            let first_sample = (chunk.first_block + block) * W;
            let mut counts = [0usize; TILE];
            for (q, count) in counts.iter_mut().enumerate().take(real) {
                *count = W.min(n - (first_sample + q * W));
            }
            let input = tile_inputs(set, first_sample, &counts);
            forward(shape, params, &input, &mut chunk.acts);
            for (q, &count) in counts.iter().enumerate().take(real) {
                sq_err += output_deltas(
                    &chunk.acts[out_unit][q],
                    set,
                    first_sample + q * W,
                    count,
                    grad_scale,
                    &mut chunk.deltas[out_unit][q],
                );
            }
            for q in real..TILE {
                chunk.deltas[out_unit][q] = [0.0; W];
            }
            for l in (1..shape.spans.len()).rev() {
                backward_layer(shape, params, l, &chunk.acts, &mut chunk.deltas);
            }
            accumulate(
                shape,
                &input,
                &chunk.acts,
                &chunk.deltas,
                real,
                &mut chunk.lanes,
            );
            block += TILE;
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
    let mut x = x;
    for v in &mut x {
        *v = v.clamp(-CLAMP, CLAMP);
    }
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

#[inline(always)]
fn activate(activation: Activation, z: V) -> V {
    match activation {
        Activation::Tanh => tanh_v(z),
        Activation::Relu => {
            let mut out = z;
            for v in &mut out {
                *v = v.max(0.0);
            }
            out
        }
    }
}

/// The inputs of the tile's blocks from sample `s0` (`counts[q]` samples in block q), zero in
/// the lanes past them.
#[inline(always)]
fn tile_inputs(set: &TrainingSet, s0: usize, counts: &[usize; TILE]) -> [T; 2] {
    let mut input = [[[0.0f32; W]; TILE]; 2];
    for (q, &count) in counts.iter().enumerate() {
        let from = s0 + q * W;
        if count == 0 {
            continue;
        }
        for (b, x) in set.inputs[from..from + count].iter().enumerate() {
            input[0][q][b] = x[0];
            input[1][q][b] = x[1];
        }
    }
    input
}

/// Forward pass of the tile: each layer's outputs (activated except the last) into `acts`.
#[inline(always)]
fn forward(shape: &Shape, params: &[f32], input: &[T; 2], acts: &mut [T]) {
    let last = shape.spans.len() - 1;
    for (l, span) in shape.spans.iter().enumerate() {
        let (done, rest) = acts.split_at_mut(shape.unit_offset[l]);
        let prev: &[T] = if l == 0 {
            input
        } else {
            &done[shape.unit_offset[l - 1]..][..span.inputs]
        };
        let out = &mut rest[..span.outputs];
        let act = (l != last).then_some(shape.activation);
        let mut i0 = 0;
        while i0 + FWD_ROWS <= span.outputs {
            forward_rows::<FWD_ROWS>(params, span, i0, prev, act, out);
            i0 += FWD_ROWS;
        }
        while i0 < span.outputs {
            forward_rows::<1>(params, span, i0, prev, act, out);
            i0 += 1;
        }
    }
}

/// Outputs i0 … i0 + R − 1 of a layer for every block of the tile:
/// z_i = b_i + Σ_j W[i][j]·a_j (j ascending), activated with `act` if given.
#[inline(always)]
fn forward_rows<const R: usize>(
    params: &[f32],
    span: &LayerSpan,
    i0: usize,
    prev: &[T],
    act: Option<Activation>,
    out: &mut [T],
) {
    let inputs = span.inputs;
    let prev = &prev[..inputs];
    // Plain loops, not `array::from_fn` or `map` closures: a closure is compiled apart from
    // the SIMD dispatch, without its vector features (and `mul_add` there is a libm call).
    let mut weights = [&params[..0]; R];
    let mut z = [[[0.0f32; W]; TILE]; R];
    for r in 0..R {
        weights[r] = &params[span.weight_offset + (i0 + r) * inputs..][..inputs];
        z[r] = [splat(params[span.bias_offset + i0 + r]); TILE];
    }
    for j in 0..inputs {
        let a = &prev[j];
        for r in 0..R {
            let w = splat(weights[r][j]);
            for q in 0..TILE {
                z[r][q] = fma(w, a[q], z[r][q]);
            }
        }
    }
    for r in 0..R {
        for q in 0..TILE {
            out[i0 + r][q] = match act {
                Some(activation) => activate(activation, z[r][q]),
                None => z[r][q],
            };
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
fn backward_layer(shape: &Shape, params: &[f32], l: usize, acts: &[T], deltas: &mut [T]) {
    let span = shape.spans[l];
    let (before, current) = deltas.split_at_mut(shape.unit_offset[l]);
    let delta = &current[..span.outputs];
    let prev_acts = &acts[shape.unit_offset[l - 1]..][..span.inputs];
    let prev_delta = &mut before[shape.unit_offset[l - 1]..][..span.inputs];
    let mut j0 = 0;
    while j0 + BWD_COLS <= span.inputs {
        backward_cols::<BWD_COLS>(
            params,
            &span,
            j0,
            delta,
            prev_acts,
            shape.activation,
            prev_delta,
        );
        j0 += BWD_COLS;
    }
    while j0 < span.inputs {
        backward_cols::<1>(
            params,
            &span,
            j0,
            delta,
            prev_acts,
            shape.activation,
            prev_delta,
        );
        j0 += 1;
    }
}

/// Input deltas j0 … j0 + C − 1 of a layer for every block of the tile.
#[inline(always)]
fn backward_cols<const C: usize>(
    params: &[f32],
    span: &LayerSpan,
    j0: usize,
    delta: &[T],
    prev_acts: &[T],
    activation: Activation,
    prev_delta: &mut [T],
) {
    let inputs = span.inputs;
    let delta = &delta[..span.outputs];
    let weights = &params[span.weight_offset..][..span.outputs * inputs];
    let mut back = [[[0.0f32; W]; TILE]; C];
    for (i, d) in delta.iter().enumerate() {
        let row = &weights[i * inputs + j0..][..C];
        for c in 0..C {
            let w = splat(row[c]);
            for q in 0..TILE {
                back[c][q] = fma(w, d[q], back[c][q]);
            }
        }
    }
    for c in 0..C {
        let a = &prev_acts[j0 + c];
        for q in 0..TILE {
            let mut slope = [0.0f32; W];
            for b in 0..W {
                slope[b] = match activation {
                    Activation::Tanh => a[q][b].mul_add(-a[q][b], 1.0),
                    Activation::Relu => {
                        if a[q][b] > 0.0 {
                            1.0
                        } else {
                            0.0
                        }
                    }
                };
            }
            prev_delta[j0 + c][q] = mul(back[c][q], slope);
        }
    }
}

/// Adds δ_i·a_j (and δ_i for the biases) of the first `real` blocks of the tile to the 8
/// lane accumulators, block after block, so each lane keeps ascending sample order.
#[inline(always)]
fn accumulate(
    shape: &Shape,
    input: &[T; 2],
    acts: &[T],
    deltas: &[T],
    real: usize,
    lanes: &mut [V],
) {
    for (l, span) in shape.spans.iter().enumerate() {
        let prev: &[T] = if l == 0 {
            input
        } else {
            &acts[shape.unit_offset[l - 1]..][..span.inputs]
        };
        let delta = &deltas[shape.unit_offset[l]..][..span.outputs];
        let (weights, rest) = lanes[span.weight_offset..].split_at_mut(span.outputs * span.inputs);
        for (bias, d) in rest[..span.outputs].iter_mut().zip(delta) {
            for dq in &d[..real] {
                for b in 0..W {
                    bias[b] += dq[b];
                }
            }
        }
        let mut i0 = 0;
        while i0 + GRAD_ROWS <= span.outputs {
            gradient_rows::<GRAD_ROWS>(span, i0, delta, prev, real, weights);
            i0 += GRAD_ROWS;
        }
        while i0 < span.outputs {
            gradient_rows::<1>(span, i0, delta, prev, real, weights);
            i0 += 1;
        }
    }
}

/// The lanes of weight rows i0 … i0 + R − 1 of a layer, [`GRAD_COLS`] columns at a time.
#[inline(always)]
fn gradient_rows<const R: usize>(
    span: &LayerSpan,
    i0: usize,
    delta: &[T],
    prev: &[T],
    real: usize,
    weights: &mut [V],
) {
    let inputs = span.inputs;
    let mut j0 = 0;
    while j0 + GRAD_COLS <= inputs {
        gradient_tile::<R, GRAD_COLS>(inputs, i0, j0, delta, prev, real, weights);
        j0 += GRAD_COLS;
    }
    while j0 < inputs {
        gradient_tile::<R, 1>(inputs, i0, j0, delta, prev, real, weights);
        j0 += 1;
    }
}

/// The lanes of W[i0 … i0 + R − 1][j0 … j0 + C − 1] held in registers while the first
/// `real` blocks of the tile add δ_i·a_j to them, blocks ascending.
#[inline(always)]
fn gradient_tile<const R: usize, const C: usize>(
    inputs: usize,
    i0: usize,
    j0: usize,
    delta: &[T],
    prev: &[T],
    real: usize,
    weights: &mut [V],
) {
    let d = &delta[i0..][..R];
    let a = &prev[j0..][..C];
    let mut g = [[[0.0f32; W]; C]; R];
    for r in 0..R {
        g[r].copy_from_slice(&weights[(i0 + r) * inputs + j0..][..C]);
    }
    for q in 0..real.min(TILE) {
        for r in 0..R {
            let dq = d[r][q];
            for c in 0..C {
                g[r][c] = fma(dq, a[c][q], g[r][c]);
            }
        }
    }
    for r in 0..R {
        weights[(i0 + r) * inputs + j0..][..C].copy_from_slice(&g[r]);
    }
}
