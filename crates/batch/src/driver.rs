//! A job run from start to commit (`errmap batch`) and the reduce of a sharded job (`errmap merge`): staging, `--resume`, the manifest, the family rebuilt from the shards.

use crate::commit::{self, Staging};
use crate::journal::{self, Finished, Journal};
use crate::manifest::{self, PartRecord, RunManifest, RUN_MANIFEST};
use crate::reduce::{self, PartReduce, REDUCE_FILE};
use crate::resolve::{with_backend, ResolvedJob, SelectTrainer};
use crate::stages::report::write_report;
use crate::summary::{BatchSummary, PartSummary, ToolpathSummary};
use crate::{BatchOptions, JobError, JobFile, MergeError, RunError, Shard};
use errmap_core::error::{Diagnostic, Location, Result};
use errmap_core::progress::Reporter;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// A committed run: its summary and folder, and which parts `--resume` kept.
#[derive(Debug)]
pub struct JobRun {
    /// What the run did, as written to its `summary.json`.
    pub summary: BatchSummary,
    /// The committed run folder (the shard's own `shard-I-of-N` folder for a shard).
    pub folder: PathBuf,
    /// Parts kept from the previous run by `--resume`, by name; empty without it.
    pub reused: Vec<String>,
}

/// Sharding and `--resume` put parts mapped by different processes into one family: they
/// must share one domain, which only the job can fix.
fn require_domain(file: &JobFile, what: &str) -> Result<()> {
    if file.job.domain.is_none() {
        return Err(Diagnostic::input(
            Location::cell(&file.path, 1, "domain"),
            format!("{what} needs a fixed map domain, and the job has no `domain`"),
            "add domain = [u_min, v_min, u_max, v_max] (mm) to the job; an unsharded run prints the probes' box as domain_mm in summary.json",
        ));
    }
    Ok(())
}

/// Every input of the job: probe files, toolpaths and the job file itself.
fn job_inputs(file: &JobFile) -> Result<Vec<PathBuf>> {
    let mut inputs = file.probe_files()?;
    inputs.extend(file.toolpath_files());
    inputs.push(file.path.clone());
    Ok(inputs)
}

/// `p` with the prefix `from` replaced by `to`.
fn relocate(p: &mut PathBuf, from: &Path, to: &Path) {
    if let Ok(rest) = p.strip_prefix(from) {
        *p = if rest.as_os_str().is_empty() {
            to.to_path_buf()
        } else {
            to.join(rest)
        };
    }
}

fn relocate_summary(summary: &mut BatchSummary, from: &Path, to: &Path) {
    for p in &mut summary.parts {
        if let Some(d) = &mut p.output_dir {
            relocate(d, from, to);
        }
    }
    if let Some(f) = &mut summary.family_map {
        relocate(&mut f.output_dir, from, to);
    }
    for t in &mut summary.toolpaths {
        relocate(&mut t.output, from, to);
    }
}

/// Run a job (or one shard of it) into its folder and commit it: the run is written into a
/// staging folder, `run.json` last, and the staging folder then replaces the old folder.
pub fn run_job(job: &ResolvedJob, reporter: &dyn Reporter) -> Result<JobRun, RunError> {
    let file = &job.file;
    let opened = OpenRun::begin(job)?;
    let folders = &opened.folders;
    let (plan, kept) = plan_resumed(job, folders, &opened.sources, &opened.input_hashes)?;
    for dir in &opened.stale {
        commit::remove_path(dir)?;
    }
    let journal = Journal::create(&folders.staging, &opened.job_hash, &opened.input_hashes)?;
    for k in &kept {
        journal.record(k)?;
    }
    let reused: Vec<String> = kept.iter().map(|k| k.part.part.clone()).collect();
    let recorder = PartJournal {
        folders,
        journal: &journal,
        input_hashes: &opened.input_hashes,
    };
    let on_part = |p: &PartSummary, t: &[ToolpathSummary]| recorder.record(p, t);
    let trainer = job.trainer.as_ref();
    let mut summary = crate::execute_with(&plan, trainer, reporter, &on_part)?;
    relocate_summary(&mut summary, &folders.staging, &folders.target);
    if !kept.is_empty() {
        add_reused(&mut summary, file, &folders.staging, &kept)?;
        if job.opts.shard.is_none() {
            reduce_resumed_family(&mut summary, job, folders)?;
        }
    }
    journal.remove()?;
    let kind = if job.opts.shard.is_some() {
        "shard"
    } else {
        "batch"
    };
    let sealed = Sealed {
        kind,
        job_hash: opened.job_hash,
        input_hashes: opened.input_hashes,
        reused: &reused,
    };
    seal_run(file, &folders.staging, &summary, sealed)?;
    let folder = folders.target.clone();
    opened.staging.commit()?;
    Ok(JobRun {
        summary,
        folder,
        reused,
    })
}

