//! Old flag spellings kept for one release: each is a hidden argument of its own, merged here
//! into the new one with a note on stderr, so a script learns the new spelling before the old
//! one goes. Clap's aliases would accept them silently.

use errmap::{Error, Result};
use std::path::{Path, PathBuf};

/// The note printed when an old spelling is used.
pub fn note(old: &str, new: &str) -> String {
    format!("warning: `{old}` is deprecated, use `{new}`; it will be removed in the next release")
}

/// The value of a renamed flag: the new spelling's, else the old one's with a deprecation
/// note. Clap refuses both together (`conflicts_with`), so at most one is set.
pub fn renamed<T>(new: Option<T>, old: Option<T>, old_flag: &str, new_flag: &str) -> Option<T> {
    match (new, old) {
        (Some(v), _) => Some(v),
        (None, Some(v)) => {
            super::terminal::warn(&note(old_flag, new_flag));
            Some(v)
        }
        (None, None) => None,
    }
}

/// [`renamed`] for an old `-o/--output` that named a folder, while `-o/--output` now means one
/// file everywhere: a value that looks like a file (it has an extension and is not an existing
/// folder) is refused rather than guessed at.
pub fn old_output_folder(
    new: Option<PathBuf>,
    old: Option<PathBuf>,
    new_flag: &str,
    writes: &str,
) -> Result<Option<PathBuf>> {
    if let (None, Some(dir)) = (&new, &old) {
        if looks_like_a_file(dir) {
            return Err(Error::usage(
                format!(
                    "-o/--output {} names a file, but this command writes a folder ({writes})",
                    dir.display()
                ),
                format!("give the folder with {new_flag} DIR"),
            ));
        }
    }
    Ok(renamed(new, old, "-o/--output", new_flag))
}

fn looks_like_a_file(path: &Path) -> bool {
    path.extension().is_some() && !path.is_dir()
}

/// A folder every caller must give, under its new or its old spelling (clap checks that one is
/// there).
pub fn required<T>(new: Option<T>, old: Option<T>, old_flag: &str, new_flag: &str) -> Result<T> {
    renamed(new, old, old_flag, new_flag).ok_or_else(|| {
        Error::usage(
            format!("{new_flag} is required"),
            format!("give the output folder with {new_flag} DIR"),
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_new_spelling_wins_and_the_old_one_still_counts() {
        assert_eq!(renamed(Some(1), None, "--out", "--out-dir"), Some(1));
        assert_eq!(renamed(None, Some(2), "--out", "--out-dir"), Some(2));
        assert_eq!(renamed::<u8>(None, None, "--out", "--out-dir"), None);
    }

    #[test]
    fn an_old_output_folder_that_looks_like_a_file_is_refused() {
        let err = old_output_folder(None, Some("diff.csv".into()), "--out-dir", "three files")
            .unwrap_err();
        assert_eq!(err.kind(), "input");
        let dir = old_output_folder(None, Some("out/difference".into()), "--out-dir", "x").unwrap();
        assert_eq!(dir, Some(PathBuf::from("out/difference")));
    }

    #[test]
    fn the_note_names_both_spellings() {
        assert_eq!(
            note("--out", "--out-dir"),
            "warning: `--out` is deprecated, use `--out-dir`; it will be removed in the next release"
        );
    }
}
