//! CLI of `errmap thermal …` and `errmap synth thermal`.

use super::Globals;
use errmap::error::{Error, Result};
use errmap::io::{write_atomic, write_json};
use errmap::linear::Standard;
use errmap::synth::thermal::{write_campaigns, SynthThermalOptions};
use errmap::thermal::campaign::{campaign_file_path, direction_name, Campaign};
use errmap::thermal::charts::{evaluate_chart, fan_chart};
use errmap::thermal::compensate::compensate_file;
use errmap::thermal::difference::difference;
use errmap::thermal::evaluate::evaluate_campaigns;
use errmap::thermal::model::{fit, FitOptions, Reference, ThermalModel};
use errmap::thermal::sensors::{calibrate, SensorTable, TemperatureLog};
use errmap::thermal::store::{IngestHooks, Store, DEFAULT_STORE};
use std::path::{Path, PathBuf};

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
    /// Test hook: fail after this many temperature samples.
    #[arg(long, hide = true)]
    pub fail_after_samples: Option<u64>,
    /// Test hook: pause (waiting for a line on stdin) after this many temperature samples.
    #[arg(long, hide = true)]
    pub pause_after_samples: Option<u64>,
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
    #[arg(long, value_enum, default_value = "iso230-2:2014")]
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

fn opt(v: Option<f64>) -> String {
    errmap::numeric::format::opt(v, 3, "n/a")
}

fn run_calibrate(a: CalibrateArgs, _g: Globals) -> Result<i32> {
    let mut table = SensorTable::read(&a.sensors)?;
    let log = TemperatureLog::read(&a.log, &table)?;
    let from = a.from.unwrap_or(f64::NEG_INFINITY);
    let to = a.to.unwrap_or(f64::INFINITY);
    let fits = calibrate(&log, &table, from, to, a.min_span_c)?;
    table.apply_calibrations(&fits);
    // Without -o the table is updated in place (atomically): the one documented output that
    // replaces an input. With -o, the output must not be an input.
    let out = match a.output {
        Some(out) => out,
        None => {
            errmap::io::safety::allow_replacing(&a.sensors);
            a.sensors
        }
    };
    table.write(&out)?;
    if a.json {
        print_json(&fits)?;
    } else {
        outln!("sensor      offset_c     scale  residual_rms_c  samples");
        for f in &fits {
            outln!(
                "{:<10} {:>9.4} {:>9.5} {:>15.4} {:>8}{}",
                f.sensor,
                f.calibration.offset_c,
                f.calibration.scale,
                f.residual_rms_c,
                f.samples,
                if f.scale_fitted {
                    ""
                } else {
                    "  (offset only: too little range)"
                }
            );
        }
        info!("calibrated table written to {}", out.display());
    }
    Ok(0)
}

fn run_difference(a: DifferenceArgs, _g: Globals) -> Result<i32> {
    let campaign = Campaign::read(&a.campaign)?;
    let d = difference(&campaign)?;
    let out = super::deprecated::old_output_folder(
        a.out_dir,
        a.old_output,
        "--out-dir",
        "difference.csv, lines.csv and fan.png",
    )?
    .unwrap_or_else(|| campaign.dir.join("difference"));
    write_atomic(&out.join("difference.csv"), |w| {
        writeln!(w, "time_s,direction,target_mm,e_um,es_um,et_um")?;
        for r in &d.rows {
            writeln!(
                w,
                "{},{},{},{:.4},{:.4},{:.4}",
                r.time_s,
                r.direction.symbol(),
                r.target_mm,
                r.e_um,
                r.es_um,
                r.et_um
            )?;
        }
        Ok(())
    })?;
    let sensors: Vec<String> = campaign.log.sensors.clone();
    write_atomic(&out.join("lines.csv"), |w| {
        write!(w, "time_s,direction,slope_um_per_m,offset_um,rms_um")?;
        for s in &sensors {
            write!(w, ",{s}_c")?;
        }
        writeln!(w)?;
        for l in &d.lines {
            write!(
                w,
                "{},{},{:.4},{:.4},{:.4}",
                l.time_s,
                l.direction.symbol(),
                l.slope_um_per_m,
                l.offset_um,
                l.rms_um
            )?;
            for s in &sensors {
                write!(
                    w,
                    ",{:.3}",
                    l.temperatures_c.get(s).copied().unwrap_or(f64::NAN)
                )?;
            }
            writeln!(w)?;
        }
        Ok(())
    })?;
    fan_chart(&out.join("fan.png"), &d)?;
    errmap::report::result::write_result(
        &out.join("difference.json"),
        &errmap::report::result::ResultSpec {
            kind: "thermal-difference",
            title: format!("Thermal difference, campaign {}", d.campaign),
            inputs: &[campaign_file_path(&a.campaign).as_path()],
            charts: &[&out.join("fan.png")],
            table: None,
        },
        &d,
    )?;
    if a.json {
        print_json(&d)?;
    } else {
        outln!(
            "campaign {} — thermal error lines Et = offset + slope·x (cold measurement at {} s)",
            d.campaign,
            d.cold_time_s
        );
        outln!("  time_s  dir  slope_um_per_m  offset_um  rms_um");
        for l in &d.lines {
            outln!(
                "{:>8} {:>4} {:>15.3} {:>10.3} {:>7.3}",
                l.time_s,
                l.direction.symbol(),
                l.slope_um_per_m,
                l.offset_um,
                l.rms_um
            );
        }
        info!(
            "wrote difference.csv, lines.csv, fan.png, difference.json in {}",
            out.display()
        );
    }
    Ok(0)
}

