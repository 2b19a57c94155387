//! Positioning evaluation of an axis by standard: ISO 230-2:2014, ISO 230-2:1997 (= GB/T 17421.2-2000), GB 10931-1989, VDI/DGQ 3441.
//!
//! All figures are unit-agnostic: they come out in the unit of [`Sample::deviation`] (µm for linear
//! axes, arcsec for rotary axes). Notation (ISO 230-2): target i = 1…m, approach j = 1…n,
//! ↑ forward (`+`), ↓ reverse (`-`), x_ij = actual − target.
//!
//! | figure | ISO 230-2:2014 / :1997 | GB 10931-1989 | VDI/DGQ 3441 |
//! |---|---|---|---|
//! | x̄_i↑, x̄_i↓ | mean of x_ij (2014 3.8) | X̄_j | x̄_j |
//! | s_i↑, s_i↓ | √(Σ(x_ij − x̄_i)²/(n−1)) (2014 3.13) | S_j, same | s_j, same |
//! | reversal B_i | x̄_i↑ − x̄_i↓ (2014 3.10) | B_j | U_j |
//! | repeatability ↑ at i | R_i↑ = 4 s_i↑ (2014 3.14) | R_j = 6 S_j | 6 s_i↑ (Ps of one direction, errmap) |
//! | repeatability at i | R_i = max(2s_i↑ + 2s_i↓ + \|B_i\|, R_i↑, R_i↓) (2014 3.15) | max(R_j↑, R_j↓) | Ps_j = 6·s̄_j, s̄_j = (s_j↑ + s_j↓)/2 |
//! | B | max \|B_i\| (2014 3.11) | max \|B_j\| | U = max \|U_j\| |
//! | B̄ | Σ B_i / m, signed (2014 3.12) | same (errmap) | same (errmap) |
//! | R↑, R↓, R | max over i (2014 3.16, 3.17) | max over j | Ps = max Ps_j |
//! | E↑, E↓ | max x̄_i↑ − min x̄_i↑ (2014 3.18) | same (errmap) | same (errmap) |
//! | E | max(x̄↑, x̄↓) − min(x̄↑, x̄↓) (2014 3.19) | same (errmap) | same (errmap) |
//! | M | max x̄_i − min x̄_i, x̄_i = (x̄_i↑ + x̄_i↓)/2 (2014 3.20) | same (errmap) | Pa |
//! | A↑ | max(x̄_i↑ + 2s_i↑) − min(x̄_i↑ − 2s_i↑) (2014 3.21) | (X̄ + 3S)max − (X̄ − 3S)min | same with 3s (errmap) |
//! | A | max over both directions of x̄ + 2s − min of x̄ − 2s (2014 3.22) | same with 3S | P = max(x̄_j + ½(\|U_j\| + Ps_j)) − min(x̄_j − ½(\|U_j\| + Ps_j)) |
//!
//! ISO 230-2:1997 (and GB/T 17421.2-2000, its identical Chinese adoption) defines the same
//! figures with the same 2s/4s factors as the 2014 edition in its terms-and-definitions clause;
//! the 2014 edition adds the measurement-uncertainty estimation (ISO/TR 230-9) and k = 2 wording.
//! GB 10931-1989 (seed 002) uses ±3S: repeatability 6S, accuracy (X̄ + 3S)max − (X̄ − 3S)min.
//! VDI/DGQ 3441 (1977): position scatter Ps = 6·s̄, reversal span U, position deviation Pa,
//! position uncertainty P. Figures a standard does not define but that need no coverage factor
//! (E, M, B̄) are computed by the ISO definitions and marked "errmap" above.
//!
//! With a single approach (n = 1) no standard deviation exists: every figure that needs one
//! (s, repeatability, accuracy) is `None` ("not applicable"), never zero.
//!
//! Unidirectional tests (every target approached from one direction only, ISO 230-2 allows it):
//! only the measured direction's figures exist — x̄_i↑, s_i↑, R_i↑ per target and E↑, R↑, A↑ for
//! the axis (or the ↓ ones). Every figure the standard defines from both directions (x̄_i, B_i,
//! R_i, B, B̄, R, E, M, A) and the other direction's figures are `None`, never zeros nor copies.
//! A mix (some targets from both directions, some from one) is an error.

