//! Refractive index of air by the Ciddor (1996) and modified Edlén (Birch & Downs 1993/1994) equations, exactly as NIST's Engineering Metrology Toolbox computes them.
//!
//! Source: J. A. Stone and J. H. Zimmerman, "Index of Refraction of Air", NIST Engineering
//! Metrology Toolbox, <https://emtoolbox.nist.gov/Wavelength/Documentation.asp>, Appendix A:
//! A-I saturation vapour pressure (IAPWS over water for t ≥ 0 °C, the IAPWS 1993 sublimation
//! formula over ice below 0 °C), A-II humidity (p_v = RH/100 · p_sv), A-III Ciddor, A-IV
//! modified Edlén (Birch & Downs 1993, 1994, with NIST's water-vapour term).
//! Inputs: temperature in °C, pressure in Pa internally (kPa at the API), relative humidity in
//! %, vacuum wavelength in nm (µm inside the formulas), CO₂ in µmol/mol (Ciddor only; the
//! Edlén equation assumes 450 µmol/mol).

use crate::Setting;
use errmap_core::error::{Error, Result};
use errmap_core::setting::words;

/// The equation of the refractive index of air.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum AirFormula {
    /// Ciddor (1996), NIST EMT Appendix A-III.
    Ciddor,
    /// Modified Edlén (Birch & Downs 1993/1994 + NIST water-vapour term), Appendix A-IV.
    Edlen,
}

impl AirFormula {
    /// The equation's lower-case name (`ciddor`, `edlen`): the command-line value and the name
    /// the corrections note and JSON report give.
    pub fn name(self) -> &'static str {
        match self {
            AirFormula::Ciddor => "ciddor",
            AirFormula::Edlen => "edlen",
        }
    }
}

/// Air conditions for the index.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct AirConditions {
    /// Air temperature at the beam, °C (valid −40…100 °C).
    pub temp_c: f64,
    /// Absolute air pressure, kPa (valid 10…140; standard atmosphere 101.325).
    pub pressure_kpa: f64,
    /// Relative humidity, % (0…100).
    pub humidity_pct: f64,
    /// Vacuum wavelength of the laser, nm (300…1700; He-Ne 632.991).
    pub wavelength_nm: f64,
    /// CO₂ content, µmol/mol (0…2000); only Ciddor uses it, Edlén requires the default 450.
    pub co2_ppm: f64,
}

impl AirConditions {
    /// Conditions with the NIST default CO₂ content (450 µmol/mol).
    pub fn new(temp_c: f64, pressure_kpa: f64, humidity_pct: f64, wavelength_nm: f64) -> Self {
        AirConditions {
            temp_c,
            pressure_kpa,
            humidity_pct,
            wavelength_nm,
            co2_ppm: DEFAULT_CO2_PPM,
        }
    }
}

/// CO₂ content the Edlén equation assumes and the NIST calculator defaults to.
pub const DEFAULT_CO2_PPM: f64 = 450.0;

/// Vacuum wavelength of a stabilised He-Ne laser (nm), the usual interferometer source.
pub const HENE_WAVELENGTH_NM: f64 = 632.991;

/// Saturation vapour pressure (Pa) at `temp_c` (NIST EMT A-I): over liquid water for t ≥ 0 °C
/// (IAPWS-IF97 saturation-pressure equation, Wagner et al.), over ice below 0 °C
/// (IAPWS 1993 sublimation formula).
pub fn saturation_vapour_pressure_pa(temp_c: f64) -> f64 {
    let t_k = temp_c + 273.15;
    if temp_c >= 0.0 {
        const K: [f64; 10] = [
            1.167_052_145_28e3,
            -7.242_131_670_32e5,
            -1.707_384_694_01e1,
            1.202_082_470_25e4,
            -3.232_555_032_23e6,
            1.491_510_861_35e1,
            -4.823_265_736_16e3,
            4.051_134_054_21e5,
            -2.385_555_756_78e-1,
            6.501_753_484_48e2,
        ];
        let omega = t_k + K[8] / (t_k - K[9]);
        let a = omega * omega + K[0] * omega + K[1];
        let b = K[2] * omega * omega + K[3] * omega + K[4];
        let c = K[5] * omega * omega + K[6] * omega + K[7];
        let x = -b + (b * b - 4.0 * a * c).sqrt();
        1e6 * (2.0 * c / x).powi(4)
    } else {
        const A1: f64 = -13.928_169;
        const A2: f64 = 34.707_823_8;
        let theta = t_k / 273.16;
        let y = A1 * (1.0 - theta.powf(-1.5)) + A2 * (1.0 - theta.powf(-1.25));
        611.657 * y.exp()
    }
}

