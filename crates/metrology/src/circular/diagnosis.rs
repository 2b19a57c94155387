//! Diagnosis of a circular test: the model of [`super::model`] fitted by least squares to the deviations about the least-squares centre, with spike decays and cyclic periods found by search, and each term's value, standard error and share of G.

use super::figures::Centred;
use super::model::{Column, Shape};
use super::zone::min_zone;
use crate::Setting;
use errmap_core::error::{Error, Result};
use errmap_core::setting::words;
use nalgebra::{DMatrix, DVector};
use serde::Serialize;
use std::f64::consts::PI;

/// One diagnosed term.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Term {
    /// Value in the term's unit; `None` where the data cannot give it (see `note`).
    pub value: Option<f64>,
    /// Standard error from the least-squares covariance (for a given decay or period).
    pub stderr: Option<f64>,
    /// Minimum-zone width of this term's modelled contribution alone, µm.
    pub g_alone_um: Option<f64>,
    /// `g_alone_um` / G (bidirectional G when both directions exist).
    pub share_of_g: Option<f64>,
    /// Cyclic terms: the period found in the data.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub period_mm: Option<f64>,
    /// Reversal spikes: the decay length along the path found in the data.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub decay_mm: Option<f64>,
    /// Why the value is missing (one direction only, no feed, sampling too coarse, not in the
    /// model); absent when there is a value.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
}

impl Term {
    fn missing(note: impl Into<String>) -> Term {
        Term {
            value: None,
            stderr: None,
            g_alone_um: None,
            share_of_g: None,
            period_mm: None,
            decay_mm: None,
            note: Some(note.into()),
        }
    }
}

/// The terms of the model, keyed as `errmap circular --json` prints them.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Terms {
    /// Squareness S of the two axes, µm/m: positive when the angle between +first and +second
    /// motion exceeds 90°.
    pub squareness_um_per_m: Term,
    /// Scale mismatch M = s₁ − s₂ of the axes' scale errors (e₁ = s₁·x, e₂ = s₂·y), µm/m: positive
    /// when the first axis travels farther per commanded length than the second.
    pub scale_mismatch_um_per_m: Term,
    /// Backlash b₁ of the first axis, µm: the axis lags b₁/2 behind its command in the direction of
    /// motion, so the radius steps out by b₁ at its reversals (ψ = 0°, 180°); negative when
    /// over-compensated.
    pub backlash_first_um: Term,
    /// Backlash b₂ of the second axis, µm, as for the first, at its reversals (ψ = 90°, 270°).
    pub backlash_second_um: Term,
    /// Height h₁ of the first axis' reversal spike, µm: an outward error h₁·exp(−s/λ) along the
    /// path s after the axis reverses; λ in `decay_mm`.
    pub reversal_spike_first_um: Term,
    /// Height h₂ of the second axis' reversal spike, µm; λ in `decay_mm`.
    pub reversal_spike_second_um: Term,
    /// Servo mismatch Δτ = τ₁ − τ₂ of the axes' lags, ms: positive when the first axis lags more.
    /// Needs both directions and the feed (without it, `model.servo_amplitude_um` only).
    pub servo_mismatch_ms: Term,
    /// Amplitude A₁ of the first axis' cyclic error e₁ = A₁·sin(2π·x/P₁ + φ₁), µm; P₁ in
    /// `period_mm`.
    pub cyclic_first_um: Term,
    /// Amplitude A₂ of the second axis' cyclic error e₂ = A₂·sin(2π·y/P₂ + φ₂), µm; P₂ in
    /// `period_mm`.
    pub cyclic_second_um: Term,
}

