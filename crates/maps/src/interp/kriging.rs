//! Ordinary kriging (Gaussian-process regression) of scattered sites: Matérn 5/2 covariance with a nugget, hyper-parameters by maximum likelihood, solved by Cholesky (nalgebra).
//!
//! Model: `e(p) = μ + f(p) + ε`, f a zero-mean Gaussian process with covariance
//! `σ²·m(r/ℓ)`, `m(t) = (1 + √5·t + 5t²/3)·exp(−√5·t)` (Matérn ν = 5/2, r the distance in mm),
//! ε white noise of variance `σ²·g` (the nugget: probe noise and detail finer than the
//! sites). With `R = M + g·I` (M the Matérn correlations of the sites), μ and σ² have closed
//! forms — `μ̂ = 1ᵀR⁻¹e / 1ᵀR⁻¹1`, `σ̂² = (e − μ̂)ᵀR⁻¹(e − μ̂)/n` — and ℓ and g maximise the
//! profiled log-likelihood `−n/2·ln σ̂² − ½·ln|R|` over a log-spaced grid refined once around
//! its best node. The prediction is the posterior mean `μ̂ + m(p)ᵀ·R⁻¹(e − μ̂)`: it smooths
//! through the noise instead of passing through every site (g > 0), and it returns to μ̂ far
//! from the sites.

use errmap_core::error::{Error, Result};
use nalgebra::{DMatrix, DVector};

/// A fitted kriging model (serialized into `model.json` when it is the delivered map).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Kriging {
    /// Site positions (u, v) in mm.
    pub sites: Vec<[f64; 2]>,
    /// R⁻¹(e − μ̂) per site.
    pub weights: Vec<f64>,
    /// Constant mean μ̂ (µm, the unit of the values).
    pub mean: f64,
    /// Correlation length ℓ (mm).
    pub length_mm: f64,
    /// Nugget as a fraction g of the process variance.
    pub nugget_ratio: f64,
    /// Process variance σ̂² (unit²).
    pub variance: f64,
}

/// Matérn 5/2 correlation at distance `r` for length `l`.
#[inline]
pub(crate) fn matern52(r: f64, l: f64) -> f64 {
    let t = 5f64.sqrt() * r / l;
    (1.0 + t + t * t / 3.0) * (-t).exp()
}

/// Most sites one fit takes (the solve is O(n³)); more is an error naming the limit.
pub const MAX_SITES: usize = 4000;

/// The profiled fit of one (ℓ, g): (−log-likelihood without constants, μ̂, σ̂², weights).
pub(crate) fn profile(
    distances: &DMatrix<f64>,
    e: &[f64],
    l: f64,
    g: f64,
) -> Option<(f64, f64, f64, Vec<f64>)> {
    let n = e.len();
    // Symmetric: each correlation computed once.
    let mut r = DMatrix::zeros(n, n);
    for j in 0..n {
        r[(j, j)] = 1.0 + g;
        for i in j + 1..n {
            let c = matern52(distances[(i, j)], l);
            r[(i, j)] = c;
            r[(j, i)] = c;
        }
    }
    let chol = r.cholesky()?;
    let ones = DVector::from_element(n, 1.0);
    let y = DVector::from_column_slice(e);
    let r_ones = chol.solve(&ones);
    let r_y = chol.solve(&y);
    let mean = r_y.sum() / r_ones.sum();
    let resid = &y - &ones * mean;
    let w = chol.solve(&resid);
    let variance = resid.dot(&w) / n as f64;
    if !(variance.is_finite() && variance > 0.0) {
        return None;
    }
    let log_det: f64 = 2.0 * chol.l().diagonal().iter().map(|d| d.ln()).sum::<f64>();
    let nll = 0.5 * n as f64 * variance.ln() + 0.5 * log_det;
    nll.is_finite()
        .then(|| (nll, mean, variance, w.iter().copied().collect()))
}

