//! The temperature-history store of seed 004, in SQLite (WAL mode): sensors and their
//! calibrations, campaigns with coolant state and ambient, temperature samples, laser readings,
//! and fitted models with versions.
//!
//! A campaign is added in one transaction: a failure part-way (or a killed process) leaves the
//! store exactly as it was. WAL journaling lets readers (`models`, `fit --from-store`) work while
//! an ingest writes.

use super::campaign::{Campaign, CampaignFile, LaserPoint};
use super::filter::FilterSpec;
use super::model::ThermalModel;
use super::sensors::{Calibration, Role, Sensor, SensorTable, TemperatureLog, Unit};
use crate::linear::Direction;
use crate::Setting;
use errmap_core::error::{Error, Location, Result};
use errmap_core::setting::words;
use rusqlite::{params, Connection, OptionalExtension, Transaction};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// File name of the default store, placed beside the campaigns.
pub const DEFAULT_STORE: &str = "thermal.sqlite";

/// thermal.sqlite in the parent folder of a campaign folder (beside the campaign), however
/// the folder is spelled (`x`, `./x`, `/abs/x`, `.`): the folder is made absolute first.
pub fn store_beside(campaign: &Path) -> PathBuf {
    let file = super::campaign::campaign_file_path(campaign);
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

const SCHEMA: &str = "
CREATE TABLE IF NOT EXISTS sensors (
    id INTEGER PRIMARY KEY,
    name TEXT NOT NULL UNIQUE,
    role TEXT NOT NULL,
    unit TEXT NOT NULL,
    median_window INTEGER NOT NULL,
    sg_window INTEGER NOT NULL,
    sg_order INTEGER NOT NULL
);
CREATE TABLE IF NOT EXISTS calibrations (
    id INTEGER PRIMARY KEY,
    sensor_id INTEGER NOT NULL REFERENCES sensors(id),
    offset_c REAL NOT NULL,
    scale REAL NOT NULL,
    created_unix INTEGER NOT NULL
);
CREATE TABLE IF NOT EXISTS campaigns (
    id INTEGER PRIMARY KEY,
    name TEXT NOT NULL UNIQUE,
    axis TEXT NOT NULL,
    coolant TEXT NOT NULL,
    ambient_c REAL,
    reference_point_mm REAL NOT NULL,
    measurement_s REAL NOT NULL,
    source TEXT NOT NULL,
    ingested_unix INTEGER NOT NULL
);
CREATE TABLE IF NOT EXISTS campaign_sensors (
    campaign_id INTEGER NOT NULL REFERENCES campaigns(id),
    sensor_id INTEGER NOT NULL REFERENCES sensors(id),
    calibration_id INTEGER NOT NULL REFERENCES calibrations(id),
    column_index INTEGER NOT NULL,
    PRIMARY KEY (campaign_id, sensor_id)
);
CREATE TABLE IF NOT EXISTS temperature_samples (
    campaign_id INTEGER NOT NULL REFERENCES campaigns(id),
    sensor_id INTEGER NOT NULL REFERENCES sensors(id),
    time_s REAL NOT NULL,
    temperature_c REAL NOT NULL,
    PRIMARY KEY (campaign_id, sensor_id, time_s)
) WITHOUT ROWID;
CREATE TABLE IF NOT EXISTS laser_readings (
    campaign_id INTEGER NOT NULL REFERENCES campaigns(id),
    time_s REAL NOT NULL,
    run INTEGER NOT NULL,
    direction TEXT NOT NULL,
    target_mm REAL NOT NULL,
    deviation_um REAL NOT NULL,
    line INTEGER NOT NULL
);
CREATE INDEX IF NOT EXISTS laser_readings_campaign ON laser_readings(campaign_id);
CREATE TABLE IF NOT EXISTS models (
    id INTEGER PRIMARY KEY,
    name TEXT NOT NULL,
    version INTEGER NOT NULL,
    created_unix INTEGER NOT NULL,
    campaigns TEXT NOT NULL,
    loco_rms_um REAL,
    model_json TEXT NOT NULL,
    UNIQUE (name, version)
);
";

/// An open store.
pub struct Store {
    /// The SQLite file.
    pub path: PathBuf,
    conn: Connection,
}

/// Fault injection inside an ingest's open transaction, for the tests of its atomicity. Debug
/// builds only: a release build has no way to inject a fault.
#[cfg(any(test, debug_assertions))]
#[doc(hidden)]
pub struct IngestFaults<'a> {
    /// Fail with an internal error after this many temperature samples.
    pub fail_after_samples: Option<u64>,
    /// After this many samples call `pause` with the count, inside the open transaction (the
    /// caller may block there, e.g. to be killed by a test).
    pub pause_after_samples: Option<u64>,
    pub pause: &'a mut dyn FnMut(u64),
}

