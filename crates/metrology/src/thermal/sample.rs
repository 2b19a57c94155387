//! Synthetic thermal campaigns: warm-up with known temperature lags and a fanning error line.
//!
//! Truth (all written to `truth.json`): per direction a cubic cold pitch curve (Legendre series
//! in s over the travel) with a reversal between the directions; nut and bearing rises above
//! the room that follow first-order lags while the machine runs and decay after it stops;
//! a slowly drifting room; error lines that fan about Px = 0 with
//! `tanβ = k_nut·ΔT_nut + k_bearing·ΔT_bearing + ρ·ΔT_env` (gains per coolant state);
//! sensor offsets and scales (undone by `errmap thermal calibrate` on `calibration.csv`),
//! sensor noise and spikes, and laser noise. The model's convention is errmap's:
//! `E = Er(x) + tanβ·(x − Px)/1000` (µm, x in mm, tanβ in µm/m).

use crate::thermal::lsq::legendre_sum;
use crate::thermal::pt100;
use crate::Setting;
use errmap_core::error::Result;
use errmap_core::io::{write_atomic, write_json};
use errmap_core::setting::words;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// What to generate.
#[derive(Debug, Clone, PartialEq)]
pub struct SynthThermalOptions {
    /// Seed of the random streams (sensor and laser noise, warm-start times).
    pub seed: u64,
    /// Number of campaigns; coolant alternates off, on, off, on …
    pub campaigns: usize,
    /// Bidirectional runs per measurement.
    pub repeats: u32,
    /// Measured travel, mm: targets run from 0 to this.
    pub travel_mm: f64,
    /// Spacing of the targets, mm.
    pub step_mm: f64,
    /// Time between measurement starts (s).
    pub every_s: f64,
    /// Length of a campaign (s); the machine runs for the first 60 % of it, then cools.
    pub duration_s: f64,
    /// Duration of one measurement (s): temperatures are averaged over it.
    pub measurement_s: f64,
    /// Temperature log period (s).
    pub log_period_s: f64,
    /// Laser reading noise, one sigma (µm).
    pub laser_noise_um: f64,
    /// Temperature sensor noise, one sigma (°C).
    pub sensor_noise_c: f64,
    /// Warm start: the machine program starts during the cold measurement, at a time drawn
    /// per campaign (from the seed) between 20 % and 40 % of `measurement_s`, so the cold
    /// measurement already sees a small rise (about 0.26 K on the nut on average).
    pub warm_start: bool,
}

impl Default for SynthThermalOptions {
    fn default() -> Self {
        SynthThermalOptions {
            seed: 1,
            campaigns: 4,
            repeats: 2,
            travel_mm: 500.0,
            step_mm: 25.0,
            every_s: 900.0,
            duration_s: 14_400.0,
            measurement_s: 300.0,
            log_period_s: 10.0,
            laser_noise_um: 0.5,
            sensor_noise_c: 0.02,
            warm_start: false,
        }
    }
}

/// Gains of one coolant state (µm/m/K).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrueGains {
    /// Coolant state label (`off`, `on`).
    pub coolant: String,
    /// Gain of the nut's rise above the room, µm/(m·K).
    pub k_nut_um_per_m_k: f64,
    /// Gain of the bearing's rise above the room, µm/(m·K).
    pub k_bearing_um_per_m_k: f64,
}

/// Truth of one direction.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrueDirection {
    /// `forward` or `reverse`.
    pub direction: String,
    /// Er(x) = Σ c_n·P_n(s), s = 2x/travel − 1 (µm).
    pub pitch_legendre_um: Vec<f64>,
    /// Gains of each coolant state, `off` first.
    pub gains: Vec<TrueGains>,
}

/// A sensor's reading is `(T − offset_c)/scale`, so calibration `T = scale·reading + offset_c`
/// recovers T.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrueSensor {
    /// Sensor name: its column in the logs.
    pub name: String,
    /// Offset of the calibration that recovers T, °C.
    pub offset_c: f64,
    /// Scale of the calibration that recovers T (dimensionless).
    pub scale: f64,
}

