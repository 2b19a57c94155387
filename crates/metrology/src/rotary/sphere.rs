//! Sphere fit from touch points: algebraic least squares for a start, Gauss–Newton on the geometric distances to finish.

use super::angle::normal_frame;
use nalgebra::{DMatrix, DVector, Matrix3, SymmetricEigen, Vector3};
use serde::Serialize;
use std::fmt;

/// A fitted sphere.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SphereFit {
    /// Centre of the sphere in the touch points' coordinates, mm.
    pub centre_mm: [f64; 3],
    /// Fitted radius, or the given one when the radius was fixed.
    pub radius_mm: f64,
    /// Root mean square of the geometric residuals |p − c| − r.
    pub form_rms_mm: f64,
    /// Form error: largest minus smallest geometric residual.
    pub form_pv_mm: f64,
    /// Points used.
    pub n: usize,
    /// Gauss–Newton iterations taken.
    pub iterations: u32,
}

/// Why a sphere could not be fitted.
#[derive(Debug, Clone, PartialEq)]
pub enum SphereFitError {
    /// Fewer than 4 points (3 with a known radius still leave two mirror solutions).
    TooFewPoints(usize),
    /// The points lie on a plane (or a line): no unique sphere passes through them.
    Degenerate,
    /// Gauss–Newton did not settle (points far from any sphere).
    NoConvergence,
}

impl fmt::Display for SphereFitError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SphereFitError::TooFewPoints(n) => {
                write!(f, "{n} touch points, a sphere needs at least 4")
            }
            SphereFitError::Degenerate => f.write_str(
                "the touch points lie in one plane, so no unique sphere passes through them",
            ),
            SphereFitError::NoConvergence => {
                f.write_str("the sphere fit did not converge (the points are far from any sphere)")
            }
        }
    }
}

/// Smallest/largest principal spread (standard deviation) of the points below which they
/// count as coplanar. A hemisphere has ≈ 0.4, a 10° cap ≈ 0.05; a ring of points with probe
/// noise has noise/radius ≈ 10⁻⁵, whose "sphere" would be noise — so 10⁻³ is the line.
const COPLANAR_RATIO: f64 = 1e-3;
const MAX_ITERATIONS: u32 = 100;

/// Fit a sphere to `points_mm`. With `known_radius_mm` only the centre is fitted.
///
/// Start: the algebraic fit x² + y² + z² + D x + E y + F z + G = 0, linear in D…G
/// (Kåsa-type; points centred and scaled first for conditioning). Finish: Gauss–Newton on
/// the geometric residuals rᵢ = |pᵢ − c| − R, whose Jacobian rows are (−(pᵢ − c)/|pᵢ − c|, −1)
/// (ISO 10360-6 / Forbes, NPL DITC 140/89, "Least-squares best-fit geometric elements").
pub fn fit_sphere(
    points_mm: &[[f64; 3]],
    known_radius_mm: Option<f64>,
) -> Result<SphereFit, SphereFitError> {
    let n = points_mm.len();
    if n < 4 {
        return Err(SphereFitError::TooFewPoints(n));
    }
    let pts: Vec<Vector3<f64>> = points_mm.iter().map(|p| Vector3::from(*p)).collect();
    let (mean, scale) = spread(&pts)?;
    let (centre, radius) = algebraic_start(&pts, mean, scale)?;
    let radius = known_radius_mm.unwrap_or(radius);
    let (centre, radius, iterations) = gauss_newton(&pts, centre, radius, known_radius_mm)?;
    let residuals: Vec<f64> = pts.iter().map(|p| (p - centre).norm() - radius).collect();
    let form_rms_mm = (residuals.iter().map(|r| r * r).sum::<f64>() / n as f64).sqrt();
    let max = residuals.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    let min = residuals.iter().cloned().fold(f64::INFINITY, f64::min);
    Ok(SphereFit {
        centre_mm: [centre.x, centre.y, centre.z],
        radius_mm: radius,
        form_rms_mm,
        form_pv_mm: max - min,
        n,
        iterations,
    })
}

/// The mean of the points and their largest principal spread (the scale of the algebraic
/// fit); points with (nearly) no spread in one direction are coplanar and refused.
fn spread(pts: &[Vector3<f64>]) -> Result<(Vector3<f64>, f64), SphereFitError> {
    let n = pts.len();
    let mean = pts.iter().sum::<Vector3<f64>>() / n as f64;
    // Principal spreads: a plane has one (near) zero.
    let mut scatter = Matrix3::zeros();
    for p in pts {
        let d = p - mean;
        scatter += d * d.transpose();
    }
    let eig = SymmetricEigen::new(scatter / n as f64);
    let largest = eig.eigenvalues.max();
    let smallest = eig.eigenvalues.min();
    if largest.is_nan()
        || largest <= 0.0
        || smallest.max(0.0).sqrt() <= COPLANAR_RATIO * largest.sqrt()
    {
        return Err(SphereFitError::Degenerate);
    }
    Ok((mean, largest.sqrt()))
}

