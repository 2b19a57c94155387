//! Stopping on the hold-out RMS: Adam in segments of `check_every_epochs`, the hold-out RMS measured on the CPU between segments, the best parameters kept; and time-to-accuracy on the recorded curve.
//!
//! The decision reads only parameters and held-out points, evaluated with [`Mlp::forward`]
//! on the CPU whatever trained the networks, so the same job on the same backend stops at
//! the same epoch every run. Seconds are recorded beside the curve but decide nothing.

use std::time::Instant;

use super::train::{AdamRun, Trainer, TrainingSet};
use super::{Mlp, ModelConfig, Normalisation};
use errmap_core::Result;

/// Share of the converged hold-out RMS within which a fit counts as accurate (5 %).
pub const ACCURACY_TOLERANCE: f64 = 0.05;

/// Held-out probe points of one network, in its units: scaled inputs, the measured errors in
/// µm, and the normalisation that turns its output into µm.
#[derive(Debug, Clone, PartialEq)]
pub struct Holdout {
    /// Scaled `(u, v)` of each held-out point, in [-1, 1]² over the map domain.
    pub inputs: Vec<[f32; 2]>,
    /// Measured error E of each held-out point, µm, one per input.
    pub e_um: Vec<f64>,
    /// The normalisation of the network judged on these points.
    pub norm: Normalisation,
}

impl Holdout {
    /// RMS of (held-out value − network), µm; NaN when there are no points.
    pub fn rms_um(&self, net: &Mlp) -> f64 {
        let sq: f64 = self
            .inputs
            .iter()
            .zip(&self.e_um)
            .map(|(&x, &e)| (e - self.norm.unscale_output(net.forward(x))).powi(2))
            .sum();
        (sq / self.e_um.len() as f64).sqrt()
    }
}

/// Networks of a batch that stop together: `judge` is measured on `holdout`, and every
/// member (the judge included) ends with its parameters of the judge's best check.
#[derive(Debug, Clone, PartialEq)]
pub struct StopGroup {
    /// Index of the network whose hold-out RMS decides, in the batch given to
    /// [`train_until_holdout_stops`].
    pub judge: usize,
    /// Indices of the networks that stop with the judge, the judge included.
    pub members: Vec<usize>,
    /// The points the judge is measured on (points it was not trained on).
    pub holdout: Holdout,
}

/// One hold-out check: steps done, training seconds so far, the judge's hold-out RMS.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct CurvePoint {
    /// Optimiser steps done at the check.
    pub epochs: u32,
    /// Wall-clock seconds of training up to the check (hold-out evaluations not counted).
    pub seconds: f64,
    /// RMS of (held-out E − network), µm, at the check; NaN for no held-out points.
    pub holdout_rmse_um: f64,
}

/// What the stage did for one group.
#[derive(Debug, Clone, PartialEq)]
pub struct GroupOutcome {
    /// Checks in order, the first at epoch 0 (the starting parameters).
    pub curve: Vec<CurvePoint>,
    /// Steps of the best check: the parameters every member keeps.
    pub best_epochs: u32,
    /// Steps trained when the group stopped.
    pub stopped_epochs: u32,
}

/// When a curve first came within `tolerance` of its converged (lowest) hold-out RMS.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Accuracy {
    /// The lowest finite hold-out RMS of the curve, µm.
    pub converged_rmse_um: f64,
    /// Steps at the first check within the tolerance of it.
    pub epochs: u32,
    /// Training seconds at that check.
    pub seconds: f64,
}

/// The first check whose hold-out RMS is at most (1 + `tolerance`) × the lowest of the
/// curve; `None` for a curve with no finite RMS.
pub fn time_to_accuracy(curve: &[CurvePoint], tolerance: f64) -> Option<Accuracy> {
    let best = curve
        .iter()
        .map(|p| p.holdout_rmse_um)
        .filter(|r| r.is_finite())
        .min_by(f64::total_cmp)?;
    let first = curve
        .iter()
        .find(|p| p.holdout_rmse_um <= best * (1.0 + tolerance))?;
    Some(Accuracy {
        converged_rmse_um: best,
        epochs: first.epochs,
        seconds: first.seconds,
    })
}

/// A group's running state: best check so far and checks since.
struct Tracker {
    outcome: GroupOutcome,
    best_rmse_um: f64,
    best_nets: Vec<Mlp>,
    stale: u32,
    active: bool,
}

/// The current network of run `k` (`None` while the run is out in a segment).
fn current(runs: &[Option<AdamRun>], k: usize) -> Option<Mlp> {
    runs[k].as_ref().map(|r| r.net.clone())
}

impl Tracker {
    /// The group at epoch 0: its judge's starting hold-out RMS is the first check and the best.
    fn start(group: &StopGroup, runs: &[Option<AdamRun>]) -> Tracker {
        let start = runs[group.judge]
            .as_ref()
            .map_or(f64::NAN, |r| group.holdout.rms_um(&r.net));
        Tracker {
            outcome: GroupOutcome {
                curve: vec![CurvePoint {
                    epochs: 0,
                    seconds: 0.0,
                    holdout_rmse_um: start,
                }],
                best_epochs: 0,
                stopped_epochs: 0,
            },
            best_rmse_um: start,
            best_nets: group
                .members
                .iter()
                .filter_map(|&k| current(runs, k))
                .collect(),
            stale: 0,
            active: true,
        }
    }

