//! The state file for the monitor (`errmap live --state PATH`, schema `errmap-live-state/1`):
//! values, limits, alarms and source health, rewritten atomically every cycle (a temporary file
//! in the same folder, then a rename, so a reader never sees half a file).
//!
//! The file is not synced to disk each cycle: it is rewritten many times a second and only
//! describes the present; the store holds the record. A thread of its own writes it, so the
//! file system's latency stretches a cycle only when it falls a whole queue behind.

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

/// Writes the state file atomically from a thread of its own, every cycle's state in turn: a
/// cycle hands over its state and goes on; the thread writes the states in the order they came.
/// Should the file system be slower than the loop for a while, up to [`STATE_QUEUE`] states
/// wait; beyond that the cycle waits for the disk (a late cycle, counted as missed), so no
/// cycle's state is ever skipped and memory stays bounded. A failed write is returned by the
/// next `write`.
pub struct StateWriter {
    shared: std::sync::Arc<Shared>,
    thread: Option<std::thread::JoinHandle<()>>,
    buf: Vec<u8>,
}

/// The states that may wait for the writer thread (0.64 s of a 100 Hz loop).
pub const STATE_QUEUE: usize = 64;

#[derive(Default)]
struct Slot {
    queue: std::collections::VecDeque<Vec<u8>>,
    closing: bool,
    failure: Option<Error>,
}

#[derive(Default)]
struct Shared {
    slot: std::sync::Mutex<Slot>,
    /// Signalled when a state is queued or the writer is to close.
    ready: std::sync::Condvar,
    /// Signalled when the writer took a state off a full queue.
    room: std::sync::Condvar,
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
        })
    }

    /// Hand over a cycle's state; it is written after those handed over before it (the cycle
    /// waits only while [`STATE_QUEUE`] states are waiting already).
    pub fn write(&mut self, state: &State) -> Result<()> {
        self.buf.clear();
        serde_json::to_writer_pretty(&mut self.buf, state)
            .map_err(|e| Error::Internal(format!("state JSON: {e}")))?;
        self.buf.push(b'\n');
        let lock_failed = || Error::Internal("state writer lock".into());
        let mut slot = self.shared.slot.lock().map_err(|_| lock_failed())?;
        while slot.queue.len() >= STATE_QUEUE && slot.failure.is_none() {
            slot = self.shared.room.wait(slot).map_err(|_| lock_failed())?;
        }
        if let Some(e) = slot.failure.take() {
            return Err(e);
        }
        slot.queue
            .push_back(std::mem::replace(&mut self.buf, Vec::with_capacity(4096)));
        self.shared.ready.notify_one();
        Ok(())
    }

    /// Write the states still waiting and stop the thread.
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
    let mut exchange = true;
    loop {
        let bytes = {
            let Ok(mut slot) = shared.slot.lock() else {
                return;
            };
            while slot.queue.is_empty() && !slot.closing {
                slot = match shared.ready.wait(slot) {
                    Ok(s) => s,
                    Err(_) => return,
                };
            }
            let Some(b) = slot.queue.pop_front() else {
                return;
            };
            shared.room.notify_one();
            b
        };
        if let Err(e) = replace(path, tmp, &bytes, &mut exchange) {
            if let Ok(mut slot) = shared.slot.lock() {
                slot.failure = Some(e);
                shared.room.notify_one();
            }
        }
    }
}

/// Write `bytes` to `tmp`, then rename it over `path` (a reader sees the old file or the new
/// one, never a part).
///
/// On Linux the two names are exchanged (`renameat2` with `RENAME_EXCHANGE`) and the old file,
/// now under the temporary name, is removed: on ext4 a rename that replaces a file starts
/// writing the new file to disk at once (its `auto_da_alloc`), about three times the CPU of the
/// whole rewrite and a disk write each cycle; a file replaced within the next cycle need never
/// reach the disk. Where the file system cannot exchange (or before the first state file
/// exists) a plain rename does; `exchange` turns false after the file system refused once.
fn replace(path: &Path, tmp: &Path, bytes: &[u8], exchange: &mut bool) -> Result<()> {
    std::fs::File::create(tmp)
        .and_then(|mut f| f.write_all(bytes))
        .map_err(|e| Error::write(tmp, e))?;
    #[cfg(target_os = "linux")]
    if *exchange {
        use rustix::fs::{renameat_with, RenameFlags, CWD};
        match renameat_with(CWD, tmp, CWD, path, RenameFlags::EXCHANGE) {
            Ok(()) => {
                return std::fs::remove_file(tmp)
                    .map_err(|e| Error::io("remove the old state file", tmp, e));
            }
            // No state file yet: the plain rename below makes it.
            Err(rustix::io::Errno::NOENT) => {}
            // A file system or kernel without the exchange.
            Err(_) => *exchange = false,
        }
    }
    #[cfg(not(target_os = "linux"))]
    let _ = exchange;
    std::fs::rename(tmp, path).map_err(|e| Error::io("rename the state file to", path, e))
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