/// What an ingest added.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct IngestSummary {
    /// Name of the campaign added.
    pub campaign: String,
    /// Its row id in the `campaigns` table.
    pub campaign_id: i64,
    /// Sensors stored with the campaign.
    pub sensors: usize,
    /// Temperature samples stored (calibrated °C, before filtering).
    pub temperature_samples: u64,
    /// Laser readings stored.
    pub laser_readings: u64,
    /// Whether a stored campaign of the same name was replaced (`--replace`).
    pub replaced: bool,
}

/// One stored model version.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ModelEntry {
    /// Model name (default: the axis).
    pub name: String,
    /// Version number, counting from 1 per name.
    pub version: i64,
    /// When the version was saved, seconds since the Unix epoch (wall clock).
    pub created_unix: i64,
    /// Names of the campaigns it was fitted to.
    pub campaigns: Vec<String>,
    /// Pooled leave-one-campaign-out RMS, µm; `None` when no campaign had one.
    pub loco_rms_um: Option<f64>,
}

/// Counts of every table, for checks and `models --json`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct StoreCounts {
    /// Rows of `sensors`.
    pub sensors: i64,
    /// Rows of `calibrations`.
    pub calibrations: i64,
    /// Rows of `campaigns`.
    pub campaigns: i64,
    /// Rows of `temperature_samples`.
    pub temperature_samples: i64,
    /// Rows of `laser_readings`.
    pub laser_readings: i64,
    /// Rows of `models` (every version of every model).
    pub models: i64,
}

fn now_unix() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs() as i64)
        .unwrap_or(0)
}

