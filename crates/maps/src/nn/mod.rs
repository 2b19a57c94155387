//! Small neural networks for error maps: the MLP parameter layout (shared with the shaders), normalisation, the Trainer trait and the CPU reference trainer.
//!
//! Architecture 2 → hidden… → 1; parameters per layer W row-major `[out][in]` then b (see
//! [`Mlp`]). Training is full-batch Adam on the mean squared error; the CPU trainer is the
//! specification `shaders/train.wgsl` is tested against (`tests/gpu_parity.rs`).

mod config;
mod fast;
pub mod lbfgs;
mod mlp;
mod norm;
pub mod stop;
mod train;
pub mod workload;

pub use config::{
    network_seed, tanh_f32, Activation, Backend, ModelConfig, Optimizer, Stop, WarmStart,
    MAX_EPOCHS, MAX_HIDDEN_LAYERS, MAX_WIDTH,
};
pub use fast::{FastCpuTrainer, FastGradient, CHUNK_BLOCKS};
pub use mlp::{layer_spans, param_count, unit_offsets, LayerSpan, Mlp};
pub use norm::Normalisation;
pub(crate) use train::diverged;
pub use train::{
    adam_update, check_batch, check_nets, initial_networks, loss_gradient, mse, train_network,
    AdamRun, AdamScalars, CpuTrainer, Trainer, TrainingSet, ADAM_BETA1, ADAM_BETA2, ADAM_EPSILON,
    ADAM_ONE_MINUS_BETA1, ADAM_ONE_MINUS_BETA2, GRAD_LANES, REFERENCE_LANES,
};