/// A run begun: its job hash and input hashes, its staging folder (and the stale staging
/// folders of interrupted runs) and where `--resume` may find finished parts.
struct OpenRun {
    job_hash: String,
    input_hashes: BTreeMap<PathBuf, String>,
    staging: Staging,
    stale: Vec<PathBuf>,
    folders: RunFolders,
    sources: Vec<Source>,
}

impl OpenRun {
    /// Check the job's inputs, hash them, open the staging folder and find the finished parts
    /// `--resume` may keep.
    fn begin(job: &ResolvedJob) -> Result<OpenRun, RunError> {
        let (file, opts) = (&job.file, &job.opts);
        require_shared_domain(file, opts)?;
        let probe_files = file.probe_files()?;
        let job_hash = manifest::job_hash(&file.job, &probe_files, &file.base_dir())?;
        let out = job.output();
        let target = match opts.shard {
            Some(s) => out.join(s.folder_name()),
            None => out.clone(),
        };
        let inputs = job_inputs(file)?;
        commit::check_inputs_outside(&out, &inputs).map_err(RunError::output)?;
        let previous = if opts.resume {
            RunManifest::read(&target)?.filter(|m| m.job_hash == job_hash)
        } else {
            None
        };
        let input_hashes = manifest::hash_inputs(&inputs)?;
        let (staging, stale) = if opts.resume {
            Staging::begin_keeping_stale(&target).map_err(RunError::output)?
        } else {
            (
                Staging::begin(&target).map_err(RunError::output)?,
                Vec::new(),
            )
        };
        let folders = RunFolders {
            staging: staging.path().to_path_buf(),
            target,
        };
        let sources = resume_sources(previous, &folders, &stale, &job_hash);
        Ok(OpenRun {
            job_hash,
            input_hashes,
            staging,
            stale,
            folders,
            sources,
        })
    }
}

/// Finished parts to keep: the committed run's, then those the journals of interrupted runs
/// into the same folder record.
fn resume_sources(
    previous: Option<RunManifest>,
    folders: &RunFolders,
    stale: &[PathBuf],
    job_hash: &str,
) -> Vec<Source> {
    let mut sources: Vec<Source> = Vec::new();
    if let Some(m) = previous {
        let toolpaths = BatchSummary::read(&folders.target.join("summary.json"))
            .map(|s| toolpaths_by_part(s.toolpaths))
            .unwrap_or_default();
        sources.push(Source {
            manifest: m,
            folder: folders.target.clone(),
            toolpaths,
        });
    }
    for dir in stale {
        if let Some((m, toolpaths)) = journal::read(dir).filter(|(m, _)| m.job_hash == job_hash) {
            sources.push(Source {
                manifest: m,
                folder: dir.clone(),
                toolpaths,
            });
        }
    }
    sources
}

/// Each part, once written: its summary naming its final folder, then its journal line.
struct PartJournal<'a> {
    folders: &'a RunFolders,
    journal: &'a Journal,
    input_hashes: &'a BTreeMap<PathBuf, String>,
}

impl PartJournal<'_> {
    fn record(&self, p: &PartSummary, toolpaths: &[ToolpathSummary]) -> Result<()> {
        let folders = self.folders;
        let mut p = p.clone();
        if let Some(d) = &mut p.output_dir {
            relocate(d, &folders.staging, &folders.target);
        }
        let mut toolpaths = toolpaths.to_vec();
        for t in &mut toolpaths {
            relocate(&mut t.output, &folders.staging, &folders.target);
        }
        let dir = folders.staging.join(&p.part);
        errmap_core::io::write_json(&dir.join("summary.json"), &p)?;
        let outputs = manifest::hash_tree(&dir)?
            .into_iter()
            .map(|(k, v)| (format!("{}/{k}", p.part), v))
            .collect();
        let input_sha256 = self
            .input_hashes
            .get(&p.probe_file)
            .cloned()
            .unwrap_or_default();
        self.journal.record(&Finished {
            part: PartRecord {
                part: p.part.clone(),
                probe_file: p.probe_file.clone(),
                input_sha256,
                ok: true,
                reused: false,
                outputs,
            },
            toolpaths,
        })
    }
}

/// Sharding and `--resume` put parts mapped by different processes into one family.
fn require_shared_domain(file: &JobFile, opts: &BatchOptions) -> Result<()> {
    if let Some(s) = opts.shard {
        require_domain(
            file,
            &format!(
                "{} {}/{}",
                errmap_core::setting::words(crate::Setting::Shard),
                s.index,
                s.count
            ),
        )?;
    }
    if opts.resume {
        require_domain(file, &errmap_core::setting::words(crate::Setting::Resume))?;
    }
    Ok(())
}

