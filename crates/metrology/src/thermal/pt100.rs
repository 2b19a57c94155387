//! Pt100 resistance ↔ temperature by IEC 60751 (Callendar–Van Dusen, both branches).
//!
//! IEC 60751: `R(t) = R0·(1 + A·t + B·t²)` for 0 °C ≤ t ≤ 850 °C and
//! `R(t) = R0·(1 + A·t + B·t² + C·(t − 100)·t³)` for −200 °C ≤ t < 0 °C, with
//! A = 3.9083e-3 /°C, B = −5.775e-7 /°C², C = −4.183e-12 /°C⁴, R0 = 100 Ω.
//! Above 0 °C the quadratic is inverted in closed form; below 0 °C the quartic is
//! inverted by Newton's method started from the quadratic's root.

use errmap_core::error::{Error, Result};

/// IEC 60751 coefficient A (1/°C).
pub const A: f64 = 3.9083e-3;
/// IEC 60751 coefficient B (1/°C²).
pub const B: f64 = -5.775e-7;
/// IEC 60751 coefficient C (1/°C⁴), used below 0 °C only.
pub const C: f64 = -4.183e-12;
/// Nominal resistance of a Pt100 at 0 °C (Ω).
pub const R0_OHM: f64 = 100.0;

/// Lowest temperature IEC 60751 defines the curve for (°C).
pub const T_MIN_C: f64 = -200.0;
/// Highest temperature IEC 60751 defines the curve for (°C).
pub const T_MAX_C: f64 = 850.0;

/// Resistance of an ideal Pt100 at `t_c` (°C), IEC 60751.
pub fn resistance_ohm(t_c: f64) -> f64 {
    let poly = if t_c >= 0.0 {
        1.0 + A * t_c + B * t_c * t_c
    } else {
        1.0 + A * t_c + B * t_c * t_c + C * (t_c - 100.0) * t_c.powi(3)
    };
    R0_OHM * poly
}

/// Temperature (°C) of an ideal Pt100 reading `r_ohm`, the inverse of [`resistance_ohm`].
///
/// Fails when the resistance lies outside the IEC 60751 range (−200 °C … 850 °C),
/// which usually means an open or shorted sensor.
pub fn temperature_c(r_ohm: f64) -> Result<f64> {
    let r_min = resistance_ohm(T_MIN_C);
    let r_max = resistance_ohm(T_MAX_C);
    // A small margin so that table values rounded to 0.01 Ω at the ends still convert.
    if !r_ohm.is_finite() || r_ohm < r_min - 0.05 || r_ohm > r_max + 0.05 {
        return Err(Error::numeric(
            format!(
                "{r_ohm} Ω is outside the Pt100 range {r_min:.2} … {r_max:.2} Ω (−200 … 850 °C)"
            ),
            "check the sensor wiring, or mark the sensor's unit as c if the column holds °C",
        ));
    }
    // Root of R0·(B·t² + A·t + 1) − r = 0 that is continuous through 0 °C.
    let ratio = r_ohm / R0_OHM;
    let quadratic = (-A + (A * A - 4.0 * B * (1.0 - ratio)).sqrt()) / (2.0 * B);
    if r_ohm >= R0_OHM {
        return Ok(quadratic);
    }
    // Below 0 °C: Newton on f(t) = R(t) − r, from the quadratic root (within 0.1 °C of the answer).
    let mut t = quadratic;
    for _ in 0..50 {
        let f = resistance_ohm(t) - r_ohm;
        let df = R0_OHM * (A + 2.0 * B * t + C * (4.0 * t.powi(3) - 300.0 * t * t));
        let step = f / df;
        t -= step;
        if step.abs() < 1e-12 {
            break;
        }
    }
    Ok(t)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Published IEC 60751 Pt100 table values (Ω, rounded to 0.01 Ω), as reproduced at
    /// <http://www.sensorsci.com/reference.htm> (−200 … 600 °C) and
    /// <https://sensingtemp.com/resources-rtd-resistance-tables.html> (850 °C).
    const TABLE: [(f64, f64); 12] = [
        (-200.0, 18.52),
        (-100.0, 60.26),
        (-50.0, 80.31),
        (-10.0, 96.09),
        (0.0, 100.00),
        (10.0, 103.90),
        (20.0, 107.79),
        (100.0, 138.51),
        (200.0, 175.86),
        (400.0, 247.09),
        (600.0, 313.71),
        (850.0, 390.48),
    ];

    #[test]
    fn resistance_matches_the_published_table() {
        for (t, r) in TABLE {
            let got = resistance_ohm(t);
            assert!((got - r).abs() <= 0.005 + 1e-9, "R({t}) = {got}, table {r}");
        }
    }

    #[test]
    fn temperature_from_table_resistance_within_rounding() {
        // 0.005 Ω of table rounding is at most 0.005/0.17 ≈ 0.03 °C at the steepest-flat end.
        for (t, r) in TABLE {
            let got = temperature_c(r).unwrap();
            assert!((got - t).abs() < 0.03, "T({r}) = {got}, table {t}");
        }
    }

    #[test]
    fn inverse_round_trips_on_both_branches() {
        let mut t = -200.0;
        while t <= 850.0 {
            let back = temperature_c(resistance_ohm(t)).unwrap();
            assert!((back - t).abs() < 1e-9, "{t} → {back}");
            t += 7.25;
        }
        // Just either side of 0 °C, where the branches meet.
        for t in [-1e-3, 0.0, 1e-3] {
            assert!((temperature_c(resistance_ohm(t)).unwrap() - t).abs() < 1e-9);
        }
    }

    #[test]
    fn below_zero_uses_the_quartic_not_the_quadratic() {
        // At −200 °C the C term is worth 100·C·(−300)·(−200)³ = −1.0039 Ω; a quadratic-only
        // inverse would be off by several degrees.
        let r = resistance_ohm(-200.0);
        let quad_only = R0_OHM * (1.0 + A * -200.0 + B * 40_000.0);
        assert!((quad_only - r - 1.003_92).abs() < 1e-4, "{}", quad_only - r);
        assert!((temperature_c(r).unwrap() + 200.0).abs() < 1e-9);
    }

    #[test]
    fn out_of_range_resistance_is_an_error() {
        for r_ohm in [5.0, 500.0, f64::NAN] {
            let err = temperature_c(r_ohm).unwrap_err();
            assert_eq!(err.kind(), "input", "{err}");
            assert!(
                err.to_string()
                    .contains(&format!("{r_ohm} Ω is outside the Pt100 range")),
                "{err}"
            );
        }
    }
}
