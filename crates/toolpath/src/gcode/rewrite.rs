//! The rewriter: a compensated move's points written as blocks, the first in place of the original line's motion words (its other words kept), the others on lines of their own.

use super::super::arc::Arc;
use super::super::dialect::{Dialect, Motion, G};
use super::super::lexer::{Line, TokenKind};
use super::format::{decimal_units, format_decimals_slow, push_units};
use super::{dist, MotionMode, Rewriter, AXES, W};
use errmap_core::error::Result;
use std::ops::Range;

/// The segments of a rewritten move: their words (`G1 X… Y… Z…`) one after another in `text`.
#[derive(Debug, Default)]
pub(super) struct Segments {
    pub(super) text: String,
    pub(super) spans: Vec<Range<usize>>,
}

impl<'a> Rewriter<'a> {
    /// Write a move whose `emitted` points (with E where compensated) replace its motion words.
    pub(super) fn rewrite(
        &mut self,
        line: &Line,
        words: &[W],
        emitted: &[([f64; 3], Option<f64>)],
        arc: Option<&Arc>,
        motion: MotionMode,
    ) -> Result<()> {
        let mut segs = std::mem::take(&mut self.segments);
        segs.text.clear();
        segs.spans.clear();
        let last_e = self.count_compensated(emitted);
        self.segment_words(emitted, arc, motion, &mut segs);
        self.write_move(line, words, arc.is_some(), &mut segs);
        // Offset of the output along the normal at the end of the move.
        self.m.offset = last_e.map_or(0.0, |e| -e);
        self.segments = segs;
        Ok(())
    }

    /// Write a rewritten move's segments in place of its line (the line keeps its other words
    /// only when every point rounds to where the tool stands) and count them in the report.
    pub(super) fn write_move(
        &mut self,
        line: &Line,
        words: &[W],
        is_arc: bool,
        segs: &mut Segments,
    ) {
        if segs.spans.is_empty() {
            segs.spans.push(0..0);
        }
        let nseg = segs.spans.len();
        self.write_lines(line, words, is_arc, segs);
        self.report.moves_changed += 1;
        if nseg > 1 {
            self.report.moves_split += 1;
        }
        self.report.segments_emitted += nseg as u64;
    }

    /// Count the compensated points in the report; E of the last point.
    pub(super) fn count_compensated(&mut self, emitted: &[([f64; 3], Option<f64>)]) -> Option<f64> {
        for e in emitted.iter().filter_map(|(_, e)| *e) {
            let e_mm = e.abs() * self.m.scale_mm();
            if e_mm > self.report.max_abs_error_mm {
                self.report.max_abs_error_mm = e_mm;
            }
            self.report.points_compensated += 1;
        }
        emitted.last().and_then(|(_, e)| *e)
    }

    /// The words of each segment to the targets P' = P − E along the normal, leaving out
    /// targets that repeat the output position or round onto it (no zero-length moves).
    fn segment_words(
        &mut self,
        emitted: &[([f64; 3], Option<f64>)],
        arc: Option<&Arc>,
        motion: MotionMode,
        segs: &mut Segments,
    ) {
        // Current output position: the original's, offset along the normal.
        let mut out_pos = self.m.pos.map(|c| c.unwrap_or(0.0));
        out_pos[self.m.normal] += self.m.offset;
        // The targets that move the tool; the last one may be an arc piece.
        let normal = self.m.normal;
        let target = |(p, e): &([f64; 3], Option<f64>)| {
            let mut q = *p;
            if let Some(e) = e {
                q[normal] -= e;
            }
            q
        };
        let moves = |q: &[f64; 3], prev: &[f64; 3]| dist(q, prev) > 1e-12;
        let mut prev = out_pos;
        let mut pending: Option<[f64; 3]> = None;
        for q in emitted.iter().map(target) {
            if moves(&q, &prev) {
                if let Some(p) = pending.replace(q) {
                    self.segment(p, None, motion, &mut out_pos, segs);
                }
                prev = q;
            }
        }
        // No target moves: the move ends where the output already is.
        let last = pending.unwrap_or(prev);
        self.segment(last, arc, motion, &mut out_pos, segs);
    }

