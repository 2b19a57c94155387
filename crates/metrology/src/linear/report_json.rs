//! The JSON documents of the linear-axis analyses: `linear analyze --json` (and the result beside its chart) and `linear air-index --json`; serde types whose field order is the documents' key order.

use super::air::AirConditions;
use super::eval::{target_symbols, AxisFigures, Evaluation, Figure};
use super::pitch::PitchFit;
use super::runs::Direction;
use std::path::Path;

/// One target of the analyze document (issue 4's shape, in its order).
///
/// A projection of [`super::TargetFigures`] kept as its own type on purpose: its keys and their
/// order are a published format (docs/linear.md) that must not follow changes to the library's
/// struct, which other documents serialize whole.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct TargetJson {
    pub target_mm: f64,
    pub mean_up: Option<f64>,
    pub mean_down: Option<f64>,
    pub s_up: Option<f64>,
    pub s_down: Option<f64>,
    pub reversal: Option<f64>,
    pub repeatability_up: Option<f64>,
    pub repeatability_down: Option<f64>,
    pub repeatability: Option<f64>,
}

/// The per-target figures of an evaluation in the document's shape.
pub fn targets_json(ev: &Evaluation) -> Vec<TargetJson> {
    ev.targets
        .iter()
        .map(|t| TargetJson {
            target_mm: t.target,
            mean_up: t.mean_up,
            mean_down: t.mean_down,
            s_up: t.s_up,
            s_down: t.s_down,
            reversal: t.reversal,
            repeatability_up: t.repeatability_up,
            repeatability_down: t.repeatability_down,
            repeatability: t.repeatability,
        })
        .collect()
}

/// The figures after applying a compensation table.
#[derive(Debug, Clone, serde::Serialize)]
pub struct AfterJson<'a> {
    pub table: String,
    pub targets: Vec<TargetJson>,
    pub axis: &'a AxisFigures,
    pub figures: Vec<Figure>,
}

/// The analyze document: `standard`, `unit`, `targets`, `axis`, then the optional parts.
#[derive(Debug, Clone, serde::Serialize)]
pub struct AnalyzeJson<'a> {
    pub standard: &'static str,
    pub unit: &'static str,
    /// Present only for a unidirectional test: the one direction measured.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub unidirectional: Option<Direction>,
    /// Headings of the `targets` keys mean_up … repeatability in the standard's own symbols
    /// (empty: the standard defines no such figure).
    pub target_symbols: [&'static str; 8],
    pub targets: Vec<TargetJson>,
    pub axis: &'a AxisFigures,
    /// The axis figures in the standard's own symbols, with their definitions.
    pub figures: Vec<Figure>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pitch_fit: Option<&'a PitchFit>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub after: Option<AfterJson<'a>>,
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub corrections: Vec<String>,
}

impl<'a> AnalyzeJson<'a> {
    /// The document of an evaluation (µm), with its pitch fit, the evaluation after a table
    /// (`table` names it) and the notes of the corrections applied.
    pub fn new(
        ev: &'a Evaluation,
        fit: Option<&'a PitchFit>,
        after: Option<(&Path, &'a Evaluation)>,
        corrections: &[String],
    ) -> AnalyzeJson<'a> {
        AnalyzeJson {
            standard: ev.standard.name(),
            unit: "um",
            unidirectional: ev.unidirectional,
            target_symbols: target_symbols(ev.standard),
            targets: targets_json(ev),
            axis: &ev.axis,
            figures: ev.figures(),
            pitch_fit: fit,
            after: after.map(|(path, a)| AfterJson {
                table: path.display().to_string(),
                targets: targets_json(a),
                axis: &a.axis,
                figures: a.figures(),
            }),
            corrections: corrections.to_vec(),
        }
    }
}

/// The air-index document: the equation, n, the air wavelength, then the conditions.
#[derive(Debug, Clone, serde::Serialize)]
pub struct AirIndexJson {
    pub formula: &'static str,
    pub n: f64,
    pub air_wavelength_nm: f64,
    #[serde(flatten)]
    pub conditions: AirConditions,
}

impl AirIndexJson {
    /// The refractive index of air at `conditions` by `formula`, and the air wavelength.
    pub fn compute(
        conditions: AirConditions,
        formula: super::air::AirFormula,
    ) -> errmap_core::Result<AirIndexJson> {
        let n = super::air::refractive_index(&conditions, formula)?;
        Ok(AirIndexJson {
            formula: formula.name(),
            n,
            air_wavelength_nm: conditions.wavelength_nm / n,
            conditions,
        })
    }
}
