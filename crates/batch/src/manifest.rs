//! `run.json`, the manifest that commits a run: job hash, input hashes, errmap version, per-part status and output hashes; written last.
//!
//! A folder holds a complete run exactly when its `run.json` exists and every file it lists
//! has the listed SHA-256. `--resume` keeps a part whose input and outputs still match.

use super::summary::BatchSummary;
use errmap_core::error::{Diagnostic, Location, Result};
pub use errmap_core::io::stamp::{sha256_bytes, sha256_file, utc_now, utc_rfc3339};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// File name of the manifest in a run's folder.
pub const RUN_MANIFEST: &str = "run.json";
/// `format` of the manifest.
pub const RUN_FORMAT: &str = "errmap-run/1";

/// The manifest of one run (a whole batch, one shard of it, or the reduce of the shards).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunManifest {
    /// The manifest's format, [`RUN_FORMAT`].
    pub format: String,
    /// Version of the errmap that wrote the run.
    pub errmap_version: String,
    /// `batch`, `shard` or `reduce`.
    pub kind: String,
    /// The job file as it was given.
    pub job: Option<PathBuf>,
    /// SHA-256 of the job's effective settings (see [`job_hash`]): shards of one job share it.
    pub job_hash: String,
    /// `[index, count]` of a shard.
    pub shard: Option<[usize; 2]>,
    /// The trainer that fitted the networks.
    pub backend: String,
    /// Every input file (probe files, toolpaths) with its SHA-256.
    pub inputs: BTreeMap<PathBuf, String>,
    /// Per part: status, input hash, output hashes.
    pub parts: Vec<PartRecord>,
    /// Every other output, by path relative to the folder (family files, summary.json).
    pub files: BTreeMap<String, String>,
    /// For a reduce: each shard folder (relative) and the SHA-256 of its `run.json`.
    pub shards: BTreeMap<String, String>,
    /// When the run was committed, UTC, RFC 3339 (`SOURCE_DATE_EPOCH` when set); the report's date.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub created_utc: Option<String>,
    /// The job's free-form `[metadata]` (machine, serial, operator, temperatures …).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub metadata: BTreeMap<String, serde_json::Value>,
    /// `[clean] k_sigma`: a point was rejected when its leave-one-out residual exceeded k·σ.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub k_sigma: Option<f64>,
}

/// One part of a run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PartRecord {
    /// The part's name, which is also its folder in the run.
    pub part: String,
    /// The part's probe file, as the job's glob found it.
    pub probe_file: PathBuf,
    /// SHA-256 of the probe file when the run read it (empty when it was not among the
    /// run's inputs).
    pub input_sha256: String,
    /// Whether the part was mapped; `false` when it failed (its error is in `summary.json`).
    pub ok: bool,
    /// Kept from the previous run by `--resume` (not recomputed).
    pub reused: bool,
    /// The part's files, by path relative to the run's folder.
    pub outputs: BTreeMap<String, String>,
}

/// Hash of what decides a run's results: the job's settings after command-line overrides
/// (output folder excluded, so shards writing elsewhere still match) and the probe files'
/// names in batch order, relative to the job's folder `base` (however the job path was spelled).
pub fn job_hash(job: &super::Job, probe_files: &[PathBuf], base: &Path) -> Result<String> {
    let mut job = job.clone();
    job.output = None;
    // Free-form metadata names the machine and set-up; it decides no result.
    job.metadata.clear();
    let names: Vec<String> = probe_files
        .iter()
        .map(|f| {
            f.strip_prefix(base)
                .unwrap_or(f)
                .to_string_lossy()
                .to_string()
        })
        .collect();
    let text = serde_json::to_string(&(&job, names))
        .map_err(|e| Diagnostic::Internal(format!("job hash: {e}")))?;
    Ok(sha256_bytes(text.as_bytes()))
}

/// Every file below `dir` (relative paths with `/`), the manifest itself and temporaries left out.
pub fn hash_tree(dir: &Path) -> Result<BTreeMap<String, String>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).map_err(|e| Diagnostic::read(&d, e))? {
            let entry = entry.map_err(|e| Diagnostic::read(&d, e))?;
            let path = entry.path();
            let name = entry.file_name().to_string_lossy().to_string();
            if name.starts_with(".errmap-") {
                continue;
            }
            if entry.file_type().is_ok_and(|t| t.is_dir()) {
                stack.push(path);
                continue;
            }
            let rel = relative(dir, &path);
            if rel == RUN_MANIFEST {
                continue;
            }
            out.insert(rel, sha256_file(&path)?);
        }
    }
    Ok(out)
}

fn relative(dir: &Path, path: &Path) -> String {
    let rel = path.strip_prefix(dir).unwrap_or(path);
    rel.components()
        .map(|c| c.as_os_str().to_string_lossy().to_string())
        .collect::<Vec<_>>()
        .join("/")
}