/// Refuses fewer than 3 sites, more than [`MAX_SITES`], or a non-finite number.
fn check_sites(points_uve: &[[f64; 3]]) -> Result<()> {
    let n = points_uve.len();
    if n < 3 {
        return Err(Error::numeric(
            format!("kriging needs at least 3 points, got {n}"),
            "probe more points",
        ));
    }
    if n > MAX_SITES {
        return Err(Error::usage(
            format!("kriging solves one {n}×{n} system; at most {MAX_SITES} points"),
            "use another [interp] method for this many points",
        ));
    }
    if points_uve.iter().flatten().any(|v| !v.is_finite()) {
        return Err(Error::numeric(
            "a kriging site has a non-finite coordinate or value",
            "remove NaN and infinite values",
        ));
    }
    Ok(())
}

/// The diagonal of the sites' bounding box, mm.
fn diagonal_mm(sites: &[[f64; 2]]) -> f64 {
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for s in sites {
        for k in 0..2 {
            lo[k] = lo[k].min(s[k]);
            hi[k] = hi[k].max(s[k]);
        }
    }
    ((hi[0] - lo[0]).powi(2) + (hi[1] - lo[1]).powi(2)).sqrt()
}

/// The (ℓ, g) of least negative log-likelihood: a coarse grid (ℓ from 1 % to 200 % of the
/// diagonal `diag`, g from 1e-6 to 1), then one refinement around its best node.
fn best_length_and_nugget(distances: &DMatrix<f64>, e: &[f64], diag: f64) -> Result<(f64, f64)> {
    let lengths: Vec<f64> = (0..7)
        .map(|k| diag * 0.01 * 200f64.powf(k as f64 / 6.0))
        .collect();
    let nuggets = [1e-6, 1e-3, 1e-2, 0.1, 1.0];
    let mut best: Option<(f64, f64, f64)> = None; // (nll, l, g)
    let consider = |l: f64, g: f64, best: &mut Option<(f64, f64, f64)>| {
        if let Some((nll, ..)) = profile(distances, e, l, g) {
            if best.is_none_or(|b| nll < b.0) {
                *best = Some((nll, l, g));
            }
        }
    };
    for &l in &lengths {
        for &g in &nuggets {
            consider(l, g, &mut best);
        }
    }
    // One refinement around the best node (half a grid step each way, in log scale).
    if let Some((_, l0, g0)) = best {
        let step_l = 200f64.powf(1.0 / 12.0);
        for fl in [1.0 / step_l, 1.0, step_l] {
            for fg in [1.0 / 3.0, 1.0, 3.0] {
                if fl != 1.0 || fg != 1.0 {
                    consider(l0 * fl, (g0 * fg).min(1.0), &mut best);
                }
            }
        }
    }
    let (_, length_mm, nugget_ratio) = best.ok_or_else(|| {
        Error::numeric(
            "no kriging length and nugget gave a positive-definite system",
            "check the probe file for repeated points with different values",
        )
    })?;
    Ok((length_mm, nugget_ratio))
}

impl Kriging {
    /// Fit to sites `(u_mm, v_mm, e)`. Errors: fewer than 3 sites, non-finite numbers, more
    /// than [`MAX_SITES`], or no (ℓ, g) giving a positive-definite system.
    pub fn fit(points_uve: &[[f64; 3]]) -> Result<Kriging> {
        check_sites(points_uve)?;
        let n = points_uve.len();
        let sites: Vec<[f64; 2]> = points_uve.iter().map(|p| [p[0], p[1]]).collect();
        let e: Vec<f64> = points_uve.iter().map(|p| p[2]).collect();
        let diag = diagonal_mm(&sites);
        if diag <= 0.0 {
            return Err(Error::numeric(
                "all kriging sites are at one position",
                "probe points spread over the part",
            ));
        }
        let distances = DMatrix::from_fn(n, n, |i, j| {
            (sites[i][0] - sites[j][0]).hypot(sites[i][1] - sites[j][1])
        });
        let (length_mm, nugget_ratio) = best_length_and_nugget(&distances, &e, diag)?;
        let (_, mean, variance, weights) = profile(&distances, &e, length_mm, nugget_ratio)
            .ok_or_else(|| Error::Internal("kriging refit failed".into()))?;
        Ok(Kriging {
            sites,
            weights,
            mean,
            length_mm,
            nugget_ratio,
            variance,
        })
    }

