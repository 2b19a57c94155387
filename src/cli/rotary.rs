//! CLI of `errmap rotary …` and `errmap synth rotary`: arguments, printing, exit codes.

use super::Globals;
use errmap::error::Error;
use errmap::rotary::{
    analyze, build_table, chart::save_error_chart, read_measurement, render, table::fixed,
    Analysis, AnalyzeOptions, RotaryAxis, Sign, TableFormat, TableOptions,
};
use errmap::synth::rotary::{write_set, RotarySynthConfig};
use errmap::Result;
use std::fmt::Write as _;
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
    fn analyze(&self) -> Result<Analysis> {
        let m = read_measurement(&self.file)?;
        let opts = AnalyzeOptions {
            fit_axis: self.fit_axis,
            sphere_diameter_mm: self.sphere_diameter,
            stylus_radius_mm: self.stylus_radius,
            radius_tolerance_mm: self.radius_tolerance,
            fix_radius: self.fix_radius,
            reference_angle_deg: self.reference_angle,
        };
        analyze(&m, &opts)
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
    #[arg(long, value_enum, default_value = "errmap")]
    pub sign: Sign,
}

#[derive(Debug, clap::Args)]
pub struct TableArgs {
    #[command(flatten)]
    pub measurement: MeasurementArgs,
    /// Table format.
    #[arg(long, value_enum, default_value = "csv")]
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
    #[arg(long, value_name = "AXIS", default_value = "C", value_parser = parse_axis)]
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

fn parse_axis(s: &str) -> std::result::Result<RotaryAxis, String> {
    RotaryAxis::parse(s).ok_or_else(|| format!("'{s}' is not A, B or C"))
}

pub fn run(cmd: RotaryCommand, _globals: Globals) -> Result<i32> {
    match cmd {
        RotaryCommand::Analyze(args) => {
            let analysis = args.measurement.analyze()?.with_sign(args.sign);
            if let Some(png) = &args.chart {
                save_error_chart(png, &analysis)?;
                // The result beside the chart, for `errmap report`.
                errmap::report::result::write_result(
                    &errmap::report::result::beside(png),
                    &errmap::report::result::ResultSpec {
                        kind: "rotary-analysis",
                        title: format!("Rotary axis {}", analysis.axis),
                        inputs: &[args.measurement.file.as_path()],
                        charts: &[png.as_path()],
                        table: None,
                    },
                    &analysis,
                )?;
            }
            if args.json {
                let text = serde_json::to_string_pretty(&analysis)
                    .map_err(|e| Error::Internal(format!("JSON of the analysis: {e}")))?;
                print_stdout(&format!("{text}\n"))?;
            } else {
                print_stdout(&human_report(&analysis))?;
            }
            Ok(0)
        }
        RotaryCommand::Table(args) => {
            let analysis = args.measurement.analyze()?;
            let table = build_table(&analysis, args.step_deg, args.start_deg)?;
            let mut opts = TableOptions {
                linuxcnc_type: args.linuxcnc_type,
                axis: args.machine_axis.clone(),
                fanuc_unit_um: args.fanuc_unit_um,
                cec_table: args.cec_table,
                ..TableOptions::default()
            };
            args.controller.apply(&mut opts);
            let files = render(&table, args.format, &opts, &args.output)?;
            for (path, text) in &files {
                errmap::io::write_atomic_bytes(path, text.as_bytes())?;
            }
            let names: Vec<String> = files.iter().map(|f| f.0.display().to_string()).collect();
            print_stdout(&format!(
                "{} entries, 0° … 360° every {}°, written to {}\n{}\nvalues: {}\n",
                table.angles_deg.len(),
                table.step_deg,
                names.join(" and "),
                table.grid_note,
                errmap::rotary::INTERPOLATION,
            ))?;
            Ok(0)
        }
    }
}

/// Write to stdout; a closed pipe (`| head`) is not an error.
fn print_stdout(text: &str) -> Result<()> {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => Err(Error::write("stdout", e)),
        _ => Ok(()),
    }
}

fn opt(v: Option<f64>, digits: usize) -> String {
    v.map_or_else(|| "-".to_string(), |v| fixed(v, digits))
}

