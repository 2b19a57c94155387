//! Stage 7, report: the run's `report.html` (and, in a large family, each part's page in its folder) from the summary in memory and the run's manifest, each page listed in the manifest before `run.json` is written; the table of parts is written row by row and the part pages one at a time.
//!
//! The summary is the one just written to `summary.json`; its numbers read back from the file
//! are the same bits (serde_json parses with `float_roundtrip`), so `errmap report` on the
//! folder gives the same bytes.

use crate::manifest::{self, RunManifest};
use crate::run_page::{self, RunInput, RunPage, REPORT_FILE};
use crate::summary::BatchSummary;
use errmap_core::error::{Diagnostic, Result};
use std::path::Path;

/// Write `report.html` into the run's folder `dir` and list it in the manifest `m`; in a
/// family of more than [`run_page::INLINE_PARTS`] parts, each part's page too, listed with
/// the part's files.
pub(crate) fn write_report(dir: &Path, m: &mut RunManifest, summary: &BatchSummary) -> Result<()> {
    let input = RunInput {
        dir,
        manifest: m,
        summary,
    };
    let page = RunPage::new(&input)?;
    let path = dir.join(REPORT_FILE);
    errmap_core::io::write_atomic(&path, |w| page.write(&input, w))?;
    drop(page);
    let hash = manifest::sha256_file(&path)?;
    m.files.insert(REPORT_FILE.to_string(), hash);
    if !run_page::has_part_pages(summary.parts.len()) {
        return Ok(());
    }
    // A large family: each part's page in its folder, one at a time, listed with the part's
    // files.
    let mut pages = Vec::new();
    for p in &summary.parts {
        let input = RunInput {
            dir,
            manifest: m,
            summary,
        };
        let html = run_page::render_part(&input, p)?;
        let rel = format!("{}/{REPORT_FILE}", p.part);
        let path = dir.join(&rel);
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent)
                .map_err(|e| Diagnostic::io("create folder", parent, e))?;
        }
        errmap_core::io::write_atomic_bytes(&path, html.as_bytes())?;
        pages.push((p.part.clone(), rel, manifest::sha256_bytes(html.as_bytes())));
    }
    for (part, rel, hash) in pages {
        match m.parts.iter_mut().find(|r| r.part == part) {
            Some(r) => {
                r.outputs.insert(rel, hash);
            }
            None => {
                m.files.insert(rel, hash);
            }
        }
    }
    Ok(())
}
