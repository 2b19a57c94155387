//! The live loop's record in the SQLite temperature history store: one `live_cycles` row per
//! cycle, each cycle's sensor temperatures in `temperature_samples` under the run's own campaign
//! (`live-<start time>`), operators' commands read from `live_commands` and marked handled,
//! and old rows deleted past the retention.
//!
//! A writer thread owns the connection, so a busy store (another process holding the write
//! lock up to the 2000 ms busy timeout) delays the record, never the cycle; the channel to it
//! is bounded, so the record stays complete and memory stays flat.

use errmap_core::error::{Error, Location, Result};
use errmap_metrology::thermal::sensors::Sensor;
use rusqlite::{params, Connection, OptionalExtension};
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::sync::{Arc, Mutex};

/// The `live_commands` table (byte-identical in `errmap serve`).
pub const LIVE_COMMANDS_DDL: &str = "CREATE TABLE IF NOT EXISTS live_commands (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    issued_utc TEXT NOT NULL,          -- RFC 3339, UTC, millisecond precision, 'Z'
    user TEXT NOT NULL,
    command TEXT NOT NULL CHECK (command IN ('pause', 'resume', 'ack')),
    alarm_id INTEGER,                  -- the alarm acknowledged (ack only)
    handled_utc TEXT,                  -- set by errmap live when it applied the command
    outcome TEXT                       -- 'applied' or why not (e.g. 'unknown alarm 7')
);";

