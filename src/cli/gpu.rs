//! CLI of `errmap gpu-info`: adapters, the one chosen and its limits.

use serde::Serialize;

use super::Globals;
use errmap::gpu::{auto_allows_software, list_adapters, AdapterSummary, GpuContext, LimitsSummary};
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
    /// What `--backend auto` trains on: "gpu" or "cpu" (auto skips software adapters
    /// unless ERRMAP_SOFTWARE_GPU=1).
    auto_backend: &'static str,
    /// Why no device could be opened, when none could.
    error: Option<String>,
}

pub fn run(args: GpuInfoArgs, _globals: Globals) -> Result<i32> {
    let adapters = list_adapters();
    let info = match GpuContext::open(true) {
        Ok(ctx) => GpuInfo {
            adapters,
            chosen: Some(ctx.adapter.clone()),
            limits: Some(LimitsSummary::of(&ctx.limits)),
            auto_backend: if ctx.adapter.software && !auto_allows_software() {
                "cpu"
            } else {
                "gpu"
            },
            error: None,
        },
        Err(e) => GpuInfo {
            adapters,
            chosen: None,
            limits: None,
            auto_backend: "cpu",
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
            if info.auto_backend == "gpu" {
                outln!("--backend auto trains on the GPU");
            } else {
                outln!(
                    "--backend auto trains on the CPU (faster than a software adapter; ERRMAP_SOFTWARE_GPU=1 changes that); --backend gpu uses {}",
                    chosen.name
                );
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