/// Where a run is written (`staging`) and the folder it then replaces (`target`).
struct RunFolders {
    staging: PathBuf,
    target: PathBuf,
}

/// The plan of the parts left to map after `--resume` kept those of the previous run that
/// still match (hard-linked into the staging folder), and the names of the kept parts.
fn plan_resumed(
    job: &ResolvedJob,
    folders: &RunFolders,
    sources: &[Source],
    input_hashes: &BTreeMap<PathBuf, String>,
) -> Result<(crate::Plan, Vec<Finished>)> {
    let mut plan = job.plan(&folders.staging)?;
    let reused = reuse_parts(sources, &folders.staging, &plan, input_hashes)?;
    let all_parts = plan.parts.clone();
    plan.parts
        .retain(|p| !reused.iter().any(|r| r.part.part == p.name));
    if !reused.is_empty() {
        // The family needs every part: the reduce builds it after the run. Parts that start
        // from the family network get it rebuilt from every part, as the whole run builds it.
        plan.family_dir = None;
        if plan.family_parts.is_empty() {
            plan.family_parts = all_parts;
        }
    }
    Ok((plan, reused))
}

/// The family of a resumed unsharded run, rebuilt from every part's reduce inputs.
fn reduce_resumed_family(
    summary: &mut BatchSummary,
    job: &ResolvedJob,
    folders: &RunFolders,
) -> Result<()> {
    let dir = &folders.staging;
    let full = job.plan(dir)?;
    let paths = reduce_paths(summary, dir, None)?;
    let outcome = reduce::reduce_family(
        &part_source(&paths),
        &full.settings,
        &domain_of(&job.file)?,
        &dir.join("family"),
        full.toolpaths.as_ref(),
        job.trainer.as_ref(),
    )?;
    summary.family_map = outcome.family;
    summary.toolpaths.extend(outcome.toolpaths);
    relocate_summary(summary, dir, &folders.target);
    Ok(())
}

/// What a run's manifest records besides its files.
struct Sealed<'a> {
    kind: &'a str,
    job_hash: String,
    input_hashes: BTreeMap<PathBuf, String>,
    reused: &'a [String],
}

/// The run's last files in its staging folder: `summary.json`, the timing, `report.html` and
/// `run.json` (last: it vouches for the rest).
fn seal_run(file: &JobFile, dir: &Path, summary: &BatchSummary, sealed: Sealed) -> Result<()> {
    crate::json_out::write_json(&dir.join("summary.json"), summary)?;
    if let Some(timing) = &summary.timing {
        timing.write(dir)?;
    }
    let files = manifest::hash_tree(dir)?;
    let mut m = RunManifest::build(
        files,
        sealed.kind,
        sealed.job_hash,
        summary,
        sealed.input_hashes,
        sealed.reused,
    )?;
    m.metadata = file.job.metadata_json();
    m.k_sigma = Some(file.job.clean.k_sigma);
    write_report(dir, &mut m, summary)?;
    m.write(dir)
}

fn domain_of(file: &JobFile) -> Result<errmap_core::geom::Domain> {
    file.job
        .domain()
        .ok_or_else(|| Diagnostic::Internal("the job's domain was checked above".into()))
}

/// Where `--resume` may find finished parts: a committed run (its manifest) or an interrupted
/// one (its journal), its folder and its parts' toolpaths.
struct Source {
    manifest: RunManifest,
    folder: PathBuf,
    toolpaths: BTreeMap<String, Vec<ToolpathSummary>>,
}

/// A summary's toolpaths by the part whose map compensated them.
fn toolpaths_by_part(toolpaths: Vec<ToolpathSummary>) -> BTreeMap<String, Vec<ToolpathSummary>> {
    let mut by_part: BTreeMap<String, Vec<ToolpathSummary>> = BTreeMap::new();
    for t in toolpaths {
        by_part.entry(t.map.clone()).or_default().push(t);
    }
    by_part
}

