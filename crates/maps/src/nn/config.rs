//! Model configuration (the `[model]` table of a job): architecture, optimiser settings, seed, hold-out share, backend.

use serde::{Deserialize, Serialize};

use errmap_core::{Error, Result};

/// Largest hidden layer width accepted (the shaders keep one layer in private memory).
pub const MAX_WIDTH: usize = 256;
/// Largest number of hidden layers accepted.
pub const MAX_HIDDEN_LAYERS: usize = 8;
/// Largest number of epochs accepted (a typo guard: 10⁶ full-batch steps is hours).
pub const MAX_EPOCHS: u32 = 1_000_000;

/// Hidden-layer activation; the output layer is always linear.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Activation {
    /// tanh(z); derivative 1 − a².
    Tanh,
    /// max(z, 0); derivative 1 for a > 0, else 0.
    Relu,
}

impl Activation {
    /// Applies the activation.
    #[inline]
    pub fn apply(self, z: f32) -> f32 {
        match self {
            Activation::Tanh => tanh_f32(z),
            Activation::Relu => z.max(0.0),
        }
    }
    /// Derivative expressed through the activation's output `a` (what backprop keeps).
    #[inline]
    pub fn derivative_from_output(self, a: f32) -> f32 {
        match self {
            Activation::Tanh => 1.0 - a * a,
            Activation::Relu => {
                if a > 0.0 {
                    1.0
                } else {
                    0.0
                }
            }
        }
    }
    /// The code the shaders use for this activation (`Dims.activation` in `shaders/*.wgsl`).
    pub fn shader_code(self) -> u32 {
        match self {
            Activation::Tanh => 0,
            Activation::Relu => 1,
        }
    }
    /// The name a job file's `activation` key uses: `tanh` or `relu`.
    pub fn name(self) -> &'static str {
        match self {
            Activation::Tanh => "tanh",
            Activation::Relu => "relu",
        }
    }
}

/// tanh as a rational function (Eigen's `generic_fast_tanh_float`: odd degree-13 numerator over
/// even degree-6 denominator, input clamped to ±7.9053, identity below |x| < 4e-4), accurate
/// to a few ulp. Written with plain multiplies, adds and one division, in the same order as
/// `tanh_f32` in shaders/common.wgsl, with the same f32 coefficients (given by their bits, as
/// hex floats there), so every IEEE device that does not contract a·b + c into an FMA gets
/// the very same bits as the CPU: libm's `tanhf` and the GPU's `tanh` differ in the last ulp,
/// and full-batch Adam amplifies such differences.
#[inline]
pub fn tanh_f32(x: f32) -> f32 {
    const A1: f32 = f32::from_bits(0x3ba0_59dc);
    const A3: f32 = f32::from_bits(0x3a27_0ded);
    const A5: f32 = f32::from_bits(0x3779_434a);
    const A7: f32 = f32::from_bits(0x335c_0041);
    const A9: f32 = f32::from_bits(0xaebd_37ff);
    const A11: f32 = f32::from_bits(0x2a61_337e);
    const A13: f32 = f32::from_bits(0xa59f_25c0);
    const B0: f32 = f32::from_bits(0x3ba0_59dd);
    const B2: f32 = f32::from_bits(0x3b14_aa05);
    const B4: f32 = f32::from_bits(0x38f8_95d6);
    const B6: f32 = f32::from_bits(0x35a0_d3d8);
    const CLAMP: f32 = f32::from_bits(0x40fc_f84f);
    const TINY: f32 = f32::from_bits(0x39d1_b717);
    let x = x.clamp(-CLAMP, CLAMP);
    let x2 = x * x;
    let mut p = x2 * A13 + A11;
    p = x2 * p + A9;
    p = x2 * p + A7;
    p = x2 * p + A5;
    p = x2 * p + A3;
    p = x2 * p + A1;
    p *= x;
    let mut q = x2 * B6 + B4;
    q = x2 * q + B2;
    q = x2 * q + B0;
    if x.abs() < TINY {
        x
    } else {
        p / q
    }
}

/// Where networks are trained.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Backend {
    /// The fastest backend this machine has, by a short measurement cached per machine
    /// (`errmap gpu-info` shows the choice and why).
    #[default]
    Auto,
    /// Any wgpu adapter (a hardware GPU first, else software Vulkan such as lavapipe);
    /// fails instead of falling back.
    Gpu,
    /// The fast CPU trainer (SIMD, all cores).
    Cpu,
    /// The CPU reference trainer: the readable specification, slow.
    CpuReference,
}

impl Backend {
    /// The name a job file's `backend` key and `--backend` use: `auto`, `gpu`, `cpu` or
    /// `cpu-reference`.
    pub fn name(self) -> &'static str {
        match self {
            Backend::Auto => "auto",
            Backend::Gpu => "gpu",
            Backend::Cpu => "cpu",
            Backend::CpuReference => "cpu-reference",
        }
    }
}

