//! The synthetic-data settings that hints name; the front end words them (the binary as its
//! flags).

/// A setting of a synthetic data set that a hint can tell the user to give.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Setting {
    /// The probe noise, 1σ, µm (circular, rotary and web-plate sets).
    NoiseUm,
    /// The circular test's radius, mm.
    Radius,
    /// The circular test's feed, mm/min.
    Feed,
    /// The rotary test's step between indexed positions, degrees.
    StepDeg,
    /// The rotary test's number of repeats of the turn.
    Repeats,
    /// The rotary test's probe points per sphere.
    Points,
    /// The web plate's size, `XxY` mm.
    Size,
    /// The number of web plates (parts).
    Parts,
    /// The web plate's probe grid, `NXxNY` points.
    Grid,
    /// The web plate's number of irregularly placed probe points.
    Irregular,
}

impl errmap_core::Setting for Setting {
    fn key(self) -> &'static str {
        match self {
            Setting::NoiseUm => "noise_um",
            Setting::Radius => "radius_mm",
            Setting::Feed => "feed_mm_per_min",
            Setting::StepDeg => "step_deg",
            Setting::Repeats => "repeats",
            Setting::Points => "points",
            Setting::Size => "size_mm",
            Setting::Parts => "parts",
            Setting::Grid => "grid",
            Setting::Irregular => "irregular",
        }
    }
}
