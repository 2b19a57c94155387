//! Local ordinary kriging: the posterior mean and standard deviation of the noise-free surface at any point from its k nearest sites, with Matérn 5/2 + nugget parameters fitted by likelihood on a subsample, so it costs O(n log n + nodes·k³) at any size.
//!
//! The model is [`kriging`](super::kriging)'s: `e(p) = μ + f(p) + ε`, f of covariance
//! `σ²·m(r/ℓ)`, ε of variance `σ²·g`. ℓ, g and σ² maximise the profiled likelihood on at most
//! [`SUBSAMPLE`] sites (every ⌈n/SUBSAMPLE⌉-th of the file order, which spreads over a raster
//! or a scan). At a point p the [`NEIGHBOURS`] nearest sites give the ordinary-kriging weights w
//! and Lagrange multiplier λ of `R·w + λ·1 = r`, `1ᵀw = 1` (R the sites' correlations with the
//! nugget, r the point's correlations with the sites), and the variance of the error of
//! `wᵀe` as an estimate of the noise-free `μ + f(p)`:
//!
//! ```text
//! σ_K²(p) = σ²·(1 − wᵀr − λ)
//! ```
//!
//! (Cressie 1993, *Statistics for Spatial Data*, §3.2, eq. 3.2.16, with the nugget on the data
//! and not on the predicted value). σ_K grows away from the sites and with the nugget.

use super::kriging::{matern52, Kriging};
use errmap_core::error::{Error, Result};
use nalgebra::{DMatrix, DVector};

/// Most sites the likelihood search takes (it is O(n³) per trial).
pub const SUBSAMPLE: usize = 200;

/// Sites each prediction uses.
pub const NEIGHBOURS: usize = 40;

/// The covariance model's parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Parameters {
    /// Correlation length ℓ, mm.
    pub length_mm: f64,
    /// Nugget g as a share of the process variance.
    pub nugget_ratio: f64,
    /// Process variance σ², µm².
    pub variance_um2: f64,
}

impl Parameters {
    /// Maximum-likelihood parameters of `points_uve` (u mm, v mm, e µm), on a subsample of at
    /// most [`SUBSAMPLE`] sites.
    pub fn fit(points_uve: &[[f64; 3]]) -> Result<Parameters> {
        let stride = points_uve.len().div_ceil(SUBSAMPLE).max(1);
        let sub: Vec<[f64; 3]> = points_uve.iter().step_by(stride).copied().collect();
        let k = Kriging::fit(&sub)?;
        Ok(Parameters {
            length_mm: k.length_mm,
            nugget_ratio: k.nugget_ratio,
            variance_um2: k.variance,
        })
    }

    /// Standard deviation of the noise the nugget stands for, µm.
    pub fn noise_um(&self) -> f64 {
        (self.variance_um2 * self.nugget_ratio).sqrt()
    }
}

/// Sites sorted into square cells, for nearest-neighbour queries.
#[derive(Debug, Clone)]
struct Cells {
    u0: f64,
    v0: f64,
    cell: f64,
    nu: usize,
    nv: usize,
    /// Cell c holds `items[start[c]..start[c + 1]]`.
    start: Vec<usize>,
    items: Vec<usize>,
}

impl Cells {
    fn new(sites: &[[f64; 2]]) -> Cells {
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for s in sites {
            for k in 0..2 {
                lo[k] = lo[k].min(s[k]);
                hi[k] = hi[k].max(s[k]);
            }
        }
        let (w, h) = (hi[0] - lo[0], hi[1] - lo[1]);
        let n = sites.len().max(1) as f64;
        // About two sites per cell; a line of sites gets cells along it.
        let cell = (2.0 * w * h / n)
            .sqrt()
            .max(w.max(h) / n)
            .max(1e-9 * (1.0 + w.max(h)));
        let nu = ((w / cell).floor() as usize + 1).min(1 << 12);
        let nv = ((h / cell).floor() as usize + 1).min(1 << 12);
        let index = |s: &[f64; 2]| {
            let i = (((s[0] - lo[0]) / cell) as usize).min(nu - 1);
            let j = (((s[1] - lo[1]) / cell) as usize).min(nv - 1);
            j * nu + i
        };
        let mut count = vec![0usize; nu * nv + 1];
        for s in sites {
            count[index(s) + 1] += 1;
        }
        for c in 1..count.len() {
            count[c] += count[c - 1];
        }
        let mut fill = count.clone();
        let mut items = vec![0usize; sites.len()];
        for (k, s) in sites.iter().enumerate() {
            let c = index(s);
            items[fill[c]] = k;
            fill[c] += 1;
        }
        Cells {
            u0: lo[0],
            v0: lo[1],
            cell,
            nu,
            nv,
            start: count,
            items,
        }
    }

