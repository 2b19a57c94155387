//! Synthetic sphere probing around a rotary axis with planted angular errors, tilt and offset.
//!
//! A bar carries two spheres at `inner_radius_mm` and `inner_radius_mm + bar_length_mm` from
//! the axis. The real axis is tilted and offset from nominal; at a commanded angle α it turns
//! by θ = α − err(α, direction), where err = α − β is the planted angular error (zero at 0° in
//! the + direction, the reference). Touch points are stylus-centre positions on a sphere of
//! radius sphere + stylus, spread over the upper cap, with Gaussian noise along the normal.

use crate::Setting;
use errmap_core::error::{Error, Result};
use errmap_core::io::{write_atomic, write_json};
use errmap_core::setting::words;
use errmap_metrology::rotary::input::{Direction, RotaryAxis};
use errmap_metrology::rotary::sphere::cap_directions;
use nalgebra::{Rotation3, Unit, Vector3};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// What to generate. Defaults: a C axis, 15° steps, 3 repeats each way, 25 touch points per
/// sphere, 0.5 µm probe noise, 200 mm bar.
#[derive(Debug, Clone, Serialize)]
pub struct RotarySynthConfig {
    /// The rotary axis probed (A, B or C: nominally about X, Y or Z).
    pub axis: RotaryAxis,
    /// Seed of the probe noise (ChaCha8).
    pub seed: u64,
    /// Angle between commanded positions, degrees; it must divide 360 and be at least
    /// [`MIN_STEP_DEG`].
    pub step_deg: f64,
    /// Runs in each direction (+ runs ascending, − runs descending).
    pub repeats: u32,
    /// Radial distance from sphere 1 to sphere 2 along the bar, mm.
    pub bar_length_mm: f64,
    /// Distance of sphere 1 from the axis.
    pub inner_radius_mm: f64,
    /// Heights of the sphere centres along the axis.
    pub heights_mm: [f64; 2],
    /// Diameter of each reference sphere, mm.
    pub sphere_diameter_mm: f64,
    /// Radius of the stylus tip, mm: touch points (stylus centres) lie at sphere radius +
    /// this from the sphere's centre.
    pub stylus_radius_mm: f64,
    /// Touch points per sphere and position (at least 4).
    pub points_per_sphere: usize,
    /// Touch points lie within this angle of the sphere's pole (90° = hemisphere).
    pub cap_half_angle_deg: f64,
    /// Standard deviation of each touch point along the surface normal (and of each centre
    /// coordinate in the centres file).
    pub probe_noise_um: f64,
    /// Amplitude of err's once-per-turn term `sin(α + φ₁)`, arcsec.
    pub once_per_turn_arcsec: f64,
    /// Phase φ₁ of the once-per-turn term, degrees.
    pub once_per_turn_phase_deg: f64,
    /// Amplitude of err's twice-per-turn term `sin(2α + 0.3 rad)`, arcsec.
    pub twice_per_turn_arcsec: f64,
    /// Amplitude of err's three-times-per-turn term `sin(3α + 1.1 rad)`, arcsec.
    pub thrice_per_turn_arcsec: f64,
    /// Added to err in the − direction.
    pub reversal_arcsec: f64,
    /// Inclination of the axis toward the two other machine axes (for C: X then Y; A: Y, Z; B: Z, X).
    pub tilt_arcsec: [f64; 2],
    /// Axis location in the plane through the origin normal to the nominal axis (same order).
    pub offset_mm: [f64; 2],
}

impl Default for RotarySynthConfig {
    fn default() -> Self {
        RotarySynthConfig {
            axis: RotaryAxis::C,
            seed: 1,
            step_deg: 15.0,
            repeats: 3,
            bar_length_mm: 200.0,
            inner_radius_mm: 50.0,
            heights_mm: [80.0, 95.0],
            sphere_diameter_mm: 25.0,
            stylus_radius_mm: 1.5,
            points_per_sphere: 25,
            cap_half_angle_deg: 90.0,
            probe_noise_um: 0.5,
            once_per_turn_arcsec: 8.0,
            once_per_turn_phase_deg: 40.0,
            twice_per_turn_arcsec: 5.0,
            thrice_per_turn_arcsec: 2.5,
            reversal_arcsec: 4.0,
            tilt_arcsec: [25.0, -15.0],
            offset_mm: [0.8, -0.5],
        }
    }
}

