//! The Klartext interpreter: each block's meaning applied to the state (position, circle centre, tool axis, radius compensation, datum shift, transformation cycles, labels), and the refusals of what errmap does not follow in the zone.

use super::super::arc::{Arc, Plane};
use super::super::dialect::Motion;
use super::super::TracedMove;
use super::block::{Block, Value};
use super::Comp;
use super::{Frame, Kt, Point};
use crate::setting::Setting;
use errmap_core::error::Result;
use errmap_core::setting::words;
use std::borrow::Cow;

const AXES: [&str; 3] = ["X", "Y", "Z"];

/// M functions that act at the start of their block (TNC manual, "Overview of miscellaneous
/// functions"): kept on the first piece of a split cut.
const M_START: [f64; 6] = [3.0, 4.0, 7.0, 8.0, 13.0, 14.0];
/// M functions that act at the end of their block: moved to the last piece.
const M_END: [f64; 7] = [0.0, 1.0, 2.0, 5.0, 6.0, 9.0, 30.0];

/// Why a block cannot be compensated when it may touch the zone: column, word, message, hint.
pub(super) type Refusal = (usize, String, String, Cow<'static, str>);

/// A path block (`L`, `C`, `CR`, `CT`) read against the state.
pub(super) struct PathMove {
    pub start: Point,
    pub end: Point,
    pub arc: Option<Arc>,
    pub cutting: bool,
    /// The reason it cannot be compensated in the zone, if any.
    pub refusal: Option<Refusal>,
}

impl Kt<'_> {
    /// One line: dispatch on its function.
    pub(super) fn line(&mut self, n: u64, content: &str, term: &str, b: &Block) -> Result<()> {
        if b.skip {
            return self.skipped_block(n, content, term, b);
        }
        match b.head.as_str() {
            "" | ";" | "*" | "BEGIN" | "END" | "BLK" | "FPOL" | "FSELECT" | "SEL" => {
                self.copy(content, term, b);
                Ok(())
            }
            "L" | "C" | "CR" | "CT" | "LP" | "CP" => self.path(n, content, term, b),
            "CC" => self.circle_centre(n, content, term, b),
            "RND" | "CHF" => self.corner_block(n, content, term, b),
            "FL" | "FLT" | "FC" | "FCT" | "APPR" | "DEP" => {
                self.unfollowed_contour(n, content, term, b)
            }
            "LBL" => self.label_block(n, content, term, b),
            "CALL" => self.call_block(n, content, term, b),
            "CYCL" => self.cycle_block(n, content, term, b),
            "TOOL" => self.tool_block(n, content, term, b),
            "STOP" => self.unchanged(n, content, term, b, false),
            "FN" if !b.rest.trim_start().starts_with("17") => {
                self.copy(content, term, b);
                Ok(())
            }
            h if is_m_block(h) => {
                self.unchanged(n, content, term, b, false)?;
                self.after_path_m(n, b)
            }
            h if h.starts_with('Q') => {
                self.copy(content, term, b);
                Ok(())
            }
            _ => {
                let what = format!("{} {}", b.head, b.rest).trim().to_string();
                let up = what.to_ascii_uppercase();
                // PLANE RESET STAY with no tilt active resets nothing and moves no axis.
                let words: Vec<&str> = up.split_whitespace().collect();
                if words.starts_with(&["PLANE", "RESET", "STAY"])
                    && words.len() == 3
                    && !self
                        .frames
                        .iter()
                        .any(|f| f.cycle == "5x" || f.cycle == "19")
                {
                    return self.unchanged(n, content, term, b, false);
                }
                let kind = if up.starts_with("PLANE") || up.contains("TCPM") {
                    "5x"
                } else if up.starts_with("TCH PROBE") {
                    "probe"
                } else {
                    "?"
                };
                self.frames.push(Frame {
                    cycle: kind.into(),
                    line: n,
                    what,
                    normal: true,
                });
                self.m.lose_position(n, &[0, 1, 2]);
                self.unchanged(n, content, term, b, false)
            }
        }
    }

    /// Copy a block that changes nothing errmap compensates, after a return along the normal
    /// when the last cut ended compensated (unless the block itself moves the normal axis to
    /// an absolute coordinate).
    pub(super) fn unchanged(
        &mut self,
        _n: u64,
        content: &str,
        term: &str,
        b: &Block,
        absolute_normal: bool,
    ) -> Result<()> {
        if self.m.offset != 0.0 && !absolute_normal && self.comp_word().is_some() {
            // Under RL/RR the return rides on the next move in the plane (or is refused).
            let folded = self.fold_return(_n, content, b)?;
            self.copy(folded.as_deref().unwrap_or(content), term, b);
            return Ok(());
        }
        if self.m.offset != 0.0 && !absolute_normal {
            // Before a rapid the return is a rapid too (the original's rapid starts there).
            self.return_step(term, b.head == "L" && b.has("FMAX"));
        }
        self.m.offset = if absolute_normal { 0.0 } else { self.m.offset };
        self.copy(content, term, b);
        Ok(())
    }

    /// The working plane of the tool axis (TOOL CALL … Z: XY).
    pub(super) fn plane(&self) -> Plane {
        match self.tool_axis {
            0 => Plane::G19,
            1 => Plane::G18,
            _ => Plane::G17,
        }
    }

    /// End point of a block's coordinate words from `start` (`X` absolute, `IX` incremental;
    /// a Q parameter gives an unknown value).
    fn end_point(&self, b: &Block, start: Point) -> Point {
        let mut end = start;
        for (i, a) in AXES.iter().enumerate() {
            if let Some(w) = b.word(a) {
                end[i] = w.num();
            } else if let Some(w) = b.word(&format!("I{a}")) {
                end[i] = start[i].zip(w.num()).map(|(s, d)| s + d);
            }
        }
        end
    }

    /// Radius compensation words of a path block: `R0` ends it, `RL`/`RR` start it.
    fn radius_words(&mut self, n: u64, b: &Block, radius_is_r: bool) {
        self.radius_comp = self.radius_after(n, b, radius_is_r);
    }

    /// The radius compensation in force after a block's `R0`/`RL`/`RR` word.
    fn radius_after(&self, n: u64, b: &Block, radius_is_r: bool) -> Option<(u64, String)> {
        if b.has("RL") || b.has("RR") {
            let w = if b.has("RL") { "RL" } else { "RR" };
            Some((n, w.to_string()))
        } else if !radius_is_r && b.word("R").and_then(|w| w.num()) == Some(0.0) {
            None
        } else {
            self.radius_comp.clone()
        }
    }

    /// A straight line or a circle: followed, compensated in the zone, or refused there.
    fn path(&mut self, n: u64, content: &str, term: &str, b: &Block) -> Result<()> {
        self.check_path_words(n, b)?;
        // The compensation before the block stays in force while it is written (a return
        // along the normal due before it rides on it), the block's own from its end.
        let comp_after = self.radius_after(n, b, b.head == "CR");
        let comp = self.comp_mode(&comp_after);
        let coordinates = has_coordinates(b);
        if b.head == "L" && !coordinates {
            // `L R0 F200 M3`: no motion.
            self.unchanged(n, content, term, b, false)?;
            self.radius_comp = comp_after;
            return self.after_path_m(n, b);
        }
        let mut mv = self.path_move(n, b)?;
        if mv.refusal.is_none() {
            mv.refusal = self.comp_refusal(b, &comp_after, comp);
        }
        let touch = self.may_touch(&self.touch_points(&mv));
        if let Some((l, col, word)) = self.corner.take() {
            if touch {
                return Err(self.err(
                    l,
                    col,
                    &word,
                    format!("`{word}` rounds or chamfers the corner before a contour element ({}) that may lie in the compensation zone: errmap does not follow RND and CHF there", self.at(n)),
                    CORNER_HINT,
                ));
            }
        }
        if b.head == "CT" && self.prev_touch {
            return Err(self.err(
                n,
                b.head_col,
                "CT",
                "tangential arc CT after a contour element that may lie in the compensation zone: its arc follows that element's direction, which compensation changes".into(),
                CT_HINT,
            ));
        }
        self.prev_touch = touch;
        self.cut_seen |= mv.cutting && touch;
        if mv.cutting && (touch || !self.m.units_known) {
            if let Some((col, word, msg, hint)) = mv.refusal.clone() {
                return Err(self.err(n, col, &word, msg, &hint));
            }
        }
        if self.trace.is_some() {
            self.trace_move(b, &mv);
        }
        let absolute_normal = b.head == "L"
            && b.word(AXES[self.m.normal])
                .is_some_and(|w| w.num().is_some())
            && self.frames.is_empty()
            && !b
                .words
                .iter()
                .any(|w| w.addr == "M" && matches!(w.num(), Some(91.0 | 92.0)));
        if mv.cutting && touch && mv.refusal.is_none() && comp != Comp::Off {
            self.compensate_contour(n, content, term, b, &mv, comp)?;
        } else if mv.cutting && touch && mv.refusal.is_none() {
            self.compensate_path(n, content, term, b, &mv)?;
        } else {
            self.unchanged(n, content, term, b, absolute_normal)?;
        }
        self.radius_comp = comp_after;
        let lost: Vec<usize> = (0..3)
            .filter(|&i| mv.end[i].is_none() && self.m.pos[i].is_some())
            .collect();
        if !lost.is_empty() {
            self.m.lose_position(n, &lost);
        }
        self.m.pos = mv.end;
        self.after_path_m(n, b)
    }

    /// Words a path block may hold; anything else is an error (strict blocks).
    fn check_path_words(&self, n: u64, b: &Block) -> Result<()> {
        const COMMON: [&str; 31] = [
            "X", "Y", "Z", "IX", "IY", "IZ", "A", "B", "C", "IA", "IB", "IC", "U", "V", "W", "R",
            "RL", "RR", "F", "FMAX", "FAUTO", "FU", "FZ", "AUTO", "M", "DR", "MB", "PA", "IPA",
            "PR", "IPR",
        ];
        for w in &b.words {
            let ok = COMMON.contains(&w.addr.as_str())
                && (w.addr != "DR" || matches!(b.head.as_str(), "C" | "CR" | "CP"))
                && (!matches!(w.addr.as_str(), "PA" | "IPA")
                    || matches!(b.head.as_str(), "LP" | "CP"))
                && (!matches!(w.addr.as_str(), "PR" | "IPR") || b.head == "LP")
                && (w.addr != "MB"
                    || b.words
                        .iter()
                        .any(|m| m.addr == "M" && m.num() == Some(140.0)));
            let value_ok = match w.addr.as_str() {
                "RL" | "RR" | "FMAX" | "FAUTO" | "AUTO" => w.value == Value::None,
                "MB" => matches!(w.value, Value::None | Value::Num(_)),
                "DR" => matches!(w.value, Value::Sign(_)),
                _ => matches!(w.value, Value::Num(_) | Value::Param),
            };
            let axis = matches!(
                w.addr.trim_start_matches('I'),
                "X" | "Y" | "Z" | "A" | "B" | "C" | "U" | "V" | "W"
            );
            if ok && axis && w.value == Value::None {
                return Err(self.err(
                    n,
                    w.col,
                    &w.text,
                    format!("axis word `{}` without a value right after it (a TNC block writes `{}+25`, not `{} 25`)", w.text, w.addr, w.addr),
                    "join the value to its axis letter (e.g. `L Z+25.000 FMAX`), as the TNC writes it",
                ));
            }
            if !ok || !value_ok {
                return Err(self.err(
                    n,
                    w.col,
                    &w.text,
                    format!("`{}` is not a word of a Klartext {} block errmap knows", w.text, b.head),
                    "write the block as the TNC does (e.g. `L X+10 Y-5 R0 F200 M3`, `C X+0 Y+25 DR+`, `CR X+0 Y+25 R+20 DR-`)",
                ));
            }
            let a = w.addr.strip_prefix('I').unwrap_or(&w.addr);
            if w.addr.starts_with('I') && b.has(a) {
                return Err(self.err(
                    n,
                    w.col,
                    &w.text,
                    format!("both {a} and {} in one block", w.addr),
                    "give the coordinate once, absolute or incremental",
                ));
            }
        }
        Ok(())
    }

    /// Start, end, arc and what forbids compensating a path block.
    fn path_move(&self, n: u64, b: &Block) -> Result<PathMove> {
        let start = self.m.pos;
        let mut end = self.end_point(b, start);
        let machine = b
            .words
            .iter()
            .find(|w| w.addr == "M" && matches!(w.num(), Some(91.0 | 92.0)));
        if machine.is_some() {
            for (i, a) in AXES.iter().enumerate() {
                if b.has(a) || b.has(&format!("I{a}")) {
                    end[i] = None;
                }
            }
        }
        // An M91/M92 block ends at machine coordinates, outside the map's frame: errmap never
        // compensates it (it is copied) and treats it as leaving the zone.
        let cutting = !b.has("FMAX") && machine.is_none();
        let (arc, arc_refusal) = match b.head.as_str() {
            "C" | "CR" => self.arc(n, b, start, end)?,
            "LP" | "CP" => {
                let (e, arc, refusal) = self.polar_move(n, b, start)?;
                end = e;
                (arc, refusal)
            }
            _ => (None, None),
        };
        let refusal = self
            .context_refusal(b)
            .or(arc_refusal)
            .or_else(|| self.word_refusal(b, &start));
        Ok(PathMove {
            start,
            end,
            arc,
            cutting,
            refusal,
        })
    }

    /// The points a move may reach: its ends, and its arc sampled within the chord tolerance.
    fn touch_points(&self, mv: &PathMove) -> Vec<Point> {
        let mut pts = vec![mv.start, mv.end];
        if let Some(a) = &mv.arc {
            let k = a.chords(self.m.chord_tol(), self.m.step()).min(100_000);
            pts = (0..=k)
                .map(|i| a.point(i as f64 / k as f64).map(Some))
                .collect();
        }
        pts
    }

    /// The arc of a C or CR block, or why it cannot be followed in the zone.
    fn arc(&self, n: u64, b: &Block, s: Point, e: Point) -> Result<(Option<Arc>, Option<Refusal>)> {
        let at = |w: &str| b.word(w).map_or(b.head_col, |w| w.col);
        let Some(dr) = b.word("DR").and_then(|w| match w.value {
            Value::Sign(ccw) => Some(ccw),
            _ => None,
        }) else {
            return Err(self.err(
                n,
                b.head_col,
                &b.head,
                format!(
                    "{} block without a direction of rotation DR+ or DR-",
                    b.head
                ),
                "add DR+ (counterclockwise) or DR- (clockwise)",
            ));
        };
        let plane = if b.head == "C" {
            self.circle_plane()
        } else {
            self.plane()
        };
        let (a1, a2, ax) = plane.axes();
        if self.tool_axis != 2 {
            return Ok((None, Some((
                b.head_col,
                b.head.clone(),
                format!("a circle in the plane of tool axis {} (TOOL CALL): errmap follows circles in the XY plane (tool axis Z) only", AXES[self.tool_axis]),
                "post the arc as L moves for this zone, or move the zone away".into(),
            ))));
        }
        let axis_word = b.has(AXES[ax]) || b.has(&format!("I{}", AXES[ax]));
        if axis_word && e[ax] != s[ax] {
            return Ok((None, Some((
                at(AXES[ax]),
                format!("{} … {}", b.head, AXES[ax]),
                format!("{} with a tool-axis coordinate (a helix) in the compensation zone: errmap does not follow it", b.head),
                "post helices as L moves for this zone, or move the zone away".into(),
            ))));
        }
        let (Some(s), Some(e)) = (known(s), known(e)) else {
            return Ok((None, None));
        };
        let result = if b.head == "C" {
            let (Some(c1), Some(c2)) = (self.centre[a1], self.centre[a2]) else {
                return Ok((None, Some((
                    b.head_col,
                    "C".into(),
                    "circle C with an unknown circle centre CC (none since the program start, a label or a block errmap does not follow)".into(),
                    "program CC X… Y… before the circle".into(),
                ))));
            };
            return self
                .circle_c(n, b, plane, s, e, (c1, c2), !dr)
                .map(|a| (Some(a), None));
        } else {
            let Some(r) = b.word("R").and_then(|w| w.num()).filter(|r| *r != 0.0) else {
                return Err(self.err(
                    n,
                    at("R"),
                    "CR",
                    "CR block without a radius R+… or R-…".into(),
                    "give the radius: R+ for an arc up to 180°, R- for a larger one",
                ));
            };
            Arc::from_radius(plane, s, e, r, !dr, 1)
        };
        result.map(|a| (Some(a), None)).map_err(|m| {
            self.err(
                n,
                b.head_col,
                &b.head,
                m,
                "fix the arc's end point, centre CC or radius",
            )
        })
    }

    /// The arc of a C block. Its end may lie off the circle through the start by up to the
    /// TNC's input tolerance (0.016 mm, TNC 410 manual "Circular path C around circle centre
    /// CC"): the radius then changes linearly from start to end, as the TNC's own correction
    /// is not documented; beyond it the TNC refuses the block, and so does errmap.
    #[allow(clippy::too_many_arguments)]
    fn circle_c(
        &self,
        n: u64,
        b: &Block,
        plane: Plane,
        s: [f64; 3],
        e: [f64; 3],
        centre: (f64, f64),
        clockwise: bool,
    ) -> Result<Arc> {
        let (a1, a2, _) = plane.axes();
        let r_start = (s[a1] - centre.0).hypot(s[a2] - centre.1);
        let r_end = (e[a1] - centre.0).hypot(e[a2] - centre.1);
        let tol = C_END_TOLERANCE_MM / self.m.scale_mm();
        let bad = |m: String| {
            self.err(
                n,
                b.head_col,
                "C",
                m,
                "fix the arc's end point or its centre CC",
            )
        };
        if r_start < 1e-9 || r_end < 1e-9 {
            return Err(bad(
                "circle C whose start or end point is its centre CC".into()
            ));
        }
        if (r_start - r_end).abs() > tol {
            return Err(bad(format!(
                "the end point of C is not on the circle about CC: radius {r_start:.4} at the start, {r_end:.4} at the end ({:.4} apart; the TNC accepts at most {C_END_TOLERANCE_MM} mm)",
                (r_start - r_end).abs()
            )));
        }
        // The arc is built to the end point moved onto the start circle (same angle), then ends
        // at the programmed point with its own radius.
        let mut on = e;
        on[a1] = centre.0 + (e[a1] - centre.0) * r_start / r_end;
        on[a2] = centre.1 + (e[a2] - centre.1) * r_start / r_end;
        let mut arc = Arc::from_centre(plane, s, on, centre, clockwise, 1).map_err(bad)?;
        arc.end = e;
        arc.r_end = r_end;
        Ok(arc)
    }

    /// The program's state forbids compensating a cut here.
    fn context_refusal(&self, b: &Block) -> Option<Refusal> {
        let col = b.head_col;
        if !self.m.units_known {
            return Some((col, b.head.clone(), "cut with no unit in a BEGIN PGM block before it: errmap cannot tell millimetres from inches (a 25.4× error)".into(), format!("begin the program with `0 BEGIN PGM name MM` (or INCH), or pass {} mm|inch", words(Setting::Units)).into()));
        }
        if let Some((l, w)) = &self.label {
            return Some((col, w.clone(), format!("cut inside the label `{w}` ({}), which runs once per call or jump, from positions and datums errmap cannot see, and may lie in the compensation zone", self.at(*l)), "expand CALL LBL calls and repeats into plain blocks (or move the zone away)".into()));
        }
        if let Some(f) = self.frames.last() {
            let at = self.at(f.line);
            let (msg, hint) = match f.cycle.as_str() {
                "?" => (format!("`{}` ({at}) is a function errmap does not follow (it may move or transform the coordinates), and this cut may lie in the compensation zone", f.what), "post the cuts in the zone without it, or move the zone away".into()),
                "5x" => (format!("`{}` ({at}) tilts the working plane or moves the tool tip with the rotary axes (5-axis), which errmap does not follow, and this cut may lie in the compensation zone", f.what), "errmap compensates 3-axis cuts in an untilted working plane: post the cuts in the zone without PLANE/cycle 19/M128/TCPM, or move the zone away".into()),
                "rot" => (format!("rotary axis {} ({at}) stands away from 0, where errmap takes the map to be measured: the part is turned, and this cut may lie in the compensation zone", f.what), "compensate the cuts of each rotary position with a map measured there, bring the axis back to 0 before the cuts in the zone, or move the zone away".into()),
                "pgm" => (format!("`{}` ({at}) runs another program, which errmap cannot see (it may move the datum or the tool), and this cut may lie in the compensation zone", f.what), "paste the called program's blocks into this one, or move the zone away".into()),
                "247" => (format!("`{}` ({at}): errmap applies the map in the coordinates of the first preset the program selects, and this cut may lie in the compensation zone", f.what), if self.m.settings.same_part_per_offset || f.what.contains("cannot read") {
                    "select the program's first preset again (CYCL DEF 247 with its Q339 as a number) before the cuts in the zone, or compensate this part with a map measured in this preset".into()
                } else {
                    format!("select the program's first preset again (CYCL DEF 247 with its Q339) before the cuts in the zone; for identical parts, one per preset, pass {} to apply the map in each preset's coordinates", words(Setting::SamePartPerOffset)).into()
                }),
                "param" => (format!("`{}` ({at}) shifts the datum by a Q parameter, whose value errmap does not know (read at run time, e.g. by FN18 SYSREAD, or computed), and this cut may lie in the compensation zone", f.what), "shift the datum by numbers (CYCL DEF 7.1 Z+…) for the cuts in the zone, or move the zone away".into()),
                "probe" => (format!("`{}` ({at}) probes the workpiece and may set the datum or Q parameters from what it measures, which errmap cannot know, and this cut may lie in the compensation zone", f.what), "set the datum with the probe in a separate program before this one, or move the zone away".into()),
                _ => (format!("`{}` ({at}) transforms the coordinates (cycle {}), which errmap does not follow, and this cut may lie in the compensation zone", f.what, f.cycle), "reset the cycle before the cuts in the zone (8.1 with no axes, 10.1 ROT+0, 11.1 SCL 1, 26.1 with factors 1, 19.1 with angles 0), or post the program without it".into()),
            };
            return Some((col, f.what.clone(), msg, hint));
        }
        if b.head == "CT" {
            return Some((col, "CT".into(), "tangential arc CT in the compensation zone: its arc follows the direction of the element before it, which compensation changes".into(), CT_HINT.into()));
        }
        None
    }

    /// A word of the block forbids compensating, or the start point is unknown.
    fn word_refusal(&self, b: &Block, start: &Point) -> Option<Refusal> {
        // A feed from a parameter (`F Q5`) does not move the path.
        if let Some(w) = b
            .words
            .iter()
            .find(|w| w.value == Value::Param && w.addr != "F")
        {
            let q = w
                .text
                .get(w.addr.len()..)
                .unwrap_or("")
                .trim_start_matches(['+', '-']);
            return Some((
                w.col,
                w.text.clone(),
                format!("`{}` takes its value from the Q parameter {q} on a cut in the compensation zone: errmap does not compute Q parameters", w.text),
                "post the program with numbers instead of Q parameters (or move the zone away)".into(),
            ));
        }
        if let Some(w) = b.words.iter().find(|w| {
            matches!(
                w.addr.as_str(),
                "A" | "B" | "C" | "IA" | "IB" | "IC" | "U" | "V" | "W"
            )
        }) {
            return Some((
                w.col,
                w.text.clone(),
                format!(
                    "{}axis {} moves together with a cut in the compensation zone",
                    if matches!(w.addr.trim_start_matches('I'), "A" | "B" | "C") {
                        "rotary "
                    } else {
                        ""
                    },
                    w.addr.trim_start_matches('I')
                ),
                "errmap compensates 3-axis X/Y/Z moves only; move the zone away from this move"
                    .into(),
            ));
        }
        if let Some(w) = b.words.iter().find(|w| {
            w.addr == "M"
                && !w
                    .num()
                    .is_some_and(|m| M_START.contains(&m) || M_END.contains(&m))
        }) {
            return Some((w.col, w.text.clone(), format!("{} on a cut in the compensation zone: errmap does not follow this miscellaneous function on a cut it rewrites", w.text), "put the M function in a block of its own outside the zone (M91/M92 cuts: program them in workpiece coordinates)".into()));
        }
        if start.iter().any(Option::is_none) {
            let since = self
                .m
                .unknown_since
                .map(|l| format!(" since {}", self.at(l)))
                .unwrap_or_else(|| " (no X, Y and Z since the program start)".into());
            return Some((b.head_col, b.head.clone(), format!("the start point of this cut is unknown{since}, so errmap cannot tell whether it lies in the compensation zone"), "give absolute X, Y and Z (e.g. L X… Y… Z… R0 FMAX) before the cut".into()));
        }
        None
    }

    /// Record a move whose start and end are known, in mm and work coordinates.
    fn trace_move(&mut self, b: &Block, mv: &PathMove) {
        let (Some(s), Some(e)) = (known(mv.start), known(mv.end)) else {
            return;
        };
        let k = self.m.scale_mm();
        let shift = self.m.shift;
        let mm = |p: [f64; 3]| [0, 1, 2].map(|i| (p[i] + shift[i]) * k);
        let kind = match (&mv.arc, mv.cutting) {
            (Some(a), _) if a.sweep < 0.0 => Motion::ArcCw,
            (Some(_), _) => Motion::ArcCcw,
            (None, false) => Motion::Rapid,
            (None, true) => Motion::Linear,
        };
        if !matches!(b.head.as_str(), "L" | "LP") && mv.arc.is_none() {
            return;
        }
        let arc_mm = mv.arc.as_ref().map(|a| {
            let (a1, a2, _) = a.plane.axes();
            Arc {
                start: mm(a.start),
                end: mm(a.end),
                centre: ((a.centre.0 + shift[a1]) * k, (a.centre.1 + shift[a2]) * k),
                r_start: a.r_start * k,
                r_end: a.r_end * k,
                ..a.clone()
            }
        });
        let line = self.report.lines_in;
        if let Some(t) = self.trace.as_mut() {
            t.push(TracedMove {
                line,
                kind,
                start_mm: mm(s),
                end_mm: mm(e),
                arc_mm,
            });
        }
    }

    /// M99/M89 on a path block call the cycle defined last at the end point; M140 retracts
    /// along the tool axis (`MB MAX`: to the end of the traverse range), so the tool-axis
    /// coordinate is unknown after it, until an absolute one.
    fn after_path_m(&mut self, n: u64, b: &Block) -> Result<()> {
        // M128 (TCPM), M114 and M144 make X/Y/Z depend on the rotary axes until M129, M115
        // and M145: cuts in the zone are refused while one is active.
        for w in b.words.iter().filter(|w| w.addr == "M") {
            match w.num() {
                Some(m @ (114.0 | 128.0 | 144.0)) => self.frames.push(Frame {
                    cycle: "5x".into(),
                    line: n,
                    what: format!("M{m}"),
                    normal: true,
                }),
                Some(m @ (115.0 | 129.0 | 145.0)) => {
                    let on = format!("M{}", m - 1.0);
                    self.frames.retain(|f| f.what != on);
                }
                _ => {}
            }
        }
        if b.words
            .iter()
            .any(|w| w.addr == "M" && w.num() == Some(140.0))
        {
            self.m.lose_position(n, &[self.tool_axis]);
        }
        self.rotary_positions(n, b);
        if let Some(w) = b
            .words
            .iter()
            .find(|w| w.addr == "M" && matches!(w.num(), Some(99.0 | 89.0)))
        {
            let (col, text) = (w.col, w.text.clone());
            // M89 calls the cycle after every positioning block from here on; errmap does
            // not end it (each later position is judged as a call).
            self.modal_call |= w.num() == Some(89.0);
            self.cycle_call(n, col, &text)?;
        } else if self.modal_call && b.head == "L" && has_coordinates(b) {
            self.cycle_call(n, b.head_col, "M89 (modal cycle call)")?;
        }
        Ok(())
    }

    /// Rotary axes: the map is taken as measured with every rotary axis at 0, so one standing
    /// elsewhere (or moved incrementally, to where errmap cannot tell) is a frame under which
    /// cuts in the zone are refused, until it is back at 0.
    fn rotary_positions(&mut self, n: u64, b: &Block) {
        for w in b
            .words
            .iter()
            .filter(|w| matches!(w.addr.as_str(), "A" | "B" | "C" | "IA" | "IB" | "IC"))
        {
            let axis = w.addr.trim_start_matches('I').to_string();
            self.frames
                .retain(|f| !(f.cycle == "rot" && f.what.starts_with(axis.as_str())));
            let at_zero = w.addr.len() == 1 && w.num() == Some(0.0);
            if !at_zero {
                self.frames.push(Frame {
                    cycle: "rot".into(),
                    line: n,
                    what: format!("{axis}{}", w.text.trim_start_matches(['I', 'A', 'B', 'C'])),
                    normal: true,
                });
            }
        }
    }

    /// A machining cycle runs at the current position: refused if it may touch the zone; it
    /// leaves the tool-axis coordinate unknown.
    pub(super) fn cycle_call(&mut self, n: u64, col: usize, word: &str) -> Result<()> {
        if let Some(back) = self.hole_call(n, col, word)? {
            if !back {
                self.m.lose_position(n, &[self.tool_axis, self.m.normal]);
            }
            return Ok(());
        }
        let mut p = self.m.pos;
        p[self.tool_axis] = None;
        p[self.m.normal] = None;
        if self.may_touch(&[self.m.pos, p]) {
            let cycle = match self.machining_cycle {
                Some((c, l)) if c >= 0 => format!(" of cycle {c} ({})", self.at(l)),
                _ => String::new(),
            };
            // A drilling cycle errmap follows is refused here only under a frame or function
            // it does not follow: name that, the real cause.
            if let (Some(_), Some(f)) = (&self.hole_cycle, self.frames.last()) {
                let what = if f.cycle == "?" {
                    "is a function errmap does not follow (it may move or transform the coordinates)"
                } else {
                    "transforms the coordinates, which errmap does not follow"
                };
                return Err(self.err(
                    n,
                    col,
                    word,
                    format!("`{}` ({}) {what}, and the call `{word}`{cycle} after it may drill in the compensation zone", f.what, self.at(f.line)),
                    "post the program without that block before the holes in the zone (or move the zone away)",
                ));
            }
            return Err(self.err(
                n,
                col,
                word,
                format!("cycle call `{word}`{cycle} in the compensation zone: errmap does not follow machining cycles"),
                "expand the cycle into L moves with your CAM post (or move the zone away)",
            ));
        }
        self.m.lose_position(n, &[self.tool_axis, self.m.normal]);
        Ok(())
    }

    /// `CC X… Y…` (absolute), `CC IX… IY…` (from the last position), `CC` (the last position).
    fn circle_centre(&mut self, n: u64, content: &str, term: &str, b: &Block) -> Result<()> {
        let mut axes: Vec<usize> = Vec::new();
        for w in &b.words {
            let axis = AXES
                .iter()
                .position(|a| w.addr.trim_start_matches('I') == *a && w.addr.len() <= 2);
            match axis {
                Some(i) if w.value != Value::None && !axes.contains(&i) => axes.push(i),
                _ => {
                    return Err(self.err(
                        n,
                        w.col,
                        &w.text,
                        format!("`{}` is not a coordinate of a plane for CC", w.text),
                        "write CC with two coordinates of a plane, e.g. CC X+25 Y+25 (or CC X… Z… for a circle in the ZX plane)",
                    ))
                }
            }
        }
        if b.words.is_empty() {
            self.centre = self.m.pos;
            self.cc_plane = None;
        } else {
            // The CC's two axes give the plane of the circles about it (ZX: 0° along +Z,
            // positive towards +X; YZ: 0° along +Y, positive towards +Z).
            let plane = match (axes.contains(&0), axes.contains(&1), axes.contains(&2)) {
                (true, true, false) => Some(Plane::G17),
                (true, false, true) => Some(Plane::G18),
                (false, true, true) => Some(Plane::G19),
                _ => None,
            };
            self.cc_plane = plane;
            let c = self.end_point(b, self.m.pos);
            let (a1, a2, _) = self.circle_plane().axes();
            let given = |i: usize| b.has(AXES[i]) || b.has(&format!("I{}", AXES[i]));
            for i in [a1, a2] {
                self.centre[i] = if given(i) { c[i] } else { None };
            }
        }
        // A bare or incremental CC depends on the last position: the output's must be the
        // original's. An absolute one does not.
        if !b.words.is_empty() && b.words.iter().all(|w| !w.addr.starts_with('I')) {
            self.copy(content, term, b);
            return Ok(());
        }
        self.unchanged(n, content, term, b, false)
    }

    /// `RND R…` or `CHF …`: refused when the element before it may lie in the zone; the element
    /// after it is checked when it comes.
    fn corner_block(&mut self, n: u64, content: &str, term: &str, b: &Block) -> Result<()> {
        let word = format!("{} {}", b.head, b.rest).trim().to_string();
        if self.prev_touch {
            return Err(self.err(n, b.head_col, &word, format!("`{word}` rounds or chamfers the corner after a contour element that may lie in the compensation zone: errmap does not follow RND and CHF there"), CORNER_HINT));
        }
        self.corner = Some((n, b.head_col, word));
        self.unchanged(n, content, term, b, false)
    }

    /// A block with the block skip `/`: it runs or not by the operator's switch. One that
    /// changes no position or mode errmap follows is read as usual; a move leaves the axes it
    /// names unknown and is refused where it may cut in the zone; anything else is a function
    /// errmap does not follow.
    fn skipped_block(&mut self, n: u64, content: &str, term: &str, b: &Block) -> Result<()> {
        let mut plain = b.clone();
        plain.skip = false;
        let harmless_m = is_m_block(&b.head)
            && !b.words.iter().any(|w| {
                w.addr == "M" && matches!(w.num(), Some(89.0 | 91.0 | 92.0 | 99.0 | 140.0))
            });
        let path = matches!(b.head.as_str(), "L" | "C" | "CR" | "CT" | "LP" | "CP");
        if matches!(b.head.as_str(), "" | ";" | "*" | "STOP") || harmless_m {
            return self.line(n, content, term, &plain);
        }
        if path
            && !has_coordinates(b)
            && !b.words.iter().any(|w| {
                w.addr == "M"
                    && !w
                        .num()
                        .is_some_and(|m| M_START.contains(&m) || M_END.contains(&m))
            })
            && !b.has("RL")
            && !b.has("RR")
        {
            return self.line(n, content, term, &plain);
        }
        if path {
            let mut end = self.end_point(b, self.m.pos);
            let (a1, a2, _) = self.circle_plane().axes();
            if b.head != "L" {
                end[a1] = None;
                end[a2] = None;
            }
            let cutting = !b.has("FMAX");
            self.prev_touch = self.may_touch(&[self.m.pos, end]);
            if cutting && self.prev_touch {
                return Err(self.err(n, 1, "/", format!("block skip `/` on a cut that may lie in the compensation zone: whether the TNC runs `{} {}` depends on the block-skip switch", b.head, b.rest), "remove the `/` from cuts in the zone (or the block), or move the zone away"));
            }
            self.unchanged(n, content, term, b, false)?;
            let moved: Vec<usize> = (0..3).filter(|&i| end[i] != self.m.pos[i]).collect();
            self.m.lose_position(n, &moved);
            if b.has("RL") || b.has("RR") || b.has("R") {
                self.radius_comp = Some((
                    n,
                    format!("/ {} {} (radius compensation unknown here)", b.head, b.rest),
                ));
            }
            return Ok(());
        }
        let what = format!("/ {} {}", b.head, b.rest).trim().to_string();
        self.frames.push(Frame {
            cycle: "?".into(),
            line: n,
            what,
            normal: true,
        });
        self.m.lose_position(n, &[0, 1, 2]);
        self.unchanged(n, content, term, b, false)
    }

    /// FK (`FL`, `FC` …) and approach/departure blocks: not followed; refused
    /// when they may touch the zone, and they leave the plane position unknown.
    fn unfollowed_contour(&mut self, n: u64, content: &str, term: &str, b: &Block) -> Result<()> {
        self.radius_words(n, b, false);
        let (what, hint) = match b.head.as_str() {
            "LP" | "CP" => ("polar coordinates (LP/CP)", "post the program with Cartesian L and C/CR blocks for the zone (or move the zone away)"),
            "APPR" | "DEP" => ("an approach/departure function (APPR/DEP)", "post the approach with explicit L and C blocks, R0, for the zone (or move the zone away)"),
            _ => ("FK free contour programming", "post the contour as L and C/CR blocks for the zone (or move the zone away)"),
        };
        let start = self.m.pos;
        let mut end = self.end_point(b, start);
        let (a1, a2, ax) = self.plane().axes();
        end[a1] = None;
        end[a2] = None;
        if !matches!(b.head.as_str(), "LP" | "CP") && b.rest.to_ascii_uppercase().contains(AXES[ax])
        {
            end[ax] = None;
        }
        let cutting = !b.has("FMAX");
        self.prev_touch = self.may_touch(&[start, end]);
        if cutting && self.prev_touch {
            return Err(self.err(n, b.head_col, &b.head, format!("{what} on a cut that may lie in the compensation zone: errmap does not follow it"), hint));
        }
        self.corner = None;
        self.unchanged(n, content, term, b, false)?;
        self.m.pos = end;
        self.m.lose_position(n, &[]);
        Ok(())
    }

    /// `LBL n` starts a label body (entered by calls and jumps from anywhere); `LBL 0` ends it.
    fn label_block(&mut self, n: u64, content: &str, term: &str, b: &Block) -> Result<()> {
        let name = b.rest.trim().to_string();
        if name == "0" {
            self.label = None;
        } else {
            self.label = Some((n, format!("LBL {name}")));
            self.enter_unknown(n, &format!("LBL {name}"));
        }
        self.unchanged(n, content, term, b, false)
    }

    /// After a label entry or a call: the position is unknown, and so are the frames and the
    /// radius compensation when the program has any.
    fn enter_unknown(&mut self, n: u64, what: &str) {
        self.m.lose_position(n, &[0, 1, 2]);
        self.centre = [None; 3];
        self.prev_touch = true;
        if self.program_transforms {
            self.frames.push(Frame {
                cycle: "?".into(),
                line: n,
                what: format!("{what} (datum and transformations unknown here)"),
                normal: true,
            });
        }
        if self.program_radius_comp {
            self.radius_comp = Some((n, format!("{what} (radius compensation unknown here)")));
        }
    }

    /// `CALL LBL n [REP m]` runs a label body; `CALL PGM` another program.
    fn call_block(&mut self, n: u64, content: &str, term: &str, b: &Block) -> Result<()> {
        let what = format!("CALL {}", b.rest).trim().to_string();
        self.unchanged(n, content, term, b, false)?;
        self.enter_unknown(n, &what);
        let up = b.rest.trim_start().to_ascii_uppercase();
        if !up.starts_with("LBL") {
            self.frames.push(Frame {
                cycle: if up.starts_with("PGM") { "pgm" } else { "?" }.into(),
                line: n,
                what,
                normal: true,
            });
        }
        Ok(())
    }

    /// `TOOL CALL n Z …` sets the tool axis; the tool change leaves the position unknown.
    fn tool_block(&mut self, n: u64, content: &str, term: &str, b: &Block) -> Result<()> {
        let up = b.rest.to_ascii_uppercase();
        if up.starts_with("CALL") {
            for tok in up.split_whitespace().skip(1) {
                if let Some(i) = AXES.iter().position(|a| *a == tok) {
                    self.tool_axis = i;
                }
            }
            self.unchanged(n, content, term, b, false)?;
            self.m.lose_position(n, &[0, 1, 2]);
            return Ok(());
        }
        self.copy(content, term, b);
        Ok(())
    }
}

/// How far the end point of a C block may lie off the circle through its start, mm.
const C_END_TOLERANCE_MM: f64 = 0.016;

const CT_HINT: &str = "post the arc as CC + C or as CR (or move the zone away)";

const CORNER_HINT: &str = "post the rounding as an explicit arc (CR/C) and the chamfer as an L block, or move the zone away";

/// Whether a path block moves an axis (`X`, `IY`, `A` …, or polar `PA`, `IPA`, `PR`, `IPR`).
fn has_coordinates(b: &Block) -> bool {
    b.words.iter().any(|w| {
        let a = w.addr.strip_prefix('I').unwrap_or(&w.addr);
        matches!(
            a,
            "X" | "Y" | "Z" | "A" | "B" | "C" | "U" | "V" | "W" | "PA" | "PR"
        )
    })
}

/// A block of M functions only (`M30`).
pub(super) fn is_m_block(head: &str) -> bool {
    super::block::is_m_head(head)
}

pub(super) use super::super::point::known;
