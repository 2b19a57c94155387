//! CLI of `errmap compensate`: rewrite a G-code or CSV toolpath with P' = P − E.

use super::Globals;
use errmap::toolpath::{compensate_file, CompensationSettings};
use errmap::{Error, Result};
use std::path::PathBuf;

#[derive(Debug, clap::Args)]
pub struct CompensateArgs {
    /// Fitted map (`model.json` from `errmap map` or a batch).
    #[arg(long, value_name = "MODEL.json")]
    pub model: PathBuf,
    /// Band along the map's normal axis where moves are compensated, in program units
    /// (inches in a G20 program). Default: everywhere.
    #[arg(long, value_name = "MIN,MAX", allow_hyphen_values = true)]
    pub zone: Option<String>,
    /// Longest segment emitted in the zone, mm.
    #[arg(
        long,
        value_name = "MM",
        default_value_t = 5.0,
        allow_negative_numbers = true
    )]
    pub max_segment: f64,
    /// Largest distance between an arc and its chords, mm.
    #[arg(
        long,
        value_name = "MM",
        default_value_t = 0.005,
        allow_negative_numbers = true
    )]
    pub chord_tol: f64,
    /// The toolpath to compensate: G-code (.ngc, .nc, …) or CSV (x_mm,y_mm,z_mm).
    pub input: PathBuf,
    /// Where to write the compensated toolpath.
    #[arg(short = 'o', long = "output", value_name = "OUT")]
    pub output: PathBuf,
    /// Print the report as one JSON document on stdout.
    #[arg(long)]
    pub json: bool,
    /// Plausibility bound, mm: a map reaching |E| beyond it anywhere in its domain is refused
    /// (it would move the tool by that much; almost always a unit slip).
    #[arg(long, value_name = "MM", default_value_t = errmap::probe::DEFAULT_MAX_DEVIATION_MM)]
    pub max_deviation_mm: f64,
}

/// Parse `MIN,MAX`.
pub fn parse_zone(text: &str) -> Result<(f64, f64)> {
    let bad = || {
        Error::usage(
            format!("--zone '{text}' is not MIN,MAX"),
            "give two numbers in program units, e.g. --zone -5,0",
        )
    };
    let (a, b) = text.split_once(',').ok_or_else(bad)?;
    let lo: f64 = a.trim().parse().map_err(|_| bad())?;
    let hi: f64 = b.trim().parse().map_err(|_| bad())?;
    Ok((lo, hi))
}

pub fn run(args: CompensateArgs, _globals: Globals) -> Result<i32> {
    let settings = CompensationSettings {
        zone: args.zone.as_deref().map(parse_zone).transpose()?,
        max_segment: args.max_segment,
        chord_tol: args.chord_tol,
    };
    settings.validate()?;
    errmap::probe::validate_max_deviation(args.max_deviation_mm, "--max-deviation-mm")?;
    let model = errmap::map::FittedModel::read(&args.model)?;
    model.check_plausible(args.max_deviation_mm, &args.model)?;
    errmap::io::safety::protect(&args.input);
    let report = compensate_file(&args.input, &args.output, &model, &settings)?;
    if args.json {
        let doc = serde_json::json!({
            "input": args.input,
            "output": args.output,
            "report": report,
        });
        outln!("{doc}");
    } else {
        outln!("{}: {}", args.output.display(), report.summary_line());
    }
    Ok(0)
}
