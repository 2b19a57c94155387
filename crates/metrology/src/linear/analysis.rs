//! The linear-axis commands as library calls: read the runs with their corrections, evaluate by a standard, fit the pitch, apply a table, draw the chart with its result file; plan a compensation table.

use super::chart::{save_chart, ChartInput};
use super::columns::ColumnMap;
use super::correct::{correct_air, normalise_material, AirCorrection};
use super::eval::{evaluate, Evaluation, Standard};
use super::pitch::{fit_pitch, PitchFit};
use super::report_json::AnalyzeJson;
use super::runs::{read_runs, read_runs_mapped, Direction, RunFile, Sample};
use super::table::{read_table, CompTable, TableFormat, TableOptions};
use errmap_core::error::Result;
use std::path::{Path, PathBuf};

/// Corrections applied to the readings before anything else.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Corrections {
    /// Readings on the vacuum-wavelength scale, rescaled by each row's air.
    pub air: Option<AirCorrection>,
    /// Normalise to 20 °C with this expansion coefficient (µm/(m·K)).
    pub material_expansion_ppm_per_k: Option<f64>,
    /// Machine position (mm) where the laser was zeroed.
    pub datum_mm: f64,
}

/// A run file to read: through an instrument's column map (`FIELD=COLUMN[unit],…`) if given,
/// with corrections applied.
#[derive(Debug, Clone, Copy)]
pub struct RunSource<'a> {
    /// The run file: errmap's run CSV, or an instrument's export when `columns` is given.
    pub path: &'a Path,
    /// Column mapping of an instrument export (`FIELD=COLUMN[unit],…`, see [`ColumnMap`]); `None`:
    /// the file is errmap's run CSV.
    pub columns: Option<&'a str>,
    /// Air and material corrections applied to the readings after reading.
    pub corrections: Corrections,
}

impl RunSource<'_> {
    /// Read the runs and apply the corrections; returns the file and a note per correction.
    pub fn load(&self) -> Result<(RunFile, Vec<String>), crate::error::LinearError> {
        let mut notes = Vec::new();
        let mut file = match self.columns {
            Some(spec) => read_runs_mapped(self.path, &ColumnMap::parse(spec)?)?,
            None => read_runs(self.path)?,
        };
        if let Some(air) = &self.corrections.air {
            let (corrected, n) = correct_air(&file, air)?;
            let mean = n.iter().sum::<f64>() / n.len().max(1) as f64;
            notes.push(format!(
                "air-corrected with {} at {} nm: mean n = {mean:.9}",
                air.formula.name(),
                air.wavelength_nm
            ));
            file = corrected;
        }
        if let Some(alpha) = self.corrections.material_expansion_ppm_per_k {
            file = normalise_material(&file, alpha, self.corrections.datum_mm)?;
            notes.push(format!("normalised to 20 °C with α = {alpha} µm/(m·K)"));
        }
        Ok((file, notes))
    }
}

/// What `linear analyze` does.
#[derive(Debug, Clone)]
pub struct AnalyzeRequest<'a> {
    /// The laser runs to evaluate and their corrections.
    pub runs: RunSource<'a>,
    /// The standard the figures follow, before and after the table.
    pub standard: Standard,
    /// Fit the pitch error with this screw lead (mm).
    pub fit_pitch_lead_mm: Option<f64>,
    /// Apply this compensation table and evaluate again.
    pub apply_table: Option<&'a Path>,
    /// Its format (`None`: recognised from the content).
    pub table_format: Option<TableFormat>,
    /// Options of reading the table; a missing reference is the first target.
    pub table_options: TableOptions,
    /// Draw the chart here and write the result beside it.
    pub chart: Option<&'a Path>,
}

/// The result of [`analyze`].
#[derive(Debug, Clone)]
pub struct Analysis {
    /// The figures of the corrected runs (deviations actual − target, µm).
    pub evaluation: Evaluation,
    /// The pitch-error fit of the targets' mean deviations; `None` when no screw lead was given.
    pub fit: Option<PitchFit>,
    /// The table applied and the evaluation with it active.
    pub after: Option<(PathBuf, Evaluation)>,
    /// A note per correction applied.
    pub notes: Vec<String>,
}