/// Parts of earlier runs kept by `--resume` (hard-linked, or copied, into the staging folder):
/// same probe file, same input hash, mapped, every output unchanged; the first source that has
/// a part gives it. Nothing is kept from a source whose toolpaths or job file differ.
fn reuse_parts(
    sources: &[Source],
    staging: &Path,
    plan: &crate::Plan,
    input_hashes: &BTreeMap<PathBuf, String>,
) -> Result<Vec<Finished>> {
    let mut reused: Vec<Finished> = Vec::new();
    for src in sources {
        let prev = &src.manifest;
        let others_same = input_hashes
            .iter()
            .filter(|(f, _)| !plan.parts.iter().any(|p| &p.probe_file == *f))
            .all(|(f, h)| prev.inputs.get(f) == Some(h));
        if !others_same {
            continue;
        }
        for part in &plan.parts {
            if reused.iter().any(|r| r.part.part == part.name) {
                continue;
            }
            let Some(rec) = prev.parts.iter().find(|r| r.part == part.name) else {
                continue;
            };
            let same_input = rec.probe_file == part.probe_file
                && input_hashes.get(&part.probe_file) == Some(&rec.input_sha256);
            if rec.ok && same_input && RunManifest::outputs_match(&src.folder, rec) {
                for rel in rec.outputs.keys() {
                    let (from, to) = (src.folder.join(rel), staging.join(rel));
                    if let Some(parent) = to.parent() {
                        std::fs::create_dir_all(parent)
                            .map_err(|e| Diagnostic::io("create folder", parent, e))?;
                    }
                    if std::fs::hard_link(&from, &to).is_err() {
                        std::fs::copy(&from, &to)
                            .map_err(|e| Diagnostic::io("copy the earlier output to", &to, e))?;
                    }
                }
                reused.push(Finished {
                    part: PartRecord {
                        reused: true,
                        ..rec.clone()
                    },
                    toolpaths: src.toolpaths.get(&part.name).cloned().unwrap_or_default(),
                });
            }
        }
    }
    Ok(reused)
}

/// The kept parts' lines and per-part toolpaths, in batch order.
fn add_reused(
    summary: &mut BatchSummary,
    file: &JobFile,
    staging: &Path,
    kept: &[Finished],
) -> Result<()> {
    for k in kept {
        let path = staging.join(&k.part.part).join("summary.json");
        let text = errmap_core::io::read_text(&path)?;
        let p: PartSummary = serde_json::from_str(&text).map_err(|e| {
            Diagnostic::input(
                Location::file(&path),
                format!("not a part summary: {e}"),
                format!(
                    "rerun without {}",
                    errmap_core::setting::words(crate::Setting::Resume)
                ),
            )
        })?;
        summary.parts.push(p);
        summary.toolpaths.extend(k.toolpaths.iter().cloned());
    }
    let order = file.probe_files()?;
    summary.parts.sort_by_key(|p| {
        order
            .iter()
            .position(|f| *f == p.probe_file)
            .unwrap_or(usize::MAX)
    });
    summary.failed_parts = summary.parts.iter().filter(|p| !p.ok).count();
    Ok(())
}

/// The reduce records at `paths`, read one at a time.
fn part_source(paths: &[PathBuf]) -> reduce::PartSource<'_> {
    reduce::PartSource {
        count: paths.len(),
        load: Box::new(move |k| PartReduce::read(&paths[k])),
    }
}

/// The reduce inputs of the mapped parts of `summary`, in its (batch) order:
/// `<folder>/<part>/reduce.json`, each checked against its hash when a manifest is given.
fn reduce_paths(
    summary: &BatchSummary,
    folder: &Path,
    manifest: Option<&RunManifest>,
) -> Result<Vec<PathBuf>> {
    let mut parts = Vec::new();
    for p in summary.parts.iter().filter(|p| p.ok) {
        let rel = format!("{}/{REDUCE_FILE}", p.part);
        let path = folder.join(&rel);
        if let Some(m) = manifest {
            let want = m
                .parts
                .iter()
                .find(|r| r.part == p.part)
                .and_then(|r| r.outputs.get(&rel));
            if want != Some(&manifest::sha256_file(&path)?) {
                return Err(Diagnostic::input(
                    Location::file(&path),
                    "the file differs from the one its shard's run.json lists",
                    "rerun that shard",
                ));
            }
        }
        parts.push(path);
    }
    Ok(parts)
}

/// What `errmap merge` reduces.
#[derive(Debug, Clone, Default)]
pub struct MergeRequest {
    /// The batch's output folder (holding `shard-I-of-N/`), shard folders, or their
    /// `summary.json` / `run.json` files.
    pub inputs: Vec<PathBuf>,
    /// The number of shards, when no shard folder may exist yet.
    pub shards: Option<usize>,
    /// The job file, instead of the one the shards' manifests name.
    pub job: Option<PathBuf>,
    /// `--backend` for the family network the merge trains, replacing the job's; `None` =
    /// the job's.
    pub backend: Option<errmap_maps::nn::Backend>,
    /// Wait this long for missing shards before reporting them.
    pub wait: Option<std::time::Duration>,
}

