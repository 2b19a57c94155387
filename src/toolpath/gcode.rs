//! The G-code rewrite: modal state, classification of each move against the zone and the map
//! domain, and emission of compensated segments (P' = P − E along the normal axis).
//!
//! Lines that are not rewritten are copied byte for byte from the input. See `docs/toolpath.md`.

mod emit;
mod format;
mod modal;

use emit::emit_curve;
pub(crate) use emit::{dist, emit_points, lerp};
use format::{coordinate_decimals, decimal_units, format_decimals_slow, units_text};
pub use format::{format_coord, format_decimals};
use modal::{first_jump, refuse_klartext};

use super::arc::{Arc, Plane};
use super::dialect::{self, Dialect, Frame, Motion, G};
use super::expr::{eval, Params};
use super::lexer::{lex_dialect, Line, TokenKind, WordValue};
use super::{CompensationReport, CompensationSettings};
use crate::error::{Error, Location, Result};
use crate::geom::ErrorField;
use std::cell::Cell;
use std::collections::HashMap;
use std::ops::Range;
use std::path::Path;

const AXES: [u8; 3] = [b'X', b'Y', b'Z'];

/// A word of the current line, with its value evaluated when possible.
#[derive(Debug, Clone)]
struct W {
    letter: u8,
    value: Option<f64>,
    is_expr: bool,
    token: usize,
    span: Range<usize>,
    /// Sinumerik `AC()` (`Some(true)`) or `IC()` (`Some(false)`): overrides G90/G91.
    abs: Option<bool>,
    /// The number was written without a decimal point.
    no_dot: bool,
}

/// What a subroutine body does, collected while reading its definition.
#[derive(Debug, Default, Clone)]
struct SubInfo {
    def_line: u64,
    writes_normal: bool,
    first_move: Option<u64>,
    calls: Vec<String>,
}

/// An open O-word block (`if`, `while`, `do`, `repeat`) at the top level.
#[derive(Debug)]
struct Block {
    name: String,
    keyword: String,
    line: u64,
    written: [bool; 3],
}

struct Rewriter<'a> {
    text: &'a str,
    source: &'a Path,
    field: &'a dyn ErrorField,
    settings: &'a CompensationSettings,
    normal: usize,
    plane_uv: (usize, usize),
    // Modal state of the original program.
    pos: [Option<f64>; 3],
    inches: bool,
    absolute: bool,
    arc_absolute: bool,
    plane: Plane,
    motion: Option<i32>,
    cutter_comp: Option<(u64, String)>,
    params: Params,
    // Output state: the output position differs from `pos` only along the normal, by `offset`.
    offset: f64,
    out_motion: Option<i32>,
    // Flow control.
    blocks: Vec<Block>,
    sub: Option<(String, SubInfo)>,
    subs: HashMap<String, SubInfo>,
    /// Most decimals in any coordinate word of the program (capped at 9).
    program_decimals: usize,
    /// Line where the position became unknown, for messages.
    unknown_since: Option<u64>,
    report: CompensationReport,
    out: String,
    dialect: Dialect,
    /// Whether the program's units are known (a G20/G21 or equivalent, or `--units`).
    units_known: bool,
    /// The zone in the program's first units, until those are known; then `zone_mm`.
    zone_first_units: Option<(f64, f64)>,
    zone_mm: Option<(f64, f64)>,
    /// Work coordinates = program coordinates + `shift` (G92, G52, Sinumerik TRANS), program units.
    shift: [f64; 3],
    /// Fanuc G52 local offsets (part of `shift`).
    local: [f64; 3],
    /// Transformations errmap does not follow, with the line and word that started them.
    frames: Vec<(Frame, u64, String)>,
    /// The first work offset selected (the map's coordinates); another one is a frame.
    first_offset: Option<i32>,
    /// A jump (`GOTO`, Sinumerik flow control): any cut in the zone is refused.
    flow: Option<(u64, String)>,
    /// Fanuc: O-number headers seen, and the line of an `M99` in the main program.
    programs: u32,
    m99: Option<u64>,
    /// Set by `error_at` when a point in the zone lies outside the measured domain.
    extrapolated: Cell<bool>,
}