impl Terms {
    /// (key, term) in the printed order.
    pub fn list(&self) -> [(&'static str, &Term); 9] {
        [
            ("squareness_um_per_m", &self.squareness_um_per_m),
            ("scale_mismatch_um_per_m", &self.scale_mismatch_um_per_m),
            ("backlash_first_um", &self.backlash_first_um),
            ("backlash_second_um", &self.backlash_second_um),
            ("reversal_spike_first_um", &self.reversal_spike_first_um),
            ("reversal_spike_second_um", &self.reversal_spike_second_um),
            ("servo_mismatch_ms", &self.servo_mismatch_ms),
            ("cyclic_first_um", &self.cyclic_first_um),
            ("cyclic_second_um", &self.cyclic_second_um),
        ]
    }
}

/// What else the fit found: nuisance values and the ranking of the terms.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ModelInfo {
    /// The programmed feed given, mm/min; `None`: not given, so no servo mismatch in ms.
    pub feed_mm_per_min: Option<f64>,
    /// The constant of the model (mean radius about the least-squares centre), µm.
    pub constant_um: f64,
    /// Centre terms refitted with the other terms, µm (near zero: the data are centred).
    pub centre_um: [f64; 2],
    /// Servo mismatch as a radial amplitude (µm) before conversion to ms.
    pub servo_amplitude_um: Option<f64>,
    /// Keys of the terms with the widest contribution, widest first (share ≥ 5 %).
    pub largest: Vec<String>,
    /// Number of readings fitted (both directions together).
    pub observations: usize,
    /// Number of coefficients of the linear least-squares fit (9 to 14 columns).
    pub unknowns: usize,
}

/// Result of [`diagnose`].
#[derive(Debug, Clone, PartialEq)]
pub struct Diagnosis {
    /// Each diagnosed term: value, standard error and share of G.
    pub terms: Terms,
    /// Root mean square of the deviations minus the fitted model, µm.
    pub residual_rms_um: f64,
    /// The nuisance values, the size of the fit and the ranking of the terms.
    pub model: ModelInfo,
    /// The modelled deviation at each reading (same order as the input).
    pub fitted_um: Vec<f64>,
}

/// Least-squares solution with its covariance.
struct Fit {
    beta: Vec<f64>,
    cov: DMatrix<f64>,
    rss: f64,
}

struct Data<'a> {
    psi: &'a [f64],
    sigma: Vec<f64>,
    y: &'a [f64],
}

fn design(data: &Data, shape: &Shape, cols: &[Column]) -> DMatrix<f64> {
    DMatrix::from_fn(data.y.len(), cols.len(), |i, j| {
        shape.value(cols[j], data.psi[i], data.sigma[i])
    })
}

/// Least squares by the shared QR solver; `None` when the design is rank deficient or
/// leaves no degree of freedom.
fn lstsq(a: &DMatrix<f64>, y: &[f64]) -> Option<Fit> {
    if a.nrows() <= a.ncols() {
        return None;
    }
    let fit = errmap_core::numeric::lsq::solve(a, y, 1e-9).ok()?;
    Some(Fit {
        cov: fit.covariance()?,
        beta: fit.beta,
        rss: fit.rss,
    })
}

/// The model with some columns left out, factored once, so that the residual sum of squares
/// with candidate columns added costs one projection (partial regression).
struct Profile {
    q: DMatrix<f64>,
    resid: DVector<f64>,
    rss: f64,
}

impl Profile {
    fn new(data: &Data, shape: &Shape, leave_out: &[Column]) -> Profile {
        let cols: Vec<Column> = shape
            .columns()
            .into_iter()
            .filter(|c| !leave_out.contains(c))
            .collect();
        let q = design(data, shape, &cols).qr().q();
        let y = DVector::from_column_slice(data.y);
        let resid = &y - &q * (q.transpose() * &y);
        let rss = resid.norm_squared();
        Profile { q, resid, rss }
    }

    /// Residual sum of squares with the columns `g` (n × k) added.
    fn rss_with(&self, g: &DMatrix<f64>) -> f64 {
        let g_perp = g - &self.q * (self.q.transpose() * g);
        let m = g_perp.transpose() * &g_perp;
        let b = g_perp.transpose() * &self.resid;
        match m.clone().cholesky() {
            Some(ch) => self.rss - b.dot(&ch.solve(&b)),
            None => self.rss,
        }
    }
}

fn columns_of(data: &Data, shape: &Shape, cols: &[Column]) -> DMatrix<f64> {
    design(data, shape, cols)
}

/// Golden-section minimum of `f` on [a, b].
fn golden(mut a: f64, mut b: f64, iters: usize, f: impl Fn(f64) -> f64) -> f64 {
    let g = (5f64.sqrt() - 1.0) / 2.0;
    let (mut x1, mut x2) = (b - g * (b - a), a + g * (b - a));
    let (mut f1, mut f2) = (f(x1), f(x2));
    for _ in 0..iters {
        if f1 <= f2 {
            b = x2;
            (x2, f2) = (x1, f1);
            x1 = b - g * (b - a);
            f1 = f(x1);
        } else {
            a = x1;
            (x1, f1) = (x2, f2);
            x2 = a + g * (b - a);
            f2 = f(x2);
        }
    }
    if f1 <= f2 {
        x1
    } else {
        x2
    }
}

