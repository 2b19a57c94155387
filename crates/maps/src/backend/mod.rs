//! Which trainer runs a batch: the backend the user names, or for `auto` the fastest this machine has, measured by a short probe and cached per machine.
//!
//! `auto` considers the fast CPU trainer and the best wgpu adapter (hardware or software,
//! such as lavapipe). The first time a machine, driver and architecture are seen, each
//! candidate trains the probe workload ([`probe`]); the throughputs are cached in
//! [`probe::cache_file`], so later runs choose at once. A device that fails mid-batch
//! (lost, out of memory) hands the batch to the CPU with one note.

pub mod bench;
pub mod info;
pub mod probe;

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use crate::gpu::GpuTrainer;
use crate::nn::{Backend, CpuTrainer, FastCpuTrainer, Mlp, ModelConfig, Trainer, TrainingSet};
use crate::Setting;
use errmap_core::setting::words;
use errmap_core::{Error, Result};

pub use errmap_core::progress::{silent, Notes};

/// The trainer chosen for a backend and why.
pub struct Selection {
    /// The opened trainer (for `auto` on a GPU, one that hands the batch to the CPU if the
    /// device fails mid-batch).
    pub trainer: Box<dyn Trainer>,
    /// The backend that trains: `gpu`, `cpu` or `cpu-reference` (never `auto`).
    pub backend: Backend,
    /// One line: what was chosen and on what grounds.
    pub reason: String,
}

/// Opens the trainer for `backend`; `config` gives the architecture `auto` measures.
/// `gpu` fails with a device error when no adapter opens; `auto` never fails for want of a GPU.
pub fn select_trainer(backend: Backend, config: &ModelConfig, notes: Notes) -> Result<Selection> {
    select_trainer_cached_in(backend, config, notes, probe::cache_file())
}

/// [`select_trainer`] with `auto`'s probe cache in `cache_file` (`None`: measure every time).
pub fn select_trainer_cached_in(
    backend: Backend,
    config: &ModelConfig,
    notes: Notes,
    cache_file: Option<std::path::PathBuf>,
) -> Result<Selection> {
    match backend {
        Backend::Cpu => Ok(Selection {
            trainer: Box::new(FastCpuTrainer),
            backend,
            reason: format!("{} cpu: {}", words(Setting::Backend), FastCpuTrainer.name()),
        }),
        Backend::CpuReference => Ok(Selection {
            trainer: Box::new(CpuTrainer::reference()),
            backend,
            reason: format!(
                "{} cpu-reference: the reference trainer",
                words(Setting::Backend)
            ),
        }),
        Backend::Gpu => {
            let gpu = GpuTrainer::new()?.with_notes(notes);
            let reason = format!("{} gpu: {}", words(Setting::Backend), gpu.name());
            Ok(Selection {
                trainer: Box::new(gpu),
                backend,
                reason,
            })
        }
        Backend::Auto => select_auto(config, notes, cache_file),
    }
}

fn select_auto(
    config: &ModelConfig,
    notes: Notes,
    cache_file: Option<std::path::PathBuf>,
) -> Result<Selection> {
    if config.optimizer != crate::nn::Optimizer::Adam {
        return Ok(Selection {
            trainer: Box::new(FastCpuTrainer),
            backend: Backend::Cpu,
            reason: format!("auto: L-BFGS runs on the CPU; {}", FastCpuTrainer.name()),
        });
    }
    let gpu = match GpuTrainer::new() {
        Ok(gpu) => gpu.with_notes(Arc::clone(&notes)),
        Err(e) => {
            return Ok(Selection {
                trainer: Box::new(FastCpuTrainer),
                backend: Backend::Cpu,
                reason: format!("auto: no usable GPU ({e}); {}", FastCpuTrainer.name()),
            })
        }
    };
    // A software adapter's first kernel build takes tens of seconds: a run does not wait for
    // it. Until `errmap gpu-info` (or `bench training`) has measured it, auto trains on the CPU.
    if gpu.context().adapter.software
        && probe::cached_verdict(&gpu, config, cache_file.as_deref()).is_none()
    {
        return Ok(Selection {
            trainer: Box::new(FastCpuTrainer),
            backend: Backend::Cpu,
            reason: format!(
                "auto: {} (the software adapter {} is not measured yet: `errmap gpu-info` measures it once)",
                FastCpuTrainer.name(),
                gpu.context().adapter.name
            ),
        });
    }
    let verdict = probe::compare_cached_in(&gpu, config, cache_file)?;
    if verdict.gpu_is_faster() {
        let reason = format!("auto: {}", verdict.describe(true));
        Ok(Selection {
            trainer: Box::new(AutoTrainer {
                gpu,
                notes,
                fell_back: AtomicBool::new(false),
            }),
            backend: Backend::Gpu,
            reason,
        })
    } else {
        Ok(Selection {
            trainer: Box::new(FastCpuTrainer),
            backend: Backend::Cpu,
            reason: format!("auto: {}", verdict.describe(false)),
        })
    }
}

/// `auto` on a GPU: the GPU, and the fast CPU trainer when the device fails (lost, out of
/// memory), with one note for the whole batch.
pub struct AutoTrainer {
    gpu: GpuTrainer,
    notes: Notes,
    fell_back: AtomicBool,
}

impl AutoTrainer {
    fn fallback<T>(&self, what: &str, error: Error, cpu: impl FnOnce() -> Result<T>) -> Result<T> {
        match error {
            Error::Device { .. } => {
                if !self.fell_back.swap(true, Ordering::Relaxed) {
                    (self.notes)(&format!("note: {error}; {what} on the CPU instead"));
                }
                cpu()
            }
            other => Err(other),
        }
    }
}

impl Trainer for AutoTrainer {
    fn name(&self) -> String {
        self.gpu.name()
    }

    fn networks_per_call(&self) -> usize {
        self.gpu.networks_per_call()
    }

    fn train_from(
        &self,
        initial: Vec<Mlp>,
        sets: &[TrainingSet],
        config: &ModelConfig,
    ) -> Result<Vec<Mlp>> {
        if self.fell_back.load(Ordering::Relaxed) {
            return FastCpuTrainer.train_from(initial, sets, config);
        }
        match self.gpu.train_from(initial.clone(), sets, config) {
            Ok(nets) => Ok(nets),
            Err(e) => self.fallback("training", e, || {
                FastCpuTrainer.train_from(initial, sets, config)
            }),
        }
    }

    fn evaluate_batch(&self, nets: &[Mlp], inputs: &[[f32; 2]]) -> Result<Vec<Vec<f32>>> {
        // A software adapter evaluates grids several times slower than the CPU
        // (docs/performance.md): it only trains.
        if self.fell_back.load(Ordering::Relaxed) || self.gpu.context().adapter.software {
            return FastCpuTrainer.evaluate_batch(nets, inputs);
        }
        match self.gpu.evaluate_batch(nets, inputs) {
            Ok(out) => Ok(out),
            Err(e) => self.fallback("evaluating", e, || {
                FastCpuTrainer.evaluate_batch(nets, inputs)
            }),
        }
    }
}
