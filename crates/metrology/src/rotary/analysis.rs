//! `rotary analyze`: sphere centres per position, vectors a and b, err = α − β per position, averaged over repeats.

use super::angle::{angle_error_arcsec, signed_angle_about, wrap_deg};
use super::axis_fit::{fit_axis, AxisFit, CircleFit};
use super::input::{Direction, Measurement, Position, RotaryAxis};
use super::sphere::{fit_sphere, SphereFit};
use crate::linear::{self, Evaluation, Sample, Standard};
use crate::Setting;
use errmap_core::error::{Error, Location, Result};
use errmap_core::setting::words;
use serde::Serialize;
use std::collections::BTreeMap;

/// How to analyse a measurement.
#[derive(Debug, Clone, PartialEq)]
pub struct AnalyzeOptions {
    /// Fit the axis direction from the sphere trajectories instead of using the nominal one.
    pub fit_axis: bool,
    /// Nominal sphere diameter; with touch points, fits whose radius disagrees are errors.
    pub sphere_diameter_mm: Option<f64>,
    /// Stylus tip radius: touch points lie on a sphere of radius sphere + stylus.
    pub stylus_radius_mm: f64,
    /// Largest accepted |fitted radius − (sphere diameter / 2 + stylus radius)|.
    pub radius_tolerance_mm: f64,
    /// Fit only the centre, with the radius fixed at sphere diameter / 2 + stylus radius.
    pub fix_radius: bool,
    /// Angle of vector a; default 0° if measured, else the smallest measured angle.
    pub reference_angle_deg: Option<f64>,
}

impl Default for AnalyzeOptions {
    fn default() -> Self {
        AnalyzeOptions {
            fit_axis: false,
            sphere_diameter_mm: None,
            stylus_radius_mm: 0.0,
            radius_tolerance_mm: 0.010,
            fix_radius: false,
            reference_angle_deg: None,
        }
    }
}

/// One sphere fitted at one position (touch-point files only).
#[derive(Debug, Clone, Serialize)]
pub struct SphereReport {
    /// Approach direction of the position (`+` increasing angle, `-` decreasing).
    #[serde(with = "errmap_core::direction::symbol")]
    pub direction: Direction,
    /// Repeat number of the position.
    pub repeat: u32,
    /// Commanded angle α of the position, degrees.
    pub angle_deg: f64,
    /// Sphere number (1 or 2).
    pub sphere: u8,
    /// First file line of the sphere's touch points.
    pub line: u64,
    /// The fit: centre, radius and form residuals, its keys flattened into the report.
    #[serde(flatten)]
    pub fit: SphereFit,
    /// Fitted minus nominal radius (sphere + stylus), when the diameter is known.
    pub radius_deviation_mm: Option<f64>,
}

/// The angular error of one position in one repeat.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Observation {
    /// Approach direction (`+` increasing angle, `-` decreasing).
    #[serde(with = "errmap_core::direction::symbol")]
    pub direction: Direction,
    /// Repeat number.
    pub repeat: u32,
    /// Commanded angle α, degrees.
    pub angle_deg: f64,
    /// Angular error err = α − β (commanded − measured, relative to the reference angle),
    /// arcsec; β − α after [`Analysis::with_sign`] with [`Sign::Calibrator`].
    pub error_arcsec: f64,
    /// First file line of the position.
    pub line: u64,
}

/// Mean error at one target angle and direction over the repeats.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TableRow {
    /// Commanded angle α, degrees.
    pub angle_deg: f64,
    /// Approach direction (`+` increasing angle, `-` decreasing).
    #[serde(with = "errmap_core::direction::symbol")]
    pub direction: Direction,
    /// Mean angular error over the repeats, arcsec, in the analysis' [`Sign`].
    pub error_arcsec: f64,
    /// Sample standard deviation over the repeats (n − 1); `null` for a single repeat.
    pub s_arcsec: Option<f64>,
    /// Number of repeats averaged.
    pub n: usize,
    /// Smallest error over the repeats, arcsec.
    pub min_arcsec: f64,
    /// Largest error over the repeats, arcsec.
    pub max_arcsec: f64,
}