impl RunManifest {
    /// The manifest of a run from the hashes of its files (see [`hash_tree`]): each file goes to
    /// its part (files under `<part>/`) or to `files`.
    pub fn build(
        mut files: BTreeMap<String, String>,
        kind: &str,
        job_hash: String,
        summary: &BatchSummary,
        inputs: BTreeMap<PathBuf, String>,
        reused: &[String],
    ) -> Result<RunManifest> {
        let mut parts = Vec::new();
        for p in &summary.parts {
            let prefix = format!("{}/", p.part);
            let outputs: BTreeMap<String, String> = files
                .iter()
                .filter(|(k, _)| k.starts_with(&prefix))
                .map(|(k, v)| (k.clone(), v.clone()))
                .collect();
            files.retain(|k, _| !k.starts_with(&prefix));
            parts.push(PartRecord {
                part: p.part.clone(),
                probe_file: p.probe_file.clone(),
                input_sha256: inputs.get(&p.probe_file).cloned().unwrap_or_default(),
                ok: p.ok,
                reused: reused.contains(&p.part),
                outputs,
            });
        }
        Ok(RunManifest {
            format: RUN_FORMAT.into(),
            errmap_version: env!("CARGO_PKG_VERSION").into(),
            kind: kind.into(),
            job: summary.job.clone(),
            job_hash,
            shard: summary.shard,
            backend: summary.backend.clone(),
            inputs,
            parts,
            files,
            shards: BTreeMap::new(),
            created_utc: Some(utc_now()),
            metadata: BTreeMap::new(),
            k_sigma: None,
        })
    }

    /// Write the manifest into `dir` (atomically): the run's commit point.
    pub fn write(&self, dir: &Path) -> Result<()> {
        crate::json_out::write_json(&dir.join(RUN_MANIFEST), self)
    }

    /// The manifest of the run in `dir`, `None` when there is none.
    pub fn read(dir: &Path) -> Result<Option<RunManifest>, crate::FolderError> {
        let path = dir.join(RUN_MANIFEST);
        if !path.is_file() {
            return Ok(None);
        }
        // Not a protected input: a run's manifest is errmap's own record, replaced by design
        // when the next run commits.
        let text = std::fs::read_to_string(&path).map_err(|e| Diagnostic::read(&path, e))?;
        let m: RunManifest = serde_json::from_str(&text).map_err(|e| {
            Diagnostic::input(
                Location::cell(&path, e.line() as u64, e.column().to_string()),
                format!("not an errmap run manifest: {e}"),
                "run.json is written by errmap batch and errmap merge; rerun the batch",
            )
        })?;
        if m.format != RUN_FORMAT {
            return Err(crate::FolderError::File(Diagnostic::input(
                Location::file(&path),
                format!("run manifest format '{}' is not {RUN_FORMAT}", m.format),
                "rerun the batch with this errmap",
            )));
        }
        Ok(Some(m))
    }

    /// Whether every output of part `rec` in `dir` still has its recorded hash.
    pub fn outputs_match(dir: &Path, rec: &PartRecord) -> bool {
        !rec.outputs.is_empty()
            && rec
                .outputs
                .iter()
                .all(|(rel, h)| sha256_file(&dir.join(rel)).is_ok_and(|x| &x == h))
    }
}

/// SHA-256 of each input file.
pub fn hash_inputs(files: &[PathBuf]) -> Result<BTreeMap<PathBuf, String>> {
    files
        .iter()
        .map(|f| Ok((f.clone(), sha256_file(f)?)))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sha256_matches_the_published_test_vectors() {
        // FIPS 180-2 appendix B.1 and the empty string.
        assert_eq!(
            sha256_bytes(b"abc"),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
        assert_eq!(
            sha256_bytes(b""),
            "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855"
        );
    }

    #[test]
    fn dates_are_utc_rfc3339() {
        // Values checked with `date -u -d @SECS`.
        assert_eq!(utc_rfc3339(0), "1970-01-01T00:00:00Z");
        assert_eq!(utc_rfc3339(951_782_400), "2000-02-29T00:00:00Z");
        assert_eq!(utc_rfc3339(1_795_450_265), "2026-11-23T16:11:05Z");
        assert_eq!(utc_rfc3339(-1), "1969-12-31T23:59:59Z");
    }

    #[test]
    fn job_hash_ignores_the_output_folder_but_not_the_settings() {
        let files = vec![PathBuf::from("p/a.csv")];
        let base = Path::new(".");
        let a = super::super::Job::default();
        let mut b = a.clone();
        b.output = Some(PathBuf::from("elsewhere"));
        assert_eq!(
            job_hash(&a, &files, base).unwrap(),
            job_hash(&b, &files, base).unwrap()
        );
        b.model.epochs += 1;
        assert_ne!(
            job_hash(&a, &files, base).unwrap(),
            job_hash(&b, &files, base).unwrap()
        );
        let more = vec![PathBuf::from("p/a.csv"), PathBuf::from("p/b.csv")];
        assert_ne!(
            job_hash(&a, &files, base).unwrap(),
            job_hash(&a, &more, base).unwrap()
        );
        // The same files named from another folder: the same job.
        let abs = vec![PathBuf::from("/data/job/p/a.csv")];
        assert_eq!(
            job_hash(&a, &abs, Path::new("/data/job")).unwrap(),
            job_hash(&a, &files, Path::new("")).unwrap()
        );
    }
}