    /// The X Y Z values the controller reads from the words written to reach `q` from
    /// `out_pos` (absolute, or increments under G91, rounded as written), and for each axis
    /// whether it rounds to no motion.
    fn written_target(
        &self,
        q: [f64; 3],
        out_pos: &[f64; 3],
    ) -> ([(Option<i64>, f64); 3], [bool; 3]) {
        let d = self.decimals();
        let written = [0, 1, 2].map(|i| {
            let v = if self.absolute {
                q[i]
            } else {
                q[i] - out_pos[i]
            };
            rounded(v, d)
        });
        let still = [0, 1, 2].map(|i| {
            let now = decimal_units(written[i].1, d);
            if self.absolute {
                now == decimal_units(out_pos[i], d)
            } else {
                now == Some(0)
            }
        });
        (written, still)
    }

    /// Append ` X… Y… Z…` and move `out_pos` to where the controller goes after rounding.
    fn push_axis_words(
        &self,
        written: &[(Option<i64>, f64); 3],
        out_pos: &mut [f64; 3],
        text: &mut String,
        d: usize,
    ) {
        for (i, l) in AXES.iter().enumerate() {
            out_pos[i] = if self.absolute {
                written[i].1
            } else {
                out_pos[i] + written[i].1
            };
            text.push(' ');
            text.push(*l as char);
            push_rounded(text, written[i], d);
        }
    }

    /// One segment to `q` (an arc piece when `final_arc`), unless it rounds to no motion.
    fn segment(
        &mut self,
        q: [f64; 3],
        final_arc: Option<&Arc>,
        motion: MotionMode,
        out_pos: &mut [f64; 3],
        segs: &mut Segments,
    ) {
        let d = self.decimals();
        let (written, still) = self.written_target(q, out_pos);
        if still.iter().all(|s| *s) {
            return;
        }
        // The last piece of an arc is an arc, so the modal motion stays the original's.
        let r_word = final_arc.and_then(|a| {
            let (a1, a2, _) = a.plane.axes();
            let chord = (q[a1] - out_pos[a1]).hypot(q[a2] - out_pos[a2]);
            (chord > 1e-6 && 2.0 * a.r_end > chord).then_some(a.r_end)
        });
        let start = segs.text.len();
        let mode = if r_word.is_some() {
            motion
        } else {
            MotionMode::LINEAR
        };
        segs.text.push_str(mode.word());
        self.push_axis_words(&written, out_pos, &mut segs.text, d);
        if let Some(r) = r_word {
            segs.text.push_str(if self.dialect == Dialect::Sinumerik {
                " CR="
            } else {
                " R"
            });
            self.push_coord(&mut segs.text, r);
        }
        self.out_motion = Some(mode);
        segs.spans.push(start..segs.text.len());
    }

    /// One piece of a contour under cutter radius compensation to `q`: a G1, or with `centre`
    /// an arc about it (G2/G3 with the plane's centre words, incremental from the piece's
    /// rounded start unless G90.1), unless it rounds to no motion — or, with `in_plane`, to no
    /// motion in the plane (a Z-only block the control's compensation must not see).
    pub(super) fn contour_segment(
        &mut self,
        q: [f64; 3],
        centre: Option<(f64, f64)>,
        motion: MotionMode,
        in_plane: bool,
        out_pos: &mut [f64; 3],
        segs: &mut Segments,
    ) {
        let d = self.decimals();
        let (written, still) = self.written_target(q, out_pos);
        let (a1, a2, _) = self.plane.axes();
        if still.iter().all(|s| *s) || (in_plane && still[a1] && still[a2]) {
            return;
        }
        let from = *out_pos;
        let start = segs.text.len();
        let mode = if centre.is_some() {
            motion
        } else {
            MotionMode::LINEAR
        };
        segs.text.push_str(mode.word());
        self.push_axis_words(&written, out_pos, &mut segs.text, d);
        if let Some(c) = centre {
            let (a1, a2, _) = self.plane.axes();
            for (axis, c) in [(a1, c.0), (a2, c.1)] {
                let v = if self.arc_absolute { c } else { c - from[axis] };
                segs.text.push(' ');
                segs.text.push([b'I', b'J', b'K'][axis] as char);
                push_rounded(&mut segs.text, rounded(v, d), d);
            }
        }
        self.out_motion = Some(mode);
        segs.spans.push(start..segs.text.len());
    }