/// The `live_cycles` table.
pub const LIVE_CYCLES_DDL: &str = "CREATE TABLE IF NOT EXISTS live_cycles (
    cycle INTEGER NOT NULL,
    at_utc TEXT NOT NULL,
    mode TEXT NOT NULL,                -- as the state file's \"mode\"
    inputs_json TEXT NOT NULL,         -- {\"T1\": 21.3, ..., \"coolant_on\": true}
    outputs_json TEXT NOT NULL,        -- {\"X\": {\"computed_um\": .., \"written_um\": .., \"target\": \"..\"}, ...}
    note TEXT,                         -- alarm raised, command applied, write retried, ...
    PRIMARY KEY (cycle, at_utc)
);";

/// The `source` of a live campaign in the `campaigns` table.
pub const LIVE_SOURCE: &str = "errmap live";

/// The writer commits at most this often: the cycles that arrive in between go into one
/// transaction (at 100 Hz five cycles a commit instead of one), and the operators' commands
/// are read once per commit.
const COMMIT_EVERY: std::time::Duration = std::time::Duration::from_millis(50);

/// One cycle's record.
#[derive(Debug, Clone)]
pub struct CycleRecord {
    /// The cycle's number in the run.
    pub cycle: u64,
    /// The cycle's time (RFC 3339 UTC, ms; in a replay the start time plus the replayed time).
    pub at_utc: String,
    /// The cycle's mode, as [`Mode::name`](crate::state::Mode::name) spells it.
    pub mode: &'static str,
    /// The cycle's inputs as JSON: each sensor's °C as the model used it, `raw` readings,
    /// coolant, each axis's position and direction, `time_s`.
    pub inputs_json: String,
    /// The cycle's outputs as JSON, per axis: `computed_um`, `written_um`, `error_um`,
    /// `tan_beta_um_per_m`, the written line, `px_mm`, `held`, `target`.
    pub outputs_json: String,
    /// What happened in the cycle (alarms raised, commands applied, write retries, why it
    /// stopped); None when nothing did.
    pub note: Option<String>,
    /// Loop time (s): the time of the temperature samples.
    pub time_s: f64,
    /// (index into the logged sensors, °C used by the model).
    pub samples: Vec<(usize, f64)>,
}

/// An operator's command.
#[derive(Debug, Clone, PartialEq)]
pub struct Command {
    /// The command's row id in `live_commands`.
    pub id: i64,
    /// When the operator issued it (RFC 3339 UTC, ms).
    pub issued_utc: String,
    /// The operator who issued it (an `errmap serve` user).
    pub user: String,
    /// `pause`, `resume` or `ack`.
    pub command: String,
    /// The alarm acknowledged (`ack` only; None for the others).
    pub alarm_id: Option<i64>,
}

enum ToWriter {
    Cycle(Box<CycleRecord>),
    Handled {
        id: i64,
        utc: String,
        outcome: String,
    },
    Retention {
        cutoff_utc: String,
        cutoff_time_s: f64,
    },
}

/// The loop's end of the writer thread.
pub struct StoreLink {
    tx: Option<mpsc::SyncSender<ToWriter>>,
    commands: mpsc::Receiver<Command>,
    thread: Option<std::thread::JoinHandle<()>>,
    failure: Arc<Mutex<Option<String>>>,
    /// The run's campaign name in the store (`live-<start time>`).
    pub campaign: String,
    /// The store's path.
    pub path: PathBuf,
}

/// Open a connection to the store the way both live processes do: WAL, 2000 ms busy timeout.
pub fn connect(path: &Path) -> Result<Connection> {
    // The thermal store's own schema (sensors, campaigns, samples …) first.
    drop(errmap_metrology::thermal::store::Store::open(path)?);
    let conn = Connection::open(path).map_err(|e| db_err(path, "open", e))?;
    conn.busy_timeout(std::time::Duration::from_millis(2000))
        .map_err(|e| db_err(path, "open", e))?;
    let _mode: String = conn
        .query_row("PRAGMA journal_mode=WAL", [], |r| r.get(0))
        .map_err(|e| db_err(path, "open", e))?;
    conn.execute_batch("PRAGMA synchronous=NORMAL; PRAGMA foreign_keys=ON;")
        .map_err(|e| db_err(path, "open", e))?;
    conn.execute_batch(LIVE_COMMANDS_DDL)
        .and_then(|()| conn.execute_batch(LIVE_CYCLES_DDL))
        .map_err(|e| db_err(path, "create the live tables in", e))?;
    Ok(conn)
}

fn db_err(path: &Path, what: &str, e: rusqlite::Error) -> Error {
    Error::input(
        Location::file(path),
        format!("cannot {what} the store: {e}"),
        "give a writable SQLite file (errmap's temperature history store) on a local disk",
    )
}

/// The live run's campaign: `campaigns`, `sensors`, `calibrations` and `campaign_sensors` rows,
/// in one transaction. Returns (campaign id, sensor ids in `sensors` order).
fn add_campaign(
    conn: &mut Connection,
    path: &Path,
    name: &str,
    axis: &str,
    px_mm: f64,
    sensors: &[Sensor],
    now_unix: i64,
) -> Result<(i64, Vec<i64>)> {
    let e = |e| db_err(path, "write", e);
    let tx = conn.transaction().map_err(e)?;
    tx.execute(
        "INSERT INTO campaigns (name, axis, coolant, ambient_c, reference_point_mm, measurement_s, source, ingested_unix)
         VALUES (?1, ?2, 'live', NULL, ?3, 0, ?4, ?5)",
        params![name, axis, px_mm, LIVE_SOURCE, now_unix],
    )
    .map_err(e)?;
    let campaign_id = tx.last_insert_rowid();
    let mut ids = Vec::with_capacity(sensors.len());
    for (k, s) in sensors.iter().enumerate() {
        let existing: Option<(i64, String, String)> = tx
            .query_row(
                "SELECT id, role, unit FROM sensors WHERE name = ?1",
                params![s.name],
                |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?)),
            )
            .optional()
            .map_err(e)?;
        let id = match existing {
            Some((id, role, unit)) => {
                if role != s.role.name() || unit != s.unit.name() {
                    return Err(Error::input(
                        Location::file(path),
                        format!(
                            "sensor '{}' is stored as {role} in {unit}, the model has it as {} in {}",
                            s.name,
                            s.role.name(),
                            s.unit.name()
                        ),
                        "a sensor keeps its role and unit in one store: use the store its model was fitted from",
                    ));
                }
                id
            }
            None => {
                tx.execute(
                    "INSERT INTO sensors (name, role, unit, median_window, sg_window, sg_order) VALUES (?1, ?2, ?3, ?4, ?5, ?6)",
                    params![
                        s.name,
                        s.role.name(),
                        s.unit.name(),
                        s.filter.median_window as i64,
                        s.filter.sg_window as i64,
                        s.filter.sg_order as i64
                    ],
                )
                .map_err(e)?;
                tx.last_insert_rowid()
            }
        };
        tx.execute(
            "INSERT INTO calibrations (sensor_id, offset_c, scale, created_unix) VALUES (?1, ?2, ?3, ?4)",
            params![id, s.calibration.offset_c, s.calibration.scale, now_unix],
        )
        .map_err(e)?;
        let cal = tx.last_insert_rowid();
        tx.execute(
            "INSERT INTO campaign_sensors (campaign_id, sensor_id, calibration_id, column_index) VALUES (?1, ?2, ?3, ?4)",
            params![campaign_id, id, cal, k as i64],
        )
        .map_err(e)?;
        ids.push(id);
    }
    tx.commit().map_err(e)?;
    Ok((campaign_id, ids))
}

