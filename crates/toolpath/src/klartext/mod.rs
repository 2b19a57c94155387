//! Heidenhain conversational (Klartext) programs: errmap's own reader, interpreter and rewriter of numbered TNC blocks (`L`, `CC`, `C`, `CR` …), which follows what it can vouch for and refuses the rest in the zone.
//!
//! The rules and the table of what is followed, rewritten and refused are in
//! `docs/toolpath.md` (Heidenhain). Lines errmap does not change are copied byte for byte; when it
//! inserts blocks (pieces of a cut, a return along the normal) every block is renumbered so the
//! numbers stay sequential (labels are named by `LBL n`, never by block number).

mod block;
mod contour;
mod cycles;
mod holes;
mod interp;
mod polar;
mod rewrite;

use super::dialect::{self, Dialect};
use super::machine::Machine;
use super::{CompensationReport, CompensationSettings, TracedMove, Units};
use crate::setting::Setting;
use crate::CompensateError;
use block::Block;
use errmap_core::error::{Error, Location, Result};
use errmap_core::geom::ErrorField;
use errmap_core::setting::words;
use std::path::Path;

/// A point of the original program, some coordinates unknown.
type Point = [Option<f64>; 3];

/// Whether `text` is a Klartext program errmap should read as such: it begins with
/// `0 BEGIN PGM` (unless another dialect is given), or it is Heidenhain and its first block is
/// a numbered conversational block.
pub(crate) fn applies(text: &str, source: &Path, given: Option<Dialect>) -> bool {
    if !matches!(given, None | Some(Dialect::Heidenhain)) {
        return false;
    }
    let Some(first) = text
        .lines()
        .map(str::trim)
        .find(|l| !l.is_empty() && !l.starts_with(';'))
    else {
        return false;
    };
    let mut words = first.split_whitespace().peekable();
    // Block numbers are optional: CAM posts (the APT post, some NX posts) leave them out.
    let number = words
        .peek()
        .is_some_and(|w| w.bytes().all(|b| b.is_ascii_digit()));
    if number {
        words.next();
    }
    let head = words.next().unwrap_or("");
    let second = words.next().unwrap_or("");
    if head.eq_ignore_ascii_case("BEGIN") && second.eq_ignore_ascii_case("PGM") {
        return true;
    }
    let klartext_head = matches!(
        head.to_ascii_uppercase().as_str(),
        "L" | "CC" | "C" | "CR" | "LBL" | "CALL" | "TOOL" | "CYCL" | "BLK" | "LP" | "CP" | "FN"
    );
    let uppercase = !head.is_empty() && head.bytes().all(|b| b.is_ascii_uppercase());
    (number && uppercase || klartext_head)
        && dialect::resolve(text, source, given).ok() == Some(Dialect::Heidenhain)
}

/// How a cut relates to tool radius compensation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Comp {
    /// No compensation: chords and steps as everywhere else.
    Off,
    /// RL/RR in force before and after the block: pieces that all move in the plane.
    Contour,
    /// The block switches RL/RR on or changes it, or ends it with R0: one block.
    Transition,
}

/// A line of the output: `before` + `number` + `after` + `term`; numbered lines are renumbered
/// when the output has a different number of blocks than the input.
#[derive(Debug)]
struct OutLine {
    before: String,
    number: Option<String>,
    after: String,
    term: String,
}

/// A transformation (cycle 8, 10, 11, 26, 19, or a function errmap does not know) that is
/// active: cuts that may lie in the zone are refused.
#[derive(Debug, Clone)]
struct Frame {
    /// `8`, `10`, `11`, `26`, `19`, or `?` for a block errmap does not follow.
    cycle: String,
    line: u64,
    what: String,
    /// Whether it may move the normal coordinate too.
    normal: bool,
}

