//! The G-code rewrite: modal state, classification of each move against the zone and the map
//! domain, and emission of compensated segments (P' = P − E along the normal axis).
//!
//! Lines that are not rewritten are copied byte for byte from the input. See `docs/toolpath.md`.

mod contour;
mod cycles;
mod emit;
mod format;
mod modal;
mod moves;
mod rewrite;
mod sinumerik_cycles;

use crate::CompensateError;
pub(crate) use emit::{dist, emit_curve, emit_points, lerp, Breaks};
use format::{coordinate_decimals, decimal_units, push_units};
pub use format::{format_coord, format_decimals};
use modal::{first_jump, refuse_klartext};

use super::arc::Plane;
use super::dialect::{self, Dialect, Frame, GCode, Motion, G};
use super::expr::{eval, Params};
use super::lexer::{self, Line, TokenKind, WordValue};
use super::machine::Machine;
use super::{CompensationReport, CompensationSettings, TracedMove};
use errmap_core::error::{Error, Location, Result};
use errmap_core::geom::ErrorField;
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
    /// A G word's code and its meaning in the dialect (`None`: not a G word, or unknown).
    g: Option<(GCode, G)>,
}

impl W {
    /// The meaning of a G word in the dialect.
    fn g(&self) -> Option<G> {
        self.g.map(|(_, g)| g)
    }
}

/// The motion mode (group 1) in effect: what it does and the code that selected it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct MotionMode {
    kind: Motion,
    code: GCode,
}

impl MotionMode {
    /// The word errmap writes for a piece in this mode: `G2`, `G3`, or `G1` for every other.
    fn word(self) -> &'static str {
        match self.kind {
            Motion::ArcCw => "G2",
            Motion::ArcCcw => "G3",
            _ => "G1",
        }
    }

    const RAPID: MotionMode = MotionMode {
        kind: Motion::Rapid,
        code: GCode::whole(0),
    };
    const LINEAR: MotionMode = MotionMode {
        kind: Motion::Linear,
        code: GCode::whole(1),
    };
}

/// The modes in force where a line errmap inserts before the current line stands (those of the
/// previous line, before the current line's own codes apply): a return step is written in
/// them, so it runs as written whatever the current line switches.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Standing {
    absolute: bool,
    inches: bool,
    /// The original's normal coordinate and the output's offset from it, in `inches` units.
    normal_pos: Option<f64>,
    offset: f64,
}

