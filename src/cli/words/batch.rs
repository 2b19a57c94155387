//! The flags of `errmap_batch`'s settings.

use errmap::batch::Setting;
use std::any::Any;

/// The flag of a batch setting.
pub fn words(setting: Setting) -> &'static str {
    match setting {
        Setting::Shard => "--shard",
        Setting::Shards => "--shards",
        Setting::Resume => "--resume",
        Setting::OutDir => "--out-dir",
        Setting::Job => "--job",
        Setting::Array => "--array",
        Setting::DryRun => "--dry-run",
        Setting::Submit => "--submit",
        Setting::GridStep => "--grid-step",
        Setting::Spacing => "--spacing",
        Setting::KSigma => "--k-sigma",
        Setting::Chart => "--chart",
    }
}

/// [`words`] for a setting given as `&dyn Any`; `None` when it is not a batch setting.
pub fn flag(setting: &dyn Any) -> Option<&'static str> {
    setting.downcast_ref::<Setting>().map(|s| words(*s))
}
