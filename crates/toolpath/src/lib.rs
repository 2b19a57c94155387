//! Toolpaths: a G-code lexer that keeps text spans, modal state, and the P' = P − E compensation rewrite; CSV paths too.
//!
//! Only cutting moves (G1/G2/G3; CSV rows) whose points lie in the map domain
//! ([`ErrorField::error_mm`] returns `Some`) and in the zone (a band along the field's normal
//! axis, in program units) are changed; every other line is copied byte for byte. Long moves are
//! split to at most `max_segment`, arcs are linearised within `chord_tol`, and every emitted
//! point in the zone gets P' = P − E(P) along the normal. Where a move enters or leaves the zone
//! or domain it is split at the boundary: the outside part keeps the original coordinates and a
//! short step along the normal joins it to the compensated part. Cutter radius compensation is
//! followed when the map normal is the tool axis, drilling cycles under G90 (their holes with
//! `--compensate-holes`). What cannot be compensated safely in the zone (parameters,
//! expressions, O-word blocks, polar coordinates, G91 cycles, unknown start points …) is
//! refused with an error naming file:line.
//! `docs/toolpath.md` has the details and a worked example.
#![forbid(unsafe_code)]
#![warn(missing_docs)]
#![deny(rustdoc::broken_intra_doc_links)]

mod arc;
mod bytes;
mod csv_path;
pub mod dialect;
mod error;
mod expand;
mod expr;
mod gcode;
mod klartext;
pub mod lexer;
mod machine;
mod point;
mod reach;
mod setting;
pub mod zone_spec;

pub use arc::{Arc, Plane};
pub use dialect::{Dialect, FanucNumbers, PowerOnMotion, Units};
pub use error::{CompensateError, DialectError, SettingsError};
pub use gcode::format_coord;
pub use setting::Setting;

use errmap_core::error::{Error, Location, Result};
use errmap_core::geom::ErrorField;
use errmap_core::setting::words;
use serde::Serialize;
use std::path::Path;

/// How to compensate. `zone` is in the units the program starts in (inches in a G20 program,
/// mm in CSV) and follows later G20/G21 switches; `max_segment` and `chord_tol` are in mm
/// (converted to inches for G20 programs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CompensationSettings {
    /// Band `(min, max)` along the normal axis where moves are compensated. `None`: the map's
    /// probed surface ± `surface_tol_mm` (or everywhere if `everywhere`).
    pub zone: Option<(f64, f64)>,
    /// With no `zone`: compensate at every height along the normal (an explicit opt-in).
    pub everywhere: bool,
    /// Half-width of the default zone around the probed surface, mm (default 0.5).
    pub surface_tol_mm: f64,
    /// Longest segment emitted in the zone, mm (default 5).
    pub max_segment: f64,
    /// Largest distance between an arc and its chords, mm (default 0.005).
    pub chord_tol: f64,
    /// The program's controller dialect; `None` = detect (refused when uncertain).
    pub dialect: Option<Dialect>,
    /// Units of a program that does not say (no G20/G21 before its first cut); `None` = refuse.
    pub units: Option<Units>,
    /// How a Fanuc reads decimal-less coordinates; `None` = refuse such a program.
    pub fanuc_numbers: Option<FanucNumbers>,
    /// Also compensate outside the measured domain, where the map extrapolates.
    pub extrapolate: bool,
    /// Margin around the probes' hull that still counts as measured, mm.
    pub domain_margin_mm: f64,
    /// The motion mode the controller powers on in, for blocks with axis words before any
    /// motion word (Fanuc, Sinumerik, Heidenhain ISO); `None` = refuse such a block.
    pub power_on_motion: Option<PowerOnMotion>,
    /// Execute subprograms, loops and parameters whose every value is in the program, and
    /// write the flattened, compensated program (`--expand`); `false` = refuse them in the zone.
    pub expand: bool,
    /// Move a canned cycle's depth and reference by −E at a hole whose bottom lies in the zone
    /// (`--compensate-holes`); `false` = refuse such a hole.
    pub compensate_holes: bool,
    /// Apply the map in each work offset's coordinates (identical parts on a fixture plate,
    /// `--same-part-per-offset`); `false` = refuse cuts in the zone under a second offset.
    pub same_part_per_offset: bool,
}

