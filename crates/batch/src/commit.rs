//! A run's folder replaced as a whole: the run is written into a hidden staging folder beside it, which is then exchanged with the old folder in one rename.
//!
//! Staging folders are named `.errmap-<folder name>-<random>.tmp`; anything of that name (and
//! every `.errmap-*.tmp` file inside the run's folder, left by an interrupted atomic write) is
//! stale and removed when the next run into that folder starts.

use super::manifest::RUN_MANIFEST;
use errmap_core::error::{Diagnostic, Result};
use std::path::{Path, PathBuf};

/// The staging folder of one run and the folder it will replace.
#[derive(Debug)]
pub struct Staging {
    /// Where the run will be visible once committed.
    pub target: PathBuf,
    /// Where it is written meanwhile (removed when the staging is dropped uncommitted).
    dir: Option<tempfile::TempDir>,
}

impl Staging {
    /// Remove stale temporaries of `target`, refuse a folder that holds anything but an errmap
    /// run, and create the staging folder beside it.
    pub fn begin(target: &Path) -> Result<Staging> {
        check_replaceable(target)?;
        Staging::begin_owned(target)
    }

    /// [`Staging::begin`] that keeps the staging folders of interrupted runs into `target`
    /// (their finished parts may be resumed) and returns them; the caller removes them.
    pub fn begin_keeping_stale(target: &Path) -> Result<(Staging, Vec<PathBuf>)> {
        check_replaceable(target)?;
        let stale = stale_stagings(target);
        remove_temporaries_inside(target)?;
        Ok((Staging::create(target)?, stale))
    }

    /// [`Staging::begin`] for a folder errmap owns inside a run's folder (e.g. `family/`),
    /// which has no manifest of its own.
    pub fn begin_owned(target: &Path) -> Result<Staging> {
        remove_stale(target)?;
        Staging::create(target)
    }

    /// A new staging folder beside `target`.
    fn create(target: &Path) -> Result<Staging> {
        let parent = parent_of(target);
        std::fs::create_dir_all(&parent)
            .map_err(|e| Diagnostic::io("create folder", &parent, e))?;
        let dir = tempfile::Builder::new()
            .prefix(&staging_prefix(target))
            .suffix(".tmp")
            .tempdir_in(&parent)
            .map_err(|e| Diagnostic::io("create a staging folder in", &parent, e))?;
        Ok(Staging {
            target: target.to_path_buf(),
            dir: Some(dir),
        })
    }

    /// The folder the run writes into.
    pub fn path(&self) -> &Path {
        self.dir.as_ref().map_or(&self.target, |d| d.path())
    }

    /// Make the staged run the target folder: one atomic exchange where the file system
    /// allows it (Linux `renameat2(RENAME_EXCHANGE)`), then the old run is removed.
    pub fn commit(mut self) -> Result<()> {
        let Some(dir) = self.dir.take() else {
            return Ok(());
        };
        let staged = dir.keep();
        if !self.target.exists() {
            return std::fs::rename(&staged, &self.target)
                .map_err(|e| Diagnostic::io("rename the finished run to", &self.target, e));
        }
        if !exchange(&staged, &self.target)? {
            // No atomic exchange here: move the old run aside, then the new one in.
            let aside = tempfile::Builder::new()
                .prefix(&staging_prefix(&self.target))
                .suffix(".tmp")
                .tempdir_in(parent_of(&self.target))
                .map_err(|e| Diagnostic::io("create a folder beside", &self.target, e))?
                .keep();
            std::fs::rename(&self.target, &aside)
                .map_err(|e| Diagnostic::io("move aside", &self.target, e))?;
            std::fs::rename(&staged, &self.target)
                .map_err(|e| Diagnostic::io("rename the finished run to", &self.target, e))?;
            std::fs::remove_dir_all(&aside)
                .map_err(|e| Diagnostic::io("remove the earlier run", &aside, e))?;
            return Ok(());
        }
        // `staged` now holds the old run.
        std::fs::remove_dir_all(&staged)
            .map_err(|e| Diagnostic::io("remove the earlier run", &staged, e))
    }
}

