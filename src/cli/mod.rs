//! The command tree: one file per area, each with its clap arguments and a `run` that calls the library.

mod compensate;
mod gpu;
mod grid;
mod linear;
mod part;
mod rotary;
mod scale;
mod synth_web_plate;
mod thermal;

use clap::{Parser, Subcommand};
use errmap::Result;

/// errmap: error maps and compensation for CNC machine tools and the parts they cut.
#[derive(Debug, Parser)]
#[command(name = "errmap", version, about, long_about = None, propagate_version = true)]
pub struct Cli {
    /// No progress bars or informational lines on stderr.
    #[arg(long, short, global = true)]
    pub quiet: bool,
    #[command(subcommand)]
    pub command: Command,
}

/// Options every command sees.
#[derive(Debug, Clone, Copy)]
pub struct Globals {
    pub quiet: bool,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Map every part of a family from a job file (probe files → maps, heatmaps, compensated toolpaths).
    Batch(part::BatchArgs),
    /// Map one part from its probe file, without a job file.
    Map(part::MapArgs),
    /// Reduce a sharded batch: check the shards, join their summaries, build the family (maps, network, toolpaths).
    Merge(part::MergeArgs),
    /// Run a job on Slurm: an array job of shards and a merge job after it (write, print or submit).
    Slurm(scale::SlurmArgs),
    /// Run a job on Kubernetes: Indexed Job manifests for the shards and a merge Job.
    K8s(scale::K8sArgs),
    /// Interpolate probe points onto a grid (no network).
    Grid(grid::GridArgs),
    /// Rewrite a toolpath with P' = P − E from a fitted map.
    Compensate(compensate::CompensateArgs),
    /// List GPU adapters, the one errmap would choose and its limits.
    GpuInfo(gpu::GpuInfoArgs),
    /// Linear axes measured by laser interferometer.
    #[command(subcommand)]
    Linear(linear::LinearCommand),
    /// Thermal positioning error of linear axes.
    #[command(subcommand)]
    Thermal(thermal::ThermalCommand),
    /// Rotary axes measured with two spheres on a bar.
    #[command(subcommand)]
    Rotary(rotary::RotaryCommand),
    /// Generate sample data with known ground truth.
    #[command(subcommand)]
    Synth(SynthCommand),
}

#[derive(Debug, Subcommand)]
pub enum SynthCommand {
    /// A thin-walled web-plate family: probe files, ground truth, a finishing program.
    WebPlate(synth_web_plate::SynthWebPlateArgs),
    /// Laser runs of a linear axis with known pitch error and reversal.
    Linear(linear::SynthLinearArgs),
    /// A thermal warm-up campaign with known sensor gains.
    Thermal(thermal::SynthThermalArgs),
    /// Sphere probing around a rotary axis with planted angular errors.
    Rotary(rotary::SynthRotaryArgs),
}

/// Run a parsed command line; the result is the process exit code.
pub fn run(cli: Cli) -> Result<i32> {
    let globals = Globals { quiet: cli.quiet };
    match cli.command {
        Command::Batch(args) => part::run_batch(args, globals),
        Command::Map(args) => part::run_map(args, globals),
        Command::Merge(args) => part::run_merge(args, globals),
        Command::Slurm(args) => scale::run_slurm(args, globals),
        Command::K8s(args) => scale::run_k8s(args, globals),
        Command::Grid(args) => grid::run(args, globals),
        Command::Compensate(args) => compensate::run(args, globals),
        Command::GpuInfo(args) => gpu::run(args, globals),
        Command::Linear(cmd) => linear::run(cmd, globals),
        Command::Thermal(cmd) => thermal::run(cmd, globals),
        Command::Rotary(cmd) => rotary::run(cmd, globals),
        Command::Synth(SynthCommand::WebPlate(args)) => synth_web_plate::run(args, globals),
        Command::Synth(SynthCommand::Linear(args)) => linear::run_synth(args, globals),
        Command::Synth(SynthCommand::Thermal(args)) => thermal::run_synth(args, globals),
        Command::Synth(SynthCommand::Rotary(args)) => rotary::run_synth(args, globals),
    }
}
