//! errmap's machine analyses, each reading its instrument's files and writing figures, charts
//! and tables: laser-interferometer axes by ISO 230-2, GB and VDI (`linear`), thermal error and
//! the composite model (`thermal`), rotary axes from sphere probing (`rotary`), circular tests by
//! ISO 230-4 (`circular`), and the compensation tables of each controller (`controller`).
#![forbid(unsafe_code)]
#![warn(missing_docs)]
#![deny(rustdoc::broken_intra_doc_links)]

pub mod circular;
pub mod controller;
mod error;
pub mod linear;
pub mod rotary;
mod setting;
pub mod thermal;

pub use error::{CircularError, LinearError, RotaryError, TableError, ThermalError};
pub use setting::Setting;