/// Settings of one campaign.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrueCampaign {
    /// Campaign name, also its folder's name.
    pub name: String,
    /// Coolant state label of the campaign (`off`, `on`).
    pub coolant: String,
    /// Room temperature at the campaign's start, °C.
    pub ambient_start_c: f64,
    /// Linear drift of the room over the campaign, °C per hour.
    pub ambient_drift_c_per_h: f64,
    /// Rise of the nut above the room that its first-order lag approaches while the machine
    /// runs, K.
    pub nut_rise_c: f64,
    /// Time constant of the nut's lag, s (heating and cooling alike).
    pub nut_tau_s: f64,
    /// Rise of the bearing above the room that its lag approaches while the machine runs, K.
    pub bearing_rise_c: f64,
    /// Time constant of the bearing's lag, s.
    pub bearing_tau_s: f64,
    /// Time the machine program starts, s from the campaign's start (inside the cold measurement
    /// with a warm start).
    pub machine_on_s: f64,
    /// Time the machine stops, s from the campaign's start; the rises decay after it.
    pub machine_off_s: f64,
}

/// Everything `truth.json` holds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ThermalTruth {
    /// Seed the campaigns were generated with.
    pub seed: u64,
    /// Measured travel, mm (targets 0 … travel).
    pub travel_mm: f64,
    /// Px, the point the error lines fan about, mm (0).
    pub reference_point_mm: f64,
    /// Ambient temperature at which the pitch curves hold (ΔT_env = T_amb − this).
    pub pitch_ambient_c: f64,
    /// Expansion ρ with the room temperature, µm/(m·K).
    pub rho_um_per_m_k: f64,
    /// Laser reading noise, one sigma, µm.
    pub laser_noise_um: f64,
    /// Temperature sensor noise, one sigma, °C.
    pub sensor_noise_c: f64,
    /// Pitch curve and gains of each direction, forward first.
    pub directions: Vec<TrueDirection>,
    /// Offsets and scales of the sensors: nut, bearing, room, reference.
    pub sensors: Vec<TrueSensor>,
    /// Settings of each campaign, in generation order.
    pub campaigns: Vec<TrueCampaign>,
}

impl TrueCampaign {
    fn lag(rise: f64, tau: f64, on: f64, off: f64, t: f64) -> f64 {
        if t <= on {
            0.0
        } else if t <= off {
            rise * (1.0 - (-(t - on) / tau).exp())
        } else {
            rise * (1.0 - (-(off - on) / tau).exp()) * (-(t - off) / tau).exp()
        }
    }
    /// True (ambient, nut, bearing) temperatures at time t (°C).
    pub fn temperatures_c(&self, t: f64) -> (f64, f64, f64) {
        let amb = self.ambient_start_c + self.ambient_drift_c_per_h * t / 3600.0;
        let nut = Self::lag(
            self.nut_rise_c,
            self.nut_tau_s,
            self.machine_on_s,
            self.machine_off_s,
            t,
        );
        let bearing = Self::lag(
            self.bearing_rise_c,
            self.bearing_tau_s,
            self.machine_on_s,
            self.machine_off_s,
            t,
        );
        (amb, amb + nut, amb + bearing)
    }
}

impl ThermalTruth {
    /// True error (µm) of a direction at x for mean rises and ambient.
    pub fn error_um(
        &self,
        direction: usize,
        coolant: &str,
        x_mm: f64,
        nut_rise_c: f64,
        bearing_rise_c: f64,
        ambient_c: f64,
    ) -> f64 {
        let d = &self.directions[direction];
        let s = 2.0 * x_mm / self.travel_mm - 1.0;
        let g = d
            .gains
            .iter()
            .find(|g| g.coolant == coolant)
            .unwrap_or(&d.gains[0]);
        let slope = g.k_nut_um_per_m_k * nut_rise_c
            + g.k_bearing_um_per_m_k * bearing_rise_c
            + self.rho_um_per_m_k * (ambient_c - self.pitch_ambient_c);
        legendre_sum(&d.pitch_legendre_um, s) + slope * (x_mm - self.reference_point_mm) / 1000.0
    }

    /// Gains of a direction (0 forward, 1 reverse) and coolant state.
    pub fn gains(&self, direction: usize, coolant: &str) -> Option<&TrueGains> {
        self.directions
            .get(direction)?
            .gains
            .iter()
            .find(|g| g.coolant == coolant)
    }
}