/// Partial pressure of water vapour (Pa) from relative humidity (NIST EMT A-II).
pub fn vapour_pressure_pa(temp_c: f64, humidity_pct: f64) -> f64 {
    humidity_pct / 100.0 * saturation_vapour_pressure_pa(temp_c)
}

/// Validate conditions against the range NIST states for its calculator.
fn check(c: &AirConditions, formula: AirFormula) -> Result<()> {
    let bad = |what: String, hint: &str| Err(Error::usage(what, hint));
    let all = [
        c.temp_c,
        c.pressure_kpa,
        c.humidity_pct,
        c.wavelength_nm,
        c.co2_ppm,
    ];
    if all.iter().any(|v| !v.is_finite()) {
        return bad(
            "air conditions must be finite numbers".into(),
            "check the inputs",
        );
    }
    // (value, valid range, what it is, its unit, the range as the message says it, hint)
    let ranges = [
        (
            c.temp_c,
            -40.0..=100.0,
            "air temperature",
            "°C",
            "−40…100 °C",
            "the equations are valid for −40…100 °C (NIST validates −40…50 °C)",
        ),
        (
            c.pressure_kpa,
            10.0..=140.0,
            "pressure",
            "kPa",
            "10…140 kPa",
            "give the absolute air pressure in kPa (standard: 101.325)",
        ),
        (
            c.humidity_pct,
            0.0..=100.0,
            "relative humidity",
            "%",
            "0…100 %",
            "give the relative humidity in percent",
        ),
        (
            c.wavelength_nm,
            300.0..=1700.0,
            "wavelength",
            "nm",
            "300…1700 nm",
            "give the vacuum wavelength in nm (He-Ne: 632.991)",
        ),
        (
            c.co2_ppm,
            0.0..=2000.0,
            "CO2 content",
            "µmol/mol",
            "0…2000",
            "typical laboratory air holds about 450 µmol/mol",
        ),
    ];
    for (value, range, what, unit, range_text, hint) in ranges {
        if !range.contains(&value) {
            return bad(
                format!("{what} {value} {unit} is outside {range_text}"),
                hint,
            );
        }
    }
    if formula == AirFormula::Edlen && c.co2_ppm != DEFAULT_CO2_PPM {
        return bad(
            "the modified Edlén equation assumes 450 µmol/mol CO2".into(),
            &format!(
                "use {} ciddor for another CO2 content",
                words(Setting::Formula)
            ),
        );
    }
    Ok(())
}

/// Refractive index of air (phase index) by `formula`.
pub fn refractive_index(c: &AirConditions, formula: AirFormula) -> Result<f64> {
    check(c, formula)?;
    Ok(match formula {
        AirFormula::Ciddor => ciddor(c),
        AirFormula::Edlen => edlen(c),
    })
}

/// The conditions in the units both equations take.
struct Terms {
    /// Temperature, °C and K.
    t: f64,
    t_k: f64,
    /// Pressure and water-vapour pressure, Pa.
    p: f64,
    pv: f64,
    /// Wavenumber squared σ² = 1/λ², µm⁻².
    s: f64,
}

impl Terms {
    fn of(c: &AirConditions) -> Terms {
        let t = c.temp_c;
        let lambda_um = c.wavelength_nm * 1e-3;
        Terms {
            t,
            t_k: t + 273.15,
            p: c.pressure_kpa * 1e3,
            pv: vapour_pressure_pa(t, c.humidity_pct),
            s: 1.0 / (lambda_um * lambda_um),
        }
    }
}

