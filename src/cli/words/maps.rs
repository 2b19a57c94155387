//! The flags of `errmap_maps`'s settings.

use errmap_maps::Setting;
use std::any::Any;

/// The flag of a map setting.
pub fn words(setting: Setting) -> &'static str {
    match setting {
        Setting::Backend => "--backend",
        Setting::Columns => "--columns",
        Setting::HeaderLine => "--header-line",
        Setting::NominalPlane => "--nominal-plane",
        Setting::Normal => "--normal",
        Setting::MaxDeviation => "--max-deviation-mm",
        Setting::MaxUncertainty => "--max-uncertainty-um",
        Setting::MaxMemory => "--max-memory-mb",
        Setting::BenchParts => "--parts",
        Setting::BenchSamples => "--samples",
    }
}

/// [`words`] for a setting given as `&dyn Any`; `None` when it is not a map setting.
pub fn flag(setting: &dyn Any) -> Option<&'static str> {
    setting.downcast_ref::<Setting>().map(|s| words(*s))
}
