//! CLI of `errmap linear …` and `errmap synth linear`: analyse laser runs, air index, error budget, compensation tables, sample data.

use super::exit::Result;
use super::Globals;
use errmap::controller::{FanucSeries, SINUMERIK_DEFAULT_MAX_POINTS};
use errmap::linear::{
    compute_budget, read_budget_setup, render_table, AirConditions, AirCorrection, AirFormula,
    AirIndexJson, AnalyzeRequest, Corrections, Evaluation, RunSource, Standard, TableFormat,
    TableOptions, DEFAULT_CO2_PPM, HENE_WAVELENGTH_NM,
};
use errmap::Error;
use std::path::{Path, PathBuf};

#[derive(Debug, clap::Subcommand)]
pub enum LinearCommand {
    /// Evaluate laser runs by a standard (ISO 230-2, GB 10931, VDI 3441); optional corrections, pitch fit, chart, table check.
    Analyze(AnalyzeArgs),
    /// Refractive index of air (Ciddor 1996 or modified Edlén), as NIST's metrology toolbox computes it.
    AirIndex(AirIndexArgs),
    /// Error budget of the laser set-up: each term and the root-sum-square total (µm).
    Budget(BudgetArgs),
    /// Write a bidirectional pitch-error compensation table for a controller.
    Table(TableArgs),
}

/// Corrections applied to the readings before anything else.
#[derive(Debug, Clone, clap::Args)]
pub struct CorrectionArgs {
    /// Readings are on the vacuum-wavelength scale: rescale each by the refractive index of its
    /// row's air (air_temp_c, pressure_kpa, humidity_pct columns).
    #[arg(long)]
    pub correct_air: bool,
    /// Air equation for --correct-air.
    #[arg(long, value_parser = super::choices::AirFormula::parser(), default_value = "ciddor")]
    pub air_formula: AirFormula,
    /// Vacuum wavelength of the laser (nm) for --correct-air.
    #[arg(long, default_value_t = HENE_WAVELENGTH_NM)]
    pub wavelength_nm: f64,
    /// CO2 content (µmol/mol) for --correct-air with Ciddor.
    #[arg(long, default_value_t = DEFAULT_CO2_PPM)]
    pub co2_ppm: f64,
    /// Normalise to 20 °C with this expansion coefficient (µm/(m·K)) and each row's material_temp_c.
    #[arg(long, value_name = "PPM_PER_K")]
    pub material_expansion: Option<f64>,
    /// Machine position (mm) where the laser was zeroed; corrections scale lengths from here.
    #[arg(long, default_value_t = 0.0)]
    pub datum_mm: f64,
}

/// Options shared by table writing and reading.
#[derive(Debug, Clone, clap::Args)]
pub struct TableOptionArgs {
    /// LinuxCNC COMP_FILE_TYPE: 0 = nominal/actual positions, 1 = trims.
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u8).range(0..=1))]
    pub linuxcnc_type: u8,
    /// Fanuc detection unit in µm (1 = IS-B, 0.1 = IS-C).
    #[arg(long, default_value_t = 1.0)]
    pub fanuc_unit_um: f64,
    /// Reference position (mm), a table point: Fanuc's reference point (3620) and the point
    /// where the Sinumerik LEC is zero; default: the first target.
    #[arg(long, allow_negative_numbers = true)]
    pub reference_mm: Option<f64>,
}

/// Controller limits and options of `linear table` and `rotary table`.
#[derive(Debug, Clone, clap::Args)]
pub struct ControllerArgs {
    /// Fanuc control series whose parameter ranges are checked (0i-F or 30i-B).
    #[arg(long, value_parser = super::choices::FanucSeries::parser(), default_value = "0i-F")]
    pub fanuc_series: FanucSeries,
    /// Fanuc pitch-error compensation magnification (parameter 3623), 1 ... 100.
    #[arg(long, default_value_t = 1)]
    pub fanuc_magnification: u32,
    /// Interpolation points per Sinumerik table, as configured in MD38000 (LEC) and MD18342 (CEC).
    #[arg(long, default_value_t = SINUMERIK_DEFAULT_MAX_POINTS)]
    pub sinumerik_max_points: usize,
}