use super::runs::{distinct_targets, target_index, Direction, Sample};
use errmap_core::error::{Error, Result};
use std::fmt;
use std::str::FromStr;

/// The evaluation standard.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Standard {
    /// ISO 230-2:2014 (k = 2: R↑ = 4s, A from x̄ ± 2s).
    Iso230_2_2014,
    /// ISO 230-2:1997 = GB/T 17421.2-2000 (same 2s/4s figures).
    Iso230_2_1997,
    /// GB 10931-1989 (±3S: repeatability 6S).
    Gb10931_1989,
    /// VDI/DGQ 3441 (Ps = 6s̄, U, Pa, P).
    Vdi3441,
}

impl Standard {
    /// Every standard, in a fixed order.
    pub const ALL: [Standard; 4] = [
        Standard::Iso230_2_2014,
        Standard::Iso230_2_1997,
        Standard::Gb10931_1989,
        Standard::Vdi3441,
    ];

    /// The name used on the command line and in JSON.
    pub fn name(self) -> &'static str {
        match self {
            Standard::Iso230_2_2014 => "iso230-2:2014",
            Standard::Iso230_2_1997 => "iso230-2:1997",
            Standard::Gb10931_1989 => "gb10931-1989",
            Standard::Vdi3441 => "vdi3441",
        }
    }

    /// Coverage factor of the ±k·s band: 2 for ISO 230-2, 3 for GB 10931 and VDI 3441.
    pub fn k(self) -> f64 {
        match self {
            Standard::Iso230_2_2014 | Standard::Iso230_2_1997 => 2.0,
            Standard::Gb10931_1989 | Standard::Vdi3441 => 3.0,
        }
    }
}

