//! Linear least squares `A·β ≈ y` by Householder QR on unit-norm columns (nalgebra), with the rank and condition number reported so a caller can refuse a fit that is not determined.

use nalgebra::{DMatrix, DVector};

/// Relative size of a diagonal element of R (columns scaled to unit norm) at or below which
/// a column counts as a combination of the ones before it, when the caller has no reason to
/// choose another.
pub const DEFAULT_RANK_TOLERANCE: f64 = 1e-10;

/// Why a system has no unique least-squares solution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Refusal {
    /// The design has `values` entries, not `rows`×`columns`, or no column.
    Shape {
        /// Values given: observations y ([`solve`]) or regressors row by row ([`solve_rows`]).
        values: usize,
        /// Observations the design has (rows of A, or y's length in [`solve_rows`]).
        rows: usize,
        /// Unknowns (columns of A).
        columns: usize,
    },
    /// Fewer observations than unknowns.
    TooFew {
        /// Observations (rows of A).
        rows: usize,
        /// Unknowns (columns of A).
        columns: usize,
    },
    /// Column `column` is zero for every observation.
    ZeroColumn {
        /// 0-based index of the zero column.
        column: usize,
    },
    /// Column `column` holds a value that is not finite.
    NotFinite {
        /// 0-based index of the column with a NaN or infinite value.
        column: usize,
    },
    /// Column `column` is (to the tolerance) a combination of the columns before it:
    /// the numerical rank is below the number of unknowns. `condition` is the condition
    /// number of the column-scaled design (infinite when exactly singular).
    RankDeficient {
        /// 0-based index of the first column found dependent.
        column: usize,
        /// Numerical rank: the columns independent to the tolerance.
        rank: usize,
        /// Condition number of the column-scaled design (σ_max/σ_min of R).
        condition: f64,
    },
}

impl std::fmt::Display for Refusal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match *self {
            Refusal::Shape { values, rows, columns } => {
                write!(f, "{values} values for a {rows}×{columns} design")
            }
            Refusal::TooFew { rows, columns } => {
                write!(f, "{rows} observations for {columns} unknowns")
            }
            Refusal::ZeroColumn { column } => write!(f, "regressor {column} is zero throughout"),
            Refusal::NotFinite { column } => write!(f, "regressor {column} is not finite"),
            Refusal::RankDeficient { column, rank, condition } => write!(
                f,
                "regressor {column} depends on the others (rank {rank}, condition number {condition:.3e})"
            ),
        }
    }
}

/// A least-squares solution.
#[derive(Debug, Clone)]
pub struct Lstsq {
    /// The coefficients β.
    pub beta: Vec<f64>,
    /// Residual sum of squares ‖y − A·β‖².
    pub rss: f64,
    /// Observations (rows of A).
    pub n: usize,
    /// Condition number of the design with its columns scaled to unit norm (σ_max/σ_min of
    /// R): the factor by which relative errors in y may grow in β, independent of units.
    pub condition: f64,
    /// Column norms of A (the scaling undone in β).
    norms: Vec<f64>,
    /// R⁻¹ of the scaled design.
    r_inv: DMatrix<f64>,
}

impl Lstsq {
    /// Number of unknowns.
    pub fn p(&self) -> usize {
        self.beta.len()
    }

    /// Residual variance σ² = RSS/(n − p); `None` when n = p (no degrees of freedom).
    pub fn sigma2(&self) -> Option<f64> {
        (self.n > self.p()).then(|| self.rss / (self.n - self.p()) as f64)
    }

    /// Standard error of each coefficient, sqrt(diag(σ²·(AᵀA)⁻¹)); `None` when n = p.
    pub fn standard_errors(&self) -> Option<Vec<f64>> {
        let sigma2 = self.sigma2()?;
        let cov = &self.r_inv * self.r_inv.transpose();
        Some(
            (0..self.p())
                .map(|j| (sigma2 * cov[(j, j)]).sqrt() / self.norms[j])
                .collect(),
        )
    }

    /// Covariance σ²·(AᵀA)⁻¹ of the coefficients; `None` when n = p.
    pub fn covariance(&self) -> Option<DMatrix<f64>> {
        let sigma2 = self.sigma2()?;
        let (p, r) = (self.p(), &self.r_inv);
        Some(DMatrix::from_fn(p, p, |i, j| {
            (0..p).map(|k| r[(i, k)] * r[(j, k)]).sum::<f64>() * sigma2
                / (self.norms[i] * self.norms[j])
        }))
    }
}

/// The QR factorization of a design with unit-norm columns, checked for rank.
struct Factored {
    norms: Vec<f64>,
    q: DMatrix<f64>,
    r: DMatrix<f64>,
    condition: f64,
}