/// The interpreter's state while reading the program, and the output it writes.
struct Kt<'a> {
    source: &'a Path,
    /// Position, units, shift, zone and the map (shared with the G-code reader).
    m: Machine<'a>,
    /// Circle centre / pole (coordinates of its plane).
    centre: Point,
    /// The plane of the last CC block's two axes (`None`: the working plane).
    cc_plane: Option<super::arc::Plane>,
    /// Tool axis from `TOOL CALL` (index; Z by default).
    tool_axis: usize,
    radius_comp: Option<(u64, String)>,
    frames: Vec<Frame>,
    /// The label body being read (`LBL n` … `LBL 0`).
    label: Option<(u64, String)>,
    /// A rounding or chamfer waiting for the element after it: line, column, word.
    corner: Option<(u64, usize, String)>,
    /// The program has blocks that transform coordinates or that errmap does not know, or
    /// radius compensation: a label entered from elsewhere may find them active.
    program_transforms: bool,
    program_radius_comp: bool,
    /// The previous contour element may lie in the zone.
    prev_touch: bool,
    decimals: usize,
    report: CompensationReport,
    out: Vec<OutLine>,
    out_bytes: usize,
    numbered_in: usize,
    /// The TNC block number of each line (index = line − 1), for messages.
    block_numbers: Vec<Option<u64>>,
    /// The lines (content, terminator) of the block being read, and where its output starts.
    block_lines: Vec<(String, String)>,
    block_out_start: usize,
    /// The machining cycle defined last (its number and line), named by a refused call.
    machining_cycle: Option<(i64, u64)>,
    /// The last drilling cycle defined (200–209), if it is the active machining cycle.
    hole_cycle: Option<holes::HoleCycle>,
    /// The surface Q203 of the definition written last in the output, when errmap wrote it
    /// again (`None`: the program's own definition is in force).
    hole_surface_out: Option<f64>,
    /// `M89`: the cycle is called after every positioning block from here on.
    modal_call: bool,
    /// The preset (cycle 247 Q339) whose coordinates the map is applied in, once selected.
    first_preset: Option<f64>,
    /// A cut that may lie in the zone has been read (or a hole compensated).
    cut_seen: bool,
    /// The largest path tolerance of cycle 32 in the program (mm) and its line.
    path_tolerance_mm: Option<(f64, u64)>,
    trace: Option<Vec<TracedMove>>,
}

/// Compensate a Klartext program.
pub(crate) fn compensate(
    text: &str,
    source: &Path,
    field: &dyn ErrorField,
    settings: &CompensationSettings,
) -> Result<(String, CompensationReport), CompensateError> {
    let mut kt = Kt::start(text, source, field, settings)?;
    kt.run(text)?;
    Ok(kt.finish(text))
}

/// The moves of a Klartext program as errmap reads them (mm, work coordinates).
pub(crate) fn trace(
    text: &str,
    source: &Path,
    settings: &CompensationSettings,
) -> Result<Vec<TracedMove>, CompensateError> {
    let settings = super::trace_settings(settings);
    let mut kt = Kt::start(text, source, &super::Nothing, &settings)?;
    kt.trace = Some(Vec::new());
    kt.run(text)?;
    Ok(kt.trace.take().unwrap_or_default())
}

