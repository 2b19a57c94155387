//! Synthetic thin-walled web-plate family: probe files with a known error field, outliers and a finishing-pass program.
//!
//! The part (seed 001) is a plate `size_x × size_y` mm with a wall `WALL_MM` wide all round and a
//! thin web (the pocket floor) at `z = floor_z_mm`. Under the cutting force the web deflects away
//! from the cutter and springs back afterwards, so the finished floor stands proud (E > 0) most in
//! the middle of the web and hardly at all next to the supported walls. The truth field of part k is
//!
//! ```text
//! s = (x − x0 − w) / (Lx − 2w),  r = (y − y0 − w) / (Ly − 2w)          (0…1 across the web)
//! E(x, y) = A·sin(πs)·sin(πr)·(1 + a·(s − ½))            first plate mode, skewed along the feed
//!         + B·sin(2πs)·sin(πr)                            second mode (tool entry side)
//!         + c0 + c1·(s − ½) + c2·(r − ½)                  set-up offset and tilt of this clamping
//! ```
//!
//! in µm, with A, a, B, c0, c1, c2 drawn per part around family values ([`PartTruth`]). The probe
//! reads `z = floor_z + E/1000 + noise` (noise N(0, σ)); a few chips under the probe add +40 µm at
//! known points ([`PlantedOutlier`]); two points per part are measured twice (same `id`).

use crate::Setting;
use errmap_core::error::{Error, Result};
use errmap_core::io;
use errmap_core::setting::words;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;
use std::fmt::Write as _;
use std::path::Path;

/// Width of the supporting wall all round the web, mm.
pub const WALL_MM: f64 = 10.0;

/// How the probe points are laid out over the web.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Layout {
    /// A regular `nx × ny` grid (seed 001: 12 × 12).
    Grid {
        /// Probe columns along x, edges included (at least 3).
        nx: usize,
        /// Probe rows along y, edges included (at least 3).
        ny: usize,
    },
    /// `n` scattered points (seeded), plus the four corners of the probed rectangle.
    Irregular {
        /// Scattered points besides the four corners (at least 8).
        n: usize,
    },
}

/// Everything that defines a generated family.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WebPlateSpec {
    /// Family name: the job's `family` and the title line of the instrument files.
    pub family: String,
    /// Number of parts (1 to 9999), named `p01`, `p02`, … (`p100`, `p1000` past 99 and 999).
    pub parts: usize,
    /// Seed of the family: each part's truth, outliers, repeats and noise, and an irregular
    /// layout, follow from it.
    pub seed: u64,
    /// Outer size of the plate along X, walls included, mm.
    pub size_x_mm: f64,
    /// Outer size of the plate along Y, walls included, mm.
    pub size_y_mm: f64,
    /// X of the plate's lower-left corner, machine coordinates, mm.
    pub origin_x_mm: f64,
    /// Y of the plate's lower-left corner, machine coordinates, mm.
    pub origin_y_mm: f64,
    /// Nominal Z of the web floor (the probed surface), mm: the job's nominal plane.
    pub floor_z_mm: f64,
    /// How the probe points are laid out over the web.
    pub layout: Layout,
    /// Probe noise, 1σ, µm.
    pub noise_um: f64,
    /// Gross outliers planted per part.
    pub outliers_per_part: usize,
    /// Size of each planted outlier (a chip under the probe), µm.
    pub outlier_um: f64,
    /// Write per-point nominal columns `nx_mm,ny_mm,nz_mm` instead of relying on the job's plane.
    pub nominal_columns: bool,
    /// Training epochs written into the job's `[model]` table.
    pub epochs: u32,
    /// `Some(n)`: the job starts each part from the family network and trains it n steps
    /// (`warm_start = "family"`).
    pub warm_epochs: Option<u32>,
    /// How each part's probe file is written (errmap's CSV unless asked otherwise).
    #[serde(default, skip_serializing_if = "ProbeFileFormat::is_csv")]
    pub probe_format: ProbeFileFormat,
}

/// How the generator writes a part's probe file: errmap's CSV, or as an instrument would.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ProbeFileFormat {
    /// `id,x_mm,y_mm,z_mm` (errmap's columns).
    #[default]
    Csv,
    /// A CMM's CSV export: a date line, then `POINT,X,Y,Z,I,J,K` (read with `columns`).
    CmmCsv,
    /// DMIS output: `F(P001)=FEAT/POINT,CART,…` nominals, then `FA(P001)=…` actuals.
    Dmis,
    /// ASCII point cloud `x y z`.
    Xyz,
    /// Binary little-endian PLY point cloud, double x, y, z.
    Ply,
}