impl Store {
    /// Open (creating if needed) a store, in WAL mode, with the schema in place.
    pub fn open(path: &Path) -> Result<Store> {
        if let Some(dir) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|e| Error::io("create folder", dir, e))?;
        }
        let conn = Connection::open(path).map_err(|e| read_err(path, e))?;
        // The store is an input of the command: no output file may replace it.
        errmap_core::io::safety::protect(path);
        let mode: String = conn
            .query_row("PRAGMA journal_mode=WAL", [], |r| r.get(0))
            .map_err(|e| read_err(path, e))?;
        if !mode.eq_ignore_ascii_case("wal") {
            return Err(Error::input(
                Location::file(path),
                format!("the store could not switch to WAL mode (journal mode {mode})"),
                "put the store on a local file system",
            ));
        }
        conn.execute_batch("PRAGMA foreign_keys=ON; PRAGMA busy_timeout=5000;")
            .map_err(|e| read_err(path, e))?;
        // Create the schema only when missing: a reader must not need the write lock, so that
        // it never waits for an ingest in progress (WAL readers see the last commit).
        let have: i64 = conn
            .query_row(
                "SELECT COUNT(*) FROM sqlite_master WHERE type = 'table' AND name = 'models'",
                [],
                |r| r.get(0),
            )
            .map_err(|e| read_err(path, e))?;
        if have == 0 {
            conn.execute_batch(SCHEMA).map_err(|e| write_err(path, e))?;
        }
        Ok(Store {
            path: path.to_path_buf(),
            conn,
        })
    }

    /// Add a campaign in one transaction. A campaign of the same name is an error unless
    /// `replace`, which swaps it inside the same transaction.
    pub fn ingest(&mut self, campaign: &Campaign, replace: bool) -> Result<IngestSummary> {
        self.ingest_observed(campaign, replace, &mut |_| Ok(()))
    }

    /// [`Store::ingest`] with faults injected inside the transaction (debug builds only).
    #[cfg(any(test, debug_assertions))]
    #[doc(hidden)]
    pub fn ingest_with_faults(
        &mut self,
        campaign: &Campaign,
        replace: bool,
        faults: IngestFaults,
    ) -> Result<IngestSummary> {
        let mut after_sample = |samples: u64| {
            if faults.fail_after_samples == Some(samples) {
                return Err(Error::Internal(format!(
                    "ingest stopped after {samples} samples (injected failure)"
                )));
            }
            if faults.pause_after_samples == Some(samples) {
                (faults.pause)(samples);
            }
            Ok(())
        };
        self.ingest_observed(campaign, replace, &mut after_sample)
    }

    /// The ingest transaction; `after_sample` sees the count of samples written so far.
    fn ingest_observed(
        &mut self,
        campaign: &Campaign,
        replace: bool,
        after_sample: &mut dyn FnMut(u64) -> Result<()>,
    ) -> Result<IngestSummary> {
        let path = self.path.clone();
        let tx = self.conn.transaction().map_err(|e| write_err(&path, e))?;
        let summary = ingest_in(&tx, &path, campaign, replace, after_sample)?;
        tx.commit().map_err(|e| write_err(&path, e))?;
        Ok(summary)
    }

    /// Names of stored laser campaigns, in name order. The temperature logs `errmap live`
    /// adds (source `errmap live`, no laser readings) are not campaigns to fit from.
    pub fn campaign_names(&self) -> Result<Vec<String>> {
        let mut stmt = self
            .conn
            .prepare("SELECT name FROM campaigns WHERE source != 'errmap live' ORDER BY name")
            .map_err(|e| read_err(&self.path, e))?;
        let names = stmt
            .query_map([], |r| r.get::<_, String>(0))
            .and_then(|rows| rows.collect::<rusqlite::Result<Vec<_>>>())
            .map_err(|e| read_err(&self.path, e))?;
        Ok(names)
    }

    /// Rebuild a stored campaign (temperatures re-filtered with the stored filter settings).
    pub fn load_campaign(&self, name: &str) -> Result<Campaign> {
        let p = &self.path;
        let row = campaign_row(&self.conn, p, name)?;
        let (table, sensor_ids) = campaign_sensors(&self.conn, p, row.id)?;
        let raw_log = stored_log(&self.conn, p, name, row.id, &sensor_ids, &table)?;
        // Stored samples are already calibrated: filter them with identity calibrations.
        let mut identity = table.clone();
        for s in &mut identity.sensors {
            s.calibration = Calibration::default();
        }
        let log = raw_log.process(&identity)?;
        let timed = stored_readings(&self.conn, p, name, row.id)?;
        let settings = CampaignFile {
            name: Some(name.to_string()),
            axis: row.axis,
            coolant: row.coolant,
            runs: PathBuf::from(&row.source),
            temperatures: PathBuf::from(&row.source),
            sensors: PathBuf::from(&row.source),
            measurement_s: row.measurement_s,
            reference_point_mm: row.reference_point_mm,
        };
        let dir = p
            .parent()
            .map(Path::to_path_buf)
            .unwrap_or_else(|| PathBuf::from("."));
        let mut campaign = Campaign::assemble(
            name.to_string(),
            dir,
            &settings,
            table,
            raw_log,
            log,
            timed,
            Path::new(&row.source),
        )?;
        campaign.runs_path = PathBuf::from(row.source);
        Ok(campaign)
    }

    /// Every stored campaign, in name order.
    pub fn load_all(&self) -> Result<Vec<Campaign>> {
        self.campaign_names()?
            .iter()
            .map(|n| self.load_campaign(n))
            .collect()
    }

    /// Save a model as the next version of `name`; older versions are kept. Returns the version.
    pub fn save_model(&mut self, name: &str, model: &ThermalModel) -> Result<i64> {
        let p = self.path.clone();
        let json = serde_json::to_string(model)
            .map_err(|e| Error::Internal(format!("model JSON: {e}")))?;
        let campaigns: Vec<&str> = model.campaigns.iter().map(|c| c.name.as_str()).collect();
        let tx = self.conn.transaction().map_err(|e| write_err(&p, e))?;
        let version: i64 = tx
            .query_row(
                "SELECT COALESCE(MAX(version), 0) + 1 FROM models WHERE name = ?1",
                params![name],
                |r| r.get(0),
            )
            .map_err(|e| write_err(&p, e))?;
        tx.execute(
            "INSERT INTO models (name, version, created_unix, campaigns, loco_rms_um, model_json)
             VALUES (?1, ?2, ?3, ?4, ?5, ?6)",
            params![
                name,
                version,
                now_unix(),
                campaigns.join(","),
                model.loco_rms_um,
                json
            ],
        )
        .map_err(|e| write_err(&p, e))?;
        tx.commit().map_err(|e| write_err(&p, e))?;
        Ok(version)
    }

    /// Every stored model version, by name then version.
    pub fn models(&self) -> Result<Vec<ModelEntry>> {
        let mut stmt = self
            .conn
            .prepare(
                "SELECT name, version, created_unix, campaigns, loco_rms_um FROM models
                 ORDER BY name, version",
            )
            .map_err(|e| read_err(&self.path, e))?;
        let rows = stmt
            .query_map([], |r| {
                Ok(ModelEntry {
                    name: r.get(0)?,
                    version: r.get(1)?,
                    created_unix: r.get(2)?,
                    campaigns: r
                        .get::<_, String>(3)?
                        .split(',')
                        .filter(|s| !s.is_empty())
                        .map(str::to_string)
                        .collect(),
                    loco_rms_um: r.get(4)?,
                })
            })
            .and_then(|rows| rows.collect::<rusqlite::Result<Vec<_>>>())
            .map_err(|e| read_err(&self.path, e))?;
        Ok(rows)
    }

    /// A stored model; the latest version when `version` is `None`.
    pub fn model(&self, name: &str, version: Option<i64>) -> Result<ThermalModel> {
        let json: Option<String> = self
            .conn
            .query_row(
                "SELECT model_json FROM models WHERE name = ?1 AND (?2 IS NULL OR version = ?2)
                 ORDER BY version DESC LIMIT 1",
                params![name, version],
                |r| r.get(0),
            )
            .optional()
            .map_err(|e| read_err(&self.path, e))?;
        let json = json.ok_or_else(|| {
            Error::usage(
                format!(
                    "no model '{name}' (version {version:?}) in {}",
                    self.path.display()
                ),
                "list the stored models with `errmap thermal models`",
            )
        })?;
        let model: ThermalModel = serde_json::from_str(&json).map_err(|e| {
            Error::input(
                Location::file(&self.path),
                format!("stored model '{name}' is unreadable: {e}"),
                refit_from_store(),
            )
        })?;
        model.validate().map_err(|m| {
            Error::input(
                Location::file(&self.path),
                format!("stored model '{name}': {m}"),
                refit_from_store(),
            )
        })?;
        Ok(model)
    }

    /// Row counts of every table.
    pub fn counts(&self) -> Result<StoreCounts> {
        let count = |table: &str| -> Result<i64> {
            self.conn
                .query_row(&format!("SELECT COUNT(*) FROM {table}"), [], |r| r.get(0))
                .map_err(|e| read_err(&self.path, e))
        };
        Ok(StoreCounts {
            sensors: count("sensors")?,
            calibrations: count("calibrations")?,
            campaigns: count("campaigns")?,
            temperature_samples: count("temperature_samples")?,
            laser_readings: count("laser_readings")?,
            models: count("models")?,
        })
    }
}

