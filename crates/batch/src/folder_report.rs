//! Which report a folder gets: a batch run's (it has `run.json`) or its analysis results' (`*.json` of format `errmap-result/1`).

use super::manifest::{RunManifest, RUN_MANIFEST};
use super::run_page::{render_run, RunInput};
use super::summary::BatchSummary;
use crate::FolderError;
use errmap_core::error::{Diagnostic, Result};
use errmap_report::result::{read_result, render_results, results_in};
use std::path::Path;

/// The report of `source`: a batch run's folder, a folder of analysis results, or one
/// result file.
pub fn render_path(source: &Path) -> Result<String, FolderError> {
    if source.is_file() {
        return match read_result(source)? {
            Some(r) => render_results(&[(source.to_path_buf(), r)]).map_err(Into::into),
            None => Err(FolderError::NotARun(not_a_source(source))),
        };
    }
    if !source.is_dir() {
        return Err(FolderError::NotARun(Diagnostic::usage(
            format!("{} does not exist", source.display()),
            "pass the folder of an errmap batch run or of an analysis's outputs",
        )));
    }
    if source.join(RUN_MANIFEST).is_file() {
        errmap_core::io::safety::protect(&source.join(RUN_MANIFEST));
        let manifest = RunManifest::read(source)?
            .ok_or_else(|| Diagnostic::Internal("run.json vanished".into()))?;
        let summary = BatchSummary::read(&source.join("summary.json"))?;
        let input = RunInput {
            dir: source,
            manifest: &manifest,
            summary: &summary,
        };
        return Ok(render_run(&input)?);
    }
    let results = results_in(source)?;
    if results.is_empty() {
        return Err(FolderError::NotARun(not_a_source(source)));
    }
    render_results(&results).map_err(Into::into)
}

fn not_a_source(source: &Path) -> Diagnostic {
    Diagnostic::usage(
        format!(
            "{} holds no errmap run ({RUN_MANIFEST}) and no analysis result",
            source.display()
        ),
        format!("pass a batch's output folder, or the folder where linear analyze {chart}, thermal difference/evaluate, rotary analyze {chart} or circular -o wrote", chart = errmap_core::setting::words(crate::Setting::Chart)),
    )
}