/// thermal.sqlite in the parent folder of a campaign folder (beside the campaign), however
/// the folder is spelled (`x`, `./x`, `/abs/x`, `.`): the folder is made absolute first.
fn store_beside(campaign: &Path) -> PathBuf {
    let file = campaign_file_path(campaign);
    let dir = file.parent().map(Path::to_path_buf).unwrap_or_default();
    let dir = if dir.as_os_str().is_empty() {
        PathBuf::from(".")
    } else {
        dir
    };
    let dir = std::fs::canonicalize(&dir)
        .or_else(|_| std::path::absolute(&dir))
        .unwrap_or(dir);
    dir.parent()
        .map(|p| p.join(DEFAULT_STORE))
        .unwrap_or_else(|| dir.join(DEFAULT_STORE))
}

fn run_ingest(a: IngestArgs, _g: Globals) -> Result<i32> {
    let db =
        a.db.clone()
            .unwrap_or_else(|| store_beside(&a.campaigns[0]));
    let mut store = Store::open(&db)?;
    let hooks = IngestHooks {
        fail_after_samples: a.fail_after_samples,
        pause_after_samples: a.pause_after_samples,
    };
    let mut summaries = Vec::new();
    for path in &a.campaigns {
        let campaign = Campaign::read(path)?;
        let s = store.ingest(&campaign, a.replace, hooks)?;
        if !a.json {
            outln!(
                "{}: {} sensors, {} temperature samples, {} laser readings{}",
                s.campaign,
                s.sensors,
                s.temperature_samples,
                s.laser_readings,
                if s.replaced { " (replaced)" } else { "" }
            );
        }
        summaries.push(s);
    }
    if a.json {
        print_json(&serde_json::json!({ "store": db, "ingested": summaries }))?;
    } else {
        info!("store: {}", db.display());
    }
    Ok(0)
}

fn run_fit(a: FitArgs, _g: Globals) -> Result<i32> {
    let db = a.db.clone().or_else(|| {
        a.from_store.then(|| {
            a.campaigns
                .first()
                .map(|c| store_beside(c))
                .unwrap_or_else(|| PathBuf::from(DEFAULT_STORE))
        })
    });
    let campaigns: Vec<Campaign> = if a.from_store {
        let store = Store::open(db.as_deref().unwrap_or(Path::new(DEFAULT_STORE)))?;
        if a.campaign_names.is_empty() {
            store.load_all()?
        } else {
            a.campaign_names
                .iter()
                .map(|n| store.load_campaign(n))
                .collect::<Result<_>>()?
        }
    } else {
        if a.campaigns.is_empty() {
            return Err(Error::usage(
                "no campaigns to fit",
                "name campaign folders, or use --from-store",
            ));
        }
        a.campaigns
            .iter()
            .map(|p| Campaign::read(p))
            .collect::<Result<_>>()?
    };
    if campaigns.is_empty() {
        return Err(Error::usage(
            "the store holds no campaigns",
            "add campaigns with `errmap thermal ingest`",
        ));
    }
    let reference = match a.reference.as_str() {
        "cv" => None,
        other => Some(Reference::parse(other).ok_or_else(|| {
            Error::usage(
                format!("--reference {other} is not a reference"),
                "give shared, own-start, campaign-offset or cv",
            )
        })?),
    };
    let options = FitOptions {
        reference,
        sensors: a.sensors.clone(),
        max_order: a.max_order,
        order: a.order,
        rho_um_per_m_k: a.rho,
        reference_point_mm: a.reference_mm,
        leave_one_out: !a.no_loco,
    };
    let model = fit(&campaigns, &options)?;
    write_json(&a.output, &model)?;
    let mut saved = None;
    if let Some(db) = &db {
        let mut store = Store::open(db)?;
        let name = a.name.clone().unwrap_or_else(|| model.axis.clone());
        let version = store.save_model(&name, &model)?;
        saved = Some((db.clone(), name, version));
    }
    if a.json {
        print_json(&model)?;
        return Ok(0);
    }
    print_model(&model)?;
    info!("model written to {}", a.output.display());
    if let Some((db, name, version)) = saved {
        info!(
            "saved as model '{name}' version {version} in {}",
            db.display()
        );
    }
    Ok(0)
}

