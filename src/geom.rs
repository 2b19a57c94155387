//! Machine axes and the plane a map lies in: which coordinate is the error direction and which two span the map.

use serde::{Deserialize, Serialize};

/// A linear machine axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Axis {
    X,
    Y,
    Z,
}

impl Axis {
    /// Index of the axis in an `[x, y, z]` triple.
    pub fn index(self) -> usize {
        match self {
            Axis::X => 0,
            Axis::Y => 1,
            Axis::Z => 2,
        }
    }

    /// Lower-case name as used in column names (`x`, `y`, `z`).
    pub fn name(self) -> &'static str {
        match self {
            Axis::X => "x",
            Axis::Y => "y",
            Axis::Z => "z",
        }
    }

    /// The two axes that span the map plane when `self` is the normal (error) direction,
    /// in right-handed order: z → (x, y), x → (y, z), y → (z, x).
    pub fn plane_axes(self) -> (Axis, Axis) {
        match self {
            Axis::Z => (Axis::X, Axis::Y),
            Axis::X => (Axis::Y, Axis::Z),
            Axis::Y => (Axis::Z, Axis::X),
        }
    }

    /// Parse `x`, `y` or `z` (either case).
    pub fn parse(text: &str) -> Option<Axis> {
        match text.trim().to_ascii_lowercase().as_str() {
            "x" => Some(Axis::X),
            "y" => Some(Axis::Y),
            "z" => Some(Axis::Z),
            _ => None,
        }
    }
}

/// An axis-aligned rectangle in the map plane, in mm.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Domain {
    pub u_min_mm: f64,
    pub v_min_mm: f64,
    pub u_max_mm: f64,
    pub v_max_mm: f64,
}

impl Domain {
    pub fn contains(&self, u_mm: f64, v_mm: f64) -> bool {
        u_mm >= self.u_min_mm
            && u_mm <= self.u_max_mm
            && v_mm >= self.v_min_mm
            && v_mm <= self.v_max_mm
    }
    pub fn width_mm(&self) -> f64 {
        self.u_max_mm - self.u_min_mm
    }
    pub fn height_mm(&self) -> f64 {
        self.v_max_mm - self.v_min_mm
    }
}

/// A machining-error field over a map plane: what toolpath compensation asks of a fitted map.
pub trait ErrorField: Sync {
    /// The error direction; the field is a function of the two plane axes ([`Axis::plane_axes`]).
    fn normal(&self) -> Axis;
    /// Error E in mm along the normal at plane point (u, v) in mm; `None` outside the map's domain.
    fn error_mm(&self, u_mm: f64, v_mm: f64) -> Option<f64>;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plane_axes_are_right_handed_and_exclude_the_normal() {
        for n in [Axis::X, Axis::Y, Axis::Z] {
            let (u, v) = n.plane_axes();
            assert!(u != n && v != n && u != v);
            // u × v = n for a right-handed frame: index order is cyclic.
            assert_eq!((u.index() + 1) % 3, v.index());
            assert_eq!((v.index() + 1) % 3, n.index());
        }
    }
}
