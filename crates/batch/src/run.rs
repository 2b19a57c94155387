//! The family pipeline: read → clean → hold-out split → training sets (rayon), one `train_batch` for every network of the batch, grid evaluation, outputs.
//!
//! Every part brings up to two networks: the hold-out fit (trained without the held-out probe
//! points; it gives `holdout_rmse_um`) and the delivered fit (all clean points). The family
//! network is fitted to the node-wise mean of the parts' training sets. All of them go to the
//! trainer in one call, so on a GPU a whole family trains in the same dispatches.

use super::family_sums::{FamilyMaps, FamilyNodes};
use super::part_record::Marks;
use super::summary::{BatchSummary, FamilySummary, PartSummary, ToolpathSummary};
use super::timing::{PartTiming, Stopping, Timing};
use super::train_step::{train_family, train_parts, Role};
use errmap_core::error::{Error, Result};
use errmap_core::geom::{Axis, Domain};
use errmap_core::progress::Reporter;
use errmap_maps::interp::{self, Grid, Method, Surface};
use errmap_maps::map::uncertainty::{self, Uncertainty};
use errmap_maps::map::{Benefit, ErrorMap, FittedModel};
use errmap_maps::nn::stop::Holdout;
use errmap_maps::nn::{Mlp, ModelConfig, Normalisation, Trainer, TrainingSet};
use errmap_maps::probe::{self, ProbePoint, ProbeSpec, Rejected};
use errmap_report::heatmap::{self, Heatmap, Scale};
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use std::path::{Path, PathBuf};

/// Everything the pipeline needs, from a job file or from `errmap map` flags.
#[derive(Debug, Clone)]
pub struct Settings {
    /// Family name for titles and the summary (a single part's own name without a job).
    pub family: String,
    /// Error direction: the maps give E along it over the two other axes.
    pub normal: Axis,
    /// Nominal coordinate along the normal for every point, mm, when the probe files have no
    /// nominal columns; `None` = the files' own.
    pub nominal_plane_mm: Option<f64>,
    /// Fixed map domain; `None`: bounding box of all probe points of the batch.
    pub domain: Option<Domain>,
    /// Node spacing of the output map grids, mm.
    pub grid_step_mm: f64,
    /// Gross-error threshold: a probe whose leave-one-out residual exceeds k·σ (robust σ) is
    /// rejected.
    pub k_sigma: f64,
    /// How the probes are interpolated into the training sets.
    pub method: Method,
    /// Node spacing of the training sets inside the probes' hull, mm.
    pub spacing_mm: f64,
    /// The networks, their training and the backend that trains them.
    pub model: ModelConfig,
    /// Plausibility bound of probe deviations and map values, mm.
    pub max_deviation_mm: f64,
    /// Column mapping of the probe files (CSV exports), see [`ProbeSpec::columns`].
    pub columns: Option<String>,
    /// 1-based header line of the probe files, see [`ProbeSpec::header_line`].
    pub header_line: Option<u64>,
    /// Write each part's `reduce.json` (batch runs: the shards' input to the reduce).
    pub reduce_inputs: bool,
    /// The job's `max_memory_mb`: a part whose points need more memory is refused before it
    /// is read (`--max-memory-mb` wins; see [`errmap_maps::probe::budget`]).
    pub max_memory_mb: Option<u64>,
}

/// One part to map and where its files go.
#[derive(Debug, Clone)]
pub struct PartInput {
    /// The part's name (its folder's name, from the probe file's stem).
    pub name: String,
    /// The part's probe file.
    pub probe_file: PathBuf,
    /// Folder the part's files ([`PART_OUTPUTS`]) are written to.
    pub out_dir: PathBuf,
}

/// Toolpaths to compensate after fitting.
#[derive(Debug, Clone)]
pub struct ToolpathPlan {
    /// The programs (G-code or CSV) to compensate.
    pub files: Vec<PathBuf>,
    /// How to compensate them (zone, dialect, units, segment length …).
    pub settings: errmap_toolpath::CompensationSettings,
    /// `true`: each part's map (outputs in the part's folder); `false`: the family map.
    pub per_part: bool,
    /// Use maps that remove less than [`errmap_maps::map::MIN_BENEFIT_SHARE`] of E at their
    /// held-out points (job key `[toolpaths] allow_weak_map`).
    pub allow_weak_map: bool,
    /// Leave points where the map's u(E) exceeds this (µm) nominal, as points outside the
    /// domain (job key `max_uncertainty_um`); `None`: no bound.
    pub max_uncertainty_um: Option<f64>,
}

/// A whole run.
#[derive(Debug, Clone)]
pub struct Plan {
    /// What every part is mapped with.
    pub settings: Settings,
    /// The parts this run maps (a shard's share, or those `--resume` did not keep).
    pub parts: Vec<PartInput>,
    /// Every part of the family in batch order, when this run maps only some of them (a shard,
    /// a resumed run) and its parts start from the family network: the family network is then
    /// rebuilt from all of them, as the whole run builds it. Empty otherwise.
    pub family_parts: Vec<PartInput>,
    /// Folder of the family maps; `None` for a single part.
    pub family_dir: Option<PathBuf>,
    /// Toolpaths to compensate; `None` when there are none (or, in a shard, when they take
    /// the family map, which only an unsharded run or the merge builds).
    pub toolpaths: Option<ToolpathPlan>,
    /// The job file; `None` for a single part without one (`errmap map`).
    pub job: Option<PathBuf>,
    /// `[index, count]` of the shard this run maps; `None` when the job is not split.
    pub shard: Option<[usize; 2]>,
}

impl Plan {
    /// Every file the plan reads is an input no output may replace: protect them all, then
    /// check every part's outputs before the first is written, so a refused plan writes nothing.
    pub fn protect_files(&self) -> Result<()> {
        use errmap_core::io::safety::{check_output, protect};
        for part in &self.parts {
            protect(&part.probe_file);
        }
        if let Some(job) = &self.job {
            protect(job);
        }
        for f in self.toolpaths.iter().flat_map(|t| &t.files) {
            protect(f);
        }
        for part in &self.parts {
            for name in PART_OUTPUTS {
                check_output(&part.out_dir.join(name))?;
            }
        }
        Ok(())
    }
}

/// A part after reading and cleaning.
struct Prepared {
    input: PartInput,
    points: usize,
    repeats_averaged: usize,
    preamble_lines: usize,
    skipped_features: usize,
    clean: Vec<ProbePoint>,
    rejected: Vec<Rejected>,
    sigma_um: f64,
    holdout: Vec<usize>,
}

/// A part with its training sets (values at training-grid nodes, `None` outside the hull).
struct Interpolated {
    prep: Prepared,
    full_nodes: Vec<Option<f64>>,
    holdout_nodes: Option<Vec<Option<f64>>>,
    /// Hold-out RMSE of the kriging baseline (fitted on the same kept points), µm.
    kriging_holdout_rmse_um: Option<f64>,
    /// The kriging baseline's misses at the held-out points, µm (empty without a hold-out).
    kriging_misses_um: Vec<f64>,
}

/// Which points lie on the boundary of their convex hull (vertices and points on its edges).
fn hull_boundary(points: &[ProbePoint]) -> Vec<bool> {
    let uv: Vec<[f64; 2]> = points.iter().map(|p| [p.u_mm, p.v_mm]).collect();
    let hull = errmap_core::geom::convex_hull(&uv);
    if hull.len() < 2 {
        return vec![true; points.len()];
    }
    let scale = uv
        .iter()
        .map(|q| q[0].abs().max(q[1].abs()))
        .fold(1.0, f64::max);
    let on_edge = |a: [f64; 2], b: [f64; 2], q: [f64; 2]| {
        let (du, dv) = (b[0] - a[0], b[1] - a[1]);
        let len = du.hypot(dv);
        let cross = du * (q[1] - a[1]) - dv * (q[0] - a[0]);
        let t = ((q[0] - a[0]) * du + (q[1] - a[1]) * dv) / (len * len);
        len > 0.0 && (cross / len).abs() <= 1e-9 * scale && (-1e-12..=1.0 + 1e-12).contains(&t)
    };
    uv.iter()
        .map(|&q| (0..hull.len()).any(|k| on_edge(hull[k], hull[(k + 1) % hull.len()], q)))
        .collect()
}

/// Most held-out points of a part: 10,000 misses give its hold-out RMS to better than 1 %, and
/// more would only slow the hold-out checks of a dense scan's training.
pub const MAX_HOLDOUT_POINTS: usize = 10_000;