impl fmt::Display for Standard {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Standard {
    type Err = Error;
    fn from_str(s: &str) -> Result<Standard> {
        let key = s.trim().to_ascii_lowercase();
        let found = match key.as_str() {
            "iso230-2:2014" | "iso230-2" | "iso" => Some(Standard::Iso230_2_2014),
            "iso230-2:1997" | "gb/t17421.2-2000" | "gbt17421.2-2000" => {
                Some(Standard::Iso230_2_1997)
            }
            "gb10931-1989" | "gb10931" => Some(Standard::Gb10931_1989),
            "vdi3441" | "vdi/dgq3441" => Some(Standard::Vdi3441),
            _ => None,
        };
        found.ok_or_else(|| {
            Error::usage(
                format!("unknown standard '{s}'"),
                "use iso230-2:2014, iso230-2:1997, gb10931-1989 or vdi3441",
            )
        })
    }
}

impl serde::Serialize for Standard {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

/// Figures at one target position.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct TargetFigures {
    /// Target position, in the samples' unit (mm on a linear axis, degrees on a rotary one).
    pub target: f64,
    /// Number of forward (↑) approaches to the target.
    pub n_up: usize,
    /// Number of reverse (↓) approaches to the target.
    pub n_down: usize,
    /// x̄_i↑: mean deviation (actual − target) of the forward approaches; `None` when that
    /// direction was not measured.
    pub mean_up: Option<f64>,
    /// x̄_i↓: mean deviation of the reverse approaches; `None` when that direction was not
    /// measured.
    pub mean_down: Option<f64>,
    /// x̄_i = (x̄_i↑ + x̄_i↓)/2; `None` in a unidirectional test.
    pub mean: Option<f64>,
    /// s_i↑: standard deviation of the forward approaches (n − 1 in the denominator); `None`
    /// when n < 2.
    pub s_up: Option<f64>,
    /// s_i↓: standard deviation of the reverse approaches (n − 1); `None` when n < 2.
    pub s_down: Option<f64>,
    /// B_i = x̄_i↑ − x̄_i↓ (signed); `None` in a unidirectional test.
    pub reversal: Option<f64>,
    /// Unidirectional repeatability ↑ at the target, 2k·s_i↑ (ISO R_i↑ = 4s, GB 6S, VDI 6s);
    /// `None` without s_i↑.
    pub repeatability_up: Option<f64>,
    /// Unidirectional repeatability ↓ at the target, 2k·s_i↓; `None` without s_i↓.
    pub repeatability_down: Option<f64>,
    /// Bidirectional repeatability at the target (ISO R_i, GB max(R↑, R↓), VDI Ps_j).
    pub repeatability: Option<f64>,
}

impl TargetFigures {
    /// The target's systematic deviation: x̄_i when both directions exist, else the measured
    /// direction's mean (a unidirectional test). Used for pitch fits and compensation tables.
    pub fn mean_any(&self) -> f64 {
        self.mean
            .or(self.mean_up)
            .or(self.mean_down)
            .unwrap_or(f64::NAN)
    }
}

/// Figures of the whole axis in the deviations' unit (µm on a linear axis, arcsec on a rotary
/// one), by the ISO 230-2 names of the module table. `None` = not applicable (n = 1, or a
/// unidirectional test).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
#[allow(non_snake_case)]
pub struct AxisFigures {
    /// Reversal value B = max |B_i| (VDI: largest reversal span U max).
    pub B: Option<f64>,
    /// Mean reversal value B̄ = Σ B_i / m, signed.
    pub B_mean: Option<f64>,
    /// Unidirectional repeatability R↑ = max R_i↑ over the targets.
    pub R_up: Option<f64>,
    /// Unidirectional repeatability R↓ = max R_i↓ over the targets.
    pub R_down: Option<f64>,
    /// Bidirectional repeatability R = max over the targets of the standard's per-target
    /// repeatability (VDI: largest position scatter Ps max).
    pub R: Option<f64>,
    /// Unidirectional systematic positioning error E↑ = max x̄_i↑ − min x̄_i↑.
    pub E_up: Option<f64>,
    /// Unidirectional systematic positioning error E↓ = max x̄_i↓ − min x̄_i↓.
    pub E_down: Option<f64>,
    /// Bidirectional systematic positioning error E = max(x̄_i↑, x̄_i↓) − min(x̄_i↑, x̄_i↓).
    pub E: Option<f64>,
    /// Mean bidirectional positioning error M = max x̄_i − min x̄_i (VDI: position deviation Pa).
    pub M: Option<f64>,
    /// Unidirectional accuracy A↑ = max(x̄_i↑ + k·s_i↑) − min(x̄_i↑ − k·s_i↑).
    pub A_up: Option<f64>,
    /// Unidirectional accuracy A↓ = max(x̄_i↓ + k·s_i↓) − min(x̄_i↓ − k·s_i↓).
    pub A_down: Option<f64>,
    /// Bidirectional accuracy A: the ±k·s band over both directions (VDI: position uncertainty P).
    pub A: Option<f64>,
}

/// The result of [`evaluate`].
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Evaluation {
    /// The standard whose definitions and coverage factor the figures follow.
    pub standard: Standard,
    /// Coverage factor of the band (2 or 3).
    pub k: f64,
    /// `None` for a bidirectional test, else the only direction measured (serialized only then,
    /// so bidirectional documents keep their keys).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub unidirectional: Option<Direction>,
    /// Targets ascending.
    pub targets: Vec<TargetFigures>,
    /// The figures of the whole axis.
    pub axis: AxisFigures,
}

/// One axis figure as its standard names and defines it.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Figure {
    /// The standard's own symbol (e.g. `Ps max`, `P̄s`, `Ū`, `A↑`).
    pub symbol: &'static str,
    /// The standard's name of the figure.
    pub name: &'static str,
    /// Its definition in the standard's notation (position j, approach ↑ ↓).
    pub definition: &'static str,
    /// `None` where not applicable (n = 1, unidirectional test).
    pub value: Option<f64>,
}

