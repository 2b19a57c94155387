//! u(E), the standard uncertainty of a delivered map at every grid node: the local kriging's σ_K (or the map's distance to the kriging, when larger) scaled by one calibration factor per part chosen on cross-validation folds, stored in `model.json`, and the field that leaves nodes with u above a bound nominal.
//!
//! The shape of u comes from the kriging variance ([`crate::interp::local`]): it grows away
//! from the probes and with the noise the likelihood finds. Where the delivered map (a network)
//! stands further from the kriging's mean E_K than σ_K, that distance counts instead:
//! `u = c·max(σ_K, |E_map − E_K|)`.
//!
//! Two steps make u calibrated rather than merely shaped:
//!
//! - **The likelihood's own maximum** ([`refined_parameters`]). The kriging's search
//!   ([`crate::interp::kriging`]) tries the nugget g in decades and refines once by ×3, so
//!   the noise it implies, s = √(g·σ²), lands up to some 30 % off the likelihood's maximum
//!   (0.78–1.20 µm for parts of 1 µm noise). σ_K depends on g, so the calibration continues
//!   the search (a pattern search on ln ℓ and ln g, steps √2 down to 2^(1/16)) for the local
//!   kriging that u uses; the delivered map and its kriging are not touched.
//! - **One scale for the whole predictive variance** ([`likelihood_factor`]). The clean points
//!   are split into [`FOLDS`] seeded folds, each fold predicted by the local kriging of the
//!   others, and c maximises the likelihood of the misses r_i ~ N(0, c²·(σ_K,i² + s²)): c
//!   rescales the process variance σ², of which both σ_K² and the nugget's s² = g·σ² are
//!   parts (the cross-validation estimate of a Gaussian process's variance, Bachoc 2013,
//!   *Comput. Stat. Data Anal.* 66, 55–69). An earlier form, r_i ~ N(0, c²·σ_K,i² + s²) with s
//!   held fixed, set c against the noise: at 1–3 µm of noise the misses are mostly noise, so
//!   c absorbed every error of s (c from 0.70 to 1.38 on parts where σ_K alone was right to
//!   some 10 %) and the family coverage of 2u ranged 92.6–97.7 % over 4 seeds × 2 noise
//!   levels. The scale of the whole variance is fixed by ~140 misses to about 1/√(2n) ≈ 6 %
//!   (c 0.95–1.04 on the same parts, coverage 93.7–96.7 %; docs/job.md has the table).
//!   A log-normal prior of width [`PRIOR_WIDTH`] about c = 1 (the likelihood fit's own scale)
//!   only matters for parts with few points.

use crate::interp::kriging::profile;
use crate::interp::local::{LocalKriging, Parameters, SUBSAMPLE};
use crate::interp::Grid;
use errmap_core::error::{Error, Result};
use errmap_core::geom::{Axis, ErrorField};
use nalgebra::DMatrix;
use rand::seq::SliceRandom;
use rand::SeedableRng;
use serde::{Deserialize, Serialize};

/// Cross-validation folds of the calibration.
pub const FOLDS: usize = 10;

/// Most points the folds predict (a seeded share of each fold, in the shuffled order): c is
/// one number, and 20,000 misses fix it far more closely than its prior; a dense scan of 10⁶
/// points would otherwise spend most of its time here.
pub const MAX_FOLD_PREDICTIONS: usize = 20_000;

/// Width (standard deviation of ln c) of the prior about c = 1.
pub const PRIOR_WIDTH: f64 = 0.5;

/// Step factors on ℓ and g of [`refined_parameters`]' pattern search, coarse to fine.
const REFINE_STEPS: [f64; 4] = [
    std::f64::consts::SQRT_2,
    1.189_207_115_002_721,   // 2^(1/4)
    1.090_507_732_665_257_7, // 2^(1/8)
    1.044_273_782_427_413_8, // 2^(1/16)
];

/// Moves at one step size before the search takes the next.
const REFINE_MOVES: usize = 8;

