//! A LinuxCNC source: HAL pins (axis positions, velocities for the direction, a temperature
//! component's outputs) read through errmap's HAL component (`crate::hal`) by a thread each
//! `period_ms`; value = `scale`·pin + `offset` for numbers, bits as bits. A failed read is the
//! source's problem (the watchdog sees its age grow) and the thread starts the helper again.

use super::poll::{poll_period, Device, Failure, PolledSource};
use super::Value;
use crate::config::{LiveConfig, SourceConfig};
use crate::hal::{HalLink, HalValue};
use crate::LinkError;
use errmap_core::error::Result;
use std::time::Duration;

/// The Python of a Debian LinuxCNC, which has its `hal` module.
pub const DEFAULT_PYTHON: &str = "/usr/bin/python3";

/// How a channel's pin becomes its value.
#[derive(Clone)]
struct Channel {
    name: String,
    scale: f64,
    offset: f64,
}

/// How to start the helper (again), and the pins to read as channels.
struct Helper {
    what: String,
    python: String,
    component: String,
    timeout: Duration,
    pins: Vec<String>,
    channels: Vec<Channel>,
}

impl Helper {
    fn start(&self) -> Result<HalLink> {
        HalLink::start(&self.what, &self.python, &self.component, &[], self.timeout)
    }
}

/// Start errmap's HAL component for `sources[index]` and read every pin once (a LinuxCNC
/// that is not running, a missing pin: exit 3), then poll.
pub fn connect(
    config: &LiveConfig,
    index: usize,
    s: &SourceConfig,
) -> Result<PolledSource, LinkError> {
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
            return Err(LinkError::Config(config.key_error(
                &format!("{k}.pin"),
                format!("'{pin}' is not a HAL name"),
                "e.g. axis.z.pos-cmd",
            )));
        }
        for (field, present) in [
            ("table", c.table.is_some()),
            ("register", c.register.is_some()),
            ("type", c.data_type.is_some()),
            ("word_order", c.word_order.is_some()),
            ("node", c.node.is_some()),
        ] {
            if present {
                return Err(LinkError::Config(config.key_error(
                    &format!("{k}.{field}"),
                    format!("a linuxcnc channel has no key '{field}'"),
                    "its keys: name, pin, scale, offset",
                )));
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
        pins,
        channels,
    };
    let link = helper.start()?;
    let place = helper.what.clone();
    let names = helper.channels.iter().map(|c| c.name.clone()).collect();
    let period = poll_period(config, s);
    Ok(PolledSource::start(
        "linuxcnc", &s.name, &place, names, helper, link, period,
    )?)
}

impl Device for Helper {
    type Link = HalLink;
    fn reconnect(&self) -> Option<HalLink> {
        self.start().ok()
    }
    fn unreachable(&self) -> String {
        format!("cannot start {}", self.what)
    }
    fn read(&self, link: &mut HalLink) -> std::result::Result<Vec<Value>, Failure> {
        let values = link.get(&self.pins).map_err(|message| Failure {
            message,
            // The helper may be gone (LinuxCNC restarted): start it again next time.
            reconnect: true,
        })?;
        Ok(self
            .channels
            .iter()
            .zip(values)
            .map(|(c, v)| match v {
                HalValue::Bit(b) => Value::Flag(b),
                other => Value::Number(c.scale * other.as_f64() + c.offset),
            })
            .collect())
    }
}
