//! CSV toolpaths: rows of `x_mm,y_mm,z_mm` (extra columns passed through) compensated with the same rule as G-code.
//!
//! Consecutive rows are joined by straight moves. A row whose move from the previous row stays
//! outside the zone or domain is copied byte for byte. Otherwise the move is split like a G1:
//! rows are inserted (at most `max_segment` apart in the zone, and at zone/domain boundaries),
//! each inserted row copies the extra columns of the row it leads to, and every point in the
//! zone gets z' = z − E (or x/y for a wall map). A changed row keeps the text of its
//! coordinates that did not change.

use super::gcode::{emit_points, format_coord};
use super::{CompensationReport, CompensationSettings};
use crate::error::{Error, Location, Result};
use crate::geom::ErrorField;
use crate::io::CsvTable;
use std::path::Path;

const COLUMNS: [&str; 3] = ["x_mm", "y_mm", "z_mm"];

/// Split one CSV line into its raw field texts (quotes kept), commas inside quotes respected.
fn raw_fields(line: &str) -> Vec<&str> {
    let mut out = Vec::new();
    let mut start = 0;
    let mut quoted = false;
    for (i, c) in line.char_indices() {
        match c {
            '"' => quoted = !quoted,
            ',' if !quoted => {
                out.push(&line[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    out.push(&line[start..]);
    out
}

pub fn compensate(
    text: &str,
    source: &Path,
    field: &dyn ErrorField,
    settings: &CompensationSettings,
) -> Result<(String, CompensationReport)> {
    settings.validate()?;
    let table = CsvTable::parse(source, text)?;
    let cols = [
        table.require(COLUMNS[0])?,
        table.require(COLUMNS[1])?,
        table.require(COLUMNS[2])?,
    ];
    let zone = super::default_zone_mm(source, field, settings)?.or(settings.zone);
    let normal = field.normal().index();
    let (ui, vi) = field.normal().plane_axes();
    let (ui, vi) = (ui.index(), vi.index());
    let extrapolated = std::cell::Cell::new(false);
    let error_at = |p: &[f64; 3]| -> Option<f64> {
        if let Some((lo, hi)) = zone {
            if p[normal] < lo || p[normal] > hi {
                return None;
            }
        }
        let e = field.error_mm(p[ui], p[vi]).filter(|e| e.is_finite())?;
        let measured = field.measured(p[ui], p[vi], settings.domain_margin_mm) == Some(true);
        if !settings.extrapolate && !measured {
            extrapolated.set(true);
            return None;
        }
        Some(e)
    };

    // Lines with their terminators, so unchanged ones are copied exactly.
    let lines: Vec<&str> = text.split_inclusive('\n').collect();
    let mut report = CompensationReport {
        lines_in: lines.len() as u64,
        ..CompensationReport::default()
    };
    // Rewritten text per line index (0-based); `None` = copy.
    let mut replaced: Vec<Option<String>> = vec![None; lines.len()];
    let mut prev: Option<[f64; 3]> = None;
    // Last point written (compensated or not), to drop repeated boundary points.
    let mut prev_out: Option<[f64; 3]> = None;
    let mut grown_bytes = 0usize;
    for row in &table.rows {
        let p = [
            table.f64(row, cols[0])?,
            table.f64(row, cols[1])?,
            table.f64(row, cols[2])?,
        ];
        let li = (row.line as usize).saturating_sub(1);
        let raw_line = lines.get(li).copied().unwrap_or("");
        let (content, term) = split_terminator(raw_line);
        let fields = raw_fields(content);
        if fields.len() != table.headers.len() {
            return Err(Error::input(
                Location::line(source, row.line),
                "a row that spans several lines (a quoted field with a line break) cannot be rewritten",
                "keep each toolpath point on one line",
            ));
        }
        if let Some(q) = prev {
            let len = super::gcode::dist(&q, &p);
            if len / settings.max_segment > 1e6 {
                return Err(Error::input(
                    Location::line(source, row.line),
                    format!("the move to this row ({len:.6e} mm) would need more than a million segments"),
                    "check the coordinates and units, or raise --max-segment",
                ));
            }
        }
        let path: Vec<[f64; 3]> = match prev {
            Some(q) => vec![q, p],
            None => vec![p],
        };
        let mut emitted = emit_points(&path, settings.max_segment, zone, normal, &error_at);
        if extrapolated.replace(false) {
            report.moves_outside_domain += 1;
        }
        if prev.is_some() {
            emitted.remove(0); // the previous row, already written
        }
        prev = Some(p);
        let untouched = emitted.len() == 1 && emitted[0].1.is_none();
        if untouched {
            prev_out = Some(p);
            continue;
        }
        let mut new_text = String::new();
        let total = emitted.len();
        let mut n = 0;
        for (k, (q, e)) in emitted.iter().enumerate() {
            let mut q = *q;
            if let Some(e) = e {
                q[normal] -= e;
            }
            let last = k + 1 == total;
            if !last && prev_out.is_some_and(|po| super::gcode::dist(&po, &q) < 1e-12) {
                continue;
            }
            if let Some(e) = e {
                report.points_compensated += 1;
                report.max_abs_error_mm = report.max_abs_error_mm.max(e.abs());
            }
            prev_out = Some(q);
            n += 1;
            let mut out_fields: Vec<String> = fields.iter().map(|f| f.to_string()).collect();
            for axis in 0..3 {
                // The row's own point keeps the text of coordinates that did not change.
                if !last || q[axis] != p[axis] {
                    out_fields[cols[axis]] = format_coord(q[axis], false);
                }
            }
            new_text.push_str(&out_fields.join(","));
            new_text.push_str(if last {
                term
            } else if term.is_empty() {
                "\n"
            } else {
                term
            });
        }
        report.moves_changed += 1;
        report.segments_emitted += n as u64;
        if n > 1 {
            report.moves_split += 1;
        }
        grown_bytes += new_text.len();
        super::check_output_size(source, row.line, text.len() + grown_bytes)?;
        if let Some(slot) = replaced.get_mut(li) {
            *slot = Some(new_text);
        }
    }
    let mut out = String::with_capacity(text.len());
    for (i, l) in lines.iter().enumerate() {
        match &replaced[i] {
            Some(t) => out.push_str(t),
            None => out.push_str(l),
        }
    }
    report.lines_out = out.split_inclusive('\n').count() as u64;
    Ok((out, report))
}

fn split_terminator(line: &str) -> (&str, &str) {
    if let Some(c) = line.strip_suffix("\r\n") {
        (c, "\r\n")
    } else if let Some(c) = line.strip_suffix('\n') {
        (c, "\n")
    } else {
        (line, "")
    }
}
