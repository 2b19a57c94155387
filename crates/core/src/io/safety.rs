//! Output safety rules every writer obeys: no output over an input, nothing outside the output root, and file names that cannot escape a folder.
//!
//! The command line calls [`activate`] once; from then on every file read through
//! [`crate::io`] is remembered as an input, commands [`protect`] the inputs they name up front
//! (a batch protects every probe file and toolpath before it writes anything), and
//! [`crate::io::write_atomic`] refuses an output that is, or resolves to, one of them (same
//! device and inode, or the same canonical path when the output does not exist yet). A command
//! that writes into a folder confines its outputs there with [`confine_to`]. Library users who
//! never call [`activate`] see none of this.

use crate::error::{Error, Result};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;

/// The protected inputs, by canonical path and, where the platform has them, by device and
/// inode, each with the path as the command was given it (for messages). Ordered maps: a batch
/// of many parts checks every output in logarithmic time.
#[derive(Debug, Default)]
struct Rules {
    active: bool,
    by_path: BTreeMap<PathBuf, PathBuf>,
    by_id: BTreeMap<(u64, u64), PathBuf>,
    roots: Vec<PathBuf>,
}

static RULES: Mutex<Rules> = Mutex::new(Rules {
    active: false,
    by_path: BTreeMap::new(),
    by_id: BTreeMap::new(),
    roots: Vec::new(),
});

/// Default of `--max-output-mb`: the largest file one output may grow to, MB (10⁶ bytes).
pub const DEFAULT_MAX_OUTPUT_MB: u64 = 1000;

static MAX_OUTPUT_BYTES: AtomicU64 = AtomicU64::new(DEFAULT_MAX_OUTPUT_MB * 1_000_000);

/// Set the largest file a writer may produce (`--max-output-mb`).
pub fn set_max_output_mb(mb: u64) {
    MAX_OUTPUT_BYTES.store(mb.saturating_mul(1_000_000), Ordering::Relaxed);
}

/// The largest file a writer may produce, bytes.
pub fn max_output_bytes() -> u64 {
    MAX_OUTPUT_BYTES.load(Ordering::Relaxed)
}

fn rules() -> std::sync::MutexGuard<'static, Rules> {
    // A panic while holding the lock cannot leave the lists half-updated: recover them.
    RULES
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// Turn the rules on for this process (the CLI does this before running a command).
pub fn activate() {
    rules().active = true;
}

#[cfg(unix)]
fn file_id(meta: &std::fs::Metadata) -> Option<(u64, u64)> {
    use std::os::unix::fs::MetadataExt;
    Some((meta.dev(), meta.ino()))
}

#[cfg(not(unix))]
fn file_id(_meta: &std::fs::Metadata) -> Option<(u64, u64)> {
    None
}

/// Remember `path` as an input that no output may replace. Paths that do not exist (yet) are
/// ignored: there is nothing to lose.
pub fn protect(path: &Path) {
    let mut r = rules();
    if !r.active {
        return;
    }
    let Ok(canonical) = std::fs::canonicalize(path) else {
        return;
    };
    if r.by_path.contains_key(&canonical) {
        return;
    }
    if let Some(id) = std::fs::metadata(&canonical).ok().and_then(|m| file_id(&m)) {
        r.by_id.insert(id, path.to_path_buf());
    }
    r.by_path.insert(canonical, path.to_path_buf());
}

/// Let one protected input be replaced after all: a command whose documented purpose is to
/// update a file in place (`thermal calibrate` without `-o`) says so here.
pub fn allow_replacing(path: &Path) {
    let mut r = rules();
    if let Ok(canonical) = std::fs::canonicalize(path) {
        if let Some(id) = std::fs::metadata(&canonical).ok().and_then(|m| file_id(&m)) {
            r.by_id.remove(&id);
        }
        r.by_path.remove(&canonical);
    }
}

/// Keep every output of this process under `root` (created if missing). A second call adds
/// another root.
pub fn confine_to(root: &Path) -> Result<()> {
    let mut r = rules();
    if !r.active {
        return Ok(());
    }
    std::fs::create_dir_all(root).map_err(|e| Error::io("create folder", root, e))?;
    let canonical = std::fs::canonicalize(root).map_err(|e| Error::io("resolve", root, e))?;
    if !r.roots.contains(&canonical) {
        r.roots.push(canonical);
    }
    Ok(())
}

/// The canonical form of a path that may not exist yet: its deepest existing ancestor,
/// canonicalised, with the rest of the path appended (`..` taken lexically there: folders that
/// do not exist cannot be symlinks). `None` when no ancestor resolves.
fn resolve(path: &Path) -> Option<PathBuf> {
    let mut base = path.to_path_buf();
    let mut rest: Vec<std::ffi::OsString> = Vec::new();
    loop {
        let probe = if base.as_os_str().is_empty() {
            Path::new(".")
        } else {
            base.as_path()
        };
        if let Ok(mut out) = std::fs::canonicalize(probe) {
            for part in rest.iter().rev() {
                match part.to_str() {
                    Some("..") => {
                        out.pop();
                    }
                    Some(".") => {}
                    _ => out.push(part),
                }
            }
            return Some(out);
        }
        let last = base.components().next_back()?;
        rest.push(last.as_os_str().to_owned());
        if !base.pop() {
            return None;
        }
    }
}

