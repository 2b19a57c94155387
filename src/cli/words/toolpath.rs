//! The flags of `errmap_toolpath`'s settings.

use errmap::toolpath::Setting;
use std::any::Any;

/// The flag of a toolpath setting.
pub fn words(setting: Setting) -> &'static str {
    match setting {
        Setting::Units => "--units",
        Setting::Dialect => "--dialect",
        Setting::Expand => "--expand",
        Setting::PowerOnMotion => "--power-on-motion",
        Setting::SamePartPerOffset => "--same-part-per-offset",
        Setting::MaxSegment => "--max-segment",
        Setting::ChordTol => "--chord-tol",
        Setting::SurfaceTol => "--surface-tol",
        Setting::Zone => "--zone",
        Setting::CompensateHoles => "--compensate-holes",
        Setting::FanucNumbers => "--fanuc-numbers",
        Setting::Extrapolate => "--extrapolate",
        Setting::MaxUncertaintyUm => "--max-uncertainty-um",
    }
}

/// [`words`] for a setting given as `&dyn Any`; `None` when it is not a toolpath setting.
pub fn flag(setting: &dyn Any) -> Option<&'static str> {
    setting.downcast_ref::<Setting>().map(|s| words(*s))
}