impl Default for CompensationSettings {
    fn default() -> Self {
        CompensationSettings {
            zone: None,
            everywhere: false,
            surface_tol_mm: 0.5,
            max_segment: 5.0,
            chord_tol: 0.005,
            dialect: None,
            units: None,
            fanuc_numbers: None,
            extrapolate: false,
            domain_margin_mm: 0.0,
            power_on_motion: None,
            expand: false,
            compensate_holes: false,
            same_part_per_offset: false,
        }
    }
}

/// Shortest `max_segment` accepted, mm (docs/toolpath.md): below it a program grows without
/// bound for no measurable gain.
pub const MIN_SEGMENT_MM: f64 = 0.01;

impl CompensationSettings {
    /// Reject settings that would loop forever or mean nothing.
    pub fn validate(&self) -> Result<(), SettingsError> {
        if !(self.max_segment.is_finite() && self.max_segment >= MIN_SEGMENT_MM) {
            return Err(SettingsError::Range(Error::usage(
                format!(
                    "maximum segment length must be at least {MIN_SEGMENT_MM} mm, got {}",
                    self.max_segment
                ),
                format!(
                    "use e.g. {} 5 (shorter segments only grow the program)",
                    words(Setting::MaxSegment)
                ),
            )));
        }
        if !(self.chord_tol.is_finite() && self.chord_tol > 0.0) {
            return Err(SettingsError::Range(Error::usage(
                format!(
                    "chord tolerance must be a positive number of mm, got {}",
                    self.chord_tol
                ),
                format!("use e.g. {} 0.005", words(Setting::ChordTol)),
            )));
        }
        if !(self.surface_tol_mm.is_finite() && self.surface_tol_mm >= 0.0) {
            return Err(SettingsError::Range(Error::usage(
                format!(
                    "surface tolerance must be a non-negative number of mm, got {}",
                    self.surface_tol_mm
                ),
                format!("use e.g. {} 0.5", words(Setting::SurfaceTol)),
            )));
        }
        if !(self.domain_margin_mm.is_finite() && self.domain_margin_mm >= 0.0) {
            return Err(SettingsError::Range(Error::usage(
                format!(
                    "domain margin must be a non-negative number of mm, got {}",
                    self.domain_margin_mm
                ),
                "use e.g. domain_margin_mm = 2",
            )));
        }
        if let Some((lo, hi)) = self.zone {
            if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
                return Err(SettingsError::Range(Error::usage(
                    format!("zone must be MIN,MAX with MIN ≤ MAX, got {lo},{hi}"),
                    format!(
                        "use e.g. {} -5,0 (program units, along the map's normal axis)",
                        words(Setting::Zone)
                    ),
                )));
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

/// Checks shared by G-code and CSV: the map must know its measured domain unless
/// `extrapolate`; with no zone given, the zone is the map's probed surface ± the tolerance (mm),
/// or everywhere when asked for, else the program is refused.
pub(crate) fn default_zone_mm(
    source: &Path,
    field: &dyn ErrorField,
    settings: &CompensationSettings,
) -> Result<Option<(f64, f64)>, CompensateError> {
    if !settings.extrapolate && field.measured(0.0, 0.0, 0.0).is_none() {
        return Err(CompensateError::Uncovered(Error::input(
            Location::file(source),
            "the map does not record its measured domain (a model.json from an older errmap), so errmap cannot keep compensation inside the probed area",
            format!(
                "refit the map with this version of errmap, or pass {} to compensate wherever the map is defined",
                words(Setting::Extrapolate)
            ),
        )));
    }
    match (settings.zone, field.surface_mm()) {
        (Some(_), _) => Ok(None),
        (None, _) if settings.everywhere => Ok(None),
        (None, Some((lo, hi))) => Ok(Some((
            lo - settings.surface_tol_mm,
            hi + settings.surface_tol_mm,
        ))),
        (None, None) => Err(CompensateError::Uncovered(Error::input(
            Location::file(source),
            format!(
                "no compensation zone: the map does not record its probed surface and no {} was given",
                words(Setting::Zone)
            ),
            format!(
                "pass {zone} MIN,MAX (program units along the map's normal axis; job key [toolpaths] zone), or {zone} all (job key zone_all) to compensate at every height, or refit the map",
                zone = words(Setting::Zone)
            ),
        ))),
    }
}

/// Refuse a compensated toolpath that outgrows `--max-output-mb` while it is generated (checked
/// after each line or row), so that memory and time stay bounded by the limit, not by how many
/// long moves and many-turn arcs the input holds.
pub(crate) fn check_output_size(source: &Path, line: u64, bytes: usize) -> Result<()> {
    let limit = errmap_core::io::safety::max_output_bytes();
    if bytes as u64 > limit {
        return Err(Error::input(
            Location::line(source, line),
            format!(
                "the compensated toolpath would exceed the output limit of {} MB by this line",
                limit / 1_000_000
            ),
            format!(
                "check arc turn counts (P) and move lengths, raise {} / {}, or raise {}",
                words(Setting::MaxSegment),
                words(Setting::ChordTol),
                words(errmap_core::core_setting::Setting::MaxOutputMb)
            ),
        ));
    }
    Ok(())
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
    /// Cutting moves in the zone that reach outside the measured domain (the probes' hull),
    /// where they keep their nominal coordinates (unless `--extrapolate`).
    pub moves_outside_domain: u64,
    /// Cutting moves in the zone that reach, inside the measured domain, where the map's u(E)
    /// exceeds `--max-uncertainty-um`, where they keep their nominal coordinates (whatever
    /// `--extrapolate` says). A move can count here and in `moves_outside_domain`.
    pub moves_uncertain: u64,
    /// The dialect the program was read in.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub dialect: Option<Dialect>,
    /// The zone used, mm along the normal (`None`: everywhere).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub zone_mm: Option<(f64, f64)>,
    /// Segments (G-code lines or CSV rows) emitted for rewritten moves.
    pub segments_emitted: u64,
    /// Returns along the normal inserted before an unchanged line that starts where a
    /// compensated cut ended (G-code only).
    pub returns_inserted: u64,
    /// Unchanged lines that got their modal motion word (e.g. `G2 `) prefixed because an inserted
    /// return changed the modal motion (G-code only; rare).
    pub lines_prefixed: u64,
    /// Lines (G-code lines or CSV lines, header included) read from the input.
    pub lines_in: u64,
    /// Lines written to the compensated output.
    pub lines_out: u64,
    /// What a machinist should know about the compensated program (e.g. a path tolerance of
    /// the program's own larger than the compensation it carries).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
}

impl CompensationReport {
    /// The one-line summary the CLI prints.
    pub fn summary_line(&self) -> String {
        format!(
            "{} moves changed, {} split, max |E| applied {:.4} mm ({} points compensated, {} moves kept nominal outside the measured domain, {} where u(E) > {}, {} lines in, {} out)",
            self.moves_changed,
            self.moves_split,
            self.max_abs_error_mm,
            self.points_compensated,
            self.moves_outside_domain,
            self.moves_uncertain,
            words(Setting::MaxUncertaintyUm),
            self.lines_in,
            self.lines_out
        )
    }
}

/// A map that compensates nothing: reading a program through it traces its moves.
struct Nothing;

impl ErrorField for Nothing {
    fn normal(&self) -> errmap_core::geom::Axis {
        errmap_core::geom::Axis::Z
    }
    fn error_mm(&self, _u_mm: f64, _v_mm: f64) -> Option<f64> {
        None
    }
}

/// The settings a trace reads a program with: every move followed (no zone, no domain), none
/// compensated.
fn trace_settings(settings: &CompensationSettings) -> CompensationSettings {
    CompensationSettings {
        zone: None,
        everywhere: true,
        extrapolate: true,
        ..*settings
    }
}

/// Compensate a G-code program in its dialect (`settings.dialect`, or detected; Heidenhain
/// Klartext too): the compensated text and what was done. `source` names the file in errors.
///
/// A map that measured the part 10 µm high everywhere moves every cut 10 µm down (P' = P − E):
///
/// ```
/// use errmap_core::geom::{Axis, ErrorField};
/// use errmap_toolpath::{compensate_gcode, CompensationSettings, Dialect};
/// use std::path::Path;
///
/// /// E = +0.010 mm along Z everywhere (the part is measured 10 µm above nominal).
/// struct TenMicronsHigh;
/// impl ErrorField for TenMicronsHigh {
///     fn normal(&self) -> Axis {
///         Axis::Z
///     }
///     fn error_mm(&self, _x_mm: f64, _y_mm: f64) -> Option<f64> {
///         Some(0.010)
///     }
/// }
///
/// let program = "G21 G90 G17\nG0 X0 Y0 Z5\nG1 Z-1 F100\nG1 X20\nG0 Z5\nM2\n";
/// let settings = CompensationSettings {
///     everywhere: true,
///     dialect: Some(Dialect::Linuxcnc),
///     ..CompensationSettings::default()
/// };
/// let (compensated, report) =
///     compensate_gcode(program, Path::new("face.ngc"), &TenMicronsHigh, &settings).unwrap();
/// assert!(compensated.contains("Z-1.01"), "{compensated}");
/// assert_eq!(report.max_abs_error_mm, 0.010);
/// ```
pub fn compensate_gcode(
    text: &str,
    source: &Path,
    field: &dyn ErrorField,
    settings: &CompensationSettings,
) -> Result<(String, CompensationReport), CompensateError> {
    if klartext::applies(text, source, settings.dialect) {
        return match klartext::compensate(text, source, field, settings) {
            Err(refused) => expand_refused(text, source, field, settings, refused),
            done => done,
        };
    }
    match gcode::compensate(text, source, field, settings) {
        Err(refused) => expand_refused(text, source, field, settings, refused),
        done => done,
    }
}

/// The plain rewrite refused: run the program's control flow (`--expand`) and compensate the
/// flattened program, its refusals naming the original lines; without `--expand`, point to it
/// when the flattened program would compensate. A program with nothing to run keeps the
/// plain refusal.
fn expand_refused(
    text: &str,
    source: &Path,
    field: &dyn ErrorField,
    settings: &CompensationSettings,
    refused: CompensateError,
) -> Result<(String, CompensationReport), CompensateError> {
    // A Klartext program is run by the Klartext reader (its dialect is Heidenhain).
    let is_klartext = klartext::applies(text, source, settings.dialect);
    let dialect = match dialect::resolve(text, source, settings.dialect) {
        _ if is_klartext => Dialect::Heidenhain,
        Ok(d) => d,
        Err(_) => return Err(refused),
    };
    let mut flat = match expand::flatten(text, source, dialect, !settings.expand) {
        Ok(Some(flat)) => flat,
        Ok(None) => return Err(refused),
        Err(e) if settings.expand => return Err(e.into()),
        // A trial too long to finish here: the full run with the flag decides.
        Err(e) if expand::is_trial_stop(&e) => {
            return Err(refused.map_diagnostic(expand::with_hint))
        }
        Err(_) => return Err(refused),
    };
    let flat_settings = CompensationSettings {
        dialect: Some(dialect),
        ..*settings
    };
    // A run stopped by what it cannot follow: the blocks before it are compensated, so a
    // refusal of an earlier cut comes first; else the run's own refusal. A trial keeps the
    // plain refusal.
    let pending = flat.pending.take();
    if pending.is_some() && !settings.expand {
        return Err(refused);
    }
    let result = expand::compensate_flat(text, &flat, |t| {
        if is_klartext {
            klartext::compensate(t, source, field, &flat_settings)
        } else {
            gcode::compensate(t, source, field, &flat_settings)
        }
    });
    let result = match (result, pending) {
        (Ok(_), Some(stop)) => Err(stop.into()),
        (result, _) => result,
    };
    match (settings.expand, result) {
        // The run compensates nothing: the original runs exactly as its flattened program
        // does, so it is copied byte for byte (a file of subroutines alone runs nothing).
        (true, Ok((_, report))) if report.moves_changed == 0 => {
            let lines = text.lines().count() as u64;
            Ok((
                text.to_string(),
                CompensationReport {
                    lines_in: lines,
                    lines_out: lines,
                    ..report
                },
            ))
        }
        (true, result) => result,
        (false, Ok(_)) => Err(refused.map_diagnostic(expand::with_hint)),
        (false, Err(_)) => Err(refused),
    }
}

/// A move of a G-code program as errmap's interpreter reads it: mm, in work coordinates (the
/// program's coordinates plus the shifts errmap follows: G92, G52, Sinumerik TRANS).
#[derive(Debug, Clone)]
pub struct TracedMove {
    /// 1-based line of the block.
    pub line: u64,
    /// The block's motion mode (rapid, feed, arc, cycle …).
    pub kind: dialect::Motion,
    /// Where the move starts, `[x, y, z]` mm in work coordinates.
    pub start_mm: [f64; 3],
    /// Where the move ends, `[x, y, z]` mm in work coordinates.
    pub end_mm: [f64; 3],
    /// The arc of a G2/G3 block, mm.
    pub arc_mm: Option<Arc>,
}

/// The moves of a G-code program whose start and end errmap knows, as its interpreter reads
/// them (the same reading `compensate_gcode` rewrites by): what the program commands, for
/// checking a rewrite against its original. Refuses what `compensate_gcode` refuses at every
/// height (unknown codes, malformed blocks, a cut before the unit code …).
pub fn trace_gcode(
    text: &str,
    source: &Path,
    settings: &CompensationSettings,
) -> Result<Vec<TracedMove>, CompensateError> {
    if klartext::applies(text, source, settings.dialect) {
        return klartext::trace(text, source, settings);
    }
    gcode::trace(text, source, settings)
}

/// Compensate a CSV toolpath: header with `x_mm,y_mm,z_mm` (other columns passed through), one
/// point per row, consecutive rows joined by straight moves.
pub fn compensate_csv(
    text: &str,
    source: &Path,
    field: &dyn ErrorField,
    settings: &CompensationSettings,
) -> Result<(String, CompensationReport), CompensateError> {
    csv_path::compensate(text, source, field, settings)
}

/// The JSON document `errmap compensate --json` prints: which file became which, and what was
/// done.
#[derive(Debug, Serialize)]
pub struct CompensationDocument<'a> {
    /// The toolpath read, as given.
    pub input: &'a Path,
    /// The compensated toolpath written, as given.
    pub output: &'a Path,
    /// What the compensation did.
    pub report: &'a CompensationReport,
}

impl CompensationDocument<'_> {
    /// The document on one line, its keys in alphabetical order at every level (the order
    /// scripts have read since the first release).
    pub fn to_json(&self) -> Result<String> {
        serde_json::to_value(self)
            .and_then(|v| serde_json::to_string(&v))
            .map_err(|e| Error::Internal(e.to_string()))
    }
}

/// Compensate `input` into `output` (written atomically): `.csv` as a CSV toolpath, anything
/// else (`.ngc`, `.nc`, `.gcode`, `.tap` …) as G-code.
pub fn compensate_file(
    input: &Path,
    output: &Path,
    field: &dyn ErrorField,
    settings: &CompensationSettings,
) -> Result<CompensationReport, CompensateError> {
    let same = input == output
        || matches!((input.canonicalize(), output.canonicalize()), (Ok(a), Ok(b)) if a == b);
    if same {
        return Err(CompensateError::Overwrite(Error::input(
            Location::file(output),
            "the output would overwrite the input toolpath",
            "write the compensated toolpath to another file (-o)",
        )));
    }
    let is_csv = input
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("csv"));
    if is_csv {
        let text = errmap_core::io::read_text(input)?;
        let (out, report) = compensate_csv(&text, input, field, settings)?;
        errmap_core::io::write_atomic_bytes(output, out.as_bytes())?;
        return Ok(report);
    }
    // A program that is not UTF-8 (GBK or Latin-1 comments) is read with its bytes ≥ 0x80 as
    // private-use characters, allowed in comments only, and written back byte for byte.
    errmap_core::io::safety::protect(input);
    let raw = std::fs::read(input).map_err(|e| Error::read(input, e))?;
    let (text, mapped) = bytes::decode(raw);
    if !mapped {
        let (out, report) = compensate_gcode(&text, input, field, settings)?;
        errmap_core::io::write_atomic_bytes(output, out.as_bytes())?;
        return Ok(report);
    }
    bytes::check_comments(&text, input, settings.dialect)?;
    let (out, report) = compensate_gcode(&text, input, field, settings)
        .map_err(|e| e.map_diagnostic(bytes::show_error))?;
    errmap_core::io::write_atomic_bytes(output, &bytes::encode(&out))?;
    Ok(report)
}
