//! CLI of part-family mapping: `batch`, `map` and `merge`.

use super::exit::Result;
use super::terminal::Terminal;
use super::Globals;
use errmap::batch::{self, BatchOptions, BatchSummary, Job, MapRequest, MergeRequest, Shard};
use errmap::geom::{Axis, Domain};
use errmap::interp::Method;
use errmap::nn::{Backend, ModelConfig};
use errmap::Diagnostic;
use std::path::PathBuf;

#[derive(Debug, clap::Args)]
pub struct BatchArgs {
    /// The job manifest (TOML; every key in docs/job.md).
    pub job: PathBuf,
    /// Trainer: auto (the fastest this machine has, measured once; see docs/gpu.md), gpu (any adapter, software included; fails without one), cpu (fast CPU trainer) or cpu-reference; overrides [model] backend.
    #[arg(long, value_parser = super::choices::Backend::parser())]
    pub backend: Option<Backend>,
    /// Map only shard INDEX of COUNT (0-based): the parts at positions INDEX, INDEX+COUNT, … of the sorted probe files.
    #[arg(long, value_name = "INDEX/COUNT")]
    pub shard: Option<String>,
    /// Number of shards when the index comes from SLURM_ARRAY_TASK_ID or JOB_COMPLETION_INDEX.
    #[arg(long, value_name = "COUNT")]
    pub shards: Option<usize>,
    /// Output folder instead of the job's `output` (default out/<family>); a shard writes into its own DIR/shard-I-of-N/.
    #[arg(long, value_name = "DIR")]
    pub out_dir: Option<PathBuf>,
    /// Old spelling of --out-dir.
    #[arg(
        long = "out",
        value_name = "DIR",
        hide = true,
        conflicts_with = "out_dir"
    )]
    pub old_out: Option<PathBuf>,
    /// Keep the parts of the folder's last run whose probe file and outputs still match its run.json; redo the rest.
    #[arg(long)]
    pub resume: bool,
    /// Print the summary as one JSON document instead of the table.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, clap::Args)]
pub struct MapArgs {
    /// The probe file (CSV: x_mm,y_mm,z_mm [,nx_mm,ny_mm,nz_mm] [,id], or a CSV export with
    /// --columns, DMIS .dmi/.dms/.dmis, point cloud .xyz/.ply).
    pub probes: PathBuf,
    /// Output folder (map.csv, map.png, model.json, clean.csv, rejected.csv, summary.json).
    #[arg(long, value_name = "DIR", required_unless_present = "old_out")]
    pub out_dir: Option<PathBuf>,
    /// Old spelling of --out-dir.
    #[arg(
        long = "out",
        value_name = "DIR",
        hide = true,
        conflicts_with = "out_dir"
    )]
    pub old_out: Option<PathBuf>,
    /// Error direction: z maps E over x,y; x over y,z; y over z,x.
    #[arg(long, default_value = "z", value_parser = Axis::parse_arg)]
    pub normal: Axis,
    /// Nominal coordinate along the normal for every point (when the file has no nominal columns).
    #[arg(long, value_name = "MM", allow_hyphen_values = true)]
    pub nominal_plane: Option<f64>,
    /// Map domain UMIN,VMIN,UMAX,VMAX in mm (default: the probes' bounding box).
    #[arg(long, value_name = "UMIN,VMIN,UMAX,VMAX", value_parser = Domain::parse_arg, allow_hyphen_values = true)]
    pub domain: Option<Domain>,
    /// Step of the output grid, mm.
    #[arg(long, value_name = "MM", default_value_t = 5.0)]
    pub grid_step: f64,
    /// Interpolation method of the training set.
    #[arg(long, value_parser = super::choices::Method::parser(), default_value = "natural-neighbour")]
    pub method: Method,
    /// Spacing of the training set, mm.
    #[arg(long, value_name = "MM", default_value_t = 10.0)]
    pub spacing: f64,
    /// Gross-error threshold k: probes with |residual| > k·σ are rejected.
    #[arg(long, value_name = "K", default_value_t = 3.0)]
    pub k_sigma: f64,
    /// Training epochs (default: the job file's [model] default, see docs/job.md).
    #[arg(long, value_name = "N")]
    pub epochs: Option<u32>,
    /// Seed of the random choices (network start weights, hold-out points); same seed, same map.
    #[arg(long, value_name = "N")]
    pub seed: Option<u64>,
    /// Trainer: auto, gpu, cpu or cpu-reference (see errmap batch --help).
    #[arg(long, value_parser = super::choices::Backend::parser(), default_value = "auto")]
    pub backend: Backend,
    /// Plausibility bound, mm: a probe deviation or map value beyond it is an error naming the
    /// likely unit slip.
    #[arg(long, value_name = "MM", default_value_t = errmap::probe::DEFAULT_MAX_DEVIATION_MM)]
    pub max_deviation_mm: f64,
    /// Read an instrument's CSV export: FIELD=COLUMN[unit],… with fields x,y,z (required),
    /// nx,ny,nz, i,j,k (the point's surface normal), id; COLUMN a header name or 1-based number,
    /// unit mm, um, m or in (e.g. x=X,y=Y,z=Z[um],i=I,j=J,k=K,id=POINT). Unmapped columns are
    /// ignored; the header is the first line naming every mapped column.
    #[arg(long, value_name = "MAP")]
    pub columns: Option<String>,
    /// 1-based line of the CSV header (lines before it are skipped and counted).
    #[arg(long, value_name = "N")]
    pub header_line: Option<u64>,
    /// Print the summary as one JSON document.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, clap::Args)]
