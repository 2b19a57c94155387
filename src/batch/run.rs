//! The family pipeline: read → clean → hold-out split → training sets (rayon), one `train_batch` for every network of the batch, grid evaluation, outputs.
//!
//! Every part brings up to two networks: the hold-out fit (trained without the held-out probe
//! points; it gives `holdout_rmse_um`) and the delivered fit (all clean points). The family
//! network is fitted to the node-wise mean of the parts' training sets. All of them go to the
//! trainer in one call, so on a GPU a whole family trains in the same dispatches.

use super::summary::{BatchSummary, FamilySummary, PartSummary, ToolpathSummary};
use super::timing::{PartTiming, Stopping, Timing};
use super::train_step::{train_all, Role};
use crate::error::{Error, Result};
use crate::geom::{Axis, Domain};
use crate::interp::{self, Grid, Method, Surface};
use crate::map::{family_stats, ErrorMap, FittedModel};
use crate::nn::stop::Holdout;
use crate::nn::{ModelConfig, Normalisation, Trainer, TrainingSet};
use crate::probe::{self, ProbePoint, ProbeSpec, Rejected};
use crate::report::heatmap::{self, Heatmap, Scale};
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use std::path::{Path, PathBuf};

/// Everything the pipeline needs, from a job file or from `errmap map` flags.
#[derive(Debug, Clone)]
pub struct Settings {
    pub family: String,
    pub normal: Axis,
    pub nominal_plane_mm: Option<f64>,
    /// Fixed map domain; `None`: bounding box of all probe points of the batch.
    pub domain: Option<Domain>,
    pub grid_step_mm: f64,
    pub k_sigma: f64,
    pub method: Method,
    pub spacing_mm: f64,
    pub model: ModelConfig,
    /// Plausibility bound of probe deviations and map values, mm.
    pub max_deviation_mm: f64,
    /// Write each part's `reduce.json` (batch runs: the shards' input to the reduce).
    pub reduce_inputs: bool,
}

/// One part to map and where its files go.
#[derive(Debug, Clone)]
pub struct PartInput {
    pub name: String,
    pub probe_file: PathBuf,
    pub out_dir: PathBuf,
}

/// Toolpaths to compensate after fitting.
#[derive(Debug, Clone)]
pub struct ToolpathPlan {
    pub files: Vec<PathBuf>,
    pub settings: crate::toolpath::CompensationSettings,
    /// `true`: each part's map (outputs in the part's folder); `false`: the family map.
    pub per_part: bool,
}

/// A whole run.
#[derive(Debug, Clone)]
pub struct Plan {
    pub settings: Settings,
    pub parts: Vec<PartInput>,
    /// Every part of the family in batch order, when this run maps only some of them (a shard,
    /// a resumed run) and its parts start from the family network: the family network is then
    /// rebuilt from all of them, as the whole run builds it. Empty otherwise.
    pub family_parts: Vec<PartInput>,
    /// Folder of the family maps; `None` for a single part.
    pub family_dir: Option<PathBuf>,
    pub toolpaths: Option<ToolpathPlan>,
    pub job: Option<PathBuf>,
    pub shard: Option<[usize; 2]>,
}

/// A part after reading and cleaning.
struct Prepared {
    input: PartInput,
    points: usize,
    repeats_averaged: usize,
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
}

/// Indices of points on the boundary of the convex hull (vertices and points on its edges).
fn hull_boundary(points: &[ProbePoint]) -> Vec<bool> {
    let n = points.len();
    let mut idx: Vec<usize> = (0..n).collect();
    idx.sort_by(|&a, &b| {
        points[a]
            .u_mm
            .total_cmp(&points[b].u_mm)
            .then(points[a].v_mm.total_cmp(&points[b].v_mm))
    });
    let cross = |o: usize, a: usize, b: usize| {
        (points[a].u_mm - points[o].u_mm) * (points[b].v_mm - points[o].v_mm)
            - (points[a].v_mm - points[o].v_mm) * (points[b].u_mm - points[o].u_mm)
    };
    // Andrew's monotone chain (strict hull).
    let mut hull: Vec<usize> = Vec::new();
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &usize>> = if pass == 0 {
            Box::new(idx.iter())
        } else {
            Box::new(idx.iter().rev())
        };
        for &p in iter {
            while hull.len() >= start + 2
                && cross(hull[hull.len() - 2], hull[hull.len() - 1], p) <= 0.0
            {
                hull.pop();
            }
            hull.push(p);
        }
        hull.pop();
    }
    let scale = points
        .iter()
        .map(|p| p.u_mm.abs().max(p.v_mm.abs()))
        .fold(1.0, f64::max);
    let mut on = vec![false; n];
    if hull.len() < 2 {
        return vec![true; n];
    }
    for k in 0..hull.len() {
        let (a, b) = (hull[k], hull[(k + 1) % hull.len()]);
        let len = (points[b].u_mm - points[a].u_mm).hypot(points[b].v_mm - points[a].v_mm);
        for (i, flag) in on.iter_mut().enumerate() {
            if len > 0.0 && (cross(a, b, i) / len).abs() <= 1e-9 * scale {
                let t = ((points[i].u_mm - points[a].u_mm) * (points[b].u_mm - points[a].u_mm)
                    + (points[i].v_mm - points[a].v_mm) * (points[b].v_mm - points[a].v_mm))
                    / (len * len);
                if (-1e-12..=1.0 + 1e-12).contains(&t) {
                    *flag = true;
                }
            }
        }
    }
    on
}

