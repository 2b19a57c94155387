//! Pitch-error fit of seed 002: e(x) = a + k·x + d·sin(2πx/P + φ), a linear (cumulative lead) term plus the periodic ball-screw term of lead P.
//!
//! Linear least squares on the basis {1, x, sin(2πx/P), cos(2πx/P)}: with
//! c_s = d·cos φ and c_c = d·sin φ, d·sin(θ + φ) = c_s·sin θ + c_c·cos θ, so
//! d = √(c_s² + c_c²), φ = atan2(c_c, c_s). Solved by the shared QR solver (`errmap_core::numeric::lsq`), whose rank
//! test refuses targets that cannot see the periodic term (all at multiples of the lead: sin θ, cos θ constant).

use crate::Setting;
use errmap_core::error::{Error, Result};
use errmap_core::numeric::lsq::Refusal;
use errmap_core::setting::words;
use nalgebra::DMatrix;
use std::f64::consts::PI;

/// The fitted pitch-error curve. Lengths in mm, errors in the input's unit (µm).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct PitchFit {
    /// Ball-screw lead P of the periodic term, mm.
    pub lead_mm: f64,
    /// Offset a (µm).
    pub a_um: f64,
    /// Slope k (µm per metre of travel).
    pub k_um_per_m: f64,
    /// Amplitude d ≥ 0 of the periodic term (µm).
    pub d_um: f64,
    /// Phase φ in radians, (−π, π].
    pub phi_rad: f64,
    /// Root mean square of the residuals e_i − e(x_i) (µm).
    pub residual_rms_um: f64,
    /// Number of targets fitted.
    pub points: usize,
}

impl PitchFit {
    /// The fitted error at `x_mm` (µm).
    pub fn eval(&self, x_mm: f64) -> f64 {
        self.a_um
            + self.k_um_per_m * x_mm * 1e-3
            + self.d_um * (2.0 * PI * x_mm / self.lead_mm + self.phi_rad).sin()
    }
}

/// Fit `e_um` at `x_mm` (at least 5 points so that the fit leaves a residual).
pub fn fit_pitch(x_mm: &[f64], e_um: &[f64], lead_mm: f64) -> Result<PitchFit> {
    if !(lead_mm.is_finite() && lead_mm > 0.0) {
        return Err(Error::usage(
            format!("screw lead {lead_mm} mm is not a positive length"),
            format!(
                "give the ball-screw lead in mm, e.g. {} 10",
                words(Setting::FitPitch)
            ),
        ));
    }
    let n = x_mm.len();
    if n != e_um.len() || n < 5 {
        return Err(Error::numeric(
            format!("the pitch fit needs at least 5 targets, got {n}"),
            "measure more targets along the axis",
        ));
    }
    let design = DMatrix::from_fn(n, 4, |i, j| {
        let theta = 2.0 * PI * x_mm[i] / lead_mm;
        match j {
            0 => 1.0,
            1 => x_mm[i] * 1e-3, // metres, so the slope comes out in µm/m
            2 => theta.sin(),
            _ => theta.cos(),
        }
    });
    let fit = errmap_core::numeric::lsq::solve(&design, e_um, 1e-9).map_err(|refusal| match refusal {
        Refusal::RankDeficient { .. } | Refusal::ZeroColumn { .. } => Error::numeric(
            "the targets cannot separate the periodic term from the line (are they all at multiples of the lead?)",
            "place targets at irregular positions (ISO 230-2 recommends it) or off multiples of the lead",
        ),
        other => Error::numeric(format!("pitch fit failed: {other}"), "check the targets"),
    })?;
    let c = &fit.beta;
    let rms = (fit.rss / n as f64).sqrt();
    Ok(PitchFit {
        lead_mm,
        a_um: c[0],
        k_um_per_m: c[1],
        d_um: (c[2] * c[2] + c[3] * c[3]).sqrt(),
        phi_rad: c[3].atan2(c[2]),
        residual_rms_um: rms,
        points: n,
    })
}
