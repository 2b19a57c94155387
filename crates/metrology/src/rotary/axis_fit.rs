//! Axis direction and location from the sphere-centre trajectories: a common plane normal and one circle per sphere.

use super::angle::normal_frame;
use nalgebra::{DMatrix, DVector, Matrix3, SymmetricEigen, Vector3};
use serde::Serialize;

/// Arcseconds per radian.
const ARCSEC_PER_RAD: f64 = 180.0 * 3600.0 / std::f64::consts::PI;

/// The circle one sphere centre traced about the axis.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CircleFit {
    /// Sphere number (1 or 2).
    pub sphere: u8,
    /// Centre of the circle, a point on the axis, mm (machine coordinates).
    pub centre_mm: [f64; 3],
    /// Radius of the circle, mm.
    pub radius_mm: f64,
    /// RMS distance of the centres from the fitted plane.
    pub plane_rms_mm: f64,
    /// RMS of the in-plane radial residuals.
    pub circle_rms_mm: f64,
    /// Number of sphere centres (positions) on the circle.
    pub n: usize,
}

/// A fitted rotary axis.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AxisFit {
    /// Unit direction of the axis, oriented like the nominal axis.
    pub direction: [f64; 3],
    /// Angle between the fitted and the nominal direction.
    pub tilt_arcsec: f64,
    /// Inclination of the axis toward each of the two other machine axes, e.g. for C:
    /// `x` = atan2(n_x, n_z), `y` = atan2(n_y, n_z). Keys are the axis letters.
    pub tilt_toward_arcsec: std::collections::BTreeMap<String, f64>,
    /// Mean of the circle centres: a point on the axis.
    pub centre_mm: [f64; 3],
    /// Where the axis crosses the machine plane through the origin normal to the nominal
    /// axis (for C: its X and Y at Z = 0) — the axis location a kinematic calibration uses.
    pub location_mm: [f64; 3],
    /// The circle of each sphere, sphere 1 first.
    pub circles: Vec<CircleFit>,
}

/// Why an axis fit failed.
#[derive(Debug, Clone, PartialEq)]
pub enum AxisFitError {
    /// Fewer than 3 distinct positions for a sphere.
    TooFewPositions { sphere: u8, n: usize },
    /// The centres of a sphere do not span a plane (all on a line or one point).
    Degenerate { sphere: u8 },
}

impl std::fmt::Display for AxisFitError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            AxisFitError::TooFewPositions { sphere, n } => write!(
                f,
                "sphere {sphere} has {n} distinct positions; an axis fit needs at least 3"
            ),
            AxisFitError::Degenerate { sphere } => write!(
                f,
                "the centres of sphere {sphere} do not trace a circle (they lie on a line)"
            ),
        }
    }
}

/// Fit the axis to the centre trajectories of sphere 1 and sphere 2 (`trajectories[k]`
/// holds the centres of sphere k+1 over the turn). `nominal` orients the result.
///
/// Direction: the common normal of the two circle planes — each trajectory is centred on its
/// own mean, the scatter matrices are summed, and the eigenvector of the smallest eigenvalue
/// is the least-squares normal (total least squares plane, the SVD of the stacked centred
/// points). Centres: each trajectory is projected onto that plane and a circle is fitted
/// algebraically (Kåsa: x² + y² + D x + E y + F = 0), which is unbiased enough for arcs
/// spanning most of a turn; the two circle centres lie on the axis.
pub fn fit_axis(
    trajectories: [&[[f64; 3]]; 2],
    nominal: [f64; 3],
) -> Result<AxisFit, AxisFitError> {
    let nominal = Vector3::from(nominal).normalize();
    let mut scatter = Matrix3::zeros();
    let mut means = Vec::new();
    for (k, traj) in trajectories.iter().enumerate() {
        let (s, mean) = trajectory_scatter(traj, k as u8 + 1)?;
        scatter += s;
        means.push(mean);
    }
    let n = common_normal(scatter, &nominal);
    let frame = normal_frame(&n);
    let mut circles = Vec::new();
    for (k, traj) in trajectories.iter().enumerate() {
        circles.push(fit_circle(traj, k as u8 + 1, means[k], &n, frame)?);
    }
    let centre = circles
        .iter()
        .map(|c| Vector3::from(c.centre_mm))
        .sum::<Vector3<f64>>()
        / circles.len() as f64;
    // Axis line centre + t n crossing the plane nominal · p = 0.
    let t = -nominal.dot(&centre) / n.dot(&nominal);
    let location = centre + n * t;
    let (tilt, toward) = tilts_arcsec(&n, &nominal);
    Ok(AxisFit {
        direction: [n.x, n.y, n.z],
        tilt_arcsec: tilt,
        tilt_toward_arcsec: toward,
        centre_mm: [centre.x, centre.y, centre.z],
        location_mm: [location.x, location.y, location.z],
        circles,
    })
}