/// The reference vector a.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Reference {
    /// Reference angle, degrees: the commanded angle at which vector a was taken; errors are
    /// measured from it.
    pub angle_deg: f64,
    /// The direction whose repeats gave a: `+`, or `-` when `+` was not measured at that angle.
    #[serde(with = "errmap_core::direction::symbol")]
    pub direction: Direction,
    /// Repeats averaged into a.
    pub n: usize,
    /// a = c2 − c1 (mean over those repeats).
    pub vector_mm: [f64; 3],
    /// |a| projected on the plane normal to the axis: the lever arm of the angle.
    pub lever_mm: f64,
}

/// Axis direction used for the angles, and the fitted location when `--fit-axis` is on.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AxisReport {
    /// `nominal` or `fitted`.
    pub method: &'static str,
    /// Unit vector of the machine axis the rotary axis nominally turns about (X for A, Y for B, Z
    /// for C).
    pub nominal_direction: [f64; 3],
    /// Unit direction of the axis the angles are taken about: the nominal one, or the fitted one.
    pub direction: [f64; 3],
    /// Angle between the fitted and the nominal direction, arcsec; `None` with the nominal axis.
    pub tilt_arcsec: Option<f64>,
    /// Inclination of the fitted axis toward each of the two other machine axes, arcsec, keyed by
    /// their letters; `None` with the nominal axis.
    pub tilt_toward_arcsec: Option<BTreeMap<String, f64>>,
    /// Mean of the circle centres, a point on the fitted axis, mm; `None` with the nominal axis.
    pub centre_mm: Option<[f64; 3]>,
    /// Where the fitted axis crosses the plane through the machine origin normal to the nominal
    /// axis, mm; `None` with the nominal axis.
    pub location_mm: Option<[f64; 3]>,
    /// The circle each sphere centre traced about the fitted axis; empty with the nominal axis.
    pub circles: Vec<CircleFit>,
}

impl AxisReport {
    fn nominal(axis: RotaryAxis) -> Self {
        AxisReport {
            method: "nominal",
            nominal_direction: axis.nominal_direction(),
            direction: axis.nominal_direction(),
            tilt_arcsec: None,
            tilt_toward_arcsec: None,
            centre_mm: None,
            location_mm: None,
            circles: Vec::new(),
        }
    }

    fn fitted(axis: RotaryAxis, fit: AxisFit) -> Self {
        AxisReport {
            method: "fitted",
            nominal_direction: axis.nominal_direction(),
            direction: fit.direction,
            tilt_arcsec: Some(fit.tilt_arcsec),
            tilt_toward_arcsec: Some(fit.tilt_toward_arcsec),
            centre_mm: Some(fit.centre_mm),
            location_mm: Some(fit.location_mm),
            circles: fit.circles,
        }
    }
}

/// Summary of the sphere fits of a touch-point file.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SphereSummary {
    /// Number of sphere fits (two per position).
    pub fits: usize,
    /// Largest RMS of the geometric residuals over the fits, mm.
    pub max_form_rms_mm: f64,
    /// Largest form error (peak-to-valley of the residuals) over the fits, mm.
    pub max_form_pv_mm: f64,
    /// Mean fitted radius (sphere + stylus), mm.
    pub mean_radius_mm: f64,
    /// Largest |fitted − nominal radius| over the fits, mm; `None` when no sphere diameter was
    /// given.
    pub max_abs_radius_deviation_mm: Option<f64>,
}

/// Sign convention of the angular errors of an analysis (`rotary analyze --sign`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Sign {
    /// err = α − β = commanded − measured (what `rotary table` compensates).
    #[default]
    Errmap,
    /// error = β − α = measured − commanded: ISO 230-2's deviation x (actual − target), the
    /// sign of laser and rotary-calibrator reports.
    Calibrator,
}