/// Shard folders by shard index.
type ShardFolders = BTreeMap<usize, (Shard, PathBuf)>;

/// The batch folder and its shard folders (`shard-I-of-N` → Shard) named by the inputs.
/// With `only_count`, folders of another split are left out.
fn shard_folders(
    inputs: &[PathBuf],
    only_count: Option<usize>,
) -> Result<(PathBuf, ShardFolders), MergeError> {
    let mut found: Vec<(Shard, PathBuf)> = Vec::new();
    for input in inputs {
        let dir = if input.is_file() {
            input.parent().map(Path::to_path_buf).unwrap_or_default()
        } else {
            input.clone()
        };
        let name = dir.file_name().map(|n| n.to_string_lossy().to_string());
        if let Some(s) = name.as_deref().and_then(Shard::from_folder_name) {
            found.push((s, dir));
            continue;
        }
        let entries =
            std::fs::read_dir(&dir).map_err(|e| MergeError::Read(Diagnostic::read(&dir, e)))?;
        for entry in entries.flatten() {
            let n = entry.file_name().to_string_lossy().to_string();
            if let Some(s) = Shard::from_folder_name(&n) {
                if entry.path().is_dir() {
                    found.push((s, entry.path()));
                }
            }
        }
        let merged_already = RunManifest::read(&dir)
            .ok()
            .flatten()
            .is_some_and(|m| m.kind == "reduce");
        if !found.iter().any(|(_, p)| p.starts_with(&dir)) && merged_already {
            return Err(MergeError::Split(Diagnostic::usage(
                format!(
                    "{} is a merged run already: its shards' parts are in it and their folders are gone",
                    dir.display()
                ),
                format!("to merge anew, run the shards again (errmap batch JOB {} I/N), then merge", errmap_core::setting::words(crate::Setting::Shard)),
            )));
        }
        if !found.iter().any(|(_, p)| p.starts_with(&dir)) && only_count.is_none() {
            return Err(MergeError::Missing(Diagnostic::usage(
                format!("{} holds no shard folder (shard-I-of-N)", dir.display()),
                format!("pass the batch's output folder, or run the shards first with errmap batch {} I/N", errmap_core::setting::words(crate::Setting::Shard)),
            )));
        }
    }
    if let Some(n) = only_count {
        found.retain(|(s, _)| s.count == n);
    }
    let batch_dir = found
        .first()
        .and_then(|(_, p)| p.parent())
        .map(Path::to_path_buf)
        .unwrap_or_default();
    let mut by_index = BTreeMap::new();
    let counts: std::collections::BTreeSet<usize> = found.iter().map(|(s, _)| s.count).collect();
    if counts.len() > 1 {
        return Err(MergeError::Split(Diagnostic::usage(
            format!("the shard folders are of different splits (of {counts:?})"),
            format!(
                "remove the folders of an earlier split, or pass {} N to merge the split of N",
                errmap_core::setting::words(crate::Setting::Shards)
            ),
        )));
    }
    for (s, p) in found {
        if p.parent() != Some(batch_dir.as_path()) {
            return Err(MergeError::Split(Diagnostic::usage(
                format!(
                    "shard folder {} is not in {}",
                    p.display(),
                    batch_dir.display()
                ),
                "merge the shards of one output folder",
            )));
        }
        by_index.insert(s.index, (s, p));
    }
    Ok((batch_dir, by_index))
}

/// Shard indexes of `0..count` that have no committed run.
fn missing_shards(folders: &ShardFolders, count: usize) -> Vec<usize> {
    (0..count)
        .filter(|i| {
            !folders
                .get(i)
                .is_some_and(|(s, p)| s.count == count && p.join(RUN_MANIFEST).is_file())
        })
        .collect()
}

/// The shard count: `--shards`, or the count every shard folder names.
fn shard_count(req: &MergeRequest, folders: &ShardFolders) -> Result<usize, MergeError> {
    req.shards
        .or(folders.values().next().map(|(s, _)| s.count))
        .ok_or_else(|| {
            MergeError::Missing(Diagnostic::usage(
                "no shard folder found",
                format!(
                    "pass {} N or the shards' folder",
                    errmap_core::setting::words(crate::Setting::Shards)
                ),
            ))
        })
}

/// Reduce the shards of a job: check they are one job's and complete, merge their summaries,
/// fit the family network, write the family folder, the merged `summary.json` and `run.json`.
pub fn merge_job(req: &MergeRequest, select: &SelectTrainer) -> Result<JobRun, MergeError> {
    let (batch_dir, folders) = complete_shards(req)?;
    let manifests = shard_manifests(&folders)?;
    let file = merged_job(req, &manifests[0], &batch_dir)?;
    let shards = Shards {
        folders: &folders,
        manifests: &manifests,
    };
    reduce_into(req, &file, &batch_dir, shards, select)
}

