//! Synthetic circular-test runs: a forward simulation of two axes contouring a circle with planted squareness, scale, backlash, reversal spikes, servo lag and cyclic errors, read as a ballbar or as two axes.
//!
//! Each axis follows its command delayed by its own lag, through a backlash element (a play
//! operator of width b for b > 0; a controller over-compensation that jumps by |b| at the
//! reversal for b < 0), plus a reversal spike h·exp(−s/λ) outward after each reversal (s: path
//! since the reversal), squareness (the second axis tilted toward −first for S > 0), scale
//! and a cyclic error A·sin(2π·x/P + φ) along the axis. The path is displaced by the set-up
//! offset; a ballbar reading is the exact distance from the set-up centre minus R, at the
//! commanded angle; two-axis readings are the positions. Gaussian noise is added to each.

use crate::Setting;
use errmap_core::error::{Error, Result};
use errmap_core::io::{write_atomic, write_json};
use errmap_core::setting::words;
use errmap_metrology::circular::input::Form;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use serde::Serialize;
use std::f64::consts::{PI, TAU};
use std::path::{Path, PathBuf};

/// What to generate; the defaults plant every term.
#[derive(Debug, Clone, Serialize)]
pub struct CircularSynthConfig {
    /// Seed of the reading noise (ChaCha8).
    pub seed: u64,
    /// What the instrument reads: radial deviations (ballbar) or the two axis positions.
    pub form: Form,
    /// Nominal radius R of the circle, mm (the ballbar's length).
    pub radius_mm: f64,
    /// Contouring feed along the circle, mm/min: with the servo lags it sets how far each
    /// axis trails its command.
    pub feed_mm_per_min: f64,
    /// Angle between two readings, degrees; it must divide 360 and be at most 10.
    pub step_deg: f64,
    /// Overshoot arc before and after each turn, degrees (its rows are labelled `overshoot`).
    pub overshoot_deg: f64,
    /// Write the counter-clockwise run (first).
    pub ccw: bool,
    /// Write the clockwise run (after the ccw one).
    pub cw: bool,
    /// Standard deviation of each reading (radial, or each axis).
    pub noise_um: f64,
    /// Nominal centre added to two-axis positions.
    pub centre_mm: [f64; 2],
    /// Set-up offset: centre of the measured path minus nominal centre.
    pub centre_offset_um: [f64; 2],
    /// Squareness S, µm/m: the first axis moves by −S·(second axis position), the second
    /// axis tilted toward −first for S > 0.
    pub squareness_um_per_m: f64,
    /// Scale error of each axis (first, second), µm per m of position from the centre;
    /// positive: the axis travels further than commanded.
    pub scale_um_per_m: [f64; 2],
    /// Backlash b of each axis, µm: b > 0 lost motion (a play of width b), b < 0 a
    /// controller over-compensation that jumps by |b| at the reversal.
    pub backlash_um: [f64; 2],
    /// Height h of each axis' reversal spike, µm, outward along the axis after its reversal.
    pub spike_um: [f64; 2],
    /// Decay length λ of each axis' spike, mm of path since the reversal.
    pub spike_decay_mm: [f64; 2],
    /// Servo lag of each axis, ms: the axis follows its command this much later.
    pub lag_ms: [f64; 2],
    /// Amplitude A of each axis' cyclic error, µm.
    pub cyclic_um: [f64; 2],
    /// Period P of each axis' cyclic error, mm of axis position from the centre.
    pub cyclic_period_mm: [f64; 2],
    /// Phase φ of each axis' cyclic error at the centre, degrees.
    pub cyclic_phase_deg: [f64; 2],
}

