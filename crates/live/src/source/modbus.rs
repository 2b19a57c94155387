//! A Modbus TCP source: a thread polls every channel each `period_ms` and hands the newest
//! values to the loop; a failed poll is the source's problem (the watchdog sees its age grow)
//! and the thread reconnects on the next poll.

use super::{Snapshot, Source, Value};
use crate::config::{LiveConfig, SourceConfig};
use crate::modbus::{Client, Layout, ReadValue, Table};
use errmap_core::error::{Error, Result};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// What the poller hands over.
#[derive(Default)]
struct Shared {
    values: Vec<(String, ReadValue)>,
    at: Option<Instant>,
    fresh: bool,
    problem: Option<String>,
    quit: bool,
}

/// A Modbus TCP source: a thread polls every channel each period and hands the values over;
/// a failed poll is the source's problem and the next poll reconnects.
pub struct ModbusSource {
    name: String,
    channels: Vec<String>,
    shared: Arc<Mutex<Shared>>,
    snap: Snapshot,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl ModbusSource {
    /// Check the channel layouts, connect, read every channel once (a device that cannot be
    /// reached or refuses a channel is exit 3), then start polling.
    pub fn connect(config: &LiveConfig, index: usize, s: &SourceConfig) -> Result<ModbusSource> {
        let key = format!("sources.{index}");
        let layouts = s
            .channels
            .iter()
            .enumerate()
            .map(|(j, c)| Layout::parse(config, &format!("{key}.channels.{j}"), c, Table::Input))
            .collect::<Result<Vec<_>>>()?;
        let address = s.address.clone().unwrap_or_default();
        let timeout = Duration::from_millis(s.timeout_ms);
        let what = format!("Modbus source '{}'", s.name);
        let unit = s.unit_id.unwrap_or(1);
        let mut client = Client::connect(&what, &address, unit, timeout)?;
        let mut first = Vec::new();
        for l in &layouts {
            let v = client
                .read(l)
                .map_err(|e| {
                    Error::io(
                        "read",
                        format!("{what} at {address}"),
                        std::io::Error::other(e),
                    )
                })
                .map_err(|e| match e {
                    // A refused read at start: the source cannot be used (exit 3).
                    Error::Io { path, source, .. } => Error::Io {
                        action: "read from",
                        path,
                        source,
                    },
                    other => other,
                })?;
            first.push((l.name.clone(), v));
        }
        let shared = Arc::new(Mutex::new(Shared {
            values: first,
            at: Some(Instant::now()),
            fresh: true,
            problem: None,
            quit: false,
        }));
        let period = Duration::from_millis(s.period_ms.unwrap_or(config.cycle.period_ms).max(1));
        let poller = shared.clone();
        let thread = std::thread::Builder::new()
            .name(format!("modbus-{}", s.name))
            .spawn(move || {
                poll_loop(
                    client, layouts, poller, period, what, address, unit, timeout,
                )
            })
            .map_err(|e| Error::io("start the poller of", &s.name, e))?;
        Ok(ModbusSource {
            name: s.name.clone(),
            channels: s.channels.iter().map(|c| c.name.clone()).collect(),
            shared,
            snap: Snapshot::default(),
            thread: Some(thread),
        })
    }
}

#[allow(clippy::too_many_arguments)]
fn poll_loop(
    client: Client,
    layouts: Vec<Layout>,
    shared: Arc<Mutex<Shared>>,
    period: Duration,
    what: String,
    address: String,
    unit: u8,
    timeout: Duration,
) {
    let mut client = Some(client);
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
        if client.is_none() {
            client = Client::connect(&what, &address, unit, timeout).ok();
        }
        let Some(c) = client.as_mut() else {
            if let Ok(mut s) = shared.lock() {
                s.problem = Some(format!("cannot connect to {address}"));
            }
            continue;
        };
        let mut values = Vec::with_capacity(layouts.len());
        let mut failed = None;
        for l in &layouts {
            match c.read(l) {
                Ok(v) => values.push((l.name.clone(), v)),
                Err(e) => {
                    failed = Some(e);
                    break;
                }
            }
        }
        let Ok(mut s) = shared.lock() else { return };
        match failed {
            None => {
                s.values = values;
                s.at = Some(Instant::now());
                s.fresh = true;
                s.problem = None;
            }
            Some(e) => {
                s.problem = Some(e);
                // Reconnect next time: the connection may be gone.
                drop(s);
                client = None;
            }
        }
    }
}

impl Source for ModbusSource {
    fn name(&self) -> &str {
        &self.name
    }
    fn kind(&self) -> &'static str {
        "modbus"
    }
    fn channel_names(&self) -> Vec<String> {
        self.channels.clone()
    }
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
        for (name, v) in &s.values {
            let value = match v {
                ReadValue::Number(x) => Value::Number(*x),
                ReadValue::Flag(b) => Value::Flag(*b),
            };
            self.snap.set(name, value, at_s);
        }
        self.snap.last_ok_s = Some(at_s);
    }
    fn snapshot(&self) -> &Snapshot {
        &self.snap
    }
}

impl Drop for ModbusSource {
    fn drop(&mut self) {
        if let Ok(mut s) = self.shared.lock() {
            s.quit = true;
        }
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}
