//! `timing.json` of a run that stops on the hold-out RMS: each part's hold-out RMS at every check with the training seconds so far, and its time-to-accuracy; the one output that differs from run to run.

use serde::{Deserialize, Serialize};
use std::path::Path;

use errmap_core::Result;
use errmap_maps::nn::stop::{time_to_accuracy, CurvePoint, GroupOutcome, ACCURACY_TOLERANCE};

/// Deterministic figures of a part's hold-out stopping, kept in `summary.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Stopping {
    /// Steps of the best check: the steps the part's networks keep.
    pub best_epochs: u32,
    /// Steps trained when the fit stopped.
    pub stopped_epochs: u32,
    /// First check within 5 % of the converged (lowest) hold-out RMS.
    pub epochs_to_accuracy: Option<u32>,
}

/// One part's curve and time-to-accuracy.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PartTiming {
    pub part: String,
    pub best_epochs: u32,
    pub stopped_epochs: u32,
    /// Lowest hold-out RMS of the curve, µm: the converged value.
    pub converged_holdout_rmse_um: Option<f64>,
    pub epochs_to_accuracy: Option<u32>,
    /// Training seconds until the hold-out RMS was within 5 % of the converged value.
    pub seconds_to_accuracy: Option<f64>,
    /// Training seconds until the fit stopped.
    pub seconds_to_stop: f64,
    /// Every check, the first at epoch 0 (the starting network).
    pub curve: Vec<CurvePoint>,
}

impl PartTiming {
    pub fn new(part: &str, outcome: &GroupOutcome) -> PartTiming {
        let accuracy = time_to_accuracy(&outcome.curve, ACCURACY_TOLERANCE);
        PartTiming {
            part: part.to_string(),
            best_epochs: outcome.best_epochs,
            stopped_epochs: outcome.stopped_epochs,
            converged_holdout_rmse_um: accuracy.map(|a| a.converged_rmse_um),
            epochs_to_accuracy: accuracy.map(|a| a.epochs),
            seconds_to_accuracy: accuracy.map(|a| a.seconds),
            seconds_to_stop: outcome.curve.last().map_or(0.0, |p| p.seconds),
            curve: outcome.curve.clone(),
        }
    }

    /// The deterministic part, for `summary.json`.
    pub fn stopping(&self) -> Stopping {
        Stopping {
            best_epochs: self.best_epochs,
            stopped_epochs: self.stopped_epochs,
            epochs_to_accuracy: self.epochs_to_accuracy,
        }
    }
}

/// `timing.json` (`format = "errmap-timing/1"`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Timing {
    pub format: String,
    /// Share of the converged hold-out RMS that counts as accurate.
    pub tolerance: f64,
    /// The trainer (as in `summary.json`).
    pub backend: String,
    pub parts: Vec<PartTiming>,
}

impl Timing {
    pub fn new(backend: String, parts: Vec<PartTiming>) -> Timing {
        Timing {
            format: "errmap-timing/1".into(),
            tolerance: ACCURACY_TOLERANCE,
            backend,
            parts,
        }
    }

    /// One line for the console: the parts' stop epochs and their slowest time-to-accuracy.
    pub fn line(&self) -> String {
        let range = |v: Vec<u32>| match (v.iter().min(), v.iter().max()) {
            (Some(a), Some(b)) if a == b => format!("{a}"),
            (Some(a), Some(b)) => format!("{a}–{b}"),
            _ => "-".into(),
        };
        let stopped = range(self.parts.iter().map(|p| p.stopped_epochs).collect());
        let best = range(self.parts.iter().map(|p| p.best_epochs).collect());
        let slowest = self
            .parts
            .iter()
            .filter_map(|p| p.seconds_to_accuracy.map(|s| (s, p)))
            .max_by(|a, b| a.0.total_cmp(&b.0));
        let accuracy = slowest.map_or("-".into(), |(s, p)| {
            format!(
                "{s:.2} s at most ({}, {} epochs)",
                p.part,
                p.epochs_to_accuracy.unwrap_or(0)
            )
        });
        format!(
            "hold-out stopping: {} parts stopped at {stopped} epochs, kept {best}; within {:.0} % of the converged hold-out RMS after {accuracy}",
            self.parts.len(),
            self.tolerance * 100.0
        )
    }

    pub fn write(&self, dir: &Path) -> Result<()> {
        errmap_core::io::write_json(&dir.join("timing.json"), self)
    }
}