impl ProbeFileFormat {
    fn is_csv(&self) -> bool {
        *self == ProbeFileFormat::Csv
    }

    /// The probe file's extension.
    pub fn extension(self) -> &'static str {
        match self {
            ProbeFileFormat::Csv | ProbeFileFormat::CmmCsv => "csv",
            ProbeFileFormat::Dmis => "dmi",
            ProbeFileFormat::Xyz => "xyz",
            ProbeFileFormat::Ply => "ply",
        }
    }
}

/// The column mapping of the CMM export [`ProbeFileFormat::CmmCsv`].
pub const CMM_CSV_COLUMNS: &str = "x=X,y=Y,z=Z,i=I,j=J,k=K,id=POINT";

impl Default for WebPlateSpec {
    fn default() -> Self {
        WebPlateSpec {
            family: "web-plate".into(),
            parts: 8,
            seed: 1,
            size_x_mm: 600.0,
            size_y_mm: 300.0,
            origin_x_mm: 0.0,
            origin_y_mm: 0.0,
            floor_z_mm: 5.0,
            layout: Layout::Grid { nx: 12, ny: 12 },
            noise_um: 1.0,
            outliers_per_part: 3,
            outlier_um: 40.0,
            nominal_columns: false,
            epochs: 400,
            warm_epochs: None,
            probe_format: ProbeFileFormat::Csv,
        }
    }
}

/// Analytic truth of one part (µm; see the module docs for the formula).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PartTruth {
    /// Part name (`p01`, …).
    pub part: String,
    /// Amplitude A of the first plate mode (the mid-web bulge), µm.
    pub a_um: f64,
    /// Skew a of the first mode along the feed (x): its amplitude scales by 1 + a·(s − ½).
    pub skew: f64,
    /// Amplitude B of the second mode along x, µm.
    pub b_um: f64,
    /// Set-up offset c0, µm.
    pub c0_um: f64,
    /// Set-up tilt c1 along x, µm across the web's width.
    pub c1_um: f64,
    /// Set-up tilt c2 along y, µm across the web's depth.
    pub c2_um: f64,
}

/// A gross error planted in a probe file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlantedOutlier {
    /// Part name (`p01`, …).
    pub part: String,
    /// The probe point's `id` (`P001`, …).
    pub id: String,
    /// X of the point, mm (to 0.001 mm).
    pub x_mm: f64,
    /// Y of the point, mm (to 0.001 mm).
    pub y_mm: f64,
    /// What the chip adds to the point's E, µm.
    pub added_um: f64,
}

/// The ground truth of a generated family (`truth.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Truth {
    /// The settings the family was generated with.
    pub spec: WebPlateSpec,
    /// Width of the wall all round the web, mm ([`WALL_MM`]).
    pub wall_mm: f64,
    /// The rectangle the probes span (x_min, y_min, x_max, y_max), mm.
    pub probed_mm: [f64; 4],
    /// The truth of every part, in part order.
    pub parts: Vec<PartTruth>,
    /// Every planted outlier, by part, then in file order.
    pub outliers: Vec<PlantedOutlier>,
}

impl Truth {
    /// Read a `truth.json`.
    pub fn read(path: &Path) -> Result<Truth, crate::SynthError> {
        let text = io::read_text(path)?;
        serde_json::from_str(&text)
            .map_err(|e| {
                Error::input(
                    errmap_core::Location::line(path, e.line() as u64),
                    format!("not a web-plate truth file: {e}"),
                    "regenerate it with `errmap synth web-plate`",
                )
            })
            .map_err(Into::into)
    }

    /// Truth error of part `k` at (x, y), µm.
    pub fn e_um(&self, k: usize, x_mm: f64, y_mm: f64) -> Option<f64> {
        self.parts.get(k).map(|p| p.e_um(&self.spec, x_mm, y_mm))
    }

    /// Mean over the parts of the truth error at (x, y), µm (the family's truth).
    pub fn family_e_um(&self, x_mm: f64, y_mm: f64) -> f64 {
        let n = self.parts.len().max(1) as f64;
        self.parts
            .iter()
            .map(|p| p.e_um(&self.spec, x_mm, y_mm))
            .sum::<f64>()
            / n
    }
}

