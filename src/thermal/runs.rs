//! Laser readings of a campaign from a linear-axis run file with a `time_s` column.

use super::campaign::{Direction, LaserPoint};
use crate::error::Result;
use crate::io::CsvTable;
use std::path::Path;

/// Every reading of a run file with its measurement time.
pub fn read_timed_points(path: &Path) -> Result<Vec<(f64, LaserPoint)>> {
    // Interim reader until the linear module's run-file reader is merged.
    let t = CsvTable::read(path)?;
    let (c_run, c_dir, c_x, c_e, c_t) = (
        t.require("run")?,
        t.require("direction")?,
        t.require("target_mm")?,
        t.require("deviation_um")?,
        t.require("time_s")?,
    );
    let mut out = Vec::new();
    for row in &t.rows {
        let direction = Direction::parse(t.text(row, c_dir)).ok_or_else(|| {
            t.error_at(row, Some(c_dir), "direction must be + or -", "write + or -")
        })?;
        let run = t.text(row, c_run).parse::<u32>().map_err(|_| {
            t.error_at(row, Some(c_run), "run must be a whole number", "number runs 1, 2, …")
        })?;
        out.push((
            t.f64(row, c_t)?,
            LaserPoint {
                run,
                direction,
                target_mm: t.f64(row, c_x)?,
                deviation_um: t.f64(row, c_e)?,
                line: row.line,
            },
        ));
    }
    Ok(out)
}