/// Per-target column headings in the standard's own symbols: mean ↑, mean ↓, s ↑, s ↓,
/// reversal, repeatability ↑, repeatability ↓, repeatability (an empty heading = not defined).
pub fn target_symbols(standard: Standard) -> [&'static str; 8] {
    match standard {
        Standard::Iso230_2_2014 | Standard::Iso230_2_1997 => {
            ["x̄_i↑", "x̄_i↓", "s_i↑", "s_i↓", "B_i", "R_i↑", "R_i↓", "R_i"]
        }
        Standard::Gb10931_1989 => ["X̄_j↑", "X̄_j↓", "S_j↑", "S_j↓", "B_j", "R_j↑", "R_j↓", "R_j"],
        Standard::Vdi3441 => ["x̄_j↑", "x̄_j↓", "s_j↑", "s_j↓", "U_j", "", "", "Ps_j"],
    }
}

impl Evaluation {
    /// The axis figures the standard defines, in its own symbols, with their definitions.
    /// ISO 230-2 and GB 10931 take their values from [`AxisFigures`]; VDI/DGQ 3441 adds the
    /// means over the positions, Ū = Σ|U_j|/m and P̄s = Σ Ps_j/m.
    pub fn figures(&self) -> Vec<Figure> {
        match self.standard {
            Standard::Iso230_2_2014 | Standard::Iso230_2_1997 => iso_figures(&self.axis),
            Standard::Gb10931_1989 => gb_figures(&self.axis),
            Standard::Vdi3441 => vdi_figures(&self.axis, &self.targets),
        }
    }

    /// The value of the figure with `symbol` (`None` if the standard has no such figure).
    pub fn figure(&self, symbol: &str) -> Option<Option<f64>> {
        self.figures()
            .into_iter()
            .find(|f| f.symbol == symbol)
            .map(|f| f.value)
    }
}

/// A [`Figure`] from its parts.
fn figure(
    symbol: &'static str,
    name: &'static str,
    definition: &'static str,
    value: Option<f64>,
) -> Figure {
    Figure {
        symbol,
        name,
        definition,
        value,
    }
}

/// The axis figures of ISO 230-2 (2014 and 1997).
fn iso_figures(a: &AxisFigures) -> Vec<Figure> {
    let f = figure;
    vec![
        f(
            "A",
            "accuracy, bidirectional",
            "max(x̄_i↑ + 2s_i↑, x̄_i↓ + 2s_i↓) − min(x̄_i↑ − 2s_i↑, x̄_i↓ − 2s_i↓)",
            a.A,
        ),
        f(
            "A↑",
            "accuracy, unidirectional ↑",
            "max(x̄_i↑ + 2s_i↑) − min(x̄_i↑ − 2s_i↑)",
            a.A_up,
        ),
        f(
            "A↓",
            "accuracy, unidirectional ↓",
            "max(x̄_i↓ + 2s_i↓) − min(x̄_i↓ − 2s_i↓)",
            a.A_down,
        ),
        f(
            "R",
            "repeatability, bidirectional",
            "max R_i, R_i = max(2s_i↑ + 2s_i↓ + |B_i|, R_i↑, R_i↓)",
            a.R,
        ),
        f(
            "R↑",
            "repeatability, unidirectional ↑",
            "max R_i↑, R_i↑ = 4s_i↑",
            a.R_up,
        ),
        f(
            "R↓",
            "repeatability, unidirectional ↓",
            "max R_i↓, R_i↓ = 4s_i↓",
            a.R_down,
        ),
        f(
            "E",
            "systematic positioning error, bidirectional",
            "max(x̄_i↑, x̄_i↓) − min(x̄_i↑, x̄_i↓)",
            a.E,
        ),
        f(
            "E↑",
            "systematic positioning error, unidirectional ↑",
            "max x̄_i↑ − min x̄_i↑",
            a.E_up,
        ),
        f(
            "E↓",
            "systematic positioning error, unidirectional ↓",
            "max x̄_i↓ − min x̄_i↓",
            a.E_down,
        ),
        f(
            "M",
            "mean bidirectional positioning error",
            "max x̄_i − min x̄_i, x̄_i = (x̄_i↑ + x̄_i↓)/2",
            a.M,
        ),
        f("B", "reversal value", "max |B_i|, B_i = x̄_i↑ − x̄_i↓", a.B),
        f("B̄", "mean reversal value", "Σ B_i / m", a.B_mean),
    ]
}