/// Seeded choice of the held-out points: interior points only (the hull stays the same, so the
/// hold-out fit is judged where it interpolates), `round(fraction · n)` of them, at least one
/// and at most [`MAX_HOLDOUT_POINTS`].
fn choose_holdout(clean: &[ProbePoint], fraction: f64, seed: u64, name: &str) -> Vec<usize> {
    if fraction <= 0.0 || clean.len() < 8 {
        return Vec::new();
    }
    let boundary = hull_boundary(clean);
    let mut candidates: Vec<usize> = (0..clean.len()).filter(|&i| !boundary[i]).collect();
    let want = ((fraction * clean.len() as f64).round() as usize).clamp(1, MAX_HOLDOUT_POINTS);
    let want = want
        .min(candidates.len())
        .min(clean.len().saturating_sub(5));
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ super::train_step::fnv1a(name));
    candidates.shuffle(&mut rng);
    let mut chosen: Vec<usize> = candidates.into_iter().take(want).collect();
    chosen.sort_unstable();
    chosen
}

fn prepare(
    input: PartInput,
    s: &Settings,
) -> std::result::Result<Prepared, Box<(PartInput, Error)>> {
    let spec = ProbeSpec {
        normal: s.normal,
        nominal_plane_mm: s.nominal_plane_mm,
        domain: s.domain,
        max_deviation_mm: s.max_deviation_mm,
        columns: s.columns.clone(),
        header_line: s.header_line,
    };
    let bound_mb = probe::budget::max_memory_mb(s.max_memory_mb);
    if let Err(e) = probe::budget::check(&input.probe_file, bound_mb) {
        return Err(Box::new((input, e)));
    }
    let (set, preamble_lines, skipped_features) =
        match probe::read_probe_file(&input.probe_file, &spec) {
            Ok(read) => (read.set, read.preamble_lines, read.skipped_features),
            Err(e) => return Err(Box::new((input, e.into()))),
        };
    let cleaned = match probe::reject_gross_errors(&set, s.k_sigma) {
        Ok(c) => c,
        Err(e) => return Err(Box::new((input, e.into()))),
    };
    let rows: u32 = set.points.iter().map(|p| p.repeats).sum();
    let holdout = choose_holdout(
        &cleaned.clean,
        s.model.holdout_fraction,
        s.model.seed,
        &input.name,
    );
    Ok(Prepared {
        points: set.points.len(),
        repeats_averaged: (rows as usize).saturating_sub(set.points.len()),
        preamble_lines,
        skipped_features,
        clean: cleaned.clean,
        rejected: cleaned.rejected,
        sigma_um: cleaned.sigma_um,
        holdout,
        input,
    })
}

/// The part's training-grid values from all its clean points (`None` outside their hull).
fn full_nodes(prep: &Prepared, s: &Settings, train_grid: &Grid) -> Result<Vec<Option<f64>>> {
    training_nodes(&probe::uve(&prep.clean), s, train_grid)
}

/// Training-grid values from points: binned where they are dense, interpolated with the
/// job's method otherwise ([`interp::bin`]).
fn training_nodes(uve: &[[f64; 3]], s: &Settings, train_grid: &Grid) -> Result<Vec<Option<f64>>> {
    if interp::bin::choose(uve, train_grid) == interp::bin::TrainingSource::Binned {
        return Ok(interp::bin::binned_nodes(uve, train_grid));
    }
    let surface = Surface::new(uve)?;
    if s.method == Method::Kriging {
        surface.kriging()?;
    }
    Ok(interp::resample(&surface, s.method, train_grid))
}

fn interpolate(
    prep: Prepared,
    s: &Settings,
    train_grid: &Grid,
) -> std::result::Result<Interpolated, Box<(PartInput, Error)>> {
    let full = match full_nodes(&prep, s, train_grid) {
        Ok(nodes) => nodes,
        Err(e) => return Err(Box::new((prep.input, e))),
    };
    let kriging_misses_um = kriging_holdout_misses(&prep).unwrap_or_default();
    let kriging_holdout_rmse_um = errmap_maps::map::rms_um(&kriging_misses_um);
    let holdout_nodes = if prep.holdout.is_empty() {
        None
    } else {
        match training_nodes(&probe::uve(&kept_points(&prep)), s, train_grid) {
            Ok(nodes) => Some(nodes),
            Err(e) => return Err(Box::new((prep.input, e))),
        }
    };
    if full.iter().flatten().count() < 3 {
        let e = Error::input(
            errmap_core::Location::file(&prep.input.probe_file),
            format!(
                "the probes' convex hull holds fewer than 3 nodes of the {} mm training grid",
                s.spacing_mm
            ),
            "use a smaller [interp] spacing_mm or probe a larger area",
        );
        return Err(Box::new((prep.input, e)));
    }
    Ok(Interpolated {
        prep,
        full_nodes: full,
        holdout_nodes,
        kriging_holdout_rmse_um,
        kriging_misses_um,
    })
}

/// The clean points the hold-out fits see: all but the held-out ones.
fn kept_points(prep: &Prepared) -> Vec<ProbePoint> {
    prep.clean
        .iter()
        .enumerate()
        .filter(|(i, _)| prep.holdout.binary_search(i).is_err())
        .map(|(_, p)| p.clone())
        .collect()
}

/// The kriging baseline a metrologist would compare the map with (exact up to
/// [`interp::baseline::EXACT_MAX_SITES`] points, local above): fitted on the points the
/// hold-out network saw, its misses at the held-out points (µm); `None` without a hold-out or
/// when the points cannot be kriged.
fn kriging_holdout_misses(prep: &Prepared) -> Option<Vec<f64>> {
    if prep.holdout.is_empty() {
        return None;
    }
    let k = interp::baseline::Baseline::fit(&probe::uve(&kept_points(prep))).ok()?;
    let at: Vec<[f64; 2]> = prep
        .holdout
        .iter()
        .map(|&i| [prep.clean[i].u_mm, prep.clean[i].v_mm])
        .collect();
    prep.holdout
        .iter()
        .zip(k.predict_many(&at))
        .map(|(&i, e)| Some(prep.clean[i].e_um - e?))
        .collect()
}

/// A training set from node values: the nodes that have a value.
pub(crate) fn training_set(
    grid: &Grid,
    values: &[Option<f64>],
    domain: &Domain,
) -> (TrainingSet, Normalisation) {
    let present: Vec<f64> = values.iter().flatten().copied().collect();
    let norm = Normalisation::new(domain, &present);
    let mut set = TrainingSet {
        inputs: Vec::with_capacity(present.len()),
        targets: Vec::with_capacity(present.len()),
    };
    for j in 0..grid.nv {
        for i in 0..grid.nu {
            if let Some(Some(e)) = values.get(j * grid.nu + i) {
                let (u, v) = grid.node(i, j);
                set.inputs.push(norm.scale_input(u, v));
                set.targets.push(norm.scale_target(*e));
            }
        }
    }
    (set, norm)
}

/// Bounding box of every clean point of the batch.
fn union_box(parts: &[Prepared]) -> Option<Domain> {
    let mut all: Option<Domain> = None;
    for p in parts {
        if let Some(b) = probe::bounding_box(&p.clean) {
            all = Some(match all {
                None => b,
                Some(a) => Domain {
                    u_min_mm: a.u_min_mm.min(b.u_min_mm),
                    v_min_mm: a.v_min_mm.min(b.v_min_mm),
                    u_max_mm: a.u_max_mm.max(b.u_max_mm),
                    v_max_mm: a.v_max_mm.max(b.v_max_mm),
                },
            });
        }
    }
    all
}

/// Parts mapped together: read, cleaned, trained in one trainer call, written, then dropped.
/// A run holds one chunk at a time, so its memory does not grow with the family; 32 parts
/// (64 networks) keep the CPU trainer's cores and a GPU's dispatches busy.
pub const CHUNK_PARTS: usize = 32;

/// A part read and cleaned, or why not.
type Prep = std::result::Result<Prepared, Box<(PartInput, Error)>>;

/// Read and clean the parts of one chunk (rayon).
fn prepare_chunk(chunk: &[PartInput], s: &Settings) -> Vec<Prep> {
    chunk.par_iter().map(|p| prepare(p.clone(), s)).collect()
}

/// Run the plan with `trainer`, telling `reporter` how it goes; every part's outcome (and its
/// error) is in the summary. The parts go through in chunks of [`CHUNK_PARTS`] (read → clean →
/// grid → train → evaluate → write) and only their summaries and the family's running sums
/// stay; the family (mean, spread, network, toolpaths) is written after the last chunk.
pub fn execute(
    plan: &Plan,
    trainer: &dyn Trainer,
    reporter: &dyn Reporter,
) -> Result<BatchSummary> {
    execute_with(plan, trainer, reporter, &|_, _| Ok(()))
}

