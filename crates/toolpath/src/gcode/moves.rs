//! One block's move: its G codes applied to the modal state, its start and end, what forbids compensating it (refusals in the zone), and the hand-off to the rewriter or to a byte-for-byte copy.

use super::super::arc::Arc;
use super::super::dialect::{Dialect, Frame, Motion, PowerOnMotion, G};
use super::super::lexer::{Line, TokenKind};
use super::super::TracedMove;
use super::contour::CompMode;
use super::emit::{emit_curve, Breaks};
use super::{dist, lerp, MotionMode, Rewriter, AXES, W};
use crate::setting::Setting;
use errmap_core::error::{Error, Result};
use std::borrow::Cow;

/// The fewest bytes a segment line errmap writes can take: `G1 X0.0000 Y0.0000 Z0.0000` and a
/// newline (every segment writes all three axes with at least four decimals).
const MIN_SEGMENT_BYTES: u64 = 27;

/// A known point of the original program (some coordinates may be unknown).
type Point = [Option<f64>; 3];

/// What stops a move from being compensated, when it may touch the zone: the word to point
/// at, the message and the hint.
type Refusal = (String, String, Cow<'static, str>);

/// The words of a block that change its meaning beyond a plain X/Y/Z move.
struct Move<'w> {
    motion: MotionMode,
    start: Point,
    end: Point,
    /// G1, G2 or G3 (not a rapid, cycle, probe or special move).
    cutting: bool,
    g53: bool,
    /// How the block says it is in machine coordinates: `G53`, or Sinumerik `SUPA`.
    machine_word: &'static str,
    polar: Option<&'w W>,
    expr: Option<&'w W>,
    other_axis: Option<&'w W>,
    block_delete: bool,
}

/// The first user variable a word reads: LinuxCNC/Fanuc `#100`, `#<name>`; Sinumerik `R1` or
/// a named variable.
fn variable_in(word: &str, dialect: Dialect) -> Option<String> {
    if let Some(at) = word.find('#') {
        let rest = &word[at + 1..];
        let len = if rest.starts_with('<') {
            rest.find('>').map_or(rest.len(), |e| e + 1)
        } else {
            rest.bytes().take_while(u8::is_ascii_digit).count()
        };
        return Some(format!("#{}", &rest[..len]));
    }
    if dialect != Dialect::Sinumerik {
        return None;
    }
    // After the axis letter and `=`: the first identifier (R-parameter or named variable).
    let body = word.get(1..)?.trim_start_matches('=');
    let bytes = body.as_bytes();
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i].is_ascii_alphabetic() || bytes[i] == b'_' {
            let start = i;
            while i < bytes.len() && (bytes[i].is_ascii_alphanumeric() || bytes[i] == b'_') {
                i += 1;
            }
            let name = &body[start..i];
            let function = matches!(
                name.to_ascii_uppercase().as_str(),
                "SIN"
                    | "COS"
                    | "TAN"
                    | "SQRT"
                    | "ABS"
                    | "AC"
                    | "IC"
                    | "ATAN2"
                    | "POT"
                    | "TRUNC"
                    | "ROUND"
            );
            if !function {
                return Some(name.to_string());
            }
        } else {
            i += 1;
        }
    }
    None
}

fn is_axis(letter: u8) -> bool {
    matches!(
        letter,
        b'X' | b'Y' | b'Z' | b'A' | b'B' | b'C' | b'U' | b'V' | b'W' | b'@' | b'^'
    )
}

