//! Training sets, the `Trainer` trait, full-batch Adam and the CPU reference trainer (the specification the shaders follow).

use rayon::prelude::*;

use super::config::{network_seed, Activation, ModelConfig, Optimizer};
use super::mlp::{layer_spans, param_count, unit_offsets, LayerSpan, Mlp};
use errmap_core::{Error, Result};

/// Samples of one network: inputs scaled to [-1, 1]², targets standardised
/// (see [`super::Normalisation`]).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TrainingSet {
    /// Scaled `(u, v)` of each sample, in [-1, 1]² over the map domain.
    pub inputs: Vec<[f32; 2]>,
    /// Standardised error `(e − mean) / std` of each sample, one per input.
    pub targets: Vec<f32>,
}

impl TrainingSet {
    /// Number of samples (targets).
    pub fn len(&self) -> usize {
        self.targets.len()
    }
    /// Whether the set has no samples.
    pub fn is_empty(&self) -> bool {
        self.targets.is_empty()
    }
}

/// Trains and evaluates a batch of networks (one per part). Implemented by [`CpuTrainer`]
/// and by the wgpu trainer of [`crate::gpu`]; both do the same f32 arithmetic in the same order.
pub trait Trainer: Send + Sync {
    /// Backend name for notes and summaries, e.g. "cpu" or "gpu (llvmpipe, Vulkan)".
    fn name(&self) -> String;

    /// About how many networks one call should get to keep this trainer's cores or device
    /// busy. A batch maps its parts in chunks of about this many networks and holds one chunk
    /// at a time, so it also sets a run's memory: the CPU trainers want 16 (8 parts; more
    /// only costs memory), a GPU 64 (a dispatch of fewer leaves its units idle).
    fn networks_per_call(&self) -> usize {
        16
    }

    /// One network per set; network k starts from [`initial_networks`] (seeded from `(config.seed, k)`).
    fn train_batch(&self, sets: &[TrainingSet], config: &ModelConfig) -> Result<Vec<Mlp>> {
        config.validate()?;
        self.train_from(initial_networks(sets.len(), config), sets, config)
    }

    /// Trains `initial[k]` on `sets[k]` for `config.epochs` full-batch Adam steps.
    fn train_from(
        &self,
        initial: Vec<Mlp>,
        sets: &[TrainingSet],
        config: &ModelConfig,
    ) -> Result<Vec<Mlp>>;

    /// Every network on the same inputs: result `[k][i]` = `nets[k].forward(inputs[i])`.
    fn evaluate_batch(&self, nets: &[Mlp], inputs: &[[f32; 2]]) -> Result<Vec<Vec<f32>>>;

    /// Continues the Adam fit of every run on its set from its `epoch` to `to_epoch` of
    /// `config`'s schedule (learning rate and bias corrections of the full `config.epochs`).
    /// The CPU trainers carry the moments, so segments give the bits of one
    /// [`Trainer::train_from`] call. This default, for trainers that take no moments in (the
    /// GPU kernels), restarts the moments each segment and continues the learning-rate
    /// schedule; it needs every run at the same epoch.
    fn train_segment(
        &self,
        runs: &mut [AdamRun],
        sets: &[TrainingSet],
        config: &ModelConfig,
        to_epoch: u32,
    ) -> Result<()> {
        let Some(from) = runs.first().map(|r| r.epoch) else {
            return Ok(());
        };
        check_segment(runs, sets, config, to_epoch)?;
        if runs.iter().any(|r| r.epoch != from) {
            return Err(Error::Internal(
                "a restarted segment needs every network at the same epoch".into(),
            ));
        }
        let steps = to_epoch - from;
        if steps == 0 {
            return Ok(());
        }
        let first = config.learning_rate_at(from);
        let last = config.learning_rate_at(to_epoch - 1);
        let segment = ModelConfig {
            epochs: steps,
            learning_rate: first,
            lr_decay: if steps > 1 {
                (last / first).min(1.0)
            } else {
                1.0
            },
            loss_every: config.loss_every.min(steps),
            stop: super::Stop::Epochs,
            ..config.clone()
        };
        let nets = runs.iter().map(|r| r.net.clone()).collect();
        for (run, net) in runs.iter_mut().zip(self.train_from(nets, sets, &segment)?) {
            run.net = net;
            run.m.fill(0.0);
            run.v.fill(0.0);
            run.epoch = to_epoch;
        }
        Ok(())
    }
}