impl Sign {
    /// The error's definition, e.g. "α − β (commanded − measured)".
    pub fn formula(self) -> &'static str {
        match self {
            Sign::Errmap => "α − β (commanded − measured)",
            Sign::Calibrator => "β − α (measured − commanded)",
        }
    }

    /// What a positive error means for `axis`, in words.
    pub fn positive(self, axis: RotaryAxis) -> String {
        let about = ["X", "Y", "Z"][axis.index()];
        let side = match self {
            Sign::Errmap => "clockwise",
            Sign::Calibrator => "counter-clockwise",
        };
        format!(
            "positive: the axis stopped {side} of the commanded angle, seen from +{about} (angles right-handed about +{about})"
        )
    }
}

/// Result of `rotary analyze`.
#[derive(Debug, Clone, Serialize)]
pub struct Analysis {
    /// The rotary axis measured.
    pub axis: RotaryAxis,
    /// Unit of every angular error: always `arcsec`.
    pub unit: &'static str,
    /// Sign of `table` (and of the observations): `errmap` (α − β) or `calibrator` (β − α).
    /// `iso230_2` keeps ISO's x = β − α whatever the sign.
    pub sign: Sign,
    /// Mean error per direction and target angle, direction `+` first, angles ascending.
    pub table: Vec<TableRow>,
    /// The axis direction the angles are taken about and, with `--fit-axis`, its location.
    pub axis_fit: AxisReport,
    /// Positioning figures by ISO 230-2:2014 in arcsec (from [`crate::linear::evaluate`]),
    /// with ISO's sign x = actual − target = β − α = −err; `null` when not applicable.
    pub iso230_2: Option<Evaluation>,
    /// Why `iso230_2` is `null`, if it is.
    pub iso230_2_note: Option<String>,
    /// The reference vector a, from whose angle the errors are measured.
    pub reference: Reference,
    /// Present for touch-point files.
    pub spheres: Option<SphereSummary>,
    /// Every sphere fit of a touch-point file: centre, radius, form residual (empty for centres).
    pub sphere_fits: Vec<SphereReport>,
    /// Every position of every repeat (not in the JSON).
    #[serde(skip)]
    pub observations: Vec<Observation>,
}

fn key(angle_deg: f64) -> i64 {
    (angle_deg * 1e6).round() as i64
}

/// Analyse a measurement, stage by stage: options checked → sphere centres at every position
/// → axis direction → reference vector a → err = α − β per position → mean per angle and
/// direction → ISO 230-2 figures and the sphere-fit summary.
pub fn analyze(
    m: &Measurement,
    opts: &AnalyzeOptions,
) -> Result<Analysis, crate::error::RotaryError> {
    opts.check()?;
    let nominal_radius = opts.nominal_radius_mm();
    let centres = sphere_centres(m, opts, nominal_radius)?;
    let axis_fit = axis_direction(m, &centres.pairs, opts.fit_axis)?;
    let reference = reference_vector(m, &centres.pairs, axis_fit.direction, opts)?;
    let observations = angular_errors(m, &centres.pairs, &reference, axis_fit.direction)?;
    let table = mean_over_repeats(&observations);
    let (iso230_2, iso230_2_note) = iso_figures(&observations);
    let spheres = sphere_summary(&centres.fits, nominal_radius);
    Ok(Analysis {
        axis: m.axis,
        unit: "arcsec",
        sign: Sign::Errmap,
        reference,
        table,
        axis_fit,
        spheres,
        iso230_2,
        iso230_2_note,
        observations,
        sphere_fits: centres.fits,
    })
}

