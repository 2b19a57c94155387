//! The parts a run has finished, recorded as it goes: one line per part in `.errmap-journal.jsonl` in its staging folder (its files and their SHA-256), after a first line naming the job and inputs, so `--resume` after a killed run keeps every part it finished.
//!
//! A line is appended once every file of the part is written (each atomically), so a part in
//! the journal is complete; a line cut short by the kill is ignored. The journal is removed
//! before the run commits: `run.json` then records the same.

use super::manifest::{PartRecord, RunManifest, RUN_FORMAT};
use super::summary::ToolpathSummary;
use errmap_core::error::{Diagnostic, Result};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// File name of the journal in a run's staging folder (hidden: no output of the run).
pub const JOURNAL_FILE: &str = ".errmap-journal.jsonl";
const JOURNAL_FORMAT: &str = "errmap-journal/1";

/// The journal's first line: which job, on which inputs.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Header {
    format: String,
    job_hash: String,
    inputs: BTreeMap<PathBuf, String>,
}

/// One finished part: its record as `run.json` will list it, and its compensated toolpaths.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Finished {
    /// The part's record (files and hashes).
    pub part: PartRecord,
    /// The part's compensated toolpaths (per-part maps), as `summary.json` lists them.
    pub toolpaths: Vec<ToolpathSummary>,
}

/// An open journal that parts are appended to.
#[derive(Debug)]
pub struct Journal {
    path: PathBuf,
    file: Mutex<std::fs::File>,
}

impl Journal {
    /// Start the journal of a run in its staging folder `dir`.
    pub fn create(
        dir: &Path,
        job_hash: &str,
        inputs: &BTreeMap<PathBuf, String>,
    ) -> Result<Journal> {
        let path = dir.join(JOURNAL_FILE);
        let file = std::fs::File::create(&path).map_err(|e| Diagnostic::io("create", &path, e))?;
        let journal = Journal {
            path,
            file: Mutex::new(file),
        };
        journal.append(&Header {
            format: JOURNAL_FORMAT.into(),
            job_hash: job_hash.into(),
            inputs: inputs.clone(),
        })?;
        Ok(journal)
    }

    /// Record a finished part (its files already written).
    pub fn record(&self, part: &Finished) -> Result<()> {
        self.append(part)
    }

    fn append(&self, value: &impl Serialize) -> Result<()> {
        let mut line = serde_json::to_string(value)
            .map_err(|e| Diagnostic::Internal(format!("journal line: {e}")))?;
        line.push('\n');
        let mut file = self
            .file
            .lock()
            .map_err(|_| Diagnostic::Internal("the journal's lock is poisoned".into()))?;
        file.write_all(line.as_bytes())
            .and_then(|_| file.sync_data())
            .map_err(|e| Diagnostic::io("append to", &self.path, e))
    }

    /// Close and remove the journal (the run is about to commit).
    pub fn remove(self) -> Result<()> {
        let path = self.path.clone();
        drop(self);
        std::fs::remove_file(&path).map_err(|e| Diagnostic::io("remove", &path, e))
    }
}

/// The journal in the staging folder `dir` of an interrupted run: a manifest of the parts it
/// finished (job hash, inputs, parts) and their toolpaths by part; `None` when it has none or
/// it cannot be read.
pub fn read(dir: &Path) -> Option<(RunManifest, BTreeMap<String, Vec<ToolpathSummary>>)> {
    let text = std::fs::read_to_string(dir.join(JOURNAL_FILE)).ok()?;
    let mut lines = text.lines();
    let header: Header = serde_json::from_str(lines.next()?).ok()?;
    if header.format != JOURNAL_FORMAT {
        return None;
    }
    // A torn last line (the kill came while it was written) is not a finished part.
    let finished: Vec<Finished> = lines.filter_map(|l| serde_json::from_str(l).ok()).collect();
    let toolpaths = finished
        .iter()
        .map(|f| (f.part.part.clone(), f.toolpaths.clone()))
        .collect();
    let parts = finished.into_iter().map(|f| f.part).collect();
    let manifest = RunManifest {
        format: RUN_FORMAT.into(),
        errmap_version: env!("CARGO_PKG_VERSION").into(),
        kind: "batch".into(),
        job: None,
        job_hash: header.job_hash,
        shard: None,
        backend: String::new(),
        inputs: header.inputs,
        parts,
        files: BTreeMap::new(),
        shards: BTreeMap::new(),
        created_utc: None,
        metadata: BTreeMap::new(),
        k_sigma: None,
    };
    Some((manifest, toolpaths))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finished_parts_read_back_and_a_torn_line_is_left_out() {
        let dir = tempfile::tempdir().unwrap();
        let inputs = BTreeMap::from([(PathBuf::from("p01.csv"), "aa".to_string())]);
        let j = Journal::create(dir.path(), "hash", &inputs).unwrap();
        let rec = PartRecord {
            part: "p01".into(),
            probe_file: "p01.csv".into(),
            input_sha256: "aa".into(),
            ok: true,
            reused: false,
            outputs: BTreeMap::from([("p01/map.csv".to_string(), "bb".to_string())]),
        };
        j.record(&Finished {
            part: rec.clone(),
            toolpaths: Vec::new(),
        })
        .unwrap();
        // The kill cut the next line short.
        let mut f = std::fs::OpenOptions::new()
            .append(true)
            .open(dir.path().join(JOURNAL_FILE))
            .unwrap();
        f.write_all(b"{\"part\":\"p02\",\"probe").unwrap();
        let (m, toolpaths) = read(dir.path()).unwrap();
        assert_eq!(toolpaths["p01"], Vec::new());
        assert_eq!(m.job_hash, "hash");
        assert_eq!(m.inputs, inputs);
        assert_eq!(m.parts, vec![rec]);
        j.remove().unwrap();
        assert!(read(dir.path()).is_none());
    }
}