#[derive(Debug, clap::Args)]
pub struct AnalyzeArgs {
    /// Run file (CSV): run,direction,target_mm, actual_mm or deviation_um, optional environment.
    pub runs: PathBuf,
    /// Evaluation standard.
    #[arg(long, value_parser = super::choices::Standard::parser())]
    pub standard: Standard,
    /// Read an instrument's CSV export: FIELD=COLUMN[unit],… e.g.
    /// target=Position,deviation=Error[mm],direction=Dir (see docs/linear.md).
    #[arg(long, value_name = "MAP")]
    pub columns: Option<String>,
    /// Print one JSON document on stdout.
    #[arg(long)]
    pub json: bool,
    /// Write a chart (PNG) and, beside it, the result as NAME.json (read by `errmap report`).
    #[arg(long, value_name = "PNG")]
    pub chart: Option<PathBuf>,
    #[command(flatten)]
    pub corrections: CorrectionArgs,
    /// Fit e(x) = a + k·x + d·sin(2πx/P + φ) with the screw lead P (mm) to the mean bidirectional deviation.
    #[arg(long, value_name = "LEAD_MM")]
    pub fit_pitch: Option<f64>,
    /// Apply a compensation table to the runs and report the figures before and after.
    #[arg(long, value_name = "FILE")]
    pub apply_table: Option<PathBuf>,
    /// Format of --apply-table (default: recognised from the content).
    #[arg(long, value_parser = super::choices::TableFormat::parser())]
    pub table_format: Option<TableFormat>,
    #[command(flatten)]
    pub table_options: TableOptionArgs,
}

