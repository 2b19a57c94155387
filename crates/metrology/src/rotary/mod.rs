//! Rotary axes: sphere fits, double-vector angular error (seed 003), axis location and compensation tables.
//!
//! Data flow: [`read_measurement`] (centres or touch points) → [`fit_sphere`] per sphere and
//! position → vector a = c2 − c1 at the reference angle and b at each α → β by
//! [`signed_angle_about`] → err = α − β per position, averaged over repeats ([`analyze`]) →
//! tables for controllers ([`build_table`], [`render`]), a text report ([`text_report()`]) and a
//! chart (`chart::save_error_chart`). [`commands`] runs each `rotary` command as one call.

pub mod analysis;
pub(crate) mod angle;
pub(crate) mod axis_fit;
pub(crate) mod chart;
pub mod commands;
pub mod input;
pub mod sphere;
pub(crate) mod table;
pub(crate) mod text_report;

pub use crate::error::RotaryError;
pub use analysis::{analyze, Analysis, AnalyzeOptions, AxisReport, Observation, Sign, TableRow};
pub use angle::{angle_error_arcsec, signed_angle_about, wrap_deg};
pub use axis_fit::{fit_axis, AxisFit, CircleFit};
pub use input::{read_measurement, Direction, Measurement, Position, RotaryAxis};
pub use sphere::{fit_sphere, SphereFit, SphereFitError};
pub use table::{
    build_table, render, table_from_rows, CompTable, TableFormat, TableOptions, INTERPOLATION,
};
pub use text_report::text_report;
