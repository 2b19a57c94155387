//! CLI of `errmap gpu-info`: adapters, the one chosen and its limits.

use serde::Serialize;

use super::Globals;
use errmap::backend::probe::{self, Verdict};
use errmap::gpu::{list_adapters, AdapterSummary, GpuTrainer, LimitsSummary};
use errmap::nn::ModelConfig;
use errmap::Result;

/// List GPU adapters, the one `--backend auto|gpu` would use, and its limits.
#[derive(Debug, clap::Args)]
pub struct GpuInfoArgs {
    /// Print one JSON document instead of text.
    #[arg(long)]
    pub json: bool,
}

#[derive(Serialize)]
struct GpuInfo {
    adapters: Vec<AdapterSummary>,
    /// The adapter `--backend gpu` uses (hardware first, else software).
    chosen: Option<AdapterSummary>,
    limits: Option<LimitsSummary>,
    /// What `--backend auto` trains the default architecture on: "gpu" or "cpu".
    auto_backend: &'static str,
    /// Why: the probe's figures (cached per machine, driver and architecture).
    auto_reason: String,
    auto_probe: Option<Verdict>,
    /// Where the probe's figures are cached.
    probe_cache: Option<String>,
    /// Why no device could be opened, when none could.
    error: Option<String>,
}

pub fn run(args: GpuInfoArgs, _globals: Globals) -> Result<i32> {
    let adapters = list_adapters();
    let config = ModelConfig::default();
    let cache = probe::cache_file().map(|p| p.display().to_string());
    let info = match GpuTrainer::new() {
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
    };
    if args.json {
        let text = serde_json::to_string_pretty(&info)
            .map_err(|e| errmap::Error::Internal(format!("gpu-info JSON: {e}")))?;
        outln!("{text}");
        return Ok(0);
    }
    if info.adapters.is_empty() {
        outln!("adapters: none");
    } else {
        outln!("adapters (best first):");
        for a in &info.adapters {
            outln!(
                "  {} — {} {}{}, driver {} {}",
                a.name,
                a.backend,
                a.device_type,
                if a.software { " (software)" } else { "" },
                a.driver,
                a.driver_info
            );
        }
    }
    match (&info.chosen, &info.limits) {
        (Some(chosen), Some(limits)) => {
            outln!("chosen: {} ({})", chosen.name, chosen.backend);
            outln!("limits:");
            outln!(
                "  max_buffer_size                      {}",
                limits.max_buffer_size
            );
            outln!(
                "  max_storage_buffer_binding_size      {}",
                limits.max_storage_buffer_binding_size
            );
            outln!(
                "  max_storage_buffers_per_shader_stage {}",
                limits.max_storage_buffers_per_shader_stage
            );
            outln!(
                "  max_compute_workgroups_per_dimension {}",
                limits.max_compute_workgroups_per_dimension
            );
            outln!(
                "  max_compute_invocations_per_workgroup {}",
                limits.max_compute_invocations_per_workgroup
            );
            outln!(
                "  min_uniform_buffer_offset_alignment  {}",
                limits.min_uniform_buffer_offset_alignment
            );
            outln!(
                "--backend auto trains on the {}: {}",
                info.auto_backend.to_uppercase(),
                info.auto_reason
            );
            if let Some(cache) = &info.probe_cache {
                outln!("probe cache: {cache} (delete it to measure again)");
            }
        }
        _ => {
            outln!(
                "chosen: none ({})",
                info.error.as_deref().unwrap_or("no adapter")
            );
            outln!("--backend auto trains on the CPU; --backend gpu fails");
        }
    }
    Ok(0)
}