/// A network in the middle of a full-batch Adam fit: its parameters, Adam's first and
/// second moments, and the steps done.
#[derive(Debug, Clone, PartialEq)]
pub struct AdamRun {
    /// The network with its current parameters.
    pub net: Mlp,
    /// Adam's first moment (decaying mean of the gradient), one per parameter.
    pub m: Vec<f32>,
    /// Adam's second moment (decaying mean of the squared gradient), one per parameter.
    pub v: Vec<f32>,
    /// Steps done; the next step is epoch `epoch` (0-based) of the schedule.
    pub epoch: u32,
}

impl AdamRun {
    /// A fit about to take its first step from `net`.
    pub fn new(net: Mlp) -> AdamRun {
        let n = net.params.len();
        AdamRun {
            net,
            m: vec![0.0; n],
            v: vec![0.0; n],
            epoch: 0,
        }
    }
}

/// Checks a segment: one set per run, Adam, consistent moments, `epoch ≤ to_epoch ≤
/// config.epochs`, and the batch checks of [`check_batch`].
pub fn check_segment(
    runs: &[AdamRun],
    sets: &[TrainingSet],
    config: &ModelConfig,
    to_epoch: u32,
) -> Result<()> {
    if config.optimizer != Optimizer::Adam {
        return Err(Error::usage(
            "training in segments is for optimizer = \"adam\"",
            "use stop = \"epochs\" with L-BFGS",
        ));
    }
    if to_epoch > config.epochs
        || runs.iter().any(|r| {
            r.epoch > to_epoch || r.m.len() != r.net.params.len() || r.v.len() != r.m.len()
        })
    {
        return Err(Error::Internal(format!(
            "a training segment to epoch {to_epoch} of {} does not fit its runs",
            config.epochs
        )));
    }
    let nets: Vec<Mlp> = runs.iter().map(|r| r.net.clone()).collect();
    check_batch(&nets, sets, config)
}

/// The starting networks of a batch of `count`: Glorot-uniform, network k seeded with
/// [`network_seed`]`(config.seed, k)`.
pub fn initial_networks(count: usize, config: &ModelConfig) -> Vec<Mlp> {
    let sizes = config.layer_sizes();
    (0..count)
        .map(|k| Mlp::init(&sizes, config.activation, network_seed(config.seed, k)))
        .collect()
}

/// Gradient lanes of the reference order: sample s goes to lane s mod 8, each lane sums its
/// samples in ascending order, then the lanes are added in a binary tree (lane l += lane
/// l + 4, then + 2, then + 1). The CPU-adapter kernels (`src/gpu/lavapipe.rs`: 8 invocations
/// per network) and the fast CPU trainer sum in this order.
pub const REFERENCE_LANES: usize = 8;

/// Gradient lanes of the hardware-GPU kernels (`shaders/train.wgsl`, `src/gpu/fixed.rs`):
/// the same rule with 64 lanes (tree 32, 16, … 1). [`CpuTrainer::with_lanes`]`(GRAD_LANES)`
/// reproduces their order.
pub const GRAD_LANES: usize = 64;

/// Adam (Kingma & Ba 2015, Algorithm 1) constants. 1 − β is written out, not computed,
/// so CPU and shader use the very same f32 values.
/// The shader spells them as hex floats with these bits.
///
/// β₁ = 0.9, the decay of the first moment.
pub const ADAM_BETA1: f32 = f32::from_bits(0x3f66_6666); // 0.9
/// 1 − β₁ = 0.1, the weight of the new gradient in the first moment.
pub const ADAM_ONE_MINUS_BETA1: f32 = f32::from_bits(0x3dcc_cccd); // 0.1
/// β₂ = 0.999, the decay of the second moment.
pub const ADAM_BETA2: f32 = f32::from_bits(0x3f7f_be77); // 0.999
/// 1 − β₂ = 0.001, the weight of the new squared gradient in the second moment.
pub const ADAM_ONE_MINUS_BETA2: f32 = f32::from_bits(0x3a83_126f); // 0.001
/// ε = 1e-8, added to √v̂ in the step's denominator.
pub const ADAM_EPSILON: f32 = f32::from_bits(0x322b_cc77); // 1e-8

/// Per-step Adam scalars, computed on the host in f64: learning rate and the bias
/// corrections 1/(1 − β₁ᵗ), 1/(1 − β₂ᵗ) for step t = epoch + 1.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AdamScalars {
    /// Step size of this epoch ([`ModelConfig::learning_rate_at`]).
    pub learning_rate: f32,
    /// 1/(1 − β₁ᵗ), the first moment's bias correction.
    pub correction1: f32,
    /// 1/(1 − β₂ᵗ), the second moment's bias correction.
    pub correction2: f32,
}