/// The fixed truth of the generator (campaign settings depend on the seed only through noise,
/// and through the machine start times of a warm start).
pub fn truth(options: &SynthThermalOptions) -> ThermalTruth {
    ThermalTruth {
        seed: options.seed,
        travel_mm: options.travel_mm,
        reference_point_mm: 0.0,
        pitch_ambient_c: 20.0,
        rho_um_per_m_k: 11.5,
        laser_noise_um: options.laser_noise_um,
        sensor_noise_c: options.sensor_noise_c,
        directions: true_directions(),
        sensors: true_sensors(),
        campaigns: true_campaigns(options),
    }
}

/// Both directions' pitch curves (with the reversal between them) and gains per coolant state.
fn true_directions() -> Vec<TrueDirection> {
    let gains = |f: f64| {
        vec![
            TrueGains {
                coolant: "off".into(),
                k_nut_um_per_m_k: 9.0 * f,
                k_bearing_um_per_m_k: 4.0 * f,
            },
            TrueGains {
                coolant: "on".into(),
                k_nut_um_per_m_k: 6.0 * f,
                k_bearing_um_per_m_k: 2.5 * f,
            },
        ]
    };
    vec![
        TrueDirection {
            direction: "forward".into(),
            pitch_legendre_um: vec![1.0, 4.0, -2.5, 1.8],
            gains: gains(1.0),
        },
        TrueDirection {
            direction: "reverse".into(),
            pitch_legendre_um: vec![4.0, 4.0, -1.9, 1.8],
            gains: gains(0.95),
        },
    ]
}

/// The sensors' offsets and scales, in the order nut, bearing, room, reference.
fn true_sensors() -> Vec<TrueSensor> {
    let sensor = |name: &str, offset_c: f64, scale: f64| TrueSensor {
        name: name.into(),
        offset_c,
        scale,
    };
    vec![
        sensor("nut", 0.35, 1.004),
        sensor("bearing", -0.2, 0.995),
        sensor("room", 0.15, 1.0),
        sensor("ref", 0.0, 1.0),
    ]
}

/// Each campaign's coolant, room and rises; coolant alternates off, on, …
fn true_campaigns(options: &SynthThermalOptions) -> Vec<TrueCampaign> {
    // A stream of its own, so the warm-start times do not change the noise of the campaigns.
    let mut start_rng = ChaCha8Rng::seed_from_u64(options.seed ^ 0x5741_524d);
    (0..options.campaigns)
        .map(|i| {
            let machine_on_s = if options.warm_start {
                options.measurement_s * start_rng.random_range(0.2..0.4)
            } else {
                options.measurement_s
            };
            let on = i % 2 == 1;
            let spread = 1.0 + 0.08 * i as f64;
            TrueCampaign {
                name: format!(
                    "campaign-{}-{}",
                    i + 1,
                    if on { "coolant-on" } else { "coolant-off" }
                ),
                coolant: if on { "on" } else { "off" }.into(),
                ambient_start_c: 19.5 + ((i * 7) % 5) as f64 * 0.6,
                ambient_drift_c_per_h: if i % 2 == 0 { 0.4 } else { -0.3 },
                nut_rise_c: if on { 4.0 } else { 6.0 } * spread,
                nut_tau_s: 1500.0,
                bearing_rise_c: if on { 2.5 } else { 3.5 } * spread,
                bearing_tau_s: 5000.0,
                machine_on_s,
                machine_off_s: 0.6 * options.duration_s,
            }
        })
        .collect()
}

fn reading(truth: &ThermalTruth, sensor: usize, t_c: f64, noise: f64) -> f64 {
    let s = &truth.sensors[sensor];
    (t_c - s.offset_c) / s.scale + noise
}

/// The random streams of a generation: one generator and the two noise distributions.
struct Noise {
    rng: ChaCha8Rng,
    sensor_c: Normal<f64>,
    laser_um: Normal<f64>,
}