/// The calibration of one part: the fitted covariance, the factor and the folds' figures.
#[derive(Debug, Clone)]
pub struct Calibration {
    /// The local kriging of every clean point (σ_K anywhere), with the refined parameters.
    pub kriging: LocalKriging,
    /// c: u = c·σ_K for the kriging.
    pub factor: f64,
    /// The folds' misses r_i: held-out measured E − the fold's prediction, µm.
    pub misses_um: Vec<f64>,
    /// σ_K,i of each fold prediction, in the order of `misses_um`, µm.
    pub sd_um: Vec<f64>,
}

/// The c of largest posterior density given the misses r_i ~ N(0, c²·(σ_i² + s²)) and the
/// prior ln c ~ N(0, [`PRIOR_WIDTH`]²): golden-section search of ln c over [ln 0.1, ln 10].
/// Without the prior c² would be the mean of r_i² / (σ_i² + s²).
pub fn likelihood_factor(misses_um: &[f64], sd_um: &[f64], noise_um: f64) -> Option<f64> {
    if misses_um.is_empty() {
        return None;
    }
    let s2 = noise_um * noise_um;
    let nll = |log_c: f64| -> f64 {
        let c2 = (2.0 * log_c).exp();
        (log_c / PRIOR_WIDTH).powi(2)
            + misses_um
                .iter()
                .zip(sd_um)
                .map(|(r, s)| {
                    let v = (c2 * (s * s + s2)).max(1e-30);
                    v.ln() + r * r / v
                })
                .sum::<f64>()
    };
    let (mut a, mut b) = (0.1f64.ln(), 10f64.ln());
    let g = (5f64.sqrt() - 1.0) / 2.0;
    for _ in 0..80 {
        let (x1, x2) = (b - g * (b - a), a + g * (b - a));
        if nll(x1) <= nll(x2) {
            b = x2;
        } else {
            a = x1;
        }
    }
    Some((0.5 * (a + b)).exp())
}

