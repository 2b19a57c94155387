//! Denoising of temperature channels that keeps real steps: a running median (removes spikes,
//! keeps edges) followed by a Savitzky–Golay smoother (keeps polynomial trends).
//!
//! Windows count samples, so a channel should be sampled evenly (a temperature log usually is).
//! Savitzky–Golay after Savitzky & Golay, Anal. Chem. 36 (1964) 1627: the smoothed value is the
//! least-squares polynomial of order `order` through the `window` samples around a point,
//! evaluated at that point; near the ends the window is held against the end and the same
//! polynomial is evaluated off-centre, so a polynomial of the filter's order passes unchanged
//! everywhere.

use errmap_core::error::{Error, Result};
use errmap_core::numeric::lsq;
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// Filter parameters of one sensor (columns of the sensor table).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FilterSpec {
    /// Running-median window in samples (odd; 1 = no median).
    pub median_window: usize,
    /// Savitzky–Golay window in samples (odd; 1 = no smoothing).
    pub sg_window: usize,
    /// Savitzky–Golay polynomial order (< sg_window).
    pub sg_order: usize,
}

impl Default for FilterSpec {
    fn default() -> Self {
        FilterSpec {
            median_window: 5,
            sg_window: 11,
            sg_order: 2,
        }
    }
}

impl FilterSpec {
    /// No filtering at all.
    pub const NONE: FilterSpec = FilterSpec {
        median_window: 1,
        sg_window: 1,
        sg_order: 0,
    };

    /// Check the parameters; the message says what is wrong, the caller adds the location.
    pub fn validate(&self) -> std::result::Result<(), String> {
        if self.median_window == 0 || self.median_window.is_multiple_of(2) {
            return Err(format!(
                "median window {} must be an odd number of samples (1 = off)",
                self.median_window
            ));
        }
        if self.sg_window == 0 || self.sg_window.is_multiple_of(2) {
            return Err(format!(
                "Savitzky–Golay window {} must be an odd number of samples (1 = off)",
                self.sg_window
            ));
        }
        if self.sg_window > 1 && self.sg_order >= self.sg_window {
            return Err(format!(
                "Savitzky–Golay order {} must be below the window {}",
                self.sg_order, self.sg_window
            ));
        }
        if self.sg_window > 1001 || self.median_window > 1001 {
            return Err("filter windows above 1001 samples are not supported".into());
        }
        if self.sg_window > 1 && self.sg_order > MAX_SG_ORDER {
            return Err(format!(
                "Savitzky–Golay order {} is above {MAX_SG_ORDER}: its normal equations are too ill-conditioned to mean anything",
                self.sg_order
            ));
        }
        Ok(())
    }

    /// Running median then Savitzky–Golay, as the sensor table asks.
    pub fn apply(&self, samples: &[f64]) -> Result<Vec<f64>> {
        self.validate()
            .map_err(|m| Error::usage(m, "fix the filter columns of the sensor table"))?;
        let median = running_median(samples, self.median_window);
        savitzky_golay(&median, self.sg_window, self.sg_order)
    }
}

/// Running median over `window` samples (odd). Near the ends the window shrinks symmetrically,
/// so the first and last samples are kept as they are.
pub fn running_median(samples: &[f64], window: usize) -> Vec<f64> {
    let half = window / 2;
    let n = samples.len();
    let mut out = Vec::with_capacity(n);
    let mut buf = Vec::with_capacity(window);
    for i in 0..n {
        let h = half.min(i).min(n - 1 - i);
        buf.clear();
        buf.extend_from_slice(&samples[i - h..=i + h]);
        buf.sort_by(f64::total_cmp);
        out.push(buf[h]);
    }
    out
}

/// Highest Savitzky–Golay polynomial order accepted: beyond it the monomial normal equations
/// lose every digit, and their cost grows with the cube of the order.
pub const MAX_SG_ORDER: usize = 10;

/// The least-squares projection of a `window`-sample polynomial fit of `order`:
/// `(JᵀJ)⁻¹Jᵀ` by QR (`numeric::lsq::projection`) with positions scaled to about [-1, 1], and
/// the scaled position of each sample.
struct SgProjection {
    p: DMatrix<f64>,
    centre: f64,
    scale: f64,
}