impl AdamScalars {
    /// The scalars of epoch `epoch` (0-based) of `config`'s schedule.
    pub fn at(config: &ModelConfig, epoch: u32) -> AdamScalars {
        let t = epoch as f64 + 1.0;
        AdamScalars {
            learning_rate: config.learning_rate_at(epoch),
            correction1: (1.0 / (1.0 - (ADAM_BETA1 as f64).powf(t))) as f32,
            correction2: (1.0 / (1.0 - (ADAM_BETA2 as f64).powf(t))) as f32,
        }
    }
}

/// One Adam update of one parameter, in the shader's operation order.
#[inline]
pub fn adam_update(p: &mut f32, m: &mut f32, v: &mut f32, g: f32, s: &AdamScalars) {
    *m = ADAM_BETA1 * *m + ADAM_ONE_MINUS_BETA1 * g;
    *v = ADAM_BETA2 * *v + ADAM_ONE_MINUS_BETA2 * (g * g);
    let m_hat = *m * s.correction1;
    let v_hat = *v * s.correction2;
    *p -= s.learning_rate * m_hat / (v_hat.sqrt() + ADAM_EPSILON);
}

/// Checks a batch before training: matching counts, the configured architecture,
/// non-empty sets of finite numbers.
pub fn check_batch(initial: &[Mlp], sets: &[TrainingSet], config: &ModelConfig) -> Result<()> {
    config.validate()?;
    if initial.len() != sets.len() {
        return Err(Error::usage(
            format!(
                "{} initial networks for {} training sets",
                initial.len(),
                sets.len()
            ),
            "give one network per training set",
        ));
    }
    let sizes = config.layer_sizes();
    for (k, (net, set)) in initial.iter().zip(sets).enumerate() {
        if !net.is_consistent() || net.layer_sizes != sizes || net.activation != config.activation {
            return Err(Error::usage(
                format!(
                    "network {k} has layers {:?} ({}), the model config asks for {:?} ({})",
                    net.layer_sizes,
                    net.activation.name(),
                    sizes,
                    config.activation.name()
                ),
                "start every network of a batch from the configured architecture",
            ));
        }
        check_set(k, set)?;
    }
    Ok(())
}

/// A training set must be non-empty, one target per input, finite, and of u32 size.
fn check_set(k: usize, set: &TrainingSet) -> Result<()> {
    if set.is_empty() || set.inputs.len() != set.targets.len() {
        return Err(Error::usage(
            format!(
                "training set {k} has {} inputs and {} targets",
                set.inputs.len(),
                set.targets.len()
            ),
            "each training set needs at least one sample and one target per input",
        ));
    }
    if set
        .inputs
        .iter()
        .flatten()
        .chain(&set.targets)
        .any(|x| !x.is_finite())
    {
        return Err(Error::numeric(
            format!("training set {k} contains NaN or infinite values"),
            "scale inputs and targets with a Normalisation built from finite data",
        ));
    }
    if set.len() > u32::MAX as usize / 2 {
        return Err(Error::usage(
            format!("training set {k} has {} samples", set.len()),
            "use a coarser training-set spacing",
        ));
    }
    Ok(())
}

/// The CPU reference trainer: plain Rust f32, networks in parallel with rayon; the readable
/// specification every other trainer is tested against.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CpuTrainer {
    /// Gradient lanes (a power of two, at least 8): [`REFERENCE_LANES`], or [`GRAD_LANES`]
    /// to follow the hardware-GPU kernels' order.
    lanes: usize,
}

impl Default for CpuTrainer {
    fn default() -> Self {
        CpuTrainer::reference()
    }
}

impl CpuTrainer {
    /// The reference order ([`REFERENCE_LANES`] lanes).
    pub const fn reference() -> CpuTrainer {
        CpuTrainer {
            lanes: REFERENCE_LANES,
        }
    }

    /// The reference arithmetic with `lanes` gradient lanes (a power of two, 8 to 1024).
    pub fn with_lanes(lanes: usize) -> Result<CpuTrainer> {
        if !lanes.is_power_of_two() || !(BLOCK..=1024).contains(&lanes) {
            return Err(Error::usage(
                format!("{lanes} gradient lanes"),
                "use a power of two from 8 to 1024",
            ));
        }
        Ok(CpuTrainer { lanes })
    }