/// The parameters of largest profiled likelihood near `start` (the kriging's grid search), on
/// the same subsample as [`Parameters::fit`]: a pattern search over ln ℓ and ln g (the best of
/// the 8 neighbours at factors `REFINE_STEPS`, up to `REFINE_MOVES` moves per step),
/// within the grid's own range (ℓ from 1 % to 200 % of the sites' diagonal, g from 1e-6 to
/// 1). `start` is kept when no neighbour improves it.
pub fn refined_parameters(points_uve: &[[f64; 3]], start: Parameters) -> Parameters {
    let stride = points_uve.len().div_ceil(SUBSAMPLE).max(1);
    let sub: Vec<[f64; 3]> = points_uve.iter().step_by(stride).copied().collect();
    let n = sub.len();
    let distances = DMatrix::from_fn(n, n, |i, j| {
        (sub[i][0] - sub[j][0]).hypot(sub[i][1] - sub[j][1])
    });
    let e: Vec<f64> = sub.iter().map(|p| p[2]).collect();
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in &sub {
        for k in 0..2 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let diag = (hi[0] - lo[0]).hypot(hi[1] - lo[1]);
    if diag.is_nan() || diag <= 0.0 {
        return start;
    }
    let eval = |l: f64, g: f64| profile(&distances, &e, l, g).map(|(nll, _, var, _)| (nll, var));
    let Some((mut best, _)) = eval(start.length_mm, start.nugget_ratio) else {
        return start;
    };
    let mut at = start;
    for step in REFINE_STEPS {
        for _ in 0..REFINE_MOVES {
            let mut next: Option<(f64, Parameters)> = None;
            for fl in [1.0 / step, 1.0, step] {
                for fg in [1.0 / step, 1.0, step] {
                    let l = (at.length_mm * fl).clamp(0.01 * diag, 2.0 * diag);
                    let g = (at.nugget_ratio * fg).clamp(1e-6, 1.0);
                    if (l, g) == (at.length_mm, at.nugget_ratio) {
                        continue;
                    }
                    if let Some((nll, var)) = eval(l, g) {
                        if nll < next.map_or(best, |b| b.0) {
                            let p = Parameters {
                                length_mm: l,
                                nugget_ratio: g,
                                variance_um2: var,
                            };
                            next = Some((nll, p));
                        }
                    }
                }
            }
            match next {
                Some((nll, p)) => (best, at) = (nll, p),
                None => break,
            }
        }
    }
    at
}

/// Calibrate the local kriging of `points_uve` on [`FOLDS`] folds drawn with `seed`.
pub fn calibrate(points_uve: &[[f64; 3]], seed: u64) -> Result<Calibration> {
    let parameters = refined_parameters(points_uve, Parameters::fit(points_uve)?);
    let kriging = LocalKriging::with_parameters(points_uve, parameters)?;
    let n = points_uve.len();
    let mut order: Vec<usize> = (0..n).collect();
    order.shuffle(&mut rand_chacha::ChaCha8Rng::seed_from_u64(seed));
    let folds = FOLDS.min(n / 4).max(2);
    let mut fold_of = vec![0usize; n];
    // Points past the first MAX_FOLD_PREDICTIONS of the shuffled order are in every fold's
    // `rest` and predicted by none (usize::MAX is no fold).
    for (pos, &i) in order.iter().enumerate() {
        fold_of[i] = if pos < MAX_FOLD_PREDICTIONS {
            pos % folds
        } else {
            usize::MAX
        };
    }
    let (mut misses_um, mut sd_um) = (Vec::with_capacity(n), Vec::with_capacity(n));
    for f in 0..folds {
        let rest: Vec<[f64; 3]> = (0..n)
            .filter(|&i| fold_of[i] != f)
            .map(|i| points_uve[i])
            .collect();
        let held: Vec<usize> = (0..n).filter(|&i| fold_of[i] == f).collect();
        if rest.len() < 3 || held.is_empty() {
            continue;
        }
        let fold = LocalKriging::with_parameters(&rest, kriging.parameters)?;
        let at: Vec<[f64; 2]> = held
            .iter()
            .map(|&i| [points_uve[i][0], points_uve[i][1]])
            .collect();
        for (&i, p) in held.iter().zip(fold.predict_many(&at)) {
            if let Some(p) = p {
                misses_um.push(points_uve[i][2] - p.e_um);
                sd_um.push(p.sd_um);
            }
        }
    }
    let factor =
        likelihood_factor(&misses_um, &sd_um, kriging.parameters.noise_um()).ok_or_else(|| {
            Error::numeric(
                "no cross-validation fold could be predicted to calibrate the uncertainty",
                "probe more points, spread over the part",
            )
        })?;
    Ok(Calibration {
        kriging,
        factor,
        misses_um,
        sd_um,
    })
}

/// A map's u(E) on its grid, as `model.json` keeps it (`uncertainty`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Uncertainty {
    /// How u was made, in words (`local-kriging-cv`, or `family` for a family map).
    pub method: String,
    /// The grid of `u_um` (node (i, j) at (u0 + i·step, v0 + j·step), u fastest).
    pub grid: Grid,
    /// u(E) per node, µm. Written as one line of JSON (`one_line`); read as any JSON list,
    /// so files written one number per line (errmap before this form) read as before.
    #[serde(serialize_with = "one_line")]
    pub u_um: Vec<f64>,
    /// The calibration factor c (u = c·σ_K); absent for a family map.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub factor: Option<f64>,
    /// The probe noise s the nugget stands for, µm; absent for a family map.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub noise_um: Option<f64>,
}

/// Numbers as one line of JSON inside an indented `model.json`: one node per line (14 bytes
/// of indent, digits and newline each) made u most of the file, about twice the bytes of the
/// list itself. The numbers are serde_json's own (shortest round-trip) text, as before.
fn one_line<S: serde::Serializer>(
    values: &[f64],
    serializer: S,
) -> std::result::Result<S::Ok, S::Error> {
    use serde::ser::Error as _;
    let text = serde_json::to_string(values).map_err(S::Error::custom)?;
    let raw = serde_json::value::RawValue::from_string(text).map_err(S::Error::custom)?;
    raw.serialize(serializer)
}

impl Uncertainty {
    /// Consistency of a record read from a file (the message says what is wrong).
    pub fn validate(&self) -> std::result::Result<(), String> {
        let g = &self.grid;
        if g.nu == 0 || g.nv == 0 || g.nu.checked_mul(g.nv) != Some(self.u_um.len()) {
            return Err(format!(
                "uncertainty has {} values for a {} × {} grid",
                self.u_um.len(),
                g.nu,
                g.nv
            ));
        }
        if !(g.step_mm.is_finite() && g.step_mm > 0.0 && g.u0_mm.is_finite() && g.v0_mm.is_finite())
            || self.u_um.iter().any(|u| !(u.is_finite() && *u >= 0.0))
        {
            return Err("uncertainty holds a non-finite number, a negative u or a step ≤ 0".into());
        }
        Ok(())
    }