impl SgProjection {
    fn new(window: usize, order: usize) -> Result<SgProjection> {
        if window == 0 || order >= window {
            return Err(Error::usage(
                format!("no Savitzky–Golay filter of order {order} over {window} samples"),
                "use an odd window larger than the order",
            ));
        }
        let centre = (window as f64 - 1.0) / 2.0;
        let scale = centre.max(1.0);
        let z = |i: usize| (i as f64 - centre) / scale;
        let j = DMatrix::from_fn(window, order + 1, |r, c| z(r).powi(c as i32));
        let p = lsq::projection(&j, lsq::DEFAULT_RANK_TOLERANCE).map_err(|refusal| {
            Error::numeric(
                format!("the Savitzky–Golay polynomial fit is not determined: {refusal}"),
                "use a smaller order",
            )
        })?;
        Ok(SgProjection { p, centre, scale })
    }

    /// Weights of the fitted polynomial's value at sample `at` of the window.
    fn weights(&self, at: usize) -> Vec<f64> {
        let z = (at as f64 - self.centre) / self.scale;
        let e = DVector::from_fn(self.p.nrows(), |c, _| z.powi(c as i32));
        (e.transpose() * &self.p).iter().copied().collect()
    }
}

/// Savitzky–Golay weights of a `window`-sample least-squares polynomial of `order`, evaluated at
/// sample `at` (0-based within the window). `weights · samples` is the smoothed value.
pub fn sg_weights(window: usize, order: usize, at: usize) -> Result<Vec<f64>> {
    if at >= window {
        return Err(Error::usage(
            format!("no Savitzky–Golay weights at sample {at} of a {window}-sample window"),
            "use an odd window larger than the order",
        ));
    }
    Ok(SgProjection::new(window, order)?.weights(at))
}

/// Savitzky–Golay smoothing over `window` samples (odd) with a polynomial of `order`.
/// A channel shorter than the window is fitted as a whole with the order capped.
pub fn savitzky_golay(samples: &[f64], window: usize, order: usize) -> Result<Vec<f64>> {
    let n = samples.len();
    if window <= 1 || n == 0 {
        return Ok(samples.to_vec());
    }
    let w = window.min(if n % 2 == 1 { n } else { n - 1 });
    if w <= 1 {
        return Ok(samples.to_vec());
    }
    let order = order.min(w - 1);
    let half = w / 2;
    // One projection for the window; each edge sample only needs its own row of weights.
    let projection = SgProjection::new(w, order)?;
    let centre = projection.weights(half);
    let mut out = vec![0.0; n];
    for (i, slot) in out.iter_mut().enumerate() {
        let (start, weights);
        let edge;
        if i < half {
            edge = projection.weights(i);
            start = 0;
            weights = &edge;
        } else if i + half >= n {
            edge = projection.weights(w - (n - i));
            start = n - w;
            weights = &edge;
        } else {
            start = i - half;
            weights = &centre;
        }
        *slot = weights
            .iter()
            .zip(&samples[start..start + w])
            .map(|(a, b)| a * b)
            .sum();
    }
    Ok(out)
}

