//! Batch jobs over a part family: the job manifest, scheduling over parts, sharding and the summary.

pub mod job;
pub mod run;
pub mod summary;

pub use job::{Job, JobFile, MapChoice};
pub use run::{execute, PartInput, Plan, Settings, ToolpathPlan};
pub use summary::{merge, BatchSummary, PartSummary};

use crate::error::{Error, Result};
use std::path::{Path, PathBuf};

/// Which share of the parts this process maps: shard `index` of `count` (0-based) takes the
/// parts whose position in the sorted file list is `index` modulo `count`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    pub index: usize,
    pub count: usize,
}

impl Shard {
    /// Parse `i/n` (0-based i < n).
    pub fn parse(text: &str) -> Result<Shard> {
        let hint = "write --shard INDEX/COUNT with 0 ≤ INDEX < COUNT, e.g. --shard 0/4";
        let (a, b) = text
            .split_once('/')
            .ok_or_else(|| Error::usage(format!("--shard '{text}' is not INDEX/COUNT"), hint))?;
        let index: usize = a
            .trim()
            .parse()
            .map_err(|_| Error::usage(format!("--shard index '{a}' is not a number"), hint))?;
        let count: usize = b
            .trim()
            .parse()
            .map_err(|_| Error::usage(format!("--shard count '{b}' is not a number"), hint))?;
        Shard::new(index, count)
            .ok_or_else(|| Error::usage(format!("--shard {index}/{count} is out of range"), hint))
    }

    pub fn new(index: usize, count: usize) -> Option<Shard> {
        (count > 0 && index < count).then_some(Shard { index, count })
    }

    /// The shard from a scheduler's environment: `SLURM_ARRAY_TASK_ID` (with
    /// `SLURM_ARRAY_TASK_COUNT`, or `count`) or `JOB_COMPLETION_INDEX` of a Kubernetes
    /// Indexed Job (with `count`). `None` when neither variable is set.
    pub fn from_env(
        count: Option<usize>,
        env: impl Fn(&str) -> Option<String>,
    ) -> Result<Option<Shard>> {
        let hint = "pass --shards COUNT (the number of array tasks / completions)";
        for (var, count_var) in [
            ("SLURM_ARRAY_TASK_ID", Some("SLURM_ARRAY_TASK_COUNT")),
            ("JOB_COMPLETION_INDEX", None),
        ] {
            let Some(value) = env(var) else { continue };
            let index: usize = value
                .trim()
                .parse()
                .map_err(|_| Error::usage(format!("{var}='{value}' is not an index"), hint))?;
            let count = match count {
                Some(c) => c,
                None => count_var
                    .and_then(&env)
                    .and_then(|v| v.trim().parse().ok())
                    .ok_or_else(|| {
                        Error::usage(
                            format!("{var} is set but the number of shards is not known"),
                            hint,
                        )
                    })?,
            };
            // Slurm arrays often start at 1 (--array=1-N); accept index == count as the last shard.
            let index = if var == "SLURM_ARRAY_TASK_ID" && index == count {
                0
            } else {
                index
            };
            return Shard::new(index, count).map(Some).ok_or_else(|| {
                Error::usage(
                    format!("{var}={index} is not below the shard count {count}"),
                    hint,
                )
            });
        }
        Ok(None)
    }

    pub fn takes(&self, position: usize) -> bool {
        position % self.count == self.index
    }
}

/// Part names from probe file stems; a repeated stem gets its position appended so each
/// part has its own folder.
pub fn part_names(files: &[PathBuf]) -> Vec<String> {
    let stems: Vec<String> = files
        .iter()
        .map(|f| {
            f.file_stem()
                .map_or("part".into(), |s| s.to_string_lossy().to_string())
        })
        .collect();
    stems
        .iter()
        .enumerate()
        .map(|(i, s)| {
            if stems.iter().filter(|t| *t == s).count() > 1 {
                format!("{s}-{}", i + 1)
            } else {
                s.clone()
            }
        })
        .collect()
}

/// Options of `errmap batch` that override or add to the job file.
#[derive(Debug, Clone, Default)]
pub struct BatchOptions {
    pub backend: Option<crate::nn::Backend>,
    pub shard: Option<Shard>,
    pub output: Option<PathBuf>,
}