impl<'a> Rewriter<'a> {
    /// A block of words (no keyword, O-word or subroutine body): modal codes, then either a
    /// group-0 code, no motion, a move errmap copies, or a move it compensates.
    pub(super) fn block(&mut self, line: &Line, words_in: &[W]) -> Result<()> {
        self.check_g_words(line, words_in)?;
        // Where this block's output begins (a Sinumerik modal cycle call wraps it).
        let out_start = self.out.len();
        if self.m.offset != 0.0 && self.changes_offset(words_in) {
            // Back to the program's Z in the offset the cut was made in.
            self.return_if_needed(line, &[], true)?;
        }
        self.modal(line, words_in);
        self.fadal_offset(line, words_in);
        self.fanuc_l_word(line, words_in)?;
        self.modes_said(words_in);
        let gs = || words_in.iter().filter_map(|w| w.g.map(|(c, g)| (w, c, g)));
        let scaled = self.fanuc_numbers(line, words_in)?;
        let words: &[W] = scaled.as_deref().unwrap_or(words_in);
        let motion_word = gs().find(|(_, _, g)| g.is_motion());
        self.retract_mode(words_in);
        if let Some((_, code, g)) = motion_word {
            self.motion = match g {
                G::Motion(kind) => Some(MotionMode { kind, code }),
                _ => None,
            };
            if g != G::Motion(Motion::Canned) {
                // G80 or another motion mode ends the canned-cycle series.
                self.cycle = None;
            }
        }
        let group0 = gs().find(|(_, _, g)| {
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
        // Group 0 codes that take axis words (G10, G28, G30, G92…): no cutting move on the line.
        if let Some((gw, _, g)) = group0 {
            if words.iter().any(|w| is_axis(w.letter)) {
                self.modal_hole_unknown(line)?;
            }
            self.return_if_needed(line, words, true)?;
            self.group0(line, words, gw, g)?;
            self.sync_out_motion(words);
            self.copy_line(line);
            return Ok(());
        }
        let g53 = gs().any(|(_, _, g)| g == G::Machine) || self.machine_block == Some(line.number);
        let arc_words = words
            .iter()
            .any(|w| matches!(w.letter, b'I' | b'J' | b'K' | b'R'));
        let arc_mode = self
            .motion
            .is_some_and(|m| matches!(m.kind, Motion::ArcCw | Motion::ArcCcw));
        let moves = words.iter().any(|w| is_axis(w.letter))
            || (motion_word.is_some() && arc_words && arc_mode);
        if moves && self.motion.is_none() {
            if let Some(u) = self
                .unfollowed
                .iter()
                .find(|u| u.key == super::Holds::Mode("motion"))
            {
                let why = u.why.clone();
                return Err(self.err(line, "X", why, &u.hint));
            }
            self.motion = Some(self.power_on_motion(line, words)?);
            // The output powers on in the same mode.
            self.out_motion = self.out_motion.or(self.motion);
        }
        if moves {
            self.rotary_positions(line, words);
        }
        let Some(motion) = self.motion.filter(|_| moves) else {
            self.sync_out_motion(words);
            self.copy_line(line);
            return Ok(());
        };
        self.m.fix_zone();
        let mv = self.classify(line, words, motion, g53);
        if motion.kind == Motion::Canned && !mv.block_delete && mv.polar.is_none() {
            if self.trace.is_some() {
                self.trace_move(line, words, &mv)?;
            }
            return self.canned(line, words, mv.start, mv.end);
        }
        if motion.kind == Motion::Canned {
            if let Some(c) = self.cycle.as_mut() {
                c.forget_levels();
            }
        }
        if let Some((col, msg, hint)) = self.refusal(words, &mv) {
            return Err(self.err(line, &col, msg, &hint));
        }
        if self.trace.is_some() {
            self.trace_move(line, words, &mv)?;
        }
        let in_plane = self.moves_in_plane(&mv.start, &mv.end);
        let result = if !self.plain(&mv) {
            // Not compensable, but shown above not to touch the zone: copy as is.
            let end = self.end_after_unfollowed(&mv);
            self.finish_unchanged(line, words, end)
        } else {
            self.compensate_move(line, words, &mv, in_plane)
        };
        if in_plane {
            // The start-up or cancel block of cutter radius compensation has run.
            self.comp_transition = None;
        }
        result?;
        self.modal_hole(line, out_start)
    }

    /// Rotary axes (and the parallel axes U V W): the map is taken as measured with every such
    /// axis at 0, so one commanded elsewhere (or incrementally, to where errmap cannot tell)
    /// refuses the cuts in the zone after it, until it is commanded back to 0.
    fn rotary_positions(&mut self, line: &Line, words: &[W]) {
        for w in words
            .iter()
            .filter(|w| matches!(w.letter, b'A' | b'B' | b'C' | b'U' | b'V' | b'W'))
        {
            let axis = w.letter as char;
            let key = super::Holds::Axis(w.letter);
            self.unfollowed.retain(|u| u.key != key);
            let at_zero = w.value == Some(0.0) && !w.is_expr && w.abs.unwrap_or(self.absolute);
            if !at_zero {
                let word = self.wtext(w).to_string();
                self.unfollowed.push(super::Unfollowed {
                    key,
                    why: format!("axis {axis} stands away from 0 (`{word}`, line {}), where errmap takes the map to be measured: the part or the tool is moved, and this cut may lie in the compensation zone", line.number),
                    word,
                    hint: "compensate the cuts of each rotary or parallel-axis position with a map measured there, bring the axis back to 0 before the cuts in the zone, or move the zone away".into(),
                });
            }
        }
    }

    /// The modal groups a block sets end what a subroutine left unknown in them.
    fn modes_said(&mut self, words: &[W]) {
        if self.unfollowed.is_empty() {
            return;
        }
        for group in words
            .iter()
            .filter_map(|w| w.g().and_then(super::modal_group))
        {
            self.unfollowed
                .retain(|u| u.key != super::Holds::Mode(group));
        }
    }

    /// Fanuc `L`: a repeat count with M98, G65 or a canned cycle, and data with G10; anywhere
    /// else it is a Fadal subprogram definition or call (`L100`, `L101`) or a Fadal repeat count
    /// (`G3 I-2. L19`), which errmap does not follow.
    fn fanuc_l_word(&self, line: &Line, words: &[W]) -> Result<()> {
        if self.dialect != Dialect::Fanuc {
            return Ok(());
        }
        let Some(l) = words.iter().find(|w| w.letter == b'L') else {
            return Ok(());
        };
        let with = words.iter().any(|w| {
            (w.letter == b'M' && w.value == Some(98.0))
                || matches!(
                    w.g(),
                    Some(G::Call | G::DataSetting | G::Motion(Motion::Canned))
                )
        }) || self.motion.is_some_and(|m| m.kind == Motion::Canned);
        if with {
            return Ok(());
        }
        let t = self.wtext(l).to_string();
        // Never offer the flag the user already gave.
        let hint = if self.m.settings.expand {
            "post the program without Fadal subprograms and repeat counts (plain blocks), or rewrite them as M98 subprograms in the same file".to_string()
        } else {
            format!("post the program without Fadal subprograms and repeat counts (plain blocks), or rewrite them as M98 subprograms in the same file and pass {}", errmap_core::setting::words(Setting::Expand))
        };
        Err(self.err(
            line,
            &t,
            format!("`{t}`: a Fadal subprogram definition or call (L100, L101) or a repeat count on a move, which errmap does not follow"),
            &hint,
        ))
    }

    /// The motion of a block with axis words before any motion word: LinuxCNC refuses such a
    /// block; a Fanuc, a Sinumerik or a TNC in ISO runs it in the motion mode it powers on in,
    /// which errmap takes from `--power-on-motion`, or refuses.
    fn power_on_motion(&self, line: &Line, words: &[W]) -> Result<MotionMode> {
        let at = words
            .iter()
            .find(|w| is_axis(w.letter))
            .map(|w| self.wtext(w).to_string())
            .unwrap_or_else(|| "X".into());
        let (message, hint) = match (self.dialect, self.m.settings.power_on_motion) {
            (Dialect::Linuxcnc, _) => (
                format!("`{at}`: axis words with no motion mode in force (no G0, G1, G2, G3 before them); LinuxCNC stops here: \"Cannot use axis values without a g code that uses them\""),
                "add G0 or G1 to this block (or to one before it)".to_string(),
            ),
            (_, Some(PowerOnMotion::Rapid)) => return Ok(MotionMode::RAPID),
            (_, Some(PowerOnMotion::Linear)) => return Ok(MotionMode::LINEAR),
            (Dialect::Fanuc, None) => (
                format!("`{at}`: axis words before any motion word; a Fanuc moves them in the motion mode it powers on in (parameter 3402#0: G00 or G01), which the program does not show"),
                power_on_hint("G0/G1"),
            ),
            (Dialect::Sinumerik, None) => (
                format!("`{at}`: axis words before any motion word; a Sinumerik moves them in its reset motion mode (MD20150 $MC_GCODE_RESET_VALUES[0]), which the program does not show"),
                power_on_hint("G0/G1"),
            ),
            (Dialect::Heidenhain, None) => (
                format!("`{at}`: axis words before any motion word; the control moves them in the motion mode it starts in, which the program does not show"),
                power_on_hint("G00/G01"),
            ),
        };
        Err(self.err(line, &at, message, &hint))
    }

    /// Start, end and the words of a move that bear on whether it can be compensated.
    fn classify<'w>(&self, line: &Line, words: &'w [W], motion: MotionMode, g53: bool) -> Move<'w> {
        let start = self.m.pos;
        let mut end = self.m.pos;
        for (i, l) in AXES.iter().enumerate() {
            if let Some(w) = words.iter().find(|w| w.letter == *l) {
                end[i] = if g53 {
                    None
                } else if w.abs.unwrap_or(self.absolute) {
                    w.value
                } else {
                    start[i].zip(w.value).map(|(s, d)| s + d)
                };
            }
        }
        let polar = words.iter().find(|w| w.letter == b'@' || w.letter == b'^');
        if polar.is_some() {
            let (a1, a2, _) = self.plane.axes();
            end[a1] = None;
            end[a2] = None;
        }
        // `/` at the start of a line: block delete, the controller may skip the line.
        let block_delete = line
            .tokens
            .iter()
            .find(|t| t.kind != TokenKind::Space)
            .is_some_and(|t| {
                t.kind == TokenKind::Other && self.text.get(t.span.clone()) == Some("/")
            });
        Move {
            motion,
            start,
            end,
            cutting: matches!(motion.kind, Motion::Linear | Motion::ArcCw | Motion::ArcCcw),
            g53,
            machine_word: if self.machine_block == Some(line.number) {
                "SUPA"
            } else {
                "G53"
            },
            polar,
            expr: words.iter().find(|w| w.is_expr),
            other_axis: words
                .iter()
                .find(|w| matches!(w.letter, b'A' | b'B' | b'C' | b'U' | b'V' | b'W')),
            block_delete,
        }
    }