impl AnalyzeOptions {
    /// Refuse options that cannot describe a measurement (a usage error saying which flag).
    pub fn check(&self) -> Result<()> {
        if self.stylus_radius_mm < 0.0 || !self.stylus_radius_mm.is_finite() {
            return Err(Error::usage(
                format!("stylus radius {} mm", self.stylus_radius_mm),
                "give the stylus tip radius as a positive number of mm (half the ball diameter)",
            ));
        }
        if let Some(d) = self.sphere_diameter_mm {
            if !(d > 0.0 && d.is_finite()) {
                return Err(Error::usage(
                    format!("sphere diameter {d} mm"),
                    "give the calibrated sphere diameter in mm, e.g. 25.0",
                ));
            }
        }
        if let Some(a) = self.reference_angle_deg {
            if !a.is_finite() {
                return Err(Error::usage(
                    format!("reference angle {a}"),
                    "give the reference angle in degrees, e.g. 0",
                ));
            }
        }
        if self.radius_tolerance_mm.is_nan() || self.radius_tolerance_mm < 0.0 {
            return Err(Error::usage(
                format!("radius tolerance {} mm", self.radius_tolerance_mm),
                "give the tolerance as a positive number of mm, e.g. 0.01",
            ));
        }
        if self.fix_radius && self.sphere_diameter_mm.is_none() {
            return Err(Error::usage(
                "a fixed radius needs the sphere diameter",
                format!(
                    "add {} MM (and {} MM)",
                    words(Setting::SphereDiameter),
                    words(Setting::StylusRadius)
                ),
            ));
        }
        Ok(())
    }

    /// The radius the touch points lie on, sphere diameter / 2 + stylus radius, when the
    /// sphere diameter is known.
    pub fn nominal_radius_mm(&self) -> Option<f64> {
        self.sphere_diameter_mm
            .map(|d| d / 2.0 + self.stylus_radius_mm)
    }
}

/// Output of the sphere stage: the centres of sphere 1 and 2 at every position (in the order
/// of [`Measurement::positions`]) and, for touch points, every sphere fit.
#[derive(Debug, Clone)]
struct Centres {
    pairs: Vec<[[f64; 3]; 2]>,
    fits: Vec<SphereReport>,
}

/// Stage 1: the centres of both spheres at every position — read as given, or fitted to the
/// touch points (with the radius checked against the nominal one).
fn sphere_centres(
    m: &Measurement,
    opts: &AnalyzeOptions,
    nominal_radius: Option<f64>,
) -> Result<Centres> {
    let mut pairs: Vec<[[f64; 3]; 2]> = Vec::with_capacity(m.positions.len());
    let mut fits = Vec::new();
    for p in &m.positions {
        let mut pair = [[0.0; 3]; 2];
        for (k, s) in p.spheres.iter().enumerate() {
            if !m.touch_points {
                pair[k] = s.points_mm[0];
                continue;
            }
            let fit = fit_touch_sphere(m, p, k, opts, nominal_radius)?;
            pair[k] = fit.fit.centre_mm;
            fits.push(fit);
        }
        pairs.push(pair);
    }
    Ok(Centres { pairs, fits })
}

/// Fit sphere `k` (0 or 1) of position `p` to its touch points; a fit that fails or whose
/// radius is off the nominal one by more than the tolerance is an error at its first line.
fn fit_touch_sphere(
    m: &Measurement,
    p: &Position,
    k: usize,
    opts: &AnalyzeOptions,
    nominal_radius: Option<f64>,
) -> Result<SphereReport> {
    let s = &p.spheres[k];
    let line = s.lines.first().copied().unwrap_or(0);
    let at = || Location::line(&m.path, line);
    let what = || {
        format!(
            "sphere {} at {}° ({}) repeat {}",
            k + 1,
            p.angle_deg,
            p.direction,
            p.repeat
        )
    };
    let known = if opts.fix_radius {
        nominal_radius
    } else {
        None
    };
    let fit = fit_sphere(&s.points_mm, known).map_err(|e| {
        Error::input(
            at(),
            format!("{}: {e}", what()),
            "probe at least 4 points spread over the sphere (pole and around), not all in one plane",
        )
    })?;
    let deviation = nominal_radius.map(|r| fit.radius_mm - r);
    if let Some(dev) = deviation {
        if dev.abs() > opts.radius_tolerance_mm {
            return Err(Error::input(
                at(),
                format!(
                    "{}: fitted radius {:.4} mm differs from sphere + stylus {:.4} mm by {:+.4} mm (tolerance {} mm)",
                    what(),
                    fit.radius_mm,
                    nominal_radius.unwrap_or(0.0),
                    dev,
                    opts.radius_tolerance_mm
                ),
                format!(
                    "check {} and {}, then the touch points of this sphere (a stray point or the wrong sphere)",
                    words(Setting::SphereDiameter),
                    words(Setting::StylusRadius)
                ),
            ));
        }
    }
    Ok(SphereReport {
        direction: p.direction,
        repeat: p.repeat,
        angle_deg: p.angle_deg,
        sphere: k as u8 + 1,
        line,
        fit,
        radius_deviation_mm: deviation,
    })
}

