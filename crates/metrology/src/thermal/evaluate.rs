//! Positioning figures before and after thermal compensation, per measurement time, by the
//! linear module's evaluation (ISO 230-2, GB 10931, VDI 3441).
//!
//! "After" is what the axis would read with the model's compensation applied:
//! deviation − E_model(x, T) for every reading (P' = P − E moves the axis by −E).

use super::campaign::{Campaign, LaserPoint};
use super::model::ThermalModel;
use crate::linear::{evaluate, AxisFigures, Sample, Standard};
use errmap_core::error::Result;
use serde::Serialize;

/// Axis figures of one measurement, before and after compensation.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TimeFigures {
    pub campaign: String,
    pub time_s: f64,
    pub before: AxisFigures,
    pub after: AxisFigures,
    /// RMS of the readings before and after (µm).
    pub rms_before_um: f64,
    pub rms_after_um: f64,
}

/// Figures of every measurement of every campaign.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EvaluationReport {
    pub standard: Standard,
    pub times: Vec<TimeFigures>,
}

fn rms(v: &[Sample]) -> f64 {
    (v.iter().map(|s| s.deviation * s.deviation).sum::<f64>() / v.len().max(1) as f64).sqrt()
}

/// Evaluate campaigns before and after compensation by `model`.
pub fn evaluate_campaigns(
    model: &ThermalModel,
    campaigns: &[Campaign],
    standard: Standard,
) -> Result<EvaluationReport> {
    let mut times = Vec::new();
    for c in campaigns {
        for m in &c.measurements {
            let state = model.state_of(c, m)?;
            // The measured deviations less `modelled_um` of each point.
            let samples = |modelled_um: &dyn Fn(&LaserPoint) -> f64| -> Vec<Sample> {
                m.points
                    .iter()
                    .map(|p| Sample {
                        run: p.run,
                        direction: p.direction,
                        target: p.target_mm,
                        deviation: p.deviation_um - modelled_um(p),
                    })
                    .collect()
            };
            let before = samples(&|_| 0.0);
            let after = samples(&|p| model.error_um(p.direction, p.target_mm, &state));
            times.push(TimeFigures {
                campaign: c.name.clone(),
                time_s: m.time_s,
                before: evaluate(&before, standard)?.axis,
                after: evaluate(&after, standard)?.axis,
                rms_before_um: rms(&before),
                rms_after_um: rms(&after),
            });
        }
    }
    Ok(EvaluationReport { standard, times })
}
