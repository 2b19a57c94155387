//! `summary.json` of a batch (and of one part), the printed table, and `merge` of shard summaries.

use crate::{FolderError, MergeError};
use errmap_core::error::{Diagnostic, ErrorReport, Location, Result};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// What happened to one part.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PartSummary {
    /// The part's name, which is also its folder in the run.
    pub part: String,
    /// The part's probe file, as the job's glob found it.
    pub probe_file: PathBuf,
    /// True when every output of the part was written.
    pub ok: bool,
    /// Probe points after averaging repeats (0 when the file could not be read).
    pub points: usize,
    /// Rows that were repeats of another row's nominal point, averaged into it.
    pub repeats_averaged: usize,
    /// Lines with text before a CSV export's header (date, title, program name), skipped;
    /// absent when none.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub preamble_lines: usize,
    /// DMIS features that are not points (planes, circles …), skipped; absent when none.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub skipped_features: usize,
    /// Probe points rejected as gross errors (leave-one-out residual beyond k·σ), listed in
    /// the part's `rejected.csv`.
    pub rejected: usize,
    /// Robust σ of the leave-one-out residuals of the clean points, µm.
    pub sigma_um: Option<f64>,
    /// Clean points held out of the first fit.
    pub holdout_points: usize,
    /// RMS of (held-out probe value − hold-out network), µm: the honest accuracy of the map.
    pub holdout_rmse_um: Option<f64>,
    /// The same for the kriging baseline (Gaussian process, Matérn 5/2 + nugget, maximum
    /// likelihood) fitted on the same points, µm.
    #[serde(default)]
    pub kriging_holdout_rmse_um: Option<f64>,
    /// `network` or `kriging`: the lower hold-out RMSE (a tie goes to the network).
    #[serde(default)]
    pub better_fit: Option<String>,
    /// The delivered map's hold-out RMSE, nested: each held-out point judged by the kind (network
    /// or kriging) chosen on the other held-out points, µm. The benefit share uses it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub delivered_holdout_rmse_um: Option<f64>,
    /// RMS of E (about zero) at the held-out points, µm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub holdout_e_rms_um: Option<f64>,
    /// Share of E the delivered map removes there: 1 − (its hold-out RMSE) / `holdout_e_rms_um`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub benefit_share: Option<f64>,
    /// RMS (about 0) of the map over the grid nodes in the measured domain (the probes' hull),
    /// µm.
    pub rms_um: Option<f64>,
    /// Peak-to-valley of the map over the same nodes, µm.
    pub pv_um: Option<f64>,
    /// Share of grid nodes outside the measured domain, where the map extrapolates.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub extrapolated_fraction: Option<f64>,
    /// RMS of the map over the extrapolated nodes alone, µm (not an accuracy figure).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rms_extrapolated_um: Option<f64>,
    /// Peak-to-valley over the extrapolated nodes alone, µm (not an accuracy figure).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pv_extrapolated_um: Option<f64>,
    /// Hold-out stopping (`stop = "holdout"`): the steps kept and trained, and the
    /// epochs to within 5 % of the converged hold-out RMS. Absent otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stopping: Option<super::timing::Stopping>,
    /// Median u(E) of the map over the grid nodes in the measured domain, µm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub u_median_um: Option<f64>,
    /// Largest u(E) of the map over the grid nodes in the measured domain, µm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub u_max_um: Option<f64>,
    /// The calibration factor c of u = c·σ_K, fitted on cross-validation folds.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub u_factor: Option<f64>,
    /// The probe noise s (1σ) the local kriging's nugget stands for, µm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub noise_um: Option<f64>,
    /// Folder of the part's files.
    pub output_dir: Option<PathBuf>,
    /// Why the part failed: `{kind, message, file, line, column, hint}` (kind `input`, `io`,
    /// `device` or `internal`).
    pub error: Option<ErrorReport>,
}

