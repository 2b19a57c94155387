//! The job manifest (`job.toml`) of a part-family batch: every key, its default, validation, and TOML errors located by line and column.
//!
//! Every key is documented in `docs/job.md`. Relative paths in the file (probe glob, toolpaths)
//! are taken from the job file's folder; the output folder is taken from the current directory.

use crate::JobError;
use errmap_core::error::{Diagnose, Diagnostic, Location, Result};
use errmap_core::geom::{Axis, Domain};
use errmap_core::io::line_col;
use errmap_maps::interp::Method;
use errmap_maps::nn::ModelConfig;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// A batch job over one part family.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Job {
    /// Family name: names the output folder `out/<family>` and the pictures.
    pub family: String,
    /// Error direction; the map spans the two other axes (z → x,y; x → y,z; y → z,x).
    pub normal: Axis,
    /// Nominal coordinate along the normal for every point, when the probe files have no
    /// `nx_mm,ny_mm,nz_mm` columns (the columns win when both are given).
    pub nominal_plane_mm: Option<f64>,
    /// Glob of the probe files, relative to the job file; one file per part, sorted by path.
    pub probes: String,
    /// Map domain `[u_min, v_min, u_max, v_max]` in mm; default: bounding box of all probe points.
    pub domain: Option<[f64; 4]>,
    /// Step of the output map grid, mm.
    pub grid_step_mm: f64,
    /// Output folder, relative to the current directory; default `out/<family>`.
    pub output: Option<PathBuf>,
    /// Plausibility bound, mm: a probe deviation or map value beyond it is an error that
    /// names the likely unit slip.
    pub max_deviation_mm: f64,
    /// Column mapping of the probe files when they are an instrument's CSV export
    /// (`x=X,y=Y,z=Z[um],i=I,j=J,k=K,id=POINT`, as `--columns`; docs/probe-files.md).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub columns: Option<String>,
    /// 1-based line of the probe files' header (default: the first line, or with `columns`
    /// the first line naming every mapped column).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub header_line: Option<u64>,
    /// Toolpaths leave points where the map's u(E) exceeds this many µm nominal, as points
    /// outside the domain (`--max-uncertainty-um`); none: no bound.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_uncertainty_um: Option<f64>,
    /// Memory one part may need, MB (`--max-memory-mb` wins): a scan of more points is
    /// refused before it is read; none: [`errmap_maps::probe::budget::DEFAULT_MAX_MEMORY_MB`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_memory_mb: Option<u64>,
    /// `[clean]`: gross-error rejection of probe points.
    pub clean: CleanConfig,
    /// `[interp]`: how the probes are interpolated into the network's training set.
    pub interp: InterpConfig,
    /// `[model]`: the network, its training and the backend that trains it.
    pub model: ModelConfig,
    /// `[toolpaths]`: the programs compensated with the fitted map, and how.
    pub toolpaths: ToolpathConfig,
    /// `[metadata]`: free-form facts for the report (machine, serial, operator, temperatures …),
    /// each a string or a number; they decide no result and are left out of the job hash.
    #[serde(skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    pub metadata: std::collections::BTreeMap<String, toml::Value>,
}

impl Default for Job {
    fn default() -> Self {
        Job {
            family: "family".into(),
            normal: Axis::Z,
            nominal_plane_mm: None,
            probes: "probes/*.csv".into(),
            domain: None,
            grid_step_mm: 5.0,
            output: None,
            max_deviation_mm: errmap_maps::probe::DEFAULT_MAX_DEVIATION_MM,
            columns: None,
            header_line: None,
            max_uncertainty_um: None,
            max_memory_mb: None,
            clean: CleanConfig::default(),
            interp: InterpConfig::default(),
            model: ModelConfig::default(),
            toolpaths: ToolpathConfig::default(),
            metadata: std::collections::BTreeMap::new(),
        }
    }
}

/// `[clean]`: gross-error rejection.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CleanConfig {
    /// Reject a point whose leave-one-out residual exceeds k·σ (σ robust, from the MAD).
    pub k_sigma: f64,
}

impl Default for CleanConfig {
    fn default() -> Self {
        CleanConfig { k_sigma: 3.0 }
    }
}

