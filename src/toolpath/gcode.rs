//! The G-code rewrite: modal state, classification of each move against the zone and the map
//! domain, and emission of compensated segments (P' = P − E along the normal axis).
//!
//! Lines that are not rewritten are copied byte for byte from the input. See `docs/toolpath.md`.

use super::arc::{Arc, Plane};
use super::dialect::{self, Dialect, Frame, Motion, G};
use super::expr::{eval, Params};
use super::lexer::{lex_dialect, Line, TokenKind, WordValue};
use super::{CompensationReport, CompensationSettings};
use crate::error::{Error, Location, Result};
use crate::geom::ErrorField;
use std::cell::Cell;
use std::collections::{HashMap, HashSet};
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

/// Fixed-point text of a coordinate: 4 decimals in mm, 5 in inches; never `-0` nor an exponent.
pub fn format_coord(v: f64, inches: bool) -> String {
    format_decimals(v, if inches { 5 } else { 4 })
}

/// Fixed-point text with `d` decimals; never `-0` nor an exponent.
pub fn format_decimals(v: f64, d: usize) -> String {
    // Fast path: the value in units of the last decimal fits an integer exactly.
    if let Some(units) = decimal_units(v, d) {
        return units_text(units, d);
    }
    format_decimals_slow(v, d)
}

/// `v` rounded to `d` decimals, in units of the last decimal, when that is exact in an f64.
fn decimal_units(v: f64, d: usize) -> Option<i64> {
    const POW10: [f64; 10] = [1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9];
    let n = (v * *POW10.get(d)?).round();
    (n.is_finite() && n.abs() < 4e15).then_some(n as i64)
}

/// `units` × 10^-d as fixed-point text (`-0` written as `0`).
fn units_text(units: i64, d: usize) -> String {
    use std::fmt::Write;
    let p = 10u64.pow(d as u32);
    let a = units.unsigned_abs();
    let mut t = String::with_capacity(24);
    if units < 0 {
        t.push('-');
    }
    let _ = write!(t, "{}", a / p);
    if d > 0 {
        let _ = write!(t, ".{:0d$}", a % p);
    }
    t
}

fn format_decimals_slow(v: f64, d: usize) -> String {
    let s = format!("{v:.d$}");
    if s.trim_start_matches('-')
        .chars()
        .all(|c| c == '0' || c == '.')
    {
        s.trim_start_matches('-').to_string()
    } else {
        s
    }
}

/// Most decimals written in an X/Y/Z/I/J/K/R number of the program, capped at 9.
fn coordinate_decimals(text: &str, lines: &[Line]) -> usize {
    let mut most = 0;
    for line in lines {
        for t in &line.tokens {
            if let TokenKind::Word {
                letter: b'X' | b'Y' | b'Z' | b'I' | b'J' | b'K' | b'R',
                value: WordValue::Number(_),
            } = t.kind
            {
                let w = text.get(t.span.clone()).unwrap_or("");
                if let Some(dot) = w.find('.') {
                    let d = w[dot + 1..]
                        .chars()
                        .take_while(|c| c.is_ascii_digit())
                        .count();
                    most = most.max(d);
                }
            }
        }
    }
    most.min(9)
}

/// `G` value × 10, rounded (G38.2 → 382).
fn g_code(v: f64) -> i32 {
    (v * 10.0).round() as i32
}

/// Heidenhain conversational (Klartext) programs are refused as a whole.
fn refuse_klartext(text: &str, source: &Path, dialect: Dialect) -> Result<()> {
    if dialect != Dialect::Heidenhain {
        return Ok(());
    }
    for (i, l) in text.lines().enumerate() {
        let t = l.trim_start();
        if t.starts_with('%') || t.starts_with(';') || t.is_empty() {
            continue;
        }
        let mut words = t.split_whitespace();
        let first = words.next().unwrap_or("");
        let klartext = first.chars().all(|c| c.is_ascii_digit())
            && words
                .next()
                .is_some_and(|w| w.chars().all(|c| c.is_ascii_uppercase()));
        if klartext || t.contains("BEGIN PGM") {
            return Err(Error::input(
                Location::cell(source, i as u64 + 1, "1"),
                format!("`{}`: a Heidenhain conversational (Klartext) program; errmap follows Heidenhain ISO programs only", t.chars().take(40).collect::<String>()),
                "output the program as Heidenhain ISO (G-code) from the CAM post, or as another dialect errmap follows",
            ));
        }
    }
    Ok(())
}

