//! The live loop's state file (schema `errmap-live-state/1`, rewritten atomically by `errmap live --state`), read at most 10 times a second by one task and handed to every client as one JSON snapshot.
//!
//! A snapshot is `{"state": …, "problem": …, "stale": …, "read_utc": …}`: the state as the
//! contract defines it (fields this reader does not know are dropped), or `null` with the
//! problem in words when the file is missing, unreadable or not the contract's; `stale` when
//! the file has not been rewritten for three periods (and at least 2 s).

use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::watch;

/// The schema string this reader follows.
pub const SCHEMA: &str = "errmap-live-state/1";
/// Shortest time between two reads of the state file.
pub const READ_INTERVAL: Duration = Duration::from_millis(100);
/// Largest state file read.
pub const MAX_STATE_BYTES: u64 = 1 << 20;

/// One temperature sensor of the live loop, as the state file's `sensors` lists it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SensorState {
    /// The sensor's name in the live loop's configuration (e.g. `T1`).
    pub name: String,
    /// The temperature the model used this cycle (calibrated, filtered), °C; `None` when unknown.
    pub value_c: Option<f64>,
    /// Whether the reading is usable: a value and no problem.
    pub ok: bool,
    /// The name of the source (e.g. a Modbus rack) the sensor is read from.
    pub source: String,
    /// Time since the sensor's last reading, ms; `None` when it was never read.
    pub age_ms: Option<f64>,
    /// Why the reading is not usable, in words (e.g. an open RTD); `None` when fine.
    #[serde(default)]
    pub problem: Option<String>,
}

/// One compensated axis of the live loop, as the state file's `axes` lists it. Compensation
/// values are −E (E = measured − nominal), in the live loop's sign: P' = P − E.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AxisState {
    /// The axis name (e.g. `X`).
    pub axis: String,
    /// The axis's present position, mm; `None` when unknown.
    pub position_mm: Option<f64>,
    /// The direction of travel the model uses (`forward` or `reverse`); `None` when unknown.
    pub direction: Option<String>,
    /// The compensation the model asks for at the present position, µm; `None` when it cannot
    /// be computed (position or temperatures unknown).
    pub computed_um: Option<f64>,
    /// The compensation written to the controller at the present position (rate-limited,
    /// or held), µm; `None` before anything was written.
    pub written_um: Option<f64>,
    /// Largest |compensation| allowed anywhere on the fitted travel, µm; beyond it the axis holds.
    pub limit_um: f64,
    /// Fastest change of the written compensation anywhere on the travel, µm/s.
    pub rate_limit_um_s: f64,
    /// The name of the controller target written (e.g. `sinumerik-opcua`, or `dry-run`).
    pub target: String,
    /// Whether the written value is held instead of following the model (holding, paused, or
    /// a bounds or rate limit in force).
    pub held: bool,
}

/// One input source of the live loop (a Modbus rack, an OPC UA server, a replayed file), as
/// the state file's `sources` lists it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SourceState {
    /// The source's name in the live loop's configuration.
    pub name: String,
    /// The kind of source (e.g. `modbus`).
    pub kind: String,
    /// Whether the source answered within its timeout.
    pub healthy: bool,
    /// When the source last answered, RFC 3339 UTC; `None` when it never has.
    #[serde(default)]
    pub last_ok_utc: Option<String>,
    /// What is wrong with the source, in words; `None` when healthy.
    #[serde(default)]
    pub problem: Option<String>,
}

/// An alarm of the live loop, as the state file's `alarms` lists it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AlarmState {
    /// The alarm's number, which an operator's `ack` command names (`live_commands.alarm_id`).
    pub id: i64,
    /// When the alarm was raised, RFC 3339 UTC.
    pub raised_utc: String,
    /// What raised it (a source's name, or e.g. `store`).
    pub source: String,
    /// The alarm in words, as the live loop wrote it (untrusted text: escape it to show it).
    pub message: String,
    /// Whether an operator has acknowledged it.
    pub acknowledged: bool,
}

/// The state file as the contract defines it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LiveState {
    /// The schema string; [`parse_state`] accepts only [`SCHEMA`].
    pub schema: String,
    /// When the live loop wrote the file, RFC 3339 UTC with ms; the staleness counts from it.
    pub written_utc: String,
    /// The live loop's cycle number.
    pub cycle: u64,
    /// The live loop's cycle period, ms.
    pub period_ms: u64,
    /// The loop's mode, one of [`MODES`].
    pub mode: String,
    /// Whether the loop computes and logs only, writing to no controller.
    pub dry_run: bool,
    /// Whether the coolant is on; `None` when unknown.
    pub coolant_on: Option<bool>,
    /// The temperature sensors.
    pub sensors: Vec<SensorState>,
    /// The compensated axes.
    pub axes: Vec<AxisState>,
    /// The input sources and their health.
    pub sources: Vec<SourceState>,
    /// The alarms, acknowledged or not.
    pub alarms: Vec<AlarmState>,
}

