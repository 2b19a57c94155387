//! Generators of sample data with known ground truth, for every kind of measurement errmap reads.
#![forbid(unsafe_code)]
#![warn(missing_docs)]
#![deny(rustdoc::broken_intra_doc_links)]

pub mod circular;
mod error;
pub mod linear;
pub mod rotary;
pub mod scan;
mod setting;
/// The training workload of throughput measurements (kept under this name for callers).
pub use errmap_maps::nn::workload as training;
/// Thermal campaigns with known truth (generated beside the analysis that reads them).
pub use errmap_metrology::thermal::sample as thermal;
pub mod web_plate;
pub mod web_plate_args;

pub use error::SynthError;
pub use setting::Setting;