impl SynthThermalOptions {
    /// Refuse settings that cannot make campaigns: no campaigns, repeats or time between
    /// measurements, or a noise level that is not a number ≥ 0.
    pub fn check(&self) -> Result<()> {
        if self.campaigns == 0
            || self.repeats == 0
            || !(self.every_s.is_finite() && self.every_s > 0.0)
        {
            return Err(errmap_core::Error::usage(
                format!(
                    "campaigns, repeats and {} must be positive",
                    words(Setting::EveryS)
                ),
                format!(
                    "e.g. {} 4 {} 2 {} 900",
                    words(Setting::Campaigns),
                    words(Setting::Repeats),
                    words(Setting::EveryS)
                ),
            ));
        }
        if !(self.laser_noise_um.is_finite() && self.laser_noise_um >= 0.0) {
            return Err(errmap_core::Error::usage(
                format!(
                    "{} {} is not a noise level",
                    words(Setting::LaserNoiseUm),
                    self.laser_noise_um
                ),
                format!(
                    "give one sigma in µm, 0 or more, e.g. {} 0.5",
                    words(Setting::LaserNoiseUm)
                ),
            ));
        }
        Ok(())
    }
}

/// Write a set of campaigns with known truth into `dir`: `sensors.csv`, `calibration.csv`,
/// one folder per campaign (`campaign.toml`, `runs.csv`, `temperatures.csv`) and `truth.json`.
pub fn write_campaigns(dir: &Path, options: &SynthThermalOptions) -> Result<ThermalTruth> {
    let truth = truth(options);
    let mut noise = Noise {
        rng: ChaCha8Rng::seed_from_u64(options.seed),
        sensor_c: Normal::new(0.0, options.sensor_noise_c.max(0.0)).map_err(|e| {
            errmap_core::Error::usage(format!("sensor noise: {e}"), "give a noise ≥ 0")
        })?,
        laser_um: Normal::new(0.0, options.laser_noise_um.max(0.0)).map_err(|e| {
            errmap_core::Error::usage(format!("laser noise: {e}"), "give a noise ≥ 0")
        })?,
    };
    write_sensor_table(&dir.join("sensors.csv"))?;
    write_calibration_log(&dir.join("calibration.csv"), &truth, &mut noise)?;
    for c in &truth.campaigns {
        let cdir = dir.join(&c.name);
        write_temperature_log(
            &cdir.join("temperatures.csv"),
            &truth,
            c,
            options,
            &mut noise,
        )?;
        write_runs(&cdir.join("runs.csv"), &truth, c, options, &mut noise)?;
        let toml = format!(
            "name = \"{}\"\naxis = \"X\"\ncoolant = \"{}\"\nruns = \"runs.csv\"\n\
             temperatures = \"temperatures.csv\"\nsensors = \"../sensors.csv\"\n\
             measurement_s = {}\nreference_point_mm = {}\n",
            c.name, c.coolant, options.measurement_s, truth.reference_point_mm
        );
        errmap_core::io::write_atomic_bytes(&cdir.join("campaign.toml"), toml.as_bytes())?;
    }
    write_json(&dir.join("truth.json"), &truth)?;
    Ok(truth)
}

/// The sensor table: a Pt100 nut sensor (Ω), bearing and room in °C, and the reference.
fn write_sensor_table(path: &Path) -> Result<()> {
    write_atomic(path, |w| {
        writeln!(
            w,
            "name,role,unit,offset_c,scale,median_window,sg_window,sg_order"
        )?;
        writeln!(w, "nut,nut,ohm,,,5,11,2")?;
        writeln!(w, "bearing,bearing,c,,,5,11,2")?;
        writeln!(w, "room,ambient,c,,,5,11,2")?;
        writeln!(w, "ref,reference,c,,,1,1,0")
    })
}

/// Calibration: every sensor in one block with the reference, ramped 15 → 35 °C in an hour.
fn write_calibration_log(path: &Path, truth: &ThermalTruth, noise: &mut Noise) -> Result<()> {
    let mut cal = String::from("time_s,ref,nut,bearing,room\n");
    for i in 0..=360 {
        let t_s = i as f64 * 10.0;
        let t_c = 15.0 + 20.0 * t_s / 3600.0;
        let nut_c = reading(truth, 0, t_c, noise.sensor_c.sample(&mut noise.rng));
        cal.push_str(&format!(
            "{},{:.4},{:.4},{:.4},{:.4}\n",
            t_s,
            reading(truth, 3, t_c, noise.sensor_c.sample(&mut noise.rng)),
            pt100::resistance_ohm(nut_c),
            reading(truth, 1, t_c, noise.sensor_c.sample(&mut noise.rng)),
            reading(truth, 2, t_c, noise.sensor_c.sample(&mut noise.rng)),
        ));
    }
    errmap_core::io::write_atomic_bytes(path, cal.as_bytes())
}