/// The scatter matrix of one trajectory about its mean, and the mean; a trajectory of fewer
/// than 3 centres or on a line is refused.
fn trajectory_scatter(
    traj: &[[f64; 3]],
    sphere: u8,
) -> Result<(Matrix3<f64>, Vector3<f64>), AxisFitError> {
    if traj.len() < 3 {
        return Err(AxisFitError::TooFewPositions {
            sphere,
            n: traj.len(),
        });
    }
    let pts: Vec<Vector3<f64>> = traj.iter().map(|p| Vector3::from(*p)).collect();
    let mean = pts.iter().sum::<Vector3<f64>>() / pts.len() as f64;
    let mut s = Matrix3::zeros();
    for p in &pts {
        let d = p - mean;
        s += d * d.transpose();
    }
    // A line has only one non-zero principal spread.
    let eig = SymmetricEigen::new(s);
    let mut ev: Vec<f64> = eig.eigenvalues.iter().copied().collect();
    ev.sort_by(f64::total_cmp);
    if ev[1].is_nan() || ev[1] <= 1e-12 * ev[2] {
        return Err(AxisFitError::Degenerate { sphere });
    }
    Ok((s, mean))
}

/// The common plane normal: the eigenvector of the smallest eigenvalue of the summed scatter,
/// oriented like the nominal axis.
fn common_normal(scatter: Matrix3<f64>, nominal: &Vector3<f64>) -> Vector3<f64> {
    let eig = SymmetricEigen::new(scatter);
    let imin = eig.eigenvalues.imin();
    let mut n: Vector3<f64> = eig.eigenvectors.column(imin).into_owned().normalize();
    if n.dot(nominal) < 0.0 {
        n = -n;
    }
    n
}

/// The circle one trajectory traces: projected onto the plane normal to `n` through its mean
/// (in-plane axes `frame`) and fitted algebraically (Kåsa).
fn fit_circle(
    traj: &[[f64; 3]],
    sphere: u8,
    mean: Vector3<f64>,
    n: &Vector3<f64>,
    (e1, e2): (Vector3<f64>, Vector3<f64>),
) -> Result<CircleFit, AxisFitError> {
    let m = traj.len();
    let mut a = DMatrix::zeros(m, 3);
    let mut b = DVector::zeros(m);
    let mut plane_sq = 0.0;
    let uv: Vec<(f64, f64)> = traj
        .iter()
        .map(|p| {
            let d = Vector3::from(*p) - mean;
            plane_sq += n.dot(&d).powi(2);
            (e1.dot(&d), e2.dot(&d))
        })
        .collect();
    for (i, (u, v)) in uv.iter().enumerate() {
        a[(i, 0)] = *u;
        a[(i, 1)] = *v;
        a[(i, 2)] = 1.0;
        b[i] = -(u * u + v * v);
    }
    let sol = errmap_core::numeric::lsq::solve(&a, b.as_slice(), 1e-12)
        .map_err(|_| AxisFitError::Degenerate { sphere })?
        .beta;
    let (cu, cv) = (-sol[0] / 2.0, -sol[1] / 2.0);
    let r2 = cu * cu + cv * cv - sol[2];
    if r2.is_nan() || r2 <= 0.0 {
        return Err(AxisFitError::Degenerate { sphere });
    }
    let radius = r2.sqrt();
    let circle_sq: f64 = uv
        .iter()
        .map(|(u, v)| (((u - cu).powi(2) + (v - cv).powi(2)).sqrt() - radius).powi(2))
        .sum();
    let c = mean + e1 * cu + e2 * cv;
    Ok(CircleFit {
        sphere,
        centre_mm: [c.x, c.y, c.z],
        radius_mm: radius,
        plane_rms_mm: (plane_sq / m as f64).sqrt(),
        circle_rms_mm: (circle_sq / m as f64).sqrt(),
        n: m,
    })
}