/// The batch folder and its shard folders once every shard has committed its run (waiting up
/// to `req.wait` for them); the missing shards are an error naming how to rerun them.
fn complete_shards(req: &MergeRequest) -> Result<(PathBuf, ShardFolders), MergeError> {
    let start = std::time::Instant::now();
    loop {
        let (batch_dir, folders) = shard_folders(&req.inputs, req.shards)?;
        let count = shard_count(req, &folders)?;
        let missing = missing_shards(&folders, count);
        if missing.is_empty() {
            return Ok((batch_dir, folders));
        }
        if req.wait.is_some_and(|w| start.elapsed() < w) {
            std::thread::sleep(std::time::Duration::from_secs(2));
            continue;
        }
        let ids = missing
            .iter()
            .map(|i| i.to_string())
            .collect::<Vec<_>>()
            .join(",");
        return Err(MergeError::Missing(Diagnostic::usage(
            format!(
                "shards [{ids}] of {count} have no complete run in {} (Slurm array task ids {ids}; Kubernetes completion indexes {ids})",
                batch_dir.display()
            ),
            format!("rerun only those: errmap slurm JOB {shards} {count} {array} {ids} {submit}, or errmap batch JOB {shard} I/{count} for each; then merge again", submit = errmap_core::setting::words(crate::Setting::Submit), shards = errmap_core::setting::words(crate::Setting::Shards), array = errmap_core::setting::words(crate::Setting::Array), shard = errmap_core::setting::words(crate::Setting::Shard)),
        )));
    }
}

/// Every shard's manifest, checked to be that shard's run and of one job.
fn shard_manifests(folders: &ShardFolders) -> Result<Vec<RunManifest>, MergeError> {
    let mut manifests = Vec::new();
    for (s, dir) in folders.values() {
        let m = RunManifest::read(dir)?.ok_or_else(|| {
            MergeError::Internal(Diagnostic::Internal(format!(
                "{} lost its run.json",
                dir.display()
            )))
        })?;
        if m.shard != Some([s.index, s.count]) {
            return Err(MergeError::Mismatch(Diagnostic::input(
                Location::file(dir.join(RUN_MANIFEST)),
                format!(
                    "the run in {} is not shard {}/{}",
                    dir.display(),
                    s.index,
                    s.count
                ),
                format!(
                    "let errmap batch {} name the folders",
                    errmap_core::setting::words(crate::Setting::Shard)
                ),
            )));
        }
        manifests.push(m);
    }
    let first = &manifests[0];
    for (m, (_, dir)) in manifests.iter().zip(folders.values()) {
        if m.job_hash != first.job_hash {
            return Err(MergeError::Mismatch(Diagnostic::input(
                Location::file(dir.join(RUN_MANIFEST)),
                format!(
                    "shard {} belongs to another job (job hash {}…, not {}… of {})",
                    dir.display(),
                    &m.job_hash[..12],
                    &first.job_hash[..12],
                    folders[&0].1.display()
                ),
                "rerun that shard with the same job file and options, then merge again",
            )));
        }
    }
    Ok(manifests)
}

/// The job the shards ran (`--job` or the one their manifests name), checked against their
/// job hash, with a fixed domain and its inputs outside the batch folder.
fn merged_job(
    req: &MergeRequest,
    first: &RunManifest,
    batch_dir: &Path,
) -> Result<JobFile, MergeError> {
    let job_path = req
        .job
        .clone()
        .or_else(|| first.job.clone())
        .ok_or_else(|| {
            MergeError::Missing(Diagnostic::usage(
                "the shards name no job file",
                format!(
                    "pass {} JOB.toml",
                    errmap_core::setting::words(crate::Setting::Job)
                ),
            ))
        })?;
    let file = with_backend(&crate::Job::read(&job_path)?, req.backend);
    require_domain(&file, "the reduce").map_err(|d| MergeError::Job(JobError::Value(d)))?;
    commit::check_inputs_outside(batch_dir, &job_inputs(&file)?)
        .map_err(|d| MergeError::Run(RunError::output(d)))?;
    let hash = manifest::job_hash(&file.job, &file.probe_files()?, &file.base_dir())?;
    if hash != first.job_hash {
        return Err(MergeError::Mismatch(Diagnostic::input(
            Location::file(&job_path),
            "this job (with these options) is not the one the shards ran",
            format!(
                "pass the shards' job file unchanged and the same {} as the shards",
                errmap_core::setting::words(errmap_maps::Setting::Backend)
            ),
        )));
    }
    Ok(file)
}

