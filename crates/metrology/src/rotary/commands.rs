//! The `rotary` commands as library calls: analyse a measurement file into the text or JSON document (with the chart and its result file beside it), and write a compensation table; each returns what the command prints.

use super::analysis::{analyze, Analysis, AnalyzeOptions, Sign};
use super::chart::save_error_chart;
use super::input::read_measurement;
use super::table::{build_table, render, CompTable, TableFormat, TableOptions, INTERPOLATION};
use super::text_report::text_report;
use errmap_core::error::{Error, Result};
use errmap_report::result::{beside, write_result, ResultSpec};
use std::path::{Path, PathBuf};

/// Read a measurement file and analyse it (errors in the `errmap` sign).
pub fn analyze_file(
    path: &Path,
    opts: &AnalyzeOptions,
) -> Result<Analysis, crate::error::RotaryError> {
    let m = read_measurement(path)?;
    analyze(&m, opts)
}

/// What `rotary analyze` is asked for.
#[derive(Debug, Clone)]
pub struct AnalyzeRequest<'a> {
    /// The measurement file (sphere centres or touch points, see docs/rotary.md).
    pub file: &'a Path,
    /// How to analyse it: sphere and stylus sizes, axis fit, reference angle.
    pub options: AnalyzeOptions,
    /// Sign of the errors in the text, JSON and chart.
    pub sign: Sign,
    /// Write the chart here and the result beside it as NAME.json (read by `errmap report`).
    pub chart: Option<&'a Path>,
    /// The JSON document instead of the text report.
    pub json: bool,
}

/// `rotary analyze`: analyse, write the chart and its result when asked, and return the text
/// report or the JSON document to print.
pub fn analyze_command(req: &AnalyzeRequest<'_>) -> Result<String, crate::error::RotaryError> {
    let analysis = analyze_file(req.file, &req.options)?.with_sign(req.sign);
    if let Some(png) = req.chart {
        save_chart_and_result(png, &analysis, req.file)?;
    }
    if req.json {
        json_document(&analysis).map_err(Into::into)
    } else {
        Ok(text_report(&analysis))
    }
}

/// The chart of `analysis` at `png` and, beside it, the result file for `errmap report`.
pub fn save_chart_and_result(
    png: &Path,
    analysis: &Analysis,
    input: &Path,
) -> Result<(), crate::error::RotaryError> {
    save_error_chart(png, analysis)?;
    write_result(
        &beside(png),
        &ResultSpec {
            kind: "rotary-analysis",
            title: format!("Rotary axis {}", analysis.axis),
            inputs: &[input],
            charts: &[png],
            table: None,
        },
        analysis,
    )
    .map_err(Into::into)
}

/// The JSON document of an analysis (pretty, with a final newline).
pub fn json_document(analysis: &Analysis) -> Result<String> {
    let text = serde_json::to_string_pretty(analysis)
        .map_err(|e| Error::Internal(format!("JSON of the analysis: {e}")))?;
    Ok(format!("{text}\n"))
}

/// What `rotary table` is asked for.
#[derive(Debug, Clone)]
pub struct TableRequest<'a> {
    /// The measurement file (sphere centres or touch points, see docs/rotary.md).
    pub file: &'a Path,
    /// How to analyse it: sphere and stylus sizes, axis fit, reference angle.
    pub options: AnalyzeOptions,
    /// The controller format to write.
    pub format: TableFormat,
    /// The output file (Sinumerik and Heidenhain write a second one beside it).
    pub output: &'a Path,
    /// Spacing of the entries (default: the measured spacing); must divide 360.
    pub step_deg: Option<f64>,
    /// Angle of one grid entry.
    pub start_deg: Option<f64>,
    /// The controller's options (axis name, units, table numbers).
    pub controller: TableOptions,
}

/// `rotary table`: analyse, build the table over the turn, write it in the controller's format
/// and return the summary to print.
pub fn table_command(req: &TableRequest<'_>) -> Result<String, crate::error::RotaryError> {
    let analysis = analyze_file(req.file, &req.options)?;
    let table = build_table(&analysis, req.step_deg, req.start_deg)?;
    let files = render(&table, req.format, &req.controller, req.output)?;
    for (path, text) in &files {
        errmap_core::io::write_atomic_bytes(path, text.as_bytes())?;
    }
    let paths: Vec<PathBuf> = files.into_iter().map(|f| f.0).collect();
    Ok(table_summary(&table, &paths))
}

/// The lines `rotary table` prints: entries, grid, files written and how the values come.
pub fn table_summary(table: &CompTable, written: &[PathBuf]) -> String {
    let names: Vec<String> = written.iter().map(|p| p.display().to_string()).collect();
    format!(
        "{} entries, 0° … 360° every {}°, written to {}\n{}\nvalues: {}\n",
        table.angles_deg.len(),
        table.step_deg,
        names.join(" and "),
        table.grid_note,
        INTERPOLATION,
    )
}