/// `[interp]`: the training set.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct InterpConfig {
    /// `natural-neighbour`, `sibson-c1` or `linear`.
    pub method: Method,
    /// Spacing of the training grid inside the probes' convex hull, mm.
    pub spacing_mm: f64,
}

impl Default for InterpConfig {
    fn default() -> Self {
        InterpConfig {
            method: Method::NaturalNeighbour,
            spacing_mm: 10.0,
        }
    }
}

/// Which fitted map compensates the toolpaths.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum MapChoice {
    /// The family network (fitted to the mean of the parts): one program for the next part.
    #[default]
    Family,
    /// Each part's own map: one program per part.
    Part,
}

/// `[toolpaths]`: programs rewritten with P' = P − E.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ToolpathConfig {
    /// G-code (`.ngc`, `.nc`, `.gcode`, `.tap`) or CSV (`.csv`) toolpaths, relative to the job file.
    pub files: Vec<PathBuf>,
    /// Band `[min, max]` along the normal axis, in the program's units, where moves are
    /// compensated; default: the map's probed surface ± `surface_tol_mm`.
    pub zone: Option<[f64; 2]>,
    /// With no `zone`: compensate at every height along the normal.
    pub zone_all: bool,
    /// Half-width of the default zone around the probed surface, mm.
    pub surface_tol_mm: f64,
    /// The programs' controller dialect (`linuxcnc`, `fanuc`, `sinumerik`, `heidenhain`);
    /// default: detected, refused when uncertain.
    pub dialect: Option<errmap_toolpath::Dialect>,
    /// Units of programs that do not state them (`mm` or `inch`).
    pub units: Option<errmap_toolpath::Units>,
    /// Fanuc decimal-less numbers: `calculator`, `is-a`, `is-b` or `is-c`.
    pub fanuc_numbers: Option<errmap_toolpath::FanucNumbers>,
    /// Also compensate where the map extrapolates beyond the measured domain.
    pub extrapolate: bool,
    /// Margin around the probes' hull that still counts as measured, mm.
    pub domain_margin_mm: f64,
    /// The motion mode the controller powers on in (`g0` or `g1`), for blocks with axis
    /// words before any motion word.
    pub power_on_motion: Option<errmap_toolpath::PowerOnMotion>,
    /// Execute subprograms and loops and write the flattened, compensated program.
    pub expand: bool,
    /// Move canned-cycle holes whose bottom lies in the zone by −E.
    pub compensate_holes: bool,
    /// Apply the map in each work offset's coordinates.
    pub same_part_per_offset: bool,
    /// Longest segment after splitting, mm (converted to inches for G20 programs).
    pub max_segment_mm: f64,
    /// Chord tolerance when arcs are linearised, mm.
    pub chord_tol_mm: f64,
    /// `family` or `part`.
    pub map: MapChoice,
    /// Use a map that removes less than 10 % of E at its held-out points (refused otherwise).
    pub allow_weak_map: bool,
}

impl Default for ToolpathConfig {
    fn default() -> Self {
        ToolpathConfig {
            files: Vec::new(),
            zone: None,
            zone_all: false,
            surface_tol_mm: 0.5,
            dialect: None,
            units: None,
            fanuc_numbers: None,
            extrapolate: false,
            domain_margin_mm: 0.0,
            power_on_motion: None,
            expand: false,
            compensate_holes: false,
            same_part_per_offset: false,
            max_segment_mm: 5.0,
            chord_tol_mm: 0.005,
            map: MapChoice::Family,
            allow_weak_map: false,
        }
    }
}

/// A job read from a file, with the folder its relative paths are taken from.
#[derive(Debug, Clone)]
pub struct JobFile {
    /// The job file as given; relative probe and toolpath paths are taken from its folder.
    pub path: PathBuf,
    /// The job it holds, validated.
    pub job: Job,
}

/// 1-based (line, column) of the value of a dotted key (`clean.k_sigma`) in job TOML, from the
/// spans the `toml` crate keeps; `None` when the key is not in the text (a default).
fn key_line_col(text: &str, key: &str) -> Option<(u64, u64)> {
    let doc = toml::de::DeTable::parse(text).ok()?;
    let mut value = toml::de::DeValue::Table(doc.into_inner());
    let mut span = None;
    for part in key.split('.') {
        let next = value.get(part)?;
        span = Some(next.span());
        value = next.get_ref().clone();
    }
    span.map(|s| line_col(text, s.start))
}

