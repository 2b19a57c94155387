//! The binary's wording of the settings that library hints name: each crate's `Setting` as
//! the command-line flag that gives it (`errmap_toolpath::Setting::Units` → `--units`).
//!
//! The libraries name a setting by its type ([`errmap::setting`]); only this module knows the
//! flags. `main` installs [`flag`] before anything else runs, and a test checks that every
//! word here is a flag the command line has.

mod batch;
mod core_setting;
mod live;
mod maps;
mod metrology;
mod report;
mod serve;
mod synth;
mod toolpath;

use std::any::Any;

/// Each crate's wording: the flag of a setting given as `&dyn Any`, `None` if not its type.
const CRATES: &[fn(&dyn Any) -> Option<&'static str>] = &[
    core_setting::flag,
    maps::flag,
    toolpath::flag,
    metrology::flag,
    report::flag,
    synth::flag,
    batch::flag,
    live::flag,
    serve::flag,
];

/// The flag for any crate's setting, or `None` for a type that is not a setting.
pub fn flag(setting: &dyn Any) -> Option<&'static str> {
    CRATES.iter().find_map(|words| words(setting))
}

/// Every flag this module words settings with, for the test against the command line: the
/// string of each match arm in the crates' files (the arms are the whole table, checked
/// exhaustive by the compiler, so no list of them is kept beside).
#[cfg(test)]
fn all_flags() -> Vec<String> {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src/cli/words");
    let mut flags = Vec::new();
    for entry in std::fs::read_dir(&dir).expect("read src/cli/words") {
        let path = entry.expect("entry").path();
        if path.file_name().is_some_and(|n| n == "mod.rs") {
            continue;
        }
        let text = std::fs::read_to_string(&path).expect("read a table");
        let arms = text
            .lines()
            .filter(|l| l.trim_start().starts_with("Setting::") && l.contains("=>"))
            .count();
        let before = flags.len();
        for arm in text.split("=> \"").skip(1) {
            flags.push(arm.split('"').next().unwrap_or_default().to_string());
        }
        // Every arm words its setting with a literal flag, so the scan sees them all.
        assert_eq!(flags.len() - before, arms, "{}", path.display());
    }
    flags
}

/// The command line's flags, for the tests.
#[cfg(test)]
mod tests_support {
    use clap::CommandFactory;
    use std::collections::BTreeSet;

    /// Every `--long` flag of every subcommand, at any depth.
    pub fn command_line_flags() -> BTreeSet<String> {
        fn walk(cmd: &clap::Command, out: &mut BTreeSet<String>) {
            for arg in cmd.get_arguments() {
                if let Some(long) = arg.get_long() {
                    out.insert(format!("--{long}"));
                }
            }
            for sub in cmd.get_subcommands() {
                walk(sub, out);
            }
        }
        let mut out = BTreeSet::new();
        walk(&crate::cli::Cli::command(), &mut out);
        out
    }
}

#[cfg(test)]
mod tests {
    use super::tests_support::command_line_flags;
    use super::*;

    #[test]
    fn every_setting_is_worded_as_a_flag_the_command_line_has() {
        let flags = command_line_flags();
        assert!(flags.contains("--out-dir"), "the walk finds flags");
        let worded = all_flags();
        assert!(
            worded.iter().any(|w| w == "--units"),
            "the scan finds the tables"
        );
        for word in worded {
            assert!(flags.contains(&word), "{word} names no flag of errmap");
        }
    }
}

/// The libraries' sources name no flag of errmap: a string literal with `--name`, where
/// `name` is a long flag of the command line, is wording that belongs here. Lines that write
/// another program's options (`#SBATCH --time=…`) are not errmap's flags and are skipped.
#[cfg(test)]
mod libraries_name_no_flag {
    use super::tests_support::command_line_flags;
    use std::path::Path;

    /// The places a library names an errmap flag: `file:line: text`.
    fn flag_wording(flags: &std::collections::BTreeSet<String>) -> Vec<String> {
        let crates = Path::new(env!("CARGO_MANIFEST_DIR")).join("crates");
        let mut found = Vec::new();
        let mut stack = vec![crates];
        while let Some(dir) = stack.pop() {
            for entry in std::fs::read_dir(&dir).expect("read crates/") {
                let path = entry.expect("entry").path();
                if path.is_dir() {
                    stack.push(path);
                    continue;
                }
                if path.extension().is_none_or(|e| e != "rs")
                    || !path.to_string_lossy().contains("/src/")
                {
                    continue;
                }
                let text = std::fs::read_to_string(&path).expect("read source");
                // A crate's own unit tests may assert its words; they end a file.
                let code_end = text.find("#[cfg(test)]\nmod ").unwrap_or(text.len());
                for (k, line) in text[..code_end].lines().enumerate() {
                    let code = line.trim_start();
                    if code.starts_with("//") || line.contains("#SBATCH") {
                        continue;
                    }
                    if names_a_flag(line, flags) {
                        found.push(format!("{}:{}: {}", path.display(), k + 1, code));
                    }
                }
            }
        }
        found.sort();
        found
    }

    /// Whether a line holds, inside a string literal, `--name` for one of `flags`.
    fn names_a_flag(line: &str, flags: &std::collections::BTreeSet<String>) -> bool {
        let mut in_string = false;
        let bytes = line.as_bytes();
        let mut i = 0;
        while i < bytes.len() {
            match bytes[i] {
                b'\\' if in_string => i += 1,
                b'"' => in_string = !in_string,
                b'-' if in_string && line[i..].starts_with("--") => {
                    let name: String = line[i + 2..]
                        .chars()
                        .take_while(|c| c.is_ascii_alphanumeric() || *c == '-')
                        .collect();
                    if flags.contains(&format!("--{name}")) {
                        return true;
                    }
                }
                _ => {}
            }
            i += 1;
        }
        false
    }

    #[test]
    fn the_detector_sees_a_flag_in_a_string_only() {
        let flags = ["--units".to_string()].into_iter().collect();
        assert!(names_a_flag(r#"    "or pass --units mm|inch","#, &flags));
        assert!(!names_a_flag("    let units = 1; // --units", &flags));
        assert!(!names_a_flag(r#"    "pass --unit-cell""#, &flags));
    }

    #[test]
    fn no_library_words_an_errmap_flag() {
        let found = flag_wording(&command_line_flags());
        assert!(
            found.is_empty(),
            "{} library lines name errmap's flags; name a `Setting` and word it in src/cli/words:\n{}",
            found.len(),
            found.join("\n")
        );
    }
}
