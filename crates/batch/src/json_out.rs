//! Large JSON documents of a run (`summary.json`, `run.json`) written straight into their file, pretty as `errmap_core::io::write_json` writes them, without the whole text in memory.

use errmap_core::error::{Diagnostic, Result};
use serde::Serialize;
use std::path::Path;

/// Write `value` as pretty JSON with a final newline, atomically: the same bytes as
/// `errmap_core::io::write_json`, streamed.
pub(crate) fn write_json<T: Serialize>(path: &Path, value: &T) -> Result<()> {
    // A value that cannot be JSON (a path that is not UTF-8) fails before the file is begun,
    // with the message the in-memory writer gives.
    serde_json::to_writer(std::io::sink(), value)
        .map_err(|e| Diagnostic::Internal(format!("JSON for {}: {e}", path.display())))?;
    errmap_core::io::write_atomic(path, |w| {
        serde_json::to_writer_pretty(&mut *w, value).map_err(std::io::Error::other)?;
        w.write_all(b"\n")
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streamed_json_is_byte_for_byte_the_in_memory_one() {
        let dir = tempfile::tempdir().unwrap();
        let value = serde_json::json!({
            "parts": [{"part": "p<1>", "rms_um": 0.1 + 0.2, "none": null}, {"e": [1e-300, -0.0]}],
            "text": "µm \"quoted\"\n",
        });
        let (a, b) = (dir.path().join("a.json"), dir.path().join("b.json"));
        errmap_core::io::write_json(&a, &value).unwrap();
        write_json(&b, &value).unwrap();
        assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
        // Pretty printed, with the final newline.
        let text = std::fs::read_to_string(&b).unwrap();
        assert!(
            text.starts_with("{\n  \"parts\": [\n") && text.ends_with("}\n"),
            "{text}"
        );
    }
}