    /// The number of gradient lanes this trainer sums in.
    pub fn lanes(&self) -> usize {
        self.lanes
    }
}

impl Trainer for CpuTrainer {
    fn name(&self) -> String {
        "cpu-reference".to_string()
    }

    fn train_from(
        &self,
        initial: Vec<Mlp>,
        sets: &[TrainingSet],
        config: &ModelConfig,
    ) -> Result<Vec<Mlp>> {
        let lanes = self.lanes;
        train_each(initial, sets, config, |net, set, k| {
            fit_reference(net, set, config, k, lanes)
        })
    }

    fn train_segment(
        &self,
        runs: &mut [AdamRun],
        sets: &[TrainingSet],
        config: &ModelConfig,
        to_epoch: u32,
    ) -> Result<()> {
        let lanes = self.lanes;
        continue_each(runs, sets, config, to_epoch, |run, set, k| {
            let mut ws = GradientWorkspace::new(&run.net, lanes);
            let activation = run.net.activation;
            adam_steps(run, config, to_epoch, k, |params, grad| {
                ws.loss_and_gradient(params, activation, set, grad)
            })
        })
    }

    fn evaluate_batch(&self, nets: &[Mlp], inputs: &[[f32; 2]]) -> Result<Vec<Vec<f32>>> {
        check_nets(nets)?;
        Ok(nets
            .iter()
            .map(|net| {
                let eval = Evaluator::new(net);
                let mut out = vec![0.0f32; inputs.len()];
                out.par_chunks_mut(4096)
                    .zip(inputs.par_chunks(4096))
                    .for_each(|(out, chunk)| {
                        let mut scratch = eval.block_scratch();
                        for (o, x) in out.chunks_mut(BLOCK).zip(chunk.chunks(BLOCK)) {
                            let y = eval.forward_block(x, &mut scratch);
                            o.copy_from_slice(&y[..o.len()]);
                        }
                    });
                out
            })
            .collect())
    }
}

/// Rejects networks whose sizes and parameters disagree (e.g. a hand-edited model.json).
pub fn check_nets(nets: &[Mlp]) -> Result<()> {
    for (k, net) in nets.iter().enumerate() {
        if !net.is_consistent() {
            return Err(Error::usage(
                format!(
                    "network {k}: layer sizes {:?} need {} parameters, it has {}",
                    net.layer_sizes,
                    param_count(&net.layer_sizes),
                    net.params.len()
                ),
                "layer sizes must start with 2 inputs and end with 1 output; regenerate the model",
            ));
        }
    }
    Ok(())
}

/// Forward pass with reusable scratch (same arithmetic as [`Mlp::forward`]).
struct Evaluator<'a> {
    net: &'a Mlp,
    spans: Vec<LayerSpan>,
    width: usize,
}

impl<'a> Evaluator<'a> {
    fn new(net: &'a Mlp) -> Self {
        let spans = layer_spans(&net.layer_sizes);
        let width = net.layer_sizes.iter().copied().max().unwrap_or(2);
        Evaluator { net, spans, width }
    }
    fn scratch(&self) -> (Vec<f32>, Vec<f32>) {
        (vec![0.0; self.width], vec![0.0; self.width])
    }
    fn block_scratch(&self) -> (Vec<[f32; BLOCK]>, Vec<[f32; BLOCK]>) {
        (
            vec![[0.0; BLOCK]; self.width],
            vec![[0.0; BLOCK]; self.width],
        )
    }
    /// Up to BLOCK points at once (SIMD across points; each point's sums in the same order
    /// as [`Evaluator::forward`], so the bits are the same).
    fn forward_block(
        &self,
        x: &[[f32; 2]],
        (prev, next): &mut (Vec<[f32; BLOCK]>, Vec<[f32; BLOCK]>),
    ) -> [f32; BLOCK] {
        prev[0] = [0.0; BLOCK];
        prev[1] = [0.0; BLOCK];
        for (b, p) in x.iter().take(BLOCK).enumerate() {
            prev[0][b] = p[0];
            prev[1][b] = p[1];
        }
        let last = self.spans.len() - 1;
        let p = &self.net.params;
        for (l, span) in self.spans.iter().enumerate() {
            for (i, out) in next[..span.outputs].iter_mut().enumerate() {
                let row = &p[span.weight_offset + i * span.inputs..][..span.inputs];
                let mut z = [p[span.bias_offset + i]; BLOCK];
                for (w, a) in row.iter().zip(prev.iter()) {
                    for b in 0..BLOCK {
                        z[b] += w * a[b];
                    }
                }
                if l != last {
                    for zb in &mut z {
                        *zb = self.net.activation.apply(*zb);
                    }
                }
                *out = z;
            }
            std::mem::swap(prev, next);
        }
        prev[0]
    }
    fn forward(&self, x: [f32; 2], (prev, next): &mut (Vec<f32>, Vec<f32>)) -> f32 {
        prev[0] = x[0];
        prev[1] = x[1];
        let last = self.spans.len() - 1;
        let p = &self.net.params;
        for (l, span) in self.spans.iter().enumerate() {
            for i in 0..span.outputs {
                let row = &p[span.weight_offset + i * span.inputs..][..span.inputs];
                let mut z = p[span.bias_offset + i];
                for (w, a) in row.iter().zip(prev.iter()) {
                    z += w * a;
                }
                next[i] = if l == last {
                    z
                } else {
                    self.net.activation.apply(z)
                };
            }
            std::mem::swap(prev, next);
        }
        prev[0]
    }
}

