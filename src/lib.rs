//! errmap: error maps and compensation for CNC machine tools and the parts they cut.
//!
//! - Part families: probe points → gross errors rejected → natural-neighbour training set →
//!   one small network per part (GPU or CPU) → dense error maps, heatmaps, compensated toolpaths.
//! - Linear axes: laser runs → ISO 230-2 / GB / VDI figures, air and material correction,
//!   pitch-error fits, bidirectional compensation tables.
//! - Thermal error: cold/warm difference and the composite geometric + thermal model.
//! - Rotary axes: double-vector angular error, axis location and tables.
//! - Circular tests (ISO 230-4): circular deviation, hysteresis and a diagnosis of axis errors.
//!
//! This crate gathers the workspace's library crates under one name, one module per area, so a
//! program (and errmap's own binary and tests) writes `errmap::toolpath::…` whichever crate
//! holds it; docs/architecture.md draws the crates and what each owns.
#![forbid(unsafe_code)]
#![warn(missing_docs)]
#![deny(rustdoc::broken_intra_doc_links)]

pub use errmap_batch as batch;
pub use errmap_core::{direction, error, geom, io, numeric, progress, setting};
pub use errmap_live as live;
pub use errmap_maps::{backend, gpu, interp, map, nn, probe};
pub use errmap_metrology::{circular, controller, linear, rotary, thermal};
pub use errmap_report as report;
pub use errmap_serve as serve;
pub use errmap_synth as synth;
pub use errmap_toolpath as toolpath;

pub use error::{Diagnose, Diagnostic, Error, Location, Result};