/// Told of each part once all its files are written (its summary and its compensated
/// toolpaths), in batch order within a chunk; an error stops the run.
pub type PartDone<'a> = dyn Fn(&PartSummary, &[ToolpathSummary]) -> Result<()> + Sync + 'a;

/// [`execute`], telling `on_part` of each part mapped as soon as its files are written (a
/// batch records it for `--resume`).
pub fn execute_with(
    plan: &Plan,
    trainer: &dyn Trainer,
    reporter: &dyn Reporter,
    on_part: &PartDone,
) -> Result<BatchSummary> {
    let s = &plan.settings;
    let mut first: Option<Vec<Prep>> = None;
    let domain = match s.domain {
        Some(d) => Some(d),
        None => {
            let survey = survey_box(plan, reporter);
            if survey.domain.is_none() {
                // Nothing could be fitted: every part failed before training.
                return Ok(finish(plan, trainer, None, survey.failed, None, Vec::new()));
            }
            first = Some(survey.first);
            survey.domain
        }
    };
    let domain = checked_domain(domain)?;
    let grids = Grids::new(&domain, s)?;
    let builds_family = plan.family_dir.is_some();
    let warm = s.model.warm_start == errmap_maps::nn::WarmStart::Family;
    let mut nodes = FamilyNodes::new(grids.train.len());
    let mut family_net = None;
    if warm {
        let members = if builds_family {
            &plan.parts
        } else {
            &plan.family_parts
        };
        let kept = family_prepass(
            members,
            builds_family,
            &mut first,
            &mut nodes,
            &grids,
            s,
            reporter,
        );
        first = kept;
        family_net = family_network(trainer, &nodes, &grids.train, &domain, s)?;
    }
    let mut acc = Accumulated {
        summaries: Vec::new(),
        maps: FamilyMaps::new(grids.map, s.normal),
        delivered: Vec::new(),
        kept_maps: Vec::new(),
        timings: Vec::new(),
        toolpaths: Vec::new(),
    };
    let inputs = grid_inputs(&domain, &grids.map);
    let bar = reporter.progress(plan.parts.len() as u64, "map parts");
    for (k, chunk) in plan.parts.chunks(CHUNK_PARTS).enumerate() {
        let preps = match first.take().filter(|_| k == 0) {
            Some(p) => p,
            None => prepare_chunk(chunk, s),
        };
        let mut failed = Vec::new();
        let mut parts = Vec::new();
        for r in preps {
            match r {
                Ok(p) => parts.push(p),
                Err(b) => failed.push(failed_part(&b.0, &b.1)),
            }
        }
        bar.inc(failed.len() as u64);
        let (interpolated, lost) = interpolate_all(parts, s, &grids.train);
        bar.inc(lost.len() as u64);
        failed.extend(lost);
        acc.summaries.append(&mut failed);
        if !warm && builds_family {
            for p in &interpolated {
                nodes.add(&p.full_nodes);
            }
        }
        if interpolated.is_empty() {
            continue;
        }
        let sets = training_sets(&interpolated, &grids.train, &domain);
        let networks = train(
            trainer,
            &sets,
            &interpolated,
            s,
            family_net.as_ref(),
            reporter,
        )?;
        let fit = Fit {
            settings: s,
            domain,
            grid: grids.map,
            sets: &sets,
            nets: &networks.nets,
        };
        let outputs = trainer.evaluate_batch(&fit.delivered_nets(), &inputs)?;
        let delivered = write_parts(&fit, &interpolated, &outputs, &networks.timings, &*bar);
        acc.add(delivered, plan, on_part)?;
        acc.timings.extend(networks.timings.into_iter().flatten());
    }
    bar.finish();
    if !warm && builds_family {
        family_net = family_network(trainer, &nodes, &grids.train, &domain, s)?;
    }
    let (family_model, family_summary) = write_family_maps(plan, s, domain, family_net, &acc)?;
    let mut toolpaths = std::mem::take(&mut acc.toolpaths);
    if let (Some(tp), Some(model), Some(dir)) = (&plan.toolpaths, &family_model, &plan.family_dir) {
        if !tp.per_part {
            for f in &tp.files {
                toolpaths.push(compensate_one(f, dir, "family", model, tp));
            }
        }
    }
    let mut summary = finish(
        plan,
        trainer,
        Some(domain),
        acc.summaries,
        family_summary,
        toolpaths,
    );
    if !acc.timings.is_empty() {
        summary.timing = Some(Timing::new(trainer.name(), acc.timings));
    }
    Ok(summary)
}

/// What a run keeps of its parts once they are written: their summary rows, the family's
/// running sums, the delivered parts' folders (to read their maps again for the spread), the
/// stopping figures and the per-part toolpaths.
struct Accumulated {
    summaries: Vec<PartSummary>,
    maps: FamilyMaps,
    delivered: Vec<PathBuf>,
    /// The delivered maps themselves, only when the parts write no `reduce.json` to read them
    /// back from (a single part's run).
    kept_maps: Vec<Vec<f64>>,
    timings: Vec<PartTiming>,
    toolpaths: Vec<ToolpathSummary>,
}

impl Accumulated {
    /// Take in a chunk's delivered parts, in batch order, compensate their per-part toolpaths
    /// and tell `on_part` of each.
    fn add(&mut self, delivered: Delivered, plan: &Plan, on_part: &PartDone) -> Result<()> {
        for m in &delivered.maps {
            self.maps.add(
                &m.map.values,
                m.u_um(),
                (m.model.hull_mm.as_ref(), m.model.surface_mm),
                &m.marks,
            );
            if let Some(dir) = &m.dir {
                self.delivered.push(dir.clone());
            }
            if !plan.settings.reduce_inputs {
                self.kept_maps.push(m.map.values.clone());
            }
        }
        for p in delivered.summaries.iter().filter(|p| p.ok) {
            let mut own = Vec::new();
            let tp = plan.toolpaths.as_ref().filter(|tp| tp.per_part);
            let m = delivered.maps.iter().find(|m| m.name == p.part);
            if let (Some(tp), Some(m)) = (tp, m) {
                if let Some(dir) = &m.dir {
                    for f in &tp.files {
                        own.push(compensate_one(f, dir, &m.name, &m.model, tp));
                    }
                }
            }
            on_part(p, &own)?;
            self.toolpaths.extend(own);
        }
        self.summaries.extend(delivered.summaries);
        Ok(())
    }

    /// The delivered maps again, in the order they were added: from the parts' `reduce.json`
    /// (bit-exact), or those kept.
    fn maps_again(&self) -> Box<dyn Iterator<Item = Result<Vec<f64>>> + '_> {
        if !self.kept_maps.is_empty() || self.delivered.is_empty() {
            return Box::new(self.kept_maps.iter().map(|m| Ok(m.clone())));
        }
        Box::new(self.delivered.iter().map(|d| {
            super::part_record::PartReduce::read(&d.join(super::part_record::REDUCE_FILE))
                .map(|p| p.map_e_um)
        }))
    }
}

/// The survey of a run without a fixed domain: the clean points' box over every part, the
/// first chunk's parts (kept for the run) and the summaries of the parts that failed.
struct Survey {
    domain: Option<Domain>,
    first: Vec<Prep>,
    failed: Vec<PartSummary>,
}

/// Read and clean every part once, chunk by chunk, for the box of their clean points.
fn survey_box(plan: &Plan, reporter: &dyn Reporter) -> Survey {
    let bar = reporter.progress(plan.parts.len() as u64, "clean");
    let mut survey = Survey {
        domain: None,
        first: Vec::new(),
        failed: Vec::new(),
    };
    for (k, chunk) in plan.parts.chunks(CHUNK_PARTS).enumerate() {
        let preps = prepare_chunk(chunk, &plan.settings);
        for r in &preps {
            match r {
                Ok(p) => {
                    let b = union_box(std::slice::from_ref(p));
                    survey.domain = match (survey.domain, b) {
                        (Some(a), Some(b)) => union_box_of(a, b),
                        (a, b) => a.or(b),
                    };
                }
                Err(b) => survey.failed.push(failed_part(&b.0, &b.1)),
            }
        }
        bar.inc(chunk.len() as u64);
        if k == 0 {
            survey.first = preps;
        }
    }
    bar.finish();
    survey
}