/// The stages of an ingest, inside its transaction.
fn ingest_in(
    tx: &Transaction,
    p: &Path,
    campaign: &Campaign,
    replace: bool,
    after_sample: &mut dyn FnMut(u64) -> Result<()>,
) -> Result<IngestSummary> {
    let replaced = remove_existing(tx, p, &campaign.name, replace)?;
    let campaign_id = insert_campaign(tx, p, campaign)?;
    let sensor_ids = insert_campaign_sensors(tx, p, campaign, campaign_id)?;
    let samples = insert_samples(tx, p, campaign, campaign_id, &sensor_ids, after_sample)?;
    let readings = insert_readings(tx, p, campaign, campaign_id)?;
    Ok(IngestSummary {
        campaign: campaign.name.clone(),
        campaign_id,
        sensors: sensor_ids.len(),
        temperature_samples: samples,
        laser_readings: readings,
        replaced,
    })
}

/// Refuse a campaign name already stored, or with `replace` delete its rows. True if replaced.
fn remove_existing(tx: &Connection, p: &Path, name: &str, replace: bool) -> Result<bool> {
    let w = |e| write_err(p, e);
    let existing: Option<i64> = tx
        .query_row(
            "SELECT id FROM campaigns WHERE name = ?1",
            params![name],
            |r| r.get(0),
        )
        .optional()
        .map_err(w)?;
    let Some(id) = existing else {
        return Ok(false);
    };
    if !replace {
        return Err(Error::usage(
            format!("campaign '{name}' is already in {}", p.display()),
            format!(
                "give the campaign another name in campaign.toml, or pass {}",
                words(Setting::Replace)
            ),
        ));
    }
    for table in ["temperature_samples", "laser_readings", "campaign_sensors"] {
        tx.execute(
            &format!("DELETE FROM {table} WHERE campaign_id = ?1"),
            params![id],
        )
        .map_err(w)?;
    }
    tx.execute("DELETE FROM campaigns WHERE id = ?1", params![id])
        .map_err(w)?;
    Ok(true)
}

/// The campaign's row (with the ambient temperature of its cold measurement); returns its id.
fn insert_campaign(tx: &Connection, p: &Path, campaign: &Campaign) -> Result<i64> {
    let ambient_c = campaign.sensors.with_role(Role::Ambient).and_then(|a| {
        campaign
            .measurements
            .first()?
            .temperatures_c
            .get(&a.name)
            .copied()
    });
    tx.execute(
        "INSERT INTO campaigns (name, axis, coolant, ambient_c, reference_point_mm, measurement_s,
                                source, ingested_unix)
         VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8)",
        params![
            campaign.name,
            campaign.axis,
            campaign.coolant,
            ambient_c,
            campaign.reference_point_mm,
            campaign.measurement_s,
            campaign.runs_path.display().to_string(),
            now_unix()
        ],
    )
    .map_err(|e| write_err(p, e))?;
    Ok(tx.last_insert_rowid())
}