    /// Records the check at `epoch` (`seconds` of training so far), keeps the members if the
    /// judge is the best yet, and deactivates the group after `patience_checks` stale checks.
    /// Returns whether the group stops here.
    fn check(
        &mut self,
        group: &StopGroup,
        runs: &[Option<AdamRun>],
        epoch: u32,
        seconds: f64,
        patience_checks: u32,
    ) -> bool {
        let Some(judge) = runs[group.judge].as_ref() else {
            return false;
        };
        let rmse_um = group.holdout.rms_um(&judge.net);
        self.outcome.curve.push(CurvePoint {
            epochs: epoch,
            seconds,
            holdout_rmse_um: rmse_um,
        });
        self.outcome.stopped_epochs = epoch;
        // Strictly lower (NaN never is): ties keep the earlier, cheaper parameters.
        if rmse_um < self.best_rmse_um || (!self.best_rmse_um.is_finite() && rmse_um.is_finite()) {
            self.best_rmse_um = rmse_um;
            self.outcome.best_epochs = epoch;
            self.best_nets = group
                .members
                .iter()
                .filter_map(|&k| current(runs, k))
                .collect();
            self.stale = 0;
        } else {
            self.stale += 1;
        }
        if self.stale >= patience_checks {
            self.active = false;
        }
        !self.active
    }
}

/// Trains `initial[k]` on `sets[k]` with Adam for at most `config.epochs` steps in segments
/// of `config.check_every_epochs`; after each, every active group's judge is measured on its
/// hold-out points, and a group whose RMS has not fallen below its best for
/// `config.patience_checks` checks stops: its members leave the batch unchanged from then
/// on and end with their parameters of the best check. Networks in no group train all
/// `config.epochs` steps. Returns the networks and one outcome per group.
pub fn train_until_holdout_stops(
    trainer: &dyn Trainer,
    initial: Vec<Mlp>,
    sets: &[TrainingSet],
    groups: &[StopGroup],
    config: &ModelConfig,
) -> Result<(Vec<Mlp>, Vec<GroupOutcome>)> {
    let mut runs: Vec<Option<AdamRun>> =
        initial.into_iter().map(|n| Some(AdamRun::new(n))).collect();
    let mut trackers: Vec<Tracker> = groups.iter().map(|g| Tracker::start(g, &runs)).collect();
    let mut stopped = vec![false; runs.len()];
    let (mut epoch, mut seconds) = (0u32, 0.0f64);
    while epoch < config.epochs && stopped.iter().any(|s| !s) {
        let to = epoch
            .saturating_add(config.check_every_epochs)
            .min(config.epochs);
        seconds += train_segment_of_active(trainer, &mut runs, sets, &stopped, config, to)?;
        epoch = to;
        for (group, tracker) in groups.iter().zip(&mut trackers).filter(|(_, t)| t.active) {
            if tracker.check(group, &runs, epoch, seconds, config.patience_checks) {
                group.members.iter().for_each(|&k| stopped[k] = true);
            }
        }
    }
    Ok(best_of_groups(runs, groups, trackers))
}

/// Continues every run not `stopped` to epoch `to` in one batch; returns the seconds it took.
/// The runs come back to `runs` even when training fails.
fn train_segment_of_active(
    trainer: &dyn Trainer,
    runs: &mut [Option<AdamRun>],
    sets: &[TrainingSet],
    stopped: &[bool],
    config: &ModelConfig,
    to: u32,
) -> Result<f64> {
    let active: Vec<usize> = (0..runs.len()).filter(|&k| !stopped[k]).collect();
    let mut batch: Vec<AdamRun> = active.iter().filter_map(|&k| runs[k].take()).collect();
    let batch_sets: Vec<TrainingSet> = active.iter().map(|&k| sets[k].clone()).collect();
    let started = Instant::now();
    let trained = trainer.train_segment(&mut batch, &batch_sets, config, to);
    let seconds = started.elapsed().as_secs_f64();
    for (&k, run) in active.iter().zip(batch) {
        runs[k] = Some(run);
    }
    trained?;
    Ok(seconds)
}

/// The final networks (each group's members with their parameters of its best check) and
/// the groups' outcomes.
fn best_of_groups(
    runs: Vec<Option<AdamRun>>,
    groups: &[StopGroup],
    trackers: Vec<Tracker>,
) -> (Vec<Mlp>, Vec<GroupOutcome>) {
    let mut nets: Vec<Mlp> = runs.into_iter().flatten().map(|r| r.net).collect();
    let mut outcomes = Vec::with_capacity(groups.len());
    for (group, tracker) in groups.iter().zip(trackers) {
        for (&k, best) in group.members.iter().zip(tracker.best_nets) {
            nets[k] = best;
        }
        outcomes.push(tracker.outcome);
    }
    (nets, outcomes)
}
