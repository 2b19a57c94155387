//! CLI of `errmap compensate`: rewrite a G-code or CSV toolpath with P' = P − E.

use super::exit::Result;
use super::Globals;
use errmap::toolpath::compensate_file;
use errmap::toolpath::zone_spec::SettingsText;
use std::path::PathBuf;

#[derive(Debug, clap::Args)]
pub struct CompensateArgs {
    /// Fitted map (`model.json` from `errmap map` or a batch).
    #[arg(long, value_name = "MODEL.json")]
    pub model: PathBuf,
    /// Band along the map's normal axis where moves are compensated, in the units the program
    /// starts in (inches in a G20 program), or `all`. Default: the map's probed surface ±
    /// --surface-tol.
    #[arg(long, value_name = "MIN,MAX|all", allow_hyphen_values = true)]
    pub zone: Option<String>,
    /// Half-width of the default zone around the map's probed surface, mm.
    #[arg(
        long,
        value_name = "MM",
        default_value_t = 0.5,
        allow_negative_numbers = true
    )]
    pub surface_tol: f64,
    /// The program's controller dialect: linuxcnc, fanuc, sinumerik or heidenhain. Default:
    /// detected from the program (refused when uncertain).
    #[arg(long, value_name = "DIALECT")]
    pub dialect: Option<String>,
    /// Units of a program that states none before its first cut: mm or inch.
    #[arg(long, value_name = "mm|inch")]
    pub units: Option<String>,
    /// How the Fanuc reads numbers without a decimal point: calculator (mm/inch), or the
    /// increment system is-a, is-b (0.001 mm) or is-c.
    #[arg(long, value_name = "MODE")]
    pub fanuc_numbers: Option<String>,
    /// The motion mode the controller powers on in (Fanuc parameter 3402#0, Sinumerik
    /// MD20150): g0 or g1. Needed for blocks with axis words before any motion word.
    #[arg(long, value_name = "g0|g1")]
    pub power_on_motion: Option<String>,
    /// Execute subprograms, loops and parameters whose values are all in the program and write
    /// the flattened, compensated program.
    #[arg(long)]
    pub expand: bool,
    /// Move the depth and reference of canned-cycle holes whose bottom lies in the zone by −E.
    #[arg(long)]
    pub compensate_holes: bool,
    /// Apply the map in each work offset's own coordinates (identical parts on a fixture plate).
    #[arg(long)]
    pub same_part_per_offset: bool,
    /// Also compensate outside the measured domain (the probes' hull), where the map extrapolates.
    #[arg(long)]
    pub extrapolate: bool,
    /// Margin around the probes' hull that still counts as measured, mm.
    #[arg(
        long,
        value_name = "MM",
        default_value_t = 0.0,
        allow_negative_numbers = true
    )]
    pub domain_margin: f64,
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
    /// Where to write the compensated toolpath (a new file; never the input).
    #[arg(short = 'o', long = "output", value_name = "FILE")]
    pub output: PathBuf,
    /// Print the report as one JSON document on stdout.
    #[arg(long)]
    pub json: bool,
    /// Plausibility bound, mm: a map reaching |E| beyond it anywhere in its domain is refused
    /// (it would move the tool by that much; almost always a unit slip).
    #[arg(long, value_name = "MM", default_value_t = errmap::probe::DEFAULT_MAX_DEVIATION_MM)]
    pub max_deviation_mm: f64,
    /// Use a map that removes less than 10 % of E at its held-out points (refused otherwise:
    /// the surface's scatter is noise).
    #[arg(long)]
    pub allow_weak_map: bool,
    /// Leave points where the map's u(E) (model.json's uncertainty, map.csv's u_um) exceeds
    /// UM µm nominal, as points outside the measured domain.
    #[arg(long, value_name = "UM")]
    pub max_uncertainty_um: Option<f64>,
}

pub fn run(args: CompensateArgs, _globals: Globals) -> Result<i32> {
    let settings = SettingsText {
        zone: args.zone.as_deref(),
        surface_tol_mm: args.surface_tol,
        max_segment_mm: args.max_segment,
        chord_tol_mm: args.chord_tol,
        dialect: args.dialect.as_deref(),
        units: args.units.as_deref(),
        fanuc_numbers: args.fanuc_numbers.as_deref(),
        extrapolate: args.extrapolate,
        domain_margin_mm: args.domain_margin,
        power_on_motion: args.power_on_motion.as_deref(),
        expand: args.expand,
        compensate_holes: args.compensate_holes,
        same_part_per_offset: args.same_part_per_offset,
    }
    .settings()?;
    errmap::probe::validate_max_deviation(args.max_deviation_mm, "--max-deviation-mm")?;
    let model = errmap::map::FittedModel::read(&args.model)?;
    model.check_plausible(args.max_deviation_mm, &args.model)?;
    let benefit_warning =
        model.check_benefit(args.allow_weak_map, "pass --allow-weak-map", &args.model)?;
    errmap::io::safety::protect(&args.input);
    let report = match args.max_uncertainty_um {
        None => compensate_file(&args.input, &args.output, &model, &settings)?,
        Some(max_um) => {
            let bounded = model.bounded_by_uncertainty(max_um, &args.model)?;
            compensate_file(&args.input, &args.output, &bounded, &settings)?
        }
    };
    // Said once the map was used: a refused program's message stays the only line.
    if let Some(warning) = benefit_warning {
        super::terminal::warn(&format!("warning: {warning}"));
    }
    if args.json {
        let doc = errmap::toolpath::CompensationDocument {
            input: &args.input,
            output: &args.output,
            report: &report,
        };
        outln!("{}", doc.to_json()?);
    } else {
        outln!("{}: {}", args.output.display(), report.summary_line());
        for note in &report.notes {
            outln!("note: {note}");
        }
    }
    Ok(0)
}