#[cfg(test)]
/// Closed-form variance reduction of the central Savitzky–Golay smoother for white noise:
/// Σ h_k² = h_0 for a least-squares projection; for order 0 or 1 it is 1/(2m+1), for order 2
/// or 3 it is 3(3m² + 3m − 1)/((2m − 1)(2m + 1)(2m + 3)), window 2m + 1
/// (Savitzky & Golay 1964; Schafer, "What is a Savitzky–Golay filter?", IEEE SP Mag. 2011).
pub fn sg_noise_factor(window: usize, order: usize) -> Option<f64> {
    let m = (window / 2) as f64;
    match order {
        0 | 1 => Some(1.0 / (2.0 * m + 1.0)),
        2 | 3 if window >= 5 => Some(
            3.0 * (3.0 * m * m + 3.0 * m - 1.0)
                / ((2.0 * m - 1.0) * (2.0 * m + 1.0) * (2.0 * m + 3.0)),
        ),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    #[test]
    fn five_point_quadratic_weights_are_the_published_ones() {
        // Savitzky & Golay (1964), table I: (−3, 12, 17, 12, −3)/35.
        let w = sg_weights(5, 2, 2).unwrap();
        let expect = [-3.0, 12.0, 17.0, 12.0, -3.0].map(|v| v / 35.0);
        for (a, b) in w.iter().zip(expect) {
            assert!((a - b).abs() < 1e-12, "{w:?}");
        }
        // Seven-point cubic is the same as quadratic: (−2, 3, 6, 7, 6, 3, −2)/21.
        let w = sg_weights(7, 3, 3).unwrap();
        let expect = [-2.0, 3.0, 6.0, 7.0, 6.0, 3.0, -2.0].map(|v| v / 21.0);
        for (a, b) in w.iter().zip(expect) {
            assert!((a - b).abs() < 1e-12, "{w:?}");
        }
    }

    #[test]
    fn orders_above_the_limit_are_refused_before_any_fit() {
        // A 1001-sample window of order 1000 once meant 1000 edge fits of a 1001 × 1001 system
        // per channel: hours for one sensor table row.
        let spec = FilterSpec {
            median_window: 1,
            sg_window: 1001,
            sg_order: 1000,
        };
        let msg = spec.validate().unwrap_err();
        assert!(
            msg.contains("order 1000") && msg.contains("above 10"),
            "{msg}"
        );
        let ok = FilterSpec {
            sg_order: MAX_SG_ORDER,
            ..spec
        };
        assert_eq!(ok.validate(), Ok(()));
        assert!(ok.apply(&[1.0; 50]).is_ok());
    }

    #[test]
    fn polynomial_of_the_filter_order_passes_unchanged_including_ends() {
        let x: Vec<f64> = (0..60).map(|i| i as f64 * 0.1).collect();
        let cubic: Vec<f64> = x
            .iter()
            .map(|t| 20.0 + 0.8 * t - 0.3 * t * t + 0.02 * t * t * t)
            .collect();
        let out = savitzky_golay(&cubic, 11, 3).unwrap();
        for (a, b) in out.iter().zip(&cubic) {
            assert!((a - b).abs() < 1e-9, "{a} vs {b}");
        }
        // A quadratic through an order-2 filter too; a cubic through order 2 does not.
        let out2 = savitzky_golay(&cubic, 11, 2).unwrap();
        let worst = out2
            .iter()
            .zip(&cubic)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(
            worst > 1e-4,
            "an order-2 filter should bend a cubic ({worst})"
        );
    }

    #[test]
    fn white_noise_variance_drops_by_the_closed_form_factor() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let normal = Normal::new(0.0, 1.0).unwrap();
        let noise: Vec<f64> = (0..200_000).map(|_| normal.sample(&mut rng)).collect();
        for (window, order) in [(5, 2), (11, 2), (21, 3), (9, 1)] {
            let out = savitzky_golay(&noise, window, order).unwrap();
            let interior = &out[window..out.len() - window];
            let var = interior.iter().map(|v| v * v).sum::<f64>() / interior.len() as f64;
            let factor = sg_noise_factor(window, order).unwrap();
            // Σh² computed from the weights equals the closed form exactly …
            let sum_sq: f64 = sg_weights(window, order, window / 2)
                .unwrap()
                .iter()
                .map(|h| h * h)
                .sum();
            assert!((sum_sq - factor).abs() < 1e-12, "{window}/{order}");
            // … and the measured variance of 200 000 samples within 3 %.
            assert!(
                (var / factor - 1.0).abs() < 0.03,
                "window {window} order {order}: variance {var}, closed form {factor}"
            );
        }
    }

    #[test]
    fn a_step_survives_and_a_spike_is_removed() {
        // Level 20 °C, a real step to 21 °C at sample 50, and a one-sample spike at 20.
        let mut signal: Vec<f64> = (0..100).map(|i| if i < 50 { 20.0 } else { 21.0 }).collect();
        signal[20] = 35.0;
        let spec = FilterSpec {
            median_window: 5,
            sg_window: 7,
            sg_order: 2,
        };
        let out = spec.apply(&signal).unwrap();
        // The spike is gone entirely.
        assert!((out[20] - 20.0).abs() < 1e-12, "{}", out[20]);
        // Outside the SG half-window around the step both levels are exact: the step is
        // neither removed nor smeared wider than the filter.
        for i in (0..47).chain(53..100) {
            let want = if i < 50 { 20.0 } else { 21.0 };
            assert!((out[i] - want).abs() < 1e-12, "sample {i}: {}", out[i]);
        }
        // The full 1 °C rise is still there across the step.
        assert!((out[53] - out[46] - 1.0).abs() < 1e-12);
        // The median alone keeps the step perfectly sharp.
        let med = running_median(&signal, 5);
        assert_eq!(med[49], 20.0);
        assert_eq!(med[50], 21.0);
    }

    #[test]
    fn bad_parameters_are_rejected() {
        let even = FilterSpec {
            median_window: 4,
            ..FilterSpec::default()
        };
        let err = even.validate().unwrap_err();
        assert!(
            err.contains("median window 4 must be an odd number"),
            "{err}"
        );
        let high = FilterSpec {
            median_window: 1,
            sg_window: 5,
            sg_order: 5,
        };
        let err = high.validate().unwrap_err();
        assert!(err.contains("order 5 must be below the window 5"), "{err}");
        assert!(FilterSpec::NONE.validate().is_ok());
    }
}