/// The optimiser of every network's fit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Optimizer {
    /// Full-batch Adam, `epochs` steps (every backend).
    #[default]
    Adam,
    /// Full-batch L-BFGS, at most `epochs` loss evaluations (the CPU trainers).
    Lbfgs,
}

/// Where each part's networks start.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum WarmStart {
    /// Seeded random weights, `epochs` steps.
    #[default]
    None,
    /// The family network (trained first, `epochs` steps), rescaled to the part's targets,
    /// then `warm_epochs` steps.
    Family,
}

/// When a fit ends.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Stop {
    /// After `epochs` steps (`warm_epochs` for a warm-started part).
    #[default]
    Epochs,
    /// When the hold-out RMS has not improved for `patience_checks` checks, one check every
    /// `check_every_epochs` steps, or after `epochs` (`warm_epochs`) steps; the fit keeps
    /// the parameters of its best check ([`crate::nn::stop`]).
    Holdout,
}

/// How networks are fitted. Every key has a default, so `[model]` may be empty.
///
/// Training is full-batch Adam (β₁ 0.9, β₂ 0.999, ε 1e-8) on the mean squared error of the
/// standardised targets, with the learning rate decaying exponentially from `learning_rate`
/// to `learning_rate × lr_decay` over the epochs. One epoch = one optimiser step.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ModelConfig {
    /// Hidden layer widths, input side first (input 2 and output 1 are implied).
    pub hidden: Vec<usize>,
    /// Activation of every hidden layer (the output layer is linear).
    pub activation: Activation,
    /// Full-batch optimiser steps.
    pub epochs: u32,
    /// Adam step size at the first epoch.
    pub learning_rate: f32,
    /// Final learning rate as a share of `learning_rate` (1 = constant).
    pub lr_decay: f32,
    /// Seed of the initial weights; network k of a batch uses [`network_seed`]`(seed, k)`.
    pub seed: u64,
    /// Share of probe points held out of the first fit to measure the map's accuracy.
    pub holdout_fraction: f64,
    /// Where the networks are trained.
    pub backend: Backend,
    /// The loss is read back (for progress and divergence checks) every this many epochs.
    pub loss_every: u32,
    /// The optimiser of every fit; with L-BFGS, `epochs` bounds the loss evaluations.
    pub optimizer: Optimizer,
    /// Whether each part's networks start from seeded random weights or from the family
    /// network.
    pub warm_start: WarmStart,
    /// Steps of a part's fit when it starts from the family network.
    pub warm_epochs: u32,
    /// When a fit ends; the keys below only matter for `stop = "holdout"` and are left out
    /// of the serialised settings at their defaults (so a job's hash is as before).
    #[serde(skip_serializing_if = "is_default")]
    pub stop: Stop,
    /// Steps between two hold-out checks.
    #[serde(skip_serializing_if = "is_default_check_every")]
    pub check_every_epochs: u32,
    /// Checks without a lower hold-out RMS after which a fit stops.
    #[serde(skip_serializing_if = "is_default_patience")]
    pub patience_checks: u32,
}

fn is_default<T: Default + PartialEq>(value: &T) -> bool {
    *value == T::default()
}
/// Default of `check_every_epochs`.
pub const CHECK_EVERY_EPOCHS: u32 = 10;
/// Default of `patience_checks`.
pub const PATIENCE_CHECKS: u32 = 5;
fn is_default_check_every(value: &u32) -> bool {
    *value == CHECK_EVERY_EPOCHS
}
fn is_default_patience(value: &u32) -> bool {
    *value == PATIENCE_CHECKS
}

impl Default for ModelConfig {
    fn default() -> Self {
        ModelConfig {
            hidden: vec![32, 32],
            activation: Activation::Tanh,
            epochs: 1500,
            learning_rate: 0.01,
            lr_decay: 0.05,
            seed: 1,
            holdout_fraction: 0.1,
            backend: Backend::Auto,
            loss_every: 250,
            optimizer: Optimizer::Adam,
            warm_start: WarmStart::None,
            warm_epochs: 150,
            stop: Stop::Epochs,
            check_every_epochs: CHECK_EVERY_EPOCHS,
            patience_checks: PATIENCE_CHECKS,
        }
    }
}

impl ModelConfig {
    /// Layer sizes including the 2 inputs and the 1 output.
    pub fn layer_sizes(&self) -> Vec<usize> {
        let mut sizes = Vec::with_capacity(self.hidden.len() + 2);
        sizes.push(2);
        sizes.extend_from_slice(&self.hidden);
        sizes.push(1);
        sizes
    }