    /// u at (u, v): the largest u of the nodes of the grid cell holding the point (a node's
    /// own value on a node); `None` outside the grid.
    pub fn at_um(&self, u_mm: f64, v_mm: f64) -> Option<f64> {
        let g = &self.grid;
        let fu = (u_mm - g.u0_mm) / g.step_mm;
        let fv = (v_mm - g.v0_mm) / g.step_mm;
        let tol = 1e-9;
        if !(fu >= -tol
            && fv >= -tol
            && fu <= (g.nu - 1) as f64 + tol
            && fv <= (g.nv - 1) as f64 + tol)
        {
            return None;
        }
        let span = |f: f64, n: usize| {
            let near = f.round();
            if (f - near).abs() <= tol {
                let k = (near.max(0.0) as usize).min(n - 1);
                (k, k)
            } else {
                let lo = (f.floor().max(0.0) as usize).min(n - 1);
                (lo, (lo + 1).min(n - 1))
            }
        };
        let (i0, i1) = span(fu, g.nu);
        let (j0, j1) = span(fv, g.nv);
        let mut worst = 0.0_f64;
        for j in [j0, j1] {
            for i in [i0, i1] {
                worst = worst.max(self.u_um[j * g.nu + i]);
            }
        }
        Some(worst)
    }
}

/// Median and largest of u over the nodes not flagged (`skip`: e.g. the extrapolated ones), µm.
pub fn median_max_um(u_um: &[f64], skip: &[bool]) -> Option<(f64, f64)> {
    let mut kept: Vec<f64> = u_um
        .iter()
        .zip(skip.iter().chain(std::iter::repeat(&false)))
        .filter(|(_, &s)| !s)
        .map(|(&u, _)| u)
        .collect();
    if kept.is_empty() {
        return None;
    }
    kept.sort_by(f64::total_cmp);
    let n = kept.len();
    let median = if n % 2 == 1 {
        kept[n / 2]
    } else {
        0.5 * (kept[n / 2 - 1] + kept[n / 2])
    };
    Some((median, kept[n - 1]))
}

/// A map whose nodes with u(E) above `max_um` are left out as points outside its domain are:
/// there E is `None` (the point is left nominal, whatever `--extrapolate` says) and
/// [`ErrorField::withheld`] says why, for the compensation's `moves_uncertain` count.
pub struct Bounded<'a> {
    /// The delivered map whose E is bounded.
    pub field: &'a dyn ErrorField,
    /// Its u(E) grid.
    pub uncertainty: &'a Uncertainty,
    /// Largest u(E) still trusted, µm (`--max-uncertainty-um`).
    pub max_um: f64,
}

impl Bounded<'_> {
    fn trusted(&self, u_mm: f64, v_mm: f64) -> bool {
        self.uncertainty
            .at_um(u_mm, v_mm)
            .is_some_and(|u| u <= self.max_um)
    }
}

impl ErrorField for Bounded<'_> {
    fn normal(&self) -> Axis {
        self.field.normal()
    }
    fn error_mm(&self, u_mm: f64, v_mm: f64) -> Option<f64> {
        if self.trusted(u_mm, v_mm) {
            self.field.error_mm(u_mm, v_mm)
        } else {
            None
        }
    }
    fn measured(&self, u_mm: f64, v_mm: f64, margin_mm: f64) -> Option<bool> {
        // The domain stays the probes' hull: an untrusted point is withheld by `error_mm`, so
        // a compensation can tell the two reasons apart.
        self.field.measured(u_mm, v_mm, margin_mm)
    }
    fn withheld(&self, u_mm: f64, v_mm: f64) -> bool {
        !self.trusted(u_mm, v_mm) && self.field.error_mm(u_mm, v_mm).is_some()
    }
    fn surface_mm(&self) -> Option<(f64, f64)> {
        self.field.surface_mm()
    }
}