impl Analysis {
    /// The JSON document of the analysis.
    pub fn document(&self) -> AnalyzeJson<'_> {
        AnalyzeJson::new(
            &self.evaluation,
            self.fit.as_ref(),
            self.after.as_ref().map(|(p, a)| (p.as_path(), a)),
            &self.notes,
        )
    }
}

/// Evaluate laser runs by a standard, with the pitch fit, the table check and the chart (and
/// its result file) that `req` asks for.
pub fn analyze(req: &AnalyzeRequest<'_>) -> Result<Analysis, crate::error::LinearError> {
    let (file, notes) = req.runs.load()?;
    let samples = file.samples();
    let ev = evaluate(&samples, req.standard)?;
    let fit = match req.fit_pitch_lead_mm {
        Some(lead) => {
            let xs: Vec<f64> = ev.targets.iter().map(|t| t.target).collect();
            let es: Vec<f64> = ev.targets.iter().map(|t| t.mean_any()).collect();
            Some(fit_pitch(&xs, &es, lead)?)
        }
        None => None,
    };
    let after = match req.apply_table {
        Some(path) => {
            let opts = TableOptions {
                reference_mm: req
                    .table_options
                    .reference_mm
                    .or(ev.targets.first().map(|t| t.target)),
                ..req.table_options.clone()
            };
            let table = read_table(path, req.table_format, &opts)?;
            let with_table = evaluate(&table.apply(&samples), req.standard)?;
            Some((path.to_path_buf(), with_table))
        }
        None => None,
    };
    let analysis = Analysis {
        evaluation: ev,
        fit,
        after,
        notes,
    };
    if let Some(png) = req.chart {
        write_chart(req, &analysis, png)?;
    }
    Ok(analysis)
}

/// The chart of an analysis and, beside it, its result (read by `errmap report`).
fn write_chart(req: &AnalyzeRequest<'_>, a: &Analysis, png: &Path) -> Result<()> {
    let title = format!(
        "{} — positioning deviation",
        req.runs
            .path
            .file_name()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default()
    );
    save_chart(
        png,
        &ChartInput {
            title,
            unit: "µm",
            before: &a.evaluation,
            after: a.after.as_ref().map(|a| &a.1),
            fit: a.fit.as_ref(),
        },
    )?;
    let mut inputs: Vec<&Path> = vec![req.runs.path];
    inputs.extend(req.apply_table);
    errmap_report::result::write_result(
        &errmap_report::result::beside(png),
        &errmap_report::result::ResultSpec {
            kind: "linear-analysis",
            title: format!(
                "Linear axis {} ({})",
                req.runs.path.display(),
                a.evaluation.standard
            ),
            inputs: &inputs,
            charts: &[png],
            table: req.apply_table,
        },
        &a.document(),
    )
}

/// A compensation table ready to render (`render_table`), and what the user should know.
#[derive(Debug, Clone)]
pub struct TablePlan {
    /// The table: each direction's mean error (µm) at points every spacing from the first target.
    pub table: CompTable,
    /// The one direction of unidirectional runs (the table carries it for both).
    pub unidirectional: Option<Direction>,
    /// Notes of the corrections and of the table.
    pub notes: Vec<String>,
}

/// Evaluate runs by ISO 230-2:2014 and build their compensation table with points every
/// `spacing_mm` from the first target.
pub fn plan_table(
    runs: &RunSource<'_>,
    spacing_mm: f64,
) -> Result<TablePlan, crate::error::LinearError> {
    let (file, mut notes) = runs.load()?;
    let ev = evaluate(&file.samples(), Standard::Iso230_2_2014)?;
    let table = CompTable::from_evaluation(&ev, spacing_mm)?;
    notes.extend(table.notes.iter().cloned());
    Ok(TablePlan {
        table,
        unidirectional: ev.unidirectional,
        notes,
    })
}

impl CompTable {
    /// The deviations the runs would show with the table active: e − e_table(direction, x).
    pub fn apply(&self, samples: &[Sample]) -> Vec<Sample> {
        samples
            .iter()
            .map(|s| Sample {
                deviation: s.deviation - self.error_at(s.direction, s.target),
                ..*s
            })
            .collect()
    }
}