/// Planted truth at one commanded angle.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TruthRow {
    /// Commanded angle α, degrees in [0, 360).
    pub angle_deg: f64,
    /// Approach direction (written `+` or `-`).
    #[serde(with = "errmap_core::direction::symbol")]
    pub direction: Direction,
    /// Planted err = α − β (commanded − actual), arcsec; 0 at 0° in the + direction.
    pub error_arcsec: f64,
}

/// The planted axis and errors.
#[derive(Debug, Clone, Serialize)]
pub struct RotaryTruth {
    /// The rotary axis probed.
    pub axis: RotaryAxis,
    /// Unit direction of the real (tilted) axis, machine coordinates.
    pub direction: [f64; 3],
    /// Angle between the real and the nominal axis direction, arcsec.
    pub tilt_arcsec: f64,
    /// Keyed by axis letter, as `rotary analyze --fit-axis` reports it.
    pub tilt_toward_arcsec: std::collections::BTreeMap<String, f64>,
    /// Where the real axis crosses the plane through the origin normal to the nominal axis,
    /// machine coordinates, mm.
    pub location_mm: [f64; 3],
    /// The planted err at every commanded angle, the + direction first.
    pub table: Vec<TruthRow>,
    /// The whole configuration generated from.
    pub config: RotarySynthConfig,
}

/// One generated CSV row.
#[derive(Debug, Clone, PartialEq)]
pub struct SynthRow {
    /// Direction of the run.
    pub direction: Direction,
    /// Repeat of the run, from 0.
    pub repeat: u32,
    /// Commanded angle α, degrees.
    pub angle_deg: f64,
    /// 1 for the inner sphere, 2 for the one at the end of the bar.
    pub sphere: u8,
    /// Touch point number on the sphere, from 1; `None` for a centre row.
    pub point: Option<usize>,
    /// The touch point (stylus centre) or the sphere centre, noise included, machine
    /// coordinates, mm.
    pub xyz_mm: [f64; 3],
}

/// Generated data: touch points, noisy centres and the truth.
#[derive(Debug, Clone)]
pub struct RotarySynth {
    /// Touch points of both spheres at every position of every run, in probing order
    /// (`touch_points.csv`).
    pub touch_points: Vec<SynthRow>,
    /// One centre per sphere and position, each coordinate with the probe noise
    /// (`centres.csv`).
    pub centres: Vec<SynthRow>,
    /// The planted axis and errors (`truth.json`).
    pub truth: RotaryTruth,
}

const ARCSEC_PER_RAD: f64 = 180.0 * 3600.0 / std::f64::consts::PI;

/// The two machine axes (indices) normal to the rotary axis, in cyclic order.
fn other_axes(axis: RotaryAxis) -> [usize; 2] {
    match axis {
        RotaryAxis::A => [1, 2],
        RotaryAxis::B => [2, 0],
        RotaryAxis::C => [0, 1],
    }
}

/// Smallest angle step the generator takes: 36 000 positions a turn.
pub const MIN_STEP_DEG: f64 = 0.01;
/// Most probe points the generator makes (positions × repeats × 2 spheres × points).
pub const MAX_SAMPLES: f64 = 1e7;