/// Link every logged sensor (in log column order) to the campaign with its calibration.
/// Returns each column's sensor id and calibration.
fn insert_campaign_sensors(
    tx: &Connection,
    p: &Path,
    campaign: &Campaign,
    campaign_id: i64,
) -> Result<Vec<(i64, Calibration)>> {
    let mut sensor_ids = Vec::new();
    for (column, name) in campaign.raw_log.sensors.iter().enumerate() {
        let s = campaign.sensors.get(name).ok_or_else(|| {
            Error::Internal(format!("log sensor '{name}' missing from the sensor table"))
        })?;
        let sid = upsert_sensor(tx, p, &campaign.sensors.path, s)?;
        let cal_id = calibration_id(tx, p, sid, s.calibration)?;
        tx.execute(
            "INSERT INTO campaign_sensors (campaign_id, sensor_id, calibration_id, column_index)
             VALUES (?1, ?2, ?3, ?4)",
            params![campaign_id, sid, cal_id, column as i64],
        )
        .map_err(|e| write_err(p, e))?;
        sensor_ids.push((sid, s.calibration));
    }
    Ok(sensor_ids)
}

/// The id of a sensor, added if new. The same name must keep its role and unit; its filter
/// settings are updated. `table` (the sensor table) names the input in messages.
fn upsert_sensor(tx: &Connection, p: &Path, table: &Path, s: &Sensor) -> Result<i64> {
    let w = |e| write_err(p, e);
    let found: Option<(i64, String, String)> = tx
        .query_row(
            "SELECT id, role, unit FROM sensors WHERE name = ?1",
            params![s.name],
            |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?)),
        )
        .optional()
        .map_err(w)?;
    let filter = [
        s.filter.median_window as i64,
        s.filter.sg_window as i64,
        s.filter.sg_order as i64,
    ];
    let Some((id, role, unit)) = found else {
        tx.execute(
            "INSERT INTO sensors (name, role, unit, median_window, sg_window, sg_order)
             VALUES (?1, ?2, ?3, ?4, ?5, ?6)",
            params![
                s.name,
                s.role.name(),
                s.unit.name(),
                filter[0],
                filter[1],
                filter[2]
            ],
        )
        .map_err(w)?;
        return Ok(tx.last_insert_rowid());
    };
    if role != s.role.name() || unit != s.unit.name() {
        return Err(Error::input(
            Location::file(table),
            format!(
                "sensor '{}' is stored as {role}/{unit}, this table says {}/{}",
                s.name,
                s.role.name(),
                s.unit.name()
            ),
            "keep a sensor's role and unit, or give a new sensor a new name",
        ));
    }
    tx.execute(
        "UPDATE sensors SET median_window = ?2, sg_window = ?3, sg_order = ?4
         WHERE id = ?1",
        params![id, filter[0], filter[1], filter[2]],
    )
    .map_err(w)?;
    Ok(id)
}

/// The id of the sensor's latest calibration if it equals `cal`, else of a new row for `cal`.
fn calibration_id(tx: &Connection, p: &Path, sensor_id: i64, cal: Calibration) -> Result<i64> {
    let w = |e| write_err(p, e);
    let latest: Option<(i64, f64, f64)> = tx
        .query_row(
            "SELECT id, offset_c, scale FROM calibrations WHERE sensor_id = ?1
             ORDER BY id DESC LIMIT 1",
            params![sensor_id],
            |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?)),
        )
        .optional()
        .map_err(w)?;
    match latest {
        Some((id, o, k)) if o == cal.offset_c && k == cal.scale => Ok(id),
        _ => {
            tx.execute(
                "INSERT INTO calibrations (sensor_id, offset_c, scale, created_unix)
                 VALUES (?1, ?2, ?3, ?4)",
                params![sensor_id, cal.offset_c, cal.scale, now_unix()],
            )
            .map_err(w)?;
            Ok(tx.last_insert_rowid())
        }
    }
}

/// Every logged sample, calibrated; `after_sample` sees the running count. Returns the count.
fn insert_samples(
    tx: &Connection,
    p: &Path,
    campaign: &Campaign,
    campaign_id: i64,
    sensor_ids: &[(i64, Calibration)],
    after_sample: &mut dyn FnMut(u64) -> Result<()>,
) -> Result<u64> {
    let w = |e| write_err(p, e);
    let mut insert = tx
        .prepare_cached(
            "INSERT INTO temperature_samples (campaign_id, sensor_id, time_s, temperature_c)
             VALUES (?1, ?2, ?3, ?4)",
        )
        .map_err(w)?;
    let mut samples = 0u64;
    for (k, (sid, cal)) in sensor_ids.iter().enumerate() {
        let log = &campaign.raw_log;
        for (t, raw) in log.time_s.iter().zip(&log.raw_c[k]) {
            insert
                .execute(params![campaign_id, sid, t, cal.apply(*raw)])
                .map_err(w)?;
            samples += 1;
            after_sample(samples)?;
        }
    }
    Ok(samples)
}

