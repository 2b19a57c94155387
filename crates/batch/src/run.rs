//! The family pipeline, chunk by chunk: the stages of [`crate::stages`] (read → clean → hold-out split → training sets (rayon), one `train_batch` for every network of a chunk, grid evaluation, outputs), then the family and the summary.
//!
//! Every part brings up to two networks: the hold-out fit (trained without the held-out probe
//! points; it gives `holdout_rmse_um`) and the delivered fit (all clean points). The family
//! network is fitted to the node-wise mean of the parts' training sets. A chunk's networks go
//! to the trainer in one call, so on a GPU a chunk of parts trains in the same dispatches.

use crate::family_sums::{FamilyMaps, FamilyNodes};
use crate::plan::PartInput;
use crate::plan::Plan;
use crate::stages::evaluate::{grid_inputs, write_parts, Delivered, Fit};
use crate::stages::family::{family_network, write_family_folder, FamilyInput};
use crate::stages::nodes::{checked_domain, interpolate_all, member_nodes, Grids};
use crate::stages::read::{failed_part, prepare_chunk, union_box, union_box_of, Prep};
use crate::stages::summary::finish;
use crate::stages::toolpaths::{compensate_family, compensate_one};
use crate::stages::train::{train, training_sets};
use crate::summary::{BatchSummary, PartSummary, ToolpathSummary};
use crate::timing::{PartTiming, Timing};
use crate::RunError;
use errmap_core::error::Result;
use errmap_core::geom::Domain;
use errmap_core::progress::Reporter;
use errmap_maps::interp::Grid;
use errmap_maps::nn::{Mlp, Normalisation, Trainer};
use rayon::prelude::*;
use std::path::PathBuf;

/// Parts mapped together with `trainer`: read, cleaned, trained in one trainer call, written,
/// then dropped. A run holds one chunk at a time, so its memory does not grow with the family;
/// each part trains two networks (hold-out and delivered), so a chunk gives the trainer about
/// the networks it wants per call ([`Trainer::networks_per_call`]): 8 parts on the CPU
/// trainers, 32 on a GPU. The chunk size changes no byte of the outputs.
pub fn parts_per_chunk(trainer: &dyn Trainer) -> usize {
    (trainer.networks_per_call() / 2).max(1)
}

/// Run the plan with `trainer`, telling `reporter` how it goes; every part's outcome (and its
/// error) is in the summary. The parts go through in chunks of [`parts_per_chunk`] (read → clean →
/// grid → train → evaluate → write) and only their summaries and the family's running sums
/// stay; the family (mean, spread, network, toolpaths) is written after the last chunk.
pub fn execute(
    plan: &Plan,
    trainer: &dyn Trainer,
    reporter: &dyn Reporter,
) -> Result<BatchSummary, RunError> {
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
) -> Result<BatchSummary, RunError> {
    let chunk_parts = parts_per_chunk(trainer);
    let (domain, mut first) = match run_domain(plan, chunk_parts, reporter) {
        RunDomain::Found(domain, first) => (domain, first),
        // Nothing could be fitted: every part failed before training.
        RunDomain::NoPart(failed) => {
            return Ok(finish(plan, trainer, None, failed, None, Vec::new()))
        }
    };
    let domain = checked_domain(domain)?;
    let run = Run {
        plan,
        trainer,
        reporter,
        grids: Grids::new(&domain, &plan.settings)?,
        inputs: Vec::new(),
        domain,
        chunk_parts,
    };
    let run = Run {
        inputs: grid_inputs(&run.domain, &run.grids.map),
        ..run
    };
    let mut family = run.family_start(&mut first)?;
    let mut acc = Accumulated::new(run.grids.map, plan.settings.normal);
    let bar = reporter.progress(plan.parts.len() as u64, "map parts");
    for (k, chunk) in plan.parts.chunks(chunk_parts).enumerate() {
        let preps = match first.take().filter(|_| k == 0) {
            Some(p) => p,
            None => prepare_chunk(chunk, &plan.settings),
        };
        run.map_chunk(preps, &mut family, &mut acc, &*bar, on_part)?;
    }
    bar.finish();
    Ok(run.conclude(family, acc)?)
}

