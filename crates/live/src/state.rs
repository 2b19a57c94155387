//! The state file for the monitor (`errmap live --state PATH`, schema `errmap-live-state/1`):
//! values, limits, alarms and source health, rewritten atomically every cycle, at most every
//! 50 ms (a temporary file in the same folder, then a rename, so a reader never sees half a
//! file).
//!
//! The file is not synced to disk each cycle: it is rewritten many times a second and only
//! describes the present; the store holds the record. A thread of its own writes it, so the
//! file system's latency never stretches a cycle.

use errmap_core::error::{Error, Result};
use serde::Serialize;
use std::io::Write;
use std::path::{Path, PathBuf};

/// The schema string of the state file; it changes only when a field changes meaning (the
/// contract with `errmap serve`).
pub const SCHEMA: &str = "errmap-live-state/1";

/// The loop's modes, as the state file and `live_cycles.mode` spell them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Mode {
    /// Ramping at the rate limit from the controller's present value (zero in a dry run, or after
    /// a ramp to zero) toward the model's line.
    Starting,
    /// Following the model's line.
    Running,
    /// Values held: a source silent past its `timeout_ms`, an implausible reading, a bound
    /// exceeded, or an unknown coolant state, position or input.
    Holding,
    /// Values held by an operator's `pause` command until `resume`.
    Paused,
    /// Every axis ramping to zero at its rate limit (a source silent or a reading implausible past
    /// `ramp_timeout_ms`, or a stop with `on_stop = "ramp_to_zero"`).
    RampingToZero,
    /// The last cycle of a run (SIGTERM, SIGINT or the end of a replay); nothing more is written.
    Stopped,
}

