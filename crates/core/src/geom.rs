//! Machine axes and the plane a map lies in: which coordinate is the error direction and which two span the map.

use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};

/// A linear machine axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Axis {
    /// The machine's X axis.
    X,
    /// The machine's Y axis.
    Y,
    /// The machine's Z axis.
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

    /// [`Axis::parse`] for a command-line value: the message says what to write.
    pub fn parse_arg(text: &str) -> std::result::Result<Axis, String> {
        Axis::parse(text).ok_or_else(|| format!("'{text}' is not an axis: use x, y or z"))
    }
}

/// An axis-aligned rectangle in the map plane, in mm.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Domain {
    /// Lower bound along the first plane axis ([`Axis::plane_axes`]`.0`), mm.
    pub u_min_mm: f64,
    /// Lower bound along the second plane axis ([`Axis::plane_axes`]`.1`), mm.
    pub v_min_mm: f64,
    /// Upper bound along the first plane axis, mm.
    pub u_max_mm: f64,
    /// Upper bound along the second plane axis, mm.
    pub v_max_mm: f64,
}

impl Domain {
    /// Whether plane point (u, v), mm, lies inside the rectangle or on its edge.
    pub fn contains(&self, u_mm: f64, v_mm: f64) -> bool {
        u_mm >= self.u_min_mm
            && u_mm <= self.u_max_mm
            && v_mm >= self.v_min_mm
            && v_mm <= self.v_max_mm
    }
    /// Extent along the first plane axis (u), mm.
    pub fn width_mm(&self) -> f64 {
        self.u_max_mm - self.u_min_mm
    }
    /// Extent along the second plane axis (v), mm.
    pub fn height_mm(&self) -> f64 {
        self.v_max_mm - self.v_min_mm
    }

    /// A command-line value `UMIN,VMIN,UMAX,VMAX` (mm, finite, each minimum below its maximum),
    /// for clap: [`parse_domain`]'s message as a string.
    pub fn parse_arg(text: &str) -> std::result::Result<Domain, String> {
        parse_domain(text).map_err(|e| e.to_string())
    }
}

/// Parse a domain written `UMIN,VMIN,UMAX,VMAX` in mm (the two plane axes of the normal, e.g.
/// `XMIN,YMIN,XMAX,YMAX` for normal z), as given on the command line.
pub fn parse_domain(text: &str) -> Result<Domain> {
    let hint =
        "write the domain as UMIN,VMIN,UMAX,VMAX in mm along the two plane axes, e.g. 0,0,600,300";
    let values: Vec<f64> = text
        .split(',')
        .map(|s| s.trim().parse::<f64>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| Error::usage(format!("domain '{text}' is not four numbers"), hint))?;
    let [u_min_mm, v_min_mm, u_max_mm, v_max_mm] = values[..] else {
        return Err(Error::usage(
            format!("domain '{text}' has {} values, not 4", values.len()),
            hint,
        ));
    };
    if !values.iter().all(|v| v.is_finite()) || u_max_mm <= u_min_mm || v_max_mm <= v_min_mm {
        return Err(Error::usage(
            format!("domain '{text}' is not a rectangle: each minimum must be below its maximum"),
            hint,
        ));
    }
    Ok(Domain {
        u_min_mm,
        v_min_mm,
        u_max_mm,
        v_max_mm,
    })
}

/// A machining-error field over a map plane: what toolpath compensation asks of a fitted map.
pub trait ErrorField: Sync {
    /// The error direction; the field is a function of the two plane axes ([`Axis::plane_axes`]).
    fn normal(&self) -> Axis;
    /// Error E in mm along the normal at plane point (u, v) in mm; `None` outside the map's domain.
    fn error_mm(&self, u_mm: f64, v_mm: f64) -> Option<f64>;
    /// Whether (u, v) lies in the measured domain (where E rests on probes, not extrapolation)
    /// or within `margin_mm` of it; `None` when the map does not record it (a `model.json`
    /// from an older errmap).
    fn measured(&self, _u_mm: f64, _v_mm: f64, _margin_mm: f64) -> Option<bool> {
        Some(true)
    }
    /// Whether E at (u, v) is withheld (`error_mm` gives `None`) because the map's standard
    /// uncertainty there exceeds the user's bound (`--max-uncertainty-um`), so that a
    /// compensation can say why the point stayed nominal.
    fn withheld(&self, _u_mm: f64, _v_mm: f64) -> bool {
        false
    }
    /// The probed surface's nominal extent along the normal, mm, when the map records it.
    fn surface_mm(&self) -> Option<(f64, f64)> {
        None
    }
}

