//! The settings of the analyses that hints name; the front end words them (the binary as its
//! flags).

/// A setting of an analysis (linear, thermal, rotary, circular, controller tables) that a hint
/// can tell the user to give.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Setting {
    /// Circular test: the programmed feed in mm/min.
    Feed,
    /// Circular test: the programmed radius in mm.
    Radius,
    /// Circular test: the nominal centre of the circle on the plane, in mm.
    Centre,
    /// Controller table: the controlled-axis number (Fanuc).
    Axis,
    /// Controller table: the Fanuc pitch-error magnification (parameter 3623).
    FanucMagnification,
    /// Controller table: the Fanuc detection unit in µm (IS-B 1, IS-C 0.1).
    FanucUnitUm,
    /// Controller table: the LinuxCNC compensation file type (0 positions, 1 trims).
    LinuxcncType,
    /// Controller table: the Sinumerik table's point count (MD38000, MD18342).
    SinumerikMaxPoints,
    /// Linear and controller tables: the spacing of the table's points.
    Spacing,
    /// Linear: the column mapping of an instrument export.
    Columns,
    /// Linear: rescale the readings by the refractive index of each row's air.
    CorrectAir,
    /// Linear: fit the ball-screw pitch error with this lead in mm.
    FitPitch,
    /// Linear: the refractive-index formula of air (Edlén or Ciddor).
    Formula,
    /// Linear: refer the readings to 20 °C by the material's expansion.
    MaterialExpansion,
    /// Rotary: fit the axis of rotation instead of taking the nominal one.
    FitAxis,
    /// Rotary: the angle whose error is zero by definition.
    ReferenceAngle,
    /// Rotary: the sign convention of the error (`errmap` or `calibrator`).
    Sign,
    /// Rotary: the calibration sphere's diameter in mm.
    SphereDiameter,
    /// Rotary table: the first angle of the table in degrees.
    StartDeg,
    /// Rotary table: the step between the table's angles in degrees.
    StepDeg,
    /// Rotary: the probe stylus radius in mm.
    StylusRadius,
    /// Thermal sample: the number of campaigns.
    Campaigns,
    /// Thermal: the campaign store (an SQLite file).
    Db,
    /// Thermal sample: the time between laser readings in s.
    EveryS,
    /// Thermal fit: the campaigns come from the store.
    FromStore,
    /// Thermal sample: the laser's noise, one sigma in µm.
    LaserNoiseUm,
    /// Thermal sensor calibration: the smallest temperature span to fit, in °C.
    MinSpanC,
    /// Thermal fit: the polynomial order of the error along the axis.
    Order,
    /// Thermal fit: the temperature reference of the rises.
    Reference,
    /// Thermal fit: the axis position where the error is referred, in mm.
    ReferenceMm,
    /// Thermal sample: the repeats of each campaign.
    Repeats,
    /// Thermal ingest: replace a campaign of the same name in the store.
    Replace,
    /// Thermal fit: the sensors the model uses.
    Sensors,
}

impl errmap_core::Setting for Setting {
    fn key(self) -> &'static str {
        match self {
            Setting::Feed => "feed",
            Setting::Radius => "radius",
            Setting::Centre => "centre",
            Setting::Axis => "axis",
            Setting::FanucMagnification => "fanuc_magnification",
            Setting::FanucUnitUm => "fanuc_unit_um",
            Setting::LinuxcncType => "linuxcnc_type",
            Setting::SinumerikMaxPoints => "sinumerik_max_points",
            Setting::Spacing => "spacing",
            Setting::Columns => "columns",
            Setting::CorrectAir => "correct_air",
            Setting::FitPitch => "fit_pitch",
            Setting::Formula => "air_formula",
            Setting::MaterialExpansion => "material_expansion",
            Setting::FitAxis => "fit_axis",
            Setting::ReferenceAngle => "reference_angle",
            Setting::Sign => "sign",
            Setting::SphereDiameter => "sphere_diameter",
            Setting::StartDeg => "start_deg",
            Setting::StepDeg => "step_deg",
            Setting::StylusRadius => "stylus_radius",
            Setting::Campaigns => "campaigns",
            Setting::Db => "db",
            Setting::EveryS => "every_s",
            Setting::FromStore => "from_store",
            Setting::LaserNoiseUm => "laser_noise_um",
            Setting::MinSpanC => "min_span_c",
            Setting::Order => "order",
            Setting::Reference => "reference",
            Setting::ReferenceMm => "reference_mm",
            Setting::Repeats => "repeats",
            Setting::Replace => "replace",
            Setting::Sensors => "sensors",
        }
    }
}