impl PartTruth {
    /// E(x, y) in µm (module docs).
    pub fn e_um(&self, spec: &WebPlateSpec, x_mm: f64, y_mm: f64) -> f64 {
        let s = (x_mm - spec.origin_x_mm - WALL_MM) / (spec.size_x_mm - 2.0 * WALL_MM);
        let r = (y_mm - spec.origin_y_mm - WALL_MM) / (spec.size_y_mm - 2.0 * WALL_MM);
        self.a_um * (PI * s).sin() * (PI * r).sin() * (1.0 + self.skew * (s - 0.5))
            + self.b_um * (2.0 * PI * s).sin() * (PI * r).sin()
            + self.c0_um
            + self.c1_um * (s - 0.5)
            + self.c2_um * (r - 0.5)
    }
}

/// What [`generate`] wrote.
#[derive(Debug, Clone)]
pub struct Generated {
    /// The family's truth, as written to `truth.json`.
    pub truth: Truth,
    /// One probe file per part, in part order, under `probes/`.
    pub probe_files: Vec<std::path::PathBuf>,
    /// Probe positions per part (the two repeated measurements not counted).
    pub points_per_part: usize,
}

/// Probe inset from the walls' inner faces, mm (a touch probe keeps off the fillet).
fn probe_inset_mm() -> f64 {
    15.0
}

/// The rectangle the probe points span: (x_min, y_min, x_max, y_max).
pub fn probed_rect(spec: &WebPlateSpec) -> [f64; 4] {
    let m = WALL_MM + probe_inset_mm();
    [
        spec.origin_x_mm + m,
        spec.origin_y_mm + m,
        spec.origin_x_mm + spec.size_x_mm - m,
        spec.origin_y_mm + spec.size_y_mm - m,
    ]
}

fn validate(spec: &WebPlateSpec) -> Result<()> {
    let min = 2.0 * (WALL_MM + probe_inset_mm()) + 40.0;
    if !(spec.size_x_mm.is_finite() && spec.size_y_mm.is_finite())
        || spec.size_x_mm < min
        || spec.size_y_mm < min
    {
        return Err(Error::usage(
            format!(
                "plate size {}x{} mm is too small",
                spec.size_x_mm, spec.size_y_mm
            ),
            format!("give {} of at least {min}x{min} mm", words(Setting::Size)),
        ));
    }
    if spec.parts == 0 || spec.parts > 9999 {
        return Err(Error::usage(
            format!("{} must be 1…9999", words(Setting::Parts)),
            format!("e.g. {} 8", words(Setting::Parts)),
        ));
    }
    match spec.layout {
        Layout::Grid { nx, ny } if nx < 3 || ny < 3 || nx * ny > 100_000 => Err(Error::usage(
            format!("probe grid {nx}x{ny} is too small or too large"),
            format!("use at least 3x3, e.g. {} 12x12", words(Setting::Grid)),
        )),
        Layout::Irregular { n } if !(8..=100_000).contains(&n) => Err(Error::usage(
            format!("{} {n}: need at least 8 points", words(Setting::Irregular)),
            format!("e.g. {} 150", words(Setting::Irregular)),
        )),
        _ => Ok(()),
    }?;
    let interior = match spec.layout {
        Layout::Grid { nx, ny } => (nx - 2) * (ny - 2),
        Layout::Irregular { n } => n,
    };
    if spec.outliers_per_part * 9 > interior {
        return Err(Error::usage(
            format!(
                "{} outliers per part is too many for {interior} interior points",
                spec.outliers_per_part
            ),
            "plant fewer outliers or probe more points",
        ));
    }
    Ok(())
}