fn print_model(m: &ThermalModel) -> Result<()> {
    outln!(
        "axis {}: Px = {} mm, travel {} … {} mm, sensors {}{}",
        m.axis,
        m.reference_point_mm,
        m.x_min_mm,
        m.x_max_mm,
        m.gain_sensors.join(", "),
        m.ambient_sensor
            .as_ref()
            .map(|a| format!(", ambient {a}"))
            .unwrap_or_default()
    );
    let scores: Vec<String> = m
        .reference_cv
        .iter()
        .map(|r| format!("{} {}", r.reference.name(), opt(r.loco_rms_um)))
        .collect();
    outln!(
        "rises from: {} ({}); held-out RMS µm by reference: {}",
        m.reference.name(),
        m.reference_chosen_by,
        scores.join(", ")
    );
    for d in &m.directions {
        outln!(
            "{}: Er(x) order {} ({}), residual RMS {:.3} µm over {} readings",
            direction_name(d.direction),
            d.order,
            d.order_chosen_by,
            d.residual_rms_um,
            d.points
        );
        let coeffs: Vec<String> = d
            .legendre_um
            .iter()
            .zip(&d.legendre_se_um)
            .map(|(c, se)| format!("{c:.3}±{}", opt(*se)))
            .collect();
        outln!("  Er Legendre coefficients (µm): {}", coeffs.join("  "));
        for gset in &d.gains {
            let ks: Vec<String> = gset
                .k_um_per_m_k
                .iter()
                .map(|(s, k)| {
                    let se = gset.k_se_um_per_m_k.get(s).copied().flatten();
                    format!("k_{s} = {k:.3}±{} µm/m/K", opt(se))
                })
                .collect();
            outln!("  coolant {}: {}", gset.coolant, ks.join(", "));
        }
        if m.ambient_sensor.is_some() {
            outln!(
                "  ρ = {:.3}{} µm/m/K ({})",
                d.rho_um_per_m_k,
                d.rho_se_um_per_m_k
                    .map(|s| format!("±{s:.3}"))
                    .unwrap_or_default(),
                if d.rho_fitted { "fitted" } else { "given" }
            );
        }
    }
    outln!("campaign                     coolant  times  residual_rms_um  loco_rms_um");
    for c in &m.campaigns {
        outln!(
            "{:<28} {:<8} {:>5} {:>16.3} {:>12}{}",
            c.name,
            c.coolant,
            c.measurements,
            c.residual_rms_um,
            opt(c.loco_rms_um),
            c.loco_note
                .as_ref()
                .map(|n| format!("  ({n})"))
                .unwrap_or_default()
        );
    }
    if let Some(l) = m.loco_rms_um {
        outln!("leave-one-campaign-out RMS: {l:.3} µm");
    }
    Ok(())
}

fn run_models(a: ModelsArgs) -> Result<i32> {
    let db = a.db.unwrap_or_else(|| PathBuf::from(DEFAULT_STORE));
    if !db.exists() {
        return Err(Error::usage(
            format!("no store at {}", db.display()),
            "give --db, or create one with `errmap thermal ingest`",
        ));
    }
    let store = Store::open(&db)?;
    let models = store.models()?;
    if a.json {
        print_json(&serde_json::json!({
            "store": db,
            "counts": store.counts()?,
            "campaigns": store.campaign_names()?,
            "models": models,
        }))?;
        return Ok(0);
    }
    outln!("campaigns: {}", store.campaign_names()?.join(", "));
    outln!("name        version  created_unix  loco_rms_um  campaigns");
    for m in &models {
        outln!(
            "{:<11} {:>7} {:>13} {:>12}  {}",
            m.name,
            m.version,
            m.created_unix,
            opt(m.loco_rms_um),
            m.campaigns.join(",")
        );
    }
    Ok(0)
}

