//! Stage 3, train: a chunk's interpolated parts ([`Interpolated`]) made training sets (per part a hold-out and a delivered fit) and trained in one trainer call ([`Networks`]).

use super::nodes::Interpolated;
use crate::plan::Settings;
use crate::timing::PartTiming;
use crate::train_step::{train_parts, Role};
use errmap_core::error::{Diagnostic, Result};
use errmap_core::geom::Domain;
use errmap_core::progress::Reporter;
use errmap_maps::interp::Grid;
use errmap_maps::nn::stop::Holdout;
use errmap_maps::nn::{Mlp, Normalisation, Trainer, TrainingSet};

/// A chunk's training sets with their scaling and role: per part [hold-out fit], delivered fit.
pub(crate) struct TrainingSets {
    pub(crate) sets: Vec<TrainingSet>,
    pub(crate) norms: Vec<Normalisation>,
    pub(crate) roles: Vec<Role>,
    /// Per part: (hold-out slot, delivered slot).
    pub(crate) slots: Vec<(Option<usize>, usize)>,
    /// The held-out points of each slot (none for a delivered fit).
    pub(crate) holdouts: Vec<Option<Holdout>>,
}

impl TrainingSets {
    pub(crate) fn push(&mut self, (set, norm): (TrainingSet, Normalisation), role: Role) -> usize {
        self.sets.push(set);
        self.norms.push(norm);
        self.roles.push(role);
        self.sets.len() - 1
    }
}

/// The training sets of a chunk's parts.
pub(crate) fn training_sets(
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

/// A part's held-out probe points in the units of its hold-out network (`norm`).
pub(crate) fn held_out(p: &Interpolated, norm: &Normalisation) -> Holdout {
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

/// A chunk's networks, and per part its hold-out stopping.
pub(crate) struct Networks {
    pub(crate) nets: Vec<Mlp>,
    pub(crate) timings: Vec<Option<PartTiming>>,
}

/// Train a chunk's networks in one trainer call, from the family network when given.
pub(crate) fn train(
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
        return Err(Diagnostic::Internal(format!(
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

/// The `--verbose` line on a chunk's training: how many networks, how many points, which
/// schedule, on which trainer.
pub(crate) fn describe_training(
    t: &TrainingSets,
    s: &Settings,
    warm: bool,
    trainer: &dyn Trainer,
) -> String {
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