/// Samples processed together in the CPU forward/backward pass (SIMD across samples; each
/// sample keeps its own operation order, so blocking changes no bit).
const BLOCK: usize = 8;

/// Per-thread scratch of the blocked pass: unit-major, BLOCK samples innermost.
struct BlockScratch {
    acts: Vec<[f32; BLOCK]>,
    deltas: Vec<[f32; BLOCK]>,
    back: Vec<[f32; BLOCK]>,
    column: Vec<f32>,
}

/// Scratch of one network's gradient computation, reused across epochs.
struct GradientWorkspace {
    spans: Vec<LayerSpan>,
    unit_offset: Vec<usize>,
    /// One per lane group: the samples of block b go to lanes (8b mod L)…(8b mod L) + 7, so
    /// the L/8 groups of 8 lanes are disjoint and run in parallel without changing any sum.
    scratch: Vec<BlockScratch>,
    /// L partial gradients; after [`GradientWorkspace::gradient`] lane 0 holds the sum.
    lanes: Vec<f32>,
    lane_count: usize,
}

impl GradientWorkspace {
    fn new(net: &Mlp, lane_count: usize) -> Self {
        let spans = layer_spans(&net.layer_sizes);
        let unit_offset = unit_offsets(&spans);
        let units: usize = spans.iter().map(|s| s.outputs).sum();
        let width = net.layer_sizes.iter().copied().max().unwrap_or(2);
        let scratch = (0..lane_count / BLOCK)
            .map(|_| BlockScratch {
                acts: vec![[0.0; BLOCK]; units],
                deltas: vec![[0.0; BLOCK]; units],
                back: vec![[0.0; BLOCK]; width],
                column: vec![0.0; width],
            })
            .collect();
        GradientWorkspace {
            spans,
            unit_offset,
            scratch,
            lanes: vec![0.0; lane_count * net.params.len()],
            lane_count,
        }
    }

    /// [`GradientWorkspace::gradient`], the sum copied into `grad`; returns the loss.
    fn loss_and_gradient(
        &mut self,
        params: &[f32],
        activation: Activation,
        set: &TrainingSet,
        grad: &mut [f32],
    ) -> f64 {
        let loss = self.gradient(params, activation, set);
        grad.copy_from_slice(&self.lanes[..params.len()]);
        loss
    }