    /// The `k` sites nearest to p as (squared distance, index), nearest first.
    fn nearest(&self, sites: &[[f64; 2]], p: [f64; 2], k: usize, out: &mut Vec<(f64, usize)>) {
        out.clear();
        let fu = (p[0] - self.u0) / self.cell;
        let fv = (p[1] - self.v0) / self.cell;
        let ci = (fu.max(0.0) as usize).min(self.nu - 1) as isize;
        let cj = (fv.max(0.0) as usize).min(self.nv - 1) as isize;
        // How far p lies outside its (clamped) cell, which weakens the ring bound.
        let out_u = (fu - ci as f64).max(ci as f64 + 1.0 - fu).max(1.0) - 1.0;
        let out_v = (fv - cj as f64).max(cj as f64 + 1.0 - fv).max(1.0) - 1.0;
        let slack = out_u.hypot(out_v) * self.cell;
        let rings = self.nu.max(self.nv) as isize;
        for r in 0..=rings {
            for j in cj - r..=cj + r {
                if j < 0 || j >= self.nv as isize {
                    continue;
                }
                let edge = j == cj - r || j == cj + r;
                let step = if edge { 1 } else { (2 * r).max(1) };
                let mut i = ci - r;
                while i <= ci + r {
                    if i >= 0 && i < self.nu as isize {
                        let c = j as usize * self.nu + i as usize;
                        for &s in &self.items[self.start[c]..self.start[c + 1]] {
                            let d2 = (sites[s][0] - p[0]).powi(2) + (sites[s][1] - p[1]).powi(2);
                            out.push((d2, s));
                        }
                    }
                    i += step;
                }
            }
            // Every site not yet seen is at least r cells (less the slack) away.
            if out.len() >= k {
                let bound = (r as f64 * self.cell - slack).max(0.0);
                out.select_nth_unstable_by(k - 1, |a, b| a.0.total_cmp(&b.0));
                if out[k - 1].0 <= bound * bound {
                    break;
                }
            }
        }
        let k = k.min(out.len());
        if k > 0 && k < out.len() {
            out.select_nth_unstable_by(k - 1, |a, b| a.0.total_cmp(&b.0));
        }
        out.truncate(k);
        out.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    }
}

/// Sites, values and parameters, ready to predict anywhere.
#[derive(Debug, Clone)]
pub struct LocalKriging {
    sites: Vec<[f64; 2]>,
    values: Vec<f64>,
    /// The Matérn 5/2 + nugget parameters fitted by likelihood on a subsample.
    pub parameters: Parameters,
    cells: Cells,
}

/// One prediction: the posterior mean and the standard deviation σ_K of its error as an
/// estimate of the noise-free surface, µm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Prediction {
    /// Kriged E at the point, µm (measured − nominal).
    pub e_um: f64,
    /// σ_K: standard deviation of the kriged E about the noise-free surface, µm.
    pub sd_um: f64,
}

impl LocalKriging {
    /// Fit the parameters by likelihood ([`Parameters::fit`]) and keep every site.
    pub fn fit(points_uve: &[[f64; 3]]) -> Result<LocalKriging> {
        let parameters = Parameters::fit(points_uve)?;
        LocalKriging::with_parameters(points_uve, parameters)
    }

    /// Keep the sites with given parameters (a cross-validation fold reuses the part's).
    pub fn with_parameters(
        points_uve: &[[f64; 3]],
        parameters: Parameters,
    ) -> Result<LocalKriging> {
        if points_uve.len() < 3 || points_uve.iter().flatten().any(|v| !v.is_finite()) {
            return Err(Error::numeric(
                format!(
                    "local kriging needs at least 3 finite points, got {}",
                    points_uve.len()
                ),
                "probe more points",
            ));
        }
        let sites: Vec<[f64; 2]> = points_uve.iter().map(|p| [p[0], p[1]]).collect();
        let cells = Cells::new(&sites);
        Ok(LocalKriging {
            values: points_uve.iter().map(|p| p[2]).collect(),
            sites,
            parameters,
            cells,
        })
    }

    /// The prediction at (u, v) from the [`NEIGHBOURS`] nearest sites; `None` when their
    /// system is singular (repeated sites without a nugget).
    pub fn predict(&self, u_mm: f64, v_mm: f64) -> Option<Prediction> {
        let mut near = Vec::new();
        self.predict_with(u_mm, v_mm, &mut near)
    }