fn union_box_of(a: Domain, b: Domain) -> Option<Domain> {
    Some(Domain {
        u_min_mm: a.u_min_mm.min(b.u_min_mm),
        v_min_mm: a.v_min_mm.min(b.v_min_mm),
        u_max_mm: a.u_max_mm.max(b.u_max_mm),
        v_max_mm: a.v_max_mm.max(b.v_max_mm),
    })
}

/// The family's training-grid sums before its parts train from its network (`warm_start =
/// "family"`): every member read, cleaned and interpolated once, chunk by chunk, in batch order.
/// Returns the first chunk of the run's own parts (`members` are they when `own`), kept.
fn family_prepass(
    members: &[PartInput],
    own: bool,
    first: &mut Option<Vec<Prep>>,
    nodes: &mut FamilyNodes,
    grids: &Grids,
    s: &Settings,
    reporter: &dyn Reporter,
) -> Option<Vec<Prep>> {
    let bar = reporter.progress(members.len() as u64, "family mean");
    let mut kept = None;
    for (k, chunk) in members.chunks(CHUNK_PARTS).enumerate() {
        let preps = match first.take().filter(|_| k == 0 && own) {
            Some(p) => p,
            None => prepare_chunk(chunk, s),
        };
        let member_nodes: Vec<Option<Vec<Option<f64>>>> = preps
            .par_iter()
            .map(|r| {
                r.as_ref()
                    .ok()
                    .and_then(|p| member_nodes(p, s, &grids.train))
            })
            .collect();
        for n in member_nodes.iter().flatten() {
            nodes.add(n);
        }
        bar.inc(chunk.len() as u64);
        if k == 0 && own {
            kept = Some(preps);
        }
    }
    bar.finish();
    kept
}

/// A family member's training-grid values: those of a part that interpolates (see
/// [`interpolate`]), without its kriging baseline; `None` for a part that does not.
fn member_nodes(prep: &Prepared, s: &Settings, train_grid: &Grid) -> Option<Vec<Option<f64>>> {
    let full = full_nodes(prep, s, train_grid).ok()?;
    if full.iter().flatten().count() < 3 {
        return None;
    }
    if !prep.holdout.is_empty() && Surface::new(&probe::uve(&kept_points(prep))).is_err() {
        return None;
    }
    Some(full)
}

/// The family network fitted to the members' node-wise mean, with its normalisation; `None`
/// without members or with fewer than 3 nodes every member has.
fn family_network(
    trainer: &dyn Trainer,
    nodes: &FamilyNodes,
    train_grid: &Grid,
    domain: &Domain,
    s: &Settings,
) -> Result<Option<(Mlp, Normalisation)>> {
    let Some(mean) = nodes.mean() else {
        return Ok(None);
    };
    let (set, norm) = training_set(train_grid, &mean, domain);
    Ok(Some((train_family(trainer, &set, &s.model)?, norm)))
}

/// The summary of a part that failed.
fn failed_part(input: &PartInput, e: &Error) -> PartSummary {
    PartSummary::failed(&input.name, &input.probe_file, e)
}

/// The map domain, checked to span an area.
fn checked_domain(domain: Option<Domain>) -> Result<Domain> {
    match domain {
        Some(d) if d.width_mm() > 0.0 && d.height_mm() > 0.0 => Ok(d),
        _ => Err(Error::usage(
            "the probe points span no area (zero width or height)",
            "give a map domain",
        )),
    }
}

/// The training grid (the networks' training points) and the map grid (the outputs).
struct Grids {
    train: Grid,
    map: Grid,
}

impl Grids {
    fn new(domain: &Domain, s: &Settings) -> Result<Grids> {
        Ok(Grids {
            train: Grid::covering(domain, s.spacing_mm)?,
            map: Grid::covering(domain, s.grid_step_mm)?,
        })
    }
}

/// A chunk's training-grid values (rayon); the parts that fail are summarised.
fn interpolate_all(
    parts: Vec<Prepared>,
    s: &Settings,
    train_grid: &Grid,
) -> (Vec<Interpolated>, Vec<PartSummary>) {
    let results: Vec<_> = parts
        .into_par_iter()
        .map(|p| interpolate(p, s, train_grid))
        .collect();
    let mut interpolated = Vec::new();
    let mut failed = Vec::new();
    for r in results {
        match r {
            Ok(p) => interpolated.push(p),
            Err(b) => failed.push(failed_part(&b.0, &b.1)),
        }
    }
    (interpolated, failed)
}

/// A chunk's training sets with their scaling and role: per part [hold-out fit], delivered fit.
struct TrainingSets {
    sets: Vec<TrainingSet>,
    norms: Vec<Normalisation>,
    roles: Vec<Role>,
    /// Per part: (hold-out slot, delivered slot).
    slots: Vec<(Option<usize>, usize)>,
    /// The held-out points of each slot (none for a delivered fit).
    holdouts: Vec<Option<Holdout>>,
}

impl TrainingSets {
    fn push(&mut self, (set, norm): (TrainingSet, Normalisation), role: Role) -> usize {
        self.sets.push(set);
        self.norms.push(norm);
        self.roles.push(role);
        self.sets.len() - 1
    }
}

/// The training sets of a chunk's parts.
fn training_sets(
    interpolated: &[Interpolated],
    train_grid: &Grid,
    domain: &Domain,
) -> TrainingSets {
    let mut t = TrainingSets {
        sets: Vec::new(),
        norms: Vec::new(),
        roles: Vec::new(),
        slots: Vec::new(),
        holdouts: Vec::new(),
    };
    for p in interpolated {
        let name = &p.prep.input.name;
        let h = p.holdout_nodes.as_ref().map(|nodes| {
            let (set, norm) = training_set(train_grid, nodes, domain);
            t.holdouts.push(Some(held_out(p, &norm)));
            t.push((set, norm), Role::Holdout(name.clone()))
        });
        let delivered = training_set(train_grid, &p.full_nodes, domain);
        t.holdouts.push(None);
        let d = t.push(delivered, Role::Delivered(name.clone()));
        t.slots.push((h, d));
    }
    t
}

/// The `--verbose` line on a chunk's training: how many networks, how many points, which
/// schedule, on which trainer.
fn describe_training(t: &TrainingSets, s: &Settings, warm: bool, trainer: &dyn Trainer) -> String {
    let epochs = if warm {
        format!(
            "the family network {} epochs, then the parts {} epochs from it",
            s.model.epochs, s.model.warm_epochs
        )
    } else {
        format!("{} epochs", s.model.epochs)
    };
    let epochs = if s.model.stop == errmap_maps::nn::Stop::Holdout {
        format!(
            "{epochs} at most, stopping on the hold-out RMS: a check every {} epochs, patience {} checks",
            s.model.check_every_epochs, s.model.patience_checks
        )
    } else {
        epochs
    };
    format!(
        "training {} networks ({} points each at most; {epochs}) on {}",
        t.sets.len(),
        t.sets.iter().map(|t| t.len()).max().unwrap_or(0),
        trainer.name()
    )
}

/// A chunk's networks, and per part its hold-out stopping.
struct Networks {
    nets: Vec<Mlp>,
    timings: Vec<Option<PartTiming>>,
}

/// Train a chunk's networks in one trainer call, from the family network when given.
fn train(
    trainer: &dyn Trainer,
    t: &TrainingSets,
    interpolated: &[Interpolated],
    s: &Settings,
    family: Option<&(Mlp, Normalisation)>,
    reporter: &dyn Reporter,
) -> Result<Networks> {
    let warm = family.filter(|_| s.model.warm_start == errmap_maps::nn::WarmStart::Family);
    if reporter.shows_detail() {
        reporter.detail(&describe_training(t, s, warm.is_some(), trainer));
    }
    let bar = reporter.activity("train");
    let trained = train_parts(
        trainer,
        &t.sets,
        &t.norms,
        &t.roles,
        &s.model,
        &t.holdouts,
        warm.map(|(n, m)| (n, m)),
    );
    bar.finish();
    let trained = trained?;
    let timings = interpolated
        .iter()
        .zip(&t.slots)
        .map(|(p, &(h, _))| {
            let outcome = trained.stops.get(h?)?.as_ref()?;
            Some(PartTiming::new(&p.prep.input.name, outcome))
        })
        .collect();
    if trained.nets.len() != t.sets.len() {
        return Err(Error::Internal(format!(
            "trainer returned {} networks for {} training sets",
            trained.nets.len(),
            t.sets.len()
        )));
    }
    Ok(Networks {
        nets: trained.nets,
        timings,
    })
}

/// What the steps after training share: the settings, the domain and map grid, the training
/// sets and their networks.
struct Fit<'a> {
    settings: &'a Settings,
    domain: Domain,
    grid: Grid,
    sets: &'a TrainingSets,
    nets: &'a [Mlp],
}