    /// Gradient of the mean squared error over `set` w.r.t. `params` into `lanes[..P]`;
    /// returns the mean squared error (f64, for progress only).
    ///
    /// Per sample: forward z = b[i] + Σ_j W[i][j]·a[j] (j ascending), δ_out = (y − t)·(2/n),
    /// δ_prev[j] = (Σ_i W[i][j]·δ[i], i ascending)·f'(a[j]); sample s adds δ[i]·a[j] to lane
    /// s mod L, lanes sum their samples in ascending order, then a binary tree adds lanes.
    fn gradient(&mut self, params: &[f32], activation: Activation, set: &TrainingSet) -> f64 {
        let n_params = params.len();
        let n = set.len();
        let spans = &self.spans;
        let unit_offset = &self.unit_offset;
        let grad_scale = 2.0f32 / n as f32;
        let groups = self.lane_count / BLOCK;
        self.lanes.fill(0.0);
        let losses: Vec<f64> = self
            .lanes
            .par_chunks_mut(BLOCK * n_params)
            .zip(self.scratch.par_iter_mut())
            .enumerate()
            .map(|(group, (lanes, scratch))| {
                let mut loss = 0.0f64;
                // Blocks group, group + 8, … : samples 8·block … 8·block + 7.
                let mut block = group;
                while block * BLOCK < n {
                    let s0 = block * BLOCK;
                    let count = BLOCK.min(n - s0);
                    loss += block_pass(
                        params,
                        activation,
                        spans,
                        unit_offset,
                        set,
                        s0,
                        count,
                        grad_scale,
                        scratch,
                        lanes,
                    );
                    block += groups;
                }
                loss
            })
            .collect();
        // Tree over lanes: lane l += lane l + stride, stride L/2, L/4, … 1.
        let mut stride = self.lane_count / 2;
        while stride > 0 {
            let (low, high) = self.lanes.split_at_mut(stride * n_params);
            for (a, b) in low.iter_mut().zip(&high[..stride * n_params]) {
                *a += b;
            }
            stride /= 2;
        }
        losses.iter().sum::<f64>() / n.max(1) as f64
    }
}

/// Forward and backward pass of samples s0 … s0 + count − 1 (count ≤ BLOCK), adding their
/// gradient contributions to `lanes` (the 8 lanes of this block, each `P` long).
#[allow(clippy::too_many_arguments)]
fn block_pass(
    params: &[f32],
    activation: Activation,
    spans: &[LayerSpan],
    unit_offset: &[usize],
    set: &TrainingSet,
    s0: usize,
    count: usize,
    grad_scale: f32,
    scratch: &mut BlockScratch,
    lanes: &mut [f32],
) -> f64 {
    let last = spans.len() - 1;
    let input = block_inputs(set, s0, count);
    let BlockScratch {
        acts,
        deltas,
        back,
        column,
    } = scratch;
    block_forward(params, activation, spans, unit_offset, &input, acts);
    let out = unit_offset[last];
    let loss = output_deltas(&acts[out], set, s0, count, grad_scale, &mut deltas[out]);
    // Backward.
    for l in (0..spans.len()).rev() {
        let span = spans[l];
        let (before, current) = deltas.split_at_mut(unit_offset[l]);
        let delta = &current[..span.outputs];
        let prev: &[[f32; BLOCK]] = if l == 0 {
            &input
        } else {
            &acts[unit_offset[l - 1]..][..span.inputs]
        };
        add_lane_terms(&span, delta, prev, s0, count, column, lanes);
        if l > 0 {
            let prev_delta = &mut before[unit_offset[l - 1]..][..span.inputs];
            back_propagate(params, activation, &span, delta, prev, back, prev_delta);
        }
    }
    loss
}

/// The block's inputs by coordinate: `[x or y][sample of the block]`, zero past `count`.
fn block_inputs(set: &TrainingSet, s0: usize, count: usize) -> [[f32; BLOCK]; 2] {
    let mut input = [[0.0f32; BLOCK]; 2];
    for (b, x) in set.inputs[s0..s0 + count].iter().enumerate() {
        input[0][b] = x[0];
        input[1][b] = x[1];
    }
    input
}

/// Forward pass of the block: z = b[i] + Σ_j W[i][j]·a[j] (j ascending), activated except
/// in the last layer, into `acts` (units in layer order).
fn block_forward(
    params: &[f32],
    activation: Activation,
    spans: &[LayerSpan],
    unit_offset: &[usize],
    input: &[[f32; BLOCK]; 2],
    acts: &mut [[f32; BLOCK]],
) {
    let last = spans.len() - 1;
    for (l, span) in spans.iter().enumerate() {
        let (done, rest) = acts.split_at_mut(unit_offset[l]);
        let prev: &[[f32; BLOCK]] = if l == 0 {
            input
        } else {
            &done[unit_offset[l - 1]..][..span.inputs]
        };
        for (i, out) in rest[..span.outputs].iter_mut().enumerate() {
            let row = &params[span.weight_offset + i * span.inputs..][..span.inputs];
            let mut z = [params[span.bias_offset + i]; BLOCK];
            for (w, a) in row.iter().zip(prev) {
                for b in 0..BLOCK {
                    z[b] += w * a[b];
                }
            }
            if l != last {
                for zb in &mut z {
                    *zb = activation.apply(*zb);
                }
            }
            *out = z;
        }
    }
}

