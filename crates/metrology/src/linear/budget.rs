//! Error budget of a laser measurement (seed 002): laser stability, wavelength correction, Abbe, cosine misalignment and thermal expansion terms, combined by root-sum-square.
//!
//! Set-up file (TOML, every length in mm):
//! ```toml
//! length_mm = 1000.0                 # measured travel L
//! laser_stability_ppm = 0.1          # δ1 = 0.1 ppm × L (seed 002); default 0.1
//! [air]                               # δ2: wavelength correction
//! formula = "edlen"                  # or "ciddor"; default edlen
//! wavelength_nm = 632.991            # default He-Ne
//! temp_c = 20.0                      # conditions at which the sensitivities are taken
//! pressure_kpa = 101.325
//! humidity_pct = 50.0
//! temp_uncertainty_c = 0.1           # sensor uncertainties
//! pressure_uncertainty_kpa = 0.1
//! humidity_uncertainty_pct = 5.0
//! [abbe]                              # δ3 = offset × tan(angle)
//! offset_mm = 10.0
//! angle_arcsec = 2.0
//! [alignment]                         # δ4 = L·(1 − cos θ)
//! angle_arcsec = 30.0                # or lateral_offset_mm = 0.1 over L: θ = atan(offset/L)
//! [thermal]                           # δ5 = α·ΔT·L
//! expansion_ppm_per_k = 11.5
//! temp_uncertainty_c = 0.2
//! ```
//! A missing section contributes nothing: its term is left out of the list and the total.

use super::air::{sensitivities, AirConditions, AirFormula, DEFAULT_CO2_PPM, HENE_WAVELENGTH_NM};
use errmap_core::error::{Error, Location, Result};
use std::path::Path;

const ARCSEC_TO_RAD: f64 = std::f64::consts::PI / (180.0 * 3600.0);

/// The set-up of an error budget as read from its TOML file (keys in the module doc); a missing
/// section adds no term.
#[derive(Debug, Clone, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BudgetSetup {
    /// Measured travel L, mm; the stability, cosine and thermal terms scale with it.
    pub length_mm: f64,
    /// Wavelength stability of the laser, ppm of L (term δ1); 0.1 when not given.
    #[serde(default = "default_stability")]
    pub laser_stability_ppm: f64,
    /// Conditions and sensor uncertainties of the wavelength-correction term δ2; `None`: no term.
    pub air: Option<AirSetup>,
    /// Abbe offset and angle of term δ3; `None`: no term.
    pub abbe: Option<AbbeSetup>,
    /// Beam misalignment of the cosine term δ4; `None`: no term.
    pub alignment: Option<AlignmentSetup>,
    /// Expansion coefficient and temperature uncertainty of term δ5; `None`: no term.
    pub thermal: Option<ThermalSetup>,
}

fn default_stability() -> f64 {
    0.1
}

/// The `[air]` section: the wavelength-correction term δ2 = L·√Σ(∂n/∂q · u_q)², with the
/// sensitivities of the index equation taken at the given conditions.
#[derive(Debug, Clone, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AirSetup {
    /// The index equation whose sensitivities are taken; Edlén when not given.
    #[serde(default = "default_formula")]
    pub formula: AirFormula,
    /// Vacuum wavelength of the laser, nm; He-Ne 632.991 when not given.
    #[serde(default = "default_wavelength")]
    pub wavelength_nm: f64,
    /// Air temperature at which the sensitivities are taken, °C; 20 when not given.
    #[serde(default = "default_temp")]
    pub temp_c: f64,
    /// Absolute air pressure at which the sensitivities are taken, kPa; 101.325 when not given.
    #[serde(default = "default_pressure")]
    pub pressure_kpa: f64,
    /// Relative humidity at which the sensitivities are taken, %; 50 when not given.
    #[serde(default = "default_humidity")]
    pub humidity_pct: f64,
    /// Uncertainty of the air-temperature sensor, °C.
    pub temp_uncertainty_c: f64,
    /// Uncertainty of the pressure sensor, kPa.
    pub pressure_uncertainty_kpa: f64,
    /// Uncertainty of the humidity sensor, percentage points of relative humidity.
    pub humidity_uncertainty_pct: f64,
}

