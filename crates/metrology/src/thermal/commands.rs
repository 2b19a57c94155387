//! The thermal commands as library calls: each reads its inputs, validates them, runs the
//! analysis and writes its files; it returns what a caller shows ([`super::text`] formats it).
//! A command whose output folder the caller resolves after the analysis is split in two:
//! `…_run` (read and analyse) and `write_…` (the files).

use super::campaign::{campaign_file_path, Campaign};
use super::charts::{evaluate_chart, fan_chart};
use super::compensate::{compensate_file, CompensateSummary};
use super::difference::{difference, Difference};
use super::evaluate::{evaluate_campaigns, EvaluationReport};
use super::model::{fit, FitOptions, Reference, ThermalModel};
use super::outputs;
use super::sensors::{calibrate, CalibrationFit, SensorTable, TemperatureLog};
use super::store::{store_beside, IngestSummary, ModelEntry, Store, StoreCounts, DEFAULT_STORE};
use crate::linear::Standard;
use crate::Setting;
use errmap_core::error::{Error, Result};
use errmap_core::setting::words;
use errmap_report::result::{write_result, ResultSpec};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// `thermal calibrate`: fit every sensor against the reference over `[from_s, to_s]` (the
/// whole log when `None`) and write the calibrated table to `output`, or over `sensors` in
/// place (atomically: the one documented output that replaces an input). Returns the fits and
/// the table written.
pub fn calibrate_table(
    sensors: &Path,
    log: &Path,
    from_s: Option<f64>,
    to_s: Option<f64>,
    min_span_c: f64,
    output: Option<PathBuf>,
) -> Result<(Vec<CalibrationFit>, PathBuf), crate::error::ThermalError> {
    let mut table = SensorTable::read(sensors)?;
    let log = TemperatureLog::read(log, &table)?;
    let from = from_s.unwrap_or(f64::NEG_INFINITY);
    let to = to_s.unwrap_or(f64::INFINITY);
    let fits = calibrate(&log, &table, from, to, min_span_c)?;
    table.apply_calibrations(&fits);
    // With an output, the output must not be an input.
    let out = match output {
        Some(out) => out,
        None => {
            errmap_core::io::safety::allow_replacing(sensors);
            sensors.to_path_buf()
        }
    };
    table.write(&out)?;
    Ok((fits, out))
}

/// A campaign with its cold/warm difference, before its files are written.
pub struct DifferenceRun {
    /// The campaign argument as given (a folder or its campaign.toml).
    pub campaign_arg: PathBuf,
    /// The campaign read.
    pub campaign: Campaign,
    /// Its cold/warm difference Et = E − Es per time, target and direction, with each time's error
    /// line.
    pub difference: Difference,
}

/// `thermal difference`, first half: read the campaign and compute the difference.
pub fn difference_run(campaign_arg: &Path) -> Result<DifferenceRun, crate::error::ThermalError> {
    let campaign = Campaign::read(campaign_arg)?;
    let d = difference(&campaign)?;
    Ok(DifferenceRun {
        campaign_arg: campaign_arg.to_path_buf(),
        campaign,
        difference: d,
    })
}

impl DifferenceRun {
    /// The default output folder: `difference` inside the campaign folder.
    pub fn default_out_dir(&self) -> PathBuf {
        self.campaign.dir.join("difference")
    }

    /// Second half: difference.csv, lines.csv, fan.png and difference.json in `out`.
    pub fn write_files(&self, out: &Path) -> Result<(), crate::error::ThermalError> {
        let d = &self.difference;
        outputs::write_difference_csv(&out.join("difference.csv"), d)?;
        outputs::write_lines_csv(&out.join("lines.csv"), d, &self.campaign.log.sensors)?;
        fan_chart(&out.join("fan.png"), d)?;
        write_result(
            &out.join("difference.json"),
            &ResultSpec {
                kind: "thermal-difference",
                title: format!("Thermal difference, campaign {}", d.campaign),
                inputs: &[campaign_file_path(&self.campaign_arg).as_path()],
                charts: &[&out.join("fan.png")],
                table: None,
            },
            d,
        )
        .map_err(Into::into)
    }
}

/// What `thermal ingest` added, and to which store.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct IngestReport {
    /// What each campaign added, in argument order.
    pub ingested: Vec<IngestSummary>,
    /// The store written.
    pub store: PathBuf,
}