/// What a subroutine body does, collected while reading its definition.
#[derive(Debug, Default, Clone)]
struct SubInfo {
    def_line: u64,
    writes_normal: bool,
    first_move: Option<u64>,
    calls: Vec<String>,
    /// Modal groups the body sets (`distance`, `units`, `plane`, `arc`, `motion`, `comp`),
    /// with the line and word of the first setting of each.
    sets: Vec<(&'static str, u64, String)>,
}

/// What a state errmap does not follow is about, and so what ends it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Holds {
    /// A rotary or parallel axis (its letter) away from 0: ended by that axis at 0.
    Axis(u8),
    /// A modal group a called subroutine may have changed (see [`modal_group`]): ended by a
    /// block that sets it.
    Mode(&'static str),
}

/// A state errmap does not follow (a rotary axis away from 0, modes a subroutine changed):
/// cuts in the zone are refused while it lasts; `key` says what ends it.
#[derive(Debug, Clone)]
struct Unfollowed {
    key: Holds,
    word: String,
    why: String,
    hint: std::borrow::Cow<'static, str>,
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
    /// Position, units, shift, zone and the map (shared with the Klartext reader).
    m: Machine<'a>,
    // Modal state of the original program.
    absolute: bool,
    arc_absolute: bool,
    plane: Plane,
    motion: Option<MotionMode>,
    cutter_comp: Option<(u64, String)>,
    /// G41/G42/G40 given, and the block that starts up or cancels the offset (the next move
    /// in the plane) not yet read: its line and code.
    comp_transition: Option<(u64, String)>,
    /// The canned-cycle series in progress, and the retract mode (G99: R level; G98: initial
    /// level; `None` before either).
    cycle: Option<cycles::Cycle>,
    retract_to_r: Option<bool>,
    /// Sinumerik `MCALL CYCLE8x(…)` in force: every block with path motion drills it.
    mcall: Option<sinumerik_cycles::Call>,
    /// The largest `CYCLE832` path tolerance of the program (mm) and its line.
    path_tolerance_mm: Option<(f64, u64)>,
    params: Params,
    /// The modes at the start of the current line, for lines inserted before it.
    standing: Standing,
    out_motion: Option<MotionMode>,
    // Flow control.
    blocks: Vec<Block>,
    sub: Option<(String, SubInfo)>,
    subs: HashMap<String, SubInfo>,
    /// Most decimals in any coordinate word of the program (capped at 9).
    program_decimals: usize,
    report: CompensationReport,
    out: String,
    dialect: Dialect,
    /// Fanuc G52 local offsets (part of `shift`).
    local: [f64; 3],
    /// States errmap does not follow, under which cuts in the zone are refused.
    unfollowed: Vec<Unfollowed>,
    /// Transformations errmap does not follow, with the line and word that started them.
    frames: Vec<(Frame, u64, String)>,
    /// The first work offset selected (the map's coordinates); another one is a frame.
    first_offset: Option<String>,
    /// The work offset selected now (`G55`, `G54.1 P3`), `None` before the first selection.
    active_offset: Option<String>,
    /// The line of a Sinumerik `SUPA` block: its coordinates are machine coordinates (as G53).
    machine_block: Option<u64>,
    /// A jump (`GOTO`, Sinumerik flow control): any cut in the zone is refused.
    flow: Option<(u64, String)>,
    /// Fanuc: O-number headers seen, and the line of an `M99` in the main program.
    programs: u32,
    m99: Option<u64>,
    /// Buffers kept from line to line: the words of a line, the points of a move and the
    /// segments written for it.
    words: Vec<W>,
    emitted: Vec<([f64; 3], Option<f64>)>,
    segments: rewrite::Segments,
    /// The moves read, when tracing.
    trace: Option<Vec<TracedMove>>,
}

/// Compensate a G-code program. See the module documentation of [`crate`].
pub fn compensate(
    text: &str,
    source: &Path,
    field: &dyn ErrorField,
    settings: &CompensationSettings,
) -> Result<(String, CompensationReport), CompensateError> {
    let mut rw = Rewriter::start(text, source, field, settings)?;
    rw.run()?;
    Ok(rw.finish()?)
}

/// The moves of a G-code program as errmap's interpreter reads them (see
/// [`crate::trace_gcode`]).
pub fn trace(
    text: &str,
    source: &Path,
    settings: &CompensationSettings,
) -> Result<Vec<TracedMove>, CompensateError> {
    let settings = super::trace_settings(settings);
    let mut rw = Rewriter::start(text, source, &super::Nothing, &settings)?;
    rw.trace = Some(Vec::new());
    rw.run()?;
    Ok(rw.trace.take().unwrap_or_default())
}

impl<'a> Rewriter<'a> {
    /// The state at the program start, after the checks that need the whole text.
    fn start(
        text: &'a str,
        source: &'a Path,
        field: &'a dyn ErrorField,
        settings: &'a CompensationSettings,
    ) -> Result<Rewriter<'a>, CompensateError> {
        settings.validate()?;
        let dialect = dialect::resolve(text, source, settings.dialect)?;
        refuse_klartext(text, source, dialect)?;
        let zone_mm = super::default_zone_mm(source, field, settings)?;
        let units = settings.units;
        let mut rw = Rewriter {
            text,
            source,
            m: Machine::new(field, settings, units == Some(super::Units::Inch), zone_mm),
            absolute: true,
            arc_absolute: false,
            plane: Plane::G17,
            motion: None,
            cutter_comp: None,
            comp_transition: None,
            cycle: None,
            retract_to_r: None,
            mcall: None,
            path_tolerance_mm: None,
            params: Params::new(),
            standing: Standing {
                absolute: true,
                inches: units == Some(super::Units::Inch),
                normal_pos: None,
                offset: 0.0,
            },
            out_motion: None,
            blocks: Vec::new(),
            sub: None,
            subs: HashMap::new(),
            program_decimals: 0,
            report: CompensationReport::default(),
            out: String::with_capacity(text.len() + text.len() / 4),
            dialect,
            local: [0.0; 3],
            frames: Vec::new(),
            unfollowed: Vec::new(),
            first_offset: None,
            active_offset: None,
            flow: None,
            machine_block: None,
            programs: 0,
            m99: None,
            words: Vec::new(),
            emitted: Vec::new(),
            segments: rewrite::Segments::default(),
            trace: None,
        };
        if units.is_some() {
            rw.set_units_known();
        }
        Ok(rw)
    }