fn default_formula() -> AirFormula {
    AirFormula::Edlen
}
fn default_wavelength() -> f64 {
    HENE_WAVELENGTH_NM
}
fn default_temp() -> f64 {
    20.0
}
fn default_pressure() -> f64 {
    101.325
}
fn default_humidity() -> f64 {
    50.0
}

/// The `[abbe]` section: the Abbe term δ3 = offset × tan(angle).
#[derive(Debug, Clone, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AbbeSetup {
    /// Abbe offset between the laser beam and the point whose position matters (tool,
    /// workpiece), mm.
    pub offset_mm: f64,
    /// Angular error (pitch or yaw) of the carriage over the travel, arcsec.
    pub angle_arcsec: f64,
}

/// The `[alignment]` section: the cosine term δ4 = L·(1 − cos θ); exactly one of its two keys.
#[derive(Debug, Clone, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AlignmentSetup {
    /// Angle θ between the beam and the axis of travel, arcsec.
    pub angle_arcsec: Option<f64>,
    /// Lateral walk of the beam over the travel L, mm; θ = atan(offset / L).
    pub lateral_offset_mm: Option<f64>,
}

/// The `[thermal]` section: the material-expansion term δ5 = α·ΔT·L.
#[derive(Debug, Clone, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ThermalSetup {
    /// Expansion coefficient α of the axis' scale or screw, µm/(m·K) (steel ≈ 11.5).
    pub expansion_ppm_per_k: f64,
    /// Uncertainty ΔT of the material temperature, °C.
    pub temp_uncertainty_c: f64,
}

/// One term of the budget.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct BudgetTerm {
    /// The term's key: `laser_stability`, `wavelength_correction`, `abbe`, `cosine_misalignment` or
    /// `thermal_expansion`.
    pub name: &'static str,
    /// Its contribution to the budget, µm (non-negative).
    pub value_um: f64,
    /// The formula with this set-up's numbers, as the report prints it.
    pub formula: String,
}

/// The error budget of a laser set-up: its terms and their root-sum-square.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Budget {
    /// Travel L the budget was computed for, mm.
    pub length_mm: f64,
    /// The terms in the order δ1 … δ5; only those whose section the set-up gives.
    pub terms: Vec<BudgetTerm>,
    /// √(Σ δ²).
    pub total_um: f64,
}

/// Read a set-up TOML (errors name the file and line).
pub fn read_budget_setup(path: &Path) -> Result<BudgetSetup, crate::error::LinearError> {
    let text = errmap_core::io::read_text(path)?;
    toml::from_str(&text)
        .map_err(|e| {
            let line = e
                .span()
                .and_then(|s| text.get(..s.start))
                .map(|before| 1 + before.matches('\n').count() as u64);
            let location = match line {
                Some(l) => Location::line(path, l),
                None => Location::file(path),
            };
            Error::input(
                location,
                format!("bad set-up: {}", e.message()),
                "see docs/linear.md, 'errmap linear budget', for the keys",
            )
        })
        .map_err(Into::into)
}

/// Compute every term (µm) and the RSS total.
pub fn compute_budget(setup: &BudgetSetup) -> Result<Budget, crate::error::LinearError> {
    let l_mm = setup.length_mm;
    if !(l_mm.is_finite() && l_mm > 0.0) {
        return Err(Error::usage(
            format!("length_mm = {l_mm} is not a positive length"),
            "give the measured travel in mm",
        )
        .into());
    }
    let l_um = l_mm * 1e3;
    // δ1: laser wavelength stability, ppm of the length.
    let mut terms = vec![BudgetTerm {
        name: "laser_stability",
        value_um: setup.laser_stability_ppm * 1e-6 * l_um,
        formula: format!("{} ppm × {l_mm} mm", setup.laser_stability_ppm),
    }];
    if let Some(air) = &setup.air {
        terms.push(wavelength_term(air, l_um)?);
    }
    if let Some(abbe) = &setup.abbe {
        terms.push(abbe_term(abbe));
    }
    if let Some(al) = &setup.alignment {
        terms.push(cosine_term(al, l_mm)?);
    }
    if let Some(th) = &setup.thermal {
        terms.push(thermal_term(th, l_mm));
    }
    let total_um = terms
        .iter()
        .map(|t| t.value_um * t.value_um)
        .sum::<f64>()
        .sqrt();
    Ok(Budget {
        length_mm: l_mm,
        terms,
        total_um,
    })
}