    /// Consistency of a model read from a file (the message says what is wrong).
    pub fn validate(&self) -> std::result::Result<(), String> {
        let finite = self
            .sites
            .iter()
            .flatten()
            .chain(&self.weights)
            .all(|v| v.is_finite())
            && [self.mean, self.length_mm, self.nugget_ratio, self.variance]
                .iter()
                .all(|v| v.is_finite());
        if self.sites.len() != self.weights.len() || self.sites.len() < 3 {
            return Err("kriging needs one weight per site and at least 3 sites".into());
        }
        if !finite || self.length_mm <= 0.0 {
            return Err("kriging holds a non-finite number or a length ≤ 0".into());
        }
        Ok(())
    }

    /// The posterior mean at (u, v).
    pub fn predict(&self, u_mm: f64, v_mm: f64) -> f64 {
        let mut e = self.mean;
        for (s, w) in self.sites.iter().zip(&self.weights) {
            let d = ((u_mm - s[0]).powi(2) + (v_mm - s[1]).powi(2)).sqrt();
            e += w * matern52(d, self.length_mm);
        }
        e
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matern_five_halves_closed_form() {
        // t = √5·r/ℓ; at r = ℓ: (1 + √5 + 5/3)·e^(−√5).
        let want = (1.0 + 5f64.sqrt() + 5.0 / 3.0) * (-(5f64.sqrt())).exp();
        assert!((matern52(2.0, 2.0) - want).abs() < 1e-15);
        assert_eq!(matern52(0.0, 1.0), 1.0);
    }

    #[test]
    fn a_smooth_field_is_predicted_between_the_sites() {
        // e = 3·sin(u/40)·cos(v/50) µm on a 9 × 9 grid of 100 mm, no noise: between the sites
        // the posterior mean is within 2 % of the field's range.
        let f = |u: f64, v: f64| 3.0 * (u / 40.0).sin() * (v / 50.0).cos();
        let mut pts = Vec::new();
        for i in 0..9 {
            for j in 0..9 {
                let (u, v) = (i as f64 * 12.5, j as f64 * 12.5);
                pts.push([u, v, f(u, v)]);
            }
        }
        let k = Kriging::fit(&pts).unwrap();
        let mut worst: f64 = 0.0;
        for i in 0..8 {
            for j in 0..8 {
                let (u, v) = (6.25 + i as f64 * 12.5, 6.25 + j as f64 * 12.5);
                worst = worst.max((k.predict(u, v) - f(u, v)).abs());
            }
        }
        assert!(worst < 0.12, "worst {worst} µm, ℓ {} mm", k.length_mm);
        assert!(
            k.nugget_ratio <= 1e-3,
            "noise-free data, nugget {}",
            k.nugget_ratio
        );
    }

    #[test]
    fn too_few_or_bad_sites_are_errors() {
        let refused = |sites: &[[f64; 3]], words: &str| {
            let err = Kriging::fit(sites).unwrap_err();
            assert_eq!(err.kind(), "input", "{err}");
            assert!(err.to_string().contains(words), "{err}");
        };
        refused(
            &[[0.0, 0.0, 1.0], [1.0, 0.0, 2.0]],
            "at least 3 points, got 2",
        );
        refused(
            &[[0.0, 0.0, 1.0], [1.0, 0.0, f64::NAN], [0.0, 1.0, 0.0]],
            "non-finite coordinate or value",
        );
        refused(
            &[[1.0, 1.0, 1.0], [1.0, 1.0, 2.0], [1.0, 1.0, 0.0]],
            "all kriging sites are at one position",
        );
    }
}