/// Search ranges of the nonlinear settings, from the radius and the sampling.
struct Ranges {
    decay_mm: (f64, f64),
    /// Spatial frequency of the cyclic error (1/mm); `None` when sampling is too coarse.
    freq_per_mm: Option<(f64, f64)>,
}

fn ranges(c: &Centred, radius_mm: f64) -> Ranges {
    let mut steps = Vec::new();
    for d in [super::Rotation::Ccw, super::Rotation::Cw] {
        let mut a: Vec<f64> = c.of(d).iter().map(|&i| c.nominal_angle_rad[i]).collect();
        a.sort_by(f64::total_cmp);
        steps.extend(a.windows(2).map(|w| w[1] - w[0]));
    }
    steps.sort_by(f64::total_cmp);
    let step = steps
        .get(steps.len() / 2)
        .copied()
        .unwrap_or(0.01)
        .max(1e-6);
    let lo = (radius_mm * step).max(1e-3);
    let hi = (radius_mm * PI / 12.0).max(2.0 * lo);
    // Periods from R/2 down to 2.5 reading spacings along the axis, and not below 1 mm
    // (screw leads; a scale's µm-long period is beyond any circular test).
    let (f_lo, f_hi) = (2.0 / radius_mm, (1.0 / (2.5 * radius_mm * step)).min(1.0));
    Ranges {
        decay_mm: (lo, hi),
        freq_per_mm: (f_hi > 1.5 * f_lo).then_some((f_lo, f_hi)),
    }
}

fn cyclic_pair(axis: usize) -> [Column; 2] {
    if axis == 0 {
        [Column::CyclicFirstSin, Column::CyclicFirstCos]
    } else {
        [Column::CyclicSecondSin, Column::CyclicSecondCos]
    }
}

/// Coarse scan of one axis' cyclic error over spatial frequency: the best 2-column fit of the
/// residual of the model without this axis' cyclic term.
fn scan_frequency(data: &Data, shape: &Shape, axis: usize, f_range: (f64, f64)) -> f64 {
    let prof = Profile::new(data, shape, &cyclic_pair(axis));
    let r = shape.radius_mm;
    // Position along the axis (relative) and the radial projection of an axis error.
    let (pos, proj): (Vec<f64>, Vec<f64>) = data
        .psi
        .iter()
        .map(|p| {
            if axis == 0 {
                (r * p.cos(), p.cos())
            } else {
                (r * p.sin(), p.sin())
            }
        })
        .unzip();
    let df = 1.0 / (8.0 * r);
    let (mut best_f, mut best_gain) = (f_range.0, -1.0);
    let mut f = f_range.0;
    while f <= f_range.1 {
        let (mut g11, mut g12, mut g22, mut b1, mut b2) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for i in 0..pos.len() {
            let (s, c) = (std::f64::consts::TAU * f * pos[i]).sin_cos();
            let (u, v) = (proj[i] * s, proj[i] * c);
            g11 += u * u;
            g12 += u * v;
            g22 += v * v;
            b1 += u * prof.resid[i];
            b2 += v * prof.resid[i];
        }
        let det = g11 * g22 - g12 * g12;
        if det > 0.0 {
            let gain = (g22 * b1 * b1 - 2.0 * g12 * b1 * b2 + g11 * b2 * b2) / det;
            if gain > best_gain {
                (best_f, best_gain) = (f, gain);
            }
        }
        f += df;
    }
    best_f
}

/// Refine one axis' cyclic frequency within ±`half_width` on the full model's residual sum of squares.
fn refine_frequency(
    data: &Data,
    shape: &Shape,
    axis: usize,
    f0: f64,
    half_width: f64,
    f_range: (f64, f64),
) -> f64 {
    let pair = cyclic_pair(axis);
    let prof = Profile::new(data, shape, &pair);
    let lo = (f0 - half_width).max(f_range.0);
    let hi = (f0 + half_width).min(f_range.1);
    golden(lo, hi, 30, |f| {
        let mut s = *shape;
        s.cyclic_period_mm[axis] = Some(1.0 / f);
        prof.rss_with(&columns_of(data, &s, &pair))
    })
}