pub struct MergeArgs {
    /// The batch's output folder (holding shard-I-of-N/), or shard folders, or their summary.json.
    #[arg(required = true)]
    pub inputs: Vec<PathBuf>,
    /// Number of shards (default: the count the shard folders name).
    #[arg(long, value_name = "N")]
    pub shards: Option<usize>,
    /// The job file (default: the one the shards' run.json names).
    #[arg(long, value_name = "JOB.toml")]
    pub job: Option<PathBuf>,
    /// Trainer of the family network: pass the shards' --backend (it is part of the job hash).
    #[arg(long, value_parser = super::choices::Backend::parser())]
    pub backend: Option<Backend>,
    /// Wait up to this many seconds for shards that have not committed yet.
    #[arg(long, value_name = "SECONDS")]
    pub wait: Option<u64>,
    /// Print the merged summary as one JSON document instead of the table.
    #[arg(long)]
    pub json: bool,
}

fn report(
    summary: &BatchSummary,
    path: &std::path::Path,
    json: bool,
    quiet: bool,
) -> errmap::Result<()> {
    if json {
        let text = serde_json::to_string_pretty(summary)
            .map_err(|e| Diagnostic::Internal(e.to_string()))?;
        outln!("{text}");
    } else {
        out!("{}", summary.table());
        if !quiet {
            outln!("summary: {}", path.display());
        }
    }
    Ok(())
}

/// The trainer for `backend`, its choice explained with --verbose.
fn select(
    backend: Backend,
    model: &ModelConfig,
    globals: Globals,
) -> errmap::Result<Box<dyn errmap::nn::Trainer>> {
    let selection = errmap::backend::select_trainer(backend, model, super::notes(globals))?;
    super::terminal::detail(&format!("trainer: {}", selection.reason));
    Ok(selection.trainer)
}

pub fn run_batch(args: BatchArgs, globals: Globals) -> Result<i32> {
    let file = Job::read(&args.job)?;
    let shard = match &args.shard {
        Some(text) => Some(Shard::parse(text)?),
        None => Shard::from_env(args.shards, |k| std::env::var(k).ok())?,
    };
    let opts = BatchOptions {
        backend: args.backend,
        shard,
        output: super::deprecated::renamed(args.out_dir, args.old_out, "--out", "--out-dir"),
        resume: args.resume,
    };
    for note in batch::renamed_parts(&file.probe_files()?) {
        info!("note: {note}");
    }
    let job = batch::ResolvedJob::new(&file, &opts, &|b, model| select(b, model, globals))?;
    let run = batch::run_job(&job, &Terminal)?;
    if args.resume && !args.json {
        info!(
            "resume: kept {} part(s) of the previous run{}",
            run.reused.len(),
            if run.reused.is_empty() {
                String::new()
            } else {
                format!(" ({})", run.reused.join(", "))
            }
        );
    }
    // A closed stdout must not turn "some parts failed" (exit 1) into success.
    super::ignore_closed_pipe(report(
        &run.summary,
        &run.folder.join("summary.json"),
        args.json,
        globals.quiet,
    ))?;
    Ok(run.summary.exit_code())
}

pub fn run_map(args: MapArgs, globals: Globals) -> Result<i32> {
    let out_dir = super::deprecated::required(args.out_dir, args.old_out, "--out", "--out-dir")?;
    let plan = MapRequest {
        probes: args.probes,
        out_dir: out_dir.clone(),
        normal: args.normal,
        nominal_plane_mm: args.nominal_plane,
        domain: args.domain,
        grid_step_mm: args.grid_step,
        method: args.method,
        spacing_mm: args.spacing,
        k_sigma: args.k_sigma,
        epochs: args.epochs,
        seed: args.seed,
        backend: args.backend,
        max_deviation_mm: args.max_deviation_mm,
        columns: args.columns,
        header_line: args.header_line,
    }
    .plan()?;
    errmap::io::safety::confine_to(&out_dir)?;
    plan.protect_files()?;
    let trainer = select(args.backend, &plan.settings.model, globals)?;
    let summary = batch::map_part(&plan, trainer.as_ref(), &Terminal)?;
    report(
        &summary,
        &out_dir.join("summary.json"),
        args.json,
        globals.quiet,
    )?;
    Ok(0)
}

pub fn run_merge(args: MergeArgs, globals: Globals) -> Result<i32> {
    let req = MergeRequest {
        inputs: args.inputs,
        shards: args.shards,
        job: args.job,
        backend: args.backend,
        wait: args.wait.map(std::time::Duration::from_secs),
    };
    // The merge's trainer is chosen as before the job's model was at hand: with the defaults.
    let select_for = |b: Backend, _: &ModelConfig| select(b, &ModelConfig::default(), globals);
    let run = batch::merge_job(&req, &select_for)?;
    super::ignore_closed_pipe(report(
        &run.summary,
        &run.folder.join("summary.json"),
        args.json,
        globals.quiet,
    ))?;
    Ok(run.summary.exit_code())
}