/// The output deltas δ_out = (y − t)·grad_scale (zero past `count`); returns the block's sum
/// of squared errors.
fn output_deltas(
    output: &[f32; BLOCK],
    set: &TrainingSet,
    s0: usize,
    count: usize,
    grad_scale: f32,
    delta: &mut [f32; BLOCK],
) -> f64 {
    let mut loss = 0.0f64;
    for b in 0..BLOCK {
        let err = if b < count {
            output[b] - set.targets[s0 + b]
        } else {
            0.0
        };
        loss += (err as f64) * (err as f64);
        delta[b] = err * grad_scale;
    }
    loss
}

/// Adds sample s0 + b's terms δ[i]·a[j] (and δ[i]) of one layer to lane (s0 + b) mod BLOCK.
fn add_lane_terms(
    span: &LayerSpan,
    delta: &[[f32; BLOCK]],
    prev: &[[f32; BLOCK]],
    s0: usize,
    count: usize,
    column: &mut [f32],
    lanes: &mut [f32],
) {
    let n_params = lanes.len() / BLOCK;
    for b in 0..count {
        let lane = &mut lanes[((s0 + b) % BLOCK) * n_params..][..n_params];
        let column = &mut column[..span.inputs];
        for (c, a) in column.iter_mut().zip(prev) {
            *c = a[b];
        }
        for (i, d) in delta.iter().enumerate() {
            let d = d[b];
            lane[span.bias_offset + i] += d;
            let row = &mut lane[span.weight_offset + i * span.inputs..][..span.inputs];
            for (g, a) in row.iter_mut().zip(column.iter()) {
                *g += d * a;
            }
        }
    }
}

/// δ_prev[j] = (Σ_i W[i][j]·δ[i], i ascending)·f'(a_prev[j]) of one layer into `prev_delta`.
fn back_propagate(
    params: &[f32],
    activation: Activation,
    span: &LayerSpan,
    delta: &[[f32; BLOCK]],
    prev: &[[f32; BLOCK]],
    back: &mut [[f32; BLOCK]],
    prev_delta: &mut [[f32; BLOCK]],
) {
    let back = &mut back[..span.inputs];
    back.iter_mut().for_each(|v| *v = [0.0; BLOCK]);
    for (i, d) in delta.iter().enumerate() {
        let row = &params[span.weight_offset + i * span.inputs..][..span.inputs];
        for (bj, w) in back.iter_mut().zip(row) {
            for b in 0..BLOCK {
                bj[b] += w * d[b];
            }
        }
    }
    for ((pd, bj), a) in prev_delta.iter_mut().zip(back.iter()).zip(prev) {
        for b in 0..BLOCK {
            pd[b] = bj[b] * activation.derivative_from_output(a[b]);
        }
    }
}

/// Gradient of the mean squared error of `net` on `set` w.r.t. its parameters, summed
/// exactly as one training step sums it; also returns the mean squared error.
pub fn loss_gradient(net: &Mlp, set: &TrainingSet) -> Result<(f64, Vec<f32>)> {
    check_nets(std::slice::from_ref(net))?;
    check_set(0, set)?;
    let mut ws = GradientWorkspace::new(net, REFERENCE_LANES);
    let loss = ws.gradient(&net.params, net.activation, set);
    Ok((loss, ws.lanes[..net.params.len()].to_vec()))
}

/// Full-batch Adam on one network: `config.epochs` steps of
/// forward → loss gradient 2(y − t)/n → backprop → lane sums → tree → Adam, in the
/// reference order ([`REFERENCE_LANES`]).
/// Fails with a numeric error if the loss stops being finite.
pub fn train_network(
    net: &mut Mlp,
    set: &TrainingSet,
    config: &ModelConfig,
    k: usize,
) -> Result<()> {
    train_network_with_lanes(net, set, config, k, REFERENCE_LANES)
}

/// [`train_network`] with `lanes` gradient lanes (and `config.optimizer`).
fn train_network_with_lanes(
    net: &mut Mlp,
    set: &TrainingSet,
    config: &ModelConfig,
    k: usize,
    lanes: usize,
) -> Result<()> {
    check_batch(std::slice::from_ref(net), std::slice::from_ref(set), config)?;
    fit_reference(net, set, config, k, lanes)
}

/// One checked network fitted with the reference gradient.
fn fit_reference(
    net: &mut Mlp,
    set: &TrainingSet,
    config: &ModelConfig,
    k: usize,
    lanes: usize,
) -> Result<()> {
    let mut ws = GradientWorkspace::new(net, lanes);
    let activation = net.activation;
    fit_one(net, config, k, |params, grad| {
        ws.loss_and_gradient(params, activation, set, grad)
    })
}

