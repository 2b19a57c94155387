//! Cuts under cutter radius compensation (G41/G42) with the map normal along the tool axis: only the tool-axis coordinate gets −E, every block errmap writes moves in the plane, arcs stay arcs about their centre, and start-up and cancel blocks stay single blocks.
//!
//! The control offsets the contour it reads in the plane; P − E changes no plane coordinate,
//! so the offset contour is the original's as long as lines are split into collinear pieces
//! and arcs into pieces about the same centre (tangent joints: no corner for the control to
//! go round). A block without motion in the plane is never written while compensation is
//! active: the step along the normal where a cut enters or leaves the zone is merged into the
//! next piece, and the return after a compensated cut rides on the next line's own move.

use super::super::arc::Arc;
use super::super::dialect::Motion;
use super::super::lexer::{Line, TokenKind};
use super::{lerp, MotionMode, Rewriter, AXES, W};
use crate::setting::Setting;
use errmap_core::error::{Error, Result};

/// How a cut relates to cutter radius compensation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum CompMode {
    /// Compensation is off: chords and steps as everywhere else.
    Off,
    /// In offset mode: pieces that all move in the plane, arcs as arcs.
    Contour,
    /// The block that starts up or cancels the offset (G41/G42/G40 on it or before it): one
    /// block, whatever its length.
    Transition,
}

impl<'a> Rewriter<'a> {
    /// Whether cutter radius compensation is on, or its start-up or cancel block is still to
    /// come.
    pub(super) fn comp_sensitive(&self) -> bool {
        self.cutter_comp.is_some() || self.comp_transition.is_some()
    }

    /// The active plane's tool axis is the map's normal (G17 with a Z map …).
    pub(super) fn tool_axis_is_normal(&self) -> bool {
        self.plane.axes().2 == self.m.normal
    }

    /// Whether a move goes anywhere in the active plane (an arc always does; an unknown
    /// coordinate may).
    pub(super) fn moves_in_plane(&self, start: &[Option<f64>; 3], end: &[Option<f64>; 3]) -> bool {
        let (a1, a2, _) = self.plane.axes();
        self.motion
            .is_some_and(|m| matches!(m.kind, Motion::ArcCw | Motion::ArcCcw))
            || [a1, a2].iter().any(|&i| match (start[i], end[i]) {
                (Some(s), Some(e)) => (s - e).abs() > 1e-12,
                _ => true,
            })
    }

    pub(super) fn comp_mode(&self, in_plane: bool) -> CompMode {
        match (
            self.comp_sensitive(),
            self.comp_transition.is_some() && in_plane,
        ) {
            (false, _) => CompMode::Off,
            (true, true) => CompMode::Transition,
            (true, false) => CompMode::Contour,
        }
    }