/// The axis figures of GB 10931-1989.
fn gb_figures(a: &AxisFigures) -> Vec<Figure> {
    let f = figure;
    vec![
        f(
            "A",
            "定位精度 positioning accuracy",
            "(X̄_j + 3S_j)max − (X̄_j − 3S_j)min over both directions",
            a.A,
        ),
        f(
            "A↑",
            "定位精度 positioning accuracy ↑",
            "(X̄_j↑ + 3S_j↑)max − (X̄_j↑ − 3S_j↑)min",
            a.A_up,
        ),
        f(
            "A↓",
            "定位精度 positioning accuracy ↓",
            "(X̄_j↓ + 3S_j↓)max − (X̄_j↓ − 3S_j↓)min",
            a.A_down,
        ),
        f("R", "重复定位精度 repeatability", "max(R↑, R↓)", a.R),
        f(
            "R↑",
            "重复定位精度 repeatability ↑",
            "max R_j↑, R_j↑ = 6S_j↑",
            a.R_up,
        ),
        f(
            "R↓",
            "重复定位精度 repeatability ↓",
            "max R_j↓, R_j↓ = 6S_j↓",
            a.R_down,
        ),
        f(
            "B",
            "反向差值 reversal value",
            "max |B_j|, B_j = X̄_j↑ − X̄_j↓",
            a.B,
        ),
    ]
}

/// The axis figures of VDI/DGQ 3441, with the means over the positions Ū and P̄s.
fn vdi_figures(a: &AxisFigures, t: &[TargetFigures]) -> Vec<Figure> {
    let f = figure;
    let m = t.len() as f64;
    let mean_of = |pick: &dyn Fn(&TargetFigures) -> Option<f64>| {
        t.iter().map(pick).sum::<Option<f64>>().map(|s| s / m)
    };
    vec![
        f(
            "P",
            "Positionsunsicherheit, position uncertainty",
            "max(x̄_j + (U_j + Ps_j)/2) − min(x̄_j − (U_j + Ps_j)/2)",
            a.A,
        ),
        f(
            "Pa",
            "Positionsabweichung, position deviation",
            "max x̄_j − min x̄_j, x̄_j = (x̄_j↑ + x̄_j↓)/2",
            a.M,
        ),
        f(
            "Ps max",
            "größte Positionsstreubreite, largest position scatter",
            "max Ps_j, Ps_j = 6·s̄_j, s̄_j = (s_j↑ + s_j↓)/2",
            a.R,
        ),
        f(
            "P̄s",
            "mittlere Positionsstreubreite, mean position scatter",
            "Σ Ps_j / m",
            mean_of(&|x| x.repeatability),
        ),
        f(
            "U max",
            "größte Umkehrspanne, largest reversal span",
            "max U_j, U_j = |x̄_j↑ − x̄_j↓|",
            a.B,
        ),
        f(
            "Ū",
            "mittlere Umkehrspanne, mean reversal span",
            "Σ U_j / m",
            mean_of(&|x| x.reversal.map(f64::abs)),
        ),
    ]
}

/// Arithmetic mean; NaN for no values.
pub fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}

/// Sample standard deviation (n − 1); `None` for n < 2.
pub fn std_dev(v: &[f64]) -> Option<f64> {
    if v.len() < 2 {
        return None;
    }
    let m = mean(v);
    let ss: f64 = v.iter().map(|x| (x - m) * (x - m)).sum();
    Some((ss / (v.len() - 1) as f64).sqrt())
}

fn max_of(it: impl Iterator<Item = f64>) -> f64 {
    it.fold(f64::NEG_INFINITY, f64::max)
}

fn min_of(it: impl Iterator<Item = f64>) -> f64 {
    it.fold(f64::INFINITY, f64::min)
}

/// Picks (x̄, s) of one direction at a target.
type MeanAndS = dyn Fn(&TargetFigures) -> (Option<f64>, Option<f64>);

/// Max over options: `None` if any is `None`.
fn max_opt(it: impl Iterator<Item = Option<f64>>) -> Option<f64> {
    let mut out = f64::NEG_INFINITY;
    for v in it {
        out = out.max(v?);
    }
    Some(out)
}

