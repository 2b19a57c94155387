//! Generators of sample data with known ground truth, for every kind of measurement errmap reads.

pub mod circular;
pub mod linear;
pub mod rotary;
/// The training workload of throughput measurements (kept under this name for callers).
pub use crate::nn::workload as training;
/// Thermal campaigns with known truth (generated beside the analysis that reads them).
pub use crate::thermal::sample as thermal;
pub mod web_plate;
pub mod web_plate_args;
