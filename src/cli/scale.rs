//! CLI of scale-out: `slurm` (array job + merge job, written or submitted) and `k8s` (Indexed Job + merge Job manifests).

use super::exit::Result;
use super::Globals;
use errmap::batch::k8s::{self, K8sPlan};
use errmap::batch::slurm::{self, SlurmPlan, Word};
use errmap::batch::{self, Job};
use errmap::nn::Backend;
use errmap::Diagnostic;
use std::path::{Path, PathBuf};

#[derive(Debug, clap::Args)]
pub struct SlurmArgs {
    /// The job manifest (its `domain` must be set: shards share one).
    pub job: PathBuf,
    /// Number of shards = array tasks.
    #[arg(long, value_name = "N")]
    pub shards: usize,
    /// Slurm partition of both jobs (default: the cluster's default partition).
    #[arg(long, value_name = "NAME")]
    pub partition: Option<String>,
    /// Time limit of each task and of the merge (Slurm format, e.g. 00:30:00; default: the
    /// partition's limit).
    #[arg(long, value_name = "HH:MM:SS")]
    pub time: Option<String>,
    /// Output folder (default: the job's output): DIR/shard-I-of-N/, DIR/family/, DIR/slurm/.
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
    /// Trainer for every task and the merge (recorded in the job hash).
    #[arg(long, value_parser = super::choices::Backend::parser())]
    pub backend: Option<Backend>,
    /// The errmap binary on the nodes (default: this one).
    #[arg(long, value_name = "PATH")]
    pub errmap: Option<PathBuf>,
    /// Submit only these array task ids (e.g. 1,3 or 0-2): the shards a merge reported missing.
    #[arg(long, value_name = "IDS")]
    pub array: Option<String>,
    /// Print the scripts and the sbatch commands; write and submit nothing.
    #[arg(long, conflicts_with = "submit")]
    pub dry_run: bool,
    /// Submit the array job, then the merge job with --dependency=afterok on it.
    #[arg(long)]
    pub submit: bool,
}

#[derive(Debug, clap::Args)]
pub struct K8sArgs {
    /// The job manifest, as a path inside the volume (relative to --mount); read here too.
    pub job: PathBuf,
    /// Number of shards = completions of the Indexed Job.
    #[arg(long, value_name = "N")]
    pub shards: usize,
    /// Container image with errmap (see Containerfile).
    #[arg(long, value_name = "IMG")]
    pub image: String,
    /// PersistentVolumeClaim holding the job, probes and outputs (ReadWriteMany across nodes).
    #[arg(long, value_name = "NAME")]
    pub pvc: String,
    /// Mount path of the claim in the containers (their working directory).
    #[arg(long, value_name = "PATH", default_value = "/work")]
    pub mount: String,
    /// Output folder of the job inside the volume (default: the job's output).
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
    /// Trainer for every shard and the merge.
    #[arg(long, value_parser = super::choices::Backend::parser())]
    pub backend: Option<Backend>,
    /// Seconds the merge Job waits for the shards.
    #[arg(long, value_name = "SECONDS", default_value_t = 86_400)]
    pub wait: u64,
    /// Retries per shard index and for the merge.
    #[arg(long, value_name = "N", default_value_t = 2)]
    pub retries: u32,
    /// Folder the manifests are written to (default: <out-dir>/k8s, relative to the current folder).
    #[arg(long, value_name = "DIR")]
    pub manifest_dir: Option<PathBuf>,
    /// Old spelling of --manifest-dir.
    #[arg(
        long = "output",
        short = 'o',
        value_name = "DIR",
        hide = true,
        conflicts_with = "manifest_dir"
    )]
    pub old_output: Option<PathBuf>,
    /// Print the manifests instead of writing them.
    #[arg(long)]
    pub dry_run: bool,
}

/// `--backend NAME` when a backend is given, for the nodes' command lines.
fn backend_args(b: Option<Backend>) -> Vec<String> {
    b.iter()
        .flat_map(|b| ["--backend".to_string(), b.name().to_string()])
        .collect()
}

/// The array task's command line: `batch JOB --shard "$TASK/N" --out-dir OUT [--backend B] --quiet`.
fn slurm_shard_args(job: &Path, out: &Path, backend: Option<Backend>) -> Vec<Word> {
    let text = |w: &str| Word::Text(w.to_string());
    let mut args = vec![
        text("batch"),
        text(&job.to_string_lossy()),
        text("--shard"),
        Word::TaskShard,
        text("--out-dir"),
        text(&out.to_string_lossy()),
    ];
    args.extend(backend_args(backend).into_iter().map(Word::Text));
    args.push(text("--quiet"));
    args
}

/// The merge job's command line: `merge OUT --shards N --job JOB [--backend B] --quiet`.
fn slurm_merge_args(
    job: &Path,
    out: &Path,
    shards: usize,
    backend: Option<Backend>,
) -> Vec<String> {
    let mut args = vec![
        "merge".to_string(),
        out.to_string_lossy().into(),
        "--shards".to_string(),
        shards.to_string(),
        "--job".to_string(),
        job.to_string_lossy().into(),
    ];
    args.extend(backend_args(backend));
    args.push("--quiet".to_string());
    args
}

