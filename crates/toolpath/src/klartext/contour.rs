//! Klartext cuts under tool radius compensation (RL/RR) with the map normal along the tool axis: only the tool-axis coordinate gets −E, lines become collinear `L` pieces, arcs become helical `CP IPA… IZ… DR…` pieces about the same pole, the RL/RR and R0 blocks stay one block, and no block without motion in the working plane is written.
//!
//! The TNC offsets the contour it reads in the working plane; P − E changes no plane
//! coordinate, so the offset contour is the original's as long as lines are split into
//! collinear pieces and arcs into pieces about the same centre (tangent joints: no corner for
//! the control to go round). On a TNC a helix is programmed only in polar coordinates (TNC 320
//! User's Manual §6.5 "Helical interpolation": the incremental total angle and the total
//! height), so an arc piece that carries P − E is a `CP` about the pole CC, which for a `C`
//! or `CP` block is the arc's own centre.

use super::super::arc::{Arc, Plane};
use super::super::gcode::{emit_curve, lerp, Breaks};
use super::block::{Block, Word};
use super::interp::{PathMove, Refusal};
use super::Kt;
use crate::setting::Setting;
use errmap_core::error::Result;
use errmap_core::setting::words;

const AXES: [&str; 3] = ["X", "Y", "Z"];

/// Decimals of an angle the TNC accepts (PA/IPA: ±99 999.9999°).
const ANGLE_DECIMALS: usize = 4;

/// M functions that act at the end of their block: they go with the last piece.
const M_END: [f64; 7] = [0.0, 1.0, 2.0, 5.0, 6.0, 9.0, 30.0];

use super::super::machine::Emitted;
use super::Comp;

