//! The toolpath settings that hints name; the front end words them (the binary as its flags).

/// A setting of toolpath compensation that a hint can tell the user to give.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Setting {
    /// The program's units when it sets none (`mm` or `inch`).
    Units,
    /// The program's controller dialect (`linuxcnc`, `fanuc`, `sinumerik`, `heidenhain`).
    Dialect,
    /// Run subprograms, loops and parameters and compensate the flattened program.
    Expand,
    /// The motion mode the controller powers on in (`g0` or `g1`).
    PowerOnMotion,
    /// Apply the map in each work offset's coordinates.
    SamePartPerOffset,
    /// Longest segment emitted in the zone, mm.
    MaxSegment,
    /// Largest distance between an arc and its chords, mm.
    ChordTol,
    /// Half-width of the default zone around the map's probed surface, mm.
    SurfaceTol,
    /// The band along the map's normal axis where moves are compensated (`MIN,MAX` or `all`).
    Zone,
    /// Move a canned cycle's holes whose bottom lies in the zone by −E.
    CompensateHoles,
    /// How a Fanuc reads decimal-less numbers (`calculator`, `is-a`, `is-b`, `is-c`).
    FanucNumbers,
    /// Also compensate where the map extrapolates beyond the measured domain.
    Extrapolate,
    /// The largest u(E) at which the map is applied, µm.
    MaxUncertaintyUm,
}

impl errmap_core::Setting for Setting {
    fn key(self) -> &'static str {
        match self {
            Setting::Units => "units",
            Setting::Dialect => "dialect",
            Setting::Expand => "expand",
            Setting::PowerOnMotion => "power_on_motion",
            Setting::SamePartPerOffset => "same_part_per_offset",
            Setting::MaxSegment => "max_segment_mm",
            Setting::ChordTol => "chord_tol_mm",
            Setting::SurfaceTol => "surface_tol_mm",
            Setting::Zone => "zone",
            Setting::CompensateHoles => "compensate_holes",
            Setting::FanucNumbers => "fanuc_numbers",
            Setting::Extrapolate => "extrapolate",
            Setting::MaxUncertaintyUm => "max_uncertainty_um",
        }
    }
}
