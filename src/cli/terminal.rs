//! What the command line says on stderr, by verbosity: progress bars (shown on a terminal,
//! hidden when piped or with --quiet), informational lines (hidden by --quiet), details (only
//! with --verbose) and warnings (always). [`Terminal`] is the library's reporter for this.

use errmap::progress::{Progress, Reporter, Verbosity};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::{IsTerminal, Write};
use std::sync::atomic::{AtomicU8, Ordering};

static LEVEL: AtomicU8 = AtomicU8::new(Verbosity::Normal as u8);

/// Set the verbosity of this process (once, from --quiet / --verbose).
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

/// The reporter of this process: stderr at its verbosity, indicatif bars on a terminal.
#[derive(Debug, Clone, Copy, Default)]
pub struct Terminal;

/// The bar's line: what, how far (steps done of all), time so far and the time left, which
/// indicatif estimates from the recent rate (a family's parts: parts done, time to the last).
const BAR_TEMPLATE: &str = "{msg:>12} [{bar:30}] {pos}/{len} {elapsed_precise}, {eta} left";

/// A progress bar of `len` steps with a message, drawn on stderr only when it is a terminal and the run is not quiet.
fn bar(len: u64, message: &str) -> ProgressBar {
    let bar = ProgressBar::new(len);
    if verbosity() == Verbosity::Quiet || !std::io::stderr().is_terminal() {
        bar.set_draw_target(ProgressDrawTarget::hidden());
    }
    bar.set_style(
        ProgressStyle::with_template(BAR_TEMPLATE)
            .expect("progress template is valid")
            .progress_chars("=> "),
    );
    bar.set_message(message.to_string());
    bar
}

struct Bar(ProgressBar);

impl Progress for Bar {
    fn inc(&self, n: u64) {
        self.0.inc(n);
    }
    fn finish(&self) {
        self.0.finish_and_clear();
    }
}

impl Reporter for Terminal {
    fn info(&self, line: &str) {
        info(line);
    }
    fn detail(&self, line: &str) {
        detail(line);
    }
    fn warn(&self, line: &str) {
        warn(line);
    }
    fn shows_detail(&self) -> bool {
        verbosity() == Verbosity::Verbose
    }
    fn progress(&self, len: u64, message: &str) -> Box<dyn Progress> {
        Box::new(Bar(bar(len, message)))
    }
    fn activity(&self, message: &str) -> Box<dyn Progress> {
        // The bar ticks so a terminal shows the run is alive.
        let bar = bar(1, message);
        bar.enable_steady_tick(std::time::Duration::from_millis(200));
        Box::new(Bar(bar))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn verbosity_is_stored_and_read_back() {
        set_verbosity(Verbosity::Verbose);
        assert_eq!(verbosity(), Verbosity::Verbose);
        assert!(Terminal.shows_detail());
        set_verbosity(Verbosity::Quiet);
        assert_eq!(verbosity(), Verbosity::Quiet);
        assert!(!Terminal.shows_detail());
        set_verbosity(Verbosity::Normal);
        assert_eq!(verbosity(), Verbosity::Normal);
    }
}
