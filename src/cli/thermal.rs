//! CLI of `errmap thermal …` and `errmap synth thermal`.

use super::exit::Result;
use super::Globals;
use errmap::error::Error;
use errmap::linear::Standard;
use errmap::synth::thermal::{write_campaigns, SynthThermalOptions};
use errmap::thermal::campaign::Campaign;
#[cfg(debug_assertions)]
use errmap::thermal::store::IngestFaults;
use errmap::thermal::store::{IngestSummary, Store};
use errmap::thermal::{commands, text, FitOptions};
use std::path::PathBuf;

#[derive(Debug, clap::Subcommand)]
pub enum ThermalCommand {
    /// Calibrate every sensor against the reference sensor (offset and scale by least squares)
    /// and store the result in the sensor table.
    Calibrate(CalibrateArgs),
    /// Thermal error Et = E − Es at every measurement time against the cold measurement, with
    /// a fitted straight error line per time (table, CSV and chart).
    Difference(DifferenceArgs),
    /// Add campaigns to the temperature-history store (one transaction per campaign).
    Ingest(IngestArgs),
    /// Fit the thermal error model to campaigns: the geometric error plus the growth driven by
    /// the temperature sensors.
    Fit(FitArgs),
    /// List the model versions in the store.
    Models(ModelsArgs),
    /// Compensation values for a machine log (streamed).
    Compensate(CompensateArgs),
    /// Positioning figures before and after compensation for each measurement time.
    Evaluate(EvaluateArgs),
}

#[derive(Debug, clap::Args)]
pub struct CalibrateArgs {
    /// Sensor table to calibrate (CSV).
    #[arg(long, value_name = "FILE")]
    pub sensors: PathBuf,
    /// Temperature log of the calibration period (all sensors beside the reference).
    pub log: PathBuf,
    /// Start of the calibration period, seconds of the log; default: the start of the log.
    #[arg(long, value_name = "SECONDS")]
    pub from: Option<f64>,
    /// End of the calibration period, seconds of the log; default: the end of the log.
    #[arg(long, value_name = "SECONDS")]
    pub to: Option<f64>,
    /// Below this span of readings (°C) only the offset is fitted (scale kept at 1).
    #[arg(long, value_name = "DEG_C", default_value_t = 1.0)]
    pub min_span_c: f64,
    /// Write the calibrated table to this file instead of updating --sensors in place.
    #[arg(short, long, value_name = "FILE")]
    pub output: Option<PathBuf>,
    /// Print one JSON document instead of the table.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, clap::Args)]
pub struct DifferenceArgs {
    /// Campaign folder (or its campaign.toml).
    pub campaign: PathBuf,
    /// Output folder for difference.csv, lines.csv, fan.png and difference.json (default: <campaign>/difference).
    #[arg(long, value_name = "DIR")]
    pub out_dir: Option<PathBuf>,
    /// Old spelling of --out-dir.
    #[arg(
        short = 'o',
        long = "output",
        value_name = "DIR",
        hide = true,
        conflicts_with = "out_dir"
    )]
    pub old_output: Option<PathBuf>,
    /// Print one JSON document instead of the table.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, clap::Args)]
