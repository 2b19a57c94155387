//! CLI of `errmap live` (the loop) and `errmap synth live-replay` (a machine log to replay).

use super::exit::Result;
use super::Globals;
use errmap::live::replay::{write_replay, ReplayOptions};
use errmap::live::{LiveConfig, RunOptions, StopFlags};
use std::path::PathBuf;

#[derive(Debug, clap::Args)]
pub struct LiveArgs {
    /// The live configuration (TOML; see docs/live.md).
    pub config: PathBuf,
    /// Compute and log only: no target is contacted or written.
    #[arg(long)]
    pub dry_run: bool,
    /// One cycle, written at once without the start ramp (says so on stderr).
    #[arg(long)]
    pub once: bool,
    /// Rewrite this state file (JSON, schema errmap-live-state/1) every cycle for the monitor.
    #[arg(long, value_name = "PATH")]
    pub state: Option<PathBuf>,
    /// Print the run's summary as one JSON document at the end.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, clap::Args)]
pub struct SynthLiveReplayArgs {
    /// The machine log to write (CSV, the format `errmap thermal compensate` reads).
    #[arg(short, long, value_name = "FILE")]
    pub output: PathBuf,
    /// Seed of the sensor noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Campaign of `errmap synth thermal` whose temperatures are replayed (1, 3: coolant off;
    /// 2, 4: coolant on).
    #[arg(long, value_name = "N", default_value_t = 2)]
    pub campaign: usize,
    /// Length of the log, hours.
    #[arg(long, value_name = "HOURS", default_value_t = 4.0)]
    pub hours: f64,
    /// Time between rows, seconds.
    #[arg(long, value_name = "SECONDS", default_value_t = 1.0)]
    pub period_s: f64,
    /// Feed of the axis moving back and forth over its travel, mm/min.
    #[arg(long, value_name = "MM_PER_MIN", default_value_t = 1500.0)]
    pub feed_mm_min: f64,
    /// Switch the coolant label between off and on every this many seconds.
    #[arg(long, value_name = "SECONDS")]
    pub coolant_every_s: Option<f64>,
}

pub fn run(a: LiveArgs, _g: Globals) -> Result<i32> {
    let config = LiveConfig::read(&a.config)?;
    let stop = StopFlags::new();
    stop.register_signals()?;
    let options = RunOptions {
        dry_run: a.dry_run,
        once: a.once,
        state: a.state,
    };
    let notes = |line: &str| info!("{line}");
    let summary = errmap::live::run(&config, &options, &stop, &notes)?;
    if a.json {
        let text = serde_json::to_string_pretty(&summary)
            .map_err(|e| errmap::Error::Internal(format!("summary JSON: {e}")))?;
        outln!("{text}");
    } else {
        info!(
            "{} cycles, {} missed, {} alarms; {}; logged as campaign {} in the store",
            summary.cycles,
            summary.missed_cycles,
            summary.alarms_raised,
            summary.stop_reason,
            summary.campaign
        );
    }
    Ok(0)
}

pub fn run_synth_replay(a: SynthLiveReplayArgs, _g: Globals) -> Result<i32> {
    let options = ReplayOptions {
        seed: a.seed,
        campaign: a.campaign,
        duration_s: a.hours * 3600.0,
        period_s: a.period_s,
        feed_mm_per_min: a.feed_mm_min,
        coolant_every_s: a.coolant_every_s,
    };
    let rows = write_replay(&a.output, &options)?;
    info!("wrote {rows} rows to {}", a.output.display());
    Ok(0)
}

#[derive(Debug, clap::Args)]
pub struct BenchLiveArgs {
    /// Temperature sensors (gain sensors of every axis's model).
    #[arg(long, value_name = "N", default_value_t = 16)]
    pub sensors: usize,
    /// Axes, each with its own model.
    #[arg(long, value_name = "N", default_value_t = 3)]
    pub axes: usize,
    /// Cycle rate, Hz.
    #[arg(long, value_name = "HZ", default_value_t = 100.0)]
    pub hz: f64,
    /// How long to run, seconds.
    #[arg(long, value_name = "SECONDS", default_value_t = 10.0)]
    pub seconds: f64,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

pub fn run_bench(a: BenchLiveArgs) -> Result<i32> {
    let report = errmap::live::bench::run(&errmap::live::bench::LiveBench {
        sensors: a.sensors,
        axes: a.axes,
        hz: a.hz,
        seconds: a.seconds,
    })?;
    if a.json {
        let text = serde_json::to_string_pretty(&report)
            .map_err(|e| errmap::Error::Internal(format!("bench JSON: {e}")))?;
        outln!("{text}");
    } else {
        outln!(
            "{} sensors, {} axes at {} Hz: {} cycles, {} missed; cycle {:.0} µs mean, {:.0} µs largest; CPU {:.2} s in {:.2} s = {:.1} % of one core",
            report.sensors,
            report.axes,
            report.hz,
            report.cycles,
            report.missed_cycles,
            report.cycle_mean_us,
            report.cycle_max_us,
            report.cpu_s,
            report.wall_s,
            100.0 * report.cpu_share_of_one_core
        );
    }
    Ok(0)
}
