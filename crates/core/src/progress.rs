//! What a long run tells its caller while it works: a [`Reporter`] the caller passes in, with
//! informational lines, details, warnings and progress handles. The library never writes to
//! stderr itself; the CLI's reporter draws bars and honours --quiet / --verbose, [`Silent`]
//! says nothing (tests, library users).

use std::sync::Mutex;

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

/// The progress of one stage of a run: `len` steps, counted as they finish.
pub trait Progress: Send + Sync {
    /// `n` more steps done.
    fn inc(&self, n: u64);
    /// The stage is over: the handle disappears from the terminal.
    fn finish(&self);
}

/// Where a run's notes and progress go; the caller decides what is shown and how.
pub trait Reporter: Send + Sync {
    /// A line a normal run shows ("wrote …").
    fn info(&self, line: &str);
    /// A line for a verbose run (which trainer, on which device, how much work).
    fn detail(&self, line: &str);
    /// A warning the user should act on (a deprecated flag, a fallback).
    fn warn(&self, line: &str);
    /// Whether detail lines are shown: a caller may skip composing them otherwise.
    fn shows_detail(&self) -> bool {
        false
    }
    /// A handle for a stage of `len` steps named `message`.
    fn progress(&self, len: u64, message: &str) -> Box<dyn Progress>;
    /// A handle for one long step (a training call) that shows it is alive while it runs.
    fn activity(&self, message: &str) -> Box<dyn Progress> {
        self.progress(1, message)
    }
}

/// A reporter that says nothing.
#[derive(Debug, Clone, Copy, Default)]
pub struct Silent;

impl Progress for Silent {
    fn inc(&self, _n: u64) {}
    fn finish(&self) {}
}

impl Reporter for Silent {
    fn info(&self, _line: &str) {}
    fn detail(&self, _line: &str) {}
    fn warn(&self, _line: &str) {}
    fn progress(&self, _len: u64, _message: &str) -> Box<dyn Progress> {
        Box::new(Silent)
    }
}

/// One thing a [`Recorder`] was told.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Event {
    /// A line for a normal run ([`Reporter::info`]).
    Info(String),
    /// A line for a verbose run ([`Reporter::detail`]).
    Detail(String),
    /// A warning ([`Reporter::warn`]).
    Warn(String),
    /// A progress handle opened: its message and length.
    Stage(String, u64),
}

/// A reporter that keeps everything it is told, in order (for tests and for callers that show
/// a run's notes their own way).
#[derive(Debug, Default)]
pub struct Recorder {
    events: Mutex<Vec<Event>>,
}

impl Recorder {
    /// Everything reported so far.
    pub fn events(&self) -> Vec<Event> {
        self.events.lock().map(|e| e.clone()).unwrap_or_default()
    }

    fn push(&self, event: Event) {
        if let Ok(mut events) = self.events.lock() {
            events.push(event);
        }
    }
}

impl Reporter for Recorder {
    fn info(&self, line: &str) {
        self.push(Event::Info(line.into()));
    }
    fn detail(&self, line: &str) {
        self.push(Event::Detail(line.into()));
    }
    fn warn(&self, line: &str) {
        self.push(Event::Warn(line.into()));
    }
    fn shows_detail(&self) -> bool {
        true
    }
    fn progress(&self, len: u64, message: &str) -> Box<dyn Progress> {
        self.push(Event::Stage(message.into(), len));
        Box::new(Silent)
    }
}

/// Where a library call sends a one-line note for the user (the CLI prints it on stderr
/// unless `--quiet`; tests pass [`silent`]).
pub type Notes = std::sync::Arc<dyn Fn(&str) + Send + Sync>;

/// Notes that go nowhere.
pub fn silent() -> Notes {
    std::sync::Arc::new(|_| {})
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn verbosity_levels_are_ordered() {
        assert!(Verbosity::Quiet < Verbosity::Normal && Verbosity::Normal < Verbosity::Verbose);
    }

    #[test]
    fn a_recorder_keeps_every_line_and_stage_in_order() {
        let r = Recorder::default();
        r.info("wrote a");
        let bar = r.progress(3, "clean");
        bar.inc(3);
        bar.finish();
        r.detail("trainer: cpu");
        r.warn("careful");
        let _ = r.activity("train");
        assert_eq!(
            r.events(),
            vec![
                Event::Info("wrote a".into()),
                Event::Stage("clean".into(), 3),
                Event::Detail("trainer: cpu".into()),
                Event::Warn("careful".into()),
                Event::Stage("train".into(), 1),
            ]
        );
        assert!(r.shows_detail() && !Silent.shows_detail());
    }
}