    /// The original line with its motion words replaced by the first segment, then the other
    /// segments on lines of their own; program stops move to the last one.
    pub(super) fn write_lines(&mut self, line: &Line, words: &[W], is_arc: bool, segs: &Segments) {
        let text = self.text;
        let nseg = segs.spans.len();
        // Program stops (M0 M1 M2 M30 M60) act after the line's motion: they move to the last
        // segment, so the program does not stop after the first one.
        let is_stop = |w: &W| {
            nseg > 1
                && w.letter == b'M'
                && w.value
                    .is_some_and(|v| [0.0, 1.0, 2.0, 30.0, 60.0].contains(&v))
        };
        let removed = |w: &W| {
            matches!(w.letter, b'X' | b'Y' | b'Z' | b'I' | b'J' | b'K' | b'R')
                || matches!(
                    w.g(),
                    Some(G::Motion(
                        Motion::Rapid | Motion::Linear | Motion::ArcCw | Motion::ArcCcw
                    ))
                )
                || (w.letter == b'P' && is_arc)
        };
        let first_text = &segs.text[segs.spans[0].clone()];
        let line_start = self.out.len();
        let mut inserted = false;
        let mut skip_space = false;
        // Words are in token order: walk both together.
        let mut wi = 0;
        for (ti, tok) in line.tokens.iter().enumerate() {
            while wi < words.len() && words[wi].token < ti {
                wi += 1;
            }
            let word = words.get(wi).filter(|w| w.token == ti);
            if word.is_some_and(is_stop) {
                skip_space = true;
                continue;
            }
            if word.is_some_and(removed) {
                if !inserted {
                    self.out.push_str(first_text);
                    inserted = true;
                }
                skip_space = true;
                continue;
            }
            if skip_space && tok.kind == TokenKind::Space {
                skip_space = false;
                let next_removed = words
                    .get(wi)
                    .filter(|w| w.token == ti + 1)
                    .is_some_and(removed);
                if ti + 1 < line.tokens.len() && !next_removed {
                    self.out.push(' ');
                }
                continue;
            }
            skip_space = false;
            self.out.push_str(text.get(tok.span.clone()).unwrap_or(""));
        }
        if !inserted {
            self.out.push_str(first_text);
        }
        while self.out.len() > line_start && self.out.ends_with([' ', '\t']) {
            self.out.pop();
        }
        self.write_more_segments(line, words, segs, is_stop);
    }

    /// Segments after the first, each on its own line; the last keeps the line's terminator
    /// and gets the program stops.
    fn write_more_segments(
        &mut self,
        line: &Line,
        words: &[W],
        segs: &Segments,
        is_stop: impl Fn(&W) -> bool,
    ) {
        let text = self.text;
        let term = super::line_terminator(text, line);
        let term_last = line.terminator(text);
        let nseg = segs.spans.len();
        let eob = self.eob();
        for (k, span) in segs.spans.iter().enumerate() {
            if k > 0 {
                self.out.push_str(term);
                self.out.push_str(&segs.text[span.clone()]);
                if k + 1 == nseg {
                    for w in words.iter().filter(|w| is_stop(w)) {
                        self.out.push(' ');
                        self.out.push_str(self.wtext(w));
                    }
                }
                self.out.push_str(eob);
            }
        }
        self.out.push_str(term_last);
    }
}

/// A coordinate rounded to `d` decimals: its units of the last decimal when exact in an f64,
/// and the value the controller reads.
fn rounded(v: f64, d: usize) -> (Option<i64>, f64) {
    match decimal_units(v, d) {
        Some(u) => (Some(u), u as f64 / 10f64.powi(d as i32)),
        None => {
            let r = format_decimals_slow(v, d).parse().unwrap_or(v);
            (None, r)
        }
    }
}

/// Append the text of a rounded coordinate.
fn push_rounded(buf: &mut String, r: (Option<i64>, f64), d: usize) {
    match r.0 {
        Some(u) => push_units(buf, u, d),
        None => buf.push_str(&format_decimals_slow(r.1, d)),
    }
}
