//! Linear axes measured by laser interferometer: run files, positioning evaluation by standard, air and material correction, error budget, pitch-error fit, compensation tables.

mod eval;
mod runs;

pub use eval::{evaluate, AxisFigures, Evaluation, Standard, TargetFigures};
pub use runs::{
    parse_runs, read_runs, Direction, Env, RunFile, RunRow, Sample, RUN_COLUMNS,
    TARGET_TOLERANCE_MM,
};