fn run_compensate(a: CompensateArgs, _g: Globals) -> Result<i32> {
    let model = ThermalModel::read(&a.model)?;
    let s = compensate_file(&model, &a.log, &a.output)?;
    if a.json {
        print_json(&s)?;
    } else {
        outln!(
            "{} rows, max |compensation| {:.3} µm, {} rows outside the fitted travel {} … {} mm",
            s.rows,
            s.max_abs_compensation_um,
            s.outside_travel,
            model.x_min_mm,
            model.x_max_mm
        );
        info!("wrote {}", a.output.display());
    }
    Ok(0)
}

fn run_evaluate(a: EvaluateArgs, _g: Globals) -> Result<i32> {
    let model = ThermalModel::read(&a.model)?;
    let campaigns: Vec<Campaign> = a
        .campaigns
        .iter()
        .map(|p| Campaign::read(p))
        .collect::<Result<_>>()?;
    let report = evaluate_campaigns(&model, &campaigns, a.standard)?;
    let out_dir = super::deprecated::old_output_folder(
        a.out_dir,
        a.old_output,
        "--out-dir",
        "evaluate.csv and evaluate.png",
    )?;
    let out = out_dir.unwrap_or_else(|| {
        a.model
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .map(Path::to_path_buf)
            .unwrap_or_else(|| PathBuf::from("."))
    });
    let fmt = |v: Option<f64>| v.map(|v| format!("{v:.4}")).unwrap_or_default();
    write_atomic(&out.join("evaluate.csv"), |w| {
        writeln!(
            w,
            "campaign,time_s,e_before_um,e_after_um,a_before_um,a_after_um,r_before_um,r_after_um,b_before_um,b_after_um,rms_before_um,rms_after_um"
        )?;
        for t in &report.times {
            writeln!(
                w,
                "{},{},{},{},{},{},{},{},{},{},{:.4},{:.4}",
                t.campaign,
                t.time_s,
                fmt(t.before.E),
                fmt(t.after.E),
                fmt(t.before.A),
                fmt(t.after.A),
                fmt(t.before.R),
                fmt(t.after.R),
                fmt(t.before.B),
                fmt(t.after.B),
                t.rms_before_um,
                t.rms_after_um
            )?;
        }
        Ok(())
    })?;
    evaluate_chart(&out.join("evaluate.png"), &report)?;
    errmap::report::result::write_result(
        &out.join("evaluate.json"),
        &errmap::report::result::ResultSpec {
            kind: "thermal-evaluate",
            title: format!("Thermal model {} evaluated", a.model.display()),
            inputs: &[a.model.as_path()],
            charts: &[&out.join("evaluate.png")],
            table: None,
        },
        &report,
    )?;
    if a.json {
        print_json(&report)?;
        return Ok(0);
    }
    outln!(
        "standard {}: figures before → after compensation (µm)",
        report.standard
    );
    outln!("campaign                      time_s   E before → after   A before → after   B before → after");
    for t in &report.times {
        outln!(
            "{:<28} {:>7} {:>8} → {:<7} {:>8} → {:<7} {:>7} → {:<7}",
            t.campaign,
            t.time_s,
            opt(t.before.E),
            opt(t.after.E),
            opt(t.before.A),
            opt(t.after.A),
            opt(t.before.B),
            opt(t.after.B)
        );
    }
    info!(
        "wrote evaluate.csv, evaluate.png, evaluate.json in {}",
        out.display()
    );
    Ok(0)
}

pub fn run_synth(a: SynthThermalArgs, _g: Globals) -> Result<i32> {
    if a.campaigns == 0 || a.repeats == 0 || !(a.every_s.is_finite() && a.every_s > 0.0) {
        return Err(Error::usage(
            "campaigns, repeats and --every-s must be positive",
            "e.g. --campaigns 4 --repeats 2 --every-s 900",
        ));
    }
    if !(a.laser_noise_um.is_finite() && a.laser_noise_um >= 0.0) {
        return Err(Error::usage(
            format!("--laser-noise-um {} is not a noise level", a.laser_noise_um),
            "give one sigma in µm, 0 or more, e.g. --laser-noise-um 0.5",
        ));
    }
    let options = SynthThermalOptions {
        seed: a.seed,
        campaigns: a.campaigns,
        repeats: a.repeats,
        every_s: a.every_s,
        laser_noise_um: a.laser_noise_um,
        warm_start: a.warm_start,
        ..Default::default()
    };
    let out_dir = super::deprecated::required(a.out_dir, a.old_out, "--out", "--out-dir")?;
    let truth = write_campaigns(&out_dir, &options)?;
    info!(
        "wrote {} campaigns, sensors.csv, calibration.csv and truth.json in {}",
        truth.campaigns.len(),
        out_dir.display()
    );
    Ok(0)
}