/// The job key a validation message is about: `model.epochs = 0 …` names `model.epochs`.
fn key_of_message(message: &str) -> Option<&str> {
    let start = message.find("model.")?;
    let rest = &message[start..];
    let end = rest
        .find(|c: char| !(c.is_alphanumeric() || c == '_' || c == '.'))
        .unwrap_or(rest.len());
    Some(rest[..end].trim_end_matches('.'))
}

impl Job {
    /// Parse job TOML; `path` is only used in messages. Errors (syntax, types, unknown keys and
    /// values out of range) name the line and column of the offending value.
    pub fn parse(path: &Path, text: &str) -> Result<Job, JobError> {
        let job: Job = toml::from_str(text).map_err(|e| {
            let (line, col) = e.span().map_or((1, 1), |s| line_col(text, s.start));
            JobError::Toml(Diagnostic::input(
                Location::cell(path, line, col.to_string()),
                e.message().trim().to_string(),
                "see docs/job.md for every key and its type",
            ))
        })?;
        job.validate(path).map_err(|e| match e.into_diagnostic() {
            Diagnostic::Input {
                location,
                message,
                hint,
            } => {
                // Validation names the key in the location's column: find its span.
                let key = location.column.clone().unwrap_or_default();
                let location = match key_line_col(text, &key) {
                    Some((line, col)) => Location::cell(path, line, col.to_string()),
                    None => location,
                };
                JobError::Value(Diagnostic::Input {
                    location,
                    message,
                    hint,
                })
            }
            other => JobError::from(other),
        })?;
        Ok(job)
    }

    /// Read and validate a job file.
    pub fn read(path: &Path) -> Result<JobFile, JobError> {
        let text = errmap_core::io::read_text(path)?;
        let job = Job::parse(path, &text)?;
        Ok(JobFile {
            path: path.to_path_buf(),
            job,
        })
    }

    /// The map domain, if the job fixes it.
    pub fn domain(&self) -> Option<Domain> {
        self.domain.map(|[a, b, c, d]| Domain {
            u_min_mm: a,
            v_min_mm: b,
            u_max_mm: c,
            v_max_mm: d,
        })
    }

    /// Check values serde cannot: positive steps, ordered ranges, a usable family name.
    pub fn validate(&self, path: &Path) -> Result<(), JobError> {
        // The key travels in the column; `parse` replaces it with the value's line and column.
        let bad = |key: &str, msg: String, hint: &str| {
            Diagnostic::input(
                Location {
                    file: path.to_path_buf(),
                    line: None,
                    column: Some(key.to_string()),
                },
                format!("{key}: {msg}"),
                hint.to_string(),
            )
        };
        self.validate_family(&bad)?;
        self.validate_metadata(&bad)?;
        self.validate_geometry(&bad)?;
        self.validate_numbers(&bad)?;
        self.validate_model(path)?;
        Ok(())
    }
}

/// A validation error at a key: `(key, message, hint)`.
type Bad<'a> = &'a dyn Fn(&str, String, &str) -> Diagnostic;

impl Job {
    /// The family names the output folder.
    fn validate_family(&self, bad: Bad) -> Result<()> {
        if self.family.is_empty()
            || self.family.starts_with('.')
            || self
                .family
                .chars()
                .any(|c| !(c.is_alphanumeric() || c == '-' || c == '_' || c == '.'))
        {
            return Err(bad(
                "family",
                format!("'{}' cannot name a folder", self.family),
                "use letters, digits, '-', '_' or '.', e.g. family = \"web-plate\"",
            ));
        }
        Ok(())
    }