/// Build the plan of a job file: its parts (this shard's), folders, family and toolpaths.
pub fn plan_job(file: &JobFile, opts: &BatchOptions) -> Result<(Plan, PathBuf)> {
    let job = &file.job;
    let files = file.probe_files()?;
    let names = part_names(&files);
    let out = opts.output.clone().unwrap_or_else(|| file.output_dir());
    let parts: Vec<PartInput> = files
        .iter()
        .zip(&names)
        .enumerate()
        .filter(|(i, _)| opts.shard.is_none_or(|s| s.takes(*i)))
        .map(|(_, (f, n))| PartInput {
            name: n.clone(),
            probe_file: f.clone(),
            out_dir: out.join(n),
        })
        .collect();
    let mut model = job.model.clone();
    if let Some(b) = opts.backend {
        model.backend = b;
    }
    let toolpaths = (!job.toolpaths.files.is_empty()).then(|| ToolpathPlan {
        files: file.toolpath_files(),
        settings: crate::toolpath::CompensationSettings {
            zone: job.toolpaths.zone.map(|[a, b]| (a, b)),
            everywhere: job.toolpaths.zone_all,
            surface_tol_mm: job.toolpaths.surface_tol_mm,
            max_segment: job.toolpaths.max_segment_mm,
            chord_tol: job.toolpaths.chord_tol_mm,
            dialect: job.toolpaths.dialect,
            units: job.toolpaths.units,
            fanuc_numbers: job.toolpaths.fanuc_numbers,
            extrapolate: job.toolpaths.extrapolate,
            domain_margin_mm: job.toolpaths.domain_margin_mm,
        },
        per_part: job.toolpaths.map == MapChoice::Part,
    });
    // A shard sees only some parts, so family maps (and toolpaths compensated with the family
    // map) come from an unsharded run; each shard maps its own parts and per-part toolpaths.
    let family_dir = opts.shard.is_none().then(|| out.join("family"));
    let toolpaths = match (&toolpaths, opts.shard) {
        (Some(tp), Some(_)) if !tp.per_part => None,
        _ => toolpaths,
    };
    let plan = Plan {
        settings: Settings {
            family: job.family.clone(),
            normal: job.normal,
            nominal_plane_mm: job.nominal_plane_mm,
            domain: job.domain(),
            grid_step_mm: job.grid_step_mm,
            k_sigma: job.clean.k_sigma,
            method: job.interp.method,
            spacing_mm: job.interp.spacing_mm,
            model,
        },
        parts,
        family_dir,
        toolpaths,
        job: Some(file.path.clone()),
        shard: opts.shard.map(|s| [s.index, s.count]),
    };
    let summary_path = match opts.shard {
        None => out.join("summary.json"),
        Some(s) => out.join(format!("summary-shard-{}-of-{}.json", s.index, s.count)),
    };
    Ok((plan, summary_path))
}

/// Family mean and standard-deviation maps (CSV + heatmaps, no network) rebuilt from the
/// `map.csv` of every mapped part of a merged summary, written to `dir`.
pub fn family_maps_from_files(
    summary: &BatchSummary,
    dir: &Path,
) -> Result<Option<summary::FamilySummary>> {
    let mut maps = Vec::new();
    for p in summary.parts.iter().filter(|p| p.ok) {
        if let Some(out) = &p.output_dir {
            maps.push(crate::map::ErrorMap::read_csv(
                &out.join("map.csv"),
                summary.normal,
            )?);
        }
    }
    let refs: Vec<&crate::map::ErrorMap> = maps.iter().collect();
    let Some((mean, std)) = crate::map::family_stats(&refs) else {
        if maps.is_empty() {
            return Ok(None);
        }
        return Err(Error::usage(
            "the parts' maps are on different grids",
            "merge the shards of one job (same domain and grid step)",
        ));
    };
    let axes = summary.normal.plane_axes();
    mean.write_csv(&dir.join("mean.csv"), "e_um")?;
    std.write_csv(&dir.join("std.csv"), "std_um")?;
    let (pv, rms) = mean.pv_rms_um();
    let std_max = std.values.iter().cloned().fold(0.0, f64::max);
    let none: Vec<(f64, f64)> = Vec::new();
    let title = format!(
        "{} family mean of {} parts — PV {pv:.1} µm, RMS {rms:.1} µm",
        summary.family,
        maps.len()
    );
    run::draw(
        &dir.join("mean.png"),
        &title,
        &mean,
        &none,
        &none,
        crate::report::heatmap::Scale::Diverging,
        axes,
        "E (µm)",
    )?;
    let title = format!(
        "{} part-to-part standard deviation — max {std_max:.2} µm",
        summary.family
    );
    run::draw(
        &dir.join("std.png"),
        &title,
        &std,
        &none,
        &none,
        crate::report::heatmap::Scale::Sequential,
        axes,
        "σ (µm)",
    )?;
    Ok(Some(summary::FamilySummary {
        parts: maps.len(),
        output_dir: dir.to_path_buf(),
        mean_rms_um: rms,
        mean_pv_um: pv,
        std_max_um: std_max,
    }))
}

/// Where a summary for `out` goes when shards are merged: `summary.json` beside the first.
pub fn merged_summary_path(first_shard: &Path) -> PathBuf {
    first_shard
        .parent()
        .map_or_else(|| PathBuf::from("summary.json"), |p| p.join("summary.json"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shards_split_parts_round_robin_and_read_the_scheduler_env() {
        let s = Shard::parse("1/3").unwrap();
        let taken: Vec<usize> = (0..8).filter(|&i| s.takes(i)).collect();
        assert_eq!(taken, vec![1, 4, 7]);
        assert!(Shard::parse("3/3").is_err());
        assert!(Shard::parse("a/3").is_err());
        let env = |k: &str| match k {
            "SLURM_ARRAY_TASK_ID" => Some("2".to_string()),
            "SLURM_ARRAY_TASK_COUNT" => Some("4".to_string()),
            _ => None,
        };
        assert_eq!(Shard::from_env(None, env).unwrap(), Shard::new(2, 4));
        let k8s = |k: &str| (k == "JOB_COMPLETION_INDEX").then(|| "5".to_string());
        assert_eq!(Shard::from_env(Some(6), k8s).unwrap(), Shard::new(5, 6));
        assert!(Shard::from_env(None, k8s).is_err());
        assert_eq!(Shard::from_env(None, |_| None).unwrap(), None);
    }

    #[test]
    fn repeated_stems_get_distinct_names() {
        let files = vec![
            PathBuf::from("a/p1.csv"),
            PathBuf::from("b/p1.csv"),
            PathBuf::from("b/p2.csv"),
        ];
        assert_eq!(part_names(&files), vec!["p1-1", "p1-2", "p2"]);
    }
}