/// The first jump of the program (Fanuc `GOTO`, Sinumerik `GOTOF`/`GOTOB`/`GOTO`/loops): after
/// one, a block may run any number of times, so no cut in the zone can be vouched for.
fn first_jump(text: &str, lines: &[Line], dialect: Dialect) -> Option<(u64, String)> {
    const JUMPS: [&str; 13] = [
        "GOTO", "GOTOF", "GOTOB", "GOTOC", "WHILE", "FOR", "LOOP", "REPEAT", "REPEATB", "UNTIL",
        "CASE", "IF", "ELSE",
    ];
    if dialect == Dialect::Linuxcnc {
        return None;
    }
    for l in lines {
        for t in &l.tokens {
            if let TokenKind::Keyword { name } = &t.kind {
                let body = text.get(t.span.clone()).unwrap_or("").to_ascii_uppercase();
                let jump = match dialect {
                    Dialect::Fanuc => body.contains("GOTO"),
                    _ => JUMPS.contains(&name.as_str()),
                };
                if jump {
                    return Some((l.number, name.clone()));
                }
            }
        }
    }
    None
}

impl<'a> Rewriter<'a> {
    fn g(&self, code: i32) -> Option<G> {
        dialect::g_code(self.dialect, code)
    }

    fn is_canned(&self, code: i32) -> bool {
        self.g(code) == Some(G::Motion(Motion::Canned))
    }

    fn is_group1(&self, code: i32) -> bool {
        matches!(self.g(code), Some(G::Motion(_) | G::MotionCancel))
    }

