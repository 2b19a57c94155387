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
    /// Target position, mm.
    pub target_mm: f64,
    /// x̄_i↑: mean deviation (actual − target) of the forward approaches, µm; null when not
    /// measured.
    pub mean_up: Option<f64>,
    /// x̄_i↓: mean deviation of the reverse approaches, µm; null when not measured.
    pub mean_down: Option<f64>,
    /// s_i↑: standard deviation of the forward approaches, µm; null when n < 2.
    pub s_up: Option<f64>,
    /// s_i↓: standard deviation of the reverse approaches, µm; null when n < 2.
    pub s_down: Option<f64>,
    /// Reversal B_i = x̄_i↑ − x̄_i↓, µm; null in a unidirectional test.
    pub reversal: Option<f64>,
    /// Unidirectional repeatability ↑ at the target (2k·s_i↑), µm.
    pub repeatability_up: Option<f64>,
    /// Unidirectional repeatability ↓ at the target (2k·s_i↓), µm.
    pub repeatability_down: Option<f64>,
    /// Bidirectional repeatability at the target (ISO R_i, GB max(R_i↑, R_i↓), VDI Ps_j), µm.
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
    /// The compensation table applied, its path as given.
    pub table: String,
    /// The per-target figures with the table active.
    pub targets: Vec<TargetJson>,
    /// The axis figures with the table active, µm.
    pub axis: &'a AxisFigures,
    /// The standard's axis figures with the table active.
    pub figures: Vec<Figure>,
}

/// The analyze document: `standard`, `unit`, `targets`, `axis`, then the optional parts.
#[derive(Debug, Clone, serde::Serialize)]
pub struct AnalyzeJson<'a> {
    /// The standard's name (`iso230-2:2014`, `iso230-2:1997`, `gb10931-1989`, `vdi3441`).
    pub standard: &'static str,
    /// Unit of every deviation figure: always `um`.
    pub unit: &'static str,
    /// Present only for a unidirectional test: the one direction measured.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub unidirectional: Option<Direction>,
    /// Headings of the `targets` keys mean_up … repeatability in the standard's own symbols
    /// (empty: the standard defines no such figure).
    pub target_symbols: [&'static str; 8],
    /// The per-target figures, targets ascending.
    pub targets: Vec<TargetJson>,
    /// The axis figures, µm.
    pub axis: &'a AxisFigures,
    /// The axis figures in the standard's own symbols, with their definitions.
    pub figures: Vec<Figure>,
    /// The pitch-error fit; absent when no screw lead was given.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pitch_fit: Option<&'a PitchFit>,
    /// The figures with a compensation table applied; absent when none was.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub after: Option<AfterJson<'a>>,
    /// A note per correction applied to the readings (air, material); absent when none.
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
    /// The equation's name (`ciddor`, `edlen`).
    pub formula: &'static str,
    /// Refractive index of air (phase index, dimensionless, > 1).
    pub n: f64,
    /// Wavelength in air λ₀ / n, nm.
    pub air_wavelength_nm: f64,
    /// The conditions n was computed at, their keys flattened into the document.
    #[serde(flatten)]
    pub conditions: AirConditions,
}

impl AirIndexJson {
    /// The refractive index of air at `conditions` by `formula`, and the air wavelength.
    pub fn compute(
        conditions: AirConditions,
        formula: super::air::AirFormula,
    ) -> errmap_core::Result<AirIndexJson, crate::error::LinearError> {
        let n = super::air::refractive_index(&conditions, formula)?;
        Ok(AirIndexJson {
            formula: formula.name(),
            n,
            air_wavelength_nm: conditions.wavelength_nm / n,
            conditions,
        })
    }
}