fn absolute(p: &Path) -> errmap::Result<PathBuf> {
    std::path::absolute(p).map_err(|e| Diagnostic::io("resolve", p, e))
}

pub fn run_slurm(args: SlurmArgs, _globals: Globals) -> Result<i32> {
    batch::check_shard_count(args.shards)?;
    let file = Job::read(&args.job)?;
    batch::require_shard_domain(&file)?;
    if let Some(ids) = &args.array {
        slurm::check_array_ids(ids, args.shards)?;
    }
    let errmap = match args.errmap {
        Some(p) => p,
        None => {
            std::env::current_exe().map_err(|e| Diagnostic::io("find the running", "errmap", e))?
        }
    };
    let out = super::deprecated::renamed(args.out_dir, args.old_out, "--out", "--out-dir")
        .unwrap_or_else(|| file.output_dir());
    let job = args
        .job
        .canonicalize()
        .map_err(|e| Diagnostic::read(&args.job, e))?;
    let out = absolute(&out)?;
    let plan = SlurmPlan {
        errmap,
        shard_args: slurm_shard_args(&job, &out, args.backend),
        merge_args: slurm_merge_args(&job, &out, args.shards, args.backend),
        out,
        family: file.job.family.clone(),
        shards: args.shards,
        partition: args.partition,
        time: args.time,
    };
    let array = args.array.as_deref();
    let shards_cmd = format!("sbatch {}", plan.sbatch_shards_args(array).join(" "));
    let merge_cmd = format!(
        "sbatch {}",
        plan.sbatch_merge_args("<ARRAY_JOB_ID>").join(" ")
    );
    if args.dry_run {
        let dir = plan.slurm_dir();
        println!(
            "# {}\n{}",
            dir.join("shards.sbatch").display(),
            plan.shards_script()
        );
        println!(
            "# {}\n{}",
            dir.join("merge.sbatch").display(),
            plan.merge_script()
        );
        println!("# submit:\n{shards_cmd}\n{merge_cmd}");
        return Ok(0);
    }
    let [shards_file, merge_file] = slurm::write_scripts(&plan)?;
    if !args.submit {
        println!(
            "wrote {} and {}",
            shards_file.display(),
            merge_file.display()
        );
        println!("submit with:\n  {shards_cmd}\n  {merge_cmd}");
        return Ok(0);
    }
    let (array_id, merge_id) = slurm::submit(&plan, array)?;
    info!(
        "slurm: array job {array_id} ({} shards), merge job {merge_id} after it",
        args.shards
    );
    println!("{array_id} {merge_id}");
    Ok(0)
}

pub fn run_k8s(args: K8sArgs, _globals: Globals) -> Result<i32> {
    batch::check_shard_count(args.shards)?;
    let file = Job::read(&args.job)?;
    batch::require_shard_domain(&file)?;
    let out = super::deprecated::renamed(args.out_dir, args.old_out, "--out", "--out-dir")
        .unwrap_or_else(|| file.output_dir());
    let manifest_dir = super::deprecated::old_output_folder(
        args.manifest_dir,
        args.old_output,
        "--manifest-dir",
        "shards-job.json and merge-job.json",
    )?;
    let (job, out_text): (String, String) = (
        args.job.to_string_lossy().into(),
        out.to_string_lossy().into(),
    );
    // Each completion's index comes from JOB_COMPLETION_INDEX; the merge waits on the volume.
    let mut shard_args = vec![
        "batch".to_string(),
        job.clone(),
        "--shards".to_string(),
        args.shards.to_string(),
        "--out-dir".to_string(),
        out_text.clone(),
        "--quiet".to_string(),
    ];
    shard_args.extend(backend_args(args.backend));
    let mut merge_args = vec![
        "merge".to_string(),
        out_text,
        "--shards".to_string(),
        args.shards.to_string(),
        "--job".to_string(),
        job,
        "--wait".to_string(),
        args.wait.to_string(),
        "--quiet".to_string(),
    ];
    merge_args.extend(backend_args(args.backend));
    let plan = K8sPlan {
        family: file.job.family.clone(),
        shards: args.shards,
        image: args.image,
        pvc: args.pvc,
        mount: args.mount,
        shard_args,
        merge_args,
        retries: args.retries,
    };
    if args.dry_run {
        for (_, text) in k8s::manifest_files(&plan)? {
            println!("{text}");
        }
        return Ok(0);
    }
    let dir = manifest_dir.unwrap_or_else(|| out.join("k8s"));
    let paths = k8s::write_manifests(&plan, &dir)?;
    info!("apply with: kubectl apply -f {}", dir.display());
    for path in paths {
        println!("{}", path.display());
    }
    Ok(0)
}