/// Evaluate an axis by `standard` (see the module table for every formula and its clause).
///
/// Every target needs at least one approach from each direction (bidirectional test), or every
/// target approaches from the same single direction (unidirectional test: the other direction's
/// and the bidirectional figures are `None`). Targets closer than
/// 1e-6 (in the samples' target unit) are one target.
///
/// Two targets approached twice from each side, figures by hand (ISO 230-2:2014, k = 2):
///
/// ```
/// use errmap_metrology::linear::{evaluate, Direction, Sample, Standard};
///
/// // (target mm, run, direction, deviation µm)
/// let readings = [
///     (0.0, 1, Direction::Forward, 1.0), (0.0, 2, Direction::Forward, 3.0),
///     (0.0, 1, Direction::Reverse, 2.0), (0.0, 2, Direction::Reverse, 4.0),
///     (100.0, 1, Direction::Forward, 5.0), (100.0, 2, Direction::Forward, 7.0),
///     (100.0, 1, Direction::Reverse, 6.0), (100.0, 2, Direction::Reverse, 8.0),
/// ];
/// let samples: Vec<Sample> = readings
///     .iter()
///     .map(|&(target, run, direction, deviation)| Sample { run, direction, target, deviation })
///     .collect();
/// let axis = evaluate(&samples, Standard::Iso230_2_2014).unwrap().axis;
/// let near = |a: Option<f64>, b: f64| (a.unwrap() - b).abs() < 1e-12;
/// // E↑ = max x̄↑ − min x̄↑ = 6 − 2; E = max(x̄↑, x̄↓) − min(x̄↑, x̄↓) = 7 − 2
/// assert!(near(axis.E_up, 4.0) && near(axis.E, 5.0));
/// // s↑ = √2 at both targets: R↑ = 4s↑, A↑ = (6 + 2√2) − (2 − 2√2)
/// assert!(near(axis.R_up, 4.0 * 2f64.sqrt()) && near(axis.A_up, 4.0 + 4.0 * 2f64.sqrt()));
/// // B = x̄↑ − x̄↓ = −1 at both targets
/// assert!(near(axis.B.map(f64::abs), 1.0));
/// ```
pub fn evaluate(samples: &[Sample], standard: Standard) -> Result<Evaluation> {
    check_samples(samples)?;
    let groups = group_by_direction(samples)?;
    let unidirectional = which_test(&groups)?;
    let k = standard.k();
    let targets: Vec<TargetFigures> = groups
        .positions
        .iter()
        .zip(groups.up.iter().zip(&groups.down))
        .map(|(&target, (up, down))| target_figures(standard, target, up, down))
        .collect();
    let axis = axis_figures(standard, unidirectional.is_none(), &targets);
    Ok(Evaluation {
        standard,
        k,
        unidirectional,
        targets,
        axis,
    })
}

/// Refuse an empty sample set and non-finite values.
fn check_samples(samples: &[Sample]) -> Result<()> {
    if samples.is_empty() {
        return Err(Error::numeric(
            "no samples to evaluate",
            "give at least one reading per target and direction",
        ));
    }
    if let Some(bad) = samples
        .iter()
        .find(|s| !s.target.is_finite() || !s.deviation.is_finite())
    {
        return Err(Error::numeric(
            format!(
                "run {} direction {} has a non-finite target or deviation",
                bad.run,
                bad.direction.symbol()
            ),
            "remove NaN and infinite values",
        ));
    }
    Ok(())
}

/// The deviations at each distinct target, by approach direction.
struct Groups {
    /// Targets ascending.
    positions: Vec<f64>,
    up: Vec<Vec<f64>>,
    down: Vec<Vec<f64>>,
}

fn group_by_direction(samples: &[Sample]) -> Result<Groups> {
    let positions = distinct_targets(samples.iter().map(|s| s.target));
    let mut up: Vec<Vec<f64>> = vec![Vec::new(); positions.len()];
    let mut down: Vec<Vec<f64>> = vec![Vec::new(); positions.len()];
    for s in samples {
        let i = target_index(&positions, s.target)
            .ok_or_else(|| Error::Internal("sample target not among targets".into()))?;
        match s.direction {
            Direction::Forward => up[i].push(s.deviation),
            Direction::Reverse => down[i].push(s.deviation),
        }
    }
    Ok(Groups {
        positions,
        up,
        down,
    })
}