/// Stage 2: the axis direction — nominal, or fitted to the circles the sphere centres trace
/// (which needs at least 3 distinct angles of the turn).
fn axis_direction(m: &Measurement, centres: &[[[f64; 3]; 2]], fit: bool) -> Result<AxisReport> {
    if !fit {
        return Ok(AxisReport::nominal(m.axis));
    }
    let mut distinct: Vec<i64> = m
        .positions
        .iter()
        .map(|p| key(modulo_deg(p.angle_deg)))
        .collect();
    distinct.sort_unstable();
    distinct.dedup();
    if distinct.len() < 3 {
        return Err(Error::input(
            Location::file(&m.path),
            format!(
                "{}: {} distinct angles; the circles of the sphere centres need at least 3",
                words(Setting::FitAxis),
                distinct.len()
            ),
            drop_fit_axis(),
        ));
    }
    let t1: Vec<[f64; 3]> = centres.iter().map(|c| c[0]).collect();
    let t2: Vec<[f64; 3]> = centres.iter().map(|c| c[1]).collect();
    let fit = fit_axis([&t1, &t2], m.axis.nominal_direction()).map_err(|e| {
        Error::input(
            Location::file(&m.path),
            format!("{}: {e}", words(Setting::FitAxis)),
            drop_fit_axis(),
        )
    })?;
    Ok(AxisReport::fitted(m.axis, fit))
}

/// The reference angle: the one given, else 0° when measured, else the smallest measured angle.
fn reference_angle_deg(m: &Measurement, given: Option<f64>) -> f64 {
    match given {
        Some(a) => a,
        None => {
            if m.positions.iter().any(|p| key(p.angle_deg) == 0) {
                0.0
            } else {
                m.positions
                    .iter()
                    .map(|p| p.angle_deg)
                    .fold(f64::INFINITY, f64::min)
            }
        }
    }
}

/// Stage 3: the reference vector a = c2 − c1 at the reference angle, averaged over the repeats
/// of the + direction (of the − direction when + was not measured there), and its lever arm
/// about the axis `n`.
fn reference_vector(
    m: &Measurement,
    centres: &[[[f64; 3]; 2]],
    n: [f64; 3],
    opts: &AnalyzeOptions,
) -> Result<Reference> {
    let reference_angle = reference_angle_deg(m, opts.reference_angle_deg);
    let at_ref = |d: Direction| -> Vec<usize> {
        (0..m.positions.len())
            .filter(|&i| {
                m.positions[i].direction == d
                    && key(m.positions[i].angle_deg) == key(reference_angle)
            })
            .collect()
    };
    let (ref_dir, ref_idx) = {
        let fwd = at_ref(Direction::Forward);
        if fwd.is_empty() {
            (Direction::Reverse, at_ref(Direction::Reverse))
        } else {
            (Direction::Forward, fwd)
        }
    };
    if ref_idx.is_empty() {
        return Err(Error::usage(
            format!("no position measured at the reference angle {reference_angle}°"),
            format!(
                "give {} one of the measured angles",
                words(Setting::ReferenceAngle)
            ),
        ));
    }
    let mut a = [0.0; 3];
    for &i in &ref_idx {
        for (k, ak) in a.iter_mut().enumerate() {
            *ak += (centres[i][1][k] - centres[i][0][k]) / ref_idx.len() as f64;
        }
    }
    let nn = nalgebra::Vector3::from(n);
    let av = nalgebra::Vector3::from(a);
    let lever = (av - nn * nn.dot(&av)).norm();
    if lever < 1e-6 * av.norm().max(1.0) {
        return Err(Error::input(
            Location::line(&m.path, m.positions[ref_idx[0]].first_line()),
            "the bar (sphere 1 → sphere 2) is parallel to the axis: it has no angle about it",
            "mount the bar in the plane normal to the axis (C: XY, A: YZ, B: XZ)",
        ));
    }
    Ok(Reference {
        angle_deg: reference_angle,
        direction: ref_dir,
        n: ref_idx.len(),
        vector_mm: a,
        lever_mm: lever,
    })
}

