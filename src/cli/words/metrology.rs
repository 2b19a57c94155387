//! The flags of `errmap_metrology`'s settings (linear, thermal, rotary, circular, controller tables).

use errmap_metrology::Setting;
use std::any::Any;

/// The flag of a analysis setting.
pub fn words(setting: Setting) -> &'static str {
    match setting {
        Setting::Feed => "--feed",
        Setting::Radius => "--radius",
        Setting::Centre => "--centre",
        Setting::Axis => "--axis",
        Setting::FanucMagnification => "--fanuc-magnification",
        Setting::FanucUnitUm => "--fanuc-unit-um",
        Setting::LinuxcncType => "--linuxcnc-type",
        Setting::SinumerikMaxPoints => "--sinumerik-max-points",
        Setting::Spacing => "--spacing",
        Setting::Columns => "--columns",
        Setting::CorrectAir => "--correct-air",
        Setting::FitPitch => "--fit-pitch",
        Setting::Formula => "--air-formula",
        Setting::MaterialExpansion => "--material-expansion",
        Setting::FitAxis => "--fit-axis",
        Setting::ReferenceAngle => "--reference-angle",
        Setting::Sign => "--sign",
        Setting::SphereDiameter => "--sphere-diameter",
        Setting::StartDeg => "--start-deg",
        Setting::StepDeg => "--step-deg",
        Setting::StylusRadius => "--stylus-radius",
        Setting::Campaigns => "--campaigns",
        Setting::Db => "--db",
        Setting::EveryS => "--every-s",
        Setting::FromStore => "--from-store",
        Setting::LaserNoiseUm => "--laser-noise-um",
        Setting::MinSpanC => "--min-span-c",
        Setting::Order => "--order",
        Setting::Reference => "--reference",
        Setting::ReferenceMm => "--reference-mm",
        Setting::Repeats => "--repeats",
        Setting::Replace => "--replace",
        Setting::Sensors => "--sensors",
    }
}

/// [`words`] for a setting given as `&dyn Any`; `None` when it is not a analysis setting.
pub fn flag(setting: &dyn Any) -> Option<&'static str> {
    setting.downcast_ref::<Setting>().map(|s| words(*s))
}
