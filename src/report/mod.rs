//! Pictures and reports: the shared chart plumbing (fonts, PNG output) and the heatmaps and charts built on it.

pub mod chart;
pub mod colormap;
pub mod heatmap;
