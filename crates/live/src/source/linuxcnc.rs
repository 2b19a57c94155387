//! A LinuxCNC source: HAL pins (axis positions, velocities for the direction, a temperature
//! component's outputs) read through errmap's HAL component (`crate::hal`) by a thread each
//! `period_ms`; value = `scale`·pin + `offset` for numbers, bits as bits. A failed read is the
//! source's problem (the watchdog sees its age grow) and the thread starts the helper again.

use super::{Snapshot, Source, Value};
use crate::config::{LiveConfig, SourceConfig};
use crate::hal::{HalLink, HalValue};
use errmap_core::error::Result;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// The Python of a Debian LinuxCNC, which has its `hal` module.
pub const DEFAULT_PYTHON: &str = "/usr/bin/python3";

#[derive(Default)]
struct Shared {
    values: Vec<HalValue>,
    at: Option<Instant>,
    fresh: bool,
    problem: Option<String>,
    quit: bool,
}

/// How a channel's pin becomes its value.
#[derive(Clone)]
struct Channel {
    name: String,
    scale: f64,
    offset: f64,
}

/// How to start the helper (again).
struct Helper {
    what: String,
    python: String,
    component: String,
    timeout: Duration,
}

impl Helper {
    fn start(&self) -> Result<HalLink> {
        HalLink::start(&self.what, &self.python, &self.component, &[], self.timeout)
    }
}

/// A source whose channels are LinuxCNC HAL pins.
pub struct LinuxCncSource {
    name: String,
    channels: Vec<Channel>,
    shared: Arc<Mutex<Shared>>,
    snap: Snapshot,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl LinuxCncSource {
    /// Start errmap's HAL component for `sources[index]` and read every pin once (a LinuxCNC
    /// that is not running, a missing pin: exit 3), then poll.
    pub fn connect(config: &LiveConfig, index: usize, s: &SourceConfig) -> Result<LinuxCncSource> {
        let key = format!("sources.{index}");
        let mut pins = Vec::new();
        let mut channels = Vec::new();
        for (j, c) in s.channels.iter().enumerate() {
            let k = format!("{key}.channels.{j}");
            let pin = c.pin.clone().ok_or_else(|| {
                config.key_error(
                    &k,
                    format!("channel '{}' has no pin", c.name),
                    "pin = \"axis.z.pos-cmd\"",
                )
            })?;
            if pin.is_empty() || pin.chars().any(|ch| ch.is_whitespace() || ch == '=') {
                return Err(config.key_error(
                    &format!("{k}.pin"),
                    format!("'{pin}' is not a HAL name"),
                    "e.g. axis.z.pos-cmd",
                ));
            }
            for (field, present) in [
                ("table", c.table.is_some()),
                ("register", c.register.is_some()),
                ("type", c.data_type.is_some()),
                ("word_order", c.word_order.is_some()),
                ("node", c.node.is_some()),
            ] {
                if present {
                    return Err(config.key_error(
                        &format!("{k}.{field}"),
                        format!("a linuxcnc channel has no key '{field}'"),
                        "its keys: name, pin, scale, offset",
                    ));
                }
            }
            pins.push(pin);
            channels.push(Channel {
                name: c.name.clone(),
                scale: c.scale.unwrap_or(1.0),
                offset: c.offset.unwrap_or(0.0),
            });
        }
        let helper = Helper {
            what: format!("LinuxCNC source '{}'", s.name),
            python: s.python.clone().unwrap_or_else(|| DEFAULT_PYTHON.into()),
            component: s
                .component
                .clone()
                .unwrap_or_else(|| format!("errmap-{}", s.name)),
            timeout: Duration::from_millis(s.timeout_ms),
        };
        let mut link = helper.start()?;
        let first = link.get(&pins).map_err(|e| {
            errmap_core::error::Error::io("read from", &helper.what, std::io::Error::other(e))
        })?;
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
            .name(format!("linuxcnc-{}", s.name))
            .spawn(move || poll_loop(link, helper, pins, poller, period))
            .map_err(|e| errmap_core::error::Error::io("start the poller of", &s.name, e))?;
        Ok(LinuxCncSource {
            name: s.name.clone(),
            channels,
            shared,
            snap: Snapshot::default(),
            thread: Some(thread),
        })
    }
}

fn poll_loop(
    link: HalLink,
    helper: Helper,
    pins: Vec<String>,
    shared: Arc<Mutex<Shared>>,
    period: Duration,
) {
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
            link = helper.start().ok();
        }
        let result = match link.as_mut() {
            Some(l) => l.get(&pins),
            None => Err(format!("cannot start {}", helper.what)),
        };
        let Ok(mut s) = shared.lock() else { return };
        match result {
            Ok(values) => {
                s.values = values;
                s.at = Some(Instant::now());
                s.fresh = true;
                s.problem = None;
            }
            Err(e) => {
                s.problem = Some(e);
                drop(s);
                // The helper may be gone (LinuxCNC restarted): start it again next time.
                link = None;
            }
        }
    }
}

impl Source for LinuxCncSource {
    fn name(&self) -> &str {
        &self.name
    }
    fn kind(&self) -> &'static str {
        "linuxcnc"
    }
    fn channel_names(&self) -> Vec<String> {
        self.channels.iter().map(|c| c.name.clone()).collect()
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
        for (c, v) in self.channels.iter().zip(&s.values) {
            let value = match v {
                HalValue::Bit(b) => Value::Flag(*b),
                other => Value::Number(c.scale * other.as_f64() + c.offset),
            };
            self.snap.set(&c.name, value, at_s);
        }
        self.snap.last_ok_s = Some(at_s);
    }
    fn snapshot(&self) -> &Snapshot {
        &self.snap
    }
}

impl Drop for LinuxCncSource {
    fn drop(&mut self) {
        if let Ok(mut s) = self.shared.lock() {
            s.quit = true;
        }
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}
