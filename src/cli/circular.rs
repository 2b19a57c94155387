//! CLI of `errmap circular` and `errmap synth circular`: read a circular-test run, print the ISO 230-4 figures and the diagnosis, draw the polar chart; write synthetic runs.

use super::exit::Result;
use super::Globals;
use errmap::circular::{human_report, parse_centre_mm, run_test, Form, Plane, TestRequest};
use errmap::synth::circular::{write_set, CircularSynthConfig};
use errmap::Error;
use std::path::PathBuf;

#[derive(Debug, clap::Args)]
pub struct CircularArgs {
    /// Run file (CSV): direction,angle_deg,deviation_um (ballbar) or direction,x_mm,y_mm (two axes).
    pub run: PathBuf,
    /// Programmed radius of the circle.
    #[arg(long, value_name = "MM")]
    pub radius: f64,
    /// Plane of the circle: its first and second axis (xy: X, Y; yz: Y, Z; zx: Z, X).
    #[arg(long, value_parser = super::choices::Plane::parser(), default_value = "xy")]
    pub plane: Plane,
    /// Programmed feed; needed to give the servo mismatch in ms.
    #[arg(long, value_name = "MM_PER_MIN")]
    pub feed: Option<f64>,
    /// Nominal centre of the circle in a two-axis file's coordinates (first,second).
    #[arg(long, value_name = "MM,MM", value_parser = parse_centre_mm, allow_hyphen_values = true)]
    pub centre: Option<[f64; 2]>,
    /// Print one JSON document on stdout.
    #[arg(long)]
    pub json: bool,
    /// Write the polar chart (PNG) and, beside it, the result as NAME.json (read by `errmap report`).
    #[arg(long, short = 'o', value_name = "PNG")]
    pub output: Option<PathBuf>,
}

#[derive(Debug, clap::Args)]
pub struct SynthCircularArgs {
    /// Output folder (run.csv, truth.json).
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
    /// Seed of the noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// File form: radial (ballbar) or two-axis.
    #[arg(long, value_enum, default_value = "radial")]
    pub form: SynthForm,
    /// Radius of the circle.
    #[arg(long, value_name = "MM", default_value_t = 100.0)]
    pub radius: f64,
    /// Feed of the contouring.
    #[arg(long, value_name = "MM_PER_MIN", default_value_t = 1000.0)]
    pub feed: f64,
    /// Angle between readings (divides 360).
    #[arg(long, value_name = "DEG", default_value_t = 0.05)]
    pub step_deg: f64,
    /// Noise of each reading (standard deviation).
    #[arg(long, value_name = "UM", default_value_t = 0.2)]
    pub noise_um: f64,
    /// Only the ccw run, or only the cw run.
    #[arg(long, value_enum)]
    pub only: Option<OnlyDirection>,
}

#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum SynthForm {
    Radial,
    TwoAxis,
}

#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum OnlyDirection {
    Ccw,
    Cw,
}

pub fn run(args: CircularArgs, _globals: Globals) -> Result<i32> {
    let eval = run_test(&TestRequest {
        run: &args.run,
        radius_mm: args.radius,
        plane: args.plane,
        feed_mm_per_min: args.feed,
        centre_mm: args.centre.unwrap_or([0.0, 0.0]),
        chart: args.output.as_deref(),
    })?;
    if args.json {
        let text = serde_json::to_string_pretty(&eval)
            .map_err(|e| Error::Internal(format!("JSON of the evaluation: {e}")))?;
        outln!("{text}");
    } else {
        out!("{}", human_report(&eval));
    }
    Ok(0)
}

pub fn run_synth(args: SynthCircularArgs, _globals: Globals) -> Result<i32> {
    let config = CircularSynthConfig {
        seed: args.seed,
        form: match args.form {
            SynthForm::Radial => Form::Radial,
            SynthForm::TwoAxis => Form::TwoAxis,
        },
        radius_mm: args.radius,
        feed_mm_per_min: args.feed,
        step_deg: args.step_deg,
        noise_um: args.noise_um,
        ccw: !matches!(args.only, Some(OnlyDirection::Cw)),
        cw: !matches!(args.only, Some(OnlyDirection::Ccw)),
        ..Default::default()
    };
    config.check()?;
    let out_dir = super::deprecated::required(args.out_dir, args.old_out, "--out", "--out-dir")?;
    let written = write_set(&out_dir, &config)?;
    for p in written {
        info!("wrote {}", p.display());
    }
    Ok(0)
}