/// Stage 4: err = α − β at every position, β the angle of b = c2 − c1 from a about the axis `n`.
fn angular_errors(
    m: &Measurement,
    centres: &[[[f64; 3]; 2]],
    reference: &Reference,
    n: [f64; 3],
) -> Result<Vec<Observation>> {
    let a = reference.vector_mm;
    let mut observations = Vec::with_capacity(m.positions.len());
    for (p, c) in m.positions.iter().zip(centres) {
        let b = [c[1][0] - c[0][0], c[1][1] - c[0][1], c[1][2] - c[0][2]];
        let beta = signed_angle_about(a, b, n).ok_or_else(|| {
            Error::input(
                Location::line(&m.path, p.first_line()),
                format!(
                    "at {}° ({}) repeat {} the spheres are on one line along the axis",
                    p.angle_deg, p.direction, p.repeat
                ),
                "check the sphere numbers and coordinates of this position",
            )
        })?;
        observations.push(Observation {
            direction: p.direction,
            repeat: p.repeat,
            angle_deg: p.angle_deg,
            error_arcsec: angle_error_arcsec(p.angle_deg - reference.angle_deg, beta),
            line: p.first_line(),
        });
    }
    Ok(observations)
}

/// Stage 5: the mean, spread and range of the errors per direction and angle over the repeats,
/// direction `+` first, angles ascending.
fn mean_over_repeats(observations: &[Observation]) -> Vec<TableRow> {
    let mut groups: BTreeMap<(Direction, i64), Vec<&Observation>> = BTreeMap::new();
    for o in observations {
        groups
            .entry((o.direction, key(o.angle_deg)))
            .or_default()
            .push(o);
    }
    groups
        .values()
        .map(|g| {
            let e: Vec<f64> = g.iter().map(|o| o.error_arcsec).collect();
            TableRow {
                angle_deg: g[0].angle_deg,
                direction: g[0].direction,
                error_arcsec: linear::mean(&e),
                s_arcsec: linear::std_dev(&e),
                n: e.len(),
                min_arcsec: e.iter().cloned().fold(f64::INFINITY, f64::min),
                max_arcsec: e.iter().cloned().fold(f64::NEG_INFINITY, f64::max),
            }
        })
        .collect()
}

/// The summary of the sphere fits of a touch-point file (`None` for a centres file).
fn sphere_summary(fits: &[SphereReport], nominal_radius: Option<f64>) -> Option<SphereSummary> {
    if fits.is_empty() {
        return None;
    }
    Some(SphereSummary {
        fits: fits.len(),
        max_form_rms_mm: fits.iter().map(|f| f.fit.form_rms_mm).fold(0.0, f64::max),
        max_form_pv_mm: fits.iter().map(|f| f.fit.form_pv_mm).fold(0.0, f64::max),
        mean_radius_mm: fits.iter().map(|f| f.fit.radius_mm).sum::<f64>() / fits.len() as f64,
        max_abs_radius_deviation_mm: nominal_radius.map(|_| {
            fits.iter()
                .filter_map(|f| f.radius_deviation_mm)
                .fold(0.0, |m: f64, d| m.max(d.abs()))
        }),
    })
}