/// Compensate a G-code program. See the module documentation of [`crate::toolpath`].
pub fn compensate(
    text: &str,
    source: &Path,
    field: &dyn ErrorField,
    settings: &CompensationSettings,
) -> Result<(String, CompensationReport)> {
    settings.validate()?;
    let dialect = dialect::resolve(text, source, settings.dialect)?;
    refuse_klartext(text, source, dialect)?;
    let zone_mm = super::default_zone_mm(source, field, settings)?;
    let normal_axis = field.normal();
    let (u, v) = normal_axis.plane_axes();
    let units = settings.units;
    let mut rw = Rewriter {
        text,
        source,
        field,
        settings,
        normal: normal_axis.index(),
        plane_uv: (u.index(), v.index()),
        pos: [None; 3],
        inches: units == Some(super::Units::Inch),
        absolute: true,
        arc_absolute: false,
        plane: Plane::G17,
        motion: None,
        cutter_comp: None,
        params: Params::new(),
        offset: 0.0,
        out_motion: None,
        blocks: Vec::new(),
        sub: None,
        subs: HashMap::new(),
        unknown_since: None,
        program_decimals: 0,
        report: CompensationReport::default(),
        out: String::with_capacity(text.len() + text.len() / 4),
        dialect,
        units_known: false,
        zone_first_units: settings.zone,
        zone_mm,
        shift: [0.0; 3],
        local: [0.0; 3],
        frames: Vec::new(),
        first_offset: None,
        flow: None,
        programs: 0,
        m99: None,
        extrapolated: Cell::new(false),
    };
    if units.is_some() {
        rw.set_units_known();
    }
    let lines = lex_dialect(text, dialect);
    rw.flow = first_jump(text, &lines, dialect);
    rw.program_decimals = coordinate_decimals(text, &lines);
    rw.report.lines_in = lines.len() as u64;
    for line in &lines {
        rw.line(line)?;
        super::check_output_size(source, line.number, rw.out.len())?;
    }
    if let (Some(l), true) = (rw.m99, rw.report.moves_changed > 0) {
        return Err(Error::input(
            Location::cell(source, l, "M99"),
            "the program ends in M99: it is a subprogram, whose moves run in its caller's position, modes and frames, which errmap cannot see",
            "compensate the main program with the subprogram expanded into it",
        ));
    }
    rw.report.dialect = Some(dialect);
    rw.report.zone_mm = rw.zone_mm;
    rw.report.lines_out = rw.out.matches('\n').count() as u64
        + u64::from(!rw.out.is_empty() && !rw.out.ends_with('\n'));
    Ok((rw.out, rw.report))
}

/// `G` value × 10, rounded (G38.2 → 382).
fn g_code(v: f64) -> i32 {
    (v * 10.0).round() as i32
}