/// The angle between `n` and the nominal axis, and the inclination of `n` toward each of the
/// two other machine axes (keyed by their letters).
fn tilts_arcsec(
    n: &Vector3<f64>,
    nominal: &Vector3<f64>,
) -> (f64, std::collections::BTreeMap<String, f64>) {
    let tilt = n.cross(nominal).norm().atan2(n.dot(nominal)) * ARCSEC_PER_RAD;
    let letters = ["x", "y", "z"];
    let main = nominal.iamax();
    let mut toward = std::collections::BTreeMap::new();
    for (i, letter) in letters.iter().enumerate() {
        if i != main {
            toward.insert(
                letter.to_string(),
                n[i].atan2(n[main] * nominal[main].signum()) * ARCSEC_PER_RAD,
            );
        }
    }
    (tilt, toward)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Rotation3, Unit};

    #[test]
    fn recovers_tilted_offset_axis_from_two_circles() {
        // Axis through (12, −7, 0) tilted 40″ toward +X and −25″ toward Y (C axis).
        let tx = (40.0 / ARCSEC_PER_RAD).tan();
        let ty = (-25.0 / ARCSEC_PER_RAD).tan();
        let dir = Vector3::new(tx, ty, 1.0).normalize();
        let origin = Vector3::new(12.0, -7.0, 0.0);
        let rot = |p: Vector3<f64>, deg: f64| {
            let r = Rotation3::from_axis_angle(&Unit::new_normalize(dir), deg.to_radians());
            origin + r * (p - origin)
        };
        let p1 = Vector3::new(62.0, -7.0, 80.0);
        let p2 = Vector3::new(262.0, -7.0, 95.0);
        let angles: Vec<f64> = (0..24).map(|i| i as f64 * 15.0).collect();
        let t1: Vec<[f64; 3]> = angles.iter().map(|a| rot(p1, *a).into()).collect();
        let t2: Vec<[f64; 3]> = angles.iter().map(|a| rot(p2, *a).into()).collect();
        let fit = fit_axis([&t1, &t2], [0.0, 0.0, 1.0]).unwrap();
        let expected_tilt = dir.angle(&Vector3::z()) * ARCSEC_PER_RAD;
        assert!((fit.tilt_arcsec - expected_tilt).abs() < 1e-6, "{fit:?}");
        assert!((fit.tilt_toward_arcsec["x"] - 40.0).abs() < 1e-6);
        assert!((fit.tilt_toward_arcsec["y"] + 25.0).abs() < 1e-6);
        // The axis crosses Z = 0 at the planted origin.
        for k in 0..3 {
            assert!((fit.location_mm[k] - origin[k]).abs() < 1e-9, "{fit:?}");
        }
        // Sphere 2 circles at its distance from the axis line.
        let d2 = (p2 - origin).cross(&dir).norm();
        assert!((fit.circles[1].radius_mm - d2).abs() < 1e-9);
        assert!(fit.circles[0].plane_rms_mm < 1e-9 && fit.circles[1].circle_rms_mm < 1e-9);
    }

    #[test]
    fn rejects_lines_and_too_few_positions() {
        let line: Vec<[f64; 3]> = (0..5).map(|i| [i as f64, 0.0, 0.0]).collect();
        let ok: Vec<[f64; 3]> = vec![[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]];
        assert_eq!(
            fit_axis([&ok, &line], [0.0, 0.0, 1.0]),
            Err(AxisFitError::Degenerate { sphere: 2 })
        );
        assert_eq!(
            fit_axis([&ok[..2], &ok], [0.0, 0.0, 1.0]),
            Err(AxisFitError::TooFewPositions { sphere: 1, n: 2 })
        );
    }
}