    fn wtext(&self, w: &W) -> &'a str {
        self.text.get(w.span.clone()).unwrap_or("").trim()
    }

    /// The units became known (a unit code, or `--units`).
    fn set_units_known(&mut self) {
        self.units_known = true;
    }

    /// Fix the zone given in program units in mm, in the units in effect now: at the program's
    /// first unit code, or its first move if that comes first.
    fn fix_zone(&mut self) {
        if let Some((lo, hi)) = self.zone_first_units.take() {
            let s = self.scale_mm();
            self.zone_mm = Some((lo * s, hi * s));
        }
    }

    /// The zone in current program coordinates (units and shift).
    fn zone_now(&self) -> Option<(f64, f64)> {
        let s = self.scale_mm();
        let (lo, hi) = match (self.zone_first_units, self.zone_mm) {
            (Some(z), _) => z,
            (None, Some((lo, hi))) => (lo / s, hi / s),
            (None, None) => return None,
        };
        let d = self.shift[self.normal];
        Some((lo - d, hi - d))
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
                    let no_dot = matches!(value, Some(_))
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

    /// Strict blocks: no stray characters, no word twice (but G and M), no unknown letter.
    fn check_block(&self, line: &Line) -> Result<()> {
        let mut seen = [false; 128];
        let mut first = true;
        let mut prev_number: Option<&str> = None;
        for t in &line.tokens {
            let here = self.text.get(t.span.clone()).unwrap_or("");
            match &t.kind {
                TokenKind::Space => continue,
                TokenKind::Other if first && here == "/" => {}
                TokenKind::Other => {
                    let (msg, hint) = match (here, prev_number) {
                        (",", Some(w)) => (
                            format!("malformed number: `{w},` has a decimal comma"),
                            "write numbers with a decimal point (e.g. X20.5)".to_string(),
                        ),
                        _ => (
                            format!("`{here}` is not a word errmap can read in the {} dialect", self.dialect.name()),
                            "fix or remove it (a word is a letter and a number), or pass the program's --dialect".to_string(),
                        ),
                    };
                    return Err(self.err(line, here, msg, &hint));
                }
                TokenKind::Word { letter, value } => {
                    let l = *letter;
                    if self.dialect == Dialect::Linuxcnc && l == b'E' {
                        return Err(self.err(
                            line,
                            here.trim(),
                            format!("`{}`: E is not a LinuxCNC word", here.trim()),
                            "remove it, or pass the program's --dialect",
                        ));
                    }
                    if l != b'G' && l != b'M' {
                        if seen[usize::from(l & 0x7f)] {
                            return Err(self.err(
                                line,
                                here.trim(),
                                format!(
                                    "word {} given twice in one block (`{}`)",
                                    l as char,
                                    here.trim()
                                ),
                                "keep one value per letter in each block",
                            ));
                        }
                        seen[usize::from(l & 0x7f)] = true;
                    }
                    prev_number = matches!(value, WordValue::Number(_)).then_some(here.trim());
                    first = false;
                    continue;
                }
                _ => {}
            }
            first = false;
            prev_number = None;
        }
        Ok(())
    }

    /// A dialect statement. `Ok(true)`: harmless, read the line's words as usual; `Ok(false)`:
    /// followed here, copy the line.
    fn keyword(&mut self, line: &Line, name: &str, span: Range<usize>) -> Result<bool> {
        let body = self.text.get(span).unwrap_or("");
        let refuse = |what: String, hint: &str| Err(self.err(line, name, what, hint));
        match (self.dialect, name) {
            (Dialect::Fanuc, "WHILE") => {
                let n = body.rsplit("DO").next().unwrap_or("").trim().to_string();
                self.blocks.push(Block {
                    name: n,
                    keyword: "WHILE … DO".into(),
                    line: line.number,
                    written: [false; 3],
                });
                Ok(false)
            }
            (Dialect::Fanuc, "END") => {
                self.close_block(line.number);
                Ok(false)
            }
            (Dialect::Fanuc, "IF") if !body.contains("GOTO") => {
                // `IF [...] THEN #i = …`: parameters are unknown afterwards.
                self.params.clear();
                Ok(false)
            }
            (Dialect::Fanuc, _) => Ok(false),
            (Dialect::Heidenhain, "%") | (Dialect::Sinumerik, "%") => {
                let upper = body.to_ascii_uppercase();
                if self.dialect == Dialect::Heidenhain {
                    if upper.contains("G70") || upper.contains("G71") {
                        self.inches = upper.contains("G70");
                        self.set_units_known();
                        self.fix_zone();
                    }
                }
                Ok(false)
            }
            (Dialect::Sinumerik, "TRANS" | "ATRANS" | "ROT" | "AROT" | "SCALE" | "ASCALE" | "MIRROR" | "AMIRROR") => {
                self.siemens_frame(line, name, body)?;
                Ok(false)
            }
            (Dialect::Sinumerik, "CALL" | "PCALL" | "MCALL" | "REPEAT" | "REPEATB" | "EXTCALL") => refuse(
                format!("`{}` runs a subprogram or program section whose moves errmap cannot follow", body.trim()),
                "expand the subprogram or repeated section into plain blocks",
            ),
            (Dialect::Sinumerik, "RET") => {
                self.m99 = Some(line.number);
                Ok(false)
            }
            (
                Dialect::Sinumerik,
                "MSG" | "SOFT" | "BRISK" | "FFWON" | "FFWOF" | "CFC" | "CFTCP" | "CFIN" | "COMPCAD" | "COMPCURV"
                | "COMPON" | "COMPOF" | "CYCLE832" | "STOPRE" | "DEF" | "WORKPIECE" | "SPOS" | "SPOSA"
                | "G642" | "G641",
            ) => Ok(true),
            (Dialect::Sinumerik, _) if self.flow.as_ref().is_some_and(|(l, _)| *l <= line.number) => Ok(false),
            _ => refuse(
                format!("`{}`: errmap does not follow the {} instruction {name}, which may move the machine or change its coordinates", body.trim(), self.dialect.name()),
                "expand it into plain G0/G1/G2/G3 blocks with your CAM post",
            ),
        }
    }

    /// Sinumerik programmable frames: TRANS/ATRANS are followed (a shift), ROT/SCALE/MIRROR
    /// (and their additive forms) are frames errmap refuses cuts under; a bare TRANS, ROT,
    /// SCALE or MIRROR deletes the whole programmable frame.
    fn siemens_frame(&mut self, line: &Line, name: &str, body: &str) -> Result<()> {
        let args = &body[name.len().min(body.len())..];
        let mut values = [None; 3];
        for w in args.split_whitespace() {
            let (l, v) = w.split_at(1);
            let i = match l.to_ascii_uppercase().as_str() {
                "X" => 0,
                "Y" => 1,
                "Z" => 2,
                _ => {
                    return Err(self.err(
                        line,
                        name,
                        format!(
                            "`{}`: errmap reads {name} with X, Y and Z numbers only",
                            body.trim()
                        ),
                        "write the frame with plain numbers, or expand the program",
                    ))
                }
            };
            values[i] = Some(v.trim_start_matches('=').parse::<f64>().map_err(|_| {
                self.err(
                    line,
                    w,
                    format!("`{w}` is not a number"),
                    "write the frame with plain numbers",
                )
            })?);
        }
        let bare = values.iter().all(|v| v.is_none());
        let mut shift = self.shift;
        match name {
            _ if bare => {
                shift = [0.0; 3];
                self.frames.retain(|f| f.0 == Frame::WorkOffset);
            }
            "TRANS" => {
                shift = values.map(|v| v.unwrap_or(0.0));
                self.frames.retain(|f| f.0 == Frame::WorkOffset);
            }
            "ATRANS" => {
                for i in 0..3 {
                    shift[i] += values[i].unwrap_or(0.0);
                }
            }
            _ => {
                let kind = match name {
                    "ROT" | "AROT" => Frame::Rotation,
                    "SCALE" | "ASCALE" => Frame::Scaling,
                    _ => Frame::Mirror,
                };
                if !name.starts_with('A') {
                    shift = [0.0; 3];
                    self.frames.retain(|f| f.0 == Frame::WorkOffset);
                }
                self.frames.push((kind, line.number, name.to_string()));
            }
        }
        self.set_shift(shift);
        Ok(())
    }

    /// Change the shift between program and work coordinates; the machine stays put.
    fn set_shift(&mut self, shift: [f64; 3]) {
        for i in 0..3 {
            self.pos[i] = self.pos[i].map(|p| p + self.shift[i] - shift[i]);
        }
        self.shift = shift;
    }

    /// Fanuc M98/M99/M30 and Sinumerik L/M17: subprogram calls are refused, subprogram bodies
    /// are kept as text.
    fn fanuc_m_codes(&mut self, line: &Line, words: &[W]) -> Result<()> {
        let m = |v: f64| words.iter().any(|w| w.letter == b'M' && w.value == Some(v));
        let call = match self.dialect {
            Dialect::Fanuc if m(98.0) => Some("M98"),
            Dialect::Sinumerik => words
                .iter()
                .find(|w| w.letter == b'L')
                .map(|w| self.wtext(w)),
            _ => None,
        };
        if let (Some(word), None) = (call, &self.sub) {
            return Err(self.err(
                line,
                word,
                format!("`{}` calls a subprogram whose moves errmap cannot follow (they run in this program's position, modes and frames)", self.text.get(line.span.clone()).unwrap_or("").trim()),
                "expand the subprogram into the program (or post the program without subprograms)",
            ));
        }
        let end_sub = match self.dialect {
            Dialect::Fanuc => m(99.0),
            Dialect::Sinumerik => m(17.0),
            _ => false,
        };
        if end_sub {
            if self.sub.is_some() && self.dialect == Dialect::Fanuc {
                self.sub = None;
            } else {
                self.m99 = Some(line.number);
            }
        }
        if self.dialect == Dialect::Fanuc && (m(30.0) || m(2.0)) {
            self.programs = self.programs.max(1);
        }
        Ok(())
    }

    fn oword(&mut self, line: &Line, name: &str, keyword: &str, otext: &str) -> Result<()> {
        match keyword {
            "sub" => {
                self.sub = Some((
                    name.to_string(),
                    SubInfo {
                        def_line: line.number,
                        ..SubInfo::default()
                    },
                ));
            }
            "endsub" => {
                if let Some((n, info)) = self.sub.take() {
                    self.subs.insert(n, info);
                }
            }
            "call" => {
                if let Some((_, info)) = self.sub.as_mut() {
                    info.calls.push(name.to_string());
                } else {
                    self.return_if_needed(line, &[], true)?;
                    self.call(line, name, otext)?;
                }
            }
            _ if self.sub.is_some() => {}
            "if" | "while" | "repeat" | "do" => {
                // `oN while` closes an open `oN do`.
                let closes_do = keyword == "while"
                    && self
                        .blocks
                        .last()
                        .is_some_and(|b| b.name == name && b.keyword == "do");
                if closes_do {
                    self.close_block(line.number);
                } else {
                    self.blocks.push(Block {
                        name: name.to_string(),
                        keyword: keyword.to_string(),
                        line: line.number,
                        written: [false; 3],
                    });
                }
            }
            "endif" | "endwhile" | "endrepeat" => self.close_block(line.number),
            _ => {}
        }
        Ok(())
    }

    fn close_block(&mut self, line: u64) {
        if let Some(b) = self.blocks.pop() {
            for (i, w) in b.written.iter().enumerate() {
                if *w {
                    self.pos[i] = None;
                    self.unknown_since = Some(line);
                }
            }
            if let Some(parent) = self.blocks.last_mut() {
                for i in 0..3 {
                    parent.written[i] |= b.written[i];
                }
            }
        }
    }

    /// Subroutine closure: does it (or what it calls) write the normal axis; its first move line.
    fn sub_summary(&self, name: &str) -> (bool, Option<(String, u64)>, bool) {
        let mut seen = HashSet::new();
        let mut stack = vec![name.to_string()];
        let mut writes = false;
        let mut first: Option<(String, u64)> = None;
        let mut external = false;
        while let Some(n) = stack.pop() {
            if !seen.insert(n.clone()) {
                continue;
            }
            match self.subs.get(&n) {
                Some(info) => {
                    writes |= info.writes_normal;
                    if let (None, Some(l)) = (&first, info.first_move) {
                        first = Some((n.clone(), l));
                    }
                    stack.extend(info.calls.iter().cloned());
                }
                None => external = true,
            }
        }
        (writes, first, external)
    }

    fn call(&mut self, line: &Line, name: &str, otext: &str) -> Result<()> {
        let (writes_normal, first_move, external) = self.sub_summary(name);
        let moves = first_move.is_some() || external;
        if moves {
            let mut p = self.pos;
            if writes_normal || external {
                p[self.normal] = None;
            }
            let (u, v) = self.plane_uv;
            p[u] = None;
            p[v] = None;
            if self.may_touch(&[p]) {
                let what = match (&first_move, external) {
                    (_, true) => format!("subroutine o{name} is not defined in this file"),
                    (Some((sub, l)), _) => format!(
                        "subroutine o{sub} (defined at line {}) moves on line {l}",
                        self.subs.get(sub).map(|i| i.def_line).unwrap_or(0)
                    ),
                    (None, _) => String::new(),
                };
                return Err(self.err(
                    line,
                    otext.split_whitespace().next().unwrap_or("O"),
                    format!(
                        "`{otext}` runs moves that may lie in the compensation zone and cannot be compensated: {what}"
                    ),
                    "expand O-word subroutines and loops into plain G-code (or move the zone away from these moves)",
                ));
            }
        }
        // After a call the plane position is unknown, and the normal too if the body writes it.
        let (u, v) = self.plane_uv;
        if moves {
            self.pos[u] = None;
            self.pos[v] = None;
            for i in 0..3 {
                if i != self.normal {
                    self.pos[i] = None;
                }
            }
            if writes_normal || external {
                self.pos[self.normal] = None;
            }
            self.unknown_since = Some(line.number);
        }
        Ok(())
    }

    /// The G words of a block with their meaning in the dialect; an unknown code is refused.
    fn g_words<'w>(&self, line: &Line, words: &'w [W]) -> Result<Vec<(&'w W, i32, G)>> {
        let mut gs = Vec::new();
        for w in words.iter().filter(|w| w.letter == b'G') {
            let Some(v) = w.value.filter(|_| !w.is_expr) else {
                return Err(self.err(
                    line,
                    self.wtext(w),
                    "a G word given by a parameter or expression".into(),
                    "write the G code as a number",
                ));
            };
            let code = g_code(v);
            let Some(g) = self.g(code) else {
                return Err(self.err(
                    line,
                    self.wtext(w),
                    format!(
                        "`{}` is not a G code errmap follows in the {} dialect",
                        self.wtext(w),
                        self.dialect.name()
                    ),
                    "expand it into G0/G1/G2/G3 moves (docs/toolpath.md lists the codes of each dialect), or pass the program's --dialect",
                ));
            };
            gs.push((w, code, g));
        }
        Ok(gs)
    }

    /// Fanuc numbers without a decimal point are least input increments unless the machine
    /// reads them as millimetres/inches (calculator type): scale them, or refuse.
    fn fanuc_numbers(&self, line: &Line, words: &[W]) -> Result<Option<Vec<W>>> {
        let coord = |l: u8| matches!(l, b'X' | b'Y' | b'Z' | b'I' | b'J' | b'K' | b'R');
        let Some(first) = words
            .iter()
            .find(|w| w.no_dot && coord(w.letter) && w.value != Some(0.0))
        else {
            return Ok(None);
        };
        if self.dialect != Dialect::Fanuc {
            return Ok(None);
        }
        let Some(numbers) = self.settings.fanuc_numbers else {
            let t = self.wtext(first);
            return Err(self.err(
                line,
                t,
                format!("`{t}` has no decimal point: a Fanuc reads it as {} mm with 0.001 mm increment input (parameter 3401#0 DPI = 0) but as {} mm with calculator-type input (DPI = 1)", first.value.unwrap_or(0.0) * 0.001, first.value.unwrap_or(0.0)),
                "pass --fanuc-numbers is-b (or is-a, is-c) or --fanuc-numbers calculator as the machine is set (job key [toolpaths] fanuc_numbers)",
            ));
        };
        let unit = numbers.unit(self.inches);
        Ok(Some(
            words
                .iter()
                .map(|w| {
                    let mut w = w.clone();
                    if w.no_dot && coord(w.letter) {
                        w.value = w.value.map(|v| v * unit);
                    }
                    w
                })
                .collect(),
        ))
    }

    /// Apply the modal G codes of a block (plane, units, distance modes, cutter compensation).
    fn modal(&mut self, line: &Line, gs: &[(&W, i32, G)]) {
        let orig_inches = self.inches;
        let mut units_word = false;
        for &(_, code, g) in gs {
            match g {
                G::Plane(p) => self.plane = p,
                G::Units(inches) => {
                    self.inches = inches;
                    units_word = true;
                }
                G::Distance(a) => self.absolute = a,
                G::ArcDistance(a) => self.arc_absolute = a,
                G::CutterComp(false) => self.cutter_comp = None,
                G::CutterComp(true) => {
                    self.cutter_comp = Some((line.number, format!("G{}", code as f64 / 10.0)));
                }
                G::WorkOffset => match self.first_offset {
                    None => self.first_offset = Some(code),
                    Some(c) if c == code => self.frames.retain(|f| f.0 != Frame::WorkOffset),
                    Some(_) => self.frames.push((
                        Frame::WorkOffset,
                        line.number,
                        format!("G{}", code as f64 / 10.0),
                    )),
                },
                _ => {}
            }
        }
        if self.inches != orig_inches {
            // The machine stays put; its coordinates change unit.
            let f = if self.inches { 1.0 / 25.4 } else { 25.4 };
            for p in self.pos.iter_mut() {
                *p = p.map(|v| v * f);
            }
            for s in self.shift.iter_mut() {
                *s *= f;
            }
            self.offset *= f;
        }
        if units_word {
            self.set_units_known();
            self.fix_zone();
        }
    }

    /// Non-motion codes that take axis words (G92, G52, G68, G51, G10, G28 …): followed where
    /// errmap can (G92 and G52 as shifts), a frame under which cuts in the zone are refused
    /// otherwise.
    fn group0(&mut self, line: &Line, words: &[W], gw: &W, g: G) -> Result<()> {
        let find = |l: u8| words.iter().find(|w| w.letter == l);
        let word = self.wtext(gw).to_string();
        match g {
            G::SetPosition => {
                let mut shift = self.shift;
                let mut known = true;
                for (i, l) in AXES.iter().enumerate() {
                    if let Some(w) = find(*l) {
                        match (self.pos[i], w.value) {
                            (Some(p), Some(v)) => shift[i] = self.shift[i] + p - v,
                            _ => known = false,
                        }
                    }
                }
                if known {
                    self.set_shift(shift);
                } else {
                    self.frames.push((Frame::Shift, line.number, word));
                    self.pos = [None; 3];
                    self.unknown_since = Some(line.number);
                }
            }
            G::Frame(Frame::Local) => {
                let mut shift = self.shift;
                for (i, l) in AXES.iter().enumerate() {
                    match find(*l).map(|w| w.value) {
                        Some(Some(v)) if self.dialect == Dialect::Fanuc => {
                            shift[i] = self.shift[i] - self.local[i] + v;
                            self.local[i] = v;
                        }
                        Some(Some(v)) => shift[i] = v,
                        Some(None) => self.frames.push((Frame::Local, line.number, word.clone())),
                        None => {}
                    }
                }
                self.set_shift(shift);
            }
            G::FrameCancel(Frame::Shift) => {
                self.local = [0.0; 3];
                self.set_shift([0.0; 3]);
                self.frames.retain(|f| f.0 != Frame::Shift);
            }
            G::Frame(kind) => self.frames.push((kind, line.number, word)),
            G::FrameCancel(kind) => self.frames.retain(|f| f.0 != kind),
            G::DataSetting => {
                let l = find(b'L').and_then(|w| w.value);
                if !matches!(l, Some(v) if [1.0, 10.0, 11.0, 12.0, 13.0].contains(&v)) {
                    self.frames.push((Frame::Data, line.number, word));
                }
            }
            G::Call => {
                return Err(self.err(
                    line,
                    &word,
                    format!("`{word}` calls a macro whose moves errmap cannot follow"),
                    "expand the macro into the program",
                ))
            }
            _ => {
                self.pos = [None; 3];
                self.unknown_since = Some(line.number);
            }
        }
        Ok(())
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

    /// The points of a move as errmap can know them under a frame: plane coordinates unknown,
    /// the normal too unless a rotation turns about it.
    fn frame_points(&self, kind: Frame, pts: &[[Option<f64>; 3]]) -> Vec<[Option<f64>; 3]> {
        let keep_normal = kind == Frame::Rotation && self.plane.axes().2 == self.normal;
        pts.iter()
            .map(|p| {
                let mut q = [None; 3];
                if keep_normal {
                    q[self.normal] = p[self.normal];
                }
                q
            })
            .collect()
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

/// Walk the polyline; split every piece so segments in the zone are at most max_segment
/// long, and split exactly where the path enters or leaves the zone/domain. Returns each
/// point with E (program units) when it is compensated. At a boundary the point is emitted
/// twice, uncompensated and compensated, so the outside part of the move stays unchanged.
pub(crate) fn emit_points(
    path: &[[f64; 3]],
    step: f64,
    zone: Option<(f64, f64)>,
    normal: usize,
    error_at: &dyn Fn(&[f64; 3]) -> Option<f64>,
) -> Vec<([f64; 3], Option<f64>)> {
    let breaks: Vec<f64> = (0..path.len()).map(|i| i as f64).collect();
    let curve = |s: f64| {
        let i = (s.floor() as usize).min(path.len().saturating_sub(2));
        match (path.get(i), path.get(i + 1)) {
            (Some(a), Some(b)) => lerp(a, b, s - i as f64),
            (Some(a), None) => *a,
            _ => [0.0; 3],
        }
    };
    emit_curve(&breaks, &curve, step, zone, normal, error_at)
}

/// [`emit_points`] along a curve given by its parameter: `breaks` are the parameters of the
/// polyline's corners; intermediate and boundary points are taken on the curve.
pub(crate) fn emit_curve(
    breaks: &[f64],
    curve: &dyn Fn(f64) -> [f64; 3],
    step: f64,
    zone: Option<(f64, f64)>,
    normal: usize,
    error_at: &dyn Fn(&[f64; 3]) -> Option<f64>,
) -> Vec<([f64; 3], Option<f64>)> {
    let mut out: Vec<([f64; 3], Option<f64>)> = Vec::new();
    let Some(&s0) = breaks.first() else {
        return out;
    };
    let first = curve(s0);
    out.push((first, error_at(&first)));
    for w in breaks.windows(2) {
        let (sa, sb) = (w[0], w[1]);
        let (a, b) = (curve(sa), curve(sb));
        let at = |t: f64| {
            if t <= 0.0 {
                a
            } else if t >= 1.0 {
                b
            } else {
                curve(sa + t * (sb - sa))
            }
        };
        let len = dist(&a, &b);
        let k = (len / step).ceil().clamp(1.0, 1e7) as usize;
        let mut ts: Vec<f64> = (1..=k).map(|i| i as f64 / k as f64).collect();
        // Exact zone crossings along the normal.
        if let Some((lo, hi)) = zone {
            let (na, nb) = (a[normal], b[normal]);
            if (nb - na).abs() > 0.0 {
                for z in [lo, hi] {
                    let t = (z - na) / (nb - na);
                    if t > 0.0 && t < 1.0 {
                        ts.push(t);
                    }
                }
            }
        }
        ts.sort_by(|x, y| x.total_cmp(y));
        let mut t_prev = 0.0;
        let mut e_prev = error_at(&a);
        for t in ts {
            // The last point is the piece end exactly (lerp can round past a domain edge).
            let p = at(t);
            let e_here = error_at(&p);
            if e_prev.is_some() != e_here.is_some() {
                // Bisect for the boundary: keep `lo_t` on the side of e_prev.
                let (mut lo_t, mut hi_t) = (t_prev, t);
                for _ in 0..60 {
                    let mid = 0.5 * (lo_t + hi_t);
                    if error_at(&at(mid)).is_some() == e_prev.is_some() {
                        lo_t = mid;
                    } else {
                        hi_t = mid;
                    }
                }
                let (t_in, t_out) = if e_prev.is_some() {
                    (lo_t, hi_t)
                } else {
                    (hi_t, lo_t)
                };
                let p_in = at(t_in);
                let p_out = at(t_out);
                let e_in = error_at(&p_in);
                if e_prev.is_some() {
                    out.push((p_in, e_in));
                    out.push((p_out, None));
                } else {
                    out.push((p_out, None));
                    out.push((p_in, e_in));
                }
            }
            // Outside stretches of a straight piece need no intermediate points.
            let last = (t - 1.0).abs() < 1e-15;
            if e_here.is_some() || last {
                out.push((if last { b } else { p }, e_here));
            }
            t_prev = t;
            e_prev = e_here;
        }
    }
    out
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

pub(crate) fn dist(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

pub(crate) fn lerp(a: &[f64; 3], b: &[f64; 3], t: f64) -> [f64; 3] {
    [
        a[0] + t * (b[0] - a[0]),
        a[1] + t * (b[1] - a[1]),
        a[2] + t * (b[2] - a[2]),
    ]
}
