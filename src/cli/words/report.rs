//! The flags of `errmap_report`'s settings.

use errmap_report::Setting;
use std::any::Any;

/// The flag of a report setting.
pub fn words(setting: Setting) -> &'static str {
    match setting {
        Setting::Pdf => "--pdf",
    }
}

/// [`words`] for a setting given as `&dyn Any`; `None` when it is not a report setting.
pub fn flag(setting: &dyn Any) -> Option<&'static str> {
    setting.downcast_ref::<Setting>().map(|s| words(*s))
}