impl PartSummary {
    /// The summary of a part that failed: no figures, `ok` false and the error as a record.
    pub fn failed(part: &str, probe_file: &Path, error: &Diagnostic) -> PartSummary {
        PartSummary {
            part: part.into(),
            probe_file: probe_file.to_path_buf(),
            ok: false,
            points: 0,
            repeats_averaged: 0,
            preamble_lines: 0,
            skipped_features: 0,
            rejected: 0,
            sigma_um: None,
            holdout_points: 0,
            holdout_rmse_um: None,
            kriging_holdout_rmse_um: None,
            better_fit: None,
            delivered_holdout_rmse_um: None,
            holdout_e_rms_um: None,
            benefit_share: None,
            rms_um: None,
            pv_um: None,
            extrapolated_fraction: None,
            rms_extrapolated_um: None,
            pv_extrapolated_um: None,
            stopping: None,
            u_median_um: None,
            u_max_um: None,
            u_factor: None,
            noise_um: None,
            output_dir: None,
            error: Some(error.report()),
        }
    }
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}

/// One compensated toolpath.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ToolpathSummary {
    /// The program, its path taken from the job file's folder.
    pub input: PathBuf,
    /// The compensated program, in the folder of the map that compensated it (family or part).
    pub output: PathBuf,
    /// `family` or the part name whose map was used.
    pub map: String,
    /// The compensation report (moves changed, split, max |E| …), when it succeeded.
    pub report: Option<serde_json::Value>,
    /// Why it failed, as for a part.
    pub error: Option<ErrorReport>,
}

/// The family maps.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FamilySummary {
    /// Parts the family maps were built from.
    pub parts: usize,
    /// The family folder (mean and std maps, the family network's `model.json`).
    pub output_dir: PathBuf,
    /// RMS (about 0) of the mean map over the measured domain, µm.
    pub mean_rms_um: f64,
    /// Peak-to-valley of the mean map over the measured domain, µm.
    pub mean_pv_um: f64,
    /// Largest part-to-part standard deviation of E over the grid, µm.
    pub std_max_um: f64,
    /// Median and largest u(E) of the family map over its measured domain, µm:
    /// u = √(std² + Σ u_i² / N²), the parts' spread and their maps' own uncertainty.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub u_median_um: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub u_max_um: Option<f64>,
}

/// `summary.json` of a batch (or of one shard of it).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BatchSummary {
    /// The family name (a single part's own name without a job).
    pub family: String,
    /// The job file as given; `None` for a single part mapped without one.
    pub job: Option<PathBuf>,
    /// The trainer that fitted the networks ("cpu", "gpu (…)").
    pub backend: String,
    /// Error direction of the maps.
    pub normal: errmap_core::geom::Axis,
    /// `[index, count]` of this shard (0-based index), absent when the batch was not split.
    pub shard: Option<[usize; 2]>,
    /// Map domain `[u_min, v_min, u_max, v_max]`, mm.
    pub domain_mm: Option<[f64; 4]>,
    /// Node spacing of the map grids, mm.
    pub grid_step_mm: f64,
    /// Every part of the run, in batch order.
    pub parts: Vec<PartSummary>,
    /// Parts that failed (their `error` says why).
    pub failed_parts: usize,
    /// The family maps; `None` for a shard or a single part.
    pub family_map: Option<FamilySummary>,
    /// The compensated toolpaths; empty when the job has none.
    pub toolpaths: Vec<ToolpathSummary>,
    /// Hold-out curves and time-to-accuracy (`stop = "holdout"`): written to `timing.json`,
    /// never to `summary.json` (seconds differ from run to run).
    #[serde(skip)]
    pub timing: Option<super::timing::Timing>,
}

impl BatchSummary {
    /// 0 when every part and toolpath succeeded, 1 otherwise (the batch finished).
    pub fn exit_code(&self) -> i32 {
        if self.failed_parts > 0 || self.toolpaths.iter().any(|t| t.error.is_some()) {
            1
        } else {
            0
        }
    }

    /// Read a `summary.json` written by a batch or a shard; an error names the line and column
    /// where it is not one.
    pub fn read(path: &Path) -> Result<BatchSummary, FolderError> {
        let text = errmap_core::io::read_text(path)?;
        serde_json::from_str(&text).map_err(|e| {
            FolderError::File(Diagnostic::input(
                Location::cell(path, e.line() as u64, e.column().to_string()),
                format!("not an errmap batch summary: {e}"),
                format!(
                    "pass the summary*.json files written by `errmap batch {}`",
                    errmap_core::setting::words(crate::Setting::Shard)
                ),
            ))
        })
    }

