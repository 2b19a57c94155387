//! The command tree: one file per area, each with its clap arguments and a `run` that calls the library.

/// A line on stdout, like `println!`, but a closed pipe (`errmap … | head`) becomes an error
/// that `main` turns into a quiet exit 0 instead of a panic. Use inside a function returning
/// `errmap::Result`.
macro_rules! outln {
    () => {
        $crate::cli::emit("\n")?
    };
    ($($arg:tt)*) => {
        $crate::cli::emit(&format!("{}\n", format_args!($($arg)*)))?
    };
}

/// `print!` with the same handling of a closed pipe as [`outln!`].
macro_rules! out {
    ($($arg:tt)*) => {
        $crate::cli::emit(&format!($($arg)*))?
    };
}

/// An informational line on stderr ("wrote …"), hidden by `--quiet`.
macro_rules! info {
    ($($arg:tt)*) => {
        $crate::cli::terminal::info(&format!($($arg)*))
    };
}

mod bench;
mod choices;
mod circular;
mod compensate;
mod deprecated;
pub mod exit;
mod gpu;
mod grid;
mod linear;
mod live;
mod part;
mod report;
mod rotary;
mod scale;
mod serve;
mod synth_web_plate;
mod terminal;
mod thermal;
pub mod words;

use clap::{Parser, Subcommand};
use errmap::Result;

/// errmap: error maps and compensation for CNC machine tools and the parts they cut.
#[derive(Debug, Parser)]
#[command(name = "errmap", version, about, long_about = None, propagate_version = true)]
pub struct Cli {
    /// Print only results, warnings and errors: no progress bars, no "wrote …" lines.
    #[arg(long, short, global = true, conflicts_with = "verbose")]
    pub quiet: bool,
    /// Also print which trainer (CPU or GPU) runs and why, and how much it trains.
    #[arg(long, short, global = true)]
    pub verbose: bool,
    /// Largest file any one output may grow to, MB; outputs whose size follows from your
    /// numbers (grid steps, segment lengths, spacings) stop with exit 2 beyond it.
    #[arg(long, global = true, value_name = "MB", default_value_t = errmap::io::safety::DEFAULT_MAX_OUTPUT_MB)]
    pub max_output_mb: u64,
    /// Memory one part may need, MB: a probe file or scan of more points stops with exit 2
    /// before it is read (job key `max_memory_mb`; default 8192).
    #[arg(long, global = true, value_name = "MB")]
    pub max_memory_mb: Option<u64>,
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
    /// Join a sharded batch: check the shards, join their summaries, build the family (maps, network, toolpaths).
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
    /// Measure this machine: training throughput of a backend on synthetic work.
    #[command(subcommand)]
    Bench(bench::BenchCommand),
    /// Linear axes measured by laser interferometer.
    #[command(subcommand)]
    Linear(linear::LinearCommand),
    /// Thermal positioning error of linear axes.
    #[command(subcommand)]
    Thermal(thermal::ThermalCommand),
    /// Rotary axes measured with two spheres on a bar.
    #[command(subcommand)]
    Rotary(rotary::RotaryCommand),
    /// Dynamic circular test (ISO 230-4, ballbar or grid encoder): G, F, H and a diagnosis of axis errors.
    Circular(circular::CircularArgs),
    /// Live thermal compensation: temperatures in, compensation out to the controller, every cycle logged.
    Live(live::LiveArgs),
    /// Write the self-contained report.html of a batch run or an analysis's outputs (and --pdf).
    Report(report::ReportArgs),
    /// Generate sample data with known ground truth.
    #[command(subcommand)]
    Synth(SynthCommand),
    /// The monitor web server with login (live loop, history, runs), and its users.
    Serve(serve::ServeArgs),
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
    /// Circular-test runs (ballbar or two-axis) with planted axis errors and noise.
    Circular(circular::SynthCircularArgs),
    /// A machine log of a thermal campaign to replay through `errmap live`.
    LiveReplay(live::SynthLiveReplayArgs),
}

/// Notes from the library (a trainer falling back to the CPU) go to stderr unless `--quiet`.
pub fn notes(_globals: Globals) -> errmap::backend::Notes {
    std::sync::Arc::new(|line: &str| terminal::info(line))
}

/// Write text to stdout and flush it; an error (a closed pipe) is returned, never a panic.
pub fn emit(text: &str) -> Result<()> {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    out.write_all(text.as_bytes())
        .and_then(|()| out.flush())
        .map_err(|e| errmap::Error::write("<stdout>", e))
}

/// Treat a closed stdout as done: for commands whose exit code says more than "printed".
pub fn ignore_closed_pipe(result: Result<()>) -> Result<()> {
    match result {
        Err(errmap::Error::Io { source, .. })
            if source.kind() == std::io::ErrorKind::BrokenPipe =>
        {
            Ok(())
        }
        other => other,
    }
}

/// Run a parsed command line; the result is the process exit code.
pub fn run(cli: Cli) -> exit::Result<i32> {
    // Every output of this process obeys the safety rules: never over an input, never
    // outside the folder a command writes into.
    errmap::io::safety::activate();
    if cli.max_output_mb == 0 {
        return Err(errmap::Error::usage(
            "--max-output-mb 0 allows no output at all",
            "give a size in MB, e.g. --max-output-mb 2000",
        )
        .into());
    }
    errmap::io::safety::set_max_output_mb(cli.max_output_mb);
    if cli.max_memory_mb == Some(0) {
        return Err(errmap::Error::usage(
            "--max-memory-mb 0 leaves no memory for any part",
            "give a size in MB, e.g. --max-memory-mb 4096",
        )
        .into());
    }
    errmap::probe::budget::set_max_memory_mb(cli.max_memory_mb.unwrap_or(0));
    let globals = Globals { quiet: cli.quiet };
    use errmap::progress::Verbosity;
    terminal::set_verbosity(match (cli.quiet, cli.verbose) {
        (true, _) => Verbosity::Quiet,
        (false, true) => Verbosity::Verbose,
        (false, false) => Verbosity::Normal,
    });
    match cli.command {
        Command::Batch(args) => part::run_batch(args, globals),
        Command::Map(args) => part::run_map(args, globals),
        Command::Merge(args) => part::run_merge(args, globals),
        Command::Slurm(args) => scale::run_slurm(args, globals),
        Command::K8s(args) => scale::run_k8s(args, globals),
        Command::Grid(args) => grid::run(args, globals),
        Command::Compensate(args) => compensate::run(args, globals),
        Command::Bench(cmd) => bench::run(cmd, globals),
        Command::GpuInfo(args) => gpu::run(args, globals),
        Command::Linear(cmd) => linear::run(cmd, globals),
        Command::Thermal(cmd) => thermal::run(cmd, globals),
        Command::Rotary(cmd) => rotary::run(cmd, globals),
        Command::Synth(SynthCommand::WebPlate(args)) => synth_web_plate::run(args, globals),
        Command::Synth(SynthCommand::Linear(args)) => linear::run_synth(args, globals),
        Command::Synth(SynthCommand::Thermal(args)) => thermal::run_synth(args, globals),
        Command::Synth(SynthCommand::Rotary(args)) => rotary::run_synth(args, globals),
        Command::Circular(args) => circular::run(args, globals),
        Command::Report(args) => report::run(args, globals),
        Command::Live(args) => live::run(args, globals),
        Command::Synth(SynthCommand::LiveReplay(args)) => live::run_synth_replay(args, globals),
        Command::Synth(SynthCommand::Circular(args)) => circular::run_synth(args, globals),
        Command::Serve(args) => serve::run(args, globals),
    }
}