/// Probe positions (x, y) in mm, and whether each is an interior point (allowed to carry an outlier).
fn layout_points(spec: &WebPlateSpec) -> Vec<(f64, f64, bool)> {
    let [x0, y0, x1, y1] = probed_rect(spec);
    match spec.layout {
        Layout::Grid { nx, ny } => {
            let mut pts = Vec::with_capacity(nx * ny);
            for j in 0..ny {
                for i in 0..nx {
                    let x = x0 + (x1 - x0) * i as f64 / (nx - 1) as f64;
                    let y = y0 + (y1 - y0) * j as f64 / (ny - 1) as f64;
                    let interior = i > 0 && i + 1 < nx && j > 0 && j + 1 < ny;
                    pts.push((x, y, interior));
                }
            }
            pts
        }
        Layout::Irregular { n } => {
            // Dart throwing with a minimum spacing, so no two probes crowd each other;
            // the four corners make the probed rectangle the convex hull.
            let mut rng = ChaCha8Rng::seed_from_u64(spec.seed ^ 0x1a70_u64);
            let area = (x1 - x0) * (y1 - y0);
            let mut min_mm = 0.7 * (area / n as f64).sqrt();
            let mut pts: Vec<(f64, f64, bool)> = vec![
                (x0, y0, false),
                (x1, y0, false),
                (x0, y1, false),
                (x1, y1, false),
            ];
            let mut tries = 0usize;
            while pts.len() < n + 4 {
                let x = rng.random_range(x0..=x1);
                let y = rng.random_range(y0..=y1);
                let ok = pts
                    .iter()
                    .all(|&(px, py, _)| (px - x).hypot(py - y) >= min_mm);
                if ok {
                    let edge = (x - x0).min(x1 - x).min(y - y0).min(y1 - y);
                    pts.push((x, y, edge > min_mm));
                }
                tries += 1;
                if tries > 2000 * n {
                    min_mm *= 0.9;
                    tries = 0;
                }
            }
            pts
        }
    }
}

fn part_seed(seed: u64, k: usize) -> u64 {
    seed ^ ((k as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15))
}

/// Draw the truth parameters of part `k`: family values plus small part-to-part variation.
fn part_truth(k: usize, rng: &mut ChaCha8Rng) -> PartTruth {
    let mut n = || -> f64 { rng.sample(StandardNormal) };
    PartTruth {
        part: part_name(k),
        a_um: 30.0 * (1.0 + 0.05 * n()),
        skew: 0.3 + 0.05 * n(),
        b_um: 4.0 + 0.5 * n(),
        c0_um: 2.0 + 1.0 * n(),
        c1_um: 1.0 * n(),
        c2_um: 1.0 * n(),
    }
}

/// Name of part `k`: `p01`, `p02`, …
pub fn part_name(k: usize) -> String {
    format!("p{:02}", k + 1)
}

/// Write the family into `out`: `probes/pNN.<ext>` (CSV unless [`WebPlateSpec::probe_format`]
/// says otherwise), `truth.json`, `outliers.csv`, `finish.ngc`,
/// `job.toml`, `README.md`. `command` is the command line recorded in the README.
pub fn generate(
    spec: &WebPlateSpec,
    out: &Path,
    command: &str,
) -> Result<Generated, crate::SynthError> {
    validate(spec)?;
    let layout = layout_points(spec);
    let mut parts = Vec::new();
    let mut outliers = Vec::new();
    let mut probe_files = Vec::new();
    let probes_dir = out.join("probes");
    for k in 0..spec.parts {
        // One generator per part, drawn in this order: truth, outliers, repeats, noise.
        let mut rng = ChaCha8Rng::seed_from_u64(part_seed(spec.seed, k));
        let truth = part_truth(k, &mut rng);
        let interior: Vec<usize> = (0..layout.len()).filter(|&i| layout[i].2).collect();
        let chosen = pick_outliers(spec, &layout, &interior, &mut rng);
        let repeats = pick_repeats(&interior, &chosen, &mut rng);
        let text = probe_csv(
            spec,
            &layout,
            &truth,
            (&chosen, &repeats),
            &mut rng,
            &mut outliers,
        );
        let path = probes_dir.join(format!("{}.{}", truth.part, spec.probe_format.extension()));
        let bytes = match spec.probe_format {
            ProbeFileFormat::Csv => text.into_bytes(),
            format => instrument_file(spec, &truth.part, &text, format),
        };
        io::write_atomic_bytes(&path, &bytes)?;
        probe_files.push(path);
        parts.push(truth);
    }
    let truth = Truth {
        spec: spec.clone(),
        wall_mm: WALL_MM,
        probed_mm: probed_rect(spec).map(round3),
        parts,
        outliers,
    };
    write_family_files(spec, out, &truth, command)?;
    Ok(Generated {
        truth,
        probe_files,
        points_per_part: layout.len(),
    })
}