impl Fit<'_> {
    /// The fitted model of training slot `slot`.
    fn model(&self, name: &str, slot: usize) -> FittedModel {
        FittedModel::new(
            name,
            self.settings.normal,
            self.domain,
            self.sets.norms[slot].clone(),
            self.nets[slot].clone(),
        )
    }

    /// The delivered networks of the chunk's parts, in part order.
    fn delivered_nets(&self) -> Vec<Mlp> {
        self.sets
            .slots
            .iter()
            .map(|&(_, d)| self.nets[d].clone())
            .collect()
    }
}

/// The map grid's nodes in network inputs (the domain's scaling).
fn grid_inputs(domain: &Domain, grid: &Grid) -> Vec<[f32; 2]> {
    let scale = Normalisation::new(domain, &[]);
    let mut inputs = Vec::with_capacity(grid.len());
    for j in 0..grid.nv {
        for i in 0..grid.nu {
            let (u, v) = grid.node(i, j);
            inputs.push(scale.scale_input(u, v));
        }
    }
    inputs
}

/// A delivered part: its name, folder, map, model and marks.
struct PartMap {
    name: String,
    dir: Option<PathBuf>,
    map: ErrorMap,
    model: FittedModel,
    marks: Marks,
}

impl PartMap {
    /// The map's u(E) per node, when it has one.
    fn u_um(&self) -> Option<&[f64]> {
        self.model.uncertainty.as_ref().map(|u| u.u_um.as_slice())
    }
}

/// A chunk's outcome: every part's summary and the delivered maps, in batch order.
struct Delivered {
    summaries: Vec<PartSummary>,
    maps: Vec<PartMap>,
}

/// Every part's outputs of a chunk (rayon), each counted on `bar` as it is written.
fn write_parts(
    fit: &Fit,
    interpolated: &[Interpolated],
    outputs: &[Vec<f32>],
    timings: &[Option<PartTiming>],
    bar: &dyn errmap_core::progress::Progress,
) -> Delivered {
    let results: Vec<(PartSummary, Option<Fitted>)> = interpolated
        .par_iter()
        .zip(fit.sets.slots.par_iter())
        .zip(outputs.par_iter())
        .zip(timings.par_iter())
        .map(|(((p, &slots), out), timing)| {
            let r = deliver_part(fit, p, slots, out, timing.as_ref());
            bar.inc(1);
            r
        })
        .collect();
    let mut delivered = Delivered {
        summaries: Vec::new(),
        maps: Vec::new(),
    };
    for (summary, fitted) in results {
        if let Some((map, model, marks)) = fitted {
            delivered.maps.push(PartMap {
                name: summary.part.clone(),
                dir: summary.output_dir.clone(),
                map,
                model,
                marks,
            });
        }
        delivered.summaries.push(summary);
    }
    delivered
}

/// One part's delivered map and model, written with its summary; a part that fails here is
/// summarised with its error.
fn deliver_part(
    fit: &Fit,
    p: &Interpolated,
    (h, d): (Option<usize>, usize),
    out: &[f32],
    timing: Option<&PartTiming>,
) -> (PartSummary, Option<Fitted>) {
    let s = fit.settings;
    let map = ErrorMap {
        grid: fit.grid,
        normal: s.normal,
        values: out
            .iter()
            .map(|&y| fit.sets.norms[d].unscale_output(y))
            .collect(),
    };
    let model = fit.model(&p.prep.input.name, d).with_probes(&p.prep.clean);
    let network_misses_um = h.map(|h| holdout_misses(p, &fit.model("holdout", h)));
    let holdout_rmse_um = network_misses_um
        .as_deref()
        .and_then(errmap_maps::map::rms_um);
    let (map, model) = match kriging_if_better(p, holdout_rmse_um) {
        Some(interp::baseline::Baseline::Exact(k)) => {
            (kriging_map(&k, fit.grid, s.normal), model.with_kriging(k))
        }
        Some(interp::baseline::Baseline::Local(k)) => {
            match local_kriging_map(&k, fit.grid, s.normal) {
                Some(m) => (m, model.with_local_kriging(&k)),
                None => (map, model),
            }
        }
        None => (map, model),
    };
    // The delivered map's hold-out figure, nested: each held-out point is predicted by the kind
    // chosen on the other held-out points, so the choice never sees the point it is judged on.
    let delivered_rmse_um = network_misses_um
        .as_deref()
        .and_then(|n| super::nested::nested_holdout_rmse(n, &p.kriging_misses_um));
    let benefit = holdout_e_rms(p)
        .zip(delivered_rmse_um)
        .and_then(|(e, r)| Benefit::from_rms(e, r));
    let uncertainty = part_uncertainty(p, &map);
    let model = model.with_benefit(benefit).with_uncertainty(uncertainty);
    let stopping = timing.map(PartTiming::stopping);
    let axes = s.normal.plane_axes();
    let holdout = Holdouts {
        network_rmse_um: holdout_rmse_um,
        delivered_rmse_um,
    };
    match write_part(p, &map, &model, holdout, stopping, s, axes) {
        Ok(summary) => (summary, Some((map, model, part_marks(p)))),
        Err(e) => (failed_part(&p.prep.input, &e), None),
    }
}

/// RMS of E (about zero) at the part's held-out points, µm; `None` without any.
fn holdout_e_rms(p: &Interpolated) -> Option<f64> {
    let e: Vec<f64> = p
        .prep
        .holdout
        .iter()
        .map(|&i| p.prep.clean[i].e_um)
        .collect();
    errmap_maps::map::rms_um(&e)
}

/// A hold-out network's misses at the part's held-out points, µm.
fn holdout_misses(p: &Interpolated, holdout_model: &FittedModel) -> Vec<f64> {
    p.prep
        .holdout
        .iter()
        .map(|&i| {
            let q = &p.prep.clean[i];
            q.e_um - holdout_model.e_um(q.u_mm, q.v_mm)
        })
        .collect()
}

/// The part's hold-out figures: the network's, and the delivered map's (nested).
#[derive(Debug, Clone, Copy)]
struct Holdouts {
    network_rmse_um: Option<f64>,
    delivered_rmse_um: Option<f64>,
}

/// The delivered map's u(E) on its grid (`errmap_maps::map::uncertainty`): c·max(σ_K, |E_map −
/// E_K|) at each node, σ_K and E_K the local kriging's of every clean point, c the factor its
/// cross-validation folds give; `None` when the points cannot be kriged (the map is delivered
/// without u).
fn part_uncertainty(p: &Interpolated, map: &ErrorMap) -> Option<Uncertainty> {
    let seed = super::train_step::fnv1a(&p.prep.input.name) ^ 0x75_6e_63_65_72_74;
    let cal = uncertainty::calibrate(&probe::uve(&p.prep.clean), seed).ok()?;
    let noise_um = cal.kriging.parameters.noise_um();
    let factor = cal.factor;
    let g = map.grid;
    let nodes: Vec<[f64; 2]> = (0..g.nv)
        .flat_map(|j| (0..g.nu).map(move |i| (i, j)))
        .map(|(i, j)| {
            let (u, v) = g.node(i, j);
            [u, v]
        })
        .collect();
    let u_um: Option<Vec<f64>> = cal
        .kriging
        .predict_many(&nodes)
        .into_iter()
        .zip(&map.values)
        .map(|(q, e)| q.map(|q| round4(factor * q.sd_um.max((e - q.e_um).abs()))))
        .collect();
    Some(Uncertainty {
        method: "local-kriging-cv".into(),
        grid: g,
        u_um: u_um?,
        factor: Some(factor),
        noise_um: Some(noise_um),
    })
}

/// To 1e-4 (µm): what `map.csv` prints, so the file and `model.json` agree.
fn round4(x: f64) -> f64 {
    (x * 1e4).round() / 1e4
}

/// The kriging of every clean point, when it fits the held-out points better than the network
/// (fitted only then: it costs a likelihood search).
fn kriging_if_better(
    p: &Interpolated,
    network_holdout_rmse_um: Option<f64>,
) -> Option<interp::baseline::Baseline> {
    if better_fit(p, network_holdout_rmse_um) != Some("kriging") {
        return None;
    }
    interp::baseline::Baseline::fit(&probe::uve(&p.prep.clean)).ok()
}

