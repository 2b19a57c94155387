//! CLI of `errmap rotary …` and `errmap synth rotary`: arguments, printing, exit codes.

use super::exit::Result;
use super::Globals;
use errmap::error::Error;
use errmap::rotary::commands::{analyze_command, table_command, AnalyzeRequest, TableRequest};
use errmap::rotary::{AnalyzeOptions, RotaryAxis, Sign, TableFormat, TableOptions};
use errmap::synth::rotary::{write_set, RotarySynthConfig};
use std::path::PathBuf;

#[derive(Debug, clap::Subcommand)]
pub enum RotaryCommand {
    /// Angular error err = α − β of a rotary axis from two spheres on a bar (centres or touch points).
    Analyze(AnalyzeArgs),
    /// Compensation table over the full turn for a controller (LinuxCNC, Sinumerik, Fanuc, Heidenhain) or as CSV.
    Table(TableArgs),
}

/// Options shared by `analyze` and `table`: how to read the measurement.
#[derive(Debug, clap::Args)]
pub struct MeasurementArgs {
    /// Measurement CSV: axis,direction,repeat,angle_deg,sphere,x_mm,y_mm,z_mm[,point].
    pub file: PathBuf,
    /// Fit the axis direction and location from the sphere trajectories (else nominal X/Y/Z).
    #[arg(long)]
    pub fit_axis: bool,
    /// Nominal (calibrated) sphere diameter; touch-point fits whose radius disagrees are errors.
    #[arg(long, value_name = "MM")]
    pub sphere_diameter: Option<f64>,
    /// Stylus tip radius: touch points lie on a sphere of radius sphere + stylus.
    #[arg(long, value_name = "MM", default_value_t = 0.0)]
    pub stylus_radius: f64,
    /// Largest accepted |fitted − nominal| radius of a touch-point fit.
    #[arg(long, value_name = "MM", default_value_t = 0.010)]
    pub radius_tolerance: f64,
    /// Fit only the centres, with the radius fixed at diameter / 2 + stylus radius.
    #[arg(long)]
    pub fix_radius: bool,
    /// Commanded angle of vector a (default 0° if measured, else the smallest angle).
    #[arg(long, value_name = "DEG", allow_hyphen_values = true)]
    pub reference_angle: Option<f64>,
}

impl MeasurementArgs {
    fn options(&self) -> AnalyzeOptions {
        AnalyzeOptions {
            fit_axis: self.fit_axis,
            sphere_diameter_mm: self.sphere_diameter,
            stylus_radius_mm: self.stylus_radius,
            radius_tolerance_mm: self.radius_tolerance,
            fix_radius: self.fix_radius,
            reference_angle_deg: self.reference_angle,
        }
    }
}

#[derive(Debug, clap::Args)]
pub struct AnalyzeArgs {
    #[command(flatten)]
    pub measurement: MeasurementArgs,
    /// Print one JSON document on stdout instead of text.
    #[arg(long)]
    pub json: bool,
    /// Write a chart of error vs angle per direction with the repeat spread, and beside it the
    /// result as NAME.json (read by `errmap report`).
    #[arg(long, value_name = "PNG")]
    pub chart: Option<PathBuf>,
    /// Sign of the errors in the text, JSON and chart: errmap = commanded − measured (α − β),
    /// calibrator = measured − commanded (β − α, as ISO 230-2 and rotary calibrators report).
    #[arg(long, value_parser = super::choices::Sign::parser(), default_value = "errmap")]
    pub sign: Sign,
}