/// Seeded choice of the held-out points: interior points only (the hull stays the same, so the
/// hold-out fit is judged where it interpolates), `round(fraction · n)` of them, at least one.
fn choose_holdout(clean: &[ProbePoint], fraction: f64, seed: u64, name: &str) -> Vec<usize> {
    if fraction <= 0.0 || clean.len() < 8 {
        return Vec::new();
    }
    let boundary = hull_boundary(clean);
    let mut candidates: Vec<usize> = (0..clean.len()).filter(|&i| !boundary[i]).collect();
    let want = ((fraction * clean.len() as f64).round() as usize).max(1);
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
    };
    let set = match probe::read_probes(&input.probe_file, &spec) {
        Ok(set) => set,
        Err(e) => return Err(Box::new((input, e))),
    };
    let cleaned = match probe::reject_gross_errors(&set, s.k_sigma) {
        Ok(c) => c,
        Err(e) => return Err(Box::new((input, e))),
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
        clean: cleaned.clean,
        rejected: cleaned.rejected,
        sigma_um: cleaned.sigma_um,
        holdout,
        input,
    })
}

/// The part's training-grid values from all its clean points (`None` outside their hull).
fn full_nodes(prep: &Prepared, s: &Settings, train_grid: &Grid) -> Result<Vec<Option<f64>>> {
    let surface = Surface::new(&probe::uve(&prep.clean))?;
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
    let kriging_holdout_rmse_um = kriging_holdout_rmse(&prep);
    let holdout_nodes = if prep.holdout.is_empty() {
        None
    } else {
        let kept: Vec<ProbePoint> = prep
            .clean
            .iter()
            .enumerate()
            .filter(|(i, _)| prep.holdout.binary_search(i).is_err())
            .map(|(_, p)| p.clone())
            .collect();
        match Surface::new(&probe::uve(&kept)) {
            Ok(surface) => Some(interp::resample(&surface, s.method, train_grid)),
            Err(e) => return Err(Box::new((prep.input, e))),
        }
    };
    if full.iter().flatten().count() < 3 {
        let e = Error::input(
            crate::Location::file(&prep.input.probe_file),
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
    })
}

/// The kriging baseline a metrologist would compare the map with: fitted on the points the
/// hold-out network saw, RMS of its misses at the held-out points (µm); `None` without a
/// hold-out or when the points cannot be kriged.
fn kriging_holdout_rmse(prep: &Prepared) -> Option<f64> {
    if prep.holdout.is_empty() {
        return None;
    }
    let kept: Vec<ProbePoint> = prep
        .clean
        .iter()
        .enumerate()
        .filter(|(i, _)| prep.holdout.binary_search(i).is_err())
        .map(|(_, p)| p.clone())
        .collect();
    let k = interp::kriging::Kriging::fit(&probe::uve(&kept)).ok()?;
    let sq: f64 = prep
        .holdout
        .iter()
        .map(|&i| {
            let q = &prep.clean[i];
            (q.e_um - k.predict(q.u_mm, q.v_mm)).powi(2)
        })
        .sum();
    Some((sq / prep.holdout.len() as f64).sqrt())
}

