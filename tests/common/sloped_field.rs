//! The sloped error field of the toolpath property tests: E = 0.05 + 0.001·x mm along Z, measured for x ≤ 3 mm, with the zone and chord tolerance the random programs are compensated under.

use errmap::geom::{Axis, ErrorField};

/// Measured (probed) for x ≤ this, mm.
pub const X_MEASURED_MM: f64 = 3.0;
/// The zone along Z, mm (the programs start in mm).
pub const ZONE_MM: (f64, f64) = (-2.0, -0.25);
pub const CHORD_TOL_MM: f64 = 0.005;

/// E = 0.05 + 0.001·x mm along Z, measured for x ≤ 3 mm.
pub struct Sloped;

/// E of [`Sloped`] at `x_mm`, mm.
pub fn sloped_e_mm(x_mm: f64) -> f64 {
    0.05 + 0.001 * x_mm
}

impl ErrorField for Sloped {
    fn normal(&self) -> Axis {
        Axis::Z
    }
    fn error_mm(&self, u: f64, v: f64) -> Option<f64> {
        (u.abs() <= 1000.0 && v.abs() <= 1000.0).then(|| sloped_e_mm(u))
    }
    fn measured(&self, u: f64, _v: f64, margin: f64) -> Option<bool> {
        Some(u <= X_MEASURED_MM + margin)
    }
}