impl Mode {
    /// The mode's name as the state file and `live_cycles.mode` spell it (`ramping_to_zero`, ...).
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

/// One model sensor in the state file.
#[derive(Debug, Clone, Serialize)]
pub struct SensorState {
    /// The sensor's name in the axes' models (`T1`, `nut`, ...).
    pub name: String,
    /// The temperature the model uses (°C, calibrated and filtered); None before the first
    /// accepted reading.
    pub value_c: Option<f64>,
    /// Whether the sensor has a value and no problem (its last reading was plausible).
    pub ok: bool,
    /// The name of the source the sensor's channel comes from.
    pub source: String,
    /// Loop time since the source's last reading of the channel (ms); None before any reading.
    pub age_ms: Option<u64>,
    /// What is wrong with the sensor (an implausible reading, no reading); None when it is fine.
    pub problem: Option<String>,
}

/// One compensated axis in the state file. The values are compensations (−E, µm) at the axis's
/// present position, the geometric part included when the axis carries it.
#[derive(Debug, Clone, Serialize)]
pub struct AxisState {
    /// The axis's name (the model's axis: `X`, ...).
    pub axis: String,
    /// The axis's position (mm, machine coordinates) from its position channel; None when unknown.
    pub position_mm: Option<f64>,
    /// The direction of travel in force (`forward` or `reverse`: the last one reported, kept while
    /// the axis stands); None without a direction channel (the mean of both models is used).
    pub direction: Option<&'static str>,
    /// The compensation the model asks for at the position (µm); None without a position or a
    /// demand (unknown input).
    pub computed_um: Option<f64>,
    /// The compensation written (or, in a dry run, that would have been) at the position (µm), after
    /// bounds and rate limit; None without a position.
    pub written_um: Option<f64>,
    /// The bound on |compensation| anywhere on the fitted travel (µm, the config's `limit_um`).
    pub limit_um: f64,
    /// The fastest allowed change of the compensation anywhere on the travel (µm/s).
    pub rate_limit_um_s: f64,
    /// The name of the target the axis is written to (`dry-run` in a dry run).
    pub target: String,
    /// Whether the axis is held: the loop is holding or paused, or, outside the start and a ramp
    /// to zero, the written line differs from the model's (a bound exceeded, a rate limit
    /// catching up).
    pub held: bool,
    /// tanβ the model gives (µm/m) and the slope written (compensation sign, µm/m).
    pub computed_slope_um_per_m: f64,
    /// The slope of the written line (compensation sign, µm/m).
    pub written_slope_um_per_m: f64,
}

/// One source's health in the state file.
#[derive(Debug, Clone, Serialize)]
pub struct SourceState {
    /// The source's name in the config.
    pub name: String,
    /// The source's kind (`csv`, `modbus`, ...).
    pub kind: &'static str,
    /// Whether the source has been heard from within its `timeout_ms` and reports no problem.
    pub healthy: bool,
    /// When the source last delivered a good reading (RFC 3339 UTC, ms); None if it never did.
    pub last_ok_utc: Option<String>,
    /// What is wrong (a failed poll, a bad row, "silent for N s"); None when healthy.
    pub problem: Option<String>,
}

/// One listed alarm in the state file.
#[derive(Debug, Clone, Serialize)]
pub struct AlarmState {
    /// The alarm's number in this run (from 1), as an operator's `ack` names it.
    pub id: u64,
    /// When it was raised (RFC 3339 UTC, ms; loop time in a replay).
    pub raised_utc: String,
    /// What raised it: a source's, sensor's, axis's or target's name.
    pub source: String,
    /// What happened (e.g. "T3 open RTD (reading 850.0 °C above 200.0 °C)").
    pub message: String,
    /// Whether an operator has acknowledged it (it stays listed while its cause is active).
    pub acknowledged: bool,
}

/// The state file's content (schema `errmap-live-state/1`, the contract with `errmap serve`).
#[derive(Debug, Clone, Serialize)]
pub struct State {
    /// Always [`SCHEMA`].
    pub schema: &'static str,
    /// When the cycle was written (RFC 3339 UTC, ms; loop time in a replay).
    pub written_utc: String,
    /// The cycle's number in this run.
    pub cycle: u64,
    /// The loop's cycle period (ms).
    pub period_ms: u64,
    /// The loop's mode in this cycle.
    pub mode: Mode,
    /// Whether this is a dry run (nothing is written to any target).
    pub dry_run: bool,
    /// Whether the coolant is on; None when there is no coolant channel or its state is unknown.
    pub coolant_on: Option<bool>,
    /// Every model sensor, in config order.
    pub sensors: Vec<SensorState>,
    /// Every compensated axis, in config order.
    pub axes: Vec<AxisState>,
    /// Every source, in config order.
    pub sources: Vec<SourceState>,
    /// The listed alarms: active or not yet acknowledged, oldest first.
    pub alarms: Vec<AlarmState>,
    /// Cycles that started later than a whole period after their time (wall clock only).
    pub missed_cycles: u64,
    /// Why the loop stopped (mode `stopped`).
    pub stop_reason: Option<String>,
}

/// Writes the state file atomically from a thread of its own, so a slow file system delays
/// the file, never the cycle: a cycle hands over its state when it is [due](StateWriter::due)
/// (and the last always), and when the thread is still
/// writing the previous one only the newest waits (the file is never more than one write
/// behind). A failed write is returned by the next `write`.
pub struct StateWriter {
    shared: std::sync::Arc<Shared>,
    thread: Option<std::thread::JoinHandle<()>>,
    buf: Vec<u8>,
    last_handover: Option<std::time::Instant>,
}

/// The state file is rewritten at most this often (wall clock): every cycle at the default
/// 100 ms period; at faster loops the newest cycle's state every 50 ms, and always the last.
/// (A rewrite is a file, a rename and, on ext4, the flush a replacing rename starts: most of
/// the loop's CPU at 100 Hz when done every cycle. The monitor pushes it to browsers.)
pub const STATE_EVERY: std::time::Duration = std::time::Duration::from_millis(50);

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
    /// A writer of the state file at `path` (its folder is created; its temporary file is
    /// `.<name>.<pid>.tmp` beside it). Fails when the path is not a safe output.
    pub fn new(path: &Path) -> Result<StateWriter> {
        errmap_core::io::safety::check_output(path)?;
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
            last_handover: None,
        })
    }

    /// Whether a state handed over now would be written ([`STATE_EVERY`] since the last).
    pub fn due(&self) -> bool {
        self.last_handover
            .is_none_or(|at| at.elapsed() >= STATE_EVERY)
    }

    /// Hand over a cycle's state (the previous one is dropped if it is not written yet).
    pub fn write(&mut self, state: &State) -> Result<()> {
        self.last_handover = Some(std::time::Instant::now());
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
    errmap_core::io::stamp::utc_rfc3339_ms(i64::try_from(d.as_millis()).unwrap_or(i64::MAX))
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
