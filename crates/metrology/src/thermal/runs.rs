//! Laser readings of a campaign: the linear module's run file, whose rows must carry `time_s`.
//! Below [`super::campaign`], which groups these readings into measurements.

use crate::linear::Direction;
use errmap_core::error::{Error, Location, Result};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// One laser reading.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LaserPoint {
    /// Run number from the run file.
    pub run: u32,
    /// Approach direction (forward `+`, reverse `-`).
    pub direction: Direction,
    /// Target position, mm.
    pub target_mm: f64,
    /// Measured minus target (µm).
    pub deviation_um: f64,
    /// Line in the run file (0 when not from a file).
    pub line: u64,
}

/// Every reading of a run file with its measurement time (`time_s`, required on every row).
pub fn read_timed_points(path: &Path) -> Result<Vec<(f64, LaserPoint)>> {
    let file = crate::linear::read_runs(path)?;
    let mut out = Vec::with_capacity(file.rows.len());
    for row in &file.rows {
        let time_s = row.time_s.ok_or_else(|| {
            Error::input(
                Location::cell(path, row.line, "time_s"),
                "a thermal campaign needs the measurement time on every row",
                "add a time_s column: the start time (s) of the measurement the row belongs to",
            )
        })?;
        out.push((
            time_s,
            LaserPoint {
                run: row.run,
                direction: row.direction,
                target_mm: row.target_mm,
                deviation_um: row.deviation_um,
                line: row.line,
            },
        ));
    }
    Ok(out)
}