impl<'a> Kt<'a> {
    fn start(
        text: &str,
        source: &'a Path,
        field: &'a dyn ErrorField,
        settings: &'a CompensationSettings,
    ) -> Result<Kt<'a>, CompensateError> {
        settings.validate()?;
        let header = header_units(text, source)?;
        let units = match (header, settings.units) {
            (Some((h, line)), Some(u)) if h != u => {
                return Err(Error::input(
                    Location::line(source, line),
                    format!(
                        "the program says {} in BEGIN PGM, but {} says {}",
                        units_word(h),
                        words(Setting::Units),
                        units_word(u)
                    ),
                    format!(
                        "leave out {} (the BEGIN PGM block gives the units of a Klartext program)",
                        words(Setting::Units)
                    ),
                )
                .into())
            }
            (Some((h, _)), _) => Some(h),
            (None, u) => u,
        };
        let zone_mm = super::default_zone_mm(source, field, settings)?;
        let inches = units == Some(Units::Inch);
        let mut m = Machine::new(field, settings, inches, zone_mm);
        // The header gives the units before any block: the zone is fixed in them at once.
        m.units_known = units.is_some();
        m.fix_zone();
        let report = CompensationReport {
            zone_mm: m.zone_mm,
            dialect: Some(Dialect::Heidenhain),
            ..CompensationReport::default()
        };
        Ok(Kt {
            source,
            m,
            centre: [None; 3],
            cc_plane: None,
            tool_axis: 2,
            radius_comp: None,
            frames: Vec::new(),
            label: None,
            corner: None,
            program_transforms: false,
            program_radius_comp: false,
            prev_touch: false,
            decimals: program_decimals(text).max(if inches { 5 } else { 4 }),
            report,
            out: Vec::new(),
            out_bytes: 0,
            numbered_in: 0,
            block_numbers: Vec::new(),
            block_lines: Vec::new(),
            block_out_start: 0,
            machining_cycle: None,
            hole_cycle: None,
            hole_surface_out: None,
            modal_call: false,
            path_tolerance_mm: None,
            first_preset: None,
            cut_seen: false,
            trace: None,
        })
    }

    /// Read every block in order; a block continued with `~` at the end of its lines (a cycle
    /// definition) is read as one and copied line by line.
    fn run(&mut self, text: &str) -> Result<()> {
        self.prescan(text);
        let lines: Vec<&str> = text.split_inclusive('\n').collect();
        let content_of = |raw: &str| raw.trim_end_matches(['\n', '\r']).len();
        self.block_numbers = lines
            .iter()
            .map(|raw| block::read(&raw[..content_of(raw)]).ok()?.number)
            .collect();
        let mut i = 0;
        while i < lines.len() {
            let number = i as u64 + 1;
            let raw = lines[i];
            let content = &raw[..content_of(raw)];
            let term = &raw[content.len()..];
            let mut last = i;
            // A block continues only from a line with code of its own (`CYCL DEF 203 … ~`).
            let has_code = !code_part(content).trim().is_empty();
            while has_code
                && last + 1 < lines.len()
                && continued(&lines[last][..content_of(lines[last])])
            {
                last += 1;
            }
            let joined = if last > i {
                let parts: Vec<&str> = lines[i..=last]
                    .iter()
                    .map(|l| code_part(&l[..content_of(l)]))
                    .collect();
                parts.join(" ")
            } else {
                content.to_string()
            };
            self.report.lines_in += 1;
            let block = block::read(&joined).map_err(|(col, word, msg)| {
                Error::input(
                    Location::cell(self.source, number, format!("{col} ({word})")),
                    format!("{}{msg}", self.block_prefix(number)),
                    "write each word once, with a number like +10 or -2.5 (a point, not a comma)",
                )
            })?;
            let path_head = matches!(
                block.head.as_str(),
                "L" | "C" | "CR" | "CT" | "CC" | "LP" | "CP" | "RND" | "CHF"
            ) || block::is_m_head(&block.head);
            if last > i && path_head {
                return Err(Error::input(
                    Location::cell(self.source, number, format!("{} ({})", block.head_col, block.head)),
                    format!("{}a {} block continued with `~` on the next line: errmap reads path and M blocks on one line", self.block_prefix(number), block.head),
                    "write the block on one line (only cycle definitions are continued with ~)",
                ));
            }
            if block.number.is_some() {
                self.numbered_in += 1;
            }
            self.block_lines = lines[i..=last]
                .iter()
                .map(|l| {
                    let c = &l[..content_of(l)];
                    (c.to_string(), l[c.len()..].to_string())
                })
                .collect();
            self.block_out_start = self.out.len();
            self.line(number, content, term, &block)?;
            for raw in &lines[i + 1..=last] {
                let content = &raw[..content_of(raw)];
                self.report.lines_in += 1;
                self.push(OutLine {
                    before: String::new(),
                    number: None,
                    after: content.to_string(),
                    term: raw[content.len()..].to_string(),
                });
            }
            super::check_output_size(self.source, last as u64 + 1, self.out_bytes)?;
            i = last + 1;
        }
        Ok(())
    }

    /// `block 45: ` for a line with a TNC block number, else nothing.
    fn block_prefix(&self, line: u64) -> String {
        match self.block_numbers.get(line.wrapping_sub(1) as usize) {
            Some(Some(b)) => format!("block {b}: "),
            _ => String::new(),
        }
    }

    /// `block 45, line 47` (or `line 47` in a program without block numbers).
    fn at(&self, line: u64) -> String {
        match self.block_numbers.get(line.wrapping_sub(1) as usize) {
            Some(Some(b)) => format!("block {b}, line {line}"),
            _ => format!("line {line}"),
        }
    }

    /// Whether the program transforms coordinates (or has blocks errmap does not know) or uses
    /// radius compensation anywhere: a label entered from elsewhere may find them active.
    fn prescan(&mut self, text: &str) {
        const KNOWN: [&str; 23] = [
            "", ";", "*", "BEGIN", "END", "BLK", "FPOL", "FSELECT", "SEL", "L", "C", "CR", "CT",
            "CC", "RND", "CHF", "LP", "CP", "FL", "FLT", "FC", "FCT", "LBL",
        ];
        for l in text.lines() {
            let Ok(b) = block::read(l) else { continue };
            let rest = b.rest.to_ascii_uppercase();
            let harmless = KNOWN.contains(&b.head.as_str())
                || b.head.starts_with('Q')
                || interp::is_m_block(&b.head)
                || matches!(b.head.as_str(), "STOP" | "APPR" | "DEP")
                || (b.head == "FN" && !rest.starts_with("17"))
                || (b.head == "TOOL")
                || (b.head == "CALL" && rest.starts_with("LBL"))
                || (b.head == "CYCL" && !is_transform_cycle(&b));
            if !harmless {
                self.program_transforms = true;
            }
            if b.has("RL") || b.has("RR") || rest.contains(" RL") || rest.contains(" RR") {
                self.program_radius_comp = true;
            }
        }
    }

    /// The output text: renumbered when blocks were inserted or removed.
    fn finish(mut self, text: &str) -> (String, CompensationReport) {
        let numbered_out = self.out.iter().filter(|l| l.number.is_some()).count();
        // An inserted block has no number of its own; a removed one leaves a gap.
        let inserted = self.out.iter().any(|l| l.number.as_deref() == Some(""));
        let renumber = inserted || numbered_out != self.numbered_in;
        let first = text
            .lines()
            .find_map(|l| block::read(l).ok()?.number)
            .unwrap_or(0);
        let mut out = String::with_capacity(self.out_bytes + self.out.len() * 4);
        let mut n = first;
        let numbered = self.numbered_in > 0;
        for l in &self.out {
            out.push_str(&l.before);
            if !numbered {
                // A program without block numbers gets none: an inserted block is ` L …`.
                let after = match &l.number {
                    Some(_) => l.after.strip_prefix(' ').unwrap_or(&l.after),
                    None => &l.after,
                };
                out.push_str(after);
                out.push_str(&l.term);
                continue;
            }
            if let Some(num) = &l.number {
                if renumber {
                    out.push_str(&n.to_string());
                } else {
                    out.push_str(num);
                }
                n += 1;
            }
            out.push_str(&l.after);
            out.push_str(&l.term);
        }
        self.report.lines_out = self.out.len() as u64;
        let applied = self.report.max_abs_error_mm;
        if let Some((t, line)) = self.path_tolerance_mm {
            if applied > 0.0 && t > applied {
                self.report.notes.push(format!(
                    "CYCL DEF 32 TOLERANCE T{t} mm ({}) is larger than the largest |E| applied ({applied:.4} mm): the control may smooth the path by up to T, which can swallow the compensation; set a tolerance smaller than |E| for the finishing cuts",
                    self.at(line)
                ));
            }
        }
        (out, self.report)
    }

    /// Copy a line unchanged.
    fn copy(&mut self, content: &str, term: &str, block: &Block) {
        let span = block.number_span.clone();
        let (before, number, after) = match block.number {
            Some(_) if span.end <= content.len() && content.is_char_boundary(span.start) => (
                &content[..span.start],
                Some(&content[span.clone()]),
                &content[span.end..],
            ),
            _ => ("", None, content),
        };
        self.push(OutLine {
            before: before.to_string(),
            number: number.map(str::to_string),
            after: after.to_string(),
            term: term.to_string(),
        });
    }

    fn push(&mut self, line: OutLine) {
        self.out_bytes += line.before.len()
            + line.number.as_ref().map_or(2, String::len)
            + line.after.len()
            + line.term.len();
        self.out.push(line);
    }

    /// An inserted block ` L X… Y… Z…` (its number given when the output is renumbered).
    fn push_block(&mut self, body: String, term: &str) {
        self.push(OutLine {
            before: String::new(),
            number: Some(String::new()),
            after: body,
            term: if term.is_empty() { "\n" } else { term }.to_string(),
        });
    }

    /// An error at a column of a line, naming the word.
    fn err(&self, line: u64, col: usize, word: &str, message: String, hint: &str) -> Error {
        Error::input(
            Location::cell(self.source, line, format!("{col} ({word})")),
            format!("{}{message}", self.block_prefix(line)),
            hint,
        )
    }

    /// Could a path through these points (some coordinates unknown) touch the zone and the
    /// measured domain? Under an active frame the plane coordinates (and the normal one when
    /// the frame may move it) are unknown.
    fn may_touch(&self, points: &[Point]) -> bool {
        let framed: Vec<Point> = if self.frames.is_empty() {
            points.to_vec()
        } else {
            let normal_moves = self.frames.iter().any(|f| f.normal);
            points
                .iter()
                .map(|p| {
                    let mut q = [None; 3];
                    if !normal_moves {
                        q[self.m.normal] = p[self.m.normal];
                    }
                    q
                })
                .collect()
        };
        self.m.may_touch(&framed)
    }

    /// Coordinate text with sign: `+10.0000`, `-2.5000`.
    fn coord(&self, v: f64) -> String {
        let t = super::gcode::format_decimals(v, self.decimals);
        if t.starts_with('-') {
            t
        } else {
            format!("+{t}")
        }
    }
}

