//! Shared numerics: linear least squares with its conditioning, and the number formatting of written files.

pub mod format;
pub mod lsq;

/// Peak-to-valley and RMS (about 0) of the values present, µm.
pub fn pv_rms_um(values: &[Option<f64>]) -> (f64, f64) {
    let present: Vec<f64> = values.iter().flatten().copied().collect();
    if present.is_empty() {
        return (0.0, 0.0);
    }
    let max = present.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    let min = present.iter().cloned().fold(f64::INFINITY, f64::min);
    let rms = (present.iter().map(|v| v * v).sum::<f64>() / present.len() as f64).sqrt();
    (max - min, rms)
}
