//! A dense scan of one web-plate floor with known truth: n points on jittered scan lines (as a laser line scanner or a scanning probe gives them), a smooth error field, Gaussian noise and a few chips, written as errmap's CSV with a job file.
//!
//! The truth is [`truth_um`], the same for every scan, so a test or a bench can judge a map
//! against it at any size. Lines run along x; the points of a line are spaced evenly with a
//! seeded jitter of ±30 % of the spacing, and each line wanders ±30 % of the line spacing in y.
//! Memory and time are linear in n; the file is about 30 bytes per point.

use errmap_core::error::Result;
use errmap_core::io;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// What a scan is made of.
#[derive(Debug, Clone, PartialEq)]
pub struct ScanSpec {
    /// Points (at least 16).
    pub points: usize,
    /// Seed of the jitter, the noise and the chips.
    pub seed: u64,
    /// Probe noise, 1σ, µm.
    pub noise_um: f64,
    /// Chips (+40 µm gross errors) per million points (at least one).
    pub chips_per_million: usize,
    /// Training epochs written into the job.
    pub epochs: u32,
}

impl Default for ScanSpec {
    fn default() -> Self {
        ScanSpec {
            points: 10_000,
            seed: 1,
            noise_um: 1.0,
            chips_per_million: 50,
            epochs: 400,
        }
    }
}

/// The scanned rectangle `[x0, y0, x1, y1]`, mm: the sample web floor.
pub const SCAN_RECT_MM: [f64; 4] = [10.0, 10.0, 590.0, 290.0];

/// Nominal z of the floor, mm.
pub const FLOOR_Z_MM: f64 = 5.0;

/// Size of a chip, µm.
pub const CHIP_UM: f64 = 40.0;

/// The error field of every scan at (x, y), µm: a smooth wave over the floor and a tilt.
pub fn truth_um(x_mm: f64, y_mm: f64) -> f64 {
    let (u, v) = ((x_mm - 10.0) / 580.0, (y_mm - 10.0) / 280.0);
    18.0 * (2.6 * std::f64::consts::PI * u + 0.4).sin() * (1.3 * std::f64::consts::PI * v).cos()
        + 6.0 * u
        - 4.0 * v * v
}

/// The files of a written scan.
#[derive(Debug, Clone)]
pub struct ScanFiles {
    /// The job file.
    pub job: PathBuf,
    /// The probe file.
    pub probes: PathBuf,
    /// Indices (0-based, in file order) of the points carrying a chip.
    pub chips: Vec<usize>,
}

/// Write `probes/scan.csv` and `job.toml` into `out`.
pub fn write_scan(spec: &ScanSpec, out: &Path) -> Result<ScanFiles, crate::SynthError> {
    if spec.points < 16 {
        return Err(errmap_core::Error::usage(
            format!("a scan of {} points is too small", spec.points),
            "ask for at least 16 points",
        )
        .into());
    }
    let [x0, y0, x1, y1] = SCAN_RECT_MM;
    let (w, h) = (x1 - x0, y1 - y0);
    // Lines along x, about as many points per mm along a line as lines per mm across.
    let lines = ((spec.points as f64 * h / w).sqrt().round() as usize).max(2);
    let mut rng = ChaCha8Rng::seed_from_u64(spec.seed);
    let noise = Normal::new(0.0, spec.noise_um.max(0.0)).expect("a finite σ");
    let chips_wanted = (spec.points * spec.chips_per_million / 1_000_000).max(1);
    let chip_every = spec.points / chips_wanted;
    let mut text = String::with_capacity(spec.points * 32 + 16);
    text.push_str("x_mm,y_mm,z_mm\n");
    let mut chips = Vec::new();
    let dy = h / (lines - 1) as f64;
    let mut k = 0usize;
    for line in 0..lines {
        // Points of this line: the total shared out evenly.
        let count = (spec.points * (line + 1)) / lines - (spec.points * line) / lines;
        let dx = w / count.max(1) as f64;
        let y_line = y0 + line as f64 * dy;
        for i in 0..count {
            let x = (x0 + (i as f64 + 0.5) * dx + rng.random_range(-0.3..0.3) * dx).clamp(x0, x1);
            let y = (y_line + rng.random_range(-0.3..0.3) * dy).clamp(y0, y1);
            let mut e = truth_um(x, y) + noise.sample(&mut rng);
            // Chips away from the first and last line (the hull).
            if k % chip_every == chip_every / 2 && line > 0 && line + 1 < lines {
                e += CHIP_UM;
                chips.push(k);
            }
            let z = FLOOR_Z_MM + e / 1000.0;
            let _ = writeln!(text, "{x:.4},{y:.4},{z:.7}");
            k += 1;
        }
    }
    let probes = out.join("probes").join("scan.csv");
    io::write_atomic_bytes(&probes, text.as_bytes())?;
    let job = out.join("job.toml");
    let toml = format!(
        "# A dense scan of the web floor: {} points (errmap_synth::scan).\n\
         family = \"scan\"\nnormal = \"z\"\nnominal_plane_mm = {FLOOR_Z_MM}\nprobes = \"probes/*.csv\"\n\
         domain = [{x0}, {y0}, {x1}, {y1}]\ngrid_step_mm = 5.0\n\n[clean]\nk_sigma = 3.0\n\n\
         [interp]\nmethod = \"natural-neighbour\"\nspacing_mm = 10.0\n\n\
         [model]\nhidden = [32, 32]\nepochs = {}\nseed = 1\nholdout_fraction = 0.1\nbackend = \"cpu\"\n",
        spec.points, spec.epochs
    );
    io::write_atomic_bytes(&job, toml.as_bytes())?;
    Ok(ScanFiles { job, probes, chips })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_scan_has_the_points_asked_for_inside_the_floor() {
        let dir = tempfile::tempdir().unwrap();
        let files = write_scan(
            &ScanSpec {
                points: 5000,
                noise_um: 0.0,
                ..ScanSpec::default()
            },
            dir.path(),
        )
        .unwrap();
        let text = std::fs::read_to_string(&files.probes).unwrap();
        let rows: Vec<[f64; 3]> = text
            .lines()
            .skip(1)
            .map(|l| {
                let v: Vec<f64> = l.split(',').map(|x| x.parse().unwrap()).collect();
                [v[0], v[1], v[2]]
            })
            .collect();
        assert_eq!(rows.len(), 5000);
        assert!(!files.chips.is_empty());
        for (k, r) in rows.iter().enumerate() {
            assert!((10.0..=590.0).contains(&r[0]) && (10.0..=290.0).contains(&r[1]));
            // Without noise: E = truth (to the file's 0.1 nm), plus 40 µm at a chip.
            let chip = if files.chips.contains(&k) {
                CHIP_UM
            } else {
                0.0
            };
            let e = (r[2] - FLOOR_Z_MM) * 1000.0;
            assert!(
                (e - truth_um(r[0], r[1]) - chip).abs() < 2e-3,
                "row {k}: {e}"
            );
        }
    }
}