/// `None` for a bidirectional test (every target from both sides), the one direction of a
/// unidirectional test (every target from the same side); a mix is an error.
fn which_test(g: &Groups) -> Result<Option<Direction>> {
    let (up, down) = (&g.up, &g.down);
    let all_up = up.iter().all(|v| !v.is_empty());
    let all_down = down.iter().all(|v| !v.is_empty());
    match (all_up, all_down) {
        (true, true) => Ok(None),
        (true, false) if down.iter().all(|v| v.is_empty()) => Ok(Some(Direction::Forward)),
        (false, true) if up.iter().all(|v| v.is_empty()) => Ok(Some(Direction::Reverse)),
        _ => {
            let i = (0..g.positions.len())
                .find(|&i| up[i].is_empty() || down[i].is_empty())
                .unwrap_or(0);
            let missing = if up.get(i).is_some_and(|v| v.is_empty()) {
                "+"
            } else {
                "-"
            };
            let target = g.positions.get(i).copied().unwrap_or(f64::NAN);
            Err(Error::numeric(
                format!("target {target} has no approach in direction {missing} while other targets do (mixed uni/bidirectional samples)"),
                "measure every target from both directions, or every target from the same one direction",
            ))
        }
    }
}

/// The figures at one target from its deviations approached ↑ (`up`) and ↓ (`down`).
fn target_figures(standard: Standard, target: f64, up: &[f64], down: &[f64]) -> TargetFigures {
    let k = standard.k();
    let nonempty = |v: &[f64]| (!v.is_empty()).then(|| mean(v));
    let mean_up = nonempty(up);
    let mean_down = nonempty(down);
    let s_up = std_dev(up);
    let s_down = std_dev(down);
    let reversal = mean_up.zip(mean_down).map(|(u, d)| u - d);
    TargetFigures {
        target,
        n_up: up.len(),
        n_down: down.len(),
        mean_up,
        mean_down,
        mean: mean_up.zip(mean_down).map(|(u, d)| (u + d) / 2.0),
        s_up,
        s_down,
        reversal,
        // Unidirectional repeatability: 2k·s (ISO 4s, GB 6S, VDI 6s).
        repeatability_up: s_up.map(|s| 2.0 * k * s),
        repeatability_down: s_down.map(|s| 2.0 * k * s),
        repeatability: repeatability_at(standard, s_up, s_down, reversal),
    }
}

/// Bidirectional repeatability at a target from s↑, s↓ and B_i; `None` if any is missing.
fn repeatability_at(
    standard: Standard,
    s_up: Option<f64>,
    s_down: Option<f64>,
    reversal: Option<f64>,
) -> Option<f64> {
    let (su, sd, b_i) = (s_up?, s_down?, reversal?);
    Some(match standard {
        // ISO 230-2:2014 3.15 (same in 1997): R_i = max(2s↑ + 2s↓ + |B_i|, R_i↑, R_i↓).
        Standard::Iso230_2_2014 | Standard::Iso230_2_1997 => (2.0 * su + 2.0 * sd + b_i.abs())
            .max(4.0 * su)
            .max(4.0 * sd),
        // GB 10931-1989: repeatability 6S of each direction; the larger at the target.
        Standard::Gb10931_1989 => (6.0 * su).max(6.0 * sd),
        // VDI/DGQ 3441: Ps_j = 6·s̄_j with s̄_j = (s_j↑ + s_j↓)/2.
        Standard::Vdi3441 => 6.0 * (su + sd) / 2.0,
    })
}

