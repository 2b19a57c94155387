//! What a run maps and how: the settings every part is mapped with, the parts and their folders, the family folder and the toolpaths — the input of the pipeline (`run`) and of the reduce.

use errmap_core::error::Result;
use errmap_core::geom::{Axis, Domain};
use errmap_maps::interp::Method;
use errmap_maps::nn::ModelConfig;
use std::path::PathBuf;

/// Everything the pipeline needs, from a job file or from `errmap map` flags.
#[derive(Debug, Clone)]
pub struct Settings {
    /// Family name for titles and the summary (a single part's own name without a job).
    pub family: String,
    /// Error direction: the maps give E along it over the two other axes.
    pub normal: Axis,
    /// Nominal coordinate along the normal for every point, mm, when the probe files have no
    /// nominal columns; `None` = the files' own.
    pub nominal_plane_mm: Option<f64>,
    /// Fixed map domain; `None`: bounding box of all probe points of the batch.
    pub domain: Option<Domain>,
    /// Node spacing of the output map grids, mm.
    pub grid_step_mm: f64,
    /// Gross-error threshold: a probe whose leave-one-out residual exceeds k·σ (robust σ) is
    /// rejected.
    pub k_sigma: f64,
    /// How the probes are interpolated into the training sets.
    pub method: Method,
    /// Node spacing of the training sets inside the probes' hull, mm.
    pub spacing_mm: f64,
    /// The networks, their training and the backend that trains them.
    pub model: ModelConfig,
    /// Plausibility bound of probe deviations and map values, mm.
    pub max_deviation_mm: f64,
    /// Column mapping of the probe files (CSV exports), see [`errmap_maps::probe::ProbeSpec::columns`].
    pub columns: Option<String>,
    /// 1-based header line of the probe files, see [`errmap_maps::probe::ProbeSpec::header_line`].
    pub header_line: Option<u64>,
    /// Write each part's `reduce.json` (batch runs: the shards' input to the reduce).
    pub reduce_inputs: bool,
    /// The job's `max_memory_mb`: a part whose points need more memory is refused before it
    /// is read (`--max-memory-mb` wins; see [`errmap_maps::probe::budget`]).
    pub max_memory_mb: Option<u64>,
}

/// One part to map and where its files go.
#[derive(Debug, Clone)]
pub struct PartInput {
    /// The part's name (its folder's name, from the probe file's stem).
    pub name: String,
    /// The part's probe file.
    pub probe_file: PathBuf,
    /// Folder the part's files ([`PART_OUTPUTS`]) are written to.
    pub out_dir: PathBuf,
}

/// Toolpaths to compensate after fitting.
#[derive(Debug, Clone)]
pub struct ToolpathPlan {
    /// The programs (G-code or CSV) to compensate.
    pub files: Vec<PathBuf>,
    /// How to compensate them (zone, dialect, units, segment length …).
    pub settings: errmap_toolpath::CompensationSettings,
    /// `true`: each part's map (outputs in the part's folder); `false`: the family map.
    pub per_part: bool,
    /// Use maps that remove less than [`errmap_maps::map::MIN_BENEFIT_SHARE`] of E at their
    /// held-out points (job key `[toolpaths] allow_weak_map`).
    pub allow_weak_map: bool,
    /// Leave points where the map's u(E) exceeds this (µm) nominal, as points outside the
    /// domain (job key `max_uncertainty_um`); `None`: no bound.
    pub max_uncertainty_um: Option<f64>,
}

/// A whole run.
#[derive(Debug, Clone)]
pub struct Plan {
    /// What every part is mapped with.
    pub settings: Settings,
    /// The parts this run maps (a shard's share, or those `--resume` did not keep).
    pub parts: Vec<PartInput>,
    /// Every part of the family in batch order, when this run maps only some of them (a shard,
    /// a resumed run) and its parts start from the family network: the family network is then
    /// rebuilt from all of them, as the whole run builds it. Empty otherwise.
    pub family_parts: Vec<PartInput>,
    /// Folder of the family maps; `None` for a single part.
    pub family_dir: Option<PathBuf>,
    /// Toolpaths to compensate; `None` when there are none (or, in a shard, when they take
    /// the family map, which only an unsharded run or the merge builds).
    pub toolpaths: Option<ToolpathPlan>,
    /// The job file; `None` for a single part without one (`errmap map`).
    pub job: Option<PathBuf>,
    /// `[index, count]` of the shard this run maps; `None` when the job is not split.
    pub shard: Option<[usize; 2]>,
}

impl Plan {
    /// Every file the plan reads is an input no output may replace: protect them all, then
    /// check every part's outputs before the first is written, so a refused plan writes nothing.
    pub fn protect_files(&self) -> Result<(), crate::RunError> {
        use errmap_core::io::safety::{check_output, protect};
        for part in &self.parts {
            protect(&part.probe_file);
        }
        if let Some(job) = &self.job {
            protect(job);
        }
        for f in self.toolpaths.iter().flat_map(|t| &t.files) {
            protect(f);
        }
        for part in &self.parts {
            for name in PART_OUTPUTS {
                check_output(&part.out_dir.join(name))?;
            }
        }
        Ok(())
    }
}

/// The files a mapped part gets in its folder: the map grid (with u(E)), the fitted model, the
/// kept and the rejected probe points, the heatmaps of E and of u(E), and the part's summary.
pub const PART_OUTPUTS: [&str; 7] = [
    "map.csv",
    "model.json",
    "clean.csv",
    "rejected.csv",
    "map.png",
    "uncertainty.png",
    "summary.json",
];
