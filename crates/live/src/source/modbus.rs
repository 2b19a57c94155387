//! A Modbus TCP source: a thread polls every channel each `period_ms` and hands the newest
//! values to the loop; a failed poll is the source's problem (the watchdog sees its age grow)
//! and the thread reconnects on the next poll.

use super::poll::{poll_period, Device, Failure, PolledSource};
use super::Value;
use crate::config::{LiveConfig, SourceConfig};
use crate::modbus::{Client, Layout, ReadValue, Table};
use crate::LinkError;
use errmap_core::error::Result;
use std::time::Duration;

/// The device behind the source: how to connect again and the channels' layouts.
struct Rack {
    what: String,
    address: String,
    unit: u8,
    timeout: Duration,
    layouts: Vec<Layout>,
}

impl Device for Rack {
    type Link = Client;
    fn reconnect(&self) -> Option<Client> {
        Client::connect(&self.what, &self.address, self.unit, self.timeout).ok()
    }
    fn unreachable(&self) -> String {
        format!("cannot connect to {}", self.address)
    }
    fn read(&self, client: &mut Client) -> std::result::Result<Vec<Value>, Failure> {
        self.layouts
            .iter()
            .map(|l| client.read(l).map(value))
            // Reconnect next time: the connection may be gone.
            .collect::<std::result::Result<Vec<_>, String>>()
            .map_err(|message| Failure {
                message,
                reconnect: true,
            })
    }
}

fn value(v: ReadValue) -> Value {
    match v {
        ReadValue::Number(x) => Value::Number(x),
        ReadValue::Flag(b) => Value::Flag(b),
    }
}

/// Check the channel layouts, connect, read every channel once (a device that cannot be
/// reached or refuses a channel is exit 3), then start polling.
pub fn connect(
    config: &LiveConfig,
    index: usize,
    s: &SourceConfig,
) -> Result<PolledSource, LinkError> {
    let key = format!("sources.{index}");
    let layouts = s
        .channels
        .iter()
        .enumerate()
        .map(|(j, c)| Layout::parse(config, &format!("{key}.channels.{j}"), c, Table::Input))
        .collect::<Result<Vec<_>>>()?;
    let rack = Rack {
        what: format!("Modbus source '{}'", s.name),
        address: s.address.clone().unwrap_or_default(),
        unit: s.unit_id.unwrap_or(1),
        timeout: Duration::from_millis(s.timeout_ms),
        layouts,
    };
    let client = Client::connect(&rack.what, &rack.address, rack.unit, rack.timeout)?;
    let place = format!("{} at {}", rack.what, rack.address);
    let names = s.channels.iter().map(|c| c.name.clone()).collect();
    let period = poll_period(config, s);
    Ok(PolledSource::start(
        "modbus", &s.name, &place, names, rack, client, period,
    )?)
}
