//! The flags of `errmap_core`'s settings.

use errmap_core::core_setting::Setting;
use std::any::Any;

/// The flag of a the ground floor's (output safety) setting.
pub fn words(setting: Setting) -> &'static str {
    match setting {
        Setting::MaxOutputMb => "--max-output-mb",
    }
}

/// [`words`] for a setting given as `&dyn Any`; `None` when it is not a the ground floor's (output safety) setting.
pub fn flag(setting: &dyn Any) -> Option<&'static str> {
    setting.downcast_ref::<Setting>().map(|s| words(*s))
}