/// Every laser reading with its measurement time. Returns the count.
fn insert_readings(
    tx: &Connection,
    p: &Path,
    campaign: &Campaign,
    campaign_id: i64,
) -> Result<u64> {
    let w = |e| write_err(p, e);
    let mut insert = tx
        .prepare_cached(
            "INSERT INTO laser_readings (campaign_id, time_s, run, direction, target_mm,
                                         deviation_um, line)
             VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7)",
        )
        .map_err(w)?;
    let mut readings = 0u64;
    for m in &campaign.measurements {
        for pt in &m.points {
            insert
                .execute(params![
                    campaign_id,
                    m.time_s,
                    pt.run as i64,
                    pt.direction.symbol(),
                    pt.target_mm,
                    pt.deviation_um,
                    pt.line as i64
                ])
                .map_err(w)?;
            readings += 1;
        }
    }
    Ok(readings)
}

/// A stored campaign's own row.
struct CampaignRow {
    id: i64,
    axis: String,
    coolant: String,
    reference_point_mm: f64,
    measurement_s: f64,
    /// The run file it was ingested from.
    source: String,
}

/// The row of campaign `name`; a usage error when there is none.
fn campaign_row(conn: &Connection, p: &Path, name: &str) -> Result<CampaignRow> {
    conn.query_row(
        "SELECT id, axis, coolant, reference_point_mm, measurement_s, source
         FROM campaigns WHERE name = ?1",
        params![name],
        |r| {
            Ok(CampaignRow {
                id: r.get(0)?,
                axis: r.get(1)?,
                coolant: r.get(2)?,
                reference_point_mm: r.get(3)?,
                measurement_s: r.get(4)?,
                source: r.get(5)?,
            })
        },
    )
    .optional()
    .map_err(|e| read_err(p, e))?
    .ok_or_else(|| {
        Error::usage(
            format!("no campaign '{name}' in {}", p.display()),
            "list the stored campaigns with `errmap thermal models`",
        )
    })
}

/// The campaign's sensors in log column order, with the calibration it was ingested with,
/// and their ids.
fn campaign_sensors(conn: &Connection, p: &Path, id: i64) -> Result<(SensorTable, Vec<i64>)> {
    let mut stmt = conn
        .prepare(
            "SELECT s.id, s.name, s.role, s.unit, s.median_window, s.sg_window, s.sg_order,
                    c.offset_c, c.scale
             FROM campaign_sensors cs JOIN sensors s ON s.id = cs.sensor_id
             JOIN calibrations c ON c.id = cs.calibration_id
             WHERE cs.campaign_id = ?1 ORDER BY cs.column_index",
        )
        .map_err(|e| read_err(p, e))?;
    let rows = stmt
        .query_map(params![id], |r| {
            Ok((
                r.get::<_, i64>(0)?,
                r.get::<_, String>(1)?,
                r.get::<_, String>(2)?,
                r.get::<_, String>(3)?,
                [
                    r.get::<_, i64>(4)?,
                    r.get::<_, i64>(5)?,
                    r.get::<_, i64>(6)?,
                ],
                Calibration {
                    offset_c: r.get(7)?,
                    scale: r.get(8)?,
                },
            ))
        })
        .and_then(|rows| rows.collect::<rusqlite::Result<Vec<_>>>())
        .map_err(|e| read_err(p, e))?;
    let mut sensors = Vec::new();
    let mut ids = Vec::new();
    for (sid, sname, role, unit, [mw, sw, so], calibration) in rows {
        let bad = || {
            Error::input(
                Location::file(p),
                format!("sensor '{sname}' has an unknown role or unit in the store"),
                "the store was written by another program; ingest the campaign again",
            )
        };
        sensors.push(Sensor {
            name: sname.clone(),
            role: Role::parse(&role).ok_or_else(bad)?,
            unit: Unit::parse(&unit).ok_or_else(bad)?,
            calibration,
            filter: FilterSpec {
                median_window: mw.max(1) as usize,
                sg_window: sw.max(1) as usize,
                sg_order: so.max(0) as usize,
            },
        });
        ids.push(sid);
    }
    let table = SensorTable {
        path: p.to_path_buf(),
        sensors,
    };
    Ok((table, ids))
}

