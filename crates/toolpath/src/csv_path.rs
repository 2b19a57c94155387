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
use crate::setting::Setting;
use crate::CompensateError;
use errmap_core::error::{Error, Location, Result};
use errmap_core::geom::ErrorField;
use errmap_core::io::{CsvRow, CsvTable};
use errmap_core::setting::words;
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

/// The rewrite's state from row to row.
struct Rows<'t> {
    source: &'t Path,
    cols: [usize; 3],
    normal: usize,
    /// The previous row's point, and the last point written (compensated or not), to drop
    /// repeated boundary points.
    prev: Option<[f64; 3]>,
    prev_out: Option<[f64; 3]>,
    report: CompensationReport,
}

/// Compensate a CSV toolpath. See the module documentation.
pub fn compensate(
    text: &str,
    source: &Path,
    field: &dyn ErrorField,
    settings: &CompensationSettings,
) -> Result<(String, CompensationReport), CompensateError> {
    settings.validate()?;
    let table = CsvTable::parse(source, text)?;
    let cols = [
        table.require(COLUMNS[0])?,
        table.require(COLUMNS[1])?,
        table.require(COLUMNS[2])?,
    ];
    let zone = super::default_zone_mm(source, field, settings)?.or(settings.zone);
    let lookup = ErrorLookup::new(field, settings, zone);
    // Lines with their terminators, so unchanged ones are copied exactly.
    let lines: Vec<&str> = text.split_inclusive('\n').collect();
    let mut rows = Rows {
        source,
        cols,
        normal: lookup.normal,
        prev: None,
        prev_out: None,
        report: CompensationReport {
            lines_in: lines.len() as u64,
            ..CompensationReport::default()
        },
    };
    let replaced = rows.rewrite_rows(&table, &lines, &lookup, settings, text.len())?;
    let out = assemble(&lines, &replaced, text.len());
    let mut report = rows.report;
    report.lines_out = out.split_inclusive('\n').count() as u64;
    Ok((out, report))
}

/// E at a path point: inside the zone and the measured domain (or anywhere the map reaches,
/// with `--extrapolate`), and whether a point was left nominal outside the domain or for its
/// uncertainty.
struct ErrorLookup<'f> {
    field: &'f dyn ErrorField,
    settings: &'f CompensationSettings,
    zone: Option<(f64, f64)>,
    normal: usize,
    plane: (usize, usize),
    kept_nominal: super::reach::KeptNominal,
}

impl<'f> ErrorLookup<'f> {
    fn new(
        field: &'f dyn ErrorField,
        settings: &'f CompensationSettings,
        zone: Option<(f64, f64)>,
    ) -> Self {
        let (u, v) = field.normal().plane_axes();
        ErrorLookup {
            field,
            settings,
            zone,
            normal: field.normal().index(),
            plane: (u.index(), v.index()),
            kept_nominal: super::reach::KeptNominal::default(),
        }
    }

    fn at(&self, p: &[f64; 3]) -> Option<f64> {
        if let Some((lo, hi)) = self.zone {
            if p[self.normal] < lo || p[self.normal] > hi {
                return None;
            }
        }
        let (u, v) = (p[self.plane.0], p[self.plane.1]);
        super::reach::domain_error_mm(self.field, self.settings, u, v, &self.kept_nominal)
    }
}

