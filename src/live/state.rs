//! The state file for the monitor (`errmap live --state PATH`, schema `errmap-live-state/1`):
//! values, limits, alarms and source health, rewritten atomically every cycle (a temporary file
//! in the same folder, then a rename, so a reader never sees half a file).
//!
//! The file is not synced to disk each cycle: it is rewritten many times a second and only
//! describes the present; the store holds the record. A thread of its own writes it, so the
//! file system's latency never stretches a cycle.

use crate::error::{Error, Result};
use serde::Serialize;
use std::io::Write;
use std::path::{Path, PathBuf};

pub const SCHEMA: &str = "errmap-live-state/1";

/// The loop's modes, as the state file and `live_cycles.mode` spell them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Mode {
    Starting,
    Running,
    Holding,
    Paused,
    RampingToZero,
    Stopped,
}

impl Mode {
    pub fn name(self) -> &'static str {
        match self {
            Mode::Starting => "starting",
            Mode::Running => "running",
            Mode::Holding => "holding",
            Mode::Paused => "paused",
            Mode::RampingToZero => "ramping_to_zero",
            Mode::Stopped => "stopped",
        }
    }
}

#[derive(Debug, Clone, Serialize)]
pub struct SensorState {
    pub name: String,
    pub value_c: Option<f64>,
    pub ok: bool,
    pub source: String,
    pub age_ms: Option<u64>,
    pub problem: Option<String>,
}

#[derive(Debug, Clone, Serialize)]
pub struct AxisState {
    pub axis: String,
    pub position_mm: Option<f64>,
    pub direction: Option<&'static str>,
    pub computed_um: Option<f64>,
    pub written_um: Option<f64>,
    pub limit_um: f64,
    pub rate_limit_um_s: f64,
    pub target: String,
    pub held: bool,
    /// tanβ the model gives (µm/m) and the slope written (compensation sign, µm/m).
    pub computed_slope_um_per_m: f64,
    pub written_slope_um_per_m: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct SourceState {
    pub name: String,
    pub kind: &'static str,
    pub healthy: bool,
    pub last_ok_utc: Option<String>,
    pub problem: Option<String>,
}

#[derive(Debug, Clone, Serialize)]
pub struct AlarmState {
    pub id: u64,
    pub raised_utc: String,
    pub source: String,
    pub message: String,
    pub acknowledged: bool,
}

#[derive(Debug, Clone, Serialize)]
pub struct State {
    pub schema: &'static str,
    pub written_utc: String,
    pub cycle: u64,
    pub period_ms: u64,
    pub mode: Mode,
    pub dry_run: bool,
    pub coolant_on: Option<bool>,
    pub sensors: Vec<SensorState>,
    pub axes: Vec<AxisState>,
    pub sources: Vec<SourceState>,
    pub alarms: Vec<AlarmState>,
    /// Cycles that started later than a whole period after their time (wall clock only).
    pub missed_cycles: u64,
    /// Why the loop stopped (mode `stopped`).
    pub stop_reason: Option<String>,
}

/// Writes the state file atomically from a thread of its own, so a slow file system delays
/// the file, never the cycle: each cycle hands over its state, and when the thread is still
/// writing the previous one only the newest waits (the file is never more than one write
/// behind). A failed write is returned by the next `write`.
pub struct StateWriter {
    shared: std::sync::Arc<Shared>,
    thread: Option<std::thread::JoinHandle<()>>,
    buf: Vec<u8>,
}

#[derive(Default)]
struct Slot {
    next: Option<Vec<u8>>,
    closing: bool,
    failure: Option<Error>,
}

#[derive(Default)]
struct Shared {
    slot: std::sync::Mutex<Slot>,
    ready: std::sync::Condvar,
}

impl StateWriter {
    pub fn new(path: &Path) -> Result<StateWriter> {
        crate::io::safety::check_output(path)?;
        let dir = match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        std::fs::create_dir_all(&dir).map_err(|e| Error::io("create folder", &dir, e))?;
        let file_name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "state.json".into());
        let tmp = dir.join(format!(".{file_name}.{}.tmp", std::process::id()));
        let path = path.to_path_buf();
        let shared = std::sync::Arc::new(Shared::default());
        let mine = shared.clone();
        let thread = std::thread::Builder::new()
            .name("live-state".into())
            .spawn(move || writer(&mine, &path, &tmp))
            .map_err(|e| Error::io("start the state writer for", &dir, e))?;
        Ok(StateWriter {
            shared,
            thread: Some(thread),
            buf: Vec::with_capacity(4096),
        })
    }

    /// Hand over a cycle's state (the previous one is dropped if it is not written yet).
    pub fn write(&mut self, state: &State) -> Result<()> {
        self.buf.clear();
        serde_json::to_writer_pretty(&mut self.buf, state)
            .map_err(|e| Error::Internal(format!("state JSON: {e}")))?;
        self.buf.push(b'\n');
        let mut slot = self
            .shared
            .slot
            .lock()
            .map_err(|_| Error::Internal("state writer lock".into()))?;
        if let Some(e) = slot.failure.take() {
            return Err(e);
        }
        slot.next = Some(std::mem::replace(&mut self.buf, Vec::with_capacity(4096)));
        self.shared.ready.notify_one();
        Ok(())
    }

    /// Write the last state handed over and stop the thread.
    pub fn close(&mut self) -> Result<()> {
        if let Ok(mut slot) = self.shared.slot.lock() {
            slot.closing = true;
            self.shared.ready.notify_one();
        }
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        match self.shared.slot.lock().map(|mut s| s.failure.take()) {
            Ok(Some(e)) => Err(e),
            _ => Ok(()),
        }
    }
}

impl Drop for StateWriter {
    fn drop(&mut self) {
        let _ = self.close();
    }
}

fn writer(shared: &Shared, path: &Path, tmp: &Path) {
    loop {
        let bytes = {
            let Ok(mut slot) = shared.slot.lock() else {
                return;
            };
            while slot.next.is_none() && !slot.closing {
                slot = match shared.ready.wait(slot) {
                    Ok(s) => s,
                    Err(_) => return,
                };
            }
            match slot.next.take() {
                Some(b) => b,
                None => return,
            }
        };
        let written = std::fs::File::create(tmp)
            .and_then(|mut f| f.write_all(&bytes))
            .map_err(|e| Error::write(tmp, e))
            .and_then(|()| {
                std::fs::rename(tmp, path)
                    .map_err(|e| Error::io("rename the state file to", path, e))
            });
        if let Err(e) = written {
            if let Ok(mut slot) = shared.slot.lock() {
                slot.failure = Some(e);
            }
        }
    }
}

/// Now as RFC 3339 UTC with milliseconds and `Z` (the contract's time stamps).
pub fn utc_ms(t: std::time::SystemTime) -> String {
    let d = t.duration_since(std::time::UNIX_EPOCH).unwrap_or_default();
    let secs = d.as_secs() as i64;
    let s = crate::io::stamp::utc_rfc3339(secs);
    // "YYYY-MM-DDThh:mm:ssZ" → "YYYY-MM-DDThh:mm:ss.mmmZ"
    format!("{}.{:03}Z", &s[..s.len() - 1], d.subsec_millis())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn millisecond_utc() {
        let t = std::time::UNIX_EPOCH + std::time::Duration::from_millis(1_795_766_400_123);
        // 1 795 766 400 s = 2026-11-27T08:00:00Z (date -u -d @1795766400).
        assert_eq!(utc_ms(t), "2026-11-27T08:00:00.123Z");
    }
}
