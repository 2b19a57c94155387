//! Corrections of laser readings: air refractive index (readings on the vacuum-wavelength scale) and material expansion (normalisation to 20 °C, ISO 1).
//!
//! Both work on the laser's length L = actual − datum (the laser was zeroed with the machine at
//! `datum_mm`, usually the first target), and rewrite each row's deviation.
//!
//! - Air: an interferometer counting fringes of vacuum wavelength λ₀ without compensation shows
//!   L_read = N·λ₀/2, while the true length is L = N·λ₀/(2n) (λ_air = λ₀/n, NIST EMT eq. 1), so
//!   **L = L_read / n**. With n > 1 the corrected length is shorter: in standard air
//!   (n − 1 ≈ 2.7·10⁻⁴) a 1000 mm reading becomes 999.729 mm, and the deviation falls by 271 µm.
//! - Material: at material temperature T the axis' scale/screw is longer by α·(T − 20 °C), so
//!   positions measured at T are normalised to the reference temperature 20 °C of ISO 1 by
//!   **L₂₀ = L_T / (1 + α·(T − 20))**. A warm axis (T > 20 °C, α > 0) reads long; the
//!   normalisation lowers its deviations by ≈ α·(T − 20)·L.

use super::air::{refractive_index, AirConditions, AirFormula};
use super::runs::RunFile;
use crate::Setting;
use errmap_core::error::{Error, Location, Result};
use errmap_core::setting::words;

/// Reference temperature of dimensional measurement (ISO 1:2016), °C.
pub const REFERENCE_TEMP_C: f64 = 20.0;

/// Settings of the air correction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AirCorrection {
    /// The refractive-index equation.
    pub formula: AirFormula,
    /// Vacuum wavelength of the laser, nm (He-Ne 632.991).
    pub wavelength_nm: f64,
    /// CO₂ content of the air, µmol/mol (used by Ciddor; Edlén requires the default 450).
    pub co2_ppm: f64,
    /// Machine position at which the laser was zeroed, mm.
    pub datum_mm: f64,
}

fn missing(file: &RunFile, line: u64, column: &str, why: &str) -> Error {
    Error::input(
        Location::cell(&file.path, line, column),
        format!("no {column} on this row, needed for {why}"),
        format!("add a {column} value to every row, or drop the {why} option"),
    )
}

/// Rescale every row's reading by the refractive index of its own air (see module doc).
/// Returns the corrected file and the index of each row.
pub fn correct_air(file: &RunFile, settings: &AirCorrection) -> Result<(RunFile, Vec<f64>)> {
    let mut out = file.clone();
    let mut indices = Vec::with_capacity(file.rows.len());
    let why = &words(Setting::CorrectAir);
    for row in &mut out.rows {
        let t = row
            .env
            .air_temp_c
            .ok_or_else(|| missing(file, row.line, "air_temp_c", why))?;
        let p = row
            .env
            .pressure_kpa
            .ok_or_else(|| missing(file, row.line, "pressure_kpa", why))?;
        let h = row
            .env
            .humidity_pct
            .ok_or_else(|| missing(file, row.line, "humidity_pct", why))?;
        let cond = AirConditions {
            temp_c: t,
            pressure_kpa: p,
            humidity_pct: h,
            wavelength_nm: settings.wavelength_nm,
            co2_ppm: settings.co2_ppm,
        };
        let n = refractive_index(&cond, settings.formula).map_err(|e| {
            Error::input(
                Location::line(&file.path, row.line),
                format!("air conditions out of range: {e}"),
                "check the environment columns of this row",
            )
        })?;
        let l_read_mm = row.actual_mm() - settings.datum_mm;
        let actual_mm = settings.datum_mm + l_read_mm / n;
        row.deviation_um = (actual_mm - row.target_mm) * 1e3;
        indices.push(n);
    }
    Ok((out, indices))
}

/// Normalise every row to 20 °C with the row's `material_temp_c` and expansion coefficient
/// `alpha_ppm_per_k` (µm/(m·K)), see module doc.
pub fn normalise_material(file: &RunFile, alpha_ppm_per_k: f64, datum_mm: f64) -> Result<RunFile> {
    if !alpha_ppm_per_k.is_finite() || alpha_ppm_per_k.abs() > 1000.0 {
        return Err(Error::usage(
            format!("expansion coefficient {alpha_ppm_per_k} ppm/K is not plausible"),
            "give the coefficient in µm/(m·K), e.g. 11.5 for steel, 23 for aluminium",
        ));
    }
    let mut out = file.clone();
    for row in &mut out.rows {
        let t = row.env.material_temp_c.ok_or_else(|| {
            missing(
                file,
                row.line,
                "material_temp_c",
                &words(Setting::MaterialExpansion),
            )
        })?;
        let l_mm = row.actual_mm() - datum_mm;
        let l20_mm = l_mm / (1.0 + alpha_ppm_per_k * 1e-6 * (t - REFERENCE_TEMP_C));
        row.deviation_um = (datum_mm + l20_mm - row.target_mm) * 1e3;
    }
    Ok(out)
}