#[cfg(target_os = "linux")]
fn exchange(a: &Path, b: &Path) -> Result<bool> {
    use rustix::fs::{renameat_with, RenameFlags, CWD};
    match renameat_with(CWD, a, CWD, b, RenameFlags::EXCHANGE) {
        Ok(()) => Ok(true),
        Err(e) if e == rustix::io::Errno::INVAL || e == rustix::io::Errno::NOSYS => Ok(false),
        Err(e) => Err(Diagnostic::io(
            "exchange the finished run with",
            b,
            e.into(),
        )),
    }
}

#[cfg(not(target_os = "linux"))]
fn exchange(_: &Path, _: &Path) -> Result<bool> {
    Ok(false)
}

fn parent_of(target: &Path) -> PathBuf {
    match target.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

fn folder_name(target: &Path) -> String {
    target
        .file_name()
        .map_or_else(|| "run".to_string(), |n| n.to_string_lossy().to_string())
}

/// `.errmap-<name>-`: staging folders of `target` (and only of it) start with this.
fn staging_prefix(target: &Path) -> String {
    format!(".errmap-{}-", folder_name(target))
}

fn is_temporary(name: &str) -> bool {
    name.starts_with(".errmap-") && name.ends_with(".tmp")
}

/// Remove what an interrupted run into `target` left: its staging folders beside it and
/// `.errmap-*.tmp` files anywhere inside it.
pub fn remove_stale(target: &Path) -> Result<()> {
    for dir in stale_stagings(target) {
        remove_path(&dir)?;
    }
    remove_temporaries_inside(target)
}

/// The staging folders interrupted runs into `target` left beside it, by name.
pub fn stale_stagings(target: &Path) -> Vec<PathBuf> {
    let parent = parent_of(target);
    let prefix = staging_prefix(target);
    let mut found = Vec::new();
    if let Ok(entries) = std::fs::read_dir(&parent) {
        for entry in entries.flatten() {
            let name = entry.file_name().to_string_lossy().to_string();
            if name.starts_with(&prefix) && name.ends_with(".tmp") {
                found.push(entry.path());
            }
        }
    }
    found.sort();
    found
}

/// Remove the `.errmap-*.tmp` files interrupted writes left anywhere inside `target`.
fn remove_temporaries_inside(target: &Path) -> Result<()> {
    let mut stack = vec![target.to_path_buf()];
    while let Some(dir) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for entry in entries.flatten() {
            let path = entry.path();
            let name = entry.file_name().to_string_lossy().to_string();
            let is_dir = entry.file_type().is_ok_and(|t| t.is_dir());
            if is_temporary(&name) {
                remove_path(&path)?;
            } else if is_dir {
                stack.push(path);
            }
        }
    }
    Ok(())
}

/// Remove a file or a folder tree; one already gone is fine.
pub fn remove_path(path: &Path) -> Result<()> {
    let r = if path.is_dir() {
        std::fs::remove_dir_all(path)
    } else {
        std::fs::remove_file(path)
    };
    match r {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(Diagnostic::io("remove the stale temporary", path, e)),
    }
}

/// A run replaces its folder as a whole, so the folder must be absent, empty, or an errmap
/// run (it has `run.json`); anything else may be a user's files.
fn check_replaceable(target: &Path) -> Result<()> {
    if !target.exists() {
        return Ok(());
    }
    if !target.is_dir() {
        return Err(Diagnostic::usage(
            format!("output folder {} is a file", target.display()),
            format!(
                "pass {} a folder name",
                errmap_core::setting::words(crate::Setting::OutDir)
            ),
        ));
    }
    if target.join(RUN_MANIFEST).is_file() {
        return Ok(());
    }
    let has_content = std::fs::read_dir(target)
        .map_err(|e| Diagnostic::read(target, e))?
        .flatten()
        .any(|e| !is_temporary(&e.file_name().to_string_lossy()));
    if has_content {
        return Err(Diagnostic::usage(
            format!(
                "output folder {} is not empty and holds no errmap run ({RUN_MANIFEST})",
                target.display()
            ),
            format!("a run replaces its output folder as a whole: pass {} a new or empty folder, or remove this one", errmap_core::setting::words(crate::Setting::OutDir)),
        ));
    }
    Ok(())
}