/// Check a `--max-uncertainty-um` value: a finite number ≥ 0.
pub fn validate_max_uncertainty(max_um: f64, flag: &str) -> Result<()> {
    if max_um.is_finite() && max_um >= 0.0 {
        return Ok(());
    }
    Err(Error::usage(
        format!("{flag} {max_um} is not a number ≥ 0 (µm)"),
        format!("give {flag} a bound in µm, e.g. 2.5"),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn likelihood_factor_by_hand() {
        // Noise-free misses (s = 0) of σ_i = 1: the posterior's −2·log density is
        // n·ln c² + Σr²/c² + (ln c / w)²; at ln c = x its derivative is
        // 2n − 2Σr²·e^(−2x) + 2x/w². With r = ±2 (Σr² = 4n), n = 100, w = 0.5 the root is
        // found here by bisection, independently of the golden sections.
        let n = 100usize;
        let misses: Vec<f64> = (0..n)
            .map(|k| if k % 2 == 0 { 2.0 } else { -2.0 })
            .collect();
        let sd = vec![1.0; n];
        let g = |x: f64| 2.0 * n as f64 - 8.0 * n as f64 * (-2.0 * x).exp() + 2.0 * x / 0.25;
        let want = root_by_bisection(g, 0.0, 2.0).exp();
        let got = likelihood_factor(&misses, &sd, 0.0).unwrap();
        assert!((got - want).abs() < 1e-6, "{got} vs {want}");
        // Without the prior it would be exactly 2; the prior pulls it a little towards 1.
        assert!(got < 2.0 && got > 1.95, "{got}");
        assert_eq!(likelihood_factor(&[], &[], 1.0), None);
    }

    /// The root of an increasing `g` in `[lo, hi]`, by 200 halvings (an independent solve of the
    /// likelihood's stationarity condition).
    fn root_by_bisection(g: impl Fn(f64) -> f64, mut lo: f64, mut hi: f64) -> f64 {
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if g(mid) > 0.0 {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        0.5 * (lo + hi)
    }

    #[test]
    fn likelihood_factor_scales_the_noise_with_the_kriging_variance() {
        // r = ±3, σ_i = 1, s = 2: the misses' variance model is c²·(1 + 4) = 5c², so without the
        // prior c² = 9/5. With it, −2·log density at ln c = x is
        // n·(ln 5 + 2x) + 9n·e^(−2x)/5 + (x/w)², of derivative 2n − 18n·e^(−2x)/5 + 2x/w²,
        // whose root is found by bisection.
        let n = 50usize;
        let misses: Vec<f64> = (0..n)
            .map(|k| if k % 2 == 0 { 3.0 } else { -3.0 })
            .collect();
        let sd = vec![1.0; n];
        let nf = n as f64;
        let g = |x: f64| 2.0 * nf - 18.0 * nf * (-2.0 * x).exp() / 5.0 + 2.0 * x / 0.25;
        let want = root_by_bisection(g, 0.0, 2.0).exp();
        let got = likelihood_factor(&misses, &sd, 2.0).unwrap();
        assert!((got - want).abs() < 1e-6, "{got} vs {want}");
        // Close to √(9/5) = 1.342, a little towards 1; holding s fixed instead would have
        // given c² = 9 − 4 = 5 (c = 2.24).
        assert!(got < 1.8f64.sqrt() && got > 1.3, "{got}");
    }

    #[test]
    fn refined_parameters_reach_the_likelihood_maximum_of_a_brute_force_grid() {
        // 60 sites (10 × 6, 20 mm pitch), a smooth field plus a fixed pseudo-random ±1.7 µm
        // (uniform, σ ≈ 1 µm). The search must not end worse than the kriging's grid, and no
        // node of a 41 × 41 grid over ℓ and g (factor 2 either way of its answer, steps of
        // 2^(1/20)) may have a profiled likelihood better than it by more than 0.01.
        let mut x = 0.37f64;
        let mut points = Vec::new();
        for j in 0..6 {
            for i in 0..10 {
                x = (x * 3.987 * (1.0 - x)).clamp(1e-6, 1.0 - 1e-6);
                let (u, v) = (i as f64 * 20.0, j as f64 * 20.0);
                let e = 10.0 * (u / 60.0).sin() * (v / 40.0).cos() + (x - 0.5) * 3.4;
                points.push([u, v, e]);
            }
        }
        let start = Parameters::fit(&points).unwrap();
        let got = refined_parameters(&points, start);
        let n = points.len();
        let d = DMatrix::from_fn(n, n, |i, j| {
            (points[i][0] - points[j][0]).hypot(points[i][1] - points[j][1])
        });
        let e: Vec<f64> = points.iter().map(|p| p[2]).collect();
        let nll = |l: f64, g: f64| profile(&d, &e, l, g).map(|p| p.0);
        let at = nll(got.length_mm, got.nugget_ratio).unwrap();
        assert!(at <= nll(start.length_mm, start.nugget_ratio).unwrap() + 1e-12);
        let (_, _, var, _) = profile(&d, &e, got.length_mm, got.nugget_ratio).unwrap();
        assert!((got.variance_um2 - var).abs() <= 1e-9 * var);
        let mut best = f64::INFINITY;
        for a in -20..=20 {
            for b in -20..=20 {
                let l = got.length_mm * 2f64.powf(a as f64 / 20.0);
                let g = (got.nugget_ratio * 2f64.powf(b as f64 / 20.0)).min(1.0);
                if let Some(v) = nll(l, g) {
                    best = best.min(v);
                }
            }
        }
        assert!(at <= best + 0.01, "search {at}, grid {best}: {got:?}");
    }

    fn hand_made() -> Uncertainty {
        // 3 × 2 nodes, step 10: u = 1 2 3 / 4 5 9 µm.
        Uncertainty {
            method: "test".into(),
            grid: Grid {
                u0_mm: 0.0,
                v0_mm: 0.0,
                step_mm: 10.0,
                nu: 3,
                nv: 2,
            },
            u_um: vec![1.0, 2.0, 3.0, 4.0, 5.0, 9.0],
            factor: None,
            noise_um: None,
        }
    }

    #[test]
    fn u_at_a_point_is_the_worst_node_of_its_cell() {
        let u = hand_made();
        assert_eq!(u.at_um(0.0, 0.0), Some(1.0));
        assert_eq!(u.at_um(20.0, 10.0), Some(9.0));
        assert_eq!(u.at_um(10.0, 0.0), Some(2.0));
        assert_eq!(u.at_um(5.0, 5.0), Some(5.0));
        assert_eq!(u.at_um(15.0, 5.0), Some(9.0));
        assert_eq!(u.at_um(5.0, 0.0), Some(2.0));
        assert_eq!(u.at_um(-0.1, 0.0), None);
        assert_eq!(u.at_um(20.0, 10.1), None);
        assert!(u.validate().is_ok());
        let mut bad = hand_made();
        bad.u_um.pop();
        assert!(bad
            .validate()
            .unwrap_err()
            .contains("5 values for a 3 × 2 grid"));
    }

    #[test]
    fn u_is_written_on_one_line_and_older_files_read_as_before() {
        let u = hand_made();
        let text = serde_json::to_string_pretty(&u).unwrap();
        assert!(
            text.contains("\"u_um\": [1.0,2.0,3.0,4.0,5.0,9.0]"),
            "{text}"
        );
        let back: Uncertainty = serde_json::from_str(&text).unwrap();
        assert_eq!(back, u);
        // As errmap wrote it before: one number per line.
        let older = r#"{
          "method": "test",
          "grid": {"u0_mm": 0.0, "v0_mm": 0.0, "step_mm": 10.0, "nu": 3, "nv": 2},
          "u_um": [
            1.0,
            2.0,
            3.0,
            4.0,
            5.0,
            9.0
          ]
        }"#;
        assert_eq!(serde_json::from_str::<Uncertainty>(older).unwrap(), u);
    }

    #[test]
    fn median_and_max_skip_flagged_nodes() {
        let u = [1.0, 7.0, 3.0, 2.0, 100.0];
        assert_eq!(
            median_max_um(&u, &[false, false, false, false, true]),
            Some((2.5, 7.0))
        );
        assert_eq!(median_max_um(&u, &[]), Some((3.0, 100.0)));
        assert_eq!(median_max_um(&u, &[true; 5]), None);
    }
}