/// The modes the contract names: `holding` (a source silent past its first timeout, or a
/// plausibility failure), `paused` (an operator's pause: values held), `ramping_to_zero`
/// (every axis on its way to zero compensation at its rate limit).
pub const MODES: [&str; 6] = [
    "starting",
    "running",
    "holding",
    "paused",
    "ramping_to_zero",
    "stopped",
];

/// Parse and check a state file's text: JSON of the contract's shape (unknown fields dropped),
/// schema [`SCHEMA`], a mode of [`MODES`] and a `written_utc` that parses. The error is the
/// problem in words, shown on the live page.
pub fn parse_state(text: &str) -> Result<LiveState, String> {
    let state: LiveState =
        serde_json::from_str(text).map_err(|e| format!("not a state file: {e}"))?;
    if state.schema != SCHEMA {
        return Err(format!(
            "schema {:?}, this monitor reads {SCHEMA:?}",
            state.schema
        ));
    }
    if !MODES.contains(&state.mode.as_str()) {
        return Err(format!("unknown mode {:?}", state.mode));
    }
    if super::clock::parse_utc_ms(&state.written_utc).is_none() {
        return Err(format!(
            "written_utc {:?} is not an RFC 3339 UTC time",
            state.written_utc
        ));
    }
    Ok(state)
}

/// What every client gets.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Snapshot {
    /// The state file's content; `None` when it cannot be used (then `problem` says why).
    pub state: Option<LiveState>,
    /// Why there is no state (no `--live`, missing, over [`MAX_STATE_BYTES`], not JSON, another
    /// schema, an unknown mode, a missing field); `None` with a state.
    pub problem: Option<String>,
    /// Whether the state was written more than three periods ago (at least 2 s); always true
    /// without a state.
    pub stale: bool,
    /// When the server read the file, RFC 3339 UTC with ms.
    pub read_utc: String,
}

impl Snapshot {
    fn problem(text: String) -> Snapshot {
        Snapshot {
            state: None,
            problem: Some(text),
            stale: true,
            read_utc: super::clock::utc_now_ms(),
        }
    }
}

/// A snapshot and its JSON, shared by every stream.
#[derive(Debug)]
pub struct Published {
    /// The snapshot.
    pub snapshot: Snapshot,
    /// The snapshot as JSON, serialised once for every stream (the SSE event's data).
    pub json: String,
    /// Counts the publications (the SSE event id).
    pub seq: u64,
}

/// Whether a state is older than three periods (at least 2 s) at `now_ms`.
fn is_stale(state: &LiveState, now_ms: i64) -> bool {
    let written = super::clock::parse_utc_ms(&state.written_utc).unwrap_or(i64::MIN);
    let limit_ms = (3 * state.period_ms as i64).max(2000);
    now_ms.saturating_sub(written) > limit_ms
}

/// The state file's watcher: start it once; subscribers get every new snapshot.
pub struct Feed {
    /// The latest publication; clone it to follow changes (a new value only when the state,
    /// its problem or its staleness changed).
    pub rx: watch::Receiver<Arc<Published>>,
    /// How many times the file was read (for the bench and the docs' claim).
    pub reads: Arc<std::sync::atomic::AtomicU64>,
}

/// File identity that changes with each atomic rewrite.
fn stamp(meta: &std::fs::Metadata) -> (Option<std::time::SystemTime>, u64, u64) {
    #[cfg(unix)]
    let ino = std::os::unix::fs::MetadataExt::ino(meta);
    #[cfg(not(unix))]
    let ino = 0;
    (meta.modified().ok(), meta.len(), ino)
}

impl Feed {
    /// Watch `path` in a background task (needs a Tokio runtime): every 100 ms, re-read only when
    /// the file's modification time, size or inode changed. `None`: one snapshot saying no state
    /// file was given.
    pub fn start(path: Option<PathBuf>) -> Feed {
        let first = match &path {
            Some(_) => Snapshot::problem("the state file has not been read yet".into()),
            None => Snapshot::problem(format!(
                "no live state: errmap serve was started without {}",
                errmap_core::setting::words(crate::Setting::Live)
            )),
        };
        let json = serde_json::to_string(&first).unwrap_or_default();
        let (tx, rx) = watch::channel(Arc::new(Published {
            snapshot: first,
            json,
            seq: 0,
        }));
        let reads = Arc::new(std::sync::atomic::AtomicU64::new(0));
        if let Some(path) = path {
            tokio::spawn(watch_file(path, tx, reads.clone()));
        }
        Feed { rx, reads }
    }
}

async fn read_state(path: &Path) -> Snapshot {
    let meta = match tokio::fs::metadata(path).await {
        Ok(m) => m,
        Err(e) => return Snapshot::problem(format!("cannot read the state file: {e}")),
    };
    if meta.len() > MAX_STATE_BYTES {
        return Snapshot::problem(format!(
            "the state file is larger than {MAX_STATE_BYTES} bytes"
        ));
    }
    let text = match tokio::fs::read_to_string(path).await {
        Ok(t) => t,
        Err(e) => return Snapshot::problem(format!("cannot read the state file: {e}")),
    };
    match parse_state(&text) {
        Ok(state) => Snapshot {
            stale: is_stale(&state, super::clock::now_ms()),
            state: Some(state),
            problem: None,
            read_utc: super::clock::utc_now_ms(),
        },
        Err(p) => Snapshot::problem(p),
    }
}