/// Convex hull of plane points, counter-clockwise, without collinear points (Andrew's monotone
/// chain). Fewer than three distinct points give those points.
pub fn convex_hull(points: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let mut p: Vec<[f64; 2]> = points
        .iter()
        .copied()
        .filter(|q| q[0].is_finite() && q[1].is_finite())
        .collect();
    p.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    p.dedup();
    if p.len() < 3 {
        return p;
    }
    let cross = |o: [f64; 2], a: [f64; 2], b: [f64; 2]| {
        (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    };
    let mut hull: Vec<[f64; 2]> = Vec::with_capacity(2 * p.len());
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &[f64; 2]>> = if pass == 0 {
            Box::new(p.iter())
        } else {
            Box::new(p.iter().rev())
        };
        for &q in iter {
            while hull.len() >= start + 2
                && cross(hull[hull.len() - 2], hull[hull.len() - 1], q) <= 0.0
            {
                hull.pop();
            }
            hull.push(q);
        }
        hull.pop();
    }
    hull
}

/// Distance from `q` to a convex polygon from [`convex_hull`] (0 inside), mm.
pub fn hull_distance_mm(hull: &[[f64; 2]], q: [f64; 2]) -> f64 {
    let seg = |a: [f64; 2], b: [f64; 2]| {
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let len2 = dx * dx + dy * dy;
        let t = if len2 > 0.0 {
            (((q[0] - a[0]) * dx + (q[1] - a[1]) * dy) / len2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        (q[0] - a[0] - t * dx).hypot(q[1] - a[1] - t * dy)
    };
    match hull.len() {
        0 => f64::INFINITY,
        1 => seg(hull[0], hull[0]),
        2 => seg(hull[0], hull[1]),
        n => {
            let inside = (0..n).all(|i| {
                let (a, b) = (hull[i], hull[(i + 1) % n]);
                (b[0] - a[0]) * (q[1] - a[1]) - (b[1] - a[1]) * (q[0] - a[0]) >= 0.0
            });
            if inside {
                0.0
            } else {
                (0..n)
                    .map(|i| seg(hull[i], hull[(i + 1) % n]))
                    .fold(f64::INFINITY, f64::min)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hull_of_a_square_with_inner_points_and_distances() {
        let pts = [
            [0.0, 0.0],
            [2.0, 0.0],
            [2.0, 2.0],
            [0.0, 2.0],
            [1.0, 1.0],
            [1.0, 0.0],
        ];
        let h = convex_hull(&pts);
        assert_eq!(h, vec![[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]]);
        assert_eq!(hull_distance_mm(&h, [1.0, 1.5]), 0.0);
        assert!((hull_distance_mm(&h, [3.0, 1.0]) - 1.0).abs() < 1e-12);
        // Beyond a corner: the distance to the corner, √2.
        assert!((hull_distance_mm(&h, [3.0, 3.0]) - 2f64.sqrt()).abs() < 1e-12);
        // A triangle's hypotenuse: (1.5, 1.5) is 0.5·√2 from x + y = 2.
        let t = convex_hull(&[[0.0, 0.0], [2.0, 0.0], [0.0, 2.0]]);
        assert!((hull_distance_mm(&t, [1.5, 1.5]) - 0.5 * 2f64.sqrt()).abs() < 1e-12);
    }

    #[test]
    fn command_line_axes_and_domains_parse_or_say_what_to_write() {
        assert_eq!(Axis::parse_arg("Y"), Ok(Axis::Y));
        assert_eq!(
            Axis::parse_arg("w"),
            Err("'w' is not an axis: use x, y or z".to_string())
        );
        let d = Domain::parse_arg("-10, 0,600,300.5").unwrap();
        assert_eq!(
            [d.u_min_mm, d.v_min_mm, d.u_max_mm, d.v_max_mm],
            [-10.0, 0.0, 600.0, 300.5]
        );
        let refusal = |text: &str| Domain::parse_arg(text).unwrap_err();
        assert!(refusal("0,a,1,1").contains("is not four numbers"));
        assert!(refusal("0,0,1").contains("has 3 values, not 4"));
        for bad in ["1,0,0,1", "0,0,1,0", "0,0,inf,1"] {
            let message = refusal(bad);
            assert!(message.contains("is not a rectangle"), "{bad}: {message}");
            assert!(message.contains("UMIN,VMIN,UMAX,VMAX"), "{bad}: {message}");
        }
    }

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