/// Ciddor (1996) as NIST EMT Appendix A-III computes it.
fn ciddor(c: &AirConditions) -> f64 {
    const W0: f64 = 295.235;
    const W1: f64 = 2.6422;
    const W2: f64 = -0.032_38;
    const W3: f64 = 0.004_028;
    const K0: f64 = 238.0185;
    const K1: f64 = 5_792_105.0;
    const K2: f64 = 57.362;
    const K3: f64 = 167_917.0;
    const A0: f64 = 1.581_23e-6;
    const A1: f64 = -2.9331e-8;
    const A2: f64 = 1.1043e-10;
    const B0: f64 = 5.707e-6;
    const B1: f64 = -2.051e-8;
    const C0: f64 = 1.9898e-4;
    const C1: f64 = -2.376e-6;
    const D: f64 = 1.83e-11;
    const E: f64 = -0.765e-8;
    const P_R1: f64 = 101_325.0;
    const T_R1: f64 = 288.15;
    const Z_A: f64 = 0.999_592_211_5;
    const RHO_VS: f64 = 0.009_859_38;
    const R: f64 = 8.314_472;
    const M_V: f64 = 0.018_015;
    // Enhancement factor f = α + βp + γt² of water vapour in air.
    const ALPHA: f64 = 1.000_62;
    const BETA: f64 = 3.14e-8;
    const GAMMA: f64 = 5.60e-7;

    let Terms { t, t_k, p, pv, s } = Terms::of(c);
    // Refractivities of standard dry air (15 °C, 101 325 Pa, 450 µmol/mol CO2) and standard
    // water vapour (20 °C, 1333 Pa).
    let r_as = 1e-8 * (K1 / (K0 - s) + K3 / (K2 - s));
    let r_vs = 1.022e-8 * (W0 + W1 * s + W2 * s * s + W3 * s * s * s);
    // Molar mass of dry air with x_c CO2, and the CO2 correction of its refractivity.
    let m_a = 0.028_963_5 + 1.2011e-8 * (c.co2_ppm - 400.0);
    let r_axs = r_as * (1.0 + 5.34e-7 * (c.co2_ppm - 450.0));
    // Mole fraction of water vapour.
    let f = ALPHA + BETA * p + GAMMA * t * t;
    let x_v = f * pv / p;
    // Compressibility of moist air (BIPM 1981/91).
    let pt = p / t_k;
    let z_m = 1.0
        - pt * (A0 + A1 * t + A2 * t * t + (B0 + B1 * t) * x_v + (C0 + C1 * t) * x_v * x_v)
        + pt * pt * (D + E * x_v * x_v);
    let rho_axs = P_R1 * m_a / (Z_A * R * T_R1);
    let rho_v = x_v * p * M_V / (z_m * R * t_k);
    let rho_a = (1.0 - x_v) * p * m_a / (z_m * R * t_k);
    1.0 + (rho_a / rho_axs) * r_axs + (rho_v / RHO_VS) * r_vs
}

/// Modified Edlén (Birch & Downs 1993, 1994) as NIST EMT Appendix A-IV computes it.
fn edlen(c: &AirConditions) -> f64 {
    const A: f64 = 8342.54;
    const B: f64 = 2_406_147.0;
    const C: f64 = 15_998.0;
    const D: f64 = 96_095.43;
    const E: f64 = 0.601;
    const F: f64 = 0.009_72;
    const G: f64 = 0.003_661;
    let Terms { t, t_k, p, pv, s } = Terms::of(c);
    let ns = 1.0 + 1e-8 * (A + B / (130.0 - s) + C / (38.9 - s));
    let x = (1.0 + 1e-8 * (E - F * t) * p) / (1.0 + G * t);
    let ntp = 1.0 + p * (ns - 1.0) * x / D;
    // NIST's water-vapour term (its modification: the 292.75/T factor).
    ntp - 1e-10 * (292.75 / t_k) * (3.7345 - 0.0401 * s) * pv
}

/// Sensitivities ∂n/∂t (1/K), ∂n/∂p (1/kPa), ∂n/∂RH (1/%) at `c`, by central differences of
/// the chosen equation (steps 0.01 K, 0.01 kPa, 0.1 %; the equations are smooth on that scale).
pub fn sensitivities(c: &AirConditions, formula: AirFormula) -> Result<[f64; 3]> {
    let n = |c: AirConditions| refractive_index(&c, formula);
    let (dt, dp, dh) = (0.01, 0.01, 0.1);
    let d_t = (n(AirConditions {
        temp_c: c.temp_c + dt,
        ..*c
    })? - n(AirConditions {
        temp_c: c.temp_c - dt,
        ..*c
    })?) / (2.0 * dt);
    let d_p = (n(AirConditions {
        pressure_kpa: c.pressure_kpa + dp,
        ..*c
    })? - n(AirConditions {
        pressure_kpa: c.pressure_kpa - dp,
        ..*c
    })?) / (2.0 * dp);
    // Humidity at the 0/100 % edges: one-sided difference.
    let h_hi = (c.humidity_pct + dh).min(100.0);
    let h_lo = (c.humidity_pct - dh).max(0.0);
    let d_h = (n(AirConditions {
        humidity_pct: h_hi,
        ..*c
    })? - n(AirConditions {
        humidity_pct: h_lo,
        ..*c
    })?) / (h_hi - h_lo);
    Ok([d_t, d_p, d_h])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nist_values_quoted_in_the_issue() {
        let dry = AirConditions::new(20.0, 101.325, 0.0, 633.0);
        let n = refractive_index(&dry, AirFormula::Ciddor).unwrap();
        assert!((n - 1.000_271_800).abs() < 1e-9, "{n:.12}");
        let n = refractive_index(&dry, AirFormula::Edlen).unwrap();
        assert!((n - 1.000_271_799).abs() < 1e-9, "{n:.12}");
        let humid = AirConditions::new(20.0, 101.325, 50.0, 633.0);
        let n = refractive_index(&humid, AirFormula::Ciddor).unwrap();
        assert!((n - 1.000_271_373).abs() < 1e-9, "{n:.12}");
    }
}