impl Analysis {
    /// The analysis with its errors in `sign`: the table's means, minima and maxima and the
    /// observations change sign (minimum and maximum swap); the ISO figures stay as they are.
    pub fn with_sign(mut self, sign: Sign) -> Analysis {
        // 0 stays 0, not −0 (which JSON and text would print as "-0").
        let neg = |v: f64| if v == 0.0 { 0.0 } else { -v };
        if sign != self.sign {
            for r in &mut self.table {
                r.error_arcsec = neg(r.error_arcsec);
                (r.min_arcsec, r.max_arcsec) = (neg(r.max_arcsec), neg(r.min_arcsec));
            }
            for o in &mut self.observations {
                o.error_arcsec = neg(o.error_arcsec);
            }
            self.sign = sign;
        }
        self
    }
}

/// ISO 230-2:2014 figures of the observations (targets = commanded angles, runs = repeats).
fn iso_figures(observations: &[Observation]) -> (Option<Evaluation>, Option<String>) {
    let has = |d: Direction| observations.iter().any(|o| o.direction == d);
    if !(has(Direction::Forward) && has(Direction::Reverse)) {
        return (
            None,
            Some("ISO 230-2 figures need every angle approached in both directions".into()),
        );
    }
    let samples: Vec<Sample> = observations
        .iter()
        .map(|o| Sample {
            run: o.repeat,
            direction: o.direction,
            target: o.angle_deg,
            // ISO 230-2 deviation x = actual − target = β − α = −err.
            deviation: -o.error_arcsec,
        })
        .collect();
    match linear::evaluate(&samples, Standard::Iso230_2_2014) {
        Ok(e) => (Some(e), None),
        Err(e) => (None, Some(e.to_string())),
    }
}

/// Angle folded into [0, 360): the table position of a modulo axis.
pub fn modulo_deg(angle_deg: f64) -> f64 {
    let w = wrap_deg(angle_deg);
    if w < 0.0 {
        w + 360.0
    } else if w >= 360.0 {
        0.0
    } else {
        w
    }
}