/// A line continued on the next (`CYCL DEF 203 … ~`, `Q200=+5 ;SET-UP CLEARANCE ~`).
fn continued(content: &str) -> bool {
    content.trim_end().ends_with('~')
}

/// The code of a continued line: before its comment, without the `~`.
fn code_part(content: &str) -> &str {
    let code = content.split(';').next().unwrap_or("");
    code.trim_end().trim_end_matches('~').trim_end()
}

/// `CYCL DEF` 7, 8, 10, 11, 19, 26 or 247: a cycle that moves the coordinate system.
fn is_transform_cycle(b: &Block) -> bool {
    let id = cycle_id(b);
    id.is_none_or(|v| [7, 8, 10, 11, 19, 26, 247].contains(&(v.trunc() as i64)))
}

/// The cycle number of a `CYCL DEF n.m …` block (`7.1`, `203`), read from its words or, when a
/// word errmap does not read follows (`Q200=+2`, `~`), from its text.
fn cycle_id(b: &Block) -> Option<f64> {
    let from_words = b
        .words
        .iter()
        .find(|w| w.addr.is_empty())
        .and_then(|w| w.num());
    from_words.or_else(|| {
        let mut t = b.rest.split_whitespace();
        t.next()
            .filter(|d| d.eq_ignore_ascii_case("DEF"))
            .and(t.next())
            .filter(|n| n.bytes().all(|c| c.is_ascii_digit() || c == b'.'))
            .and_then(|n| n.parse().ok())
    })
}

