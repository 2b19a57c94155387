//! CLI of `errmap synth web-plate`: write a sample web-plate family with its ground truth.

use super::exit::Result;
use super::Globals;
use errmap::synth::web_plate::{self, WebPlateSpec};
use errmap::synth::web_plate_args;

#[derive(Debug, clap::Args)]
pub struct SynthWebPlateArgs {
    /// Output folder (probes/, job.toml, finish.ngc, truth.json, outliers.csv, README.md).
    #[arg(long, value_name = "DIR", required_unless_present = "old_out")]
    pub out_dir: Option<std::path::PathBuf>,
    /// Old spelling of --out-dir.
    #[arg(
        long = "out",
        value_name = "DIR",
        hide = true,
        conflicts_with = "out_dir"
    )]
    pub old_out: Option<std::path::PathBuf>,
    /// Number of parts in the family.
    #[arg(long, value_name = "N", default_value_t = 8)]
    pub parts: usize,
    /// Seed of every random choice (noise, part variation, outliers, layout).
    #[arg(long, value_name = "N", default_value_t = 1)]
    pub seed: u64,
    /// Plate size XxY in mm.
    #[arg(long, value_name = "XxY", default_value = "600x300", value_parser = web_plate_args::parse_size)]
    pub size: (f64, f64),
    /// Lower-left corner of the plate X,Y in mm.
    #[arg(long, value_name = "X,Y", default_value = "0,0", value_parser = web_plate_args::parse_origin, allow_hyphen_values = true)]
    pub origin: (f64, f64),
    /// Regular probe grid NXxNY, points along X and Y (default 12x12).
    #[arg(long, value_name = "NXxNY", value_parser = web_plate_args::parse_grid, conflicts_with = "irregular")]
    pub grid: Option<(usize, usize)>,
    /// Scattered probe layout of N points (plus the 4 corners of the probed rectangle) instead of a grid.
    #[arg(long, value_name = "N")]
    pub irregular: Option<usize>,
    /// Probe noise, 1σ, µm.
    #[arg(long, value_name = "UM", default_value_t = 1.0)]
    pub noise_um: f64,
    /// Gross outliers (+40 µm chips) planted per part.
    #[arg(long, value_name = "N", default_value_t = 3)]
    pub outliers: usize,
    /// Write per-point nominal columns nx_mm,ny_mm,nz_mm (the job then has no nominal plane).
    #[arg(long)]
    pub nominal_columns: bool,
    /// Training epochs written into job.toml.
    #[arg(long, value_name = "N", default_value_t = WebPlateSpec::default().epochs)]
    pub epochs: u32,
    /// Start each part from the family network and train it N steps (warm_start = "family" in
    /// job.toml).
    #[arg(long, value_name = "N")]
    pub warm_epochs: Option<u32>,
    /// How each probe file is written: csv (errmap's columns), cmm-csv (a date line, then
    /// POINT,X,Y,Z,I,J,K; the job gets `columns`), dmis, xyz or ply (binary).
    #[arg(long, value_parser = super::choices::ProbeFileFormat::parser(), default_value = "csv")]
    pub probe_format: web_plate::ProbeFileFormat,
    /// Family name written into job.toml.
    #[arg(long, value_name = "NAME", default_value = "web-plate")]
    pub family: String,
}

pub fn run(args: SynthWebPlateArgs, _globals: Globals) -> Result<i32> {
    let out_dir = super::deprecated::required(args.out_dir, args.old_out, "--out", "--out-dir")?;
    web_plate_args::check_noise_um(args.noise_um)?;
    let layout = web_plate_args::layout(args.grid, args.irregular);
    let spec = WebPlateSpec {
        family: args.family.clone(),
        parts: args.parts,
        seed: args.seed,
        size_x_mm: args.size.0,
        size_y_mm: args.size.1,
        origin_x_mm: args.origin.0,
        origin_y_mm: args.origin.1,
        layout,
        noise_um: args.noise_um,
        outliers_per_part: args.outliers,
        nominal_columns: args.nominal_columns,
        epochs: args.epochs,
        warm_epochs: args.warm_epochs,
        probe_format: args.probe_format,
        ..WebPlateSpec::default()
    };
    let command = std::iter::once("errmap".to_string())
        .chain(std::env::args().skip(1))
        .collect::<Vec<_>>()
        .join(" ");
    let generated = web_plate::generate(&spec, &out_dir, &command)?;
    info!(
        "wrote {} parts × {} points, {} planted outliers, to {}",
        spec.parts,
        generated.points_per_part,
        generated.truth.outliers.len(),
        out_dir.display()
    );
    Ok(0)
}
