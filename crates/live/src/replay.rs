//! A machine log to replay through `errmap live` (`errmap synth live-replay`): the temperatures
//! of one of `errmap synth thermal`'s campaigns (the same truth: lags, room drift, sensor
//! offsets, scales and noise, the nut as a Pt100 in Ω), sampled every `period_s`, with the axis
//! moving back and forth over the travel at a feed, in the format `errmap thermal compensate`
//! reads: `time_s,position_mm,direction,nut,bearing,ambient_c,coolant`.

use crate::Setting;
use errmap_core::error::{Error, Result};
use errmap_core::setting::words;
use errmap_metrology::thermal::pt100;
use errmap_metrology::thermal::sample::{truth, SynthThermalOptions};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use std::path::Path;

/// What to generate.
#[derive(Debug, Clone, PartialEq)]
pub struct ReplayOptions {
    /// Seed of `errmap synth thermal`'s truth and of the replay's sensor noise (same seed, same log).
    pub seed: u64,
    /// 1-based campaign of `errmap synth thermal` (1, 3: coolant off; 2, 4: on).
    pub campaign: usize,
    /// Length of the log (s of machine time); rows at 0, `period_s`, … up to it.
    pub duration_s: f64,
    /// Time between rows (s).
    pub period_s: f64,
    /// The axis's feed while it moves back and forth over the travel (mm/min).
    pub feed_mm_per_min: f64,
    /// Switch the coolant label every this many seconds (None: the campaign's state throughout).
    pub coolant_every_s: Option<f64>,
}

impl Default for ReplayOptions {
    fn default() -> Self {
        ReplayOptions {
            seed: 1,
            campaign: 2,
            duration_s: 14_400.0,
            period_s: 1.0,
            feed_mm_per_min: 1500.0,
            coolant_every_s: None,
        }
    }
}

/// The axis position (mm) and direction at time t: a triangle wave over [0, travel].
pub fn motion(t_s: f64, travel_mm: f64, feed_mm_per_min: f64) -> (f64, &'static str) {
    let v = feed_mm_per_min / 60.0;
    let s = (t_s * v).rem_euclid(2.0 * travel_mm);
    if s < travel_mm {
        (s, "+")
    } else {
        (2.0 * travel_mm - s, "-")
    }
}

/// Write the log to `out` (atomically); the number of rows.
pub fn write_replay(out: &Path, o: &ReplayOptions) -> Result<u64> {
    if !(o.period_s > 0.0 && o.duration_s >= o.period_s && o.feed_mm_per_min > 0.0) {
        return Err(Error::usage(
            "the period, duration and feed must be positive (duration ≥ period)",
            format!(
                "e.g. {} 4 {} 1 {} 1500",
                words(Setting::Hours),
                words(Setting::PeriodS),
                words(Setting::FeedMmMin)
            ),
        ));
    }
    let synth = SynthThermalOptions {
        seed: o.seed,
        duration_s: o.duration_s,
        ..SynthThermalOptions::default()
    };
    let t = truth(&synth);
    let campaign = t.campaigns.get(o.campaign.wrapping_sub(1)).ok_or_else(|| {
        Error::usage(
            format!(
                "no campaign {} (there are {})",
                o.campaign,
                t.campaigns.len()
            ),
            format!("give {} 1 … 4", words(Setting::Campaign)),
        )
    })?;
    let noise = Normal::new(0.0, synth.sensor_noise_c)
        .map_err(|e| Error::Internal(format!("noise: {e}")))?;
    let mut rng = ChaCha8Rng::seed_from_u64(o.seed ^ 0x6c69_7665);
    let reading = |k: usize, t_c: f64, n: f64| {
        let s = &t.sensors[k];
        (t_c - s.offset_c) / s.scale + n
    };
    let rows = (o.duration_s / o.period_s).floor() as u64 + 1;
    errmap_core::io::write_atomic(out, |w| {
        writeln!(
            w,
            "time_s,position_mm,direction,nut,bearing,ambient_c,coolant"
        )?;
        for i in 0..rows {
            let time_s = i as f64 * o.period_s;
            let (amb, nut, bearing) = campaign.temperatures_c(time_s);
            let (x, dir) = motion(time_s, t.travel_mm, o.feed_mm_per_min);
            let coolant = match o.coolant_every_s {
                Some(every) if every > 0.0 => {
                    if ((time_s / every).floor() as u64).is_multiple_of(2) {
                        "off"
                    } else {
                        "on"
                    }
                }
                _ => campaign.coolant.as_str(),
            };
            let nut_c = reading(0, nut, noise.sample(&mut rng));
            writeln!(
                w,
                "{time_s:.3},{x:.3},{dir},{:.4},{:.4},{:.4},{coolant}",
                pt100::resistance_ohm(nut_c),
                reading(1, bearing, noise.sample(&mut rng)),
                reading(2, amb, noise.sample(&mut rng)),
            )?;
        }
        Ok(())
    })?;
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn triangle_motion() {
        // 1500 mm/min = 25 mm/s over 500 mm: 20 s up, 20 s down.
        assert_eq!(motion(0.0, 500.0, 1500.0), (0.0, "+"));
        assert_eq!(motion(10.0, 500.0, 1500.0), (250.0, "+"));
        assert_eq!(motion(30.0, 500.0, 1500.0), (250.0, "-"));
        assert_eq!(motion(40.0, 500.0, 1500.0), (0.0, "+"));
    }
}
