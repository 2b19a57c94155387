//! One part mapped without a job file (`errmap map`): its settings checked and made a plan,
//! and the part's failure turned into the run's error.

use super::summary::BatchSummary;
use crate::plan::{PartInput, Plan, Settings};
use crate::RunError;
use errmap_core::error::{Diagnostic, Result};
use errmap_core::geom::{Axis, Domain};
use errmap_core::progress::Reporter;
use errmap_maps::interp::Method;
use errmap_maps::nn::{Backend, ModelConfig, Trainer};
use std::path::PathBuf;

/// The settings of one part's map, as `errmap map` takes them.
#[derive(Debug, Clone)]
pub struct MapRequest {
    /// The part's probe file (errmap CSV, a CSV export with `columns`, DMIS, XYZ or PLY); its
    /// stem names the part.
    pub probes: PathBuf,
    /// Folder the part's map, pictures, model and summary are written to.
    pub out_dir: PathBuf,
    /// Error direction: the map gives E along it over the two other axes.
    pub normal: Axis,
    /// Nominal coordinate along the normal for every point, mm, when the file has no nominal
    /// columns; `None` = the file's own.
    pub nominal_plane_mm: Option<f64>,
    /// Map domain in the plane, mm; `None` = the probes' bounding box.
    pub domain: Option<Domain>,
    /// Node spacing of the output map grid, mm.
    pub grid_step_mm: f64,
    /// How the probes are interpolated into the training set.
    pub method: Method,
    /// Node spacing of the training set inside the probes' hull, mm.
    pub spacing_mm: f64,
    /// Gross-error threshold: a probe whose leave-one-out residual exceeds k·σ (robust σ) is
    /// rejected.
    pub k_sigma: f64,
    /// Training epochs; `None`: the job file's default.
    pub epochs: Option<u32>,
    /// Seed of the random choices; `None`: the job file's default.
    pub seed: Option<u64>,
    /// The trainer: `auto`, `gpu`, `cpu` or `cpu-reference`.
    pub backend: Backend,
    /// Plausibility bound, mm: a probe deviation or map value beyond it is an error that names
    /// the likely unit slip.
    pub max_deviation_mm: f64,
    /// Column mapping of the probe file (a CSV export), see [`errmap_maps::probe::ProbeSpec::columns`].
    pub columns: Option<String>,
    /// 1-based header line of the probe file.
    pub header_line: Option<u64>,
}

impl MapRequest {
    /// The model configuration: the job file's defaults with this request's backend, epochs
    /// and seed, checked.
    pub fn model(&self) -> Result<ModelConfig, RunError> {
        let mut model = ModelConfig {
            backend: self.backend,
            ..ModelConfig::default()
        };
        if let Some(e) = self.epochs {
            model.epochs = e;
        }
        if let Some(s) = self.seed {
            model.seed = s;
        }
        model.validate()?;
        Ok(model)
    }

    /// The checked plan of one part named after its probe file, written into `out_dir`.
    pub fn plan(&self) -> Result<Plan, RunError> {
        if let Some(z) = self.nominal_plane_mm {
            if !z.is_finite() {
                return Err(RunError::Options(Diagnostic::usage(
                    format!(
                        "{} must be a finite number",
                        errmap_core::setting::words(errmap_maps::Setting::NominalPlane)
                    ),
                    format!(
                        "e.g. {} 5.0",
                        errmap_core::setting::words(errmap_maps::Setting::NominalPlane)
                    ),
                )));
            }
        }
        let model = self.model()?;
        if let Some(text) = &self.columns {
            errmap_maps::probe::ProbeColumns::parse(text)?;
        }
        if self.header_line == Some(0) {
            return Err(RunError::Options(Diagnostic::usage(
                format!(
                    "{} 0: lines are numbered from 1",
                    errmap_core::setting::words(errmap_maps::Setting::HeaderLine)
                ),
                "give the 1-based line of the header, as an editor shows it",
            )));
        }
        errmap_maps::probe::validate_max_deviation(
            self.max_deviation_mm,
            &errmap_core::setting::words(errmap_maps::Setting::MaxDeviation),
        )
        .map_err(Diagnostic::from)?;
        // One scan: too large for the memory bound is a refusal (exit 2) before it is read.
        let bound_mb = errmap_maps::probe::budget::max_memory_mb(None);
        errmap_maps::probe::budget::check(&self.probes, bound_mb)?;
        for (flag, v) in [
            (crate::Setting::GridStep, self.grid_step_mm),
            (crate::Setting::Spacing, self.spacing_mm),
            (crate::Setting::KSigma, self.k_sigma),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(RunError::Options(Diagnostic::usage(
                    format!(
                        "{} {v} must be a positive number",
                        errmap_core::setting::words(flag)
                    ),
                    "see errmap map --help",
                )));
            }
        }
        let name = self
            .probes
            .file_stem()
            .map_or("part".to_string(), |s| s.to_string_lossy().to_string());
        Ok(Plan {
            settings: Settings {
                family: name.clone(),
                normal: self.normal,
                nominal_plane_mm: self.nominal_plane_mm,
                domain: self.domain,
                grid_step_mm: self.grid_step_mm,
                k_sigma: self.k_sigma,
                method: self.method,
                spacing_mm: self.spacing_mm,
                model,
                max_deviation_mm: self.max_deviation_mm,
                columns: self.columns.clone(),
                header_line: self.header_line,
                reduce_inputs: false,
                max_memory_mb: None,
            },
            parts: vec![PartInput {
                name,
                probe_file: self.probes.clone(),
                out_dir: self.out_dir.clone(),
            }],
            family_parts: Vec::new(),
            family_dir: None,
            toolpaths: None,
            job: None,
            shard: None,
        })
    }
}

/// Map the one part of `plan`. A single part has no batch to finish: its failure is the
/// run's error, with its kind (and exit code), place and fix.
pub fn map_part(
    plan: &Plan,
    trainer: &dyn Trainer,
    reporter: &dyn Reporter,
) -> Result<BatchSummary, RunError> {
    let summary = super::execute(plan, trainer, reporter)?;
    if let Some(err) = summary.parts.first().and_then(|p| p.error.clone()) {
        return Err(RunError::from(err.into_error()));
    }
    Ok(summary)
}
