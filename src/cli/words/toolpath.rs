//! The flags of `errmap_toolpath`'s settings.

use errmap::toolpath::Setting;
use std::any::Any;

/// Every toolpath setting, for the test that each is a flag.
#[cfg(test)]
pub const ALL: &[Setting] = &[Setting::Units];

/// The flag of a toolpath setting.
pub fn words(setting: Setting) -> &'static str {
    match setting {
        Setting::Units => "--units",
    }
}

/// [`words`] for a setting given as `&dyn Any`; `None` when it is not a toolpath setting.
pub fn flag(setting: &dyn Any) -> Option<&'static str> {
    setting.downcast_ref::<Setting>().map(|s| words(*s))
}
