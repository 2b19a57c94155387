//! A job resolved once: the job file with the command line's options applied (`--backend` included), the trainer selected for it, the output folder, and the job's plan (parts, settings, family folder, toolpaths) built from it.
//!
//! The backend is applied here and nowhere else: the job file the run hashes, plans and
//! records names the backend its trainer was selected for.

use crate::job::{JobFile, MapChoice};
use crate::plan::{PartInput, Plan, Settings, ToolpathPlan};
use crate::RunError;
use crate::{part_names, BatchOptions, Shard};
use errmap_core::error::Result;
use errmap_maps::nn::{Backend, ModelConfig, Trainer, WarmStart};
use std::path::{Path, PathBuf};

/// How a caller turns a backend into a trainer (the binary's choice, with its notes): the
/// backend and the job's model configuration.
pub type SelectTrainer<'a> = dyn Fn(Backend, &ModelConfig) -> Result<Box<dyn Trainer>> + 'a;

/// A job with every option applied and its trainer selected.
pub struct ResolvedJob {
    /// The job file with `--backend` applied.
    pub file: JobFile,
    /// The options of the run.
    pub opts: BatchOptions,
    /// The trainer selected for the job's backend.
    pub trainer: Box<dyn Trainer>,
}

impl std::fmt::Debug for ResolvedJob {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ResolvedJob")
            .field("file", &self.file)
            .field("opts", &self.opts)
            .field("trainer", &self.trainer.name())
            .finish()
    }
}

impl ResolvedJob {
    /// Apply `opts` to `file` and select the trainer of the resulting backend with `select`.
    pub fn new(
        file: &JobFile,
        opts: &BatchOptions,
        select: &SelectTrainer,
    ) -> Result<ResolvedJob, RunError> {
        let file = with_backend(file, opts.backend);
        let trainer = select(file.job.model.backend, &file.job.model)?;
        Ok(ResolvedJob {
            file,
            opts: opts.clone(),
            trainer,
        })
    }

    /// The batch's output folder: `--out-dir`, else the job's `output`, else `out/<family>`.
    pub fn output(&self) -> PathBuf {
        self.opts
            .output
            .clone()
            .unwrap_or_else(|| self.file.output_dir())
    }

    /// The plan of this run's parts (this shard's) with their folders under `out`.
    pub fn plan(&self, out: &Path) -> Result<Plan, RunError> {
        Ok(plan_resolved(&self.file, self.opts.shard, out)?)
    }
}

/// The job as a run sees it: `backend` (`--backend`), when given, replaces `[model] backend`.
pub fn with_backend(file: &JobFile, backend: Option<Backend>) -> JobFile {
    let mut file = file.clone();
    if let Some(b) = backend {
        file.job.model.backend = b;
    }
    file
}

/// Build the plan of a job file: its parts (this shard's) with their folders under `out`,
/// the family folder and the toolpaths (`opts.backend` applied).
pub fn plan_job(file: &JobFile, opts: &BatchOptions, out: &Path) -> Result<Plan, RunError> {
    Ok(plan_resolved(
        &with_backend(file, opts.backend),
        opts.shard,
        out,
    )?)
}

/// The plan of a resolved job file.
fn plan_resolved(file: &JobFile, shard: Option<Shard>, out: &Path) -> Result<Plan> {
    let all_parts = job_parts(file, out)?;
    let parts: Vec<PartInput> = all_parts
        .iter()
        .enumerate()
        .filter(|(i, _)| shard.is_none_or(|s| s.takes(*i)))
        .map(|(_, p)| p.clone())
        .collect();
    let model = &file.job.model;
    // A shard that warm-starts its parts needs the family network: it rebuilds it from every
    // part of the job, exactly as the unsharded run does.
    let family_parts = if shard.is_some() && model.warm_start == WarmStart::Family {
        all_parts
    } else {
        Vec::new()
    };
    // A shard sees only some parts, so family maps (and toolpaths compensated with the family
    // map) come from an unsharded run; each shard maps its own parts and per-part toolpaths.
    let toolpaths = match (toolpath_plan(file), shard) {
        (Some(tp), Some(_)) if !tp.per_part => None,
        (tp, _) => tp,
    };
    Ok(Plan {
        settings: settings(file),
        parts,
        family_parts,
        family_dir: shard.is_none().then(|| out.join("family")),
        toolpaths,
        job: Some(file.path.clone()),
        shard: shard.map(|s| [s.index, s.count]),
    })
}

/// Every part of the job in batch order, its folder under `out`.
fn job_parts(file: &JobFile, out: &Path) -> Result<Vec<PartInput>> {
    let files = file.probe_files()?;
    let names = part_names(&files);
    Ok(files
        .iter()
        .zip(&names)
        .map(|(f, n)| PartInput {
            name: n.clone(),
            probe_file: f.clone(),
            out_dir: out.join(n),
        })
        .collect())
}

/// What every part is mapped with, from the job.
fn settings(file: &JobFile) -> Settings {
    let job = &file.job;
    Settings {
        family: job.family.clone(),
        normal: job.normal,
        nominal_plane_mm: job.nominal_plane_mm,
        domain: job.domain(),
        grid_step_mm: job.grid_step_mm,
        k_sigma: job.clean.k_sigma,
        method: job.interp.method,
        spacing_mm: job.interp.spacing_mm,
        model: job.model.clone(),
        max_deviation_mm: job.max_deviation_mm,
        columns: job.columns.clone(),
        header_line: job.header_line,
        reduce_inputs: true,
        max_memory_mb: job.max_memory_mb,
    }
}

/// The job's toolpaths and how to compensate them; `None` without any.
fn toolpath_plan(file: &JobFile) -> Option<ToolpathPlan> {
    let t = &file.job.toolpaths;
    if t.files.is_empty() {
        return None;
    }
    Some(ToolpathPlan {
        files: file.toolpath_files(),
        settings: errmap_toolpath::CompensationSettings {
            zone: t.zone.map(|[a, b]| (a, b)),
            everywhere: t.zone_all,
            surface_tol_mm: t.surface_tol_mm,
            max_segment: t.max_segment_mm,
            chord_tol: t.chord_tol_mm,
            dialect: t.dialect,
            units: t.units,
            fanuc_numbers: t.fanuc_numbers,
            extrapolate: t.extrapolate,
            domain_margin_mm: t.domain_margin_mm,
            power_on_motion: t.power_on_motion,
            expand: t.expand,
            compensate_holes: t.compensate_holes,
            same_part_per_offset: t.same_part_per_offset,
        },
        per_part: t.map == MapChoice::Part,
        allow_weak_map: t.allow_weak_map,
        max_uncertainty_um: file.job.max_uncertainty_um,
    })
}