/// The outliers of one part: interior points, well apart so no two mask each other (sorted).
fn pick_outliers(
    spec: &WebPlateSpec,
    layout: &[(f64, f64, bool)],
    interior: &[usize],
    rng: &mut ChaCha8Rng,
) -> Vec<usize> {
    let spacing_mm = typical_spacing_mm(spec, layout.len());
    let mut chosen: Vec<usize> = Vec::new();
    let mut guard = 0;
    while chosen.len() < spec.outliers_per_part && guard < 100_000 && !interior.is_empty() {
        guard += 1;
        let cand = interior[rng.random_range(0..interior.len())];
        let far = chosen.iter().all(|&c| {
            (layout[c].0 - layout[cand].0).hypot(layout[c].1 - layout[cand].1) > 2.5 * spacing_mm
        });
        if far {
            chosen.push(cand);
        }
    }
    chosen.sort_unstable();
    chosen
}

/// Two repeated measurements per part (fewer if the interior has no room), away from the
/// outliers `chosen`.
fn pick_repeats(interior: &[usize], chosen: &[usize], rng: &mut ChaCha8Rng) -> Vec<usize> {
    let mut repeats: Vec<usize> = Vec::new();
    let spare = interior.iter().filter(|i| !chosen.contains(i)).count();
    while repeats.len() < spare.min(2) {
        let cand = interior[rng.random_range(0..interior.len())];
        if !chosen.contains(&cand) && !repeats.contains(&cand) {
            repeats.push(cand);
        }
    }
    repeats
}

/// The probe file of one part: every layout point with its truth plus noise (plus the outlier
/// offset for the `chosen`, recorded in `outliers`), then the `repeats` measured again.
fn probe_csv(
    spec: &WebPlateSpec,
    layout: &[(f64, f64, bool)],
    truth: &PartTruth,
    (chosen, repeats): (&[usize], &[usize]),
    rng: &mut ChaCha8Rng,
    outliers: &mut Vec<PlantedOutlier>,
) -> String {
    let mut text = String::new();
    if spec.nominal_columns {
        text.push_str("id,x_mm,y_mm,z_mm,nx_mm,ny_mm,nz_mm\n");
    } else {
        text.push_str("id,x_mm,y_mm,z_mm\n");
    }
    let row = |id: usize, x: f64, y: f64, e_um: f64, text: &mut String| {
        let z = spec.floor_z_mm + e_um / 1000.0;
        let _ = write!(text, "P{:03},{x:.3},{y:.3},{z:.4}", id + 1);
        if spec.nominal_columns {
            let _ = write!(text, ",{x:.3},{y:.3},{:.4}", spec.floor_z_mm);
        }
        text.push('\n');
    };
    for (i, &(x, y, _)) in layout.iter().enumerate() {
        let mut e = truth.e_um(spec, x, y) + spec.noise_um * rng.sample::<f64, _>(StandardNormal);
        if chosen.contains(&i) {
            e += spec.outlier_um;
            outliers.push(PlantedOutlier {
                part: truth.part.clone(),
                id: format!("P{:03}", i + 1),
                x_mm: round3(x),
                y_mm: round3(y),
                added_um: spec.outlier_um,
            });
        }
        row(i, x, y, e, &mut text);
    }
    for &i in repeats {
        let (x, y, _) = layout[i];
        let e = truth.e_um(spec, x, y) + spec.noise_um * rng.sample::<f64, _>(StandardNormal);
        row(i, x, y, e, &mut text);
    }
    text
}