#[derive(Debug, clap::Args)]
pub struct TableArgs {
    #[command(flatten)]
    pub measurement: MeasurementArgs,
    /// Table format.
    #[arg(long, value_parser = super::choices::TableFormat::parser(), default_value = "csv")]
    pub format: TableFormat,
    /// Output file.
    #[arg(long, short = 'o', value_name = "FILE")]
    pub output: PathBuf,
    /// Spacing of the table entries; must divide 360 (default: the measured spacing).
    #[arg(long, value_name = "DEG")]
    pub step_deg: Option<f64>,
    /// Angle of one grid entry (default: the first measured angle when the measured angles
    /// are equally spaced, else 0).
    #[arg(long, value_name = "DEG", allow_negative_numbers = true)]
    pub start_deg: Option<f64>,
    /// Controller axis: Sinumerik machine axis in $AA_ENC_COMP[0,N,<name>] and (<name>) of the
    /// CEC tables (default: axis letter + 1, e.g. C1), Heidenhain column (default: the axis
    /// letter), Fanuc axis number (default 1).
    #[arg(long, value_name = "NAME")]
    pub machine_axis: Option<String>,
    /// LinuxCNC COMP_FILE_TYPE: 0 = nominal/actual positions, 1 = trims.
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u8).range(0..=1))]
    pub linuxcnc_type: u8,
    /// Fanuc detection unit in 0.001 deg (1 = IS-B, 0.1 = IS-C).
    #[arg(long, default_value_t = 1.0)]
    pub fanuc_unit_um: f64,
    /// First Sinumerik CEC table index for the direction-dependent part (uses it and the next).
    #[arg(long, default_value_t = 0)]
    pub cec_table: u32,
    #[command(flatten)]
    pub controller: super::linear::ControllerArgs,
}

#[derive(Debug, clap::Args)]
pub struct SynthRotaryArgs {
    /// Output folder (touch_points.csv, centres.csv, truth.json).
    #[arg(long, value_name = "DIR", required_unless_present = "old_out")]
    pub out_dir: Option<PathBuf>,
    /// Old spelling of --out-dir.
    #[arg(
        long = "out",
        value_name = "DIR",
        hide = true,
        conflicts_with = "out_dir"
    )]
    pub old_out: Option<PathBuf>,
    /// Seed of the probe noise.
    #[arg(long, value_name = "N", default_value_t = 1)]
    pub seed: u64,
    /// Rotary axis: A, B or C.
    #[arg(long, value_name = "AXIS", default_value = "C")]
    pub axis: RotaryAxis,
    /// Angle step of the runs (divides 360).
    #[arg(long, value_name = "DEG", default_value_t = 15.0)]
    pub step_deg: f64,
    /// Runs in each direction.
    #[arg(long, value_name = "N", default_value_t = 3)]
    pub repeats: u32,
    /// Touch points per sphere and position.
    #[arg(long, value_name = "N", default_value_t = 25)]
    pub points: usize,
    /// Probe noise (standard deviation along the surface normal).
    #[arg(long, value_name = "UM", default_value_t = 0.5)]
    pub noise_um: f64,
}

pub fn run(cmd: RotaryCommand, _globals: Globals) -> Result<i32> {
    let text = match cmd {
        RotaryCommand::Analyze(args) => analyze_command(&AnalyzeRequest {
            file: &args.measurement.file,
            options: args.measurement.options(),
            sign: args.sign,
            chart: args.chart.as_deref(),
            json: args.json,
        })?,
        RotaryCommand::Table(args) => {
            let mut controller = TableOptions {
                linuxcnc_type: args.linuxcnc_type,
                axis: args.machine_axis.clone(),
                fanuc_unit_um: args.fanuc_unit_um,
                cec_table: args.cec_table,
                ..TableOptions::default()
            };
            args.controller.apply(&mut controller);
            table_command(&TableRequest {
                file: &args.measurement.file,
                options: args.measurement.options(),
                format: args.format,
                output: &args.output,
                step_deg: args.step_deg,
                start_deg: args.start_deg,
                controller,
            })?
        }
    };
    print_stdout(&text)?;
    Ok(0)
}

/// Write to stdout; a closed pipe (`| head`) is not an error.
fn print_stdout(text: &str) -> errmap::Result<()> {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => Err(Error::write("stdout", e)),
        _ => Ok(()),
    }
}

pub fn run_synth(args: SynthRotaryArgs, _globals: Globals) -> Result<i32> {
    let config = RotarySynthConfig {
        axis: args.axis,
        seed: args.seed,
        step_deg: args.step_deg,
        repeats: args.repeats,
        points_per_sphere: args.points,
        probe_noise_um: args.noise_um,
        ..Default::default()
    };
    // Refused before the folder is resolved, so a bad value is the only message.
    config.check()?;
    let out_dir = super::deprecated::required(args.out_dir, args.old_out, "--out", "--out-dir")?;
    let written = write_set(&out_dir, &config)?;
    for p in written {
        info!("wrote {}", p.display());
    }
    Ok(0)
}