/// How the store link starts.
pub struct LinkSettings<'a> {
    /// The store's path.
    pub path: &'a Path,
    /// The run's campaign name (`live-<start time>`).
    pub campaign: String,
    /// The axis recorded on the campaign (the config's first axis).
    pub axis: &'a str,
    /// The reference point Px recorded on the campaign (mm, the first axis's model).
    pub px_mm: f64,
    /// The logged sensors with their calibrations, in the order [`CycleRecord::samples`] indexes.
    pub sensors: &'a [Sensor],
    /// The run's start (RFC 3339 UTC, ms): commands issued before it are marked not applied.
    pub start_utc: &'a str,
    /// The start as Unix seconds (the campaign's `ingested_unix`).
    pub now_unix: i64,
}

impl StoreLink {
    /// Open the store, add the run's campaign, mark commands issued before the start as not
    /// applied, and start the writer.
    pub fn open(s: LinkSettings) -> Result<StoreLink> {
        let path = s.path.to_path_buf();
        let mut conn = connect(&path)?;
        let (campaign_id, sensor_ids) = add_campaign(
            &mut conn,
            &path,
            &s.campaign,
            s.axis,
            s.px_mm,
            s.sensors,
            s.now_unix,
        )?;
        conn.execute(
            "UPDATE live_commands SET handled_utc = ?1, outcome = ?2 WHERE handled_utc IS NULL",
            params![
                s.start_utc,
                format!(
                    "not applied: issued before errmap live started at {}",
                    s.start_utc
                )
            ],
        )
        .map_err(|e| db_err(&path, "write", e))?;
        let last_id: i64 = conn
            .query_row("SELECT COALESCE(MAX(id), 0) FROM live_commands", [], |r| {
                r.get(0)
            })
            .map_err(|e| db_err(&path, "read", e))?;
        let (tx, rx) = mpsc::sync_channel::<ToWriter>(4096);
        let (ctx, crx) = mpsc::channel::<Command>();
        let failure = Arc::new(Mutex::new(None));
        let writer = Writer {
            conn,
            campaign_id,
            sensor_ids,
            last_command_id: last_id,
            failure: failure.clone(),
        };
        let thread = std::thread::Builder::new()
            .name("live-store".into())
            .spawn(move || writer.run(rx, ctx))
            .map_err(|e| Error::io("start the store writer for", &path, e))?;
        Ok(StoreLink {
            tx: Some(tx),
            commands: crx,
            thread: Some(thread),
            failure,
            campaign: s.campaign,
            path,
        })
    }

    /// Queue a cycle's record (waits while 4096 records are queued).
    pub fn log(&self, record: CycleRecord) {
        if let Some(tx) = &self.tx {
            let _ = tx.send(ToWriter::Cycle(Box::new(record)));
        }
    }

    /// Mark a command handled.
    pub fn handled(&self, id: i64, utc: String, outcome: String) {
        if let Some(tx) = &self.tx {
            let _ = tx.send(ToWriter::Handled { id, utc, outcome });
        }
    }

    /// Delete cycles before `cutoff_utc` and this run's samples before `cutoff_time_s`.
    pub fn retain(&self, cutoff_utc: String, cutoff_time_s: f64) {
        if let Some(tx) = &self.tx {
            let _ = tx.send(ToWriter::Retention {
                cutoff_utc,
                cutoff_time_s,
            });
        }
    }

    /// Commands that arrived since the last call.
    pub fn commands(&self) -> Vec<Command> {
        self.commands.try_iter().collect()
    }

    /// The last failure of the writer (cleared by a later good write).
    pub fn failure(&self) -> Option<String> {
        self.failure.lock().map(|f| f.clone()).unwrap_or(None)
    }

    /// Flush everything queued and stop the writer.
    pub fn close(&mut self) -> Result<()> {
        self.tx = None;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        match self.failure() {
            Some(f) => Err(Error::write(&self.path, std::io::Error::other(f))),
            None => Ok(()),
        }
    }
}

impl Drop for StoreLink {
    fn drop(&mut self) {
        let _ = self.close();
    }
}