    /// A finite nominal plane and a domain that is a rectangle.
    fn validate_geometry(&self, bad: Bad) -> Result<()> {
        if let Some(z) = self.nominal_plane_mm {
            if !z.is_finite() {
                return Err(bad(
                    "nominal_plane_mm",
                    format!("{z} is not finite"),
                    "give the nominal coordinate in mm",
                ));
            }
        }
        if let Some(text) = &self.columns {
            match errmap_maps::probe::ProbeColumns::parse(text) {
                Ok(_) => {}
                Err(Diagnostic::Usage { message, .. }) => {
                    return Err(bad(
                        "columns",
                        message,
                        "write columns = \"x=COLUMN,y=COLUMN,z=COLUMN[,i=…,j=…,k=…][,id=COLUMN]\" (see docs/probe-files.md)",
                    ))
                }
                Err(e) => return Err(e),
            }
        }
        if self.header_line == Some(0) {
            return Err(bad(
                "header_line",
                "0: lines are numbered from 1".into(),
                "give the 1-based line of the header, as an editor shows it",
            ));
        }
        if let Some([a, b, c, d]) = self.domain {
            let finite = [a, b, c, d].iter().all(|x| x.is_finite());
            if !finite || a >= c || b >= d {
                return Err(bad(
                    "domain",
                    format!("[{a}, {b}, {c}, {d}] is not a rectangle"),
                    "write [u_min, v_min, u_max, v_max] in mm with min < max",
                ));
            }
        }
        Ok(())
    }

    /// Positive steps and bounds, a toolpath band, a small hold-out share, a usable segment.
    fn validate_numbers(&self, bad: Bad) -> Result<()> {
        let positive = [
            ("grid_step_mm", self.grid_step_mm),
            ("max_deviation_mm", self.max_deviation_mm),
            ("clean.k_sigma", self.clean.k_sigma),
            ("interp.spacing_mm", self.interp.spacing_mm),
            ("toolpaths.max_segment_mm", self.toolpaths.max_segment_mm),
            ("toolpaths.chord_tol_mm", self.toolpaths.chord_tol_mm),
        ];
        for (key, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(bad(
                    key,
                    format!("{v} must be a positive number"),
                    "see docs/job.md for the default",
                ));
            }
        }
        if let Some(u) = self.max_uncertainty_um {
            if !(u.is_finite() && u >= 0.0) {
                return Err(bad(
                    "max_uncertainty_um",
                    format!("{u} must be a number ≥ 0 (µm)"),
                    "give the largest u(E) in µm at which a toolpath point is still compensated, e.g. 2.5",
                ));
            }
        }
        if self.max_memory_mb == Some(0) {
            return Err(bad(
                "max_memory_mb",
                "0 MB leaves no memory for any part".into(),
                "give the memory one part may use in MB, e.g. 4096, or leave the key out",
            ));
        }
        if let Some([lo, hi]) = self.toolpaths.zone {
            if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
                return Err(bad(
                    "toolpaths.zone",
                    format!("[{lo}, {hi}] is not a band"),
                    "write [min, max] along the normal axis in the program's units",
                ));
            }
        }
        if !(0.0..0.5).contains(&self.model.holdout_fraction) {
            return Err(bad(
                "model.holdout_fraction",
                format!("{} is outside 0 … 0.5", self.model.holdout_fraction),
                "hold out a small share of points, e.g. 0.1 (0 turns the hold-out fit off)",
            ));
        }
        if self.toolpaths.max_segment_mm < errmap_toolpath::MIN_SEGMENT_MM {
            return Err(bad(
                "toolpaths.max_segment_mm",
                format!(
                    "{} is below the smallest segment of {} mm",
                    self.toolpaths.max_segment_mm,
                    errmap_toolpath::MIN_SEGMENT_MM
                ),
                "see docs/job.md for the default",
            ));
        }
        Ok(())
    }

    /// The `[model]` table's own checks, located at the key its message names.
    fn validate_model(&self, path: &Path) -> Result<()> {
        self.model.validate().map_err(|e| {
            let (message, hint) = match &e {
                Diagnostic::Usage { message, hint } => (message.clone(), hint.clone()),
                other => (other.to_string(), "see docs/job.md".to_string()),
            };
            let key = key_of_message(&message).unwrap_or("model").to_string();
            Diagnostic::input(
                Location {
                    file: path.to_path_buf(),
                    line: None,
                    column: Some(key),
                },
                format!("[model]: {message}"),
                hint,
            )
        })
    }
}

impl Job {
    /// `[metadata]` values are strings or finite numbers under non-empty keys.
    fn validate_metadata(&self, bad: Bad) -> Result<()> {
        let hint = "write key = \"text\" or key = number, e.g. machine = \"DMU 50\", spindle_temp_c = 21.4";
        for (key, value) in &self.metadata {
            let at = format!("metadata.{key}");
            if key.trim().is_empty() {
                return Err(bad("metadata", "a key is empty".into(), hint));
            }
            match value {
                toml::Value::String(_) | toml::Value::Integer(_) => {}
                toml::Value::Float(f) if f.is_finite() => {}
                toml::Value::Float(f) => {
                    return Err(bad(&at, format!("{f} is not a finite number"), hint))
                }
                other => {
                    return Err(bad(
                        &at,
                        format!("a {} is neither text nor a number", other.type_str()),
                        hint,
                    ))
                }
            }
        }
        Ok(())
    }

