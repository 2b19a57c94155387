//! errmap: error maps and compensation for CNC machine tools and the parts they cut.
//!
//! - Part families: probe points → gross errors rejected → natural-neighbour training set →
//!   one small network per part (GPU or CPU) → dense error maps, heatmaps, compensated toolpaths.
//! - Linear axes: laser runs → ISO 230-2 / GB / VDI figures, air and material correction,
//!   pitch-error fits, bidirectional compensation tables.
//! - Thermal error: cold/warm difference and the composite geometric + thermal model.
//! - Rotary axes: double-vector angular error, axis location and tables.
//! - Circular tests (ISO 230-4): circular deviation, hysteresis and a diagnosis of axis errors.
#![forbid(unsafe_code)]
#![deny(rustdoc::broken_intra_doc_links)]

pub mod backend;
pub mod batch;
pub mod circular;
pub mod controller;
pub mod direction;
pub mod error;
pub mod geom;
pub mod gpu;
pub mod interp;
pub mod io;
pub mod linear;
pub mod map;
pub mod nn;
pub mod numeric;
pub mod probe;
pub mod progress;
pub mod report;
pub mod rotary;
pub mod serve;
pub mod synth;
pub mod thermal;
pub mod toolpath;

pub use error::{Error, Location, Result};