/// The stored (calibrated) samples of campaign `id` as a log, one channel per sensor id;
/// every sensor must have the same sample times.
fn stored_log(
    conn: &Connection,
    p: &Path,
    name: &str,
    id: i64,
    sensor_ids: &[i64],
    table: &SensorTable,
) -> Result<TemperatureLog> {
    let mut time_s: Vec<f64> = Vec::new();
    let mut channels: Vec<Vec<f64>> = Vec::new();
    for (k, sid) in sensor_ids.iter().enumerate() {
        let mut stmt = conn
            .prepare_cached(
                "SELECT time_s, temperature_c FROM temperature_samples
                 WHERE campaign_id = ?1 AND sensor_id = ?2 ORDER BY time_s",
            )
            .map_err(|e| read_err(p, e))?;
        let samples = stmt
            .query_map(params![id, sid], |r| {
                Ok((r.get::<_, f64>(0)?, r.get::<_, f64>(1)?))
            })
            .and_then(|rows| rows.collect::<rusqlite::Result<Vec<_>>>())
            .map_err(|e| read_err(p, e))?;
        if k == 0 {
            time_s = samples.iter().map(|s| s.0).collect();
        } else if samples.len() != time_s.len()
            || samples.iter().zip(&time_s).any(|(s, t)| s.0 != *t)
        {
            return Err(Error::input(
                Location::file(p),
                format!("campaign '{name}': sensors have different sample times in the store"),
                ingest_again(),
            ));
        }
        channels.push(samples.into_iter().map(|s| s.1).collect());
    }
    Ok(TemperatureLog {
        path: p.to_path_buf(),
        time_s,
        sensors: table.sensors.iter().map(|s| s.name.clone()).collect(),
        raw_c: channels,
    })
}

/// The stored laser readings of campaign `id` with their measurement times, in ingest order.
fn stored_readings(
    conn: &Connection,
    p: &Path,
    name: &str,
    id: i64,
) -> Result<Vec<(f64, LaserPoint)>> {
    let mut stmt = conn
        .prepare(
            "SELECT time_s, run, direction, target_mm, deviation_um, line
             FROM laser_readings WHERE campaign_id = ?1 ORDER BY rowid",
        )
        .map_err(|e| read_err(p, e))?;
    let readings = stmt
        .query_map(params![id], |r| {
            Ok((
                r.get::<_, f64>(0)?,
                r.get::<_, i64>(1)?,
                r.get::<_, String>(2)?,
                r.get::<_, f64>(3)?,
                r.get::<_, f64>(4)?,
                r.get::<_, i64>(5)?,
            ))
        })
        .and_then(|rows| rows.collect::<rusqlite::Result<Vec<_>>>())
        .map_err(|e| read_err(p, e))?;
    let mut timed = Vec::with_capacity(readings.len());
    for (t, run, dir, x, e, line) in readings {
        let direction = Direction::parse(&dir).ok_or_else(|| {
            Error::input(
                Location::file(p),
                format!("campaign '{name}': direction '{dir}' in the store"),
                ingest_again(),
            )
        })?;
        timed.push((
            t,
            LaserPoint {
                run: run.max(0) as u32,
                direction,
                target_mm: x,
                deviation_um: e,
                line: line.max(0) as u64,
            },
        ));
    }
    Ok(timed)
}

fn read_err(path: &Path, e: rusqlite::Error) -> Error {
    Error::read(path, std::io::Error::other(format!("store: {e}")))
}

fn write_err(path: &Path, e: rusqlite::Error) -> Error {
    Error::write(path, std::io::Error::other(format!("store: {e}")))
}

/// The hint for a stored model that cannot be used: fit it again from the store.
fn refit_from_store() -> String {
    format!(
        "refit it with `errmap thermal fit {}`",
        words(Setting::FromStore)
    )
}