impl CircularSynthConfig {
    /// The step must divide the turn into steps of 10° or less; radius and feed positive, the
    /// noise finite and ≥ 0.
    pub fn check(&self) -> Result<(), crate::SynthError> {
        let steps = 360.0 / self.step_deg;
        if !(self.step_deg.is_finite() && self.step_deg > 0.0 && self.step_deg <= 10.0)
            || (steps - steps.round()).abs() > 1e-9
        {
            return Err(Error::usage(
                format!(
                    "step {}° does not divide the turn into steps of 10° or less",
                    self.step_deg
                ),
                "choose a step that divides 360, e.g. 0.1, 0.5, 1",
            )
            .into());
        }
        let positive = |v: f64| v.is_finite() && v > 0.0;
        let noise_ok = self.noise_um.is_finite() && self.noise_um >= 0.0;
        if !positive(self.radius_mm) || !positive(self.feed_mm_per_min) || !noise_ok {
            return Err(Error::usage(
                format!(
                    "synth circular needs a positive {} and {} and a finite {} ≥ 0",
                    words(Setting::Radius),
                    words(Setting::Feed),
                    words(Setting::NoiseUm)
                ),
                format!(
                    "e.g. {} 100 {} 1000 {} 0.2",
                    words(Setting::Radius),
                    words(Setting::Feed),
                    words(Setting::NoiseUm)
                ),
            )
            .into());
        }
        Ok(())
    }
}

impl Default for CircularSynthConfig {
    fn default() -> Self {
        CircularSynthConfig {
            seed: 1,
            form: Form::Radial,
            radius_mm: 100.0,
            feed_mm_per_min: 1000.0,
            step_deg: 0.05,
            overshoot_deg: 10.0,
            ccw: true,
            cw: true,
            noise_um: 0.2,
            centre_mm: [0.0, 0.0],
            centre_offset_um: [12.0, -8.0],
            squareness_um_per_m: 30.0,
            scale_um_per_m: [25.0, 5.0],
            backlash_um: [3.0, -1.5],
            spike_um: [4.0, 2.5],
            spike_decay_mm: [1.5, 3.0],
            lag_ms: [1.2, 0.7],
            cyclic_um: [1.0, 0.8],
            cyclic_period_mm: [10.0, 16.0],
            cyclic_phase_deg: [30.0, 200.0],
        }
    }
}

/// The planted terms, keyed as `errmap circular --json` reports them.
#[derive(Debug, Clone, Serialize)]
pub struct CircularTruth {
    /// Planted squareness S, µm/m (sign as [`CircularSynthConfig::squareness_um_per_m`]).
    pub squareness_um_per_m: f64,
    /// Scale error of the first axis minus that of the second, µm/m.
    pub scale_mismatch_um_per_m: f64,
    /// Backlash of the first axis, µm (negative: over-compensation).
    pub backlash_first_um: f64,
    /// Backlash of the second axis, µm (negative: over-compensation).
    pub backlash_second_um: f64,
    /// Reversal spike height of the first axis, µm.
    pub reversal_spike_first_um: f64,
    /// Reversal spike height of the second axis, µm.
    pub reversal_spike_second_um: f64,
    /// Servo lag of the first axis minus that of the second, ms.
    pub servo_mismatch_ms: f64,
    /// Cyclic error amplitude of the first axis, µm.
    pub cyclic_first_um: f64,
    /// Cyclic error amplitude of the second axis, µm.
    pub cyclic_second_um: f64,
    /// Spike decay lengths (first, second axis), mm of path.
    pub spike_decay_mm: [f64; 2],
    /// Cyclic error periods (first, second axis), mm.
    pub cyclic_period_mm: [f64; 2],
    /// The whole configuration generated from.
    pub config: CircularSynthConfig,
}

/// One generated row: direction label, commanded angle, reading.
#[derive(Debug, Clone, PartialEq)]
pub struct SynthRow {
    /// `ccw` or `cw`, or `overshoot` for a reading outside the measured turn.
    pub label: &'static str,
    /// Commanded angle, degrees counter-clockwise from the first axis: a ccw run goes from
    /// −overshoot to 360 + overshoot, a cw run back.
    pub angle_deg: f64,
    /// Radial form: `[deviation, 0]`, the deviation (distance from the set-up centre − R)
    /// in µm; two-axis form: `[x_mm, y_mm]`, the positions in mm.
    pub reading: [f64; 2],
}

