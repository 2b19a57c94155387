//! Modbus TCP (crate `tokio-modbus`, its blocking client): the register and coil layout of a
//! channel — table (input or holding registers, coils, discrete inputs), 0-based address,
//! 16- or 32-bit, signed, unsigned or IEEE 754 float, word order of 32-bit values, scale and
//! offset — shared by the source (temperature input modules) and the register-write target.
//!
//! Modbus Application Protocol V1.1b3: registers are 16-bit big-endian words; a 32-bit value
//! spans two registers, and which comes first is the device's choice (`word_order`).

use super::config::{ChannelConfig, LiveConfig};
use errmap_core::error::{Error, Result};
use std::net::{SocketAddr, ToSocketAddrs};
use std::time::Duration;
use tokio_modbus::client::sync::{tcp, Context, Reader, Writer};
use tokio_modbus::Slave;

/// Where a channel lives.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Table {
    /// Input registers (function code 4, read-only 16-bit words).
    Input,
    /// Holding registers (function codes 3 and 16, read-write 16-bit words).
    Holding,
    /// Coils (function code 1, read-write bits).
    Coil,
    /// Discrete inputs (function code 2, read-only bits).
    Discrete,
}

/// How a register value is encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DataType {
    /// Unsigned 16-bit integer, one register.
    U16,
    /// Two's-complement signed 16-bit integer, one register.
    S16,
    /// Unsigned 32-bit integer, two registers.
    U32,
    /// Two's-complement signed 32-bit integer, two registers.
    S32,
    /// IEEE 754 single-precision float, two registers.
    F32,
}

impl DataType {
    /// How many 16-bit registers a value of this type spans (1 or 2).
    pub fn words(self) -> u16 {
        match self {
            DataType::U16 | DataType::S16 => 1,
            _ => 2,
        }
    }
}

/// One channel's layout.
#[derive(Debug, Clone, PartialEq)]
pub struct Layout {
    /// The channel's name (a source's channel, or the axis a target writes).
    pub name: String,
    /// The table the value lives in.
    pub table: Table,
    /// The 0-based protocol address of the (first) register or bit.
    pub register: u16,
    /// The encoding of a register value (`U16` for bits, unused there).
    pub data_type: DataType,
    /// High word first.
    pub big_words: bool,
    /// Engineering units per count: value = scale·raw + offset (≠ 0; default 1).
    pub scale: f64,
    /// Added after scaling, in engineering units (default 0).
    pub offset: f64,
}

impl Layout {
    /// A channel's layout from its config; `key` is the channel's key (`sources.0.channels.2`).
    pub fn parse(
        config: &LiveConfig,
        key: &str,
        c: &ChannelConfig,
        default_table: Table,
    ) -> Result<Layout> {
        let table = match c.table.as_deref() {
            None => default_table,
            Some("input") => Table::Input,
            Some("holding") => Table::Holding,
            Some("coil") => Table::Coil,
            Some("discrete") => Table::Discrete,
            Some(other) => {
                return Err(config.key_error(
                    &format!("{key}.table"),
                    format!("'{other}' is not a Modbus table"),
                    "input, holding, coil or discrete",
                ))
            }
        };
        let register = c.register.ok_or_else(|| {
            config.key_error(
                key,
                format!("channel '{}' has no register", c.name),
                "give register = N (0-based address)",
            )
        })?;
        let bits = matches!(table, Table::Coil | Table::Discrete);
        let data_type = match (c.data_type.as_deref(), bits) {
            (None, _) => DataType::U16,
            (Some(_), true) => {
                return Err(config.key_error(
                    &format!("{key}.type"),
                    "coils and discrete inputs are single bits",
                    "remove type",
                ))
            }
            (Some("u16"), _) => DataType::U16,
            (Some("s16"), _) => DataType::S16,
            (Some("u32"), _) => DataType::U32,
            (Some("s32"), _) => DataType::S32,
            (Some("f32"), _) => DataType::F32,
            (Some(other), _) => {
                return Err(config.key_error(
                    &format!("{key}.type"),
                    format!("'{other}' is not a register type"),
                    "u16, s16, u32, s32 or f32",
                ))
            }
        };
        let big_words = match c.word_order.as_deref() {
            None | Some("big") => true,
            Some("little") => false,
            Some(other) => {
                return Err(config.key_error(
                    &format!("{key}.word_order"),
                    format!("'{other}' is not a word order"),
                    "big (high word first) or little",
                ))
            }
        };
        let scale = c.scale.unwrap_or(1.0);
        let offset = c.offset.unwrap_or(0.0);
        if !(scale.is_finite() && scale != 0.0 && offset.is_finite()) {
            return Err(config.key_error(
                &format!("{key}.scale"),
                "scale must be finite and not 0, offset finite",
                "e.g. scale = 0.1 for a module reporting tenths of a degree",
            ));
        }
        Ok(Layout {
            name: c.name.clone(),
            table,
            register,
            data_type,
            big_words,
            scale,
            offset,
        })
    }