impl Rows<'_> {
    /// Every row compensated in turn: the rewritten text per line index (0-based), `None`
    /// where the line is copied.
    fn rewrite_rows(
        &mut self,
        table: &CsvTable,
        lines: &[&str],
        lookup: &ErrorLookup,
        settings: &CompensationSettings,
        input_bytes: usize,
    ) -> Result<Vec<Option<String>>> {
        let mut replaced: Vec<Option<String>> = vec![None; lines.len()];
        let mut grown_bytes = 0usize;
        for row in &table.rows {
            let p = row_point(table, row, self.cols)?;
            let li = (row.line as usize).saturating_sub(1);
            let (content, term) = split_terminator(lines.get(li).copied().unwrap_or(""));
            let fields = raw_fields(content);
            self.check_row(
                row.line,
                &fields,
                table.headers.len(),
                &p,
                settings.max_segment,
            )?;
            let path: Vec<[f64; 3]> = self.prev.into_iter().chain([p]).collect();
            let error_at = |q: &[f64; 3]| lookup.at(q);
            let mut emitted = emit_points(
                &path,
                settings.max_segment,
                lookup.zone,
                self.normal,
                &error_at,
            );
            lookup.kept_nominal.count(&mut self.report);
            if self.prev.is_some() {
                emitted.remove(0); // the previous row, already written
            }
            self.prev = Some(p);
            if emitted.len() == 1 && emitted[0].1.is_none() {
                self.prev_out = Some(p);
                continue;
            }
            let new_text = self.rewrite(&emitted, &p, &fields, term);
            grown_bytes += new_text.len();
            super::check_output_size(self.source, row.line, input_bytes + grown_bytes)?;
            if let Some(slot) = replaced.get_mut(li) {
                *slot = Some(new_text);
            }
        }
        Ok(replaced)
    }

    /// A row must be one line, and its move from the previous row of a sane length.
    fn check_row(
        &self,
        line: u64,
        fields: &[&str],
        columns: usize,
        p: &[f64; 3],
        max_segment: f64,
    ) -> Result<()> {
        if fields.len() != columns {
            return Err(Error::input(
                Location::line(self.source, line),
                "a row that spans several lines (a quoted field with a line break) cannot be rewritten",
                "keep each toolpath point on one line",
            ));
        }
        if let Some(q) = self.prev {
            let len = super::gcode::dist(&q, p);
            if len / max_segment > 1e6 {
                return Err(Error::input(
                    Location::line(self.source, line),
                    format!("the move to this row ({len:.6e} mm) would need more than a million segments"),
                    format!(
                        "check the coordinates and units, or raise {}",
                        words(Setting::MaxSegment)
                    ),
                ));
            }
        }
        Ok(())
    }

    /// The rows replacing row `p`: one per emitted point (with E subtracted where
    /// compensated); the row's own point keeps the text of coordinates that did not change.
    fn rewrite(
        &mut self,
        emitted: &[([f64; 3], Option<f64>)],
        p: &[f64; 3],
        fields: &[&str],
        term: &str,
    ) -> String {
        let mut new_text = String::new();
        let total = emitted.len();
        let mut n = 0;
        for (k, (q, e)) in emitted.iter().enumerate() {
            let mut q = *q;
            if let Some(e) = e {
                q[self.normal] -= e;
            }
            let last = k + 1 == total;
            if !last
                && self
                    .prev_out
                    .is_some_and(|po| super::gcode::dist(&po, &q) < 1e-12)
            {
                continue;
            }
            if let Some(e) = e {
                self.report.points_compensated += 1;
                self.report.max_abs_error_mm = self.report.max_abs_error_mm.max(e.abs());
            }
            self.prev_out = Some(q);
            n += 1;
            let mut out_fields: Vec<String> = fields.iter().map(|f| f.to_string()).collect();
            for axis in 0..3 {
                if !last || q[axis] != p[axis] {
                    out_fields[self.cols[axis]] = format_coord(q[axis], false);
                }
            }
            new_text.push_str(&out_fields.join(","));
            new_text.push_str(match (last, term) {
                (false, "") => "\n",
                _ => term,
            });
        }
        self.report.moves_changed += 1;
        self.report.segments_emitted += n as u64;
        if n > 1 {
            self.report.moves_split += 1;
        }
        new_text
    }
}

/// The x, y, z of a row, mm.
fn row_point(table: &CsvTable, row: &CsvRow, cols: [usize; 3]) -> Result<[f64; 3]> {
    Ok([
        table.f64(row, cols[0])?,
        table.f64(row, cols[1])?,
        table.f64(row, cols[2])?,
    ])
}

/// The output: each line as rewritten, or copied.
fn assemble(lines: &[&str], replaced: &[Option<String>], capacity: usize) -> String {
    let mut out = String::with_capacity(capacity);
    for (l, r) in lines.iter().zip(replaced) {
        out.push_str(r.as_deref().unwrap_or(l));
    }
    out
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