/// Factor `a` (n ≥ p, no zero column) with its columns scaled to unit norm, refusing a rank
/// deficiency: a diagonal element of R at or below `rank_tolerance` times the largest.
fn factor(a: &DMatrix<f64>, rank_tolerance: f64) -> Result<Factored, Refusal> {
    let (n, p) = a.shape();
    if n < p {
        return Err(Refusal::TooFew {
            rows: n,
            columns: p,
        });
    }
    let norms: Vec<f64> = (0..p).map(|j| a.column(j).norm()).collect();
    if let Some(column) = norms.iter().position(|&v| !v.is_finite()) {
        return Err(Refusal::NotFinite { column });
    }
    if let Some(column) = norms.iter().position(|&v| v == 0.0) {
        return Err(Refusal::ZeroColumn { column });
    }
    let mut scaled = a.clone();
    for (j, norm) in norms.iter().enumerate() {
        scaled.column_mut(j).scale_mut(1.0 / norm);
    }
    let qr = scaled.qr();
    let r = qr.r();
    let diag: Vec<f64> = (0..p).map(|i| r[(i, i)].abs()).collect();
    let max = diag.iter().cloned().fold(0.0, f64::max);
    let condition = condition_of(&r);
    if let Some(column) = diag.iter().position(|&d| d <= rank_tolerance * max) {
        let rank = diag.iter().filter(|&&d| d > rank_tolerance * max).count();
        return Err(Refusal::RankDeficient {
            column,
            rank,
            condition,
        });
    }
    Ok(Factored {
        norms,
        q: qr.q(),
        r,
        condition,
    })
}

/// The refusal of a triangular solve or inverse that failed after the rank test passed.
fn singular(p: usize) -> Refusal {
    Refusal::RankDeficient {
        column: p - 1,
        rank: p - 1,
        condition: f64::INFINITY,
    }
}

/// Solve `a·β ≈ y` by Householder QR of `a` with its columns scaled to unit norm (so that
/// the rank test does not depend on units). A diagonal element of R at or below
/// `rank_tolerance` times the largest is a rank deficiency: refused, never split arbitrarily.
pub fn solve(a: &DMatrix<f64>, y: &[f64], rank_tolerance: f64) -> Result<Lstsq, Refusal> {
    let (n, p) = a.shape();
    if p == 0 || y.len() != n {
        return Err(Refusal::Shape {
            values: y.len(),
            rows: n,
            columns: p,
        });
    }
    let f = factor(a, rank_tolerance)?;
    let yv = DVector::from_column_slice(y);
    let z =
        f.r.solve_upper_triangular(&(f.q.transpose() * &yv))
            .ok_or(singular(p))?;
    let beta: Vec<f64> = (0..p).map(|j| z[j] / f.norms[j]).collect();
    let rss = (&yv - a * DVector::from_column_slice(&beta)).norm_squared();
    let r_inv = f.r.try_inverse().ok_or(singular(p))?;
    Ok(Lstsq {
        beta,
        rss,
        n,
        condition: f.condition,
        norms: f.norms,
        r_inv,
    })
}

/// The least-squares projection A⁺ = (AᵀA)⁻¹Aᵀ (p × n), so that β = A⁺·y for every y
/// (fixed-design filters such as Savitzky–Golay); by the same QR and rank test as [`solve`].
pub fn projection(a: &DMatrix<f64>, rank_tolerance: f64) -> Result<DMatrix<f64>, Refusal> {
    let p = a.ncols();
    if p == 0 {
        return Err(Refusal::Shape {
            values: 0,
            rows: a.nrows(),
            columns: 0,
        });
    }
    let f = factor(a, rank_tolerance)?;
    let mut pinv = f.r.try_inverse().ok_or(singular(p))? * f.q.transpose();
    for (j, norm) in f.norms.iter().enumerate() {
        pinv.row_mut(j).scale_mut(1.0 / norm);
    }
    Ok(pinv)
}

/// Solve with the design given row by row: `rows` holds `p` regressors per observation.
pub fn solve_rows(
    rows: &[f64],
    p: usize,
    y: &[f64],
    rank_tolerance: f64,
) -> Result<Lstsq, Refusal> {
    if p == 0 || rows.len() != y.len() * p {
        return Err(Refusal::Shape {
            values: rows.len(),
            rows: y.len(),
            columns: p,
        });
    }
    solve(
        &DMatrix::from_row_slice(y.len(), p, rows),
        y,
        rank_tolerance,
    )
}

