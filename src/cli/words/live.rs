//! The flags of `errmap_live`'s settings (the live loop, its bench and replay).

use errmap::live::Setting;
use std::any::Any;

/// The flag of a live setting.
pub fn words(setting: Setting) -> &'static str {
    match setting {
        Setting::Once => "--once",
        Setting::DryRun => "--dry-run",
        Setting::Sensors => "--sensors",
        Setting::Axes => "--axes",
        Setting::Hz => "--hz",
        Setting::Seconds => "--seconds",
        Setting::Hours => "--hours",
        Setting::PeriodS => "--period-s",
        Setting::FeedMmMin => "--feed-mm-min",
        Setting::Campaign => "--campaign",
    }
}

/// [`words`] for a setting given as `&dyn Any`; `None` when it is not a live setting.
pub fn flag(setting: &dyn Any) -> Option<&'static str> {
    setting.downcast_ref::<Setting>().map(|s| words(*s))
}