    /// Rejects settings that cannot train, each with the key to change.
    pub fn validate(&self) -> Result<()> {
        if self.hidden.is_empty() {
            return Err(Error::usage(
                "model.hidden is empty",
                "give at least one hidden layer, e.g. hidden = [32, 32]",
            ));
        }
        if self.hidden.len() > MAX_HIDDEN_LAYERS {
            return Err(Error::usage(
                format!(
                    "model.hidden has {} layers, at most {MAX_HIDDEN_LAYERS} are supported",
                    self.hidden.len()
                ),
                "a smooth error map needs 2 or 3 hidden layers",
            ));
        }
        if let Some(&w) = self.hidden.iter().find(|&&w| w == 0 || w > MAX_WIDTH) {
            return Err(Error::usage(
                format!("model.hidden has a layer of width {w}; widths must be 1..={MAX_WIDTH}"),
                "use widths like 16, 32 or 64",
            ));
        }
        if self.epochs == 0 || self.epochs > MAX_EPOCHS {
            return Err(Error::usage(
                format!(
                    "model.epochs = {} is out of range 1..={MAX_EPOCHS}",
                    self.epochs
                ),
                "the default 1500 fits a smooth map",
            ));
        }
        if !(self.learning_rate.is_finite()
            && self.learning_rate > 0.0
            && self.learning_rate <= 1.0)
        {
            return Err(Error::usage(
                format!(
                    "model.learning_rate = {} must be in (0, 1]",
                    self.learning_rate
                ),
                "Adam works well with 0.001 to 0.03",
            ));
        }
        if !(self.lr_decay.is_finite() && self.lr_decay > 0.0 && self.lr_decay <= 1.0) {
            return Err(Error::usage(
                format!("model.lr_decay = {} must be in (0, 1]", self.lr_decay),
                "1 keeps the learning rate constant; 0.05 ends at 5 % of it",
            ));
        }
        if !(self.holdout_fraction.is_finite() && (0.0..=0.5).contains(&self.holdout_fraction)) {
            return Err(Error::usage(
                format!(
                    "model.holdout_fraction = {} must be in [0, 0.5]",
                    self.holdout_fraction
                ),
                "0.1 holds out 10 % of the probe points",
            ));
        }
        if self.warm_epochs == 0 || self.warm_epochs > MAX_EPOCHS {
            return Err(Error::usage(
                format!(
                    "model.warm_epochs = {} is out of range 1..={MAX_EPOCHS}",
                    self.warm_epochs
                ),
                "150 steps from the family network match a fit from scratch on the sample plates",
            ));
        }
        if self.loss_every == 0 {
            return Err(Error::usage(
                "model.loss_every must be at least 1",
                "the default reads the loss every 250 epochs",
            ));
        }
        self.validate_stop()
    }

    /// The hold-out stopping keys: checked whatever `stop` is, so a typo shows at once.
    fn validate_stop(&self) -> Result<()> {
        if self.check_every_epochs == 0 || self.check_every_epochs > MAX_EPOCHS {
            return Err(Error::usage(
                format!(
                    "model.check_every_epochs = {} is out of range 1..={MAX_EPOCHS}",
                    self.check_every_epochs
                ),
                "check the hold-out RMS every 10 to 50 steps",
            ));
        }
        if self.patience_checks == 0 || self.patience_checks > MAX_EPOCHS {
            return Err(Error::usage(
                format!(
                    "model.patience_checks = {} is out of range 1..={MAX_EPOCHS}",
                    self.patience_checks
                ),
                "5 checks without improvement are the default",
            ));
        }
        if self.stop != Stop::Holdout {
            return Ok(());
        }
        if self.optimizer != Optimizer::Adam {
            return Err(Error::usage(
                "model.stop = \"holdout\" needs optimizer = \"adam\"",
                "L-BFGS stops on its own evaluation budget (epochs); use stop = \"epochs\" with it",
            ));
        }
        if self.holdout_fraction == 0.0 {
            return Err(Error::usage(
                "model.stop = \"holdout\" needs held-out points, and holdout_fraction is 0",
                "set holdout_fraction = 0.1, or stop = \"epochs\"",
            ));
        }
        Ok(())
    }

    /// Learning rate of epoch `t` (0-based): exponential decay from `learning_rate`
    /// to `learning_rate × lr_decay` at the last epoch. Computed in f64, used as f32
    /// by the CPU trainer and the shaders alike.
    pub fn learning_rate_at(&self, t: u32) -> f32 {
        let last = self.epochs.saturating_sub(1).max(1) as f64;
        let frac = t as f64 / last;
        (self.learning_rate as f64 * (self.lr_decay as f64).powf(frac)) as f32
    }
}

/// Seed of network `k` of a batch: a SplitMix64 mix of the job seed and `k`,
/// so neighbouring networks get unrelated initial weights.
pub fn network_seed(seed: u64, k: usize) -> u64 {
    let mut z = seed
        ^ (k as u64)
            .wrapping_add(1)
            .wrapping_mul(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}