    /// `[metadata]` as JSON values, for the run manifest and the report.
    pub fn metadata_json(&self) -> std::collections::BTreeMap<String, serde_json::Value> {
        self.metadata
            .iter()
            .map(|(k, v)| {
                let j = match v {
                    toml::Value::String(t) => serde_json::Value::from(t.clone()),
                    toml::Value::Integer(i) => serde_json::Value::from(*i),
                    toml::Value::Float(f) => serde_json::Value::from(*f),
                    other => serde_json::Value::from(other.to_string()),
                };
                (k.clone(), j)
            })
            .collect()
    }
}

impl JobFile {
    /// Folder relative paths in the job are taken from.
    pub fn base_dir(&self) -> PathBuf {
        match self.path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        }
    }

    /// Probe files matching the glob, sorted by path; an error when none match.
    pub fn probe_files(&self) -> Result<Vec<PathBuf>, JobError> {
        let pattern = self.base_dir().join(&self.job.probes);
        let pattern_text = pattern.to_string_lossy().to_string();
        let paths = glob::glob(&pattern_text).map_err(|e| {
            JobError::Probes(Diagnostic::input(
                Location::cell(&self.path, 1, "probes"),
                format!("probes: bad glob '{}': {e}", self.job.probes),
                "write a glob such as \"probes/*.csv\"",
            ))
        })?;
        // Folders that match are skipped; a match that cannot be read (a broken link, no
        // permission) stays, so that the run stops naming it instead of leaving its part out.
        let mut files = Vec::new();
        for entry in paths {
            let path = entry.map_err(|e| {
                let path = e.path().to_path_buf();
                JobError::Read(Diagnostic::read(path, std::io::Error::from(e)))
            })?;
            if !path.is_dir() {
                files.push(path);
            }
        }
        files.sort();
        if files.is_empty() {
            return Err(JobError::Probes(Diagnostic::input(
                Location::cell(&self.path, 1, "probes"),
                format!("probes: no file matches '{pattern_text}'"),
                "the glob is relative to the job file's folder",
            )));
        }
        Ok(files)
    }

    /// Toolpath files, resolved against the job's folder.
    pub fn toolpath_files(&self) -> Vec<PathBuf> {
        self.job
            .toolpaths
            .files
            .iter()
            .map(|f| self.base_dir().join(f))
            .collect()
    }

    /// The output folder: `output`, or `out/<family>`.
    pub fn output_dir(&self) -> PathBuf {
        self.job
            .output
            .clone()
            .unwrap_or_else(|| PathBuf::from("out").join(&self.job.family))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn empty_file_gives_every_default() {
        let job = Job::parse(Path::new("j.toml"), "").unwrap();
        assert_eq!(job, Job::default());
        assert_eq!(job.clean.k_sigma, 3.0);
        assert_eq!(job.model.holdout_fraction, 0.1);
        assert_eq!(job.toolpaths.map, MapChoice::Family);
    }

    #[test]
    fn full_example_parses() {
        let text = r#"
family = "web-plate"
normal = "x"
nominal_plane_mm = 5.0
probes = "p/*.csv"
domain = [10, 10, 590, 290]
grid_step_mm = 10.0
output = "elsewhere"
[clean]
k_sigma = 4.0
[interp]
method = "sibson-c1"
spacing_mm = 7.5
[model]
hidden = [16, 16]
epochs = 300
seed = 9
[toolpaths]
files = ["a.ngc", "b.csv"]
zone = [4, 6]
max_segment_mm = 2.0
chord_tol_mm = 0.01
map = "part"
"#;
        let job = Job::parse(Path::new("j.toml"), text).unwrap();
        assert_eq!(job.normal, Axis::X);
        assert_eq!(job.interp.method, Method::SibsonC1);
        assert_eq!(job.model.hidden, vec![16, 16]);
        assert_eq!(job.model.epochs, 300);
        assert_eq!(job.toolpaths.zone, Some([4.0, 6.0]));
        assert_eq!(job.toolpaths.map, MapChoice::Part);
        assert_eq!(job.domain().unwrap().u_max_mm, 590.0);
    }

    #[test]
    fn errors_name_line_and_column() {
        let err = Job::parse(
            Path::new("j.toml"),
            "family = \"a\"\n\n[clean]\nk_sigmaa = 3\n",
        )
        .unwrap_err()
        .to_string();
        assert!(err.starts_with("j.toml:4, column 1:"), "{err}");
        assert!(err.contains("k_sigmaa"), "{err}");
        let err = Job::parse(
            Path::new("j.toml"),
            "family = \"a\"\ngrid_step_mm = \"x\"\n",
        )
        .unwrap_err()
        .to_string();
        assert!(err.starts_with("j.toml:2, column 16:"), "{err}");
        let err = Job::parse(Path::new("j.toml"), "normal = \"w\"\n")
            .unwrap_err()
            .to_string();
        assert!(err.starts_with("j.toml:1, column 10:"), "{err}");
        let err = Job::parse(Path::new("j.toml"), "grid_step_mm = -1\n")
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("grid_step_mm") && err.contains("positive"),
            "{err}"
        );
    }

    #[test]
    fn metadata_takes_text_and_numbers_and_names_a_bad_value() {
        let text = "family = \"a\"\n[metadata]\nmachine = \"DMU <50>\"\nserial = 1234\ncoolant_temp_c = 21.5\n";
        let job = Job::parse(Path::new("j.toml"), text).unwrap();
        let m = job.metadata_json();
        assert_eq!(m["machine"], "DMU <50>");
        assert_eq!(m["serial"], 1234);
        assert_eq!(m["coolant_temp_c"], 21.5);
        let text = "family = \"a\"\n[metadata]\nmachine = \"m\"\naxes = [1, 2]\n";
        let err = Job::parse(Path::new("j.toml"), text)
            .unwrap_err()
            .to_string();
        assert!(err.starts_with("j.toml:4, column 8:"), "{err}");
        assert!(err.contains("metadata.axes"), "{err}");
        let text = "[metadata]\nwhen = 2026-01-01\n";
        let err = Job::parse(Path::new("j.toml"), text).unwrap_err();
        assert_eq!(err.diagnostic().kind(), "input", "{err}");
        assert!(err.to_string().starts_with("j.toml:2"), "{err}");
    }

    #[test]
    fn range_errors_name_the_line_and_column_of_the_value() {
        // k_sigma = -3.0 on line 7, column 11 (where the value starts).
        let text =
            "family = \"a\"\n\n# comment\n[interp]\nspacing_mm = 5\n[clean]\nk_sigma = -3.0\n";
        let err = Job::parse(Path::new("j.toml"), text)
            .unwrap_err()
            .to_string();
        assert!(err.starts_with("j.toml:7, column 11:"), "{err}");
        assert!(err.contains("clean.k_sigma"), "{err}");
        // epochs = 0 in [model] on line 4.
        let text = "family = \"a\"\n[model]\nseed = 3\n  epochs = 0\n";
        let err = Job::parse(Path::new("j.toml"), text)
            .unwrap_err()
            .to_string();
        assert!(err.starts_with("j.toml:4, column 12:"), "{err}");
        assert!(err.contains("model.epochs"), "{err}");
        // A dotted key and an inline table are found too.
        let text = "family = \"a\"\nclean.k_sigma = 0\n";
        let err = Job::parse(Path::new("j.toml"), text)
            .unwrap_err()
            .to_string();
        assert!(err.starts_with("j.toml:2, column 17:"), "{err}");
        let text = "family = \"a\"\ntoolpaths = { max_segment_mm = 0.001 }\n";
        let err = Job::parse(Path::new("j.toml"), text)
            .unwrap_err()
            .to_string();
        assert!(err.starts_with("j.toml:2, column 32:"), "{err}");
        assert!(err.contains("0.01"), "{err}");
        let text = "family = \"..\"\n";
        let err = Job::parse(Path::new("j.toml"), text)
            .unwrap_err()
            .to_string();
        assert!(err.starts_with("j.toml:1, column 10:"), "{err}");
    }
}
