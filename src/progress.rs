//! What a run tells the user on stderr, by verbosity: progress bars (shown on a terminal, hidden
//! when piped or with --quiet), informational lines (hidden by --quiet), details (only with
//! --verbose) and warnings (always).

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::{IsTerminal, Write};
use std::sync::atomic::{AtomicU8, Ordering};

/// How much a run says on stderr besides its results and errors.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Verbosity {
    /// `--quiet`: no progress bars, no informational lines; warnings and errors only.
    Quiet = 0,
    /// The default: progress bars on a terminal and one line per file written.
    Normal = 1,
    /// `--verbose`: also the trainer chosen and why, and the size of the training work.
    Verbose = 2,
}

static LEVEL: AtomicU8 = AtomicU8::new(Verbosity::Normal as u8);

/// Set the verbosity of this process (the CLI does it once, from --quiet / --verbose).
pub fn set_verbosity(v: Verbosity) {
    LEVEL.store(v as u8, Ordering::Relaxed);
}

/// The verbosity of this process.
pub fn verbosity() -> Verbosity {
    match LEVEL.load(Ordering::Relaxed) {
        0 => Verbosity::Quiet,
        2 => Verbosity::Verbose,
        _ => Verbosity::Normal,
    }
}

fn line_at(level: Verbosity, line: &str) {
    if verbosity() >= level {
        // A closed stderr has nowhere to report to: the line is dropped.
        let _ = writeln!(std::io::stderr().lock(), "{line}");
    }
}

/// A line a normal run shows ("wrote …"); hidden by --quiet.
pub fn info(line: &str) {
    line_at(Verbosity::Normal, line);
}

/// A line shown only with --verbose (which trainer, on which device, how much work).
pub fn detail(line: &str) {
    line_at(Verbosity::Verbose, line);
}

/// A warning the user should act on (a deprecated flag, a fallback); shown even with --quiet.
pub fn warn(line: &str) {
    line_at(Verbosity::Quiet, line);
}

/// A progress bar of `len` steps with a message, drawn on stderr only when it is a terminal and `quiet` is off.
pub fn bar(len: u64, message: &str, quiet: bool) -> ProgressBar {
    let bar = ProgressBar::new(len);
    if quiet || verbosity() == Verbosity::Quiet || !std::io::stderr().is_terminal() {
        bar.set_draw_target(ProgressDrawTarget::hidden());
    }
    bar.set_style(
        ProgressStyle::with_template("{msg:>12} [{bar:30}] {pos}/{len} {elapsed_precise}")
            .expect("progress template is valid")
            .progress_chars("=> "),
    );
    bar.set_message(message.to_string());
    bar
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn verbosity_levels_are_ordered_and_stored() {
        assert!(Verbosity::Quiet < Verbosity::Normal && Verbosity::Normal < Verbosity::Verbose);
        set_verbosity(Verbosity::Verbose);
        assert_eq!(verbosity(), Verbosity::Verbose);
        set_verbosity(Verbosity::Quiet);
        assert_eq!(verbosity(), Verbosity::Quiet);
        set_verbosity(Verbosity::Normal);
        assert_eq!(verbosity(), Verbosity::Normal);
    }
}
