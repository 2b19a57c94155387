//! CLI of `errmap gpu-info`: adapters, the one chosen and its limits.

use super::exit::Result;
use super::Globals;
use errmap::backend::info::GpuInfo;

/// List GPU adapters, the one `--backend auto|gpu` would use, and its limits.
#[derive(Debug, clap::Args)]
pub struct GpuInfoArgs {
    /// Print one JSON document instead of text.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: GpuInfoArgs, _globals: Globals) -> Result<i32> {
    let info = GpuInfo::gather()?;
    if args.json {
        outln!("{}", info.to_json()?);
        return Ok(0);
    }
    print_adapters(&info)?;
    print_choice(&info)?;
    Ok(0)
}

fn print_adapters(info: &GpuInfo) -> Result<()> {
    if info.adapters.is_empty() {
        outln!("adapters: none");
        return Ok(());
    }
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
    Ok(())
}

fn print_choice(info: &GpuInfo) -> Result<()> {
    let (Some(chosen), Some(limits)) = (&info.chosen, &info.limits) else {
        outln!(
            "chosen: none ({})",
            info.error.as_deref().unwrap_or("no adapter")
        );
        outln!("--backend auto trains on the CPU; --backend gpu fails");
        return Ok(());
    };
    outln!("chosen: {} ({})", chosen.name, chosen.backend);
    outln!("limits:");
    // Names padded to one column (the longest keeps its one space).
    for (name, value) in [
        ("max_buffer_size", limits.max_buffer_size),
        (
            "max_storage_buffer_binding_size",
            limits.max_storage_buffer_binding_size,
        ),
        (
            "max_storage_buffers_per_shader_stage",
            u64::from(limits.max_storage_buffers_per_shader_stage),
        ),
        (
            "max_compute_workgroups_per_dimension",
            u64::from(limits.max_compute_workgroups_per_dimension),
        ),
        (
            "max_compute_invocations_per_workgroup",
            u64::from(limits.max_compute_invocations_per_workgroup),
        ),
        (
            "min_uniform_buffer_offset_alignment",
            u64::from(limits.min_uniform_buffer_offset_alignment),
        ),
    ] {
        outln!("  {name:<36} {value}");
    }
    outln!(
        "--backend auto trains on the {}: {}",
        info.auto_backend.to_uppercase(),
        info.auto_reason
    );
    if let Some(cache) = &info.probe_cache {
        outln!("probe cache: {cache} (delete it to measure again)");
    }
    Ok(())
}