/// Error state of one axis along the run (backlash play and the last reversal).
struct Axis {
    play_mm: Option<f64>,
}

impl CircularSynthConfig {
    /// The planted terms of this configuration, as `truth.json` records them.
    pub fn truth(&self) -> CircularTruth {
        CircularTruth {
            squareness_um_per_m: self.squareness_um_per_m,
            scale_mismatch_um_per_m: self.scale_um_per_m[0] - self.scale_um_per_m[1],
            backlash_first_um: self.backlash_um[0],
            backlash_second_um: self.backlash_um[1],
            reversal_spike_first_um: self.spike_um[0],
            reversal_spike_second_um: self.spike_um[1],
            servo_mismatch_ms: self.lag_ms[0] - self.lag_ms[1],
            cyclic_first_um: self.cyclic_um[0],
            cyclic_second_um: self.cyclic_um[1],
            spike_decay_mm: self.spike_decay_mm,
            cyclic_period_mm: self.cyclic_period_mm,
            config: self.clone(),
        }
    }

    /// Actual position of axis `k` (mm) for commanded angle `theta` (rad) in direction `sigma`.
    fn axis_position(&self, k: usize, theta: f64, sigma: f64, state: &mut Axis) -> f64 {
        let r = self.radius_mm;
        let omega = self.feed_mm_per_min / 60.0 / r; // rad/s
        let lagged = theta - sigma * omega * self.lag_ms[k] * 1e-3;
        let pos = |t: f64| if k == 0 { r * t.cos() } else { r * t.sin() };
        let cmd = pos(lagged);
        // Velocity sign of the axis: d(pos)/dθ times σ.
        let vel = sigma * if k == 0 { -lagged.sin() } else { lagged.cos() };
        let b_mm = self.backlash_um[k] * 1e-3;
        let mut actual = if b_mm > 0.0 {
            let half = b_mm / 2.0;
            let p = state
                .play_mm
                .unwrap_or(cmd - half * vel.signum())
                .clamp(cmd - half, cmd + half);
            state.play_mm = Some(p);
            p
        } else {
            cmd + (b_mm.abs() / 2.0) * vel.signum()
        };
        // Reversal spike: outward along the axis after its last reversal.
        let shift = if k == 0 { 0.0 } else { PI / 2.0 };
        let phi = (sigma * (theta - shift)).rem_euclid(PI);
        let reversal_at = theta - sigma * phi;
        let outward = if k == 0 {
            reversal_at.cos()
        } else {
            reversal_at.sin()
        }
        .signum();
        actual += self.spike_um[k] * 1e-3 * (-r * phi / self.spike_decay_mm[k]).exp() * outward;
        // Scale, cyclic error; squareness moves the first axis by −α·(second axis position).
        actual += self.scale_um_per_m[k] * 1e-6 * cmd;
        let (a, p, ph) = (
            self.cyclic_um[k],
            self.cyclic_period_mm[k],
            self.cyclic_phase_deg[k],
        );
        actual += a * 1e-3 * (TAU * cmd / p + ph.to_radians()).sin();
        if k == 0 {
            let y = r * (theta - sigma * omega * self.lag_ms[1] * 1e-3).sin();
            actual -= self.squareness_um_per_m * 1e-6 * y;
        }
        actual
    }
}