/// `path` with its longest existing ancestor resolved (symbolic links, `..`).
fn canonical_prefix(path: &Path) -> PathBuf {
    let mut rest = Vec::new();
    let mut head = path.to_path_buf();
    loop {
        if let Ok(c) = head.canonicalize() {
            return rest.iter().rev().fold(c, |acc, n| acc.join(n));
        }
        match (head.file_name().map(|n| n.to_os_string()), head.parent()) {
            (Some(name), Some(parent)) => {
                rest.push(name);
                head = parent.to_path_buf();
            }
            _ => return path.to_path_buf(),
        }
    }
}

/// Refuse an output folder that holds one of the run's inputs: replacing it would delete them.
pub fn check_inputs_outside(target: &Path, inputs: &[PathBuf]) -> Result<()> {
    let Ok(target_abs) = std::path::absolute(target) else {
        return Ok(());
    };
    let target_abs = canonical_prefix(&target_abs);
    for input in inputs {
        let abs = input
            .canonicalize()
            .or_else(|_| std::path::absolute(input))
            .unwrap_or_else(|_| input.clone());
        if abs.starts_with(&target_abs) {
            return Err(Diagnostic::usage(
                format!(
                    "input {} lies inside the output folder {}",
                    input.display(),
                    target.display()
                ),
                format!("a run replaces its output folder as a whole: pass {} a folder that holds no input", errmap_core::setting::words(crate::Setting::OutDir)),
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn commit_replaces_the_folder_as_a_whole_and_cleans_up() {
        let root = tempfile::tempdir().unwrap();
        let target = root.path().join("out");
        // First run into a missing folder.
        let s = Staging::begin(&target).unwrap();
        std::fs::write(s.path().join("a.txt"), "old a").unwrap();
        std::fs::write(s.path().join(RUN_MANIFEST), "{}").unwrap();
        s.commit().unwrap();
        assert_eq!(
            std::fs::read_to_string(target.join("a.txt")).unwrap(),
            "old a"
        );
        // Second run: b.txt only; a.txt must be gone, no staging left beside.
        std::fs::write(target.join(".errmap-x.tmp"), "stale").unwrap();
        let s = Staging::begin(&target).unwrap();
        assert!(!target.join(".errmap-x.tmp").exists());
        std::fs::write(s.path().join("b.txt"), "new b").unwrap();
        std::fs::write(s.path().join(RUN_MANIFEST), "{}").unwrap();
        s.commit().unwrap();
        assert!(!target.join("a.txt").exists());
        assert_eq!(
            std::fs::read_to_string(target.join("b.txt")).unwrap(),
            "new b"
        );
        let left: Vec<_> = std::fs::read_dir(root.path()).unwrap().flatten().collect();
        assert_eq!(left.len(), 1, "only out/ remains: {left:?}");
        // A staging dropped without commit leaves the old run and nothing else.
        let s = Staging::begin(&target).unwrap();
        std::fs::write(s.path().join("c.txt"), "never").unwrap();
        drop(s);
        assert!(target.join("b.txt").exists() && !target.join("c.txt").exists());
        assert_eq!(std::fs::read_dir(root.path()).unwrap().count(), 1);
    }

    #[test]
    fn a_folder_of_other_files_or_holding_an_input_is_refused() {
        let root = tempfile::tempdir().unwrap();
        let target = root.path().join("mine");
        std::fs::create_dir(&target).unwrap();
        std::fs::write(target.join("notes.txt"), "keep me").unwrap();
        let err = Staging::begin(&target).unwrap_err().to_string();
        assert!(err.contains("holds no errmap run"), "{err}");
        assert!(target.join("notes.txt").exists());
        let input = target.join("p01.csv");
        std::fs::write(&input, "x").unwrap();
        let err = check_inputs_outside(&target, &[input])
            .unwrap_err()
            .to_string();
        assert!(err.contains("inside the output folder"), "{err}");
        assert!(
            check_inputs_outside(&root.path().join("other"), &[target.join("p01.csv")]).is_ok()
        );
    }
}
