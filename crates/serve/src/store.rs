//! The monitor's side of the temperature-history store: the `live_commands` an operator issues, the `audit_log` of logins and actions, and the read-only queries of the history page (live cycles, campaigns, samples, models).
//!
//! Opened as the live contract says (WAL, busy timeout 2000 ms); `live_commands` is created with
//! the contract's DDL, byte for byte the same as `errmap live`'s.

use crate::Setting;
use errmap_core::error::{Error, Location, Result};
use errmap_core::setting::words;
use rusqlite::{params, Connection, OptionalExtension};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// The contract's DDL of `live_commands` (docs/monitor.md; errmap live creates the same).
pub const LIVE_COMMANDS_DDL: &str = "CREATE TABLE IF NOT EXISTS live_commands (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    issued_utc TEXT NOT NULL,          -- RFC 3339, UTC, millisecond precision, 'Z'
    user TEXT NOT NULL,
    command TEXT NOT NULL CHECK (command IN ('pause', 'resume', 'ack')),
    alarm_id INTEGER,                  -- the alarm acknowledged (ack only)
    handled_utc TEXT,                  -- set by errmap live when it applied the command
    outcome TEXT                       -- 'applied' or why not (e.g. 'unknown alarm 7')
);";

/// The audit log errmap serve owns: every login, failed or throttled login, logout and
/// operator action, and every refused state change.
pub const AUDIT_LOG_DDL: &str = "CREATE TABLE IF NOT EXISTS audit_log (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    at_utc TEXT NOT NULL,              -- RFC 3339, UTC, millisecond precision, 'Z'
    user TEXT,                         -- the user acting (the name tried, for a failed login)
    address TEXT NOT NULL,             -- the client address (X-Forwarded-For only from --trusted-proxy)
    action TEXT NOT NULL,              -- login, login_failed, login_throttled, logout, pause, resume, ack, refused
    detail TEXT
);";

/// A live loop command an operator may issue.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Command {
    /// Pause the loop: it holds the written values until resumed.
    Pause,
    /// Resume following the model after a pause.
    Resume,
    /// Acknowledge an alarm (its id goes into `live_commands.alarm_id`).
    Ack,
}

impl Command {
    /// The command of a form's `command` value (`pause`, `resume`, `ack`; exact, lower case);
    /// `None` for anything else.
    pub fn parse(text: &str) -> Option<Command> {
        match text {
            "pause" => Some(Command::Pause),
            "resume" => Some(Command::Resume),
            "ack" => Some(Command::Ack),
            _ => None,
        }
    }
    /// The command as `live_commands.command` and `audit_log.action` spell it.
    pub fn as_str(self) -> &'static str {
        match self {
            Command::Pause => "pause",
            Command::Resume => "resume",
            Command::Ack => "ack",
        }
    }
}

fn db_err(path: &Path, e: rusqlite::Error) -> Error {
    Error::input(
        Location::file(path),
        format!("store: {e}"),
        format!(
            "check that the file is an errmap store (`errmap thermal ingest {} …` makes one) and not locked by another program",
            words(Setting::Db)
        ),
    )
}

/// One connection to the store, opened as the contract says: WAL journal mode (an error if
/// SQLite cannot switch to it, e.g. on a network file system) and a 2000 ms busy timeout.
pub fn connect(path: &Path) -> Result<Connection> {
    let conn = Connection::open(path).map_err(|e| db_err(path, e))?;
    let mode: String = conn
        .query_row("PRAGMA journal_mode=WAL", [], |r| r.get(0))
        .map_err(|e| db_err(path, e))?;
    if !mode.eq_ignore_ascii_case("wal") {
        return Err(Error::input(
            Location::file(path),
            format!("the store could not switch to WAL mode (journal mode {mode})"),
            "put the store on a local file system",
        ));
    }
    conn.execute_batch("PRAGMA busy_timeout=2000;")
        .map_err(|e| db_err(path, e))?;
    Ok(conn)
}