/// A local kriging's values on the map grid; `None` if a node cannot be predicted.
fn local_kriging_map(
    k: &interp::local::LocalKriging,
    grid: Grid,
    normal: Axis,
) -> Option<ErrorMap> {
    let nodes: Vec<[f64; 2]> = (0..grid.nv)
        .flat_map(|j| (0..grid.nu).map(move |i| (i, j)))
        .map(|(i, j)| {
            let (u, v) = grid.node(i, j);
            [u, v]
        })
        .collect();
    let values: Option<Vec<f64>> = k
        .predict_many(&nodes)
        .into_iter()
        .map(|q| q.map(|q| q.e_um))
        .collect();
    Some(ErrorMap {
        grid,
        normal,
        values: values?,
    })
}

/// A kriging's values on the map grid.
fn kriging_map(k: &interp::kriging::Kriging, grid: Grid, normal: Axis) -> ErrorMap {
    let values = (0..grid.nv)
        .flat_map(|j| (0..grid.nu).map(move |i| (i, j)))
        .map(|(i, j)| {
            let (u, v) = grid.node(i, j);
            k.predict(u, v)
        })
        .collect();
    ErrorMap {
        grid,
        normal,
        values,
    }
}

/// The family maps and network, when this run writes the family: the mean from the running
/// sums, the spread from the delivered maps taken again.
fn write_family_maps(
    plan: &Plan,
    s: &Settings,
    domain: Domain,
    family: Option<(Mlp, Normalisation)>,
    acc: &Accumulated,
) -> Result<(Option<FittedModel>, Option<FamilySummary>)> {
    let (Some(dir), Some((net, norm))) = (&plan.family_dir, family) else {
        return Ok((None, None));
    };
    let Some(mean) = acc.maps.mean() else {
        return Ok((None, None));
    };
    let std = acc.maps.std_map(&mean, acc.maps_again())?;
    let family_file = plan.job.clone().unwrap_or_else(|| dir.clone());
    check_map_plausible(&mean, s.max_deviation_mm, &family_file)?;
    let model = FittedModel::new("family", s.normal, domain, norm, net);
    let (summary, model) = write_family(dir, &mean, &std, model, &acc.maps, s)?;
    Ok((Some(model), Some(summary)))
}

fn finish(
    plan: &Plan,
    trainer: &dyn Trainer,
    domain: Option<Domain>,
    mut parts: Vec<PartSummary>,
    family_map: Option<FamilySummary>,
    toolpaths: Vec<ToolpathSummary>,
) -> BatchSummary {
    // Stable order: the plan's part order.
    let order = |p: &PartSummary| {
        plan.parts
            .iter()
            .position(|q| q.name == p.part)
            .unwrap_or(usize::MAX)
    };
    parts.sort_by_key(order);
    BatchSummary {
        family: plan.settings.family.clone(),
        job: plan.job.clone(),
        backend: trainer.name(),
        normal: plan.settings.normal,
        shard: plan.shard,
        domain_mm: domain.map(|d| [d.u_min_mm, d.v_min_mm, d.u_max_mm, d.v_max_mm]),
        grid_step_mm: plan.settings.grid_step_mm,
        failed_parts: parts.iter().filter(|p| !p.ok).count(),
        parts,
        family_map,
        toolpaths,
        timing: None,
    }
}

/// A part's held-out probe points in the units of its hold-out network (`norm`).
fn held_out(p: &Interpolated, norm: &Normalisation) -> Holdout {
    let points = p.prep.holdout.iter().map(|&i| &p.prep.clean[i]);
    Holdout {
        inputs: points
            .clone()
            .map(|q| norm.scale_input(q.u_mm, q.v_mm))
            .collect(),
        e_um: points.map(|q| q.e_um).collect(),
        norm: norm.clone(),
    }
}

/// A part's delivered map, its model and its marks.
type Fitted = (ErrorMap, FittedModel, Marks);

/// A part's kept and rejected probe points in the map plane.
fn part_marks(p: &Interpolated) -> Marks {
    Marks {
        probes: p.prep.clean.iter().map(|q| (q.u_mm, q.v_mm)).collect(),
        rejected: p
            .prep
            .rejected
            .iter()
            .map(|r| (r.point.u_mm, r.point.v_mm))
            .collect(),
        totals: None,
    }
}

/// The family map's u(E) per node: √(std² + Σ u_i² / N²) — how far the next part may stand
/// from the family mean, and how well the parts' maps know their own parts.
fn family_uncertainty(std: &ErrorMap, u_squared_sum: &[f64], n: usize) -> Option<Uncertainty> {
    if n == 0 || u_squared_sum.len() != std.values.len() {
        return None;
    }
    let u_um = std
        .values
        .iter()
        .zip(u_squared_sum)
        .map(|(s, q)| round4((s.powi(2) + q / (n * n) as f64).sqrt()))
        .collect();
    Some(Uncertainty {
        method: "family".into(),
        grid: std.grid,
        u_um,
        factor: None,
        noise_um: None,
    })
}

/// The family folder: mean and std maps (CSV, heatmaps with every part's probe and rejected
/// points and the family's measured hull), the family map's u(E) (`uncertainty.png`, when
/// every part has one) and the family network's `model.json`, which is returned with the
/// parts' measured domain and that u.
pub(crate) fn write_family(
    dir: &Path,
    mean: &ErrorMap,
    std: &ErrorMap,
    mut model: FittedModel,
    maps: &FamilyMaps,
    s: &Settings,
) -> Result<(FamilySummary, FittedModel)> {
    if let Some((hull, surface)) = maps.domain() {
        model.hull_mm = Some(hull);
        model.surface_mm = Some(surface);
    }
    let parts = maps.count();
    let marks = &maps.marks().to_marks();
    let u = maps
        .u_squared_sum()
        .and_then(|q| family_uncertainty(std, q, parts));
    let model = model.with_uncertainty(u);
    let axes = s.normal.plane_axes();
    mean.write_csv(&dir.join("mean.csv"), "e_um")?;
    std.write_csv(&dir.join("std.csv"), "std_um")?;
    let extrapolated = mean.extrapolated_nodes(model.hull_mm.as_deref());
    let (pv, rms) = mean
        .pv_rms_where_um(&extrapolated, false)
        .unwrap_or_else(|| mean.pv_rms_um());
    let std_max = std.values.iter().cloned().fold(0.0, f64::max);
    let title_mean = format!(
        "{} family mean of {parts} parts — PV {pv:.1} µm, RMS {rms:.1} µm (measured area)",
        s.family
    );
    let hull = model.hull_mm.as_deref().unwrap_or(&[]);
    draw_shaded(
        &dir.join("mean.png"),
        &title_mean,
        mean,
        marks,
        hull,
        Scale::Diverging,
        axes,
        "mean E (µm)",
        &extrapolated,
    )?;
    let title_std = format!(
        "{} part-to-part standard deviation — max {std_max:.2} µm",
        s.family
    );
    draw_shaded(
        &dir.join("std.png"),
        &title_std,
        std,
        marks,
        hull,
        Scale::Sequential,
        axes,
        "σ of E (µm)",
        &extrapolated,
    )?;
    let u_um = model.uncertainty.as_ref().map(|u| u.u_um.as_slice());
    let u_figures = u_um.and_then(|u| uncertainty::median_max_um(u, &extrapolated));
    draw_uncertainty(
        &dir.join("uncertainty.png"),
        &format!("{} family", s.family),
        mean,
        u_um,
        u_figures,
        marks,
        hull,
        axes,
        &extrapolated,
    )?;
    errmap_core::io::write_json(&dir.join("model.json"), &model)?;
    let summary = FamilySummary {
        parts,
        output_dir: dir.to_path_buf(),
        mean_rms_um: rms,
        mean_pv_um: pv,
        std_max_um: std_max,
        u_median_um: u_figures.map(|f| f.0),
        u_max_um: u_figures.map(|f| f.1),
    };
    Ok((summary, model))
}

/// `finish.ngc` → `finish-compensated.ngc` in `dir`.
fn compensated_name(input: &Path) -> PathBuf {
    let stem = input
        .file_stem()
        .map_or("toolpath".into(), |s| s.to_string_lossy().to_string());
    match input.extension() {
        Some(ext) => PathBuf::from(format!("{stem}-compensated.{}", ext.to_string_lossy())),
        None => PathBuf::from(format!("{stem}-compensated")),
    }
}

