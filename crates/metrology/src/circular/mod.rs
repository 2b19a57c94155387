//! Dynamic circular test (ISO 230-4, ballbar or grid encoder): circular deviation G, radial deviation F, hysteresis H, and a least-squares diagnosis of the machine errors behind them.
//!
//! Data flow: [`read_run`] (radial or two-axis CSV, checked and sorted by angle) →
//! [`evaluate`] (least-squares centre by [`fit_circle`], exact minimum zone by
//! [`min_zone`] iterated on the exact radii, F, H) → [`diagnose`] (the model of
//! `model` fitted by least squares, decays and periods searched) → the polar chart
//! (`chart::save_polar_chart`).

pub(crate) mod chart;
pub(crate) mod circle;
pub(crate) mod diagnosis;
pub(crate) mod figures;
pub mod input;
pub(crate) mod model;
pub(crate) mod report;
pub(crate) mod zone;

pub use crate::error::CircularError;
pub use circle::{fit_circle, CircleFit};
pub use diagnosis::{diagnose, Diagnosis, Term, Terms};
pub use figures::{evaluate, Centred, Figures, PerDirection};
pub use input::{parse_run, read_run, CircularRun, Form, Plane, ReadOptions, Reading, Rotation};
pub use report::{human_report, parse_centre_mm, run_test, TestRequest};
pub use zone::{min_zone, Zone};

use serde::Serialize;

/// Everything `errmap circular` reports: the ISO 230-4 figures and the diagnosis.
#[derive(Debug, Clone, Serialize)]
pub struct Evaluation {
    /// The plane of the circle, which names its first and second axis.
    pub plane: Plane,
    /// Names of the plane's first and second axis.
    pub axes: [&'static str; 2],
    /// The ISO 230-4 figures, their keys flattened into the document.
    #[serde(flatten)]
    pub figures: Figures,
    /// The machine errors the diagnosis found behind the path's shape.
    pub terms: Terms,
    /// Root mean square of the deviations the diagnosis model leaves unexplained, µm.
    pub residual_rms_um: f64,
    /// The model's nuisance values, its size and the ranking of the terms.
    pub model: diagnosis::ModelInfo,
}

/// Evaluate a run: the figures, then the diagnosis of the deviations about the least-squares
/// centre. Also returns the centred readings and the modelled deviation at each (for charts).
pub fn analyze(
    run: &CircularRun,
    plane: Plane,
    feed_mm_per_min: Option<f64>,
) -> errmap_core::Result<(Evaluation, Centred, Vec<f64>)> {
    let (figures, centred) = evaluate(run)?;
    let d = diagnose(
        &centred,
        run.radius_mm,
        feed_mm_per_min,
        figures.reference_g_um(),
    )?;
    let eval = Evaluation {
        plane,
        axes: plane.axes(),
        figures,
        terms: d.terms,
        residual_rms_um: d.residual_rms_um,
        model: d.model,
    };
    Ok((eval, centred, d.fitted_um))
}