impl IngestReport {
    /// The `--json` document: keys in alphabetical order at every level.
    pub fn json(&self) -> Result<serde_json::Value> {
        sorted_json(self)
    }
}

/// A document as a JSON value, whose objects keep their keys in alphabetical order.
fn sorted_json(value: &impl Serialize) -> Result<serde_json::Value> {
    serde_json::to_value(value).map_err(|e| Error::Internal(format!("JSON output: {e}")))
}

/// The store an ingest writes: `db`, else thermal.sqlite beside the first campaign.
pub fn ingest_store(db: Option<PathBuf>, campaigns: &[PathBuf]) -> PathBuf {
    db.unwrap_or_else(|| {
        campaigns
            .first()
            .map(|c| store_beside(c))
            .unwrap_or_else(|| PathBuf::from(DEFAULT_STORE))
    })
}

/// `thermal ingest`: add each campaign folder to the store at `db`, one transaction each;
/// `ingest` adds one campaign to the open store (the caller may inject faults there), and
/// `each` sees every summary as it is made.
pub fn ingest_folders(
    db: &Path,
    campaigns: &[PathBuf],
    ingest: &mut dyn FnMut(&mut Store, &Campaign) -> Result<IngestSummary>,
    each: &mut dyn FnMut(&IngestSummary) -> Result<()>,
) -> Result<IngestReport, crate::error::ThermalError> {
    let mut store = Store::open(db)?;
    let mut summaries = Vec::new();
    for path in campaigns {
        let campaign = Campaign::read(path)?;
        let s = ingest(&mut store, &campaign)?;
        each(&s)?;
        summaries.push(s);
    }
    Ok(IngestReport {
        ingested: summaries,
        store: db.to_path_buf(),
    })
}

/// What `thermal fit` is asked to do.
#[derive(Debug, Clone, Default)]
pub struct FitRequest {
    /// Campaign folders; with `from_store` they only locate the default store.
    pub campaigns: Vec<PathBuf>,
    /// The model file (model.json) to write.
    pub output: PathBuf,
    /// Read the campaigns from the store instead of their folders.
    pub from_store: bool,
    /// With `from_store`: only these stored campaigns (all when empty).
    pub campaign_names: Vec<String>,
    /// The store to read from and save the model in; `None`: thermal.sqlite beside the first
    /// campaign with `from_store`, else no store.
    pub db: Option<PathBuf>,
    /// Model name in the store (default: the axis).
    pub name: Option<String>,
    /// The `--reference` text: room, shared, own-start, campaign-offset or cv.
    pub reference: String,
    /// The fit's settings; its `reference` is replaced by the parsed `reference` text.
    pub options: FitOptions,
}

/// A fitted model and where it was saved in a store (store, name, version).
pub struct FitOutcome {
    /// The fitted model, as written to the model file.
    pub model: ThermalModel,
    /// (store, model name, version) of the copy saved in a store; `None` when no store was in play.
    pub saved: Option<(PathBuf, String, i64)>,
}

/// `thermal fit`: read the campaigns (from folders or the store), fit, write the model file
/// and, when a store is in play, save the model there as a new version.
pub fn fit_model(request: &FitRequest) -> Result<FitOutcome, crate::error::ThermalError> {
    let db = request.db.clone().or_else(|| {
        request
            .from_store
            .then(|| ingest_store(None, &request.campaigns))
    });
    let campaigns = fit_campaigns(request, db.as_deref())?;
    let options = FitOptions {
        reference: parse_reference(&request.reference)?,
        ..request.options.clone()
    };
    let model = fit(&campaigns, &options)?;
    errmap_core::io::write_json(&request.output, &model)?;
    let mut saved = None;
    if let Some(db) = &db {
        let mut store = Store::open(db)?;
        let name = request.name.clone().unwrap_or_else(|| model.axis.clone());
        let version = store.save_model(&name, &model)?;
        saved = Some((db.clone(), name, version));
    }
    Ok(FitOutcome { model, saved })
}

