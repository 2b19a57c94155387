//! CLI of `errmap circular` and `errmap synth circular`: read a circular-test run, print the ISO 230-4 figures and the diagnosis, draw the polar chart; write synthetic runs.

use super::Globals;
use errmap::circular::{
    analyze, chart::save_polar_chart, read_run, Evaluation, Form, Plane, ReadOptions,
};
use errmap::synth::circular::{write_set, CircularSynthConfig};
use errmap::{Error, Result};
use std::fmt::Write as _;
use std::path::PathBuf;

#[derive(Debug, clap::Args)]
pub struct CircularArgs {
    /// Run file (CSV): direction,angle_deg,deviation_um (ballbar) or direction,x_mm,y_mm (two axes).
    pub run: PathBuf,
    /// Programmed radius of the circle.
    #[arg(long, value_name = "MM")]
    pub radius: f64,
    /// Plane of the circle: its first and second axis (xy: X, Y; yz: Y, Z; zx: Z, X).
    #[arg(long, value_enum, default_value = "xy")]
    pub plane: Plane,
    /// Programmed feed; needed to give the servo mismatch in ms.
    #[arg(long, value_name = "MM_PER_MIN")]
    pub feed: Option<f64>,
    /// Nominal centre of the circle in a two-axis file's coordinates (first,second).
    #[arg(long, value_name = "MM,MM", value_parser = parse_pair, allow_hyphen_values = true)]
    pub centre: Option<[f64; 2]>,
    /// Print one JSON document on stdout.
    #[arg(long)]
    pub json: bool,
    /// Write the polar chart (PNG) and, beside it, the result as NAME.json (read by `errmap report`).
    #[arg(long, short = 'o', value_name = "PNG")]
    pub output: Option<PathBuf>,
}

fn parse_pair(s: &str) -> std::result::Result<[f64; 2], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|p| p.trim().parse::<f64>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| format!("'{s}' is not two numbers such as 250,-120"))?;
    match v.as_slice() {
        [a, b] if a.is_finite() && b.is_finite() => Ok([*a, *b]),
        _ => Err(format!("'{s}' is not two numbers such as 250,-120")),
    }
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
    if let Some(feed) = args.feed {
        if !(feed.is_finite() && feed > 0.0) {
            return Err(Error::usage(
                format!("feed {feed} mm/min is not a positive speed"),
                "give the programmed feed, e.g. --feed 1000",
            ));
        }
    }
    if let Some(png) = &args.output {
        let same = png == &args.run
            || matches!((png.canonicalize(), args.run.canonicalize()), (Ok(a), Ok(b)) if a == b);
        if same {
            return Err(Error::usage(
                format!("the chart {} would overwrite the run file", png.display()),
                "give the chart another name with -o, e.g. -o circle.png",
            ));
        }
    }
    let opts = ReadOptions {
        radius_mm: args.radius,
        centre_mm: args.centre.unwrap_or([0.0, 0.0]),
    };
    let run = read_run(&args.run, &opts)?;
    let (eval, centred, _) = analyze(&run, args.plane, args.feed)?;
    if let Some(png) = &args.output {
        save_polar_chart(png, &eval, &centred)?;
        // The result beside the chart, for `errmap report`.
        errmap::report::result::write_result(
            &errmap::report::result::beside(png),
            &errmap::report::result::ResultSpec {
                kind: "circular",
                title: format!("Circular test {}", args.run.display()),
                inputs: &[args.run.as_path()],
                charts: &[png.as_path()],
                table: None,
            },
            &eval,
        )?;
    }
    let text = if args.json {
        let mut t = serde_json::to_string_pretty(&eval)
            .map_err(|e| Error::Internal(format!("JSON of the evaluation: {e}")))?;
        t.push('\n');
        t
    } else {
        human_report(&eval)
    };
    print_stdout(&text)?;
    Ok(0)
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

fn num(v: Option<f64>, digits: usize) -> String {
    errmap::numeric::format::opt(v, digits, "-")
}

/// The text report of `errmap circular`.
fn human_report(e: &Evaluation) -> String {
    let f = &e.figures;
    let [first, second] = e.axes;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "circular test, R {} mm, plane {first}{second}: {} ccw, {} cw readings ({} overshoot rows ignored)",
        f.radius_mm, f.readings.ccw, f.readings.cw, f.readings.overshoot
    );
    let _ = writeln!(s, "\nISO 230-4 (µm)        ccw       cw    both");
    for (name, v) in [
        ("G circular deviation", &f.g_um),
        ("F max", &f.f_max_um),
        ("F min", &f.f_min_um),
    ] {
        let _ = writeln!(
            s,
            "{name:<20} {:>7} {:>8} {:>7}",
            num(v.ccw, 2),
            num(v.cw, 2),
            num(v.bidirectional, 2)
        );
    }
    let _ = writeln!(s, "H circular hysteresis {:>22}", num(f.h_um, 2));
    let _ = writeln!(
        s,
        "centre offset (set-up, removed): {first} {:+.2} µm, {second} {:+.2} µm; mean radius {:+.2} µm",
        f.centre_offset_um[0], f.centre_offset_um[1], f.mean_radius_deviation_um
    );
    let _ = writeln!(
        s,
        "\ndiagnosis (least squares)        value    stderr   share of G"
    );
    for (key, t) in e.terms.list() {
        let mut extra = String::new();
        if let Some(p) = t.period_mm {
            let _ = write!(extra, "  period {p:.3} mm");
        }
        if let Some(d) = t.decay_mm {
            let _ = write!(extra, "  decay {d:.3} mm");
        }
        if let Some(n) = &t.note {
            let _ = write!(extra, "  ({n})");
        }
        let _ = writeln!(
            s,
            "{key:<28} {:>9} {:>9} {:>8}{extra}",
            num(t.value, 3),
            num(t.stderr, 3),
            t.share_of_g
                .map_or_else(|| "-".to_string(), |v| format!("{:.0} %", 100.0 * v)),
        );
    }
    let _ = writeln!(s, "residual RMS {:.3} µm", e.residual_rms_um);
    if !e.model.largest.is_empty() {
        let _ = writeln!(s, "largest contributors: {}", e.model.largest.join(", "));
    }
    s
}

pub fn run_synth(args: SynthCircularArgs, _globals: Globals) -> Result<i32> {
    let steps = 360.0 / args.step_deg;
    if !(args.step_deg.is_finite() && args.step_deg > 0.0 && args.step_deg <= 10.0)
        || (steps - steps.round()).abs() > 1e-9
    {
        return Err(Error::usage(
            format!(
                "step {}° does not divide the turn into steps of 10° or less",
                args.step_deg
            ),
            "choose a step that divides 360, e.g. 0.1, 0.5, 1",
        ));
    }
    let positive = |v: f64| v.is_finite() && v > 0.0;
    let noise_ok = args.noise_um.is_finite() && args.noise_um >= 0.0;
    if !positive(args.radius) || !positive(args.feed) || !noise_ok {
        return Err(Error::usage(
            "synth circular needs a positive --radius and --feed and a finite --noise-um ≥ 0",
            "e.g. --radius 100 --feed 1000 --noise-um 0.2",
        ));
    }
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
    let out_dir = super::deprecated::required(args.out_dir, args.old_out, "--out", "--out-dir")?;
    let written = write_set(&out_dir, &config)?;
    for p in written {
        info!("wrote {}", p.display());
    }
    Ok(0)
}
