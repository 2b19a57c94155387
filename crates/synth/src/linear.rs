//! Synthetic laser-interferometer runs of a linear axis with known pitch error, reversal and noise.
//!
//! Ground truth (seed 002's curve model plus a reversal): the forward approach deviates by
//! e↑(x) = a + k·x + d·sin(2πx/P + φ) + B/2 and the reverse by e↓(x) = e↑(x) − B, each reading
//! adds Gaussian noise σ; these are the errors at 20 °C. The axis is read at its logged
//! material temperature T, so each reading also carries the expansion α·(T − 20 °C)·x
//! (α = `expansion_ppm_per_k`, laser zeroed at 0 mm) that `--material-expansion` removes. Targets follow ISO 230-2's advice: nominally equal steps with an
//! irregular offset so that periodic errors are sampled at different phases.
//! Files written: `runs.csv` (deviation_um, already on the air-corrected scale, with the
//! environment logged per row), `runs_raw.csv` (the same readings as `actual_mm` on the vacuum
//! scale, L_read = n·L, for `--correct-air`), `truth.json`.

use errmap_core::error::Result;
use errmap_metrology::linear::{refractive_index, AirConditions, AirFormula, HENE_WAVELENGTH_NM};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use std::fmt::Write as _;
use std::path::Path;

/// The planted axis and campaign.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct LinearTruth {
    /// Travel of the axis from 0, mm.
    pub travel_mm: f64,
    /// Nominal target positions in ascending order, 0 and the travel included, mm.
    pub targets_mm: Vec<f64>,
    /// Runs in each direction (each run is a forward then a reverse pass).
    pub runs: u32,
    /// Period P of the periodic error, mm: the ball-screw lead.
    pub lead_mm: f64,
    /// Offset a of the error, µm.
    pub a_um: f64,
    /// Slope k of the error (linear scale error), µm per m of travel.
    pub k_um_per_m: f64,
    /// Amplitude d of the periodic error, µm.
    pub d_um: f64,
    /// Phase φ of the periodic error at x = 0, radians.
    pub phi_rad: f64,
    /// Reversal B = e↑ − e↓, forward minus reverse error at the same target, µm.
    pub reversal_um: f64,
    /// Standard deviation σ of the Gaussian noise of each reading, µm.
    pub noise_um: f64,
    /// Expansion coefficient of the axis, µm/(m·K); readings are taken at material_temp_c.
    pub expansion_ppm_per_k: f64,
    /// Seed of the generator (ChaCha8): targets and noise follow from it.
    pub seed: u64,
    /// Laser datum (zeroed here), mm.
    pub datum_mm: f64,
    /// Refractive-index formula `runs_raw.csv` is put on the vacuum scale with (`ciddor`).
    pub air_formula: &'static str,
    /// Vacuum wavelength of the laser, nm (helium-neon).
    pub wavelength_nm: f64,
}

impl LinearTruth {
    /// Planted mean error of a direction at `x_mm` (µm).
    pub fn error_um(&self, forward: bool, x_mm: f64) -> f64 {
        let base = self.a_um
            + self.k_um_per_m * x_mm * 1e-3
            + self.d_um * (2.0 * std::f64::consts::PI * x_mm / self.lead_mm + self.phi_rad).sin();
        if forward {
            base + self.reversal_um / 2.0
        } else {
            base - self.reversal_um / 2.0
        }
    }
}

/// One generated reading.
#[derive(Debug, Clone, PartialEq)]
pub struct SynthRow {
    /// Run number, from 1.
    pub run: u32,
    /// Approach direction: `true` forward (+, ascending targets), `false` reverse.
    pub forward: bool,
    /// Nominal position, mm.
    pub target_mm: f64,
    /// Reading − target at the material temperature, µm, on the air-corrected scale: the
    /// planted error, the noise and the axis' thermal expansion.
    pub deviation_um: f64,
    /// Air temperature logged with the reading, °C.
    pub air_temp_c: f64,
    /// Air pressure logged with the reading, kPa.
    pub pressure_kpa: f64,
    /// Relative humidity logged with the reading, %.
    pub humidity_pct: f64,
    /// Temperature of the axis (scale or workpiece material) logged with the reading, °C.
    pub material_temp_c: f64,
    /// Time of the reading since the campaign started, s (8 s per reading).
    pub time_s: f64,
}