/// The map domain of a run before it is checked.
enum RunDomain {
    /// The job's domain, or the box of every part's clean points with the first chunk's
    /// parts, read for it.
    Found(Option<Domain>, Option<Vec<Prep>>),
    /// No part could be read: their summaries.
    NoPart(Vec<PartSummary>),
}

/// The job's domain, or the box of the parts' clean points (reading every part once).
fn run_domain(plan: &Plan, chunk_parts: usize, reporter: &dyn Reporter) -> RunDomain {
    if let Some(d) = plan.settings.domain {
        return RunDomain::Found(Some(d), None);
    }
    let survey = survey_box(plan, chunk_parts, reporter);
    if survey.domain.is_none() {
        return RunDomain::NoPart(survey.failed);
    }
    RunDomain::Found(survey.domain, Some(survey.first))
}

/// One run of the pipeline: its plan, trainer and reporter, its domain and grids.
struct Run<'a> {
    plan: &'a Plan,
    trainer: &'a dyn Trainer,
    reporter: &'a dyn Reporter,
    domain: Domain,
    grids: Grids,
    /// The map grid's nodes in network inputs.
    inputs: Vec<[f32; 2]>,
    /// Parts read and mapped together ([`parts_per_chunk`] of the trainer).
    chunk_parts: usize,
}

/// The family network as the parts need it: built before them (`warm_start = "family"`, from
/// a pass over its members) or summed while they are mapped and built after them.
struct FamilyState {
    /// The parts start from the family network.
    warm: bool,
    /// This run writes the family folder.
    builds: bool,
    nodes: FamilyNodes,
    network: Option<(Mlp, Normalisation)>,
}