/// A part's probe file as an instrument writes it, from the rows of its errmap CSV `csv`
/// (`id,x,y,z[,nx,ny,nz]`, numbers as written there, so every format carries the same values).
fn instrument_file(spec: &WebPlateSpec, part: &str, csv: &str, format: ProbeFileFormat) -> Vec<u8> {
    let rows: Vec<Vec<&str>> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').take(4).collect())
        .collect();
    let z0 = format!("{:.4}", spec.floor_z_mm);
    let mut out = String::new();
    match format {
        ProbeFileFormat::Csv => return csv.as_bytes().to_vec(),
        ProbeFileFormat::CmmCsv => {
            let _ = writeln!(
                out,
                "Flatness export {} {part}, seed {}",
                spec.family, spec.seed
            );
            out.push_str("POINT,X,Y,Z,I,J,K\n");
            for r in &rows {
                let _ = writeln!(out, "{},{},{},{},0,0,1", r[0], r[1], r[2], r[3]);
            }
        }
        ProbeFileFormat::Dmis => {
            let _ = writeln!(out, "DMISMN/'{} {part}',05.2", spec.family);
            out.push_str("UNITS/MM,ANGDEC\n$$ nominals\n");
            let mut seen: Vec<&str> = Vec::new();
            for r in &rows {
                if !seen.contains(&r[0]) {
                    seen.push(r[0]);
                    let _ = writeln!(
                        out,
                        "F({})=FEAT/POINT,CART,{},{},{z0},0,0,1",
                        r[0], r[1], r[2]
                    );
                }
            }
            out.push_str("$$ actuals (a point measured twice has two)\n");
            for r in &rows {
                let _ = writeln!(
                    out,
                    "FA({})=FEAT/POINT,CART,{},{},{},0,0,1",
                    r[0], r[1], r[2], r[3]
                );
            }
            out.push_str("ENDFIL\n");
        }
        ProbeFileFormat::Xyz => {
            let _ = writeln!(out, "# {} {part}: x y z, mm", spec.family);
            for r in &rows {
                let _ = writeln!(out, "{} {} {}", r[1], r[2], r[3]);
            }
        }
        ProbeFileFormat::Ply => {
            let mut bytes = format!(
                "ply\nformat binary_little_endian 1.0\ncomment {} {part}, mm\nelement vertex {}\nproperty double x\nproperty double y\nproperty double z\nend_header\n",
                spec.family,
                rows.len()
            )
            .into_bytes();
            for r in &rows {
                for v in &r[1..4] {
                    let v: f64 = v.parse().unwrap_or(f64::NAN);
                    bytes.extend_from_slice(&v.to_le_bytes());
                }
            }
            return bytes;
        }
    }
    out.into_bytes()
}

/// `truth.json`, `outliers.csv`, `finish.ngc`, `job.toml` and `README.md` of the family.
fn write_family_files(spec: &WebPlateSpec, out: &Path, truth: &Truth, command: &str) -> Result<()> {
    io::write_json(&out.join("truth.json"), truth)?;
    let mut text = String::from("part,id,x_mm,y_mm,added_um\n");
    for o in &truth.outliers {
        let _ = writeln!(
            text,
            "{},{},{:.3},{:.3},{}",
            o.part, o.id, o.x_mm, o.y_mm, o.added_um
        );
    }
    io::write_atomic_bytes(&out.join("outliers.csv"), text.as_bytes())?;
    io::write_atomic_bytes(&out.join("finish.ngc"), finishing_program(spec).as_bytes())?;
    io::write_atomic_bytes(&out.join("job.toml"), job_toml(spec).as_bytes())?;
    io::write_atomic_bytes(&out.join("README.md"), readme(spec, command).as_bytes())
}

fn typical_spacing_mm(spec: &WebPlateSpec, n: usize) -> f64 {
    let [x0, y0, x1, y1] = probed_rect(spec);
    match spec.layout {
        Layout::Grid { nx, ny } => ((x1 - x0) / (nx - 1) as f64).max((y1 - y0) / (ny - 1) as f64),
        Layout::Irregular { .. } => ((x1 - x0) * (y1 - y0) / n.max(1) as f64).sqrt(),
    }
}

fn round3(v: f64) -> f64 {
    (v * 1000.0).round() / 1000.0
}

/// Margin of the finishing program's tool-centre path from the wall's inner face, mm: the
/// program stays inside the probed rectangle, where the map is measured rather than extrapolated.
fn program_margin_mm() -> f64 {
    probe_inset_mm() + 5.0
}