/// Best spike decay length of one axis: a log-spaced scan, refined by golden section.
fn best_decay(data: &Data, shape: &Shape, axis: usize, range: (f64, f64)) -> f64 {
    let col = [if axis == 0 {
        Column::SpikeFirst
    } else {
        Column::SpikeSecond
    }];
    let prof = Profile::new(data, shape, &col);
    let eval = |log_lambda: f64| {
        let mut s = *shape;
        s.spike_decay_mm[axis] = log_lambda.exp();
        prof.rss_with(&columns_of(data, &s, &col))
    };
    let (l0, l1) = (range.0.ln(), range.1.ln());
    const N: usize = 24;
    let grid: Vec<f64> = (0..N)
        .map(|k| l0 + (l1 - l0) * k as f64 / (N - 1) as f64)
        .collect();
    let values: Vec<f64> = grid.iter().map(|&l| eval(l)).collect();
    let k = (0..N)
        .min_by(|&a, &b| values[a].total_cmp(&values[b]))
        .unwrap_or(0);
    let lo = grid[k.saturating_sub(1)];
    let hi = grid[(k + 1).min(N - 1)];
    golden(lo, hi, 30, eval).exp()
}

/// Search the nonlinear settings: cyclic frequencies (scan, then refinement), spike decays,
/// and the play of a positive backlash (its estimate), alternating for three rounds.
fn search_shape(data: &Data, shape: &mut Shape, rg: &Ranges) {
    let df = 1.0 / (8.0 * shape.radius_mm);
    for round in 0..3 {
        if let Some(fr) = rg.freq_per_mm {
            for axis in 0..2 {
                let f0 = match (round, shape.cyclic_period_mm[axis]) {
                    (0, _) | (_, None) => scan_frequency(data, shape, axis, fr),
                    (_, Some(p)) => 1.0 / p,
                };
                shape.cyclic_period_mm[axis] =
                    Some(1.0 / refine_frequency(data, shape, axis, f0, df, fr));
            }
        }
        for axis in 0..2 {
            shape.spike_decay_mm[axis] = best_decay(data, shape, axis, rg.decay_mm);
        }
        update_play(data, shape, rg);
    }
}

/// Shape each axis' backlash from the data: an ideal step (play 0), or lost motion whose
/// play is the current positive estimate, whichever leaves the smaller residual.
fn update_play(data: &Data, shape: &mut Shape, rg: &Ranges) {
    for (axis, col) in [(0, Column::BacklashFirst), (1, Column::BacklashSecond)] {
        let cols = shape.columns();
        let Some(j) = cols.iter().position(|&c| c == col) else {
            continue;
        };
        let Some(fit) = lstsq(&design(data, shape, &cols), data.y) else {
            continue;
        };
        let play_mm = (fit.beta[j] * 1e-3).max(0.0);
        // Each candidate with the spike decay of the same axis found again: a spike can mimic
        // part of the ramp, so the two are judged together.
        let candidate = |play: f64| {
            let mut s = *shape;
            s.backlash_play_mm[axis] = play;
            s.spike_decay_mm[axis] = best_decay(data, &s, axis, rg.decay_mm);
            let cols = s.columns();
            let rss = lstsq(&design(data, &s, &cols), data.y).map_or(f64::INFINITY, |f| f.rss);
            (rss, s)
        };
        let step = candidate(0.0);
        *shape = if play_mm > 0.0 {
            let ramp = candidate(play_mm);
            if ramp.0 < step.0 {
                ramp.1
            } else {
                step.1
            }
        } else {
            step.1
        };
    }
}