    /// The engineering value of the words read: scale·raw + offset.
    pub fn decode(&self, words: &[u16]) -> f64 {
        let (hi, lo) = if self.big_words {
            (words[0], words.get(1).copied().unwrap_or(0))
        } else {
            (words.get(1).copied().unwrap_or(0), words[0])
        };
        let both = (u32::from(hi) << 16) | u32::from(lo);
        let raw = match self.data_type {
            DataType::U16 => f64::from(words[0]),
            DataType::S16 => f64::from(words[0] as i16),
            DataType::U32 => f64::from(both),
            DataType::S32 => f64::from(both as i32),
            DataType::F32 => f64::from(f32::from_bits(both)),
        };
        self.scale * raw + self.offset
    }

    /// The words that decode to `value` (rounded to the nearest count), or why it does not fit.
    pub fn encode(&self, value: f64) -> std::result::Result<Vec<u16>, String> {
        let raw = (value - self.offset) / self.scale;
        let fits = |lo: f64, hi: f64| {
            let r = raw.round();
            if r.is_finite() && r >= lo && r <= hi {
                Ok(r)
            } else {
                Err(format!(
                    "{value} does not fit register type {:?} at scale {}",
                    self.data_type, self.scale
                ))
            }
        };
        let both = match self.data_type {
            DataType::U16 => return Ok(vec![fits(0.0, 65535.0)? as u16]),
            DataType::S16 => return Ok(vec![fits(-32768.0, 32767.0)? as i16 as u16]),
            DataType::U32 => fits(0.0, 4_294_967_295.0)? as u32,
            DataType::S32 => fits(-2_147_483_648.0, 2_147_483_647.0)? as i32 as u32,
            DataType::F32 => {
                if !raw.is_finite() {
                    return Err(format!("{value} is not a number"));
                }
                (raw as f32).to_bits()
            }
        };
        let (hi, lo) = ((both >> 16) as u16, both as u16);
        Ok(if self.big_words {
            vec![hi, lo]
        } else {
            vec![lo, hi]
        })
    }
}

/// A connected Modbus TCP client.
pub struct Client {
    /// The device's `host:port`, as configured.
    pub address: String,
    ctx: Context,
}

/// Resolve `host:port`.
pub fn socket(address: &str) -> std::io::Result<SocketAddr> {
    address
        .to_socket_addrs()?
        .next()
        .ok_or_else(|| std::io::Error::new(std::io::ErrorKind::NotFound, "no address"))
}

impl Client {
    /// Connect (exit 3 when the device cannot be reached).
    pub fn connect(what: &str, address: &str, unit_id: u8, timeout: Duration) -> Result<Client> {
        let unreachable =
            |e: std::io::Error| Error::io("connect to", format!("{what} at {address}"), e);
        let addr = socket(address).map_err(unreachable)?;
        let ctx = tcp::connect_slave_with_timeout(addr, Slave(unit_id), Some(timeout))
            .map_err(unreachable)?;
        Ok(Client {
            address: address.to_string(),
            ctx,
        })
    }