impl<'a> Rewriter<'a> {
    fn wtext(&self, w: &W) -> &'a str {
        self.text.get(w.span.clone()).unwrap_or("").trim()
    }

    /// Whether the map compensates at plane point (u, v) in program coordinates.
    fn compensable(&self, u: f64, v: f64) -> bool {
        let s = self.scale_mm();
        let (u, v) = (
            (u + self.shift[self.plane_uv.0]) * s,
            (v + self.shift[self.plane_uv.1]) * s,
        );
        self.field.error_mm(u, v).is_some()
            && (self.settings.extrapolate
                || self.field.measured(u, v, self.settings.domain_margin_mm) == Some(true))
    }

    /// Coordinates get at least 4 decimals in mm and 5 in inches, and as many as the program
    /// itself uses (so unchanged end points are written back exactly).
    fn fmt(&self, v: f64) -> String {
        format_decimals(v, self.decimals())
    }

    fn decimals(&self) -> usize {
        let d = if self.inches { 5 } else { 4 };
        d.max(self.program_decimals)
    }

    /// The text of a coordinate and the value the controller reads from it.
    fn written(&self, v: f64) -> (String, f64) {
        let d = self.decimals();
        match decimal_units(v, d) {
            Some(u) => (units_text(u, d), u as f64 / 10f64.powi(d as i32)),
            None => {
                let t = format_decimals_slow(v, d);
                let r = t.parse().unwrap_or(v);
                (t, r)
            }
        }
    }

    fn scale_mm(&self) -> f64 {
        if self.inches {
            25.4
        } else {
            1.0
        }
    }

    /// An error at `word` (its first occurrence on the line gives the column).
    fn err(&self, line: &Line, word: &str, message: String, hint: &str) -> Error {
        let content = self.text.get(line.span.clone()).unwrap_or("");
        let at = content
            .find(word)
            .or_else(|| {
                content
                    .to_ascii_uppercase()
                    .find(&word.to_ascii_uppercase())
            })
            .unwrap_or(0);
        let column = content[..at].chars().count() + 1;
        Error::input(
            Location::cell(self.source, line.number, format!("{column} ({word})")),
            message,
            hint,
        )
    }

    /// What ends an inserted block: ` *` in Heidenhain ISO.
    fn eob(&self) -> &'static str {
        if self.dialect == Dialect::Heidenhain {
            " *"
        } else {
            ""
        }
    }

    fn copy_line(&mut self, line: &Line) {
        self.out.push_str(&self.text[line.span.start..line.end]);
    }

    /// E in program units at a point, if the point is in the zone and the map domain.
    fn error_at(&self, p: &[f64; 3]) -> Option<f64> {
        if let Some((lo, hi)) = self.zone_now() {
            let n = p[self.normal];
            if n < lo || n > hi {
                return None;
            }
        }
        let s = self.scale_mm();
        let (u, v) = (
            (p[self.plane_uv.0] + self.shift[self.plane_uv.0]) * s,
            (p[self.plane_uv.1] + self.shift[self.plane_uv.1]) * s,
        );
        let e_mm = self.field.error_mm(u, v)?;
        if !self.settings.extrapolate
            && self.field.measured(u, v, self.settings.domain_margin_mm) != Some(true)
        {
            self.extrapolated.set(true);
            return None;
        }
        e_mm.is_finite().then_some(e_mm / s)
    }

    /// Could a path through these points (some coordinates unknown) touch the zone and domain?
    fn may_touch(&self, points: &[[Option<f64>; 3]]) -> bool {
        let mut lo = f64::INFINITY;
        let mut hi = f64::NEG_INFINITY;
        let mut normal_known = true;
        for p in points {
            match p[self.normal] {
                Some(n) => {
                    lo = lo.min(n);
                    hi = hi.max(n);
                }
                None => normal_known = false,
            }
        }
        if let (Some((zlo, zhi)), true) = (self.zone_now(), normal_known) {
            if hi < zlo || lo > zhi {
                return false;
            }
        }
        // The domain only needs the two plane coordinates; unknown ones may be anywhere.
        let (ui, vi) = self.plane_uv;
        let known: Option<Vec<[f64; 3]>> =
            points.iter().map(|p| Some([p[ui]?, p[vi]?, 0.0])).collect();
        let Some(known) = known else {
            return true;
        };
        if known.is_empty() {
            return true;
        }
        let step = self.settings.max_segment_in(self.inches);
        let inside = |p: &[f64; 3]| self.compensable(p[0], p[1]);
        if inside(&known[0]) {
            return true;
        }
        for w in known.windows(2) {
            let len = dist(&w[0], &w[1]);
            let k = (len / step).ceil().clamp(1.0, 1e6) as usize;
            for i in 1..=k {
                if inside(&lerp(&w[0], &w[1], i as f64 / k as f64)) {
                    return true;
                }
            }
        }
        false
    }

    fn line(&mut self, line: &Line) -> Result<()> {
        let text = self.text;
        self.check_block(line)?;
        let keyword = line.tokens.iter().find_map(|t| match &t.kind {
            TokenKind::Keyword { name } => Some((name.clone(), t.span.clone())),
            _ => None,
        });
        if let Some((name, span)) = keyword {
            if !self.keyword(line, &name, span)? {
                self.copy_line(line);
                return Ok(());
            }
        }
        // Words, assignments and O-words of the line.
        let mut words: Vec<W> = Vec::new();
        let mut oword: Option<(String, String, String)> = None;
        let mut assignments: Vec<(String, Option<f64>)> = Vec::new();
        for (ti, tok) in line.tokens.iter().enumerate() {
            match &tok.kind {
                TokenKind::Word { letter, value } => {
                    let (value, is_expr, abs) = match value {
                        WordValue::Number(v) => (Some(*v), false, None),
                        WordValue::Abs(v) => (Some(*v), false, Some(true)),
                        WordValue::Inc(v) => (Some(*v), false, Some(false)),
                        WordValue::Expr(r) => (
                            text.get(r.clone()).and_then(|t| eval(t, &self.params)),
                            true,
                            None,
                        ),
                    };
                    let no_dot = value.is_some()
                        && !is_expr
                        && !text.get(tok.span.clone()).unwrap_or("").contains('.');
                    words.push(W {
                        letter: *letter,
                        value,
                        is_expr,
                        token: ti,
                        span: tok.span.clone(),
                        abs,
                        no_dot,
                    });
                }
                TokenKind::OWord { name, keyword } => {
                    let t = text.get(tok.span.clone()).unwrap_or("").to_string();
                    oword = Some((name.clone(), keyword.clone(), t));
                }
                TokenKind::Assignment { target, value_span } => {
                    let v = text
                        .get(value_span.clone())
                        .and_then(|t| eval(t, &self.params));
                    assignments.push((target.clone(), v));
                }
                _ => {}
            }
        }
        // LinuxCNC evaluates all assignments of a line after its words: store them now, but
        // only outside blocks and subroutines (inside, the value depends on the flow).
        let top = self.blocks.is_empty() && self.sub.is_none();
        for (name, v) in assignments {
            match (top, v) {
                (true, Some(v)) => {
                    self.params.insert(name, v);
                }
                _ => {
                    self.params.remove(&name);
                }
            }
        }
        if let Some((name, keyword, otext)) = oword {
            if self.dialect == Dialect::Fanuc {
                // `O1234`: a program number; a second one starts a subprogram.
                self.programs += 1;
                if self.programs > 1 && self.sub.is_none() {
                    self.sub = Some((name.clone(), SubInfo::default()));
                }
                self.copy_line(line);
                return Ok(());
            }
            self.oword(line, &name, &keyword, &otext)?;
            self.copy_line(line);
            return Ok(());
        }
        self.fanuc_m_codes(line, &words)?;
        if self.sub.is_some() {
            // Subroutine bodies are classified where they are called.
            let n = AXES[self.normal];
            let writes = words.iter().filter(|w| w.letter == b'G').any(|w| {
                !matches!(
                    w.value.and_then(|v| self.g(g_code(v))),
                    Some(
                        G::Motion(Motion::Rapid | Motion::Linear | Motion::ArcCw | Motion::ArcCcw)
                            | G::Plane(_)
                            | G::Units(_)
                            | G::Distance(_)
                            | G::ArcDistance(_)
                            | G::CutterComp(_)
                            | G::Neutral
                            | G::MotionCancel
                    )
                )
            });
            let axis_words = words
                .iter()
                .any(|w| matches!(w.letter, b'X' | b'Y' | b'Z' | b'@' | b'^'));
            let Some((_, info)) = self.sub.as_mut() else {
                return Ok(());
            };
            if words.iter().any(|w| w.letter == n) || writes {
                info.writes_normal = true;
            }
            if axis_words && info.first_move.is_none() {
                info.first_move = Some(line.number);
            }
            self.copy_line(line);
            return Ok(());
        }
        self.words(line, &words)
    }

    fn words(&mut self, line: &Line, words_in: &[W]) -> Result<()> {
        let gs = self.g_words(line, words_in)?;
        self.modal(line, &gs);
        let scaled = self.fanuc_numbers(line, words_in)?;
        let words: &[W] = scaled.as_deref().unwrap_or(words_in);
        let find = |l: u8| words.iter().find(|w| w.letter == l);
        let motion_word = gs
            .iter()
            .find(|(_, _, g)| matches!(g, G::Motion(_) | G::MotionCancel));
        let group0 = gs.iter().find(|(_, _, g)| {
            matches!(
                g,
                G::SetPosition
                    | G::Frame(_)
                    | G::FrameCancel(_)
                    | G::Home
                    | G::DataSetting
                    | G::Call
            )
        });
        let g53 = gs.iter().any(|(_, _, g)| *g == G::Machine);
        let axis_present = words.iter().any(|w| {
            matches!(
                w.letter,
                b'X' | b'Y' | b'Z' | b'A' | b'B' | b'C' | b'U' | b'V' | b'W' | b'@' | b'^'
            )
        });
        let arc_words = words
            .iter()
            .any(|w| matches!(w.letter, b'I' | b'J' | b'K' | b'R'));
        if let Some((_, c, g)) = motion_word {
            self.motion = (*g != G::MotionCancel).then_some(*c);
        }
        let motion = self.motion;

        // Group 0 codes that take axis words (G10, G28, G30, G92…): no cutting move on the line.
        if let Some(&(gw, _, g)) = group0 {
            self.return_if_needed(line, words, true)?;
            self.group0(line, words, gw, g)?;
            self.sync_out_motion(words);
            self.copy_line(line);
            return Ok(());
        }

        let moves =
            axis_present || (motion_word.is_some() && arc_words && matches!(motion, Some(20 | 30)));
        let Some(motion) = motion.filter(|_| moves) else {
            // No motion on this line.
            self.sync_out_motion(words);
            self.copy_line(line);
            return Ok(());
        };

        self.fix_zone();
        // Start and end of the move in the original program.
        let start = self.pos;
        let mut end = self.pos;
        let polar = words.iter().find(|w| w.letter == b'@' || w.letter == b'^');
        for (i, l) in AXES.iter().enumerate() {
            if let Some(w) = find(*l) {
                end[i] = if g53 {
                    None
                } else if w.abs.unwrap_or(self.absolute) {
                    w.value
                } else {
                    match (start[i], w.value) {
                        (Some(s), Some(d)) => Some(s + d),
                        _ => None,
                    }
                };
            }
        }
        if polar.is_some() {
            let (a1, a2, _) = self.plane.axes();
            end[a1] = None;
            end[a2] = None;
        }
        let other_axis = words
            .iter()
            .find(|w| matches!(w.letter, b'A' | b'B' | b'C' | b'U' | b'V' | b'W'));
        let expr_word = words.iter().find(|w| w.is_expr);
        let cutting = matches!(
            self.g(motion),
            Some(G::Motion(Motion::Linear | Motion::ArcCw | Motion::ArcCcw))
        );
        // `/` at the start of a line: block delete, the controller may skip the line.
        let block_delete = line
            .tokens
            .iter()
            .find(|t| t.kind != TokenKind::Space)
            .is_some_and(|t| {
                t.kind == TokenKind::Other && self.text.get(t.span.clone()) == Some("/")
            });

        // Refusals: things errmap cannot compensate safely, if the move may touch the zone.
        let refusal: Option<(String, String, &str)> = if !cutting {
            let special = self.g(motion) == Some(G::Motion(Motion::Special))
                && !(self.dialect == Dialect::Linuxcnc && (380..=385).contains(&motion));
            if self.is_canned(motion) || special {
                let mut pts = vec![start, end];
                if self.is_canned(motion) {
                    // The drill axis runs from the start through the R level to the bottom Z;
                    // under G91, R is relative to the start and Z to the R level.
                    let (_, _, ax) = self.plane.axes();
                    let r = find(b'R').and_then(|w| w.value);
                    let z = find(AXES[ax]).and_then(|w| w.value);
                    let (r_abs, z_abs) = if self.absolute {
                        (r, z)
                    } else {
                        let ra = start[ax].zip(r).map(|(s, r)| s + r);
                        (ra, ra.zip(z).map(|(ra, z)| ra + z))
                    };
                    pts[1][ax] = start[ax];
                    for level in [r_abs, z_abs] {
                        let mut p = pts[1];
                        p[ax] = level;
                        pts.push(p);
                    }
                }
                let name = format!("G{}", motion as f64 / 10.0);
                let what = if self.is_canned(motion) {
                    format!("canned cycle {name}")
                } else {
                    format!(
                        "{name} (in the {} dialect a spline, thread, tap or other move errmap does not follow)",
                        self.dialect.name()
                    )
                };
                self.may_touch(&pts).then(|| {
                    (
                        name,
                        format!("{what} in the compensation zone cannot be compensated"),
                        "expand the cycle into G0/G1 moves with your CAM post (or move the zone away)",
                    )
                })
            } else {
                None
            }
        } else if !self.units_known {
            let at = words
                .iter()
                .find(|w| matches!(w.letter, b'G' | b'X' | b'Y' | b'Z'))
                .map(|w| self.wtext(w).to_string())
                .unwrap_or_default();
            let (codes, hint) = match self.dialect {
                Dialect::Linuxcnc | Dialect::Fanuc => ("G20/G21", "add G21 (mm) or G20 (inch) before the first cut, or pass --units mm|inch"),
                Dialect::Sinumerik => ("G70/G71/G700/G710", "add G71 (mm) or G70 (inch) before the first cut, or pass --units mm|inch"),
                Dialect::Heidenhain => ("G70/G71 in the % header", "begin the program with %NAME G71 * (mm) or G70 * (inch), or pass --units mm|inch"),
            };
            Some((
                at,
                format!("cut with no unit code ({codes}) before it: errmap cannot tell millimetres from inches (a 25.4× error)"),
                hint,
            ))
        } else if let Some((kind, fl, fw)) = self.frames.last().cloned() {
            let pts = self.frame_points(kind, &[start, end]);
            self.may_touch(&pts).then(|| {
                (
                    fw.clone(),
                    format!("`{fw}` (line {fl}) transforms the coordinates ({kind:?}), which errmap does not follow, and this cut may lie in the compensation zone"),
                    "cancel the transformation before the cuts in the zone (G69, G50, G50.1, G54 …), or post the program without it",
                )
            })
        } else if let Some((fl, fw)) = self.flow.clone() {
            self.may_touch(&[start, end]).then(|| {
                (
                    fw.clone(),
                    format!("the program jumps (`{fw}` on line {fl}), so a cut may run any number of times from any position, and this cut may lie in the compensation zone"),
                    "expand loops and jumps into plain blocks",
                )
            })
        } else if !self.blocks.is_empty() {
            let b = &self.blocks[self.blocks.len() - 1];
            let head = format!("o{} {}", b.name, b.keyword);
            let bl = b.line;
            self.may_touch(&[start, end]).then(|| {
                (
                    head.clone(),
                    format!("move inside the O-word block `{head}` (line {bl}) may lie in the compensation zone"),
                    "expand O-word loops, conditions and subroutines into plain G-code (or move the zone away)",
                )
            })
        } else if let Some((cl, code)) = self.cutter_comp.clone() {
            self.may_touch(&[start, end]).then(|| {
                (
                    code.clone(),
                    format!("cutter radius compensation {code} (from line {cl}) is active on a move in the compensation zone"),
                    "post the program as the tool-centre path (G40) for the zone, or move the zone away",
                )
            })
        } else if block_delete {
            self.may_touch(&[start, end]).then(|| {
                (
                    "/".into(),
                    "block delete `/` on a move in the compensation zone (the controller may skip the line)".into(),
                    "remove the `/` or move the zone away",
                )
            })
        } else if let Some(w) = polar {
            self.may_touch(&[start, end]).then(|| {
                (
                    self.wtext(w).to_string(),
                    "polar coordinates (@ ^) on a move in the compensation zone".into(),
                    "post the program with X/Y coordinates (or move the zone away)",
                )
            })
        } else if let Some(w) = expr_word {
            self.may_touch(&[start, end]).then(|| {
                (
                    self.wtext(w).to_string(),
                    "# parameters or [expressions] on a move in the compensation zone".into(),
                    "expand the program to plain numbers (or move the zone away)",
                )
            })
        } else if let Some(w) = other_axis {
            self.may_touch(&[start, end]).then(|| {
                (
                    self.wtext(w).to_string(),
                    format!(
                        "axis {} moves together with a cut in the compensation zone",
                        w.letter as char
                    ),
                    "errmap compensates 3-axis X/Y/Z moves only; move the zone away from this move",
                )
            })
        } else if g53 {
            self.may_touch(&[start, end]).then(|| {
                (
                    "G53".into(),
                    "G53 machine-coordinate cutting move in the compensation zone".into(),
                    "program the cut in work coordinates",
                )
            })
        } else if start.iter().any(|c| c.is_none()) {
            let since = self
                .unknown_since
                .map(|l| format!(" since line {l}"))
                .unwrap_or_else(|| " (no absolute X, Y and Z since the program start)".into());
            self.may_touch(&[start, end]).then(|| {
                (
                    "start".into(),
                    format!("the start point of this move is unknown{since}, so errmap cannot tell whether it lies in the compensation zone"),
                    "give absolute X, Y and Z (G90) before the first cut",
                )
            })
        } else {
            None
        };
        if let Some((col, msg, hint)) = refusal {
            return Err(self.err(line, &col, msg, hint));
        }

        let plain = cutting
            && self.units_known
            && self.frames.is_empty()
            && self.flow.is_none()
            && !block_delete
            && self.blocks.is_empty()
            && self.cutter_comp.is_none()
            && polar.is_none()
            && expr_word.is_none()
            && other_axis.is_none()
            && !g53
            && start.iter().all(|c| c.is_some());
        if !plain {
            // Not compensable, but shown above not to touch the zone: copy as is.
            let mut end = end;
            if block_delete {
                // Executed or not: the axes it writes are unknown afterwards.
                for i in 0..3 {
                    if end[i] != start[i] {
                        end[i] = None;
                    }
                }
            }
            if (380..=385).contains(&motion) {
                // A probing move stops where it touches.
                for i in 0..3 {
                    if end[i] != start[i] {
                        end[i] = None;
                    }
                }
            }
            if self.is_canned(motion) {
                // The cycle retracts to the R level or the start (G98/G99): not tracked.
                end[self.plane.axes().2] = None;
            }
            return self.finish_unchanged(line, words, end);
        }
        let s = [
            start[0].unwrap_or(0.0),
            start[1].unwrap_or(0.0),
            start[2].unwrap_or(0.0),
        ];
        let e = [
            end[0].unwrap_or(s[0]),
            end[1].unwrap_or(s[1]),
            end[2].unwrap_or(s[2]),
        ];
        // The original path as a polyline of points on it.
        let arc = if motion == 10 {
            None
        } else {
            Some(self.arc(line, words, s, e, motion == 20)?)
        };
        // Keep the output finite: a move needing over a million segments is a typo or a unit
        // mistake, not a toolpath.
        let step = self.settings.max_segment_in(self.inches);
        let (length, chords) = match &arc {
            None => (dist(&s, &e), 1),
            Some(a) => {
                let (_, _, ax) = a.plane.axes();
                let len = (a.sweep.abs() * a.r_start.max(a.r_end)).hypot(a.end[ax] - a.start[ax]);
                (len, a.chords(self.settings.chord_tol_in(self.inches), step))
            }
        };
        if !length.is_finite() || length / step > 1e6 || chords >= 1_000_000 {
            return Err(self.err(
                line,
                "X",
                format!("this move ({length:.6e} program units) would need more than a million segments"),
                "check the coordinates and units, or raise --max-segment / --chord-tol",
            ));
        }
        // The move as a curve over [0, 1] with its chord ends as break points: splits at the
        // zone and domain edges fall on the curve itself (on the arc, not on a chord).
        let breaks: Vec<f64> = (0..=chords).map(|i| i as f64 / chords as f64).collect();
        let line_at = |t: f64| lerp(&s, &e, t);
        let arc_at = |t: f64| arc.as_ref().map_or(e, |a| a.point(t));
        let curve: &dyn Fn(f64) -> [f64; 3] = if arc.is_some() { &arc_at } else { &line_at };
        let emitted = emit_curve(
            &breaks,
            curve,
            self.settings.max_segment_in(self.inches),
            self.zone_now(),
            self.normal,
            &|p| self.error_at(p),
        );
        if self.extrapolated.replace(false) {
            self.report.moves_outside_domain += 1;
        }
        if !emitted.iter().any(|(_, e)| e.is_some()) {
            return self.finish_unchanged(line, words, end);
        }
        self.rewrite(line, words, &emitted, arc.as_ref(), motion)?;
        self.pos = [Some(e[0]), Some(e[1]), Some(e[2])];
        Ok(())
    }

    fn arc(&self, line: &Line, words: &[W], s: [f64; 3], e: [f64; 3], cw: bool) -> Result<Arc> {
        let find = |l: u8| words.iter().find(|w| w.letter == l).and_then(|w| w.value);
        let turns = match find(b'P') {
            Some(p) if p >= 1.0 && p.fract() == 0.0 => p as u32,
            Some(_) => {
                return Err(self.err(
                    line,
                    "P",
                    "arc turn count P must be a positive whole number".into(),
                    "use P1, P2, …",
                ))
            }
            None => 1,
        };
        let (a1, a2, _) = self.plane.axes();
        let result = if let Some(r) = find(b'R') {
            Arc::from_radius(self.plane, s, e, r, cw, turns)
        } else {
            // Offsets I, J, K go with X, Y, Z; Sinumerik `I=AC(…)` is an absolute centre.
            let word = |axis: usize| words.iter().find(|w| w.letter == [b'I', b'J', b'K'][axis]);
            let off = |axis: usize| word(axis).and_then(|w| w.value);
            let abs = |axis: usize| word(axis).and_then(|w| w.abs).unwrap_or(self.arc_absolute);
            let (o1, o2) = (off(a1), off(a2));
            if o1.is_none() && o2.is_none() {
                return Err(self.err(
                    line,
                    if cw { "G2" } else { "G3" },
                    "arc without R and without centre words for the selected plane".into(),
                    "give R or the I/J/K words of the plane (G17: I J, G18: I K, G19: J K)",
                ));
            }
            let centre = |o: Option<f64>, axis: usize, start: f64| {
                if abs(axis) {
                    o.unwrap_or(start)
                } else {
                    start + o.unwrap_or(0.0)
                }
            };
            let c = (centre(o1, a1, s[a1]), centre(o2, a2, s[a2]));
            Arc::from_centre(self.plane, s, e, c, cw, turns)
        };
        result.map_err(|m| {
            self.err(
                line,
                if cw { "G2" } else { "G3" },
                m,
                "fix the arc's end point or centre",
            )
        })
    }

    /// Emit a return along the normal to the original position before an unchanged line that
    /// depends on the current position, when the last cut ended compensated.
    fn return_if_needed(&mut self, line: &Line, words: &[W], group0: bool) -> Result<()> {
        if self.offset == 0.0 {
            return Ok(());
        }
        let n = AXES[self.normal];
        // A canned cycle's Z word is the hole bottom, and it retracts to its start: not a move
        // to an absolute normal coordinate.
        let absolute_normal = !group0
            && self.absolute
            && !self.motion.is_some_and(|m| self.is_canned(m))
            && words.iter().any(|w| w.letter == n && w.value.is_some())
            && !words
                .iter()
                .any(|w| w.letter == b'G' && w.value.map(g_code) == Some(530));
        if absolute_normal {
            self.offset = 0.0;
            return Ok(());
        }
        let Some(orig) = self.pos[self.normal] else {
            return Err(Error::Internal(format!(
                "{}:{}: compensated position with unknown normal coordinate",
                self.source.display(),
                line.number
            )));
        };
        let value = if self.absolute { orig } else { -self.offset };
        let code = if self.out_motion == Some(0) {
            "G0"
        } else {
            "G1"
        };
        self.out.push_str(&format!(
            "{code} {}{}{}",
            n as char,
            self.fmt(value),
            self.eob()
        ));
        self.out.push_str(line_terminator(self.text, line));
        self.out_motion = Some(if code == "G0" { 0 } else { 10 });
        self.offset = 0.0;
        self.report.returns_inserted += 1;
        Ok(())
    }

    /// Keep the output's modal motion in step with the original's on an unchanged line.
    fn sync_out_motion(&mut self, words: &[W]) {
        if words
            .iter()
            .any(|w| w.letter == b'G' && w.value.map(g_code).is_some_and(|c| self.is_group1(c)))
        {
            self.out_motion = self.motion;
        }
    }

    fn finish_unchanged(&mut self, line: &Line, words: &[W], end: [Option<f64>; 3]) -> Result<()> {
        self.return_if_needed(line, words, false)?;
        let has_motion_g = words
            .iter()
            .any(|w| w.letter == b'G' && w.value.map(g_code).is_some_and(|c| self.is_group1(c)));
        let moves = words.iter().any(|w| {
            matches!(
                w.letter,
                b'X' | b'Y'
                    | b'Z'
                    | b'A'
                    | b'B'
                    | b'C'
                    | b'U'
                    | b'V'
                    | b'W'
                    | b'I'
                    | b'J'
                    | b'K'
                    | b'R'
                    | b'@'
                    | b'^'
            )
        });
        match self.motion {
            Some(m) if moves && !has_motion_g && self.out_motion != self.motion => {
                // The output's modal motion differs (after a return step): say it on this
                // line, after its block delete and N-word, which must come first.
                let mut at = line.span.start;
                for t in &line.tokens {
                    let lead = match &t.kind {
                        TokenKind::Space => true,
                        TokenKind::Word { letter: b'N', .. } => true,
                        TokenKind::Other => self.text.get(t.span.clone()) == Some("/"),
                        _ => false,
                    };
                    if !lead {
                        break;
                    }
                    at = t.span.end;
                }
                let text = self.text;
                self.out.push_str(&text[line.span.start..at]);
                if at > line.span.start && !text[..at].ends_with([' ', '\t']) {
                    self.out.push(' ');
                }
                self.out.push_str(&format!("G{} ", m as f64 / 10.0));
                self.out.push_str(&text[at..line.end]);
                self.report.lines_prefixed += 1;
            }
            _ => self.copy_line(line),
        }
        if has_motion_g || moves {
            self.out_motion = self.motion;
        }
        // Position bookkeeping.
        let mut end = end;
        if !self.blocks.is_empty() && !self.absolute {
            // Incremental moves inside a loop land somewhere else on each pass.
            for (i, l) in AXES.iter().enumerate() {
                if words.iter().any(|w| w.letter == *l) {
                    end[i] = None;
                }
            }
        }
        for (i, e) in end.iter().enumerate() {
            if *e != self.pos[i] {
                if let Some(b) = self.blocks.last_mut() {
                    b.written[i] = true;
                }
                if e.is_none() {
                    self.unknown_since = Some(line.number);
                }
            }
        }
        self.pos = end;
        Ok(())
    }

    fn rewrite(
        &mut self,
        line: &Line,
        words: &[W],
        emitted: &[([f64; 3], Option<f64>)],
        arc: Option<&Arc>,
        motion: i32,
    ) -> Result<()> {
        let text = self.text;
        let term = line_terminator(text, line);
        let term_last = line.terminator(text);
        // Current output position.
        let mut out_pos = [
            self.pos[0].unwrap_or(0.0),
            self.pos[1].unwrap_or(0.0),
            self.pos[2].unwrap_or(0.0),
        ];
        out_pos[self.normal] += self.offset;
        // Targets: compensated points P' = P − E along the normal.
        let mut targets: Vec<[f64; 3]> = Vec::with_capacity(emitted.len());
        let mut last_e = None;
        for (p, e) in emitted {
            let mut q = *p;
            if let Some(e) = e {
                q[self.normal] -= e;
                let e_mm = e.abs() * self.scale_mm();
                if e_mm > self.report.max_abs_error_mm {
                    self.report.max_abs_error_mm = e_mm;
                }
                self.report.points_compensated += 1;
            }
            last_e = *e;
            targets.push(q);
        }
        // Drop points that repeat the current output position.
        let mut segs: Vec<[f64; 3]> = Vec::with_capacity(targets.len());
        let mut prev = out_pos;
        for q in targets {
            if dist(&q, &prev) > 1e-12 {
                segs.push(q);
                prev = q;
            }
        }
        if segs.is_empty() {
            segs.push(prev);
        }
        let removed = |w: &W| {
            matches!(w.letter, b'X' | b'Y' | b'Z' | b'I' | b'J' | b'K' | b'R')
                || (w.letter == b'G'
                    && w.value
                        .map(g_code)
                        .is_some_and(|c| matches!(c, 0 | 10 | 20 | 30)))
                || (w.letter == b'P' && arc.is_some())
        };
        let mut removed_tokens = vec![false; line.tokens.len()];
        for w in words.iter().filter(|w| removed(w)) {
            removed_tokens[w.token] = true;
        }
        let nseg = segs.len();
        let mut lines_text: Vec<String> = Vec::with_capacity(nseg);
        for (k, q) in segs.iter().enumerate() {
            let final_arc = k + 1 == nseg && arc.is_some();
            let mut words_text = String::new();
            let mut code = "G1".to_string();
            let mut r_word = None;
            if final_arc {
                if let Some(a) = arc {
                    let (a1, a2, _) = a.plane.axes();
                    let chord = (q[a1] - out_pos[a1]).hypot(q[a2] - out_pos[a2]);
                    if chord > 1e-6 && 2.0 * a.r_end > chord {
                        code = if motion == 20 {
                            "G2".into()
                        } else {
                            "G3".into()
                        };
                        r_word = Some(a.r_end);
                    }
                }
            }
            // The words as written, and the values the controller reads from them.
            let written: Vec<(String, f64)> = (0..3)
                .map(|i| {
                    let v = if self.absolute {
                        q[i]
                    } else {
                        q[i] - out_pos[i]
                    };
                    self.written(v)
                })
                .collect();
            // No zero-length moves: a point that rounds to where the tool already is goes.
            let d = self.decimals();
            let zero = (0..3).all(|i| {
                if self.absolute {
                    decimal_units(written[i].1, d) == decimal_units(out_pos[i], d)
                } else {
                    decimal_units(written[i].1, d) == Some(0)
                }
            });
            if zero {
                continue;
            }
            words_text.push_str(&code);
            for (i, l) in AXES.iter().enumerate() {
                // Track the position the controller will reach after rounding.
                out_pos[i] = if self.absolute {
                    written[i].1
                } else {
                    out_pos[i] + written[i].1
                };
                words_text.push_str(&format!(" {}{}", *l as char, written[i].0));
            }
            if let Some(r) = r_word {
                let r_letter = if self.dialect == Dialect::Sinumerik {
                    "CR="
                } else {
                    "R"
                };
                words_text.push_str(&format!(" {r_letter}{}", self.fmt(r)));
            }
            self.out_motion = Some(if code == "G1" { 10 } else { motion });
            lines_text.push(words_text);
        }
        if lines_text.is_empty() {
            // Every point rounds to the current position: the line keeps its other words only.
            lines_text.push(String::new());
        }
        let nseg = lines_text.len();
        // Program stops (M0 M1 M2 M30 M60) act after the line's motion: they move to the last
        // segment, so the program does not stop after the first one.
        let stops: Vec<&W> = if nseg > 1 {
            words
                .iter()
                .filter(|w| {
                    w.letter == b'M'
                        && w.value
                            .is_some_and(|v| [0.0, 1.0, 2.0, 30.0, 60.0].contains(&v))
                })
                .collect()
        } else {
            Vec::new()
        };
        if let Some(last) = lines_text.last_mut() {
            for w in &stops {
                last.push(' ');
                last.push_str(self.wtext(w));
            }
        }
        let mut stop_tokens = vec![false; line.tokens.len()];
        for w in &stops {
            stop_tokens[w.token] = true;
        }
        // First line: the original line with its motion words replaced by the first segment.
        let mut first = String::new();
        let mut inserted = false;
        let mut skip_space = false;
        for (ti, tok) in line.tokens.iter().enumerate() {
            if stop_tokens[ti] {
                skip_space = true;
                continue;
            }
            if removed_tokens[ti] {
                if !inserted {
                    first.push_str(&lines_text[0]);
                    inserted = true;
                }
                skip_space = true;
                continue;
            }
            if skip_space && tok.kind == TokenKind::Space {
                skip_space = false;
                if ti + 1 < line.tokens.len() && !removed_tokens[ti + 1] {
                    first.push(' ');
                }
                continue;
            }
            skip_space = false;
            first.push_str(text.get(tok.span.clone()).unwrap_or(""));
        }
        if !inserted {
            first.push_str(&lines_text[0]);
        }
        // Inserted lines use the file's terminator; the last one keeps the line's own
        // (none on a last line without a newline).
        let eob = self.eob();
        let extra: Vec<String> = lines_text[1..]
            .iter()
            .map(|t| format!("{t}{eob}"))
            .collect();
        let mut pieces: Vec<&str> = vec![first.trim_end_matches([' ', '\t'])];
        pieces.extend(extra.iter().map(|t| t.as_str()));
        let count = pieces.len();
        for (k, piece) in pieces.into_iter().enumerate() {
            self.out.push_str(piece);
            self.out
                .push_str(if k + 1 == count { term_last } else { term });
        }
        self.report.moves_changed += 1;
        if nseg > 1 {
            self.report.moves_split += 1;
        }
        self.report.segments_emitted += nseg as u64;
        // Offset of the output along the normal at the end of the move.
        self.offset = match last_e {
            Some(e) => -e,
            None => 0.0,
        };
        Ok(())
    }
}

fn line_terminator<'t>(text: &'t str, line: &Line) -> &'t str {
    match line.terminator(text) {
        "" => {
            if text.contains("\r\n") {
                "\r\n"
            } else {
                "\n"
            }
        }
        t => t,
    }
}
