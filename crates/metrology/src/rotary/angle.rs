//! The double-vector angle (seed 003): signed angle of b from a about the axis, and err = α − β with wrap handling.

use nalgebra::Vector3;

/// Arcseconds per degree.
pub const ARCSEC_PER_DEG: f64 = 3600.0;

/// Signed angle (radians, in (−π, π]) that turns `a` into `b` about `axis`, right-handed.
///
/// Both vectors are first projected onto the plane normal to the axis; then
/// β = atan2((a × b)·n, a · b). Returns `None` when either projection is (nearly) zero:
/// a vector along the axis has no angle about it.
pub fn signed_angle_about(a: [f64; 3], b: [f64; 3], axis: [f64; 3]) -> Option<f64> {
    let n = Vector3::from(axis);
    let n_len = n.norm();
    if n_len.is_nan() || n_len <= 0.0 {
        return None;
    }
    let n = n / n_len;
    let a = Vector3::from(a);
    let b = Vector3::from(b);
    let ap = a - n * n.dot(&a);
    let bp = b - n * n.dot(&b);
    if ap.norm() <= 1e-9 * a.norm() || bp.norm() <= 1e-9 * b.norm() || ap.norm() == 0.0 {
        return None;
    }
    Some(ap.cross(&bp).dot(&n).atan2(ap.dot(&bp)))
}

/// Two unit vectors spanning the plane normal to the unit vector `n`, with (e1, e2, n)
/// right-handed: e1 = n × x (n × y when n is near x), e2 = n × e1.
pub fn normal_frame(n: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    // Any vector not parallel to n gives the frame.
    let helper = if n.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let e1 = n.cross(&helper).normalize();
    let e2 = n.cross(&e1);
    (e1, e2)
}

/// Wrap an angle in degrees into (−180, 180].
pub fn wrap_deg(angle_deg: f64) -> f64 {
    let w = angle_deg.rem_euclid(360.0);
    if w > 180.0 {
        w - 360.0
    } else {
        w
    }
}

/// Angular error err = α − β in arcseconds, with α the commanded angle (degrees, any
/// turn, either sign) relative to the reference angle and β the measured signed angle
/// (radians, in (−π, π]). The difference is wrapped into (−180°, 180°], so α = 270° with
/// β = −90° + ε gives err = −ε, and α = −30° works as well as α = 330°.
pub fn angle_error_arcsec(commanded_deg: f64, beta_rad: f64) -> f64 {
    wrap_deg(commanded_deg - beta_rad.to_degrees()) * ARCSEC_PER_DEG
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Rotation3, Unit};

    /// Rotate `v` by `angle_deg` about `axis` with nalgebra's own axis-angle rotation
    /// (Rodrigues), independent of the atan2 code under test.
    fn rotate(v: [f64; 3], axis: [f64; 3], angle_deg: f64) -> [f64; 3] {
        let r = Rotation3::from_axis_angle(
            &Unit::new_normalize(Vector3::from(axis)),
            angle_deg.to_radians(),
        );
        let w = r * Vector3::from(v);
        [w.x, w.y, w.z]
    }

    #[test]
    fn signed_angle_over_the_whole_turn_both_directions() {
        // The bar is not in the plane normal to the axis (second sphere higher): projection matters.
        let a = [150.0, 80.0, 35.0];
        let axes = [
            [0.0, 0.0, 1.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.1, -0.2, 1.0],
        ];
        for axis in axes {
            // Forward 0 … 360° and reverse 0 … −360° in 7.5° steps, plus odd angles.
            let mut angles: Vec<f64> = (0..=48).map(|i| i as f64 * 7.5).collect();
            angles.extend((1..=48).map(|i| -(i as f64) * 7.5));
            angles.extend([179.999, 180.001, -179.999, 359.9999, 0.0001, 725.0]);
            for alpha in angles {
                let b = rotate(a, axis, alpha);
                let beta = signed_angle_about(a, b, axis).unwrap();
                assert!(
                    beta > -std::f64::consts::PI - 1e-12 && beta <= std::f64::consts::PI + 1e-12
                );
                // β is α folded into (−180°, 180°].
                let folded = wrap_deg(alpha);
                let diff = wrap_deg(beta.to_degrees() - folded);
                assert!(
                    diff.abs() < 1e-9,
                    "axis {axis:?} α {alpha}: β {}",
                    beta.to_degrees()
                );
                // A perfect axis has no error anywhere in the turn.
                assert!(angle_error_arcsec(alpha, beta).abs() < 1e-6, "α {alpha}");
            }
        }
    }

    #[test]
    fn error_sign_and_size_across_the_turn() {
        let a = [200.0, 0.0, 0.0];
        let z = [0.0, 0.0, 1.0];
        // The axis turns short of the command by 5″ (β = α − 5″) → err = α − β = +5″,
        // and overshoots by 3″ → err = −3″, at every angle and in both senses.
        for alpha in [
            0.0, 10.0, 179.9990, 180.0, 190.0, 270.0, 359.9990, -90.0, -200.0,
        ] {
            let short = rotate(a, z, alpha - 5.0 / 3600.0);
            let beta = signed_angle_about(a, short, z).unwrap();
            assert!(
                (angle_error_arcsec(alpha, beta) - 5.0).abs() < 1e-6,
                "α {alpha}"
            );
            let over = rotate(a, z, alpha + 3.0 / 3600.0);
            let beta = signed_angle_about(a, over, z).unwrap();
            assert!(
                (angle_error_arcsec(alpha, beta) + 3.0).abs() < 1e-6,
                "α {alpha}"
            );
        }
        // Reversing the axis vector reverses the sense of the angle.
        let b = rotate(a, z, 30.0);
        let beta = signed_angle_about(a, b, [0.0, 0.0, -1.0]).unwrap();
        assert!((beta.to_degrees() + 30.0).abs() < 1e-9);
    }

    #[test]
    fn vector_along_the_axis_has_no_angle() {
        assert_eq!(
            signed_angle_about([0.0, 0.0, 5.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]),
            None
        );
        assert_eq!(
            signed_angle_about([1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]),
            None
        );
        assert_eq!(wrap_deg(180.0), 180.0);
        assert_eq!(wrap_deg(-180.0), 180.0);
        assert_eq!(wrap_deg(540.5), -179.5);
    }
}
