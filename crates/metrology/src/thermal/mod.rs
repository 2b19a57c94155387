//! Thermal positioning error of linear axes: cold/warm difference (seed 000), the composite geometric + thermal model (seed 004), sensors and the temperature store.

pub mod campaign;
pub mod charts;
pub mod commands;
pub mod compensate;
pub mod difference;
pub mod evaluate;
pub mod filter;
pub mod lsq;
pub mod model;
pub mod outputs;
pub mod pt100;
pub mod runs;
pub mod sample;
pub mod sensors;
pub mod store;
pub mod text;

pub use campaign::{Campaign, Direction, LaserPoint, Measurement};
pub use model::{fit, FitOptions, ThermalModel, ThermalState};
