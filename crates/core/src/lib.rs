//! errmap's ground floor, shared by every other crate: the error type with file, line and
//! column, atomic output that never lands over an input, CSV reading with line numbers, the
//! machine axes and map plane, least squares and the formatting of written numbers, the progress
//! a long call reports, and the approach direction of linear, rotary and thermal data.
#![forbid(unsafe_code)]
#![warn(missing_docs)]
#![deny(rustdoc::broken_intra_doc_links)]

pub mod core_setting;
pub mod direction;
pub mod error;
pub mod geom;
pub mod io;
pub mod numeric;
pub mod progress;
pub mod setting;

pub use error::{Diagnose, Diagnostic, Error, Location, Result};
pub use setting::Setting;