#[derive(Debug, clap::Args)]
pub struct AirIndexArgs {
    /// Air temperature (°C).
    #[arg(long, allow_negative_numbers = true)]
    pub temp_c: f64,
    /// Absolute air pressure (kPa).
    #[arg(long)]
    pub pressure_kpa: f64,
    /// Relative humidity (%).
    #[arg(long)]
    pub humidity_pct: f64,
    /// Vacuum wavelength (nm).
    #[arg(long)]
    pub wavelength_nm: f64,
    /// CO2 content (µmol/mol); Ciddor only.
    #[arg(long, default_value_t = DEFAULT_CO2_PPM)]
    pub co2_ppm: f64,
    /// Equation (the same flag as `linear analyze --air-formula`; `--formula` is still read).
    #[arg(long = "air-formula", alias = "formula", value_parser = super::choices::AirFormula::parser(), default_value = "ciddor")]
    pub formula: AirFormula,
    /// Print one JSON document on stdout.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, clap::Args)]
pub struct BudgetArgs {
    /// Set-up file (TOML), see docs/linear.md.
    pub setup: PathBuf,
    /// Print one JSON document on stdout.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, clap::Args)]
pub struct TableArgs {
    /// Run file (CSV).
    pub runs: PathBuf,
    /// Controller format.
    #[arg(long, value_parser = super::choices::TableFormat::parser())]
    pub format: TableFormat,
    /// Read an instrument's CSV export: FIELD=COLUMN[unit],… (see `analyze --columns`).
    #[arg(long, value_name = "MAP")]
    pub columns: Option<String>,
    /// Spacing of the table points (mm), from the first target.
    #[arg(long, value_name = "MM")]
    pub spacing: f64,
    /// Output file (Sinumerik also writes <name>_cec.<ext> beside it).
    #[arg(short = 'o', long = "output", value_name = "FILE")]
    pub output: PathBuf,
    /// Axis name: Sinumerik machine axis (default AX1), Heidenhain column (default X), Fanuc axis number (default 1).
    #[arg(long)]
    pub axis: Option<String>,
    /// First Sinumerik CEC table index for the direction-dependent part (uses it and the next).
    #[arg(long, default_value_t = 0)]
    pub cec_table: u32,
    #[command(flatten)]
    pub corrections: CorrectionArgs,
    #[command(flatten)]
    pub table_options: TableOptionArgs,
    #[command(flatten)]
    pub controller: ControllerArgs,
}

#[derive(Debug, clap::Args)]
pub struct SynthLinearArgs {
    /// Output folder (runs.csv, truth.json).
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
    /// Seed of the noise and the planted errors.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

pub fn run(cmd: LinearCommand, globals: Globals) -> Result<i32> {
    match cmd {
        LinearCommand::Analyze(args) => analyze(args, globals),
        LinearCommand::AirIndex(args) => air_index(args),
        LinearCommand::Budget(args) => budget(args),
        LinearCommand::Table(args) => table(args, globals),
    }
}

pub fn run_synth(args: SynthLinearArgs, _globals: Globals) -> Result<i32> {
    let out_dir = super::deprecated::required(args.out_dir, args.old_out, "--out", "--out-dir")?;
    let (truth, rows) = errmap::synth::linear::generate(args.seed)?;
    errmap::synth::linear::write(&out_dir, &truth, &rows)?;
    info!(
        "wrote {} readings ({} targets × 2 directions × {} runs) to {}",
        rows.len(),
        truth.targets_mm.len(),
        truth.runs,
        out_dir.display()
    );
    Ok(0)
}

impl CorrectionArgs {
    /// The run file at `path` (through the column map `columns`) with these corrections.
    fn source<'a>(&self, path: &'a Path, columns: Option<&'a str>) -> RunSource<'a> {
        RunSource {
            path,
            columns,
            corrections: Corrections {
                air: self.correct_air.then_some(AirCorrection {
                    formula: self.air_formula,
                    wavelength_nm: self.wavelength_nm,
                    co2_ppm: self.co2_ppm,
                    datum_mm: self.datum_mm,
                }),
                material_expansion_ppm_per_k: self.material_expansion,
                datum_mm: self.datum_mm,
            },
        }
    }
}

fn table_options(t: &TableOptionArgs, axis: Option<String>, cec_table: u32) -> TableOptions {
    TableOptions {
        linuxcnc_type: t.linuxcnc_type,
        axis,
        fanuc_unit_um: t.fanuc_unit_um,
        reference_mm: t.reference_mm,
        cec_table,
        ..TableOptions::default()
    }
}

impl ControllerArgs {
    /// Copy the options into the writers' options.
    pub fn apply(&self, opts: &mut TableOptions) {
        opts.fanuc_series = self.fanuc_series;
        opts.fanuc_magnification = self.fanuc_magnification;
        opts.sinumerik_max_points = self.sinumerik_max_points;
    }
}

fn print_json<T: serde::Serialize>(value: &T) -> Result<()> {
    let text = serde_json::to_string_pretty(value).map_err(|e| Error::Internal(e.to_string()))?;
    outln!("{text}");
    Ok(())
}

fn print_evaluation(title: &str, ev: &Evaluation) -> Result<()> {
    out!("{}", errmap::linear::text::evaluation_report(title, ev));
    Ok(())
}

fn analyze(args: AnalyzeArgs, _globals: Globals) -> Result<i32> {
    let analysis = errmap::linear::analyze(&AnalyzeRequest {
        runs: args.corrections.source(&args.runs, args.columns.as_deref()),
        standard: args.standard,
        fit_pitch_lead_mm: args.fit_pitch,
        apply_table: args.apply_table.as_deref(),
        table_format: args.table_format,
        table_options: table_options(&args.table_options, None, 0),
        chart: args.chart.as_deref(),
    })?;
    if args.json {
        print_json(&analysis.document())?;
        return Ok(0);
    }
    for n in &analysis.notes {
        outln!("{n}");
    }
    print_evaluation(&args.runs.display().to_string(), &analysis.evaluation)?;
    if let Some(f) = &analysis.fit {
        outln!(
            "pitch fit (P = {} mm, {} targets): a = {:.3} µm, k = {:.3} µm/m, d = {:.3} µm, φ = {:.4} rad, residual RMS = {:.3} µm",
            f.lead_mm, f.points, f.a_um, f.k_um_per_m, f.d_um, f.phi_rad, f.residual_rms_um
        );
    }
    if let Some((path, after_ev)) = &analysis.after {
        print_evaluation(&format!("after applying {}", path.display()), after_ev)?;
    }
    if let Some(png) = &args.chart {
        info!(
            "chart written to {} (result: {})",
            png.display(),
            errmap::report::result::beside(png).display()
        );
    }
    Ok(0)
}

fn air_index(args: AirIndexArgs) -> Result<i32> {
    let cond = AirConditions {
        temp_c: args.temp_c,
        pressure_kpa: args.pressure_kpa,
        humidity_pct: args.humidity_pct,
        wavelength_nm: args.wavelength_nm,
        co2_ppm: args.co2_ppm,
    };
    let doc = AirIndexJson::compute(cond, args.formula)?;
    if args.json {
        print_json(&doc)?;
    } else {
        outln!("n = {:.9} ({})", doc.n, doc.formula);
        outln!("air wavelength = {:.6} nm", doc.air_wavelength_nm);
    }
    Ok(0)
}

fn budget(args: BudgetArgs) -> Result<i32> {
    let setup = read_budget_setup(&args.setup)?;
    let b = compute_budget(&setup)?;
    if args.json {
        print_json(&b)?;
    } else {
        out!("{}", errmap::linear::text::budget_report(&b));
    }
    Ok(0)
}

fn table(args: TableArgs, _globals: Globals) -> Result<i32> {
    let runs = args.corrections.source(&args.runs, args.columns.as_deref());
    let plan = errmap::linear::plan_table(&runs, args.spacing)?;
    if let Some(d) = plan.unidirectional {
        info!(
            "unidirectional runs (direction {} only): the table carries the same values for both directions",
            d.symbol()
        );
    }
    let mut opts = table_options(&args.table_options, args.axis.clone(), args.cec_table);
    args.controller.apply(&mut opts);
    for (path, text) in render_table(&plan.table, args.format, &opts, &args.output)? {
        errmap::io::write_atomic_bytes(&path, text.as_bytes())?;
        info!(
            "wrote {} ({} points, {} format)",
            path.display(),
            plan.table.positions_mm.len(),
            args.format.name()
        );
    }
    for n in &plan.notes {
        info!("{n}");
    }
    if args.format == TableFormat::Fanuc && plan.unidirectional.is_none() {
        info!("Fanuc: set bit 3605#0 = 1 for bidirectional compensation; the reference return is taken as + direction");
    }
    Ok(0)
}
