//! CLI of `errmap bench`: measure this machine (training throughput of a backend).

use super::exit::Result;
use super::Globals;
use errmap::backend::bench::{self, TrainingBench};
use errmap::nn::Backend;

#[derive(Debug, clap::Subcommand)]
pub enum BenchCommand {
    /// Time the training of N networks (one per part, the default network size) on synthetic
    /// web-plate data and print the throughput in sample·epochs/s (training only).
    Training(TrainingArgs),
    /// Time the cycle of `errmap live` (N sensors, M axes, at a rate; dry run, store and state
    /// file written every cycle) and its CPU share of one core.
    Live(super::live::BenchLiveArgs),
}

#[derive(Debug, clap::Args)]
pub struct TrainingArgs {
    /// Networks trained together (one per part of a family).
    #[arg(long, value_name = "N", default_value_t = 8)]
    pub parts: usize,
    /// Training points per network.
    #[arg(long, value_name = "N", default_value_t = 1536)]
    pub samples: usize,
    /// Training epochs (passes over all of a network's points).
    #[arg(long, value_name = "N", default_value_t = 100)]
    pub epochs: u32,
    /// auto: the fastest this machine has; gpu: any GPU adapter (software included);
    /// cpu: the fast CPU trainer; cpu-reference: the slow reference trainer.
    #[arg(long, value_parser = super::choices::Backend::parser(), default_value = "auto")]
    pub backend: Backend,
    /// Network size: neurons in each hidden layer, comma-separated.
    #[arg(
        long,
        value_name = "N,N",
        value_delimiter = ',',
        default_value = "32,32"
    )]
    pub hidden: Vec<usize>,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

pub fn run(cmd: BenchCommand, _globals: Globals) -> Result<i32> {
    match cmd {
        BenchCommand::Live(args) => super::live::run_bench(args),
        BenchCommand::Training(args) => {
            let report = bench::run(&TrainingBench {
                parts: args.parts,
                samples: args.samples,
                epochs: args.epochs,
                backend: args.backend,
                hidden: args.hidden,
            })?;
            if args.json {
                let text = serde_json::to_string_pretty(&report)
                    .map_err(|e| errmap::Error::Internal(format!("bench JSON: {e}")))?;
                outln!("{text}");
            } else {
                let per_cpu = report
                    .sample_epochs_per_cpu_s
                    .map(|r| format!(", {r:.3e} per CPU second"))
                    .unwrap_or_default();
                outln!(
                    "{} on {}: {:.3e} sample·epochs/s{per_cpu} ({} × {} samples × {} epochs in {:.3} s; pipeline build {:.3} s)\n{}",
                    report.backend,
                    report.device,
                    report.sample_epochs_per_s,
                    report.parts,
                    report.samples,
                    report.epochs,
                    report.train_s,
                    report.pipeline_build_s,
                    report.reason
                );
            }
            Ok(0)
        }
    }
}