/// The hint for a stored campaign that cannot be read back: ingest it again over itself.
fn ingest_again() -> String {
    format!("ingest the campaign again with {}", words(Setting::Replace))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::thermal::sample::{write_campaigns, SynthThermalOptions};

    fn small() -> SynthThermalOptions {
        SynthThermalOptions {
            campaigns: 2,
            repeats: 1,
            every_s: 1800.0,
            duration_s: 7200.0,
            log_period_s: 30.0,
            ..Default::default()
        }
    }

    /// A store in `dir` holding the first synthetic campaign, whose second sensor has a
    /// non-trivial calibration; returns the store and the campaign as read from its folder.
    fn store_with_one_campaign(dir: &Path) -> (Store, Campaign) {
        let truth = write_campaigns(dir, &small()).unwrap();
        let mut store = Store::open(&dir.join(DEFAULT_STORE)).unwrap();
        let table_path = dir.join("sensors.csv");
        let mut table = SensorTable::read(&table_path).unwrap();
        table.sensors[1].calibration = Calibration {
            offset_c: 0.3,
            scale: 1.01,
        };
        table.write(&table_path).unwrap();
        let original = Campaign::read(&dir.join(&truth.campaigns[0].name)).unwrap();
        let summary = store.ingest(&original, false).unwrap();
        assert_eq!(summary.sensors, 3);
        assert_eq!(
            summary.temperature_samples,
            3 * original.raw_log.time_s.len() as u64
        );
        (store, original)
    }

    #[test]
    fn ingest_load_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let (store, original) = store_with_one_campaign(dir.path());
        let mode: String = Connection::open(&store.path)
            .unwrap()
            .query_row("PRAGMA journal_mode", [], |r| r.get(0))
            .unwrap();
        assert_eq!(mode.to_ascii_lowercase(), "wal");
        let back = store.load_campaign(&original.name).unwrap();
        assert_eq!(back.coolant, original.coolant);
        assert_eq!(back.measurements.len(), original.measurements.len());
        for (a, b) in back.measurements.iter().zip(&original.measurements) {
            assert_eq!(a.time_s, b.time_s);
            assert_eq!(a.points.len(), b.points.len());
            for (pa, pb) in a.points.iter().zip(&b.points) {
                assert_eq!(
                    (pa.run, pa.direction, pa.target_mm, pa.deviation_um),
                    (pb.run, pb.direction, pb.target_mm, pb.deviation_um)
                );
            }
            for (k, v) in &b.temperatures_c {
                assert!((a.temperatures_c[k] - v).abs() < 1e-9, "{k}");
            }
        }
        // The logged sensors come back with their calibrations (the reference is not logged).
        assert_eq!(back.sensors.sensors[..], original.sensors.sensors[..3]);
        assert_eq!(back.sensors.sensors[1].calibration.scale, 1.01);
    }

    #[test]
    fn the_same_name_is_refused_unless_replaced() {
        let dir = tempfile::tempdir().unwrap();
        let (mut store, original) = store_with_one_campaign(dir.path());
        // Refused without --replace, and the store is left as it was.
        let before = store.counts().unwrap();
        let err = store.ingest(&original, false).unwrap_err();
        assert!(matches!(err, Error::Usage { .. }), "{err:?}");
        assert!(err.to_string().contains("is already in"), "{err}");
        assert_eq!(store.counts().unwrap(), before);
        let again = store.ingest(&original, true).unwrap();
        assert!(again.replaced);
        assert_eq!(store.counts().unwrap(), before);
    }

    #[test]
    fn saved_models_get_versions_and_read_back() {
        let dir = tempfile::tempdir().unwrap();
        let (mut store, original) = store_with_one_campaign(dir.path());
        let back = store.load_campaign(&original.name).unwrap();
        let model = crate::thermal::fit(
            &[back],
            &crate::thermal::FitOptions {
                order: Some(3),
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(store.save_model("X", &model).unwrap(), 1);
        assert_eq!(store.save_model("X", &model).unwrap(), 2);
        let list = store.models().unwrap();
        assert_eq!(list.iter().map(|m| m.version).collect::<Vec<_>>(), [1, 2]);
        // serde_json parses floats to within an ulp: compare structure exactly, numbers closely.
        let stored = store.model("X", Some(1)).unwrap();
        assert_eq!(stored.campaigns.len(), model.campaigns.len());
        assert_eq!(stored.gain_sensors, model.gain_sensors);
        for (a, b) in stored.directions.iter().zip(&model.directions) {
            for (x, y) in a.legendre_um.iter().zip(&b.legendre_um) {
                assert!((x - y).abs() <= 1e-12 * y.abs().max(1.0));
            }
            for ((sx, x), (sy, y)) in a.gains[0].k_um_per_m_k.iter().zip(&b.gains[0].k_um_per_m_k) {
                assert_eq!(sx, sy);
                assert!((x - y).abs() <= 1e-12 * y.abs().max(1.0));
            }
        }
    }

    #[test]
    fn injected_failure_mid_ingest_leaves_the_store_unchanged() {
        let dir = tempfile::tempdir().unwrap();
        let truth = write_campaigns(dir.path(), &small()).unwrap();
        let db = dir.path().join(DEFAULT_STORE);
        let mut store = Store::open(&db).unwrap();
        let first = Campaign::read(&dir.path().join(&truth.campaigns[0].name)).unwrap();
        store.ingest(&first, false).unwrap();
        let before = store.counts().unwrap();
        let second = Campaign::read(&dir.path().join(&truth.campaigns[1].name)).unwrap();
        let faults = IngestFaults {
            fail_after_samples: Some(100),
            pause_after_samples: None,
            pause: &mut |_| unreachable!("no pause asked for"),
        };
        let err = store
            .ingest_with_faults(&second, false, faults)
            .unwrap_err();
        assert!(err.to_string().contains("injected"), "{err}");
        assert_eq!(store.counts().unwrap(), before);
        assert_eq!(
            store.campaign_names().unwrap(),
            std::slice::from_ref(&first.name)
        );
        // A fresh connection sees the same.
        drop(store);
        let store = Store::open(&db).unwrap();
        assert_eq!(store.counts().unwrap(), before);
    }
}