    /// Read every line, rewriting the moves to compensate.
    fn run(&mut self) -> Result<()> {
        let (text, dialect) = (self.text, self.dialect);
        // What the whole program decides before its first line is rewritten: where control
        // first jumps, and how many decimals its coordinates are written with. The lines are
        // lexed twice rather than kept, so memory is that of one line.
        let (mut flow, mut decimals, mut lines) = (None, 0, 0);
        let _ = lexer::for_each_line(text, dialect, |line| {
            if flow.is_none() {
                flow = first_jump(text, line, dialect);
            }
            decimals = decimals.max(coordinate_decimals(text, line));
            lines = line.number;
            Ok::<(), std::convert::Infallible>(())
        });
        self.flow = flow;
        self.program_decimals = decimals;
        self.report.lines_in = lines;
        lexer::for_each_line(text, dialect, |line| {
            self.line(line)?;
            super::check_output_size(self.source, line.number, self.out.len())
        })
    }

    /// The output and its report; a subprogram whose moves changed is refused.
    fn finish(mut self) -> Result<(String, CompensationReport)> {
        if let (Some(l), true) = (self.m99, self.report.moves_changed > 0) {
            return Err(Error::input(
                Location::cell(self.source, l, "M99"),
                "the program ends in M99: it is a subprogram, whose moves run in its caller's position, modes and frames, which errmap cannot see",
                "compensate the main program with the subprogram expanded into it",
            ));
        }
        self.tolerance_note();
        self.report.dialect = Some(self.dialect);
        self.report.zone_mm = self.m.zone_mm;
        self.report.lines_out = self.out.bytes().filter(|&b| b == b'\n').count() as u64
            + u64::from(!self.out.is_empty() && !self.out.ends_with('\n'));
        Ok((self.out, self.report))
    }
}