/// The shards of a merge: their folders and committed manifests, in shard order.
#[derive(Clone, Copy)]
struct Shards<'a> {
    folders: &'a ShardFolders,
    manifests: &'a [RunManifest],
}

/// Merge the shards' summaries and write the family, `summary.json` and `run.json` into the
/// batch folder (the family folder is replaced as a whole; `run.json` is written last).
fn reduce_into(
    req: &MergeRequest,
    file: &JobFile,
    batch_dir: &Path,
    shards: Shards,
    select: &SelectTrainer,
) -> Result<JobRun, MergeError> {
    let Shards { folders, manifests } = shards;
    let summaries = shard_summaries(folders, manifests)?;
    let mut merged = crate::merge(&summaries)?;
    let paths = shard_reduce_parts(&merged, &summaries, folders, manifests)?;
    let opts = BatchOptions {
        backend: req.backend,
        ..BatchOptions::default()
    };
    let job = ResolvedJob::new(file, &opts, select)?;
    let plan = job.plan(batch_dir)?;
    flatten_shards(batch_dir, shards, &mut merged)?;
    let family_dir = batch_dir.join("family");
    let staging = Staging::begin_owned(&family_dir)?;
    let outcome = reduce::reduce_family(
        &part_source(&paths),
        &plan.settings,
        &domain_of(file)?,
        staging.path(),
        plan.toolpaths.as_ref(),
        job.trainer.as_ref(),
    )?;
    let staged = staging.path().to_path_buf();
    merged.family_map = outcome.family;
    merged.toolpaths.extend(outcome.toolpaths);
    relocate_summary(&mut merged, &staged, &family_dir);
    staging.commit()?;
    crate::json_out::write_json(&batch_dir.join("summary.json"), &merged)?;
    let mut m = reduce_manifest(batch_dir, folders, manifests, &merged)?;
    m.job = Some(file.path.clone());
    m.metadata = file.job.metadata_json();
    m.k_sigma = Some(file.job.clean.k_sigma);
    write_report(batch_dir, &mut m, &merged)?;
    m.write(batch_dir)?;
    for (_, dir) in folders.values() {
        std::fs::remove_dir_all(dir)
            .map_err(|e| Diagnostic::io("remove the merged shard folder", dir, e))?;
    }
    Ok(JobRun {
        summary: merged,
        folder: batch_dir.to_path_buf(),
        reused: Vec::new(),
    })
}

/// The batch folder laid out as one machine's run: the run it held before removed (a stale
/// `run.json` must not vouch for a family being replaced), each shard's parts at `<part>/`,
/// and each part's summary naming its new folder.
fn flatten_shards(batch_dir: &Path, shards: Shards, merged: &mut BatchSummary) -> Result<()> {
    let manifest_path = batch_dir.join(RUN_MANIFEST);
    if let Some(old) = RunManifest::read(batch_dir).ok().flatten() {
        remove_part_outputs(batch_dir, &old)?;
    }
    if manifest_path.exists() {
        std::fs::remove_file(&manifest_path)
            .map_err(|e| Diagnostic::io("remove the earlier manifest", &manifest_path, e))?;
    }
    // Each shard's parts at `<part>/` in the batch folder, as one machine writes them: their
    // files hard-linked out of the shard folders, which go once `run.json` is written.
    link_parts_flat(batch_dir, shards.folders, shards.manifests)?;
    for (_, dir) in shards.folders.values() {
        relocate_summary(merged, dir, batch_dir);
    }
    // Each part's own summary names its new folder (a new file: the shard's stays as it was).
    for p in merged.parts.iter().filter(|p| p.ok) {
        let path = batch_dir.join(&p.part).join("summary.json");
        std::fs::remove_file(&path)
            .map_err(|e| Diagnostic::io("replace the part summary", &path, e))?;
        errmap_core::io::write_json(&path, p)?;
    }
    Ok(())
}

/// Every shard's summary, checked against its manifest, in shard order.
fn shard_summaries(
    folders: &ShardFolders,
    manifests: &[RunManifest],
) -> Result<Vec<(PathBuf, BatchSummary)>> {
    let mut summaries = Vec::new();
    for ((_, dir), m) in folders.values().zip(manifests) {
        let path = dir.join("summary.json");
        if m.files.get("summary.json") != Some(&manifest::sha256_file(&path)?) {
            return Err(Diagnostic::input(
                Location::file(&path),
                "the summary differs from the one the shard's run.json lists",
                "rerun that shard",
            ));
        }
        summaries.push((path.clone(), BatchSummary::read(&path)?));
    }
    Ok(summaries)
}