/// Generate the rows of the runs in time order (ccw first, then cw), with overshoot arcs.
pub fn generate(config: &CircularSynthConfig) -> Vec<SynthRow> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(config.seed);
    let normal = Normal::new(0.0, config.noise_um.max(0.0)).ok();
    let mut noise = move || normal.map_or(0.0, |n| n.sample(&mut rng));
    let n_turn = (360.0 / config.step_deg).round().max(1.0) as i64;
    let step = 360.0 / n_turn as f64;
    let n_over = (config.overshoot_deg / step).round() as i64;
    let mut rows = Vec::new();
    let runs = [(config.ccw, 1.0, "ccw"), (config.cw, -1.0, "cw")];
    for (wanted, sigma, label) in runs.into_iter().filter(|r| r.0) {
        let _ = wanted;
        let mut axes = [Axis { play_mm: None }, Axis { play_mm: None }];
        for k in -n_over..(n_turn + n_over) {
            // ccw: −overshoot … 360 + overshoot; cw: 360 + overshoot … −overshoot. Readings
            // fall half a step off the axis reversals (0°, 90°, …), as a sampled run does: a
            // reading exactly at a reversal would land inside the servo lag's delay of it.
            let offset = (k as f64 + 0.5) * step;
            let angle_deg = if sigma > 0.0 { offset } else { 360.0 - offset };
            let theta = angle_deg.to_radians();
            let in_turn = (0..n_turn).contains(&k);
            let x = config.axis_position(0, theta, sigma, &mut axes[0]);
            let y = config.axis_position(1, theta, sigma, &mut axes[1]);
            let q = [
                x + config.centre_offset_um[0] * 1e-3,
                y + config.centre_offset_um[1] * 1e-3,
            ];
            let reading = match config.form {
                Form::Radial => [(q[0].hypot(q[1]) - config.radius_mm) * 1e3 + noise(), 0.0],
                Form::TwoAxis => [
                    config.centre_mm[0] + q[0] + noise() * 1e-3,
                    config.centre_mm[1] + q[1] + noise() * 1e-3,
                ],
            };
            rows.push(SynthRow {
                label: if in_turn { label } else { "overshoot" },
                angle_deg,
                reading,
            });
        }
    }
    rows
}

/// Write `run.csv` and `truth.json` into `dir`.
pub fn write_set(
    dir: &Path,
    config: &CircularSynthConfig,
) -> Result<Vec<PathBuf>, crate::SynthError> {
    let rows = generate(config);
    let run = dir.join("run.csv");
    let truth = dir.join("truth.json");
    write_atomic(&run, |w| {
        match config.form {
            Form::Radial => writeln!(w, "direction,angle_deg,deviation_um")?,
            Form::TwoAxis => writeln!(w, "direction,x_mm,y_mm")?,
        }
        for r in &rows {
            match config.form {
                Form::Radial => writeln!(w, "{},{:.6},{:.5}", r.label, r.angle_deg, r.reading[0])?,
                Form::TwoAxis => {
                    writeln!(w, "{},{:.8},{:.8}", r.label, r.reading[0], r.reading[1])?
                }
            }
        }
        Ok(())
    })?;
    write_json(&truth, &config.truth())?;
    Ok(vec![run, truth])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_perfect_machine_reads_the_set_up_offset_as_a_limacon() {
        let c = CircularSynthConfig {
            noise_um: 0.0,
            squareness_um_per_m: 0.0,
            scale_um_per_m: [0.0; 2],
            backlash_um: [0.0; 2],
            spike_um: [0.0; 2],
            lag_ms: [0.0; 2],
            cyclic_um: [0.0; 2],
            step_deg: 10.0,
            ..Default::default()
        };
        let rows = generate(&c);
        for r in rows.iter().filter(|r| r.label != "overshoot") {
            let t = r.angle_deg.to_radians();
            // Exact distance from the set-up centre, and its limaçon within |e|²/(2R).
            let (x, y) = (100.0 * t.cos() + 0.012, 100.0 * t.sin() - 0.008);
            let exact_um = (x.hypot(y) - 100.0) * 1e3;
            assert!((r.reading[0] - exact_um).abs() < 1e-6, "{r:?}");
            let limacon = 12.0 * t.cos() - 8.0 * t.sin();
            let bound_um = (0.012_f64.powi(2) + 0.008_f64.powi(2)) / 200.0 * 1e3;
            assert!((r.reading[0] - limacon).abs() <= bound_um + 1e-6, "{r:?}");
        }
        assert_eq!(rows.iter().filter(|r| r.label == "ccw").count(), 36);
        assert_eq!(rows.iter().filter(|r| r.label == "overshoot").count(), 4);
    }
}