pub struct IngestArgs {
    /// Campaign folders (or campaign.toml files).
    #[arg(required = true)]
    pub campaigns: Vec<PathBuf>,
    /// Store file (default: thermal.sqlite beside the first campaign's folder).
    #[arg(long, value_name = "FILE")]
    pub db: Option<PathBuf>,
    /// Replace a stored campaign of the same name.
    #[arg(long)]
    pub replace: bool,
    /// Print one JSON document.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, clap::Args)]
pub struct FitArgs {
    /// Campaign folders (or campaign.toml files). With --from-store they only locate the
    /// default store (thermal.sqlite beside them).
    pub campaigns: Vec<PathBuf>,
    /// Write the model to this file (JSON).
    #[arg(short, long, value_name = "MODEL.json")]
    pub output: PathBuf,
    /// Fit every campaign in the store (or those named with --campaign) and save the model as
    /// a new version there.
    #[arg(long)]
    pub from_store: bool,
    /// With --from-store: only these stored campaigns (repeatable).
    #[arg(long = "campaign", value_name = "NAME")]
    pub campaign_names: Vec<String>,
    /// Store file (default: thermal.sqlite beside the first campaign, or in the current folder).
    /// Given without --from-store, the model is also saved there as a new version.
    #[arg(long, value_name = "FILE")]
    pub db: Option<PathBuf>,
    /// Model name in the store (default: the axis).
    #[arg(long)]
    pub name: Option<String>,
    /// Sensors driving tanβ, comma-separated (default: the nut and bearing sensors).
    #[arg(long, value_delimiter = ',')]
    pub sensors: Option<Vec<String>>,
    /// Polynomial order of the geometric error Er(x) (default: chosen by cross-validation).
    #[arg(long, value_name = "N")]
    pub order: Option<usize>,
    /// Highest order cross-validation may choose.
    #[arg(long, value_name = "N", default_value_t = 8)]
    pub max_order: usize,
    /// Ambient coefficient ρ in µm/m/K (default: fitted when there is an ambient sensor).
    #[arg(long, value_name = "UM_PER_M_K")]
    pub rho: Option<f64>,
    /// Reference point Px in mm (default: reference_point_mm of the campaigns).
    #[arg(long, value_name = "MM")]
    pub reference_mm: Option<f64>,
    /// Skip the leave-one-campaign-out cross-validation.
    #[arg(long)]
    pub no_loco: bool,
    /// Where the rises are measured from: shared (one cold state for all campaigns),
    /// own-start (each campaign's cold measurement), campaign-offset (shared plus a fitted
    /// tanβ offset per campaign), or cv (the lowest leave-one-campaign-out RMS).
    #[arg(long, default_value = "cv")]
    pub reference: String,
    /// Print the model as one JSON document instead of the report.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, clap::Args)]
pub struct ModelsArgs {
    /// Store file (default: thermal.sqlite in the current folder).
    #[arg(long, value_name = "FILE")]
    pub db: Option<PathBuf>,
    /// Print one JSON document.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, clap::Args)]
pub struct CompensateArgs {
    /// Model from `errmap thermal fit`.
    #[arg(long)]
    pub model: PathBuf,
    /// Machine log: time_s,position_mm,direction,<sensor…>,ambient_c,coolant.
    pub log: PathBuf,
    /// Output CSV file: time_s,position_mm,direction,error_um,compensation_um.
    #[arg(short, long, value_name = "FILE.csv")]
    pub output: PathBuf,
    /// Print the summary as one JSON document.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, clap::Args)]
pub struct EvaluateArgs {
    /// Model from `errmap thermal fit`.
    #[arg(long)]
    pub model: PathBuf,
    /// Campaign folders (or campaign.toml files).
    #[arg(required = true)]
    pub campaigns: Vec<PathBuf>,
    /// Evaluation standard.
    #[arg(long, value_parser = super::choices::Standard::parser(), default_value = "iso230-2:2014")]
    pub standard: Standard,
    /// Output folder for evaluate.csv, evaluate.png and evaluate.json (default: the model's folder).
    #[arg(long, value_name = "DIR")]
    pub out_dir: Option<PathBuf>,
    /// Old spelling of --out-dir.
    #[arg(
        short = 'o',
        long = "output",
        value_name = "DIR",
        hide = true,
        conflicts_with = "out_dir"
    )]
    pub old_output: Option<PathBuf>,
    /// Print one JSON document instead of the table.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, clap::Args)]
pub struct SynthThermalArgs {
    /// Output folder (campaign folders, sensors.csv, calibration.csv, truth.json).
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
    /// Number of campaigns (coolant alternates off, on, …).
    #[arg(long, value_name = "N", default_value_t = 4)]
    pub campaigns: usize,
    /// Bidirectional runs per measurement.
    #[arg(long, value_name = "N", default_value_t = 2)]
    pub repeats: u32,
    /// Time between measurements, seconds.
    #[arg(long, value_name = "SECONDS", default_value_t = 900.0)]
    pub every_s: f64,
    /// Laser noise, one sigma, µm.
    #[arg(long, value_name = "UM", default_value_t = 0.5)]
    pub laser_noise_um: f64,
    /// Start the machine program during the cold measurement of each campaign (at a time
    /// drawn from the seed), so the cold state already holds a small rise.
    #[arg(long)]
    pub warm_start: bool,
}

pub fn run(cmd: ThermalCommand, globals: Globals) -> Result<i32> {
    match cmd {
        ThermalCommand::Calibrate(a) => run_calibrate(a, globals),
        ThermalCommand::Difference(a) => run_difference(a, globals),
        ThermalCommand::Ingest(a) => run_ingest(a, globals),
        ThermalCommand::Fit(a) => run_fit(a, globals),
        ThermalCommand::Models(a) => run_models(a),
        ThermalCommand::Compensate(a) => run_compensate(a, globals),
        ThermalCommand::Evaluate(a) => run_evaluate(a, globals),
    }
}

fn print_json<T: serde::Serialize>(value: &T) -> Result<()> {
    let text = serde_json::to_string_pretty(value)
        .map_err(|e| Error::Internal(format!("JSON output: {e}")))?;
    outln!("{text}");
    Ok(())
}

fn run_calibrate(a: CalibrateArgs, _g: Globals) -> Result<i32> {
    let (fits, out) =
        commands::calibrate_table(&a.sensors, &a.log, a.from, a.to, a.min_span_c, a.output)?;
    if a.json {
        print_json(&fits)?;
    } else {
        out!("{}", text::calibration_table(&fits));
        info!("calibrated table written to {}", out.display());
    }
    Ok(0)
}

fn run_difference(a: DifferenceArgs, _g: Globals) -> Result<i32> {
    let run = commands::difference_run(&a.campaign)?;
    let out = super::deprecated::old_output_folder(
        a.out_dir,
        a.old_output,
        "--out-dir",
        "difference.csv, lines.csv and fan.png",
    )?
    .unwrap_or_else(|| run.default_out_dir());
    run.write_files(&out)?;
    if a.json {
        print_json(&run.difference)?;
    } else {
        out!("{}", text::difference_table(&run.difference));
        info!(
            "wrote difference.csv, lines.csv, fan.png, difference.json in {}",
            out.display()
        );
    }
    Ok(0)
}

fn run_ingest(a: IngestArgs, _g: Globals) -> Result<i32> {
    let db = commands::ingest_store(a.db.clone(), &a.campaigns);
    let mut each = |s: &IngestSummary| -> errmap::Result<()> {
        if !a.json {
            out!("{}", text::ingest_line(s));
        }
        Ok(())
    };
    let report =
        commands::ingest_folders(&db, &a.campaigns, &mut ingest_one(a.replace), &mut each)?;
    if a.json {
        print_json(&report.json()?)?;
    } else {
        info!("store: {}", db.display());
    }
    Ok(0)
}

/// One campaign into the open store. Debug builds (the tests) honour two fault injections
/// inside the transaction: ERRMAP_TEST_FAIL_AFTER_SAMPLES=N fails after N temperature samples,
/// ERRMAP_TEST_PAUSE_AFTER_SAMPLES=N says so on stderr and waits for a line on stdin there.
fn ingest_one(replace: bool) -> impl FnMut(&mut Store, &Campaign) -> errmap::Result<IngestSummary> {
    move |store: &mut Store, campaign: &Campaign| {
        #[cfg(debug_assertions)]
        {
            let env = |name: &str| std::env::var(name).ok().and_then(|v| v.parse::<u64>().ok());
            let fail_after_samples = env("ERRMAP_TEST_FAIL_AFTER_SAMPLES");
            let pause_after_samples = env("ERRMAP_TEST_PAUSE_AFTER_SAMPLES");
            if fail_after_samples.is_some() || pause_after_samples.is_some() {
                let mut pause = |samples: u64| {
                    eprintln!("errmap: ingest paused after {samples} samples");
                    let mut line = String::new();
                    let _ = std::io::stdin().read_line(&mut line);
                };
                let faults = IngestFaults {
                    fail_after_samples,
                    pause_after_samples,
                    pause: &mut pause,
                };
                return store.ingest_with_faults(campaign, replace, faults);
            }
        }
        store.ingest(campaign, replace)
    }
}

fn run_fit(a: FitArgs, _g: Globals) -> Result<i32> {
    let request = commands::FitRequest {
        campaigns: a.campaigns,
        output: a.output,
        from_store: a.from_store,
        campaign_names: a.campaign_names,
        db: a.db,
        name: a.name,
        reference: a.reference,
        options: FitOptions {
            reference: None,
            sensors: a.sensors,
            max_order: a.max_order,
            order: a.order,
            rho_um_per_m_k: a.rho,
            reference_point_mm: a.reference_mm,
            leave_one_out: !a.no_loco,
        },
    };
    let outcome = commands::fit_model(&request)?;
    if a.json {
        print_json(&outcome.model)?;
        return Ok(0);
    }
    out!("{}", text::model_report(&outcome.model));
    info!("model written to {}", request.output.display());
    if let Some((db, name, version)) = outcome.saved {
        info!(
            "saved as model '{name}' version {version} in {}",
            db.display()
        );
    }
    Ok(0)
}

fn run_models(a: ModelsArgs) -> Result<i32> {
    let report = commands::list_models(a.db)?;
    if a.json {
        print_json(&report.json()?)?;
    } else {
        out!("{}", text::models_table(&report));
    }
    Ok(0)
}

fn run_compensate(a: CompensateArgs, _g: Globals) -> Result<i32> {
    let (model, s) = commands::compensate_log(&a.model, &a.log, &a.output)?;
    if a.json {
        print_json(&s)?;
    } else {
        out!("{}", text::compensate_line(&s, &model));
        info!("wrote {}", a.output.display());
    }
    Ok(0)
}

fn run_evaluate(a: EvaluateArgs, _g: Globals) -> Result<i32> {
    let run = commands::evaluate_run(&a.model, &a.campaigns, a.standard)?;
    let out = super::deprecated::old_output_folder(
        a.out_dir,
        a.old_output,
        "--out-dir",
        "evaluate.csv and evaluate.png",
    )?
    .unwrap_or_else(|| run.default_out_dir());
    run.write_files(&out)?;
    if a.json {
        print_json(&run.report)?;
        return Ok(0);
    }
    out!("{}", text::evaluate_table(&run.report));
    info!(
        "wrote evaluate.csv, evaluate.png, evaluate.json in {}",
        out.display()
    );
    Ok(0)
}

pub fn run_synth(a: SynthThermalArgs, _g: Globals) -> Result<i32> {
    let options = SynthThermalOptions {
        seed: a.seed,
        campaigns: a.campaigns,
        repeats: a.repeats,
        every_s: a.every_s,
        laser_noise_um: a.laser_noise_um,
        warm_start: a.warm_start,
        ..Default::default()
    };
    options.check()?;
    let out_dir = super::deprecated::required(a.out_dir, a.old_out, "--out", "--out-dir")?;
    let truth = write_campaigns(&out_dir, &options)?;
    info!(
        "wrote {} campaigns, sensors.csv, calibration.csv and truth.json in {}",
        truth.campaigns.len(),
        out_dir.display()
    );
    Ok(0)
}
