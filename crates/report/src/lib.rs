//! Pictures and reports: the shared chart plumbing (fonts, PNG output), the heatmaps and charts built on it, and the self-contained `report.html`.
#![forbid(unsafe_code)]
#![warn(missing_docs)]
#![deny(rustdoc::broken_intra_doc_links)]

pub mod chart;
pub mod colormap;
mod error;
pub mod heatmap;
pub mod html;
pub mod pdf;
pub mod result;
mod setting;

pub use error::ReportError;
pub use setting::Setting;
