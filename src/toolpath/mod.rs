//! Toolpaths: a G-code lexer that keeps text spans, modal state, and the P' = P − E compensation rewrite; CSV paths too.
//!
//! Only cutting moves (G1/G2/G3; CSV rows) whose points lie in the map domain
//! ([`ErrorField::error_mm`] returns `Some`) and in the zone (a band along the field's normal
//! axis, in program units) are changed; every other line is copied byte for byte. Long moves are
//! split to at most `max_segment`, arcs are linearised within `chord_tol`, and every emitted
//! point in the zone gets P' = P − E(P) along the normal. Where a move enters or leaves the zone
//! or domain it is split at the boundary: the outside part keeps the original coordinates and a
//! short step along the normal joins it to the compensated part. What cannot be compensated
//! safely in the zone (cutter compensation, parameters, expressions, O-word blocks, polar
//! coordinates, canned cycles, unknown start points) is refused with an error naming file:line.
//! `docs/toolpath.md` has the details and a worked example.

mod arc;
mod csv_path;
mod expr;
mod gcode;
pub mod lexer;

pub use arc::{Arc, Plane};
pub use gcode::format_coord;

use crate::error::{Error, Location, Result};
use crate::geom::ErrorField;
use serde::Serialize;
use std::path::Path;

/// How to compensate. `zone` is in program units (inches in a G20 program, mm in CSV);
/// `max_segment` and `chord_tol` are in mm (converted to inches for G20 programs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CompensationSettings {
    /// Band `(min, max)` along the normal axis where moves are compensated; `None` = everywhere.
    pub zone: Option<(f64, f64)>,
    /// Longest segment emitted in the zone, mm (default 5).
    pub max_segment: f64,
    /// Largest distance between an arc and its chords, mm (default 0.005).
    pub chord_tol: f64,
}

impl Default for CompensationSettings {
    fn default() -> Self {
        CompensationSettings {
            zone: None,
            max_segment: 5.0,
            chord_tol: 0.005,
        }
    }
}

/// Shortest `max_segment` accepted, mm (docs/toolpath.md): below it a program grows without
/// bound for no measurable gain.
pub const MIN_SEGMENT_MM: f64 = 0.01;

impl CompensationSettings {
    /// Reject settings that would loop forever or mean nothing.
    pub fn validate(&self) -> Result<()> {
        if !(self.max_segment.is_finite() && self.max_segment >= MIN_SEGMENT_MM) {
            return Err(Error::usage(
                format!(
                    "maximum segment length must be at least {MIN_SEGMENT_MM} mm, got {}",
                    self.max_segment
                ),
                "use e.g. --max-segment 5 (shorter segments only grow the program)",
            ));
        }
        if !(self.chord_tol.is_finite() && self.chord_tol > 0.0) {
            return Err(Error::usage(
                format!(
                    "chord tolerance must be a positive number of mm, got {}",
                    self.chord_tol
                ),
                "use e.g. --chord-tol 0.005",
            ));
        }
        if let Some((lo, hi)) = self.zone {
            if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
                return Err(Error::usage(
                    format!("zone must be MIN,MAX with MIN ≤ MAX, got {lo},{hi}"),
                    "use e.g. --zone -5,0 (program units, along the map's normal axis)",
                ));
            }
        }
        Ok(())
    }

    fn max_segment_in(&self, inches: bool) -> f64 {
        if inches {
            self.max_segment / 25.4
        } else {
            self.max_segment
        }
    }

    fn chord_tol_in(&self, inches: bool) -> f64 {
        if inches {
            self.chord_tol / 25.4
        } else {
            self.chord_tol
        }
    }
}

/// What a compensation did.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct CompensationReport {
    /// Cutting moves (G-code lines or CSV rows) rewritten.
    pub moves_changed: u64,
    /// Rewritten moves emitted as more than one segment.
    pub moves_split: u64,
    /// Largest |E| applied, mm.
    pub max_abs_error_mm: f64,
    /// Points that received P' = P − E.
    pub points_compensated: u64,
    /// Segments (G-code lines or CSV rows) emitted for rewritten moves.
    pub segments_emitted: u64,
    /// Returns along the normal inserted before an unchanged line that starts where a
    /// compensated cut ended (G-code only).
    pub returns_inserted: u64,
    /// Unchanged lines that got their modal motion word (e.g. `G2 `) prefixed because an inserted
    /// return changed the modal motion (G-code only; rare).
    pub lines_prefixed: u64,
    /// Lines read and written.
    pub lines_in: u64,
    pub lines_out: u64,
}

impl CompensationReport {
    /// The one-line summary the CLI prints.
    pub fn summary_line(&self) -> String {
        format!(
            "{} moves changed, {} split, max |E| applied {:.4} mm ({} points compensated, {} lines in, {} out)",
            self.moves_changed,
            self.moves_split,
            self.max_abs_error_mm,
            self.points_compensated,
            self.lines_in,
            self.lines_out
        )
    }
}

/// Compensate a G-code program (RS274/NGC, LinuxCNC dialect). `source` names the file in errors.
pub fn compensate_gcode(
    text: &str,
    source: &Path,
    field: &dyn ErrorField,
    settings: &CompensationSettings,
) -> Result<(String, CompensationReport)> {
    gcode::compensate(text, source, field, settings)
}

/// Compensate a CSV toolpath: header with `x_mm,y_mm,z_mm` (other columns passed through), one
/// point per row, consecutive rows joined by straight moves.
pub fn compensate_csv(
    text: &str,
    source: &Path,
    field: &dyn ErrorField,
    settings: &CompensationSettings,
) -> Result<(String, CompensationReport)> {
    csv_path::compensate(text, source, field, settings)
}

/// Compensate `input` into `output` (written atomically): `.csv` as a CSV toolpath, anything
/// else (`.ngc`, `.nc`, `.gcode`, `.tap` …) as G-code.
pub fn compensate_file(
    input: &Path,
    output: &Path,
    field: &dyn ErrorField,
    settings: &CompensationSettings,
) -> Result<CompensationReport> {
    let same = input == output
        || matches!((input.canonicalize(), output.canonicalize()), (Ok(a), Ok(b)) if a == b);
    if same {
        return Err(Error::input(
            Location::file(output),
            "the output would overwrite the input toolpath",
            "write the compensated toolpath to another file (-o)",
        ));
    }
    let text = crate::io::read_text(input)?;
    let is_csv = input
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("csv"));
    let (out, report) = if is_csv {
        compensate_csv(&text, input, field, settings)?
    } else {
        compensate_gcode(&text, input, field, settings)?
    };
    crate::io::write_atomic_bytes(output, out.as_bytes())?;
    Ok(report)
}