/// The campaigns a fit uses: from the store at `db` (all, or those named) or from folders.
fn fit_campaigns(request: &FitRequest, db: Option<&Path>) -> Result<Vec<Campaign>> {
    let campaigns: Vec<Campaign> = if request.from_store {
        let store = Store::open(db.unwrap_or(Path::new(DEFAULT_STORE)))?;
        if request.campaign_names.is_empty() {
            store.load_all()?
        } else {
            request
                .campaign_names
                .iter()
                .map(|n| store.load_campaign(n))
                .collect::<Result<_>>()?
        }
    } else {
        if request.campaigns.is_empty() {
            return Err(Error::usage(
                "no campaigns to fit",
                format!(
                    "name campaign folders, or use {}",
                    words(Setting::FromStore)
                ),
            ));
        }
        request
            .campaigns
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
    Ok(campaigns)
}

/// `cv` (chosen by cross-validation: `None`) or a reference name.
fn parse_reference(text: &str) -> Result<Option<Reference>> {
    match text {
        "cv" => Ok(None),
        other => Reference::parse(other).map(Some).ok_or_else(|| {
            Error::usage(
                format!("{} {other} is not a reference", words(Setting::Reference)),
                "give shared, own-start, campaign-offset, room or cv",
            )
        }),
    }
}

/// What a store holds: campaign names, table counts and model versions.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ModelsReport {
    /// Names of the stored campaigns, in name order.
    pub campaigns: Vec<String>,
    /// Rows in each table of the store.
    pub counts: StoreCounts,
    /// Every stored model version, by name then version.
    pub models: Vec<ModelEntry>,
    /// The store read.
    pub store: PathBuf,
}

impl ModelsReport {
    /// The `--json` document: keys in alphabetical order at every level.
    pub fn json(&self) -> Result<serde_json::Value> {
        sorted_json(self)
    }
}

/// `thermal models`: what the store at `db` (default: thermal.sqlite here) holds; it must exist.
pub fn list_models(db: Option<PathBuf>) -> Result<ModelsReport, crate::error::ThermalError> {
    let db = db.unwrap_or_else(|| PathBuf::from(DEFAULT_STORE));
    if !db.exists() {
        return Err(Error::usage(
            format!("no store at {}", db.display()),
            format!(
                "give {}, or create one with `errmap thermal ingest`",
                words(Setting::Db)
            ),
        )
        .into());
    }
    let store = Store::open(&db)?;
    let models = store.models()?;
    Ok(ModelsReport {
        campaigns: store.campaign_names()?,
        counts: store.counts()?,
        models,
        store: db,
    })
}

/// `thermal compensate`: stream the machine log at `log` through the model at `model` into
/// `output`. Returns the model (for its travel) and the summary.
pub fn compensate_log(
    model: &Path,
    log: &Path,
    output: &Path,
) -> Result<(ThermalModel, CompensateSummary), crate::error::ThermalError> {
    let m = ThermalModel::read(model)?;
    let s = compensate_file(&m, log, output)?;
    Ok((m, s))
}

/// A model evaluated on campaigns, before its files are written.
pub struct EvaluateRun {
    /// The model file evaluated.
    pub model_path: PathBuf,
    /// The axis figures before and after compensation for each measurement of each campaign.
    pub report: EvaluationReport,
}

/// `thermal evaluate`, first half: read the model and campaigns and evaluate.
pub fn evaluate_run(
    model: &Path,
    campaigns: &[PathBuf],
    standard: Standard,
) -> Result<EvaluateRun, crate::error::ThermalError> {
    let m = ThermalModel::read(model)?;
    let campaigns: Vec<Campaign> = campaigns
        .iter()
        .map(|p| Campaign::read(p))
        .collect::<Result<_>>()?;
    let report = evaluate_campaigns(&m, &campaigns, standard)?;
    Ok(EvaluateRun {
        model_path: model.to_path_buf(),
        report,
    })
}

impl EvaluateRun {
    /// The default output folder: the model's.
    pub fn default_out_dir(&self) -> PathBuf {
        self.model_path
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .map(Path::to_path_buf)
            .unwrap_or_else(|| PathBuf::from("."))
    }

    /// Second half: evaluate.csv, evaluate.png and evaluate.json in `out`.
    pub fn write_files(&self, out: &Path) -> Result<(), crate::error::ThermalError> {
        outputs::write_evaluate_csv(&out.join("evaluate.csv"), &self.report)?;
        evaluate_chart(&out.join("evaluate.png"), &self.report)?;
        write_result(
            &out.join("evaluate.json"),
            &ResultSpec {
                kind: "thermal-evaluate",
                title: format!("Thermal model {} evaluated", self.model_path.display()),
                inputs: &[self.model_path.as_path()],
                charts: &[&out.join("evaluate.png")],
                table: None,
            },
            &self.report,
        )
        .map_err(Into::into)
    }
}