/// Generate the default campaign: 0…1000 mm, 21 targets, 5 runs each way, screw lead 10 mm.
pub fn generate(seed: u64) -> Result<(LinearTruth, Vec<SynthRow>), crate::SynthError> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let travel_mm = 1000.0;
    let steps = 20;
    let step_mm = travel_mm / steps as f64;
    // Irregular offsets (rounded to 0.001 mm) inside each step, ends kept at 0 and the travel.
    let targets_mm: Vec<f64> = (0..=steps)
        .map(|i| {
            let base = i as f64 * step_mm;
            if i == 0 || i == steps {
                base
            } else {
                base + (rng.random_range(-0.3..0.3) * step_mm * 1000.0).round() / 1000.0
            }
        })
        .collect();
    let truth = LinearTruth {
        travel_mm,
        targets_mm: targets_mm.clone(),
        runs: 5,
        lead_mm: 10.0,
        a_um: 1.5,
        k_um_per_m: 12.0,
        d_um: 1.8,
        phi_rad: 0.7,
        reversal_um: 4.0,
        noise_um: 0.4,
        expansion_ppm_per_k: 11.5,
        seed,
        datum_mm: 0.0,
        air_formula: "ciddor",
        wavelength_nm: HENE_WAVELENGTH_NM,
    };
    let noise = Normal::new(0.0, truth.noise_um)
        .map_err(|e| errmap_core::Error::Internal(format!("noise distribution: {e}")))?;
    let mut rows = Vec::new();
    let mut time_s = 0.0;
    for run in 1..=truth.runs {
        for forward in [true, false] {
            let order: Vec<f64> = if forward {
                targets_mm.clone()
            } else {
                targets_mm.iter().rev().copied().collect()
            };
            for x in order {
                time_s += 8.0;
                // Slow drifts of the room over the campaign (about 20 min).
                let phase = time_s / 1200.0;
                let material_temp_c = 20.5 + 0.3 * phase;
                // Error at 20 °C, then the axis' expansion at T: L_T = L_20·(1 + α(T − 20)).
                let e20_um = truth.error_um(forward, x) + noise.sample(&mut rng);
                let l20_mm = x + e20_um * 1e-3 - truth.datum_mm;
                let lt_mm =
                    l20_mm * (1.0 + truth.expansion_ppm_per_k * 1e-6 * (material_temp_c - 20.0));
                rows.push(SynthRow {
                    run,
                    forward,
                    target_mm: x,
                    deviation_um: (truth.datum_mm + lt_mm - x) * 1e3,
                    air_temp_c: 20.3 + 0.2 * phase,
                    pressure_kpa: 101.2 - 0.05 * phase,
                    humidity_pct: 45.0 + 2.0 * phase,
                    material_temp_c,
                    time_s,
                });
            }
        }
    }
    Ok((truth, rows))
}

/// Write `runs.csv`, `runs_raw.csv` and `truth.json` into `dir`.
pub fn write(dir: &Path, truth: &LinearTruth, rows: &[SynthRow]) -> Result<(), crate::SynthError> {
    let mut runs = String::from(
        "run,direction,target_mm,deviation_um,air_temp_c,pressure_kpa,humidity_pct,material_temp_c,time_s\n",
    );
    let mut raw = String::from(
        "run,direction,target_mm,actual_mm,air_temp_c,pressure_kpa,humidity_pct,material_temp_c,time_s\n",
    );
    for r in rows {
        let dir = if r.forward { "+" } else { "-" };
        let env = format!(
            "{:.3},{:.4},{:.2},{:.3},{:.1}",
            r.air_temp_c, r.pressure_kpa, r.humidity_pct, r.material_temp_c, r.time_s
        );
        let dev = (r.deviation_um * 1e4).round() / 1e4;
        let _ = writeln!(runs, "{},{dir},{},{dev:.4},{env}", r.run, r.target_mm);
        // Raw reading on the vacuum scale: L_read = n·L with n from the logged (rounded) air.
        let cond = AirConditions::new(
            format!("{:.3}", r.air_temp_c)
                .parse()
                .unwrap_or(r.air_temp_c),
            format!("{:.4}", r.pressure_kpa)
                .parse()
                .unwrap_or(r.pressure_kpa),
            format!("{:.2}", r.humidity_pct)
                .parse()
                .unwrap_or(r.humidity_pct),
            truth.wavelength_nm,
        );
        let n = refractive_index(&cond, AirFormula::Ciddor)?;
        let actual_mm = r.target_mm + dev * 1e-3;
        let read_mm = truth.datum_mm + n * (actual_mm - truth.datum_mm);
        let _ = writeln!(raw, "{},{dir},{},{read_mm:.9},{env}", r.run, r.target_mm);
    }
    errmap_core::io::write_atomic_bytes(&dir.join("runs.csv"), runs.as_bytes())?;
    errmap_core::io::write_atomic_bytes(&dir.join("runs_raw.csv"), raw.as_bytes())?;
    errmap_core::io::write_json(&dir.join("truth.json"), truth).map_err(Into::into)
}
