//! The `auto` probe: the fast CPU trainer and a wgpu adapter train the same short workload, and the throughputs are cached per machine, driver and architecture.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::gpu::GpuTrainer;
use crate::nn::{FastCpuTrainer, ModelConfig, Trainer, TrainingSet};
use errmap_core::Result;

/// The probe workload: this many networks …
pub const PROBE_PARTS: usize = 8;
/// … of this many samples …
pub const PROBE_SAMPLES: usize = 768;
/// … for this many Adam epochs (after one warm-up epoch that builds the pipelines).
pub const PROBE_EPOCHS: u32 = 20;

pub use errmap_core::io::CACHE_ENV;

/// One backend's figures on a workload.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Measure {
    /// `cpu` or `gpu`.
    pub backend: String,
    /// What ran it: the adapter's name (e.g. llvmpipe) or the CPU trainer's SIMD path.
    pub device: String,
    /// Networks × samples × epochs per second of training, the warm-up excluded.
    pub sample_epochs_per_s: f64,
    /// Seconds to open the device and build the pipelines (the warm-up epoch included).
    pub pipeline_build_s: f64,
}

/// The probe's outcome for one machine and architecture.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Verdict {
    /// The fast CPU trainer's figures.
    pub cpu: Measure,
    /// The wgpu adapter's figures.
    pub gpu: Measure,
    /// Read from the cache rather than measured now.
    #[serde(default)]
    pub cached: bool,
}

impl Verdict {
    /// Whether the GPU trained more sample·epochs per second than the CPU (the pipeline
    /// build not counted); a tie goes to the CPU.
    pub fn gpu_is_faster(&self) -> bool {
        self.gpu.sample_epochs_per_s > self.cpu.sample_epochs_per_s
    }

    /// One line for notes and `gpu-info`.
    pub fn describe(&self, chose_gpu: bool) -> String {
        let (win, lose) = if chose_gpu {
            (&self.gpu, &self.cpu)
        } else {
            (&self.cpu, &self.gpu)
        };
        format!(
            "{} ({}) trains at {:.3e} sample·epochs/s, {} ({}) at {:.3e} ({})",
            win.backend,
            win.device,
            win.sample_epochs_per_s,
            lose.backend,
            lose.device,
            lose.sample_epochs_per_s,
            if self.cached {
                "measured earlier on this machine"
            } else {
                "measured now"
            }
        )
    }
}

pub use errmap_core::io::cache_dir;

/// The probe cache: one JSON object, probe key → [`Verdict`].
pub fn cache_file() -> Option<PathBuf> {
    cache_dir().map(|d| d.join("backend-probe.json"))
}

/// What a verdict depends on: errmap's version, the CPU path and threads, the adapter and
/// its driver, and the architecture.
pub fn probe_key(gpu: &GpuTrainer, config: &ModelConfig) -> String {
    let a = &gpu.context().adapter;
    format!(
        "errmap {}; cpu {} x{}; gpu {} | {} | {} | {} | {}; net {:?} {}",
        env!("CARGO_PKG_VERSION"),
        FastCpuTrainer::simd_path(),
        rayon::current_num_threads(),
        a.name,
        a.backend,
        a.device_type,
        a.driver,
        a.driver_info,
        config.layer_sizes(),
        config.activation.name()
    )
}

/// The cached verdict for this machine and architecture, or a new measurement (then cached
/// in [`cache_file`]; a cache that cannot be read or written is only a missed shortcut).
pub fn compare(gpu: &GpuTrainer, config: &ModelConfig) -> Result<Verdict> {
    compare_cached_in(gpu, config, cache_file())
}

/// [`compare`] with the cache in `path` (`None`: measure, keep nothing).
pub fn compare_cached_in(
    gpu: &GpuTrainer,
    config: &ModelConfig,
    path: Option<PathBuf>,
) -> Result<Verdict> {
    let key = probe_key(gpu, config);
    let mut cache = read_cache(path.as_deref());
    if let Some(found) = cache.get(&key) {
        return Ok(Verdict {
            cached: true,
            ..found.clone()
        });
    }
    let sets = crate::nn::workload::plate_family(PROBE_PARTS, PROBE_SAMPLES);
    let verdict = Verdict {
        cpu: measure(&FastCpuTrainer, "cpu", 0.0, &sets, config, PROBE_EPOCHS)?,
        gpu: measure(gpu, "gpu", 0.0, &sets, config, PROBE_EPOCHS)?,
        cached: false,
    };
    if let Some(path) = path {
        cache.insert(key, verdict.clone());
        if let Some(dir) = path.parent() {
            let _ = std::fs::create_dir_all(dir);
        }
        let _ = errmap_core::io::write_json(&path, &cache);
    }
    Ok(verdict)
}

fn read_cache(path: Option<&std::path::Path>) -> BTreeMap<String, Verdict> {
    path.and_then(|p| std::fs::read_to_string(p).ok())
        .and_then(|text| serde_json::from_str(&text).ok())
        .unwrap_or_default()
}

/// The verdict cached for this machine and architecture, without measuring.
pub fn cached_verdict(
    gpu: &GpuTrainer,
    config: &ModelConfig,
    path: Option<&std::path::Path>,
) -> Option<Verdict> {
    read_cache(path)
        .remove(&probe_key(gpu, config))
        .map(|v| Verdict { cached: true, ..v })
}

/// Trains `sets` on `trainer` for one warm-up epoch (timed as the pipeline build, on top of
/// `open_s` spent opening it), then for `epochs` timed epochs.
pub fn measure(
    trainer: &dyn Trainer,
    backend: &str,
    open_s: f64,
    sets: &[TrainingSet],
    config: &ModelConfig,
    epochs: u32,
) -> Result<Measure> {
    measure_with_cpu(trainer, backend, open_s, sets, config, epochs).map(|(m, _)| m)
}

/// [`measure`], and the CPU seconds the whole process (every thread: rayon's, a software
/// adapter's workers) spent in the timed epochs; `None` where the platform cannot tell.
pub fn measure_with_cpu(
    trainer: &dyn Trainer,
    backend: &str,
    open_s: f64,
    sets: &[TrainingSet],
    config: &ModelConfig,
    epochs: u32,
) -> Result<(Measure, Option<f64>)> {
    let warm = ModelConfig {
        epochs: 1,
        loss_every: 1,
        ..config.clone()
    };
    let start = Instant::now();
    trainer.train_batch(&sets[..1], &warm)?;
    let pipeline_build_s = open_s + start.elapsed().as_secs_f64();
    let timed = ModelConfig {
        epochs,
        loss_every: epochs,
        ..config.clone()
    };
    let cpu = cpu_time::ProcessTime::try_now().ok();
    let start = Instant::now();
    trainer.train_batch(sets, &timed)?;
    let train_s = start.elapsed().as_secs_f64().max(1e-9);
    let cpu_s = cpu
        .and_then(|c| c.try_elapsed().ok())
        .map(|d| d.as_secs_f64());
    let samples: usize = sets.iter().map(|s| s.len()).sum();
    let measure = Measure {
        backend: backend.to_string(),
        device: device_name(trainer),
        sample_epochs_per_s: samples as f64 * epochs as f64 / train_s,
        pipeline_build_s,
    };
    Ok((measure, cpu_s))
}

/// The adapter or SIMD path in a trainer's name: "gpu: llvmpipe (…) (Vulkan, software)" →
/// "llvmpipe (…) (Vulkan, software)".
fn device_name(trainer: &dyn Trainer) -> String {
    let name = trainer.name();
    name.strip_prefix("gpu: ").unwrap_or(&name).to_string()
}