    /// [`LocalKriging::predict`] with a caller's buffer (no allocation per point for it).
    fn predict_with(
        &self,
        u_mm: f64,
        v_mm: f64,
        near: &mut Vec<(f64, usize)>,
    ) -> Option<Prediction> {
        let Parameters {
            length_mm: l,
            nugget_ratio: g,
            variance_um2: var,
        } = self.parameters;
        self.cells
            .nearest(&self.sites, [u_mm, v_mm], NEIGHBOURS, near);
        let k = near.len();
        let mut r_mat = DMatrix::zeros(k, k);
        for a in 0..k {
            r_mat[(a, a)] = 1.0 + g;
            let sa = self.sites[near[a].1];
            for b in a + 1..k {
                let sb = self.sites[near[b].1];
                let c = matern52((sa[0] - sb[0]).hypot(sa[1] - sb[1]), l);
                r_mat[(a, b)] = c;
                r_mat[(b, a)] = c;
            }
        }
        let r = DVector::from_iterator(k, near.iter().map(|&(d2, _)| matern52(d2.sqrt(), l)));
        let chol = r_mat.cholesky()?;
        let a = chol.solve(&r);
        let b = chol.solve(&DVector::from_element(k, 1.0));
        let lambda = (a.sum() - 1.0) / b.sum();
        let w = &a - &b * lambda;
        let e_um: f64 = w
            .iter()
            .zip(near.iter())
            .map(|(wi, &(_, s))| wi * self.values[s])
            .sum();
        let sd2 = var * (1.0 - w.dot(&r) - lambda);
        (e_um.is_finite() && sd2.is_finite()).then(|| Prediction {
            e_um,
            sd_um: sd2.max(0.0).sqrt(),
        })
    }

    /// The sites `(u_mm, v_mm, e_um)` it predicts from.
    pub fn sites_uve(&self) -> Vec<[f64; 3]> {
        self.sites
            .iter()
            .zip(&self.values)
            .map(|(s, &e)| [s[0], s[1], e])
            .collect()
    }

