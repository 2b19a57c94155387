//! What `errmap gpu-info` reports: the adapters, the one `--backend gpu` uses and its limits,
//! and what `--backend auto` chooses and why (one JSON document).

use super::probe::{self, Verdict};
use crate::gpu::{list_adapters, AdapterSummary, GpuTrainer, LimitsSummary};
use crate::nn::ModelConfig;
use errmap_core::error::Result;
use serde::Serialize;

/// The GPU adapters of this machine and the choice `--backend auto|gpu` makes.
#[derive(Debug, Serialize)]
pub struct GpuInfo {
    /// Every adapter wgpu finds, best first (hardware before software).
    pub adapters: Vec<AdapterSummary>,
    /// The adapter `--backend gpu` uses (hardware first, else software).
    pub chosen: Option<AdapterSummary>,
    /// The limits the chosen adapter's device grants; `None` when no device opened.
    pub limits: Option<LimitsSummary>,
    /// What `--backend auto` trains the default architecture on: "gpu" or "cpu".
    pub auto_backend: &'static str,
    /// Why: the probe's figures (cached per machine, driver and architecture).
    pub auto_reason: String,
    /// The probe's CPU and GPU figures; `None` when no device opened (auto then takes the CPU).
    pub auto_probe: Option<Verdict>,
    /// Where the probe's figures are cached.
    pub probe_cache: Option<String>,
    /// Why no device could be opened, when none could.
    pub error: Option<String>,
}

impl GpuInfo {
    /// Look at this machine: list the adapters, open the chosen one and run (or read) the
    /// probe that decides `--backend auto` for the default architecture.
    pub fn gather() -> Result<GpuInfo> {
        let adapters = list_adapters();
        let config = ModelConfig::default();
        let cache = probe::cache_file().map(|p| p.display().to_string());
        Ok(match GpuTrainer::new() {
            Ok(gpu) => {
                let verdict = probe::compare(&gpu, &config)?;
                let gpu_wins = verdict.gpu_is_faster();
                GpuInfo {
                    adapters,
                    chosen: Some(gpu.context().adapter.clone()),
                    limits: Some(LimitsSummary::of(&gpu.context().limits)),
                    auto_backend: if gpu_wins { "gpu" } else { "cpu" },
                    auto_reason: verdict.describe(gpu_wins),
                    auto_probe: Some(verdict),
                    probe_cache: cache,
                    error: None,
                }
            }
            Err(e) => GpuInfo {
                adapters,
                chosen: None,
                limits: None,
                auto_backend: "cpu",
                auto_reason: format!("no usable GPU ({e})"),
                auto_probe: None,
                probe_cache: cache,
                error: Some(e.to_string()),
            },
        })
    }

    /// The document as pretty JSON.
    pub fn to_json(&self) -> Result<String> {
        serde_json::to_string_pretty(self)
            .map_err(|e| errmap_core::Error::Internal(format!("gpu-info JSON: {e}")))
    }
}