    /// Read one channel: its value (a number, or 1/0 for a bit).
    pub fn read(&mut self, l: &Layout) -> std::result::Result<ReadValue, String> {
        let n = l.data_type.words();
        let flat = |r: tokio_modbus::Result<Vec<u16>>| -> std::result::Result<Vec<u16>, String> {
            match r {
                Ok(Ok(w)) if w.len() >= n as usize => Ok(w),
                Ok(Ok(w)) => Err(format!("{} words instead of {n}", w.len())),
                Ok(Err(code)) => Err(format!("exception {code:?}")),
                Err(e) => Err(e.to_string()),
            }
        };
        let bit = |r: tokio_modbus::Result<Vec<bool>>| -> std::result::Result<bool, String> {
            match r {
                Ok(Ok(b)) if !b.is_empty() => Ok(b[0]),
                Ok(Ok(_)) => Err("no bit returned".into()),
                Ok(Err(code)) => Err(format!("exception {code:?}")),
                Err(e) => Err(e.to_string()),
            }
        };
        let what =
            |e: String| format!("{} (register {} of {:?}): {e}", l.name, l.register, l.table);
        Ok(match l.table {
            Table::Input => ReadValue::Number(
                l.decode(&flat(self.ctx.read_input_registers(l.register, n)).map_err(what)?),
            ),
            Table::Holding => ReadValue::Number(
                l.decode(&flat(self.ctx.read_holding_registers(l.register, n)).map_err(what)?),
            ),
            Table::Coil => ReadValue::Flag(bit(self.ctx.read_coils(l.register, 1)).map_err(what)?),
            Table::Discrete => {
                ReadValue::Flag(bit(self.ctx.read_discrete_inputs(l.register, 1)).map_err(what)?)
            }
        })
    }

    /// Write holding registers.
    pub fn write(&mut self, register: u16, words: &[u16]) -> std::result::Result<(), String> {
        match self.ctx.write_multiple_registers(register, words) {
            Ok(Ok(())) => Ok(()),
            Ok(Err(code)) => Err(format!("exception {code:?} writing register {register}")),
            Err(e) => Err(format!("writing register {register}: {e}")),
        }
    }
}

/// A channel's value as read.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ReadValue {
    /// A register's engineering value (scale·raw + offset).
    Number(f64),
    /// A coil's or discrete input's bit.
    Flag(bool),
}

#[cfg(test)]
mod tests {
    use super::*;

    fn layout(t: DataType, big: bool, scale: f64, offset: f64) -> Layout {
        Layout {
            name: "T".into(),
            table: Table::Input,
            register: 0,
            data_type: t,
            big_words: big,
            scale,
            offset,
        }
    }

    #[test]
    fn decoding_by_hand() {
        // 0xFF38 as s16 is −200; scale 0.1 → −20.0 °C.
        assert_eq!(
            layout(DataType::S16, true, 0.1, 0.0).decode(&[0xFF38]),
            -20.0
        );
        assert_eq!(
            layout(DataType::U16, true, 0.1, 0.0).decode(&[0xFF38]),
            6533.6
        );
        // 21.5f32 = 0x41AC0000: high word 0x41AC first (big) or second (little).
        assert_eq!(
            layout(DataType::F32, true, 1.0, 0.0).decode(&[0x41AC, 0x0000]),
            21.5
        );
        assert_eq!(
            layout(DataType::F32, false, 1.0, 0.0).decode(&[0x0000, 0x41AC]),
            21.5
        );
        // −2 as s32 = 0xFFFFFFFE; offset 20 → 18.
        assert_eq!(
            layout(DataType::S32, true, 1.0, 20.0).decode(&[0xFFFF, 0xFFFE]),
            18.0
        );
        assert_eq!(
            layout(DataType::U32, false, 1.0, 0.0).decode(&[0x0002, 0x0001]),
            65538.0
        );
    }

    #[test]
    fn encoding_round_trips_and_refuses_overflow() {
        let l = layout(DataType::S32, false, 0.01, 0.0);
        // −12.34 µm at 0.01 µm per count is −1234 = 0xFFFFFB2E, low word first.
        assert_eq!(l.encode(-12.34).unwrap(), vec![0xFB2E, 0xFFFF]);
        assert!((l.decode(&l.encode(-12.34).unwrap()) + 12.34).abs() < 1e-12);
        assert!(layout(DataType::S16, true, 0.001, 0.0)
            .encode(40.0)
            .is_err());
        let f = layout(DataType::F32, true, 1.0, 0.0);
        assert_eq!(f.decode(&f.encode(-3.25).unwrap()), -3.25);
    }
}