impl Kt<'_> {
    /// `RL` or `RR` when that compensation is known to be in force.
    pub(super) fn comp_word(&self) -> Option<&str> {
        self.radius_comp
            .as_ref()
            .map(|(_, w)| w.as_str())
            .filter(|w| matches!(*w, "RL" | "RR"))
    }

    /// The mode of a path block, from the compensation before it and after its own R word
    /// (`after`).
    pub(super) fn comp_mode(&self, after: &Option<(u64, String)>) -> Comp {
        let will = after
            .as_ref()
            .map(|(_, w)| w.as_str())
            .filter(|w| matches!(*w, "RL" | "RR"));
        match (self.comp_word(), will) {
            (None, None) => Comp::Off,
            (Some(a), Some(b)) if a == b => Comp::Contour,
            _ => Comp::Transition,
        }
    }

    /// Why a cut under radius compensation (or switching it) cannot be compensated: the
    /// compensation is unknown here, the map's normal is not the tool axis, or the block is an
    /// arc errmap cannot write as helical pieces about CC.
    pub(super) fn comp_refusal(
        &self,
        b: &Block,
        after: &Option<(u64, String)>,
        mode: Comp,
    ) -> Option<Refusal> {
        let before = &self.radius_comp;
        let col = b.head_col;
        let word_col = |w: &str| b.word(w).map_or(col, |x| x.col);
        if let Some((l, w)) = before.as_ref().or(after.as_ref()) {
            if !matches!(w.as_str(), "RL" | "RR") {
                return Some((col, w.clone(), format!("tool radius compensation {w} (from {}) may be active on a cut in the compensation zone", self.at(*l)), "post the program as the tool-centre path (R0) for the zone, or move the zone away".into()));
            }
        }
        let (l, w) = before
            .as_ref()
            .or(after.as_ref())
            .filter(|_| mode != Comp::Off)?;
        let at = self.at(*l);
        let shown = if b.has("RL") || b.has("RR") || b.has("R0") {
            ["RL", "RR", "R0"]
                .into_iter()
                .find(|x| b.has(x))
                .unwrap_or("RL")
                .to_string()
        } else {
            w.clone()
        };
        if self.m.normal != self.tool_axis {
            return Some((
                word_col(&shown),
                shown.clone(),
                format!("tool radius compensation {w} (from {at}) offsets the contour in the working plane of tool axis {}, which holds the map's normal axis {}: moving {} by −E would change the contour the TNC offsets", AXES[self.tool_axis], AXES[self.m.normal], AXES[self.m.normal]),
                "compensate with the tool axis along the map's normal (TOOL CALL … Z for a Z map), or post the program as the tool-centre path (R0) for the zone, or move the zone away".into(),
            ));
        }
        let arc_hint = "post the arc as CC + C (the pole is then its centre), or as the tool-centre path (R0) for the zone, or move the zone away";
        match b.head.as_str() {
            "CR" => Some((col, "CR".into(), format!("arc CR under tool radius compensation {w} (from {at}) in the compensation zone: errmap must write it as helical pieces, which a TNC programs only as CP about the pole CC, and a CR's centre is not the pole"), arc_hint.into())),
            "C" | "CP" if mode == Comp::Transition => Some((word_col(&shown), shown, format!("{} block that switches tool radius compensation ({w}, {at}) in the compensation zone: the TNC switches compensation on or off only in a straight-line block, and errmap keeps that block whole", b.head), "switch RL/RR and R0 in L blocks outside the zone, or move the zone away".into())),
            "C" | "CP" if self.circle_plane() != Plane::G17 || self.tool_axis != 2 => Some((col, b.head.clone(), format!("{} in another plane than the working plane under tool radius compensation {w} (from {at}) in the compensation zone", b.head), arc_hint.into())),
            _ => None,
        }
    }

    /// Compensate a cut under radius compensation: collinear `L` pieces or helical `CP` pieces
    /// that all move in the working plane, or the RL/RR/R0 block as one block.
    pub(super) fn compensate_contour(
        &mut self,
        n: u64,
        content: &str,
        term: &str,
        b: &Block,
        mv: &PathMove,
        mode: Comp,
    ) -> Result<()> {
        // Arc pieces are arcs: only length and quarter turns cut them.
        let Some((s, e, pieces)) =
            self.bounded_ends(n, b, mv, f64::INFINITY, &[Setting::MaxSegment])?
        else {
            return self.unchanged(n, content, term, b, false);
        };
        let step = self.m.step();
        if let Some(a) = &mv.arc {
            if (a.r_start - a.r_end).abs() > self.half_digit() {
                return Err(self.err(n, b.head_col, &b.head, format!("under tool radius compensation this arc must stay arcs, written as CP about CC, whose radius cannot change; its end lies {:.4} off the circle through its start", (a.r_start - a.r_end).abs()), "put the end point on the circle about CC, or post the arc as the tool-centre path (R0) for the zone"));
            }
            // The end of a CP piece is set by an angle of four decimals.
            let angle_err =
                a.r_start * (2.0 * 0.5 * 10f64.powi(-(ANGLE_DECIMALS as i32))).to_radians();
            if angle_err > self.m.chord_tol() {
                return Err(self.err(n, b.head_col, &b.head, format!("under tool radius compensation this arc must be written as CP pieces, whose end the TNC takes from an angle of {ANGLE_DECIMALS} decimals: on radius {:.4} that may leave the arc's end {angle_err:.6} away, more than {chord_tol}", a.r_start, chord_tol = words(Setting::ChordTol)), &format!("raise {}, or post the arc as the tool-centre path (R0) for the zone", words(Setting::ChordTol))));
            }
        }
        let mut emitted: Vec<Emitted> = Vec::new();
        {
            let curve = |t: f64| match &mv.arc {
                None => lerp(&s, &e, t),
                Some(a) => a.point(t),
            };
            let error_at = |p: &[f64; 3]| self.m.error_at(p);
            let complete = emit_curve(
                Breaks::Fractions(pieces),
                &curve,
                step,
                self.m.zone_now(),
                self.m.normal,
                &error_at,
                1_000_000,
                &mut emitted,
            );
            if !complete {
                return Err(self.err(
                    n,
                    b.head_col,
                    &b.head,
                    "this move is cut into more than a million pieces".into(),
                    &format!(
                        "check the move's length, or raise {}",
                        words(Setting::MaxSegment)
                    ),
                ));
            }
        }
        self.m.kept_nominal.count(&mut self.report);
        if !emitted.iter().any(|(_, e)| e.is_some()) {
            let absolute = b.head == "L" && b.word(AXES[self.m.normal]).is_some();
            return self.unchanged(n, content, term, b, absolute);
        }
        let (a1, a2, _) = Plane::G17.axes();
        let same_plane = |p: &[f64; 3], q: &[f64; 3]| {
            (p[a1] - q[a1]).abs() <= 1e-9 && (p[a2] - q[a2]).abs() <= 1e-9
        };
        let Some(&last) = emitted.last() else {
            return Ok(());
        };
        // The points written: each moves in the plane from the one before. A point that does
        // not (the second of a zone-edge pair) is dropped, so its step along the normal rides
        // on the next piece; a move with no plane motion (`L Z…`) is one block, as written.
        let in_plane = emitted.iter().any(|(p, _)| !same_plane(p, &s));
        let mut chosen: Vec<Emitted> = Vec::new();
        if !in_plane || mode == Comp::Transition {
            if mode == Comp::Transition {
                self.check_transition(n, b, &emitted, mv.arc.is_some(), s)?;
            }
            chosen.push(last);
        } else {
            let mut prev = s;
            for &(p, e) in &emitted[1..] {
                if !same_plane(&p, &prev) {
                    chosen.push((p, e));
                    prev = p;
                }
            }
        }
        if let Some(a) = mv.arc.as_ref().filter(|_| in_plane) {
            chosen = self.m.helical_pieces(a, s, &chosen).ok_or_else(|| {
                self.err(
                    n,
                    b.head_col,
                    &b.head,
                    format!("under tool radius compensation this arc must stay arcs, and no helical piece short enough follows P − E within {} (the map bends too sharply along it)", words(Setting::ChordTol)),
                    &format!("raise {}, or post the arc as the tool-centre path (R0)", words(Setting::ChordTol)),
                )
            })?;
        }
        self.write_contour(
            content,
            term,
            b,
            s,
            &chosen,
            mv.arc.as_ref().filter(|_| in_plane),
        );
        Ok(())
    }

    /// Half a unit of the last decimal written.
    fn half_digit(&self) -> f64 {
        0.5 * 10f64.powi(-(self.decimals as i32))
    }

    /// The RL/RR or R0 block stays one block (the TNC ramps the offset on or off over it): it
    /// must lie wholly in the zone and domain, be straight, and its tool-axis coordinate,
    /// linear along it, must stay within `chord_tol` of P − E.
    fn check_transition(
        &self,
        n: u64,
        b: &Block,
        emitted: &[Emitted],
        arc: bool,
        s: [f64; 3],
    ) -> Result<()> {
        let word = ["RL", "RR", "R0"]
            .into_iter()
            .find(|w| b.has(w))
            .unwrap_or("R0");
        let what = if word == "R0" {
            "ends tool radius compensation (R0)"
        } else {
            "starts tool radius compensation"
        };
        let col = b.word(word).map_or(b.head_col, |w| w.col);
        let refuse = |why: String| {
            Err(self.err(
                n,
                col,
                word,
                format!("this block {what}, so errmap must keep it one block, but {why}"),
                "switch RL/RR and R0 outside the zone (or where the map is flat along the block), or move the zone away",
            ))
        };
        if arc {
            return refuse("it is an arc".into());
        }
        if emitted.iter().any(|(_, e)| e.is_none()) {
            return refuse("it crosses the edge of the zone or of the measured domain".into());
        }
        let (Some(&(end, Some(e_end))), Some(e_start)) =
            (emitted.last(), emitted.first().and_then(|(_, e)| *e))
        else {
            return Ok(());
        };
        let k = self.m.normal;
        let (from, to) = (s[k] - e_start, end[k] - e_end);
        for i in 0..=8 {
            let f = f64::from(i) / 8.0;
            let p = lerp(&s, &end, f);
            let Some(e) = self.m.error_at(&p) else {
                return refuse("it leaves the zone or the measured domain".into());
            };
            let dev = (from + f * (to - from)) - (p[k] - e);
            if dev.abs() > self.m.chord_tol() {
                return refuse(format!(
                    "as one block it strays {:.4} from P − E (more than {})",
                    dev.abs(),
                    words(Setting::ChordTol)
                ));
            }
        }
        Ok(())
    }

    /// Write the pieces: `L X… Y… Z…` for a line, `CP IPA… IZ… DR±` about CC for an arc; the
    /// first keeps the block's other words and comment, the last the M words that act at block
    /// end. Increments are differences of the values as written, so they add up exactly.
    fn write_contour(
        &mut self,
        content: &str,
        term: &str,
        b: &Block,
        s: [f64; 3],
        pieces: &[Emitted],
        arc: Option<&Arc>,
    ) {
        let d = self.decimals;
        let written = |v: f64, d: usize| {
            let p = 10f64.powi(d as i32);
            (v * p).round() / p
        };
        let k = self.m.normal;
        let mut out_n = written(s[k] + self.m.offset, d);
        // Angles unwrapped along the arc from the start's, written to four decimals.
        let (c1, c2) = arc.map_or((0.0, 0.0), |a| a.centre);
        let angle = |p: &[f64; 3]| (p[1] - c2).atan2(p[0] - c1).to_degrees();
        let mut theta = angle(&s);
        let mut theta_w = written(theta, ANGLE_DECIMALS);
        let mut bodies: Vec<String> = Vec::new();
        let mut last_e = None;
        for (p, e) in pieces {
            let mut q = *p;
            if let Some(e) = e {
                q[k] -= e;
                self.report.max_abs_error_mm = self
                    .report
                    .max_abs_error_mm
                    .max(e.abs() * self.m.scale_mm());
                self.report.points_compensated += 1;
            }
            last_e = *e;
            let body = match arc {
                None => {
                    let mut t = String::from(" L");
                    for (i, a) in AXES.iter().enumerate() {
                        t.push_str(&format!(" {a}{}", self.coord(q[i])));
                    }
                    out_n = written(q[k], d);
                    t
                }
                Some(a) => {
                    let mut delta = angle(p) - theta;
                    // The piece turns in the arc's direction, less than a full turn.
                    if a.sweep >= 0.0 {
                        delta = delta.rem_euclid(360.0);
                    } else {
                        delta = -(-delta).rem_euclid(360.0);
                    }
                    theta += delta;
                    let tw = written(theta, ANGLE_DECIMALS);
                    let ipa = signed(tw - theta_w, ANGLE_DECIMALS);
                    theta_w = tw;
                    let zw = written(q[k], d);
                    let iz = signed(zw - out_n, d);
                    out_n = zw;
                    let dr = if a.sweep >= 0.0 { "DR+" } else { "DR-" };
                    format!(" CP IPA{ipa} I{}{iz} {dr}", AXES[k])
                }
            };
            bodies.push(body);
        }
        let end_m = |w: &Word| w.addr == "M" && w.num().is_some_and(|m| M_END.contains(&m));
        let replaced = |w: &Word| {
            matches!(
                w.addr.as_str(),
                "X" | "Y" | "Z" | "IX" | "IY" | "IZ" | "DR" | "PA" | "IPA" | "PR" | "IPR"
            ) || (b.head == "CR" && w.addr == "R")
                || end_m(w)
        };
        let first: String = b
            .words
            .iter()
            .filter(|w| !replaced(w))
            .map(|w| format!(" {}", w.text))
            .collect();
        let end: String = b
            .words
            .iter()
            .filter(|w| end_m(w))
            .map(|w| format!(" {}", w.text))
            .collect();
        let count = bodies.len();
        let span = b.number_span.clone();
        for (i, mut body) in bodies.into_iter().enumerate() {
            if i == 0 {
                body.push_str(&first);
            }
            if i + 1 == count {
                body.push_str(&end);
            }
            if i == 0 {
                body.push_str(&b.comment);
            }
            let t = match (i + 1 == count, term.is_empty()) {
                (false, true) => "\n",
                _ => term,
            };
            let (before, number) = if i == 0 && span.end <= content.len() {
                (
                    content[..span.start].to_string(),
                    content[span.clone()].to_string(),
                )
            } else {
                (String::new(), String::new())
            };
            self.push(super::OutLine {
                before,
                number: Some(number),
                after: body,
                term: t.to_string(),
            });
        }
        self.report.moves_changed += 1;
        if count > 1 {
            self.report.moves_split += 1;
        }
        self.report.segments_emitted += count as u64;
        // Where the output stands against the original's end.
        let end_orig = pieces.last().map_or(s[k], |(p, _)| p[k]);
        let written_off = out_n - end_orig;
        let e_last = last_e.unwrap_or(0.0);
        self.m.offset = if (written_off + e_last).abs() <= self.half_digit() {
            -e_last
        } else {
            written_off
        };
    }

    /// Under RL/RR a return along the normal may not be a block of its own: a block that moves
    /// nothing waits for it (`Ok(None)` — copied as is), an `L` that moves in the plane without
    /// a tool-axis word carries it (its text with ` Z…` added), anything else is refused.
    pub(super) fn fold_return(
        &mut self,
        n: u64,
        content: &str,
        b: &Block,
    ) -> Result<Option<String>> {
        let k = self.m.normal;
        let waits = match b.head.as_str() {
            "" | ";" | "*" => true,
            "CC" => !b.has(AXES[k]) && !b.has(&format!("I{}", AXES[k])),
            "L" => !b.words.iter().any(|w| {
                matches!(
                    w.addr.trim_start_matches('I'),
                    "X" | "Y" | "Z" | "A" | "B" | "C" | "U" | "V" | "W" | "PA" | "PR"
                ) || matches!(w.addr.as_str(), "RL" | "RR" | "R" | "M")
            }),
            h if super::interp::is_m_block(h) => b.words.iter().all(|w| {
                w.addr == "M"
                    && w.num().is_some_and(|m| {
                        !matches!(m as i64, 0 | 1 | 2 | 6 | 30 | 89 | 91 | 92 | 99 | 140)
                    })
            }),
            h => h.starts_with('Q') || (h == "FN" && !b.rest.trim_start().starts_with("17")),
        };
        if waits {
            return Ok(None);
        }
        let plane_word = b
            .words
            .iter()
            .filter(|w| w.value != super::block::Value::Param)
            .any(|w| matches!(w.addr.as_str(), "X" | "Y" | "IX" | "IY"));
        let blocked = b.head != "L"
            || b.skip
            || !plane_word
            || b.words.iter().any(|w| {
                w.addr.trim_start_matches('I') == AXES[k]
                    || (w.addr == "M" && matches!(w.num(), Some(91.0 | 92.0 | 140.0)))
            });
        let orig = self.m.pos[k];
        let insert_at = b
            .words
            .iter()
            .filter(|w| matches!(w.addr.as_str(), "X" | "Y" | "IX" | "IY"))
            .map(|w| w.col - 1 + w.text.chars().count())
            .max()
            .and_then(|c| {
                content
                    .char_indices()
                    .map(|(i, _)| i)
                    .chain([content.len()])
                    .nth(c)
            });
        let (Some(orig), Some(at), false) = (orig, insert_at, blocked) else {
            let (l, w) = self.radius_comp.clone().unwrap_or((n, "RL".into()));
            let axis = AXES[k];
            return Err(self.err(
                n,
                b.head_col,
                &b.head,
                format!("a compensated cut under tool radius compensation {w} (from {}) ends {axis} −E away from the program, and this block cannot carry the return along {axis}: errmap would have to insert a block without motion in the working plane, which the TNC's compensation does not look past (it may gouge the contour or stop)", self.at(l)),
                &format!("give this block an absolute {axis}, or make it an L move in the plane, or end the contour above the zone before it"),
            ));
        };
        let mut text = content.to_string();
        text.insert_str(at, &format!(" {}{}", AXES[k], self.coord(orig)));
        self.m.offset = 0.0;
        self.report.returns_inserted += 1;
        Ok(Some(text))
    }
}

/// `+12.3456` / `-0.0100` with `d` decimals.
fn signed(v: f64, d: usize) -> String {
    let t = super::super::gcode::format_decimals(v, d);
    if t.starts_with('-') {
        t
    } else {
        format!("+{t}")
    }
}