impl Run<'_> {
    /// The family's state before the parts: with a warm start, its members read once and its
    /// network trained (`first` becomes the run's first chunk, kept from that pass).
    fn family_start(&self, first: &mut Option<Vec<Prep>>) -> Result<FamilyState> {
        let s = &self.plan.settings;
        let mut family = FamilyState {
            warm: s.model.warm_start == errmap_maps::nn::WarmStart::Family,
            builds: self.plan.family_dir.is_some(),
            nodes: FamilyNodes::new(self.grids.train.len()),
            network: None,
        };
        if family.warm {
            let members = if family.builds {
                &self.plan.parts
            } else {
                &self.plan.family_parts
            };
            let kept = family_prepass(self, members, family.builds, first, &mut family.nodes);
            *first = kept;
            family.network = self.family_network(&family.nodes)?;
        }
        Ok(family)
    }

    fn family_network(&self, nodes: &FamilyNodes) -> Result<Option<(Mlp, Normalisation)>> {
        let s = &self.plan.settings;
        family_network(self.trainer, nodes, &self.grids.train, &self.domain, s)
    }

    /// One chunk through the stages: training-grid values, training, evaluation and the
    /// parts' files; every part counted on `bar` once, its outcome in `acc`.
    fn map_chunk(
        &self,
        preps: Vec<Prep>,
        family: &mut FamilyState,
        acc: &mut Accumulated,
        bar: &dyn errmap_core::progress::Progress,
        on_part: &PartDone,
    ) -> Result<()> {
        let s = &self.plan.settings;
        let mut failed = Vec::new();
        let mut parts = Vec::new();
        for r in preps {
            match r {
                Ok(p) => parts.push(p),
                Err(b) => failed.push(failed_part(&b.0, &b.1)),
            }
        }
        bar.inc(failed.len() as u64);
        let (interpolated, lost) = interpolate_all(parts, s, &self.grids.train);
        bar.inc(lost.len() as u64);
        failed.extend(lost);
        acc.summaries.append(&mut failed);
        if !family.warm && family.builds {
            for p in &interpolated {
                family.nodes.add(&p.full_nodes);
            }
        }
        if interpolated.is_empty() {
            return Ok(());
        }
        let sets = training_sets(&interpolated, &self.grids.train, &self.domain);
        let warm_from = family.network.as_ref();
        let networks = train(
            self.trainer,
            &sets,
            &interpolated,
            s,
            warm_from,
            self.reporter,
        )?;
        let fit = Fit {
            settings: s,
            domain: self.domain,
            grid: self.grids.map,
            sets: &sets,
            nets: &networks.nets,
        };
        let outputs = self
            .trainer
            .evaluate_batch(&fit.delivered_nets(), &self.inputs)?;
        let delivered = write_parts(&fit, &interpolated, &outputs, &networks.timings, bar);
        acc.add(delivered, self.plan, on_part)?;
        acc.timings.extend(networks.timings.into_iter().flatten());
        Ok(())
    }

    /// After the last chunk: the family (network, folder, toolpaths) and the run's summary.
    fn conclude(&self, mut family: FamilyState, mut acc: Accumulated) -> Result<BatchSummary> {
        let plan = self.plan;
        if !family.warm && family.builds {
            family.network = self.family_network(&family.nodes)?;
        }
        let written = match (&plan.family_dir, family.network) {
            (Some(dir), Some(network)) => {
                let check_against = plan.job.clone().unwrap_or_else(|| dir.clone());
                let input = FamilyInput {
                    dir,
                    domain: self.domain,
                    network,
                    maps: &acc.maps,
                    check_against: Some(&check_against),
                };
                write_family_folder(input, acc.maps_again(), &plan.settings)?
            }
            _ => None,
        };
        let mut toolpaths = std::mem::take(&mut acc.toolpaths);
        let (family_summary, family_model) = written.unzip();
        if let (Some(model), Some(dir)) = (&family_model, &plan.family_dir) {
            toolpaths.extend(compensate_family(plan.toolpaths.as_ref(), dir, model));
        }
        let mut summary = finish(
            plan,
            self.trainer,
            Some(self.domain),
            acc.summaries,
            family_summary,
            toolpaths,
        );
        if !acc.timings.is_empty() {
            summary.timing = Some(Timing::new(self.trainer.name(), acc.timings));
        }
        Ok(summary)
    }
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
    /// Nothing yet, on the map grid `grid`.
    fn new(grid: Grid, normal: errmap_core::geom::Axis) -> Accumulated {
        Accumulated {
            summaries: Vec::new(),
            maps: FamilyMaps::new(grid, normal),
            delivered: Vec::new(),
            kept_maps: Vec::new(),
            timings: Vec::new(),
            toolpaths: Vec::new(),
        }
    }

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
fn survey_box(plan: &Plan, chunk_parts: usize, reporter: &dyn Reporter) -> Survey {
    let bar = reporter.progress(plan.parts.len() as u64, "clean");
    let mut survey = Survey {
        domain: None,
        first: Vec::new(),
        failed: Vec::new(),
    };
    for (k, chunk) in plan.parts.chunks(chunk_parts).enumerate() {
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

/// The family's training-grid sums before its parts train from its network (`warm_start =
/// "family"`): every member read, cleaned and interpolated once, chunk by chunk, in batch order.
/// Returns the first chunk of the run's own parts (`members` are they when `own`), kept.
fn family_prepass(
    run: &Run,
    members: &[PartInput],
    own: bool,
    first: &mut Option<Vec<Prep>>,
    nodes: &mut FamilyNodes,
) -> Option<Vec<Prep>> {
    let (grids, s) = (&run.grids, &run.plan.settings);
    let bar = run.reporter.progress(members.len() as u64, "family mean");
    let mut kept = None;
    for (k, chunk) in members.chunks(run.chunk_parts).enumerate() {
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

#[cfg(test)]
mod tests {
    use super::*;
    use errmap_core::geom::Axis;
    use errmap_maps::interp::Method;
    use std::path::Path;

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
}