/// Refuse `output` when it is, or resolves to, a protected input, or lies outside the output
/// roots. Called by every writer just before it creates its temporary file (the folder exists
/// by then).
pub fn check_output(output: &Path) -> Result<()> {
    let r = rules();
    if !r.active {
        return Ok(());
    }
    let resolved = resolve(output);
    let id = std::fs::metadata(output).ok().and_then(|m| file_id(&m));
    let same_file = id.and_then(|id| r.by_id.get(&id));
    let same_path = resolved.as_ref().and_then(|p| r.by_path.get(p));
    if let Some(input) = same_file.or(same_path) {
        return Err(Error::usage(
            format!(
                "refusing to write {}: it is the input {}",
                output.display(),
                input.display()
            ),
            "choose an output path that is not one of the command's input files",
        ));
    }
    if !r.roots.is_empty() {
        let inside = resolved
            .as_deref()
            .is_some_and(|p| r.roots.iter().any(|root| p.starts_with(root)));
        if !inside {
            let roots: Vec<String> = r.roots.iter().map(|p| p.display().to_string()).collect();
            return Err(Error::Internal(format!(
                "refusing to write {}: it lies outside the output folder {}",
                output.display(),
                roots.join(", ")
            )));
        }
    }
    Ok(())
}

/// Names a part's folder may not take: they hold the batch's own outputs.
pub const RESERVED_NAMES: [&str; 2] = ["family", "summary.json"];

/// A file or folder name made from free text (a probe file's stem): every character other than
/// letters, digits, `-`, `_` and `.` becomes `_`, leading dots are dropped (no hidden files,
/// no `.` or `..`), an empty result becomes `part`, and names longer than 100 bytes are cut.
pub fn safe_name(text: &str) -> String {
    let mut name: String = text
        .chars()
        .map(|c| {
            if c.is_alphanumeric() || matches!(c, '-' | '_' | '.') {
                c
            } else {
                '_'
            }
        })
        .collect();
    name = name.trim_start_matches('.').to_string();
    while name.len() > 100 {
        name.pop();
    }
    if name.is_empty() {
        name = "part".into();
    }
    name
}

/// One safe, distinct folder name per part from the parts' stems: [`safe_name`], reserved
/// names get a `-part` suffix, and a name already taken (case-insensitively, for file systems
/// that fold case) gets `-2`, `-3`, … — the first number that collides with no other name.
/// Returns the names and, for each name that differs from its stem, a line saying so.
pub fn part_names(stems: &[String]) -> (Vec<String>, Vec<String>) {
    let base: Vec<String> = stems
        .iter()
        .map(|s| {
            let n = safe_name(s);
            if RESERVED_NAMES.iter().any(|r| r.eq_ignore_ascii_case(&n)) {
                format!("{n}-part")
            } else {
                n
            }
        })
        .collect();
    let key = |s: &str| s.to_lowercase();
    let mut taken: std::collections::HashSet<String> = std::collections::HashSet::new();
    // Names that occur once keep their form; they are reserved first so a renamed duplicate
    // cannot take them (`p1`, `p1` and `p1-2` must not give `p1-2` twice).
    let mut count: std::collections::HashMap<String, usize> = std::collections::HashMap::new();
    for b in &base {
        *count.entry(key(b)).or_default() += 1;
    }
    for b in &base {
        if count[&key(b)] == 1 {
            taken.insert(key(b));
        }
    }
    let mut names = Vec::with_capacity(base.len());
    let mut notes = Vec::new();
    for (stem, b) in stems.iter().zip(&base) {
        let name = if count[&key(b)] == 1 {
            b.clone()
        } else {
            let mut k = 1;
            loop {
                let candidate = format!("{b}-{k}");
                if taken.insert(key(&candidate)) {
                    break candidate;
                }
                k += 1;
            }
        };
        if &name != stem {
            notes.push(format!("part '{stem}' is written as '{name}'"));
        }
        names.push(name);
    }
    (names, notes)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn strings(v: &[&str]) -> Vec<String> {
        v.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn safe_names_cannot_leave_their_folder() {
        assert_eq!(safe_name(".."), "part");
        assert_eq!(safe_name("..."), "part");
        assert_eq!(safe_name(".hidden"), "hidden");
        assert_eq!(safe_name("a/b"), "a_b");
        assert_eq!(safe_name("a\\b:c"), "a_b_c");
        assert_eq!(safe_name(""), "part");
        assert_eq!(safe_name("p 01"), "p_01");
        assert_eq!(safe_name(&"x".repeat(300)).len(), 100);
    }

    #[test]
    fn part_names_are_distinct_and_avoid_reserved_names() {
        // `a/p1.csv`, `b/p1.csv` and `c/p1-1.csv`: the plain "append the position" scheme gave
        // p1-1 twice.
        let (names, notes) = part_names(&strings(&["p1", "p1", "p1-1"]));
        assert_eq!(names, ["p1-2", "p1-3", "p1-1"]);
        assert_eq!(notes.len(), 2);
        let (names, _) = part_names(&strings(&["family", "Family", "summary.json"]));
        assert_eq!(
            names,
            ["family-part-1", "Family-part-2", "summary.json-part"]
        );
        let (names, _) = part_names(&strings(&["..", "...", "part"]));
        let mut sorted = names.clone();
        sorted.sort();
        sorted.dedup();
        assert_eq!(sorted.len(), 3, "{names:?}");
        assert!(names.iter().all(|n| !n.starts_with('.')), "{names:?}");
        let (names, notes) = part_names(&strings(&["p01", "p02"]));
        assert_eq!(names, ["p01", "p02"]);
        assert!(notes.is_empty());
    }
}
