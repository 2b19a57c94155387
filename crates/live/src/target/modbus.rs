//! A Modbus register-write target (a PLC gateway): per axis, the compensation at the axis's
//! position written into holding registers (type, word order and scale per axis: the register
//! holds value/scale counts), read back at start so the loop ramps from the present value.

use super::{Output, Present, Target};
use crate::config::{ChannelConfig, LiveConfig, TargetConfig};
use crate::modbus::{Client, Layout, Table};
use crate::LinkError;
use errmap_core::error::{Error, Result};
use std::collections::BTreeMap;
use std::time::Duration;

/// A connected PLC gateway: per axis, a holding-register layout (default type `s32`, µm per
/// count as `scale`) written with the compensation at the axis's position.
pub struct ModbusTarget {
    name: String,
    address: String,
    unit_id: u8,
    client: Client,
    axes: BTreeMap<String, Layout>,
}

impl ModbusTarget {
    /// Connect to the gateway of `[[targets]]` entry `index` (unit id default 1, 1 s timeout),
    /// with each axis's register layout checked; exit 2 for a bad key, exit 3 when it cannot be
    /// reached.
    pub fn connect(
        config: &LiveConfig,
        index: usize,
        t: &TargetConfig,
    ) -> Result<ModbusTarget, LinkError> {
        let key = format!("targets.{index}");
        let address = t.address.clone().ok_or_else(|| {
            config.key_error(
                &key,
                "a modbus-registers target needs 'address'",
                "address = \"host:port\"",
            )
        })?;
        let mut axes = BTreeMap::new();
        for (axis, a) in &t.axes {
            let channel = ChannelConfig {
                name: axis.clone(),
                table: Some("holding".into()),
                register: a.register,
                data_type: a.data_type.clone().or(Some("s32".into())),
                word_order: a.word_order.clone(),
                scale: a.scale,
                offset: None,
                node: None,
                pin: None,
            };
            axes.insert(
                axis.clone(),
                Layout::parse(
                    config,
                    &format!("{key}.axes.{axis}"),
                    &channel,
                    Table::Holding,
                )?,
            );
        }
        let timeout = Duration::from_millis(1000);
        let client = Client::connect(
            &format!("Modbus target '{}'", t.name),
            &address,
            t.unit_id.unwrap_or(1),
            timeout,
        )?;
        Ok(ModbusTarget {
            name: t.name.clone(),
            address,
            unit_id: t.unit_id.unwrap_or(1),
            client,
            axes,
        })
    }

    fn layout(&self, axis: &str) -> Result<&Layout> {
        self.axes.get(axis).ok_or_else(|| {
            Error::usage(
                format!("target '{}' has no register for axis {axis}", self.name),
                format!("add [targets.axes.{axis}] with register = N"),
            )
        })
    }
}

impl Target for ModbusTarget {
    fn name(&self) -> &str {
        &self.name
    }
    fn kind(&self) -> &'static str {
        "modbus-registers"
    }
    fn is_point(&self) -> bool {
        true
    }
    fn present(&mut self, axis: &str) -> Result<Present> {
        let l = self.layout(axis)?.clone();
        match self.client.read(&l) {
            Ok(crate::modbus::ReadValue::Number(v)) => Ok(Present::Value(v)),
            Ok(_) => Err(Error::Internal("a holding register read as a bit".into())),
            Err(e) => Err(Error::io(
                "read from",
                format!("Modbus target '{}' at {}", self.name, self.client.address),
                std::io::Error::other(e),
            )),
        }
    }
    fn write(&mut self, axis: &str, output: &Output) -> Result<()> {
        let l = self.layout(axis)?.clone();
        let value = output
            .value_um
            .ok_or_else(|| Error::usage("no position", "the axis needs a position channel"))?;
        let words = l.encode(value).map_err(|e| {
            Error::usage(format!("axis {axis}: {e}"), "choose a larger scale or type")
        })?;
        let failed = match self.client.write(l.register, &words) {
            Ok(()) => return Ok(()),
            Err(e) => e,
        };
        // The connection may be gone (a restarted gateway): connect again for the next try.
        if let Ok(c) = Client::connect(
            &self.name,
            &self.address,
            self.unit_id,
            Duration::from_millis(1000),
        ) {
            self.client = c;
        }
        Err(Error::io(
            "write to",
            format!("Modbus target '{}'", self.name),
            std::io::Error::other(failed),
        ))
    }
}