/// The algebraic (Kåsa-type) sphere in centred, scaled coordinates q = (p − mean) / scale:
/// centre and radius in mm.
fn algebraic_start(
    pts: &[Vector3<f64>],
    mean: Vector3<f64>,
    scale: f64,
) -> Result<(Vector3<f64>, f64), SphereFitError> {
    let n = pts.len();
    let mut a = DMatrix::zeros(n, 4);
    let mut b = DVector::zeros(n);
    for (i, p) in pts.iter().enumerate() {
        let q = (p - mean) / scale;
        a[(i, 0)] = q.x;
        a[(i, 1)] = q.y;
        a[(i, 2)] = q.z;
        a[(i, 3)] = 1.0;
        b[i] = -q.norm_squared();
    }
    let sol = errmap_core::numeric::lsq::solve(&a, b.as_slice(), 1e-12)
        .map_err(|_| SphereFitError::Degenerate)?
        .beta;
    let cq = Vector3::new(-sol[0] / 2.0, -sol[1] / 2.0, -sol[2] / 2.0);
    let r2 = cq.norm_squared() - sol[3];
    if r2.is_nan() || r2 <= 0.0 || !cq.iter().all(|v| v.is_finite()) {
        return Err(SphereFitError::Degenerate);
    }
    Ok((mean + cq * scale, r2.sqrt() * scale))
}

/// Gauss–Newton on the geometric distances from `centre`, `radius` (the radius held when
/// `known_radius_mm` is given): the converged centre, radius and iterations taken.
fn gauss_newton(
    pts: &[Vector3<f64>],
    mut centre: Vector3<f64>,
    mut radius: f64,
    known_radius_mm: Option<f64>,
) -> Result<(Vector3<f64>, f64, u32), SphereFitError> {
    let n = pts.len();
    let cols = if known_radius_mm.is_some() { 3 } else { 4 };
    let mut iterations = 0;
    let mut converged = false;
    while iterations < MAX_ITERATIONS {
        iterations += 1;
        let mut j = DMatrix::zeros(n, cols);
        let mut r = DVector::zeros(n);
        for (i, p) in pts.iter().enumerate() {
            let d = p - centre;
            let dist = d.norm();
            let u = if dist > 0.0 {
                d / dist
            } else {
                Vector3::zeros()
            };
            j[(i, 0)] = -u.x;
            j[(i, 1)] = -u.y;
            j[(i, 2)] = -u.z;
            if cols == 4 {
                j[(i, 3)] = -1.0;
            }
            r[i] = dist - radius;
        }
        let minus_r: Vec<f64> = r.iter().map(|v| -v).collect();
        let step = errmap_core::numeric::lsq::solve(&j, &minus_r, 1e-12)
            .map_err(|_| SphereFitError::Degenerate)?
            .beta;
        centre += Vector3::new(step[0], step[1], step[2]);
        if cols == 4 {
            radius += step[3];
        }
        if !centre.iter().all(|v| v.is_finite()) || !radius.is_finite() {
            return Err(SphereFitError::NoConvergence);
        }
        if step.iter().map(|v| v * v).sum::<f64>().sqrt() <= 1e-13 * (1.0 + radius.abs()) {
            converged = true;
            break;
        }
    }
    if !converged || radius.is_nan() || radius <= 0.0 {
        return Err(SphereFitError::NoConvergence);
    }
    Ok((centre, radius, iterations))
}

