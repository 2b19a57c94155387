//! Thermal least squares (the shared QR solver with thermal's messages and standard errors), and Legendre polynomials.

use errmap_core::error::{Error, Result};
use errmap_core::numeric::lsq::{self, Refusal};

/// A least-squares solution of `A·β ≈ y`.
#[derive(Debug, Clone)]
pub struct LstsqFit {
    pub beta: Vec<f64>,
    /// Standard error of each coefficient: sqrt(diag(σ²·(AᵀA)⁻¹)), σ² = RSS/(n − p).
    /// `None` when n = p (no degrees of freedom).
    pub se: Option<Vec<f64>>,
    pub rss: f64,
    pub n: usize,
}

/// Solve `rows·β ≈ y` (one row of `p` regressors per observation) with
/// [`errmap_core::numeric::lsq`]. A rank-deficient design (a column that is a combination of
/// others) is an error naming `what`, so that e.g. two sensors that always read the same are
/// reported, not silently split.
pub fn lstsq(rows: &[f64], p: usize, y: &[f64], what: &str) -> Result<LstsqFit> {
    let fit =
        lsq::solve_rows(rows, p, y, lsq::DEFAULT_RANK_TOLERANCE).map_err(|r| {
            match r {
        Refusal::Shape { values, rows, columns } => Error::Internal(format!(
            "least squares for {what}: {values} values for {rows}×{columns}"
        )),
        Refusal::TooFew { rows, columns } => Error::numeric(
            format!("{what}: {rows} observations for {columns} unknowns"),
            "measure more points or times, or fit fewer terms (lower order, fewer sensors)",
        ),
        Refusal::ZeroColumn { column } => Error::numeric(
            format!("{what}: regressor {column} is zero for every observation"),
            "a sensor whose temperature never changes cannot be fitted; leave it out",
        ),
        Refusal::NotFinite { column } => Error::numeric(
            format!("{what}: regressor {column} is not a finite number for some observation"),
            "check the temperatures and positions of the campaign for missing values",
        ),
        Refusal::RankDeficient { .. } => Error::numeric(
            format!("{what}: the regressors are linearly dependent (the fit is not determined)"),
            "use sensors whose temperatures rise differently, campaigns with different ambient \
             temperatures (to fit ρ), or give ρ with --rho",
        ),
    }
        })?;
    Ok(LstsqFit {
        se: fit.standard_errors(),
        beta: fit.beta,
        rss: fit.rss,
        n: fit.n,
    })
}

/// Legendre polynomials P_0 … P_order at `s` into `out` (Bonnet's recursion
/// (n+1)·P_{n+1} = (2n+1)·s·P_n − n·P_{n−1}).
#[inline]
pub fn legendre_into(s: f64, order: usize, out: &mut [f64]) {
    out[0] = 1.0;
    if order >= 1 {
        out[1] = s;
    }
    for n in 1..order {
        let nf = n as f64;
        out[n + 1] = ((2.0 * nf + 1.0) * s * out[n] - nf * out[n - 1]) / (nf + 1.0);
    }
}

/// Σ c_n·P_n(s) by Clenshaw's recurrence (no allocation).
#[inline]
pub fn legendre_sum(coefficients: &[f64], s: f64) -> f64 {
    // Clenshaw for Legendre: α_k(s) = (2k+1)s/(k+1), β_k = −k/(k+1).
    let n = coefficients.len();
    if n == 0 {
        return 0.0;
    }
    let (mut b1, mut b2) = (0.0, 0.0);
    for k in (1..n).rev() {
        let kf = k as f64;
        let alpha = (2.0 * kf + 1.0) * s / (kf + 1.0);
        let beta_next = -(kf + 1.0) / (kf + 2.0);
        let b0 = coefficients[k] + alpha * b1 + beta_next * b2;
        b2 = b1;
        b1 = b0;
    }
    // P_0 = 1, P_1 = s: result = c_0 + s·b1 + β_1·b2, β_1 = −1/2.
    coefficients[0] + s * b1 - 0.5 * b2
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn legendre_matches_closed_forms() {
        let mut p = [0.0; 5];
        for s in [-1.0, -0.3, 0.0, 0.55, 1.0] {
            legendre_into(s, 4, &mut p);
            let s2: f64 = s * s;
            assert!((p[2] - 0.5 * (3.0 * s2 - 1.0)).abs() < 1e-14);
            assert!((p[3] - 0.5 * (5.0 * s2 * s - 3.0 * s)).abs() < 1e-14);
            assert!((p[4] - (35.0 * s2 * s2 - 30.0 * s2 + 3.0) / 8.0).abs() < 1e-14);
            let c = [0.3, -1.2, 2.0, 0.7, -0.4];
            let direct: f64 = c.iter().zip(&p).map(|(a, b)| a * b).sum();
            assert!((legendre_sum(&c, s) - direct).abs() < 1e-13);
        }
        assert_eq!(legendre_sum(&[2.5], 0.4), 2.5);
    }

    #[test]
    fn straight_line_with_known_standard_errors() {
        // y = 1 + 2x at x = 0,1,2,3 with residuals +e,−e,−e,+e (orthogonal to 1 and x):
        // β exact, RSS = 4e², σ² = 2e², SE(slope) = σ/sqrt(Sxx) = sqrt(2)e/sqrt(5).
        let e = 0.1;
        let xs = [0.0, 1.0, 2.0, 3.0];
        let noise = [e, -e, -e, e];
        let rows: Vec<f64> = xs.iter().flat_map(|&x| [1.0, x]).collect();
        let y: Vec<f64> = xs
            .iter()
            .zip(noise)
            .map(|(x, n)| 1.0 + 2.0 * x + n)
            .collect();
        let fit = lstsq(&rows, 2, &y, "line").unwrap();
        assert!((fit.beta[0] - 1.0).abs() < 1e-12 && (fit.beta[1] - 2.0).abs() < 1e-12);
        assert!((fit.rss - 4.0 * e * e).abs() < 1e-12);
        let se = fit.se.unwrap();
        assert!((se[1] - (2.0f64).sqrt() * e / 5.0f64.sqrt()).abs() < 1e-12);
        // SE(intercept) = σ·sqrt(1/n + x̄²/Sxx) = sqrt(2)e·sqrt(1/4 + 2.25/5).
        assert!((se[0] - (2.0f64).sqrt() * e * (0.25f64 + 0.45).sqrt()).abs() < 1e-12);
    }

    #[test]
    fn dependent_columns_are_an_error() {
        let rows = [1.0, 2.0, 1.0, 2.0, 1.0, 2.0];
        let err = lstsq(&rows, 2, &[1.0, 2.0, 3.0], "gains").unwrap_err();
        assert!(err.to_string().contains("linearly dependent"), "{err}");
    }
}