/// The text report of `rotary analyze`.
fn human_report(a: &Analysis) -> String {
    let mut s = String::new();
    let r = &a.reference;
    let _ = writeln!(
        s,
        "{} axis: {} observations, reference {}° ({}, {} repeat(s)), lever {:.3} mm",
        a.axis,
        a.observations.len(),
        r.angle_deg,
        r.direction,
        r.n,
        r.lever_mm
    );
    if let Some(sp) = &a.spheres {
        let _ = writeln!(
            s,
            "sphere fits: {}, form ≤ {:.2} µm rms ({:.2} µm p-v), mean radius {:.4} mm{}",
            sp.fits,
            sp.max_form_rms_mm * 1e3,
            sp.max_form_pv_mm * 1e3,
            sp.mean_radius_mm,
            sp.max_abs_radius_deviation_mm
                .map(|d| format!(", |radius − nominal| ≤ {:.2} µm", d * 1e3))
                .unwrap_or_default()
        );
    }
    let ax = &a.axis_fit;
    let d = ax.direction;
    match (ax.tilt_arcsec, &ax.tilt_toward_arcsec, ax.location_mm) {
        (Some(tilt), Some(toward), Some(loc)) => {
            let parts: Vec<String> = toward
                .iter()
                .map(|(k, v)| format!("toward {k} {v:+.2}″"))
                .collect();
            let _ = writeln!(
                s,
                "axis (fitted): direction ({:.8}, {:.8}, {:.8}), tilt {:.2}″ ({}), location ({:.4}, {:.4}, {:.4}) mm",
                d[0],
                d[1],
                d[2],
                tilt,
                parts.join(", "),
                loc[0],
                loc[1],
                loc[2]
            );
        }
        _ => {
            let _ = writeln!(
                s,
                "axis (nominal): direction ({}, {}, {})",
                d[0], d[1], d[2]
            );
        }
    }
    match a.sign {
        Sign::Errmap => {
            let _ = writeln!(s, "\nerr = α − β (arcsec), mean over repeats");
        }
        Sign::Calibrator => {
            let _ = writeln!(
                s,
                "\nerror = β − α = measured − commanded (arcsec, --sign calibrator: ISO 230-2's x), mean over repeats\n{}",
                a.sign.positive(a.axis)
            );
        }
    }
    let _ = writeln!(
        s,
        "{:>10}  dir  {:>12}  {:>8}  {:>3}",
        "angle_deg", "error_arcsec", "s_arcsec", "n"
    );
    for row in &a.table {
        let _ = writeln!(
            s,
            "{:>10}  {:>3}  {:>12}  {:>8}  {:>3}",
            row.angle_deg,
            row.direction.symbol(),
            fixed(row.error_arcsec, 2),
            opt(row.s_arcsec, 2),
            row.n
        );
    }
    match &a.iso230_2 {
        Some(e) => {
            let f = &e.axis;
            let _ = writeln!(
                s,
                "\nISO 230-2:2014 (arcsec, x = actual − target = {}): A {}  A↑ {}  A↓ {}  R {}  R↑ {}  R↓ {}  E {}  M {}  B {}  B̄ {}",
                match a.sign {
                    Sign::Errmap => "−err",
                    Sign::Calibrator => "the error above",
                },
                opt(f.A, 2),
                opt(f.A_up, 2),
                opt(f.A_down, 2),
                opt(f.R, 2),
                opt(f.R_up, 2),
                opt(f.R_down, 2),
                opt(f.E, 2),
                opt(f.M, 2),
                opt(f.B, 2),
                f.B_mean
                    .map_or_else(|| "-".to_string(), |v| format!("{v:+.2}"))
            );
        }
        None => {
            if let Some(note) = &a.iso230_2_note {
                let _ = writeln!(s, "\nISO 230-2: not evaluated ({note})");
            }
        }
    }
    s
}

/// Smallest angle step `synth rotary` takes: 36 000 positions a turn.
const MIN_SYNTH_STEP_DEG: f64 = 0.01;
/// Most probe points `synth rotary` generates (positions × repeats × 2 spheres × points).
const MAX_SYNTH_SAMPLES: f64 = 1e7;

pub fn run_synth(args: SynthRotaryArgs, _globals: Globals) -> Result<i32> {
    if args.step_deg > 0.0 && args.step_deg < MIN_SYNTH_STEP_DEG {
        return Err(Error::usage(
            format!(
                "--step-deg {:?} is below the smallest step of {MIN_SYNTH_STEP_DEG}°",
                args.step_deg
            ),
            "choose a step that divides 360, e.g. 10, 15, 30",
        ));
    }
    let samples = 360.0 / args.step_deg * args.repeats as f64 * 2.0 * args.points as f64;
    if samples > MAX_SYNTH_SAMPLES {
        return Err(Error::usage(
            format!(
                "{samples:.3e} probe points would be generated, more than {MAX_SYNTH_SAMPLES:.0e}"
            ),
            "use a larger --step-deg or fewer --repeats or --points",
        ));
    }
    if (360.0 / args.step_deg).round() < 1.0
        || ((360.0 / args.step_deg) - (360.0 / args.step_deg).round()).abs() > 1e-9
    {
        return Err(Error::usage(
            format!("step {}° does not divide the turn", args.step_deg),
            "choose a step that divides 360, e.g. 10, 15, 30",
        ));
    }
    if args.repeats == 0 || args.points < 4 || !(args.noise_um.is_finite() && args.noise_um >= 0.0)
    {
        return Err(Error::usage(
            "synth rotary needs --repeats ≥ 1, --points ≥ 4 and a finite --noise-um ≥ 0",
            "e.g. --repeats 3 --points 25 --noise-um 0.5",
        ));
    }
    let config = RotarySynthConfig {
        axis: args.axis,
        seed: args.seed,
        step_deg: args.step_deg,
        repeats: args.repeats,
        points_per_sphere: args.points,
        probe_noise_um: args.noise_um,
        ..Default::default()
    };
    let out_dir = super::deprecated::required(args.out_dir, args.old_out, "--out", "--out-dir")?;
    let written = write_set(&out_dir, &config)?;
    for p in written {
        info!("wrote {}", p.display());
    }
    Ok(0)
}
