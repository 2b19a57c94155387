//! Sources of live readings. Each source keeps the newest reading of each of its channels with
//! the loop time it arrived at; the cycle polls every source once and judges freshness (the
//! watchdog) from those times.

pub mod csv;
pub mod linuxcnc;
pub mod modbus;
pub mod opcua;
pub mod poll;

use std::collections::HashMap;

/// A channel's value as the source delivered it.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    /// A number (a register's engineering value, a CSV field that parses as one).
    Number(f64),
    /// A bit (a coil or discrete input).
    Flag(bool),
    /// Text as delivered (a CSV field that is not a number, e.g. a coolant label or `+`/`-`).
    Text(String),
}

impl Value {
    /// The value as a number: a bit as 1 or 0, text parsed after trimming; None for text that is
    /// not a number.
    pub fn as_number(&self) -> Option<f64> {
        match self {
            Value::Number(v) => Some(*v),
            Value::Flag(b) => Some(if *b { 1.0 } else { 0.0 }),
            Value::Text(t) => t.trim().parse().ok(),
        }
    }
}

/// The newest value of a channel and the loop time (s) it arrived at.
#[derive(Debug, Clone, PartialEq)]
pub struct Reading {
    /// The channel's newest value.
    pub value: Value,
    /// The loop time it arrived at (s).
    pub at_s: f64,
    /// Counts the readings of this channel: a new one has a larger sequence number.
    pub seq: u64,
}

/// What a source holds now.
#[derive(Debug, Clone, Default)]
pub struct Snapshot {
    /// Channel name → its newest reading.
    pub channels: HashMap<String, Reading>,
    /// Loop time of the last complete, good update (s).
    pub last_ok_s: Option<f64>,
    /// The last thing that went wrong, until the next good update.
    pub problem: Option<String>,
}

impl Snapshot {
    /// Store one channel's new value.
    pub fn set(&mut self, channel: &str, value: Value, at_s: f64) {
        match self.channels.get_mut(channel) {
            Some(r) => {
                r.value = value;
                r.at_s = at_s;
                r.seq += 1;
            }
            None => {
                self.channels.insert(
                    channel.to_string(),
                    Reading {
                        value,
                        at_s,
                        seq: 1,
                    },
                );
            }
        }
    }
}

/// A live source.
/// A source of live readings (a CSV stream, a Modbus device), polled once per cycle.
pub trait Source: Send {
    /// The source's name in the config.
    fn name(&self) -> &str;
    /// `csv`, `modbus`, `opcua`, `linuxcnc`.
    fn kind(&self) -> &'static str;
    /// The channels it can deliver (checked against the config at start).
    fn channel_names(&self) -> Vec<String>;
    /// Take in what has arrived by loop time `now_s` (never blocks for long).
    fn poll(&mut self, now_s: f64);
    /// The newest readings and health, as of the last [`poll`](Source::poll).
    fn snapshot(&self) -> &Snapshot;
    /// A replay whose data is used up.
    fn finished(&self) -> bool {
        false
    }
    /// Loop time of the first data row of a replay (s).
    fn replay_start_s(&self) -> Option<f64> {
        None
    }
}
