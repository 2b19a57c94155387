//! Thermal positioning error of linear axes: cold/warm difference (seed 000), the composite geometric + thermal model (seed 004), sensors and the temperature store.

pub mod filter;
pub mod pt100;
pub mod sensors;