/// Replace the covariance of a fit by the one of the whole nonlinear problem: the Jacobian
/// gets one more column per searched setting (spike decays, the play of a ramped backlash, cyclic periods), the derivative of
/// the modelled deviation by central differences, so that the standard errors of the
/// coefficients include what the uncertainty of a decay or period does to them.
fn with_nonlinear_covariance(data: &Data, shape: &Shape, cols: &[Column], fit: Fit) -> Fit {
    let beta = DVector::from_column_slice(&fit.beta);
    let predict = |s: &Shape| design(data, s, cols) * &beta;
    let mut extra: Vec<DVector<f64>> = Vec::new();
    for axis in 0..2 {
        let lambda = shape.spike_decay_mm[axis];
        let (mut lo, mut hi) = (*shape, *shape);
        lo.spike_decay_mm[axis] = lambda * (1.0 - 1e-4);
        hi.spike_decay_mm[axis] = lambda * (1.0 + 1e-4);
        extra.push((predict(&hi) - predict(&lo)) / (2e-4 * lambda));
        let play = shape.backlash_play_mm[axis];
        if play > 0.0 {
            let (mut lo, mut hi) = (*shape, *shape);
            lo.backlash_play_mm[axis] = play * (1.0 - 1e-4);
            hi.backlash_play_mm[axis] = play * (1.0 + 1e-4);
            extra.push((predict(&hi) - predict(&lo)) / (2e-4 * play));
        }
        if let Some(p) = shape.cyclic_period_mm[axis] {
            let (mut lo, mut hi) = (*shape, *shape);
            lo.cyclic_period_mm[axis] = Some(p * (1.0 - 1e-6));
            hi.cyclic_period_mm[axis] = Some(p * (1.0 + 1e-6));
            extra.push((predict(&hi) - predict(&lo)) / (2e-6 * p));
        }
    }
    let a = design(data, shape, cols);
    let p = cols.len();
    let mut aug = DMatrix::zeros(a.nrows(), p + extra.len());
    aug.columns_mut(0, p).copy_from(&a);
    for (k, col) in extra.iter().enumerate() {
        aug.set_column(p + k, col);
    }
    match lstsq(&aug, data.y) {
        Some(full) => Fit {
            cov: full.cov.view((0, 0), (p, p)).into_owned(),
            ..fit
        },
        // A setting with no effect (a zero spike leaves its decay free): keep the linear covariance.
        None => fit,
    }
}

/// Fit the diagnosis model to deviations about the least-squares centre.
///
/// `g_ref_um` is the G the shares refer to. Servo mismatch needs both directions, and
/// `feed_mm_per_min` to be given in ms.
pub fn diagnose(
    c: &Centred,
    radius_mm: f64,
    feed_mm_per_min: Option<f64>,
    g_ref_um: f64,
) -> Result<Diagnosis> {
    let data = Data {
        psi: &c.nominal_angle_rad,
        sigma: c.direction.iter().map(|d| d.sense()).collect(),
        y: &c.dev_um,
    };
    let both = data.sigma.iter().any(|&s| s > 0.0) && data.sigma.iter().any(|&s| s < 0.0);
    let rg = ranges(c, radius_mm);
    let mut shape = Shape {
        radius_mm,
        spike_decay_mm: [(rg.decay_mm.0 * rg.decay_mm.1).sqrt(); 2],
        cyclic_period_mm: [None, None],
        backlash_play_mm: [0.0, 0.0],
        servo: both,
    };
    search_shape(&data, &mut shape, &rg);
    let cols = shape.columns();
    let a = design(&data, &shape, &cols);
    let fit = lstsq(&a, data.y).ok_or_else(|| {
        Error::numeric(
            "the diagnosis model is not determined by these readings",
            "record full turns in both directions with readings every 1° or closer",
        )
    })?;
    let fit = with_nonlinear_covariance(&data, &shape, &cols, fit);
    let fitted = &a * DVector::from_column_slice(&fit.beta);
    let ctx = TermContext {
        c,
        shape: &shape,
        cols: &cols,
        fit: &fit,
        a: &a,
        g_ref_um,
    };
    let servo_k = ctx.coef(Column::Servo);
    let terms = ctx.terms(feed_mm_per_min);
    let mut ranked: Vec<(&str, f64)> = terms
        .list()
        .iter()
        .filter_map(|(k, t)| t.share_of_g.map(|s| (*k, s)))
        .filter(|(_, s)| *s >= 0.05)
        .collect();
    ranked.sort_by(|a, b| b.1.total_cmp(&a.1));
    let beta_of = |col| ctx.coef(col).map_or(0.0, |v| v.0);
    Ok(Diagnosis {
        residual_rms_um: (fit.rss / c.len() as f64).sqrt(),
        model: ModelInfo {
            feed_mm_per_min,
            constant_um: beta_of(Column::Constant),
            centre_um: [beta_of(Column::CentreFirst), beta_of(Column::CentreSecond)],
            servo_amplitude_um: servo_k.map(|v| v.0),
            largest: ranked.iter().map(|(k, _)| k.to_string()).collect(),
            observations: c.len(),
            unknowns: cols.len(),
        },
        terms,
        fitted_um: fitted.iter().copied().collect(),
    })
}

/// What the term builders share: the fit, its design and the reference G.
struct TermContext<'a> {
    c: &'a Centred,
    shape: &'a Shape,
    cols: &'a [Column],
    fit: &'a Fit,
    a: &'a DMatrix<f64>,
    g_ref_um: f64,
}

