//! The batch runs under `--runs`, read-only: a request path is resolved inside the runs folder or refused (no `..`, no absolute path, no hidden name, no symlink leading outside: the canonical path must lie under the canonical root), and each file gets its content type.

use std::path::{Component, Path, PathBuf};

/// What a request path names under the runs folder.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Resolved {
    /// A regular file, by its canonical path (inside the root).
    File(PathBuf),
    /// A folder, by its canonical path (inside the root): answer with its listing.
    Dir(PathBuf),
}

/// Resolve a request path (already percent-decoded) under `root`, which must itself be
/// canonical. Refused: over 1024 bytes, a NUL, a backslash, `..`, a root or prefix, a name
/// starting with `.`, a name that is not UTF-8; then the joined path is canonicalised (symlinks
/// resolved) and must lie under `root`. `None` for anything refused, outside, missing or neither
/// file nor folder: the answer is the same 404 for all of them. The check is made at request
/// time: the caller opens the returned canonical path, not the request's.
pub fn resolve(root: &Path, request: &str) -> Option<Resolved> {
    if request.len() > 1024 || request.contains('\0') || request.contains('\\') {
        return None;
    }
    let rel = Path::new(request.trim_start_matches('/'));
    let mut clean = PathBuf::new();
    for c in rel.components() {
        match c {
            Component::Normal(part) => {
                let s = part.to_str()?;
                if s.starts_with('.') {
                    return None;
                }
                clean.push(part);
            }
            Component::CurDir => {}
            // `..`, a root or a prefix: refused, never normalised.
            _ => return None,
        }
    }
    let full = root.join(&clean).canonicalize().ok()?;
    if !full.starts_with(root) {
        return None;
    }
    let meta = std::fs::metadata(&full).ok()?;
    if meta.is_dir() {
        Some(Resolved::Dir(full))
    } else if meta.is_file() {
        Some(Resolved::File(full))
    } else {
        None
    }
}

/// The entries of a folder under the root that resolve inside it, sorted, folders first:
/// (name, is folder).
pub fn list(root: &Path, dir: &Path) -> Vec<(String, bool)> {
    let Ok(read) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut out: Vec<(String, bool)> = read
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            let name = e.file_name().into_string().ok()?;
            if name.starts_with('.') {
                return None;
            }
            let target = e.path().canonicalize().ok()?;
            if !target.starts_with(root) {
                return None;
            }
            Some((name, target.is_dir()))
        })
        .take(10_000)
        .collect();
    out.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
    out
}

/// Content type by extension; files errmap does not write are offered as downloads.
pub fn content_type(path: &Path) -> (&'static str, bool) {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase())
        .unwrap_or_default();
    let inline = |t| (t, true);
    match ext.as_str() {
        "html" | "htm" => inline("text/html; charset=utf-8"),
        "json" => inline("application/json"),
        "csv" => inline("text/csv; charset=utf-8"),
        "png" => inline("image/png"),
        "svg" => inline("image/svg+xml"),
        "pdf" => inline("application/pdf"),
        "txt" | "toml" | "ngc" | "nc" | "gcode" | "mpf" | "spf" | "h" | "comp" | "tab" | "log" => {
            inline("text/plain; charset=utf-8")
        }
        _ => ("application/octet-stream", false),
    }
}

/// Whether a file is an HTML page (served with the report's own policy).
pub fn is_html(path: &Path) -> bool {
    content_type(path).0.starts_with("text/html")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_resolve_inside_the_root_only() {
        let tmp = tempfile::tempdir().unwrap();
        let root = tmp.path().join("runs");
        std::fs::create_dir_all(root.join("r1/p01")).unwrap();
        std::fs::write(root.join("r1/report.html"), "x").unwrap();
        std::fs::write(root.join("r1/.hidden"), "x").unwrap();
        std::fs::write(tmp.path().join("secret.txt"), "s").unwrap();
        let root = root.canonicalize().unwrap();
        assert_eq!(
            resolve(&root, "r1/report.html"),
            Some(Resolved::File(root.join("r1/report.html")))
        );
        assert_eq!(
            resolve(&root, "r1/p01"),
            Some(Resolved::Dir(root.join("r1/p01")))
        );
        assert_eq!(resolve(&root, ""), Some(Resolved::Dir(root.clone())));
        for bad in [
            "../secret.txt",
            "r1/../../secret.txt",
            "r1/../r1/report.html",
            "/etc/passwd",
            "r1/.hidden",
            "r1\\report.html",
            "r1/report.html\0",
            "nope",
        ] {
            assert_eq!(resolve(&root, bad), None, "{bad}");
        }
        #[cfg(unix)]
        {
            std::os::unix::fs::symlink(tmp.path().join("secret.txt"), root.join("r1/link.txt"))
                .unwrap();
            std::os::unix::fs::symlink(tmp.path(), root.join("r1/up")).unwrap();
            std::os::unix::fs::symlink(root.join("r1/report.html"), root.join("r1/inside.html"))
                .unwrap();
            assert_eq!(resolve(&root, "r1/link.txt"), None);
            assert_eq!(resolve(&root, "r1/up/secret.txt"), None);
            assert!(resolve(&root, "r1/inside.html").is_some());
            let names: Vec<String> = list(&root, &root.join("r1"))
                .into_iter()
                .map(|e| e.0)
                .collect();
            assert_eq!(names, ["p01", "inside.html", "report.html"]);
        }
    }

    #[test]
    fn content_types_follow_the_extension() {
        assert_eq!(
            content_type(Path::new("a/report.html")).0,
            "text/html; charset=utf-8"
        );
        assert_eq!(content_type(Path::new("map.PNG")).0, "image/png");
        assert_eq!(
            content_type(Path::new("map.csv")).0,
            "text/csv; charset=utf-8"
        );
        assert_eq!(
            content_type(Path::new("x.ngc")).0,
            "text/plain; charset=utf-8"
        );
        assert_eq!(
            content_type(Path::new("model.bin")),
            ("application/octet-stream", false)
        );
    }
}
