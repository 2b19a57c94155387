//! Exact minimum zone of radial deviations (the limaçon form): min over (a, b) of max − min of rᵢ − a·cos θᵢ − b·sin θᵢ, solved as a linear programme by the revised simplex method on its dual.
//!
//! Primal, in (a, b, u, l): minimise u − l subject to l ≤ rᵢ − a·cᵢ − b·sᵢ ≤ u for every i
//! (cᵢ = cos θᵢ, sᵢ = sin θᵢ). Its dual has one weight λᵢ ≥ 0 per upper and μᵢ ≥ 0 per lower
//! constraint and four equality rows: Σλᵢcᵢ = Σμᵢcᵢ, Σλᵢsᵢ = Σμᵢsᵢ, Σλᵢ = 1, Σμᵢ = 1; it
//! maximises Σrᵢ(λᵢ − μᵢ). A basis has four columns, so the optimum rests on at most four
//! readings (the outer and inner contact points of the zone). The simplex multipliers of the
//! optimal basis are the primal (a, b, u, l), and the width is recomputed from them directly.

use nalgebra::{Matrix4, Vector4};

/// The minimum zone of a set of radial deviations.
#[derive(Debug, Clone, PartialEq)]
pub struct Zone {
    /// Width of the zone: max − min of the shifted deviations (G).
    pub width_um: f64,
    /// Centre shift (a, b) that gives the zone, in the units of the deviations.
    pub shift_um: [f64; 2],
    /// Largest shifted deviation: the outer circle's radius minus the nominal one.
    pub outer_um: f64,
    /// Smallest shifted deviation: the inner circle's radius minus the nominal one.
    pub inner_um: f64,
    /// Readings that touch the zone: (index, true when on the outer circle).
    pub contacts: Vec<(usize, bool)>,
}

/// Minimum zone of deviations `r_um` at angles `angle_rad`. Empty input gives a zero zone.
pub fn min_zone(r_um: &[f64], angle_rad: &[f64]) -> Zone {
    let n = r_um.len().min(angle_rad.len());
    if n == 0 {
        return Zone {
            width_um: 0.0,
            shift_um: [0.0, 0.0],
            outer_um: 0.0,
            inner_um: 0.0,
            contacts: Vec::new(),
        };
    }
    let cs: Vec<(f64, f64)> = angle_rad[..n].iter().map(|a| (a.cos(), a.sin())).collect();
    let lp = DualLp {
        r: &r_um[..n],
        cs: &cs,
    };
    let shift = lp.solve();
    let shifted: Vec<f64> = (0..n)
        .map(|i| r_um[i] - shift[0] * cs[i].0 - shift[1] * cs[i].1)
        .collect();
    let outer = shifted.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    let inner = shifted.iter().cloned().fold(f64::INFINITY, f64::min);
    let tol = 1e-9 * (1.0 + outer.abs().max(inner.abs()));
    let contacts = shifted
        .iter()
        .enumerate()
        .filter_map(|(i, &v)| {
            if outer - v <= tol {
                Some((i, true))
            } else if v - inner <= tol {
                Some((i, false))
            } else {
                None
            }
        })
        .collect();
    Zone {
        width_um: outer - inner,
        shift_um: shift,
        outer_um: outer,
        inner_um: inner,
        contacts,
    }
}

/// The dual programme in standard form: minimise cᵀz, A·z = (0, 0, 1, 1), z ≥ 0, with
/// columns j < n for λⱼ and n ≤ j < 2n for μⱼ₋ₙ, and two artificial columns 2n, 2n + 1.
struct DualLp<'a> {
    r: &'a [f64],
    cs: &'a [(f64, f64)],
}