impl TermContext<'_> {
    /// Every term of the report from the fit.
    fn terms(&self, feed_mm_per_min: Option<f64>) -> Terms {
        let servo_ms = match (self.coef(Column::Servo), feed_mm_per_min) {
            (Some((k, se)), Some(feed)) => self.term(
                &[Column::Servo],
                Some((k * 120.0 / feed, se * 120.0 / feed)),
            ),
            (Some(_), None) => Term::missing(format!(
                "give {} (mm/min) to convert the radial amplitude (model.servo_amplitude_um) to ms",
                words(Setting::Feed)
            )),
            (None, _) => Term::missing("servo mismatch needs both directions (ccw and cw)"),
        };
        let cyclic = |axis: usize, pair: [Column; 2]| match self.shape.cyclic_period_mm[axis] {
            Some(p) => {
                let mut t = self.amplitude(pair);
                t.period_mm = Some(p);
                t
            }
            None => Term::missing(
                "the sampling is too coarse to resolve a cyclic error shorter than R/2",
            ),
        };
        let spike = |axis: usize, col: Column| {
            let mut t = self.term(&[col], self.coef(col));
            t.decay_mm = Some(self.shape.spike_decay_mm[axis]);
            t
        };
        Terms {
            squareness_um_per_m: self.term(&[Column::Squareness], self.coef(Column::Squareness)),
            scale_mismatch_um_per_m: self
                .term(&[Column::ScaleMismatch], self.coef(Column::ScaleMismatch)),
            backlash_first_um: self
                .term(&[Column::BacklashFirst], self.coef(Column::BacklashFirst)),
            backlash_second_um: self
                .term(&[Column::BacklashSecond], self.coef(Column::BacklashSecond)),
            reversal_spike_first_um: spike(0, Column::SpikeFirst),
            reversal_spike_second_um: spike(1, Column::SpikeSecond),
            servo_mismatch_ms: servo_ms,
            cyclic_first_um: cyclic(0, [Column::CyclicFirstSin, Column::CyclicFirstCos]),
            cyclic_second_um: cyclic(1, [Column::CyclicSecondSin, Column::CyclicSecondCos]),
        }
    }

    fn index(&self, col: Column) -> Option<usize> {
        self.cols.iter().position(|&c| c == col)
    }
    /// (coefficient, standard error) of a column.
    fn coef(&self, col: Column) -> Option<(f64, f64)> {
        let j = self.index(col)?;
        Some((self.fit.beta[j], self.fit.cov[(j, j)].max(0.0).sqrt()))
    }
    /// Minimum-zone width of the modelled contribution of some columns.
    fn g_alone(&self, cols: &[Column]) -> f64 {
        let idx: Vec<usize> = cols.iter().filter_map(|&c| self.index(c)).collect();
        let contrib: Vec<f64> = (0..self.c.len())
            .map(|i| idx.iter().map(|&j| self.a[(i, j)] * self.fit.beta[j]).sum())
            .collect();
        min_zone(&contrib, &self.c.angle_rad).width_um
    }
    fn term(&self, cols: &[Column], value: Option<(f64, f64)>) -> Term {
        let Some((v, se)) = value else {
            return Term::missing("not in the model");
        };
        let g = self.g_alone(cols);
        Term {
            value: Some(v),
            stderr: Some(se),
            g_alone_um: Some(g),
            share_of_g: (self.g_ref_um > 0.0).then(|| g / self.g_ref_um),
            period_mm: None,
            decay_mm: None,
            note: None,
        }
    }
    /// Amplitude √(s² + c²) of a sine/cosine pair, its standard error by the delta method.
    fn amplitude(&self, pair: [Column; 2]) -> Term {
        let (Some(i), Some(j)) = (self.index(pair[0]), self.index(pair[1])) else {
            return Term::missing("not in the model");
        };
        let (s, c) = (self.fit.beta[i], self.fit.beta[j]);
        let amp = s.hypot(c);
        let cov = &self.fit.cov;
        let se = if amp > 0.0 {
            ((s * s * cov[(i, i)] + 2.0 * s * c * cov[(i, j)] + c * c * cov[(j, j)]) / (amp * amp))
                .max(0.0)
                .sqrt()
        } else {
            cov[(i, i)].max(cov[(j, j)]).sqrt()
        };
        self.term(&pair, Some((amp, se)))
    }
}
