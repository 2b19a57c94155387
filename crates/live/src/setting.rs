//! The settings of the live loop, its bench and its replay that hints name; the front end
//! words them (the binary as its flags).

/// A setting of the live loop, the bench or the replay that a hint can tell the user to give.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Setting {
    /// Loop: take one cycle of live readings, written without the start ramp.
    Once,
    /// Loop: compute and log only; no target is contacted or written.
    DryRun,
    /// Bench: the number of sensors.
    Sensors,
    /// Bench: the number of axes.
    Axes,
    /// Bench: the cycle rate in Hz.
    Hz,
    /// Bench: how long it runs, in s.
    Seconds,
    /// Replay: the log's duration in hours.
    Hours,
    /// Replay: the time between rows in s.
    PeriodS,
    /// Replay: the feed in mm/min.
    FeedMmMin,
    /// Replay: which synthetic campaign the log replays.
    Campaign,
}

impl errmap_core::Setting for Setting {
    fn key(self) -> &'static str {
        match self {
            Setting::Once => "once",
            Setting::DryRun => "dry_run",
            Setting::Sensors => "sensors",
            Setting::Axes => "axes",
            Setting::Hz => "hz",
            Setting::Seconds => "seconds",
            Setting::Hours => "hours",
            Setting::PeriodS => "period_s",
            Setting::FeedMmMin => "feed_mm_min",
            Setting::Campaign => "campaign",
        }
    }
}
