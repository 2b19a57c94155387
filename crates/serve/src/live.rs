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

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SensorState {
    pub name: String,
    pub value_c: Option<f64>,
    pub ok: bool,
    pub source: String,
    pub age_ms: f64,
    #[serde(default)]
    pub problem: Option<String>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AxisState {
    pub axis: String,
    pub position_mm: Option<f64>,
    pub direction: Option<String>,
    pub computed_um: f64,
    pub written_um: f64,
    pub limit_um: f64,
    pub rate_limit_um_s: f64,
    pub target: String,
    pub held: bool,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SourceState {
    pub name: String,
    pub kind: String,
    pub healthy: bool,
    #[serde(default)]
    pub last_ok_utc: Option<String>,
    #[serde(default)]
    pub problem: Option<String>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AlarmState {
    pub id: i64,
    pub raised_utc: String,
    pub source: String,
    pub message: String,
    pub acknowledged: bool,
}

/// The state file as the contract defines it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LiveState {
    pub schema: String,
    pub written_utc: String,
    pub cycle: u64,
    pub period_ms: u64,
    pub mode: String,
    pub dry_run: bool,
    pub coolant_on: Option<bool>,
    pub sensors: Vec<SensorState>,
    pub axes: Vec<AxisState>,
    pub sources: Vec<SourceState>,
    pub alarms: Vec<AlarmState>,
}

/// The modes the contract names.
pub const MODES: [&str; 6] = [
    "starting",
    "running",
    "holding",
    "paused",
    "ramping_to_zero",
    "stopped",
];

/// Parse and check a state file's text.
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
    pub state: Option<LiveState>,
    pub problem: Option<String>,
    pub stale: bool,
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
    pub snapshot: Snapshot,
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
    /// Watch `path` (none: a snapshot saying no state file was given).
    pub fn start(path: Option<PathBuf>) -> Feed {
        let first = match &path {
            Some(_) => Snapshot::problem("the state file has not been read yet".into()),
            None => {
                Snapshot::problem("no live state: errmap serve was started without --live".into())
            }
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

    #[test]
    fn the_contract_sample_parses_and_unknown_fields_are_ignored() {
        let s = parse_state(SAMPLE).unwrap();
        assert_eq!(s.cycle, 1234);
        assert_eq!(s.sensors[0].value_c, Some(21.3));
        assert_eq!(s.axes[0].written_um, 12.1);
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
