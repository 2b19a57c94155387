//! errmap's part maps: probe files read and cleaned (`probe`), scattered points interpolated
//! (`interp`), one small network per part (`nn`) trained on the CPU or in WGSL compute shaders
//! through wgpu (`gpu`, chosen by `backend`), and the fitted maps with their family statistics
//! and files (`map`).
#![forbid(unsafe_code)]
#![warn(missing_docs)]
#![deny(rustdoc::broken_intra_doc_links)]

pub mod backend;
mod error;
pub mod gpu;
pub mod interp;
pub mod map;
pub mod nn;
pub mod probe;
mod setting;

pub use error::{GridError, MapError, ProbeError};
pub use setting::Setting;
