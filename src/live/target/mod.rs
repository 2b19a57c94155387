//! Targets: where the compensation goes. A line target (Sinumerik K3) takes the thermal line
//! (offset, slope, reference position); a point target (LinuxCNC external offsets, a generic
//! node or register) takes the value at the axis's present position.

pub mod modbus;
pub mod opcua;

use super::axis::Line;
use crate::error::Result;

/// What is written for one axis this cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Output {
    pub line: Line,
    pub px_mm: f64,
    /// The compensation at the axis's position (µm), geometric part included when configured;
    /// None without a position.
    pub value_um: Option<f64>,
}

/// What the controller holds now, read at start so the loop ramps from it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Present {
    Line(Line),
    Value(f64),
    /// Sinumerik K3 setting data: SD43900 (mm), SD43910, SD43920 (mm).
    K3 {
        abs_mm: f64,
        slope: f64,
        reference_mm: f64,
    },
}

pub trait Target: Send {
    fn name(&self) -> &str;
    fn kind(&self) -> &'static str;
    /// Writes a value at the axis's position (needs the position channel).
    fn is_point(&self) -> bool;
    /// The controller's present compensation of an axis.
    fn present(&mut self, axis: &str) -> Result<Present>;
    /// Write an axis's compensation.
    fn write(&mut self, axis: &str, output: &Output) -> Result<()>;
}
