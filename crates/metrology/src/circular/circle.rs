//! Least-squares circle through points of a plane: the geometric fit (centre and radius minimising Σ(|p − c| − ρ)²) by Gauss–Newton.

use nalgebra::DMatrix;

/// A fitted circle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CircleFit {
    /// Centre of the circle (first, second axis) in the points' coordinates, mm.
    pub centre_mm: [f64; 2],
    /// Fitted radius ρ, mm.
    pub radius_mm: f64,
}

/// Least-squares circle through `points`, started from the circle of radius
/// `start_radius_mm` about the origin. `None` for fewer than three points, a point on the
/// centre or a singular system (all points on a line).
pub fn fit_circle(points: &[[f64; 2]], start_radius_mm: f64) -> Option<CircleFit> {
    if points.len() < 3 {
        return None;
    }
    let (mut c, mut rho) = ([0.0_f64; 2], start_radius_mm);
    for _ in 0..50 {
        // Residual e = dist − ρ; its gradient in (cx, cy, ρ) is (−u_x, −u_y, −1).
        let mut jacobian = DMatrix::<f64>::zeros(points.len(), 3);
        let mut minus_e = Vec::with_capacity(points.len());
        for (i, p) in points.iter().enumerate() {
            let (dx, dy) = (p[0] - c[0], p[1] - c[1]);
            let dist = dx.hypot(dy);
            if dist == 0.0 {
                return None;
            }
            jacobian[(i, 0)] = -dx / dist;
            jacobian[(i, 1)] = -dy / dist;
            jacobian[(i, 2)] = -1.0;
            minus_e.push(rho - dist);
        }
        let step = errmap_core::numeric::lsq::solve(&jacobian, &minus_e, 1e-12)
            .ok()?
            .beta;
        if !step.iter().all(|v| v.is_finite()) {
            return None;
        }
        c[0] += step[0];
        c[1] += step[1];
        rho += step[2];
        if step.iter().map(|v| v * v).sum::<f64>().sqrt() < 1e-13 * (1.0 + rho.abs()) {
            break;
        }
    }
    Some(CircleFit {
        centre_mm: c,
        radius_mm: rho,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_a_circle_through_exact_points() {
        let pts: Vec<[f64; 2]> = (0..7)
            .map(|i| {
                let a = i as f64 * 0.9;
                [3.0 + 50.0 * a.cos(), -2.0 + 50.0 * a.sin()]
            })
            .collect();
        let f = fit_circle(&pts, 40.0).unwrap();
        assert!((f.centre_mm[0] - 3.0).abs() < 1e-10);
        assert!((f.centre_mm[1] + 2.0).abs() < 1e-10);
        assert!((f.radius_mm - 50.0).abs() < 1e-10);
    }
}