/// The reduce inputs of the merged summary's mapped parts, in batch order, each from its own
/// shard's folder.
fn shard_reduce_parts(
    merged: &BatchSummary,
    summaries: &[(PathBuf, BatchSummary)],
    folders: &ShardFolders,
    manifests: &[RunManifest],
) -> Result<Vec<PathBuf>> {
    let mut parts = Vec::new();
    for p in merged.parts.iter().filter(|p| p.ok) {
        let (k, _) = summaries
            .iter()
            .enumerate()
            .find(|(_, (_, s))| s.parts.iter().any(|q| q.part == p.part))
            .ok_or_else(|| Diagnostic::Internal(format!("part {} has no shard", p.part)))?;
        let one = BatchSummary {
            parts: vec![p.clone()],
            ..summaries[k].1.clone()
        };
        let dir = &folders.values().nth(k).expect("one folder per summary").1;
        parts.extend(reduce_paths(&one, dir, Some(&manifests[k]))?);
    }
    Ok(parts)
}

/// Hard-link (or copy) every shard's part files to the same path in the batch folder
/// (`shard-I-of-N/<part>/map.csv` → `<part>/map.csv`), replacing what an interrupted merge left.
fn link_parts_flat(
    batch_dir: &Path,
    folders: &ShardFolders,
    manifests: &[RunManifest],
) -> Result<()> {
    for ((_, dir), m) in folders.values().zip(manifests) {
        for rel in m.parts.iter().flat_map(|r| r.outputs.keys()) {
            let (from, to) = (dir.join(rel), batch_dir.join(rel));
            if let Some(parent) = to.parent() {
                std::fs::create_dir_all(parent)
                    .map_err(|e| Diagnostic::io("create folder", parent, e))?;
            }
            match std::fs::remove_file(&to) {
                Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                    return Err(Diagnostic::io("replace the earlier output", &to, e))
                }
                _ => {}
            }
            if std::fs::hard_link(&from, &to).is_err() {
                errmap_core::io::write_atomic_bytes(
                    &to,
                    &std::fs::read(&from).map_err(|e| Diagnostic::read(&from, e))?,
                )?;
            }
        }
    }
    Ok(())
}

/// Remove the part files an earlier run of the folder listed (and the folders left empty).
fn remove_part_outputs(batch_dir: &Path, old: &RunManifest) -> Result<()> {
    for rec in &old.parts {
        for rel in rec.outputs.keys() {
            let path = batch_dir.join(rel);
            match std::fs::remove_file(&path) {
                Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                    return Err(Diagnostic::io("remove the earlier output", &path, e))
                }
                _ => {}
            }
        }
        // Only an emptied folder goes; a folder with other files stays.
        let _ = std::fs::remove_dir(batch_dir.join(&rec.part));
    }
    Ok(())
}

/// The reduce's manifest: the shards' run.json hashes, their parts (paths under the batch
/// folder), the family files and the merged summary.
fn reduce_manifest(
    batch_dir: &Path,
    folders: &ShardFolders,
    manifests: &[RunManifest],
    merged: &BatchSummary,
) -> Result<RunManifest> {
    let mut files = BTreeMap::new();
    for (rel, h) in manifest::hash_tree(&batch_dir.join("family"))? {
        files.insert(format!("family/{rel}"), h);
    }
    files.insert(
        "summary.json".to_string(),
        manifest::sha256_file(&batch_dir.join("summary.json"))?,
    );
    let mut inputs = BTreeMap::new();
    let mut parts = Vec::new();
    let mut shards = BTreeMap::new();
    for ((s, dir), m) in folders.values().zip(manifests) {
        let name = s.folder_name();
        shards.insert(
            name.clone(),
            manifest::sha256_file(&dir.join(RUN_MANIFEST))?,
        );
        inputs.extend(m.inputs.clone());
        for rec in &m.parts {
            let mut rec = rec.clone();
            // The part summaries were rewritten with their new folder.
            for (rel, hash) in rec.outputs.iter_mut() {
                if rel.ends_with("/summary.json") {
                    *hash = manifest::sha256_file(&batch_dir.join(rel.as_str()))?;
                }
            }
            parts.push(rec);
        }
    }
    Ok(RunManifest {
        format: manifest::RUN_FORMAT.into(),
        errmap_version: env!("CARGO_PKG_VERSION").into(),
        kind: "reduce".into(),
        job: merged.job.clone(),
        job_hash: manifests[0].job_hash.clone(),
        shard: None,
        backend: merged.backend.clone(),
        inputs,
        parts,
        files,
        shards,
        created_utc: Some(manifest::utc_now()),
        metadata: manifests[0].metadata.clone(),
        k_sigma: manifests[0].k_sigma,
    })
}