pub(crate) fn compensate_one(
    input: &Path,
    dir: &Path,
    map_name: &str,
    model: &FittedModel,
    tp: &ToolpathPlan,
) -> ToolpathSummary {
    let output = dir.join(compensated_name(input));
    // A weak map is refused before the program is read; one without figures is used as before.
    let model_file = dir.join("model.json");
    let checked = model
        .check_benefit(
            tp.allow_weak_map,
            "set [toolpaths] allow_weak_map = true in the job",
            &model_file,
        )
        .map_err(Error::from)
        .and_then(|_| match tp.max_uncertainty_um {
            None => errmap_toolpath::compensate_file(input, &output, model, &tp.settings)
                .map_err(Into::into),
            Some(max_um) => {
                let bounded = model.bounded_by_uncertainty(max_um, &model_file)?;
                errmap_toolpath::compensate_file(input, &output, &bounded, &tp.settings)
                    .map_err(Into::into)
            }
        });
    match checked {
        Ok(report) => ToolpathSummary {
            input: input.to_path_buf(),
            output,
            map: map_name.into(),
            report: serde_json::to_value(&report).ok(),
            error: None,
        },
        Err(e) => ToolpathSummary {
            input: input.to_path_buf(),
            output,
            map: map_name.into(),
            report: None,
            error: Some(e.report()),
        },
    }
}

/// Draw a map's heatmap with its probe and rejected points, the measured hull and the nodes
/// outside it (`extrapolated`) lightened.
#[allow(clippy::too_many_arguments)]
pub(crate) fn draw_shaded(
    path: &Path,
    title: &str,
    map: &ErrorMap,
    marks: &Marks,
    hull: &[[f64; 2]],
    scale: Scale,
    (ua, va): (Axis, Axis),
    label: &str,
    extrapolated: &[bool],
) -> Result<()> {
    let values: Vec<Option<f64>> = map.values.iter().map(|&v| Some(v)).collect();
    let counts = marks
        .totals
        .unwrap_or((marks.probes.len(), marks.rejected.len()));
    heatmap::save_heatmap_counted(
        path,
        &Heatmap {
            title: title.into(),
            u_name: ua.name(),
            v_name: va.name(),
            value_label: label,
            u0_mm: map.grid.u0_mm,
            v0_mm: map.grid.v0_mm,
            step_mm: map.grid.step_mm,
            nu: map.grid.nu,
            nv: map.grid.nv,
            values: &values,
            probes: &marks.probes,
            rejected: &marks.rejected,
            hull,
            scale,
            extrapolated,
        },
        counts,
    )?;
    Ok(())
}

/// `kriging` when its hold-out RMSE is below the network's (a tie keeps the network).
fn better_fit(p: &Interpolated, network_holdout_rmse_um: Option<f64>) -> Option<&'static str> {
    match (network_holdout_rmse_um, p.kriging_holdout_rmse_um) {
        (Some(n), Some(k)) => Some(if k < n { "kriging" } else { "network" }),
        _ => None,
    }
}

/// A fitted map whose value anywhere exceeds the plausibility bound is not delivered: the
/// network extrapolated wildly or the probe data hide a unit slip.
fn check_map_plausible(map: &ErrorMap, max_deviation_mm: f64, probe_file: &Path) -> Result<()> {
    let worst_um = map.values.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    if worst_um.is_finite() && worst_um <= max_deviation_mm * 1000.0 {
        return Ok(());
    }
    Err(Error::input(
        errmap_core::Location::file(probe_file),
        format!(
            "the fitted map reaches |E| = {worst_um:.1} µm, beyond the plausibility bound of {max_deviation_mm} mm",
        ),
        "check the probe file's units and nominal; if the part really is this far off, raise max_deviation_mm (--max-deviation-mm)",
    ))
}

/// The files a mapped part gets in its folder: the map grid (with u(E)), the fitted model, the
/// kept and the rejected probe points, the heatmaps of E and of u(E), and the part's summary.
pub const PART_OUTPUTS: [&str; 7] = [
    "map.csv",
    "model.json",
    "clean.csv",
    "rejected.csv",
    "map.png",
    "uncertainty.png",
    "summary.json",
];

/// Write every file of one part and return its summary.
fn write_part(
    p: &Interpolated,
    map: &ErrorMap,
    model: &FittedModel,
    holdout: Holdouts,
    stopping: Option<Stopping>,
    s: &Settings,
    axes: (Axis, Axis),
) -> Result<PartSummary> {
    let dir = &p.prep.input.out_dir;
    let name = &p.prep.input.name;
    check_map_plausible(map, s.max_deviation_mm, &p.prep.input.probe_file)?;
    let u_um = model.uncertainty.as_ref().map(|u| u.u_um.as_slice());
    map.write_csv_with_u(&dir.join("map.csv"), "e_um", u_um)?;
    errmap_core::io::write_json(&dir.join("model.json"), model)?;
    probe::write_points_csv(&dir.join("clean.csv"), s.normal, &p.prep.clean)?;
    probe::write_rejected_csv(&dir.join("rejected.csv"), &p.prep.rejected)?;
    let marks = part_marks(p);
    if s.reduce_inputs {
        super::part_record::PartReduce {
            part: name.clone(),
            holdout_fit: p.holdout_nodes.is_some(),
            train_nodes: p.full_nodes.clone(),
            map_e_um: map.values.clone(),
            map_u_um: u_um.map(<[f64]>::to_vec),
            hull_mm: model.hull_mm.clone(),
            surface_mm: model.surface_mm,
            marks: marks.clone(),
        }
        .write(dir)?;
    }
    let acc = Accuracy::of(map, model);
    // `errmap map` names the family after the part: say it once.
    let label = if s.family == *name {
        name.clone()
    } else {
        format!("{} {name}", s.family)
    };
    let title = format!(
        "{label} — PV {:.1} µm, RMS {:.1} µm (measured area)",
        acc.pv_um, acc.rms_um
    );
    draw_shaded(
        &dir.join("map.png"),
        &title,
        map,
        &marks,
        model.hull_mm.as_deref().unwrap_or(&[]),
        Scale::Diverging,
        axes,
        "E (µm)",
        &acc.extrapolated,
    )?;
    let u_figures = u_um.and_then(|u| uncertainty::median_max_um(u, &acc.extrapolated));
    draw_uncertainty(
        &dir.join("uncertainty.png"),
        &label,
        map,
        u_um,
        u_figures,
        &marks,
        model.hull_mm.as_deref().unwrap_or(&[]),
        axes,
        &acc.extrapolated,
    )?;
    let mut summary = part_summary(p, holdout, model.benefit, stopping, &acc);
    summary.u_median_um = u_figures.map(|f| f.0);
    summary.u_max_um = u_figures.map(|f| f.1);
    summary.u_factor = model.uncertainty.as_ref().and_then(|u| u.factor);
    summary.noise_um = model.uncertainty.as_ref().and_then(|u| u.noise_um);
    errmap_core::io::write_json(&dir.join("summary.json"), &summary)?;
    Ok(summary)
}

/// A map's accuracy figures over the measured domain, the extrapolated rest reported apart.
struct Accuracy {
    /// Nodes outside the measured hull.
    extrapolated: Vec<bool>,
    pv_um: f64,
    rms_um: f64,
    /// (PV, RMS) of the extrapolated nodes, µm; `None` when there are none.
    outside_um: Option<(f64, f64)>,
}

impl Accuracy {
    fn of(map: &ErrorMap, model: &FittedModel) -> Accuracy {
        let extrapolated = map.extrapolated_nodes(model.hull_mm.as_deref());
        let (pv_um, rms_um) = map
            .pv_rms_where_um(&extrapolated, false)
            .unwrap_or((0.0, 0.0));
        let outside_um = map.pv_rms_where_um(&extrapolated, true);
        Accuracy {
            extrapolated,
            pv_um,
            rms_um,
            outside_um,
        }
    }
}

/// The heatmap of a map's u(E) (`uncertainty.png`; viridis from 0), or of zeros with a title
/// saying it is unknown when the points could not be kriged.
#[allow(clippy::too_many_arguments)]
pub(crate) fn draw_uncertainty(
    path: &Path,
    label: &str,
    map: &ErrorMap,
    u_um: Option<&[f64]>,
    figures: Option<(f64, f64)>,
    marks: &Marks,
    hull: &[[f64; 2]],
    axes: (Axis, Axis),
    extrapolated: &[bool],
) -> Result<()> {
    let (values, title) = match (u_um, figures) {
        (Some(u), Some((median, max))) => (
            u.to_vec(),
            format!("{label} — u(E): median {median:.2} µm, max {max:.2} µm (measured area)"),
        ),
        _ => (
            vec![0.0; map.values.len()],
            format!("{label} — u(E) unknown (the points could not be kriged)"),
        ),
    };
    let u_map = ErrorMap {
        grid: map.grid,
        normal: map.normal,
        values,
    };
    draw_shaded(
        path,
        &title,
        &u_map,
        marks,
        hull,
        Scale::Sequential,
        axes,
        "u(E) (µm)",
        extrapolated,
    )
}