/// The store, one connection for writes and one for the history queries.
pub struct Db {
    /// The store's file, named in error messages.
    pub path: PathBuf,
    write: Mutex<Connection>,
    read: Mutex<Connection>,
}

impl Db {
    /// Open an existing store (an error if there is no file: it is never created here) and
    /// create `live_commands` and `audit_log` in it if missing.
    pub fn open(path: &Path) -> Result<Db> {
        if !path.is_file() {
            return Err(Error::input(
                Location::file(path),
                "no store at this path",
                format!(
                    "give the store of the thermal commands (`errmap thermal ingest {} STORE.sqlite` creates one) or the one `errmap live` writes",
                    words(Setting::Db)
                ),
            ));
        }
        let write = connect(path)?;
        write
            .execute_batch(LIVE_COMMANDS_DDL)
            .and_then(|()| write.execute_batch(AUDIT_LOG_DDL))
            .map_err(|e| db_err(path, e))?;
        let read = connect(path)?;
        Ok(Db {
            path: path.to_path_buf(),
            write: Mutex::new(write),
            read: Mutex::new(read),
        })
    }

    /// The write connection, locked (one writer at a time in this process).
    pub fn writer(&self) -> std::sync::MutexGuard<'_, Connection> {
        self.write.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The connection for the history queries, locked.
    pub fn reader(&self) -> std::sync::MutexGuard<'_, Connection> {
        self.read.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// One `audit_log` row stamped now (UTC, ms): the user acting (or the name tried), the
    /// client address, the action and an optional detail. Values are bound, not interpolated.
    pub fn audit(
        &self,
        user: Option<&str>,
        address: &str,
        action: &str,
        detail: Option<&str>,
    ) -> Result<()> {
        self.writer()
            .execute(
                "INSERT INTO audit_log (at_utc, user, address, action, detail) VALUES (?1, ?2, ?3, ?4, ?5)",
                params![super::clock::utc_now_ms(), user, address, action, detail],
            )
            .map(|_| ())
            .map_err(|e| db_err(&self.path, e))
    }

    /// An operator's command and its audit row, in one transaction; the command's
    /// `live_commands` id. It checks nothing: the caller must have checked the session, the
    /// CSRF token and the operator role (and that an `ack` names an alarm).
    pub fn issue(
        &self,
        user: &str,
        address: &str,
        command: Command,
        alarm_id: Option<i64>,
    ) -> Result<i64> {
        let mut conn = self.writer();
        let tx = conn.transaction().map_err(|e| db_err(&self.path, e))?;
        let now = super::clock::utc_now_ms();
        tx.execute(
            "INSERT INTO live_commands (issued_utc, user, command, alarm_id) VALUES (?1, ?2, ?3, ?4)",
            params![now, user, command.as_str(), alarm_id],
        )
        .map_err(|e| db_err(&self.path, e))?;
        let id = tx.last_insert_rowid();
        let detail = match alarm_id {
            Some(a) => format!("live_commands id {id}, alarm {a}"),
            None => format!("live_commands id {id}"),
        };
        tx.execute(
            "INSERT INTO audit_log (at_utc, user, address, action, detail) VALUES (?1, ?2, ?3, ?4, ?5)",
            params![now, user, address, command.as_str(), detail],
        )
        .map_err(|e| db_err(&self.path, e))?;
        tx.commit().map_err(|e| db_err(&self.path, e))?;
        Ok(id)
    }
}

/// Whether the store has a table (a store the live loop never wrote has no `live_cycles`).
pub fn has_table(conn: &Connection, name: &str) -> bool {
    conn.query_row(
        "SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = ?1",
        [name],
        |_| Ok(()),
    )
    .optional()
    .ok()
    .flatten()
    .is_some()
}