/// The finishing pass over the web floor: a zig-zag raster along X with semicircular G2/G3
/// turns, at `Z = floor_z`, in mm (G21 G90 G17). Rapid moves stay well above the floor.
pub fn finishing_program(spec: &WebPlateSpec) -> String {
    let m = WALL_MM + program_margin_mm();
    let (x0, x1) = (spec.origin_x_mm + m, spec.origin_x_mm + spec.size_x_mm - m);
    let (y0, y1) = (spec.origin_y_mm + m, spec.origin_y_mm + spec.size_y_mm - m);
    let passes = ((y1 - y0) / 15.0).ceil().max(1.0) as usize;
    let step = (y1 - y0) / passes as f64;
    let r = step / 2.0;
    let (xa, xb) = (x0 + r, x1 - r);
    let z = spec.floor_z_mm;
    let safe = z + 45.0;
    let mut g = String::new();
    let _ = writeln!(g, "%");
    let _ = writeln!(
        g,
        "(errmap synth web-plate: finishing pass over the web floor, mm)"
    );
    let _ = writeln!(
        g,
        "(plate {} x {} mm at X{:.3} Y{:.3}, floor Z{z:.3}, step-over {step:.3})",
        spec.size_x_mm, spec.size_y_mm, spec.origin_x_mm, spec.origin_y_mm
    );
    let _ = writeln!(g, "G21 G90 G17 G94");
    let _ = writeln!(g, "G0 Z{safe:.3}");
    let _ = writeln!(g, "G0 X{xa:.3} Y{y0:.3}");
    let _ = writeln!(g, "G1 Z{z:.3} F300");
    for p in 0..=passes {
        let y = y0 + step * p as f64;
        let left_to_right = p % 2 == 0;
        let target = if left_to_right { xb } else { xa };
        if p == 0 {
            let _ = writeln!(g, "G1 X{target:.3} F1200");
        } else {
            let _ = writeln!(g, "G1 X{target:.3}");
        }
        if p < passes {
            // Turn up by one step-over: CCW at the right end, CW at the left end.
            let ny = y + step;
            let word = if left_to_right { "G3" } else { "G2" };
            let _ = writeln!(g, "{word} X{target:.3} Y{ny:.3} I0 J{r:.3}");
        }
    }
    let _ = writeln!(g, "G0 Z{safe:.3}");
    let _ = writeln!(g, "M5");
    let _ = writeln!(g, "M2");
    let _ = writeln!(g, "%");
    g
}

/// The job manifest of the generated family (see docs/job.md).
pub fn job_toml(spec: &WebPlateSpec) -> String {
    let (x0, y0) = (spec.origin_x_mm + WALL_MM, spec.origin_y_mm + WALL_MM);
    let (x1, y1) = (
        spec.origin_x_mm + spec.size_x_mm - WALL_MM,
        spec.origin_y_mm + spec.size_y_mm - WALL_MM,
    );
    let z = spec.floor_z_mm;
    let mut nominal = if spec.nominal_columns {
        "# nominal coordinates are per point (nx_mm,ny_mm,nz_mm columns)\n".to_string()
    } else {
        format!("nominal_plane_mm = {z:?}\n")
    };
    if spec.probe_format == ProbeFileFormat::CmmCsv {
        nominal.push_str(&format!("columns = \"{CMM_CSV_COLUMNS}\"\n"));
    }
    let probes = format!("probes/*.{}", spec.probe_format.extension());
    format!(
        "# Part family: the thin-walled web plate of seed 001 (generated by `errmap synth web-plate`).\n\
         family = \"{family}\"\n\
         normal = \"z\"\n\
         {nominal}\
         probes = \"{probes}\"\n\
         # The web floor inside the walls; x_min, y_min, x_max, y_max in mm.\n\
         domain = [{x0}, {y0}, {x1}, {y1}]\n\
         grid_step_mm = 5.0\n\
         \n\
         [clean]\n\
         k_sigma = 3.0\n\
         \n\
         [interp]\n\
         method = \"natural-neighbour\"\n\
         spacing_mm = 10.0\n\
         \n\
         [model]\n\
         hidden = [32, 32]\n\
         epochs = {epochs}\n\
         seed = {seed}\n\
         holdout_fraction = 0.1\n\
         # auto: the fastest trainer this machine has, measured once and cached (errmap gpu-info).\n\
         backend = \"auto\"\n\
         {warm}\
         \n\
         [toolpaths]\n\
         files = [\"finish.ngc\"]\n\
         # Only moves on the web floor (Z {zlo} … {zhi}) are compensated.\n\
         zone = [{zlo}, {zhi}]\n\
         max_segment_mm = 5.0\n\
         chord_tol_mm = 0.005\n\
         map = \"family\"\n",
        family = spec.family,
        warm = spec.warm_epochs.map_or(String::new(), |n| format!(
            "# The family network trains first; each part starts from it and trains {n} steps.\n\
             warm_start = \"family\"\nwarm_epochs = {n}\n"
        )),
        epochs = spec.epochs,
        seed = spec.seed,
        zlo = z - 1.0,
        zhi = z + 1.0,
    )
}