    /// Write a compensated cut under cutter radius compensation (`emitted` from the move's
    /// curve, its first point the start `s`).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn rewrite_contour(
        &mut self,
        line: &Line,
        words: &[W],
        emitted: &[([f64; 3], Option<f64>)],
        arc: Option<&Arc>,
        motion: MotionMode,
        s: [f64; 3],
        mode: CompMode,
    ) -> Result<()> {
        let (a1, a2, _) = self.plane.axes();
        let same_plane = |p: &[f64; 3], q: &[f64; 3]| {
            (p[a1] - q[a1]).abs() <= 1e-9 && (p[a2] - q[a2]).abs() <= 1e-9
        };
        let Some(&last) = emitted.last() else {
            return Ok(());
        };
        // The points written: each moves in the plane from the one before. A point that does
        // not (the second of a zone-edge pair, the start) is dropped, so its step along the
        // normal rides on the next piece; a move with no plane motion is one block.
        let mut pieces: Vec<([f64; 3], Option<f64>)> = Vec::new();
        let in_plane = emitted.iter().any(|(p, _)| !same_plane(p, &s));
        if !in_plane || mode == CompMode::Transition {
            if mode == CompMode::Transition {
                self.check_transition(line, emitted, arc, s)?;
            }
            pieces.push(last);
        } else {
            let mut prev = s;
            for &(p, e) in &emitted[1..] {
                if !same_plane(&p, &prev) {
                    pieces.push((p, e));
                    prev = p;
                }
            }
        }
        if let Some(a) = arc.filter(|_| in_plane && mode == CompMode::Contour) {
            pieces = self.m.helical_pieces(a, s, &pieces).ok_or_else(|| {
                self.err(
                    line,
                    "X",
                    format!("under cutter radius compensation this arc must stay arcs, and no helical piece short enough follows P − E within {} (the map bends too sharply along it)", errmap_core::setting::words(Setting::ChordTol)),
                    &format!("raise {}, or post the arc as the tool-centre path (G40)", errmap_core::setting::words(Setting::ChordTol)),
                )
            })?;
        }
        if pieces.len() > 1 {
            if let Some(w) = words.iter().find(|w| w.letter == b'D') {
                let t = self.wtext(w).to_string();
                return Err(self.err(
                    line,
                    &t,
                    format!("`{t}` changes the cutter offset on a move errmap must write as {} blocks under cutter radius compensation: the control would reach the new offset at the end of the first block, not of the move", pieces.len()),
                    &format!("give the D word on a block of its own before the contour, or raise {} so the move stays one block", errmap_core::setting::words(Setting::MaxSegment)),
                ));
            }
        }
        let mut segs = std::mem::take(&mut self.segments);
        segs.text.clear();
        segs.spans.clear();
        let last_e = self.count_compensated(&pieces);
        let mut out_pos = self.m.pos.map(|c| c.unwrap_or(0.0));
        out_pos[self.m.normal] += self.m.offset;
        let centre = arc.filter(|_| in_plane).map(|a| a.centre);
        for (p, e) in &pieces {
            let mut q = *p;
            if let Some(e) = e {
                q[self.m.normal] -= e;
            }
            self.contour_segment(q, centre, motion, in_plane, &mut out_pos, &mut segs);
        }
        self.write_move(line, words, arc.is_some(), &mut segs);
        // Where the output stands against the original's end: −E of the last piece, unless a
        // piece too short to move in the plane as written was left out.
        let end_n = pieces
            .last()
            .map_or(s[self.m.normal], |(p, _)| p[self.m.normal]);
        let written_off = out_pos[self.m.normal] - end_n;
        let half_digit = 0.5 * 10f64.powi(-(self.decimals() as i32));
        let e_last = last_e.unwrap_or(0.0);
        self.m.offset = if (written_off + e_last).abs() <= half_digit {
            -e_last
        } else {
            written_off
        };
        self.segments = segs;
        Ok(())
    }

    /// A start-up or cancel block stays one block: it must lie wholly in the zone and domain,
    /// be straight, and its tool-axis coordinate, linear along it from the start's P − E to the
    /// end's, must stay within `chord_tol` of P − E.
    fn check_transition(
        &self,
        line: &Line,
        emitted: &[([f64; 3], Option<f64>)],
        arc: Option<&Arc>,
        s: [f64; 3],
    ) -> Result<()> {
        let (cl, code) = self
            .comp_transition
            .clone()
            .unwrap_or((line.number, "G41".into()));
        let what = if code == "G40" {
            "cancels"
        } else {
            "starts up"
        };
        let refuse = |why: String| {
            Err(self.err(
                line,
                if line.number == cl { &code } else { "X" },
                format!("this move {what} cutter radius compensation ({code}, line {cl}), so errmap must keep it one block, but {why}"),
                "start up and cancel compensation outside the zone (or where the map is flat along the move), or move the zone away",
            ))
        };
        if arc.is_some() {
            return refuse("it is an arc".into());
        }
        if emitted.iter().any(|(_, e)| e.is_none()) {
            return refuse("it crosses the edge of the zone or of the measured domain".into());
        }
        let Some(&(end, Some(e_end))) = emitted.last() else {
            return Ok(());
        };
        let n = self.m.normal;
        // A step at the start (the output stood nominal) rides on the block as on any first
        // piece; what is checked is that E is linear enough along it.
        let Some(e_start) = emitted.first().and_then(|(_, e)| *e) else {
            return Ok(());
        };
        let from = s[n] - e_start;
        let to = end[n] - e_end;
        let tol = self.m.settings.chord_tol_in(self.m.inches);
        for k in 0..=8 {
            let f = f64::from(k) / 8.0;
            let p = lerp(&s, &end, f);
            let Some(e) = self.m.error_at(&p) else {
                return refuse("it leaves the zone or the measured domain".into());
            };
            let dev = (from + f * (to - from)) - (p[n] - e);
            if dev.abs() > tol {
                return refuse(format!(
                    "as one block it strays {:.4} from P − E (more than {})",
                    dev.abs(),
                    errmap_core::setting::words(Setting::ChordTol)
                ));
            }
        }
        Ok(())
    }

    /// The text to append to an unchanged move under cutter radius compensation that carries
    /// the return along the normal (` Z…`, in the line's own modes), instead of a block of its
    /// own; `None` when no return is due or the line cannot carry it (then `return_if_needed`
    /// refuses).
    pub(super) fn fold_return(&mut self, line: &Line, words: &[W]) -> Option<String> {
        if self.m.offset == 0.0 || !self.comp_sensitive() {
            return None;
        }
        let n = AXES[self.m.normal];
        let (a1, a2, _) = self.plane.axes();
        let plane_word = words
            .iter()
            .any(|w| w.letter == AXES[a1] || w.letter == AXES[a2]);
        let plain_motion = self.motion.is_some_and(|m| {
            matches!(
                m.kind,
                Motion::Rapid | Motion::Linear | Motion::ArcCw | Motion::ArcCcw
            )
        });
        let blocked = words.iter().any(|w| w.letter == n || w.is_expr)
            || !plane_word
            || !plain_motion
            || block_delete(self.text, line);
        if blocked {
            return None;
        }
        let value = if self.absolute {
            self.m.pos[self.m.normal]?
        } else {
            -self.m.offset
        };
        let mut text = format!(" {}", n as char);
        self.push_coord(&mut text, value);
        self.m.offset = 0.0;
        self.standing.offset = 0.0;
        self.report.returns_inserted += 1;
        Some(text)
    }

    /// The refusal of a return step that would be a block without motion in the plane while
    /// cutter radius compensation is on.
    pub(super) fn comp_return_error(&self, line: &Line) -> Error {
        let (cl, code) = self
            .cutter_comp
            .clone()
            .or_else(|| self.comp_transition.clone())
            .unwrap_or((0, "G41".into()));
        let n = AXES[self.m.normal] as char;
        let at = self
            .text
            .get(line.span.clone())
            .unwrap_or("")
            .trim()
            .chars()
            .next()
            .map(String::from)
            .unwrap_or_default();
        self.err(
            line,
            &at,
            format!("a compensated cut under cutter radius compensation {code} (line {cl}) ends {n} −E away from the program, and this line cannot carry the return along {n}: errmap would have to insert a block without motion in the compensation plane, which the control's compensation does not look past (it may gouge the contour or alarm)"),
            &format!("give this line an absolute {n}, or a move in the plane, or end the contour above the zone before it"),
        )
    }
}

/// `/` at the start of a line: the control may skip it.
pub(super) fn block_delete(text: &str, line: &Line) -> bool {
    line.tokens
        .iter()
        .find(|t| t.kind != TokenKind::Space)
        .is_some_and(|t| t.kind == TokenKind::Other && text.get(t.span.clone()) == Some("/"))
}