/// The training-grid values of the parts the family network is fitted to, in batch order:
/// this run's parts when it maps the whole family; every part of the family (those of other
/// shards read and interpolated here, failures left out as the whole run leaves them out) when
/// only some are mapped but they start from the family network; none otherwise.
fn family_members(
    plan: &Plan,
    interpolated: &[Interpolated],
    s: &Settings,
    train_grid: &Grid,
) -> Vec<Vec<Option<f64>>> {
    if plan.family_dir.is_some() {
        return interpolated.iter().map(|p| p.full_nodes.clone()).collect();
    }
    if plan.family_parts.is_empty() || s.model.warm_start != crate::nn::WarmStart::Family {
        return Vec::new();
    }
    plan.family_parts
        .par_iter()
        .map(
            |part| match interpolated.iter().find(|p| p.prep.input.name == part.name) {
                Some(p) => Some(p.full_nodes.clone()),
                // Only its training-grid values: no hold-out fits for a part mapped elsewhere.
                None => prepare(part.clone(), s)
                    .ok()
                    .and_then(|prep| full_nodes(&prep, s, train_grid).ok()),
            },
        )
        .collect::<Vec<_>>()
        .into_iter()
        .flatten()
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

/// Run the plan with `trainer`; every part's outcome (and its error) is in the summary.
pub fn execute(plan: &Plan, trainer: &dyn Trainer, quiet: bool) -> Result<BatchSummary> {
    let s = &plan.settings;
    let mut failed: Vec<PartSummary> = Vec::new();
    let fail =
        |input: &PartInput, e: &Error| PartSummary::failed(&input.name, &input.probe_file, e);

    // 1. Read and clean every part (rayon).
    let bar = crate::progress::bar(plan.parts.len() as u64, "clean", quiet);
    let prepared: Vec<_> = plan
        .parts
        .par_iter()
        .map(|p| {
            let r = prepare(p.clone(), s);
            bar.inc(1);
            r
        })
        .collect();
    bar.finish_and_clear();
    let mut ok_parts = Vec::new();
    for r in prepared {
        match r {
            Ok(p) => ok_parts.push(p),
            Err(b) => failed.push(fail(&b.0, &b.1)),
        }
    }

    // 2. The domain every network is scaled over and the training grid.
    let domain = match s.domain.or_else(|| union_box(&ok_parts)) {
        Some(d) if d.width_mm() > 0.0 && d.height_mm() > 0.0 => Some(d),
        Some(_) => {
            return Err(Error::usage(
                "the probe points span no area (zero width or height)",
                "give a map domain",
            ))
        }
        None => None,
    };
    let mut interpolated = Vec::new();
    if let Some(domain) = domain {
        let train_grid = Grid::covering(&domain, s.spacing_mm)?;
        let grid = Grid::covering(&domain, s.grid_step_mm)?;
        let bar = crate::progress::bar(ok_parts.len() as u64, "interpolate", quiet);
        let results: Vec<_> = ok_parts
            .into_par_iter()
            .map(|p| {
                let r = interpolate(p, s, &train_grid);
                bar.inc(1);
                r
            })
            .collect();
        bar.finish_and_clear();
        for r in results {
            match r {
                Ok(p) => interpolated.push(p),
                Err(b) => failed.push(fail(&b.0, &b.1)),
            }
        }
        // 3. All training sets: per part [hold-out fit], delivered fit; then the family.
        let mut sets = Vec::new();
        let mut norms = Vec::new();
        let mut roles = Vec::new();
        let mut slots = Vec::new(); // (holdout slot, delivered slot) per part
        let mut holdouts = Vec::new(); // held-out points of each hold-out slot
        for p in &interpolated {
            let name = &p.prep.input.name;
            let h = p.holdout_nodes.as_ref().map(|nodes| {
                let (set, norm) = training_set(&train_grid, nodes, &domain);
                holdouts.push(Some(held_out(p, &norm)));
                sets.push(set);
                norms.push(norm);
                roles.push(Role::Holdout(name.clone()));
                sets.len() - 1
            });
            let (set, norm) = training_set(&train_grid, &p.full_nodes, &domain);
            sets.push(set);
            norms.push(norm);
            holdouts.push(None);
            roles.push(Role::Delivered(name.clone()));
            slots.push((h, sets.len() - 1));
        }
        let members = family_members(plan, &interpolated, s, &train_grid);
        let family_slot = if !members.is_empty() {
            let mean: Vec<Option<f64>> = (0..train_grid.len())
                .map(|k| {
                    let vals: Option<Vec<f64>> = members.iter().map(|p| p[k]).collect();
                    vals.map(|v| v.iter().sum::<f64>() / v.len() as f64)
                })
                .collect();
            if mean.iter().flatten().count() >= 3 {
                let (set, norm) = training_set(&train_grid, &mean, &domain);
                sets.push(set);
                norms.push(norm);
                roles.push(Role::Family);
                Some(sets.len() - 1)
            } else {
                None
            }
        } else {
            None
        };
        if !sets.is_empty() {
            if crate::progress::verbosity() == crate::progress::Verbosity::Verbose {
                let warm = s.model.warm_start == crate::nn::WarmStart::Family
                    && roles.contains(&Role::Family);
                let epochs = if warm {
                    format!(
                        "the family network {} epochs, then the parts {} epochs from it",
                        s.model.epochs, s.model.warm_epochs
                    )
                } else {
                    format!("{} epochs", s.model.epochs)
                };
                let epochs = if s.model.stop == crate::nn::Stop::Holdout {
                    format!(
                        "{epochs} at most, stopping on the hold-out RMS: a check every {} epochs, patience {} checks",
                        s.model.check_every_epochs, s.model.patience_checks
                    )
                } else {
                    epochs
                };
                crate::progress::detail(&format!(
                    "training {} networks ({} points each at most; {epochs}) on {}",
                    sets.len(),
                    sets.iter().map(|t| t.len()).max().unwrap_or(0),
                    trainer.name()
                ));
            }
            // One call trains every network; the bar ticks so a terminal shows it is alive.
            let bar = crate::progress::bar(1, "train", quiet);
            bar.enable_steady_tick(std::time::Duration::from_millis(200));
            let trained = train_all(trainer, &sets, &norms, &roles, &s.model, &holdouts);
            bar.finish_and_clear();
            let trained = trained?;
            let nets = trained.nets;
            let timings: Vec<Option<PartTiming>> = interpolated
                .iter()
                .zip(&slots)
                .map(|(p, &(h, _))| {
                    let outcome = trained.stops.get(h?)?.as_ref()?;
                    Some(PartTiming::new(&p.prep.input.name, outcome))
                })
                .collect();
            if nets.len() != sets.len() {
                return Err(Error::Internal(format!(
                    "trainer returned {} networks for {} training sets",
                    nets.len(),
                    sets.len()
                )));
            }
            // 4. Evaluate the delivered and family networks on the map grid.
            let scale = Normalisation::new(&domain, &[]);
            let mut inputs = Vec::with_capacity(grid.len());
            for j in 0..grid.nv {
                for i in 0..grid.nu {
                    let (u, v) = grid.node(i, j);
                    inputs.push(scale.scale_input(u, v));
                }
            }
            let mut eval_slots: Vec<usize> = slots.iter().map(|&(_, d)| d).collect();
            eval_slots.extend(family_slot.filter(|_| plan.family_dir.is_some()));
            let eval_nets: Vec<_> = eval_slots.iter().map(|&k| nets[k].clone()).collect();
            let outputs = trainer.evaluate_batch(&eval_nets, &inputs)?;
            let to_map = |slot: usize, out: &[f32]| ErrorMap {
                grid,
                normal: s.normal,
                values: out.iter().map(|&y| norms[slot].unscale_output(y)).collect(),
            };
            // 5. Outputs per part (rayon).
            let bar = crate::progress::bar(interpolated.len() as u64, "write", quiet);
            let (ua, va) = s.normal.plane_axes();
            let part_results: Vec<(PartSummary, Option<Fitted>)> = interpolated
                .par_iter()
                .zip(slots.par_iter())
                .zip(outputs.par_iter())
                .zip(timings.par_iter())
                .map(|(((p, &(h, d)), out), timing)| {
                    let map = to_map(d, out);
                    let model = FittedModel::new(
                        &p.prep.input.name,
                        s.normal,
                        domain,
                        norms[d].clone(),
                        nets[d].clone(),
                    )
                    .with_probes(&p.prep.clean);
                    let holdout_rmse_um = h.map(|h| {
                        let hm = FittedModel::new(
                            "holdout",
                            s.normal,
                            domain,
                            norms[h].clone(),
                            nets[h].clone(),
                        );
                        let sq: f64 = p
                            .prep
                            .holdout
                            .iter()
                            .map(|&i| {
                                let q = &p.prep.clean[i];
                                (q.e_um - hm.e_um(q.u_mm, q.v_mm)).powi(2)
                            })
                            .sum();
                        (sq / p.prep.holdout.len() as f64).sqrt()
                    });
                    // The delivered map: the kriging when it fits the held-out points better
                    // (fitted to every clean point only then: it costs a likelihood search).
                    let kriging_full = (better_fit(p, holdout_rmse_um) == Some("kriging"))
                        .then(|| interp::kriging::Kriging::fit(&probe::uve(&p.prep.clean)).ok())
                        .flatten();
                    let (map, model) = match &kriging_full {
                        Some(k) => {
                            let values = (0..grid.nv)
                                .flat_map(|j| (0..grid.nu).map(move |i| (i, j)))
                                .map(|(i, j)| {
                                    let (u, v) = grid.node(i, j);
                                    k.predict(u, v)
                                })
                                .collect();
                            let map = ErrorMap {
                                grid,
                                normal: s.normal,
                                values,
                            };
                            (map, model.with_kriging(k.clone()))
                        }
                        _ => (map, model),
                    };
                    let stopping = timing.as_ref().map(PartTiming::stopping);
                    let r = write_part(p, &map, &model, holdout_rmse_um, stopping, s, (ua, va));
                    bar.inc(1);
                    match r {
                        Ok(summary) => (summary, Some((map, model, part_marks(p)))),
                        Err(e) => (fail(&p.prep.input, &e), None),
                    }
                })
                .collect();
            bar.finish_and_clear();
            let mut summaries = Vec::new();
            let mut part_maps = Vec::new();
            // Every part's probe and rejected points, in batch order, for the family maps.
            let mut marks = Marks::default();
            for (summary, fitted) in part_results {
                if let Some((map, model, part)) = fitted {
                    part_maps.push((summary.part.clone(), summary.output_dir.clone(), map, model));
                    marks.probes.extend(part.probes);
                    marks.rejected.extend(part.rejected);
                }
                summaries.push(summary);
            }
            summaries.append(&mut failed);
            failed = summaries;

            // 6. Family maps.
            let mut family_model = None;
            let mut family_summary = None;
            if let (Some(dir), Some(fslot)) = (&plan.family_dir, family_slot) {
                let maps: Vec<&ErrorMap> = part_maps.iter().map(|(_, _, m, _)| m).collect();
                if let Some((mean, std)) = family_stats(&maps) {
                    let family_file = plan.job.clone().unwrap_or_else(|| dir.clone());
                    check_map_plausible(&mean, s.max_deviation_mm, &family_file)?;
                    let parts: Vec<&FittedModel> = part_maps.iter().map(|(_, _, _, m)| m).collect();
                    let model = FittedModel::new(
                        "family",
                        s.normal,
                        domain,
                        norms[fslot].clone(),
                        nets[fslot].clone(),
                    )
                    .with_parts(&parts);
                    family_summary = Some(write_family(
                        dir,
                        &mean,
                        &std,
                        &model,
                        maps.len(),
                        &marks,
                        s,
                    )?);
                    family_model = Some(model);
                }
            }

            // 7. Toolpaths.
            let mut toolpaths = Vec::new();
            if let Some(tp) = &plan.toolpaths {
                if tp.per_part {
                    for (name, dir, _, model) in &part_maps {
                        if let Some(dir) = dir {
                            for f in &tp.files {
                                toolpaths.push(compensate_one(f, dir, name, model, &tp.settings));
                            }
                        }
                    }
                } else if let (Some(model), Some(dir)) = (&family_model, &plan.family_dir) {
                    for f in &tp.files {
                        toolpaths.push(compensate_one(f, dir, "family", model, &tp.settings));
                    }
                }
            }
            let mut summary = finish(
                plan,
                trainer,
                Some(domain),
                failed,
                family_summary,
                toolpaths,
            );
            let timings: Vec<PartTiming> = timings.into_iter().flatten().collect();
            if !timings.is_empty() {
                summary.timing = Some(Timing::new(trainer.name(), timings));
            }
            return Ok(summary);
        }
    }
    // Nothing could be fitted: every part failed before training.
    Ok(finish(plan, trainer, domain, failed, None, Vec::new()))
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

/// Probe and rejected points (plane axes, mm) drawn on a map.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct Marks {
    pub probes: Vec<(f64, f64)>,
    pub rejected: Vec<(f64, f64)>,
}

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
    }
}