/// `n` unit directions spread over the cap within `half_angle_deg` of `pole`
/// (a golden-angle spiral: evenly spread, deterministic). Used by tests and the generator.
pub fn cap_directions(n: usize, half_angle_deg: f64, pole: [f64; 3]) -> Vec<[f64; 3]> {
    let pole = Vector3::from(pole).normalize();
    let (e1, e2) = normal_frame(&pole);
    let cos_min = half_angle_deg.to_radians().cos();
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            // Heights uniform in cos θ ∈ [cos_min, 1] spread points evenly by area.
            let t = (i as f64 + 0.5) / n as f64;
            let cos_t = 1.0 - t * (1.0 - cos_min);
            let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
            let phi = golden * i as f64;
            let d = pole * cos_t + e1 * (sin_t * phi.cos()) + e2 * (sin_t * phi.sin());
            [d.x, d.y, d.z]
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    fn on_sphere(centre: [f64; 3], r: f64, dirs: &[[f64; 3]]) -> Vec<[f64; 3]> {
        dirs.iter()
            .map(|d| {
                [
                    centre[0] + r * d[0],
                    centre[1] + r * d[1],
                    centre[2] + r * d[2],
                ]
            })
            .collect()
    }

    #[test]
    fn exact_sphere_is_reproduced_to_1e_9_mm() {
        let centre = [312.25, -87.5, 141.0625];
        let r = 12.7;
        let pts = on_sphere(centre, r, &cap_directions(30, 180.0, [0.3, 0.2, 1.0]));
        let fit = fit_sphere(&pts, None).unwrap();
        for (got, want) in fit.centre_mm.iter().zip(centre) {
            assert!((got - want).abs() < 1e-9, "{fit:?}");
        }
        assert!((fit.radius_mm - r).abs() < 1e-9, "{fit:?}");
        assert!(fit.form_rms_mm < 1e-9 && fit.form_pv_mm < 1e-9);
    }

    #[test]
    fn hemisphere_cap_and_narrow_cap_are_fitted() {
        let centre = [-20.0, 15.0, 400.0];
        let r = 11.0;
        // Upper hemisphere only: a sphere standing on its stem.
        let pts = on_sphere(centre, r, &cap_directions(17, 90.0, [0.0, 0.0, 1.0]));
        assert!(pts.iter().all(|p| p[2] >= centre[2] - 1e-9));
        let fit = fit_sphere(&pts, None).unwrap();
        for (got, want) in fit.centre_mm.iter().zip(centre) {
            assert!((got - want).abs() < 1e-9, "{fit:?}");
        }
        assert!((fit.radius_mm - r).abs() < 1e-9);
        // A 30° cap, fixed radius: the centre is still found exactly.
        let pts = on_sphere(centre, r, &cap_directions(9, 30.0, [1.0, 0.0, 0.0]));
        let fit = fit_sphere(&pts, Some(r)).unwrap();
        for (got, want) in fit.centre_mm.iter().zip(centre) {
            assert!((got - want).abs() < 1e-9, "{fit:?}");
        }
        assert_eq!(fit.radius_mm, r);
    }

    #[test]
    fn rejects_too_few_and_coplanar_points() {
        let pts = on_sphere([0.0; 3], 5.0, &cap_directions(3, 90.0, [0.0, 0.0, 1.0]));
        assert_eq!(fit_sphere(&pts, None), Err(SphereFitError::TooFewPoints(3)));
        // Eight points on the equator circle: coplanar.
        let ring: Vec<[f64; 3]> = (0..8)
            .map(|i| {
                let t = i as f64 * std::f64::consts::FRAC_PI_4;
                [5.0 * t.cos(), 5.0 * t.sin(), 2.0]
            })
            .collect();
        assert_eq!(fit_sphere(&ring, None), Err(SphereFitError::Degenerate));
        assert_eq!(
            fit_sphere(&ring, Some(5.0)),
            Err(SphereFitError::Degenerate)
        );
        // Tilted plane too.
        let tilted: Vec<[f64; 3]> = ring
            .iter()
            .map(|p| [p[0], p[1], 0.5 * p[0] - 0.25 * p[1]])
            .collect();
        assert_eq!(fit_sphere(&tilted, None), Err(SphereFitError::Degenerate));
        // A ring with 0.5 µm of noise off its plane is still a plane, not a sphere.
        let noisy: Vec<[f64; 3]> = ring
            .iter()
            .enumerate()
            .map(|(i, p)| [p[0], p[1], p[2] + if i % 2 == 0 { 5e-4 } else { -5e-4 }])
            .collect();
        assert_eq!(fit_sphere(&noisy, None), Err(SphereFitError::Degenerate));
    }

    #[test]
    fn centre_noise_follows_sigma_sqrt_3_over_n() {
        // Radial noise σ on N points spread evenly over a whole sphere: the least-squares
        // centre has per-coordinate standard deviation σ·√(3/N), since Σ uₓ² = N/3
        // (covariance σ²(JᵀJ)⁻¹ with the radius column orthogonal to the centre columns).
        let sigma = 0.5e-3;
        let n = 40;
        let dirs = cap_directions(n, 180.0, [0.0, 0.0, 1.0]);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let noise = Normal::new(0.0, sigma).unwrap();
        let trials = 400;
        let mut sum_sq = 0.0;
        for _ in 0..trials {
            let pts: Vec<[f64; 3]> = dirs
                .iter()
                .map(|d| {
                    let r = 10.0 + noise.sample(&mut rng);
                    [r * d[0], r * d[1], r * d[2]]
                })
                .collect();
            let fit = fit_sphere(&pts, None).unwrap();
            sum_sq += fit.centre_mm.iter().map(|c| c * c).sum::<f64>();
        }
        let measured = (sum_sq / (3.0 * trials as f64)).sqrt();
        let expected = sigma * (3.0 / n as f64).sqrt();
        // 1200 samples of a normal: the RMS is within ±10 % with overwhelming probability.
        assert!(
            (measured / expected - 1.0).abs() < 0.1,
            "measured {measured}, expected {expected}"
        );
    }
}
