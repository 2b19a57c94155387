//! Compensated toolpaths: a program rewritten with a part's or the family's map (`NAME-compensated.EXT` beside the map's `model.json`), a weak or too uncertain map refused, the outcome as a [`ToolpathSummary`].

use crate::plan::ToolpathPlan;
use crate::summary::ToolpathSummary;
use errmap_core::error::Diagnostic;
use errmap_maps::map::FittedModel;
use std::path::{Path, PathBuf};

pub(crate) fn compensate_one(
    input: &Path,
    dir: &Path,
    map_name: &str,
    model: &FittedModel,
    tp: &ToolpathPlan,
) -> ToolpathSummary {
    let output = dir.join(compensated_name(input));
    // A weak map is refused before the program is read; one without figures is used as before.
    let model_file = dir.join("model.json");
    let checked = model
        .check_benefit(
            tp.allow_weak_map,
            "set [toolpaths] allow_weak_map = true in the job",
            &model_file,
        )
        .map_err(Diagnostic::from)
        .and_then(|_| match tp.max_uncertainty_um {
            None => errmap_toolpath::compensate_file(input, &output, model, &tp.settings)
                .map_err(Into::into),
            Some(max_um) => {
                let bounded = model.bounded_by_uncertainty(max_um, &model_file)?;
                errmap_toolpath::compensate_file(input, &output, &bounded, &tp.settings)
                    .map_err(Into::into)
            }
        });
    match checked {
        Ok(report) => ToolpathSummary {
            input: input.to_path_buf(),
            output,
            map: map_name.into(),
            report: serde_json::to_value(&report).ok(),
            error: None,
        },
        Err(e) => ToolpathSummary {
            input: input.to_path_buf(),
            output,
            map: map_name.into(),
            report: None,
            error: Some(e.report()),
        },
    }
}

/// `finish.ngc` → `finish-compensated.ngc` in `dir`.
pub(crate) fn compensated_name(input: &Path) -> PathBuf {
    let stem = input
        .file_stem()
        .map_or("toolpath".into(), |s| s.to_string_lossy().to_string());
    match input.extension() {
        Some(ext) => PathBuf::from(format!("{stem}-compensated.{}", ext.to_string_lossy())),
        None => PathBuf::from(format!("{stem}-compensated")),
    }
}

/// The family map's toolpaths (those of a plan whose toolpaths take the family map), compensated
/// into the family folder `dir`.
pub(crate) fn compensate_family(
    toolpaths: Option<&ToolpathPlan>,
    dir: &Path,
    model: &FittedModel,
) -> Vec<ToolpathSummary> {
    let Some(tp) = toolpaths.filter(|tp| !tp.per_part) else {
        return Vec::new();
    };
    tp.files
        .iter()
        .map(|f| compensate_one(f, dir, "family", model, tp))
        .collect()
}