/// Samples in a campaign's temperature log (the last one at `duration_s`).
fn log_samples(options: &SynthThermalOptions) -> usize {
    (options.duration_s / options.log_period_s).round() as usize
}

/// A campaign's temperature log, with sensor noise and two spikes on the nut.
fn write_temperature_log(
    path: &Path,
    truth: &ThermalTruth,
    c: &TrueCampaign,
    options: &SynthThermalOptions,
    noise: &mut Noise,
) -> Result<()> {
    let n_log = log_samples(options);
    let spikes: Vec<usize> = (0..2)
        .map(|_| noise.rng.random_range(1..n_log.max(2)))
        .collect();
    let mut log = String::from("time_s,nut,bearing,room\n");
    for i in 0..=n_log {
        let t_s = i as f64 * options.log_period_s;
        let (amb, nut, bearing) = c.temperatures_c(t_s);
        let spike = if spikes.contains(&i) { 3.0 } else { 0.0 };
        let nut_c = reading(truth, 0, nut, noise.sensor_c.sample(&mut noise.rng)) + spike;
        log.push_str(&format!(
            "{},{:.4},{:.4},{:.4}\n",
            t_s,
            pt100::resistance_ohm(nut_c),
            reading(truth, 1, bearing, noise.sensor_c.sample(&mut noise.rng)),
            reading(truth, 2, amb, noise.sensor_c.sample(&mut noise.rng)),
        ));
    }
    errmap_core::io::write_atomic_bytes(path, log.as_bytes())
}

/// The true (ambient, nut rise, bearing rise) averaged over the log samples inside the
/// measurement starting at `t0_s`, as the fit averages the logged ones.
fn measurement_means(
    c: &TrueCampaign,
    options: &SynthThermalOptions,
    t0_s: f64,
) -> (f64, f64, f64) {
    let (mut amb, mut nut, mut bearing, mut n) = (0.0, 0.0, 0.0, 0.0);
    for i in 0..=log_samples(options) {
        let t_s = i as f64 * options.log_period_s;
        if t_s >= t0_s && t_s <= t0_s + options.measurement_s {
            let (a, nn, b) = c.temperatures_c(t_s);
            amb += a;
            nut += nn - a;
            bearing += b - a;
            n += 1.0;
        }
    }
    (amb / n, nut / n, bearing / n)
}

/// A campaign's laser runs: at every measurement, `repeats` runs each way over the targets,
/// the true error of the mean temperatures plus laser noise.
fn write_runs(
    path: &Path,
    truth: &ThermalTruth,
    c: &TrueCampaign,
    options: &SynthThermalOptions,
    noise: &mut Noise,
) -> Result<()> {
    let n_targets = (options.travel_mm / options.step_mm).round() as usize;
    let targets: Vec<f64> = (0..=n_targets)
        .map(|i| i as f64 * options.step_mm)
        .collect();
    let mut runs = String::from("run,direction,target_mm,deviation_um,time_s\n");
    let n_meas =
        ((options.duration_s - options.measurement_s) / options.every_s).floor() as usize + 1;
    for k in 0..n_meas {
        let t0 = k as f64 * options.every_s;
        let (amb, nut, bearing) = measurement_means(c, options, t0);
        for r in 0..options.repeats {
            let run = k as u32 * options.repeats + r + 1;
            for (di, sign) in [(0usize, "+"), (1usize, "-")] {
                let order: Vec<f64> = if di == 0 {
                    targets.clone()
                } else {
                    targets.iter().rev().cloned().collect()
                };
                for x in order {
                    let e = truth.error_um(di, &c.coolant, x, nut, bearing, amb)
                        + noise.laser_um.sample(&mut noise.rng);
                    runs.push_str(&format!("{run},{sign},{x},{e:.4},{t0}\n"));
                }
            }
        }
    }
    errmap_core::io::write_atomic_bytes(path, runs.as_bytes())
}