/// The family folder: mean and std maps (CSV, heatmaps with every part's probe and rejected
/// points and the family's measured hull) and the family network's `model.json`.
pub(crate) fn write_family(
    dir: &Path,
    mean: &ErrorMap,
    std: &ErrorMap,
    model: &FittedModel,
    parts: usize,
    marks: &Marks,
    s: &Settings,
) -> Result<FamilySummary> {
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
    crate::io::write_json(&dir.join("model.json"), model)?;
    Ok(FamilySummary {
        parts,
        output_dir: dir.to_path_buf(),
        mean_rms_um: rms,
        mean_pv_um: pv,
        std_max_um: std_max,
    })
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
    settings: &crate::toolpath::CompensationSettings,
) -> ToolpathSummary {
    let output = dir.join(compensated_name(input));
    match crate::toolpath::compensate_file(input, &output, model, settings) {
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
    heatmap::save_heatmap(
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
        crate::Location::file(probe_file),
        format!(
            "the fitted map reaches |E| = {worst_um:.1} µm, beyond the plausibility bound of {max_deviation_mm} mm",
        ),
        "check the probe file's units and nominal; if the part really is this far off, raise max_deviation_mm (--max-deviation-mm)",
    ))
}

/// The files [`write_part`] writes into a part's folder.
pub const PART_OUTPUTS: [&str; 6] = [
    "map.csv",
    "model.json",
    "clean.csv",
    "rejected.csv",
    "map.png",
    "summary.json",
];