impl RotarySynthConfig {
    /// Refuse a configuration the generator cannot honour (a usage error naming the flag):
    /// a step below [`MIN_STEP_DEG`] or not dividing the turn, more than [`MAX_SAMPLES`]
    /// probe points, no repeats, fewer than 4 points a sphere, or a noise that is not a
    /// finite number ≥ 0.
    pub fn check(&self) -> Result<(), crate::SynthError> {
        // NaN passes every comparison below: refuse it by name.
        if self.step_deg.is_nan() {
            return Err(Error::usage(
                format!("{} NaN is not a number of degrees", words(Setting::StepDeg)),
                "choose a step that divides 360, e.g. 10, 15, 30",
            )
            .into());
        }
        if self.step_deg > 0.0 && self.step_deg < MIN_STEP_DEG {
            return Err(Error::usage(
                format!(
                    "{} {:?} is below the smallest step of {MIN_STEP_DEG}°",
                    words(Setting::StepDeg),
                    self.step_deg
                ),
                "choose a step that divides 360, e.g. 10, 15, 30",
            )
            .into());
        }
        let samples =
            360.0 / self.step_deg * self.repeats as f64 * 2.0 * self.points_per_sphere as f64;
        if samples > MAX_SAMPLES {
            return Err(Error::usage(
                format!(
                    "{samples:.3e} probe points would be generated, more than {MAX_SAMPLES:.0e}"
                ),
                format!(
                    "use a larger {} or fewer {} or {}",
                    words(Setting::StepDeg),
                    words(Setting::Repeats),
                    words(Setting::Points)
                ),
            )
            .into());
        }
        let turns = 360.0 / self.step_deg;
        if turns.round() < 1.0 || (turns - turns.round()).abs() > 1e-9 {
            return Err(Error::usage(
                format!("step {}° does not divide the turn", self.step_deg),
                "choose a step that divides 360, e.g. 10, 15, 30",
            )
            .into());
        }
        if self.repeats == 0
            || self.points_per_sphere < 4
            || !(self.probe_noise_um.is_finite() && self.probe_noise_um >= 0.0)
        {
            return Err(Error::usage(
                format!(
                    "synth rotary needs {} ≥ 1, {} ≥ 4 and a finite {} ≥ 0",
                    words(Setting::Repeats),
                    words(Setting::Points),
                    words(Setting::NoiseUm)
                ),
                format!(
                    "e.g. {} 3 {} 25 {} 0.5",
                    words(Setting::Repeats),
                    words(Setting::Points),
                    words(Setting::NoiseUm)
                ),
            )
            .into());
        }
        Ok(())
    }

    /// Planted err = α − β (arcsec) at commanded `angle_deg` approached in `direction`.
    pub fn planted_error_arcsec(&self, angle_deg: f64, direction: Direction) -> f64 {
        let curve = |a: f64| {
            let r = a.to_radians();
            let p1 = self.once_per_turn_phase_deg.to_radians();
            self.once_per_turn_arcsec * (r + p1).sin()
                + self.twice_per_turn_arcsec * (2.0 * r + 0.3).sin()
                + self.thrice_per_turn_arcsec * (3.0 * r + 1.1).sin()
        };
        let reversal = match direction {
            Direction::Forward => 0.0,
            Direction::Reverse => self.reversal_arcsec,
        };
        curve(angle_deg) - curve(0.0) + reversal
    }

    /// Commanded angles of one run, ascending: 0, step, … below 360.
    pub fn angles_deg(&self) -> Vec<f64> {
        let n = (360.0 / self.step_deg).round().max(1.0) as usize;
        (0..n).map(|i| i as f64 * 360.0 / n as f64).collect()
    }
}

/// Generate the data set described by `config`: the real axis → the planted errors → the
/// probed centres and touch points of every run.
pub fn generate(config: &RotarySynthConfig) -> RotarySynth {
    let axis = RealAxis::of(config);
    let (touch_points, centres) = probe(config, &axis);
    let main = config.axis.index();
    let nominal = Vector3::from(config.axis.nominal_direction());
    let dir = axis.direction;
    let letters = ["x", "y", "z"];
    let tilt_toward = other_axes(config.axis)
        .iter()
        .map(|&k| {
            (
                letters[k].to_string(),
                dir[k].atan2(dir[main]) * ARCSEC_PER_RAD,
            )
        })
        .collect();
    RotarySynth {
        touch_points,
        centres,
        truth: RotaryTruth {
            axis: config.axis,
            direction: [dir.x, dir.y, dir.z],
            tilt_arcsec: dir.angle(&nominal) * ARCSEC_PER_RAD,
            tilt_toward_arcsec: tilt_toward,
            location_mm: [axis.origin.x, axis.origin.y, axis.origin.z],
            table: planted_table(config),
            config: config.clone(),
        },
    }
}