/// The summary of a delivered part.
fn part_summary(
    p: &Interpolated,
    holdout: Holdouts,
    benefit: Option<Benefit>,
    stopping: Option<Stopping>,
    acc: &Accuracy,
) -> PartSummary {
    let extrapolated = &acc.extrapolated;
    PartSummary {
        part: p.prep.input.name.clone(),
        probe_file: p.prep.input.probe_file.clone(),
        ok: true,
        points: p.prep.points,
        repeats_averaged: p.prep.repeats_averaged,
        preamble_lines: p.prep.preamble_lines,
        skipped_features: p.prep.skipped_features,
        rejected: p.prep.rejected.len(),
        sigma_um: Some(p.prep.sigma_um),
        holdout_points: p.prep.holdout.len(),
        holdout_rmse_um: holdout.network_rmse_um,
        kriging_holdout_rmse_um: p.kriging_holdout_rmse_um,
        better_fit: better_fit(p, holdout.network_rmse_um).map(str::to_string),
        delivered_holdout_rmse_um: holdout.delivered_rmse_um,
        holdout_e_rms_um: benefit.map(|b| b.holdout_e_rms_um),
        benefit_share: benefit.map(|b| b.share),
        rms_um: Some(acc.rms_um),
        pv_um: Some(acc.pv_um),
        extrapolated_fraction: Some(
            extrapolated.iter().filter(|&&x| x).count() as f64 / extrapolated.len().max(1) as f64,
        ),
        rms_extrapolated_um: acc.outside_um.map(|o| o.1),
        pv_extrapolated_um: acc.outside_um.map(|o| o.0),
        stopping,
        u_median_um: None,
        u_max_um: None,
        u_factor: None,
        noise_um: None,
        output_dir: Some(p.prep.input.out_dir.clone()),
        error: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid_points(nx: usize, ny: usize) -> Vec<ProbePoint> {
        let mut pts = Vec::new();
        for j in 0..ny {
            for i in 0..nx {
                pts.push(ProbePoint {
                    id: None,
                    line: (pts.len() + 2) as u64,
                    measured_mm: [i as f64 * 10.0, j as f64 * 5.0, 0.0],
                    nominal_mm: [i as f64 * 10.0, j as f64 * 5.0, 0.0],
                    u_mm: i as f64 * 10.0,
                    v_mm: j as f64 * 5.0,
                    e_um: 0.0,
                    repeats: 1,
                    spread_um: 0.0,
                });
            }
        }
        pts
    }

    /// A 6 × 6 probe grid on a tilted plane (E = 2 µm per 10 mm along x), 50 mm square.
    fn tilted_plate(dir: &Path) -> PathBuf {
        let mut text = String::from("x_mm,y_mm,z_mm\n");
        for j in 0..6 {
            for i in 0..6 {
                let (x, y) = (i as f64 * 10.0, j as f64 * 10.0);
                text.push_str(&format!("{x},{y},{}\n", x * 0.2e-3));
            }
        }
        let path = dir.join("plate.csv");
        std::fs::write(&path, text).unwrap();
        path
    }

    #[test]
    fn a_run_reports_every_step_to_the_reporter_it_is_given() {
        let root = tempfile::tempdir().unwrap();
        let out_dir = root.path().join("out");
        let plan = super::super::MapRequest {
            probes: tilted_plate(root.path()),
            out_dir: out_dir.clone(),
            normal: Axis::Z,
            nominal_plane_mm: Some(0.0),
            domain: None,
            grid_step_mm: 10.0,
            method: Method::NaturalNeighbour,
            spacing_mm: 10.0,
            k_sigma: 3.0,
            epochs: Some(20),
            seed: Some(1),
            backend: errmap_maps::nn::Backend::CpuReference,
            max_deviation_mm: 1.0,
            columns: None,
            header_line: None,
        }
        .plan()
        .unwrap();
        let trainer = errmap_maps::nn::CpuTrainer::reference();
        let recorder = errmap_core::progress::Recorder::default();
        let summary = execute(&plan, &trainer, &recorder).unwrap();
        assert_eq!(summary.failed_parts, 0, "{:?}", summary.parts[0].error);
        use errmap_core::progress::Event;
        let events = recorder.events();
        let stages: Vec<&Event> = events
            .iter()
            .filter(|e| matches!(e, Event::Stage(..)))
            .collect();
        assert_eq!(
            stages,
            [
                // No domain: the parts' box first; then one bar over the parts, the training
                // of each chunk inside it.
                &Event::Stage("clean".into(), 1),
                &Event::Stage("map parts".into(), 1),
                &Event::Stage("train".into(), 1),
            ]
        );
        // 36 points: 4 held out (round(0.1 · 36)), so a hold-out and a delivered network.
        assert_eq!(summary.parts[0].holdout_points, 4);
        let Some(Event::Detail(line)) = events.iter().find(|e| matches!(e, Event::Detail(_)))
        else {
            panic!("no detail line in {events:?}");
        };
        assert!(
            line.starts_with("training 2 networks (") && line.contains("; 20 epochs) on "),
            "{line}"
        );
        // The silent reporter changes nothing of the outcome.
        let again = execute(&plan, &trainer, &errmap_core::progress::Silent).unwrap();
        assert_eq!(again.parts[0].rms_um, summary.parts[0].rms_um);
        assert!(out_dir.join("summary.json").is_file());
        // The parts bar reaches the number of parts: each part counted once, as it is written.
        let counted = Counting::default();
        execute(&plan, &trainer, &counted).unwrap();
        assert_eq!(counted.done("map parts"), Some((1, 1)));
    }

    /// A reporter that counts each bar's steps: (steps done, length) by message.
    #[derive(Default)]
    struct Counting {
        bars: std::sync::Mutex<Vec<(String, u64, std::sync::Arc<std::sync::atomic::AtomicU64>)>>,
    }

    struct Count(std::sync::Arc<std::sync::atomic::AtomicU64>);

    impl errmap_core::progress::Progress for Count {
        fn inc(&self, n: u64) {
            self.0.fetch_add(n, std::sync::atomic::Ordering::Relaxed);
        }
        fn finish(&self) {}
    }

    impl Counting {
        fn done(&self, message: &str) -> Option<(u64, u64)> {
            let bars = self.bars.lock().unwrap();
            let (_, len, n) = bars.iter().find(|b| b.0 == message)?;
            Some((n.load(std::sync::atomic::Ordering::Relaxed), *len))
        }
    }

    impl Reporter for Counting {
        fn info(&self, _: &str) {}
        fn detail(&self, _: &str) {}
        fn warn(&self, _: &str) {}
        fn progress(&self, len: u64, message: &str) -> Box<dyn errmap_core::progress::Progress> {
            let n = std::sync::Arc::new(std::sync::atomic::AtomicU64::new(0));
            self.bars
                .lock()
                .unwrap()
                .push((message.to_string(), len, n.clone()));
            Box::new(Count(n))
        }
    }

    #[test]
    fn hull_boundary_is_the_outer_ring_of_a_grid() {
        let pts = grid_points(5, 4);
        let on = hull_boundary(&pts);
        for (k, p) in pts.iter().enumerate() {
            let ring = p.u_mm == 0.0 || p.u_mm == 40.0 || p.v_mm == 0.0 || p.v_mm == 15.0;
            assert_eq!(on[k], ring, "point {k} at ({}, {})", p.u_mm, p.v_mm);
        }
        // 5 × 4 grid: 14 ring points, 6 interior.
        assert_eq!(on.iter().filter(|&&b| b).count(), 14);
    }

    #[test]
    fn holdout_takes_a_tenth_of_interior_points_seeded_by_part_name() {
        let pts = grid_points(12, 12);
        let on = hull_boundary(&pts);
        let a = choose_holdout(&pts, 0.1, 1, "p01");
        // round(0.1 · 144) = 14 points, none on the hull, sorted, distinct.
        assert_eq!(a.len(), 14);
        assert!(a.iter().all(|&i| !on[i]));
        assert!(a.windows(2).all(|w| w[0] < w[1]));
        assert_eq!(a, choose_holdout(&pts, 0.1, 1, "p01"));
        assert_ne!(a, choose_holdout(&pts, 0.1, 1, "p02"));
        assert!(choose_holdout(&pts, 0.0, 1, "p01").is_empty());
        // Too few points to spare any.
        assert!(choose_holdout(&grid_points(2, 3), 0.1, 1, "p01").is_empty());
    }
}