/// The units of the `BEGIN PGM name MM|INCH` block, with its line, if the program has one.
fn header_units(text: &str, source: &Path) -> Result<Option<(Units, u64)>> {
    for (i, l) in text.lines().enumerate() {
        let up = l.to_ascii_uppercase();
        let words: Vec<&str> = up.split_whitespace().collect();
        let Some(at) = words.windows(2).position(|w| w == ["BEGIN", "PGM"]) else {
            continue;
        };
        let line = i as u64 + 1;
        return match words.get(at + 3).copied() {
            Some("MM") => Ok(Some((Units::Mm, line))),
            Some("INCH") => Ok(Some((Units::Inch, line))),
            other => Err(Error::input(
                Location::cell(source, line, format!("1 ({})", l.trim())),
                format!(
                    "BEGIN PGM without MM or INCH after the program name (found {})",
                    other.unwrap_or("nothing")
                ),
                "write the header as `0 BEGIN PGM name MM` or `0 BEGIN PGM name INCH`",
            )),
        };
    }
    Ok(None)
}

fn units_word(u: Units) -> &'static str {
    match u {
        Units::Mm => "MM",
        Units::Inch => "INCH",
    }
}

/// Most decimals in any number of the program (capped at 9), so unchanged end points are
/// written back exactly.
fn program_decimals(text: &str) -> usize {
    let mut best = 0;
    for tok in text.split(|c: char| c.is_whitespace()) {
        if let Some((i, f)) = tok.split_once('.') {
            let digits = f.bytes().take_while(u8::is_ascii_digit).count();
            if digits == f.len() && i.bytes().last().is_some_and(|b| b.is_ascii_digit()) {
                best = best.max(digits);
            }
        }
    }
    best.min(9)
}
