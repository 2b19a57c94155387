//! Normalisation between millimetres/micrometres and the network's scaled inputs and standardised targets.

use serde::{Deserialize, Serialize};

use errmap_core::geom::Domain;

/// Inputs map the domain onto [-1, 1]²; targets are standardised (e − mean) / std.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Normalisation {
    /// Lower u edge of the map domain, mm: maps to input −1.
    pub u_min_mm: f64,
    /// Upper u edge of the map domain, mm: maps to input +1.
    pub u_max_mm: f64,
    /// Lower v edge of the map domain, mm: maps to input −1.
    pub v_min_mm: f64,
    /// Upper v edge of the map domain, mm: maps to input +1.
    pub v_max_mm: f64,
    /// Mean of the finite training targets E, µm: the network's output 0.
    pub e_mean_um: f64,
    /// Population standard deviation of the finite training targets E, µm (1 when they are
    /// constant or empty): one unit of the network's output.
    pub e_std_um: f64,
}

impl Normalisation {
    /// From the map domain and the training targets. A constant (or empty) target set gets
    /// std 1 so scaling never divides by zero; non-finite targets are ignored.
    pub fn new(domain: &Domain, e_um: &[f64]) -> Normalisation {
        let finite: Vec<f64> = e_um.iter().copied().filter(|e| e.is_finite()).collect();
        let n = finite.len() as f64;
        let mean = if finite.is_empty() {
            0.0
        } else {
            finite.iter().sum::<f64>() / n
        };
        let var = if finite.is_empty() {
            0.0
        } else {
            finite.iter().map(|e| (e - mean) * (e - mean)).sum::<f64>() / n
        };
        let std = var.sqrt();
        Normalisation {
            u_min_mm: domain.u_min_mm,
            u_max_mm: domain.u_max_mm,
            v_min_mm: domain.v_min_mm,
            v_max_mm: domain.v_max_mm,
            e_mean_um: mean,
            e_std_um: if std.is_finite() && std > 1e-12 {
                std
            } else {
                1.0
            },
        }
    }

    /// (u, v) in mm → [-1, 1]² over the domain (a zero-width side maps to 0).
    pub fn scale_input(&self, u_mm: f64, v_mm: f64) -> [f32; 2] {
        [
            scale_axis(u_mm, self.u_min_mm, self.u_max_mm),
            scale_axis(v_mm, self.v_min_mm, self.v_max_mm),
        ]
    }

    /// Error E in µm → standardised training target `(e − mean) / std`.
    pub fn scale_target(&self, e_um: f64) -> f32 {
        ((e_um - self.e_mean_um) / self.e_std_um) as f32
    }

    /// Network output → error E in µm, `mean + std · y` (the inverse of
    /// [`Normalisation::scale_target`]).
    pub fn unscale_output(&self, y: f32) -> f64 {
        self.e_mean_um + self.e_std_um * y as f64
    }
}

fn scale_axis(x: f64, min: f64, max: f64) -> f32 {
    let width = max - min;
    if width > 0.0 {
        (2.0 * (x - min) / width - 1.0) as f32
    } else {
        0.0
    }
}