async fn watch_file(
    path: PathBuf,
    tx: watch::Sender<Arc<Published>>,
    reads: Arc<std::sync::atomic::AtomicU64>,
) {
    let mut tick = tokio::time::interval(READ_INTERVAL);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut last_stamp = None;
    let mut seq = 0u64;
    loop {
        tick.tick().await;
        let now_stamp = std::fs::metadata(&path).ok().map(|m| stamp(&m));
        let current = tx.borrow().snapshot.clone();
        let next = if now_stamp != last_stamp || now_stamp.is_none() {
            last_stamp = now_stamp;
            reads.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            read_state(&path).await
        } else {
            // Unchanged file: only its age moves.
            let mut s = current.clone();
            if let Some(state) = &s.state {
                s.stale = is_stale(state, super::clock::now_ms());
            }
            s
        };
        // Publish only what changed (the read time alone is no news).
        let same = next.state == current.state
            && next.problem == current.problem
            && next.stale == current.stale;
        if same {
            continue;
        }
        seq += 1;
        let json = serde_json::to_string(&next).unwrap_or_default();
        if tx
            .send(Arc::new(Published {
                snapshot: next,
                json,
                seq,
            }))
            .is_err()
        {
            return;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SAMPLE: &str = r#"{
  "schema": "errmap-live-state/1",
  "written_utc": "2026-11-27T10:00:00.123Z",
  "cycle": 1234, "period_ms": 100, "mode": "running", "dry_run": true, "coolant_on": true,
  "sensors": [{"name": "T1", "value_c": 21.30, "ok": true, "source": "modbus-rack", "age_ms": 80, "problem": null}],
  "axes": [{"axis": "X", "position_mm": 123.456, "direction": "forward", "computed_um": 12.3, "written_um": 12.1,
            "limit_um": 50.0, "rate_limit_um_s": 5.0, "target": "sinumerik-opcua", "held": false}],
  "sources": [{"name": "modbus-rack", "kind": "modbus", "healthy": true, "last_ok_utc": "2026-11-27T10:00:00.100Z", "problem": null}],
  "alarms": [{"id": 7, "raised_utc": "2026-11-27T09:59:58.000Z", "source": "modbus-rack",
              "message": "T3 open RTD", "acknowledged": false}],
  "a_field_from_later": {"x": 1}
}"#;

    /// What the live loop writes before a sensor was read or while an axis's position is
    /// unknown: `null` ages and compensations, shown as unknown instead of refusing the file.
    #[test]
    fn unknown_ages_and_compensations_are_read_as_unknown() {
        let text = SAMPLE
            .replace(r#""age_ms": 80"#, r#""age_ms": null"#)
            .replace(
                r#""computed_um": 12.3, "written_um": 12.1"#,
                r#""computed_um": null, "written_um": null"#,
            );
        let s = parse_state(&text).unwrap();
        assert_eq!(s.sensors[0].age_ms, None);
        assert_eq!((s.axes[0].computed_um, s.axes[0].written_um), (None, None));
    }

    #[test]
    fn the_contract_sample_parses_and_unknown_fields_are_ignored() {
        let s = parse_state(SAMPLE).unwrap();
        assert_eq!(s.cycle, 1234);
        assert_eq!(s.sensors[0].value_c, Some(21.3));
        assert_eq!(s.axes[0].written_um, Some(12.1));
        assert_eq!(s.alarms[0].id, 7);
        // 10:00:00.123 + 2 s is not stale, + 2.2 s is (3 × 100 ms < 2 s).
        let t = crate::clock::parse_utc_ms("2026-11-27T10:00:00.123Z").unwrap();
        assert!(!is_stale(&s, t + 2000));
        assert!(is_stale(&s, t + 2001));
    }

    #[test]
    fn other_schemas_modes_and_shapes_are_refused() {
        let other = SAMPLE.replace("errmap-live-state/1", "errmap-live-state/2");
        assert!(parse_state(&other).unwrap_err().contains("schema"));
        let mode = SAMPLE.replace("\"running\"", "\"flying\"");
        assert!(parse_state(&mode).unwrap_err().contains("mode"));
        let missing = SAMPLE.replace("\"cycle\": 1234,", "");
        assert!(parse_state(&missing).is_err());
        let nulls = SAMPLE
            .replace("\"coolant_on\": true", "\"coolant_on\": null")
            .replace("\"value_c\": 21.30", "\"value_c\": null")
            .replace("\"position_mm\": 123.456", "\"position_mm\": null")
            .replace("\"direction\": \"forward\"", "\"direction\": null");
        let s = parse_state(&nulls).unwrap();
        assert_eq!(s.coolant_on, None);
        assert_eq!(s.sensors[0].value_c, None);
        assert!(parse_state("{").is_err());
    }
}