/// The real axis of a configuration and where the spheres are at α = 0.
struct RealAxis {
    /// Unit direction, tilted from nominal.
    direction: Vector3<f64>,
    /// Where the axis crosses the plane through the origin normal to the nominal axis.
    origin: Vector3<f64>,
    /// Centres of sphere 1 and 2 before turning.
    start: [Vector3<f64>; 2],
}

impl RealAxis {
    fn of(config: &RotarySynthConfig) -> RealAxis {
        let main = config.axis.index();
        let [i, j] = other_axes(config.axis);
        let unit = |k: usize| {
            let mut v = Vector3::zeros();
            v[k] = 1.0;
            v
        };
        let mut dir = unit(main);
        dir += unit(i) * (config.tilt_arcsec[0] / ARCSEC_PER_RAD).tan();
        dir += unit(j) * (config.tilt_arcsec[1] / ARCSEC_PER_RAD).tan();
        let dir = dir.normalize();
        let origin = unit(i) * config.offset_mm[0] + unit(j) * config.offset_mm[1];
        // Bar along e_i (made normal to the real axis), spheres raised along the axis.
        let radial = (unit(i) - dir * dir.dot(&unit(i))).normalize();
        let start = [
            origin + radial * config.inner_radius_mm + dir * config.heights_mm[0],
            origin
                + radial * (config.inner_radius_mm + config.bar_length_mm)
                + dir * config.heights_mm[1],
        ];
        RealAxis {
            direction: dir,
            origin,
            start,
        }
    }
}

/// The planted error at every commanded angle, + direction first.
fn planted_table(config: &RotarySynthConfig) -> Vec<TruthRow> {
    let mut table = Vec::new();
    for direction in [Direction::Forward, Direction::Reverse] {
        for alpha in config.angles_deg() {
            table.push(TruthRow {
                angle_deg: alpha,
                direction,
                error_arcsec: config.planted_error_arcsec(alpha, direction),
            });
        }
    }
    table
}

/// Probe both spheres at every position of every run (+ runs ascending, − runs descending):
/// the touch points and the noisy centres, noise drawn from the seed in probing order.
fn probe(config: &RotarySynthConfig, axis: &RealAxis) -> (Vec<SynthRow>, Vec<SynthRow>) {
    let touch_radius = config.sphere_diameter_mm / 2.0 + config.stylus_radius_mm;
    let pole = config.axis.nominal_direction();
    let dirs = cap_directions(config.points_per_sphere, config.cap_half_angle_deg, pole);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(config.seed);
    let sigma_mm = config.probe_noise_um * 1e-3;
    // A non-finite or negative σ gives no noise rather than a panic.
    let normal = Normal::new(0.0, sigma_mm).ok();
    let noise = move |rng: &mut rand_chacha::ChaCha8Rng| normal.map_or(0.0, |n| n.sample(rng));
    let (origin, dir) = (axis.origin, axis.direction);
    let mut touch_points = Vec::new();
    let mut centres = Vec::new();
    let ascending = config.angles_deg();
    for direction in [Direction::Forward, Direction::Reverse] {
        let run: Vec<f64> = match direction {
            Direction::Forward => ascending.clone(),
            Direction::Reverse => ascending.iter().rev().copied().collect(),
        };
        for repeat in 0..config.repeats {
            for &alpha in &run {
                let theta =
                    (alpha - config.planted_error_arcsec(alpha, direction) / 3600.0).to_radians();
                let rot = Rotation3::from_axis_angle(&Unit::new_normalize(dir), theta);
                for (k, p0) in axis.start.iter().enumerate() {
                    let row = |point, p: Vector3<f64>| SynthRow {
                        direction,
                        repeat,
                        angle_deg: alpha,
                        sphere: k as u8 + 1,
                        point,
                        xyz_mm: [p.x, p.y, p.z],
                    };
                    let c = origin + rot * (p0 - origin);
                    let mut noisy = c;
                    for v in noisy.iter_mut() {
                        *v += noise(&mut rng);
                    }
                    centres.push(row(None, noisy));
                    for (q, d) in dirs.iter().enumerate() {
                        let u = Vector3::from(*d);
                        let p = c + u * (touch_radius + noise(&mut rng));
                        touch_points.push(row(Some(q + 1), p));
                    }
                }
            }
        }
    }
    (touch_points, centres)
}