/// δ2: wavelength correction: L · √Σ(∂n/∂q · u_q)², sensitivities from the index equation.
fn wavelength_term(air: &AirSetup, l_um: f64) -> Result<BudgetTerm> {
    let cond = AirConditions {
        temp_c: air.temp_c,
        pressure_kpa: air.pressure_kpa,
        humidity_pct: air.humidity_pct,
        wavelength_nm: air.wavelength_nm,
        co2_ppm: DEFAULT_CO2_PPM,
    };
    let [dn_dt, dn_dp, dn_dh] = sensitivities(&cond, air.formula)?;
    let u = ((dn_dt * air.temp_uncertainty_c).powi(2)
        + (dn_dp * air.pressure_uncertainty_kpa).powi(2)
        + (dn_dh * air.humidity_uncertainty_pct).powi(2))
    .sqrt();
    Ok(BudgetTerm {
        name: "wavelength_correction",
        value_um: u * l_um,
        formula: format!(
            "L·√((∂n/∂t·{})² + (∂n/∂p·{})² + (∂n/∂RH·{})²), ∂n/∂t = {:.3e}/K, ∂n/∂p = {:.3e}/kPa, ∂n/∂RH = {:.3e}/% ({})",
            air.temp_uncertainty_c,
            air.pressure_uncertainty_kpa,
            air.humidity_uncertainty_pct,
            dn_dt,
            dn_dp,
            dn_dh,
            air.formula.name()
        ),
    })
}

/// δ3: Abbe error, offset × tan(angle).
fn abbe_term(abbe: &AbbeSetup) -> BudgetTerm {
    BudgetTerm {
        name: "abbe",
        value_um: abbe.offset_mm * 1e3 * (abbe.angle_arcsec * ARCSEC_TO_RAD).tan().abs(),
        formula: format!("{} mm × tan({}″)", abbe.offset_mm, abbe.angle_arcsec),
    }
}

/// δ4: cosine error of beam/travel misalignment, L·(1 − cos θ).
fn cosine_term(al: &AlignmentSetup, l_mm: f64) -> Result<BudgetTerm> {
    let theta = match (al.angle_arcsec, al.lateral_offset_mm) {
        (Some(a), None) => a * ARCSEC_TO_RAD,
        (None, Some(off)) => (off / l_mm).atan(),
        _ => {
            return Err(Error::usage(
                "[alignment] needs exactly one of angle_arcsec or lateral_offset_mm",
                "give the beam angle, or the beam's lateral walk over the travel",
            ))
        }
    };
    Ok(BudgetTerm {
        name: "cosine_misalignment",
        value_um: l_mm * 1e3 * (1.0 - theta.cos()),
        formula: format!("L·(1 − cos θ), θ = {:.3}″", theta / ARCSEC_TO_RAD),
    })
}

/// δ5: thermal expansion, α·ΔT·L.
fn thermal_term(th: &ThermalSetup, l_mm: f64) -> BudgetTerm {
    BudgetTerm {
        name: "thermal_expansion",
        value_um: th.expansion_ppm_per_k * 1e-6 * th.temp_uncertainty_c * (l_mm * 1e3),
        formula: format!(
            "{} ppm/K × {} K × {l_mm} mm",
            th.expansion_ppm_per_k, th.temp_uncertainty_c
        ),
    }
}