/// σ_max/σ_min of the (square, upper-triangular) R; infinite when σ_min is zero.
fn condition_of(r: &DMatrix<f64>) -> f64 {
    let s = r.clone().singular_values();
    let (max, min) = (s.max(), s.min());
    if min > 0.0 {
        max / min
    } else {
        f64::INFINITY
    }
}

/// The straight line y = intercept + slope·x through points in the least-squares sense.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Line {
    /// y at x = 0, in y's unit.
    pub intercept: f64,
    /// Change of y per unit of x.
    pub slope: f64,
    /// Root mean square of the residuals (over n, not n − 2).
    pub rms: f64,
}

/// Fit a line; `None` with fewer than two points or when every x is the same.
///
/// Solved in closed form about the mean of x (the normal equations of the centred design are
/// diagonal, so this is as accurate as QR and needs no factorization).
///
/// ```
/// use errmap_core::numeric::lsq::fit_line;
///
/// // y = 1 + 2x with residuals +0.1, −0.2, +0.1 (they sum to zero and are orthogonal to x)
/// let line = fit_line(&[0.0, 1.0, 2.0], &[1.1, 2.8, 5.1]).unwrap();
/// assert!((line.intercept - 1.0).abs() < 1e-12 && (line.slope - 2.0).abs() < 1e-12);
/// assert!((line.rms - (0.06f64 / 3.0).sqrt()).abs() < 1e-12);
/// ```
pub fn fit_line(xs: &[f64], ys: &[f64]) -> Option<Line> {
    let n = xs.len() as f64;
    if xs.len() < 2 || xs.len() != ys.len() {
        return None;
    }
    let mx = xs.iter().sum::<f64>() / n;
    let my = ys.iter().sum::<f64>() / n;
    let sxx: f64 = xs.iter().map(|x| (x - mx).powi(2)).sum();
    if sxx <= 0.0 {
        return None;
    }
    let sxy: f64 = xs.iter().zip(ys).map(|(x, y)| (x - mx) * (y - my)).sum();
    let slope = sxy / sxx;
    let intercept = my - slope * mx;
    let rms = (xs
        .iter()
        .zip(ys)
        .map(|(x, y)| (y - intercept - slope * x).powi(2))
        .sum::<f64>()
        / n)
        .sqrt();
    Some(Line {
        intercept,
        slope,
        rms,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn line_through_exact_points() {
        // y = 3 − 0.5x at x = 1, 2, 4, 7: exact, RSS 0.
        let xs = [1.0, 2.0, 4.0, 7.0];
        let a = DMatrix::from_fn(4, 2, |i, j| if j == 0 { 1.0 } else { xs[i] });
        let y: Vec<f64> = xs.iter().map(|x| 3.0 - 0.5 * x).collect();
        let fit = solve(&a, &y, DEFAULT_RANK_TOLERANCE).unwrap();
        assert!((fit.beta[0] - 3.0).abs() < 1e-13 && (fit.beta[1] + 0.5).abs() < 1e-13);
        assert!(fit.rss < 1e-25);
        assert!(fit.standard_errors().unwrap().iter().all(|&se| se < 1e-13));
        let line = fit_line(&xs, &y).unwrap();
        assert!((line.intercept - 3.0).abs() < 1e-13 && (line.slope + 0.5).abs() < 1e-13);
        assert!(line.rms < 1e-13);
    }

    #[test]
    fn overdetermined_system_with_known_solution() {
        // Columns 1, x, x² at x = −2…2 and residuals r ⟂ every column (r = (1,−4,6,−4,1)/k is
        // the 4th difference, orthogonal to polynomials of degree < 4): β is exact, RSS = ‖r‖².
        let xs: [f64; 5] = [-2.0, -1.0, 0.0, 1.0, 2.0];
        let r = [1.0, -4.0, 6.0, -4.0, 1.0].map(|v| v * 0.01);
        let a = DMatrix::from_fn(5, 3, |i, j| xs[i].powi(j as i32));
        let y: Vec<f64> = (0..5)
            .map(|i| 2.0 + 0.25 * xs[i] - 1.5 * xs[i] * xs[i] + r[i])
            .collect();
        let fit = solve(&a, &y, DEFAULT_RANK_TOLERANCE).unwrap();
        for (b, want) in fit.beta.iter().zip([2.0, 0.25, -1.5]) {
            assert!((b - want).abs() < 1e-13, "{b} vs {want}");
        }
        let rss: f64 = r.iter().map(|v| v * v).sum();
        assert!((fit.rss - rss).abs() < 1e-15);
        // σ² = RSS/(5 − 3); (AᵀA)⁻¹ of this design by hand: AᵀA = [[5,0,10],[0,10,0],[10,0,34]],
        // so Var(β₁) = σ²/10 and Var(β₂) = σ²·5/(5·34 − 100) = σ²/14.
        let sigma2 = rss / 2.0;
        let se = fit.standard_errors().unwrap();
        assert!((se[1] - (sigma2 / 10.0).sqrt()).abs() < 1e-15);
        assert!((se[2] - (sigma2 / 14.0).sqrt()).abs() < 1e-15);
        let cov = fit.covariance().unwrap();
        // Cov(β₀, β₂) = −10σ²/70.
        assert!((cov[(0, 2)] + 10.0 * sigma2 / 70.0).abs() < 1e-15);
        assert!((cov[(0, 2)] - cov[(2, 0)]).abs() < 1e-18);
        // Unit-norm columns of this design are well conditioned.
        assert!(
            fit.condition > 1.0 && fit.condition < 10.0,
            "{}",
            fit.condition
        );
    }

    #[test]
    fn rank_deficient_design_is_reported() {
        // Third column = first + 2·second: rank 2 of 3.
        let a = DMatrix::from_row_slice(
            4,
            3,
            &[
                1.0, 0.0, 1.0, //
                1.0, 1.0, 3.0, //
                1.0, 2.0, 5.0, //
                1.0, 3.0, 7.0,
            ],
        );
        match solve(&a, &[1.0, 2.0, 3.0, 5.0], DEFAULT_RANK_TOLERANCE) {
            Err(Refusal::RankDeficient {
                column,
                rank,
                condition,
            }) => {
                assert_eq!((column, rank), (2, 2));
                assert!(condition > 1e12, "{condition}");
            }
            other => panic!("expected a rank deficiency, got {other:?}"),
        }
        let zero = DMatrix::from_row_slice(3, 2, &[1.0, 0.0, 2.0, 0.0, 3.0, 0.0]);
        assert_eq!(
            solve(&zero, &[1.0, 2.0, 3.0], 1e-10).unwrap_err(),
            Refusal::ZeroColumn { column: 1 }
        );
        let few = DMatrix::from_row_slice(1, 2, &[1.0, 2.0]);
        assert_eq!(
            solve(&few, &[1.0], 1e-10).unwrap_err(),
            Refusal::TooFew {
                rows: 1,
                columns: 2
            }
        );
        assert!(fit_line(&[2.0, 2.0, 2.0], &[1.0, 2.0, 3.0]).is_none());
        let err = Refusal::RankDeficient {
            column: 2,
            rank: 2,
            condition: f64::INFINITY,
        };
        assert!(
            err.to_string().contains("depends on the others (rank 2"),
            "{err}"
        );
    }

    #[test]
    fn projection_gives_the_savitzky_golay_weights() {
        // Quadratic through 5 equally spaced samples: the smoothed centre value has the
        // published weights (−3, 12, 17, 12, −3)/35 (Savitzky & Golay 1964, table I).
        let a = DMatrix::from_fn(5, 3, |i, j| (i as f64 - 2.0).powi(j as i32));
        let p = projection(&a, DEFAULT_RANK_TOLERANCE).unwrap();
        for (w, want) in p.row(0).iter().zip([-3.0, 12.0, 17.0, 12.0, -3.0]) {
            assert!((w - want / 35.0).abs() < 1e-15, "{w} vs {want}/35");
        }
        // The slope row: (−2, −1, 0, 1, 2)/10.
        for (w, want) in p.row(1).iter().zip([-2.0, -1.0, 0.0, 1.0, 2.0]) {
            assert!((w - want / 10.0).abs() < 1e-15, "{w} vs {want}/10");
        }
        let dependent = DMatrix::from_fn(4, 2, |i, _| i as f64 + 1.0);
        assert!(matches!(
            projection(&dependent, DEFAULT_RANK_TOLERANCE),
            Err(Refusal::RankDeficient { rank: 1, .. })
        ));
    }

    #[test]
    fn exactly_determined_system_has_no_standard_errors() {
        let a = DMatrix::from_row_slice(2, 2, &[2.0, 1.0, 1.0, 3.0]);
        let fit = solve_rows(&[2.0, 1.0, 1.0, 3.0], 2, &[3.0, 5.0], 1e-10).unwrap();
        // 2a + b = 3, a + 3b = 5 → a = 0.8, b = 1.4.
        assert!((fit.beta[0] - 0.8).abs() < 1e-14 && (fit.beta[1] - 1.4).abs() < 1e-14);
        assert!(fit.standard_errors().is_none() && fit.covariance().is_none());
        assert_eq!(
            solve(&a, &[1.0], 1e-10).unwrap_err(),
            Refusal::Shape {
                values: 1,
                rows: 2,
                columns: 2
            }
        );
    }
}