    /// Why this move cannot be compensated although it may touch the zone, if so.
    fn refusal(&self, words: &[W], mv: &Move) -> Option<Refusal> {
        if !mv.cutting {
            return self.cycle_refusal(words, mv);
        }
        if !self.m.units_known {
            return Some(self.units_refusal(words));
        }
        self.context_refusal(mv)
            .or_else(|| self.word_refusal(mv))
            .filter(|_| self.may_touch(&self.frame_points_of(mv)))
    }

    /// Canned cycles and moves errmap does not follow (splines, threads …) in the zone.
    fn cycle_refusal(&self, words: &[W], mv: &Move) -> Option<Refusal> {
        let canned = mv.motion.kind == Motion::Canned;
        if !canned && mv.motion.kind != Motion::Special {
            return None;
        }
        let find = |l: u8| words.iter().find(|w| w.letter == l).and_then(|w| w.value);
        let mut pts = vec![mv.start, mv.end];
        if canned {
            // The drill axis runs from the start through the R level to the bottom Z;
            // under G91, R is relative to the start and Z to the R level.
            let (_, _, ax) = self.plane.axes();
            let (r, z) = (find(b'R'), find(AXES[ax]));
            let (r_abs, z_abs) = if self.absolute {
                (r, z)
            } else {
                let ra = mv.start[ax].zip(r).map(|(s, r)| s + r);
                (ra, ra.zip(z).map(|(ra, z)| ra + z))
            };
            pts[1][ax] = mv.start[ax];
            for level in [r_abs, z_abs] {
                let mut p = pts[1];
                p[ax] = level;
                pts.push(p);
            }
        }
        let name = mv.motion.code.to_string();
        let what = if canned {
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
                "expand the cycle into G0/G1 moves with your CAM post (or move the zone away)"
                    .into(),
            )
        })
    }

    /// A cut before the program said its units: always refused.
    fn units_refusal(&self, words: &[W]) -> Refusal {
        let at = words
            .iter()
            .find(|w| matches!(w.letter, b'G' | b'X' | b'Y' | b'Z'))
            .map(|w| self.wtext(w).to_string())
            .unwrap_or_default();
        let (codes, hint) = match self.dialect {
            Dialect::Linuxcnc | Dialect::Fanuc => {
                ("G20/G21", "add G21 (mm) or G20 (inch) before the first cut")
            }
            Dialect::Sinumerik => (
                "G70/G71/G700/G710",
                "add G71 (mm) or G70 (inch) before the first cut",
            ),
            Dialect::Heidenhain => (
                "G70/G71 in the % header",
                "begin the program with %NAME G71 * (mm) or G70 * (inch)",
            ),
        };
        (
            at,
            format!("cut with no unit code ({codes}) before it: errmap cannot tell millimetres from inches (a 25.4× error)"),
            format!("{hint}, or pass {} mm|inch", errmap_core::setting::words(Setting::Units)).into(),
        )
    }

    /// The points errmap can vouch for under the active frame (all of them without one).
    fn frame_points_of(&self, mv: &Move) -> Vec<Point> {
        match self.frames.last() {
            Some(&(kind, _, _)) => self.frame_points(kind, &[mv.start, mv.end]),
            None => vec![mv.start, mv.end],
        }
    }

    /// The program's state forbids compensating (a frame, a jump, a loop, cutter compensation).
    fn context_refusal(&self, mv: &Move) -> Option<Refusal> {
        // An axis moving on this very cut is named by the word refusal.
        let own_axis = |u: &&super::Unfollowed| {
            mv.other_axis
                .is_some_and(|w| u.key == super::Holds::Axis(w.letter))
        };
        if let Some(u) = self.unfollowed.iter().rev().find(|u| !own_axis(u)) {
            return Some((u.word.clone(), u.why.clone(), u.hint.clone()));
        }
        if let Some((Frame::WorkOffset, fl, fw)) = self.frames.last() {
            let first = self.first_offset.clone().unwrap_or_default();
            return Some((
                fw.split_whitespace().next().unwrap_or("G").to_string(),
                format!("`{fw}` (line {fl}) selects a work offset other than the program's first ({first}), whose coordinates the map is in, and this cut may lie in the compensation zone"),
                format!("pass {} if each offset holds an identical part (the map then applies in each offset's coordinates; job key [toolpaths] same_part_per_offset), or select the first offset again before cuts in the zone", errmap_core::setting::words(Setting::SamePartPerOffset)).into(),
            ));
        }
        if let Some((kind, fl, fw)) = self.frames.last() {
            return Some((
                fw.clone(),
                format!("`{fw}` (line {fl}) transforms the coordinates ({kind:?}), which errmap does not follow, and this cut may lie in the compensation zone"),
                "cancel the transformation before the cuts in the zone (G69, G50, G50.1, G54 …), or post the program without it".into(),
            ));
        }
        if let Some((fl, fw)) = &self.flow {
            return Some((
                fw.clone(),
                format!("the program jumps (`{fw}` on line {fl}), so a cut may run any number of times from any position, and this cut may lie in the compensation zone"),
                "expand loops and jumps into plain blocks".into(),
            ));
        }
        if let Some(b) = self.blocks.last() {
            let head = format!("o{} {}", b.name, b.keyword);
            return Some((
                head.clone(),
                format!("move inside the O-word block `{head}` (line {}) may lie in the compensation zone", b.line),
                "expand O-word loops, conditions and subroutines into plain G-code (or move the zone away)".into(),
            ));
        }
        let comp = self.cutter_comp.as_ref().or(self.comp_transition.as_ref());
        if let (Some((cl, code)), false) = (comp, self.tool_axis_is_normal()) {
            let plane = format!("{:?}", self.plane);
            let n = AXES[self.m.normal] as char;
            return Some((
                code.clone(),
                format!("cutter radius compensation {code} (from line {cl}) offsets the contour in the {plane} plane, which holds the map's normal axis {n}: moving {n} by −E would change the contour the control offsets"),
                "compensate with the tool axis along the map's normal (G17 for a Z map), or post the program as the tool-centre path (G40) for the zone, or move the zone away".into(),
            ));
        }
        if mv.block_delete {
            return Some((
                "/".into(),
                "block delete `/` on a move in the compensation zone (the controller may skip the line)".into(),
                "remove the `/` or move the zone away".into(),
            ));
        }
        None
    }

    /// A word of the block forbids compensating (polar, expression, other axis, G53), or the
    /// start point is unknown.
    fn word_refusal(&self, mv: &Move) -> Option<Refusal> {
        if let Some(w) = mv.polar {
            return Some((
                self.wtext(w).to_string(),
                "polar coordinates (@ ^) on a move in the compensation zone".into(),
                "post the program with X/Y coordinates (or move the zone away)".into(),
            ));
        }
        if let Some(w) = mv.expr {
            let text = self.wtext(w).to_string();
            let reads = match variable_in(&text, self.dialect) {
                Some(v) => format!(": `{text}` reads the variable {v}"),
                None => format!(": `{text}` is an expression"),
            };
            return Some((
                text,
                format!("# parameters or [expressions] on a move in the compensation zone{reads}, whose value errmap does not carry into a rewritten move"),
                if self.m.settings.expand {
                    "expand the program to plain numbers (or move the zone away)".into()
                } else {
                    format!("pass {} to run the program's own parameter values into plain numbers, or expand the program to plain numbers (or move the zone away)", errmap_core::setting::words(Setting::Expand)).into()
                },
            ));
        }
        if let Some(w) = mv.other_axis {
            return Some((
                self.wtext(w).to_string(),
                format!(
                    "axis {} moves together with a cut in the compensation zone",
                    w.letter as char
                ),
                "errmap compensates 3-axis X/Y/Z moves only; move the zone away from this move"
                    .into(),
            ));
        }
        if mv.g53 {
            let word = mv.machine_word;
            return Some((
                word.into(),
                format!("{word} machine-coordinate cutting move in the compensation zone"),
                "program the cut in work coordinates".into(),
            ));
        }
        if mv.start.iter().any(|c| c.is_none()) {
            let since = self
                .m
                .unknown_since
                .map(|l| format!(" since line {l}"))
                .unwrap_or_else(|| " (no absolute X, Y and Z since the program start)".into());
            return Some((
                "start".into(),
                format!("the start point of this move is unknown{since}, so errmap cannot tell whether it lies in the compensation zone"),
                "give absolute X, Y and Z (G90) before the first cut".into(),
            ));
        }
        None
    }

    /// Record a move whose start and end are known, in mm and work coordinates.
    fn trace_move(&mut self, line: &Line, words: &[W], mv: &Move) -> Result<()> {
        let known = |p: Point| -> Option<[f64; 3]> { Some([p[0]?, p[1]?, p[2]?]) };
        let (Some(s), Some(e)) = (known(mv.start), known(mv.end)) else {
            return Ok(());
        };
        let k = self.m.scale_mm();
        let shift = self.m.shift;
        let mm = |p: [f64; 3]| [0, 1, 2].map(|i| (p[i] + shift[i]) * k);
        let arc_mm = match mv.motion.kind {
            Motion::ArcCw | Motion::ArcCcw => {
                let a = self.arc(line, words, s, e, mv.motion.kind == Motion::ArcCw)?;
                let (a1, a2, _) = a.plane.axes();
                Some(Arc {
                    start: mm(a.start),
                    end: mm(a.end),
                    centre: ((a.centre.0 + shift[a1]) * k, (a.centre.1 + shift[a2]) * k),
                    r_start: a.r_start * k,
                    r_end: a.r_end * k,
                    ..a
                })
            }
            _ => None,
        };
        if let Some(t) = self.trace.as_mut() {
            t.push(TracedMove {
                line: line.number,
                kind: mv.motion.kind,
                start_mm: mm(s),
                end_mm: mm(e),
                arc_mm,
            });
        }
        Ok(())
    }

    /// A cut errmap compensates: nothing in the block or the state stands in the way.
    fn plain(&self, mv: &Move) -> bool {
        mv.cutting
            && self.m.units_known
            && self.frames.is_empty()
            && self.unfollowed.is_empty()
            && self.flow.is_none()
            && !mv.block_delete
            && self.blocks.is_empty()
            && (!self.comp_sensitive() || self.tool_axis_is_normal())
            && mv.polar.is_none()
            && mv.expr.is_none()
            && mv.other_axis.is_none()
            && !mv.g53
            && mv.start.iter().all(|c| c.is_some())
    }

    /// Where the tool is known to be after a move errmap copies without following it.
    fn end_after_unfollowed(&self, mv: &Move) -> Point {
        let mut end = mv.end;
        // A block-deleted line may or may not run; a probing move stops where it touches.
        if mv.block_delete || mv.motion.kind == Motion::Probe {
            for (e, s) in end.iter_mut().zip(mv.start) {
                if *e != s {
                    *e = None;
                }
            }
        }
        if mv.motion.kind == Motion::Canned {
            // The cycle retracts to the R level or the start (G98/G99): not tracked.
            end[self.plane.axes().2] = None;
        }
        end
    }

    /// Split the move at the zone and domain edges, compensate its points in both, and write
    /// it (or copy the line when no point is in).
    fn compensate_move(
        &mut self,
        line: &Line,
        words: &[W],
        mv: &Move,
        in_plane: bool,
    ) -> Result<()> {
        let mode = self.comp_mode(in_plane);
        let s = mv.start.map(|c| c.unwrap_or(0.0));
        let e = [0, 1, 2].map(|i| mv.end[i].unwrap_or(s[i]));
        let cw = mv.motion.kind == Motion::ArcCw;
        let arc = match mv.motion.kind {
            Motion::Linear => None,
            _ => Some(self.arc(line, words, s, e, cw)?),
        };
        let step = self.m.settings.max_segment_in(self.m.inches);
        // Under cutter compensation arc pieces are arcs: only length and quarter turns cut them.
        let tol = match mode {
            CompMode::Off => self.m.settings.chord_tol_in(self.m.inches),
            _ => f64::INFINITY,
        };
        let chords = self.chord_count(line, arc.as_ref(), &s, &e, step, tol)?;
        // The move as a curve over [0, 1] with its chord ends as break points: splits at the
        // zone and domain edges fall on the curve itself (on the arc, not on a chord).
        let mut emitted = std::mem::take(&mut self.emitted);
        emitted.clear();
        {
            let curve = |t: f64| match &arc {
                None => lerp(&s, &e, t),
                Some(a) => a.point(t),
            };
            let error_at = |p: &[f64; 3]| self.m.error_at(p);
            let complete = emit_curve(
                Breaks::Fractions(chords),
                &curve,
                step,
                self.m.zone_now(),
                self.m.normal,
                &error_at,
                self.points_within_output_limit(),
                &mut emitted,
            );
            if !complete {
                self.emitted = emitted;
                return Err(self.output_limit_error(line));
            }
        }
        self.m.kept_nominal.count(&mut self.report);
        let result = if emitted.iter().any(|(_, e)| e.is_some()) {
            match mode {
                CompMode::Off => self.rewrite(line, words, &emitted, arc.as_ref(), mv.motion),
                _ => self.rewrite_contour(line, words, &emitted, arc.as_ref(), mv.motion, s, mode),
            }
            .map(|()| self.m.pos = e.map(Some))
        } else {
            self.finish_unchanged(line, words, mv.end)
        };
        self.emitted = emitted;
        result
    }

    /// How many compensated points the output limit leaves room for: each becomes a segment of
    /// at least [`MIN_SEGMENT_BYTES`] (`G1 X0.0000 Y0.0000 Z0.0000` and its newline) unless it
    /// rounds onto its neighbour.
    fn points_within_output_limit(&self) -> usize {
        let limit = errmap_core::io::safety::max_output_bytes();
        let left = limit.saturating_sub(self.out.len() as u64);
        usize::try_from(left / MIN_SEGMENT_BYTES).unwrap_or(usize::MAX)
    }

    /// The refusal of a move whose segments alone would take the output past its limit.
    fn output_limit_error(&self, line: &Line) -> Error {
        let limit_mb = errmap_core::io::safety::max_output_bytes() / 1_000_000;
        self.err(
            line,
            "X",
            format!(
                "this move is cut into more segments than the output limit of {limit_mb} MB has room for (at least {MIN_SEGMENT_BYTES} bytes each)"
            ),
            &format!(
                "check arc turn counts (P) and move lengths, raise {} / {}, or raise {}",
                errmap_core::setting::words(Setting::MaxSegment),
                errmap_core::setting::words(Setting::ChordTol),
                errmap_core::setting::words(errmap_core::core_setting::Setting::MaxOutputMb)
            ),
        )
    }

    /// Chords the move is cut into (1 for a straight move); over a million is refused.
    fn chord_count(
        &self,
        line: &Line,
        arc: Option<&Arc>,
        s: &[f64; 3],
        e: &[f64; 3],
        step: f64,
        chord_tol: f64,
    ) -> Result<usize> {
        let (length, chords) = match arc {
            None => (dist(s, e), 1),
            Some(a) => {
                let (_, _, ax) = a.plane.axes();
                let len = (a.sweep.abs() * a.r_start.max(a.r_end)).hypot(a.end[ax] - a.start[ax]);
                (len, a.chords(chord_tol, step))
            }
        };
        // Keep the output finite: a move needing over a million segments is a typo or a unit
        // mistake, not a toolpath.
        if !length.is_finite() || length / step > 1e6 || chords >= 1_000_000 {
            return Err(self.err(
                line,
                "X",
                format!("this move ({length:.6e} program units) would need more than a million segments"),
                &format!(
                    "check the coordinates and units, or raise {} / {}",
                    errmap_core::setting::words(Setting::MaxSegment),
                    errmap_core::setting::words(Setting::ChordTol)
                ),
            ));
        }
        Ok(chords)
    }

    /// The arc of a G2/G3 block from its R word or its centre words.
    fn arc(&self, line: &Line, words: &[W], s: [f64; 3], e: [f64; 3], cw: bool) -> Result<Arc> {
        let find = |l: u8| words.iter().find(|w| w.letter == l).and_then(|w| w.value);
        let code = if cw { "G2" } else { "G3" };
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
                    code,
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
        result.map_err(|m| self.err(line, code, m, "fix the arc's end point or centre"))
    }

    /// Emit a return along the normal to the original position before an unchanged line that
    /// depends on the current position, when the last cut ended compensated.
    ///
    /// The return stands before the line, so it runs under the modes in force before the line
    /// (`self.standing`: distance mode and units), not those the line itself switches to: it
    /// is written in them. It changes only the modal motion (G1, or G0 after a rapid), which
    /// the next moving line gets back explicitly (`copy_with_motion`).
    pub(super) fn return_if_needed(
        &mut self,
        line: &Line,
        words: &[W],
        group0: bool,
    ) -> Result<()> {
        if self.m.offset == 0.0 {
            return Ok(());
        }
        let n = AXES[self.m.normal];
        // A canned cycle's Z word is the hole bottom, and it retracts to its start: not a move
        // to an absolute normal coordinate. The line's own distance mode decides here.
        let absolute_normal = !group0
            && !self.motion.is_some_and(|m| m.kind == Motion::Canned)
            && words
                .iter()
                .any(|w| w.letter == n && w.value.is_some() && w.abs.unwrap_or(self.absolute))
            && !words.iter().any(|w| w.g() == Some(G::Machine));
        if absolute_normal {
            self.m.offset = 0.0;
            return Ok(());
        }
        if self.comp_sensitive() {
            return Err(self.comp_return_error(line));
        }
        let standing = self.standing;
        let Some(orig) = standing.normal_pos else {
            return Err(Error::Internal(format!(
                "{}:{}: compensated position with unknown normal coordinate",
                self.source.display(),
                line.number
            )));
        };
        let value = if standing.absolute {
            orig
        } else {
            -standing.offset
        };
        let mode = if self.out_motion.is_some_and(|m| m.kind == Motion::Rapid) {
            MotionMode::RAPID
        } else {
            MotionMode::LINEAR
        };
        let mut text = format!("{} {}", mode.code, n as char);
        self.push_coord_in(&mut text, value, standing.inches);
        text.push_str(self.eob());
        self.out.push_str(&text);
        self.out.push_str(super::line_terminator(self.text, line));
        self.out_motion = Some(mode);
        self.m.offset = 0.0;
        self.standing.offset = 0.0;
        self.report.returns_inserted += 1;
        Ok(())
    }

    /// Keep the output's modal motion in step with the original's on an unchanged line.
    pub(super) fn sync_out_motion(&mut self, words: &[W]) {
        if words.iter().any(|w| w.g().is_some_and(G::is_motion)) {
            self.out_motion = self.motion;
        }
    }

    /// Copy a line errmap does not change (after a return step if one is due), and track the
    /// position it leaves the tool at.
    pub(super) fn finish_unchanged(&mut self, line: &Line, words: &[W], end: Point) -> Result<()> {
        // Under cutter compensation the return rides on this line's own move.
        let fold = self.fold_return(line, words);
        self.return_if_needed(line, words, false)?;
        let has_motion_g = words.iter().any(|w| w.g().is_some_and(G::is_motion));
        let moves = words
            .iter()
            .any(|w| is_axis(w.letter) || matches!(w.letter, b'I' | b'J' | b'K' | b'R'));
        let prefix = match self.motion {
            Some(m) if moves && !has_motion_g && self.out_motion != self.motion => Some(m),
            _ => None,
        };
        match (prefix, fold) {
            (None, None) => self.copy_line(line),
            (prefix, fold) => self.copy_edited(line, prefix, fold.as_deref()),
        }
        if has_motion_g || moves {
            self.out_motion = self.motion;
        }
        self.track_unchanged_end(line, words, end);
        Ok(())
    }

    /// Copy a line with its modal motion said (`prefix`, after a return step changed the
    /// output's) and a word appended after its last word (`append`, a folded return).
    fn copy_edited(&mut self, line: &Line, prefix: Option<MotionMode>, append: Option<&str>) {
        let Some(text) = append else {
            if let Some(m) = prefix {
                self.copy_with_motion(line, m);
            }
            return;
        };
        let at = line
            .tokens
            .iter()
            .filter(|t| matches!(t.kind, TokenKind::Word { .. }))
            .map(|t| t.span.end)
            .max()
            .unwrap_or(line.span.end);
        let start = self.out.len();
        match prefix {
            Some(m) => self.copy_with_motion(line, m),
            None => self.copy_line(line),
        }
        // The copied line ends with the original's bytes from `at` on.
        let tail = line.end - at;
        let pos = self.out.len() - tail;
        debug_assert!(pos >= start);
        self.out.insert_str(pos, text);
    }

    /// The output's modal motion differs (after a return step): say it on this line, after its
    /// block delete and N-word, which must come first.
    fn copy_with_motion(&mut self, line: &Line, m: MotionMode) {
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
        self.out.push_str(&format!("{} ", m.code));
        self.out.push_str(&text[at..line.end]);
        self.report.lines_prefixed += 1;
    }

    /// Position bookkeeping after an unchanged line.
    fn track_unchanged_end(&mut self, line: &Line, words: &[W], end: Point) {
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
            if *e != self.m.pos[i] {
                if let Some(b) = self.blocks.last_mut() {
                    b.written[i] = true;
                }
                if e.is_none() {
                    self.m.unknown_since = Some(line.number);
                }
            }
        }
        self.m.pos = end;
    }
}

/// The hint of a block with axis words before any motion word: give the mode the controller
/// powers on in, or add `codes` (its rapid and linear codes) to the block.
fn power_on_hint(codes: &str) -> String {
    format!(
        "pass {} g0|g1 as the machine is set (job key [toolpaths] power_on_motion), or add {codes} to this block",
        errmap_core::setting::words(Setting::PowerOnMotion)
    )
}