/// The axis figures from the per-target figures.
fn axis_figures(standard: Standard, bidirectional: bool, t: &[TargetFigures]) -> AxisFigures {
    let k = standard.k();
    // Range of a per-target figure: None when any target lacks it.
    let range = |pick: &dyn Fn(&TargetFigures) -> Option<f64>| -> Option<f64> {
        let hi = max_opt(t.iter().map(pick))?;
        let lo = max_opt(t.iter().map(|f| pick(f).map(|v| -v)))?;
        Some(hi + lo)
    };
    // ISO 230-2:2014 3.19: E over both directions; not defined for a unidirectional test.
    let e = if bidirectional {
        let all = || t.iter().flat_map(|f| [f.mean_up, f.mean_down]).flatten();
        Some(max_of(all()) - min_of(all()))
    } else {
        None
    };
    AxisFigures {
        B: max_opt(t.iter().map(|f| f.reversal.map(f64::abs))),
        B_mean: t
            .iter()
            .map(|f| f.reversal)
            .sum::<Option<f64>>()
            .map(|sum| sum / t.len() as f64),
        R_up: max_opt(t.iter().map(|f| f.repeatability_up)),
        R_down: max_opt(t.iter().map(|f| f.repeatability_down)),
        R: if bidirectional {
            max_opt(t.iter().map(|f| f.repeatability))
        } else {
            None
        },
        E_up: range(&|f| f.mean_up),
        E_down: range(&|f| f.mean_down),
        E: e,
        M: range(&|f| f.mean),
        A_up: accuracy_one(t, k, &|f| (f.mean_up, f.s_up)),
        A_down: accuracy_one(t, k, &|f| (f.mean_down, f.s_down)),
        A: if bidirectional {
            accuracy_both(standard, t)
        } else {
            None
        },
    }
}

/// Unidirectional accuracy: max(x̄ + k·s) − min(x̄ − k·s) over the targets of one direction.
fn accuracy_one(t: &[TargetFigures], k: f64, pick: &MeanAndS) -> Option<f64> {
    let hi = max_opt(t.iter().map(|f| {
        let (x, s) = pick(f);
        x.zip(s).map(|(x, s)| x + k * s)
    }))?;
    let lo = max_opt(t.iter().map(|f| {
        let (x, s) = pick(f);
        x.zip(s).map(|(x, s)| -(x - k * s))
    }))?;
    Some(hi + lo)
}

/// Bidirectional accuracy A (VDI/DGQ 3441: position uncertainty P) of a bidirectional test.
fn accuracy_both(standard: Standard, t: &[TargetFigures]) -> Option<f64> {
    let k = standard.k();
    match standard {
        // VDI/DGQ 3441: P = max(x̄_j + ½(|U_j| + Ps_j)) − min(x̄_j − ½(|U_j| + Ps_j)).
        Standard::Vdi3441 => {
            let half = |f: &TargetFigures| {
                f.reversal
                    .zip(f.repeatability)
                    .map(|(u, ps)| (u.abs() + ps) / 2.0)
            };
            let hi = max_opt(t.iter().map(|f| half(f).zip(f.mean).map(|(h, x)| x + h)));
            let lo = max_opt(t.iter().map(|f| half(f).zip(f.mean).map(|(h, x)| -(x - h))));
            hi.zip(lo).map(|(h, l)| h + l)
        }
        // ISO 230-2:2014 3.22 (±2s), GB 10931-1989 (±3S): both directions together.
        _ => {
            let band = |x: Option<f64>, s: Option<f64>, sign: f64| {
                x.zip(s).map(|(x, s)| sign * (x + sign * k * s))
            };
            let hi = max_opt(t.iter().flat_map(|f| {
                [
                    band(f.mean_up, f.s_up, 1.0),
                    band(f.mean_down, f.s_down, 1.0),
                ]
            }));
            let lo = max_opt(t.iter().flat_map(|f| {
                [
                    band(f.mean_up, f.s_up, -1.0),
                    band(f.mean_down, f.s_down, -1.0),
                ]
            }));
            hi.zip(lo).map(|(h, l)| h + l)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mean_and_std_dev_by_hand() {
        assert_eq!(mean(&[1.0, 2.0, 6.0]), 3.0);
        // Σ(x − 3)² = 4 + 1 + 9 = 14; s = √(14 / 2) = √7.
        assert!((std_dev(&[1.0, 2.0, 6.0]).unwrap() - 7f64.sqrt()).abs() < 1e-15);
        assert_eq!(mean(&[2.5]), 2.5);
        assert_eq!(std_dev(&[2.5]), None);
    }
}
