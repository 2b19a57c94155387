//! Targets: where the compensation goes. A line target (Sinumerik K3) takes the thermal line
//! (offset, slope, reference position); a point target (LinuxCNC external offsets, a generic
//! node or register) takes the value at the axis's present position.

pub mod linuxcnc;
pub mod modbus;
pub mod opcua;

use super::axis::Line;
use errmap_core::error::Result;

/// What is written for one axis this cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Output {
    /// The written thermal line (compensation sign: offset about Px and slope), for a line target.
    pub line: Line,
    /// The line's reference point Px (mm, machine coordinates: the model's).
    pub px_mm: f64,
    /// The compensation at the axis's position (µm), geometric part included when configured;
    /// None without a position.
    pub value_um: Option<f64>,
}

/// What the controller holds now, read at start so the loop ramps from it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Present {
    /// A line target's present thermal line (offset and slope about Px).
    Line(Line),
    /// A point target's present compensation value (µm; taken as the line's offset, the start
    /// ramps from it).
    Value(f64),
    /// Sinumerik K3 setting data: SD43900 (mm), SD43910, SD43920 (mm).
    K3 {
        /// SD43900, the position-independent value, mm.
        abs_mm: f64,
        /// SD43910, the slope of the position-dependent line (tanβ, mm per mm).
        slope: f64,
        /// SD43920, the reference position Px of the line, machine coordinates, mm.
        reference_mm: f64,
    },
}

/// A controller interface the compensation is written to, one connection per `[[targets]]`
/// entry.
pub trait Target: Send {
    /// The target's name in the config.
    fn name(&self) -> &str;
    /// The target's kind, as the config spells it (`modbus-registers`, ...).
    fn kind(&self) -> &'static str;
    /// Writes a value at the axis's position (needs the position channel).
    fn is_point(&self) -> bool;
    /// The controller's present compensation of an axis.
    fn present(&mut self, axis: &str) -> Result<Present>;
    /// Write an axis's compensation.
    fn write(&mut self, axis: &str, output: &Output) -> Result<()>;
    /// The controller's present compensation of an axis when it is no longer what errmap last
    /// wrote (LinuxCNC zeroes its external offsets at machine-on and drops changes while the
    /// machine is off); the loop then ramps from it as at a start. Asked before each cycle's
    /// write; None when the controller holds what errmap wrote (and for targets that cannot
    /// change on their own).
    fn moved(&mut self, _axis: &str) -> Result<Option<Present>> {
        Ok(None)
    }
}