    /// The short table: part, points, rejected, hold-out RMS µm, PV µm, benefit % (and errors).
    pub fn table(&self) -> String {
        let opt = |v: Option<f64>, d: usize| v.map_or("-".to_string(), |x| format!("{x:.d$}"));
        let mut s = format!(
            "{:<12} {:>7} {:>9} {:>16} {:>8} {:>8} {:>10} {:>11}\n",
            "part",
            "points",
            "rejected",
            "hold-out RMS µm",
            "RMS µm",
            "PV µm",
            "benefit %",
            "u(E) max µm"
        );
        for p in &self.parts {
            if p.ok {
                s.push_str(&format!(
                    "{:<12} {:>7} {:>9} {:>16} {:>8} {:>8} {:>10} {:>11}\n",
                    p.part,
                    p.points,
                    p.rejected,
                    opt(p.delivered_holdout_rmse_um.or(p.holdout_rmse_um), 2),
                    opt(p.rms_um, 2),
                    opt(p.pv_um, 2),
                    opt(p.benefit_share.map(|b| b * 100.0), 1),
                    opt(p.u_max_um, 2)
                ));
            } else {
                s.push_str(&format!(
                    "{:<12} FAILED: {}\n",
                    p.part,
                    p.error
                        .as_ref()
                        .map_or("unknown error".to_string(), |e| e.to_string())
                ));
            }
        }
        if let Some(t) = &self.timing {
            s.push_str(&t.line());
            s.push('\n');
        }
        if let Some(f) = &self.family_map {
            s.push_str(&format!(
                "family of {} parts: mean map RMS {:.2} µm, PV {:.2} µm; part-to-part std up to {:.2} µm; benefit unknown (the family map has no held-out points)\n",
                f.parts, f.mean_rms_um, f.mean_pv_um, f.std_max_um
            ));
        }
        for t in &self.toolpaths {
            match (&t.error, &t.report) {
                (Some(e), _) => {
                    s.push_str(&format!("toolpath {}: FAILED: {e}\n", t.input.display()))
                }
                (None, _) => s.push_str(&format!(
                    "toolpath {} → {} ({} map)\n",
                    t.input.display(),
                    t.output.display(),
                    t.map
                )),
            }
        }
        s
    }
}

/// Join shard summaries of one family into one: parts of every shard in part order.
pub fn merge(summaries: &[(PathBuf, BatchSummary)]) -> Result<BatchSummary, MergeError> {
    let Some((first_path, first)) = summaries.first() else {
        return Err(MergeError::Missing(Diagnostic::usage(
            "no summaries to merge",
            "pass the shards' summary files",
        )));
    };
    let mut merged = first.clone();
    merged.shard = None;
    merged.parts.clear();
    merged.toolpaths.clear();
    merged.family_map = None;
    let mut seen_shards = Vec::new();
    for (path, s) in summaries {
        if s.family != first.family {
            return Err(MergeError::Mismatch(Diagnostic::input(
                Location::file(path),
                format!(
                    "family '{}' differs from '{}' in {}",
                    s.family,
                    first.family,
                    first_path.display()
                ),
                "merge the shards of one batch only",
            )));
        }
        if let Some(shard) = s.shard {
            if seen_shards.contains(&shard) {
                return Err(MergeError::Mismatch(Diagnostic::input(
                    Location::file(path),
                    format!("shard {}/{} is given twice", shard[0], shard[1]),
                    "pass each shard's summary once",
                )));
            }
            seen_shards.push(shard);
        }
        for p in &s.parts {
            if merged.parts.iter().any(|q| q.part == p.part) {
                return Err(MergeError::Mismatch(Diagnostic::input(
                    Location::file(path),
                    format!("part '{}' appears in two summaries", p.part),
                    "pass each shard's summary once",
                )));
            }
            merged.parts.push(p.clone());
        }
        merged.toolpaths.extend(s.toolpaths.iter().cloned());
    }
    if let Some(count) = seen_shards.first().map(|s| s[1]) {
        let mut missing: Vec<usize> = (0..count)
            .filter(|i| !seen_shards.iter().any(|s| s[0] == *i))
            .collect();
        missing.sort_unstable();
        if !missing.is_empty() {
            return Err(MergeError::Missing(Diagnostic::usage(
                format!("shards {missing:?} of {count} are missing"),
                "pass every shard's summary (or run the missing shards first)",
            )));
        }
    }
    merged
        .parts
        .sort_by(|a, b| a.probe_file.cmp(&b.probe_file).then(a.part.cmp(&b.part)));
    merged.failed_parts = merged.parts.iter().filter(|p| !p.ok).count();
    Ok(merged)
}