struct Writer {
    conn: Connection,
    campaign_id: i64,
    sensor_ids: Vec<i64>,
    last_command_id: i64,
    failure: Arc<Mutex<Option<String>>>,
}

impl Writer {
    fn run(mut self, rx: mpsc::Receiver<ToWriter>, commands: mpsc::Sender<Command>) {
        let mut batch: Vec<ToWriter> = Vec::new();
        let mut last_commit = std::time::Instant::now();
        loop {
            let open = match rx.recv_timeout(COMMIT_EVERY) {
                Ok(m) => {
                    batch.push(m);
                    // Group commit: gather what arrives until COMMIT_EVERY has passed.
                    let wait = COMMIT_EVERY.saturating_sub(last_commit.elapsed());
                    if !wait.is_zero() {
                        std::thread::sleep(wait);
                    }
                    batch.extend(rx.try_iter().take(4096));
                    true
                }
                Err(mpsc::RecvTimeoutError::Timeout) => true,
                Err(mpsc::RecvTimeoutError::Disconnected) => false,
            };
            // A failed batch is kept and tried again (the store may be busy for a while).
            if !batch.is_empty() {
                last_commit = std::time::Instant::now();
                match self.write(&batch) {
                    Ok(()) => {
                        batch.clear();
                        self.set_failure(None);
                    }
                    Err(e) => {
                        self.set_failure(Some(e.to_string()));
                        if !open {
                            return;
                        }
                        std::thread::sleep(std::time::Duration::from_millis(100));
                    }
                }
            }
            if let Ok(new) = self.read_commands() {
                for c in new {
                    let _ = commands.send(c);
                }
            }
            if !open && batch.is_empty() {
                return;
            }
        }
    }

    fn set_failure(&self, f: Option<String>) {
        if let Ok(mut slot) = self.failure.lock() {
            *slot = f;
        }
    }

    fn write(&mut self, batch: &[ToWriter]) -> rusqlite::Result<()> {
        let tx = self.conn.transaction()?;
        {
            let mut cycle = tx.prepare_cached(
                "INSERT OR REPLACE INTO live_cycles (cycle, at_utc, mode, inputs_json, outputs_json, note)
                 VALUES (?1, ?2, ?3, ?4, ?5, ?6)",
            )?;
            let mut sample = tx.prepare_cached(
                "INSERT OR REPLACE INTO temperature_samples (campaign_id, sensor_id, time_s, temperature_c)
                 VALUES (?1, ?2, ?3, ?4)",
            )?;
            for m in batch {
                match m {
                    ToWriter::Cycle(r) => {
                        cycle.execute(params![
                            r.cycle as i64,
                            r.at_utc,
                            r.mode,
                            r.inputs_json,
                            r.outputs_json,
                            r.note
                        ])?;
                        for (k, t) in &r.samples {
                            sample.execute(params![
                                self.campaign_id,
                                self.sensor_ids[*k],
                                r.time_s,
                                t
                            ])?;
                        }
                    }
                    ToWriter::Handled { id, utc, outcome } => {
                        tx.execute(
                            "UPDATE live_commands SET handled_utc = ?1, outcome = ?2 WHERE id = ?3",
                            params![utc, outcome, id],
                        )?;
                    }
                    ToWriter::Retention {
                        cutoff_utc,
                        cutoff_time_s,
                    } => {
                        tx.execute(
                            "DELETE FROM live_cycles WHERE at_utc < ?1",
                            params![cutoff_utc],
                        )?;
                        tx.execute(
                            "DELETE FROM temperature_samples WHERE campaign_id = ?1 AND time_s < ?2",
                            params![self.campaign_id, cutoff_time_s],
                        )?;
                    }
                }
            }
        }
        tx.commit()
    }

    fn read_commands(&mut self) -> rusqlite::Result<Vec<Command>> {
        let mut stmt = self.conn.prepare_cached(
            "SELECT id, issued_utc, user, command, alarm_id FROM live_commands
             WHERE handled_utc IS NULL AND id > ?1 ORDER BY id",
        )?;
        let rows = stmt
            .query_map(params![self.last_command_id], |r| {
                Ok(Command {
                    id: r.get(0)?,
                    issued_utc: r.get(1)?,
                    user: r.get(2)?,
                    command: r.get(3)?,
                    alarm_id: r.get(4)?,
                })
            })?
            .collect::<rusqlite::Result<Vec<_>>>()?;
        if let Some(last) = rows.last() {
            self.last_command_id = last.id;
        }
        Ok(rows)
    }
}