impl<'a> Rewriter<'a> {
    fn wtext(&self, w: &W) -> &'a str {
        self.text.get(w.span.clone()).unwrap_or("").trim()
    }

    /// Append a coordinate: at least 4 decimals in mm and 5 in inches, and as many as the
    /// program itself uses (so unchanged end points are written back exactly).
    fn push_coord(&self, buf: &mut String, v: f64) {
        self.push_coord_in(buf, v, self.m.inches);
    }

    /// [`Self::push_coord`] for a line in the given units.
    fn push_coord_in(&self, buf: &mut String, v: f64, inches: bool) {
        let d = self.decimals_in(inches);
        match decimal_units(v, d) {
            Some(u) => push_units(buf, u, d),
            None => buf.push_str(&format_decimals(v, d)),
        }
    }

    fn decimals(&self) -> usize {
        self.decimals_in(self.m.inches)
    }

    fn decimals_in(&self, inches: bool) -> usize {
        let d = if inches { 5 } else { 4 };
        d.max(self.program_decimals)
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

    /// Could a path through these points (some coordinates unknown) touch the zone and domain?
    fn may_touch(&self, points: &[[Option<f64>; 3]]) -> bool {
        self.m.may_touch(points)
    }

    /// One line: strict checks, then a dialect statement, an O-word, a subroutine body line
    /// or a block of words.
    fn line(&mut self, line: &Line) -> Result<()> {
        self.check_block(line)?;
        self.standing = Standing {
            absolute: self.absolute,
            inches: self.m.inches,
            normal_pos: self.m.pos[self.m.normal],
            offset: self.m.offset,
        };
        // Every instruction of the block in turn: one errmap follows without moving ends the
        // line here (copied); harmless ones let the block's words be read as usual.
        let keywords = line.tokens.iter().filter_map(|t| match &t.kind {
            TokenKind::Keyword { name } => Some((name.as_str(), t.span.clone())),
            _ => None,
        });
        for (name, span) in keywords {
            if self.dialect == Dialect::Sinumerik && matches!(name, "CYCLE" | "MCALL") {
                let body = self.text.get(span.clone()).unwrap_or("");
                if self.siemens_cycle(line, name, body)? {
                    return Ok(());
                }
            }
            let body = self.text.get(span.clone()).unwrap_or("");
            let harmless = self.keyword(line, name, span)?;
            if let (true, Dialect::Sinumerik, Some(rest)) =
                (harmless, self.dialect, words_after_instruction(body))
            {
                if name != "DEF" {
                    return Err(self.err(
                        line,
                        rest,
                        format!("`{}`: words after the instruction {name} and its argument on the same block, which errmap does not read there", body.trim()),
                        "put the instruction in a block of its own",
                    ));
                }
            }
            if !harmless {
                // A statement errmap follows without moving (a label, a jump, a loop, a frame):
                // the output returns to the original first, so what follows (perhaps many
                // times) starts where the original does. The `%` of a program's start or end
                // runs nothing after it.
                if name != "%" {
                    self.return_if_needed(line, &[], true)?;
                }
                self.copy_line(line);
                return Ok(());
            }
        }
        let mut words = std::mem::take(&mut self.words);
        words.clear();
        let result = self.line_words(line, &mut words);
        self.words = words;
        result
    }

    /// The line's words read into `words`, its assignments stored, and the line handled.
    fn line_words(&mut self, line: &Line, words: &mut Vec<W>) -> Result<()> {
        let oword = self.read_words(line, words).map(|ti| &line.tokens[ti]);
        if let Some(t) = oword {
            let TokenKind::OWord { name, keyword } = &t.kind else {
                return Err(Error::Internal("an O-word token expected".into()));
            };
            let otext = self.text.get(t.span.clone()).unwrap_or("");
            if self.dialect == Dialect::Fanuc {
                // `O1234`: a program number; a second one starts a subprogram.
                self.programs += 1;
                if self.programs > 1 && self.sub.is_none() {
                    self.sub = Some((name.to_string(), SubInfo::default()));
                }
            } else {
                self.oword(line, name, keyword, otext)?;
            }
            self.return_if_needed(line, &[], true)?;
            self.copy_line(line);
            return Ok(());
        }
        self.fanuc_m_codes(line, words)?;
        if self.sub.is_some() {
            self.sub_body_line(line, words);
            self.copy_line(line);
            return Ok(());
        }
        self.block(line, words)
    }

    /// Read the words of a line (values evaluated where plain) and store its assignments;
    /// returns the index of its O-word token if it has one.
    fn read_words(&mut self, line: &Line, words: &mut Vec<W>) -> Option<usize> {
        let mut oword = None;
        let mut assigned = false;
        for (ti, tok) in line.tokens.iter().enumerate() {
            match &tok.kind {
                TokenKind::Word { letter, value } => {
                    words.push(self.word(*letter, value, ti, tok.span.clone()));
                }
                TokenKind::OWord { .. } => {
                    oword = Some(ti);
                }
                TokenKind::Assignment { .. } => assigned = true,
                _ => {}
            }
        }
        if assigned {
            self.assign(line);
        }
        oword
    }

    /// A word with its value evaluated when it is a number or a plain expression.
    fn word(&self, letter: u8, value: &WordValue, token: usize, span: Range<usize>) -> W {
        let text = self.text;
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
        let no_dot =
            value.is_some() && !is_expr && !text.get(span.clone()).unwrap_or("").contains('.');
        let g = if letter == b'G' && !is_expr {
            value
                .and_then(GCode::from_value)
                .and_then(|c| Some((c, self.g(c)?)))
        } else {
            None
        };
        W {
            letter,
            value,
            is_expr,
            token,
            span,
            abs,
            no_dot,
            g,
        }
    }

    /// LinuxCNC evaluates all assignments of a line after its words: store them now, but only
    /// outside blocks and subroutines (inside, the value depends on the flow).
    fn assign(&mut self, line: &Line) {
        let top = self.blocks.is_empty() && self.sub.is_none();
        let mut assignments: Vec<(String, Option<f64>)> = Vec::new();
        for tok in &line.tokens {
            if let TokenKind::Assignment { target, value_span } = &tok.kind {
                let v = self
                    .text
                    .get(value_span.clone())
                    .and_then(|t| eval(t, &self.params));
                assignments.push((target.clone(), v));
            }
        }
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
    }

    /// A subroutine body line: classified where the subroutine is called, so only note whether
    /// it writes the normal axis (or a mode that changes it) and where it first moves.
    fn sub_body_line(&mut self, line: &Line, words: &[W]) {
        let n = AXES[self.m.normal];
        let writes = words.iter().filter(|w| w.letter == b'G').any(|w| {
            !matches!(
                w.g(),
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
            return;
        };
        if words.iter().any(|w| w.letter == n) || writes {
            info.writes_normal = true;
        }
        if axis_words && info.first_move.is_none() {
            info.first_move = Some(line.number);
        }
        for w in words.iter().filter(|w| w.letter == b'G') {
            let Some(group) = w.g().and_then(modal_group) else {
                continue;
            };
            if !info.sets.iter().any(|(k, _, _)| *k == group) {
                let word = self
                    .text
                    .get(w.span.clone())
                    .unwrap_or("")
                    .trim()
                    .to_string();
                info.sets.push((group, line.number, word));
            }
        }
    }
}

/// The modal group a G code sets, of those a called subroutine may leave changed.
fn modal_group(g: G) -> Option<&'static str> {
    Some(match g {
        G::Distance(_) => "distance",
        G::Units(_) => "units",
        G::Plane(_) => "plane",
        G::ArcDistance(_) => "arc",
        G::CutterComp(_) => "comp",
        g if g.is_motion() => "motion",
        _ => return None,
    })
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

/// The text after a Sinumerik instruction and its own argument (`MSG("…")`, `SPOS=0`), if the
/// block goes on: the lexer reads an instruction with an argument to the end of its block, so
/// words there would not be read as words.
fn words_after_instruction(body: &str) -> Option<&str> {
    let b = body.as_bytes();
    let mut i = 0;
    while i < b.len() && (b[i].is_ascii_alphanumeric() || b[i] == b'_') {
        i += 1;
    }
    let skip_spaces = |mut j: usize| {
        while j < b.len() && (b[j] == b' ' || b[j] == b'\t') {
            j += 1;
        }
        j
    };
    let mut j = skip_spaces(i);
    let (mut depth, mut quote) = (0i32, false);
    if j < b.len() && (b[j] == b'(' || b[j] == b'=') {
        if b[j] == b'=' {
            j = skip_spaces(j + 1);
        }
        while j < b.len() {
            match b[j] {
                b'"' => quote = !quote,
                b'(' | b'[' if !quote => depth += 1,
                b')' | b']' if !quote => {
                    depth -= 1;
                    if depth == 0 && b.get(j + 1).is_none_or(|c| *c == b' ' || *c == b'\t') {
                        j += 1;
                        break;
                    }
                }
                b' ' | b'\t' | b';' if depth <= 0 && !quote => break,
                _ => {}
            }
            j += 1;
        }
    }
    let rest = body.get(skip_spaces(j)..)?.split(';').next()?.trim();
    (!rest.is_empty()).then_some(rest)
}
