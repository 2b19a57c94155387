//! Thermal positioning error of linear axes: cold/warm difference (seed 000), the composite geometric + thermal model (seed 004), sensors and the temperature store.

pub mod campaign;
pub(crate) mod charts;
pub mod commands;
pub mod compensate;
pub(crate) mod difference;
pub(crate) mod evaluate;
pub mod filter;
pub(crate) mod lsq;
pub mod model;
pub(crate) mod outputs;
pub mod pt100;
pub(crate) mod runs;
pub mod sample;
pub mod sensors;
pub mod store;
pub mod text;

pub use crate::error::ThermalError;
pub use campaign::{Campaign, Direction, LaserPoint, Measurement};
pub use model::{fit, FitOptions, ThermalModel, ThermalState};
