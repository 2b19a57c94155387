//! The polling shape the device sources (Modbus, OPC UA, LinuxCNC) share: a thread reads every
//! channel each period over a link it opens again after a failure, and hands the newest values
//! to the loop; a failure is the source's problem until the next good read (the watchdog sees
//! the values' age grow).

use super::{Snapshot, Source, Value};
use errmap_core::error::{Error, Result};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// A failed read of a device's channels.
pub struct Failure {
    /// What went wrong (the source's problem in the state file).
    pub message: String,
    /// Whether the link may be gone: the next poll opens it again (else it is kept, e.g. a
    /// node with a bad status over a healthy session).
    pub reconnect: bool,
}

/// A device a [`PolledSource`] reads: how to open its link and read every channel once.
pub trait Device: Send + 'static {
    /// An open connection (a Modbus client, an OPC UA session, errmap's HAL component).
    type Link: Send + 'static;
    /// Open the link again after a failure (None: it cannot be opened now).
    fn reconnect(&self) -> Option<Self::Link>;
    /// The source's problem while the link cannot be opened.
    fn unreachable(&self) -> String;
    /// Read every channel once, in the source's channel order.
    fn read(&self, link: &mut Self::Link) -> std::result::Result<Vec<Value>, Failure>;
}

/// What the polling thread hands over.
struct Shared {
    values: Vec<Value>,
    at: Option<Instant>,
    fresh: bool,
    problem: Option<String>,
    quit: bool,
}

/// A source read by polling a device on a thread of its own: the newest values the thread read,
/// as the loop last took them.
pub struct PolledSource {
    name: String,
    kind: &'static str,
    channels: Vec<String>,
    shared: Arc<Mutex<Shared>>,
    snap: Snapshot,
    thread: Option<std::thread::JoinHandle<()>>,
}

/// A source's poll period: its own `period_ms`, else the cycle's (at least 1 ms).
pub fn poll_period(
    config: &crate::config::LiveConfig,
    s: &crate::config::SourceConfig,
) -> Duration {
    Duration::from_millis(s.period_ms.unwrap_or(config.cycle.period_ms).max(1))
}

impl PolledSource {
    /// Read every channel of `device` once over `link` (already open; a read refused at start
    /// means the source cannot be used: an io error naming `place`), then poll it each
    /// `period` on a thread of its own: the source `name` of `kind` with `channels` (in the
    /// device's order).
    pub fn start<D: Device>(
        kind: &'static str,
        name: &str,
        place: &str,
        channels: Vec<String>,
        device: D,
        mut link: D::Link,
        period: Duration,
    ) -> Result<PolledSource> {
        let first = device
            .read(&mut link)
            .map_err(|f| Error::io("read from", place, std::io::Error::other(f.message)))?;
        let shared = Arc::new(Mutex::new(Shared {
            values: first,
            at: Some(Instant::now()),
            fresh: true,
            problem: None,
            quit: false,
        }));
        let poller = shared.clone();
        let thread = std::thread::Builder::new()
            .name(format!("{kind}-{name}"))
            .spawn(move || poll_loop(&device, link, &poller, period))
            .map_err(|e| Error::io("start the poller of", name, e))?;
        Ok(PolledSource {
            name: name.to_string(),
            kind,
            channels,
            shared,
            snap: Snapshot::default(),
            thread: Some(thread),
        })
    }
}

impl Source for PolledSource {
    fn name(&self) -> &str {
        &self.name
    }
    fn kind(&self) -> &'static str {
        self.kind
    }
    fn channel_names(&self) -> Vec<String> {
        self.channels.clone()
    }
    /// Take in what the thread read since the last poll, stamped with the loop time it was
    /// read at (`now_s` less its age).
    fn poll(&mut self, now_s: f64) {
        let Ok(mut s) = self.shared.lock() else {
            return;
        };
        self.snap.problem = s.problem.clone();
        if !s.fresh {
            return;
        }
        s.fresh = false;
        let at_s = now_s - s.at.map_or(0.0, |a| a.elapsed().as_secs_f64());
        for (name, v) in self.channels.iter().zip(&s.values) {
            self.snap.set(name, v.clone(), at_s);
        }
        self.snap.last_ok_s = Some(at_s);
    }
    fn snapshot(&self) -> &Snapshot {
        &self.snap
    }
}

impl Drop for PolledSource {
    fn drop(&mut self) {
        if let Ok(mut s) = self.shared.lock() {
            s.quit = true;
        }
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn poll_loop<D: Device>(device: &D, link: D::Link, shared: &Mutex<Shared>, period: Duration) {
    let mut link = Some(link);
    let mut next = Instant::now() + period;
    loop {
        let now = Instant::now();
        if next > now {
            std::thread::sleep(next - now);
        }
        next += period;
        if Instant::now() > next {
            next = Instant::now() + period;
        }
        if shared.lock().map(|s| s.quit).unwrap_or(true) {
            return;
        }
        if link.is_none() {
            link = device.reconnect();
        }
        let result = match link.as_mut() {
            Some(l) => device.read(l),
            None => Err(Failure {
                message: device.unreachable(),
                reconnect: true,
            }),
        };
        let Ok(mut s) = shared.lock() else { return };
        match result {
            Ok(values) => {
                s.values = values;
                s.at = Some(Instant::now());
                s.fresh = true;
                s.problem = None;
            }
            Err(f) => {
                s.problem = Some(f.message);
                drop(s);
                if f.reconnect {
                    link = None;
                }
            }
        }
    }
}