/// One live cycle of the history.
#[derive(Debug, Clone)]
pub struct Cycle {
    /// The cycle's `at_utc`, ms since the Unix epoch.
    pub at_ms: i64,
    /// The loop's mode in that cycle (as the state file's `mode`).
    pub mode: String,
    /// `inputs_json`: each sensor's °C as the model used it, `coolant_on`, positions, …; empty
    /// when the column is not a JSON object.
    pub inputs: serde_json::Map<String, serde_json::Value>,
    /// `outputs_json`: per axis `computed_um`, `written_um`, `target`, …; empty when the column
    /// is not a JSON object.
    pub outputs: serde_json::Map<String, serde_json::Value>,
}

/// Cycles between two contract time stamps (both included, compared as text, so both must be
/// in the contract's form), at most `max_points` of them spread evenly over the rows there
/// (every k-th row); also how many rows the range holds. No `live_cycles` table: none.
pub fn cycles(
    conn: &Connection,
    from_utc: &str,
    to_utc: &str,
    max_points: usize,
) -> rusqlite::Result<(Vec<Cycle>, u64)> {
    if !has_table(conn, "live_cycles") {
        return Ok((Vec::new(), 0));
    }
    let total: i64 = conn.query_row(
        "SELECT COUNT(*) FROM live_cycles WHERE at_utc >= ?1 AND at_utc <= ?2",
        [from_utc, to_utc],
        |r| r.get(0),
    )?;
    let total = total.max(0) as u64;
    let stride = total.div_ceil(max_points.max(1) as u64).max(1);
    let mut stmt = conn.prepare(
        "SELECT at_utc, mode, inputs_json, outputs_json FROM live_cycles
         WHERE at_utc >= ?1 AND at_utc <= ?2 ORDER BY at_utc, cycle",
    )?;
    let mut rows = stmt.query([from_utc, to_utc])?;
    let mut out = Vec::new();
    let mut i = 0u64;
    while let Some(r) = rows.next()? {
        let keep = i.is_multiple_of(stride);
        i += 1;
        if !keep {
            continue;
        }
        let at: String = r.get(0)?;
        let Some(at_ms) = super::clock::parse_utc_ms(&at) else {
            continue;
        };
        let object = |text: String| match serde_json::from_str(&text) {
            Ok(serde_json::Value::Object(m)) => m,
            _ => serde_json::Map::new(),
        };
        out.push(Cycle {
            at_ms,
            mode: r.get(1)?,
            inputs: object(r.get(2)?),
            outputs: object(r.get(3)?),
        });
    }
    Ok((out, total))
}

/// The `at_utc` of the newest live cycle; `None` when there is none (or no `live_cycles` yet).
pub fn latest_cycle_utc(conn: &Connection) -> rusqlite::Result<Option<String>> {
    if !has_table(conn, "live_cycles") {
        return Ok(None);
    }
    conn.query_row("SELECT MAX(at_utc) FROM live_cycles", [], |r| r.get(0))
}

/// A stored campaign, as the history page lists it.
#[derive(Debug, Clone, serde::Serialize)]
pub struct CampaignRow {
    /// The campaign's unique name (e.g. `live-<start time>` for the live loop's own).
    pub name: String,
    /// The axis the campaign measured.
    pub axis: String,
    /// The coolant state during the campaign, as ingested.
    pub coolant: String,
    /// Number of temperature sensors of the campaign.
    pub sensors: i64,
    /// Number of temperature samples, all sensors together.
    pub samples: i64,
}