    /// Predictions at many points (rayon); `None` where a system is singular.
    pub fn predict_many(&self, points_uv: &[[f64; 2]]) -> Vec<Option<Prediction>> {
        use rayon::prelude::*;
        points_uv
            .par_chunks(256)
            .flat_map_iter(|chunk| {
                let mut near = Vec::with_capacity(4 * NEIGHBOURS);
                chunk
                    .iter()
                    .map(|p| self.predict_with(p[0], p[1], &mut near))
                    .collect::<Vec<_>>()
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_sites_match_a_full_sort() {
        // Scattered sites (a fixed pseudo-random sequence) and query points inside and outside.
        let mut x = 0.5f64;
        let mut next = || {
            x = (x * 3.987 * (1.0 - x)).clamp(1e-6, 1.0 - 1e-6);
            x
        };
        let sites: Vec<[f64; 2]> = (0..500).map(|_| [next() * 300.0, next() * 100.0]).collect();
        let cells = Cells::new(&sites);
        let mut out = Vec::new();
        for p in [[10.0, 10.0], [150.0, 50.0], [-80.0, 300.0], [299.0, 0.0]] {
            cells.nearest(&sites, p, 40, &mut out);
            let mut all: Vec<(f64, usize)> = sites
                .iter()
                .enumerate()
                .map(|(k, s)| ((s[0] - p[0]).powi(2) + (s[1] - p[1]).powi(2), k))
                .collect();
            all.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            assert_eq!(out, all[..40].to_vec(), "at {p:?}");
        }
    }

    #[test]
    fn a_stored_local_kriging_predicts_as_the_fitted_one() {
        // 300 sites of a smooth field: the model written to JSON and read back (cells rebuilt)
        // predicts bit for bit what the fitted kriging predicts, and a damaged one is refused.
        let pts: Vec<[f64; 3]> = (0..300)
            .map(|k| {
                let (u, v) = (
                    (k % 20) as f64 * 7.0 + (k / 20) as f64 * 0.3,
                    (k / 20) as f64 * 9.0,
                );
                [u, v, (u / 30.0).sin() * 5.0 + v * 0.02]
            })
            .collect();
        let fitted = LocalKriging::fit(&pts).unwrap();
        let json = serde_json::to_string(&LocalKrigingModel::of(&fitted)).unwrap();
        let back: LocalKrigingModel = serde_json::from_str(&json).unwrap();
        assert_eq!(back, LocalKrigingModel::of(&fitted));
        back.validate().unwrap();
        for p in [[10.0, 10.0], [70.5, 33.3], [131.0, 120.0]] {
            let want = fitted.predict(p[0], p[1]).unwrap().e_um;
            assert_eq!(
                back.predict(p[0], p[1]).to_bits(),
                want.to_bits(),
                "at {p:?}"
            );
        }
        let mut bad = back.clone();
        bad.length_mm = 0.0;
        assert!(bad.validate().is_err());
    }

    #[test]
    fn one_site_system_has_the_closed_form() {
        // Three sites at one spot, p far (≫ ℓ) away: r = 0 and R = J + g·I (J all ones), so
        // R⁻¹1 = 1/(3 + g), λ = −1/(1ᵀR⁻¹1) = −(3 + g)/3, w = 1/3 each and
        // σ_K² = σ²·(1 − 0 − λ) = σ²·(1 + (3 + g)/3); the value is the sites' mean.
        let pts = [[0.0, 0.0, 1.0], [0.0, 0.0, 2.0], [0.0, 0.0, 3.0]];
        let p = Parameters {
            length_mm: 1.0,
            nugget_ratio: 0.5,
            variance_um2: 4.0,
        };
        let k = LocalKriging::with_parameters(&pts, p).unwrap();
        let got = k.predict(1000.0, 0.0).unwrap();
        assert!((got.e_um - 2.0).abs() < 1e-12);
        let want = (4.0 * (1.0 + (3.0 + 0.5) / 3.0_f64)).sqrt();
        assert!((got.sd_um - want).abs() < 1e-9, "{} vs {want}", got.sd_um);
        // At a site, without nugget, the noise-free value is known: σ_K → 0.
        let exact = LocalKriging::with_parameters(
            &[[0.0, 0.0, 1.0], [10.0, 0.0, 2.0], [0.0, 10.0, 3.0]],
            Parameters {
                nugget_ratio: 0.0,
                ..p
            },
        )
        .unwrap();
        let at = exact.predict(10.0, 0.0).unwrap();
        assert!((at.e_um - 2.0).abs() < 1e-9 && at.sd_um < 1e-6, "{at:?}");
    }
}

/// A local kriging as `model.json` stores it when it is the delivered map: its sites and
/// parameters (the nearest-site cells are rebuilt on first use).
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LocalKrigingModel {
    /// The sites `(u_mm, v_mm, e_um)`.
    pub sites_uve: Vec<[f64; 3]>,
    /// Correlation length ℓ, mm.
    pub length_mm: f64,
    /// Nugget g as a share of the process variance.
    pub nugget_ratio: f64,
    /// Process variance σ², µm².
    pub variance_um2: f64,
    #[serde(skip)]
    fitted: std::sync::OnceLock<Option<LocalKriging>>,
}

impl PartialEq for LocalKrigingModel {
    fn eq(&self, other: &Self) -> bool {
        self.sites_uve == other.sites_uve
            && self.length_mm == other.length_mm
            && self.nugget_ratio == other.nugget_ratio
            && self.variance_um2 == other.variance_um2
    }
}

impl LocalKrigingModel {
    /// The model of a fitted local kriging.
    pub fn of(k: &LocalKriging) -> LocalKrigingModel {
        LocalKrigingModel {
            sites_uve: k.sites_uve(),
            length_mm: k.parameters.length_mm,
            nugget_ratio: k.parameters.nugget_ratio,
            variance_um2: k.parameters.variance_um2,
            fitted: std::sync::OnceLock::from(Some(k.clone())),
        }
    }

    /// The local kriging, built on first use; `None` when the stored sites cannot be kriged.
    pub fn kriging(&self) -> Option<&LocalKriging> {
        self.fitted
            .get_or_init(|| {
                let parameters = Parameters {
                    length_mm: self.length_mm,
                    nugget_ratio: self.nugget_ratio,
                    variance_um2: self.variance_um2,
                };
                LocalKriging::with_parameters(&self.sites_uve, parameters).ok()
            })
            .as_ref()
    }

    /// E at (u, v), µm; NaN where it cannot be predicted.
    pub fn predict(&self, u_mm: f64, v_mm: f64) -> f64 {
        self.kriging()
            .and_then(|k| k.predict(u_mm, v_mm))
            .map_or(f64::NAN, |q| q.e_um)
    }

    /// Consistency of a model read from a file (the message says what is wrong).
    pub fn validate(&self) -> std::result::Result<(), String> {
        let finite = self.sites_uve.iter().flatten().all(|v| v.is_finite())
            && [self.length_mm, self.nugget_ratio, self.variance_um2]
                .iter()
                .all(|v| v.is_finite());
        if self.sites_uve.len() < 3 || !finite || self.length_mm <= 0.0 || self.nugget_ratio < 0.0 {
            return Err(
                "local kriging needs at least 3 finite sites, a length > 0 and a nugget ≥ 0".into(),
            );
        }
        Ok(())
    }
}
