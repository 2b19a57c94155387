//! Causal denoising of a live temperature channel with the model's own filter settings: a
//! running median over the last `median_window` readings, then the Savitzky–Golay polynomial
//! of the last `sg_window` medians evaluated at the newest one (the window's end, since later
//! readings do not exist yet).
//!
//! Until a window is full the filter passes what it has: the median of the readings so far,
//! and the newest median unsmoothed.

use errmap_core::error::Result;
use errmap_metrology::thermal::filter::{sg_weights, FilterSpec};
use std::collections::VecDeque;

/// The filter state of one channel.
#[derive(Debug, Clone)]
pub struct CausalFilter {
    median_window: usize,
    raw: VecDeque<f64>,
    medians: VecDeque<f64>,
    /// Savitzky–Golay weights at the window's last sample (empty: no smoothing).
    sg: Vec<f64>,
    scratch: Vec<f64>,
}

impl CausalFilter {
    /// The filter of a model sensor's settings (`None`: readings pass unchanged).
    pub fn new(spec: Option<FilterSpec>) -> Result<CausalFilter> {
        let (median_window, sg) = match spec {
            None => (1, Vec::new()),
            Some(s) => {
                let sg = if s.sg_window > 1 {
                    sg_weights(
                        s.sg_window,
                        s.sg_order.min(s.sg_window - 1),
                        s.sg_window - 1,
                    )?
                } else {
                    Vec::new()
                };
                (s.median_window.max(1), sg)
            }
        };
        Ok(CausalFilter {
            median_window,
            raw: VecDeque::with_capacity(median_window),
            medians: VecDeque::with_capacity(sg.len().max(1)),
            sg,
            scratch: Vec::with_capacity(median_window),
        })
    }

    /// Forget the history (a sensor accepted again after an alarm).
    pub fn reset(&mut self) {
        self.raw.clear();
        self.medians.clear();
    }

    /// Add a reading; the filtered value at it.
    pub fn push(&mut self, value: f64) -> f64 {
        if self.raw.len() == self.median_window {
            self.raw.pop_front();
        }
        self.raw.push_back(value);
        self.scratch.clear();
        self.scratch.extend(self.raw.iter().copied());
        self.scratch.sort_by(f64::total_cmp);
        let n = self.scratch.len();
        let median = if n % 2 == 1 {
            self.scratch[n / 2]
        } else {
            0.5 * (self.scratch[n / 2 - 1] + self.scratch[n / 2])
        };
        if self.sg.is_empty() {
            return median;
        }
        if self.medians.len() == self.sg.len() {
            self.medians.pop_front();
        }
        self.medians.push_back(median);
        if self.medians.len() < self.sg.len() {
            return median;
        }
        self.sg.iter().zip(&self.medians).map(|(w, m)| w * m).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quadratic_passes_after_the_window_fills_and_spikes_are_removed() {
        let spec = FilterSpec {
            median_window: 5,
            sg_window: 11,
            sg_order: 2,
        };
        let mut f = CausalFilter::new(Some(spec)).unwrap();
        let q = |i: usize| 20.0 + 0.01 * i as f64 + 0.0005 * (i as f64).powi(2);
        let mut last = 0.0;
        for i in 0..40 {
            // One spike: the median removes it, so the smoother never sees it.
            let v = if i == 30 { 850.0 } else { q(i) };
            last = f.push(v);
            if (20..30).contains(&i) {
                // The median of a monotone series lags by two samples (window 5); the
                // order-2 Savitzky–Golay polynomial then reproduces the lagged quadratic exactly.
                assert!(
                    (last - q(i - 2)).abs() < 1e-9,
                    "i {i}: {last} vs {}",
                    q(i - 2)
                );
            } else if i >= 30 {
                // The spike only shifts the medians around it by a sample.
                assert!(
                    (last - q(i - 2)).abs() < 0.1,
                    "i {i}: {last} vs {}",
                    q(i - 2)
                );
            }
        }
        assert!(last < 25.0);
    }

    #[test]
    fn no_filter_passes_readings() {
        let mut f = CausalFilter::new(None).unwrap();
        assert_eq!(f.push(21.5), 21.5);
        assert_eq!(f.push(-3.0), -3.0);
    }
}