/// The hint when the axis cannot be fitted: more angles, or the nominal axis.
fn drop_fit_axis() -> String {
    format!(
        "measure at least 3 angles spread over the turn, or drop {} to use the nominal axis",
        words(Setting::FitAxis)
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rotary::input::parse_measurement;
    use errmap_core::io::CsvTable;
    use std::fmt::Write;
    use std::path::Path;

    /// Centres of a bar turned about Z through (5, 3) by α − err(α) with err(α) in arcsec.
    fn centre_file(err: impl Fn(f64, Direction) -> f64, repeats: u32) -> String {
        let mut s = String::from("axis,direction,repeat,angle_deg,sphere,x_mm,y_mm,z_mm\n");
        for (dir, sym) in [(Direction::Forward, "+"), (Direction::Reverse, "-")] {
            for r in 0..repeats {
                for i in 0..12 {
                    let alpha = i as f64 * 30.0;
                    let theta = (alpha - err(alpha, dir) / 3600.0).to_radians();
                    for (k, (x0, z)) in [(50.0, 40.0), (250.0, 55.0)].iter().enumerate() {
                        let (x, y) = (5.0 + x0 * theta.cos(), 3.0 + x0 * theta.sin());
                        writeln!(s, "C,{sym},{r},{alpha},{},{x},{y},{z}", k + 1).unwrap();
                    }
                }
            }
        }
        s
    }

    #[test]
    fn planted_errors_come_back_per_direction() {
        let planted = |a: f64, d: Direction| {
            10.0 * a.to_radians().sin() + if d == Direction::Reverse { 4.0 } else { 0.0 }
        };
        let text = centre_file(planted, 2);
        let m = parse_measurement(CsvTable::parse(Path::new("c.csv"), &text).unwrap()).unwrap();
        let an = analyze(&m, &AnalyzeOptions::default()).unwrap();
        assert_eq!(an.table.len(), 24);
        assert_eq!(an.reference.direction, Direction::Forward);
        assert!((an.reference.lever_mm - 200.0).abs() < 1e-9);
        for row in &an.table {
            let want = planted(row.angle_deg, row.direction);
            assert!(
                (row.error_arcsec - want).abs() < 1e-6,
                "{row:?} want {want}"
            );
            assert_eq!(row.n, 2);
            assert!(row.s_arcsec.unwrap() < 1e-6);
        }
        // Fitting the axis of a perfect C axis finds Z through (5, 3).
        let opts = AnalyzeOptions {
            fit_axis: true,
            ..Default::default()
        };
        let an = analyze(&m, &opts).unwrap();
        assert!(an.axis_fit.tilt_arcsec.unwrap() < 1e-4);
        let loc = an.axis_fit.location_mm.unwrap();
        assert!(
            (loc[0] - 5.0).abs() < 1e-9 && (loc[1] - 3.0).abs() < 1e-9,
            "{loc:?}"
        );
    }

    /// Centres of a C-axis bar for commanded angles `alphas`, one direction, turned by α − err.
    fn file_for(alphas: &[f64], sym: &str, err: impl Fn(f64) -> f64) -> Measurement {
        let mut s = String::from("axis,direction,repeat,angle_deg,sphere,x_mm,y_mm,z_mm\n");
        for &alpha in alphas {
            let theta = (alpha - err(alpha) / 3600.0).to_radians();
            for (k, r) in [(1, 40.0), (2, 240.0)] {
                writeln!(
                    s,
                    "C,{sym},0,{alpha},{k},{},{},10",
                    r * theta.cos(),
                    r * theta.sin()
                )
                .unwrap();
            }
        }
        parse_measurement(CsvTable::parse(Path::new("n.csv"), &s).unwrap()).unwrap()
    }

    #[test]
    fn negative_angles_reverse_only_and_a_chosen_reference() {
        // A turn commanded −180 … +180 in the − direction only, err = 3″·cos α − 3″.
        let alphas: Vec<f64> = (-6..=6).map(|i| i as f64 * 30.0).collect();
        let err = |a: f64| 3.0 * a.to_radians().cos() - 3.0;
        let m = file_for(&alphas, "-", err);
        let an = analyze(&m, &AnalyzeOptions::default()).unwrap();
        assert_eq!(an.reference.direction, Direction::Reverse);
        assert_eq!(an.reference.angle_deg, 0.0);
        for row in &an.table {
            assert!(
                (row.error_arcsec - err(row.angle_deg)).abs() < 1e-6,
                "{row:?}"
            );
        }
        assert!(an.iso230_2.is_none() && an.iso230_2_note.is_some());
        // Reference at −90°: errors are relative to err(−90°) = −3″.
        let opts = AnalyzeOptions {
            reference_angle_deg: Some(-90.0),
            ..Default::default()
        };
        let an = analyze(&m, &opts).unwrap();
        for row in &an.table {
            let want = err(row.angle_deg) - err(-90.0);
            assert!((row.error_arcsec - want).abs() < 1e-6, "{row:?}");
        }
        // A reference angle that was not measured is a usage error.
        let opts = AnalyzeOptions {
            reference_angle_deg: Some(45.0),
            ..Default::default()
        };
        let e = analyze(&m, &opts).unwrap_err().to_string();
        assert!(e.contains("45°"), "{e}");
        // Without 0° the smallest angle is the reference.
        let m = file_for(&[10.0, 100.0, 200.0, 300.0], "+", |_| 0.0);
        assert_eq!(
            analyze(&m, &AnalyzeOptions::default())
                .unwrap()
                .reference
                .angle_deg,
            10.0
        );
    }

    #[test]
    fn modulo_folds_into_one_turn() {
        assert_eq!(modulo_deg(360.0), 0.0);
        assert_eq!(modulo_deg(-90.0), 270.0);
    }
}
