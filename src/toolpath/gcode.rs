//! The G-code rewrite: modal state, classification of each move against the zone and the map
//! domain, and emission of compensated segments (P' = P − E along the normal axis).
//!
//! Lines that are not rewritten are copied byte for byte from the input. See `docs/toolpath.md`.

use super::arc::{Arc, Plane};
use super::expr::{eval, Params};
use super::lexer::{lex, Line, TokenKind, WordValue};
use super::{CompensationReport, CompensationSettings};
use crate::error::{Error, Location, Result};
use crate::geom::ErrorField;
use std::collections::{HashMap, HashSet};
use std::path::Path;

const AXES: [u8; 3] = [b'X', b'Y', b'Z'];

/// A word of the current line, with its value evaluated when possible.
#[derive(Debug, Clone)]
struct W {
    letter: u8,
    value: Option<f64>,
    is_expr: bool,
    token: usize,
    text: String,
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
}

/// Compensate a G-code program. See the module documentation of [`crate::toolpath`].
pub fn compensate(
    text: &str,
    source: &Path,
    field: &dyn ErrorField,
    settings: &CompensationSettings,
) -> Result<(String, CompensationReport)> {
    settings.validate()?;
    let normal_axis = field.normal();
    let (u, v) = normal_axis.plane_axes();
    let mut rw = Rewriter {
        text,
        source,
        field,
        settings,
        normal: normal_axis.index(),
        plane_uv: (u.index(), v.index()),
        pos: [None; 3],
        inches: false,
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
    };
    let lines = lex(text);
    rw.program_decimals = coordinate_decimals(text, &lines);
    rw.report.lines_in = lines.len() as u64;
    for line in &lines {
        rw.line(line)?;
    }
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

fn g_code(v: f64) -> i32 {
    (v * 10.0).round() as i32
}

fn is_canned(code: i32) -> bool {
    code == 730 || code == 740 || code == 760 || (810..=890).contains(&code)
}

fn is_group1(code: i32) -> bool {
    matches!(code, 0 | 10 | 20 | 30 | 50 | 51 | 52 | 330 | 331 | 800)
        || (380..=385).contains(&code)
        || is_canned(code)
}

impl<'a> Rewriter<'a> {
    /// Coordinates get at least 4 decimals in mm and 5 in inches, and as many as the program
    /// itself uses (so unchanged end points are written back exactly).
    fn fmt(&self, v: f64) -> String {
        let d = if self.inches { 5 } else { 4 };
        format_decimals(v, d.max(self.program_decimals))
    }

    fn scale_mm(&self) -> f64 {
        if self.inches {
            25.4
        } else {
            1.0
        }
    }

    fn err(&self, line: &Line, column: &str, message: String, hint: &str) -> Error {
        Error::input(
            Location::cell(self.source, line.number, column),
            message,
            hint,
        )
    }

    fn copy_line(&mut self, line: &Line) {
        self.out.push_str(&self.text[line.span.start..line.end]);
    }

    /// E in program units at a point, if the point is in the zone and the map domain.
    fn error_at(&self, p: &[f64; 3]) -> Option<f64> {
        if let Some((lo, hi)) = self.settings.zone {
            let n = p[self.normal];
            if n < lo || n > hi {
                return None;
            }
        }
        let s = self.scale_mm();
        let e_mm = self
            .field
            .error_mm(p[self.plane_uv.0] * s, p[self.plane_uv.1] * s)?;
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
        if let (Some((zlo, zhi)), true) = (self.settings.zone, normal_known) {
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
        let s = self.scale_mm();
        let step = self.settings.max_segment_in(self.inches);
        let inside = |p: &[f64; 3]| self.field.error_mm(p[0] * s, p[1] * s).is_some();
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
        // Words, assignments and O-words of the line.
        let mut words: Vec<W> = Vec::new();
        let mut oword: Option<(String, String, String)> = None;
        let mut assignments: Vec<(String, Option<f64>)> = Vec::new();
        for (ti, tok) in line.tokens.iter().enumerate() {
            match &tok.kind {
                TokenKind::Word { letter, value } => {
                    let (value, is_expr) = match value {
                        WordValue::Number(v) => (Some(*v), false),
                        WordValue::Expr(r) => (
                            text.get(r.clone()).and_then(|t| eval(t, &self.params)),
                            true,
                        ),
                    };
                    words.push(W {
                        letter: *letter,
                        value,
                        is_expr,
                        token: ti,
                        text: text.get(tok.span.clone()).unwrap_or("").trim().to_string(),
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
            self.oword(line, &name, &keyword, &otext)?;
            self.copy_line(line);
            return Ok(());
        }
        if let Some((_, info)) = self.sub.as_mut() {
            // Subroutine bodies are classified where they are called.
            let n = AXES[self.normal];
            let g: Vec<i32> = words
                .iter()
                .filter(|w| w.letter == b'G')
                .map(|w| w.value.map(g_code).unwrap_or(-1))
                .collect();
            let axis_words = words
                .iter()
                .any(|w| matches!(w.letter, b'X' | b'Y' | b'Z' | b'@' | b'^'));
            if words.iter().any(|w| w.letter == n)
                || g.iter()
                    .any(|c| matches!(c, 280 | 300 | 530 | 920 | 100) || is_canned(*c))
            {
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

    fn words(&mut self, line: &Line, words: &[W]) -> Result<()> {
        let find = |l: u8| words.iter().find(|w| w.letter == l);
        let gs: Vec<(&W, Option<i32>)> = words
            .iter()
            .filter(|w| w.letter == b'G')
            .map(|w| (w, w.value.map(g_code)))
            .collect();
        let has_g = |c: i32| gs.iter().any(|(_, g)| *g == Some(c));
        // Modal codes (applied before motion, RS274/NGC order of execution).
        let orig_inches = self.inches;
        for (_, g) in &gs {
            match g {
                Some(170) => self.plane = Plane::G17,
                Some(180) => self.plane = Plane::G18,
                Some(190) => self.plane = Plane::G19,
                Some(200) => self.inches = true,
                Some(210) => self.inches = false,
                Some(900) => self.absolute = true,
                Some(910) => self.absolute = false,
                Some(901) => self.arc_absolute = true,
                Some(911) => self.arc_absolute = false,
                Some(400) => self.cutter_comp = None,
                Some(c @ (410 | 411 | 420 | 421)) => {
                    self.cutter_comp = Some((line.number, format!("G{}", *c as f64 / 10.0)));
                }
                _ => {}
            }
        }
        if self.inches != orig_inches {
            // The machine stays put; its coordinates change unit.
            let f = if self.inches { 1.0 / 25.4 } else { 25.4 };
            for p in self.pos.iter_mut() {
                *p = p.map(|v| v * f);
            }
            self.offset *= f;
        }
        let motion_word = gs.iter().find(|(_, g)| g.is_some_and(is_group1));
        let unknown_g = gs.iter().find(|(_, g)| g.is_none());
        let group0 = gs
            .iter()
            .find(|(_, g)| matches!(g, Some(100 | 280 | 281 | 300 | 301 | 920 | 921 | 922 | 923)));
        let g53 = has_g(530);
        let axis_present = words.iter().any(|w| {
            matches!(
                w.letter,
                b'X' | b'Y' | b'Z' | b'A' | b'B' | b'C' | b'U' | b'V' | b'W' | b'@' | b'^'
            )
        });
        let arc_words = words
            .iter()
            .any(|w| matches!(w.letter, b'I' | b'J' | b'K' | b'R'));
        if let Some((_, Some(c))) = motion_word {
            self.motion = Some(*c);
        }
        // G80 cancels the motion mode; a line with axis words then has no motion to make.
        let motion = if motion_word.is_some_and(|(_, g)| *g == Some(800)) {
            self.motion = None;
            None
        } else {
            self.motion
        };

        // Group 0 codes that take axis words (G10, G28, G30, G92…): no cutting move on the line.
        if let Some((_, g)) = group0 {
            self.return_if_needed(line, words, true)?;
            match g {
                Some(920) => {
                    for (i, l) in AXES.iter().enumerate() {
                        if let Some(w) = find(*l) {
                            self.pos[i] = w.value;
                        }
                    }
                }
                Some(100) => {}
                _ => {
                    self.pos = [None; 3];
                    self.unknown_since = Some(line.number);
                }
            }
            self.sync_out_motion(words);
            self.copy_line(line);
            return Ok(());
        }

        let moves =
            axis_present || (motion_word.is_some() && arc_words && matches!(motion, Some(20 | 30)));
        let Some(motion) = motion.filter(|_| moves) else {
            // No motion on this line.
            if let Some((gw, _)) = unknown_g {
                if axis_present {
                    return Err(self.err(
                        line,
                        &gw.text,
                        "a G word given by a parameter or expression on a line with axis words"
                            .into(),
                        "write the G code as a number",
                    ));
                }
            }
            self.sync_out_motion(words);
            self.copy_line(line);
            return Ok(());
        };

        // Start and end of the move in the original program.
        let start = self.pos;
        let mut end = self.pos;
        let polar = words.iter().find(|w| w.letter == b'@' || w.letter == b'^');
        for (i, l) in AXES.iter().enumerate() {
            if let Some(w) = find(*l) {
                end[i] = if g53 {
                    None
                } else if self.absolute {
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
        let cutting = matches!(motion, 10 | 20 | 30);
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
            if is_canned(motion) || matches!(motion, 50 | 51 | 52 | 330 | 331) {
                let mut pts = vec![start, end];
                if is_canned(motion) {
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
                let what = if is_canned(motion) {
                    format!("canned cycle {name}")
                } else if motion < 100 {
                    format!("spline {name}")
                } else {
                    format!("threading/tapping move {name}")
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
                    w.text.clone(),
                    "polar coordinates (@ ^) on a move in the compensation zone".into(),
                    "post the program with X/Y coordinates (or move the zone away)",
                )
            })
        } else if let Some(w) = expr_word {
            self.may_touch(&[start, end]).then(|| {
                (
                    w.text.clone(),
                    "# parameters or [expressions] on a move in the compensation zone".into(),
                    "expand the program to plain numbers (or move the zone away)",
                )
            })
        } else if let Some(w) = other_axis {
            self.may_touch(&[start, end]).then(|| {
                (
                    w.text.clone(),
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
            if is_canned(motion) {
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
        let path: Vec<[f64; 3]> = match &arc {
            None => vec![s, e],
            Some(a) => (0..=chords)
                .map(|i| a.point(i as f64 / chords as f64))
                .collect(),
        };
        let emitted = self.emit_points(&path);
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
            // Offsets I, J, K go with X, Y, Z.
            let off = |axis: usize| find([b'I', b'J', b'K'][axis]);
            let (o1, o2) = (off(a1), off(a2));
            if o1.is_none() && o2.is_none() {
                return Err(self.err(
                    line,
                    if cw { "G2" } else { "G3" },
                    "arc without R and without centre words for the selected plane".into(),
                    "give R or the I/J/K words of the plane (G17: I J, G18: I K, G19: J K)",
                ));
            }
            let c = if self.arc_absolute {
                (o1.unwrap_or(0.0), o2.unwrap_or(0.0))
            } else {
                (s[a1] + o1.unwrap_or(0.0), s[a2] + o2.unwrap_or(0.0))
            };
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

    fn emit_points(&self, path: &[[f64; 3]]) -> Vec<([f64; 3], Option<f64>)> {
        emit_points(
            path,
            self.settings.max_segment_in(self.inches),
            self.settings.zone,
            self.normal,
            &|p| self.error_at(p),
        )
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
            && !self.motion.is_some_and(is_canned)
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
        self.out
            .push_str(&format!("{code} {}{}", n as char, self.fmt(value)));
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
            .any(|w| w.letter == b'G' && w.value.map(g_code).is_some_and(is_group1))
        {
            self.out_motion = self.motion;
        }
    }

    fn finish_unchanged(&mut self, line: &Line, words: &[W], end: [Option<f64>; 3]) -> Result<()> {
        self.return_if_needed(line, words, false)?;
        let has_motion_g = words
            .iter()
            .any(|w| w.letter == b'G' && w.value.map(g_code).is_some_and(is_group1));
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
        let removed_tokens: HashSet<usize> = words
            .iter()
            .filter(|w| removed(w))
            .map(|w| w.token)
            .collect();
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
            words_text.push_str(&code);
            for (i, l) in AXES.iter().enumerate() {
                let v = if self.absolute {
                    q[i]
                } else {
                    q[i] - out_pos[i]
                };
                let t = self.fmt(v);
                // Track the position the controller will reach after rounding.
                let rounded: f64 = t.parse().unwrap_or(v);
                out_pos[i] = if self.absolute {
                    rounded
                } else {
                    out_pos[i] + rounded
                };
                words_text.push_str(&format!(" {}{}", *l as char, t));
            }
            if let Some(r) = r_word {
                words_text.push_str(&format!(" R{}", self.fmt(r)));
            }
            self.out_motion = Some(if code == "G1" { 10 } else { motion });
            lines_text.push(words_text);
        }
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
                last.push_str(&w.text);
            }
        }
        let stop_tokens: HashSet<usize> = stops.iter().map(|w| w.token).collect();
        // First line: the original line with its motion words replaced by the first segment.
        let mut first = String::new();
        let mut inserted = false;
        let mut skip_space = false;
        for (ti, tok) in line.tokens.iter().enumerate() {
            if stop_tokens.contains(&ti) {
                skip_space = true;
                continue;
            }
            if removed_tokens.contains(&ti) {
                if !inserted {
                    first.push_str(&lines_text[0]);
                    inserted = true;
                }
                skip_space = true;
                continue;
            }
            if skip_space && tok.kind == TokenKind::Space {
                skip_space = false;
                if ti + 1 < line.tokens.len() && !removed_tokens.contains(&(ti + 1)) {
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
        let mut pieces: Vec<&str> = vec![first.trim_end_matches([' ', '\t'])];
        pieces.extend(lines_text[1..].iter().map(|t| t.as_str()));
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
    let mut out: Vec<([f64; 3], Option<f64>)> = Vec::new();
    let Some(first) = path.first() else {
        return out;
    };
    out.push((*first, error_at(first)));
    for w in path.windows(2) {
        let (a, b) = (w[0], w[1]);
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
            let p = if t >= 1.0 { b } else { lerp(&a, &b, t) };
            let e_here = error_at(&p);
            if e_prev.is_some() != e_here.is_some() {
                // Bisect for the boundary: keep `lo_t` on the side of e_prev.
                let (mut lo_t, mut hi_t) = (t_prev, t);
                for _ in 0..60 {
                    let mid = 0.5 * (lo_t + hi_t);
                    if error_at(&lerp(&a, &b, mid)).is_some() == e_prev.is_some() {
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
                let p_in = lerp(&a, &b, t_in);
                let p_out = lerp(&a, &b, t_out);
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
