//! Laser readings of a campaign: the linear module's run file, whose rows must carry `time_s`.

use super::campaign::LaserPoint;
use crate::error::{Error, Location, Result};
use std::path::Path;

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
