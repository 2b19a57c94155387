//! The modal-state machine of the rewrite: each dialect's G-code table applied to the state (units, distance modes, plane, frames, shifts, work offsets), dialect statements, flow control and subprograms, and strict block checks.

use super::super::dialect::{self, Dialect, Frame, GCode, G};
use super::super::lexer::{Line, TokenKind, WordValue};
use super::{Block, Rewriter, SubInfo, AXES, W};
use crate::setting::Setting;
use errmap_core::error::{Error, Location, Result};
use std::collections::HashSet;
use std::ops::Range;
use std::path::Path;

/// Heidenhain conversational (Klartext) programs are refused as a whole.
pub(super) fn refuse_klartext(text: &str, source: &Path, dialect: Dialect) -> Result<()> {
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

/// A Sinumerik jump label on a block of its own (`METKA1:`): a name of letters, digits and
/// underscores, starting with a letter or underscore, ending in a colon. Words after it on the
/// same block are not a label: errmap refuses them as an instruction it does not follow.
fn is_label(body: &str) -> bool {
    let Some(name) = body.trim().strip_suffix(':') else {
        return false;
    };
    name.len() >= 2
        && name.starts_with(|c: char| c.is_ascii_alphabetic() || c == '_')
        && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
}

/// The first jump of the program (Fanuc `GOTO`, Sinumerik `GOTOF`/`GOTOB`/`GOTO`/loops): after
/// one, a block may run any number of times, so no cut in the zone can be vouched for.
pub(super) fn first_jump(text: &str, line: &Line, dialect: Dialect) -> Option<(u64, String)> {
    const JUMPS: [&str; 13] = [
        "GOTO", "GOTOF", "GOTOB", "GOTOC", "WHILE", "FOR", "LOOP", "REPEAT", "REPEATB", "UNTIL",
        "CASE", "IF", "ELSE",
    ];
    if dialect == Dialect::Linuxcnc {
        return None;
    }
    for t in &line.tokens {
        if let TokenKind::Keyword { name } = &t.kind {
            let body = text.get(t.span.clone()).unwrap_or("").to_ascii_uppercase();
            let jump = match dialect {
                Dialect::Fanuc => body.contains("GOTO"),
                _ => JUMPS.contains(&name.as_str()),
            };
            if jump {
                return Some((line.number, name.clone()));
            }
        }
    }
    None
}

impl<'a> Rewriter<'a> {
    /// A hint, with "or pass the program's" dialect setting unless the dialect was given.
    pub(super) fn or_dialect(&self, hint: &str) -> String {
        if self.m.settings.dialect.is_some() {
            hint.to_string()
        } else {
            format!(
                "{hint}, or pass the program's {}",
                errmap_core::setting::words(Setting::Dialect)
            )
        }
    }

    /// The units became known (a unit code, or `--units`).
    pub(super) fn set_units_known(&mut self) {
        self.m.units_known = true;
    }

    pub(super) fn g(&self, code: GCode) -> Option<G> {
        dialect::g_code(self.dialect, code)
    }

    /// Every G word of a block has a meaning in the dialect; an unknown code is refused.
    pub(super) fn check_g_words(&self, line: &Line, words: &[W]) -> Result<()> {
        for w in words.iter().filter(|w| w.letter == b'G') {
            if w.value.is_none() || w.is_expr {
                return Err(self.err(
                    line,
                    self.wtext(w),
                    "a G word given by a parameter or expression".into(),
                    "write the G code as a number",
                ));
            }
            if w.g.is_none() {
                return Err(self.err(
                    line,
                    self.wtext(w),
                    format!(
                        "`{}` is not a G code errmap follows in the {} dialect",
                        self.wtext(w),
                        self.dialect.name()
                    ),
                    &self.or_dialect("expand it into G0/G1/G2/G3 moves (docs/toolpath.md lists the codes of each dialect)"),
                ));
            }
        }
        Ok(())
    }

    /// Fanuc numbers without a decimal point are least input increments unless the machine
    /// reads them as millimetres/inches (calculator type): scale them, or refuse.
    pub(super) fn fanuc_numbers(&self, line: &Line, words: &[W]) -> Result<Option<Vec<W>>> {
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
        let Some(numbers) = self.m.settings.fanuc_numbers else {
            let t = self.wtext(first);
            return Err(self.err(
                line,
                t,
                format!("`{t}` has no decimal point: a Fanuc reads it as {} mm with 0.001 mm increment input (parameter 3401#0 DPI = 0) but as {} mm with calculator-type input (DPI = 1)", first.value.unwrap_or(0.0) * 0.001, first.value.unwrap_or(0.0)),
                &format!("pass {numbers} is-b (or is-a, is-c) or {numbers} calculator as the machine is set (job key [toolpaths] fanuc_numbers)", numbers = errmap_core::setting::words(Setting::FanucNumbers)),
            ));
        };
        let unit = numbers.unit(self.m.inches);
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
    pub(super) fn modal(&mut self, line: &Line, words: &[W]) {
        let orig_inches = self.m.inches;
        let mut units_word = false;
        for (code, g) in words.iter().filter_map(|w| w.g) {
            match g {
                G::Plane(p) => self.plane = p,
                G::Units(inches) => {
                    self.m.inches = inches;
                    units_word = true;
                }
                G::Distance(a) => self.absolute = a,
                G::ArcDistance(a) => self.arc_absolute = a,
                // G40 after G41/G42: the next move in the plane is the cancel block.
                G::CutterComp(false) if self.cutter_comp.take().is_some() => {
                    self.comp_transition = Some((line.number, code.to_string()));
                }
                G::CutterComp(false) => {}
                G::CutterComp(true) => {
                    self.cutter_comp = Some((line.number, code.to_string()));
                    self.comp_transition = Some((line.number, code.to_string()));
                }
                G::WorkOffset => self.work_offset(line, words, code),
                _ => {}
            }
        }
        if self.m.inches != orig_inches {
            // The machine stays put; its coordinates change unit.
            let f = if self.m.inches { 1.0 / 25.4 } else { 25.4 };
            for p in self.m.pos.iter_mut() {
                *p = p.map(|v| v * f);
            }
            for s in self.m.shift.iter_mut() {
                *s *= f;
            }
            self.m.offset *= f;
        }
        if units_word {
            self.set_units_known();
            self.m.fix_zone();
        }
    }

    /// A work offset selected. The map is in the first one's coordinates: another is a frame
    /// errmap refuses cuts under, unless `--same-part-per-offset` (the map applies in each
    /// offset's coordinates). Either way the machine stays put while its work coordinates
    /// change by offsets the program does not show: the position is unknown after a change.
    fn work_offset(&mut self, line: &Line, words: &[W], code: GCode) {
        let id = self.offset_id(words, code);
        self.select_offset(line, id);
    }

    /// The name of a work offset: `G55`; `G54.1 P3` (Fanuc additional offsets are their P).
    fn offset_id(&self, words: &[W], code: GCode) -> String {
        let p = words
            .iter()
            .find(|w| {
                w.letter == b'P'
                    && code
                        == GCode {
                            number: 54,
                            decimal: 1,
                        }
            })
            .map(|w| format!(" P{}", self.wtext(w).get(1..).unwrap_or("")))
            .unwrap_or_default();
        format!("{code}{p}")
    }

    /// Fadal `E1`…`E48` (and `E0`, none) select fixture offsets; on a Haas line with G187 the
    /// E word is G187's tolerance, and with G33 a thread lead.
    pub(super) fn fadal_offset(&mut self, line: &Line, words: &[W]) {
        if self.dialect != Dialect::Fanuc {
            return;
        }
        let other_use = words
            .iter()
            .any(|w| matches!(w.g.map(|(c, _)| (c.number, c.decimal)), Some((187 | 33, 0))));
        if let Some(w) = words
            .iter()
            .find(|w| w.letter == b'E')
            .filter(|_| !other_use)
        {
            let id = self.wtext(w).to_ascii_uppercase();
            self.select_offset(line, id);
        }
    }

    /// Select the work offset `id` (see [`Self::work_offset`]). Fadal `E0` cancels the fixture
    /// offset: coordinates are the machine's, no work offset, so it is never the map's frame
    /// and cuts in the zone under it are refused.
    fn select_offset(&mut self, line: &Line, id: String) {
        if self.active_offset.as_ref().is_some_and(|a| *a != id) {
            self.m.forget_position(line.number);
        }
        self.active_offset = Some(id.clone());
        let no_offset = id
            .strip_prefix('E')
            .is_some_and(|n| n.parse::<f64>() == Ok(0.0));
        if no_offset {
            self.frames.retain(|f| f.0 != Frame::WorkOffset);
            self.frames.push((Frame::WorkOffset, line.number, id));
            return;
        }
        match &self.first_offset {
            None => {
                self.frames.retain(|f| f.0 != Frame::WorkOffset);
                self.first_offset = Some(id)
            }
            Some(f) if *f == id || self.m.settings.same_part_per_offset => {
                self.frames.retain(|f| f.0 != Frame::WorkOffset)
            }
            Some(_) => self.frames.push((Frame::WorkOffset, line.number, id)),
        }
    }

    /// Whether the block selects a work offset other than the active one (after a compensated
    /// cut, the return step must come before it, in the coordinates it was cut in).
    pub(super) fn changes_offset(&self, words: &[W]) -> bool {
        let Some(active) = &self.active_offset else {
            return false;
        };
        let fadal = self.dialect == Dialect::Fanuc
            && !words
                .iter()
                .any(|w| matches!(w.g.map(|(c, _)| (c.number, c.decimal)), Some((187 | 33, 0))))
            && words
                .iter()
                .any(|w| w.letter == b'E' && self.wtext(w).to_ascii_uppercase() != *active);
        fadal
            || words.iter().any(|w| match w.g {
                Some((code, G::WorkOffset)) => self.offset_id(words, code) != *active,
                _ => false,
            })
    }

    /// Non-motion codes that take axis words (G92, G52, G68, G51, G10, G28 …): followed where
    /// errmap can (G92 and G52 as shifts), a frame under which cuts in the zone are refused
    /// otherwise.
    pub(super) fn group0(&mut self, line: &Line, words: &[W], gw: &W, g: G) -> Result<()> {
        let find = |l: u8| words.iter().find(|w| w.letter == l);
        let word = self.wtext(gw).to_string();
        match g {
            G::SetPosition => {
                let mut shift = self.m.shift;
                let mut known = true;
                for (i, l) in AXES.iter().enumerate() {
                    if let Some(w) = find(*l) {
                        match (self.m.pos[i], w.value) {
                            (Some(p), Some(v)) => shift[i] = self.m.shift[i] + p - v,
                            _ => known = false,
                        }
                    }
                }
                if known {
                    self.set_shift(shift);
                } else {
                    self.frames.push((Frame::Shift, line.number, word));
                    self.m.forget_position(line.number);
                }
            }
            G::Frame(Frame::Local) => {
                let mut shift = self.m.shift;
                for (i, l) in AXES.iter().enumerate() {
                    match find(*l).map(|w| w.value) {
                        Some(Some(v)) if self.dialect == Dialect::Fanuc => {
                            shift[i] = self.m.shift[i] - self.local[i] + v;
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
            G::Home => {
                // G28/G30 (Sinumerik G74/G75) move the named axes, through the intermediate
                // point, to a machine position errmap does not know in work coordinates; the
                // others stay. With no axis word LinuxCNC sends every axis home.
                let named: Vec<usize> = (0..3).filter(|&i| find(AXES[i]).is_some()).collect();
                if named.is_empty() {
                    self.m.pos = [None; 3];
                }
                for i in named {
                    self.m.pos[i] = None;
                }
                self.m.unknown_since = Some(line.number);
            }
            _ => {
                self.m.forget_position(line.number);
            }
        }
        Ok(())
    }

    /// Change the shift between program and work coordinates; the machine stays put.
    pub(super) fn set_shift(&mut self, shift: [f64; 3]) {
        for (i, new) in shift.iter().enumerate() {
            self.m.pos[i] = self.m.pos[i].map(|p| p + self.m.shift[i] - new);
        }
        self.m.shift = shift;
    }

    /// Sinumerik programmable frames: TRANS/ATRANS are followed (a shift), ROT/SCALE/MIRROR
    /// (and their additive forms) are frames errmap refuses cuts under; a bare TRANS, ROT,
    /// SCALE or MIRROR deletes the whole programmable frame.
    pub(super) fn siemens_frame(&mut self, line: &Line, name: &str, body: &str) -> Result<()> {
        let args = &body[name.len().min(body.len())..];
        let mut values = [None; 3];
        for w in args.split_whitespace() {
            // The axis letter may be any character in a mistyped frame: split after it, never
            // inside it.
            let (l, v) = w.split_at(w.chars().next().map_or(0, char::len_utf8));
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
        let mut shift = self.m.shift;
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

    /// A dialect statement. `Ok(true)`: harmless, read the line's words as usual; `Ok(false)`:
    /// followed here, copy the line.
    pub(super) fn keyword(&mut self, line: &Line, name: &str, span: Range<usize>) -> Result<bool> {
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
                if self.dialect == Dialect::Heidenhain
                    && (upper.contains("G70") || upper.contains("G71"))
                {
                    self.m.inches = upper.contains("G70");
                    self.set_units_known();
                    self.m.fix_zone();
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
                | "COMPON" | "COMPOF" | "STOPRE" | "DEF" | "WORKPIECE" | "SPOS" | "SPOSA" | "FNORM"
                | "G642" | "G641",
            ) => Ok(true),
            // TRAFOOF switches a kinematic transformation off: errmap follows none (TRAORI and
            // the others are refused), so after it the machine is as errmap takes it to be.
            (Dialect::Sinumerik, "TRAFOOF") => Ok(true),
            // SUPA: the block's coordinates are machine coordinates, frames suppressed, as G53.
            (Dialect::Sinumerik, "SUPA") => {
                self.machine_block = Some(line.number);
                Ok(true)
            }
            (Dialect::Sinumerik, _) if is_label(body) => Ok(false),
            (Dialect::Sinumerik, _) if self.flow.as_ref().is_some_and(|(l, _)| *l <= line.number) => Ok(false),
            _ => refuse(
                format!("`{}`: errmap does not follow the {} instruction {name}, which may move the machine or change its coordinates", body.trim(), self.dialect.name()),
                "expand it into plain G0/G1/G2/G3 blocks with your CAM post",
            ),
        }
    }

    /// Fanuc M98/M99/M30 and Sinumerik L/M17: subprogram calls are refused, subprogram bodies
    /// are kept as text.
    pub(super) fn fanuc_m_codes(&mut self, line: &Line, words: &[W]) -> Result<()> {
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

    /// Strict blocks: no stray characters, no word twice (but G and M), no unknown letter.
    pub(super) fn check_block(&self, line: &Line) -> Result<()> {
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
                            format!("malformed number: `{},` has a decimal comma", w.trim()),
                            "write numbers with a decimal point (e.g. X20.5)".to_string(),
                        ),
                        _ => (
                            format!(
                                "`{here}` is not a word errmap can read in the {} dialect",
                                self.dialect.name()
                            ),
                            self.or_dialect("fix or remove it (a word is a letter and a number)"),
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
                            &self.or_dialect("remove it"),
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
                    prev_number = matches!(value, WordValue::Number(_)).then_some(here);
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

    pub(super) fn oword(
        &mut self,
        line: &Line,
        name: &str,
        keyword: &str,
        otext: &str,
    ) -> Result<()> {
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

    pub(super) fn close_block(&mut self, line: u64) {
        if let Some(b) = self.blocks.pop() {
            for (i, w) in b.written.iter().enumerate() {
                if *w {
                    self.m.pos[i] = None;
                    self.m.unknown_since = Some(line);
                }
            }
            if let Some(parent) = self.blocks.last_mut() {
                for i in 0..3 {
                    parent.written[i] |= b.written[i];
                }
            }
        }
    }

    /// The modal groups a called subroutine (or what it calls, or a subroutine in another
    /// file) may change are unknown after the call: cuts in the zone are refused until the
    /// program sets each of them again (with `--expand` the body is run instead).
    fn modes_after_call(&mut self, line: &Line, name: &str) {
        let mut sets: Vec<(&'static str, String)> = Vec::new();
        for (n, info) in self.sub_closure(name) {
            let found: Vec<(&'static str, String)> = match info {
                Some(info) => info
                    .sets
                    .iter()
                    .map(|(group, l, word)| (*group, format!("`{word}` on line {l} in o{n}")))
                    .collect(),
                None => ["distance", "units", "plane", "arc", "comp", "motion"]
                    .into_iter()
                    .map(|group| (group, format!("o{n}, not defined in this file")))
                    .collect(),
            };
            for (group, what) in found {
                if !sets.iter().any(|(g, _)| *g == group) {
                    sets.push((group, what));
                }
            }
        }
        let call = self
            .text
            .get(line.span.clone())
            .unwrap_or("")
            .trim()
            .to_string();
        for (group, what) in sets {
            let key = super::Holds::Mode(group);
            self.unfollowed.retain(|u| u.key != key);
            self.unfollowed.push(super::Unfollowed {
                key,
                word: call.split_whitespace().next().unwrap_or("o").to_string(),
                why: format!("`{call}` (line {}) may change the {} mode ({what}), which errmap does not follow across a call, and this cut may lie in the compensation zone", line.number, match group {
                    "distance" => "distance (G90/G91)",
                    "units" => "units (G20/G21)",
                    "plane" => "plane (G17/G18/G19)",
                    "arc" => "arc centre (G90.1/G91.1)",
                    "comp" => "cutter compensation (G40/G41/G42)",
                    _ => "motion (G0/G1/G2/G3)",
                }),
                hint: format!("pass {} to run the subroutine, or say the mode again after the call (e.g. G90, G21, G17, G1)", errmap_core::setting::words(Setting::Expand)).into(),
            });
        }
    }

    /// Subroutine closure: does it (or what it calls) write the normal axis; its first move line.
    pub(super) fn sub_summary(&self, name: &str) -> (bool, Option<(String, u64)>, bool) {
        let mut writes = false;
        let mut first: Option<(String, u64)> = None;
        let mut external = false;
        for (n, info) in self.sub_closure(name) {
            match info {
                Some(info) => {
                    writes |= info.writes_normal;
                    if let (None, Some(l)) = (&first, info.first_move) {
                        first = Some((n, l));
                    }
                }
                None => external = true,
            }
        }
        (writes, first, external)
    }

    /// The subroutine `name` and every one it calls, each once, in the order met (`None`: not
    /// defined in this file).
    fn sub_closure(&self, name: &str) -> Vec<(String, Option<&SubInfo>)> {
        let mut seen = HashSet::new();
        let mut stack = vec![name.to_string()];
        let mut out = Vec::new();
        while let Some(n) = stack.pop() {
            if !seen.insert(n.clone()) {
                continue;
            }
            let info = self.subs.get(&n);
            if let Some(info) = info {
                stack.extend(info.calls.iter().cloned());
            }
            out.push((n, info));
        }
        out
    }

    pub(super) fn call(&mut self, line: &Line, name: &str, otext: &str) -> Result<()> {
        self.modes_after_call(line, name);
        let (writes_normal, first_move, external) = self.sub_summary(name);
        let moves = first_move.is_some() || external;
        if moves {
            let mut p = self.m.pos;
            if writes_normal || external {
                p[self.m.normal] = None;
            }
            let (u, v) = self.m.plane_uv;
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
        let (u, v) = self.m.plane_uv;
        if moves {
            self.m.pos[u] = None;
            self.m.pos[v] = None;
            for i in 0..3 {
                if i != self.m.normal {
                    self.m.pos[i] = None;
                }
            }
            if writes_normal || external {
                self.m.pos[self.m.normal] = None;
            }
            self.m.unknown_since = Some(line.number);
        }
        Ok(())
    }

    /// The points of a move as errmap can know them under a frame: plane coordinates unknown,
    /// the normal too unless a rotation turns about it.
    pub(super) fn frame_points(
        &self,
        kind: Frame,
        pts: &[[Option<f64>; 3]],
    ) -> Vec<[Option<f64>; 3]> {
        let keep_normal = kind == Frame::Rotation && self.plane.axes().2 == self.m.normal;
        pts.iter()
            .map(|p| {
                let mut q = [None; 3];
                if keep_normal {
                    q[self.m.normal] = p[self.m.normal];
                }
                q
            })
            .collect()
    }
}