/// Every network of a checked batch fitted by `fit(net, set, k)`, networks in parallel.
pub(crate) fn train_each(
    initial: Vec<Mlp>,
    sets: &[TrainingSet],
    config: &ModelConfig,
    fit: impl Fn(&mut Mlp, &TrainingSet, usize) -> Result<()> + Sync + Send,
) -> Result<Vec<Mlp>> {
    check_batch(&initial, sets, config)?;
    initial
        .into_par_iter()
        .zip(sets.par_iter())
        .enumerate()
        .map(|(k, (mut net, set))| {
            fit(&mut net, set, k)?;
            Ok(net)
        })
        .collect()
}

/// Fits network `k` with `config.optimizer`, given its loss gradient: `loss_gradient(params,
/// grad)` writes the gradient of the mean squared error at `params` into `grad` and returns
/// the error. Adam: `config.epochs` steps; L-BFGS: at most `config.epochs` evaluations. A loss
/// that stops being finite is a divergence error.
pub(crate) fn fit_one(
    net: &mut Mlp,
    config: &ModelConfig,
    k: usize,
    mut loss_gradient: impl FnMut(&[f32], &mut [f32]) -> f64,
) -> Result<()> {
    if config.optimizer == Optimizer::Lbfgs {
        let n_params = net.params.len();
        return super::lbfgs::fit_network_checked(net, config, k, |params| {
            let mut grad = vec![0.0f32; n_params];
            let loss = loss_gradient(params, &mut grad);
            (loss, grad)
        });
    }
    let mut run = AdamRun::new(net.clone());
    let result = adam_steps(&mut run, config, config.epochs, k, loss_gradient);
    *net = run.net;
    result
}

/// Adam steps of `run` from its epoch to `to_epoch` of `config`'s schedule. The loss is
/// checked every `loss_every` steps and at the segment's and the schedule's last step.
pub(crate) fn adam_steps(
    run: &mut AdamRun,
    config: &ModelConfig,
    to_epoch: u32,
    k: usize,
    mut loss_gradient: impl FnMut(&[f32], &mut [f32]) -> f64,
) -> Result<()> {
    let mut grad = vec![0.0f32; run.net.params.len()];
    let AdamRun { net, m, v, epoch } = run;
    while *epoch < to_epoch {
        let e = *epoch;
        let loss = loss_gradient(&net.params, &mut grad);
        let read = (e + 1) % config.loss_every == 0 || e + 1 == config.epochs || e + 1 == to_epoch;
        if read && !loss.is_finite() {
            return Err(diverged(k, e));
        }
        let scalars = AdamScalars::at(config, e);
        for (((p, mi), vi), &g) in net
            .params
            .iter_mut()
            .zip(m.iter_mut())
            .zip(v.iter_mut())
            .zip(&grad)
        {
            adam_update(p, mi, vi, g, &scalars);
        }
        *epoch += 1;
    }
    if net.params.iter().any(|p| !p.is_finite()) {
        return Err(diverged(k, *epoch));
    }
    Ok(())
}

/// Every run of a segment continued to `to_epoch` by `fit(run, set, k)`, in parallel.
pub(crate) fn continue_each(
    runs: &mut [AdamRun],
    sets: &[TrainingSet],
    config: &ModelConfig,
    to_epoch: u32,
    fit: impl Fn(&mut AdamRun, &TrainingSet, usize) -> Result<()> + Sync + Send,
) -> Result<()> {
    check_segment(runs, sets, config, to_epoch)?;
    runs.par_iter_mut()
        .zip(sets.par_iter())
        .enumerate()
        .try_for_each(|(k, (run, set))| fit(run, set, k))
}

/// Mean squared error of a network on a set (f64 sum), for reports and tests.
pub fn mse(net: &Mlp, set: &TrainingSet) -> f64 {
    let eval = Evaluator::new(net);
    let mut scratch = eval.scratch();
    let sum: f64 = set
        .inputs
        .iter()
        .zip(&set.targets)
        .map(|(&x, &t)| {
            let e = (eval.forward(x, &mut scratch) - t) as f64;
            e * e
        })
        .sum();
    sum / set.len().max(1) as f64
}

pub(crate) fn diverged(k: usize, epoch: u32) -> Error {
    Error::numeric(
        format!("training of network {k} diverged (loss not finite) by epoch {epoch}"),
        "lower model.learning_rate",
    )
}