impl DualLp<'_> {
    fn n(&self) -> usize {
        self.r.len()
    }
    fn column(&self, j: usize) -> Vector4<f64> {
        let n = self.n();
        if j < n {
            let (c, s) = self.cs[j];
            Vector4::new(c, s, 1.0, 0.0)
        } else if j < 2 * n {
            let (c, s) = self.cs[j - n];
            Vector4::new(-c, -s, 0.0, 1.0)
        } else {
            let mut e = Vector4::zeros();
            e[j - 2 * n] = 1.0;
            e
        }
    }
    /// Cost of a column: the dual maximises Σ r(λ − μ), so the minimised cost is −r for λ, +r for μ.
    fn cost(&self, j: usize) -> f64 {
        let n = self.n();
        if j < n {
            -self.r[j]
        } else if j < 2 * n {
            self.r[j - n]
        } else {
            0.0
        }
    }

    fn inverse(&self, basis: &[usize; 4]) -> Option<Matrix4<f64>> {
        let b = Matrix4::from_columns(&basis.map(|j| self.column(j)));
        b.try_inverse()
    }

    /// Pricing: the column with the most negative reduced cost, or with `bland` the first one
    /// (Bland's rule, which cannot cycle, after many degenerate steps). `None` at the optimum.
    fn entering(
        &self,
        basis: &[usize; 4],
        y: &Vector4<f64>,
        tol: f64,
        bland: bool,
    ) -> Option<usize> {
        let mut entering: Option<(usize, f64)> = None;
        for j in 0..2 * self.n() {
            if basis.contains(&j) {
                continue;
            }
            let d = self.cost(j) - y.dot(&self.column(j));
            if d < -tol {
                if bland {
                    return Some(j);
                }
                if entering.is_none_or(|(_, best)| d < best) {
                    entering = Some((j, d));
                }
            }
        }
        entering.map(|e| e.0)
    }

    /// Run the simplex method; returns the primal shift (a, b).
    fn solve(&self) -> [f64; 2] {
        let n = self.n();
        let rhs = Vector4::new(0.0, 0.0, 1.0, 1.0);
        let scale = 1.0 + self.r.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        let tol = 1e-11 * scale;
        // Feasible start: λ₀ = μ₀ = 1 with the two artificial columns at zero level.
        let mut basis = [2 * n, 2 * n + 1, 0, n];
        let mut binv = self.inverse(&basis).unwrap_or_else(Matrix4::identity);
        // Drive the artificial columns out of the basis with degenerate pivots.
        for pos in 0..2 {
            let row = binv.row(pos).clone_owned();
            let best = (0..2 * n)
                .filter(|j| !basis.contains(j))
                .map(|j| (j, (row * self.column(j))[0].abs()))
                .max_by(|a, b| a.1.total_cmp(&b.1));
            if let Some((j, v)) = best {
                if v > 1e-9 {
                    let mut trial = basis;
                    trial[pos] = j;
                    if let Some(inv) = self.inverse(&trial) {
                        basis = trial;
                        binv = inv;
                    }
                }
            }
        }
        let mut degenerate_run = 0usize;
        for _ in 0..(100 * n + 1000) {
            let x = binv * rhs;
            let cb = Vector4::from_fn(|k, _| self.cost(basis[k]));
            let y = binv.transpose() * cb;
            let Some(j) = self.entering(&basis, &y, tol, degenerate_run > 50) else {
                return [-y[0], -y[1]];
            };
            let u = binv * self.column(j);
            let leave = leaving(&basis, &x, &u);
            // Unbounded cannot happen (the primal is feasible); stop with the current multipliers.
            let Some((k, ratio)) = leave else {
                return [-y[0], -y[1]];
            };
            degenerate_run = if ratio <= 1e-15 {
                degenerate_run + 1
            } else {
                0
            };
            let mut trial = basis;
            trial[k] = j;
            match self.inverse(&trial) {
                Some(inv) => {
                    basis = trial;
                    binv = inv;
                }
                None => return [-y[0], -y[1]],
            }
        }
        let cb = Vector4::from_fn(|k, _| self.cost(basis[k]));
        let y = binv.transpose() * cb;
        [-y[0], -y[1]]
    }
}

/// Ratio test: the basis position that leaves (smallest x/u over u > 0, ties to the smallest
/// column index) and its ratio; `None` when no entry of u is positive.
fn leaving(basis: &[usize; 4], x: &Vector4<f64>, u: &Vector4<f64>) -> Option<(usize, f64)> {
    let mut leave: Option<(usize, f64)> = None;
    for k in 0..4 {
        if u[k] > 1e-12 {
            let ratio = x[k].max(0.0) / u[k];
            let better = match leave {
                None => true,
                Some((kk, best)) => {
                    ratio < best - 1e-15 || (ratio <= best + 1e-15 && basis[k] < basis[kk])
                }
            };
            if better {
                leave = Some((k, ratio));
            }
        }
    }
    leave
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pure_offset_has_zero_width() {
        let ang: Vec<f64> = (0..36).map(|i| (i as f64 * 10.0).to_radians()).collect();
        let r: Vec<f64> = ang
            .iter()
            .map(|a| 3.0 + 7.0 * a.cos() - 4.0 * a.sin())
            .collect();
        let z = min_zone(&r, &ang);
        assert!(z.width_um.abs() < 1e-9, "{z:?}");
        assert!((z.shift_um[0] - 7.0).abs() < 1e-9 && (z.shift_um[1] + 4.0).abs() < 1e-9);
    }

    #[test]
    fn an_ellipse_has_its_peak_to_peak_width() {
        let ang: Vec<f64> = (0..360).map(|i| (i as f64).to_radians()).collect();
        let r: Vec<f64> = ang
            .iter()
            .map(|a| 2.5 * (2.0 * a).sin() + 1.0 * a.cos())
            .collect();
        let z = min_zone(&r, &ang);
        assert!((z.width_um - 5.0).abs() < 1e-9, "{z:?}");
    }
}
