//! The flags of `errmap_synth`'s settings.

use errmap_synth::Setting;
use std::any::Any;

/// The flag of a synthetic-data setting.
pub fn words(setting: Setting) -> &'static str {
    match setting {
        Setting::NoiseUm => "--noise-um",
        Setting::Radius => "--radius",
        Setting::Feed => "--feed",
        Setting::StepDeg => "--step-deg",
        Setting::Repeats => "--repeats",
        Setting::Points => "--points",
        Setting::Size => "--size",
        Setting::Parts => "--parts",
        Setting::Grid => "--grid",
        Setting::Irregular => "--irregular",
    }
}

/// [`words`] for a setting given as `&dyn Any`; `None` when it is not a synthetic-data setting.
pub fn flag(setting: &dyn Any) -> Option<&'static str> {
    setting.downcast_ref::<Setting>().map(|s| words(*s))
}
