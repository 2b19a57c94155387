//! `errmap bench training`: one backend's training throughput on synthetic work, as one JSON object, so a user can check a machine in one command.

use std::time::Instant;

use serde::Serialize;

use super::{probe, select_trainer, silent};
use crate::nn::{Backend, ModelConfig};
use crate::Setting;
use errmap_core::setting::words;
use errmap_core::{Error, Result};

/// What `errmap bench training` trains.
#[derive(Debug, Clone)]
pub struct TrainingBench {
    /// Networks trained together in one batch, one per synthetic part (1 to 4096).
    pub parts: usize,
    /// Training samples per network, on a grid over a synthetic plate (8 to 2²²).
    pub samples: usize,
    /// Full-batch Adam steps timed (after one warm-up epoch).
    pub epochs: u32,
    /// The backend to measure; `auto` measures the one it chooses.
    pub backend: Backend,
    /// Hidden layer widths (default 32, 32).
    pub hidden: Vec<usize>,
}

/// The figures of one bench run.
#[derive(Debug, Clone, Serialize)]
pub struct TrainingBenchReport {
    /// The backend that trained (`gpu`, `cpu` or `cpu-reference`; `auto` resolved).
    pub backend: String,
    /// The adapter (e.g. llvmpipe) or the CPU trainer's SIMD path and threads.
    pub device: String,
    /// Why this backend, for `auto`.
    pub reason: String,
    /// Networks trained together.
    pub parts: usize,
    /// Training samples per network.
    pub samples: usize,
    /// Adam steps timed.
    pub epochs: u32,
    /// Units per layer, the 2 inputs and the 1 output included.
    pub layer_sizes: Vec<usize>,
    /// parts × samples × epochs / training seconds (pipeline build excluded).
    pub sample_epochs_per_s: f64,
    /// Seconds of the timed epochs, the pipeline build and warm-up excluded.
    pub train_s: f64,
    /// Opening the device, building the pipelines and the warm-up epoch (0 for the CPU
    /// trainers apart from their warm-up).
    pub pipeline_build_s: f64,
    /// CPU seconds of the whole process (all threads) in the timed epochs; `null` where the
    /// platform cannot tell.
    pub train_cpu_s: Option<f64>,
    /// parts × samples × epochs / [`TrainingBenchReport::train_cpu_s`]: work per CPU second,
    /// which other processes on the machine change much less than the wall-clock rate.
    pub sample_epochs_per_cpu_s: Option<f64>,
}

/// Most samples a bench trains per network, and most networks (a typo guard).
const MAX_SAMPLES: usize = 1 << 22;
const MAX_PARTS: usize = 4096;

/// Opens the bench's backend (as `--backend` would), trains `parts` synthetic plate networks
/// on it and reports the throughput; refuses `parts` or `samples` out of range and a model
/// that does not validate.
pub fn run(bench: &TrainingBench) -> Result<TrainingBenchReport> {
    if !(1..=MAX_PARTS).contains(&bench.parts) || !(8..=MAX_SAMPLES).contains(&bench.samples) {
        return Err(Error::usage(
            format!(
                "{} {} {} {}: parts must be 1..={MAX_PARTS}, samples 8..={MAX_SAMPLES}",
                words(Setting::BenchParts),
                bench.parts,
                words(Setting::BenchSamples),
                bench.samples
            ),
            format!(
                "e.g. {} 8 {} 1536",
                words(Setting::BenchParts),
                words(Setting::BenchSamples)
            ),
        ));
    }
    let config = ModelConfig {
        hidden: bench.hidden.clone(),
        epochs: bench.epochs,
        loss_every: bench.epochs.max(1),
        ..ModelConfig::default()
    };
    config.validate()?;
    let open = Instant::now();
    let selection = select_trainer(bench.backend, &config, silent())?;
    let open_s = open.elapsed().as_secs_f64();
    let sets = crate::nn::workload::plate_family(bench.parts, bench.samples);
    let (measure, train_cpu_s) = probe::measure_with_cpu(
        selection.trainer.as_ref(),
        selection.backend.name(),
        open_s,
        &sets,
        &config,
        bench.epochs,
    )?;
    let work = (bench.parts * bench.samples) as f64 * bench.epochs as f64;
    Ok(TrainingBenchReport {
        backend: measure.backend,
        device: measure.device,
        reason: selection.reason,
        parts: bench.parts,
        samples: bench.samples,
        epochs: bench.epochs,
        layer_sizes: config.layer_sizes(),
        sample_epochs_per_s: measure.sample_epochs_per_s,
        train_s: work / measure.sample_epochs_per_s,
        pipeline_build_s: measure.pipeline_build_s,
        train_cpu_s,
        sample_epochs_per_cpu_s: train_cpu_s.filter(|s| *s > 0.0).map(|s| work / s),
    })
}