fn readme(spec: &WebPlateSpec, command: &str) -> String {
    let layout = match spec.layout {
        Layout::Grid { nx, ny } => format!("a {nx} × {ny} probe grid"),
        Layout::Irregular { n } => format!("{} scattered probe points", n + 4),
    };
    format!(
        "# Sample family `{family}` (synthetic, known ground truth)\n\n\
         Made by\n\n```\n{command}\n```\n\n\
         {parts} thin-walled web plates {sx} × {sy} mm (wall {w} mm, web floor at Z {z} mm), {layout},\n\
         probe noise {noise} µm (1σ), {nout} chips of +{oum} µm planted per part, two points per part\n\
         measured twice (same `id`). The error field is the web's deflection under the cutting force\n\
         (largest mid-web, ~0 at the walls) plus a small per-part set-up offset and tilt; its formula\n\
         is in `crates/synth/src/web_plate.rs` and the parameters of every part in `truth.json`.\n\n\
         | file | what |\n|---|---|\n\
         | `probes/pNN.csv` | probe points `id,x_mm,y_mm,z_mm` (measured; nominal is the plane Z {z}) |\n\
         | `job.toml` | the batch job: `errmap batch data/web-plate/job.toml` |\n\
         | `finish.ngc` | finishing pass over the web floor (G21, G90, G17; G0/G1/G2/G3) |\n\
         | `truth.json` | generator settings, truth parameters per part, planted outliers |\n\
         | `outliers.csv` | planted outliers `part,id,x_mm,y_mm,added_um` |\n",
        family = spec.family,
        parts = spec.parts,
        sx = spec.size_x_mm,
        sy = spec.size_y_mm,
        w = WALL_MM,
        z = spec.floor_z_mm,
        noise = spec.noise_um,
        nout = spec.outliers_per_part,
        oum = spec.outlier_um,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn field_is_zero_mode_at_walls_and_peaks_mid_web() {
        let spec = WebPlateSpec::default();
        let t = PartTruth {
            part: "p".into(),
            a_um: 30.0,
            skew: 0.0,
            b_um: 0.0,
            c0_um: 0.0,
            c1_um: 0.0,
            c2_um: 0.0,
        };
        // At the wall's inner face s = 0: no deflection; mid-web s = r = ½: A.
        assert!(t.e_um(&spec, 10.0, 150.0).abs() < 1e-9);
        assert!((t.e_um(&spec, 300.0, 150.0) - 30.0).abs() < 1e-9);
        // A quarter of the way across in x: A·sin(π/4).
        let x = 10.0 + 0.25 * 580.0;
        assert!((t.e_um(&spec, x, 150.0) - 30.0 * (0.5f64).sqrt()).abs() < 1e-9);
    }

    #[test]
    fn generates_files_with_planted_outliers_where_recorded() {
        let dir = tempfile::tempdir().unwrap();
        let spec = WebPlateSpec {
            parts: 2,
            ..WebPlateSpec::default()
        };
        let g = generate(&spec, dir.path(), "test").unwrap();
        assert_eq!(g.points_per_part, 144);
        assert_eq!(g.truth.outliers.len(), 6);
        let text = std::fs::read_to_string(dir.path().join("probes/p01.csv")).unwrap();
        // 144 points + 2 repeats + header.
        assert_eq!(text.lines().count(), 147);
        for o in g.truth.outliers.iter().filter(|o| o.part == "p01") {
            let line = text
                .lines()
                .find(|l| l.starts_with(&format!("{},", o.id)))
                .unwrap();
            let f: Vec<f64> = line
                .split(',')
                .skip(1)
                .map(|v| v.parse().unwrap())
                .collect();
            let e_um = (f[2] - 5.0) * 1000.0;
            let truth = g.truth.e_um(0, f[0], f[1]).unwrap();
            // The outlier stands 40 µm above the truth, give or take the probe noise.
            assert!(
                (e_um - truth - 40.0).abs() < 5.0,
                "{line}: {e_um} vs {truth}"
            );
        }
        let ngc = std::fs::read_to_string(dir.path().join("finish.ngc")).unwrap();
        assert!(ngc.contains("G3 ") && ngc.contains("G2 ") && ngc.starts_with("%\n"));
    }

    #[test]
    fn irregular_layout_has_the_corners_and_the_asked_count() {
        let spec = WebPlateSpec {
            layout: Layout::Irregular { n: 60 },
            ..WebPlateSpec::default()
        };
        let pts = layout_points(&spec);
        assert_eq!(pts.len(), 64);
        let [x0, y0, x1, y1] = probed_rect(&spec);
        assert!(pts
            .iter()
            .all(|p| p.0 >= x0 && p.0 <= x1 && p.1 >= y0 && p.1 <= y1));
        assert!(pts.contains(&(x0, y0, false)) && pts.contains(&(x1, y1, false)));
    }
}
