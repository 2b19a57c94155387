//! `errmap live`: the composite thermal model applied while the machine works. Temperatures,
//! coolant state and axis positions come in from sources (a CSV stream, Modbus TCP, OPC UA,
//! LinuxCNC HAL pins), each cycle computes every axis's compensation from its fitted model, the
//! safety rules bound
//! and rate-limit it, targets write it into the controller, and every cycle is logged into the
//! temperature history store, with a state file for the monitor (`errmap serve`).
#![forbid(unsafe_code)]
#![warn(missing_docs)]
#![deny(rustdoc::broken_intra_doc_links)]

pub mod alarms;
pub mod axis;
pub mod bench;
pub mod config;
pub mod cycle;
mod error;
pub mod filter;
pub mod hal;
pub mod log;
pub mod modbus;
pub mod opcua;
pub mod plausibility;
pub mod replay;
mod setting;
pub mod source;
pub mod state;
pub mod target;

pub use config::LiveConfig;
pub use cycle::{run, RunOptions, RunSummary, StopFlags};
pub use error::{ConfigError, LinkError, LiveError};
pub use setting::Setting;

use config::{SourceConfig, SourceKind};
use errmap_core::error::Error;
use source::Source;
use target::Target;

/// Connect a network source (exit 3 when it cannot be reached).
fn connect_source(
    config: &LiveConfig,
    index: usize,
    s: &SourceConfig,
    kind: SourceKind,
) -> Result<Box<dyn Source>, LinkError> {
    match kind {
        SourceKind::Modbus => Ok(Box::new(source::modbus::connect(config, index, s)?)),
        SourceKind::Opcua => Ok(Box::new(source::opcua::connect(config, index, s)?)),
        SourceKind::Linuxcnc => Ok(Box::new(source::linuxcnc::connect(config, index, s)?)),
        SourceKind::Csv => Err(LinkError::Internal(Error::Internal(
            "a csv source is opened by the loop".into(),
        ))),
    }
}

/// Connect every target an axis names (exit 3 when one cannot be reached).
fn connect_targets(config: &LiveConfig) -> Result<Vec<Box<dyn Target>>, LinkError> {
    let mut targets: Vec<Box<dyn Target>> = Vec::new();
    for (i, t) in config.targets.iter().enumerate() {
        if !config
            .axes
            .iter()
            .any(|a| a.target.as_deref() == Some(t.name.as_str()))
        {
            continue;
        }
        match t.kind {
            config::TargetKind::ModbusRegisters => targets.push(Box::new(
                target::modbus::ModbusTarget::connect(config, i, t)?,
            )),
            config::TargetKind::SinumerikOpcua | config::TargetKind::OpcuaNodes => {
                targets.push(Box::new(target::opcua::OpcUaTarget::connect(config, i, t)?))
            }
            config::TargetKind::Linuxcnc => targets.push(Box::new(
                target::linuxcnc::LinuxCncTarget::connect(config, i, t)?,
            )),
        }
    }
    Ok(targets)
}