/// The stored campaigns by name (at most 1000); none when the store has no `campaigns` table.
pub fn campaigns(conn: &Connection) -> rusqlite::Result<Vec<CampaignRow>> {
    if !has_table(conn, "campaigns") {
        return Ok(Vec::new());
    }
    let mut stmt = conn.prepare(
        "SELECT c.name, c.axis, c.coolant,
                (SELECT COUNT(*) FROM campaign_sensors s WHERE s.campaign_id = c.id),
                (SELECT COUNT(*) FROM temperature_samples t WHERE t.campaign_id = c.id)
         FROM campaigns c ORDER BY c.name LIMIT 1000",
    )?;
    let rows = stmt.query_map([], |r| {
        Ok(CampaignRow {
            name: r.get(0)?,
            axis: r.get(1)?,
            coolant: r.get(2)?,
            sensors: r.get(3)?,
            samples: r.get(4)?,
        })
    })?;
    rows.collect()
}

/// A campaign's temperatures per sensor, by sensor name: (time_s of the campaign's log, °C as
/// `temperature_samples` holds them: calibrated, Pt100 ohms already converted), at most `max_points` per sensor (every k-th sample);
/// `None` when there is no campaign of that name. `name` is bound, not interpolated.
#[allow(clippy::type_complexity)]
pub fn campaign_temperatures(
    conn: &Connection,
    name: &str,
    max_points: usize,
) -> rusqlite::Result<Option<Vec<(String, Vec<(f64, f64)>)>>> {
    if !has_table(conn, "campaigns") {
        return Ok(None);
    }
    let Some(id): Option<i64> = conn
        .query_row("SELECT id FROM campaigns WHERE name = ?1", [name], |r| {
            r.get(0)
        })
        .optional()?
    else {
        return Ok(None);
    };
    let mut sensors = conn.prepare(
        "SELECT s.id, s.name, COUNT(t.time_s) FROM sensors s JOIN temperature_samples t ON t.sensor_id = s.id
         WHERE t.campaign_id = ?1 GROUP BY s.id ORDER BY s.name",
    )?;
    let list: Vec<(i64, String, i64)> = sensors
        .query_map([id], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?)))?
        .collect::<rusqlite::Result<_>>()?;
    let mut out = Vec::new();
    let mut samples = conn.prepare(
        "SELECT time_s, temperature_c FROM temperature_samples
         WHERE campaign_id = ?1 AND sensor_id = ?2 ORDER BY time_s",
    )?;
    for (sensor_id, sensor, count) in list {
        let stride = (count.max(0) as u64)
            .div_ceil(max_points.max(1) as u64)
            .max(1);
        let mut rows = samples.query(params![id, sensor_id])?;
        let mut points = Vec::new();
        let mut i = 0u64;
        while let Some(r) = rows.next()? {
            if i.is_multiple_of(stride) {
                points.push((r.get(0)?, r.get(1)?));
            }
            i += 1;
        }
        out.push((sensor, points));
    }
    Ok(Some(out))
}

/// A stored model version, as the history page lists it.
#[derive(Debug, Clone, serde::Serialize)]
pub struct ModelRow {
    /// The model's name (by default its axis).
    pub name: String,
    /// The version, counting from 1 per name.
    pub version: i64,
    /// When the version was saved, seconds since the Unix epoch.
    pub created_unix: i64,
    /// The names of the campaigns it was fitted to, comma-separated.
    pub campaigns: String,
    /// Pooled leave-one-campaign-out RMS, µm; `None` when no campaign had one.
    pub loco_rms_um: Option<f64>,
}

/// The stored model versions by name and version (at most 1000); none without a `models` table.
pub fn models(conn: &Connection) -> rusqlite::Result<Vec<ModelRow>> {
    if !has_table(conn, "models") {
        return Ok(Vec::new());
    }
    let mut stmt = conn.prepare(
        "SELECT name, version, created_unix, campaigns, loco_rms_um FROM models
         ORDER BY name, version LIMIT 1000",
    )?;
    let rows = stmt.query_map([], |r| {
        Ok(ModelRow {
            name: r.get(0)?,
            version: r.get(1)?,
            created_unix: r.get(2)?,
            campaigns: r.get(3)?,
            loco_rms_um: r.get(4)?,
        })
    })?;
    rows.collect()
}