/// Write rows as a measurement CSV (with a `point` column when the rows are touch points).
pub fn write_rows(
    path: &Path,
    axis: RotaryAxis,
    rows: &[SynthRow],
) -> Result<(), crate::SynthError> {
    let with_point = rows.iter().any(|r| r.point.is_some());
    write_atomic(path, |w| {
        w.write_all(b"axis,direction,repeat,angle_deg,sphere,x_mm,y_mm,z_mm")?;
        w.write_all(if with_point { b",point\n" } else { b"\n" })?;
        for r in rows {
            write!(
                w,
                "{axis},{},{},{},{},{:.5},{:.5},{:.5}",
                r.direction, r.repeat, r.angle_deg, r.sphere, r.xyz_mm[0], r.xyz_mm[1], r.xyz_mm[2]
            )?;
            match r.point {
                Some(p) => writeln!(w, ",{p}")?,
                None => writeln!(w)?,
            }
        }
        Ok(())
    })
    .map_err(Into::into)
}

/// Check the configuration ([`RotarySynthConfig::check`]), generate and write
/// `touch_points.csv`, `centres.csv` and `truth.json` into `dir`; returns the paths written.
pub fn write_set(
    dir: &Path,
    config: &RotarySynthConfig,
) -> Result<Vec<PathBuf>, crate::SynthError> {
    config.check()?;
    let synth = generate(config);
    let touch = dir.join("touch_points.csv");
    let centres = dir.join("centres.csv");
    let truth = dir.join("truth.json");
    write_rows(&touch, config.axis, &synth.touch_points)?;
    write_rows(&centres, config.axis, &synth.centres)?;
    write_json(&truth, &synth.truth)?;
    Ok(vec![touch, centres, truth])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn planted_error_is_zero_at_the_reference_and_periodic() {
        let c = RotarySynthConfig::default();
        assert_eq!(c.planted_error_arcsec(0.0, Direction::Forward), 0.0);
        assert!(
            (c.planted_error_arcsec(0.0, Direction::Reverse) - c.reversal_arcsec).abs() < 1e-12
        );
        for a in [10.0, 123.0, 271.0] {
            let d = c.planted_error_arcsec(a, Direction::Forward)
                - c.planted_error_arcsec(a + 360.0, Direction::Forward);
            assert!(d.abs() < 1e-9);
        }
        assert_eq!(c.angles_deg().len(), 24);
    }

    #[test]
    fn noiseless_touch_points_lie_on_sphere_plus_stylus() {
        let c = RotarySynthConfig {
            probe_noise_um: 0.0,
            repeats: 1,
            step_deg: 90.0,
            ..Default::default()
        };
        let s = generate(&c);
        assert_eq!(s.touch_points.len(), 2 * 4 * 2 * 25);
        // Sphere 2 at 270° in the − run: distance from its (noise-free) centre.
        let centre = s
            .centres
            .iter()
            .find(|r| r.direction == Direction::Reverse && r.angle_deg == 270.0 && r.sphere == 2)
            .unwrap()
            .xyz_mm;
        let r = c.sphere_diameter_mm / 2.0 + c.stylus_radius_mm;
        for p in s
            .touch_points
            .iter()
            .filter(|p| p.direction == Direction::Reverse && p.angle_deg == 270.0 && p.sphere == 2)
        {
            let d = ((p.xyz_mm[0] - centre[0]).powi(2)
                + (p.xyz_mm[1] - centre[1]).powi(2)
                + (p.xyz_mm[2] - centre[2]).powi(2))
            .sqrt();
            assert!((d - r).abs() < 1e-9);
        }
        // Same seed, same rows.
        assert_eq!(generate(&c).touch_points, s.touch_points);
    }
}