/// Write every file of one part and return its summary.
fn write_part(
    p: &Interpolated,
    map: &ErrorMap,
    model: &FittedModel,
    holdout_rmse_um: Option<f64>,
    stopping: Option<Stopping>,
    s: &Settings,
    axes: (Axis, Axis),
) -> Result<PartSummary> {
    let dir = &p.prep.input.out_dir;
    let name = &p.prep.input.name;
    check_map_plausible(map, s.max_deviation_mm, &p.prep.input.probe_file)?;
    map.write_csv(&dir.join("map.csv"), "e_um")?;
    crate::io::write_json(&dir.join("model.json"), model)?;
    probe::write_points_csv(&dir.join("clean.csv"), s.normal, &p.prep.clean)?;
    probe::write_rejected_csv(&dir.join("rejected.csv"), &p.prep.rejected)?;
    let marks = part_marks(p);
    if s.reduce_inputs {
        super::reduce::PartReduce {
            part: name.clone(),
            holdout_fit: p.holdout_nodes.is_some(),
            train_nodes: p.full_nodes.clone(),
            map_e_um: map.values.clone(),
            hull_mm: model.hull_mm.clone(),
            surface_mm: model.surface_mm,
            marks: marks.clone(),
        }
        .write(dir)?;
    }
    // Accuracy figures over the measured domain; the extrapolated rest reported apart.
    let extrapolated = map.extrapolated_nodes(model.hull_mm.as_deref());
    let (pv, rms) = map
        .pv_rms_where_um(&extrapolated, false)
        .unwrap_or((0.0, 0.0));
    let outside = map.pv_rms_where_um(&extrapolated, true);
    // `errmap map` names the family after the part: say it once.
    let label = if s.family == *name {
        name.clone()
    } else {
        format!("{} {name}", s.family)
    };
    let title = format!("{label} — PV {pv:.1} µm, RMS {rms:.1} µm (measured area)");
    draw_shaded(
        &dir.join("map.png"),
        &title,
        map,
        &marks,
        model.hull_mm.as_deref().unwrap_or(&[]),
        Scale::Diverging,
        axes,
        "E (µm)",
        &extrapolated,
    )?;
    let summary = PartSummary {
        part: name.clone(),
        probe_file: p.prep.input.probe_file.clone(),
        ok: true,
        points: p.prep.points,
        repeats_averaged: p.prep.repeats_averaged,
        rejected: p.prep.rejected.len(),
        sigma_um: Some(p.prep.sigma_um),
        holdout_points: p.prep.holdout.len(),
        holdout_rmse_um,
        kriging_holdout_rmse_um: p.kriging_holdout_rmse_um,
        better_fit: better_fit(p, holdout_rmse_um).map(str::to_string),
        rms_um: Some(rms),
        pv_um: Some(pv),
        extrapolated_fraction: Some(
            extrapolated.iter().filter(|&&x| x).count() as f64 / extrapolated.len().max(1) as f64,
        ),
        rms_extrapolated_um: outside.map(|o| o.1),
        pv_extrapolated_um: outside.map(|o| o.0),
        stopping,
        output_dir: Some(dir.clone()),
        error: None,
    };
    crate::io::write_json(&dir.join("summary.json"), &summary)?;
    Ok(summary)
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
